//! Geoid undulation for orthometric → ellipsoidal heights. (Skeleton: being implemented.)

/// The geoid model used for an area.
#[derive(Debug, Clone, PartialEq)]
pub enum Geoid {
    /// Heights are already ellipsoidal.
    None,
    /// A constant undulation N in metres (h = H + N).
    Constant(f64),
    Grid(GeoidGrid),
}

impl Geoid {
    /// Undulation N (metres) at a WGS84 position: h = H + N.
    pub fn undulation_m(&self, _lat_deg: f64, _lon_deg: f64) -> f64 {
        match self {
            Geoid::None => 0.0,
            Geoid::Constant(n) => *n,
            Geoid::Grid(_) => 0.0,
        }
    }
}
#[derive(Debug, Clone, PartialEq)]
pub struct GeoidGrid;
impl GeoidGrid { pub fn load_gtx(_p: &std::path::Path) -> Result<GeoidGrid, super::GeoError> { todo!() } pub fn path(&self) -> &std::path::Path { todo!() } }
impl Geoid { pub fn find_egm96() -> Option<std::path::PathBuf> { None } pub fn name(&self) -> &'static str { "x" } }
