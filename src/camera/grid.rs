//! Grid strategy (cam2): independent poses on a uniform lattice over the area polygon.
//!
//! The lattice (spacing `grid.spacing_m`, cell-centred on the polygon's bounding box) keeps the nodes
//! inside the polygon by at least `grid.margin_m`. Every node gets one pose per view angle in
//! `grid.pitch_deg`; each pose draws its yaw (from `grid.yaw_deg`, or uniformly) and its height above
//! ground uniformly in `grid.height_range_m`, raised where needed to the clearance over nearby
//! buildings. A candidate failing the visibility test is redrawn up to `max_attempts_per_pose` times.
//!
//! Without `--count` every (node, view angle) pair is tried once, in lattice order (rows south to
//! north, west to east). With `--count N` the pairs are visited in a seeded random order, and further
//! rounds (new random heights and yaws at the same nodes) follow while fewer than N poses are placed;
//! the poses of each round are then put back in lattice order. A (node, view angle) pair that placed
//! nothing in a round (every attempt refused, or no height clears the buildings) is not tried again:
//! on an area whose buildings fill only part of the polygon, the later rounds spend the candidate
//! budget where views can be placed.

use rand::seq::SliceRandom;
use rand::Rng;
use rand_chacha::ChaCha8Rng;

use super::sample::{Ctx, Frame, SampleStats, Sampled};
use super::{AreaProblem, CameraError, Pose, Trajectory};

/// Lattice nodes inside the polygon (south to north, west to east). The lattice is cell-centred on
/// the polygon's bounding box: n = max(1, ⌊extent / spacing⌋) nodes per axis, their span centred, so
/// no node sits on the bounding box itself.
pub(crate) fn lattice_nodes(ctx: &Ctx, spacing_m: f64, margin_m: f64) -> Vec<[f64; 2]> {
    let (lo, hi) = (ctx.poly.min_m, ctx.poly.max_m);
    let count = |k: usize| (((hi[k] - lo[k]) / spacing_m).floor() as usize).max(1);
    let n = [count(0), count(1)];
    let start = [
        lo[0] + 0.5 * ((hi[0] - lo[0]) - (n[0] - 1) as f64 * spacing_m),
        lo[1] + 0.5 * ((hi[1] - lo[1]) - (n[1] - 1) as f64 * spacing_m),
    ];
    let mut nodes = Vec::new();
    for j in 0..n[1] {
        for i in 0..n[0] {
            let p = [start[0] + i as f64 * spacing_m, start[1] + j as f64 * spacing_m];
            if ctx.poly.contains_with_margin(p, margin_m) {
                nodes.push(p);
            }
        }
    }
    nodes
}

pub(crate) fn sample(ctx: &Ctx, rng: &mut ChaCha8Rng) -> Result<Sampled, CameraError> {
    let count = ctx.count;
    let mut stats = SampleStats::default();
    let g = &ctx.cfg.grid;
    let nodes = lattice_nodes(ctx, g.spacing_m, g.margin_m);
    if nodes.is_empty() {
        return Err(CameraError::Area {
            area: ctx.area.to_string(),
            problem: AreaProblem::NoGridNode {
                area_m2: ctx.poly.area_m2(),
                spacing_m: g.spacing_m,
                margin_m: g.margin_m,
            },
        });
    }
    let pairs: Vec<(usize, usize)> =
        (0..nodes.len()).flat_map(|n| (0..g.pitch_deg.len()).map(move |p| (n, p))).collect();
    let wanted = count.unwrap_or(pairs.len());
    ctx.progress.start(wanted as u64, "poses");
    let budget = ctx.budget(wanted);
    let [h_lo, h_hi] = g.height_range_m;
    let mut frames: Vec<Frame> = Vec::new();
    let mut fractions: Vec<super::visibility::ViewCensus> = Vec::new();
    // Pairs that placed nothing in an earlier round.
    let mut barren = vec![false; pairs.len()];
    'rounds: loop {
        let mut order: Vec<usize> = (0..pairs.len()).filter(|&k| !barren[k]).collect();
        if count.is_some() {
            order.shuffle(rng);
        }
        let mut round: Vec<(usize, Pose, super::visibility::ViewCensus)> = Vec::new();
        let mut exhausted = false;
        for &k in &order {
            if frames.len() + round.len() >= wanted {
                break;
            }
            if stats.candidates >= budget {
                exhausted = true;
                break;
            }
            let (node, pitch_i) = pairs[k];
            let p = nodes[node];
            let pitch = g.pitch_deg[pitch_i];
            let lo = h_lo.max(ctx.required_height_agl_m(p));
            if lo > h_hi {
                // No height in range clears the buildings here: one rejected candidate.
                stats.candidates += 1;
                stats.rejected_clearance += 1;
                barren[k] = true;
                continue;
            }
            let mut placed = false;
            for _ in 0..ctx.cfg.max_attempts_per_pose {
                let yaw = if g.yaw_deg.is_empty() {
                    rng.gen_range(0.0..360.0)
                } else {
                    g.yaw_deg[rng.gen_range(0..g.yaw_deg.len())]
                };
                let h = if lo < h_hi { rng.gen_range(lo..=h_hi) } else { lo };
                let pose = Pose::from_ypr_deg(yaw, pitch, 0.0, [p[0], p[1], ctx.ground_m + h]);
                if let Ok(f) = ctx.check(&pose, &mut stats) {
                    round.push((k, pose, f));
                    ctx.progress.inc(1);
                    placed = true;
                    break;
                }
            }
            barren[k] = !placed;
        }
        let placed_this_round = round.len();
        round.sort_by_key(|r| r.0);
        for (_, pose, f) in round {
            let sequence = frames.len() as u32;
            frames.push(Frame { pose, sequence, index: 0 });
            fractions.push(f);
        }
        if count.is_none() || frames.len() >= wanted || exhausted || placed_this_round == 0 {
            break 'rounds;
        }
    }
    if frames.is_empty() || (count.is_some() && frames.len() < wanted) {
        return Err(ctx.too_few(Trajectory::Grid, frames.len(), wanted, &stats));
    }
    Ok(Sampled { frames, fractions, stats })
}
