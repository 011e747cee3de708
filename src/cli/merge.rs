//! `insgen merge SOURCE...`: merges work directories of shards into `--workdir` (see
//! [`crate::util::merge`]).

use std::path::PathBuf;

use anyhow::Context;

/// Merges the work directories of shards (e.g. node-local scratch of a job array) into --workdir.
///
/// Per-frame outputs of `render-masks` and `render-rgb` shards are disjoint files and the shared
/// inputs (prepared scene, poses) are identical, so the merge is a union of files: missing files are
/// copied, identical ones kept, and a path holding different bytes in two places stops the merge
/// before anything is written. The command logs (commands.jsonl) are merged line by line. Run
/// `export-coco` and `eval-loc` on the merged directory: the result equals a single-process run.
#[derive(Debug, Clone, clap::Args)]
#[command(after_long_help = "Examples:\n  \
insgen merge --workdir runs /scratch/task0/runs /scratch/task1/runs\n  \
insgen merge --workdir runs runs-shard-*")]
pub struct Args {
    /// Work directories written by the shards (each holds <area>/<camera>/…).
    #[arg(value_name = "SOURCE", required = true)]
    pub sources: Vec<PathBuf>,
}

pub fn run(args: &Args, global: &super::Global) -> anyhow::Result<()> {
    let printer = global.printer();
    let report = crate::util::merge::merge_workdirs(&args.sources, &global.workdir)
        .with_context(|| format!("merging into {}", global.workdir.display()))?;
    printer.summary(format!(
        "merged {} work directories into {}: {} files copied, {} already identical, {} command-log lines \
         added{}",
        args.sources.len(),
        global.workdir.display(),
        report.copied,
        report.identical,
        report.command_lines_added,
        if report.temporaries_skipped > 0 {
            format!(", {} temporary files of interrupted runs left out", report.temporaries_skipped)
        } else {
            String::new()
        }
    ));
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(argv: &[&str]) -> Result<crate::cli::testing::Parsed<Args>, clap::Error> {
        crate::cli::testing::parse(argv)
    }

    #[test]
    fn sources_are_required_positionals() {
        assert!(parse(&[]).is_err());
        let t = parse(&["--workdir", "out", "a", "b"]).unwrap();
        assert_eq!(t.args.sources, [PathBuf::from("a"), PathBuf::from("b")]);
        assert_eq!(t.global.workdir, PathBuf::from("out"));
    }
}
