//! `insgen eval-loc`: the instance-silhouette localizer on an area's queries, and its report.

use anyhow::Context;

use super::Global;
use crate::loc::cost::{CostKind, Weighting};
use crate::loc::eval::{self, EvalOptions};
use crate::loc::oracle::Degradation;
use crate::loc::search::{CoarseParams, FineParams};
use crate::scene::PreparedScene;

/// Localizes every query of <workdir>/<area>/<camera> (poses.jsonl = ground truth, priors.jsonl =
/// priors) against the area's instanced LoD model, and writes results.jsonl, est_poses_*.txt,
/// summary.{md,json} and overlays/ under <workdir>/<area>/<camera>/loc/<tag>/.
#[derive(Debug, Clone, clap::Args)]
#[command(after_long_help = "Examples:\n  insgen eval-loc --area demo-test --camera cam2 --oracle\n  \
insgen eval-loc --area demo-test --camera cam2 --oracle --cost instance --cost semantic\n  \
insgen eval-loc --area demo-test --camera cam2 --oracle --erode 2 --drop 0.1 --merge 0.1")]
pub struct Args {
    #[arg(long, value_name = "NAME")]
    pub area: String,
    #[arg(long, value_name = "PRESET")]
    pub camera: String,
    /// Use the ground-truth masks (masks/<frame>.png) as the query, with the degradations below.
    #[arg(long, required = true)]
    pub oracle: bool,
    /// Cost(s) to evaluate; repeat to compare (each gives rows of the table).
    #[arg(long = "cost", value_enum, default_values_t = [CostKind::Instance])]
    pub costs: Vec<CostKind>,
    /// Instance weighting: by confidence score or by box area.
    #[arg(long, value_enum, default_value_t = Weighting::Conf)]
    pub weighting: Weighting,
    /// Erode the oracle masks by K pixels (at the render resolution).
    #[arg(long, value_name = "K", default_value_t = 0, conflicts_with = "dilate")]
    pub erode: u32,
    /// Dilate the oracle masks by K pixels.
    #[arg(long, value_name = "K", default_value_t = 0)]
    pub dilate: u32,
    /// Fraction of instances dropped.
    #[arg(long, value_name = "FRACTION", default_value_t = 0.0)]
    pub drop: f64,
    /// Fraction of instances merged with a touching neighbour.
    #[arg(long, value_name = "FRACTION", default_value_t = 0.0)]
    pub merge: f64,
    /// Fraction of instances split in two.
    #[arg(long, value_name = "FRACTION", default_value_t = 0.0)]
    pub split: f64,
    /// False-positive blobs added per query.
    #[arg(long, value_name = "N", default_value_t = 0)]
    pub false_positives: u32,
    /// Score jitter σ (scores = 1 − |N(0, σ)|).
    #[arg(long, value_name = "SIGMA", default_value_t = 0.0)]
    pub score_jitter: f64,
    /// Coarse stage only (ablation).
    #[arg(long)]
    pub no_refine: bool,
    /// Fine stage from the raw prior (ablation).
    #[arg(long)]
    pub no_select: bool,
    /// Width of the fine-stage renders in pixels.
    #[arg(long, value_name = "PX", default_value_t = 640)]
    pub render_width: u32,
    /// Width of the coarse-stage renders in pixels.
    #[arg(long, value_name = "PX", default_value_t = 320)]
    pub coarse_width: u32,
    /// Particle-filter iterations.
    #[arg(long, value_name = "N", default_value_t = 40)]
    pub iterations: u32,
    #[arg(long, value_name = "SEED", default_value_t = 0)]
    pub seed: u64,
    /// Evaluate only the first N queries.
    #[arg(long, value_name = "N")]
    pub limit: Option<usize>,
    /// Overlay PNGs for the first N queries.
    #[arg(long, value_name = "N", default_value_t = 4)]
    pub overlays: usize,
    /// Output sub-directory under loc/ (default: derived from the options).
    #[arg(long, value_name = "NAME")]
    pub tag: Option<String>,
}

pub fn run(args: &Args, global: &Global) -> anyhow::Result<()> {
    let area_dir = global.workdir.join(&args.area);
    let scene = PreparedScene::load(&area_dir.join("scene"))?;
    let degradation = Degradation {
        morph_px: args.dilate as i32 - args.erode as i32,
        drop_fraction: args.drop,
        merge_fraction: args.merge,
        split_fraction: args.split,
        false_positives: args.false_positives,
        score_jitter: args.score_jitter,
    };
    for (name, f) in [("--drop", args.drop), ("--merge", args.merge), ("--split", args.split)] {
        anyhow::ensure!((0.0..=1.0).contains(&f), "{name} {f}: a fraction lies in [0, 1]");
    }
    let tag = args.tag.clone().unwrap_or_else(|| {
        let mut t = String::from(if degradation.is_perfect() { "oracle" } else { "degraded" });
        if args.no_refine {
            t.push_str("-norefine");
        }
        if args.no_select {
            t.push_str("-noselect");
        }
        t
    });
    let opts = EvalOptions {
        camera_dir: area_dir.join(&args.camera),
        costs: args.costs.clone(),
        weighting: args.weighting,
        degradation,
        coarse: CoarseParams::default(),
        fine: FineParams { iterations: args.iterations, ..FineParams::default() },
        select: !args.no_select,
        refine: !args.no_refine,
        seed: args.seed,
        render_width_px: args.render_width,
        coarse_width_px: args.coarse_width,
        limit: args.limit,
        overlays: args.overlays,
        tag: tag.clone(),
    };
    let progress = global.progress();
    let summary = eval::evaluate(&scene, &opts, &progress)
        .with_context(|| format!("evaluating localization on {}/{}", args.area, args.camera))?;
    if !global.quiet {
        println!("{}", crate::loc::metrics::markdown(&summary.rows));
        println!(
            "{} queries, median {:.2} s/query, {:.0} hypotheses/s → {}",
            summary.queries,
            summary.median_seconds_per_query,
            summary.hypotheses_per_second,
            opts.camera_dir.join("loc").join(tag).display()
        );
    }
    Ok(())
}
