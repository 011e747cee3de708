//! Geo-referencing in f64: source CRS → geodetic (WGS84) → ECEF (EPSG:4978, the tileset frame) → ENU.
//!
//! - [`crs`]: parsing CRS names (EPSG codes, OGC URNs/URLs, compound CRSs) and projecting source
//!   coordinates to WGS84 latitude/longitude with PROJ (through a small safe wrapper of the PROJ C
//!   API in the private `pj` module);
//! - [`geoid`]: geoid undulation (EGM96, any `.gtx` or GeoTIFF vertical grid PROJ can read, or a
//!   per-area constant) to turn orthometric heights into ellipsoidal ones; the private `geotiff`
//!   module reads the GeoTIFF grids;
//! - [`ellipsoid`]: WGS84 geodetic ↔ ECEF;
//! - [`enu`]: local ENU frames at an area origin;
//! - [`error`]: the stage's errors, PROJ's reasons included.

pub mod crs;
pub mod ellipsoid;
pub mod enu;
pub mod error;
pub mod geoid;
mod geotiff;
mod pj;

pub use crs::{
    proj_version, AxisConvention, Crs, CrsAxis, CrsKind, CrsTransform, HeightKind, VerticalChoice,
};
pub use ellipsoid::{ecef_to_geodetic, geodetic_to_ecef, Geodetic};
pub use enu::EnuFrame;
pub use error::{CrsError, CsPart, GeoError, GeoTiffError, ProjError};
pub use geoid::{Geoid, GeoidGrid};
