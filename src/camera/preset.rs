//! Camera presets of the paper and custom cameras read from TOML files.
//!
//! A [`CameraSpec`] is what the sampler and every later stage need to know about a camera: its
//! resolution, sensor, field of view, the derived focal length (in millimetres and pixels), the
//! principal point, an optional Brown–Conrady distortion (stored for export only: insgen renders ideal
//! pinhole images, so the COLMAP model it writes is `PINHOLE`), and the sampling strategy it uses by
//! default.
//!
//! Presets (paper table "Camera configurations", SPEC.md):
//!
//! | preset | resolution | sensor \[mm\]  | hFOV | focal \[mm\] | focal \[px\] | strategy  |
//! |--------|------------|----------------|------|------------|------------|-----------|
//! | cam1   | 1600×1200  | 16 × 12        | 45°  | 19.314     | 1931.37    | irregular |
//! | cam2   | 1920×1080  | 23.76 × 13.365 | 25°  | 53.587     | 4330.28    | grid      |
//! | cam3   | 1920×1080  | 23.76 × 13.365 | 25°  | 53.587     | 4330.28    | regular   |
//!
//! focal_mm = (sensor_width_mm / 2) / tan(hfov / 2); fx_px = focal_mm · W / sensor_width_mm
//! = (W / 2) / tan(hfov / 2) and fy_px = focal_mm · H / sensor_height_mm (square pixels for all three
//! presets: 0.01 mm and 0.012375 mm pitch, so fy = fx); principal point at the image centre (W / 2, H / 2).
//!
//! Custom camera files follow `schemas/camera.schema.json`; `scenes/cameras/example.toml` is a worked
//! example.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use super::error::ConfigIssue;
use super::{CameraError, Intrinsics, Trajectory};

/// Names of the built-in presets, in table order.
pub const PRESET_NAMES: [&str; 3] = ["cam1", "cam2", "cam3"];

/// Brown–Conrady lens distortion in OpenCV's order (k1, k2, p1, p2, k3), dimensionless, for
/// normalised image coordinates. Stored and exported; the renderers ignore it.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Distortion {
    /// Radial coefficient k1.
    pub k1: f64,
    /// Radial coefficient k2.
    pub k2: f64,
    /// Tangential coefficient p1.
    pub p1: f64,
    /// Tangential coefficient p2.
    pub p2: f64,
    /// Radial coefficient k3.
    pub k3: f64,
}

/// A camera: resolution, sensor, field of view, derived intrinsics, and its default strategy.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CameraSpec {
    /// Preset or custom name; also the output directory name (`<workdir>/<area>/<name>/`).
    pub name: String,
    /// Image width, pixels.
    pub width_px: u32,
    /// Image height, pixels.
    pub height_px: u32,
    /// Physical sensor size, millimetres.
    pub sensor_width_mm: f64,
    /// Physical sensor height, millimetres.
    pub sensor_height_mm: f64,
    /// Horizontal field of view, degrees.
    pub hfov_deg: f64,
    /// Focal length, millimetres.
    pub focal_mm: f64,
    /// Pinhole intrinsics in pixels (see [`Intrinsics`] for the pixel convention).
    pub intrinsics: Intrinsics,
    /// Lens distortion, exported in `camera.json` only (images are rendered undistorted).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub distortion: Option<Distortion>,
    /// The sampling strategy used when `--strategy` is not given.
    pub strategy: Trajectory,
}

impl CameraSpec {
    /// A centred pinhole camera from its resolution, sensor size and horizontal field of view.
    ///
    /// # Units
    /// Sensor in millimetres, `hfov_deg` in degrees.
    pub fn from_sensor(
        name: &str,
        width_px: u32,
        height_px: u32,
        sensor_width_mm: f64,
        sensor_height_mm: f64,
        hfov_deg: f64,
        strategy: Trajectory,
    ) -> Self {
        let focal_mm = focal_mm_from_hfov(sensor_width_mm, hfov_deg);
        // fx from the field of view directly (identical to `Intrinsics::from_hfov`); fy from the pixel
        // aspect (pitch_x / pitch_y), snapped to 1 when the pixels are square to within 1e-9 so that
        // rounding in the sensor sizes does not make fx and fy differ in the last bits.
        let fx_px = 0.5 * width_px as f64 / (0.5 * hfov_deg.to_radians()).tan();
        let aspect = (sensor_width_mm / width_px as f64) / (sensor_height_mm / height_px as f64);
        let fy_px = if (aspect - 1.0).abs() < 1e-9 { fx_px } else { fx_px * aspect };
        let intrinsics = Intrinsics {
            width_px,
            height_px,
            fx_px,
            fy_px,
            cx_px: 0.5 * width_px as f64,
            cy_px: 0.5 * height_px as f64,
        };
        CameraSpec {
            name: name.to_string(),
            width_px,
            height_px,
            sensor_width_mm,
            sensor_height_mm,
            hfov_deg,
            focal_mm,
            intrinsics,
            distortion: None,
            strategy,
        }
    }

    /// A built-in preset by name (`cam1`, `cam2`, `cam3`), or `None`.
    ///
    /// # References
    /// LoD-Loc v3 (CVPR 2026), table "Camera configurations" (see SPEC.md).
    pub fn preset(name: &str) -> Option<Self> {
        match name {
            // 1600×1200, 16 mm × 12 mm, 45°, irregular sequences.
            "cam1" => Some(Self::from_sensor("cam1", 1600, 1200, 16.0, 12.0, 45.0, Trajectory::Irregular)),
            // 1920×1080, 23.76 mm × 13.365 mm, 25°, uniform grid.
            "cam2" => Some(Self::from_sensor("cam2", 1920, 1080, 23.76, 13.365, 25.0, Trajectory::Grid)),
            // Same body as cam2, flown on regular survey lines.
            "cam3" => Some(Self::from_sensor("cam3", 1920, 1080, 23.76, 13.365, 25.0, Trajectory::Regular)),
            _ => None,
        }
    }

    /// All built-in presets in table order.
    pub fn presets() -> Vec<Self> {
        PRESET_NAMES.iter().filter_map(|n| Self::preset(n)).collect()
    }

    /// Resolves a `--camera` value: a preset name, or the path of a camera TOML file.
    ///
    /// # Errors
    /// [`CameraError::UnknownPreset`] (listing the presets) when `arg` is neither; the errors of
    /// [`CameraSpec::load`] for a file.
    pub fn resolve(arg: &str) -> Result<Self, CameraError> {
        if let Some(spec) = Self::preset(arg) {
            return Ok(spec);
        }
        let path = Path::new(arg);
        if path.is_file() || Self::names_a_file(arg) {
            return Self::load(path);
        }
        Err(CameraError::UnknownPreset { name: arg.to_string(), available: PRESET_NAMES.join(", ") })
    }

    /// Whether a `--camera` value names a file (`.toml`, or a path) rather than a preset or a name.
    pub fn names_a_file(arg: &str) -> bool {
        arg.ends_with(".toml") || arg.contains('/') || arg.contains('\\')
    }

    /// Reads a custom camera TOML file (`schemas/camera.schema.json`).
    ///
    /// # Errors
    /// [`CameraError::File`] when it cannot be read, [`CameraError::NotUtf8`] when it is not text, and
    /// the errors of [`CameraSpec::from_toml_str`].
    pub fn load(path: &Path) -> Result<Self, CameraError> {
        let bytes = crate::util::read_file(path)?;
        let text = String::from_utf8(bytes)
            .map_err(|source| CameraError::NotUtf8 { path: path.to_path_buf(), source })?;
        Self::from_toml_str(&text, path)
    }

    /// Parses and validates a custom camera from TOML text; `path` is used in error messages only.
    ///
    /// # Errors
    /// [`CameraError::CameraToml`] when the text is not TOML or not a camera table (TOML's error, with
    /// its line, as the source); [`CameraError::CameraFile`] with one entry per broken rule (field and
    /// offending value).
    pub fn from_toml_str(text: &str, path: &Path) -> Result<Self, CameraError> {
        let raw: RawCamera = toml::from_str(text)
            .map_err(|e| CameraError::CameraToml { path: PathBuf::from(path), source: Box::new(e) })?;
        raw.into_spec().map_err(|issues| CameraError::CameraFile { path: PathBuf::from(path), issues })
    }

    /// Projects a point given in the area's ENU frame (metres) to pixel coordinates for a camera at
    /// `pose`, or `None` when the point is behind the camera. Ignores distortion (pinhole).
    pub fn project_enu(&self, pose: &super::Pose, p_enu_m: [f64; 3]) -> Option<[f64; 2]> {
        self.intrinsics.project(pose.world_to_cam(p_enu_m.into()))
    }
}

/// Focal length in millimetres from the sensor width (mm) and horizontal FOV (degrees):
/// f = (w / 2) / tan(hfov / 2).
pub fn focal_mm_from_hfov(sensor_width_mm: f64, hfov_deg: f64) -> f64 {
    0.5 * sensor_width_mm / (0.5 * hfov_deg.to_radians()).tan()
}

/// The custom camera file as written (all optional fields optional), before validation.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawCamera {
    name: String,
    width_px: i64,
    height_px: i64,
    sensor_width_mm: f64,
    sensor_height_mm: f64,
    hfov_deg: Option<f64>,
    focal_mm: Option<f64>,
    #[serde(default)]
    strategy: Option<Trajectory>,
    fx_px: Option<f64>,
    fy_px: Option<f64>,
    cx_px: Option<f64>,
    cy_px: Option<f64>,
    distortion: Option<Distortion>,
}

/// Largest accepted image side, pixels (keeps the renderers' textures within common GPU limits).
const MAX_SIDE_PX: i64 = 16384;

impl RawCamera {
    /// The camera, or every broken rule with its field.
    fn into_spec(self) -> Result<CameraSpec, Vec<ConfigIssue>> {
        let mut issues = Vec::new();
        self.check_name(&mut issues);
        self.check_size(&mut issues);
        let hfov_deg = self.hfov_deg(&mut issues);
        self.check_intrinsics(&mut issues);
        self.check_distortion(&mut issues);
        let Some(hfov_deg) = hfov_deg else { return Err(issues) };
        if !issues.is_empty() {
            return Err(issues);
        }
        Ok(self.build(hfov_deg))
    }

    /// `name`: a usable directory name that is not a preset's.
    fn check_name(&self, issues: &mut Vec<ConfigIssue>) {
        let name_ok = !self.name.is_empty()
            && self.name.chars().all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-');
        let name = format!("{:?}", self.name);
        if !name_ok {
            issues.push(ConfigIssue::value(
                "name",
                name,
                "must be non-empty and use only letters, digits, '_' and '-' (it names the output directory)",
            ));
        } else if PRESET_NAMES.contains(&self.name.as_str()) {
            issues.push(ConfigIssue::value("name", name, "is a built-in preset name; choose another"));
        }
    }

    /// `width_px`/`height_px` in range and the sensor size positive.
    fn check_size(&self, issues: &mut Vec<ConfigIssue>) {
        for (field, v) in [("width_px", self.width_px), ("height_px", self.height_px)] {
            if !(1..=MAX_SIDE_PX).contains(&v) {
                issues.push(ConfigIssue::value(field, v, format!("must be in 1..={MAX_SIDE_PX}")));
            }
        }
        for (field, v) in
            [("sensor_width_mm", self.sensor_width_mm), ("sensor_height_mm", self.sensor_height_mm)]
        {
            if !(v.is_finite() && v > 0.0) {
                issues.push(ConfigIssue::value(field, v, "must be a positive number of millimetres"));
            }
        }
    }

    /// The horizontal field of view in degrees, from `hfov_deg` or else `focal_mm` (which must agree
    /// when both are given); `None` when neither is usable.
    fn hfov_deg(&self, issues: &mut Vec<ConfigIssue>) -> Option<f64> {
        match (self.hfov_deg, self.focal_mm) {
            (None, None) => {
                issues.push(ConfigIssue::field(
                    "hfov_deg",
                    "missing; give it (the horizontal field of view) or focal_mm",
                ));
                None
            }
            (Some(h), _) if !(h.is_finite() && h > 0.0 && h < 180.0) => {
                issues.push(ConfigIssue::value("hfov_deg", h, "must be in (0, 180) degrees"));
                None
            }
            (Some(h), f) => {
                if let Some(f) = f {
                    let expect = focal_mm_from_hfov(self.sensor_width_mm, h);
                    if !(f.is_finite() && (f - expect).abs() <= 1e-3 * expect) {
                        issues.push(ConfigIssue::value(
                            "focal_mm",
                            f,
                            format!(
                                "disagrees with hfov_deg = {h} and sensor_width_mm = {} (which give \
                                 {expect:.4} mm); give only one of them",
                                self.sensor_width_mm
                            ),
                        ));
                    }
                }
                Some(h)
            }
            (None, Some(f)) if !(f.is_finite() && f > 0.0) => {
                issues.push(ConfigIssue::value("focal_mm", f, "must be a positive number of millimetres"));
                None
            }
            (None, Some(f)) => Some(2.0 * (0.5 * self.sensor_width_mm / f).atan().to_degrees()),
        }
    }

    /// Explicit focal lengths positive and the principal point inside the image.
    fn check_intrinsics(&self, issues: &mut Vec<ConfigIssue>) {
        for (field, v) in [("fx_px", self.fx_px), ("fy_px", self.fy_px)] {
            if let Some(v) = v {
                if !(v.is_finite() && v > 0.0) {
                    issues.push(ConfigIssue::value(field, v, "must be a positive number of pixels"));
                }
            }
        }
        for (field, v, side) in [("cx_px", self.cx_px, self.width_px), ("cy_px", self.cy_px, self.height_px)]
        {
            if let Some(v) = v {
                if !(v.is_finite() && v >= 0.0 && v <= side as f64) {
                    issues.push(ConfigIssue::value(
                        field,
                        v,
                        format!("must lie inside the image, in [0, {side}] pixels"),
                    ));
                }
            }
        }
    }

    /// Distortion coefficients finite.
    fn check_distortion(&self, issues: &mut Vec<ConfigIssue>) {
        if let Some(d) = &self.distortion {
            for (field, v) in [("k1", d.k1), ("k2", d.k2), ("p1", d.p1), ("p2", d.p2), ("k3", d.k3)] {
                if !v.is_finite() {
                    issues.push(ConfigIssue::value(
                        format!("distortion.{field}"),
                        v,
                        "must be a finite number",
                    ));
                }
            }
        }
    }

    /// The validated camera with field of view `hfov_deg` (degrees): the centred pinhole camera of
    /// its sensor, with the explicit intrinsics and distortion applied.
    fn build(self, hfov_deg: f64) -> CameraSpec {
        let mut spec = CameraSpec::from_sensor(
            &self.name,
            self.width_px as u32,
            self.height_px as u32,
            self.sensor_width_mm,
            self.sensor_height_mm,
            hfov_deg,
            self.strategy.unwrap_or(Trajectory::Grid),
        );
        let k = &mut spec.intrinsics;
        k.fx_px = self.fx_px.unwrap_or(k.fx_px);
        k.fy_px = self.fy_px.unwrap_or(k.fy_px);
        k.cx_px = self.cx_px.unwrap_or(k.cx_px);
        k.cy_px = self.cy_px.unwrap_or(k.cy_px);
        // An explicit fx redefines the horizontal field of view; keep the derived fields consistent.
        spec.hfov_deg = spec.intrinsics.hfov_deg();
        spec.focal_mm = spec.intrinsics.fx_px * spec.sensor_width_mm / spec.width_px as f64;
        spec.distortion = self.distortion;
        spec
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn presets_match_the_paper_table() {
        // Hand computations: cam1 f = 8 mm / tan(22.5°) = 19.3137 mm = 1931.37 px (0.01 mm pitch);
        // cam2 f = 11.88 mm / tan(12.5°) = 53.5872 mm = 4330.28 px (0.012375 mm pitch), the brief's
        // "4330.0 px" to four significant digits.
        let c1 = CameraSpec::preset("cam1").unwrap();
        assert!((c1.focal_mm - 8.0 / 22.5f64.to_radians().tan()).abs() < 1e-12);
        assert!((c1.intrinsics.fx_px - 1931.37).abs() < 0.01, "{}", c1.intrinsics.fx_px);
        assert!((c1.intrinsics.fx_px - c1.intrinsics.fy_px).abs() < 1e-9);
        assert_eq!((c1.intrinsics.cx_px, c1.intrinsics.cy_px), (800.0, 600.0));
        let c2 = CameraSpec::preset("cam2").unwrap();
        assert!((c2.focal_mm - 53.5872).abs() < 1e-4, "{}", c2.focal_mm);
        assert!((c2.intrinsics.fx_px - 4330.28).abs() < 0.005, "{}", c2.intrinsics.fx_px);
        assert!((c2.intrinsics.fx_px - 4330.0).abs() < 0.5);
        assert!((c2.intrinsics.fy_px - c2.intrinsics.fx_px).abs() < 1e-9);
        assert_eq!(CameraSpec::preset("cam3").unwrap().intrinsics, c2.intrinsics);
        assert_eq!(c2.intrinsics, Intrinsics::from_hfov(1920, 1080, 25.0));
        assert_eq!(c1.intrinsics, Intrinsics::from_hfov(1600, 1200, 45.0));
        assert_eq!(c2.strategy, Trajectory::Grid);
    }

    #[test]
    fn unknown_preset_lists_the_available_ones() {
        let e = CameraSpec::resolve("cam4").unwrap_err().to_string();
        assert!(e.contains("\"cam4\"") && e.contains("cam1, cam2, cam3"), "{e}");
    }

    #[test]
    fn custom_camera_reports_every_problem() {
        let text = "name = \"bad name\"\nwidth_px = 0\nheight_px = 100\nsensor_width_mm = -1\n\
                    sensor_height_mm = 5\nhfov_deg = 190\ncx_px = 5000\n";
        let e = CameraSpec::from_toml_str(text, Path::new("x.toml")).unwrap_err();
        let CameraError::CameraFile { issues, .. } = &e else { panic!("{e}") };
        let fields: Vec<&str> = issues.iter().map(|i| i.field.as_str()).collect();
        assert_eq!(fields, ["name", "width_px", "sensor_width_mm", "hfov_deg", "cx_px"], "{issues:#?}");
        assert_eq!(
            e.to_string(),
            "x.toml: invalid camera file:\n  \
             - name = \"bad name\": must be non-empty and use only letters, digits, '_' and '-' (it names the \
             output directory)\n  \
             - width_px = 0: must be in 1..=16384\n  \
             - sensor_width_mm = -1: must be a positive number of millimetres\n  \
             - hfov_deg = 190: must be in (0, 180) degrees\n  \
             - cx_px = 5000: must lie inside the image, in [0, 0] pixels"
        );
    }

    #[test]
    fn custom_camera_toml_errors_keep_their_cause() {
        let e = CameraSpec::from_toml_str("name = \"c\"\nwidth = 10\n", Path::new("x.toml")).unwrap_err();
        assert!(matches!(e, CameraError::CameraToml { .. }), "{e:?}");
        let msg = crate::util::error_chain(&e);
        assert!(msg.starts_with("x.toml: invalid camera file: TOML parse error at line 2"), "{msg}");
        assert!(msg.contains("unknown field `width`"), "{msg}");
    }
}
