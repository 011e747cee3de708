//! Geoid undulation for orthometric → ellipsoidal heights. (Skeleton: being implemented.)

/// The geoid model used for an area.
#[derive(Debug, Clone, PartialEq)]
pub enum Geoid {
    /// Heights are already ellipsoidal.
    None,
    /// A constant undulation N in metres (h = H + N).
    Constant(f64),
}

impl Geoid {
    /// Undulation N (metres) at a WGS84 position: h = H + N.
    pub fn undulation_m(&self, _lat_deg: f64, _lon_deg: f64) -> f64 {
        match self {
            Geoid::None => 0.0,
            Geoid::Constant(n) => *n,
        }
    }
}
