//! Errors of the LoD readers: each names the file and, where known, the object and what is wrong.

use std::path::PathBuf;

use super::tiles3d::ContentError;

#[derive(Debug, thiserror::Error)]
pub enum LodError {
    #[error(transparent)]
    File(#[from] crate::util::FileError),

    /// A 3D Tiles file read on its own (a `.b3dm`/`.glb`/`.cmpt` content, or the gzip or JSON layer of
    /// a tileset JSON) cannot be decoded; `source` says what is wrong where.
    #[error("{}", path.display())]
    Tiles3d {
        path: PathBuf,
        #[source]
        source: Box<ContentError>,
    },

    /// A tile content that a tileset references cannot be read or decoded: the tileset JSON, the JSON
    /// path of the reference (`root.children[3].content`), the URI as written and the file it names.
    #[error("{}: {at}.uri {uri:?} ({})", tileset.display(), content.display())]
    Tile {
        tileset: PathBuf,
        at: String,
        uri: String,
        content: PathBuf,
        #[source]
        source: Box<ContentError>,
    },

    /// An implicit-tiling subtree file of the tile at `at` (in `tileset`) is malformed.
    #[error("{}: {at}: subtree {}", tileset.display(), subtree.display())]
    Subtree {
        tileset: PathBuf,
        at: String,
        subtree: PathBuf,
        #[source]
        source: Box<ContentError>,
    },

    #[error("{}: cannot tell the format from the file name; set `format` (citygml, cityjson, obj, 3dtiles) in the scene file", path.display())]
    UnknownFormat { path: PathBuf },

    /// The file is not well-formed (truncated XML/JSON, bad binary header…); `source` is the parser's
    /// own error when there is one.
    #[error("{}: {what}", path.display())]
    Malformed {
        path: PathBuf,
        what: String,
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
    Invalid { path: PathBuf, at: String, what: String },
}

/// The error of the parser a reader delegates to, kept as the cause of a [`LodError::Malformed`].
#[derive(Debug, thiserror::Error)]
pub enum ParseError {
    #[error(transparent)]
    Json(#[from] serde_json::Error),
    #[error(transparent)]
    Xml(#[from] quick_xml::Error),
    #[error(transparent)]
    Obj(#[from] tobj::LoadError),
}

impl LodError {
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
    pub fn invalid(path: impl Into<PathBuf>, at: impl Into<String>, what: impl Into<String>) -> Self {
        LodError::Invalid { path: path.into(), at: at.into(), what: what.into() }
    }
}
