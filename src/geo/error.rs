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
        /// The CRS name as given.
        name: String,
        /// Boxed: PROJ's reasons make it large, and errors travel by value.
        #[source]
        source: Box<CrsError>,
    },
    /// A coordinate could not be converted (outside the projection's domain, NaN…); `why` is PROJ's
    /// reason or ours.
    #[error("cannot convert {point:?} from {crs}: {why}")]
    Transform {
        /// The source CRS.
        crs: String,
        /// The coordinate, in the CRS's axis order and units.
        point: [f64; 3],
        /// PROJ's reason or ours.
        why: String,
    },
    /// A geoid grid is malformed, or a position lies outside it.
    #[error("geoid grid {path}: {why}")]
    Geoid {
        /// The grid file.
        path: String,
        /// What is wrong.
        why: String,
    },
    /// A GeoTIFF geoid grid cannot be used; `source` says why.
    #[error("geoid grid {path}")]
    GeoTiff {
        /// The grid file.
        path: String,
        /// What is wrong with it (boxed: errors travel by value, and this one is large).
        #[source]
        source: Box<GeoTiffError>,
    },
    /// A file (the geoid grid) could not be read.
    #[error(transparent)]
    File(#[from] crate::util::FileError),
}

/// The spellings of a CRS name insgen accepts, for error messages.
pub(crate) const EXPECTED: &str = "expected an EPSG code such as EPSG:6697, urn:ogc:def:crs:EPSG::6697, \
                                   http://www.opengis.net/def/crs/EPSG/0/6697 or a compound \
                                   urn:ogc:def:crs,crs:EPSG::6668,crs:EPSG::6695 or EPSG:6668+6695";

/// Why a CRS name was refused: it is not a recognised spelling (the offending part is quoted), PROJ does
/// not know it, or it is of a kind that cannot be placed on the globe.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CrsError {
    /// The name is empty.
    #[error("empty CRS name; {EXPECTED}")]
    Empty,
    /// The name is none of the accepted spellings.
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
    /// A part of an AdV name (`urn:adv:crs:…`) insgen does not know (upper-cased as given).
    #[error(
        "AdV name {0:?} is not one insgen knows (ETRS89_UTM31..33, ETRS89_Lat-Lon, DE_DHDN_3GK2..5, \
         DE_DHDN_Lat-Lon; heights DE_DHHN2016_NH, DE_DHHN92_NH, DE_DHHN12_NOH, DE_DHHN85_NOH, DE_SNN76_NH); \
         give its EPSG codes, e.g. urn:ogc:def:crs,crs:EPSG::25832,crs:EPSG::7837"
    )]
    AdvName(String),
    /// A URN without a code.
    #[error("URN has no code; {EXPECTED}")]
    UrnWithoutCode,
    /// An OGC URL whose path is not `<authority>/<version>/<code>`.
    #[error("URL path {0:?} is not <authority>/<version>/<code>; {EXPECTED}")]
    UrlPath(String),
    /// A URL that is not an OGC CRS URL.
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
        /// The EPSG code.
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
    CompoundHorizontal {
        /// PROJ's name of the component.
        name: String,
        /// Its kind ("vertical", "engineering", …).
        kind: String,
    },
    /// The second component of a compound CRS is not a vertical CRS.
    #[error("the second component of a compound CRS must be a vertical CRS, but {name} is not")]
    CompoundVertical {
        /// PROJ's name of the component.
        name: String,
    },
    /// A component of a compound CRS has no EPSG identifier.
    #[error("the {part} component {name} has no EPSG code")]
    NoEpsgCode {
        /// "horizontal" or "vertical".
        part: &'static str,
        /// PROJ's name of the component.
        name: String,
    },
    /// PROJ failed (the code is not in its database, no operation exists, …).
    #[error(transparent)]
    Proj(#[from] ProjError),
}

/// The part of a CRS's coordinate system that PROJ could not read (see [`ProjError::Axes`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum CsPart {
    /// The coordinate system itself.
    #[error("coordinate system")]
    CoordinateSystem,
    /// Its axis count.
    #[error("axis count")]
    AxisCount,
    /// One axis (0-based).
    #[error("axis {0}")]
    Axis(i32),
}

/// A PROJ call that failed. `reason` is PROJ's own explanation: its last logged message, else the text
/// of its error number (PROJ reports errors only as text, so that is what is kept).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ProjError {
    /// No PROJ context could be created.
    #[error("PROJ could not create a context (out of memory?)")]
    NoContext,
    /// A string handed to PROJ contains a NUL byte, which C strings cannot carry.
    #[error("{what} {value:?} contains NUL")]
    Nul {
        /// What the string is (a CRS name, a definition).
        what: &'static str,
        /// The string.
        value: String,
    },
    /// `proj_create_from_database` found no CRS with this code.
    #[error("{auth}:{code} is not in PROJ's database ({database}): {reason}")]
    NotInDatabase {
        /// The authority.
        auth: String,
        /// The code.
        code: u32,
        /// PROJ's database file.
        database: String,
        /// PROJ's reason.
        reason: String,
    },
    /// A component of a compound CRS could not be extracted.
    #[error("component {index} of compound CRS {crs}: {reason}")]
    SubCrs {
        /// The compound CRS.
        crs: String,
        /// Index of the component (0 horizontal, 1 vertical).
        index: i32,
        /// PROJ's reason.
        reason: String,
    },
    /// A CRS has no coordinate system, or its axes cannot be read.
    #[error("{part} of {crs}: {reason}")]
    Axes {
        /// The part that could not be read.
        part: CsPart,
        /// The CRS.
        crs: String,
        /// PROJ's reason.
        reason: String,
    },
    /// `proj_create_crs_to_crs` found no coordinate operation.
    #[error("no coordinate operation from {from} to {to}: {reason}")]
    NoOperation {
        /// The source CRS.
        from: String,
        /// The target CRS.
        to: String,
        /// PROJ's reason.
        reason: String,
    },
    /// `proj_normalize_for_visualization` failed.
    #[error("normalising the axis order of {operation}: {reason}")]
    Normalize {
        /// The operation.
        operation: String,
        /// PROJ's reason.
        reason: String,
    },
    /// `proj_create` refused a definition.
    #[error("PROJ cannot create {definition:?}: {reason}")]
    Create {
        /// The definition.
        definition: String,
        /// PROJ's reason.
        reason: String,
    },
}

/// Why a GeoTIFF vertical grid cannot be used (see [`GeoError::GeoTiff`], which names the file).
#[derive(Debug, thiserror::Error)]
pub enum GeoTiffError {
    /// The TIFF decoder failed; `what` is the tag or step it was at.
    #[error("{what}")]
    Tiff {
        /// The tag read ("ModelTiepoint") or the step ("not a readable TIFF", "reading the samples").
        what: &'static str,
        /// The decoder's error.
        #[source]
        source: tiff::TiffError,
    },
    /// A further image file directory cannot be read.
    #[error("IFD {ifd}")]
    Ifd {
        /// Index of the image file directory (0 = the grid).
        ifd: usize,
        /// The decoder's error.
        #[source]
        source: tiff::TiffError,
    },
    /// The first image is an overview or a mask, not a grid.
    #[error("the first image has NewSubfileType {subfile} (PROJ refuses it: \"Invalid subfileType\")")]
    SubfileType {
        /// The `NewSubfileType` value.
        subfile: u32,
    },
    /// The image has no pixels.
    #[error("image size {width_px} × {height_px} is empty")]
    EmptyImage {
        /// Image width, pixels.
        width_px: u32,
        /// Image height, pixels.
        height_px: u32,
    },
    /// `SamplesPerPixel` is 0.
    #[error("SamplesPerPixel is 0")]
    NoSamples,
    /// The `GeoKeyDirectory` is not a whole number of 4-value entries.
    #[error("GeoKeyDirectory has {count} values, not a multiple of 4")]
    GeoKeyCount {
        /// Number of values in the directory.
        count: usize,
    },
    /// The GeoTIFF key directory has a major version other than 1.
    #[error("GeoTIFF major version {major} is not supported")]
    GeoKeyVersion {
        /// The key directory's major version.
        major: u16,
    },
    /// The grid is in a projected CRS.
    #[error(
        "the grid is in a projected CRS; geoid grids must be in latitude/longitude (PROJ: \"Can only handle \
         grids referenced in a geographic CRS\")"
    )]
    Projected,
    /// `GTModelTypeGeoKey` is neither geographic nor projected.
    #[error("GTModelTypeGeoKey {model_type} is neither geographic nor projected")]
    ModelType {
        /// The key's value.
        model_type: u16,
    },
    /// `ModelTransformation` rotates or shears the grid.
    #[error("ModelTransformation has rotation terms (not supported, as in PROJ)")]
    Rotation,
    /// A tag georeferencing needs is absent.
    #[error("no {tag} tag: not a georeferenced GeoTIFF")]
    MissingTag {
        /// The tag's name.
        tag: &'static str,
    },
    /// A georeferencing tag has the wrong number of values.
    #[error("{tag} has {count} values, expected {expected}")]
    TagLength {
        /// The tag's name.
        tag: &'static str,
        /// Number of values found.
        count: usize,
        /// What was expected ("3", "6 (one tiepoint)").
        expected: &'static str,
    },
    /// The node extent or the steps are not finite, out of range or reversed.
    #[error(
        "inconsistent georeferencing: nodes from {west_deg}° to {east_deg}° E, {south_deg}° to {north_deg}° N, \
         steps {h_res_deg}° × {v_res_deg}°"
    )]
    Georeferencing {
        /// Longitude of the westernmost nodes, degrees.
        west_deg: f64,
        /// Longitude of the easternmost nodes, degrees.
        east_deg: f64,
        /// Latitude of the southernmost nodes, degrees.
        south_deg: f64,
        /// Latitude of the northernmost nodes, degrees.
        north_deg: f64,
        /// Node spacing along longitude, degrees.
        h_res_deg: f64,
        /// Node spacing along latitude, degrees (negative: rows run south to north).
        v_res_deg: f64,
    },
    /// The bands are described, but none as the geoid.
    #[error("its bands are described as {names:?} but none as geoid_undulation or vertical_offset")]
    NoGeoidBand {
        /// The bands' descriptions.
        names: Vec<String>,
    },
    /// The band described as the geoid does not exist.
    #[error("band {band} is described as the geoid, but the file has {samples_per_pixel} samples per pixel")]
    BandOutOfRange {
        /// The described band (0-based sample index).
        band: usize,
        /// Samples per pixel in the file.
        samples_per_pixel: usize,
    },
    /// `GDAL_NODATA` is not a number.
    #[error("GDAL_NODATA {text:?} is not a number")]
    Nodata {
        /// The tag's text.
        text: String,
    },
    /// The samples are integers.
    #[error(
        "the samples are integers; only float32/float64 grids are supported (PROJ-data geoid grids are float32)"
    )]
    IntegerSamples,
    /// The image holds fewer samples than its size says.
    #[error("the image holds {found} samples, fewer than {rows} × {cols} × {samples_per_pixel}")]
    TooFewSamples {
        /// Samples decoded.
        found: usize,
        /// Grid rows.
        rows: usize,
        /// Grid columns.
        cols: usize,
        /// Samples per pixel.
        samples_per_pixel: usize,
    },
    /// A further full-resolution grid (a PROJ subgrid hierarchy).
    #[error(
        "IFD {ifd} is a second full-resolution grid (a PROJ subgrid hierarchy), which insgen does not \
         interpolate; use PROJ's own path ([geoid] model = \"proj\") for this grid"
    )]
    Subgrid {
        /// Index of the image file directory.
        ifd: usize,
    },
}
