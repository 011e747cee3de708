//! `insgen export-hf`: the Hugging Face `datasets` metadata of a COCO export and the card's front
//! matter that names it.

use std::path::PathBuf;

use anyhow::Context;

use crate::export::hf::{export_hf, HfPlan};

/// Write images/<split>/metadata.jsonl so that Hugging Face `datasets` loads a COCO export.
///
/// Reads instances_{train,val,test}.json of a self-contained export (`insgen export-coco` without
/// --link-root) and writes, per split with images, images/<split>/metadata.jsonl: one row per photo
/// (`file_name`, `image_id`, size, area, camera, frame) with its instances in `objects` (ids, boxes,
/// categories, areas, iscrowd, building IDs, and the exact masks as COCO RLE), and the dataset card's
/// YAML front matter (`configs:`, the files of each split) that `datasets` reads. The photos are the
/// export's own; nothing is copied. `export-coco` writes all of this already; this command rewrites it
/// (the same bytes), or adds it to an export made by an older insgen. Load with
/// `datasets.load_dataset("<export>")` (splits train, validation, test).
#[derive(Debug, Clone, clap::Args)]
#[command(after_long_help = "Examples:\n  insgen export-coco && insgen export-hf\n  \
insgen export-hf --coco datasets/buildings\n\n\
Load in Python:\n  \
from datasets import load_dataset\n  \
ds = load_dataset(\"runs/coco\")\n  \
ds[\"train\"][0][\"objects\"][\"bbox\"]")]
pub struct Args {
    /// COCO directory written by `export-coco` [default: <workdir>/coco].
    #[arg(long, value_name = "DIR")]
    pub coco: Option<PathBuf>,
}

impl Args {
    /// The plan for `global.workdir`.
    pub fn plan(&self, global: &super::Global) -> HfPlan {
        HfPlan { coco_dir: self.coco.clone().unwrap_or_else(|| global.workdir.join("coco")) }
    }
}

/// Runs `export-hf`.
pub fn run(args: &Args, global: &super::Global) -> anyhow::Result<()> {
    let plan = args.plan(global);
    let printer = global.printer();
    let summaries = export_hf(&plan)
        .with_context(|| format!("writing the Hugging Face metadata of {}", plan.coco_dir.display()))?;
    for s in summaries {
        match &s.file {
            Some(f) => printer.summary(format!(
                "{}: {} rows, {} objects → {}",
                s.split,
                s.rows,
                s.objects,
                f.display()
            )),
            None => printer.summary(format!("{}: no images, no metadata file", s.split)),
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn coco_defaults_to_the_workdir_export() {
        let t = crate::cli::testing::parse::<Args>(&[]).unwrap();
        assert_eq!(t.args.plan(&t.global).coco_dir, PathBuf::from("runs/coco"));
        let t = crate::cli::testing::parse::<Args>(&["--coco", "c"]).unwrap();
        assert_eq!(t.args.plan(&t.global).coco_dir, PathBuf::from("c"));
    }
}
