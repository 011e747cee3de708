//! Errors of the camera stage (presets, camera files, sampling, COLMAP and pose files, flight plan).

use std::path::PathBuf;

/// Everything that can go wrong while choosing cameras, sampling poses or reading/writing pose files.
#[derive(Debug, thiserror::Error)]
pub enum CameraError {
    /// A file cannot be read or written.
    #[error(transparent)]
    File(#[from] crate::util::FileError),
    /// `--camera` names neither a preset nor an existing camera file.
    #[error(
        "unknown camera {name:?}: expected one of the presets {available} or the path of a camera TOML file \
         (see scenes/cameras/example.toml), e.g. `insgen sample --area <AREA> --camera cam2`"
    )]
    UnknownPreset {
        /// The `--camera` value.
        name: String,
        /// The preset names, comma-separated.
        available: String,
    },
    /// A custom camera file breaks one or more rules (all are listed, each with its field).
    #[error("{}: invalid camera file:{}", path.display(), list(issues))]
    CameraFile {
        /// The camera file.
        path: PathBuf,
        /// Every broken rule.
        issues: Vec<ConfigIssue>,
    },
    /// A custom camera file is not TOML, or not the camera table (unknown or missing key, wrong type).
    #[error("{}: invalid camera file", path.display())]
    CameraToml {
        /// The camera file.
        path: PathBuf,
        /// Boxed: TOML's error is large, and errors travel by value.
        #[source]
        source: Box<toml::de::Error>,
    },
    /// The `[sampling]` configuration breaks one or more rules (all are listed, each with its field).
    #[error("invalid [sampling] configuration{}:{}", origin_suffix(origin), list(issues))]
    Config {
        /// The scene file the table comes from, when known.
        origin: Option<PathBuf>,
        /// Every broken rule.
        issues: Vec<ConfigIssue>,
    },
    /// The scene file is not TOML, or its `[sampling]` table does not have the expected keys and types.
    #[error("invalid [sampling] configuration{}", origin_suffix(origin))]
    ConfigToml {
        /// The scene file, when known.
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
        /// The file.
        path: PathBuf,
        /// The decoding error (where the first bad byte is).
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
        /// The area's name.
        area: String,
        /// The strategy (`grid`, `regular`, `irregular`).
        strategy: String,
        /// Poses placed.
        placed: usize,
        /// Poses asked for.
        wanted: usize,
        /// Candidate poses tried.
        candidates: u64,
        /// Candidates rejected outside the area polygon.
        outside: u64,
        /// Candidates rejected too close to buildings.
        clearance: u64,
        /// Candidates rejected for seeing too few buildings.
        visibility: u64,
        /// Which setting to change, for this strategy.
        hint: String,
    },
    /// A line of a COLMAP text file (or of a LoD-Loc list) is malformed; `source` says how.
    #[error("{}:{line}", path.display())]
    Colmap {
        /// The file.
        path: PathBuf,
        /// 1-based line number.
        line: usize,
        /// What is wrong with the line.
        #[source]
        source: ColmapIssue,
    },
    /// A `poses.jsonl`/`priors.jsonl` line is not a valid pose record.
    #[error("{}:{line}: not a valid pose record", path.display())]
    Jsonl {
        /// The file.
        path: PathBuf,
        /// 1-based line number.
        line: usize,
        /// The JSON error.
        #[source]
        source: serde_json::Error,
    },
    /// A pose record's frame name cannot be a file stem.
    #[error("{}:{line}", path.display())]
    FrameName {
        /// The file.
        path: PathBuf,
        /// 1-based line number.
        line: usize,
        /// The name and why it is refused.
        #[source]
        source: super::record::BadFrameName,
    },
    /// Two pose records share a frame name.
    #[error("{}:{line}: frame name {name:?} was already used on line {first_line}", path.display())]
    DuplicateFrame {
        /// The file.
        path: PathBuf,
        /// 1-based line number of the second use.
        line: usize,
        /// The frame name.
        name: String,
        /// 1-based line number of the first use.
        first_line: usize,
    },
    /// The flight-plan PNG could not be encoded.
    #[error("encoding {}", path.display())]
    Png {
        /// The PNG being written.
        path: PathBuf,
        /// The encoder's error.
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
    #[error(
        "the area polygon (manifest.json area_polygon_enu_m) has {vertices} vertices; at least 3 are needed"
    )]
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
    Fields {
        /// The line format, e.g. `CAMERA_ID MODEL WIDTH HEIGHT PARAMS[]`.
        expected: &'static str,
        /// The line as read.
        line: String,
    },
    /// A camera model COLMAP does not define (the name as read).
    #[error("unknown camera model {0:?}")]
    UnknownModel(String),
    /// An id or size field that is not a non-negative integer.
    #[error("{field}: {value:?} is not a valid non-negative integer")]
    NotInteger {
        /// The field's name in the line format.
        field: &'static str,
        /// The text found.
        value: String,
    },
    /// A parameter, quaternion or translation field that is not a finite number.
    #[error("{field}: {value:?} is not a finite number")]
    NotFinite {
        /// The field's name in the line format.
        field: &'static str,
        /// The text found.
        value: String,
    },
    /// A camera with a zero width or height.
    #[error("image size {width_px}×{height_px} is empty")]
    EmptyImage {
        /// Width, pixels.
        width_px: u32,
        /// Height, pixels.
        height_px: u32,
    },
    /// The number of parameters does not fit the camera model.
    #[error("model {model} takes {expected} parameters, found {found}")]
    ParamCount {
        /// The camera model.
        model: String,
        /// Parameters the model takes.
        expected: usize,
        /// Parameters found.
        found: usize,
    },
    /// An image's rotation quaternion is all zeros.
    #[error("the quaternion (QW QX QY QZ) is zero")]
    ZeroQuaternion,
    /// Two cameras share an id.
    #[error("duplicate CAMERA_ID {0}")]
    DuplicateCamera(u32),
    /// Two images share an id.
    #[error("duplicate IMAGE_ID {0}")]
    DuplicateImage(u32),
    /// The line after an image line is not its POINTS2D list.
    #[error(
        "expected the POINTS2D line (X Y POINT3D_ID triples, or empty) of image {image_id}, got {line:?}"
    )]
    Points2D {
        /// The image's `IMAGE_ID`.
        image_id: u32,
        /// The line as read.
        line: String,
    },
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
