//! Regular sequence strategy (cam3): lawn-mower survey lines.
//!
//! Lines run along `regular.line_heading_deg` (default: the polygon's principal axis), are
//! `regular.line_spacing_m` apart across track and centred on the polygon, and are flown alternately
//! forth and back (boustrophedon). Where a line crosses the polygon, frames are placed every
//! `regular.frame_spacing_m` along it, centred in the crossing. The camera's yaw follows the track
//! (the image top points in the flight direction) and its roll is 0; each line segment is flown at one
//! height drawn uniformly in `regular.height_range_m`, raised where needed to clear the buildings
//! along the whole segment.
//!
//! One pass over all lines is flown per view angle in `regular.pitch_deg`. With `--count N`, passes
//! repeat (view angles cycling, lines shifted by a random fraction of the spacing, heights redrawn)
//! until N frames are collected, the candidate budget is spent, or 16 passes in a row placed nothing
//! (over a small area one shifted pass may place no run where the next does). Rejected frames split a
//! segment into runs; runs shorter than `regular.min_sequence_frames` are dropped; every kept run is
//! one sequence.

use rand::Rng;
use rand_chacha::ChaCha8Rng;

use super::sample::{Ctx, RunCollector, SampleStats, Sampled};
use super::{CameraError, Pose, Trajectory};

/// One straight piece of a survey line: its flight heading and the frame positions in flight order.
#[derive(Debug, Clone)]
pub(crate) struct Segment {
    pub yaw_deg: f64,
    pub points: Vec<[f64; 2]>,
}

/// The segments of one pass: lines `shift_frac` of a spacing off the centred layout, alternating in
/// direction, in flight order.
pub(crate) fn plan_pass(ctx: &Ctx, heading_deg: f64, shift_frac: f64) -> Vec<Segment> {
    let r = &ctx.cfg.regular;
    let t = heading_deg.to_radians();
    let along = [t.sin(), t.cos()];
    let across = [t.cos(), -t.sin()];
    let proj = |p: &[f64; 2], d: [f64; 2]| p[0] * d[0] + p[1] * d[1];
    let (mut a_lo, mut a_hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for p in ctx.poly.ring() {
        let a = proj(p, across);
        a_lo = a_lo.min(a);
        a_hi = a_hi.max(a);
    }
    let n_lines = (((a_hi - a_lo) / r.line_spacing_m).ceil() as usize).max(1);
    let first =
        0.5 * (a_lo + a_hi) - 0.5 * (n_lines as f64 - 1.0) * r.line_spacing_m + shift_frac * r.line_spacing_m;
    let mut segments = Vec::new();
    for k in 0..n_lines {
        let a = first + k as f64 * r.line_spacing_m;
        let origin = [a * across[0], a * across[1]];
        let forward = k % 2 == 0;
        let mut pieces: Vec<Segment> = ctx
            .poly
            .clip_line(origin, along)
            .into_iter()
            .filter_map(|[s0, s1]| {
                let n = ((s1 - s0) / r.frame_spacing_m).floor() as usize + 1;
                let s_first = s0 + 0.5 * ((s1 - s0) - (n - 1) as f64 * r.frame_spacing_m);
                let mut points: Vec<[f64; 2]> = (0..n)
                    .map(|i| {
                        let s = s_first + i as f64 * r.frame_spacing_m;
                        [origin[0] + s * along[0], origin[1] + s * along[1]]
                    })
                    .collect();
                if !forward {
                    points.reverse();
                }
                let yaw_deg = if forward { heading_deg } else { heading_deg + 180.0 }.rem_euclid(360.0);
                (!points.is_empty()).then_some(Segment { yaw_deg, points })
            })
            .collect();
        if !forward {
            pieces.reverse();
        }
        segments.extend(pieces);
    }
    segments
}

/// With `--count`, passes in a row that place no frame before the sampler gives up; the candidate
/// budget ends it first wherever the passes have candidates.
const MAX_FRUITLESS_PASSES: u32 = 16;

pub(crate) fn sample(ctx: &Ctx, rng: &mut ChaCha8Rng) -> Result<Sampled, CameraError> {
    let count = ctx.count;
    let mut stats = SampleStats::default();
    let r = &ctx.cfg.regular;
    let heading = r.line_heading_deg.unwrap_or_else(|| ctx.poly.principal_axis_heading_deg());
    let first_pass = plan_pass(ctx, heading, 0.0);
    let frames_per_pass: usize = first_pass.iter().map(|s| s.points.len()).sum();
    let natural = frames_per_pass * r.pitch_deg.len();
    let wanted = count.unwrap_or(natural);
    ctx.progress.start(wanted as u64, "poses");
    let budget = ctx.budget(wanted);
    let mut runs = RunCollector::new(r.min_sequence_frames, count, ctx.progress);
    let [h_lo, h_hi] = r.height_range_m;
    let mut pass = 0usize;
    let mut fruitless_passes = 0u32;
    loop {
        let before = runs.frames.len();
        let pitch = r.pitch_deg[pass % r.pitch_deg.len()];
        let segments = if pass < r.pitch_deg.len() {
            first_pass.clone()
        } else {
            plan_pass(ctx, heading, rng.gen_range(-0.5..0.5))
        };
        for seg in &segments {
            if runs.full() || stats.candidates >= budget {
                break;
            }
            let need =
                seg.points.iter().map(|p| ctx.required_height_agl_m(*p)).fold(f64::NEG_INFINITY, f64::max);
            let lo = h_lo.max(need).min(h_hi);
            let h = if lo < h_hi { rng.gen_range(lo..=h_hi) } else { h_hi };
            for p in &seg.points {
                let pose = Pose::from_ypr_deg(seg.yaw_deg, pitch, 0.0, [p[0], p[1], ctx.ground_m + h]);
                let verdict = ctx.check(&pose, &mut stats).ok().map(|f| (pose, f));
                runs.offer(verdict, &mut stats);
                if runs.full() {
                    break;
                }
            }
            runs.end_run(&mut stats);
        }
        pass += 1;
        fruitless_passes = if runs.frames.len() > before { 0 } else { fruitless_passes + 1 };
        let done = match count {
            None => pass >= r.pitch_deg.len(),
            Some(_) => runs.full() || stats.candidates >= budget || fruitless_passes >= MAX_FRUITLESS_PASSES,
        };
        if done {
            break;
        }
    }
    let placed = runs.frames.len();
    if placed == 0 || (count.is_some() && placed < wanted) {
        return Err(ctx.too_few(Trajectory::Regular, placed, wanted, &stats));
    }
    Ok(Sampled { frames: runs.frames, fractions: runs.fractions, stats })
}
