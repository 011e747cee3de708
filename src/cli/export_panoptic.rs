//! `insgen export-panoptic`: COCO panoptic segmentation from a COCO instance export.

use std::path::PathBuf;

use anyhow::Context;

use crate::export::panoptic::{export_panoptic, PanopticPlan};

/// Export COCO panoptic segmentation (PNGs + panoptic_<split>.json) from a COCO instance export.
///
/// Reads instances_{train,val,test}.json (those present) from the COCO directory written by `insgen
/// export-coco`, and each image's ID map (`mask_file`); every annotation's mask is checked against its
/// ID map. Writes panoptic_<split>.json and panoptic_<split>/<area>/<camera>/<frame>.png: segment id =
/// R + 256·G + 256²·B (the panoptic API's rgb2id) = the instance annotation's id, 0 = void. The images
/// are the instance files' images, unchanged.
#[derive(Debug, Clone, clap::Args)]
#[command(after_long_help = "Examples:\n  insgen export-coco && insgen export-panoptic\n  \
insgen export-panoptic --coco runs/coco --out runs/panoptic\n\n\
Evaluate predictions with the COCO panoptic API:\n  \
python -m panopticapi.evaluation --gt_json_file runs/coco/panoptic_val.json \\\n    \
--gt_folder runs/coco/panoptic_val --pred_json_file pred.json --pred_folder pred/")]
pub struct Args {
    /// COCO directory written by `export-coco` [default: <workdir>/coco].
    #[arg(long, value_name = "DIR")]
    pub coco: Option<PathBuf>,
    /// Output directory [default: the COCO directory].
    #[arg(long, value_name = "DIR")]
    pub out: Option<PathBuf>,
}

impl Args {
    /// The plan for `global.workdir`.
    pub fn plan(&self, global: &super::Global) -> PanopticPlan {
        let coco_dir = self.coco.clone().unwrap_or_else(|| global.workdir.join("coco"));
        PanopticPlan { out_dir: self.out.clone().unwrap_or_else(|| coco_dir.clone()), coco_dir }
    }
}

/// Runs `export-panoptic`.
pub fn run(args: &Args, global: &super::Global) -> anyhow::Result<()> {
    let plan = args.plan(global);
    let printer = global.printer();
    let progress = printer.progress();
    let summaries = export_panoptic(&plan, &progress)
        .with_context(|| format!("exporting COCO panoptic from {}", plan.coco_dir.display()))?;
    for s in summaries {
        printer.summary(format!(
            "{}: {} images, {} segments → {}",
            s.split,
            s.images,
            s.segments,
            s.file.display()
        ));
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
    fn coco_defaults_to_the_workdir_and_out_to_coco() {
        let t = parse(&["--workdir", "w"]).unwrap();
        let p = t.args.plan(&t.global);
        assert_eq!((p.coco_dir, p.out_dir), (PathBuf::from("w/coco"), PathBuf::from("w/coco")));
    }

    #[test]
    fn coco_and_out_take_directories() {
        let t = parse(&["--coco", "c", "--out", "o"]).unwrap();
        let p = t.args.plan(&t.global);
        assert_eq!((p.coco_dir, p.out_dir), (PathBuf::from("c"), PathBuf::from("o")));
        assert!(parse(&["--coco"]).is_err());
    }
}
