//! The `[sampling]` table of a scene file: parameters of the three pose-sampling strategies, the
//! visibility and clearance checks, and the prior noise model.
//!
//! Every field has a default (the paper's values where the paper gives one), so an absent table or
//! any absent field means "paper setting". Unknown fields are rejected, so a typo is an error rather
//! than a silently ignored setting. Example (all defaults spelt out):
//!
//! ```toml
//! [sampling]
//! clearance_m = 50.0             # above the tallest building near the camera
//! clearance_radius_m = 40.0      # "near": building boxes within this horizontal distance
//! min_building_fraction = 0.15   # share of the coarse ray grid that must hit a building
//! max_building_fraction = 0.8    # … and at most this share: some ground between the buildings
//! min_visible_buildings = 3      # distinct buildings first hit by some ray of that grid
//! min_covered_cells = 0          # of the frame's 4 × 4 cells, those whose rays hit buildings
//! max_off_map_share = 0.5        # share of that grid landing beyond the modelled ground (or sky)
//! visibility_rays = [16, 12]     # coarse ray grid (columns, rows)
//! max_attempts_per_pose = 30
//!
//! [sampling.grid]                # cam2
//! spacing_m = 100.0
//! height_range_m = [200.0, 500.0]
//! pitch_deg = [0.0, 45.0]
//! yaw_deg = []                   # empty: uniform in [0, 360)
//! margin_m = 0.0
//!
//! [sampling.regular]             # cam3
//! line_spacing_m = 150.0
//! frame_spacing_m = 50.0
//! height_range_m = [400.0, 500.0]
//! pitch_deg = [0.0, 45.0]
//! # line_heading_deg = 0.0       # absent: the polygon's principal axis
//! min_sequence_frames = 2
//!
//! [sampling.irregular]           # cam1
//! height_range_m = [200.0, 500.0]
//! pitch_range_deg = [0.0, 70.0]
//! frame_spacing_m = 15.0
//! max_turn_deg_per_frame = 6.0
//! max_turn_change_deg_per_frame = 1.5
//! max_pitch_deg_per_frame = 2.0
//! max_climb_m_per_frame = 3.0
//! frames_per_sequence = 120
//! min_sequence_frames = 10
//! default_frames = 600
//! waypoint_margin_m = 60.0
//!
//! [sampling.prior]
//! sigma_enu_m = [7.0, 7.0, 5.0]
//! sigma_ypr_deg = [1.8, 1.2, 1.2]
//! bias_enu_m = [0.0, 0.0, 0.0]
//! bias_ypr_deg = [0.0, 0.0, 0.0]
//! ```
//!
//! Heights are metres above the area's ground level (`manifest.ground_enu_m`, which the scene stage
//! estimates from the lowest building vertices), not above the ellipsoid or the area origin.

use std::path::Path;

use serde::{Deserialize, Serialize};

use super::error::ConfigIssue;
use super::CameraError;

/// Sampling settings (the scene file's optional `[sampling]` table). See the module doc.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SamplingConfig {
    /// Minimum vertical distance between the camera and the top of the tallest building box within
    /// `clearance_radius_m` of it, metres.
    pub clearance_m: f64,
    /// Horizontal radius around the camera in which buildings count as "under" it, metres.
    pub clearance_radius_m: f64,
    /// Minimum share (0..1) of the coarse ray grid that must hit a building (its triangles: an
    /// estimate of the share of building pixels).
    pub min_building_fraction: f64,
    /// Maximum share (0..1) of the coarse ray grid that may hit a building: a view needs ground
    /// between its buildings. Where one or a few large buildings fill the frame (a nadir view close
    /// over a high-rise), the only outlines left are the few boundaries between roofs and the frame's
    /// edges, and the pose is ambiguous along them (issue 40, bench/loc_sparse.md: of 55 Shibuya cam2
    /// views with at most 7 buildings, the 7 whose buildings covered more than 80 % of the frame
    /// missed 3 times against the exact map and 7 times against its LoD1 map; the 48 others 1 and
    /// 11 times). 1 keeps every view.
    pub max_building_fraction: f64,
    /// Minimum number of distinct buildings a view must show: buildings that are the first hit of at
    /// least one ray of the visibility grid. Silhouettes of one or two buildings leave the pose
    /// ambiguous (issue 15).
    pub min_visible_buildings: u32,
    /// Minimum number of the frame's 4 × 4 cells whose rays hit buildings (at least 5 % of a cell's
    /// rays; [`super::visibility::ViewCensus::covered_cells`]), 0–16. Views whose buildings crowd
    /// into a few cells (looking past the map's edge) observe the camera's depth along its axis
    /// poorly, and errors in a map move the optimum along it (issue 15: eval-loc's recall per
    /// `covered_frame_cells` bucket). 0 (the default) keeps them: a perfect map localizes them.
    pub min_covered_cells: u32,
    /// Maximum share (0..1) of the coarse ray grid that hits no building and lands beyond the map:
    /// on the ground outside the convex hull of the building footprints, or at or above the horizon
    /// ([`super::visibility::ViewCensus::off_map_share`]). Such a view is mostly land the map does
    /// not model: a photogrammetry render shows buildings there that have no mask, a procedural one
    /// shows an empty plain no flight over the city would see, and the localizer pins the camera's
    /// depth from buildings crowded into a corner of the frame, which errors in a map move (issue 15).
    /// 1 keeps every view.
    pub max_off_map_share: f64,
    /// Coarse ray grid for the visibility test: [columns, rows] of rays through pixel centres of an
    /// evenly divided image.
    pub visibility_rays: [u32; 2],
    /// Candidate draws allowed per accepted pose before the strategy gives up.
    pub max_attempts_per_pose: u32,
    /// `[sampling.grid]`: the uniform-grid strategy.
    pub grid: GridConfig,
    /// `[sampling.regular]`: the survey-line strategy.
    pub regular: RegularConfig,
    /// `[sampling.irregular]`: the free-trajectory strategy.
    pub irregular: IrregularConfig,
    /// `[sampling.prior]`: the noise model of the pose priors.
    pub prior: PriorNoise,
}

/// Grid strategy (cam2): independent poses on a uniform lattice over the area polygon.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct GridConfig {
    /// Lattice spacing, metres.
    pub spacing_m: f64,
    /// Height above ground, drawn uniformly in [min, max], metres. Paper: [200, 500].
    pub height_range_m: [f64; 2],
    /// View angles (tilt from nadir), degrees; every lattice node gets one pose per angle. Paper: 0, 45.
    pub pitch_deg: Vec<f64>,
    /// Yaws to draw from (degrees clockwise from north); empty = uniform in [0, 360).
    pub yaw_deg: Vec<f64>,
    /// Lattice nodes must lie at least this far inside the polygon, metres.
    pub margin_m: f64,
}

/// Regular sequence strategy (cam3): lawn-mower survey lines.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RegularConfig {
    /// Distance between neighbouring survey lines (across track), metres.
    pub line_spacing_m: f64,
    /// Distance between consecutive frames on a line (along track), metres.
    pub frame_spacing_m: f64,
    /// Height above ground of a line, drawn uniformly per line in [min, max], metres. Paper: [400, 500].
    pub height_range_m: [f64; 2],
    /// View angles, degrees; one full pass of lines per angle. Paper: 0, 45.
    pub pitch_deg: Vec<f64>,
    /// Heading of the lines, degrees clockwise from north; absent = the polygon's principal axis.
    pub line_heading_deg: Option<f64>,
    /// Runs of consecutive accepted frames shorter than this are dropped.
    pub min_sequence_frames: u32,
}

/// Irregular sequence strategy (cam1): smooth random flights through random waypoints.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct IrregularConfig {
    /// Height above ground, metres; waypoint heights are drawn in this range. Paper: [200, 500].
    pub height_range_m: [f64; 2],
    /// Tilt from nadir, degrees; varies continuously inside this range. Paper: [0, 70].
    pub pitch_range_deg: [f64; 2],
    /// Horizontal distance flown between frames (constant ground speed), metres.
    pub frame_spacing_m: f64,
    /// Largest heading change between consecutive frames, degrees.
    pub max_turn_deg_per_frame: f64,
    /// Largest change of the turn rate between consecutive frames, degrees per frame.
    pub max_turn_change_deg_per_frame: f64,
    /// Largest tilt change between consecutive frames, degrees.
    pub max_pitch_deg_per_frame: f64,
    /// Largest height change between consecutive frames, metres.
    pub max_climb_m_per_frame: f64,
    /// Frames flown per trajectory before a new one starts elsewhere.
    pub frames_per_sequence: u32,
    /// Runs of consecutive accepted frames shorter than this are dropped.
    pub min_sequence_frames: u32,
    /// Frames sampled when `--count` is not given.
    pub default_frames: u32,
    /// Waypoints and starting points keep at least this distance from the polygon boundary, metres.
    pub waypoint_margin_m: f64,
}

/// Noise model of the prior poses (`priors.jsonl`): independent Gaussian errors plus a constant bias.
///
/// The defaults give median prior errors of about 9.7 m and 2.0° (measured over 20 000 draws; see
/// `camera::prior`), inside the range of public UAV benchmarks (UAVD4L-LoD, the paper's Tokyo set:
/// medians 6–18 m and 0.9–4°). Each frame draws its errors from a generator keyed by the run's seed
/// and the frame's name (`camera::prior::prior_rng`), independent of the other frames, areas and
/// cameras.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct PriorNoise {
    /// Standard deviation of the camera-centre error along east, north, up, metres.
    pub sigma_enu_m: [f64; 3],
    /// Standard deviation of the yaw, pitch and roll errors, degrees.
    pub sigma_ypr_deg: [f64; 3],
    /// Constant offset added to the camera centre (east, north, up), metres.
    pub bias_enu_m: [f64; 3],
    /// Constant offset added to yaw, pitch, roll, degrees.
    pub bias_ypr_deg: [f64; 3],
}

/// The default [`SamplingConfig::max_building_fraction`] (issue 40, bench/loc_sparse.md).
pub const DEFAULT_MAX_BUILDING_FRACTION: f64 = 0.8;

impl Default for SamplingConfig {
    fn default() -> Self {
        SamplingConfig {
            clearance_m: 50.0,
            clearance_radius_m: 40.0,
            min_building_fraction: 0.15,
            max_building_fraction: DEFAULT_MAX_BUILDING_FRACTION,
            min_visible_buildings: 3,
            min_covered_cells: 0,
            max_off_map_share: 0.5,
            visibility_rays: [16, 12],
            max_attempts_per_pose: 30,
            grid: GridConfig::default(),
            regular: RegularConfig::default(),
            irregular: IrregularConfig::default(),
            prior: PriorNoise::default(),
        }
    }
}

impl Default for GridConfig {
    fn default() -> Self {
        GridConfig {
            spacing_m: 100.0,
            height_range_m: [200.0, 500.0],
            pitch_deg: vec![0.0, 45.0],
            yaw_deg: Vec::new(),
            margin_m: 0.0,
        }
    }
}

impl Default for RegularConfig {
    fn default() -> Self {
        RegularConfig {
            line_spacing_m: 150.0,
            frame_spacing_m: 50.0,
            height_range_m: [400.0, 500.0],
            pitch_deg: vec![0.0, 45.0],
            line_heading_deg: None,
            min_sequence_frames: 2,
        }
    }
}

impl Default for IrregularConfig {
    fn default() -> Self {
        IrregularConfig {
            height_range_m: [200.0, 500.0],
            pitch_range_deg: [0.0, 70.0],
            frame_spacing_m: 15.0,
            max_turn_deg_per_frame: 6.0,
            max_turn_change_deg_per_frame: 1.5,
            max_pitch_deg_per_frame: 2.0,
            max_climb_m_per_frame: 3.0,
            frames_per_sequence: 120,
            min_sequence_frames: 10,
            default_frames: 600,
            waypoint_margin_m: 60.0,
        }
    }
}

impl Default for PriorNoise {
    fn default() -> Self {
        PriorNoise {
            sigma_enu_m: [7.0, 7.0, 5.0],
            // Yaw from a magnetometer/GNSS heading; pitch and roll from the IMU's gravity estimate,
            // which the localizer trusts (4-DoF search, as the paper): keep them tight. At cam2's
            // ~570 m slant range each 0.01° of tilt error moves the best 4-DoF pose by ~0.1 m.
            sigma_ypr_deg: [3.0, 0.02, 0.02],
            bias_enu_m: [0.0; 3],
            bias_ypr_deg: [0.0; 3],
        }
    }
}

impl SamplingConfig {
    /// Reads the optional `[sampling]` table from a scene file's TOML text, ignoring every other
    /// table (those belong to the scene configuration). Absent table → defaults.
    ///
    /// # Errors
    /// [`CameraError::ConfigToml`] when the text is not TOML or the table has unknown keys or wrong
    /// types (TOML's error as the source); [`CameraError::Config`] when the table breaks a rule (all
    /// listed).
    pub fn from_scene_toml(text: &str, path: Option<&Path>) -> Result<Self, CameraError> {
        let origin = path.map(Path::to_path_buf);
        let toml_err = |e| CameraError::ConfigToml { origin: origin.clone(), source: Box::new(e) };
        let doc: toml::Table = toml::from_str(text).map_err(toml_err)?;
        let cfg = match doc.get("sampling") {
            None => SamplingConfig::default(),
            Some(v) => v.clone().try_into::<SamplingConfig>().map_err(toml_err)?,
        };
        cfg.validate().map_err(|e| match e {
            CameraError::Config { issues, .. } => CameraError::Config { origin: origin.clone(), issues },
            other => other,
        })?;
        Ok(cfg)
    }

    /// Checks every rule and reports all broken ones, each naming its field and value.
    ///
    /// # Errors
    /// [`CameraError::Config`] with one entry per problem (e.g. an impossible height range).
    pub fn validate(&self) -> Result<(), CameraError> {
        let mut issues = Vec::new();
        self.check_spacings(&mut issues);
        self.check_acceptance(&mut issues);
        self.check_ranges(&mut issues);
        self.check_view_angles(&mut issues);
        self.check_sequences(&mut issues);
        self.check_prior(&mut issues);
        if issues.is_empty() {
            Ok(())
        } else {
            Err(CameraError::Config { origin: None, issues })
        }
    }

    /// Distances, spacings and per-frame limits: positive, or ≥ 0 for clearances and margins.
    fn check_spacings(&self, issues: &mut Vec<ConfigIssue>) {
        let mut positive = |field: &str, v: f64| {
            if !(v.is_finite() && v > 0.0) {
                issues.push(ConfigIssue::value(field, v, "must be a positive number"));
            }
        };
        positive("clearance_radius_m", self.clearance_radius_m);
        positive("grid.spacing_m", self.grid.spacing_m);
        positive("regular.line_spacing_m", self.regular.line_spacing_m);
        positive("regular.frame_spacing_m", self.regular.frame_spacing_m);
        positive("irregular.frame_spacing_m", self.irregular.frame_spacing_m);
        positive("irregular.max_turn_deg_per_frame", self.irregular.max_turn_deg_per_frame);
        positive("irregular.max_turn_change_deg_per_frame", self.irregular.max_turn_change_deg_per_frame);
        positive("irregular.max_pitch_deg_per_frame", self.irregular.max_pitch_deg_per_frame);
        positive("irregular.max_climb_m_per_frame", self.irregular.max_climb_m_per_frame);
        let mut non_negative = |field: &str, v: f64| {
            if !(v.is_finite() && v >= 0.0) {
                issues.push(ConfigIssue::value(field, v, "must be a number ≥ 0"));
            }
        };
        non_negative("clearance_m", self.clearance_m);
        non_negative("grid.margin_m", self.grid.margin_m);
        non_negative("irregular.waypoint_margin_m", self.irregular.waypoint_margin_m);
    }

    /// The rules a pose must pass to be kept: shares, covered cells, visibility rays, attempts.
    fn check_acceptance(&self, issues: &mut Vec<ConfigIssue>) {
        if !(0.0..=1.0).contains(&self.min_building_fraction) {
            issues.push(ConfigIssue::value(
                "min_building_fraction",
                self.min_building_fraction,
                "must be in [0, 1]",
            ));
        }
        if !(0.0..=1.0).contains(&self.max_building_fraction) {
            issues.push(ConfigIssue::value(
                "max_building_fraction",
                self.max_building_fraction,
                "must be in [0, 1]",
            ));
        } else if self.max_building_fraction < self.min_building_fraction {
            issues.push(ConfigIssue::value(
                "max_building_fraction",
                self.max_building_fraction,
                format!("must be at least min_building_fraction ({})", self.min_building_fraction),
            ));
        }
        if !(0.0..=1.0).contains(&self.max_off_map_share) {
            issues.push(ConfigIssue::value("max_off_map_share", self.max_off_map_share, "must be in [0, 1]"));
        }
        if self.min_covered_cells > super::visibility::FRAME_CELLS {
            issues.push(ConfigIssue::value(
                "min_covered_cells",
                self.min_covered_cells,
                format!("must be at most {} (the frame's cells)", super::visibility::FRAME_CELLS),
            ));
        }
        if self.visibility_rays.contains(&0) || self.visibility_rays.iter().any(|&n| n > 256) {
            let rays = format!("{:?}", self.visibility_rays);
            issues.push(ConfigIssue::value("visibility_rays", rays, "each count must be in 1..=256"));
        }
        if self.max_attempts_per_pose == 0 {
            issues.push(ConfigIssue::value("max_attempts_per_pose", 0, "must be at least 1"));
        }
    }

    /// Height ranges (metres) and the irregular pitch range (degrees).
    fn check_ranges(&self, issues: &mut Vec<ConfigIssue>) {
        for (field, r) in [
            ("grid.height_range_m", self.grid.height_range_m),
            ("regular.height_range_m", self.regular.height_range_m),
            ("irregular.height_range_m", self.irregular.height_range_m),
        ] {
            if let Some(why) = range_problem(r, 0.0, 20_000.0) {
                let range = format!("[{}, {}]", r[0], r[1]);
                issues.push(ConfigIssue::value(field, range, format!("impossible height range: {why}")));
            }
        }
        if let Some(why) = range_problem(self.irregular.pitch_range_deg, 0.0, 89.0) {
            let r = self.irregular.pitch_range_deg;
            issues.push(ConfigIssue::value(
                "irregular.pitch_range_deg",
                format!("[{}, {}]", r[0], r[1]),
                why,
            ));
        }
    }

    /// The grid and regular view angles, grid yaws and the regular line heading.
    fn check_view_angles(&self, issues: &mut Vec<ConfigIssue>) {
        for (field, list) in
            [("grid.pitch_deg", &self.grid.pitch_deg), ("regular.pitch_deg", &self.regular.pitch_deg)]
        {
            if list.is_empty() {
                issues.push(ConfigIssue::value(field, "[]", "give at least one view angle"));
            }
            for &p in list.iter() {
                if !(p.is_finite() && (0.0..=89.0).contains(&p)) {
                    issues.push(ConfigIssue::field(
                        field,
                        format!("contains {p}; view angles must be in [0, 89] degrees"),
                    ));
                }
            }
        }
        for &y in &self.grid.yaw_deg {
            if !y.is_finite() {
                issues.push(ConfigIssue::field("grid.yaw_deg", format!("contains {y}; each must be finite")));
            }
        }
        if let Some(h) = self.regular.line_heading_deg {
            if !h.is_finite() {
                issues.push(ConfigIssue::value("regular.line_heading_deg", h, "must be finite"));
            }
        }
    }

    /// Irregular sequence lengths (frames).
    fn check_sequences(&self, issues: &mut Vec<ConfigIssue>) {
        if self.irregular.frames_per_sequence == 0 {
            issues.push(ConfigIssue::value("irregular.frames_per_sequence", 0, "must be at least 1"));
        }
        if self.irregular.min_sequence_frames > self.irregular.frames_per_sequence {
            issues.push(ConfigIssue::value(
                "irregular.min_sequence_frames",
                self.irregular.min_sequence_frames,
                format!("exceeds irregular.frames_per_sequence = {}", self.irregular.frames_per_sequence),
            ));
        }
    }

    /// The pose prior's standard deviations (≥ 0) and biases (finite).
    fn check_prior(&self, issues: &mut Vec<ConfigIssue>) {
        let p = &self.prior;
        for (field, v) in [("prior.sigma_enu_m", p.sigma_enu_m), ("prior.sigma_ypr_deg", p.sigma_ypr_deg)] {
            if v.iter().any(|s| !(s.is_finite() && *s >= 0.0)) {
                issues.push(ConfigIssue::value(field, format!("{v:?}"), "standard deviations must be ≥ 0"));
            }
        }
        for (field, v) in [("prior.bias_enu_m", p.bias_enu_m), ("prior.bias_ypr_deg", p.bias_ypr_deg)] {
            if v.iter().any(|s| !s.is_finite()) {
                issues.push(ConfigIssue::value(field, format!("{v:?}"), "must be finite"));
            }
        }
    }
}

/// Why `[lo, hi]` is not a usable range inside [min, max], if it is not.
fn range_problem(r: [f64; 2], min: f64, max: f64) -> Option<String> {
    let [lo, hi] = r;
    if !(lo.is_finite() && hi.is_finite()) {
        Some("bounds must be finite".to_string())
    } else if lo > hi {
        Some("the minimum is above the maximum".to_string())
    } else if lo < min || hi > max {
        Some(format!("bounds must lie in [{min}, {max}]"))
    } else {
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn absent_table_means_paper_defaults() {
        let cfg = SamplingConfig::from_scene_toml("name = \"x\"\n[area]\nfoo = 1\n", None).unwrap();
        assert_eq!(cfg, SamplingConfig::default());
        assert_eq!(cfg.grid.height_range_m, [200.0, 500.0]);
        assert_eq!(cfg.regular.height_range_m, [400.0, 500.0]);
        assert_eq!(cfg.irregular.pitch_range_deg, [0.0, 70.0]);
    }

    #[test]
    fn partial_table_keeps_other_defaults() {
        let cfg = SamplingConfig::from_scene_toml("[sampling.grid]\nspacing_m = 40.0\n", None).unwrap();
        assert_eq!(cfg.grid.spacing_m, 40.0);
        assert_eq!(cfg.grid.pitch_deg, vec![0.0, 45.0]);
    }

    #[test]
    fn impossible_height_range_and_typos_are_errors() {
        let e = SamplingConfig::from_scene_toml(
            "[sampling.regular]\nheight_range_m = [500.0, 400.0]\n",
            Some(Path::new("scenes/x.toml")),
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("scenes/x.toml") && e.contains("regular.height_range_m = [500, 400]"), "{e}");
        let e = SamplingConfig::from_scene_toml("[sampling.grid]\nspacing = 40.0\n", None).unwrap_err();
        assert!(matches!(e, CameraError::ConfigToml { .. }), "{e:?}");
        let msg = crate::util::error_chain(&e);
        assert!(msg.starts_with("invalid [sampling] configuration: unknown field `spacing`"), "{msg}");
    }

    #[test]
    fn off_map_share_is_a_share() {
        let cfg = SamplingConfig::from_scene_toml("[sampling]\nmax_off_map_share = 1.0\n", None).unwrap();
        assert_eq!(cfg.max_off_map_share, 1.0);
        assert_eq!(SamplingConfig::default().max_off_map_share, 0.5);
        for bad in ["1.5", "-0.1", "nan"] {
            let toml = format!("[sampling]\nmax_off_map_share = {bad}\n");
            let e = SamplingConfig::from_scene_toml(&toml, None).unwrap_err();
            let msg = e.to_string();
            assert!(msg.contains("max_off_map_share") && msg.contains("[0, 1]"), "{msg}");
        }
    }

    #[test]
    fn covered_cells_are_at_most_the_frame_s() {
        let cfg = SamplingConfig::from_scene_toml("[sampling]\nmin_covered_cells = 16\n", None).unwrap();
        assert_eq!(cfg.min_covered_cells, 16);
        let e = SamplingConfig::from_scene_toml("[sampling]\nmin_covered_cells = 17\n", None).unwrap_err();
        let msg = crate::util::error_chain(&e);
        assert!(msg.contains("min_covered_cells = 17") && msg.contains("at most 16"), "{msg}");
    }
}
