//! The `sample` stage: camera poses for one area and one camera, their priors, and the files that
//! describe them.
//!
//! Input: a [`PreparedScene`] (area polygon, ground level, building boxes, mesh), a [`CameraSpec`]
//! (whose `strategy` selects the sampler) and a [`SamplingConfig`]. Output ([`SampleOutput`]): pose
//! records in the order they were flown, their noisy priors, and counters; [`write_sample`] writes
//! `poses.jsonl`, `priors.jsonl`, `colmap/{cameras,images,points3D}.txt`, `camera.json`, `sampling.json`
//! and `flight_plan.png` into `<workdir>/<area>/<camera>/`.
//!
//! Every accepted pose
//! - lies inside the area polygon (`manifest.area_polygon_enu_m`);
//! - is between the strategy's height bounds, measured above the area's ground level
//!   (`manifest.ground_enu_m`, which the scene stage estimates from the lowest building vertices);
//! - is at least `clearance_m` above the top of every building box within `clearance_radius_m`
//!   (horizontally) of it;
//! - sees the city: at least `min_building_fraction` of a coarse grid of viewing rays hits a building
//!   (its triangles), and at least `min_visible_buildings` distinct buildings are the first hit of some ray
//!   ([`BuildingIndex::view_census`]). Each pose records its count (`visible_buildings` in
//!   `poses.jsonl`) and its share of building rays (`building_fraction`);
//! - sees ground between its buildings: at most `max_building_fraction` of the grid hits a building.
//!   A frame filled by a few large roofs shows almost no outline to localize from;
//! - looks at the map: at most `max_off_map_share` of that grid hits no building and lands beyond the
//!   modelled ground (outside the convex hull of the building footprints, or the sky); each pose records
//!   its share (`off_map_share`). With
//!   `min_covered_cells` > 0, the rays hitting buildings must also spread over that many cells of the
//!   frame's 4 × 4 grid; each pose records its count (`covered_frame_cells`).
//!
//! Randomness: one ChaCha8 generator seeded with the run's seed (stream 0) drives the sampler; each
//! frame's prior draws from a generator keyed by the seed and the frame's name
//! ([`super::prior::prior_rng`]), so areas sampled with one seed get independent prior errors. Same
//! inputs and seed → identical outputs.

use std::path::{Path, PathBuf};

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use serde::Serialize;

use super::area::AreaPolygon;
use super::colmap::{ColmapCamera, ColmapImage};
use super::config::SamplingConfig;
use super::visibility::{BuildingIndex, ViewCensus};
use super::{AreaProblem, CameraError, CameraSpec, Pose, PoseRecord, Trajectory};
use crate::geo::{EnuFrame, Geodetic};
use crate::scene::PreparedScene;
use crate::util::Progress;

/// File names written by [`write_sample`] inside the camera directory (see [`crate::layout`]).
pub use crate::layout::{CAMERA_FILE, COLMAP_DIR, FLIGHT_PLAN_FILE, POSES_FILE, PRIORS_FILE, SAMPLING_FILE};

/// Counters of one sampling run.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct SampleStats {
    /// Candidate poses generated (accepted or not).
    pub candidates: u64,
    /// Poses kept.
    pub accepted: u64,
    /// Candidates outside the area polygon.
    pub rejected_outside: u64,
    /// Candidates too close to (or below the clearance over) the buildings near them.
    pub rejected_clearance: u64,
    /// Candidates whose view holds too few building rays.
    pub rejected_visibility: u64,
    /// Candidates whose view holds enough building rays but fewer distinct buildings than
    /// `min_visible_buildings`.
    #[serde(default)]
    pub rejected_few_buildings: u64,
    /// Candidates whose view is filled by buildings: more building rays than `max_building_fraction`
    /// (no ground between them to outline them).
    #[serde(default)]
    pub rejected_filled: u64,
    /// Candidates that pass the other checks but whose buildings cover fewer of the frame's cells
    /// than `min_covered_cells`.
    #[serde(default)]
    pub rejected_crowded: u64,
    /// Candidates that pass the building checks but whose view lands beyond the map for more than
    /// `max_off_map_share` of its rays.
    #[serde(default)]
    pub rejected_off_map: u64,
    /// Accepted frames dropped because their run of consecutive frames was too short.
    pub dropped_short_run_frames: u64,
    /// Sequences (grid: one per frame).
    pub sequences: u32,
    /// Mean share of building rays over the kept poses.
    pub mean_building_fraction: f64,
    /// Median errors of the priors against the poses.
    pub prior_median_translation_m: f64,
    /// Median rotation error of the priors against the poses, degrees.
    pub prior_median_rotation_deg: f64,
}

/// Result of [`sample_area`].
#[derive(Debug, Clone)]
pub struct SampleOutput {
    /// The area (scene) name.
    pub area: String,
    /// The camera the poses are for.
    pub camera: CameraSpec,
    /// The strategy that placed them.
    pub strategy: Trajectory,
    /// Seed of the random draws.
    pub seed: u64,
    /// The `--count` asked for (`None`: the strategy's natural coverage).
    pub count: Option<usize>,
    /// The `[sampling]` configuration used.
    pub config: SamplingConfig,
    /// Ground-truth poses, in flight order.
    pub poses: Vec<PoseRecord>,
    /// Noisy priors, paired with `poses` by position and name.
    pub priors: Vec<PoseRecord>,
    /// Counters of the run.
    pub stats: SampleStats,
}

/// One accepted frame before it becomes a [`PoseRecord`].
#[derive(Debug, Clone, Copy)]
pub(crate) struct Frame {
    pub pose: Pose,
    pub sequence: u32,
    pub index: u32,
}

/// What a strategy's sampler hands back: the accepted frames in flight order, each one's share of
/// building rays (paired by position), and the run's counters.
pub(crate) struct Sampled {
    pub frames: Vec<Frame>,
    pub fractions: Vec<ViewCensus>,
    pub stats: SampleStats,
}

/// Why a candidate was rejected.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Reject {
    Outside,
    Clearance,
    Visibility,
    FewBuildings,
    Filled,
    OffMap,
    Crowded,
}

/// What every sampler shares: the area, the buildings, the camera, the settings and the number of
/// poses asked for.
pub(crate) struct Ctx<'a> {
    pub area: &'a str,
    pub poly: AreaPolygon,
    pub index: BuildingIndex,
    pub ground_m: f64,
    pub camera: &'a CameraSpec,
    pub cfg: &'a SamplingConfig,
    /// `--count`: poses wanted; `None` takes the strategy's natural coverage.
    pub count: Option<usize>,
    pub progress: &'a dyn Progress,
}

impl Ctx<'_> {
    /// Lowest allowed camera height above ground at `p` (−∞ when no building is near).
    pub fn required_height_agl_m(&self, p: [f64; 2]) -> f64 {
        match self.index.tallest_top_near_m(p, self.cfg.clearance_radius_m) {
            Some(top) => top + self.cfg.clearance_m - self.ground_m,
            None => f64::NEG_INFINITY,
        }
    }

    /// Checks a candidate and counts it; returns what its view holds when it is accepted.
    pub fn check(&self, pose: &Pose, stats: &mut SampleStats) -> Result<ViewCensus, Reject> {
        stats.candidates += 1;
        let c = pose.centre_m;
        let verdict = if !self.poly.contains([c[0], c[1]]) {
            Err(Reject::Outside)
        } else if c[2] - self.ground_m < self.required_height_agl_m([c[0], c[1]]) {
            Err(Reject::Clearance)
        } else {
            let v = self.index.view_census(
                &self.camera.intrinsics,
                pose,
                self.cfg.visibility_rays,
                self.ground_m,
            );
            if v.building_fraction < self.cfg.min_building_fraction {
                Err(Reject::Visibility)
            } else if v.visible_buildings < self.cfg.min_visible_buildings {
                Err(Reject::FewBuildings)
            } else if v.building_fraction > self.cfg.max_building_fraction {
                Err(Reject::Filled)
            } else if v.off_map_share > self.cfg.max_off_map_share {
                Err(Reject::OffMap)
            } else if v.covered_cells < self.cfg.min_covered_cells {
                Err(Reject::Crowded)
            } else {
                Ok(v)
            }
        };
        match verdict {
            Err(Reject::Outside) => stats.rejected_outside += 1,
            Err(Reject::Clearance) => stats.rejected_clearance += 1,
            Err(Reject::Visibility) => stats.rejected_visibility += 1,
            Err(Reject::FewBuildings) => stats.rejected_few_buildings += 1,
            Err(Reject::Filled) => stats.rejected_filled += 1,
            Err(Reject::OffMap) => stats.rejected_off_map += 1,
            Err(Reject::Crowded) => stats.rejected_crowded += 1,
            Ok(_) => {}
        }
        verdict
    }

    /// Candidate budget for `wanted` poses.
    pub fn budget(&self, wanted: usize) -> u64 {
        wanted as u64 * self.cfg.max_attempts_per_pose as u64
    }

    /// The error for a strategy that could not place `wanted` poses.
    pub fn too_few(
        &self,
        strategy: Trajectory,
        placed: usize,
        wanted: usize,
        stats: &SampleStats,
    ) -> CameraError {
        let others = stats.rejected_clearance.max(stats.rejected_visibility).max(stats.rejected_outside);
        let hint = if stats.rejected_off_map
            > others.max(stats.rejected_few_buildings).max(stats.rejected_crowded)
        {
            format!(
                "raise max_off_map_share (now {}) in the scene file's [sampling] table, or lower the \
                 {strategy} height range or pitch: the views look past the modelled buildings",
                self.cfg.max_off_map_share
            )
        } else if stats.rejected_filled > others.max(stats.rejected_few_buildings).max(stats.rejected_crowded)
        {
            format!(
                "raise max_building_fraction (now {}) in the scene file's [sampling] table, or the {strategy} \
                 height range: large buildings fill the views",
                self.cfg.max_building_fraction
            )
        } else if stats.rejected_crowded > others.max(stats.rejected_few_buildings) {
            format!(
                "lower min_covered_cells (now {} of 16) in the scene file's [sampling] table: the views' \
                 buildings spread over fewer cells of the frame",
                self.cfg.min_covered_cells
            )
        } else if stats.rejected_few_buildings > others {
            format!(
                "lower min_visible_buildings (now {}) in the scene file's [sampling] table, or raise the \
                 {strategy} height range so that views hold more buildings",
                self.cfg.min_visible_buildings
            )
        } else if stats.rejected_clearance >= stats.rejected_visibility.max(stats.rejected_outside) {
            format!(
                "raise the {strategy} height range or lower clearance_m in the scene file's [sampling] table \
                 (the tallest building box reaches {:.0} m above ground)",
                self.index.max_top_m().map_or(0.0, |t| t - self.ground_m)
            )
        } else if stats.rejected_visibility >= stats.rejected_outside {
            "lower min_building_fraction in [sampling], or check that the area holds buildings".to_string()
        } else {
            "lower --count or the spacing settings in [sampling]".to_string()
        };
        CameraError::TooFewPoses {
            area: self.area.to_string(),
            strategy: strategy.to_string(),
            placed,
            wanted,
            candidates: stats.candidates,
            outside: stats.rejected_outside,
            clearance: stats.rejected_clearance,
            visibility: stats.rejected_visibility,
            hint,
        }
    }
}

/// Collects sequences from runs of consecutive accepted frames: a flight line or trajectory is offered
/// frame by frame (`Some` = accepted, `None` = rejected); maximal runs of at least `min_len` frames
/// become sequences, until `wanted` frames are collected (the last run may be cut short).
pub(crate) struct RunCollector<'p> {
    pub frames: Vec<Frame>,
    pub fractions: Vec<ViewCensus>,
    run: Vec<(Pose, ViewCensus)>,
    min_len: usize,
    wanted: Option<usize>,
    next_sequence: u32,
    progress: &'p dyn Progress,
}

impl<'p> RunCollector<'p> {
    pub fn new(min_len: u32, wanted: Option<usize>, progress: &'p dyn Progress) -> Self {
        RunCollector {
            frames: Vec::new(),
            fractions: Vec::new(),
            run: Vec::new(),
            min_len: min_len.max(1) as usize,
            wanted,
            next_sequence: 0,
            progress,
        }
    }

    /// Whether `wanted` frames have been collected.
    pub fn full(&self) -> bool {
        self.wanted.is_some_and(|w| self.frames.len() >= w)
    }

    /// Offers the next frame of the current line (`None`: the candidate was rejected).
    pub fn offer(&mut self, frame: Option<(Pose, ViewCensus)>, stats: &mut SampleStats) {
        match frame {
            Some(f) => {
                self.run.push(f);
                // A run that alone completes the request is flushed at once.
                if let Some(w) = self.wanted {
                    if self.run.len() >= self.min_len && self.frames.len() + self.run.len() >= w {
                        self.end_run(stats);
                    }
                }
            }
            None => self.end_run(stats),
        }
    }

    /// Ends the current run (end of a line or trajectory, or a rejected frame).
    pub fn end_run(&mut self, stats: &mut SampleStats) {
        let run = std::mem::take(&mut self.run);
        if run.is_empty() || self.full() {
            return;
        }
        if run.len() < self.min_len {
            stats.dropped_short_run_frames += run.len() as u64;
            return;
        }
        let room = self.wanted.map_or(usize::MAX, |w| w - self.frames.len());
        let take = run.len().min(room);
        for (i, (pose, f)) in run.into_iter().take(take).enumerate() {
            self.frames.push(Frame { pose, sequence: self.next_sequence, index: i as u32 });
            self.fractions.push(f);
        }
        self.progress.inc(take as u64);
        self.next_sequence += 1;
    }
}

/// Samples camera poses for one area with `camera.strategy`, and their priors.
///
/// `count`: number of poses; `None` takes the strategy's natural coverage (grid: every lattice node
/// once per view angle; regular: one pass of survey lines per view angle; irregular:
/// `irregular.default_frames`).
///
/// # Errors
/// [`CameraError::Config`] for invalid settings (e.g. an impossible height range),
/// [`CameraError::ZeroCount`] for `count = Some(0)`,
/// [`CameraError::Area`] for an empty or degenerate area polygon or one no lattice node fits in,
/// [`CameraError::TooFewPoses`] when the candidate budget (`count × max_attempts_per_pose`) runs out.
pub fn sample_area(
    scene: &PreparedScene,
    camera: &CameraSpec,
    cfg: &SamplingConfig,
    count: Option<usize>,
    seed: u64,
    progress: &dyn Progress,
) -> Result<SampleOutput, CameraError> {
    cfg.validate()?;
    let m = &scene.manifest;
    let area = m.area.as_str();
    if count == Some(0) {
        return Err(CameraError::ZeroCount);
    }
    let poly = AreaPolygon::new(area, &m.area_polygon_enu_m)?;
    if !m.ground_enu_m.is_finite() {
        return Err(CameraError::Area {
            area: area.into(),
            problem: AreaProblem::GroundNotFinite { ground_enu_m: m.ground_enu_m },
        });
    }
    let ctx = Ctx {
        area,
        poly,
        index: BuildingIndex::with_mesh(&scene.buildings, &scene.mesh),
        ground_m: m.ground_enu_m,
        camera,
        cfg,
        count,
        progress,
    };
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let strategy = camera.strategy;
    let sampler = match strategy {
        Trajectory::Grid => super::grid::sample,
        Trajectory::Regular => super::regular::sample,
        Trajectory::Irregular => super::irregular::sample,
    };
    let Sampled { frames, fractions, mut stats } = sampler(&ctx, &mut rng)?;
    progress.finish();

    let enu =
        EnuFrame::new(Geodetic { lat_deg: m.origin.lat_deg, lon_deg: m.origin.lon_deg, h_m: m.origin.h_m });
    let poses: Vec<PoseRecord> = frames
        .iter()
        .zip(&fractions)
        .map(|(f, v)| {
            let mut record = PoseRecord::new(
                frame_name(area, &camera.name, f.sequence, f.index),
                area,
                &camera.name,
                strategy,
                f.sequence,
                f.index,
                camera.intrinsics,
                &f.pose,
                &enu,
                m.ground_enu_m,
            );
            record.visible_buildings = Some(v.visible_buildings);
            record.covered_frame_cells = Some(v.covered_cells);
            record.off_map_share = Some(v.off_map_share);
            record.building_fraction = Some(v.building_fraction);
            record
        })
        .collect();
    let priors = super::prior::make_priors(&poses, &cfg.prior, seed, &enu, m.ground_enu_m);
    stats.accepted = poses.len() as u64;
    stats.sequences = frames.last().map_or(0, |f| f.sequence + 1);
    stats.mean_building_fraction = if fractions.is_empty() {
        0.0
    } else {
        fractions.iter().map(|v| v.building_fraction).sum::<f64>() / fractions.len() as f64
    };
    if let Some((t, r)) = super::prior::median_errors(&poses, &priors) {
        stats.prior_median_translation_m = t;
        stats.prior_median_rotation_deg = r;
    }
    Ok(SampleOutput {
        area: area.to_string(),
        camera: camera.clone(),
        strategy,
        seed,
        count,
        config: cfg.clone(),
        poses,
        priors,
        stats,
    })
}

/// The frame name `<area>_<camera>_<sequence:05>_<index:04>`, the stem of every per-frame file.
pub fn frame_name(area: &str, camera: &str, sequence: u32, index: u32) -> String {
    format!("{area}_{camera}_{sequence:05}_{index:04}")
}

/// What `sampling.json` records about a run (for provenance and reruns).
#[derive(Serialize)]
struct SamplingRecord<'a> {
    insgen_version: &'a str,
    area: &'a str,
    camera: &'a str,
    strategy: Trajectory,
    seed: u64,
    count: Option<usize>,
    config: &'a SamplingConfig,
    stats: &'a SampleStats,
}

/// Writes the outputs of a sampling run into `dir` (`<workdir>/<area>/<camera>/`) and returns the
/// paths written: `poses.jsonl`, `priors.jsonl`, `colmap/cameras.txt` (one `PINHOLE` camera, id 1),
/// `colmap/images.txt` (image ids from 1 in flight order, names `<frame>.png`), `colmap/points3D.txt`
/// (no points), `camera.json`,
/// `sampling.json` and `flight_plan.png`. Every file is written atomically.
///
/// # Errors
/// [`CameraError::File`] naming the file that could not be written; [`CameraError::Png`].
pub fn write_sample(
    dir: &Path,
    scene: &PreparedScene,
    out: &SampleOutput,
) -> Result<Vec<PathBuf>, CameraError> {
    let mut written = Vec::new();
    let p = dir.join(POSES_FILE);
    super::record::write_jsonl(&p, &out.poses)?;
    written.push(p);
    let p = dir.join(PRIORS_FILE);
    super::record::write_jsonl(&p, &out.priors)?;
    written.push(p);
    let colmap = dir.join(COLMAP_DIR);
    let p = colmap.join("cameras.txt");
    super::colmap::write_cameras_txt(&p, &[ColmapCamera::pinhole(1, &out.camera.intrinsics)])?;
    written.push(p);
    let images: Vec<ColmapImage> = out
        .poses
        .iter()
        .enumerate()
        .map(|(i, r)| ColmapImage::from_pose(i as u32 + 1, 1, &format!("{}.png", r.name), &r.pose()))
        .collect();
    let p = colmap.join("images.txt");
    super::colmap::write_images_txt(&p, &images)?;
    written.push(p);
    let p = colmap.join("points3D.txt");
    super::colmap::write_points3d_txt_empty(&p)?;
    written.push(p);
    let p = dir.join(CAMERA_FILE);
    crate::util::write_json_atomic(&p, &out.camera)?;
    written.push(p);
    let p = dir.join(SAMPLING_FILE);
    let rec = SamplingRecord {
        insgen_version: env!("CARGO_PKG_VERSION"),
        area: &out.area,
        camera: &out.camera.name,
        strategy: out.strategy,
        seed: out.seed,
        count: out.count,
        config: &out.config,
        stats: &out.stats,
    };
    crate::util::write_json_atomic(&p, &rec)?;
    written.push(p);
    let p = dir.join(FLIGHT_PLAN_FILE);
    super::flight_plan::write_flight_plan(&p, scene, &out.poses)?;
    written.push(p);
    Ok(written)
}
