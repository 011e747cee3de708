//! The 4-DoF pose search: a coarse grid around the prior, then the particle-filter refinement of the
//! LoD-Loc v2/v3 framework (parameters as in ../shared/SPEC.md). Pitch and roll come from the prior
//! (the IMU gives gravity); x, y, z and yaw are searched.
//! Every stage keeps to a volume around the prior derived from its uncertainty ([`SearchBounds`]), so
//! that a degenerate cost cannot pull the estimate where the prior says the camera cannot be.
//!
//! The search is generic over an [`Evaluate`] implementation that scores a batch of poses (higher is
//! better), so the renderer, the cost and the search are tested separately. It is deterministic for a
//! given seed.

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};
use serde::{Deserialize, Serialize};

use std::time::Instant;

use crate::camera::config::PriorNoise;
use crate::camera::Pose;
use glam::DVec3;

/// A 4-DoF hypothesis: camera centre (ENU metres) and yaw (degrees); pitch/roll are fixed per query.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Hypothesis {
    /// Camera centre, ENU metres.
    pub centre_m: DVec3,
    /// Yaw, degrees.
    pub yaw_deg: f64,
}

impl Hypothesis {
    /// The camera pose with the query's pitch and roll (degrees).
    pub fn pose(&self, pitch_deg: f64, roll_deg: f64) -> Pose {
        Pose::from_ypr_deg(self.yaw_deg, pitch_deg, roll_deg, self.centre_m)
    }
}

/// The volume every stage of the search keeps to, centred on the prior: the camera centre within
/// `radius_m` of the prior's horizontally and `height_m` of its height, the yaw within `yaw_deg` of
/// the prior's. Pitch and roll are not searched (they stay the prior's, the IMU's gravity), so the
/// volume needs no range for them.
///
/// A cost can have a degenerate optimum far from any pose the prior allows (issue 40: the merged
/// instances on learned masks of an unseen city pulled the particle filter and the polish 113–517 m
/// from the truth, with the coarse stage 17–28 m from it); no stage may follow it there. The coarse
/// grid leaves out its cells outside the volume, the particle filter's draws and the polish's points
/// are projected onto it (the nearest pose inside: a draw inside is left bit for bit as it was, so a
/// search that never reaches the boundary runs exactly as an unbounded one), and the basins start
/// from coarse cells. [`SearchResult::on_boundary`] says when the best pose ends on the boundary;
/// the search then reports the prior ([`OnBoundary`]).
///
/// # Units
/// Metres and degrees, each a half-range about the prior.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SearchBounds {
    /// Largest horizontal distance of the camera centre from the prior's, metres.
    pub radius_m: f64,
    /// Largest difference from the prior's height, metres.
    pub height_m: f64,
    /// Largest difference from the prior's yaw, degrees (at most 180).
    pub yaw_deg: f64,
    /// How the bounds were set (the prior noise model they were derived from, or the flags).
    #[serde(default)]
    pub origin: String,
}

/// The default half-ranges of [`SearchBounds`] along one axis (height, yaw) in standard deviations
/// of the prior's noise: the prior's error exceeds 4σ there with a probability of 6.3·10⁻⁵
/// (two-sided, erfc(4/√2)).
pub const PRIOR_SIGMA_MULTIPLE: f64 = 4.0;

/// The default horizontal radius of [`SearchBounds`] in standard deviations of the prior's noise
/// along its noisier horizontal axis, chosen so that the horizontal error leaves it as rarely as the
/// height error leaves 4σ: an isotropic error exceeds r with a probability of exp(−r²/2σ²)
/// (Rayleigh), so r = σ·√(−2·ln 6.3·10⁻⁵) = 4.40σ; with σ_e ≠ σ_n the larger one bounds it.
/// (Issue 40: the radius was 4·√(σ_e² + σ_n²), 5.66σ for an isotropic prior, which the prior's
/// error leaves with a probability of 10⁻⁷; that extra 9 m around a default prior was room for a
/// degenerate cost to end more than 50 m from the truth, and never held a true pose.)
pub const HORIZONTAL_SIGMA_MULTIPLE: f64 = 4.40;

/// Floors of the derived [`SearchBounds`] (metres, metres, degrees), so that a nearly exact prior
/// (σ → 0) still leaves the coarse grid's centre cells and the filter's steps some room.
pub const MIN_SEARCH_BOUNDS: (f64, f64, f64) = (10.0, 5.0, 2.0);

/// An estimate this close to the boundary, as a share of the half-range, counts as on it
/// ([`SearchBounds::on_boundary`]).
pub const BOUNDARY_TOLERANCE: f64 = 0.02;

impl Default for SearchBounds {
    /// Derived from the default prior noise model ([`PriorNoise::default`]: σ = 7, 7, 5 m, 3°):
    /// 30.8 m, 20 m, 12°.
    fn default() -> Self {
        SearchBounds::from_prior_noise(&PriorNoise::default(), "the default prior noise model")
    }
}

impl SearchBounds {
    /// The bounds the prior's error leaves with a probability of 6.3·10⁻⁵ each
    /// ([`HORIZONTAL_SIGMA_MULTIPLE`], [`PRIOR_SIGMA_MULTIPLE`]), plus the model's bias (the prior
    /// is off by it on average), at least [`MIN_SEARCH_BOUNDS`]: radius = |bias_en| + 4.4·max(σ_e,
    /// σ_n), height = |bias_u| + 4·σ_u, yaw = |bias_yaw| + 4·σ_yaw.
    /// `source` names where the model came from (for [`SearchBounds::origin`]).
    pub fn from_prior_noise(noise: &PriorNoise, source: &str) -> Self {
        let (k, kh) = (PRIOR_SIGMA_MULTIPLE, HORIZONTAL_SIGMA_MULTIPLE);
        let [se, sn, su] = noise.sigma_enu_m.map(|s| if s.is_finite() { s.abs() } else { 0.0 });
        let [be, bn, bu] = noise.bias_enu_m.map(|b| if b.is_finite() { b } else { 0.0 });
        let (sy, by) = (noise.sigma_ypr_deg[0], noise.bias_ypr_deg[0]);
        let (sy, by) = (if sy.is_finite() { sy.abs() } else { 0.0 }, if by.is_finite() { by } else { 0.0 });
        let (min_r, min_h, min_y) = MIN_SEARCH_BOUNDS;
        SearchBounds {
            radius_m: (be.hypot(bn) + kh * se.max(sn)).max(min_r),
            height_m: (bu.abs() + k * su).max(min_h),
            yaw_deg: (by.abs() + k * sy).clamp(min_y, 180.0),
            origin: format!(
                "{kh}σ horizontally, {k}σ in height and yaw of {source} (σ = {se}, {sn}, {su} m, yaw {sy}°; bias {be}, {bn}, {bu} m, {by}°)"
            ),
        }
    }

    /// The volume these bounds give around `prior`.
    pub fn around(&self, prior: Hypothesis) -> Volume {
        Volume { prior, radius_m: self.radius_m, height_m: self.height_m, yaw_deg: self.yaw_deg }
    }

    /// Checks the half-ranges: each positive (not NaN), the yaw's at most 180°.
    ///
    /// # Errors
    /// [`SearchBoundsError`] naming the half-range and its value.
    pub fn validate(&self) -> Result<(), SearchBoundsError> {
        for (half_range, value) in
            [("radius", self.radius_m), ("height", self.height_m), ("yaw", self.yaw_deg)]
        {
            if value.is_nan() || value <= 0.0 {
                return Err(SearchBoundsError::NotPositive { half_range, value });
            }
        }
        if self.yaw_deg > 180.0 {
            return Err(SearchBoundsError::YawOver180 { yaw_deg: self.yaw_deg });
        }
        Ok(())
    }
}

/// Unusable [`SearchBounds`].
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
pub enum SearchBoundsError {
    /// A half-range is zero, negative or NaN.
    #[error("search {half_range} {value}: a half-range is > 0")]
    NotPositive {
        /// `radius`, `height` or `yaw`.
        half_range: &'static str,
        /// The half-range given (metres, or degrees for the yaw).
        value: f64,
    },
    /// The yaw half-range exceeds 180°.
    #[error("search yaw {yaw_deg}°: at most 180°")]
    YawOver180 {
        /// The yaw half-range given, degrees.
        yaw_deg: f64,
    },
}

/// [`SearchBounds`] placed around a prior: the poses a search may score.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Volume {
    /// The prior the volume is centred on.
    pub prior: Hypothesis,
    /// Horizontal half-range (radius around the prior's centre), metres.
    pub radius_m: f64,
    /// Vertical half-range, metres.
    pub height_m: f64,
    /// Yaw half-range, degrees.
    pub yaw_deg: f64,
}

impl Volume {
    /// No bounds around `prior` (every pose is inside); for tests of the stages alone.
    pub fn unbounded(prior: Hypothesis) -> Self {
        Volume { prior, radius_m: f64::INFINITY, height_m: f64::INFINITY, yaw_deg: f64::INFINITY }
    }

    /// The offsets of `h` from the prior: horizontal distance (m), height (m), yaw (degrees, the
    /// plain difference: the search never wraps yaw).
    fn offsets(&self, h: &Hypothesis) -> (f64, f64, f64) {
        let d = h.centre_m - self.prior.centre_m;
        (d.x.hypot(d.y), d.z, h.yaw_deg - self.prior.yaw_deg)
    }

    /// Whether `h` lies inside (boundary included).
    pub fn contains(&self, h: &Hypothesis) -> bool {
        let (r, dz, dyaw) = self.offsets(h);
        r <= self.radius_m && dz.abs() <= self.height_m && dyaw.abs() <= self.yaw_deg
    }

    /// The pose inside nearest to `h` in each of the horizontal position, the height and the yaw;
    /// `h` itself, bit for bit, when it is inside. A NaN coordinate becomes the prior's.
    pub fn project(&self, h: Hypothesis) -> Hypothesis {
        if self.contains(&h) {
            return h;
        }
        // Onto the boundary less a part in 10⁹ of each half-range, so that rounding keeps the
        // projection inside.
        let inner = 1.0 - 1e-9;
        let (r, dz, dyaw) = self.offsets(&h);
        let (p, c) = (self.prior.centre_m, h.centre_m);
        let (x, y) = if r <= self.radius_m {
            (c.x, c.y)
        } else if r.is_finite() {
            let s = self.radius_m * inner / r;
            (p.x + (c.x - p.x) * s, p.y + (c.y - p.y) * s)
        } else {
            (p.x, p.y)
        };
        let clamp = |v: f64, half: f64| {
            if v.is_nan() {
                0.0
            } else if v.abs() <= half {
                v
            } else {
                v.clamp(-half * inner, half * inner)
            }
        };
        let out = Hypothesis {
            centre_m: DVec3::new(x, y, p.z + clamp(dz, self.height_m)),
            yaw_deg: self.prior.yaw_deg + clamp(dyaw, self.yaw_deg),
        };
        // Only coordinates too large for a metre's precision could still round outside.
        if self.contains(&out) {
            out
        } else {
            self.prior
        }
    }

    /// Whether `h` lies on the boundary, within [`BOUNDARY_TOLERANCE`] of a half-range from it, or
    /// outside, in any of the horizontal position, height and yaw.
    pub fn on_boundary(&self, h: &Hypothesis) -> bool {
        let (r, dz, dyaw) = self.offsets(h);
        let near = |v: f64, half: f64| v.is_nan() || v >= half * (1.0 - BOUNDARY_TOLERANCE);
        near(r, self.radius_m) || near(dz.abs(), self.height_m) || near(dyaw.abs(), self.yaw_deg)
    }
}

/// Scores batches of hypotheses (higher is better).
pub trait Evaluate {
    /// What scoring can fail with.
    type Error;
    /// The score of each hypothesis, in order.
    ///
    /// # Errors
    /// Whatever scoring fails with (a render, a file).
    fn evaluate(&mut self, hyps: &[Hypothesis]) -> Result<Vec<f64>, Self::Error>;

    /// Called once the polish has refined the particle filter's best pose `at` in the filter's cost:
    /// the evaluator takes the polish's `cost` and fits there what it fits (the silhouette offset).
    /// Returns the hypotheses it scored doing so, and whether its scores changed (then the polish runs
    /// again from `at` in the new terms). The default keeps the cost as it is.
    ///
    /// # Errors
    /// Whatever scoring returns.
    fn enter_polish(&mut self, _at: &Hypothesis, _cost: &PolishCost) -> Result<(u64, bool), Self::Error> {
        Ok((0, false))
    }

    /// Whether a batch of two hypotheses takes less time than two batches of one (the evaluator
    /// scores in parallel): then the sequential steps of [`simplex`] score a likely next point
    /// alongside the one they need. The search's course is the same either way; only the hypotheses
    /// scored differ. The default: no.
    fn scores_pairs_in_parallel(&self) -> bool {
        false
    }
}

/// The coarse grid, centred on the prior: ± range in steps (both ends included).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct CoarseParams {
    /// East and north half-range, metres.
    pub xy_range_m: f64,
    /// East and north step, metres.
    pub xy_step_m: f64,
    /// Vertical half-range, metres.
    pub z_range_m: f64,
    /// Vertical step, metres.
    pub z_step_m: f64,
    /// Yaw half-range, degrees.
    pub yaw_range_deg: f64,
    /// Yaw step, degrees.
    pub yaw_step_deg: f64,
}

/// The coarse grid's steps (east/north and height in metres, yaw in degrees): they follow the costs'
/// basins, whose width is set by the image (a step of 5 m moves a cam2 view's buildings by a few
/// pixels at the coarse width), not by the prior.
pub const COARSE_STEPS: (f64, f64, f64) = (5.0, 5.0, 2.5);

/// The coarse grid's half-ranges in standard deviations of the prior's noise (east/north, along its
/// noisier axis; height; yaw): before rounding up to whole steps, the prior's error along one axis
/// stays inside the grid with a probability of 98.8 % (95.4 % in height); the particle filter and
/// polish, which keep to the wider [`SearchBounds`], reach the rest from the grid's edge cells.
pub const COARSE_SIGMA_MULTIPLES: (f64, f64, f64) = (2.5, 2.0, 2.5);

impl Default for CoarseParams {
    /// Derived from the default prior noise model (σ = 7 m east/north, 5 m up, 3° yaw; see
    /// [`CoarseParams::from_prior_noise`]): ±20 m, ±10 m in steps of 5 m, ±7.5° in steps of 2.5°,
    /// 9 × 9 × 5 × 7 = 2835 hypotheses.
    fn default() -> Self {
        CoarseParams::from_prior_noise(&PriorNoise::default(), &SearchBounds::default())
    }
}

impl CoarseParams {
    /// The coarse grid for priors with the noise model `noise`: each half-range covers the model's bias
    /// plus [`COARSE_SIGMA_MULTIPLES`] of its σ, rounded up to whole [`COARSE_STEPS`] (at least one
    /// step, so every axis has three values), and reaches no further than `bounds` (rounded up to a
    /// whole step: the cells outside the volume are left out anyway). A prior twice as noisy gets a
    /// grid twice as wide, with four times the cells in east and north.
    pub fn from_prior_noise(noise: &PriorNoise, bounds: &SearchBounds) -> Self {
        let (kxy, kz, kyaw) = COARSE_SIGMA_MULTIPLES;
        let (sxy, sz, syaw) = COARSE_STEPS;
        let finite = |x: f64| if x.is_finite() { x.abs() } else { 0.0 };
        let [se, sn, su] = noise.sigma_enu_m.map(finite);
        let [be, bn, bu] = noise.bias_enu_m.map(finite);
        let (sy, by) = (finite(noise.sigma_ypr_deg[0]), finite(noise.bias_ypr_deg[0]));
        // Whole steps covering `cover`, at least one, at most those covering `bound`; the small
        // tolerance keeps a cover of exactly k steps (2.5 × 3° = 7.5°) at k.
        let range = |cover: f64, bound: f64, step: f64| {
            let whole = |x: f64| (x / step - 1e-9).ceil().max(1.0);
            whole(cover).min(whole(bound)) * step
        };
        CoarseParams {
            xy_range_m: range(be.hypot(bn) + kxy * se.max(sn), bounds.radius_m, sxy),
            xy_step_m: sxy,
            z_range_m: range(bu + kz * su, bounds.height_m, sz),
            z_step_m: sz,
            yaw_range_deg: range(by + kyaw * sy, bounds.yaw_deg, syaw),
            yaw_step_deg: syaw,
        }
    }

    /// The number of hypotheses of [`coarse_grid`] (before the cells outside the volume are left out),
    /// counted without building it (saturating at `u64::MAX`).
    pub fn cells(&self) -> u64 {
        let n = |range: f64, step: f64| 2.0 * half_steps(range, step) + 1.0;
        // `as` saturates; NaN (never from validated flags) counts 0.
        (n(self.xy_range_m, self.xy_step_m).powi(2)
            * n(self.z_range_m, self.z_step_m)
            * n(self.yaw_range_deg, self.yaw_step_deg)) as u64
    }

    /// The grid in words (for `summary.md` and the log).
    pub fn describe(&self) -> String {
        format!(
            "±{} m east and north, ±{} m in height in steps of {} and {} m, ±{}° in yaw in steps of {}°: {} cells \
             before those outside the volume are left out",
            self.xy_range_m,
            self.z_range_m,
            self.xy_step_m,
            self.z_step_m,
            self.yaw_range_deg,
            self.yaw_step_deg,
            self.cells()
        )
    }
}

/// The most coarse cells eval-loc scores per query (350× the default model's 2835): a prior noise
/// model or `--coarse-*` flags asking for more are refused with the sizes, rather than allocating
/// and rendering for hours.
pub const MAX_COARSE_CELLS: u64 = 1_000_000;

/// The particle-filter refinement (paper / public code values as defaults).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct FineParams {
    /// Particle-filter iterations.
    pub iterations: u32,
    /// Beams (groups of kept poses).
    pub beams: u32,
    /// Best poses kept per beam.
    pub keep_per_beam: u32,
    /// Perturbations drawn around each kept pose per iteration.
    pub perturbations: u32,
    /// σ of the position perturbations at the first iteration, metres (scaled down by the decay).
    pub sigma_m: f64,
    /// Half-width of the uniform yaw perturbations at the first iteration, degrees (scaled down
    /// by the decay).
    pub yaw_deg: f64,
    /// Floor of the perturbations' linear decay (share of the first iteration's size).
    pub gamma: f64,
    /// The first this many iterations score at the coarse stage's (lower) resolution; the pool is
    /// re-scored at the fine resolution when the switch happens. `None`: until the decay reaches its
    /// floor γ ([`FineParams::lowres_iterations`]).
    pub lowres_iterations: Option<u32>,
    /// After the particle filter, a deterministic local pattern search (not in the paper; off with
    /// `--no-polish`): see [`polish`].
    pub polish: bool,
    /// How the kept poses are grouped into beams.
    pub beams_mode: BeamMode,
    /// The cost the polish refines with.
    pub polish_cost: PolishCost,
}

/// The cost of the polish, which refines the particle filter's best pose within its basin (issue 15).
///
/// The instance cost's identities choose the basin: which building is which, where outlines repeat.
/// Within the basin, the boundaries between buildings depend on the map's occlusion order, which a
/// map coarser than the query gets wrong (an LoD1 block at the tower's height hides what the LoD2
/// podium lets the camera see), and the instance Dice then pulls the camera back along its axis to
/// shrink the too-large blocks; the outline of the union (the semantic IoU) does not depend on that
/// order. And a segmenter's masks may be uniformly thinner or fatter than the silhouettes, which the
/// costs also explain by moving the camera along its axis (a depth the narrow cam2 view hardly
/// observes otherwise); a silhouette offset fitted once, before the polish, absorbs it.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct PolishCost {
    /// Weight of the semantic IoU in the blended instance cost during the polish (1: the union's
    /// outline alone; the filter's weight is `eval-loc --semantic-weight`).
    pub semantic_weight: f64,
    /// Silhouette offsets tried at the polish's start, from −N to +N pixels (erode to dilate every
    /// rendered building), scored with spill weight 1 (the symmetric IoU); 0: none.
    pub max_silhouette_offset_px: u32,
    /// Weight λ of the rendered building pixels outside the query's union in the semantic term during
    /// the polish, |Q ∩ R| / (|Q| + λ·|R \ Q|) (1: the IoU). An LoD map generalises a building
    /// outwards: an LoD1 block filled up to the eaves or the ridge covers the gables, setbacks and
    /// courtyards the query shows, so at the true pose the render spills over the query's outline,
    /// and the IoU trades that spill for uncovered query pixels by moving the camera back. With λ < 1
    /// spill is weaker evidence than a query pixel left uncovered; the exact outline still scores 1.
    pub spill_weight: f64,
    /// Whether the second pass lets every rendered building's rim move by a pixel, in or out, each
    /// building its own way: in the semantic term ([`crate::loc::cost::Scorer::rim_tolerant_overlap`])
    /// and, per query instance, in the instance cost's best-match Dice
    /// ([`crate::loc::cost::Scorer::rim_tolerant_instance_cost`]) and, per query instance and set of
    /// buildings, in the grouped cost's union Dice
    /// ([`crate::loc::cost::Scorer::rim_tolerant_grouped_instance_cost`]):
    /// a segmenter's instance a pixel fatter or thinner than its building then moves no camera along
    /// its axis, while a building displaced by a pixel still counts. It assumes the map's outlines are
    /// those the masks were labelled from (a segmenter trained on this map's renders, or the oracle's
    /// masks): against a map coarser than the query's buildings (LoD1 blocks spilling over the
    /// outline by a pixel or more) the pixel it frees is the one that measured the misfit, and it
    /// loses; `eval-loc` turns it off there (`--polish-rim-tolerance`, bench/loc_learned.md).
    pub rim_tolerance: bool,
}

/// The default [`PolishCost::spill_weight`] (issue 15: measured on Den Haag and Shibuya against
/// their LoD1 maps and degraded masks, bench/loc_issue15.md).
pub const DEFAULT_SPILL_WEIGHT: f64 = 0.3;

impl Default for PolishCost {
    fn default() -> Self {
        PolishCost {
            semantic_weight: 1.0,
            max_silhouette_offset_px: 2,
            spill_weight: DEFAULT_SPILL_WEIGHT,
            rim_tolerance: true,
        }
    }
}

impl PolishCost {
    /// `eval-loc`'s polish for a map that is (`label_source`) or is not the model the query masks
    /// are labelled from (the area's own, unperturbed scene: the oracle's masks, or a segmenter
    /// trained on insgen's renders of it). Where it is, the second pass keeps the per-building terms
    /// (semantic weight 0) with the rims freed: the buildings' boundaries are the masks' own, so they
    /// place the camera, and a segmenter's rim a pixel off moves none (a real model's masks: 58.8 →
    /// 66.2 % with the instance cost, 58.8 → 71.2 % with the grouped cost on 80 fresh held-out
    /// Shibuya frames; bench/loc_learned.md). Where it is coarser than the buildings the masks show
    /// (LoD1 blocks, another area's model), the union's outline alone, the rims kept: the boundaries
    /// between buildings follow the map's wrong occlusion order there, and the pixel a freed rim would
    /// absorb is the one that measures the misfit (issue 15, bench/loc_issue15.md).
    pub fn for_map(label_source: bool) -> PolishCost {
        if label_source {
            PolishCost { semantic_weight: 0.0, rim_tolerance: true, ..PolishCost::default() }
        } else {
            PolishCost { rim_tolerance: false, ..PolishCost::default() }
        }
    }
}

/// How the particle filter's kept poses are grouped.
///
/// The paper ranks all candidates together every iteration ([`BeamMode::Joint`]): its best coarse
/// cells are usually grid neighbours of one another, and the pool collapses into the basin that scores
/// best at the coarse resolution in the first iterations. Where another basin scores better at the
/// fine resolution (the ground truth's, issue 15), that basin is never visited again.
/// [`BeamMode::Basins`] keeps distinct basins apart until the fine resolution can judge them.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case", tag = "kind")]
pub enum BeamMode {
    /// The paper: `beams × keep_per_beam` poses ranked jointly across beams.
    Joint,
    /// The best `count` coarse cells that are not grid neighbours of a better one (distinct basins)
    /// each seed a beam of `keep_per_beam` poses, refined separately at the coarse resolution; at the
    /// switch to the fine resolution the `survivors` beams whose best pose scores highest there go on.
    /// With `prune`, the beams are judged at the fine resolution once before the switch as well, and
    /// only the best [`Prune::keep`] go on at the coarse resolution. With `prior_basin`, the prior's
    /// own cell seeds one more beam where none of the `count` is its grid neighbour.
    Basins {
        /// Basins (beams) seeded from the coarse grid.
        count: u32,
        /// Beams that go on at the fine resolution.
        survivors: u32,
        /// An early judgement of the beams, if any.
        #[serde(default)]
        prune: Option<Prune>,
        /// Whether the prior's basin is always refined: the prior is where the camera most likely
        /// is, and a cost whose coarse renders are noisy (the paper's best-match Dice at 160 px) can
        /// rank the truth's cells below `count` others there. A record without it is a search from
        /// before it existed, which had none.
        #[serde(default)]
        prior_basin: bool,
    },
}

/// An early judgement of the basins (successive halving): after `after_iterations` particle-filter
/// iterations at the coarse resolution, every beam's poses are re-scored at the fine resolution and
/// the `keep` beams whose best pose scores highest go on. A beam's poses are a metre or two from its
/// basin's bottom by then, close enough for the fine resolution to tell the basins apart, and the
/// judgement costs `keep_per_beam` renders per beam where each further iteration costs
/// `keep_per_beam × perturbations`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct Prune {
    /// Coarse-resolution iterations before the judgement.
    pub after_iterations: u32,
    /// Beams kept.
    pub keep: u32,
}

/// The default early judgement of the basins: after 5 iterations at the coarse resolution, the best 2
/// of the 4 basins go on ([`Prune`]).
pub const DEFAULT_PRUNE: Prune = Prune { after_iterations: 5, keep: 2 };

impl Default for FineParams {
    /// The paper's particle filter ([`FineParams::paper`]) made cheaper where the distinct basins and
    /// the polish make up for it (issue 15: ≤ 1 s per Shibuya cam2 query at unchanged recall): 20
    /// iterations instead of 40 (the polish does the final precision), 4 basins of which the best 2
    /// go on after 5 iterations ([`DEFAULT_PRUNE`]) and the best 1 at the fine resolution.
    fn default() -> Self {
        FineParams {
            iterations: 20,
            beams: 2,
            keep_per_beam: 2,
            perturbations: 12,
            sigma_m: 1.5,
            yaw_deg: 2.0,
            gamma: 0.3,
            lowres_iterations: None,
            polish: true,
            beams_mode: BeamMode::Basins {
                count: 4,
                survivors: 1,
                prune: Some(DEFAULT_PRUNE),
                prior_basin: true,
            },
            polish_cost: PolishCost::default(),
        }
    }
}

impl FineParams {
    /// Iterations scored at the coarse resolution. By default those before the perturbation scale
    /// s = max(γ, (n − i)/n) reaches its floor γ (28 of 40 for γ = 0.3): until then the pool moves
    /// by at least σ·γ = 0.45 m and 0.6° per step, which the coarse renders resolve (a 320 px cam2
    /// pixel is about 0.2 m at 150 m); the last iterations, at the floor, are the final precision,
    /// scored at the fine resolution.
    pub fn lowres_iterations(&self) -> u32 {
        let n = self.iterations.max(1);
        self.lowres_iterations
            .unwrap_or_else(|| (n as f64 * (1.0 - self.gamma.clamp(0.0, 1.0)) - 1e-9).ceil() as u32)
            .min(n)
    }

    /// Candidates per iteration (kept + perturbed, all beams) in the paper's joint mode.
    pub fn candidates_per_iteration(&self) -> u32 {
        self.beams * self.keep_per_beam * (1 + self.perturbations)
    }

    /// The paper's particle filter: 40 iterations of 2 jointly ranked beams × (2 kept + 2 × 12
    /// perturbations), σ = 1.5 m, ±2°, γ = 0.3, no polish.
    pub fn paper() -> Self {
        // 2 beams × (2 kept + 2 × 12 perturbations) = 52 candidates per iteration.
        FineParams { iterations: 40, beams_mode: BeamMode::Joint, polish: false, ..FineParams::default() }
    }
}

/// Which stages run.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Stages {
    /// The coarse grid, then the particle filter from its best cells (the default).
    CoarseAndFine,
    /// The coarse grid alone (`--no-refine`): its best cell is the estimate.
    CoarseOnly,
    /// The particle filter from the raw prior (`--no-select`).
    FineOnly,
    /// Neither stage (`--no-select --no-refine`): the prior is the estimate.
    PriorOnly,
}

/// How the search runs: both stages' parameters and which stages run.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SearchOptions {
    /// The coarse grid.
    pub coarse: CoarseParams,
    /// The particle filter and polish.
    pub fine: FineParams,
    /// Which stages run.
    pub stages: Stages,
    /// The volume around the prior every stage keeps to.
    #[serde(default)]
    pub bounds: SearchBounds,
    /// What the search reports when its best pose ends on the boundary of `bounds`.
    #[serde(default)]
    pub on_boundary: OnBoundary,
}

/// What a search reports when its best pose ends on the boundary of its volume
/// ([`Volume::on_boundary`]). There the cost still improves towards poses the prior rules out (with
/// the default volume, poses the prior's error reaches with a probability of 6.3·10⁻⁵ in each of the
/// horizontal distance, the height and the yaw): the cost is degenerate on this query, and the pose
/// it found says nothing a navigator should act on.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum OnBoundary {
    /// Report the prior (no worse than the prior's own error) and flag the query (the default).
    #[default]
    Prior,
    /// Report the best pose on the boundary (`eval-loc --keep-boundary-estimates`: to study a cost).
    Keep,
}

impl Default for SearchOptions {
    fn default() -> Self {
        SearchOptions {
            coarse: CoarseParams::default(),
            fine: FineParams::default(),
            stages: Stages::CoarseAndFine,
            bounds: SearchBounds::default(),
            on_boundary: OnBoundary::default(),
        }
    }
}

/// What the search found.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SearchResult {
    /// The estimate.
    pub best: Hypothesis,
    /// Its score.
    pub best_score: f64,
    /// The coarse stage's best (equal to the prior with `--no-select`).
    pub coarse_best: Hypothesis,
    /// The coarse best's score.
    pub coarse_score: f64,
    /// Hypotheses scored in all.
    pub hypotheses_scored: u64,
    /// Hypotheses and seconds per stage (where a query's time goes).
    #[serde(default)]
    pub stages: StageCosts,
    /// Whether the search's best pose lay on the boundary of [`SearchOptions::bounds`] (or within
    /// [`BOUNDARY_TOLERANCE`] of it): the cost's optimum may lie beyond, where the prior says the
    /// camera cannot be.
    #[serde(default)]
    pub on_boundary: bool,
    /// Whether `best` is the prior because the search's best pose lay on the boundary
    /// ([`OnBoundary::Prior`]); `best_score` is then the prior's.
    #[serde(default)]
    pub kept_prior: bool,
}

/// Hypotheses scored and wall-clock seconds spent scoring them in one stage of the search.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct StageCost {
    /// Hypotheses scored.
    pub hypotheses: u64,
    /// Wall-clock seconds spent scoring them.
    pub seconds: f64,
}

/// The search's cost per stage.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct StageCosts {
    /// The coarse grid.
    pub coarse: StageCost,
    /// Particle-filter iterations scored at the coarse width.
    pub filter_coarse_width: StageCost,
    /// Particle-filter iterations (and re-scoring) at the render width.
    pub filter_render_width: StageCost,
    /// The polish after the particle filter.
    pub polish: StageCost,
}

/// Which entry of [`StageCosts`] a batch of hypotheses is charged to.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Stage {
    Coarse,
    FilterCoarseWidth,
    FilterRenderWidth,
    Polish,
}

/// Steps on each side of 0 along one axis of the coarse grid: none for a non-positive range or step.
fn half_steps(range: f64, step: f64) -> f64 {
    if step <= 0.0 || range <= 0.0 {
        0.0
    } else {
        (range / step).round()
    }
}

fn steps(range: f64, step: f64) -> Vec<f64> {
    let n = half_steps(range, step) as i64;
    (-n..=n).map(|i| i as f64 * step).collect()
}

/// The coarse grid around `prior`, in a fixed order.
pub fn coarse_grid(prior: &Hypothesis, p: &CoarseParams) -> Vec<Hypothesis> {
    let mut out = Vec::new();
    for dz in steps(p.z_range_m, p.z_step_m) {
        for dy in steps(p.xy_range_m, p.xy_step_m) {
            for dx in steps(p.xy_range_m, p.xy_step_m) {
                for dyaw in steps(p.yaw_range_deg, p.yaw_step_deg) {
                    out.push(Hypothesis {
                        centre_m: DVec3::new(
                            prior.centre_m[0] + dx,
                            prior.centre_m[1] + dy,
                            prior.centre_m[2] + dz,
                        ),
                        yaw_deg: prior.yaw_deg + dyaw,
                    });
                }
            }
        }
    }
    out
}

/// Sorts (hypothesis, score) pairs best first; ties keep their order (stable), so the search is
/// deterministic.
fn rank(mut scored: Vec<(Hypothesis, f64)>) -> Vec<(Hypothesis, f64)> {
    scored.sort_by(|a, b| b.1.total_cmp(&a.1));
    scored
}

/// Runs the search from `prior` with the stages and parameters of `opts` and the random stream of
/// `seed`. `pivot_m` is the scene point the prior looks at (where its optical axis meets the ground),
/// used by [`polish`]. The coarse stage scores with `coarse_eval` (typically at a lower resolution),
/// the fine stage with `eval`.
///
/// # Errors
/// Whatever the evaluators return.
pub fn search<E: Evaluate>(
    coarse_eval: &mut E,
    eval: &mut E,
    prior: Hypothesis,
    opts: &SearchOptions,
    seed: u64,
    pivot_m: Option<DVec3>,
) -> Result<SearchResult, E::Error> {
    let (coarse, fine) = (&opts.coarse, &opts.fine);
    let select = matches!(opts.stages, Stages::CoarseAndFine | Stages::CoarseOnly);
    let refine = matches!(opts.stages, Stages::CoarseAndFine | Stages::FineOnly);
    let volume = opts.bounds.around(prior);
    let mut counter = Counted::default();
    // Coarse stage: the grid's cells inside the volume (the prior's own cell always is).
    let ranked: Vec<(Hypothesis, f64)> = if select {
        let mut grid = coarse_grid(&prior, coarse);
        grid.retain(|h| volume.contains(h));
        let s = counter.run(coarse_eval, &grid, Stage::Coarse)?;
        rank(grid.into_iter().zip(s).collect())
    } else {
        let s = counter.run(coarse_eval, &[prior], Stage::Coarse)?;
        vec![(prior, s[0])]
    };
    let (coarse_best, coarse_score) = ranked[0];
    let (mut best, mut best_score) = (coarse_best, coarse_score);
    if refine {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let mut filter = Filter { counter: &mut counter, fine, volume, rng: &mut rng };
        (best, best_score) = match fine.beams_mode {
            BeamMode::Joint => {
                let keep = (fine.beams * fine.keep_per_beam).max(1) as usize;
                let mut pool = ranked;
                pool.truncate(keep);
                while pool.len() < keep {
                    pool.push(pool[0]);
                }
                filter.particle_filter(coarse_eval, eval, pool, keep)?[0]
            }
            BeamMode::Basins { count, survivors, prune, prior_basin } => {
                let prior_cell = prior_basin.then_some(prior);
                filter.basins(coarse_eval, eval, &ranked, coarse, (count, survivors, prune), prior_cell)?
            }
        };
        if fine.polish {
            let started = Instant::now();
            // First a simplex to the optimum of the filter's cost (it makes the fit of the
            // silhouette offset and the second pass's start as good as the filter's cost can), then,
            // if the polish's cost differs, a whole polish to its optimum from there; where it does
            // not, the moves finish the first pass. The moves of a first pass that a second one
            // follows would only sharpen an optimum the second pass leaves (issue 40: a fifth of the
            // polish's hypotheses; recall 5 queries behind over 2,600, bench/loc_learned.md).
            let (b, sc, mut n) = simplex(eval, best, best_score, SIMPLEX_EVALUATIONS, 1.0, &volume)?;
            (best, best_score) = (b, sc);
            let (fitted, changed) = eval.enter_polish(&best, &fine.polish_cost)?;
            n += fitted;
            let (b, sc, n2) = if changed {
                best_score = eval.evaluate(&[best])?[0];
                n += 1;
                polish(eval, best, best_score, pivot_m, SECOND_PASS_SIMPLEX_SCALE, &volume)?
            } else {
                descend(eval, best, best_score, pivot_m, &volume)?
            };
            (best, best_score) = (b, sc);
            n += n2;
            counter.charge(Stage::Polish, n, started.elapsed().as_secs_f64());
        }
    }
    let on_boundary = volume.on_boundary(&best);
    let kept_prior = on_boundary && opts.on_boundary == OnBoundary::Prior;
    if kept_prior {
        (best, best_score) = (prior, eval.evaluate(&[prior])?[0]);
    }
    Ok(SearchResult {
        best,
        best_score,
        coarse_best,
        coarse_score,
        hypotheses_scored: counter.scored,
        stages: counter.stages,
        on_boundary,
        kept_prior,
    })
}

/// What the particle filter's iterations share: the counter, the parameters, the volume its draws
/// are projected onto and the random stream.
struct Filter<'a> {
    counter: &'a mut Counted,
    fine: &'a FineParams,
    volume: Volume,
    rng: &'a mut ChaCha8Rng,
}

impl Filter<'_> {
    /// Iterations `from..to` of the particle filter, all scored by `eval` at `stage`'s width
    /// (`pool` already scored by it).
    fn iterations<E: Evaluate>(
        &mut self,
        eval: &mut E,
        stage: Stage,
        mut pool: Pool,
        keep: usize,
        (from, to): (u32, u32),
    ) -> Result<Pool, E::Error> {
        for i in from..to {
            pool = iterate(self.counter, eval, stage, self.fine, pool, keep, i, self.rng, &self.volume)?;
        }
        Ok(pool)
    }

    /// The particle filter (the paper's) from `pool` (scored by `coarse_eval`), switching to `eval`
    /// after [`FineParams::lowres_iterations`]; the pool comes back scored by `eval`, ranked best
    /// first.
    fn particle_filter<E: Evaluate>(
        &mut self,
        coarse_eval: &mut E,
        eval: &mut E,
        pool: Pool,
        keep: usize,
    ) -> Result<Pool, E::Error> {
        let n_iter = self.fine.iterations.max(1);
        let lowres = self.fine.lowres_iterations();
        // Scores in `pool` come from the coarse evaluator until they are re-scored at the fine one.
        let pool = self.iterations(coarse_eval, Stage::FilterCoarseWidth, pool, keep, (0, lowres))?;
        let hyps: Vec<Hypothesis> = pool.iter().map(|p| p.0).collect();
        let s = self.counter.run(eval, &hyps, Stage::FilterRenderWidth)?;
        let pool = rank(hyps.into_iter().zip(s).collect());
        self.iterations(eval, Stage::FilterRenderWidth, pool, keep, (lowres, n_iter))
    }

    /// [`BeamMode::Basins`] with its (count, survivors, prune): each distinct basin of the coarse
    /// grid's `ranked` cells refined on its own at the coarse resolution, from its own cell plus the
    /// grid neighbours that follow it in the ranking; judged at the fine resolution (early with
    /// `prune`, then at the switch); the survivors refined on there. `prior_cell`, if any, seeds one
    /// more beam where no basin's cell is its grid neighbour. Returns the best pose.
    fn basins<E: Evaluate>(
        &mut self,
        coarse_eval: &mut E,
        eval: &mut E,
        ranked: &[(Hypothesis, f64)],
        coarse: &CoarseParams,
        (count, survivors, prune): (u32, u32, Option<Prune>),
        prior_cell: Option<Hypothesis>,
    ) -> Result<(Hypothesis, f64), E::Error> {
        let keep = self.fine.keep_per_beam.max(1) as usize;
        let mut seeds = distinct_basins(ranked, coarse, count.max(1) as usize);
        if let Some(p) = prior_cell {
            if !seeds.iter().any(|s| neighbours(s, &p, coarse)) {
                seeds.push(p);
            }
        }
        let n_iter = self.fine.iterations.max(1);
        let lowres = self.fine.lowres_iterations();
        let mut beams: Vec<Pool> = seeds
            .iter()
            .map(|seed_cell| {
                let mut pool: Pool = ranked
                    .iter()
                    .filter(|(h, _)| neighbours(h, seed_cell, coarse))
                    .take(keep)
                    .copied()
                    .collect();
                while pool.len() < keep {
                    pool.push(pool[0]);
                }
                pool
            })
            .collect();
        if beams.len() == 1 {
            let pool = beams.remove(0);
            return Ok(self.particle_filter(coarse_eval, eval, pool, keep)?[0]);
        }
        // The early judgement, if any and before the switch, then the one at the switch.
        let mut done = 0;
        let mut judgements: Vec<(u32, usize)> = Vec::with_capacity(2);
        if let Some(p) = prune {
            if p.after_iterations < lowres && (p.keep.max(1) as usize) < beams.len() {
                judgements.push((p.after_iterations, p.keep.max(1) as usize));
            }
        }
        judgements.push((lowres, survivors.max(1) as usize));
        let mut judged: Vec<Judged> = Vec::new();
        for (at, kept) in judgements {
            for pool in &mut beams {
                let taken = std::mem::take(pool);
                *pool = self.iterations(coarse_eval, Stage::FilterCoarseWidth, taken, keep, (done, at))?;
            }
            done = at;
            // The fine resolution judges the basins: each beam's poses re-scored there, the best
            // `kept` beams go on.
            judged = judge(self.counter, eval, std::mem::take(&mut beams))?;
            judged.truncate(kept);
            beams = judged.iter().map(|(coarse_pool, _)| coarse_pool.clone()).collect();
        }
        let mut finals = Vec::with_capacity(judged.len());
        for (_, pool) in judged {
            let pool = self.iterations(eval, Stage::FilterRenderWidth, pool, keep, (lowres, n_iter))?;
            finals.push(pool[0]);
        }
        Ok(rank(finals)[0])
    }
}

/// A beam's poses with their scores, best first.
type Pool = Vec<(Hypothesis, f64)>;
/// A beam as it was (scored at the coarse resolution) and re-scored at the fine one, ranked.
type Judged = (Pool, Pool);

/// Re-scores every beam's poses with the fine evaluator `eval` and sorts the beams by their best pose
/// there, best first (ties keep their order). Each beam comes back twice: as it was (scored at the
/// coarse resolution, to go on there) and re-scored and ranked at the fine resolution.
fn judge<E: Evaluate>(
    counter: &mut Counted,
    eval: &mut E,
    beams: Vec<Pool>,
) -> Result<Vec<Judged>, E::Error> {
    let mut judged = Vec::with_capacity(beams.len());
    for pool in beams {
        let hyps: Vec<Hypothesis> = pool.iter().map(|p| p.0).collect();
        let s = counter.run(eval, &hyps, Stage::FilterRenderWidth)?;
        judged.push((pool, rank(hyps.into_iter().zip(s).collect())));
    }
    judged.sort_by(|a, b| b.1[0].1.total_cmp(&a.1[0].1));
    Ok(judged)
}

/// Counts the hypotheses scored and the time spent scoring them, per stage.
#[derive(Default)]
struct Counted {
    scored: u64,
    stages: StageCosts,
}

impl Counted {
    fn run<E: Evaluate>(
        &mut self,
        eval: &mut E,
        hyps: &[Hypothesis],
        stage: Stage,
    ) -> Result<Vec<f64>, E::Error> {
        let started = Instant::now();
        let out = eval.evaluate(hyps);
        self.charge(stage, hyps.len() as u64, started.elapsed().as_secs_f64());
        out
    }

    fn charge(&mut self, stage: Stage, hypotheses: u64, seconds: f64) {
        self.scored += hypotheses;
        let c = match stage {
            Stage::Coarse => &mut self.stages.coarse,
            Stage::FilterCoarseWidth => &mut self.stages.filter_coarse_width,
            Stage::FilterRenderWidth => &mut self.stages.filter_render_width,
            Stage::Polish => &mut self.stages.polish,
        };
        c.hypotheses += hypotheses;
        c.seconds += seconds;
    }
}

/// Whether `a` and `b` are the same cell or grid neighbours of the coarse grid `p` (at most one step
/// apart in every searched dimension).
fn neighbours(a: &Hypothesis, b: &Hypothesis, p: &CoarseParams) -> bool {
    let within = |d: f64, step: f64| d.abs() <= step.max(0.0) * 1.01 + 1e-9;
    within(a.centre_m[0] - b.centre_m[0], p.xy_step_m)
        && within(a.centre_m[1] - b.centre_m[1], p.xy_step_m)
        && within(a.centre_m[2] - b.centre_m[2], p.z_step_m)
        && within(a.yaw_deg - b.yaw_deg, p.yaw_step_deg)
}

/// The best `count` cells of `ranked` (best first) that are no grid neighbour of a better kept cell:
/// one seed per distinct basin of the coarse score (greedy non-maximum suppression).
pub fn distinct_basins(ranked: &[(Hypothesis, f64)], p: &CoarseParams, count: usize) -> Vec<Hypothesis> {
    let mut kept: Vec<Hypothesis> = Vec::with_capacity(count);
    for (h, _) in ranked {
        if kept.len() >= count {
            break;
        }
        if !kept.iter().any(|k| neighbours(h, k, p)) {
            kept.push(*h);
        }
    }
    kept
}

/// One particle-filter iteration: `perturbations` draws around every pose of `pool` at the decayed
/// scale s = max(γ, (n − i)/n), projected onto `volume`, scored by `eval`; the best `keep` of old and
/// new go on.
#[allow(clippy::too_many_arguments)]
fn iterate<E: Evaluate>(
    counter: &mut Counted,
    eval: &mut E,
    stage: Stage,
    fine: &FineParams,
    pool: Vec<(Hypothesis, f64)>,
    keep: usize,
    i: u32,
    rng: &mut ChaCha8Rng,
    volume: &Volume,
) -> Result<Vec<(Hypothesis, f64)>, E::Error> {
    let unit = Normal::new(0.0, 1.0).expect("σ = 1 is valid");
    let n_iter = fine.iterations.max(1);
    let s = fine.gamma.max((n_iter - i.min(n_iter)) as f64 / n_iter as f64);
    let mut fresh: Vec<Hypothesis> = Vec::with_capacity(pool.len() * fine.perturbations as usize);
    for &(h, _) in &pool {
        for _ in 0..fine.perturbations {
            // A draw outside the volume is projected onto it (one draw per draw: the random stream
            // is the same as without bounds).
            fresh.push(volume.project(Hypothesis {
                centre_m: DVec3::new(
                    h.centre_m[0] + fine.sigma_m * s * unit.sample(rng),
                    h.centre_m[1] + fine.sigma_m * s * unit.sample(rng),
                    h.centre_m[2] + fine.sigma_m * s * unit.sample(rng),
                ),
                yaw_deg: h.yaw_deg + rng.gen_range(-1.0..=1.0) * fine.yaw_deg * s,
            }));
        }
    }
    let scores = counter.run(eval, &fresh, stage)?;
    let mut all = pool;
    all.extend(fresh.into_iter().zip(scores));
    // Re-rank (across beams in the joint mode: beam b gets ranks b·keep_per_beam …); the best `keep`
    // seed the next iteration.
    let mut all = rank(all);
    all.truncate(keep);
    Ok(all)
}

/// The local moves of [`polish`] around `h` at a step of `step_m` metres / `step_deg` degrees: ±x,
/// ±y, ±z, ±yaw, ±dolly (along the prior's optical axis `axis`, the direction a narrow field of view
/// constrains least) and ±orbit (yaw with the centre swung about the vertical through `pivot_m`, so
/// the pivot stays put in the image: the valley yaw and sideways motion form together).
fn moves(h: &Hypothesis, step_m: f64, step_deg: f64, pivot_m: Option<DVec3>) -> Vec<Hypothesis> {
    let c = h.centre_m;
    let mut out = Vec::with_capacity(12);
    for sign in [1.0, -1.0] {
        for axis in 0..3 {
            let mut m = *h;
            m.centre_m[axis] += sign * step_m;
            out.push(m);
        }
        out.push(Hypothesis { centre_m: c, yaw_deg: h.yaw_deg + sign * step_deg });
        if let Some(p) = pivot_m {
            // Dolly towards/away from the pivot.
            let d = p - c;
            let n = d.length();
            if n > 1e-9 {
                out.push(Hypothesis { centre_m: c + d * (sign * step_m / n), yaw_deg: h.yaw_deg });
            }
            // Orbit: yaw + δ turns the view clockwise seen from above (Pose::from_ypr_deg), so the
            // centre turns clockwise about the pivot by the same angle.
            let delta = (sign * step_deg).to_radians();
            let (x, y) = (c[0] - p[0], c[1] - p[1]);
            let (sn, cs) = delta.sin_cos();
            out.push(Hypothesis {
                centre_m: DVec3::new(p[0] + x * cs + y * sn, p[1] - x * sn + y * cs, c[2]),
                yaw_deg: h.yaw_deg + sign * step_deg,
            });
        }
    }
    out
}

/// Evaluations of the Nelder–Mead stage of [`polish`].
pub const SIMPLEX_EVALUATIONS: u32 = 120;
/// Initial simplex of [`simplex`]: the step in metres (x, y, z) and degrees (yaw).
pub const SIMPLEX_STEP: (f64, f64) = (1.0, 0.2);

/// Nelder–Mead over (x, y, z, yaw) from `start` (maximising the score), at most `max_evals`
/// evaluations, its first simplex `scale` × [`SIMPLEX_STEP`] wide. The cost's valleys after the
/// particle filter are narrow and diagonal (the camera moved along its optical axis while yaw and
/// sideways motion trade off, issue 15), where moves along fixed directions stall; a simplex adapts
/// its shape to them. Coordinates are scaled by [`SIMPLEX_STEP`] so that 1 m and 0.2° weigh the
/// same. Every vertex is kept in `volume` (projected onto it). Returns the best, its score,
/// evaluations.
///
/// The budget counts the evaluations the method uses. Where the evaluator scores pairs in parallel
/// ([`Evaluate::scores_pairs_in_parallel`]), every reflection is scored together with the inside
/// contraction, the step the method takes next most often (issue 15: 44 % of the steps on Shibuya's
/// cam2 queries, against 33 % reflections kept without a second point, 12 % outside contractions
/// and 11 % expansions): one round of scoring instead of two where it is needed, the same course,
/// and the speculative scores are counted in the evaluations returned.
///
/// # Errors
/// Whatever the evaluator returns.
pub fn simplex<E: Evaluate>(
    eval: &mut E,
    start: Hypothesis,
    start_score: f64,
    max_evals: u32,
    scale: f64,
    volume: &Volume,
) -> Result<(Hypothesis, f64, u64), E::Error> {
    let (sm, sd) = SIMPLEX_STEP;
    let raw = |v: [f64; 4]| Hypothesis {
        centre_m: DVec3::new(v[0] * sm, v[1] * sm, v[2] * sm),
        yaw_deg: v[3] * sd,
    };
    let from_h = |h: Hypothesis| [h.centre_m[0] / sm, h.centre_m[1] / sm, h.centre_m[2] / sm, h.yaw_deg / sd];
    // Every point scored lies in the volume, and a vertex outside it is moved onto it, so that the
    // simplex never leaves it; inside, both are the identity.
    let to_h = |v: [f64; 4]| volume.project(raw(v));
    let inside = |v: [f64; 4]| if volume.contains(&raw(v)) { v } else { from_h(volume.project(raw(v))) };
    let x0 = from_h(start);
    let mut pts: Vec<([f64; 4], f64)> = vec![(x0, start_score)];
    let verts: Vec<[f64; 4]> = (0..4)
        .map(|k| {
            let mut v = x0;
            v[k] += scale;
            // On the boundary, the first simplex extends inwards rather than collapsing onto it.
            if !volume.contains(&raw(v)) {
                v[k] = x0[k] - scale;
            }
            inside(v)
        })
        .collect();
    let s = eval.evaluate(&verts.iter().map(|v| to_h(*v)).collect::<Vec<_>>())?;
    // Evaluations used (the budget's) and scored (with the speculative ones).
    let mut n = verts.len() as u64;
    let mut scored = n;
    pts.extend(verts.into_iter().zip(s));
    let lerp =
        |a: [f64; 4], b: [f64; 4], t: f64| -> [f64; 4] { std::array::from_fn(|k| a[k] + t * (b[k] - a[k])) };
    let speculate = eval.scores_pairs_in_parallel();
    while n < max_evals as u64 {
        // Best first (stable: ties keep the earlier vertex).
        pts.sort_by(|a, b| b.1.total_cmp(&a.1));
        let worst = pts[4];
        let centroid: [f64; 4] = std::array::from_fn(|k| pts[..4].iter().map(|p| p.0[k]).sum::<f64>() / 4.0);
        let one = |eval: &mut E, v: [f64; 4], n: &mut u64, scored: &mut u64| -> Result<f64, E::Error> {
            *n += 1;
            *scored += 1;
            Ok(eval.evaluate(&[to_h(v)])?[0])
        };
        // Reflection through the centroid of the others, and the inside contraction.
        let xr = inside(lerp(centroid, worst.0, -1.0));
        let xi = inside(lerp(centroid, worst.0, 0.5));
        let (fr, fi) = if speculate {
            let s = eval.evaluate(&[to_h(xr), to_h(xi)])?;
            n += 1;
            scored += 2;
            (s[0], Some(s[1]))
        } else {
            (one(eval, xr, &mut n, &mut scored)?, None)
        };
        if fr > pts[0].1 {
            let xe = inside(lerp(centroid, worst.0, -2.0));
            let fe = one(eval, xe, &mut n, &mut scored)?;
            pts[4] = if fe > fr { (xe, fe) } else { (xr, fr) };
        } else if fr > pts[3].1 {
            pts[4] = (xr, fr);
        } else {
            // Contraction (outside if the reflection beat the worst, else inside).
            let (xc, fc) = if fr > worst.1 {
                let xo = inside(lerp(centroid, xr, 0.5));
                (xo, one(eval, xo, &mut n, &mut scored)?)
            } else if let Some(fi) = fi {
                n += 1;
                (xi, fi)
            } else {
                (xi, one(eval, xi, &mut n, &mut scored)?)
            };
            if fc > fr.max(worst.1) {
                pts[4] = (xc, fc);
            } else {
                // Shrink towards the best.
                let best = pts[0].0;
                let shrunk: Vec<[f64; 4]> = pts[1..].iter().map(|p| inside(lerp(best, p.0, 0.5))).collect();
                let s = eval.evaluate(&shrunk.iter().map(|v| to_h(*v)).collect::<Vec<_>>())?;
                n += shrunk.len() as u64;
                scored += shrunk.len() as u64;
                for (i, (v, f)) in shrunk.into_iter().zip(s).enumerate() {
                    pts[i + 1] = (v, f);
                }
            }
        }
        // Collapsed below a centimetre / 0.002°: done.
        let spread = pts[1..]
            .iter()
            .map(|p| (0..4).map(|k| (p.0[k] - pts[0].0[k]).abs()).fold(0.0, f64::max))
            .fold(0.0, f64::max);
        if spread < 0.01 {
            break;
        }
    }
    pts.sort_by(|a, b| b.1.total_cmp(&a.1));
    if pts[0].1 > start_score {
        Ok((to_h(pts[0].0), pts[0].1, scored))
    } else {
        Ok((start, start_score, scored))
    }
}

/// The first simplex of the polish's second pass, in units of [`SIMPLEX_STEP`]: 2 m and 0.4°.
///
/// The second pass starts at the optimum of the filter's cost and climbs the polish's cost. Where
/// the two costs differ (the instance Dice blended with the semantic IoU against the union's
/// outline with its spill weight), their optima can lie 1.5–2.5 m apart with a shallow ridge
/// between them, mostly along the optical axis and sideways. A simplex 1 m wide then shrinks onto
/// the near side of the ridge; one 2 m wide straddles it (issue 15: Den Haag with building heights
/// perturbed and Shibuya against its LoD1 map, bench/loc_issue15.md). It costs no evaluation: the
/// simplex's budget is [`SIMPLEX_EVALUATIONS`] either way.
pub const SECOND_PASS_SIMPLEX_SCALE: f64 = 2.0;

/// First step of [`polish`]: metres and degrees.
pub const POLISH_START_STEP: (f64, f64) = (1.0, 0.2);
/// Step halvings of [`polish`] (the last level moves by 1/32 of the first step).
pub const POLISH_LEVELS: u32 = 6;
/// Improving moves allowed per level of [`polish`].
pub const POLISH_MOVES_PER_LEVEL: u32 = 10;

/// Deterministic local refinement after the particle filter: evaluate the [`moves`] around the best
/// pose and take the best improving one, then follow it (Hooke–Jeeves pattern moves: the same
/// displacement ×2, ×4, ×8 scored together, the best improving one taken), so a long valley of the
/// cost — typically along the optical axis with yaw and sideways motion — is travelled in a few
/// steps. The step halves when no move improves ([`POLISH_START_STEP`], [`POLISH_LEVELS`],
/// [`POLISH_MOVES_PER_LEVEL`]). Before the moves, a [`simplex`] whose first simplex is
/// `simplex_scale` × [`SIMPLEX_STEP`] wide. Every point scored is projected onto `volume`. Returns the
/// best, its score and the hypotheses scored.
///
/// # Errors
/// Whatever the evaluator returns.
pub fn polish<E: Evaluate>(
    eval: &mut E,
    best: Hypothesis,
    best_score: f64,
    pivot_m: Option<DVec3>,
    simplex_scale: f64,
    volume: &Volume,
) -> Result<(Hypothesis, f64, u64), E::Error> {
    let (b, sc, scored) = simplex(eval, best, best_score, SIMPLEX_EVALUATIONS, simplex_scale, volume)?;
    let (b, sc, moved) = descend(eval, b, sc, pivot_m, volume)?;
    Ok((b, sc, scored + moved))
}

/// The moves of [`polish`] from `best` (scoring `best_score`): returns the best, its score and the
/// hypotheses scored.
///
/// # Errors
/// Whatever the evaluator returns.
pub fn descend<E: Evaluate>(
    eval: &mut E,
    mut best: Hypothesis,
    mut best_score: f64,
    pivot_m: Option<DVec3>,
    volume: &Volume,
) -> Result<(Hypothesis, f64, u64), E::Error> {
    let mut scored = 0u64;
    let (mut step_m, mut step_deg) = POLISH_START_STEP;
    // Index of the strictly best score above `floor` (ties keep the current pose: deterministic, no
    // drifting on plateaus).
    let best_above = |s: &[f64], floor: f64| {
        s.iter().enumerate().fold(
            None,
            |acc: Option<(usize, f64)>, (i, &v)| {
                if v > acc.map_or(floor, |a| a.1) {
                    Some((i, v))
                } else {
                    acc
                }
            },
        )
    };
    for _level in 0..POLISH_LEVELS {
        for _ in 0..POLISH_MOVES_PER_LEVEL {
            let mut cand = moves(&best, step_m, step_deg, pivot_m);
            cand.iter_mut().for_each(|h| *h = volume.project(*h));
            let s = eval.evaluate(&cand)?;
            scored += cand.len() as u64;
            let Some((i, v)) = best_above(&s, best_score) else { break };
            let from = best;
            best = cand[i];
            best_score = v;
            // Pattern moves along the improving displacement.
            let (d, dyaw) = (best.centre_m - from.centre_m, best.yaw_deg - from.yaw_deg);
            loop {
                let pattern: Vec<Hypothesis> = [1.0, 3.0, 7.0]
                    .iter()
                    .map(|k| {
                        volume.project(Hypothesis {
                            centre_m: best.centre_m + d * *k,
                            yaw_deg: best.yaw_deg + dyaw * k,
                        })
                    })
                    .collect();
                let s = eval.evaluate(&pattern)?;
                scored += pattern.len() as u64;
                match best_above(&s, best_score) {
                    Some((j, v)) => {
                        best = pattern[j];
                        best_score = v;
                    }
                    None => break,
                }
            }
        }
        step_m *= 0.5;
        step_deg *= 0.5;
    }
    Ok((best, best_score, scored))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A smooth synthetic objective peaked at a known pose.
    struct Bowl {
        target: Hypothesis,
        calls: u64,
    }

    impl Evaluate for Bowl {
        type Error = std::convert::Infallible;
        fn evaluate(&mut self, hyps: &[Hypothesis]) -> Result<Vec<f64>, Self::Error> {
            self.calls += hyps.len() as u64;
            Ok(hyps
                .iter()
                .map(|h| {
                    let d2: f64 = (0..3).map(|k| (h.centre_m[k] - self.target.centre_m[k]).powi(2)).sum();
                    let dy = h.yaw_deg - self.target.yaw_deg;
                    (-d2 / 200.0 - dy * dy / 20.0).exp()
                })
                .collect())
        }
    }

    #[test]
    fn converges_from_a_perturbed_prior() {
        let target = Hypothesis { centre_m: DVec3::new(10.0, -5.0, 300.0), yaw_deg: 45.0 };
        let prior = Hypothesis { centre_m: DVec3::new(18.0, 2.0, 304.0), yaw_deg: 48.0 };
        let mut bowl = Bowl { target, calls: 0 };
        let mut coarse = Bowl { target, calls: 0 };
        let r = search(
            &mut coarse,
            &mut bowl,
            prior,
            &SearchOptions { stages: Stages::CoarseAndFine, ..Default::default() },
            7,
            None,
        )
        .unwrap();
        let dt: f64 = (0..3).map(|k| (r.best.centre_m[k] - target.centre_m[k]).powi(2)).sum::<f64>().sqrt();
        assert!(dt < 0.5, "translation error {dt} m");
        assert!((r.best.yaw_deg - target.yaw_deg).abs() < 0.3, "yaw {}", r.best.yaw_deg);
        let grid = coarse_grid(&prior, &CoarseParams::default()).len() as u64;
        // At least the grid and 20 iterations of one beam's 2 × 12 perturbations.
        assert!(r.hypotheses_scored >= grid + 20 * 24, "{}", r.hypotheses_scored);
        assert_eq!(coarse.calls + bowl.calls, r.hypotheses_scored);
    }

    /// A bowl whose optimum moves to `polish_target` when the polish's cost is entered: the bias of the
    /// filter's cost that the polish's cost does not share.
    struct ShiftingBowl {
        bowl: Bowl,
        polish_target: Hypothesis,
        entered_at: Option<Hypothesis>,
    }

    impl Evaluate for ShiftingBowl {
        type Error = std::convert::Infallible;
        fn evaluate(&mut self, hyps: &[Hypothesis]) -> Result<Vec<f64>, Self::Error> {
            self.bowl.evaluate(hyps)
        }
        fn enter_polish(&mut self, at: &Hypothesis, cost: &PolishCost) -> Result<(u64, bool), Self::Error> {
            self.entered_at = Some(*at);
            self.bowl.target = self.polish_target;
            Ok((3, cost.semantic_weight == 1.0))
        }
    }

    #[test]
    fn the_polish_refines_again_in_its_own_cost_from_the_filters_optimum() {
        let target = Hypothesis { centre_m: DVec3::new(10.0, -5.0, 300.0), yaw_deg: 45.0 };
        // 3 m along a diagonal: the axial bias of a coarse map's instance cost.
        let polish_target = Hypothesis { centre_m: DVec3::new(10.0, -3.0, 302.0), yaw_deg: 45.0 };
        let prior = Hypothesis { centre_m: DVec3::new(16.0, 0.0, 303.0), yaw_deg: 47.0 };
        let run = |polish_cost: PolishCost| {
            let mut coarse =
                ShiftingBowl { bowl: Bowl { target, calls: 0 }, polish_target, entered_at: None };
            let mut fine = ShiftingBowl { bowl: Bowl { target, calls: 0 }, polish_target, entered_at: None };
            let opts = SearchOptions {
                fine: FineParams { polish_cost, ..FineParams::default() },
                ..Default::default()
            };
            let r = search(&mut coarse, &mut fine, prior, &opts, 3, None).unwrap();
            assert_eq!(
                coarse.bowl.calls + fine.bowl.calls + 3,
                r.hypotheses_scored,
                "the fit's 3 are counted"
            );
            assert!(coarse.entered_at.is_none(), "the coarse evaluator never polishes");
            (r.best, fine.entered_at.expect("the polish's cost was entered"))
        };
        let dist = |a: &Hypothesis, b: &Hypothesis| a.centre_m.distance(b.centre_m);
        // Changed cost: entered at the filter's optimum (after the first pass), ends at the new one.
        let (best, entered) = run(PolishCost::default());
        assert!(dist(&entered, &target) < 0.1, "entered {:?}", entered.centre_m);
        assert!(dist(&best, &polish_target) < 0.1, "ended {:?}", best.centre_m);
        // Unchanged cost (the evaluator says so): one pass, the filter's optimum stands.
        let (best, _) = run(PolishCost {
            semantic_weight: 0.5,
            max_silhouette_offset_px: 0,
            spill_weight: 1.0,
            rim_tolerance: false,
        });
        assert!(dist(&best, &target) < 0.1, "ended {:?}", best.centre_m);
    }

    /// A narrow bump at the start and a higher, broader one at `far`: the polish's cost where
    /// the filter's optimum sits on a shallow local maximum of it.
    struct TwoBumps {
        far: Hypothesis,
    }

    impl Evaluate for TwoBumps {
        type Error = std::convert::Infallible;
        fn evaluate(&mut self, hyps: &[Hypothesis]) -> Result<Vec<f64>, Self::Error> {
            let bump = |h: &Hypothesis, at: &Hypothesis, height: f64, sigma_m: f64| {
                let d2 = h.centre_m.distance_squared(at.centre_m);
                let dy = (h.yaw_deg - at.yaw_deg) / 0.2;
                height * (-(d2 + dy * dy) / (2.0 * sigma_m * sigma_m)).exp()
            };
            let near = Hypothesis { centre_m: DVec3::new(0.0, 0.0, 200.0), yaw_deg: 0.0 };
            Ok(hyps.iter().map(|h| bump(h, &near, 0.9, 0.4).max(bump(h, &self.far, 1.0, 0.8))).collect())
        }
    }

    #[test]
    fn the_second_pass_simplex_straddles_a_shallow_ridge() {
        let start = Hypothesis { centre_m: DVec3::new(0.0, 0.0, 200.0), yaw_deg: 0.0 };
        // 2 m away, beyond a ridge where the cost falls to a third of the near bump.
        let far = Hypothesis { centre_m: DVec3::new(2.0, 0.3, 199.9), yaw_deg: 0.02 };
        let run = |scale: f64| {
            let mut e = TwoBumps { far };
            let s0 = e.evaluate(&[start]).unwrap()[0];
            polish(&mut e, start, s0, None, scale, &Volume::unbounded(start)).unwrap()
        };
        let (stuck, s_stuck, _) = run(1.0);
        assert!(stuck.centre_m.distance(start.centre_m) < 0.1, "1 m simplex left the near bump");
        assert!((s_stuck - 0.9).abs() < 1e-9, "{s_stuck}");
        let (best, s_best, _) = run(SECOND_PASS_SIMPLEX_SCALE);
        assert!(best.centre_m.distance(far.centre_m) < 0.05, "ended at {:?}", best.centre_m);
        assert!(s_best > 0.999, "{s_best}");
    }

    /// A narrow valley along a diagonal of x, z and yaw (the shape the simplex is for), which records
    /// its batches and can say it scores pairs in parallel.
    struct Valley {
        pairs: bool,
        batches: Vec<usize>,
        seen: Vec<Hypothesis>,
    }

    impl Evaluate for Valley {
        type Error = std::convert::Infallible;
        fn evaluate(&mut self, hyps: &[Hypothesis]) -> Result<Vec<f64>, Self::Error> {
            self.batches.push(hyps.len());
            self.seen.extend_from_slice(hyps);
            Ok(hyps
                .iter()
                .map(|h| {
                    let c = h.centre_m - DVec3::new(1.0, -0.5, 200.0);
                    let along = c.x + c.z + h.yaw_deg * 5.0;
                    let across = c.x - c.z;
                    (-along * along / 40.0 - across * across * 4.0 - c.y * c.y - h.yaw_deg * h.yaw_deg).exp()
                })
                .collect())
        }
        fn scores_pairs_in_parallel(&self) -> bool {
            self.pairs
        }
    }

    #[test]
    fn the_simplex_takes_the_same_course_when_it_scores_pairs() {
        let start = Hypothesis { centre_m: DVec3::new(-2.0, 0.5, 203.0), yaw_deg: 0.5 };
        let run = |pairs| {
            let mut v = Valley { pairs, batches: Vec::new(), seen: Vec::new() };
            let s0 = v.evaluate(&[start]).unwrap()[0];
            v.batches.clear();
            v.seen.clear();
            let r = simplex(&mut v, start, s0, SIMPLEX_EVALUATIONS, 1.0, &Volume::unbounded(start)).unwrap();
            (r, v)
        };
        let ((best, score, scored), plain) = run(false);
        let ((best2, score2, scored2), paired) = run(true);
        // The same course, bit for bit: every point the plain simplex scored, in its order, among the
        // paired one's.
        assert_eq!((best, score), (best2, score2));
        let mut rest = paired.seen.iter();
        assert!(plain.seen.iter().all(|p| rest.any(|q| q == p)), "a point scored out of order");
        assert!(score > 0.9, "did not climb into the valley: {score}");
        // Every score is counted; the paired simplex scored more points in fewer rounds.
        assert_eq!(scored, plain.seen.len() as u64);
        assert_eq!(scored2, paired.seen.len() as u64);
        assert!(plain.batches.iter().skip(1).all(|&b| b == 1 || b == 4), "{:?}", plain.batches);
        let pairs = paired.batches.iter().filter(|&&b| b == 2).count();
        assert!(pairs * 2 > paired.batches.len(), "{pairs} pairs in {} rounds", paired.batches.len());
        assert!(
            paired.batches.len() + 10 < plain.batches.len(),
            "{} vs {}",
            paired.batches.len(),
            plain.batches.len()
        );
        assert!(scored2 > scored);
    }

    #[test]
    fn deterministic_for_a_seed() {
        let target = Hypothesis { centre_m: DVec3::new(0.0, 0.0, 200.0), yaw_deg: 0.0 };
        let prior = Hypothesis { centre_m: DVec3::new(3.0, 3.0, 203.0), yaw_deg: 1.0 };
        let run = |seed| {
            let b = || Bowl { target, calls: 0 };
            search(
                &mut b(),
                &mut b(),
                prior,
                &SearchOptions { stages: Stages::FineOnly, ..Default::default() },
                seed,
                None,
            )
            .unwrap()
        };
        // Everything but the wall-clock seconds.
        let key = |r: SearchResult| (r.best, r.best_score, r.coarse_best, r.hypotheses_scored);
        assert_eq!(key(run(1)), key(run(1)));
        assert_ne!(run(1).best, run(2).best);
    }

    #[test]
    fn ablations() {
        let target = Hypothesis { centre_m: DVec3::new(0.0, 0.0, 200.0), yaw_deg: 0.0 };
        let prior = Hypothesis { centre_m: DVec3::new(9.0, 0.0, 200.0), yaw_deg: 0.0 };
        let b = || Bowl { target, calls: 0 };
        let r = search(
            &mut b(),
            &mut b(),
            prior,
            &SearchOptions { stages: Stages::CoarseOnly, ..Default::default() },
            0,
            None,
        )
        .unwrap();
        // No refine: the coarse best is on the 5 m grid: x = 9 − 10 = −1.
        assert_eq!(r.best, r.coarse_best);
        assert!((r.best.centre_m[0] + 1.0).abs() < 1e-12, "{:?}", r.best);
        let r = search(
            &mut b(),
            &mut b(),
            prior,
            &SearchOptions { stages: Stages::FineOnly, ..Default::default() },
            0,
            None,
        )
        .unwrap();
        assert_eq!(r.coarse_best, prior);
    }

    #[test]
    fn low_resolution_until_the_decay_reaches_its_floor() {
        assert_eq!(FineParams::default().lowres_iterations(), 14);
        let d = FineParams::paper();
        assert_eq!(d.lowres_iterations(), 28);
        // s = max(0.3, (40 − i)/40) is 0.3 from i = 28 on, and above it at i = 27.
        let s = |i: u32| d.gamma.max((d.iterations - i) as f64 / d.iterations as f64);
        assert!(s(27) > d.gamma && s(28) == d.gamma);
        assert_eq!(FineParams { iterations: 10, ..d.clone() }.lowres_iterations(), 7);
        assert_eq!(FineParams { lowres_iterations: Some(50), ..d.clone() }.lowres_iterations(), 40);
        assert_eq!(FineParams { lowres_iterations: Some(0), ..d }.lowres_iterations(), 0);
    }

    /// Two basins: a wide one that wins at the coarse resolution and a narrow one, the true optimum,
    /// that wins at the fine resolution (issue 15: the ground truth scored better than the estimate).
    struct TwoBasins {
        fine: bool,
    }

    /// A Gaussian bump of the cost around (x, 0, 200) m and yaw 0, `width_m` wide.
    fn bump(h: &Hypothesis, x: f64, width_m: f64) -> f64 {
        bump_at(h, x, 0.0, width_m)
    }

    /// A Gaussian bump of the cost around (x, y, 200) m and yaw 0, `width_m` wide.
    fn bump_at(h: &Hypothesis, x: f64, y: f64, width_m: f64) -> f64 {
        let d2 = (h.centre_m[0] - x).powi(2) + (h.centre_m[1] - y).powi(2) + (h.centre_m[2] - 200.0).powi(2);
        (-d2 / (2.0 * width_m * width_m) - h.yaw_deg * h.yaw_deg / 20.0).exp()
    }

    /// Four wide decoys 21 m from the prior that score 0.9 at both resolutions, and the truth's narrow
    /// basin at the prior, which scores 0.6 at the coarse resolution (below all four) and 1.0 at the
    /// fine one: a cost whose coarse renders are noisy.
    struct DecoysAroundThePrior {
        fine: bool,
    }

    impl Evaluate for DecoysAroundThePrior {
        type Error = std::convert::Infallible;
        fn evaluate(&mut self, hyps: &[Hypothesis]) -> Result<Vec<f64>, Self::Error> {
            let truth = if self.fine { 1.0 } else { 0.6 };
            let decoys = [(15.0, 15.0), (-15.0, 15.0), (15.0, -15.0), (-15.0, -15.0)];
            Ok(hyps
                .iter()
                .map(|h| {
                    let decoy = decoys.iter().map(|&(x, y)| 0.9 * bump_at(h, x, y, 6.0)).fold(0.0, f64::max);
                    decoy.max(truth * bump_at(h, 0.0, 0.0, 1.5))
                })
                .collect())
        }
    }

    fn with_prior_basin(prior_basin: bool) -> SearchOptions {
        let beams_mode = BeamMode::Basins { count: 4, survivors: 1, prune: Some(DEFAULT_PRUNE), prior_basin };
        SearchOptions { fine: FineParams { beams_mode, ..FineParams::default() }, ..Default::default() }
    }

    #[test]
    fn the_prior_basin_is_refined_where_the_coarse_ranking_misses_it() {
        let prior = Hypothesis { centre_m: DVec3::new(0.0, 0.0, 200.0), yaw_deg: 0.0 };
        let run = |prior_basin: bool| {
            let (mut coarse, mut fine) =
                (DecoysAroundThePrior { fine: false }, DecoysAroundThePrior { fine: true });
            search(&mut coarse, &mut fine, prior, &with_prior_basin(prior_basin), 3, None).unwrap()
        };
        // The coarse grid's four best basins are the decoys; without the prior's, the truth is lost.
        let without = run(false);
        assert!(without.coarse_best.centre_m.distance(prior.centre_m) > 20.0, "{:?}", without.coarse_best);
        assert!(without.best.centre_m.distance(prior.centre_m) > 15.0, "{:?}", without.best);
        assert!(without.best_score < 0.95, "{}", without.best_score);
        // With it, the fine resolution judges the prior's basin best.
        let with = run(true);
        assert_eq!(with.coarse_best, without.coarse_best);
        assert!(with.best.centre_m.distance(prior.centre_m) < 0.5, "{:?}", with.best);
        assert!(with.best_score > 0.95 && !with.on_boundary, "{with:?}");
        assert!(with.hypotheses_scored > without.hypotheses_scored);
    }

    #[test]
    fn a_prior_already_next_to_a_basin_adds_no_beam() {
        // The truth's wide basin at the prior wins at both resolutions: the prior's cell is the first
        // basin's, and the search is the same bit for bit with or without the flag.
        struct AtThePrior;
        impl Evaluate for AtThePrior {
            type Error = std::convert::Infallible;
            fn evaluate(&mut self, hyps: &[Hypothesis]) -> Result<Vec<f64>, Self::Error> {
                Ok(hyps
                    .iter()
                    .map(|h| bump_at(h, 1.0, -1.0, 6.0).max(0.8 * bump_at(h, -15.0, 15.0, 3.0)))
                    .collect())
            }
        }
        let prior = Hypothesis { centre_m: DVec3::new(0.0, 0.0, 200.0), yaw_deg: 0.0 };
        // Timings aside (the stages' seconds).
        let run = |b: bool| {
            let r = search(&mut AtThePrior, &mut AtThePrior, prior, &with_prior_basin(b), 3, None).unwrap();
            (r.best, r.best_score, r.hypotheses_scored)
        };
        assert_eq!(run(true), run(false));
        assert!(run(true).0.centre_m.distance(DVec3::new(1.0, -1.0, 200.0)) < 0.2, "{:?}", run(true));
    }

    impl Evaluate for TwoBasins {
        type Error = std::convert::Infallible;
        fn evaluate(&mut self, hyps: &[Hypothesis]) -> Result<Vec<f64>, Self::Error> {
            let true_height = if self.fine { 1.0 } else { 0.8 };
            Ok(hyps
                .iter()
                .map(|h| (0.9 * bump(h, 10.0, 8.0)).max(true_height * bump(h, -10.0, 2.0)))
                .collect())
        }
    }

    #[test]
    fn distinct_basins_find_the_optimum_the_joint_beams_miss() {
        let prior = Hypothesis { centre_m: DVec3::new(0.0, 0.0, 200.0), yaw_deg: 0.0 };
        let run = |fine: FineParams| {
            let opts = SearchOptions { fine, ..Default::default() };
            search(&mut TwoBasins { fine: false }, &mut TwoBasins { fine: true }, prior, &opts, 3, None)
                .unwrap()
        };
        // The paper's joint beams collapse into the basin that wins at the coarse resolution.
        let joint = run(FineParams::paper());
        assert!((joint.best.centre_m[0] - 10.0).abs() < 2.0, "{:?}", joint.best);
        assert!(joint.best_score < 0.95);
        // Distinct basins keep the narrow one until the fine resolution judges it.
        let basins = run(FineParams::default());
        assert!((basins.best.centre_m[0] + 10.0).abs() < 0.5, "{:?}", basins.best);
        assert!(basins.best_score > 0.95, "{}", basins.best_score);
    }

    #[test]
    fn early_judgement_keeps_the_fine_optimum_for_fewer_hypotheses() {
        let prior = Hypothesis { centre_m: DVec3::new(0.0, 0.0, 200.0), yaw_deg: 0.0 };
        let run = |prune: Option<Prune>| {
            let fine = FineParams {
                beams_mode: BeamMode::Basins { count: 4, survivors: 1, prune, prior_basin: false },
                ..FineParams::default()
            };
            let opts = SearchOptions { fine, ..Default::default() };
            search(&mut TwoBasins { fine: false }, &mut TwoBasins { fine: true }, prior, &opts, 3, None)
                .unwrap()
        };
        let all = run(None);
        let pruned = run(Some(DEFAULT_PRUNE));
        for r in [&all, &pruned] {
            assert!((r.best.centre_m[0] + 10.0).abs() < 0.5, "{:?}", r.best);
        }
        // 4 beams × 14 coarse-width iterations against 4 × 5 + 2 × 9, of 2 × 12 perturbations each;
        // the judgement at the switch sees 2 beams of 2 poses instead of 4, the early one 4.
        let f = |r: &SearchResult| r.stages.filter_coarse_width.hypotheses;
        assert_eq!(f(&all) - f(&pruned), 18 * 24);
        assert_eq!(
            pruned.stages.filter_render_width.hypotheses,
            all.stages.filter_render_width.hypotheses - 2 * 2 + 4 * 2
        );
    }

    #[test]
    fn basins_are_no_grid_neighbours_of_a_better_cell() {
        let prior = Hypothesis { centre_m: DVec3::new(0.0, 0.0, 200.0), yaw_deg: 0.0 };
        let p = CoarseParams::default();
        let grid = coarse_grid(&prior, &p);
        let scores = TwoBasins { fine: false }.evaluate(&grid).unwrap();
        let ranked = rank(grid.into_iter().zip(scores).collect());
        let seeds = distinct_basins(&ranked, &p, 4);
        assert_eq!(seeds.len(), 4);
        assert_eq!(seeds[0].centre_m[0], 10.0);
        assert!(seeds.iter().any(|h| h.centre_m[0] == -10.0 && h.yaw_deg == 0.0), "{seeds:?}");
        for (i, a) in seeds.iter().enumerate() {
            for b in &seeds[..i] {
                assert!(!neighbours(a, b, &p), "{a:?} next to {b:?}");
            }
        }
    }

    #[test]
    fn default_fine_stage_has_52_candidates() {
        assert_eq!(FineParams::default().candidates_per_iteration(), 52);
    }

    mod bounds {
        use super::*;

        /// A degenerate cost: the higher the closer to `far`, everywhere (a ramp, no local optimum
        /// near the prior); it records every hypothesis scored.
        struct Ramp {
            far: Hypothesis,
            seen: Vec<Hypothesis>,
        }

        impl Evaluate for Ramp {
            type Error = std::convert::Infallible;
            fn evaluate(&mut self, hyps: &[Hypothesis]) -> Result<Vec<f64>, Self::Error> {
                self.seen.extend_from_slice(hyps);
                Ok(hyps
                    .iter()
                    .map(|h| -h.centre_m.distance(self.far.centre_m) - (h.yaw_deg - self.far.yaw_deg).abs())
                    .collect())
            }
        }

        /// No bounds: every pose inside.
        fn unbounded() -> SearchBounds {
            let inf = f64::INFINITY;
            SearchBounds { radius_m: inf, height_m: inf, yaw_deg: inf, origin: "unbounded".into() }
        }

        fn prior() -> Hypothesis {
            Hypothesis { centre_m: DVec3::new(100.0, -50.0, 300.0), yaw_deg: 30.0 }
        }

        #[test]
        fn default_bounds_come_from_the_default_prior_noise() {
            let b = SearchBounds::default();
            // 4.4 × 7 m, 4 × 5 m, 4 × 3° (PriorNoise::default, by hand).
            assert!((b.radius_m - 4.4 * 7.0).abs() < 1e-9, "{}", b.radius_m);
            assert_eq!((b.height_m, b.yaw_deg), (20.0, 12.0));
            assert!(b.validate().is_ok());
            // The default coarse grid (corners at √(20² + 20²) = 28.3 m, ±10 m, ±7.5°) lies inside.
            let v = b.around(prior());
            assert!(coarse_grid(&prior(), &CoarseParams::default()).iter().all(|h| v.contains(h)));
            // A bias widens them; the noisier horizontal axis sets the radius; an exact prior gets
            // the floors.
            let biased = PriorNoise {
                sigma_enu_m: [7.0, 3.0, 5.0],
                bias_enu_m: [3.0, 4.0, -2.0],
                bias_ypr_deg: [-1.0, 0.0, 0.0],
                ..PriorNoise::default()
            };
            let b = SearchBounds::from_prior_noise(&biased, "test");
            assert!((b.radius_m - 5.0 - 4.4 * 7.0).abs() < 1e-9, "{}", b.radius_m);
            assert_eq!((b.height_m, b.yaw_deg), (22.0, 13.0));
            assert!(b.origin.starts_with("4.4σ horizontally, 4σ in height and yaw of test"), "{}", b.origin);
            let exact =
                PriorNoise { sigma_enu_m: [0.0; 3], sigma_ypr_deg: [0.0; 3], ..PriorNoise::default() };
            let b = SearchBounds::from_prior_noise(&exact, "test");
            assert_eq!((b.radius_m, b.height_m, b.yaw_deg), MIN_SEARCH_BOUNDS);
        }

        #[test]
        fn the_coarse_grid_scales_with_the_prior_noise_in_whole_steps() {
            let range = |p: &CoarseParams| {
                (p.xy_range_m, p.xy_step_m, p.z_range_m, p.z_step_m, p.yaw_range_deg, p.yaw_step_deg)
            };
            // The default model (σ = 7, 7, 5 m, 3°): 2.5 × 7 = 17.5 → 20 m, 2 × 5 = 10 m, 2.5 × 3 = 7.5°.
            let d = CoarseParams::default();
            assert_eq!(range(&d), (20.0, 5.0, 10.0, 5.0, 7.5, 2.5));
            assert_eq!((d.cells(), coarse_grid(&prior(), &d).len()), (2835, 2835));
            let l = CoarseParams { xy_range_m: 35.0, z_range_m: 0.0, yaw_range_deg: 15.0, ..d.clone() };
            assert_eq!(l.cells(), coarse_grid(&prior(), &l).len() as u64);
            // Counted, not built: a prior without any position (σ = 10⁹ m) is no allocation.
            let huge = PriorNoise { sigma_enu_m: [1e9; 3], ..PriorNoise::default() };
            let h = CoarseParams::from_prior_noise(&huge, &SearchBounds::from_prior_noise(&huge, "test"));
            assert!(h.cells() > MAX_COARSE_CELLS, "{}", h.cells());
            // Twice as noisy: 35 m, 20 m, 15° (inside its own bounds: 61.6 m, 40 m, 24°).
            let loose = PriorNoise {
                sigma_enu_m: [14.0, 9.0, 10.0],
                sigma_ypr_deg: [6.0, 0.02, 0.02],
                ..PriorNoise::default()
            };
            let lb = SearchBounds::from_prior_noise(&loose, "test");
            let l = CoarseParams::from_prior_noise(&loose, &lb);
            assert_eq!(range(&l), (35.0, 5.0, 20.0, 5.0, 15.0, 2.5));
            assert_eq!(l.cells(), 15 * 15 * 9 * 13);
            // A bias widens the grid by its size (3-4-5 m east/north, 2 m down, 1° in yaw).
            let biased = PriorNoise {
                bias_enu_m: [3.0, -4.0, -2.0],
                bias_ypr_deg: [1.0, 0.0, 0.0],
                ..PriorNoise::default()
            };
            let b = CoarseParams::from_prior_noise(&biased, &SearchBounds::from_prior_noise(&biased, "test"));
            assert_eq!(range(&b), (25.0, 5.0, 15.0, 5.0, 10.0, 2.5));
            // A nearly exact prior (or one with NaNs) still gets one step each way.
            for sigma in [0.3, f64::NAN] {
                let tight = PriorNoise {
                    sigma_enu_m: [sigma; 3],
                    sigma_ypr_deg: [sigma; 3],
                    ..PriorNoise::default()
                };
                let t =
                    CoarseParams::from_prior_noise(&tight, &SearchBounds::from_prior_noise(&tight, "test"));
                assert_eq!(range(&t), (5.0, 5.0, 5.0, 5.0, 2.5, 2.5), "σ {sigma}");
                assert_eq!(t.cells(), 81);
            }
            // Narrower bounds (the --search-* flags) cap the grid at whole steps covering them.
            let narrow = SearchBounds { radius_m: 12.0, height_m: 5.0, yaw_deg: 4.0, origin: "flags".into() };
            let n = CoarseParams::from_prior_noise(&PriorNoise::default(), &narrow);
            assert_eq!(range(&n), (15.0, 5.0, 5.0, 5.0, 5.0, 2.5));
        }

        /// A broad decoy at the prior and the truth's narrow basin 30 m east of it, at the default
        /// height and yaw.
        struct FarTruth;

        impl Evaluate for FarTruth {
            type Error = std::convert::Infallible;
            fn evaluate(&mut self, hyps: &[Hypothesis]) -> Result<Vec<f64>, Self::Error> {
                Ok(hyps.iter().map(|h| (0.6 * bump(h, 0.0, 6.0)).max(bump(h, 30.0, 2.5))).collect())
            }
        }

        #[test]
        fn a_noisy_priors_grid_reaches_the_truth_the_fixed_grid_missed() {
            // σ = 14 m east/north: a truth 30 m off is a 2.1σ error, inside the derived grid (±35 m)
            // and the volume (61.6 m), outside the grid the default model gives (±20 m).
            let loose = PriorNoise {
                sigma_enu_m: [14.0, 14.0, 10.0],
                sigma_ypr_deg: [6.0, 0.02, 0.02],
                ..PriorNoise::default()
            };
            let bounds = SearchBounds::from_prior_noise(&loose, "test");
            let prior = Hypothesis { centre_m: DVec3::new(0.0, 0.0, 200.0), yaw_deg: 0.0 };
            let run = |coarse: CoarseParams| {
                let opts = SearchOptions { coarse, bounds: bounds.clone(), ..Default::default() };
                search(&mut FarTruth, &mut FarTruth, prior, &opts, 5, None).unwrap()
            };
            let fixed = run(CoarseParams::default());
            assert!(fixed.best.centre_m[0].abs() < 3.0, "the decoy: {:?}", fixed.best);
            let derived = run(CoarseParams::from_prior_noise(&loose, &bounds));
            assert!((derived.best.centre_m[0] - 30.0).abs() < 0.5, "the truth: {:?}", derived.best);
            assert!(derived.best_score > 0.95 && !derived.on_boundary, "{derived:?}");
        }

        #[test]
        fn the_horizontal_radius_holds_the_prior_as_often_as_4_sigma_along_one_axis() {
            // P(|x| > 4σ) for a normal x, by Simpson's rule over [4, 12] (the rest is < 10⁻³²).
            let pdf = |x: f64| (-x * x / 2.0).exp() / (2.0 * std::f64::consts::PI).sqrt();
            let (a, n) = (PRIOR_SIGMA_MULTIPLE, 8000);
            let h = (12.0 - a) / n as f64;
            let simpson: f64 = (0..=n)
                .map(|i| {
                    let w = if i == 0 || i == n {
                        1.0
                    } else if i % 2 == 1 {
                        4.0
                    } else {
                        2.0
                    };
                    w * pdf(a + i as f64 * h)
                })
                .sum::<f64>()
                * h
                / 3.0;
            let tail = 2.0 * simpson;
            assert!((tail - 6.334e-5).abs() < 1e-7, "{tail}");
            // An isotropic horizontal error leaves the radius rσ with probability exp(−r²/2).
            let r = (-2.0 * tail.ln()).sqrt();
            assert!((HORIZONTAL_SIGMA_MULTIPLE - r).abs() < 0.005, "{r}");
        }

        #[test]
        fn projection_keeps_inside_poses_and_moves_outside_ones_onto_the_boundary() {
            let v = SearchBounds { radius_m: 10.0, height_m: 5.0, yaw_deg: 2.0, origin: String::new() }
                .around(prior());
            let inside = Hypothesis { centre_m: DVec3::new(103.0, -46.0, 301.0), yaw_deg: 31.0 };
            assert_eq!(v.project(inside), inside);
            assert!(!v.on_boundary(&inside));
            // 30 m east, 20 m up, 10° of yaw: onto 10 m east, 5 m up, 2°.
            let out = Hypothesis { centre_m: DVec3::new(130.0, -50.0, 320.0), yaw_deg: 40.0 };
            let p = v.project(out);
            assert!(p.centre_m.distance(DVec3::new(110.0, -50.0, 305.0)) < 1e-6, "{p:?}");
            assert!((p.yaw_deg - 32.0).abs() < 1e-6);
            assert!(v.contains(&p) && v.on_boundary(&p));
            // NaN coordinates become the prior's, and count as on the boundary.
            let nan = Hypothesis { centre_m: DVec3::new(f64::NAN, 0.0, f64::NAN), yaw_deg: f64::NAN };
            let p = v.project(nan);
            assert_eq!(p, prior());
            assert!(v.on_boundary(&nan));
            let bad = SearchBounds { radius_m: 0.0, ..SearchBounds::default() };
            assert!(bad.validate().unwrap_err().to_string().contains("radius 0"));
            assert!(SearchBounds { yaw_deg: 200.0, ..SearchBounds::default() }.validate().is_err());
        }

        /// Issue 40: a cost whose optimum lies 300 m from the prior pulls no stage out of the volume;
        /// the best pose ends on its boundary, flagged (reported as found with
        /// [`OnBoundary::Keep`]; the prior is reported by default, see the next test).
        #[test]
        fn issue_40_a_degenerate_optimum_300_m_away_cannot_pull_the_estimate_out() {
            let far = Hypothesis { centre_m: DVec3::new(400.0, -50.0, 300.0), yaw_deg: 30.0 };
            let keep = OnBoundary::Keep;
            let modes = [
                SearchOptions { on_boundary: keep, ..Default::default() },
                SearchOptions { fine: FineParams::paper(), on_boundary: keep, ..Default::default() },
                SearchOptions { stages: Stages::FineOnly, on_boundary: keep, ..Default::default() },
                SearchOptions { stages: Stages::CoarseOnly, on_boundary: keep, ..Default::default() },
            ];
            for opts in modes {
                let (mut coarse, mut fine) = (Ramp { far, seen: Vec::new() }, Ramp { far, seen: Vec::new() });
                let r = search(&mut coarse, &mut fine, prior(), &opts, 5, None).unwrap();
                let v = opts.bounds.around(prior());
                let outside = coarse.seen.iter().chain(&fine.seen).filter(|h| !v.contains(h)).count();
                assert_eq!(outside, 0, "{:?}: hypotheses scored outside the volume", opts.stages);
                assert!(v.contains(&r.best), "{:?}", r.best);
                // The coarse grid alone ends at its own edge, inside the volume.
                let coarse_only = opts.stages == Stages::CoarseOnly;
                assert_eq!(r.on_boundary, !coarse_only, "{:?}: flag at {:?}", opts.stages, r.best);
                assert!(!r.kept_prior);
                // Towards the optimum: east, at the full radius (the coarse grid's edge at 20 m alone).
                let reach_m = if opts.stages == Stages::CoarseOnly { 20.0 } else { v.radius_m };
                assert!((r.best.centre_m.x - prior().centre_m.x - reach_m).abs() < 0.5, "{:?}", r.best);
            }
            // Unbounded, the same search follows the ramp out of the volume.
            let opts = SearchOptions { bounds: unbounded(), ..Default::default() };
            let r = search(
                &mut Ramp { far, seen: Vec::new() },
                &mut Ramp { far, seen: Vec::new() },
                prior(),
                &opts,
                5,
                None,
            )
            .unwrap();
            assert!(
                r.best.centre_m.distance(prior().centre_m) > SearchBounds::default().radius_m,
                "{:?}",
                r.best
            );
        }

        /// By default a best pose on the boundary is not reported: the prior is, with its score, and
        /// the query is flagged; a search whose best lies inside is untouched (previous test, and
        /// the next).
        #[test]
        fn a_best_pose_on_the_boundary_reports_the_prior() {
            let far = Hypothesis { centre_m: DVec3::new(400.0, -50.0, 300.0), yaw_deg: 30.0 };
            for fine in [FineParams::default(), FineParams::paper()] {
                let opts = SearchOptions { fine, ..Default::default() };
                let (mut coarse, mut eval) = (Ramp { far, seen: Vec::new() }, Ramp { far, seen: Vec::new() });
                let r = search(&mut coarse, &mut eval, prior(), &opts, 5, None).unwrap();
                assert!(r.on_boundary && r.kept_prior, "{r:?}");
                assert_eq!(r.best, prior());
                assert_eq!(r.best_score, Ramp { far, seen: Vec::new() }.evaluate(&[prior()]).unwrap()[0]);
                // The coarse stage's best is still what the grid found (towards the optimum).
                assert!(r.coarse_best.centre_m.x > prior().centre_m.x + 10.0, "{:?}", r.coarse_best);
            }
        }

        #[test]
        fn a_cost_whose_optimum_lies_well_inside_runs_as_if_unbounded() {
            let target = Hypothesis { centre_m: DVec3::new(110.0, -55.0, 296.0), yaw_deg: 33.0 };
            for stages in [Stages::CoarseAndFine, Stages::FineOnly] {
                let run = |bounds: SearchBounds| {
                    let opts = SearchOptions { stages, bounds, ..Default::default() };
                    let b = || Bowl { target, calls: 0 };
                    search(&mut b(), &mut b(), prior(), &opts, 11, None).unwrap()
                };
                let (bounded, free) = (run(SearchBounds::default()), run(unbounded()));
                let key = |r: &SearchResult| (r.best, r.best_score, r.coarse_best, r.hypotheses_scored);
                assert_eq!(key(&bounded), key(&free), "{stages:?}");
                assert!(!bounded.on_boundary && !bounded.kept_prior);
                assert!(bounded.best.centre_m.distance(target.centre_m) < 0.5, "{:?}", bounded.best);
            }
        }
    }
}
