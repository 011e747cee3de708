//! CRS parsing and source → WGS84 projection with PROJ. (Skeleton: being implemented.)

use super::{GeoError, Geodetic};

/// How a format orders coordinate axes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum AxisConvention {
    /// The CRS authority's order (GML: EPSG:6697 is latitude, longitude, height).
    Authority,
    /// Always easting/longitude first (CityJSON, OBJ).
    EastNorth,
}

/// What the third coordinate of a CRS means.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum HeightKind {
    /// Height above the ellipsoid (geographic 3D, geocentric).
    Ellipsoidal,
    /// Height above a geoid/vertical datum (compound CRSs with a vertical part, and by convention the
    /// heights of 2D projected CRSs in city models).
    Orthometric,
}

/// A parsed coordinate reference system.
#[derive(Debug, Clone, PartialEq)]
pub struct Crs {
    /// The EPSG code of the horizontal (or geocentric) part.
    pub horizontal_epsg: u32,
    /// The EPSG code of the vertical part of a compound CRS, if any.
    pub vertical_epsg: Option<u32>,
    /// The name as the user or file gave it.
    pub given: String,
}

impl Crs {
    pub fn parse(name: &str) -> Result<Crs, GeoError> {
        Err(GeoError::UnknownCrs { name: name.to_string(), why: "not implemented yet".into() })
    }
    pub fn describe(&self) -> String { String::new() }
    pub fn heights(&self) -> HeightKind {
        HeightKind::Orthometric
    }
    pub fn transform(&self) -> Result<CrsTransform, GeoError> {
        Err(GeoError::UnknownCrs { name: self.given.clone(), why: "not implemented yet".into() })
    }
}

/// A ready converter from one CRS to WGS84 geodetic (not `Sync`: make one per thread).
pub struct CrsTransform {
    pub crs: Crs,
}

impl CrsTransform {
    /// Converts a source point to WGS84 latitude/longitude; the height is passed through as given
    /// (orthometric or ellipsoidal, see [`Crs::heights`]), except for geocentric input.
    pub fn to_geodetic(&self, p: [f64; 3], _axes: AxisConvention) -> Result<Geodetic, GeoError> {
        Err(GeoError::Transform { crs: self.crs.given.clone(), point: p, why: "not implemented yet".into() })
    }
}
