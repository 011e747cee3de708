//! `insgen export-yolo`: an Ultralytics YOLO segmentation dataset from a COCO instance export.

use std::path::PathBuf;

use anyhow::Context;

use crate::export::yolo::{export_yolo, YoloPlan};

/// Export YOLO segmentation labels and data.yaml (Ultralytics format) from a COCO instance export.
///
/// Reads instances_{train,val,test}.json (those present) from the COCO directory written by `insgen
/// export-coco`, and each image's ID map (`mask_file`); every annotation's mask is checked against its
/// ID map. Writes labels/<split>/<area>/<camera>/<frame>.txt (one line per instance: `0 x1 y1 x2 y2 …`,
/// normalised to [0, 1]; holes joined to the outline by zero-width cuts; crowd annotations left out),
/// images/<split>/… (hard links to the export's photos, copies across file systems) and data.yaml
/// (no `path:` key, so the folder can move).
#[derive(Debug, Clone, clap::Args)]
#[command(after_long_help = "Examples:\n  insgen export-coco && insgen export-yolo\n  \
insgen export-yolo --coco runs/coco --out datasets/buildings-yolo\n\n\
Train with Ultralytics:\n  yolo segment train data=runs/coco/yolo/data.yaml model=yolo11n-seg.pt")]
pub struct Args {
    /// COCO directory written by `export-coco` [default: <workdir>/coco].
    #[arg(long, value_name = "DIR")]
    pub coco: Option<PathBuf>,
    /// Output directory [default: <COCO directory>/yolo].
    #[arg(long, value_name = "DIR")]
    pub out: Option<PathBuf>,
}

impl Args {
    /// The plan for `global.workdir`.
    pub fn plan(&self, global: &super::Global) -> YoloPlan {
        let coco_dir = self.coco.clone().unwrap_or_else(|| global.workdir.join("coco"));
        YoloPlan { out_dir: self.out.clone().unwrap_or_else(|| coco_dir.join("yolo")), coco_dir }
    }
}

/// Runs `export-yolo`.
pub fn run(args: &Args, global: &super::Global) -> anyhow::Result<()> {
    let plan = args.plan(global);
    let printer = global.printer();
    let progress = printer.progress();
    let (summaries, yaml) = export_yolo(&plan, &progress)
        .with_context(|| format!("exporting YOLO labels from {}", plan.coco_dir.display()))?;
    for s in summaries {
        printer.summary(format!(
            "{}: {} images, {} instances ({} crowd left out), at most {} vertices per polygon",
            s.split, s.images, s.instances, s.crowd_skipped, s.max_vertices
        ));
    }
    printer.summary(format!("wrote {}", yaml.display()));
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(argv: &[&str]) -> Result<crate::cli::testing::Parsed<Args>, clap::Error> {
        crate::cli::testing::parse(argv)
    }

    #[test]
    fn out_defaults_to_yolo_inside_the_coco_directory() {
        let t = parse(&["--coco", "c"]).unwrap();
        let p = t.args.plan(&t.global);
        assert_eq!((p.coco_dir, p.out_dir), (PathBuf::from("c"), PathBuf::from("c/yolo")));
        let t = parse(&[]).unwrap();
        assert_eq!(t.args.plan(&t.global).out_dir, PathBuf::from("runs/coco/yolo"));
    }

    #[test]
    fn out_takes_a_directory() {
        let t = parse(&["--out", "o"]).unwrap();
        assert_eq!(t.args.plan(&t.global).out_dir, PathBuf::from("o"));
        assert!(parse(&["--out"]).is_err());
    }
}
