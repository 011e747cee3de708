//! Pinhole intrinsics and the paper's camera presets.
//!
//! Pixel convention (used by every stage): image coordinates have (0, 0) at the top-left corner of the
//! top-left pixel, x to the right, y down; pixel (i, j) is centred at (i + 0.5, j + 0.5). A principal
//! point at the image centre is therefore (W / 2, H / 2). This is COLMAP's convention and the one GPU
//! rasterisers sample at.

use serde::{Deserialize, Serialize};

/// Pinhole camera intrinsics in pixels.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Intrinsics {
    /// Image width, pixels.
    pub width_px: u32,
    /// Image height, pixels.
    pub height_px: u32,
    /// Focal lengths in pixels.
    pub fx_px: f64,
    /// Vertical focal length, pixels.
    pub fy_px: f64,
    /// Principal point in pixels (see the module doc for the pixel-centre convention).
    pub cx_px: f64,
    /// Principal point's row, pixels.
    pub cy_px: f64,
}

impl Intrinsics {
    /// A centred pinhole with square pixels from the horizontal field of view.
    ///
    /// # Units
    /// `hfov_deg` in degrees; focal length f = (W / 2) / tan(hfov / 2) pixels.
    pub fn from_hfov(width_px: u32, height_px: u32, hfov_deg: f64) -> Self {
        let f = 0.5 * width_px as f64 / (0.5 * hfov_deg.to_radians()).tan();
        Intrinsics {
            width_px,
            height_px,
            fx_px: f,
            fy_px: f,
            cx_px: 0.5 * width_px as f64,
            cy_px: 0.5 * height_px as f64,
        }
    }

    /// The same camera at another resolution: focal lengths and principal point scale with the image
    /// (the field of view is kept).
    pub fn scaled_to(&self, width_px: u32, height_px: u32) -> Self {
        let sx = width_px as f64 / self.width_px as f64;
        let sy = height_px as f64 / self.height_px as f64;
        Intrinsics {
            width_px,
            height_px,
            fx_px: self.fx_px * sx,
            fy_px: self.fy_px * sy,
            cx_px: self.cx_px * sx,
            cy_px: self.cy_px * sy,
        }
    }

    /// Projects a point in camera coordinates (OpenCV axes, metres) to pixel coordinates, or `None`
    /// when it is not in front of the camera.
    pub fn project(&self, p_cam: glam::DVec3) -> Option<[f64; 2]> {
        if p_cam.z <= 0.0 {
            return None;
        }
        Some([self.fx_px * p_cam.x / p_cam.z + self.cx_px, self.fy_px * p_cam.y / p_cam.z + self.cy_px])
    }

    /// Horizontal field of view in degrees.
    pub fn hfov_deg(&self) -> f64 {
        2.0 * (0.5 * self.width_px as f64 / self.fx_px).atan().to_degrees()
    }

    /// Vertical field of view in degrees.
    pub fn vfov_deg(&self) -> f64 {
        2.0 * (0.5 * self.height_px as f64 / self.fy_px).atan().to_degrees()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cam2_focal_from_fov() {
        // cam2: 25° horizontal FOV over 1920 px → f = 960 / tan(12.5°) = 4330.0 px (hand computation).
        let k = Intrinsics::from_hfov(1920, 1080, 25.0);
        assert!((k.fx_px - 960.0 / 12.5f64.to_radians().tan()).abs() < 1e-9);
        assert!((k.fx_px - 4330.0).abs() < 0.5, "{}", k.fx_px);
        assert!((k.hfov_deg() - 25.0).abs() < 1e-12);
        assert_eq!((k.cx_px, k.cy_px), (960.0, 540.0));
    }

    #[test]
    fn projection_of_axis_point_is_principal_point() {
        let k = Intrinsics::from_hfov(640, 360, 60.0);
        assert_eq!(k.project(glam::DVec3::new(0.0, 0.0, 10.0)), Some([320.0, 180.0]));
        assert_eq!(k.project(glam::DVec3::new(0.0, 0.0, -1.0)), None);
    }
}
