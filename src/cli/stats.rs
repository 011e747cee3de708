//! `insgen stats`: the statistics report of an existing COCO export.

use std::path::PathBuf;

use anyhow::Context;

use crate::export::coco::{read_json, Split};
use crate::export::format::Dataset;
use crate::export::index::FlightPlans;
use crate::export::stats::{self, ReportOptions};

/// Summarise a COCO export: images, instances per image, size classes, buildings seen per area, and per
/// area statistics that predict learnability (touching-neighbour boundaries, their colour contrast,
/// instance sizes, masks split by occluders).
///
/// Reads instances_{train,val,test}.json from the COCO directory (those present) and the images and ID
/// maps they name (found through `info.image_root`; those not on disk are skipped). Writes stats.md, stats.json,
/// hist_instances_per_image.png, hist_sizes.png and contact_sheet.png into the same directory, and, in
/// an export-coco folder (one with dataset.json), the page that shows them: index.html with each
/// area's contact sheet (figures/), as export-coco writes it (the flight plans the folder holds are
/// kept), so the page never shows other numbers than stats.md.
#[derive(Debug, Clone, clap::Args)]
#[command(after_long_help = "Examples:\n  insgen stats --coco runs/coco\n  \
insgen stats --json | jq '.splits[] | {split, images, annotations}'")]
pub struct Args {
    /// COCO directory [default: <workdir>/coco].
    #[arg(long, value_name = "DIR")]
    pub coco: Option<PathBuf>,
    /// Frames on the contact sheet (0 = none).
    #[arg(long, value_name = "N", default_value_t = 12)]
    pub contact_sheet: usize,
    /// Print the statistics as JSON on stdout (the content of stats.json) instead of the summary.
    #[arg(long)]
    pub json: bool,
}

/// Runs `stats`.
pub fn run(args: &Args, global: &super::Global) -> anyhow::Result<()> {
    let dir = args.coco.clone().unwrap_or_else(|| global.workdir.join("coco"));
    let mut datasets: Vec<(Split, Dataset)> = Vec::new();
    for split in Split::ALL {
        let path = dir.join(split.file_name());
        if path.is_file() {
            let ds: Dataset = read_json(&path).with_context(|| format!("reading {}", path.display()))?;
            datasets.push((split, ds));
        }
    }
    if datasets.is_empty() {
        anyhow::bail!(
            "{}: no instances_train.json, instances_val.json or instances_test.json here; run `insgen \
             export-coco` first or pass --coco DIR",
            dir.display()
        );
    }
    // All files of one export share the image root; it is relative to the COCO directory.
    let root = &datasets[0].1.info.image_root;
    let image_root =
        if std::path::Path::new(root).is_absolute() { PathBuf::from(root) } else { dir.join(root) };
    let refs: Vec<_> = datasets.iter().map(|(s, d)| (*s, d)).collect();
    let st = stats::compute(&refs, &image_root)
        .with_context(|| format!("computing the statistics of {}", dir.display()))?;
    // The page beside the report shows its numbers and charts: rewritten with it, as export-coco
    // writes it, keeping the flight plans the export holds (its work directory may be elsewhere).
    let files = stats::write_report_and_index(
        &st,
        &refs,
        &dir,
        &image_root,
        FlightPlans::InExport,
        ReportOptions { contact_sheet_images: args.contact_sheet },
    )
    .with_context(|| format!("writing the statistics report in {}", dir.display()))?;
    let printer = global.printer();
    if args.json {
        println!("{}", serde_json::to_string_pretty(&st).context("serialising the statistics")?);
    } else {
        for sp in &st.splits {
            printer.summary(format!(
                "{}: {} images, {} annotations ({} small, {} medium, {} large)",
                sp.split, sp.images, sp.annotations, sp.sizes.small, sp.sizes.medium, sp.sizes.large
            ));
        }
    }
    for f in files {
        log::info!("wrote {}", f.display());
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(argv: &[&str]) -> Result<crate::cli::testing::Parsed<Args>, clap::Error> {
        crate::cli::testing::parse(argv)
    }

    #[test]
    fn json_is_a_switch() {
        assert!(parse(&["--json"]).unwrap().args.json);
        assert!(!parse(&[]).unwrap().args.json);
        assert!(parse(&["--json=yes"]).is_err());
    }
}
