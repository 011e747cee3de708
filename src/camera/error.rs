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
    /// A custom camera file is not valid TOML or breaks one or more rules (all are listed).
    #[error("{}: invalid camera file:\n  - {}", path.display(), issues.join("\n  - "))]
    CameraFile { path: PathBuf, issues: Vec<String> },
    /// The `[sampling]` configuration breaks one or more rules (all are listed, with their field).
    #[error("invalid [sampling] configuration{}:\n  - {}", origin_suffix(origin), issues.join("\n  - "))]
    Config { origin: Option<PathBuf>, issues: Vec<String> },
    /// The area polygon is unusable (fewer than 3 vertices, zero area, non-finite coordinates).
    #[error("area {area}: {what}")]
    Area { area: String, what: String },
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
    /// A COLMAP text file is malformed.
    #[error("{}:{line}: {what}", path.display())]
    Colmap { path: PathBuf, line: usize, what: String },
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

fn origin_suffix(origin: &Option<PathBuf>) -> String {
    match origin {
        Some(p) => format!(" in {}", p.display()),
        None => String::new(),
    }
}
