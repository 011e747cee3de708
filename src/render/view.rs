//! What one frame looks through: intrinsics + pose, and the f64 maths that turns them into the f32
//! uniform the vertex shader reads.
//!
//! # The projection, derived
//! A camera-frame point (x, y, z) (OpenCV axes, metres) must land at the pixel coordinates
//! u = fx·x/z + cx, v = fy·y/z + cy of `camera::intrinsics` (pixel (i, j) centred at (i + ½, j + ½)).
//! WebGPU maps normalised device coordinates to framebuffer coordinates (whose pixel centres are also at
//! +½) by fb_x = (ndc_x + 1)·W/2 and fb_y = (1 − ndc_y)·H/2 (NDC y points up, framebuffer y down). Solving
//! for ndc and multiplying by the clip w = z:
//!
//! - clip_x = (2fx/W)·x + (2cx/W − 1)·z
//! - clip_y = −(2fy/H)·y + (1 − 2cy/H)·z
//! - clip_z = za·z + zb with za = −n/(f − n), zb = n·f/(f − n): reversed Z, depth = n/z·(f − z)/(f − n),
//!   1 at the near plane n and 0 at the far plane f (Depth32Float, compare `Greater`, clear 0). Reversed Z
//!   puts the float's dense exponent range at the far end and keeps depth resolution nearly uniform in
//!   relative terms from 0.1 m to 10 km.
//! - clip_w = z
//!
//! # Camera-relative transform (no f32 jitter)
//! Vertex positions are f32 ENU metres relative to the area origin. A plain f32 view matrix would add
//! the translation −R·C (possibly kilometres) to R·p (also kilometres) and lose the difference to
//! rounding. Instead the camera centre C (f64) is split into `hi = C as f32` and `lo = (C − hi) as f32`
//! and the shader computes `(p − hi) − lo`: p − hi is exact when p and hi are within a factor of two
//! (Sterbenz) and otherwise rounds relative to the camera distance, so the relative error of the
//! camera-frame point is ~2⁻²⁴ whatever the distance from the origin (≤ 0.001 px at 1920 px width).
//! The rotation R_cam_from_world and the projection coefficients are computed in f64 and cast once.

use bytemuck::{Pod, Zeroable};

use super::error::ViewProblem;
use super::RenderError;
use crate::camera::{Intrinsics, Pose};

/// One frame: the camera intrinsics and its pose in the area's ENU frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct View {
    /// Pixel grid and pinhole (pixels).
    pub intrinsics: Intrinsics,
    /// Camera pose in the area's ENU frame (metres, OpenCV camera axes).
    pub pose: Pose,
}

/// The depth range rendered; geometry nearer than `near_m` or farther than `far_m` is clipped.
///
/// # Units
/// Metres along the optical axis.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DepthRange {
    /// Near clipping plane, metres (> 0).
    pub near_m: f64,
    /// Far clipping plane, metres (> near).
    pub far_m: f64,
}

impl Default for DepthRange {
    /// 0.1 m to 10 km: UAV imagery of cities from 30–600 m height stays far inside it.
    fn default() -> Self {
        DepthRange { near_m: 0.1, far_m: 10_000.0 }
    }
}

/// The largest frame side the renderer accepts (wgpu's default `max_texture_dimension_2d`).
pub const MAX_FRAME_SIDE_PX: u32 = 8192;

/// Coefficients of the clip-space projection (see the module doc): `[ax, bx, ay, by]` and `[za, zb]`.
pub fn projection_coefficients(k: &Intrinsics, range: &DepthRange) -> ([f64; 4], [f64; 2]) {
    let (w, h) = (k.width_px as f64, k.height_px as f64);
    let (n, f) = (range.near_m, range.far_m);
    (
        [2.0 * k.fx_px / w, 2.0 * k.cx_px / w - 1.0, -2.0 * k.fy_px / h, 1.0 - 2.0 * k.cy_px / h],
        [-n / (f - n), n * f / (f - n)],
    )
}

/// Clip coordinates (x, y, z, w) of a camera-frame point, in f64 (the reference for the shader).
pub fn clip_from_cam(k: &Intrinsics, range: &DepthRange, p_cam_m: [f64; 3]) -> [f64; 4] {
    let ([ax, bx, ay, by], [za, zb]) = projection_coefficients(k, range);
    let [x, y, z] = p_cam_m;
    [ax * x + bx * z, ay * y + by * z, za * z + zb, z]
}

/// Framebuffer coordinates (pixels, y down) of clip coordinates, as WebGPU's viewport transform
/// computes them for a full-frame viewport.
pub fn framebuffer_from_clip(k: &Intrinsics, clip: [f64; 4]) -> [f64; 2] {
    let (nx, ny) = (clip[0] / clip[3], clip[1] / clip[3]);
    [(nx + 1.0) * 0.5 * k.width_px as f64, (1.0 - ny) * 0.5 * k.height_px as f64]
}

/// The uniform block of `ids.wgsl` (`struct View`), 112 bytes.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Pod, Zeroable)]
pub struct ViewUniform {
    r_cam_from_world: [[f32; 4]; 3],
    centre_hi_m: [f32; 4],
    centre_lo_m: [f32; 4],
    proj: [f32; 4],
    depth: [f32; 4],
}

impl ViewUniform {
    /// Builds the uniform in f64 and casts it once (see the module doc).
    ///
    /// # Errors
    /// [`RenderError::InvalidView`] when the view is unusable; see [`validate_view`].
    pub fn new(view: &View, range: &DepthRange) -> Result<Self, RenderError> {
        validate_view(view, range)?;
        let r = view.pose.r_cam_from_world();
        let c = view.pose.centre_m.to_array();
        let hi = c.map(|v| v as f32);
        let lo = [0, 1, 2].map(|i| (c[i] - hi[i] as f64) as f32);
        let (p, [za, zb]) = projection_coefficients(&view.intrinsics, range);
        let row = |i: usize| r.row(i).as_vec3().extend(0.0).to_array();
        Ok(ViewUniform {
            r_cam_from_world: [row(0), row(1), row(2)],
            centre_hi_m: [hi[0], hi[1], hi[2], 0.0],
            centre_lo_m: [lo[0], lo[1], lo[2], 0.0],
            proj: p.map(|v| v as f32),
            depth: [za as f32, zb as f32, range.near_m as f32, range.far_m as f32],
        })
    }
}

/// Checks that a view can be rendered: frame size in 1..=[`MAX_FRAME_SIDE_PX`], finite positive focal
/// lengths, finite principal point, finite centre, an orthonormal right-handed rotation (to 1e-6), and
/// 0 < near < far.
///
/// # Errors
/// [`RenderError::InvalidView`] naming the offending value.
pub fn validate_view(view: &View, range: &DepthRange) -> Result<(), RenderError> {
    let k = &view.intrinsics;
    let bad = |problem: ViewProblem| Err(RenderError::InvalidView { view: None, problem });
    if k.width_px == 0
        || k.height_px == 0
        || k.width_px > MAX_FRAME_SIDE_PX
        || k.height_px > MAX_FRAME_SIDE_PX
    {
        return bad(ViewProblem::FrameSize { width_px: k.width_px, height_px: k.height_px });
    }
    if !(k.fx_px.is_finite() && k.fy_px.is_finite() && k.fx_px > 0.0 && k.fy_px > 0.0) {
        return bad(ViewProblem::Focal { fx_px: k.fx_px, fy_px: k.fy_px });
    }
    if !(k.cx_px.is_finite() && k.cy_px.is_finite()) {
        return bad(ViewProblem::PrincipalPoint { cx_px: k.cx_px, cy_px: k.cy_px });
    }
    if !view.pose.centre_m.is_finite() {
        return bad(ViewProblem::Centre { centre_m: view.pose.centre_m });
    }
    let r = &view.pose.r_world_from_cam;
    let worst = (r.transpose() * *r - glam::DMat3::IDENTITY)
        .to_cols_array()
        .iter()
        .fold(0.0f64, |w, v| w.max(v.abs()));
    let det = r.determinant();
    if !(worst <= 1e-6 && (det - 1.0).abs() <= 1e-6) {
        return bad(ViewProblem::Rotation { orthonormality: worst, det, rotation: *r });
    }
    if !(range.near_m.is_finite()
        && range.far_m.is_finite()
        && range.near_m > 0.0
        && range.far_m > range.near_m)
    {
        return bad(ViewProblem::DepthRange { near_m: range.near_m, far_m: range.far_m });
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn k() -> Intrinsics {
        // Off-centre principal point and non-square pixels, so a swapped term cannot pass.
        Intrinsics { width_px: 320, height_px: 240, fx_px: 300.0, fy_px: 280.0, cx_px: 150.25, cy_px: 130.75 }
    }

    mod projection {
        use super::*;

        #[test]
        fn clip_then_viewport_equals_pinhole() {
            // Reference: Intrinsics::project (u = fx x/z + cx, v = fy y/z + cy), hand formula.
            let k = k();
            let range = DepthRange::default();
            for p in [[0.0, 0.0, 10.0], [3.0, -2.0, 7.5], [-40.0, 25.0, 123.0], [1e-3, 2e-3, 0.2]] {
                let fb = framebuffer_from_clip(&k, clip_from_cam(&k, &range, p));
                let uv = k.project(p.into()).unwrap();
                assert!(
                    (fb[0] - uv[0]).abs() < 1e-9 && (fb[1] - uv[1]).abs() < 1e-9,
                    "{p:?}: {fb:?} vs {uv:?}"
                );
            }
        }

        #[test]
        fn reversed_z_maps_near_to_one_and_far_to_zero() {
            let k = k();
            let range = DepthRange { near_m: 0.1, far_m: 10_000.0 };
            let d = |z: f64| {
                let c = clip_from_cam(&k, &range, [0.0, 0.0, z]);
                c[2] / c[3]
            };
            assert!((d(0.1) - 1.0).abs() < 1e-12);
            assert!(d(10_000.0).abs() < 1e-12);
            // Monotonically decreasing: nearer is greater (compare Greater).
            assert!(d(100.0) > d(100.01));
            // f32 resolution at 500 m: one ulp of depth there must be a small fraction of a metre.
            let (a, b) = (d(500.0) as f32, d(500.05) as f32);
            assert!(a > b, "5 cm at 500 m must be resolved in Depth32Float");
        }
    }

    mod camera_relative {
        use super::*;

        #[test]
        fn centre_split_recovers_f64_centre() {
            let view = View {
                intrinsics: k(),
                pose: Pose::from_ypr_deg(10.0, 30.0, 0.0, [4321.123456789, -987.654321, 412.3]),
            };
            let u = ViewUniform::new(&view, &DepthRange::default()).unwrap();
            for i in 0..3 {
                let back = u.centre_hi_m[i] as f64 + u.centre_lo_m[i] as f64;
                assert!((back - view.pose.centre_m[i]).abs() < 1e-9, "{back}");
            }
        }
    }

    mod validation {
        use super::*;

        #[test]
        fn rejects_bad_views() {
            let good = View { intrinsics: k(), pose: Pose::from_ypr_deg(0.0, 0.0, 0.0, [0.0, 0.0, 100.0]) };
            let r = DepthRange::default();
            assert!(validate_view(&good, &r).is_ok());
            let mut v = good;
            v.intrinsics.width_px = 0;
            assert!(validate_view(&v, &r).unwrap_err().to_string().contains("0×240"));
            let mut v = good;
            v.intrinsics.fx_px = f64::NAN;
            assert!(validate_view(&v, &r).is_err());
            let mut v = good;
            v.pose.r_world_from_cam.x_axis.x = 2.0;
            assert!(validate_view(&v, &r).unwrap_err().to_string().contains("not a rotation"));
            let mut v = good;
            v.pose.r_world_from_cam = glam::DMat3::from_diagonal(glam::DVec3::new(1.0, 1.0, -1.0)); // a mirror
            assert!(validate_view(&v, &r).is_err());
            assert!(validate_view(&good, &DepthRange { near_m: 0.0, far_m: 1.0 }).is_err());
        }
    }
}
