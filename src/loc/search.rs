//! The 4-DoF pose search: a coarse grid around the prior, then the particle-filter refinement of the
//! LoD-Loc v2/v3 framework (parameters as in ../shared/SPEC.md). Pitch and roll come from the prior
//! (the IMU gives gravity); x, y, z and yaw are searched.
//!
//! The search is generic over an [`Evaluate`] implementation that scores a batch of poses (higher is
//! better), so the renderer, the cost and the search are tested separately. It is deterministic for a
//! given seed.

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};
use serde::{Deserialize, Serialize};

use crate::camera::Pose;

/// A 4-DoF hypothesis: camera centre (ENU metres) and yaw (degrees); pitch/roll are fixed per query.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Hypothesis {
    pub centre_m: [f64; 3],
    pub yaw_deg: f64,
}

impl Hypothesis {
    pub fn pose(&self, pitch_deg: f64, roll_deg: f64) -> Pose {
        Pose::from_ypr_deg(self.yaw_deg, pitch_deg, roll_deg, self.centre_m)
    }
}

/// Scores batches of hypotheses (higher is better).
pub trait Evaluate {
    type Error;
    fn evaluate(&mut self, hyps: &[Hypothesis]) -> Result<Vec<f64>, Self::Error>;
}

/// The coarse grid, centred on the prior: ± range in steps (both ends included).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct CoarseParams {
    pub xy_range_m: f64,
    pub xy_step_m: f64,
    pub z_range_m: f64,
    pub z_step_m: f64,
    pub yaw_range_deg: f64,
    pub yaw_step_deg: f64,
}

impl Default for CoarseParams {
    /// Covers the default prior noise model (σ ≈ 6 m horizontal, 3 m vertical, 2° yaw) to about 2.5σ.
    fn default() -> Self {
        CoarseParams {
            xy_range_m: 15.0,
            xy_step_m: 5.0,
            z_range_m: 8.0,
            z_step_m: 4.0,
            yaw_range_deg: 4.0,
            yaw_step_deg: 2.0,
        }
    }
}

/// The particle-filter refinement (paper / public code values as defaults).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct FineParams {
    pub iterations: u32,
    pub beams: u32,
    /// Best poses kept per beam.
    pub keep_per_beam: u32,
    /// Perturbations drawn around each kept pose per iteration.
    pub perturbations: u32,
    pub sigma_m: f64,
    pub yaw_deg: f64,
    pub gamma: f64,
}

impl Default for FineParams {
    fn default() -> Self {
        // 2 beams × (2 kept + 2 × 12 perturbations) = 52 candidates per iteration.
        FineParams {
            iterations: 40,
            beams: 2,
            keep_per_beam: 2,
            perturbations: 12,
            sigma_m: 1.5,
            yaw_deg: 2.0,
            gamma: 0.3,
        }
    }
}

impl FineParams {
    /// Candidates per iteration (kept + perturbed, all beams).
    pub fn candidates_per_iteration(&self) -> u32 {
        self.beams * self.keep_per_beam * (1 + self.perturbations)
    }
}

/// What the search found.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SearchResult {
    pub best: Hypothesis,
    pub best_score: f64,
    /// The coarse stage's best (equal to the prior with `--no-select`).
    pub coarse_best: Hypothesis,
    pub coarse_score: f64,
    pub hypotheses_scored: u64,
}

fn steps(range: f64, step: f64) -> Vec<f64> {
    if step <= 0.0 || range <= 0.0 {
        return vec![0.0];
    }
    let n = (range / step).round() as i64;
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
                        centre_m: [prior.centre_m[0] + dx, prior.centre_m[1] + dy, prior.centre_m[2] + dz],
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

/// Runs the search. `select = false` skips the coarse stage (fine stage from the raw prior);
/// `refine = false` returns the coarse result. The coarse stage scores with `coarse_eval` (typically
/// at a lower resolution), the fine stage with `eval`.
///
/// # Errors
/// Whatever the evaluators return.
#[allow(clippy::too_many_arguments)]
pub fn search<E: Evaluate>(
    coarse_eval: &mut E,
    eval: &mut E,
    prior: Hypothesis,
    coarse: &CoarseParams,
    fine: &FineParams,
    select: bool,
    refine: bool,
    seed: u64,
) -> Result<SearchResult, E::Error> {
    let mut scored_count = 0u64;
    let keep = (fine.beams * fine.keep_per_beam).max(1) as usize;
    // Coarse stage.
    let mut pool: Vec<(Hypothesis, f64)> = if select {
        let grid = coarse_grid(&prior, coarse);
        let s = coarse_eval.evaluate(&grid)?;
        scored_count += grid.len() as u64;
        rank(grid.into_iter().zip(s).collect())
    } else {
        let s = coarse_eval.evaluate(&[prior])?;
        scored_count += 1;
        vec![(prior, s[0])]
    };
    let (coarse_best, coarse_score) = pool[0];
    if !refine {
        return Ok(SearchResult {
            best: coarse_best,
            best_score: coarse_score,
            coarse_best,
            coarse_score,
            hypotheses_scored: scored_count,
        });
    }
    pool.truncate(keep);
    while pool.len() < keep {
        pool.push(pool[0]);
    }
    // Fine stage.
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let unit = Normal::new(0.0, 1.0).expect("σ = 1 is valid");
    let n_iter = fine.iterations.max(1);
    for i in 0..n_iter {
        let s = fine.gamma.max((n_iter - i) as f64 / n_iter as f64);
        let mut fresh: Vec<Hypothesis> = Vec::new();
        for &(h, _) in &pool {
            for _ in 0..fine.perturbations {
                fresh.push(Hypothesis {
                    centre_m: [
                        h.centre_m[0] + fine.sigma_m * s * unit.sample(&mut rng),
                        h.centre_m[1] + fine.sigma_m * s * unit.sample(&mut rng),
                        h.centre_m[2] + fine.sigma_m * s * unit.sample(&mut rng),
                    ],
                    yaw_deg: h.yaw_deg + rng.gen_range(-1.0..=1.0) * fine.yaw_deg * s,
                });
            }
        }
        let scores = eval.evaluate(&fresh)?;
        scored_count += fresh.len() as u64;
        let mut all = pool.clone();
        all.extend(fresh.into_iter().zip(scores));
        // Re-rank across beams; the best `keep` seed the next iteration (beam b gets ranks
        // b·keep_per_beam … (b+1)·keep_per_beam − 1).
        pool = rank(all);
        pool.truncate(keep);
    }
    let (best, best_score) = pool[0];
    Ok(SearchResult { best, best_score, coarse_best, coarse_score, hypotheses_scored: scored_count })
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
        let target = Hypothesis { centre_m: [10.0, -5.0, 300.0], yaw_deg: 45.0 };
        let prior = Hypothesis { centre_m: [18.0, 2.0, 304.0], yaw_deg: 48.0 };
        let mut bowl = Bowl { target, calls: 0 };
        let mut coarse = Bowl { target, calls: 0 };
        let r = search(
            &mut coarse,
            &mut bowl,
            prior,
            &CoarseParams::default(),
            &FineParams::default(),
            true,
            true,
            7,
        )
        .unwrap();
        let dt: f64 = (0..3).map(|k| (r.best.centre_m[k] - target.centre_m[k]).powi(2)).sum::<f64>().sqrt();
        assert!(dt < 0.5, "translation error {dt} m");
        assert!((r.best.yaw_deg - target.yaw_deg).abs() < 0.3, "yaw {}", r.best.yaw_deg);
        let grid = coarse_grid(&prior, &CoarseParams::default()).len() as u64;
        assert_eq!(r.hypotheses_scored, grid + 40 * 48);
        assert_eq!(coarse.calls + bowl.calls, r.hypotheses_scored);
    }

    #[test]
    fn deterministic_for_a_seed() {
        let target = Hypothesis { centre_m: [0.0, 0.0, 200.0], yaw_deg: 0.0 };
        let prior = Hypothesis { centre_m: [3.0, 3.0, 203.0], yaw_deg: 1.0 };
        let run = |seed| {
            let b = || Bowl { target, calls: 0 };
            search(
                &mut b(),
                &mut b(),
                prior,
                &CoarseParams::default(),
                &FineParams::default(),
                false,
                true,
                seed,
            )
            .unwrap()
        };
        assert_eq!(run(1), run(1));
        assert_ne!(run(1).best, run(2).best);
    }

    #[test]
    fn ablations() {
        let target = Hypothesis { centre_m: [0.0, 0.0, 200.0], yaw_deg: 0.0 };
        let prior = Hypothesis { centre_m: [9.0, 0.0, 200.0], yaw_deg: 0.0 };
        let b = || Bowl { target, calls: 0 };
        let r = search(
            &mut b(),
            &mut b(),
            prior,
            &CoarseParams::default(),
            &FineParams::default(),
            true,
            false,
            0,
        )
        .unwrap();
        // No refine: the coarse best is on the 5 m grid: x = 9 − 10 = −1.
        assert_eq!(r.best, r.coarse_best);
        assert!((r.best.centre_m[0] + 1.0).abs() < 1e-12, "{:?}", r.best);
        let r = search(
            &mut b(),
            &mut b(),
            prior,
            &CoarseParams::default(),
            &FineParams::default(),
            false,
            true,
            0,
        )
        .unwrap();
        assert_eq!(r.coarse_best, prior);
    }

    #[test]
    fn default_fine_stage_has_52_candidates() {
        assert_eq!(FineParams::default().candidates_per_iteration(), 52);
    }
}
