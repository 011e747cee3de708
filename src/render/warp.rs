//! Views that differ only by a rotation about the camera centre, from one wide render.
//!
//! Two pinhole cameras at the same centre see the same rays: a pixel p of camera i looks along
//! R_i K⁻¹ p, which the reference camera 0 sees at K₀ R₀ᵀ R_i K⁻¹ p — a homography, independent of the
//! scene. So the localizer's coarse grid, which tries several yaws at every position, renders one view
//! wide enough to contain all of them ([`RotationFan::new`]) and reads each yaw's image out of it
//! ([`RotationFan::warp`]). The only difference to rendering each yaw directly is resampling: a pixel
//! takes the ID of the wide pixel its centre's ray falls into, so pixels within about half a pixel of a
//! silhouette edge may differ (tested below and in `tests/it/render_cpu_agreement.rs`).

use glam::{DMat3, DVec3};

use crate::camera::{Intrinsics, Pose};

/// The largest wide canvas, in multiples of the target image's pixel count, worth rendering; beyond
/// it (rotations too large for the field of view) the caller renders each view directly.
pub const MAX_CANVAS_RATIO: f64 = 4.0;

/// A wide reference view covering several rotated views of the same size and intrinsics.
#[derive(Debug, Clone)]
pub struct RotationFan {
    /// The reference pose (the first view's rotation) and its widened intrinsics.
    pub pose: Pose,
    /// The widened intrinsics the reference pose is rendered with, pixels.
    pub intrinsics: Intrinsics,
    /// Per view: the homography from its pixel coordinates to the wide view's.
    homographies: Vec<DMat3>,
    target: Intrinsics,
}

impl RotationFan {
    /// The fan of `views` (poses sharing one centre) seen with intrinsics `k`; `None` when a view's
    /// corner falls behind the reference camera or the canvas would exceed [`MAX_CANVAS_RATIO`].
    pub fn new(views: &[Pose], k: &Intrinsics) -> Option<RotationFan> {
        let reference = *views.first()?;
        let k_inv = DMat3::from_cols(
            DVec3::new(1.0 / k.fx_px, 0.0, 0.0),
            DVec3::new(0.0, 1.0 / k.fy_px, 0.0),
            DVec3::new(-k.cx_px / k.fx_px, -k.cy_px / k.fy_px, 1.0),
        );
        let k_mat = DMat3::from_cols(
            DVec3::new(k.fx_px, 0.0, 0.0),
            DVec3::new(0.0, k.fy_px, 0.0),
            DVec3::new(k.cx_px, k.cy_px, 1.0),
        );
        let r0_cw = reference.r_cam_from_world();
        // Homographies into the reference camera with the target's own intrinsics; the canvas offset
        // is applied once the extent is known.
        let hs: Vec<DMat3> = views.iter().map(|v| k_mat * ((r0_cw * v.r_world_from_cam) * k_inv)).collect();
        let (w, h) = (k.width_px as f64, k.height_px as f64);
        let (mut u0, mut u1, mut v0, mut v1) =
            (f64::INFINITY, f64::NEG_INFINITY, f64::INFINITY, f64::NEG_INFINITY);
        for m in &hs {
            // A homography maps the image rectangle to a quadrilateral: its corners bound it.
            for (x, y) in [(0.0, 0.0), (w, 0.0), (0.0, h), (w, h)] {
                let p = apply(m, x, y);
                if p[2] <= 1e-9 {
                    return None;
                }
                let (u, v) = (p[0] / p[2], p[1] / p[2]);
                u0 = u0.min(u);
                u1 = u1.max(u);
                v0 = v0.min(v);
                v1 = v1.max(v);
            }
        }
        // One pixel of slack on each side so that rounding never reads outside.
        // (Rounding noise of the exact corners, e.g. of the reference view itself, is ignored.)
        let (ox, oy) = ((u0 + 1e-6).floor() - 1.0, (v0 + 1e-6).floor() - 1.0);
        let (ww, wh) = ((u1 - 1e-6).ceil() + 1.0 - ox, (v1 - 1e-6).ceil() + 1.0 - oy);
        // NaN-safe: a NaN extent (never expected) fails the comparison and renders directly.
        if ww * wh > MAX_CANVAS_RATIO * w * h || (ww * wh).is_nan() {
            return None;
        }
        let intrinsics = Intrinsics {
            width_px: ww as u32,
            height_px: wh as u32,
            fx_px: k.fx_px,
            fy_px: k.fy_px,
            cx_px: k.cx_px - ox,
            cy_px: k.cy_px - oy,
        };
        // Shift into canvas coordinates: u' = u − ox, v' = v − oy.
        let shift = DMat3::from_cols(DVec3::X, DVec3::Y, DVec3::new(-ox, -oy, 1.0));
        let homographies = hs.iter().map(|m| shift * *m).collect();
        Some(RotationFan { pose: reference, intrinsics, homographies, target: *k })
    }

    /// Number of views in the fan.
    pub fn len(&self) -> usize {
        self.homographies.len()
    }

    /// Whether the fan has no view.
    pub fn is_empty(&self) -> bool {
        self.homographies.is_empty()
    }

    /// View `i`'s ID image (row-major, the target size) read from `wide` (the render of
    /// [`RotationFan::pose`] with [`RotationFan::intrinsics`]) into `out`.
    pub fn warp(&self, i: usize, wide: &[u32], out: &mut Vec<u32>) {
        let (w, h) = (self.target.width_px as usize, self.target.height_px as usize);
        let (ww, wh) = (self.intrinsics.width_px as usize, self.intrinsics.height_px as usize);
        debug_assert_eq!(wide.len(), ww * wh);
        // Every pixel is written below: no need to clear.
        out.resize(w * h, 0);
        let m = &self.homographies[i];
        // 16.16 fixed point, clamped into the canvas, so every point between two clamped ends is too.
        let (umax, vmax) = (((ww as i64) << 16) - 1, ((wh as i64) << 16) - 1);
        let fixed = |p: DVec3| {
            let r = 65536.0 / p.z;
            (((p.x * r) as i64).clamp(0, umax), ((p.y * r) as i64).clamp(0, vmax))
        };
        // Along a row the homogeneous point is affine in x: step it by SEGMENT pixels at a time.
        let step = m.x_axis * SEGMENT as f64;
        for y in 0..h {
            let row = &mut out[y * w..(y + 1) * w];
            // Exact at both ends of every SEGMENT pixels, linear in between: over so short a stretch
            // the perspective term stays far below a hundredth of a pixel for the small rotations of
            // a fan (the canvas ratio bounds them).
            let mut p = apply(m, 0.5, y as f64 + 0.5);
            let mut start = fixed(p);
            for seg in row.chunks_mut(SEGMENT) {
                p += step;
                let end = fixed(p);
                let ((u0, v0), (u1, v1)) = (start, end);
                let (du, dv) = ((u1 - u0) / SEGMENT as i64, (v1 - v0) / SEGMENT as i64);
                let (mut u, mut v) = (u0, v0);
                // Every point between the clamped ends lies between them (truncated steps): when
                // both ends fall in one canvas row, so does the whole stretch (the common case: a
                // yaw fan tilts rows only slightly).
                if v0 >> 16 == v1 >> 16 {
                    let src = &wide[(v0 >> 16) as usize * ww..][..ww];
                    for o in seg.iter_mut() {
                        *o = src[(u >> 16) as usize];
                        u += du;
                    }
                } else {
                    for o in seg.iter_mut() {
                        *o = wide[(v >> 16) as usize * ww + (u >> 16) as usize];
                        u += du;
                        v += dv;
                    }
                }
                start = end;
            }
        }
    }
}

/// Pixels per linearly interpolated stretch of a warped row.
const SEGMENT: usize = 16;

/// The homography `m` applied to the pixel point (x, y): homogeneous coordinates.
#[inline]
fn apply(m: &DMat3, x: f64, y: f64) -> DVec3 {
    *m * DVec3::new(x, y, 1.0)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::render::cpu::{render_ids, CpuScene, Frame};
    use crate::scene::{BuildingId, SceneMesh};

    /// Box buildings on a grid: walls and roofs at several heights.
    fn city() -> SceneMesh {
        let mut m = SceneMesh::default();
        let mut id = 0;
        for gx in -4..=4 {
            for gy in -4..=4 {
                id += 1;
                let (x0, y0) = (gx as f32 * 40.0, gy as f32 * 40.0);
                let (x1, y1, z1) =
                    (x0 + 25.0, y0 + 18.0 + (id % 3) as f32 * 6.0, 10.0 + (id * 7 % 40) as f32);
                let c = [[x0, y0, 0.0], [x1, y0, 0.0], [x1, y1, 0.0], [x0, y1, 0.0]];
                let base = m.positions_m.len() as u32;
                for p in c {
                    m.positions_m.push(p);
                    m.building_ids.push(BuildingId::new(id).unwrap());
                }
                for p in c {
                    m.positions_m.push([p[0], p[1], z1]);
                    m.building_ids.push(BuildingId::new(id).unwrap());
                }
                // Roof and four walls.
                let quads = [[4, 5, 6, 7], [0, 1, 5, 4], [1, 2, 6, 5], [2, 3, 7, 6], [3, 0, 4, 7]];
                for q in quads {
                    m.indices.extend([q[0], q[1], q[2], q[0], q[2], q[3]].map(|i| base + i));
                }
            }
        }
        m
    }

    #[test]
    fn warped_yaws_match_direct_renders_away_from_edges() {
        let mesh = city();
        let k = Intrinsics {
            width_px: 320,
            height_px: 180,
            fx_px: 400.0,
            fy_px: 400.0,
            cx_px: 160.0,
            cy_px: 90.0,
        };
        let centre = [5.0, -180.0, 120.0];
        let scene = CpuScene::new(&mesh, centre);
        for pitch in [0.0, 35.0, 60.0] {
            // Pitch from nadir: straight down, oblique, near the horizon.
            let views: Vec<Pose> = [0.0, -7.5, -5.0, 2.5, 7.5]
                .iter()
                .map(|d| Pose::from_ypr_deg(10.0 + d, pitch, 0.0, centre))
                .collect();
            let fan = RotationFan::new(&views, &k).expect("a small fan fits");
            assert!(fan.intrinsics.width_px >= k.width_px && fan.intrinsics.height_px >= k.height_px);
            let mut wide = Frame::default();
            render_ids(&scene, &fan.pose, &fan.intrinsics, &mut wide);
            let (mut direct, mut warped) = (Frame::default(), Vec::new());
            for (i, v) in views.iter().enumerate() {
                render_ids(&scene, v, &k, &mut direct);
                fan.warp(i, &wide.ids, &mut warped);
                // Pixels differ only where a neighbour differs (at a silhouette edge).
                let (w, h) = (k.width_px as usize, k.height_px as usize);
                let mut differ = 0;
                for y in 0..h {
                    for x in 0..w {
                        let j = y * w + x;
                        if warped[j] == direct.ids[j] {
                            continue;
                        }
                        differ += 1;
                        let near_edge =
                            [(-1i64, 0i64), (1, 0), (0, -1), (0, 1), (-1, -1), (1, 1), (-1, 1), (1, -1)]
                                .iter()
                                .any(|&(dx, dy)| {
                                    // Beyond the border the edge may lie just outside the image.
                                    let (xx, yy) = (x as i64 + dx, y as i64 + dy);
                                    xx < 0
                                        || yy < 0
                                        || xx as usize >= w
                                        || yy as usize >= h
                                        || direct.ids[yy as usize * w + xx as usize] != direct.ids[j]
                                });
                        assert!(
                            near_edge,
                            "pitch {pitch}, view {i}: pixel ({x}, {y}) differs inside a region"
                        );
                    }
                }
                let covered = direct.ids.iter().filter(|&&id| id != 0).count();
                assert!(covered > 1000, "the view sees the city");
                assert!(
                    (differ as f64) < 0.03 * (w * h) as f64,
                    "pitch {pitch}, view {i}: {differ} of {} pixels differ",
                    w * h
                );
            }
        }
    }

    #[test]
    fn the_reference_view_warps_to_itself_and_large_fans_are_refused() {
        let k =
            Intrinsics { width_px: 64, height_px: 48, fx_px: 80.0, fy_px: 80.0, cx_px: 32.0, cy_px: 24.0 };
        let v = Pose::from_ypr_deg(30.0, -45.0, 0.0, [0.0; 3]);
        let fan = RotationFan::new(&[v], &k).unwrap();
        // One view: the canvas is the image plus one pixel of slack each side, the warp an offset.
        assert_eq!((fan.intrinsics.width_px, fan.intrinsics.height_px), (66, 50));
        let wide: Vec<u32> = (0..66 * 50).collect();
        let mut out = Vec::new();
        fan.warp(0, &wide, &mut out);
        for y in 0..48 {
            for x in 0..64 {
                assert_eq!(out[y * 64 + x], ((y + 1) * 66 + x + 1) as u32);
            }
        }
        // ±60° of yaw from a horizontal camera (pitch 90°): far more than 4 images of canvas, or behind.
        let wide_fan = [-60.0, 0.0, 60.0].map(|d| Pose::from_ypr_deg(30.0 + d, 90.0, 0.0, [0.0; 3]));
        assert!(RotationFan::new(&wide_fan, &k).is_none());
        assert!(RotationFan::new(&[], &k).is_none());
    }
}
