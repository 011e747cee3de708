//! `insgen merge [SOURCE...]`: merges work directories of shards into `--workdir` (see
//! [`crate::util::merge`]) and combines the reports shards wrote in parts: COCO exports
//! ([`crate::export::parts`]) and localization results ([`crate::loc::eval::combine_parts`]). Every
//! combined file is checked against what the destination holds before anything is written.

use std::path::PathBuf;

use anyhow::Context;

/// Merges the work directories of shards (e.g. node-local scratch of a job array) into --workdir.
///
/// Per-frame outputs of `render-masks` and `render-rgb` shards are disjoint files and the shared
/// inputs (prepared scene, poses) are identical, so the merge is a union of files: missing files are
/// copied, identical ones kept, and a path holding different bytes in two places stops the merge
/// before anything is written. The command logs (commands.jsonl) are merged line by line.
///
/// Parts of reports written by shards (`export-coco --shard`, `eval-loc --shard`: <report>/parts/I-of-N/)
/// are combined, not copied: the COCO files get the images of all parts in the export's order with
/// ids renumbered, the statistics, manifest and card are recomputed; the localization results are put
/// back in query order and the summary recomputed from them. The result equals a single-process run.
/// Parts already in --workdir count too: without SOURCE, the merge combines the parts that shards
/// wrote into one shared work directory.
#[derive(Debug, Clone, clap::Args)]
#[command(after_long_help = "Examples:\n  \
insgen merge --workdir runs /scratch/task0/runs /scratch/task1/runs\n  \
insgen merge --workdir runs runs-shard-*\n  \
insgen merge --workdir runs   # combine the parts shards wrote into runs/ itself")]
pub struct Args {
    /// Work directories written by the shards (each holds <area>/<camera>/…).
    #[arg(value_name = "SOURCE")]
    pub sources: Vec<PathBuf>,
}

/// A report combined from its parts, ready to write.
enum Combined {
    Coco(Box<crate::export::parts::Combined>),
    Loc { out_dir: PathBuf, outputs: Box<crate::loc::eval::Outputs> },
}

/// Runs `insgen merge`.
pub fn run(args: &Args, global: &super::Global) -> anyhow::Result<()> {
    let printer = global.printer();
    let dest = &global.workdir;
    let plan = crate::util::merge::plan_merge(&args.sources, dest)
        .with_context(|| format!("merging into {}", dest.display()))?;
    // Combine every report's parts in memory first, and check the combined files against what the
    // destination will hold: nothing is written unless the whole merge can go through.
    let mut combined = Vec::new();
    let mut conflicts = Vec::new();
    for rp in &plan.parts {
        let out_dir = dest.join(&rp.report);
        let kind = part_kind(&rp.parts)?;
        let (c, primary): (Combined, Vec<(PathBuf, Vec<u8>)>) = match kind.as_str() {
            crate::export::parts::PART_KIND => {
                let c = crate::export::parts::combine(&rp.parts, dest, &out_dir)
                    .with_context(|| format!("combining the COCO parts of {}", out_dir.display()))?;
                let files = coco_bytes(&c, &rp.report)?;
                (Combined::Coco(Box::new(c)), files)
            }
            crate::loc::eval::PART_KIND => {
                let outputs = crate::loc::eval::combine_parts(&rp.parts, &out_dir)
                    .with_context(|| format!("combining the eval-loc parts of {}", out_dir.display()))?;
                let mut files = vec![(
                    PathBuf::from(crate::loc::eval::RESULTS_FILE),
                    outputs.results_jsonl.clone().into_bytes(),
                )];
                files.extend(
                    outputs.est_poses.iter().map(|(n, t)| (PathBuf::from(n), t.clone().into_bytes())),
                );
                (Combined::Loc { out_dir: out_dir.clone(), outputs: Box::new(outputs) }, files)
            }
            other => anyhow::bail!(
                "{}: parts of kind {other:?}, which this insgen cannot combine (a newer version wrote them?)",
                out_dir.display()
            ),
        };
        for (name, bytes) in primary {
            let rel = rp.report.join(&name);
            if let Some(holder) = plan.holder(&rel) {
                let held = crate::util::read_file(&holder)?;
                if held != bytes {
                    conflicts.push(format!(
                        "{} differs from what its parts combine into ({} part(s))",
                        holder.display(),
                        rp.parts.len()
                    ));
                }
            }
        }
        combined.push(c);
    }
    if let Some(first) = conflicts.first() {
        anyhow::bail!(
            "merging into {}: {} combined file(s) conflict with existing ones, e.g. {first}; nothing was \
             written (the parts are of another run than the files already there: remove one or the other)",
            dest.display(),
            conflicts.len()
        );
    }
    let report = plan.apply().with_context(|| format!("merging into {}", dest.display()))?;
    let mut reports = Vec::new();
    for c in combined {
        match c {
            Combined::Coco(c) => {
                let (ex, mut written) =
                    crate::export::coco::write_export(&c.plan, c.export).with_context(|| {
                        format!("writing the combined export to {}", c.plan.out_dir.display())
                    })?;
                super::log_coco_export(&c.plan, &ex);
                if let Some(opts) = c.report {
                    let files =
                        crate::export::stats::write_export_report(&c.plan, &ex, opts).with_context(|| {
                            format!("writing the statistics report in {}", c.plan.out_dir.display())
                        })?;
                    written.extend(files);
                }
                for f in &written {
                    log::info!("wrote {}", f.display());
                }
                reports.push(c.plan.out_dir.display().to_string());
            }
            Combined::Loc { out_dir, outputs } => {
                crate::loc::eval::write_outputs(&out_dir, &outputs)
                    .with_context(|| format!("writing the combined evaluation to {}", out_dir.display()))?;
                reports.push(out_dir.display().to_string());
            }
        }
    }
    printer.summary(format!(
        "merged {} work directories into {}: {} files copied, {} already identical, {} command-log lines \
         added{}{}",
        args.sources.len(),
        dest.display(),
        report.copied,
        report.identical,
        report.command_lines_added,
        if report.temporaries_skipped > 0 {
            format!(", {} temporary files of interrupted runs left out", report.temporaries_skipped)
        } else {
            String::new()
        },
        if reports.is_empty() {
            String::new()
        } else {
            format!("; combined the parts of {}", reports.join(", "))
        }
    ));
    Ok(())
}

/// The `kind` the parts of one report share (from their `part.json`).
fn part_kind(parts: &std::collections::BTreeMap<crate::util::Shard, PathBuf>) -> anyhow::Result<String> {
    #[derive(serde::Deserialize)]
    struct Kind {
        kind: String,
    }
    let mut kinds = std::collections::BTreeSet::new();
    for dir in parts.values() {
        let path = dir.join(crate::util::shard::PART_MARKER);
        let k: Kind = serde_json::from_slice(&crate::util::read_file(&path)?)
            .with_context(|| format!("reading the part marker {}", path.display()))?;
        kinds.insert(k.kind);
    }
    match kinds.len() {
        1 => Ok(kinds.into_iter().next().expect("one kind")),
        _ => anyhow::bail!(
            "{}: parts of different kinds ({}) in one report directory",
            parts.values().next().map(|p| p.display().to_string()).unwrap_or_default(),
            kinds.into_iter().collect::<Vec<_>>().join(", ")
        ),
    }
}

/// The COCO files a combined export writes to `report` (relative to the work directory), as
/// [`crate::export::coco::write_export`] will write them (names inside the export folder, or under
/// `--link-root` the image root `..` per level).
fn coco_bytes(
    c: &crate::export::parts::Combined,
    report: &std::path::Path,
) -> anyhow::Result<Vec<(PathBuf, Vec<u8>)>> {
    let levels = report.components().count();
    let root = if levels == 0 { ".".to_string() } else { vec![".."; levels].join("/") };
    let mut datasets = c.export.datasets.clone();
    if !c.plan.link_root {
        crate::export::bundle::names_inside(&mut datasets);
    }
    datasets
        .into_iter()
        .map(|(split, mut ds)| {
            if c.plan.link_root {
                ds.info.image_root.clone_from(&root);
            }
            let mut bytes = serde_json::to_vec(&ds)?;
            bytes.push(b'\n');
            Ok((PathBuf::from(split.file_name()), bytes))
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(argv: &[&str]) -> Result<crate::cli::testing::Parsed<Args>, clap::Error> {
        crate::cli::testing::parse(argv)
    }

    #[test]
    fn sources_are_positionals() {
        assert!(parse(&[]).unwrap().args.sources.is_empty());
        let t = parse(&["--workdir", "out", "a", "b"]).unwrap();
        assert_eq!(t.args.sources, [PathBuf::from("a"), PathBuf::from("b")]);
        assert_eq!(t.global.workdir, PathBuf::from("out"));
    }
}
