//! Geo-referencing in f64: source CRS → geodetic (WGS84) → ECEF (EPSG:4978, the tileset frame) → ENU.
//!
//! - [`crs`]: parsing CRS names (EPSG codes, OGC URNs/URLs, compound CRSs) and projecting source
//!   coordinates to WGS84 latitude/longitude with PROJ (through a small safe wrapper of the PROJ C
//!   API in the private `pj` module);
//! - [`geoid`]: geoid undulation (EGM96 grid or a per-area constant) to turn orthometric heights into
//!   ellipsoidal ones;
//! - [`ellipsoid`]: WGS84 geodetic ↔ ECEF;
//! - [`enu`]: local ENU frames at an area origin.

pub mod crs;
pub mod ellipsoid;
pub mod enu;
pub mod geoid;
mod pj;

pub use crs::{proj_version, AxisConvention, Crs, CrsAxis, CrsKind, CrsTransform, HeightKind};
pub use ellipsoid::{ecef_to_geodetic, geodetic_to_ecef, Geodetic};
pub use enu::EnuFrame;
pub use geoid::{Geoid, GeoidGrid};

/// Errors of the geo stage.
#[derive(Debug, thiserror::Error)]
pub enum GeoError {
    /// The CRS name could not be parsed or is not known to the CRS layer.
    #[error("unknown or unsupported CRS {name:?}: {why}; set an explicit `crs = \"EPSG:NNNN\"` for this source in the scene file")]
    UnknownCrs { name: String, why: String },
    /// A coordinate could not be converted (outside the projection's domain, NaN…).
    #[error("cannot convert {point:?} from {crs}: {why}")]
    Transform { crs: String, point: [f64; 3], why: String },
    /// A geoid grid is malformed, or a position lies outside it.
    #[error("geoid grid {path}: {why}")]
    Geoid { path: String, why: String },
    /// A file (the geoid grid) could not be read.
    #[error(transparent)]
    File(#[from] crate::util::FileError),
}
