//! The exact Blender camera for a pinhole: lens, sensor, shift and pixel aspect from (fx, fy, cx, cy), and
//! the camera object's world matrix from a [`Pose`].
//!
//! # Derivation
//! Blender (and Cycles, `blender_camera_viewplane`) with `sensor_fit = HORIZONTAL` maps the image width
//! to the sensor width: at unit depth the view plane spans `[-h, h]` horizontally with
//! `h = sensor_width / (2 lens)`, whatever the pixel aspect. With `W` pixels across,
//! `fx = W / (2h)`, hence `lens = fx · sensor_width / W`.
//!
//! Vertically the view plane spans `[-h / a, h / a]` with `a = (W · pax) / (H · pay)`
//! (`pax`, `pay` = `render.pixel_aspect_x/y`), so one pixel is `2h · pay / (W · pax)` tall and
//! `fy = fx · pax / pay`: `pax / pay = fy / fx` (Blender wants both ≥ 1, so the smaller one is 1).
//!
//! Shifts move the view plane by `shift · (view-plane width)` on both axes (the fitted dimension scales
//! both, Blender's `viewfac`), i.e. by `shift · W / fx` at unit depth. The OpenCV image spans
//! `x/z ∈ [−cx/fx, (W − cx)/fx]`, centred on `(W/2 − cx)/fx`, so `shift_x = (W/2 − cx) / W`; with y up in
//! Blender, the image centre sits at `(cy − H/2)/fy` and `shift_y = (cy − H/2) · fx / (fy · W)`.
//!
//! Pixel centres: Cycles samples pixel (i, j) at raster (i + ½, j + ½) (plus filter jitter), the
//! convention of [`crate::camera::intrinsics`].
//!
//! Axes: the glTF importer turns the scene's y-up glTF into Blender's z-up, Blender (x, y, z) = glTF
//! (x, −z, y) = ENU (e, n, u), so Blender world coordinates are the area's ENU metres. A Blender camera
//! looks along its −Z with +Y up: its axes are OpenCV's times diag(1, −1, −1).

use serde::{Deserialize, Serialize};

use super::{BlenderError, CameraProblem};
use crate::camera::{Intrinsics, Pose};

/// 4×4 row-major matrix.
pub type Mat4 = [[f64; 4]; 4];

/// Sensor width used for every camera (only lens/sensor matters; 36 mm is Blender's default).
pub const SENSOR_WIDTH_MM: f64 = 36.0;

/// Largest pixel aspect Blender accepts (`RenderSettings.pixel_aspect_x/y` soft limit 200).
pub const MAX_PIXEL_ASPECT: f64 = 200.0;

/// Largest shift Blender accepts (`Camera.shift_x/y` range ±10).
pub const MAX_SHIFT: f64 = 10.0;

/// The Blender settings reproducing one pinhole camera (what the job's `frames[i].camera` holds).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct BlenderCamera {
    /// `Camera.sensor_width` in millimetres (with `sensor_fit = HORIZONTAL`).
    pub sensor_width_mm: f64,
    /// `Camera.lens` (focal length) in millimetres.
    pub lens_mm: f64,
    /// `Camera.shift_x`, `Camera.shift_y`, in units of the view-plane width.
    pub shift_x: f64,
    /// `Camera.shift_y`, in units of the view-plane width.
    pub shift_y: f64,
    /// `RenderSettings.pixel_aspect_x/y` (one of them is 1).
    pub pixel_aspect_x: f64,
    /// `RenderSettings.pixel_aspect_y`.
    pub pixel_aspect_y: f64,
    /// Clipping distances in metres.
    pub clip_start_m: f64,
    /// Far clipping distance, metres.
    pub clip_end_m: f64,
}

impl BlenderCamera {
    /// Derives the Blender camera for `k` (see the module doc).
    ///
    /// # Errors
    /// [`BlenderError::Camera`] when the intrinsics are not finite and positive, or need a shift or
    /// pixel aspect Blender cannot represent.
    pub fn from_intrinsics(
        frame: &str,
        k: &Intrinsics,
        clip_start_m: f64,
        clip_end_m: f64,
    ) -> Result<BlenderCamera, BlenderError> {
        let bad = |problem: CameraProblem| BlenderError::Camera { frame: frame.to_string(), problem };
        if k.width_px == 0 || k.height_px == 0 {
            return Err(bad(CameraProblem::EmptyImage { width_px: k.width_px, height_px: k.height_px }));
        }
        for (name, v) in [("fx_px", k.fx_px), ("fy_px", k.fy_px)] {
            if !(v.is_finite() && v > 0.0) {
                return Err(bad(CameraProblem::Focal { name, value_px: v }));
            }
        }
        for (name, v) in [("cx_px", k.cx_px), ("cy_px", k.cy_px)] {
            if !v.is_finite() {
                return Err(bad(CameraProblem::PrincipalPoint { name, value_px: v }));
            }
        }
        if !(clip_start_m > 0.0 && clip_end_m > clip_start_m && clip_end_m.is_finite()) {
            return Err(bad(CameraProblem::Clip { start_m: clip_start_m, end_m: clip_end_m }));
        }
        let (w, h) = (k.width_px as f64, k.height_px as f64);
        let (pixel_aspect_x, pixel_aspect_y) =
            if k.fy_px >= k.fx_px { (k.fy_px / k.fx_px, 1.0) } else { (1.0, k.fx_px / k.fy_px) };
        if pixel_aspect_x > MAX_PIXEL_ASPECT || pixel_aspect_y > MAX_PIXEL_ASPECT {
            return Err(bad(CameraProblem::PixelAspect {
                fx_over_fy: k.fx_px / k.fy_px,
                max: MAX_PIXEL_ASPECT,
            }));
        }
        let shift_x = (0.5 * w - k.cx_px) / w;
        let shift_y = (k.cy_px - 0.5 * h) * k.fx_px / (k.fy_px * w);
        if shift_x.abs() > MAX_SHIFT || shift_y.abs() > MAX_SHIFT {
            return Err(bad(CameraProblem::Shift { cx_px: k.cx_px, cy_px: k.cy_px, shift_x, shift_y }));
        }
        Ok(BlenderCamera {
            sensor_width_mm: SENSOR_WIDTH_MM,
            lens_mm: k.fx_px * SENSOR_WIDTH_MM / w,
            shift_x,
            shift_y,
            pixel_aspect_x,
            pixel_aspect_y,
            clip_start_m,
            clip_end_m,
        })
    }
}

/// The Blender camera object's world matrix (row-major) for `pose`: rotation columns are the OpenCV
/// camera axes in ENU times diag(1, −1, −1), translation the camera centre in ENU metres.
pub fn blender_matrix_world(pose: &Pose) -> Mat4 {
    let flip = glam::DMat4::from_scale(glam::DVec3::new(1.0, -1.0, -1.0));
    crate::util::row_major::rows(&(pose.cam_to_world() * flip))
}

/// A pose as the 4×4 camera-to-world matrix of `poses.jsonl` (OpenCV axes, ENU metres).
pub fn cam_to_world_enu(pose: &Pose) -> Mat4 {
    crate::util::row_major::rows(&pose.cam_to_world())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Blender's own projection, written from `BKE_camera_params_compute_viewplane` (blenkernel,
    /// camera.cc) independently of the derivation above: the view plane in "pixel" units is
    /// `[-W/2, W/2] × [-ycor·H/2, ycor·H/2]` shifted by `shift · viewfac` (`viewfac = W` for a
    /// horizontal fit), scaled by `pixsize = sensor · clip / (lens · viewfac)`; raster x runs left to
    /// right over `[xmin, xmax]`, raster y top to bottom over `[ymax, ymin]`. `ycor = pay / pax`.
    fn blender_project(b: &BlenderCamera, w: u32, h: u32, p_blender_cam: [f64; 3]) -> [f64; 2] {
        let (w, h) = (w as f64, h as f64);
        let ycor = b.pixel_aspect_y / b.pixel_aspect_x;
        let clip = 1.0; // the plane at unit distance
        let viewfac = w;
        let pixsize = b.sensor_width_mm * clip / b.lens_mm / viewfac;
        let dx = b.shift_x * viewfac;
        let dy = b.shift_y * viewfac;
        let (xmin, xmax) = ((-0.5 * w + dx) * pixsize, (0.5 * w + dx) * pixsize);
        let (ymin, ymax) = ((-0.5 * ycor * h + dy) * pixsize, (0.5 * ycor * h + dy) * pixsize);
        // Blender camera looks along -z: the point meets the unit plane at (x, y) / -z.
        let (x, y) = (p_blender_cam[0] / -p_blender_cam[2], p_blender_cam[1] / -p_blender_cam[2]);
        [(x - xmin) / (xmax - xmin) * w, (ymax - y) / (ymax - ymin) * h]
    }

    #[test]
    fn blender_projection_equals_opencv_projection() {
        let cases = [
            Intrinsics::from_hfov(1920, 1080, 25.0),
            Intrinsics {
                width_px: 160,
                height_px: 120,
                fx_px: 150.0,
                fy_px: 170.0,
                cx_px: 70.3,
                cy_px: 66.8,
            },
            Intrinsics { width_px: 64, height_px: 48, fx_px: 90.0, fy_px: 60.0, cx_px: 35.0, cy_px: 20.5 },
            Intrinsics {
                width_px: 1200,
                height_px: 1600,
                fx_px: 1400.0,
                fy_px: 1400.0,
                cx_px: 600.0,
                cy_px: 800.0,
            },
        ];
        for k in cases {
            let b = BlenderCamera::from_intrinsics("t", &k, 0.1, 1e5).unwrap();
            for p in [[0.0, 0.0, 10.0], [3.0, -2.0, 7.0], [-12.0, 9.0, 40.0], [0.3, 0.1, 1.0]] {
                let cv = k.project(p.into()).unwrap();
                // OpenCV → Blender camera axes: diag(1, −1, −1).
                let bl = blender_project(&b, k.width_px, k.height_px, [p[0], -p[1], -p[2]]);
                assert!(
                    (cv[0] - bl[0]).abs() < 1e-9 && (cv[1] - bl[1]).abs() < 1e-9,
                    "{k:?} {p:?}: opencv {cv:?} blender {bl:?}"
                );
            }
        }
    }

    #[test]
    fn centred_square_pixels_need_no_shift() {
        // cam2: 1920×1080, 25° HFOV → lens = fx · 36 / 1920 = 36 / (2 tan 12.5°) = 81.19 mm (hand
        // computation), no shift, square pixels.
        let k = Intrinsics::from_hfov(1920, 1080, 25.0);
        let b = BlenderCamera::from_intrinsics("cam2", &k, 0.1, 1e5).unwrap();
        assert!((b.lens_mm - 18.0 / 12.5f64.to_radians().tan()).abs() < 1e-9, "{}", b.lens_mm);
        assert_eq!((b.shift_x, b.shift_y, b.pixel_aspect_x, b.pixel_aspect_y), (0.0, 0.0, 1.0, 1.0));
    }

    #[test]
    fn shift_signs() {
        // Principal point left of and above the centre: the view plane moves right (+x) and down (−y)
        // by 10 px / W = 0.0625 and 8 px / W = 0.05 (hand computation).
        let k = Intrinsics {
            width_px: 160,
            height_px: 120,
            fx_px: 100.0,
            fy_px: 100.0,
            cx_px: 70.0,
            cy_px: 52.0,
        };
        let b = BlenderCamera::from_intrinsics("t", &k, 0.1, 1e5).unwrap();
        assert!((b.shift_x - 0.0625).abs() < 1e-15 && (b.shift_y + 0.05).abs() < 1e-15, "{b:?}");
    }

    #[test]
    fn bad_intrinsics_are_errors() {
        let mut k = Intrinsics::from_hfov(64, 48, 60.0);
        k.fy_px = f64::NAN;
        let e = BlenderCamera::from_intrinsics("f1", &k, 0.1, 1e5).unwrap_err().to_string();
        assert!(e.contains("f1") && e.contains("fy_px"), "{e}");
        let k = Intrinsics::from_hfov(64, 48, 60.0);
        assert!(BlenderCamera::from_intrinsics("f1", &k, 1.0, 0.5).is_err());
        let mut k = Intrinsics::from_hfov(64, 48, 60.0);
        k.cx_px = 1e6;
        assert!(BlenderCamera::from_intrinsics("f1", &k, 0.1, 1e5)
            .unwrap_err()
            .to_string()
            .contains("principal"));
    }

    #[test]
    fn matrix_world_flips_y_and_z() {
        // Nadir, north-up: OpenCV x = east, y = south, z = down, so Blender's camera -Z (view
        // direction) is down and +Y (image up) is north.
        let pose = Pose::from_ypr_deg(0.0, 0.0, 0.0, [1.0, 2.0, 300.0]);
        let m = blender_matrix_world(&pose);
        let col = |j: usize| [m[0][j], m[1][j], m[2][j]];
        assert_eq!(col(0), [1.0, 0.0, 0.0]);
        assert_eq!(col(1).map(|v| v + 0.0), [0.0, 1.0, 0.0]);
        assert_eq!(col(2).map(|v| v + 0.0), [0.0, 0.0, 1.0]);
        assert_eq!(col(3), [1.0, 2.0, 300.0]);
    }
}
