//! Local East-North-Up frames at an area origin, and ECEF ↔ ENU conversion in f64.
//!
//! ENU at origin (φ₀, λ₀, h₀): e = (−sin λ₀, cos λ₀, 0), n = (−sin φ₀ cos λ₀, −sin φ₀ sin λ₀, cos φ₀),
//! u = (cos φ₀ cos λ₀, cos φ₀ sin λ₀, sin φ₀), all in ECEF; the origin is the ENU (0, 0, 0).
//!
//! # Units
//! Metres throughout; the origin's latitude/longitude in degrees.

use super::ellipsoid::{ecef_to_geodetic, geodetic_to_ecef, Geodetic};

/// A local tangent frame (ENU) at a geodetic origin.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EnuFrame {
    pub origin: Geodetic,
    /// The origin in ECEF metres.
    pub origin_ecef_m: [f64; 3],
    /// Rows are the e, n, u unit vectors in ECEF (so `rot · (p − o)` gives ENU).
    rot: [[f64; 3]; 3],
}

impl EnuFrame {
    pub fn new(origin: Geodetic) -> Self {
        let (sl, cl) = origin.lat_deg.to_radians().sin_cos();
        let (so, co) = origin.lon_deg.to_radians().sin_cos();
        EnuFrame {
            origin,
            origin_ecef_m: geodetic_to_ecef(origin),
            rot: [[-so, co, 0.0], [-sl * co, -sl * so, cl], [cl * co, cl * so, sl]],
        }
    }

    /// ECEF metres → ENU metres.
    pub fn ecef_to_enu(&self, p: [f64; 3]) -> [f64; 3] {
        let d = [p[0] - self.origin_ecef_m[0], p[1] - self.origin_ecef_m[1], p[2] - self.origin_ecef_m[2]];
        let r = &self.rot;
        [
            r[0][0] * d[0] + r[0][1] * d[1] + r[0][2] * d[2],
            r[1][0] * d[0] + r[1][1] * d[1] + r[1][2] * d[2],
            r[2][0] * d[0] + r[2][1] * d[1] + r[2][2] * d[2],
        ]
    }

    /// ENU metres → ECEF metres.
    pub fn enu_to_ecef(&self, e: [f64; 3]) -> [f64; 3] {
        let r = &self.rot;
        let o = self.origin_ecef_m;
        [
            o[0] + r[0][0] * e[0] + r[1][0] * e[1] + r[2][0] * e[2],
            o[1] + r[0][1] * e[0] + r[1][1] * e[1] + r[2][1] * e[2],
            o[2] + r[0][2] * e[0] + r[1][2] * e[1] + r[2][2] * e[2],
        ]
    }

    /// Geodetic → ENU metres.
    pub fn geodetic_to_enu(&self, g: Geodetic) -> [f64; 3] {
        self.ecef_to_enu(geodetic_to_ecef(g))
    }

    /// ENU metres → geodetic.
    pub fn enu_to_geodetic(&self, e: [f64; 3]) -> Geodetic {
        ecef_to_geodetic(self.enu_to_ecef(e))
    }

    /// The ECEF-from-ENU transform as a 4×4 row-major matrix (rotation columns e, n, u; translation
    /// = origin), as the manifest and 3D Tiles transforms use.
    pub fn ecef_from_enu_matrix(&self) -> [[f64; 4]; 4] {
        let r = &self.rot;
        let o = self.origin_ecef_m;
        [
            [r[0][0], r[1][0], r[2][0], o[0]],
            [r[0][1], r[1][1], r[2][1], o[1]],
            [r[0][2], r[1][2], r[2][2], o[2]],
            [0.0, 0.0, 0.0, 1.0],
        ]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn origin_maps_to_zero_and_up_is_up() {
        let f = EnuFrame::new(Geodetic::new(35.66, 139.70, 40.0));
        let o = f.geodetic_to_enu(Geodetic::new(35.66, 139.70, 40.0));
        assert!(o.iter().all(|v| v.abs() < 1e-9), "{o:?}");
        let up = f.geodetic_to_enu(Geodetic::new(35.66, 139.70, 140.0));
        assert!((up[2] - 100.0).abs() < 1e-9 && up[0].abs() < 1e-9 && up[1].abs() < 1e-9, "{up:?}");
    }

    #[test]
    fn north_and_east_directions() {
        let f = EnuFrame::new(Geodetic::new(52.0, 4.3, 0.0));
        let n = f.geodetic_to_enu(Geodetic::new(52.001, 4.3, 0.0));
        assert!(n[1] > 111.0 && n[1] < 111.5 && n[0].abs() < 1e-6, "{n:?}");
        let e = f.geodetic_to_enu(Geodetic::new(52.0, 4.301, 0.0));
        assert!(e[0] > 68.0 && e[0] < 69.0 && e[1].abs() < 0.01, "{e:?}");
    }

    #[test]
    fn round_trip_and_matrix_agree() {
        let f = EnuFrame::new(Geodetic::new(-33.9, 151.2, 12.0));
        let m = f.ecef_from_enu_matrix();
        for e in [[0.0, 0.0, 0.0], [1234.5, -876.25, 310.0], [-5000.0, 4000.0, -20.0]] {
            let p = f.enu_to_ecef(e);
            let pm = [0, 1, 2].map(|i| m[i][0] * e[0] + m[i][1] * e[1] + m[i][2] * e[2] + m[i][3]);
            for k in 0..3 {
                assert!((p[k] - pm[k]).abs() < 1e-9);
            }
            let back = f.ecef_to_enu(p);
            for k in 0..3 {
                assert!((back[k] - e[k]).abs() < 1e-8, "{e:?} {back:?}");
            }
        }
    }
}
