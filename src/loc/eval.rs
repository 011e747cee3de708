//! The `eval-loc` stage: localize every query of an area/camera from its prior and report the paper's
//! table.
//!
//! Per query: the query instances (oracle ground-truth masks with degradations, or predictions) at the
//! render resolution; the scene culled to the buildings the prior could see (with a margin covering the
//! search range) and renumbered densely; hypotheses rendered by the renderer given to [`evaluate`]
//! ([`crate::render::IdRenderer`]: by default the CPU rasteriser of [`crate::render::cpu`], one
//! hypothesis per thread; wgpu renders batches with frames in flight, scored on the thread pool) and
//! scored with [`super::cost`]; the search of [`super::search`]; errors against the ground truth. The
//! coarse grid's yaws at one position come from one wide render ([`RotationFan`]).
//!
//! Outputs in `<workdir>/<area>/<camera>/loc/<tag>/`: `results.jsonl` (one line per query and cost),
//! `est_poses_<cost>.txt` (COLMAP `NAME qw qx qy qz tx ty tz`), `summary.md` / `summary.json` (recall at
//! (2 m, 2°), (3 m, 3°), (5 m, 5°), median errors; the prior's own row first; per trajectory group),
//! and `overlays/<frame>.png` for the first queries ([`super::overlay`]: query outlines over the
//! renders at the prior, the estimate and the ground truth, each captioned with its error).
//!
//! A shard `i/N` of the queries (positions ≡ i mod N in the query list, after `limit`) writes its
//! `results.jsonl` and `est_poses_<cost>.txt` to `<out>/parts/<i>-of-<N>/` with a `part.json`
//! ([`PartInfo`]), and the overlays of its queries among the first ones to `<out>/overlays/`;
//! [`combine_parts`] puts the parts' lines back in query order and recomputes the summary from them.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::Instant;

use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use super::cost::{Blend, CostKind, Query, Scorer, Weighting};
use super::map::MapSummary;
use super::metrics::{self, Row};
use super::morph::morph_into;
use super::oracle::Degradation;
use super::query::{QueryError, QuerySource};
use super::search::{self, Evaluate, Hypothesis, PolishCost, SearchOptions, SearchResult};
use crate::camera::colmap::{self, ColmapCamera};
use crate::camera::record::read_jsonl;
use crate::camera::{Intrinsics, Pose, PoseRecord, Trajectory};
use crate::render::cpu::{CpuScene, Frame};
use crate::render::warp::RotationFan;
use crate::render::{IdRenderer, IdScene, RenderError, RenderOptions, RendererKind, RendererRecord, View};
use crate::scene::{BuildingId, BuildingRecord, PreparedScene, SceneMesh};
use crate::util::shard::{PARTS_DIR, PART_MARKER};
use crate::util::{self, Progress, Shard};
use glam::DVec3;

/// Errors of the eval-loc stage.
#[derive(Debug, thiserror::Error)]
pub enum EvalError {
    /// A file cannot be read or written.
    #[error(transparent)]
    File(#[from] util::FileError),
    /// The query instances (masks or predictions) cannot be built.
    #[error(transparent)]
    Query(#[from] QueryError),
    /// A pose, prior or COLMAP list cannot be read.
    #[error(transparent)]
    Camera(#[from] crate::camera::CameraError),
    /// A query list, or a file a shard wrote, holds what the evaluation cannot use.
    #[error("{}: {problem}", path.display())]
    Input {
        /// The file (the camera directory's `poses.jsonl` when it lists no query).
        path: PathBuf,
        /// What is wrong in it.
        problem: InputProblem,
    },
    /// A part's `part.json` is not the marker eval-loc writes ([`PartInfo`]).
    #[error("{}: not an eval-loc part marker", path.display())]
    PartMarker {
        /// The `part.json`.
        path: PathBuf,
        /// The parser's complaint.
        #[source]
        source: serde_json::Error,
    },
    /// A line of the parts' combined `results.jsonl` is not a [`QueryResult`].
    #[error("{}: combined line {line} is not a result", path.display())]
    ResultLine {
        /// The `results.jsonl` being combined (in the output directory).
        path: PathBuf,
        /// The 1-based line in the combined file.
        line: usize,
        /// The parser's complaint.
        #[source]
        source: serde_json::Error,
    },
    /// A part's text file is not UTF-8.
    #[error("{}: not UTF-8 text", path.display())]
    NotUtf8 {
        /// The file.
        path: PathBuf,
        /// Where the first invalid byte is.
        #[source]
        source: std::string::FromUtf8Error,
    },
    /// Stopped by Ctrl-C between queries; nothing was written.
    #[error(transparent)]
    Interrupted(#[from] util::interrupt::Interrupted),
    /// The parts shards wrote of an evaluation do not make one evaluation.
    #[error("{}: {problem}", dir.display())]
    Parts {
        /// The part directory concerned (the parts directory when all are).
        dir: PathBuf,
        /// Why the parts do not combine.
        problem: PartsProblem,
    },
    /// A part does not hold its share of the queries.
    #[error("{}: the parts do not interleave", dir.display())]
    Interleave {
        /// The parts directory.
        dir: PathBuf,
        /// Which shard holds how many lines.
        #[source]
        source: util::ShardError,
    },
    /// The renderer failed (a wgpu device error; the CPU rasteriser does not fail).
    #[error("rendering the hypotheses")]
    Render(#[from] RenderError),
}

/// What is wrong inside a query list or a part's file: the text after the path of an
/// [`EvalError::Input`].
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum InputProblem {
    /// A ground-truth pose has no prior of the same name in the priors file.
    #[error("no prior for query {query}")]
    NoPrior {
        /// The query's frame name.
        query: String,
    },
    /// A ground-truth pose has no camera of the same name in the COLMAP intrinsics list.
    #[error("no intrinsics for query {query}")]
    NoIntrinsics {
        /// The query's frame name.
        query: String,
    },
    /// A query's COLMAP camera model has distortion parameters (or is unknown).
    #[error("query {query}: camera model {model} is not a pinhole (SIMPLE_PINHOLE or PINHOLE)")]
    NotPinhole {
        /// The query's frame name.
        query: String,
        /// The COLMAP model name as written.
        model: String,
    },
    /// The query list is empty (after `--limit`).
    #[error("no queries")]
    NoQueries,
    /// A part's results or pose file does not hold the same number of lines for every query.
    #[error("{lines} lines, not {per_query} per query")]
    LinesPerQuery {
        /// Lines in the file.
        lines: usize,
        /// Lines each query should have (one per cost, or per occurrence of a cost).
        per_query: usize,
    },
}

/// Why the parts of an evaluation do not combine: the text after the directory of an
/// [`EvalError::Parts`].
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PartsProblem {
    /// No part was given.
    #[error("no parts")]
    NoParts,
    /// A part's marker is of another kind or version, or names another shard than its directory.
    #[error(
        "{PART_MARKER} is a {kind:?} part (version {version}) of shard {said}, expected a {PART_KIND:?} \
         part (version {PART_VERSION}) of shard {shard}"
    )]
    WrongMarker {
        /// The marker's `kind`.
        kind: String,
        /// The marker's `version`.
        version: u32,
        /// The shard the marker names, as written.
        said: String,
        /// The shard of the directory.
        shard: Shard,
    },
    /// Parts of runs with different shard counts.
    #[error(
        "{} is shard {shard} and {} shard {first_shard}: parts of one run have one shard count",
        dir.display(),
        first_dir.display()
    )]
    MixedCounts {
        /// A part whose count differs from the first part's.
        dir: PathBuf,
        /// Its shard.
        shard: Shard,
        /// The first part.
        first_dir: PathBuf,
        /// The first part's shard.
        first_shard: Shard,
    },
    /// Parts of runs with different options (queries, costs, weighting, search, map, source).
    #[error(
        "{} (shard {shard}) and {} (shard {first_shard}) are parts of different runs: they differ in {} \
         (values of shard {first_shard} vs shard {shard}); merge the parts of one run",
        dir.display(),
        first_dir.display(),
        differences.join(", ")
    )]
    DifferentRuns {
        /// A part that differs from the first part.
        dir: PathBuf,
        /// Its shard.
        shard: Shard,
        /// The first part.
        first_dir: PathBuf,
        /// The first part's shard.
        first_shard: Shard,
        /// The differing options, as [`part_differences`] lists them (`seed: 1 vs 2`).
        differences: Vec<String>,
    },
    /// Shards of the evaluation are missing.
    #[error(
        "shard(s) {} of the evaluation are missing; run `insgen eval-loc … --shard I/{count}` for them",
        missing.iter().map(Shard::to_string).collect::<Vec<_>>().join(", ")
    )]
    MissingShards {
        /// The missing shards.
        missing: Vec<Shard>,
        /// The shard count.
        count: u32,
    },
}

/// Options of an evaluation run.
#[derive(Debug, Clone)]
pub struct EvalOptions {
    /// The queries' poses and priors.
    pub queries: QueryPoses,
    /// Where results go (`<workdir>/<area>/<camera>/loc/<tag>` from the CLI).
    pub out_dir: PathBuf,
    /// Costs to evaluate (each gives a row of the table).
    pub costs: Vec<CostKind>,
    /// How the per-instance scores of the instance cost are weighted.
    pub weighting: Weighting,
    /// Weight w of the semantic IoU in the instance cost, (1 − w)·instance + w·semantic, in [0, 1]
    /// ([`super::cost::Scorer::blended_cost`]; 0 = the paper's).
    pub semantic_weight: f64,
    /// Oracle masks (degraded) or predictions.
    pub source: QuerySource,
    /// The search's stages and parameters.
    pub search: SearchOptions,
    /// `--seed`: drives the oracle's degradations (and the map's perturbation unless `--map-seed`).
    pub seed: u64,
    /// Width of the fine-stage renders and query masks (height keeps the aspect ratio).
    pub render_width_px: u32,
    /// Width of the coarse-stage renders.
    pub coarse_width_px: u32,
    /// Coarse stage: render one wide view per grid position and read every yaw out of it
    /// ([`crate::render::warp`]) instead of rendering each yaw.
    pub yaw_fan: bool,
    /// Queries taken from the list (before sharding); all when `None`.
    pub limit: Option<usize>,
    /// Overlay PNGs written for the first this many queries.
    pub overlays: usize,
    /// The map the scene given to [`evaluate`] is (its area and perturbation), for the summary.
    pub map: MapSummary,
    /// The queries to localize: positions ≡ i (mod N) of the list (after `limit`). A shard other
    /// than the whole list writes a part for [`combine_parts`] instead of the summary.
    pub shard: Shard,
}

/// One line of `results.jsonl`.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct QueryResult {
    /// The query's frame name.
    pub name: String,
    /// The cost it was localized with.
    pub cost: CostKind,
    /// Table group: `grid` or `sequence` (sampled queries), `query` (COLMAP lists).
    pub group: String,
    /// The estimated camera centre (east, north, up; ENU metres) and yaw (degrees).
    pub estimate: [f64; 4],
    /// Distance of the prior's centre from the ground truth's, metres.
    pub prior_translation_error_m: f64,
    /// Rotation angle between the prior and the ground truth, degrees.
    pub prior_rotation_error_deg: f64,
    /// Distance of the estimate's centre from the ground truth's, metres.
    pub translation_error_m: f64,
    /// Rotation angle between the estimate and the ground truth, degrees.
    pub rotation_error_deg: f64,
    /// The translation error along the ground truth's viewing direction (signed, positive: the estimate
    /// is in front of the ground truth) and across it, metres ([`Pose::axial_lateral_error_m`]).
    #[serde(default)]
    pub axial_error_m: f64,
    /// The translation error across the ground truth's viewing direction, metres.
    #[serde(default)]
    pub lateral_error_m: f64,
    /// The silhouette offset the polish fitted (pixels at the render width; > 0: the rendered buildings
    /// dilated to match fatter query masks, < 0: eroded), 0 without one (search::PolishCost).
    #[serde(default)]
    pub silhouette_offset_px: i32,
    /// The estimate's cost in the terms of the search's last stage: with the polish's second pass, its
    /// semantic weight, spill weight and fitted silhouette offset (search::PolishCost).
    pub best_cost: f64,
    /// The cost of the ground-truth pose (at the fine resolution, in the same terms as `best_cost`): how
    /// well the query can be explained at all. A best cost above it with a large error means the cost is ambiguous; below it, the search
    /// missed.
    pub cost_at_gt: f64,
    /// Errors of the coarse stage's best hypothesis.
    pub coarse_translation_error_m: f64,
    /// Rotation error of the coarse stage's best hypothesis, degrees (its translation error just above).
    pub coarse_rotation_error_deg: f64,
    /// Hypotheses scored by the search.
    pub hypotheses: u64,
    /// Wall-clock seconds of the search.
    pub seconds: f64,
    /// Wall-clock seconds of the query's preparation, shared by its costs: the query masks at both
    /// resolutions, culling around the prior, the CPU scene (welding, closed shells, polygons).
    #[serde(default)]
    pub setup_seconds: f64,
    /// Instances in the query (at the render width).
    pub query_instances: usize,
    /// Cells of the frame's 4 × 4 grid holding the query's buildings
    /// ([`crate::loc::cost::Query::covered_frame_cells`]): how far its silhouettes spread.
    #[serde(default)]
    pub covered_frame_cells: u32,
    /// Share of the frame the query's buildings cover (the union of its instances; at the render
    /// width): near 1, a few large roofs fill the frame and leave little outline to localize from
    /// (issue 40; the sampler's `max_building_fraction`).
    #[serde(default)]
    pub query_building_share: f64,
    /// Buildings kept around the prior (the culled map).
    pub buildings_considered: usize,
    /// Hypotheses and seconds per stage of the search.
    #[serde(default)]
    pub stages: search::StageCosts,
    /// Whether the search's best pose lay on the boundary of the search volume around the prior
    /// ([`search::SearchBounds`], within [`search::BOUNDARY_TOLERANCE`] of a half-range): the cost's
    /// optimum may lie beyond, where the prior says the camera cannot be.
    #[serde(default)]
    pub on_search_boundary: bool,
    /// Whether the estimate is the prior because the search's best pose lay on the boundary
    /// ([`search::OnBoundary::Prior`], the default).
    #[serde(default)]
    pub kept_prior: bool,
}

/// The run's summary.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Summary {
    /// The table: the prior's rows first, then each cost's, per group (and `all`).
    pub rows: Vec<Row>,
    /// Queries localized.
    pub queries: usize,
    /// Median over queries and costs of the search's wall-clock seconds.
    pub median_seconds_per_query: f64,
    /// Median over queries of the preparation shared by a query's costs (see `QueryResult`).
    #[serde(default)]
    pub median_setup_seconds: f64,
    /// Hypotheses scored per second of search, over all queries and costs.
    pub hypotheses_per_second: f64,
    /// Recall at (2 m, 2°) per bucket of query instance counts, per cost (every query in one bucket).
    #[serde(default)]
    pub instance_buckets: Vec<metrics::BucketRow>,
    /// Recall at (2 m, 2°) per bucket of the frame's cells holding buildings, per cost.
    #[serde(default)]
    pub coverage_buckets: Vec<metrics::BucketRow>,
    /// Per cost, the translation errors split along and across the camera's axis.
    #[serde(default)]
    pub axis_rows: Vec<metrics::AxisRow>,
    /// Per cost, the estimates on the boundary of the search volume.
    #[serde(default)]
    pub boundary_rows: Vec<BoundaryRow>,
    /// The search that ran (stages, coarse grid, particle filter, beams).
    pub search: SearchOptions,
    /// The map: its area and perturbation.
    pub map: MapSummary,
    /// The renderer of the hypotheses when it was not the CPU rasteriser (`--renderer gpu`, or `auto`
    /// on a hardware GPU); absent for the CPU rasteriser, the default (and every run before the
    /// renderer could be chosen).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub renderer: Option<RendererRecord>,
    /// Where the queries' instances came from: oracle masks (the ground truth, with their
    /// degradations) or a segmentation model's predictions (by SHA-256). Absent in summaries written
    /// before it was recorded.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub source: Option<PartSource>,
}

/// How many of one cost's estimates lie on the boundary of the search volume.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct BoundaryRow {
    /// The cost, as named in the table.
    pub method: String,
    /// Queries localized.
    pub queries: usize,
    /// Queries whose search ended on the boundary (`on_search_boundary`, see [`QueryResult`]).
    pub on_search_boundary: usize,
    /// Of those, the queries whose estimate is the prior (`kept_prior`).
    #[serde(default)]
    pub kept_prior: usize,
}

/// Intrinsics scaled to `width_px` (height rounded to keep the aspect ratio).
pub fn at_width(k: &Intrinsics, width_px: u32) -> Intrinsics {
    let h = ((k.height_px as f64) * width_px as f64 / k.width_px as f64).round().max(1.0) as u32;
    k.scaled_to(width_px, h)
}

/// Buildings whose bounding box may be seen from `pose` with a margin of `margin` image widths on each
/// side (to cover the search range); conservative for boxes that straddle the camera plane.
pub fn cull(buildings: &[BuildingRecord], pose: &Pose, k: &Intrinsics, margin: f64) -> Vec<BuildingId> {
    let (w, h) = (k.width_px as f64, k.height_px as f64);
    let (x0, x1, y0, y1) = (-margin * w, (1.0 + margin) * w, -margin * h, (1.0 + margin) * h);
    buildings
        .iter()
        .filter(|b| {
            let (lo, hi) = (b.bbox_min_enu_m, b.bbox_max_enu_m);
            let mut front = 0;
            let (mut u0, mut u1, mut v0, mut v1) =
                (f64::INFINITY, f64::NEG_INFINITY, f64::INFINITY, f64::NEG_INFINITY);
            for c in 0..8 {
                let p = [
                    if c & 1 == 0 { lo[0] } else { hi[0] },
                    if c & 2 == 0 { lo[1] } else { hi[1] },
                    if c & 4 == 0 { lo[2] } else { hi[2] },
                ];
                let q = pose.world_to_cam(p.into());
                if q.z > crate::render::cpu::NEAR_M {
                    front += 1;
                    let uv = k.project(q).expect("in front");
                    u0 = u0.min(uv[0]);
                    u1 = u1.max(uv[0]);
                    v0 = v0.min(uv[1]);
                    v1 = v1.max(uv[1]);
                }
            }
            match front {
                0 => false,
                8 => u1 >= x0 && u0 <= x1 && v1 >= y0 && v0 <= y1,
                _ => true,
            }
        })
        .map(|b| b.id)
        .collect()
}

/// The culled scene with dense IDs 1..=K (K = `kept.len()`).
pub fn dense_subscene(mesh: &SceneMesh, kept: &[BuildingId]) -> SceneMesh {
    let max = kept.iter().map(|id| id.get()).max().unwrap_or(0) as usize;
    let mut dense = vec![BuildingId::BACKGROUND; max + 1];
    for (i, &id) in kept.iter().enumerate() {
        // At most as many buildings as the scene has, which all have IDs.
        dense[id.get() as usize] = BuildingId::from_index(i).expect("fewer buildings than the ID space");
    }
    let dense_of = |id: BuildingId| dense.get(id.get() as usize).copied().unwrap_or(BuildingId::BACKGROUND);
    let mut sub = mesh.filter_buildings(|id| !dense_of(id).is_background());
    for id in &mut sub.building_ids {
        *id = dense_of(*id);
    }
    sub
}

/// Scores hypotheses by rendering them with an [`IdScene`]: on the CPU rasteriser one hypothesis per
/// thread of the rayon pool; on a renderer that prefers batches (wgpu), a batch's views are rendered
/// in order with frames in flight and scored on the pool.
pub struct Evaluator<'a, S: IdScene + ?Sized = CpuScene> {
    /// The culled, densely renumbered map, prepared by the renderer.
    pub scene: &'a S,
    /// Intrinsics of the renders and of the query's masks, pixels.
    pub k: Intrinsics,
    /// Pitch of every hypothesis (the prior's; not searched), degrees.
    pub pitch_deg: f64,
    /// Roll of every hypothesis (the prior's; not searched), degrees.
    pub roll_deg: f64,
    /// The query's instances at `k`.
    pub query: &'a Query,
    /// The cost scored.
    pub kind: CostKind,
    /// How the per-instance scores of [`CostKind::Instance`] (and [`CostKind::Grouped`]) are weighted.
    pub weighting: Weighting,
    /// The terms of [`CostKind::Instance`] and [`CostKind::Grouped`]: the semantic weight (see [`EvalOptions::semantic_weight`])
    /// and the semantic term's spill weight (1 until [`Evaluate::enter_polish`] sets the polish's).
    pub blend: Blend,
    /// The largest dense building ID of the scene (the scorer's table size).
    pub k_max: u32,
    /// Applied to every rendered image before scoring: dilate (> 0) or erode (< 0) each building by
    /// this many pixels ([`morph_into`]), so that query masks systematically fatter or thinner than the
    /// buildings' silhouettes (a segmenter's boundary bias) are not explained by a camera moved along
    /// its axis. 0 until [`Evaluate::enter_polish`] fits it.
    pub silhouette_offset_px: i32,
    /// Runs of at least [`MIN_FAN`] consecutive hypotheses at one centre (the coarse grid's yaws) are
    /// rendered once, wide, and warped per yaw ([`RotationFan`]).
    pub yaw_fan: bool,
    /// Buffers kept between batches, one set per thread at work ([`Workspaces`]).
    pub workspaces: Workspaces,
}

/// The evaluator of the CPU rasteriser (the default; what benches and tests build).
pub type CpuEvaluator<'a> = Evaluator<'a, CpuScene>;

/// Views a renderer that prefers batches ([`IdScene::renders_in_parallel`] false) renders at once
/// before they are scored: enough to keep its frames in flight busy, few enough for memory (64 frames
/// of 640 × 360 IDs are 59 MB).
const RENDER_BATCH: usize = 64;

/// Scoring buffers kept by an [`Evaluator`] between batches.
///
/// A set holds a frame's ID and depth buffers and one camera-frame and screen position per vertex
/// of the scene: megabytes for a city. Allocated and zeroed afresh for every batch, they weighed
/// most on the polish, whose simplex scores one hypothesis at a time (issue 15); taken from here,
/// each thread's set is allocated once per query and evaluator.
#[derive(Default)]
pub struct Workspaces {
    free: std::sync::Mutex<Vec<Workspace>>,
}

impl Workspaces {
    /// A free set (a new one when all are in use), back in the pool when the guard drops.
    fn take(&self) -> Lent<'_> {
        let ws = self.free.lock().map(|mut free| free.pop()).ok().flatten().unwrap_or_default();
        Lent { pool: self, ws: Some(ws) }
    }
}

/// A [`Workspace`] lent by [`Workspaces::take`].
struct Lent<'a> {
    pool: &'a Workspaces,
    ws: Option<Workspace>,
}

impl std::ops::Deref for Lent<'_> {
    type Target = Workspace;
    fn deref(&self) -> &Workspace {
        self.ws.as_ref().expect("lent until dropped")
    }
}

impl std::ops::DerefMut for Lent<'_> {
    fn deref_mut(&mut self) -> &mut Workspace {
        self.ws.as_mut().expect("lent until dropped")
    }
}

impl Drop for Lent<'_> {
    fn drop(&mut self) {
        if let (Some(ws), Ok(mut free)) = (self.ws.take(), self.pool.free.lock()) {
            free.push(ws);
        }
    }
}

/// The shortest run of same-centre hypotheses worth a wide render.
pub const MIN_FAN: usize = 3;

/// One thread's buffers for [`Evaluator`]: the render, the scorer, the yaw fan's warp and the
/// silhouette offset's morphology.
#[derive(Default)]
struct Workspace {
    frame: Frame,
    scorer: Scorer,
    warped: Vec<u32>,
    morphed: Vec<u32>,
    scratch: Vec<u32>,
}

impl<S: IdScene + ?Sized> Evaluator<'_, S> {
    /// The evaluator's view at `pose`.
    fn view(&self, pose: Pose) -> View {
        View { intrinsics: self.k, pose }
    }

    /// The cost of a full pose (any pitch and roll), e.g. the ground truth.
    ///
    /// # Errors
    /// The renderer's ([`IdScene::render_into`]).
    pub fn cost_of_pose(&self, pose: &Pose) -> Result<f64, RenderError> {
        let mut ws = self.workspaces.take();
        self.scene.render_into(&self.view(*pose), &mut ws.frame)?;
        let ids = std::mem::take(&mut ws.frame.ids);
        let score = self.score(&mut ws, &ids);
        ws.frame.ids = ids;
        Ok(score)
    }

    /// Scores a rendered dense-ID image of the evaluator's intrinsics, after the silhouette offset.
    fn score(&self, ws: &mut Workspace, ids: &[u32]) -> f64 {
        let ids = if self.silhouette_offset_px != 0 {
            let (w, h) = (self.k.width_px as usize, self.k.height_px as usize);
            morph_into(ids, w, h, self.silhouette_offset_px, &mut ws.scratch, &mut ws.morphed);
            &ws.morphed[..]
        } else {
            ids
        };
        ws.scorer.cost(self.kind, self.query, ids, self.k_max, self.weighting, self.blend)
    }

    /// The rotation fan of a run of hypotheses sharing a centre, when it is long enough and fits.
    fn fan(&self, poses: &[Pose]) -> Option<RotationFan> {
        if self.yaw_fan && poses.len() >= MIN_FAN {
            RotationFan::new(poses, &self.k)
        } else {
            None
        }
    }

    /// Scores every yaw of `fan` out of its wide render `wide_ids`.
    fn score_fan(&self, fan: &RotationFan, wide_ids: &[u32], ws: &mut Workspace) -> Vec<f64> {
        let mut warped = std::mem::take(&mut ws.warped);
        let scores = (0..fan.len())
            .map(|i| {
                fan.warp(i, wide_ids, &mut warped);
                self.score(ws, &warped)
            })
            .collect();
        ws.warped = warped;
        scores
    }

    /// Scores one run of hypotheses sharing a centre: through a rotation fan when it is long enough and
    /// the fan fits, else one render each.
    fn score_run(&self, run: &[Hypothesis], ws: &mut Workspace) -> Result<Vec<f64>, RenderError> {
        let poses: Vec<Pose> = run.iter().map(|h| h.pose(self.pitch_deg, self.roll_deg)).collect();
        if let Some(fan) = self.fan(&poses) {
            self.scene.render_into(&View { intrinsics: fan.intrinsics, pose: fan.pose }, &mut ws.frame)?;
            let ids = std::mem::take(&mut ws.frame.ids);
            let scores = self.score_fan(&fan, &ids, ws);
            ws.frame.ids = ids;
            return Ok(scores);
        }
        poses
            .iter()
            .map(|pose| {
                self.scene.render_into(&self.view(*pose), &mut ws.frame)?;
                let ids = std::mem::take(&mut ws.frame.ids);
                let score = self.score(ws, &ids);
                ws.frame.ids = ids;
                Ok(score)
            })
            .collect()
    }

    /// Scores runs on a renderer that prefers batches: the runs' views (one per fan, else one per
    /// hypothesis) rendered [`RENDER_BATCH`] at a time with [`IdScene::render_each`], each batch
    /// scored on the rayon pool. The scores are those of [`Evaluator::score_run`] on the same images.
    fn score_batched(&self, runs: &[&[Hypothesis]]) -> Result<Vec<f64>, RenderError> {
        let mut views: Vec<View> = Vec::new();
        let mut fans: Vec<Option<RotationFan>> = Vec::new();
        for run in runs {
            let poses: Vec<Pose> = run.iter().map(|h| h.pose(self.pitch_deg, self.roll_deg)).collect();
            match self.fan(&poses) {
                Some(fan) => {
                    views.push(View { intrinsics: fan.intrinsics, pose: fan.pose });
                    fans.push(Some(fan));
                }
                None => {
                    views.extend(poses.into_iter().map(|p| self.view(p)));
                    fans.resize_with(views.len(), || None);
                }
            }
        }
        let mut scores: Vec<f64> = Vec::with_capacity(views.len());
        let mut images: Vec<crate::scene::IdMap> = Vec::with_capacity(RENDER_BATCH);
        for (views, fans) in views.chunks(RENDER_BATCH).zip(fans.chunks(RENDER_BATCH)) {
            images.clear();
            self.scene.render_each(views, &RenderOptions::default(), &mut |_, image| {
                images.push(image.ids);
                std::ops::ControlFlow::Continue(())
            })?;
            let batch: Vec<Vec<f64>> = images
                .par_iter()
                .zip(fans.par_iter())
                .map_init(
                    || self.workspaces.take(),
                    |ws, (image, fan)| match fan {
                        Some(fan) => self.score_fan(fan, image.raw(), ws),
                        None => vec![self.score(ws, image.raw())],
                    },
                )
                .collect();
            scores.extend(batch.into_iter().flatten());
        }
        Ok(scores)
    }
}

impl<S: IdScene + ?Sized> Evaluate for Evaluator<'_, S> {
    type Error = RenderError;

    /// Takes the polish's semantic weight (the instance cost only: the semantic baseline is its own
    /// cost, the merged ablation stays the paper's) and fits the silhouette offset at `at`: every offset
    /// in ±`max_silhouette_offset_px` is scored on one render there with the symmetric IoU (spill
    /// weight 1: a boundary bias of the masks is measured without the preference for larger renders)
    /// and the best kept, the smallest |offset| on ties. Then takes the polish's spill weight and rim
    /// tolerance (both the instance and the semantic cost).
    fn enter_polish(&mut self, at: &Hypothesis, cost: &PolishCost) -> Result<(u64, bool), Self::Error> {
        let before = (self.blend, self.silhouette_offset_px);
        if matches!(self.kind, CostKind::Instance | CostKind::Grouped) {
            self.blend.semantic_weight = cost.semantic_weight;
        }
        let max = cost.max_silhouette_offset_px as i32;
        let mut offsets: Vec<i32> = (-max..=max).collect();
        offsets.sort_by_key(|b| (b.abs(), *b));
        // One render at `at`, scored under every offset.
        let mut ws = self.workspaces.take();
        self.scene.render_into(&self.view(at.pose(self.pitch_deg, self.roll_deg)), &mut ws.frame)?;
        let ids = std::mem::take(&mut ws.frame.ids);
        let mut best = (f64::NEG_INFINITY, 0);
        self.blend.spill_weight = 1.0;
        for &b in &offsets {
            self.silhouette_offset_px = b;
            let score = self.score(&mut ws, &ids);
            if score > best.0 {
                best = (score, b);
            }
        }
        ws.frame.ids = ids;
        self.silhouette_offset_px = best.1;
        if self.kind != CostKind::Merged {
            self.blend.spill_weight = cost.spill_weight;
            self.blend.rim_tolerance = cost.rim_tolerance;
        }
        Ok((offsets.len() as u64, (self.blend, self.silhouette_offset_px) != before))
    }

    /// Whenever rayon has more than one thread.
    fn scores_pairs_in_parallel(&self) -> bool {
        rayon::current_num_threads() > 1
    }

    fn evaluate(&mut self, hyps: &[Hypothesis]) -> Result<Vec<f64>, Self::Error> {
        // Runs of consecutive hypotheses with the same centre (bit for bit); without the fan every
        // hypothesis is its own run.
        let mut runs: Vec<&[Hypothesis]> = Vec::new();
        let mut start = 0;
        for i in 1..=hyps.len() {
            if i == hyps.len() || !self.yaw_fan || hyps[i].centre_m != hyps[start].centre_m {
                runs.push(&hyps[start..i]);
                start = i;
            }
        }
        let this = &*self;
        if !this.scene.renders_in_parallel() {
            return this.score_batched(&runs);
        }
        let scores = runs
            .par_iter()
            .map_init(|| this.workspaces.take(), |ws, run| this.score_run(run, ws))
            .collect::<Result<Vec<Vec<f64>>, _>>()?;
        Ok(scores.into_iter().flatten().collect())
    }
}

/// Where the optical axis of `pose` meets the horizontal plane at `ground_m` (None when it looks
/// at or above the horizon or the point lies more than 20 km away).
pub fn look_at_ground(pose: &Pose, ground_m: f64) -> Option<DVec3> {
    let d = pose.forward();
    let c = pose.centre_m;
    if d.z >= -1e-6 || !ground_m.is_finite() {
        return None;
    }
    let t = (ground_m - c.z) / d.z;
    (t > 0.0 && t < 20_000.0).then(|| DVec3::new(c.x + t * d.x, c.y + t * d.y, ground_m))
}

fn frame_seed(seed: u64, name: &str) -> u64 {
    // FNV-1a of the frame name mixed with the run seed: stable across runs and platforms.
    crate::util::fnv1a_seeded(seed, name)
}

fn group_of(t: Trajectory) -> &'static str {
    match t {
        Trajectory::Grid => "grid",
        Trajectory::Regular | Trajectory::Irregular => "sequence",
    }
}

/// One query: name (frame), intrinsics, ground truth, prior, and its group in the table.
#[derive(Debug, Clone)]
pub struct QueryPose {
    /// The query's frame name.
    pub name: String,
    /// The query's intrinsics at its full resolution.
    pub intrinsics: Intrinsics,
    /// The ground-truth pose.
    pub gt: Pose,
    /// The prior pose the search starts from.
    pub prior: Pose,
    /// `grid` or `sequence` for sampled queries, `query` for COLMAP lists.
    pub group: String,
}

/// Where the query poses come from.
#[derive(Debug, Clone)]
pub enum QueryPoses {
    /// `poses.jsonl` (ground truth) and `priors.jsonl` of a camera directory, from `insgen sample`.
    Sample {
        /// `<workdir>/<area>/<camera>/`.
        camera_dir: PathBuf,
    },
    /// The LoD-Loc lists: intrinsics (`NAME MODEL W H PARAMS[]`), ground-truth and prior poses
    /// (`NAME QW QX QY QZ TX TY TZ`, world-to-camera in the area's ENU frame).
    Colmap {
        /// The query list: one camera per query, COLMAP `SIMPLE_PINHOLE` or `PINHOLE`.
        intrinsics: PathBuf,
        /// The ground-truth poses.
        gt: PathBuf,
        /// The prior poses the search starts from (same names as the ground truth).
        prior: PathBuf,
    },
}

/// Reads the queries, in the ground-truth file's order.
///
/// # Errors
/// Unreadable or malformed files; a query without a prior; a camera model that is not a pinhole.
pub fn load_queries(src: &QueryPoses) -> Result<Vec<QueryPose>, EvalError> {
    match src {
        QueryPoses::Sample { camera_dir } => {
            let gt_path = camera_dir.join(crate::layout::POSES_FILE);
            let prior_path = camera_dir.join("priors.jsonl");
            let gts = read_jsonl(&gt_path)?;
            let priors: BTreeMap<String, PoseRecord> =
                read_jsonl(&prior_path)?.into_iter().map(|p| (p.name.clone(), p)).collect();
            gts.iter()
                .map(|gt| {
                    let prior = priors.get(&gt.name).ok_or_else(|| EvalError::Input {
                        path: prior_path.clone(),
                        problem: InputProblem::NoPrior { query: gt.name.clone() },
                    })?;
                    Ok(QueryPose {
                        name: gt.name.clone(),
                        intrinsics: gt.view.intrinsics,
                        gt: gt.pose(),
                        prior: prior.pose(),
                        group: group_of(gt.trajectory).to_string(),
                    })
                })
                .collect()
        }
        QueryPoses::Colmap { intrinsics, gt, prior } => {
            let cams = colmap::read_query_list(intrinsics)?;
            let cams: BTreeMap<String, ColmapCamera> = cams.into_iter().collect();
            let priors: BTreeMap<String, Pose> =
                colmap::read_pose_list(prior)?.into_iter().map(|im| (im.name.clone(), im.pose())).collect();
            colmap::read_pose_list(gt)?
                .into_iter()
                .map(|im| {
                    let cam = cams.get(&im.name).ok_or_else(|| EvalError::Input {
                        path: intrinsics.clone(),
                        problem: InputProblem::NoIntrinsics { query: im.name.clone() },
                    })?;
                    let k = cam.intrinsics().ok_or_else(|| EvalError::Input {
                        path: intrinsics.clone(),
                        problem: InputProblem::NotPinhole {
                            query: im.name.clone(),
                            model: cam.model.clone(),
                        },
                    })?;
                    let p = priors.get(&im.name).ok_or_else(|| EvalError::Input {
                        path: prior.clone(),
                        problem: InputProblem::NoPrior { query: im.name.clone() },
                    })?;
                    Ok(QueryPose {
                        name: im.name.clone(),
                        intrinsics: k,
                        gt: im.pose(),
                        prior: *p,
                        group: "query".to_string(),
                    })
                })
                .collect()
        }
    }
}

/// Runs the evaluation: loads the queries, localizes each one with every cost (hypotheses rendered by
/// `renderer`), then writes the results, the estimated poses and the summary tables (see the module
/// doc for the files).
///
/// # Errors
/// Missing or malformed inputs (poses, priors, masks, predictions), naming the file;
/// [`EvalError::Render`] when the renderer fails.
pub fn evaluate(
    scene: &PreparedScene,
    opts: &EvalOptions,
    renderer: &dyn IdRenderer,
    progress: &dyn Progress,
) -> Result<Summary, EvalError> {
    let all = load_selected_queries(opts)?;
    let total = all.len();
    // Positions in the whole list: they decide the shard and the overlays.
    let queries: Vec<(usize, &QueryPose)> =
        all.iter().enumerate().filter(|(p, _)| opts.shard.contains(*p)).collect();
    let mut runs: Vec<Localized> = Vec::new();
    progress.start((queries.len() * opts.costs.len()) as u64, "queries");
    for &(position, q) in &queries {
        util::interrupt::check()?;
        let setup = QuerySetup::new(scene, opts, q, renderer)?;
        for &kind in &opts.costs {
            let run = setup.localize(opts, kind)?;
            if position < opts.overlays && kind == opts.costs[0] {
                super::overlay::write_overlay(
                    &opts.out_dir,
                    &*setup.scene,
                    &setup.k_fine,
                    &setup.query_fine,
                    [&q.prior, &run.estimate, &q.gt],
                    &run.result,
                )?;
            }
            runs.push(run);
            progress.inc(1);
            progress.message(&format!("recall@2m2° {:.1}%", 100.0 * recall_2m_2deg(&runs, opts.costs[0])));
        }
    }
    progress.finish();
    let results: Vec<QueryResult> = runs.iter().map(|r| r.result.clone()).collect();
    let mut summary =
        summarise(&results, &opts.costs, opts.weighting, opts.semantic_weight, &opts.search, &opts.map);
    let record = renderer.record();
    summary.renderer = (record.kind != RendererKind::Cpu).then_some(record);
    let source = match &opts.source {
        QuerySource::Oracle { degradation, .. } => PartSource::Oracle { degradation: degradation.clone() },
        QuerySource::Predictions(p) => PartSource::Predictions {
            sha256: util::sha256_file(&p.path)?,
            min_score: p.min_score,
            zoom: p.zoom,
        },
    };
    summary.source = Some(source.clone());
    let (jsonl, est) = output_texts(&runs);
    if opts.shard.is_whole() {
        write_outputs(
            &opts.out_dir,
            &Outputs { results_jsonl: jsonl, est_poses: est, summary: summary.clone() },
        )?;
    } else {
        let dir = opts.out_dir.join(PARTS_DIR).join(opts.shard.part_dir_name());
        util::write_bytes_atomic(&dir.join(RESULTS_FILE), jsonl.as_bytes())?;
        for (name, text) in &est {
            util::write_bytes_atomic(&dir.join(name), text.as_bytes())?;
        }
        let info = PartInfo {
            kind: PART_KIND.into(),
            version: PART_VERSION,
            shard: opts.shard.to_string(),
            queries: total,
            costs: opts.costs.clone(),
            weighting: opts.weighting,
            semantic_weight: opts.semantic_weight,
            search: opts.search.clone(),
            map: opts.map.clone(),
            seed: opts.seed,
            source,
            render_width_px: opts.render_width_px,
            coarse_width_px: opts.coarse_width_px,
            yaw_fan: opts.yaw_fan,
            limit: opts.limit,
        };
        // The marker last: a part with a marker is complete.
        util::write_json_atomic(&dir.join(PART_MARKER), &info)?;
    }
    Ok(summary)
}

/// `results.jsonl`.
pub const RESULTS_FILE: &str = "results.jsonl";
/// `kind` of an eval-loc part's `part.json`.
pub const PART_KIND: &str = "eval-loc";
/// Version of [`PartInfo`] (2: the seed, the query source, the render widths, the yaw fan and the
/// limit joined the run's identity).
pub const PART_VERSION: u32 = 2;

/// The `part.json` of a shard's part of an evaluation: what the parts of one run share. Everything but
/// `kind`, `version` and `shard` must be equal in the parts of one run (schema:
/// `schemas/part.schema.json`).
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct PartInfo {
    /// Always [`PART_KIND`].
    pub kind: String,
    /// Always [`PART_VERSION`].
    pub version: u32,
    /// `i/N`.
    pub shard: String,
    /// Queries of the whole run (all shards).
    pub queries: usize,
    /// Costs evaluated.
    pub costs: Vec<CostKind>,
    /// How the per-instance scores of the instance cost are weighted.
    pub weighting: Weighting,
    /// Weight of the semantic IoU in the instance cost.
    pub semantic_weight: f64,
    /// The search's stages and parameters.
    pub search: SearchOptions,
    /// The map: its area and perturbation.
    pub map: MapSummary,
    /// `--seed`: drives the oracle's degradations (and the map's perturbation unless `--map-seed`).
    pub seed: u64,
    /// Where the queries' instances came from.
    pub source: PartSource,
    /// `--render-width`, pixels.
    pub render_width_px: u32,
    /// `--coarse-width`, pixels.
    pub coarse_width_px: u32,
    /// The coarse stage reads yaws out of one wide view (`--no-yaw-fan` turns it off).
    pub yaw_fan: bool,
    /// `--limit`: queries taken from the list before sharding.
    pub limit: Option<usize>,
}

/// Where a run's query instances came from, as its parts record it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case", tag = "kind")]
pub enum PartSource {
    /// `--oracle`: the ground-truth masks with these degradations (the masks directory is not recorded:
    /// shards on different machines read it from different places).
    Oracle {
        /// What was done to the true instances.
        degradation: Degradation,
    },
    /// `--predictions`: the results file, by content, and `--min-score`.
    Predictions {
        /// SHA-256 of the COCO results file, lowercase hex.
        sha256: String,
        /// Predictions scored below this were ignored.
        min_score: f64,
        /// `--prediction-zoom`: the masks were scaled by 1/zoom about the principal point (1: as
        /// predicted; parts written before the option read as 1).
        #[serde(default = "super::oracle::no_zoom")]
        zoom: f64,
    },
}

/// The options two parts of an evaluation differ in, as `name: a vs b` (JSON paths into
/// [`PartInfo`], e.g. `seed: 1 vs 2`, `map.perturbation.height_sigma_m: 0.0 vs 2.0`); empty for
/// parts of one run.
pub fn part_differences(a: &PartInfo, b: &PartInfo) -> Vec<String> {
    fn diff(path: &str, a: &serde_json::Value, b: &serde_json::Value, out: &mut Vec<String>) {
        use serde_json::Value;
        match (a, b) {
            (Value::Object(x), Value::Object(y)) => {
                let keys: std::collections::BTreeSet<&String> = x.keys().chain(y.keys()).collect();
                for k in keys {
                    let sub = if path.is_empty() { k.clone() } else { format!("{path}.{k}") };
                    diff(&sub, x.get(k).unwrap_or(&Value::Null), y.get(k).unwrap_or(&Value::Null), out);
                }
            }
            _ if a != b => out.push(format!("{path}: {a} vs {b}")),
            _ => {}
        }
    }
    let identity = |p: &PartInfo| {
        let mut v = serde_json::to_value(p).unwrap_or_default();
        if let Some(m) = v.as_object_mut() {
            for k in ["kind", "version", "shard"] {
                m.remove(k);
            }
        }
        v
    };
    let mut out = Vec::new();
    diff("", &identity(a), &identity(b), &mut out);
    out
}

/// The files of an evaluation, ready to write.
#[derive(Debug, Clone)]
pub struct Outputs {
    /// `results.jsonl`.
    pub results_jsonl: String,
    /// `est_poses_<cost>.txt` by file name.
    pub est_poses: BTreeMap<String, String>,
    /// The summary computed from all results.
    pub summary: Summary,
}

/// Combines the parts of one evaluation (`parts`: each shard's part directory) into the outputs one
/// process writes to `out_dir`: the result and pose lines back in query order, and the summary
/// recomputed from the combined results.
///
/// # Errors
/// [`EvalError::Parts`] when a shard is missing or the parts are of different runs (query count,
/// costs, weighting, search or map differ); [`EvalError::Interleave`] when a part does not hold its
/// share of the queries; I/O and JSON errors naming the file.
pub fn combine_parts(parts: &BTreeMap<Shard, PathBuf>, out_dir: &Path) -> Result<Outputs, EvalError> {
    let parts_dir = out_dir.join(PARTS_DIR);
    let fail = |problem: PartsProblem| EvalError::Parts { dir: parts_dir.clone(), problem };
    let mut infos = Vec::new();
    for (&shard, dir) in parts {
        let path = dir.join(PART_MARKER);
        let info: PartInfo = serde_json::from_slice(&util::read_file(&path)?)
            .map_err(|source| EvalError::PartMarker { path: path.clone(), source })?;
        if info.kind != PART_KIND || info.version != PART_VERSION || info.shard != shard.to_string() {
            return Err(EvalError::Parts {
                dir: dir.clone(),
                problem: PartsProblem::WrongMarker {
                    kind: info.kind,
                    version: info.version,
                    said: info.shard,
                    shard,
                },
            });
        }
        infos.push((shard, info, dir));
    }
    let Some((first_shard, first, _)) = infos.first() else { return Err(fail(PartsProblem::NoParts)) };
    let count = first_shard.count;
    let first_dir = infos[0].2;
    for (shard, info, dir) in &infos {
        if shard.count != count {
            return Err(fail(PartsProblem::MixedCounts {
                dir: dir.to_path_buf(),
                shard: *shard,
                first_dir: first_dir.to_path_buf(),
                first_shard: *first_shard,
            }));
        }
        let differences = part_differences(first, info);
        if !differences.is_empty() {
            return Err(fail(PartsProblem::DifferentRuns {
                dir: dir.to_path_buf(),
                shard: *shard,
                first_dir: first_dir.to_path_buf(),
                first_shard: *first_shard,
                differences,
            }));
        }
    }
    let missing: Vec<Shard> =
        (0..count).map(|index| Shard { index, count }).filter(|s| !parts.contains_key(s)).collect();
    if !missing.is_empty() {
        return Err(fail(PartsProblem::MissingShards { missing, count }));
    }
    let costs = &first.costs;
    let total = first.queries;
    // Per part: its lines grouped per query (one line per cost, or per occurrence of a cost); a
    // part without queries has no pose files.
    let grouped = |file: &str, per_query: usize| -> Result<String, EvalError> {
        let mut per_part: Vec<Vec<String>> = Vec::new();
        for (_, _, dir) in &infos {
            let path = dir.join(file);
            let text = if path.exists() {
                String::from_utf8(util::read_file(&path)?)
                    .map_err(|source| EvalError::NotUtf8 { path: path.clone(), source })?
            } else {
                String::new()
            };
            let lines: Vec<&str> = text.lines().collect();
            if per_query == 0 || !lines.len().is_multiple_of(per_query) {
                return Err(EvalError::Input {
                    path,
                    problem: InputProblem::LinesPerQuery { lines: lines.len(), per_query },
                });
            }
            per_part.push(
                lines.chunks(per_query).map(|c| c.iter().map(|l| format!("{l}\n")).collect()).collect(),
            );
        }
        let all = util::shard::interleave(per_part, total)
            .map_err(|source| EvalError::Interleave { dir: parts_dir.clone(), source })?;
        Ok(all.concat())
    };
    let results_jsonl = grouped(RESULTS_FILE, costs.len())?;
    let mut est_poses = BTreeMap::new();
    for kind in costs {
        let name = est_poses_file(*kind);
        if !est_poses.contains_key(&name) {
            let per_query = costs.iter().filter(|c| *c == kind).count();
            est_poses.insert(name.clone(), grouped(&name, per_query)?);
        }
    }
    let results: Vec<QueryResult> = results_jsonl
        .lines()
        .enumerate()
        .map(|(i, l)| {
            serde_json::from_str(l).map_err(|source| EvalError::ResultLine {
                path: out_dir.join(RESULTS_FILE),
                line: i + 1,
                source,
            })
        })
        .collect::<Result<_, _>>()?;
    let mut summary =
        summarise(&results, costs, first.weighting, first.semantic_weight, &first.search, &first.map);
    summary.source = Some(first.source.clone());
    Ok(Outputs { results_jsonl, est_poses, summary })
}

/// One query localized with one cost: its result line and the estimated pose.
struct Localized {
    result: QueryResult,
    estimate: Pose,
}

/// The queries of `opts`, truncated to its limit; at least one.
fn load_selected_queries(opts: &EvalOptions) -> Result<Vec<QueryPose>, EvalError> {
    let mut queries = load_queries(&opts.queries)?;
    if let Some(n) = opts.limit {
        queries.truncate(n);
    }
    if queries.is_empty() {
        return Err(EvalError::Input {
            path: match &opts.queries {
                QueryPoses::Sample { camera_dir } => camera_dir.join(crate::layout::POSES_FILE),
                QueryPoses::Colmap { gt, .. } => gt.clone(),
            },
            problem: InputProblem::NoQueries,
        });
    }
    Ok(queries)
}

/// What one query's costs share: its masks at both resolutions, the map culled around its prior and
/// prepared by the renderer, and the prior as a hypothesis.
struct QuerySetup<'q, 'r> {
    query: &'q QueryPose,
    k_fine: Intrinsics,
    k_coarse: Intrinsics,
    query_fine: Query,
    query_coarse: Query,
    /// Buildings kept around the prior (their dense IDs are 1..=len).
    buildings: usize,
    scene: Box<dyn IdScene + 'r>,
    seed: u64,
    pitch_deg: f64,
    roll_deg: f64,
    prior: Hypothesis,
    /// Where the prior's optical axis meets the ground (the polish's orbit pivot).
    pivot_m: Option<DVec3>,
    setup_seconds: f64,
}

impl<'q, 'r> QuerySetup<'q, 'r> {
    fn new(
        scene: &PreparedScene,
        opts: &EvalOptions,
        q: &'q QueryPose,
        renderer: &'r dyn IdRenderer,
    ) -> Result<Self, EvalError> {
        let started = Instant::now();
        let k_fine = at_width(&q.intrinsics, opts.render_width_px);
        let k_coarse = at_width(&q.intrinsics, opts.coarse_width_px);
        let seed = frame_seed(opts.seed, &q.name);
        let [query_fine, query_coarse]: [Query; 2] = opts
            .source
            .queries(&q.name, &[k_fine, k_coarse], seed)?
            .try_into()
            .expect("one query per resolution asked for");
        let kept = cull(&scene.buildings, &q.prior, &k_fine, 0.5);
        let prepared = renderer.prepare(&dense_subscene(&scene.mesh, &kept), q.prior.centre_m)?;
        let [prior_yaw, pitch_deg, roll_deg] = q.prior.ypr_deg();
        Ok(QuerySetup {
            query: q,
            k_fine,
            k_coarse,
            query_fine,
            query_coarse,
            buildings: kept.len(),
            scene: prepared,
            seed,
            pitch_deg,
            roll_deg,
            prior: Hypothesis { centre_m: q.prior.centre_m, yaw_deg: prior_yaw },
            pivot_m: look_at_ground(&q.prior, scene.manifest.ground_enu_m),
            setup_seconds: started.elapsed().as_secs_f64(),
        })
    }

    /// Localizes the query with the cost `kind`.
    fn localize(&self, opts: &EvalOptions, kind: CostKind) -> Result<Localized, EvalError> {
        let started = Instant::now();
        let (qf, qc) = if kind == CostKind::Merged {
            (self.query_fine.merged(), self.query_coarse.merged())
        } else {
            (self.query_fine.clone(), self.query_coarse.clone())
        };
        let evaluator = |k: Intrinsics, query, yaw_fan| Evaluator {
            scene: &*self.scene,
            k,
            pitch_deg: self.pitch_deg,
            roll_deg: self.roll_deg,
            query,
            kind,
            weighting: opts.weighting,
            blend: Blend::semantic(opts.semantic_weight),
            k_max: self.buildings as u32,
            silhouette_offset_px: 0,
            yaw_fan,
            workspaces: Workspaces::default(),
        };
        let mut fine_eval = evaluator(self.k_fine, &qf, false);
        let mut coarse_eval = evaluator(self.k_coarse, &qc, opts.yaw_fan);
        let r: SearchResult = if qf.instances.is_empty() {
            // Nothing to align (no instance in the query): the prior stands.
            SearchResult {
                best: self.prior,
                best_score: 0.0,
                coarse_best: self.prior,
                coarse_score: 0.0,
                hypotheses_scored: 0,
                stages: Default::default(),
                on_boundary: false,
                kept_prior: false,
            }
        } else {
            search::search(
                &mut coarse_eval,
                &mut fine_eval,
                self.prior,
                &opts.search,
                self.seed,
                self.pivot_m,
            )?
        };
        let seconds = started.elapsed().as_secs_f64();
        let (q, gt) = (self.query, &self.query.gt);
        let est = r.best.pose(self.pitch_deg, self.roll_deg);
        let coarse_est = r.coarse_best.pose(self.pitch_deg, self.roll_deg);
        let (axial, lateral) = gt.axial_lateral_error_m(&est);
        let result = QueryResult {
            name: q.name.clone(),
            cost: kind,
            group: q.group.clone(),
            estimate: [r.best.centre_m[0], r.best.centre_m[1], r.best.centre_m[2], r.best.yaw_deg],
            prior_translation_error_m: gt.translation_error_m(&q.prior),
            prior_rotation_error_deg: gt.rotation_error_deg(&q.prior),
            translation_error_m: gt.translation_error_m(&est),
            rotation_error_deg: gt.rotation_error_deg(&est),
            axial_error_m: axial,
            lateral_error_m: lateral,
            silhouette_offset_px: fine_eval.silhouette_offset_px,
            best_cost: r.best_score,
            cost_at_gt: fine_eval.cost_of_pose(gt)?,
            coarse_translation_error_m: gt.translation_error_m(&coarse_est),
            coarse_rotation_error_deg: gt.rotation_error_deg(&coarse_est),
            hypotheses: r.hypotheses_scored,
            seconds,
            setup_seconds: self.setup_seconds,
            query_instances: qf.instances.len(),
            covered_frame_cells: qf.covered_frame_cells(),
            query_building_share: building_share(&qf),
            buildings_considered: self.buildings,
            stages: r.stages,
            on_search_boundary: r.on_boundary,
            kept_prior: r.kept_prior,
        };
        Ok(Localized { result, estimate: est })
    }
}

/// Share of the frame covered by the union of `q`'s instances (0 for an empty frame).
fn building_share(q: &Query) -> f64 {
    let mut union = vec![false; (q.width as usize) * (q.height as usize)];
    for p in q.instances.iter().flat_map(|i| i.pixels()) {
        if let Some(px) = union.get_mut(p as usize) {
            *px = true;
        }
    }
    union.iter().filter(|&&b| b).count() as f64 / union.len().max(1) as f64
}

/// Share of the results of cost `kind` within 2 m and 2°.
fn recall_2m_2deg(runs: &[Localized], kind: CostKind) -> f64 {
    let done: Vec<&QueryResult> = runs.iter().map(|r| &r.result).filter(|r| r.cost == kind).collect();
    let ok =
        done.iter().filter(|r| metrics::within_2m_2deg(r.translation_error_m, r.rotation_error_deg)).count();
    ok as f64 / done.len().max(1) as f64
}

/// The tables (the prior first, then each cost; per group and overall) and the timings, from the
/// results alone (in query order, one line per cost of `costs` per query), so that the summary of
/// combined parts is computed exactly as one process computes it.
pub fn summarise(
    results: &[QueryResult],
    costs: &[CostKind],
    weighting: Weighting,
    semantic_weight: f64,
    search: &SearchOptions,
    map: &MapSummary,
) -> Summary {
    // A query's lines share its name, group, prior and setup: its first line stands for it.
    let queries: Vec<&QueryResult> = results.chunks(costs.len().max(1)).map(|c| &c[0]).collect();
    let mut rows = Vec::new();
    let groups: Vec<&str> = {
        let mut g: Vec<&str> = queries.iter().map(|q| q.group.as_str()).collect();
        g.sort();
        g.dedup();
        g
    };
    let (mut instance_buckets, mut coverage_buckets) = (Vec::new(), Vec::new());
    let mut axis_rows = Vec::new();
    let mut boundary_rows = Vec::new();
    let mut push_rows = |method: &str, errs: &[(f64, f64, &str)]| {
        for g in &groups {
            let e: Vec<(f64, f64)> = errs.iter().filter(|e| e.2 == *g).map(|e| (e.0, e.1)).collect();
            rows.push(metrics::row(method, g, &e));
        }
        if groups.len() > 1 {
            let e: Vec<(f64, f64)> = errs.iter().map(|e| (e.0, e.1)).collect();
            rows.push(metrics::row(method, "all", &e));
        }
    };
    let prior_errors: Vec<(f64, f64, &str)> = queries
        .iter()
        .map(|q| (q.prior_translation_error_m, q.prior_rotation_error_deg, q.group.as_str()))
        .collect();
    push_rows("prior", &prior_errors);
    for &kind in costs {
        let errs: Vec<(f64, f64, &str)> = results
            .iter()
            .filter(|r| r.cost == kind)
            .map(|r| (r.translation_error_m, r.rotation_error_deg, r.group.as_str()))
            .collect();
        let name = match kind {
            CostKind::Instance if semantic_weight > 0.0 => {
                format!("instance ({}) + {semantic_weight} semantic", weighting.label())
            }
            CostKind::Instance => format!("instance ({})", weighting.label()),
            CostKind::Semantic => "semantic IoU (LoD-Loc v2)".to_string(),
            CostKind::Merged => "merged instances".to_string(),
            CostKind::Grouped if semantic_weight > 0.0 => {
                format!("grouped ({}) + {semantic_weight} semantic", weighting.label())
            }
            CostKind::Grouped => format!("grouped ({})", weighting.label()),
        };
        push_rows(&name, &errs);
        let counted = |count: fn(&QueryResult) -> usize| -> Vec<(usize, f64, f64)> {
            results
                .iter()
                .filter(|r| r.cost == kind)
                .map(|r| (count(r), r.translation_error_m, r.rotation_error_deg))
                .collect()
        };
        instance_buckets.extend(metrics::bucket_rows(
            &name,
            metrics::INSTANCE_BUCKETS,
            &counted(|r| r.query_instances),
        ));
        coverage_buckets.extend(metrics::bucket_rows(
            &name,
            metrics::COVERAGE_BUCKETS,
            &counted(|r| r.covered_frame_cells as usize),
        ));
        let split: Vec<metrics::QueryOutcome> = results
            .iter()
            .filter(|r| r.cost == kind)
            .map(|r| metrics::QueryOutcome {
                axial_m: r.axial_error_m,
                lateral_m: r.lateral_error_m,
                translation_m: r.translation_error_m,
                rotation_deg: r.rotation_error_deg,
                best_cost: r.best_cost,
                cost_at_gt: r.cost_at_gt,
            })
            .collect();
        axis_rows.push(metrics::axis_row(&name, &split));
        boundary_rows.push(BoundaryRow {
            method: name.clone(),
            queries: split.len(),
            on_search_boundary: results.iter().filter(|r| r.cost == kind && r.on_search_boundary).count(),
            kept_prior: results.iter().filter(|r| r.cost == kind && r.kept_prior).count(),
        });
    }
    let secs: Vec<f64> = results.iter().map(|r| r.seconds).collect();
    // One setup per query, shared by its costs.
    let setup_times: Vec<f64> = queries.iter().map(|q| q.setup_seconds).collect();
    let total_hyp: u64 = results.iter().map(|r| r.hypotheses).sum();
    let total_s: f64 = secs.iter().sum();
    Summary {
        rows,
        queries: queries.len(),
        median_seconds_per_query: metrics::median_or_nan(&secs),
        median_setup_seconds: metrics::median_or_nan(&setup_times),
        hypotheses_per_second: if total_s > 0.0 { total_hyp as f64 / total_s } else { 0.0 },
        instance_buckets,
        coverage_buckets,
        axis_rows,
        boundary_rows,
        search: search.clone(),
        map: map.clone(),
        renderer: None,
        source: None,
    }
}

/// The search volume in words, for `summary.md`.
fn bounds_text(b: &search::SearchBounds) -> String {
    format!(
        "within {:.1} m of the prior horizontally, {:.1} m in height and {:.1}° in yaw; {}",
        b.radius_m, b.height_m, b.yaw_deg, b.origin
    )
}

/// A paragraph naming the methods whose estimates lie systematically ahead of or behind the truth
/// ([`metrics::depth_biased`]) and what to do about it given the masks' source; empty when none do.
fn depth_bias_note(rows: &[metrics::AxisRow], source: Option<&PartSource>) -> String {
    let biased = metrics::depth_biased(rows);
    let Some(first) = biased.first() else { return String::new() };
    let list: Vec<String> = biased
        .iter()
        .map(|r| {
            let side = if r.median_axial_m > 0.0 { r.estimates_ahead } else { r.queries - r.estimates_ahead };
            let dir = if r.median_axial_m > 0.0 { "ahead of" } else { "behind" };
            format!(
                "{}: {side} of {} estimates {dir} the truth, median {:+.2} m",
                r.method, r.queries, r.median_axial_m
            )
        })
        .collect();
    let (size, dir) = if first.median_axial_m > 0.0 { ("larger", "forward") } else { ("smaller", "back") };
    let advice = match source {
        Some(PartSource::Predictions { zoom, .. }) if *zoom == 1.0 => format!(
            "Masks {size} than the map renders the buildings look like a camera moved {dir}, which no cost can \
             tell apart in one frame: measure the model's mask zoom on frames whose poses are known \
             (`baseline.py score` reports `mask_zoom`; any COCO results file) and pass it as \
             `--prediction-zoom`."
        ),
        Some(PartSource::Predictions { zoom, .. }) => format!(
            "It remains after undoing a mask zoom of {zoom} (`--prediction-zoom`): the model's zoom on these \
             frames differs from the one measured, or the map's scale does."
        ),
        _ if first.median_axial_m > 0.0 => "The masks are larger than the map renders the buildings: masks \
            dilated or zoomed above 1, or a map whose buildings are smaller than the ones the masks show."
            .to_string(),
        _ => "The masks are smaller than the map renders the buildings: a map coarser than the buildings \
              (LoD1 blocks at their tops, footprints out to the eaves), or masks eroded or zoomed below 1."
            .to_string(),
    };
    format!("**Depth bias.** {}. {advice}\n\n", list.join("; "))
}

/// What the figures of `summary.md` are worth given where the query masks came from, as a paragraph
/// (empty when unknown): oracle masks make them an upper bound, predictions are named.
fn source_note(source: Option<&PartSource>) -> String {
    match source {
        Some(PartSource::Oracle { degradation }) if degradation.is_perfect() => "**Upper bound.** The query \
            masks are oracle masks: the ground truth itself, with no segmenter and no simulated error. A \
            localizer fed by a real segmentation model does at best as well as these figures.\n\n"
            .to_string(),
        Some(PartSource::Oracle { degradation: d }) => format!(
            "**Upper bound.** The query masks are oracle masks: the ground truth with simulated segmentation \
             errors ({}, {:.0} % of instances dropped, {:.0} % merged, {:.0} % split, {} false positives), \
             no segmenter. A localizer fed by a real segmentation model is expected to do worse than these \
             figures.\n\n",
            match d.morph_px {
                0 => "boundaries as they are".to_string(),
                px if px > 0 => format!("dilated by {px} px"),
                px => format!("eroded by {} px", -px),
            },
            100.0 * d.drop_fraction,
            100.0 * d.merge_fraction,
            100.0 * d.split_fraction,
            d.false_positives
        ),
        Some(PartSource::Predictions { sha256, min_score, zoom }) => format!(
            "The query masks are a segmentation model's predictions (COCO results file with SHA-256 `{sha256}`, \
             scores ≥ {min_score}){}.\n\n",
            if *zoom == 1.0 {
                String::new()
            } else {
                format!(", scaled by 1/{zoom} about the principal point to undo the model's measured zoom")
            }
        ),
        None => String::new(),
    }
}

/// The boundary rows as Markdown.
fn boundary_markdown(rows: &[BoundaryRow]) -> String {
    let mut s =
        String::from("| method | queries | on the boundary | prior reported |\n|---|---:|---:|---:|\n");
    for r in rows {
        s.push_str(&format!(
            "| {} | {} | {} | {} |\n",
            r.method, r.queries, r.on_search_boundary, r.kept_prior
        ));
    }
    s
}

/// The file name of the estimated poses of cost `kind`: `est_poses_<cost>.txt`.
pub fn est_poses_file(kind: CostKind) -> String {
    format!("est_poses_{}.txt", format!("{kind:?}").to_lowercase())
}

/// The text of `results.jsonl` and of each `est_poses_<cost>.txt` (LoD-Loc's `NAME QW QX QY QZ TX TY
/// TZ`, by file name) for `runs`.
fn output_texts(runs: &[Localized]) -> (String, BTreeMap<String, String>) {
    let mut jsonl = String::new();
    let mut est_lines: BTreeMap<String, String> = BTreeMap::new();
    for Localized { result: r, estimate } in runs {
        // A result holds only strings, numbers, booleans, unit enums and structs of them, which
        // serde_json writes without failing (a non-finite number becomes null).
        jsonl.push_str(&serde_json::to_string(r).expect("a QueryResult has no map with non-string keys"));
        jsonl.push('\n');
        let (q, t) = (estimate.colmap_qvec(), estimate.t_cam_from_world());
        est_lines.entry(est_poses_file(r.cost)).or_default().push_str(&format!(
            "{} {} {} {} {} {} {} {}\n",
            r.name, q[0], q[1], q[2], q[3], t[0], t[1], t[2]
        ));
    }
    (jsonl, est_lines)
}

/// Writes `results.jsonl`, `est_poses_<cost>.txt`, `summary.json` and `summary.md` into `out_dir`,
/// each atomically.
///
/// # Errors
/// I/O errors naming the file.
pub fn write_outputs(out_dir: &Path, outputs: &Outputs) -> Result<(), EvalError> {
    util::write_bytes_atomic(&out_dir.join(RESULTS_FILE), outputs.results_jsonl.as_bytes())?;
    for (name, text) in &outputs.est_poses {
        util::write_bytes_atomic(&out_dir.join(name), text.as_bytes())?;
    }
    let summary = &outputs.summary;
    util::write_json_atomic(&out_dir.join("summary.json"), summary)?;
    let md = format!(
        "# Localization on {}\n\n{} queries; median {:.2} s per query (search; the query's setup takes {:.2} s \
         more); {:.0} hypotheses/s.\n\n{}{}\nRecall at (2 m, 2°) by the number of query instances:\n\n{}\n\
         Recall at (2 m, 2°) by how many of the frame's 4 × 4 cells hold buildings (silhouettes crowded into one \
         part of the frame leave the depth along the axis weakly observed):\n\n{}\n\
         Translation errors along the ground truth's viewing direction (axial) and across it (lateral); a \
         failure the search missed scores below the ground truth's pose (a better optimum was left near the \
         truth), the others are the cost's (it prefers or ties a pose away from the truth):\n\n{}\n{}\
         Searches that ended on the boundary of the search volume around the prior ({}; the coarse grid {}). \
         {}\n\n{}",
        out_dir.display(),
        summary.queries,
        summary.median_seconds_per_query,
        summary.median_setup_seconds,
        summary.hypotheses_per_second,
        source_note(summary.source.as_ref()),
        metrics::markdown(&summary.rows),
        metrics::bucket_markdown("query instances", &summary.instance_buckets),
        metrics::bucket_markdown("frame cells with buildings", &summary.coverage_buckets),
        metrics::axis_markdown(&summary.axis_rows),
        depth_bias_note(&summary.axis_rows, summary.source.as_ref()),
        bounds_text(&summary.search.bounds),
        summary.search.coarse.describe(),
        match summary.search.on_boundary {
            search::OnBoundary::Prior => "There the cost still improves towards poses the prior rules out; the \
                                          prior is reported instead of the pose found:",
            search::OnBoundary::Keep => "The pose found there is reported (--keep-boundary-estimates):",
        },
        boundary_markdown(&summary.boundary_rows)
    );
    util::write_bytes_atomic(&out_dir.join("summary.md"), md.as_bytes())?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::render::cpu as raster;

    mod errors {
        use super::*;

        #[test]
        fn problems_name_the_file_and_what_is_wrong_in_it() {
            let e = EvalError::Input {
                path: "cam/intrinsics.txt".into(),
                problem: InputProblem::NotPinhole { query: "q1.jpg".into(), model: "OPENCV".into() },
            };
            assert_eq!(
                e.to_string(),
                "cam/intrinsics.txt: query q1.jpg: camera model OPENCV is not a pinhole (SIMPLE_PINHOLE or \
                 PINHOLE)"
            );
            let missing = vec![Shard { index: 1, count: 3 }, Shard { index: 2, count: 3 }];
            let e = EvalError::Parts {
                dir: "loc/parts".into(),
                problem: PartsProblem::MissingShards { missing, count: 3 },
            };
            assert_eq!(
                e.to_string(),
                "loc/parts: shard(s) 1/3, 2/3 of the evaluation are missing; run `insgen eval-loc … --shard \
                 I/3` for them"
            );
        }

        #[test]
        fn no_parts_and_a_foreign_marker_are_refused() {
            let t = tempfile::tempdir().unwrap();
            let e = combine_parts(&BTreeMap::new(), t.path()).unwrap_err();
            assert!(matches!(e, EvalError::Parts { problem: PartsProblem::NoParts, .. }), "{e:?}");
            let dir = t.path().join(PARTS_DIR).join("0-of-1");
            std::fs::create_dir_all(&dir).unwrap();
            std::fs::write(dir.join(PART_MARKER), "{\"kind\": \"eval-loc\"}").unwrap();
            let parts = BTreeMap::from([(Shard { index: 0, count: 1 }, dir.clone())]);
            let e = combine_parts(&parts, t.path()).unwrap_err();
            let EvalError::PartMarker { path, .. } = &e else { panic!("{e:?}") };
            assert_eq!(path, &dir.join(PART_MARKER));
            assert!(e.to_string().ends_with("part.json: not an eval-loc part marker"), "{e}");
        }
    }

    #[test]
    fn a_depth_bias_is_reported_with_what_to_do_about_it() {
        let row = |method: &str, ahead: usize, median: f64| metrics::AxisRow {
            method: method.to_string(),
            queries: 40,
            median_abs_axial_m: median.abs(),
            median_axial_m: median,
            estimates_ahead: ahead,
            median_lateral_m: 0.3,
            failures: 14,
            failures_along_axis_only: 9,
            failures_search_missed: 2,
        };
        let rows = [row("prior", 20, 0.1), row("instance", 37, 1.28), row("semantic", 21, 0.05)];
        let preds = |zoom: f64| PartSource::Predictions { sha256: "0".repeat(64), min_score: 0.0, zoom };
        let note = depth_bias_note(&rows, Some(&preds(1.0)));
        assert!(note.contains("instance: 37 of 40 estimates ahead of the truth, median +1.28 m"), "{note}");
        assert!(note.contains("`--prediction-zoom`") && !note.contains("semantic"), "{note}");
        assert!(depth_bias_note(&rows, Some(&preds(1.002))).contains("after undoing a mask zoom of 1.002"));
        let behind = [row("semantic", 8, -0.9)];
        let oracle = PartSource::Oracle { degradation: Degradation::default() };
        let note = depth_bias_note(&behind, Some(&oracle));
        assert!(
            note.contains("32 of 40 estimates behind the truth") && note.contains("smaller than"),
            "{note}"
        );
        assert_eq!(depth_bias_note(&rows[2..], Some(&preds(1.0))), "", "no bias, no paragraph");
    }

    #[test]
    fn dense_ids_are_contiguous() {
        let mut m = SceneMesh::default();
        for (i, id) in [5u32, 9, 12].iter().enumerate() {
            let o = i as f32 * 10.0;
            m.positions_m.extend([[o, 0.0, 0.0], [o + 1.0, 0.0, 0.0], [o, 1.0, 0.0]]);
            m.building_ids.extend([BuildingId::new(*id).unwrap(); 3]);
            m.indices.extend([3 * i as u32, 3 * i as u32 + 1, 3 * i as u32 + 2]);
        }
        let ids = |v: &[u32]| v.iter().map(|&i| BuildingId::new(i).unwrap()).collect::<Vec<_>>();
        let sub = dense_subscene(&m, &ids(&[5, 12]));
        assert_eq!(sub.triangle_count(), 2);
        assert_eq!(sub.building_ids, ids(&[1, 1, 1, 2, 2, 2]));
    }

    /// A 3 × 3 block of closed boxes (IDs 1..=9, 10 m wide, 4 m apart, 10–18 m tall).
    fn block_scene() -> SceneMesh {
        let mut m = SceneMesh::default();
        for id in 1..=9u32 {
            let (i, j) = ((id - 1) % 3, (id - 1) / 3);
            let lo = [14.0 * i as f32, 14.0 * j as f32, 0.0];
            let hi = [lo[0] + 10.0, lo[1] + 10.0, 10.0 + id as f32];
            crate::render::cpu::tests::closed_box(&mut m, lo, hi, id, false, true);
        }
        m
    }

    const BLOCK_PITCH_DEG: f64 = 20.0;

    /// The view of [`block_scene`] the evaluator tests share: 320 × 240 px, 40° across, pitched 20°
    /// down from 150 m, every box in sight; its render.
    fn block_view(scene: &CpuScene) -> (Intrinsics, Hypothesis, Frame) {
        let k = Intrinsics::from_hfov(320, 240, 40.0);
        let at = Hypothesis { centre_m: DVec3::new(17.0, -30.0, 150.0), yaw_deg: 0.0 };
        let mut frame = Frame::default();
        raster::render_ids(scene, &at.pose(BLOCK_PITCH_DEG, 0.0), &k, &mut frame);
        (k, at, frame)
    }

    /// An instance-cost evaluator (area weights, half semantic) of `query` in [`block_view`]'s frame.
    fn block_evaluator<'a>(
        scene: &'a CpuScene,
        k: Intrinsics,
        query: &'a Query,
        silhouette_offset_px: i32,
        yaw_fan: bool,
    ) -> CpuEvaluator<'a> {
        CpuEvaluator {
            scene,
            k,
            pitch_deg: BLOCK_PITCH_DEG,
            roll_deg: 0.0,
            query,
            kind: CostKind::Instance,
            weighting: Weighting::Area,
            blend: Blend::semantic(0.5),
            k_max: 9,
            silhouette_offset_px,
            yaw_fan,
            workspaces: Workspaces::default(),
        }
    }

    #[test]
    fn pooled_workspaces_score_as_fresh_ones() {
        let scene = CpuScene::new(&block_scene(), [0.0; 3]);
        let (k, at, frame) = block_view(&scene);
        let query = Query::from_labels(320, 240, &frame.ids, &[1.0; 9]);
        let evaluator = |silhouette_offset_px| block_evaluator(&scene, k, &query, silhouette_offset_px, true);
        // A yaw fan's run, distinct centres, and one far off to the side (fewer buildings in view).
        let mut hyps: Vec<Hypothesis> =
            (-2..=2).map(|i| Hypothesis { yaw_deg: i as f64 * 1.5, ..at }).collect();
        hyps.extend((1..=8).map(|i| Hypothesis {
            centre_m: at.centre_m + DVec3::new(i as f64 * 3.0, -(i as f64), 2.0 * i as f64),
            yaw_deg: -(i as f64),
        }));
        for offset_px in [0, -1] {
            let mut pooled = evaluator(offset_px);
            let first = pooled.evaluate(&hyps).unwrap();
            assert!(!pooled.workspaces.free.lock().unwrap().is_empty(), "the sets went back to the pool");
            // The distinct centres in reverse, one by one, then the batch again: each scored in
            // buffers another hypothesis left.
            let mut reversed = pooled.evaluate(&hyps[5..].iter().rev().copied().collect::<Vec<_>>()).unwrap();
            reversed.reverse();
            let singles: Vec<f64> = hyps.iter().map(|h| pooled.evaluate(&[*h]).unwrap()[0]).collect();
            let again = pooled.evaluate(&hyps).unwrap();
            let fresh: Vec<f64> =
                hyps.iter().map(|h| evaluator(offset_px).evaluate(&[*h]).unwrap()[0]).collect();
            assert_eq!(singles, fresh, "offset {offset_px}");
            assert_eq!(first, again, "offset {offset_px}");
            // The fan's warped scores differ from single renders; the pool changes neither.
            assert_eq!(first[5..], fresh[5..], "offset {offset_px}");
            assert_eq!(reversed, fresh[5..], "offset {offset_px}");
            if offset_px == 0 {
                assert!(fresh[2] > 0.99, "the query's own pose scores {}", fresh[2]);
            }
        }
    }

    #[test]
    fn the_polish_fits_the_silhouette_offset_of_thinned_masks() {
        let scene = CpuScene::new(&block_scene(), [0.0; 3]);
        let (k, at, frame) = block_view(&scene);
        let seen: std::collections::BTreeSet<u32> = frame.ids.iter().copied().filter(|&i| i != 0).collect();
        assert_eq!(seen.len(), 9, "every box in view");
        let fit = |offset_px: i32, cost: PolishCost| {
            let labels = crate::loc::morph::morph(&frame.ids, 320, 240, offset_px);
            let query = Query::from_labels(320, 240, &labels, &[1.0; 9]);
            let mut ev = block_evaluator(&scene, k, &query, 0, false);
            let (scored, changed) = ev.enter_polish(&at, &cost).unwrap();
            (ev.silhouette_offset_px, scored, changed, ev.blend)
        };
        let polish =
            Blend { semantic_weight: 1.0, spill_weight: search::DEFAULT_SPILL_WEIGHT, rim_tolerance: true };
        // Masks 2 px thinner or 1 px fatter than the silhouettes: the offset found is theirs (fitted
        // with the IoU: with the default spill weight, dilating the render would look cheaper).
        assert_eq!(fit(-2, PolishCost::default()), (-2, 5, true, polish));
        assert_eq!(fit(1, PolishCost::default()), (1, 5, true, polish));
        // Exact masks, and the filter's terms: nothing changes, so no second pass.
        let same = PolishCost {
            spill_weight: 1.0,
            semantic_weight: 0.5,
            rim_tolerance: false,
            ..PolishCost::default()
        };
        assert_eq!(fit(0, same), (0, 5, false, Blend::semantic(0.5)));
        // No offsets allowed: only the terms change.
        let none = PolishCost { max_silhouette_offset_px: 0, ..PolishCost::default() };
        assert_eq!(fit(-2, none), (0, 1, true, polish));
    }
}
