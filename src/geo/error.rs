//! Errors of the geo stage: what the caller sees ([`GeoError`]), why a CRS name was refused
//! ([`CrsError`]), and which PROJ call failed with PROJ's own reason ([`ProjError`]).

/// Errors of the geo stage.
#[derive(Debug, thiserror::Error)]
pub enum GeoError {
    /// The CRS name could not be parsed, or is not known to PROJ or not usable here; `source` says why.
    #[error(
        "unknown or unsupported CRS {name:?} (set an explicit `crs = \"EPSG:NNNN\"` for this source in the \
         scene file)"
    )]
    UnknownCrs {
        name: String,
        /// Boxed: PROJ's reasons make it large, and errors travel by value.
        #[source]
        source: Box<CrsError>,
    },
    /// A coordinate could not be converted (outside the projection's domain, NaN…); `why` is PROJ's
    /// reason or ours.
    #[error("cannot convert {point:?} from {crs}: {why}")]
    Transform { crs: String, point: [f64; 3], why: String },
    /// A geoid grid is malformed, or a position lies outside it.
    #[error("geoid grid {path}: {why}")]
    Geoid { path: String, why: String },
    /// A file (the geoid grid) could not be read.
    #[error(transparent)]
    File(#[from] crate::util::FileError),
}

/// The spellings of a CRS name insgen accepts, for error messages.
pub(crate) const EXPECTED: &str = "expected an EPSG code such as EPSG:6697, urn:ogc:def:crs:EPSG::6697, \
                                   http://www.opengis.net/def/crs/EPSG/0/6697 or a compound \
                                   urn:ogc:def:crs,crs:EPSG::6668,crs:EPSG::6695";

/// Why a CRS name was refused: it is not a recognised spelling (the offending part is quoted), PROJ does
/// not know it, or it is of a kind that cannot be placed on the globe.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CrsError {
    #[error("empty CRS name; {EXPECTED}")]
    Empty,
    #[error("not a recognised CRS name; {EXPECTED}")]
    NotRecognised,
    /// A part of a compound URN (`urn:ogc:def:crs,crs:…,crs:…`) that does not start with `crs:`.
    #[error("compound URN component {0:?} does not start with crs:")]
    UrnComponent(String),
    /// A part of a compound URL (`…/crs-compound?1=…&2=…`) that is not `key=value`.
    #[error("compound URL part {0:?} is not k=v")]
    UrlPart(String),
    /// The key of a compound URL part is not a number.
    #[error("compound URL key {0:?} is not a number")]
    UrlKey(String),
    /// A compound CRS with other than one or two components.
    #[error("a compound CRS must have 1 or 2 components (horizontal, vertical), found {0}")]
    ComponentCount(usize),
    /// An authority other than EPSG (upper-cased as given).
    #[error("authority {0:?} is not supported (only EPSG codes are)")]
    Authority(String),
    #[error("URN has no code; {EXPECTED}")]
    UrnWithoutCode,
    /// An OGC URL whose path is not `<authority>/<version>/<code>`.
    #[error("URL path {0:?} is not <authority>/<version>/<code>; {EXPECTED}")]
    UrlPath(String),
    #[error("not an OGC CRS URL; {EXPECTED}")]
    NotOgcUrl,
    /// The code part is not made of digits.
    #[error("EPSG code {0:?} is not a positive integer; {EXPECTED}")]
    NotACode(String),
    /// The code is 0 or does not fit in 32 bits.
    #[error("EPSG code {0:?} is out of range")]
    CodeOutOfRange(String),
    /// A CRS of a kind that cannot be placed on the globe (vertical-only, engineering, …).
    #[error(
        "EPSG:{code} ({name}) is a {kind} CRS; insgen needs a geographic, projected, geocentric or compound \
         CRS{}",
        if *vertical {
            format!(
                "; a height system alone cannot be placed on the globe: give a compound such as \
                 urn:ogc:def:crs,crs:EPSG::<horizontal>,crs:EPSG::{code}"
            )
        } else {
            String::new()
        }
    )]
    Unsupported {
        code: u32,
        /// PROJ's name of the CRS.
        name: String,
        /// "vertical", "engineering", …
        kind: &'static str,
        /// Whether it is a vertical CRS (the message then shows how to make a compound).
        vertical: bool,
    },
    /// The first component of a compound CRS is not a 2D geographic or projected CRS.
    #[error(
        "the first component of a compound CRS must be a 2D geographic or projected CRS, but {name} is {kind}"
    )]
    CompoundHorizontal { name: String, kind: String },
    /// The second component of a compound CRS is not a vertical CRS.
    #[error("the second component of a compound CRS must be a vertical CRS, but {name} is not")]
    CompoundVertical { name: String },
    /// A component of a compound CRS has no EPSG identifier.
    #[error("the {part} component {name} has no EPSG code")]
    NoEpsgCode {
        /// "horizontal" or "vertical".
        part: &'static str,
        name: String,
    },
    /// PROJ failed (the code is not in its database, no operation exists, …).
    #[error(transparent)]
    Proj(#[from] ProjError),
}

/// A PROJ call that failed. `reason` is PROJ's own explanation: its last logged message, else the text
/// of its error number (PROJ reports errors only as text, so that is what is kept).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ProjError {
    #[error("PROJ could not create a context (out of memory?)")]
    NoContext,
    /// A string handed to PROJ contains a NUL byte, which C strings cannot carry.
    #[error("{what} {value:?} contains NUL")]
    Nul { what: &'static str, value: String },
    /// `proj_create_from_database` found no CRS with this code.
    #[error("{auth}:{code} is not in PROJ's database ({database}): {reason}")]
    NotInDatabase { auth: String, code: u32, database: String, reason: String },
    /// A component of a compound CRS could not be extracted.
    #[error("component {index} of compound CRS {crs}: {reason}")]
    SubCrs { crs: String, index: i32, reason: String },
    /// A CRS has no coordinate system, or its axes cannot be read.
    #[error("{what} of {crs}: {reason}")]
    Axes {
        /// "coordinate system", "axis count", "axis 2".
        what: String,
        crs: String,
        reason: String,
    },
    /// `proj_create_crs_to_crs` found no coordinate operation.
    #[error("no coordinate operation from {from} to {to}: {reason}")]
    NoOperation { from: String, to: String, reason: String },
    /// `proj_normalize_for_visualization` failed.
    #[error("normalising the axis order of {operation}: {reason}")]
    Normalize { operation: String, reason: String },
    /// `proj_create` refused a definition.
    #[error("PROJ cannot create {definition:?}: {reason}")]
    Create { definition: String, reason: String },
}
