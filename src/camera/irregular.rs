//! Irregular sequence strategy (cam1): smooth random flights through random waypoints.
//!
//! Each trajectory starts at a random point inside the polygon (at least `waypoint_margin_m` from its
//! edge) and flies at constant ground speed (`frame_spacing_m` per frame) towards a random waypoint;
//! on reaching it (or after a time-out) a new waypoint is drawn. The flight is a rate-limited pursuit,
//! so by construction, between consecutive frames:
//! - the heading changes by at most `max_turn_deg_per_frame`, and the turn rate by at most
//!   `max_turn_change_deg_per_frame` (the path is C¹ with bounded curvature);
//! - the height above ground changes by at most `max_climb_m_per_frame`; it steers to the waypoint's
//!   height (drawn in `height_range_m`), climbing early — 20 frames ahead along the heading — where
//!   tall buildings require it;
//! - the tilt from nadir changes by at most `max_pitch_deg_per_frame`, steering to a target drawn in
//!   `pitch_range_deg` and redrawn whenever it is reached, so the tilt varies continuously over the
//!   whole range.
//!
//! The camera looks along the flight direction (yaw = heading, roll 0). Frames failing a check split
//! the trajectory into runs; runs shorter than `min_sequence_frames` are dropped and every kept run is
//! one sequence. A trajectory lasts `frames_per_sequence` frames, then a new one starts elsewhere.

use rand::Rng;
use rand_chacha::ChaCha8Rng;

use super::sample::{Ctx, RunCollector, SampleStats, Sampled};
use super::{AreaProblem, CameraError, Pose, Trajectory};

/// Proportional gain of the heading pursuit (turn rate commanded per degree of heading error).
const PURSUIT_GAIN: f64 = 0.2;
/// Frames looked ahead when deciding how high to climb.
const LOOKAHEAD_FRAMES: usize = 20;

/// The difference a − b of two headings in degrees, wrapped to [−180, 180).
pub(crate) fn wrap_deg(d: f64) -> f64 {
    (d + 180.0).rem_euclid(360.0) - 180.0
}

fn bearing_deg(from: [f64; 2], to: [f64; 2]) -> f64 {
    (to[0] - from[0]).atan2(to[1] - from[1]).to_degrees().rem_euclid(360.0)
}

fn dist(a: [f64; 2], b: [f64; 2]) -> f64 {
    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2)).sqrt()
}

/// Kinematic state of the aircraft.
#[derive(Debug, Clone, Copy)]
struct State {
    p: [f64; 2],
    heading_deg: f64,
    turn_deg: f64,
    height_agl_m: f64,
    pitch_deg: f64,
}

struct Targets {
    waypoint: [f64; 2],
    height_agl_m: f64,
    pitch_deg: f64,
    frames_on_leg: usize,
    leg_limit: usize,
}

pub(crate) fn sample(ctx: &Ctx, rng: &mut ChaCha8Rng) -> Result<Sampled, CameraError> {
    let count = ctx.count;
    let mut stats = SampleStats::default();
    let ic = &ctx.cfg.irregular;
    let wanted = count.unwrap_or(ic.default_frames as usize);
    ctx.progress.start(wanted as u64, "poses");
    let budget = ctx.budget(wanted);
    let mut runs = RunCollector::new(ic.min_sequence_frames, Some(wanted), ctx.progress);
    let [h_lo, h_hi] = ic.height_range_m;
    let [t_lo, t_hi] = ic.pitch_range_deg;
    let step = ic.frame_spacing_m;
    let turn_radius_m = step / ic.max_turn_deg_per_frame.to_radians();
    let margin = ic.waypoint_margin_m;
    let no_room = || CameraError::Area { area: ctx.area.to_string(), problem: AreaProblem::NoTrajectoryRoom };
    let draw = |rng: &mut ChaCha8Rng, lo: f64, hi: f64| if lo < hi { rng.gen_range(lo..=hi) } else { lo };
    let new_targets = |rng: &mut ChaCha8Rng, from: [f64; 2]| -> Result<Targets, CameraError> {
        // Far enough that the pursuit cannot orbit it: 3 turn radii, keeping the farthest of 30 draws.
        let mut best: Option<([f64; 2], f64)> = None;
        for _ in 0..30 {
            let w = ctx.poly.random_point(rng, margin).ok_or_else(no_room)?;
            let d = dist(w, from);
            if best.is_none_or(|b| d > b.1) {
                best = Some((w, d));
            }
            if d >= 3.0 * turn_radius_m {
                break;
            }
        }
        let (waypoint, d) = best.ok_or_else(no_room)?;
        Ok(Targets {
            waypoint,
            height_agl_m: draw(rng, h_lo, h_hi),
            pitch_deg: draw(rng, t_lo, t_hi),
            frames_on_leg: 0,
            leg_limit: (2.0 * d / step) as usize + 40,
        })
    };

    while !runs.full() && stats.candidates < budget {
        // A new trajectory.
        let start = ctx.poly.random_point(rng, margin).ok_or_else(no_room)?;
        let mut tg = new_targets(rng, start)?;
        let mut s = State {
            p: start,
            heading_deg: (bearing_deg(start, tg.waypoint) + rng.gen_range(-30.0..30.0)).rem_euclid(360.0),
            turn_deg: 0.0,
            height_agl_m: draw(rng, h_lo, h_hi).max(ctx.required_height_agl_m(start)).min(h_hi),
            pitch_deg: draw(rng, t_lo, t_hi),
        };
        for _ in 0..ic.frames_per_sequence {
            let pose = Pose::from_ypr_deg(
                s.heading_deg,
                s.pitch_deg,
                0.0,
                [s.p[0], s.p[1], ctx.ground_m + s.height_agl_m],
            );
            let verdict = ctx.check(&pose, &mut stats).ok().map(|f| (pose, f));
            runs.offer(verdict, &mut stats);
            if runs.full() || stats.candidates >= budget {
                break;
            }
            // Heading: rate-limited pursuit of the waypoint.
            let err = wrap_deg(bearing_deg(s.p, tg.waypoint) - s.heading_deg);
            let w_max = ic.max_turn_deg_per_frame;
            let a_max = ic.max_turn_change_deg_per_frame;
            let cmd = (PURSUIT_GAIN * err).clamp(-w_max, w_max);
            s.turn_deg = (s.turn_deg + (cmd - s.turn_deg).clamp(-a_max, a_max)).clamp(-w_max, w_max);
            s.heading_deg = (s.heading_deg + s.turn_deg).rem_euclid(360.0);
            let h = s.heading_deg.to_radians();
            s.p = [s.p[0] + step * h.sin(), s.p[1] + step * h.cos()];
            // Height: towards the waypoint's, but high enough for the buildings just ahead.
            let need = (0..=LOOKAHEAD_FRAMES)
                .step_by(4)
                .map(|k| {
                    let d = k as f64 * step;
                    ctx.required_height_agl_m([s.p[0] + d * h.sin(), s.p[1] + d * h.cos()])
                })
                .fold(f64::NEG_INFINITY, f64::max);
            let target_h = tg.height_agl_m.max(need).clamp(h_lo, h_hi);
            let c_max = ic.max_climb_m_per_frame;
            s.height_agl_m =
                (s.height_agl_m + (target_h - s.height_agl_m).clamp(-c_max, c_max)).clamp(h_lo, h_hi);
            // Tilt: towards its target, a new target once reached.
            let p_max = ic.max_pitch_deg_per_frame;
            s.pitch_deg = (s.pitch_deg + (tg.pitch_deg - s.pitch_deg).clamp(-p_max, p_max)).clamp(t_lo, t_hi);
            if (s.pitch_deg - tg.pitch_deg).abs() < 1e-9 {
                tg.pitch_deg = draw(rng, t_lo, t_hi);
            }
            tg.frames_on_leg += 1;
            if dist(s.p, tg.waypoint) < turn_radius_m.max(2.0 * step) || tg.frames_on_leg > tg.leg_limit {
                let pitch_target = tg.pitch_deg;
                tg = new_targets(rng, s.p)?;
                tg.pitch_deg = pitch_target;
            }
        }
        runs.end_run(&mut stats);
    }
    let placed = runs.frames.len();
    if placed < wanted {
        return Err(ctx.too_few(Trajectory::Irregular, placed, wanted, &stats));
    }
    Ok(Sampled { frames: runs.frames, fractions: runs.fractions, stats })
}
