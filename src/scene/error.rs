//! Errors of the scene stage.

use std::path::PathBuf;

#[derive(Debug, thiserror::Error)]
pub enum SceneError {
    #[error(transparent)]
    File(#[from] crate::util::FileError),
    #[error(transparent)]
    Lod(#[from] crate::lod::LodError),
    /// The scene file is not valid TOML or misses a field.
    #[error("{}: {what}", path.display())]
    Config { path: PathBuf, what: String },
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
}
