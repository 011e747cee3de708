//! Errors of the LoD readers: each names the file and, where known, the object and what is wrong.

use std::path::PathBuf;

use super::tiles3d::ContentError;

/// Why a LoD model file (or tileset) cannot be read.
#[derive(Debug, thiserror::Error)]
pub enum LodError {
    /// The file cannot be opened or read.
    #[error(transparent)]
    File(#[from] crate::util::FileError),

    /// A 3D Tiles file read on its own (a `.b3dm`/`.glb`/`.cmpt` content, or the gzip or JSON layer of
    /// a tileset JSON) cannot be decoded; `source` says what is wrong where.
    #[error("{}", path.display())]
    Tiles3d {
        /// The file.
        path: PathBuf,
        /// What is wrong where inside it.
        #[source]
        source: Box<ContentError>,
    },

    /// A tile content that a tileset references cannot be read or decoded: the tileset JSON, the JSON
    /// path of the reference (`root.children[3].content`), the URI as written and the file it names.
    #[error("{}: {at}.uri {uri:?} ({})", tileset.display(), content.display())]
    Tile {
        /// The tileset JSON that references the content.
        tileset: PathBuf,
        /// JSON path of the reference (`root.children[3].content`).
        at: String,
        /// The URI as written.
        uri: String,
        /// The content file it names.
        content: PathBuf,
        /// What is wrong where inside the content.
        #[source]
        source: Box<ContentError>,
    },

    /// An implicit-tiling subtree file of the tile at `at` (in `tileset`) is malformed.
    #[error("{}: {at}: subtree {}", tileset.display(), subtree.display())]
    Subtree {
        /// The tileset JSON.
        tileset: PathBuf,
        /// JSON path of the implicit tile.
        at: String,
        /// The subtree file.
        subtree: PathBuf,
        /// What is wrong with it.
        #[source]
        source: Box<ContentError>,
    },

    /// The format cannot be told from the file name.
    #[error("{}: cannot tell the format from the file name; set `format` (citygml, cityjson, obj, 3dtiles) in the scene file", path.display())]
    UnknownFormat {
        /// The file.
        path: PathBuf,
    },

    /// The file is not well-formed (truncated XML/JSON, bad binary header…); `source` is the parser's
    /// own error when there is one.
    #[error("{}: {what}", path.display())]
    Malformed {
        /// The file.
        path: PathBuf,
        /// What is wrong, with the line and column where known.
        what: String,
        /// The parser's error, when there is one.
        #[source]
        source: Option<ParseError>,
    },

    /// [`super::ReadOptions::weld_tolerance_m`] is negative or not finite.
    #[error("{}: weld_tolerance_m: weld tolerance {tolerance_m} m must be a finite number ≥ 0", path.display())]
    WeldTolerance {
        /// The file being read.
        path: PathBuf,
        /// The tolerance given, metres.
        tolerance_m: f64,
    },

    /// A specific object (building, geometry, tile) is invalid; `at` locates it (gml:id, JSON path,
    /// line, tile URI).
    #[error("{}: {at}: {what}", path.display())]
    Invalid {
        /// The file.
        path: PathBuf,
        /// Where in it: gml:id, JSON path, line, tile URI, or the option's name.
        at: String,
        /// What is wrong there.
        what: String,
    },
}

/// The error of the parser a reader delegates to, kept as the cause of a [`LodError::Malformed`].
#[derive(Debug, thiserror::Error)]
pub enum ParseError {
    /// serde_json's error (CityJSON, sidecars).
    #[error(transparent)]
    Json(#[from] serde_json::Error),
    /// quick-xml's error (CityGML).
    #[error(transparent)]
    Xml(#[from] quick_xml::Error),
    /// tobj's error (OBJ).
    #[error(transparent)]
    Obj(#[from] tobj::LoadError),
}

impl LodError {
    /// A [`LodError::Malformed`] without a parser error.
    pub fn malformed(path: impl Into<PathBuf>, what: impl Into<String>) -> Self {
        LodError::Malformed { path: path.into(), what: what.into(), source: None }
    }

    /// A [`LodError::Malformed`] caused by the parser error `source`.
    pub fn unparsable(
        path: impl Into<PathBuf>,
        what: impl Into<String>,
        source: impl Into<ParseError>,
    ) -> Self {
        LodError::Malformed { path: path.into(), what: what.into(), source: Some(source.into()) }
    }

    /// A [`LodError::Invalid`]: `what` is wrong at `at` in the file `path`.
    pub fn invalid(path: impl Into<PathBuf>, at: impl Into<String>, what: impl Into<String>) -> Self {
        LodError::Invalid { path: path.into(), at: at.into(), what: what.into() }
    }
}
