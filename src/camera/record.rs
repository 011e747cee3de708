//! `poses.jsonl` records: one camera frame per line, with every representation a downstream tool may
//! want (ENU camera-to-world, COLMAP world-to-camera, ECEF, WGS84, yaw/pitch/roll).
//!
//! The pose itself is [`PoseRecord::pose`]; all other fields are derived from it and the area's ENU
//! frame by [`PoseRecord::new`] and are checked for consistency by the tests.

use glam::DMat4;
use serde::{Deserialize, Serialize};

use super::{Intrinsics, Pose};
use crate::geo::EnuFrame;

/// The kind of flight a frame belongs to.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Trajectory {
    /// A uniform lattice of independent poses (cam2).
    Grid,
    /// Straight survey lines (cam3).
    Regular,
    /// Smooth random trajectories (cam1).
    Irregular,
}

/// One line of `poses.jsonl` (schema: `schemas/poses.schema.json`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PoseRecord {
    /// Unique frame name, also the stem of every per-frame output file.
    pub name: String,
    /// The area (scene) name.
    pub area: String,
    /// Camera preset name (cam1, cam2, cam3 or a custom one).
    pub preset: String,
    /// The sampling strategy that placed the frame.
    pub trajectory: Trajectory,
    /// Sequence (flight line/trajectory) id and the frame's index in it; grid frames are each their
    /// own sequence of length 1.
    pub sequence: u32,
    /// The frame's index in its sequence.
    pub index: u32,
    /// Intrinsics and pose in the area's ENU frame (`intrinsics`, `cam_to_world_enu`, `colmap_qvec`,
    /// `colmap_tvec` in the JSON).
    #[serde(flatten)]
    pub view: EnuCamera,
    /// Camera centre in ECEF (EPSG:4978), metres.
    pub ecef_m: [f64; 3],
    /// Position on WGS84 and attitude (`lat_deg` … `roll_deg` in the JSON).
    #[serde(flatten)]
    pub geo: GeoPose,
    /// Height of the camera above the area's ground level, metres.
    pub height_above_ground_m: f64,
    /// Distinct buildings the sampler's visibility ray grid sees first (`sample` records it; absent in
    /// older files and in poses made elsewhere).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub visible_buildings: Option<u32>,
    /// Cells of the frame's 4 × 4 grid whose census rays hit buildings
    /// ([`super::visibility::ViewCensus::covered_cells`]; `sample` records it, absent elsewhere).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub covered_frame_cells: Option<u32>,
    /// Share of the census rays that hit no building and land beyond the map
    /// ([`super::visibility::ViewCensus::off_map_share`]; `sample` records it, absent elsewhere).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub off_map_share: Option<f64>,
    /// Share of the census rays that hit a building
    /// ([`super::visibility::ViewCensus::building_fraction`]; `sample` records it, absent elsewhere).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub building_fraction: Option<f64>,
}

/// A camera in the area's ENU frame: its intrinsics and its pose, given both as a 4×4 and in COLMAP's
/// form. Flattened into `poses.jsonl` records and COCO images (the same four keys in both).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct EnuCamera {
    /// Pinhole intrinsics, pixels.
    pub intrinsics: Intrinsics,
    /// Camera-to-world in the area's ENU frame (OpenCV camera axes), metres; rows in the file.
    #[serde(with = "crate::util::row_major")]
    pub cam_to_world_enu: DMat4,
    /// COLMAP world-to-camera quaternion (qw, qx, qy, qz) and translation, ENU world frame.
    pub colmap_qvec: [f64; 4],
    /// COLMAP world-to-camera translation, metres.
    pub colmap_tvec: [f64; 3],
}

/// Where a camera is on the globe and how it is turned: what a UAV's GNSS and IMU would log.
/// Flattened into `poses.jsonl` records and COCO images (the same six keys in both).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct GeoPose {
    /// Camera centre in WGS84 with ellipsoidal height: degrees, degrees, metres.
    pub lat_deg: f64,
    /// Longitude, degrees (WGS84).
    pub lon_deg: f64,
    /// Ellipsoidal height, metres.
    pub h_m: f64,
    /// Yaw (heading of the image top, clockwise from north), pitch (tilt from nadir), roll, in degrees;
    /// see `camera::pose` for the exact convention.
    pub yaw_deg: f64,
    /// Pitch (tilt from nadir), degrees.
    pub pitch_deg: f64,
    /// Roll, degrees.
    pub roll_deg: f64,
}

impl PoseRecord {
    /// A record from its parts: the frame's identity, its camera and pose in ENU, and the area's
    /// ENU frame (for the geodetic pose, ECEF centre and height above ground).
    #[allow(clippy::too_many_arguments)]
    pub fn new(
        name: String,
        area: &str,
        preset: &str,
        trajectory: Trajectory,
        sequence: u32,
        index: u32,
        intrinsics: Intrinsics,
        pose: &Pose,
        enu: &EnuFrame,
        ground_enu_m: f64,
    ) -> Self {
        let c = pose.centre_m;
        let ecef = enu.enu_to_ecef(c);
        let g = enu.enu_to_geodetic(c);
        let [yaw_deg, pitch_deg, roll_deg] = pose.ypr_deg();
        PoseRecord {
            name,
            area: area.to_string(),
            preset: preset.to_string(),
            trajectory,
            sequence,
            index,
            view: EnuCamera {
                intrinsics,
                cam_to_world_enu: pose.cam_to_world(),
                colmap_qvec: pose.colmap_qvec(),
                colmap_tvec: pose.t_cam_from_world().to_array(),
            },
            ecef_m: ecef.to_array(),
            geo: GeoPose { lat_deg: g.lat_deg, lon_deg: g.lon_deg, h_m: g.h_m, yaw_deg, pitch_deg, roll_deg },
            height_above_ground_m: c.z - ground_enu_m,
            visible_buildings: None,
            covered_frame_cells: None,
            off_map_share: None,
            building_fraction: None,
        }
    }

    /// The pose (from `cam_to_world_enu`, the authoritative field).
    pub fn pose(&self) -> Pose {
        Pose::from_cam_to_world(&self.view.cam_to_world_enu)
    }
}

impl Trajectory {
    /// All strategies, in preset order (cam1, cam2, cam3 use irregular, grid, regular).
    pub const ALL: [Trajectory; 3] = [Trajectory::Grid, Trajectory::Regular, Trajectory::Irregular];

    /// The name used in files and on the command line.
    pub fn as_str(self) -> &'static str {
        match self {
            Trajectory::Grid => "grid",
            Trajectory::Regular => "regular",
            Trajectory::Irregular => "irregular",
        }
    }
}

impl std::fmt::Display for Trajectory {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.as_str())
    }
}

/// A strategy name that is none of `grid`, `regular`, `irregular`.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("unknown strategy {0:?}: expected one of grid, regular, irregular")]
pub struct UnknownTrajectory(pub String);

impl std::str::FromStr for Trajectory {
    type Err = UnknownTrajectory;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Trajectory::ALL.into_iter().find(|t| t.as_str() == s).ok_or_else(|| UnknownTrajectory(s.to_string()))
    }
}

/// Writes records as JSON lines (one compact object per line), atomically.
///
/// # Errors
/// The I/O error, naming `path`.
pub fn write_jsonl(path: &std::path::Path, records: &[PoseRecord]) -> Result<(), crate::util::FileError> {
    let mut bytes = Vec::new();
    for r in records {
        serde_json::to_writer(&mut bytes, r).map_err(|e| {
            crate::util::FileError::new("serialising JSON for", path, std::io::Error::other(e))
        })?;
        bytes.push(b'\n');
    }
    crate::util::write_bytes_atomic(path, &bytes)
}

/// A frame name that cannot be the stem of the frame's output files.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("frame name {name:?} {why}")]
pub struct BadFrameName {
    /// The name as given.
    pub name: String,
    /// Why it cannot be a file stem.
    pub why: &'static str,
}

/// Checks that a frame name can be a file stem: not empty, no leading dot (hidden files, `.`, `..`, and
/// the `.insgen-tmp-` prefix of files being written), no path separator, NUL or control character.
///
/// # Errors
/// [`BadFrameName`] saying which rule the name breaks.
pub fn check_frame_name(name: &str) -> Result<(), BadFrameName> {
    let why = if name.is_empty() {
        "is empty"
    } else if name.starts_with('.') {
        "starts with a dot"
    } else if name.chars().any(|c| c == '/' || c == '\\' || c.is_control()) {
        "contains a path separator or a control character"
    } else {
        return Ok(());
    };
    Err(BadFrameName { name: name.to_string(), why })
}

/// Reads a `poses.jsonl`/`priors.jsonl` file (blank lines are skipped): every line a pose record, frame
/// names unique and usable as file stems ([`check_frame_name`]).
///
/// # Errors
/// [`super::CameraError::File`] when unreadable; [`super::CameraError::Jsonl`],
/// [`super::CameraError::FrameName`] or [`super::CameraError::DuplicateFrame`] with the line number.
pub fn read_jsonl(path: &std::path::Path) -> Result<Vec<PoseRecord>, super::CameraError> {
    use super::CameraError;
    let bytes = crate::util::read_file(path)?;
    let mut out: Vec<PoseRecord> = Vec::new();
    let mut seen: std::collections::HashMap<String, usize> = std::collections::HashMap::new();
    for (i, line) in bytes.split(|&b| b == b'\n').enumerate() {
        if line.iter().all(u8::is_ascii_whitespace) {
            continue;
        }
        let line_no = i + 1;
        let rec: PoseRecord = serde_json::from_slice(line).map_err(|source| CameraError::Jsonl {
            path: path.to_path_buf(),
            line: line_no,
            source,
        })?;
        check_frame_name(&rec.name).map_err(|source| CameraError::FrameName {
            path: path.to_path_buf(),
            line: line_no,
            source,
        })?;
        if let Some(first_line) = seen.insert(rec.name.clone(), line_no) {
            return Err(CameraError::DuplicateFrame {
                path: path.to_path_buf(),
                line: line_no,
                name: rec.name,
                first_line,
            });
        }
        out.push(rec);
    }
    Ok(out)
}
