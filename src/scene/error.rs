//! Errors of the scene stage.

use std::path::PathBuf;

/// Errors of the scene stage.
#[derive(Debug, thiserror::Error)]
pub enum SceneError {
    /// A file could not be read or written.
    #[error(transparent)]
    File(#[from] crate::util::FileError),
    /// A source could not be read.
    #[error(transparent)]
    Lod(#[from] crate::lod::LodError),
    /// The scene file breaks a rule (name mismatch, no sources, bad geoid settings, an invalid area).
    #[error("{}: {what}", path.display())]
    Config {
        /// The scene file.
        path: PathBuf,
        /// The rule broken.
        what: String,
    },
    /// A `[[sources]] path` names nothing to read: a missing path, a folder without readable files, a
    /// glob that matches no file.
    #[error("{}: sources[{index}].path", scene.display())]
    Sources {
        /// The scene file.
        scene: PathBuf,
        /// The source's index in `[[sources]]`.
        index: usize,
        /// What the path names (or does not).
        #[source]
        source: super::sources::SourcesError,
    },
    /// The scene file is not TOML, or has unknown keys, missing keys or wrong types.
    #[error("{}: invalid scene file", path.display())]
    ConfigToml {
        /// The scene file.
        path: PathBuf,
        /// Boxed: TOML's error is large, and errors travel by value.
        #[source]
        source: Box<toml::de::Error>,
    },
    /// A source could not be geo-referenced.
    #[error("{}: {what}", path.display())]
    Georef {
        /// The source file.
        path: PathBuf,
        /// What could not be done.
        what: String,
        /// The geo stage's error, when it is the cause.
        #[source]
        source: Option<crate::geo::GeoError>,
    },
    /// The area has no buildings, or otherwise cannot be instanced.
    #[error("area {area}: {what}")]
    Area {
        /// The area's name.
        area: String,
        /// Why it cannot be instanced.
        what: String,
    },
    /// The area's buildings cannot all get a 24-bit ID.
    #[error("area {area}")]
    Ids {
        /// The area's name.
        area: String,
        /// The ID error.
        #[source]
        source: crate::scene::IdError,
    },
    /// The alignment record of a prepared scene's manifest (`path`) is unusable.
    #[error("{}", path.display())]
    Correction {
        /// The manifest.
        path: PathBuf,
        /// What is wrong with the record.
        #[source]
        source: CorrectionError,
    },
    /// A prepared scene on disk is missing or inconsistent.
    #[error("{}: {what}", path.display())]
    Artifact {
        /// The file of the prepared scene.
        path: PathBuf,
        /// What is missing or inconsistent.
        what: String,
    },
    /// A JSON file of a prepared scene (`what`: manifest, building table) does not parse.
    #[error("{}: not a valid {what}; run `insgen prepare --area <name>` again", path.display())]
    ArtifactJson {
        /// The JSON file.
        path: PathBuf,
        /// What the file is (manifest, building table).
        what: &'static str,
        /// The JSON parser's error.
        #[source]
        source: serde_json::Error,
    },
    /// The prepared scene's mesh (`scene.glb`) cannot be read; the source names the file.
    #[error("the prepared scene's mesh cannot be read; run `insgen prepare --area <name>` again")]
    ArtifactGlb {
        /// The GLB reader's error (it names the file).
        #[source]
        source: super::glb::GlbError,
    },
}

/// An alignment correction that cannot be applied (see [`crate::scene::correction::Correction::validate`]).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CorrectionError {
    /// A number of the correction is NaN or infinite.
    #[error("alignment {field} = {value} is not a finite number")]
    NotFinite {
        /// The field ("east_m", "yaw_deg", "pivot_enu_m[0]", …).
        field: &'static str,
        /// Its value.
        value: f64,
    },
}

/// Why synthetic photogrammetry could not be made from the buildings (see
/// [`crate::scene::photogrammetry::perturb`]).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PerturbError {
    /// The ground and clutter pieces need building IDs beyond the 24-bit ID space.
    #[error(
        "clutter needs more building IDs: ID {id} does not fit the 24-bit ID space (max {})",
        crate::scene::MAX_BUILDING_ID
    )]
    IdSpace {
        /// The first ID that does not fit.
        id: u32,
    },
}
