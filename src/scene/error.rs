//! Errors of the scene stage.

use std::path::PathBuf;

#[derive(Debug, thiserror::Error)]
pub enum SceneError {
    #[error(transparent)]
    File(#[from] crate::util::FileError),
    #[error(transparent)]
    Lod(#[from] crate::lod::LodError),
    /// The scene file breaks a rule (name mismatch, no sources, bad geoid settings, an invalid area).
    #[error("{}: {what}", path.display())]
    Config { path: PathBuf, what: String },
    /// The scene file is not TOML, or has unknown keys, missing keys or wrong types.
    #[error("{}: invalid scene file", path.display())]
    ConfigToml {
        path: PathBuf,
        /// Boxed: TOML's error is large, and errors travel by value.
        #[source]
        source: Box<toml::de::Error>,
    },
    /// A source could not be geo-referenced.
    #[error("{}: {what}", path.display())]
    Georef {
        path: PathBuf,
        what: String,
        #[source]
        source: Option<crate::geo::GeoError>,
    },
    /// The area has no buildings, or otherwise cannot be instanced.
    #[error("area {area}: {what}")]
    Area { area: String, what: String },
    /// The area's buildings cannot all get a 24-bit ID.
    #[error("area {area}")]
    Ids {
        area: String,
        #[source]
        source: crate::scene::IdError,
    },
    /// A prepared scene on disk is missing or inconsistent.
    #[error("{}: {what}", path.display())]
    Artifact { path: PathBuf, what: String },
    /// A JSON file of a prepared scene (`what`: manifest, building table) does not parse.
    #[error("{}: not a valid {what}; run `insgen prepare --area <name>` again", path.display())]
    ArtifactJson {
        path: PathBuf,
        what: &'static str,
        #[source]
        source: serde_json::Error,
    },
    /// The prepared scene's mesh (`scene.glb`) cannot be read; the source names the file.
    #[error("the prepared scene's mesh cannot be read; run `insgen prepare --area <name>` again")]
    ArtifactGlb {
        #[source]
        source: super::glb::GlbError,
    },
}
