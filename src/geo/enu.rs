//! Local East-North-Up frames at an area origin, and ECEF ↔ ENU conversion in f64.
//!
//! ENU at origin (φ₀, λ₀, h₀): e = (−sin λ₀, cos λ₀, 0), n = (−sin φ₀ cos λ₀, −sin φ₀ sin λ₀, cos φ₀),
//! u = (cos φ₀ cos λ₀, cos φ₀ sin λ₀, sin φ₀), all in ECEF; the origin is the ENU (0, 0, 0).
//!
//! # Units
//! Metres throughout; the origin's latitude/longitude in degrees.

use glam::{DMat3, DMat4, DVec3};

use super::ellipsoid::{ecef_to_geodetic, geodetic_to_ecef, Geodetic};

/// A local tangent frame (ENU) at a geodetic origin.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EnuFrame {
    /// The frame's origin.
    pub origin: Geodetic,
    /// The origin in ECEF metres.
    pub origin_ecef_m: DVec3,
    /// ECEF-from-ENU rotation: its columns are the e, n, u unit vectors in ECEF.
    ecef_from_enu_rot: DMat3,
}

impl EnuFrame {
    /// The ENU frame at `origin`.
    pub fn new(origin: Geodetic) -> Self {
        let (sl, cl) = origin.lat_deg.to_radians().sin_cos();
        let (so, co) = origin.lon_deg.to_radians().sin_cos();
        EnuFrame {
            origin,
            origin_ecef_m: DVec3::from(geodetic_to_ecef(origin)),
            ecef_from_enu_rot: DMat3::from_cols(
                DVec3::new(-so, co, 0.0),
                DVec3::new(-sl * co, -sl * so, cl),
                DVec3::new(cl * co, cl * so, sl),
            ),
        }
    }

    /// ECEF metres → ENU metres: `Rᵀ · (p − o)`.
    pub fn ecef_to_enu(&self, p: DVec3) -> DVec3 {
        self.ecef_from_enu_rot.transpose() * (p - self.origin_ecef_m)
    }

    /// ENU metres → ECEF metres: `o + e·E + n·N + u·U`, summed in that order.
    pub fn enu_to_ecef(&self, e: DVec3) -> DVec3 {
        let r = &self.ecef_from_enu_rot;
        self.origin_ecef_m + r.x_axis * e.x + r.y_axis * e.y + r.z_axis * e.z
    }

    /// Geodetic → ENU metres.
    pub fn geodetic_to_enu(&self, g: Geodetic) -> DVec3 {
        self.ecef_to_enu(DVec3::from(geodetic_to_ecef(g)))
    }

    /// ENU metres → geodetic.
    pub fn enu_to_geodetic(&self, e: DVec3) -> Geodetic {
        ecef_to_geodetic(self.enu_to_ecef(e).to_array())
    }

    /// The ECEF-from-ENU transform (rotation columns e, n, u; translation = origin), as the manifest and
    /// 3D Tiles transforms use it.
    pub fn ecef_from_enu(&self) -> DMat4 {
        DMat4::from_mat3_translation(self.ecef_from_enu_rot, self.origin_ecef_m)
    }

    /// The ENU-from-ECEF transform, the inverse of [`EnuFrame::ecef_from_enu`] (exact: the rotation is
    /// orthonormal, so its inverse is its transpose).
    pub fn enu_from_ecef(&self) -> DMat4 {
        let rt = self.ecef_from_enu_rot.transpose();
        DMat4::from_mat3_translation(rt, -(rt * self.origin_ecef_m))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn origin_maps_to_zero_and_up_is_up() {
        let f = EnuFrame::new(Geodetic::new(35.66, 139.70, 40.0));
        let o = f.geodetic_to_enu(Geodetic::new(35.66, 139.70, 40.0));
        assert!(o.abs().max_element() < 1e-9, "{o:?}");
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
        let (m, inv) = (f.ecef_from_enu(), f.enu_from_ecef());
        for e in [[0.0, 0.0, 0.0], [1234.5, -876.25, 310.0], [-5000.0, 4000.0, -20.0]].map(DVec3::from) {
            let p = f.enu_to_ecef(e);
            assert!((p - m.transform_point3(e)).abs().max_element() < 1e-9);
            let back = f.ecef_to_enu(p);
            assert!((back - e).abs().max_element() < 1e-8, "{e:?} {back:?}");
            assert!((inv.transform_point3(p) - e).abs().max_element() < 1e-8, "{e:?}");
        }
    }
}
