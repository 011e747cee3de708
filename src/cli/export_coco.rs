//! `insgen export-coco`: COCO instance files per geographic split, plus the statistics report.

use std::path::PathBuf;

use anyhow::Context;

use crate::export::coco::{build, export, ExportPlan};
use crate::export::format::{AnnotationUnit, Filters, TruncatedPolicy};
use crate::export::stats::{self, ReportOptions};
use crate::util::ShardSpec;

/// What to do with instances that touch the image border.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, clap::ValueEnum)]
pub enum TruncatedArg {
    /// Export them as ordinary annotations.
    #[default]
    Keep,
    /// Export them with iscrowd = 1 (ignored by COCOeval and most trainers).
    Flag,
    /// Leave them out.
    Drop,
}

impl From<TruncatedArg> for TruncatedPolicy {
    fn from(t: TruncatedArg) -> Self {
        match t {
            TruncatedArg::Keep => TruncatedPolicy::Keep,
            TruncatedArg::Flag => TruncatedPolicy::Flag,
            TruncatedArg::Drop => TruncatedPolicy::Drop,
        }
    }
}

/// Export COCO instance annotations for every rendered area.
///
/// Reads <workdir>/<area>/scene/{manifest,buildings}.json and, for each camera directory,
/// poses.jsonl, masks/<frame>.png (24-bit ID maps) and masks/<frame>.instances.json. Every ID map is
/// decoded and its connected components checked against the instance file.
///
/// Writes instances_train.json, instances_val.json and instances_test.json (splits come from the
/// areas' manifests, never from frames), stats.md, stats.json, hist_*.png and contact_sheet.png.
/// The folder is self-contained: each photo is placed at images/<split>/<area>/<camera>/<frame>.png and
/// each ID map under masks/<split>/… (hard links, copies across file systems), and every name is
/// relative to the folder (`info.image_root` = `.`), so it can be moved, synced or archived alone
/// (--link-root names the work directory's files instead). Segmentations are
/// compressed RLE exactly as pycocotools writes them; one annotation per connected component unless
/// --per-building.
#[derive(Debug, Clone, clap::Args)]
#[command(after_long_help = "Examples:\n  insgen export-coco\n  \
insgen export-coco --holdout shibuya --min-area 64 --truncated flag\n  \
insgen --workdir runs export-coco --out runs/coco-buildings --per-building\n  \
insgen --workdir /scratch/task3 export-coco --label-only --shard auto/8   # a part, for insgen merge")]
pub struct Args {
    /// Output directory [default: <workdir>/coco].
    #[arg(long, value_name = "DIR")]
    pub out: Option<PathBuf>,
    /// Move an area to the test split (repeatable).
    #[arg(long, value_name = "AREA")]
    pub holdout: Vec<String>,
    /// One annotation per building (all its visible parts) instead of per component.
    #[arg(long)]
    pub per_building: bool,
    /// Write polygons instead of RLE in `segmentation` (holes are lost; exact RLE kept in `mask_rle`).
    #[arg(long)]
    pub polygons: bool,
    /// Drop annotations smaller than this many pixels.
    #[arg(long, value_name = "PX", default_value_t = 1)]
    pub min_area: u64,
    /// Drop buildings less visible than this (visible / unoccluded pixels, 0–1).
    ///
    /// Needs instance files written by `insgen render-masks --visible-fraction`.
    #[arg(long, value_name = "FRACTION", value_parser = parse_fraction)]
    pub min_visible_fraction: Option<f64>,
    /// Leave out frames whose LoD/tileset consistency score is below this (0–1).
    ///
    /// Needs instance files written by `insgen render-masks --tileset`; the score is the fraction of
    /// a frame's LoD building pixels the tileset confirms.
    #[arg(long, value_name = "SCORE", value_parser = parse_fraction)]
    pub min_consistency: Option<f64>,
    /// Instances touching the image border: keep, flag (iscrowd = 1) or drop.
    #[arg(long, value_enum, value_name = "POLICY", default_value_t = TruncatedArg::Keep)]
    pub truncated: TruncatedArg,
    /// Keep images without annotations (negatives) [default].
    #[arg(long, overrides_with = "drop_empty_images", hide_short_help = true)]
    pub keep_empty_images: bool,
    /// Leave out images without annotations.
    #[arg(long, overrides_with = "keep_empty_images")]
    pub drop_empty_images: bool,
    /// Skip the statistics report.
    #[arg(long)]
    pub no_stats: bool,
    /// Export labels for every labelled frame, rendered or not: `file_name` names the RGB frame to
    /// come and `info.images_missing` is true. Without it, frames lacking an RGB frame are left out.
    #[arg(long)]
    pub label_only: bool,
    /// Frames on the contact sheet (0 = none).
    #[arg(long, value_name = "N", default_value_t = 12, hide_short_help = true)]
    pub contact_sheet: usize,
    /// Export only this shard's frames (I/N, or auto from a Slurm/Kubernetes job array), as a part.
    ///
    /// Per camera, the frames whose line in poses.jsonl is ≡ I (mod N) — the frames `render-masks
    /// --shard I/N` renders. The part goes to <out>/parts/I-of-N/; `insgen merge` combines the N parts
    /// into the export one process writes (same ids, same bytes) and computes the statistics then.
    #[arg(long, value_name = "I/N|auto")]
    pub shard: Option<ShardSpec>,
    /// Name the photos and ID maps where they lie in the work directory (`info.image_root` = `..`)
    /// instead of placing them in the export folder.
    ///
    /// By default the export folder is self-contained: photos in images/<split>/<area>/<camera>/ and
    /// ID maps in masks/<split>/…, hard links to the work directory's files (copies on another file
    /// system), every name relative to the folder, so it can be moved or archived alone. With this
    /// flag it takes no space but needs the work directory beside it.
    #[arg(long)]
    pub link_root: bool,
}

fn parse_fraction(s: &str) -> Result<f64, String> {
    let v: f64 = s.parse().map_err(|_| format!("\"{s}\" is not a number"))?;
    if (0.0..=1.0).contains(&v) {
        Ok(v)
    } else {
        Err(format!("{v} is outside 0..=1"))
    }
}

impl Args {
    /// The validated plan for `global.workdir`.
    pub fn plan(&self, global: &super::Global) -> ExportPlan {
        ExportPlan {
            workdir: global.workdir.clone(),
            out_dir: self.out.clone().unwrap_or_else(|| global.workdir.join("coco")),
            holdout: self.holdout.clone(),
            unit: if self.per_building { AnnotationUnit::Building } else { AnnotationUnit::Component },
            polygons: self.polygons,
            label_only: self.label_only,
            filters: Filters {
                min_area_px: self.min_area,
                min_visible_fraction: self.min_visible_fraction,
                truncated: self.truncated.into(),
                keep_empty_images: !self.drop_empty_images,
                min_consistency: self.min_consistency,
            },
            shard: crate::util::Shard::default(),
            link_root: self.link_root,
        }
    }

    /// The statistics report asked for (`None`: --no-stats).
    pub fn report(&self) -> Option<ReportOptions> {
        (!self.no_stats).then_some(ReportOptions { contact_sheet_images: self.contact_sheet })
    }
}

/// Runs `export-coco`.
pub fn run(args: &Args, global: &super::Global) -> anyhow::Result<()> {
    let mut plan = args.plan(global);
    plan.shard = super::resolve_shard(args.shard)?;
    let printer = global.printer();
    let progress = printer.progress();
    if !plan.shard.is_whole() {
        let ex = build(&plan, "..", &progress)
            .with_context(|| format!("exporting COCO from {}", plan.workdir.display()))?;
        super::log_coco_export(&plan, &ex);
        let written = crate::export::parts::write_part(&plan, &ex, args.report())
            .with_context(|| format!("writing shard {} of the export", plan.shard))?;
        for f in &written {
            log::info!("wrote {}", f.display());
        }
        printer.summary(format!(
            "shard {} of the export → {}; combine the parts with `insgen merge`",
            plan.shard,
            crate::export::parts::part_dir(&plan.out_dir, plan.shard).display()
        ));
        return Ok(());
    }
    let (ex, written) = export(&plan, &progress)
        .with_context(|| format!("exporting COCO from {}", plan.workdir.display()))?;
    super::log_coco_export(&plan, &ex);
    write_reports(&plan, &ex, args.report(), written)
}

/// Writes the statistics report of `ex` (unless `report` is None) next to its COCO files, and logs
/// every file written (`written`: those written already).
///
/// # Errors
/// I/O and PNG errors naming the file.
pub(crate) fn write_reports(
    plan: &ExportPlan,
    ex: &crate::export::coco::Export,
    report: Option<ReportOptions>,
    mut written: Vec<PathBuf>,
) -> anyhow::Result<()> {
    if let Some(opts) = report {
        let files = stats::write_export_report(plan, ex, opts)
            .with_context(|| format!("writing the statistics report in {}", plan.out_dir.display()))?;
        written.extend(files);
    }
    for f in &written {
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
    fn defaults() {
        let t = parse(&[]).unwrap();
        let plan = t.args.plan(&t.global);
        assert_eq!(plan.out_dir, PathBuf::from("runs/coco"));
        assert_eq!(plan.unit, AnnotationUnit::Component);
        assert_eq!(plan.filters, Filters::default());
        assert!(plan.holdout.is_empty() && !plan.polygons);
    }

    #[test]
    fn holdout_repeats_and_filters_parse() {
        let t = parse(&[
            "--holdout",
            "a",
            "--holdout",
            "b",
            "--per-building",
            "--min-area",
            "64",
            "--min-visible-fraction",
            "0.25",
            "--truncated",
            "flag",
            "--drop-empty-images",
            "--out",
            "x",
        ])
        .unwrap();
        let plan = t.args.plan(&t.global);
        assert_eq!(plan.holdout, ["a", "b"]);
        assert_eq!(plan.unit, AnnotationUnit::Building);
        assert_eq!(plan.out_dir, PathBuf::from("x"));
        assert_eq!(
            plan.filters,
            Filters {
                min_area_px: 64,
                min_visible_fraction: Some(0.25),
                truncated: TruncatedPolicy::Flag,
                keep_empty_images: false,
                min_consistency: None,
            }
        );
    }

    #[test]
    fn last_of_keep_and_drop_empty_images_wins() {
        let t = parse(&["--drop-empty-images", "--keep-empty-images"]).unwrap();
        assert!(t.args.plan(&t.global).filters.keep_empty_images);
        let t = parse(&["--keep-empty-images", "--drop-empty-images"]).unwrap();
        assert!(!t.args.plan(&t.global).filters.keep_empty_images);
    }

    #[test]
    fn bad_values_are_usage_errors() {
        assert!(parse(&["--min-visible-fraction", "1.5"]).is_err());
        assert!(parse(&["--truncated", "maybe"]).is_err());
        assert!(parse(&["--min-area", "-3"]).is_err());
    }
}
