//! `insgen eval-loc`: the instance-silhouette localizer on an area's queries, and its report.

use anyhow::Context;
use serde::Deserialize;

use super::Global;
use crate::loc::cost::{CostKind, Weighting, DEFAULT_SEMANTIC_WEIGHT};
use std::path::PathBuf;

use crate::camera::config::PriorNoise;
use crate::loc::eval::{self, EvalOptions, QueryPoses};
use crate::loc::map::{MapPerturbation, MapSummary};
use crate::loc::oracle::{Degradation, SegmenterLike};
use crate::loc::query::{load_predictions, FramePredictions, QuerySource};
use crate::loc::search::{
    BeamMode, CoarseParams, FineParams, OnBoundary, PolishCost, Prune, SearchBounds, SearchOptions, Stages,
    MAX_COARSE_CELLS,
};
use crate::render::{RendererChoice, Workload};
use crate::scene::PreparedScene;

/// `--weighting`: how per-instance Dice scores are combined ([`Weighting`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, clap::ValueEnum)]
pub enum WeightingArg {
    /// By the instance's confidence score.
    Conf,
    /// By the instance's bounding-box area (the paper's main tables).
    #[default]
    Area,
    /// By the product of the two: each instance's box area, trusted as far as its score says. For
    /// predictions whose scores rank their masks (`baseline.py score`: `score_honesty`); with scores
    /// all 1 (oracle masks) the same as `area`.
    AreaConf,
}

impl From<WeightingArg> for Weighting {
    fn from(w: WeightingArg) -> Self {
        match w {
            WeightingArg::Conf => Weighting::Conf,
            WeightingArg::Area => Weighting::Area,
            WeightingArg::AreaConf => Weighting::AreaConf,
        }
    }
}

/// `--polish-rim-tolerance`: when the polish's second pass frees the rims ([`PolishCost::rim_tolerance`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum RimToleranceArg {
    /// On when the map is the area's own, unperturbed scene.
    Auto,
    /// Always.
    On,
    /// Never: every rim as rendered.
    Off,
}

/// A switch given as `on` or `off`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Toggle {
    /// On.
    On,
    /// Off.
    Off,
}

/// `--cost`: which cost to use ([`CostKind`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, clap::ValueEnum)]
pub enum CostArg {
    /// Best-match Dice per query instance (InsLoD-Loc).
    #[default]
    Instance,
    /// IoU of the merged query mask with all rendered buildings (LoD-Loc v2 baseline).
    Semantic,
    /// Query instances merged into one mask, then instance scoring (the paper's ablation).
    Merged,
    /// Each query instance matched to the union of rendered buildings that explains it best, split
    /// pieces of one building scored together (robust to learned masks; blended like instance).
    Grouped,
}

impl From<CostArg> for CostKind {
    fn from(c: CostArg) -> Self {
        match c {
            CostArg::Instance => CostKind::Instance,
            CostArg::Semantic => CostKind::Semantic,
            CostArg::Merged => CostKind::Merged,
            CostArg::Grouped => CostKind::Grouped,
        }
    }
}

/// Localizes every query of <workdir>/<area>/<camera> (poses.jsonl = ground truth, priors.jsonl =
/// priors, or the LoD-Loc/COLMAP lists given with --query-list/--gt-poses/--prior-poses) against the
/// area's instanced LoD model, and writes results.jsonl, est_poses_*.txt, summary.{md,json} and
/// overlays/ under <workdir>/<area>/<camera>/loc/<tag>/ (or --out).
///
/// The query instances are either the ground-truth masks (--oracle, masks/<frame>.png from
/// render-masks, optionally degraded) or a segmentation model's COCO results file (--predictions; its
/// image ids are resolved through the COCO instances files from export-coco).
#[derive(Debug, Clone, clap::Args)]
#[command(after_long_help = "Examples:\n  insgen eval-loc --area demo-test --camera cam2 --oracle\n  \
insgen eval-loc --area demo-test --camera cam2 --oracle --cost instance --cost semantic\n  \
insgen eval-loc --area demo-test --camera cam2 --oracle --erode 2 --drop 0.1 --merge 0.1\n  \
insgen eval-loc --area demo-test --camera cam2 --predictions model/segm_results.json\n  \
insgen eval-loc --area demo-test --camera cam2 --oracle --shard auto/8   # a part, for insgen merge\n  \
insgen eval-loc --area tokyo --camera uav --oracle --masks uav/masks --query-list uav/queries.txt \\\n      \
--gt-poses uav/gt.txt --prior-poses uav/prior.txt --out uav/loc")]
#[command(group(clap::ArgGroup::new("source").required(true).args(["oracle", "predictions"])))]
pub struct Args {
    /// The area whose queries are localized (a prepared scene under <workdir>/<NAME>/scene).
    #[arg(long, value_name = "NAME")]
    pub area: String,
    /// The queries' camera: a preset, the camera's name, or the camera TOML file given to `sample`.
    #[arg(long, value_name = "PRESET|NAME|FILE", value_parser = super::parse_camera_dir)]
    pub camera: String,
    /// Use the ground-truth masks (masks/<frame>.png) as the query, with the degradations below.
    #[arg(long)]
    pub oracle: bool,
    /// Directory of the ground-truth ID maps for --oracle [default: <camera dir>/masks].
    #[arg(long, value_name = "DIR", requires = "oracle")]
    pub masks: Option<PathBuf>,
    /// A COCO results file (list of {image_id, segmentation: RLE, score}) with predicted instances.
    #[arg(long, value_name = "FILE", conflicts_with_all = ["erode", "dilate", "drop", "merge", "split", "false_positives", "score_jitter", "segmenter_like"])]
    pub predictions: Option<PathBuf>,
    /// COCO instances file(s) mapping the results' image ids to frames [default:
    /// <workdir>/coco/instances_{train,val,test}.json].
    #[arg(long = "coco", value_name = "FILE", requires = "predictions")]
    pub coco_files: Vec<PathBuf>,
    /// Ignore predictions scoring below this.
    #[arg(long, value_name = "SCORE", default_value_t = 0.0, requires = "predictions")]
    pub min_score: f64,
    /// Undo the segmenter's zoom: scale every predicted mask by 1/S about the principal point.
    ///
    /// S is how much larger than the buildings the model's masks are, measured on frames whose poses
    /// are known (the validation split): `baseline.py score` reports it as `mask_zoom.median`. A
    /// model whose masks bleed 0.25 % past the buildings puts the camera a metre ahead at 400 m,
    /// which no cost can tell from a single frame. 0.9–1.1; 1 leaves the masks as predicted.
    #[arg(long, value_name = "S", default_value_t = 1.0, requires = "predictions")]
    pub prediction_zoom: f64,
    /// LoD-Loc query list (NAME MODEL W H PARAMS[]) instead of <camera dir>/poses.jsonl.
    #[arg(long, value_name = "FILE", requires_all = ["gt_poses", "prior_poses"])]
    pub query_list: Option<PathBuf>,
    /// Ground-truth poses (NAME QW QX QY QZ TX TY TZ, world-to-camera, area ENU) for --query-list.
    #[arg(long, value_name = "FILE", requires = "query_list")]
    pub gt_poses: Option<PathBuf>,
    /// Prior poses in the same format, for --query-list.
    #[arg(long, value_name = "FILE", requires = "query_list")]
    pub prior_poses: Option<PathBuf>,
    /// Output directory [default: <camera dir>/loc/<tag>].
    #[arg(long, value_name = "DIR")]
    pub out: Option<PathBuf>,
    /// Cost(s) to evaluate; repeat to compare (each gives rows of the table).
    #[arg(long = "cost", value_enum, default_values_t = [CostArg::Instance])]
    pub costs: Vec<CostArg>,
    /// Instance weighting: by box area (the paper's main tables), by confidence score, or by both
    /// (`area-conf`: for a segmenter's predictions whose scores are honest).
    #[arg(long, value_enum, default_value_t = WeightingArg::Area)]
    pub weighting: WeightingArg,
    /// Weight W of the semantic IoU blended into the instance cost, (1 − W)·instance + W·semantic, so
    /// that a map coarser than the query (LoD1 blocks hiding more of the buildings behind) does not move
    /// the optimum; 0 is the paper's pure instance cost [default: 0.5; --paper: 0].
    #[arg(long, value_name = "W", value_parser = parse_unit_fraction)]
    pub semantic_weight: Option<f64>,
    /// Erode the oracle masks by K pixels (at the masks' own resolution).
    #[arg(long, value_name = "K", default_value_t = 0, conflicts_with = "dilate")]
    pub erode: u32,
    /// Dilate the oracle masks by K pixels (at the masks' own resolution).
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
    /// Degrade the oracle masks as a learned segmenter does: chains of touching buildings along a row
    /// merged, large instances split, small ones missed, rims moved ±1 px (at 640 px width), blobs at
    /// the foot of buildings. `learned` (or the flag alone) is the model calibrated to a segmenter on an
    /// unseen city (issue 40); KEY=VALUE pairs override it: chain, max-chain, split-large,
    /// large-area, miss-small, small-area, rim, blobs, zoom, holes, zoom-sd (e.g. `learned,chain=0.4`;
    /// `learned,zoom=1.0025` also scales the masks about the image centre as the closed loop's U-Net
    /// does, which the localizer reads as a camera moved along its axis; `holes=0.15` cuts 15 % of the
    /// building pixels out in blobs, as a segmenter misses low-contrast roofs; `zoom-sd=0.002` adds a
    /// per-frame scale error of that deviation).
    #[arg(long, value_name = "learned|KEY=VALUE,…", num_args = 0..=1, default_missing_value = "learned",
          value_parser = parse_segmenter, requires = "oracle")]
    pub segmenter_like: Option<SegmenterLike>,
    /// Coarse stage only (ablation).
    #[arg(long)]
    pub no_refine: bool,
    /// Fine stage from the raw prior (ablation).
    #[arg(long)]
    pub no_select: bool,
    /// Skip the local pattern search after the particle filter.
    #[arg(long)]
    pub no_polish: bool,
    /// Weight of the semantic IoU in the instance cost during the polish's second pass, after a first
    /// pass in the filter's cost [default: 0 against the area's own scene, which the masks are
    /// labelled from; 1 with --map-area or a map perturbation]. 0 keeps the per-building terms (the
    /// instance cost's with the rims freed, the grouped cost's groups): the better polish for learned
    /// masks where the photos show what the map shows. 1 scores the union's outline alone, which does
    /// not depend on the map's occlusion order: the better polish against a map coarser than the
    /// buildings (LoD1 blocks). Setting it to --semantic-weight (and --silhouette-offset 0) leaves one
    /// pass.
    #[arg(long, value_name = "W", value_parser = parse_unit_fraction)]
    pub polish_semantic_weight: Option<f64>,
    /// Largest silhouette offset in pixels fitted before the polish's second pass: the rendered
    /// buildings eroded or dilated by up to N px so that masks uniformly thinner or fatter than the
    /// buildings (a segmenter's boundary bias) do not move the camera along its axis; 0: none
    /// [default: 2].
    #[arg(long, value_name = "N")]
    pub silhouette_offset: Option<u32>,
    /// Weight λ of the rendered building pixels outside the query's outline in the polish's second
    /// pass, |Q ∩ R| / (|Q| + λ·|R \ Q|): an LoD map generalises buildings outwards (blocks filled up
    /// to the eaves or the ridge), so its render spilling over the query's outline is weaker evidence
    /// than a query pixel it leaves uncovered; 1 is the IoU [default: 0.3].
    #[arg(long, value_name = "λ", value_parser = parse_unit_fraction)]
    pub polish_spill_weight: Option<f64>,
    /// In the polish's second pass, let every rendered building's rim move by a pixel, in or out,
    /// each building its own way (in the union's outline, per query instance in the instance cost's
    /// best-match Dice, and per building of the union that the grouped cost matches to an instance):
    /// instances a pixel fatter or thinner than their buildings (a
    /// segmenter's rims) then move no camera along its axis, while a building displaced by a pixel
    /// still counts. auto: on when the map is the area's own scene, the one the masks are labelled
    /// from; off with --map-area or a map perturbation (--map-lod1 …), where the map is coarser
    /// than the buildings and the pixel it frees is the one that measured the misfit
    /// (bench/loc_learned.md)
    #[arg(long, value_enum, value_name = "WHEN", default_value_t = RimToleranceArg::Auto)]
    pub polish_rim_tolerance: RimToleranceArg,
    /// The paper's search exactly: its coarse grid, rendered at 320 px, and particle filter (40
    /// iterations, 2 beams × (2 kept + 2 × 12 perturbations) ranked jointly across beams), no
    /// distinct basins, no polish. Other search flags given with it still apply.
    #[arg(long)]
    pub paper: bool,
    /// Distinct coarse basins (best coarse cells that are no grid neighbour of a better one) refined
    /// as separate beams at the coarse width; at the switch to the render width the best --survivors
    /// go on. 1 keeps only the best cell's basin (and the prior's, with --prior-basin on) [default: 4;
    /// --paper: the paper's joint beams].
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u32).range(1..))]
    pub basins: Option<u32>,
    /// Basins refined on at the render width [default: 1].
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u32).range(1..))]
    pub survivors: Option<u32>,
    /// Judge the basins at the render width after AFTER coarse-width iterations as well and go on
    /// with the best KEEP, or `off` [default: 5/2; --paper: off].
    #[arg(long, value_name = "AFTER/KEEP|off", value_parser = parse_prune)]
    pub prune: Option<PruneFlag>,
    /// Refine the prior's own basin as one more beam where no basin's cell is its grid neighbour
    /// [default: on; --paper: off]. The prior is where the camera most likely is; a cost that is
    /// noisy at the coarse width can rank the truth's cells below the basins elsewhere.
    #[arg(long, value_enum, value_name = "on|off")]
    pub prior_basin: Option<Toggle>,
    /// Width of the fine-stage renders in pixels.
    #[arg(long, value_name = "PX", default_value_t = 640)]
    pub render_width: u32,
    /// Width of the coarse-stage renders in pixels [default: 160; --paper: 320].
    #[arg(long, value_name = "PX")]
    pub coarse_width: Option<u32>,
    /// Render every coarse yaw directly instead of warping it out of one wide render per grid
    /// position (a rotation about the camera centre is a homography; the warp differs only at
    /// silhouette edges, by resampling).
    #[arg(long)]
    pub no_yaw_fan: bool,
    /// Coarse grid in x and y: ±RANGE metres in steps of STEP [default: 2.5σ of the prior noise model
    /// (its noisier horizontal axis, plus its bias) in whole steps of 5 m; 20/5 for the default model].
    #[arg(long, value_name = "RANGE/STEP", value_parser = parse_range_step)]
    pub coarse_xy: Option<(f64, f64)>,
    /// Coarse grid in z: ±RANGE metres in steps of STEP [default: 2σ of the prior noise model's height
    /// (plus its bias) in whole steps of 5 m; 10/5 for the default model].
    #[arg(long, value_name = "RANGE/STEP", value_parser = parse_range_step)]
    pub coarse_z: Option<(f64, f64)>,
    /// Coarse grid in yaw: ±RANGE degrees in steps of STEP [default: 2.5σ of the prior noise model's
    /// yaw (plus its bias) in whole steps of 2.5°; 7.5/2.5 for the default model].
    #[arg(long, value_name = "RANGE/STEP", value_parser = parse_range_step)]
    pub coarse_yaw: Option<(f64, f64)>,
    /// Search volume: the largest horizontal distance of the camera centre from the prior's, metres.
    ///
    /// Every stage (coarse grid, particle filter, polish, basins) keeps to a volume centred on the
    /// prior, so that a degenerate cost cannot pull the estimate where the prior says the camera
    /// cannot be; results.jsonl flags an estimate on its boundary (on_search_boundary). Default:
    /// 4.4·max(σ_e, σ_n) plus the prior's horizontal bias, at least 10 m (the radius its error leaves
    /// as rarely as 4σ in height), from the noise model of <camera dir>/sampling.json (`insgen
    /// sample`), else the default model (σ = 7, 7, 5 m, yaw 3°: 30.8 m).
    #[arg(long, value_name = "M", value_parser = parse_half_range)]
    pub search_radius_m: Option<f64>,
    /// Search volume: the largest difference from the prior's height, metres [default: 4·σ_u plus
    /// the vertical bias, at least 5 m; the default model: 20 m].
    #[arg(long, value_name = "M", value_parser = parse_half_range)]
    pub search_height_m: Option<f64>,
    /// Search volume: the largest difference from the prior's yaw, degrees, at most 180 [default:
    /// 4·σ_yaw plus the yaw bias, at least 2°; the default model: 12°]. Pitch and roll are the
    /// prior's (not searched).
    #[arg(long, value_name = "DEG", value_parser = parse_half_range)]
    pub search_yaw_deg: Option<f64>,
    /// Report the search's best pose even when it ends on the boundary of the search volume.
    ///
    /// By default such a query reports its prior (the cost still improved towards poses the prior
    /// rules out, so the pose it found is not trusted) and is flagged in results.jsonl (kept_prior)
    /// and summary.md; this flag keeps the pose found, to study a cost.
    #[arg(long)]
    pub keep_boundary_estimates: bool,
    /// Particle-filter iterations [default: 20; --paper: 40].
    #[arg(long, value_name = "N")]
    pub iterations: Option<u32>,
    /// Particle-filter iterations scored at the coarse width before switching to the render width
    /// [default: those before the perturbation decay reaches its floor γ: 14 of 20, 28 of 40].
    #[arg(long, value_name = "N")]
    pub lowres_iterations: Option<u32>,
    /// Seed of the random draws: the oracle's degradations, the particle filter, the map perturbation.
    ///
    /// Each query mixes it with its own name; --map-seed, when given, seeds the map perturbation instead.
    #[arg(long, value_name = "SEED", default_value_t = 0)]
    pub seed: u64,
    /// Evaluate only the first N queries.
    #[arg(long, value_name = "N")]
    pub limit: Option<usize>,
    /// Overlay PNGs for the first N queries.
    #[arg(long, value_name = "N", default_value_t = 4)]
    pub overlays: usize,
    /// Localize against the map of another prepared area (same ENU frame: its scene file must give
    /// the same [origin]); the queries' poses and masks stay those of --area.
    #[arg(long, value_name = "NAME")]
    pub map_area: Option<String>,
    /// Map perturbation: coarsen LoD2 to LoD1 (each building's footprint extruded to its top, or to
    /// --map-lod1-percentile).
    #[arg(long)]
    pub map_lod1: bool,
    /// With --map-lod1: the LoD1 block stands at this percentile (0–100) of the building's roof
    /// heights, weighted by area (70: 3DBAG's LoD1.2) instead of its highest point.
    #[arg(long, value_name = "P", requires = "map_lod1")]
    pub map_lod1_percentile: Option<f64>,
    /// Map perturbation: σ of each building's height error, metres.
    #[arg(long, value_name = "M", default_value_t = 0.0)]
    pub map_height_sigma: f64,
    /// Map perturbation: σ of each building's horizontal footprint shift (east and north), metres.
    #[arg(long, value_name = "M", default_value_t = 0.0)]
    pub map_shift_sigma: f64,
    /// Map perturbation: σ of each building's footprint scale factor − 1 (0.05 ≈ ±5 %).
    #[arg(long, value_name = "SIGMA", default_value_t = 0.0)]
    pub map_scale_sigma: f64,
    /// Map perturbation: fraction of buildings dropped from the map.
    #[arg(long, value_name = "FRACTION", default_value_t = 0.0)]
    pub map_drop: f64,
    /// Map perturbation: fraction of buildings merged into their nearest neighbour.
    #[arg(long, value_name = "FRACTION", default_value_t = 0.0)]
    pub map_merge: f64,
    /// Map perturbation: offset of the whole map, ENU metres.
    #[arg(long, value_name = "E,N,U", value_parser = parse_offset, allow_hyphen_values = true)]
    pub map_offset: Option<[f64; 3]>,
    /// Seed of the map perturbation [default: --seed].
    #[arg(long, value_name = "SEED")]
    pub map_seed: Option<u64>,
    /// Output sub-directory under loc/ (default: derived from the options).
    #[arg(long, value_name = "NAME")]
    pub tag: Option<String>,
    /// Localize only this shard's queries (I/N, or auto from a Slurm/Kubernetes job array).
    ///
    /// The queries at positions ≡ I (mod N) of the list (after --limit). The shard writes its
    /// results.jsonl and est_poses_*.txt to <out>/parts/I-of-N/ (and its overlays among the first
    /// --overlays queries to <out>/overlays/); `insgen merge` puts the parts back in query order and
    /// recomputes the summary from all results.
    #[arg(long, value_name = "I/N|auto")]
    pub shard: Option<crate::util::ShardSpec>,
    /// Renderer of the hypotheses: cpu, gpu or auto [default: cpu].
    ///
    /// cpu: the CPU rasteriser on every core (the default: results do not depend on the machine).
    /// gpu: wgpu on whatever adapter there is, a software one (lavapipe) included; an error without
    /// one. auto: wgpu on a hardware GPU, else cpu. The two agree on all but a few edge pixels per
    /// frame, so estimates may differ in the last digits. The choice and the adapter are logged, and a
    /// GPU run records them in summary.json (`renderer`).
    #[arg(long, value_name = "auto|cpu|gpu", default_value = "cpu", hide_default_value = true)]
    pub renderer: RendererChoice,
}

/// Parses `RANGE/STEP` (both ≥ 0, STEP > 0 unless RANGE = 0).
fn parse_range_step(s: &str) -> Result<(f64, f64), String> {
    let (r, st) = s.split_once('/').ok_or_else(|| format!("{s:?}: expected RANGE/STEP, e.g. 20/5"))?;
    let r: f64 = r.trim().parse().map_err(|_| format!("{s:?}: RANGE {r:?} is not a number"))?;
    let st: f64 = st.trim().parse().map_err(|_| format!("{s:?}: STEP {st:?} is not a number"))?;
    if !(r.is_finite() && st.is_finite() && r >= 0.0 && (st > 0.0 || r == 0.0)) {
        return Err(format!("{s:?}: RANGE must be ≥ 0 and STEP > 0"));
    }
    Ok((r, st))
}

/// Parses a half-range of the search volume (`--search-*`): a number > 0.
fn parse_half_range(s: &str) -> Result<f64, String> {
    let v: f64 = s.trim().parse().map_err(|_| format!("expected a number > 0, got {s:?}"))?;
    if v.is_finite() && v > 0.0 {
        Ok(v)
    } else {
        Err(format!("expected a number > 0, got {v}"))
    }
}

/// The prior noise model the search volume is derived from, and where it came from: the one
/// `insgen sample` recorded in `<camera_dir>/sampling.json` for sampled queries, else the default.
fn prior_noise(camera_dir: &std::path::Path, queries: &QueryPoses) -> anyhow::Result<(PriorNoise, String)> {
    let path = camera_dir.join(crate::camera::sample::SAMPLING_FILE);
    if matches!(queries, QueryPoses::Colmap { .. }) || !path.is_file() {
        return Ok((PriorNoise::default(), "the default prior noise model".into()));
    }
    let text = std::fs::read_to_string(&path).with_context(|| format!("reading {}", path.display()))?;
    let record: serde_json::Value =
        serde_json::from_str(&text).with_context(|| format!("parsing {}", path.display()))?;
    let noise = match record.get("config").and_then(|c| c.get("prior")) {
        Some(prior) => PriorNoise::deserialize(prior).with_context(|| {
            format!(
                "{}: config.prior is no prior noise model (rerun `insgen sample`, or give the search \
                 volume with --search-radius-m, --search-height-m and --search-yaw-deg)",
                path.display()
            )
        })?,
        None => PriorNoise::default(),
    };
    Ok((noise, "the prior noise model in sampling.json".into()))
}

/// The search volume: derived from `noise` ([`SearchBounds::from_prior_noise`]), each half-range a
/// `--search-*` flag gives replacing the derived one.
fn search_bounds(args: &Args, noise: &PriorNoise, source: &str) -> anyhow::Result<SearchBounds> {
    let mut b = SearchBounds::from_prior_noise(noise, source);
    let mut given = Vec::new();
    for (flag, value, field) in [
        ("--search-radius-m", args.search_radius_m, &mut b.radius_m),
        ("--search-height-m", args.search_height_m, &mut b.height_m),
        ("--search-yaw-deg", args.search_yaw_deg, &mut b.yaw_deg),
    ] {
        if let Some(v) = value {
            *field = v;
            given.push(format!("{flag} {v}"));
        }
    }
    if !given.is_empty() {
        b.origin = format!("{}; {}", given.join(", "), b.origin);
    }
    b.validate()?;
    Ok(b)
}

/// Logs the search volume and the coarse grid, warns when the grid is over 10× the default model's,
/// and refuses one over [`MAX_COARSE_CELLS`].
fn check_search(search: &SearchOptions) -> anyhow::Result<()> {
    let (b, c) = (&search.bounds, &search.coarse);
    let (cells, default_cells) = (c.cells(), CoarseParams::default().cells());
    log::info!(
        "search volume ±{:.1} m, ±{:.1} m, ±{:.1}° about the prior ({}); coarse grid {}",
        b.radius_m,
        b.height_m,
        b.yaw_deg,
        b.origin,
        c.describe()
    );
    let advice =
        "larger steps (--coarse-xy RANGE/STEP, --coarse-z, --coarse-yaw) make it faster at the risk of \
                  stepping over narrow basins";
    anyhow::ensure!(
        cells <= MAX_COARSE_CELLS,
        "the coarse grid would have {cells} cells (±{} m, ±{} m, ±{}° in steps of {} m, {} m, {}°), more than the \
         {MAX_COARSE_CELLS} eval-loc scores per query: is the prior noise model in sampling.json ({}) what the \
         priors hold? Else {advice}",
        c.xy_range_m,
        c.z_range_m,
        c.yaw_range_deg,
        c.xy_step_m,
        c.z_step_m,
        c.yaw_step_deg,
        b.origin
    );
    if cells > 10 * default_cells {
        log::warn!(
            "the coarse grid has {cells} cells, {:.0}× the default prior noise model's {default_cells}: the prior's \
             uncertainty sets its range; {advice}",
            cells as f64 / default_cells as f64
        );
    }
    Ok(())
}

/// Parses `AFTER/KEEP` (an early judgement of the basins) or `off`.
/// The semantic IoU's weight in the instance cost: as given, else 0 with `--paper` (the paper's pure
/// instance cost), else [`DEFAULT_SEMANTIC_WEIGHT`].
fn semantic_weight(args: &Args) -> f64 {
    args.semantic_weight.unwrap_or(if args.paper { 0.0 } else { DEFAULT_SEMANTIC_WEIGHT })
}

/// The polish's cost: eval-loc's for the map ([`PolishCost::for_map`]) where no flag is given, each
/// given flag on top (`--polish-rim-tolerance auto` follows the map).
fn polish_cost(args: &Args, label_source: bool) -> PolishCost {
    let d = PolishCost::for_map(label_source);
    PolishCost {
        semantic_weight: args.polish_semantic_weight.unwrap_or(d.semantic_weight),
        max_silhouette_offset_px: args.silhouette_offset.unwrap_or(d.max_silhouette_offset_px),
        spill_weight: args.polish_spill_weight.unwrap_or(d.spill_weight),
        rim_tolerance: match args.polish_rim_tolerance {
            RimToleranceArg::On => true,
            RimToleranceArg::Off => false,
            RimToleranceArg::Auto => d.rim_tolerance,
        },
    }
}

/// Whether the map is the model the query masks are labelled from, and why: the area's own,
/// unperturbed scene is; another area's model (`--map-area`) or a perturbed one (`--map-*`) is not.
fn map_is_label_source(args: &Args, map: &MapSummary) -> (bool, &'static str) {
    if map.area != args.area {
        (false, "the map is another area's (--map-area)")
    } else if map.perturbation.is_some() {
        (false, "the map is perturbed (--map-*)")
    } else {
        (true, "the map is the area's own scene, which the masks are labelled from")
    }
}

/// `--segmenter-like`'s value ([`SegmenterLike::parse`]).
fn parse_segmenter(s: &str) -> Result<SegmenterLike, String> {
    SegmenterLike::parse(s).map_err(|e| e.to_string())
}

/// A weight in [0, 1] (`--semantic-weight` and the polish's weights).
fn parse_unit_fraction(s: &str) -> Result<f64, String> {
    let w: f64 = s.trim().parse().map_err(|_| format!("expected a number in [0, 1], got {s:?}"))?;
    if (0.0..=1.0).contains(&w) {
        Ok(w)
    } else {
        Err(format!("expected a number in [0, 1], got {w}"))
    }
}

/// The value of `--prune`: an early judgement, or none (`off`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PruneFlag(pub Option<Prune>);

fn parse_prune(s: &str) -> Result<PruneFlag, String> {
    if s.trim() == "off" {
        return Ok(PruneFlag(None));
    }
    let (a, k) = s.split_once('/').ok_or_else(|| format!("{s:?}: expected AFTER/KEEP (e.g. 5/2) or off"))?;
    let after_iterations: u32 =
        a.trim().parse().map_err(|_| format!("{s:?}: AFTER {a:?} is not an iteration count"))?;
    let keep: u32 = k.trim().parse().map_err(|_| format!("{s:?}: KEEP {k:?} is not a count"))?;
    if keep == 0 {
        return Err(format!("{s:?}: KEEP must be at least 1"));
    }
    Ok(PruneFlag(Some(Prune { after_iterations, keep })))
}

/// The search's stages and parameters from the flags: the defaults, or the paper's with `--paper`,
/// with each given flag applied on top, the search volume `bounds` and the coarse grid derived from
/// the prior noise model `noise` ([`CoarseParams::from_prior_noise`]) where no `--coarse-*` flag
/// replaces it, and the polish's cost ([`polish_cost`]).
fn search_options(
    args: &Args,
    bounds: SearchBounds,
    noise: &PriorNoise,
    polish_cost: PolishCost,
) -> SearchOptions {
    SearchOptions {
        on_boundary: if args.keep_boundary_estimates { OnBoundary::Keep } else { OnBoundary::Prior },
        coarse: {
            let d = CoarseParams::from_prior_noise(noise, &bounds);
            let (xy_range_m, xy_step_m) = args.coarse_xy.unwrap_or((d.xy_range_m, d.xy_step_m));
            let (z_range_m, z_step_m) = args.coarse_z.unwrap_or((d.z_range_m, d.z_step_m));
            let (yaw_range_deg, yaw_step_deg) = args.coarse_yaw.unwrap_or((d.yaw_range_deg, d.yaw_step_deg));
            CoarseParams { xy_range_m, xy_step_m, z_range_m, z_step_m, yaw_range_deg, yaw_step_deg }
        },
        fine: {
            let base = if args.paper { FineParams::paper() } else { FineParams::default() };
            let prior_flag = args.prior_basin.map(|t| t == Toggle::On);
            let beams_mode = match (base.beams_mode, args.basins, args.survivors, args.prune, prior_flag) {
                (BeamMode::Basins { count, survivors, prune, prior_basin }, b, s, p, pb) => {
                    BeamMode::Basins {
                        count: b.unwrap_or(count),
                        survivors: s.unwrap_or(survivors),
                        prune: p.map_or(prune, |PruneFlag(p)| p),
                        prior_basin: pb.unwrap_or(prior_basin),
                    }
                }
                (BeamMode::Joint, None, None, None, None) => BeamMode::Joint,
                // --paper with basin flags: the paper's filter, beams as asked (no early judgement
                // and no prior basin unless asked).
                (BeamMode::Joint, b, s, p, pb) => BeamMode::Basins {
                    count: b.unwrap_or(4),
                    survivors: s.unwrap_or(1),
                    prune: p.and_then(|PruneFlag(p)| p),
                    prior_basin: pb.unwrap_or(false),
                },
            };
            FineParams {
                iterations: args.iterations.unwrap_or(base.iterations),
                lowres_iterations: args.lowres_iterations,
                polish: base.polish && !args.no_polish,
                beams_mode,
                polish_cost,
                ..base
            }
        },
        stages: match (args.no_select, args.no_refine) {
            (false, false) => Stages::CoarseAndFine,
            (false, true) => Stages::CoarseOnly,
            (true, false) => Stages::FineOnly,
            // Both off: nothing but the prior is scored (the coarse stage over the prior alone).
            (true, true) => Stages::PriorOnly,
        },
        bounds,
    }
}

/// Parses `E,N,U` metres.
fn parse_offset(s: &str) -> Result<[f64; 3], String> {
    let v: Vec<f64> = s
        .split(',')
        .map(|x| x.trim().parse::<f64>().map_err(|_| format!("{s:?}: {x:?} is not a number")))
        .collect::<Result<_, _>>()?;
    match v.as_slice() {
        &[e, n, u] if v.iter().all(|x| x.is_finite()) => Ok([e, n, u]),
        _ => Err(format!("{s:?}: expected E,N,U in metres, e.g. 1.5,-0.5,0")),
    }
}

/// The map: the query area's scene or --map-area's (same frame checked), perturbed as asked.
fn load_map(
    args: &Args,
    global: &Global,
    query_scene: PreparedScene,
) -> anyhow::Result<(PreparedScene, MapSummary)> {
    let (scene, area) = match &args.map_area {
        Some(name) if *name != args.area => {
            let map = PreparedScene::load(&global.workdir.join(name).join(crate::layout::SCENE_DIR))
                .with_context(|| {
                    format!("loading the map area {name} (run `insgen prepare --area {name}`)")
                })?;
            crate::loc::map::check_same_frame(&query_scene, &map)?;
            (map, name.clone())
        }
        _ => (query_scene, args.area.clone()),
    };
    for (name, f) in [("--map-drop", args.map_drop), ("--map-merge", args.map_merge)] {
        anyhow::ensure!((0.0..=1.0).contains(&f), "{name} {f}: a fraction lies in [0, 1]");
    }
    for (name, v) in [
        ("--map-height-sigma", args.map_height_sigma),
        ("--map-shift-sigma", args.map_shift_sigma),
        ("--map-scale-sigma", args.map_scale_sigma),
    ] {
        anyhow::ensure!(v.is_finite() && v >= 0.0, "{name} {v}: a standard deviation is ≥ 0");
    }
    if let Some(pct) = args.map_lod1_percentile {
        anyhow::ensure!(
            (0.0..=100.0).contains(&pct),
            "--map-lod1-percentile {pct}: a percentile lies in [0, 100]"
        );
    }
    let perturbation = MapPerturbation {
        lod1: args.map_lod1,
        lod1_roof_percentile: args.map_lod1_percentile,
        height_sigma_m: args.map_height_sigma,
        shift_sigma_m: args.map_shift_sigma,
        scale_sigma: args.map_scale_sigma,
        drop_fraction: args.map_drop,
        merge_fraction: args.map_merge,
        offset_enu_m: args.map_offset.unwrap_or([0.0; 3]),
        seed: args.map_seed.unwrap_or(args.seed),
    };
    if perturbation.is_identity() {
        return Ok((scene, MapSummary { area, perturbation: None, changes: None }));
    }
    let (map, changes) = crate::loc::map::perturb(&scene, &perturbation);
    Ok((map, MapSummary { area, perturbation: Some(perturbation), changes: Some(changes) }))
}

/// The output sub-directory under loc/ without `--tag`: the query source, then each ablation and
/// map option that changes the results.
fn default_tag(args: &Args, degradation: &Degradation, map: &MapSummary) -> String {
    let mut t = String::from(if args.predictions.is_some() {
        "predictions"
    } else if degradation.is_perfect() {
        "oracle"
    } else {
        "degraded"
    });
    if args.predictions.is_some() && args.prediction_zoom != 1.0 {
        t.push_str(&format!("-zoom{}", args.prediction_zoom));
    }
    if args.no_refine {
        t.push_str("-norefine");
    }
    if args.no_select {
        t.push_str("-noselect");
    }
    if args.no_polish {
        t.push_str("-nopolish");
    }
    if args.paper {
        t.push_str("-paper");
    }
    if let Some(m) = &args.map_area {
        t.push_str(&format!("-map-{m}"));
    }
    if !map.perturbation.as_ref().is_none_or(|p| p.is_identity()) {
        t.push_str("-perturbed");
    }
    if args.no_yaw_fan {
        t.push_str("-nofan");
    }
    t
}

/// Runs `insgen eval-loc`.
pub fn run(args: &Args, global: &Global) -> anyhow::Result<()> {
    let area_dir = global.workdir.join(&args.area);
    let (scene, map) =
        load_map(args, global, PreparedScene::load(&area_dir.join(crate::layout::SCENE_DIR))?)?;
    let degradation = Degradation {
        morph_px: args.dilate as i32 - args.erode as i32,
        drop_fraction: args.drop,
        merge_fraction: args.merge,
        split_fraction: args.split,
        false_positives: args.false_positives,
        score_jitter: args.score_jitter,
        segmenter: args.segmenter_like,
    };
    for (name, f) in [("--drop", args.drop), ("--merge", args.merge), ("--split", args.split)] {
        anyhow::ensure!((0.0..=1.0).contains(&f), "{name} {f}: a fraction lies in [0, 1]");
    }
    let tag = args.tag.clone().unwrap_or_else(|| default_tag(args, &degradation, &map));
    let camera_dir = area_dir.join(&args.camera);
    let source = match &args.predictions {
        Some(results) => {
            let coco_files: Vec<PathBuf> = if args.coco_files.is_empty() {
                ["train", "val", "test"]
                    .iter()
                    .map(|s| global.workdir.join("coco").join(format!("instances_{s}.json")))
                    .filter(|p| p.is_file())
                    .collect()
            } else {
                args.coco_files.clone()
            };
            anyhow::ensure!(
                !coco_files.is_empty(),
                "--predictions needs the COCO instances file the predictions refer to: none in {} (run \
                 `insgen export-coco`) and no --coco given",
                global.workdir.join("coco").display()
            );
            anyhow::ensure!(
                crate::loc::oracle::ZOOM_RANGE.contains(&args.prediction_zoom),
                "--prediction-zoom {}: a segmenter's zoom lies in [{}, {}]",
                args.prediction_zoom,
                crate::loc::oracle::ZOOM_RANGE.start(),
                crate::loc::oracle::ZOOM_RANGE.end()
            );
            let preds = load_predictions(results, &coco_files, &args.area, &args.camera, args.min_score)?;
            QuerySource::Predictions(FramePredictions { zoom: args.prediction_zoom, ..preds })
        }
        None => QuerySource::Oracle {
            masks_dir: args.masks.clone().unwrap_or_else(|| camera_dir.join(crate::layout::MASKS_DIR)),
            degradation,
        },
    };
    let queries = match (&args.query_list, &args.gt_poses, &args.prior_poses) {
        (Some(q), Some(g), Some(p)) => {
            QueryPoses::Colmap { intrinsics: q.clone(), gt: g.clone(), prior: p.clone() }
        }
        _ => QueryPoses::Sample { camera_dir: camera_dir.clone() },
    };
    let out_dir = args.out.clone().unwrap_or_else(|| camera_dir.join("loc").join(&tag));
    let (noise, noise_source) = prior_noise(&camera_dir, &queries)?;
    let bounds = search_bounds(args, &noise, &noise_source)?;
    let (label_source, why) = map_is_label_source(args, &map);
    let polish = polish_cost(args, label_source);
    log::info!(
        "{why}: the polish's second pass weighs the union's outline by {} and {} the rims",
        polish.semantic_weight,
        if polish.rim_tolerance { "frees" } else { "keeps" }
    );
    let opts = EvalOptions {
        queries,
        out_dir: out_dir.clone(),
        costs: args.costs.iter().map(|&c| c.into()).collect(),
        weighting: args.weighting.into(),
        semantic_weight: semantic_weight(args),
        source,
        search: search_options(args, bounds, &noise, polish),
        seed: args.seed,
        render_width_px: args.render_width,
        coarse_width_px: args.coarse_width.unwrap_or(if args.paper { 320 } else { 160 }),
        yaw_fan: !args.no_yaw_fan,
        limit: args.limit,
        overlays: args.overlays,
        map,
        shard: super::resolve_shard(args.shard)?,
    };
    check_search(&opts.search)?;
    let resolved = crate::render::resolve(args.renderer, Workload::Hypotheses)
        .context("setting up the renderer of the hypotheses (`--renderer cpu` needs no GPU)")?;
    log::info!("eval-loc renders its hypotheses with {} ({})", resolved.renderer.record(), resolved.reason);
    let printer = global.printer();
    let summary = eval::evaluate(&scene, &opts, &*resolved.renderer, &printer.progress())
        .with_context(|| format!("evaluating localization on {}/{}", args.area, args.camera))?;
    printer.summary(crate::loc::metrics::markdown(&summary.rows));
    let shard = opts.shard;
    printer.summary(format!(
        "{}{} queries, median {:.2} s/query (+{:.2} s setup), {:.0} hypotheses/s → {}",
        if shard.is_whole() {
            String::new()
        } else {
            format!("shard {shard} (a part for `insgen merge`; the table is this shard's): ")
        },
        summary.queries,
        summary.median_seconds_per_query,
        summary.median_setup_seconds,
        summary.hypotheses_per_second,
        if shard.is_whole() {
            out_dir.display().to_string()
        } else {
            out_dir.join(crate::util::shard::PARTS_DIR).join(shard.part_dir_name()).display().to_string()
        }
    ));
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::loc::search::DEFAULT_SPILL_WEIGHT;
    use clap::Parser;

    #[derive(Debug, Parser)]
    struct Cli {
        #[command(flatten)]
        args: Args,
    }

    fn parse(extra: &[&str]) -> Result<Args, clap::Error> {
        let mut argv = vec!["eval-loc", "--area", "denhaag", "--camera", "cam2", "--oracle"];
        argv.extend_from_slice(extra);
        Cli::try_parse_from(argv).map(|c| c.args)
    }

    #[test]
    fn renderer_defaults_to_the_cpu_rasteriser() {
        assert_eq!(parse(&[]).unwrap().renderer, RendererChoice::Cpu);
        assert_eq!(parse(&["--renderer", "gpu"]).unwrap().renderer, RendererChoice::Gpu);
        assert_eq!(parse(&["--renderer", "auto"]).unwrap().renderer, RendererChoice::Auto);
        let e = parse(&["--renderer", "vulkan"]).unwrap_err().to_string();
        assert!(e.contains("unknown renderer \"vulkan\": expected one of auto, cpu, gpu"), "{e}");
    }

    #[test]
    fn polish_cost_defaults_and_flags() {
        let none = parse(&[]).unwrap();
        assert_eq!(polish_cost(&none, true), PolishCost::for_map(true));
        assert_eq!(polish_cost(&none, false), PolishCost::for_map(false));
        let a = parse(&["--polish-semantic-weight", "0.5", "--silhouette-offset", "0"]).unwrap();
        assert_eq!(
            polish_cost(&a, true),
            PolishCost {
                semantic_weight: 0.5,
                max_silhouette_offset_px: 0,
                spill_weight: DEFAULT_SPILL_WEIGHT,
                rim_tolerance: true,
            }
        );
        let a = parse(&["--polish-spill-weight", "1"]).unwrap();
        assert_eq!(polish_cost(&a, false), PolishCost { spill_weight: 1.0, ..PolishCost::for_map(false) });
        for bad in [["--polish-semantic-weight", "2"], ["--polish-spill-weight", "1.5"]] {
            let e = parse(&bad).unwrap_err().to_string();
            assert!(e.contains("expected a number in [0, 1]"), "{e}");
        }
    }

    #[test]
    fn the_polish_keeps_the_buildings_and_frees_the_rims_against_the_areas_own_scene_only() {
        let own = MapSummary { area: "denhaag".into(), perturbation: None, changes: None };
        let lod1 = MapSummary {
            perturbation: Some(MapPerturbation { lod1: true, ..Default::default() }),
            ..own.clone()
        };
        let other = MapSummary { area: "delft".into(), ..own.clone() };
        let auto = parse(&[]).unwrap();
        assert_eq!(auto.polish_rim_tolerance, RimToleranceArg::Auto);
        assert!(map_is_label_source(&auto, &own).0);
        assert!(!map_is_label_source(&auto, &lod1).0);
        assert!(!map_is_label_source(&auto, &other).0);
        let own_cost = PolishCost::for_map(true);
        assert_eq!((own_cost.semantic_weight, own_cost.rim_tolerance), (0.0, true));
        let coarser = PolishCost::for_map(false);
        assert_eq!((coarser.semantic_weight, coarser.rim_tolerance), (1.0, false));
        // The flags override the map's choice, each on its own.
        let on = parse(&["--polish-rim-tolerance", "on"]).unwrap();
        assert_eq!(polish_cost(&on, false), PolishCost { rim_tolerance: true, ..coarser });
        let off = parse(&["--polish-rim-tolerance", "off"]).unwrap();
        assert_eq!(polish_cost(&off, true), PolishCost { rim_tolerance: false, ..own_cost });
        assert!(parse(&["--polish-rim-tolerance", "yes"]).is_err());
    }

    #[test]
    fn search_volume_from_the_prior_noise_and_flags() {
        let noise = PriorNoise::default();
        let b = search_bounds(&parse(&[]).unwrap(), &noise, "the default prior noise model").unwrap();
        assert_eq!(b, SearchBounds::default());
        let a = parse(&["--search-radius-m", "25", "--search-yaw-deg", "6"]).unwrap();
        let b = search_bounds(&a, &noise, "the default prior noise model").unwrap();
        assert_eq!((b.radius_m, b.height_m, b.yaw_deg), (25.0, 20.0, 6.0));
        assert!(
            b.origin.starts_with("--search-radius-m 25, --search-yaw-deg 6; 4.4σ horizontally"),
            "{}",
            b.origin
        );
        assert!(search_bounds(&parse(&["--search-yaw-deg", "181"]).unwrap(), &noise, "x").is_err());
        for bad in [["--search-height-m", "0"], ["--search-radius-m", "nan"], ["--search-yaw-deg", "inf"]] {
            let e = parse(&bad).unwrap_err().to_string();
            assert!(e.contains("expected a number > 0"), "{e}");
        }
    }

    #[test]
    fn coarse_grid_from_the_prior_noise_unless_flags_give_it() {
        let loose = PriorNoise {
            sigma_enu_m: [14.0, 14.0, 10.0],
            sigma_ypr_deg: [6.0, 0.02, 0.02],
            ..PriorNoise::default()
        };
        let options = |extra: &[&str], noise: &PriorNoise| {
            let a = parse(extra).unwrap();
            search_options(&a, search_bounds(&a, noise, "test").unwrap(), noise, polish_cost(&a, true))
        };
        let grid = |extra: &[&str], noise: &PriorNoise| {
            let c = options(extra, noise).coarse;
            (c.xy_range_m, c.xy_step_m, c.z_range_m, c.z_step_m, c.yaw_range_deg, c.yaw_step_deg)
        };
        assert_eq!(grid(&[], &PriorNoise::default()), (20.0, 5.0, 10.0, 5.0, 7.5, 2.5));
        assert_eq!(grid(&["--paper"], &PriorNoise::default()), (20.0, 5.0, 10.0, 5.0, 7.5, 2.5));
        assert_eq!(grid(&[], &loose), (35.0, 5.0, 20.0, 5.0, 15.0, 2.5));
        // Narrower search flags cap it; --coarse-* flags replace it.
        assert_eq!(grid(&["--search-yaw-deg", "5"], &loose), (35.0, 5.0, 20.0, 5.0, 5.0, 2.5));
        assert_eq!(
            grid(&["--coarse-xy", "10/2", "--coarse-yaw", "3/1"], &loose),
            (10.0, 2.0, 20.0, 5.0, 3.0, 1.0)
        );
        // A grid too large to score is refused, naming its size and the way out.
        assert!(check_search(&options(&[], &loose)).is_ok());
        let lost = PriorNoise { sigma_enu_m: [500.0, 500.0, 50.0], ..PriorNoise::default() };
        let e = check_search(&options(&[], &lost)).unwrap_err().to_string();
        assert!(e.contains("would have") && e.contains("--coarse-xy RANGE/STEP"), "{e}");
        assert!(check_search(&options(&["--coarse-xy", "1250/50", "--coarse-z", "100/25"], &lost)).is_ok());
    }

    #[test]
    fn beam_flags_apply_over_defaults_and_paper() {
        let beams = |extra: &[&str]| {
            let a = parse(extra).unwrap();
            search_options(&a, SearchBounds::default(), &PriorNoise::default(), polish_cost(&a, true))
                .fine
                .beams_mode
        };
        assert_eq!(beams(&[]), FineParams::default().beams_mode);
        assert_eq!(
            beams(&["--basins", "6", "--prune", "5/3"]),
            BeamMode::Basins {
                count: 6,
                survivors: 1,
                prune: Some(Prune { after_iterations: 5, keep: 3 }),
                prior_basin: true
            }
        );
        assert_eq!(
            beams(&["--prune", "off", "--survivors", "2", "--prior-basin", "off"]),
            BeamMode::Basins { count: 4, survivors: 2, prune: None, prior_basin: false }
        );
        assert_eq!(beams(&["--paper"]), BeamMode::Joint);
        assert_eq!(
            beams(&["--paper", "--basins", "3"]),
            BeamMode::Basins { count: 3, survivors: 1, prune: None, prior_basin: false }
        );
        assert_eq!(
            beams(&["--paper", "--prune", "4/2"]),
            BeamMode::Basins {
                count: 4,
                survivors: 1,
                prune: Some(Prune { after_iterations: 4, keep: 2 }),
                prior_basin: false
            }
        );
        assert_eq!(
            beams(&["--paper", "--prior-basin", "on"]),
            BeamMode::Basins { count: 4, survivors: 1, prune: None, prior_basin: true }
        );
        for bad in ["5", "5/0", "x/2", "on"] {
            let e = parse(&["--prune", bad]).unwrap_err().to_string();
            assert!(e.contains("--prune"), "{bad}: {e}");
        }
    }

    #[test]
    fn segmenter_like_takes_the_preset_or_overrides_and_grouped_is_a_cost() {
        assert_eq!(parse(&[]).unwrap().segmenter_like, None);
        assert_eq!(parse(&["--segmenter-like"]).unwrap().segmenter_like, Some(SegmenterLike::learned()));
        let a = parse(&["--segmenter-like", "learned,chain=0.2", "--cost", "grouped"]).unwrap();
        assert_eq!(a.segmenter_like.map(|s| s.chain_share), Some(0.2));
        assert_eq!(a.costs, vec![CostArg::Grouped]);
        assert_eq!(CostKind::from(CostArg::Grouped), CostKind::Grouped);
        let e = parse(&["--segmenter-like", "chain=2"]).unwrap_err().to_string();
        assert!(e.contains("shares lie in [0, 1]"), "{e}");
    }

    #[test]
    fn weighting_is_area_by_default_and_area_conf_parses() {
        assert_eq!(Weighting::from(parse(&[]).unwrap().weighting), Weighting::Area);
        let a = parse(&["--weighting", "area-conf"]).unwrap();
        assert_eq!(Weighting::from(a.weighting), Weighting::AreaConf);
        assert!(parse(&["--weighting", "score"]).is_err());
    }

    mod semantic_weight {
        use super::*;

        #[test]
        fn default_blends_and_paper_is_pure_instance() {
            assert_eq!(semantic_weight(&parse(&[]).unwrap()), DEFAULT_SEMANTIC_WEIGHT);
            assert_eq!(semantic_weight(&parse(&["--paper"]).unwrap()), 0.0);
        }

        #[test]
        fn given_value_wins_over_paper() {
            let a = parse(&["--paper", "--semantic-weight", "0.25"]).unwrap();
            assert_eq!(semantic_weight(&a), 0.25);
            assert_eq!(semantic_weight(&parse(&["--semantic-weight", "0"]).unwrap()), 0.0);
        }

        #[test]
        fn outside_unit_interval_is_rejected() {
            for bad in ["1.5", "-0.1", "half"] {
                let flag = format!("--semantic-weight={bad}");
                let e = parse(&[&flag]).unwrap_err().to_string();
                assert!(e.contains("expected a number in [0, 1]"), "{bad}: {e}");
            }
        }
    }
}
