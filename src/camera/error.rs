//! Errors of the camera stage (presets, camera files, sampling, COLMAP and pose files, flight plan).

use std::path::PathBuf;

/// Everything that can go wrong while choosing cameras, sampling poses or reading/writing pose files.
#[derive(Debug, thiserror::Error)]
pub enum CameraError {
    #[error(transparent)]
    File(#[from] crate::util::FileError),
    /// `--camera` names neither a preset nor an existing camera file.
    #[error(
        "unknown camera {name:?}: expected one of the presets {available} or the path of a camera TOML file \
         (see scenes/cameras/example.toml), e.g. `insgen sample --area <AREA> --camera cam2`"
    )]
    UnknownPreset { name: String, available: String },
    /// A custom camera file breaks one or more rules (all are listed, each with its field).
    #[error("{}: invalid camera file:{}", path.display(), list(issues))]
    CameraFile { path: PathBuf, issues: Vec<ConfigIssue> },
    /// A custom camera file is not TOML, or not the camera table (unknown or missing key, wrong type).
    #[error("{}: invalid camera file", path.display())]
    CameraToml {
        path: PathBuf,
        /// Boxed: TOML's error is large, and errors travel by value.
        #[source]
        source: Box<toml::de::Error>,
    },
    /// The `[sampling]` configuration breaks one or more rules (all are listed, each with its field).
    #[error("invalid [sampling] configuration{}:{}", origin_suffix(origin), list(issues))]
    Config { origin: Option<PathBuf>, issues: Vec<ConfigIssue> },
    /// The scene file is not TOML, or its `[sampling]` table does not have the expected keys and types.
    #[error("invalid [sampling] configuration{}", origin_suffix(origin))]
    ConfigToml {
        origin: Option<PathBuf>,
        /// Boxed: TOML's error is large, and errors travel by value.
        #[source]
        source: Box<toml::de::Error>,
    },
    /// Zero poses were asked for.
    #[error("--count 0: ask for at least one pose")]
    ZeroCount,
    /// A text file (camera TOML, COLMAP model) is not UTF-8.
    #[error("{}: not UTF-8 text", path.display())]
    NotUtf8 {
        path: PathBuf,
        #[source]
        source: std::string::FromUtf8Error,
    },
    /// The area polygon is unusable (fewer than 3 vertices, zero area, non-finite coordinates) or
    /// leaves no room for the strategy.
    #[error("area {area}: {problem}{}", problem.hint(area))]
    Area {
        /// The area's name.
        area: String,
        /// What is wrong with it.
        problem: AreaProblem,
    },
    /// The strategy could not place as many poses as asked within its attempt budget.
    #[error(
        "area {area}: placed only {placed} of {wanted} {strategy} poses after {candidates} candidates \
         (rejected: {outside} outside the area polygon, {clearance} too close to buildings, {visibility} \
         seeing too few buildings); {hint}"
    )]
    TooFewPoses {
        area: String,
        strategy: String,
        placed: usize,
        wanted: usize,
        candidates: u64,
        outside: u64,
        clearance: u64,
        visibility: u64,
        hint: String,
    },
    /// A line of a COLMAP text file (or of a LoD-Loc list) is malformed; `source` says how.
    #[error("{}:{line}", path.display())]
    Colmap {
        path: PathBuf,
        /// 1-based line number.
        line: usize,
        #[source]
        source: ColmapIssue,
    },
    /// A `poses.jsonl`/`priors.jsonl` line is not a valid pose record.
    #[error("{}:{line}: not a valid pose record", path.display())]
    Jsonl {
        path: PathBuf,
        line: usize,
        #[source]
        source: serde_json::Error,
    },
    /// A pose record's frame name cannot be a file stem.
    #[error("{}:{line}", path.display())]
    FrameName {
        path: PathBuf,
        line: usize,
        #[source]
        source: super::record::BadFrameName,
    },
    /// Two pose records share a frame name.
    #[error("{}:{line}: frame name {name:?} was already used on line {first_line}", path.display())]
    DuplicateFrame { path: PathBuf, line: usize, name: String, first_line: usize },
    /// The flight-plan PNG could not be encoded.
    #[error("encoding {}", path.display())]
    Png {
        path: PathBuf,
        #[source]
        source: png::EncodingError,
    },
}

/// Why an area cannot be sampled ([`CameraError::Area`]).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum AreaProblem {
    /// A polygon vertex with a non-finite coordinate (ENU metres).
    #[error("the area polygon has a non-finite vertex {vertex:?}")]
    NonFiniteVertex {
        /// The vertex, ENU metres.
        vertex: [f64; 2],
    },
    /// Fewer than 3 distinct vertices.
    #[error("the area polygon (manifest.json area_polygon_enu_m) has {vertices} vertices; at least 3 are needed")]
    TooFewVertices {
        /// Distinct vertices found.
        vertices: usize,
    },
    /// The polygon encloses (almost) nothing.
    #[error("the area polygon (manifest.json area_polygon_enu_m) is empty: its area is {area_m2:.3} m²")]
    Empty {
        /// Its area, square metres.
        area_m2: f64,
    },
    /// The manifest's ground height is not finite.
    #[error("ground_enu_m = {ground_enu_m} is not finite")]
    GroundNotFinite {
        /// The ground height found, ENU metres.
        ground_enu_m: f64,
    },
    /// No node of the grid strategy's lattice lies inside the polygon.
    #[error(
        "no grid node fits inside the area polygon ({area_m2:.0} m²) at grid.spacing_m = {spacing_m} and \
         grid.margin_m = {margin_m}; lower them in the scene file's [sampling.grid] table"
    )]
    NoGridNode {
        /// The polygon's area, square metres.
        area_m2: f64,
        /// `grid.spacing_m`, metres.
        spacing_m: f64,
        /// `grid.margin_m`, metres.
        margin_m: f64,
    },
    /// The irregular strategy found no point inside the polygon to fly to.
    #[error("no point inside the area polygon found for a trajectory (is the polygon a sliver?)")]
    NoTrajectoryRoom,
}

impl AreaProblem {
    /// What to do about it, where that depends on the area's name (appended to the message).
    fn hint(&self, area: &str) -> String {
        match self {
            AreaProblem::TooFewVertices { .. } => {
                format!(" (re-run `insgen prepare --area {area}` after fixing the scene file's area)")
            }
            _ => String::new(),
        }
    }
}

/// One broken rule of a camera file or a `[sampling]` table: where it is (the TOML key), the value
/// found there, and the rule. Shown as `field = value: rule`, or `field: rule` without a value.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{field}{}: {rule}", value.as_ref().map(|v| format!(" = {v}")).unwrap_or_default())]
pub struct ConfigIssue {
    /// The dotted TOML key from the file's (or table's) root: `width_px`, `grid.height_range_m`,
    /// `distortion.k1`.
    pub field: String,
    /// The offending value as the message shows it (`0`, `[500, 400]`, `"bad name"`), when one value is
    /// at fault.
    pub value: Option<String>,
    /// The rule it breaks, e.g. `must be in 1..=16384`.
    pub rule: String,
}

impl ConfigIssue {
    /// An issue with the value found at `field`.
    pub fn value(field: impl Into<String>, value: impl std::fmt::Display, rule: impl Into<String>) -> Self {
        ConfigIssue { field: field.into(), value: Some(value.to_string()), rule: rule.into() }
    }

    /// An issue with `field` as a whole (missing, or one entry of a list).
    pub fn field(field: impl Into<String>, rule: impl Into<String>) -> Self {
        ConfigIssue { field: field.into(), value: None, rule: rule.into() }
    }
}

/// What is wrong with one line of a COLMAP `cameras.txt`/`images.txt` or a LoD-Loc list.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ColmapIssue {
    /// Too few (or too many) fields; `expected` spells the line format.
    #[error("expected {expected}, got {line:?}")]
    Fields { expected: &'static str, line: String },
    #[error("unknown camera model {0:?}")]
    UnknownModel(String),
    /// An id or size field that is not a non-negative integer.
    #[error("{field}: {value:?} is not a valid non-negative integer")]
    NotInteger { field: &'static str, value: String },
    /// A parameter, quaternion or translation field that is not a finite number.
    #[error("{field}: {value:?} is not a finite number")]
    NotFinite { field: &'static str, value: String },
    #[error("image size {width_px}×{height_px} is empty")]
    EmptyImage { width_px: u32, height_px: u32 },
    #[error("model {model} takes {expected} parameters, found {found}")]
    ParamCount { model: String, expected: usize, found: usize },
    #[error("the quaternion (QW QX QY QZ) is zero")]
    ZeroQuaternion,
    #[error("duplicate CAMERA_ID {0}")]
    DuplicateCamera(u32),
    #[error("duplicate IMAGE_ID {0}")]
    DuplicateImage(u32),
    /// The line after an image line is not its POINTS2D list.
    #[error(
        "expected the POINTS2D line (X Y POINT3D_ID triples, or empty) of image {image_id}, got {line:?}"
    )]
    Points2D { image_id: u32, line: String },
}

/// Issues as an indented list, one per line.
fn list(issues: &[ConfigIssue]) -> String {
    issues.iter().map(|i| format!("\n  - {i}")).collect()
}

fn origin_suffix(origin: &Option<PathBuf>) -> String {
    match origin {
        Some(p) => format!(" in {}", p.display()),
        None => String::new(),
    }
}
