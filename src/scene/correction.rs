//! The alignment correction of a prepared area: a rigid motion that moves the LoD model onto the
//! photogrammetry (or any reference) model, recorded in the manifest and applied by
//! [`crate::scene::PreparedScene::load`] so that every later stage sees the corrected geometry.
//!
//! # Definition
//! A [`Correction`] maps a point of the LoD model in the area's ENU frame, `p`, to its corrected
//! position
//!
//! ```text
//! p' = Rz(yaw) · (p − c) + c + t,     c = (pivot_e, pivot_n, 0),   t = (east_m, north_m, up_m)
//! ```
//!
//! where `Rz(yaw)` turns counter-clockwise seen from above (east towards north) and the pivot `c` is
//! the centre of the LoD model's footprint (so the translation and the yaw are nearly uncorrelated).
//! The camera frame, the area origin and `ecef_from_enu` stay as prepared: cameras are sampled in the
//! world the photographs show; only the LoD geometry moves. The corrected ECEF placement of the LoD
//! model is `ecef_from_enu · M`, with `M` = [`Correction::enu_from_lod`]; the manifest's
//! [`AlignmentRecord`] carries both transforms so the chain stays auditable.
//!
//! # Units
//! Metres and degrees at the file edge (`yaw_deg`), radians inside.

use glam::{DMat4, DVec3};
use serde::{Deserialize, Serialize};

use super::artifact::BuildingRecord;
pub use super::error::CorrectionError;
use super::mesh::SceneMesh;

/// A rigid correction of the LoD model in the area's ENU frame (see the module doc).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Correction {
    /// Translation, metres (ENU axes).
    pub east_m: f64,
    /// Translation north, metres.
    pub north_m: f64,
    /// Translation up, metres.
    pub up_m: f64,
    /// Rotation about the vertical through the pivot, degrees, counter-clockwise seen from above.
    pub yaw_deg: f64,
    /// Pivot of the rotation (east, north), metres in the area's ENU frame.
    #[serde(default)]
    pub pivot_enu_m: [f64; 2],
}

impl Correction {
    /// No correction (pivot at the origin).
    pub const IDENTITY: Correction =
        Correction { east_m: 0.0, north_m: 0.0, up_m: 0.0, yaw_deg: 0.0, pivot_enu_m: [0.0, 0.0] };

    /// Whether this correction moves nothing.
    pub fn is_identity(&self) -> bool {
        self.east_m == 0.0 && self.north_m == 0.0 && self.up_m == 0.0 && self.yaw_deg == 0.0
    }

    /// Checks every number is finite.
    ///
    /// # Errors
    /// [`CorrectionError::NotFinite`] naming the first non-finite field.
    pub fn validate(&self) -> Result<(), CorrectionError> {
        let fields = [
            ("east_m", self.east_m),
            ("north_m", self.north_m),
            ("up_m", self.up_m),
            ("yaw_deg", self.yaw_deg),
            ("pivot_enu_m[0]", self.pivot_enu_m[0]),
            ("pivot_enu_m[1]", self.pivot_enu_m[1]),
        ];
        for (name, v) in fields {
            if !v.is_finite() {
                return Err(CorrectionError::NotFinite { field: name, value: v });
            }
        }
        Ok(())
    }

    /// The corrected-ENU-from-LoD-ENU transform `M` (see the module doc).
    pub fn enu_from_lod(&self) -> DMat4 {
        let c = DVec3::new(self.pivot_enu_m[0], self.pivot_enu_m[1], 0.0);
        DMat4::from_translation(c + DVec3::new(self.east_m, self.north_m, self.up_m))
            * DMat4::from_rotation_z(self.yaw_deg.to_radians())
            * DMat4::from_translation(-c)
    }

    /// Applies the correction to one point (ENU metres).
    pub fn apply(&self, p_enu_m: DVec3) -> DVec3 {
        let (s, co) = self.yaw_deg.to_radians().sin_cos();
        let (dx, dy) = (p_enu_m.x - self.pivot_enu_m[0], p_enu_m.y - self.pivot_enu_m[1]);
        DVec3::new(
            co * dx - s * dy + self.pivot_enu_m[0] + self.east_m,
            s * dx + co * dy + self.pivot_enu_m[1] + self.north_m,
            p_enu_m.z + self.up_m,
        )
    }

    /// The same motion expressed about another pivot (only the translation changes).
    pub fn with_pivot(&self, pivot_enu_m: [f64; 2]) -> Correction {
        // p' = R(p − c) + c + t = R(p − c2) + c2 + t2 with t2 = t + R(c2 − c) − (c2 − c).
        let d = DVec3::new(pivot_enu_m[0] - self.pivot_enu_m[0], pivot_enu_m[1] - self.pivot_enu_m[1], 0.0);
        let (s, co) = self.yaw_deg.to_radians().sin_cos();
        let rd = DVec3::new(co * d.x - s * d.y, s * d.x + co * d.y, 0.0);
        Correction {
            east_m: self.east_m + rd.x - d.x,
            north_m: self.north_m + rd.y - d.y,
            up_m: self.up_m,
            yaw_deg: self.yaw_deg,
            pivot_enu_m,
        }
    }

    /// Moves the scene mesh (f64 arithmetic, then back to f32 ENU metres).
    pub fn apply_to_mesh(&self, mesh: &mut SceneMesh) {
        self.apply_to_points(&mut mesh.positions_m);
    }

    /// Applies the correction to ENU points in metres (f32 storage, f64 arithmetic).
    pub fn apply_to_points(&self, points_m: &mut [[f32; 3]]) {
        for p in points_m {
            let q = self.apply(DVec3::new(p[0] as f64, p[1] as f64, p[2] as f64));
            *p = [q.x as f32, q.y as f32, q.z as f32];
        }
    }

    /// Updates the building table after [`Correction::apply_to_mesh`]: bounds recomputed from the
    /// moved mesh, footprint centroids moved (lat/lon through `enu`).
    pub fn apply_to_buildings(
        &self,
        moved: &SceneMesh,
        buildings: &mut [BuildingRecord],
        enu: &crate::geo::EnuFrame,
    ) {
        use std::collections::HashMap;
        let mut bounds: HashMap<u32, ([f64; 3], [f64; 3])> = HashMap::new();
        for (p, id) in moved.positions_m.iter().zip(&moved.building_ids) {
            let b = bounds.entry(id.get()).or_insert(([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]));
            for (k, &v) in p.iter().enumerate() {
                b.0[k] = b.0[k].min(v as f64);
                b.1[k] = b.1[k].max(v as f64);
            }
        }
        for r in buildings {
            if let Some((lo, hi)) = bounds.get(&r.id.get()) {
                r.bbox_min_enu_m = *lo;
                r.bbox_max_enu_m = *hi;
            }
            let c =
                enu.geodetic_to_enu(crate::geo::Geodetic::new(r.centroid_lat_deg, r.centroid_lon_deg, 0.0));
            let g = enu.enu_to_geodetic(self.apply(c));
            r.centroid_lat_deg = g.lat_deg;
            r.centroid_lon_deg = g.lon_deg;
        }
    }
}

/// Where a recorded correction came from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum CorrectionSource {
    /// Estimated by `insgen align` against a tileset.
    Estimated,
    /// Pinned by hand in the area's scene file (`[alignment]`).
    SceneConfig,
}

/// One-sigma uncertainty of an estimated correction (from the normal matrix of the final
/// least-squares step scaled by the residual variance; optimistic when residuals are correlated).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CorrectionSigma {
    /// One sigma of the east translation, metres.
    pub east_m: f64,
    /// One sigma of the north translation, metres.
    pub north_m: f64,
    /// One sigma of the up translation, metres.
    pub up_m: f64,
    /// One sigma of the yaw, degrees.
    pub yaw_deg: f64,
}

/// Agreement of the LoD model with the reference model over the area (height maps, see
/// [`crate::scene::align`]).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Agreement {
    /// Median |h_reference − h_LoD| over the LoD's roof cells the reference also covers, metres.
    pub median_abs_dh_roofs_m: f64,
    /// IoU of the LoD's building cells with the reference's above-ground cells.
    pub footprint_iou: f64,
    /// Cells that entered the median.
    pub roof_cells: u64,
}

/// The correction record of a prepared area (`manifest.json` → `alignment`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AlignmentRecord {
    /// Where the correction came from (estimated or pinned in the scene file).
    pub source: CorrectionSource,
    /// The correction applied to the LoD model at load time.
    pub correction: Correction,
    /// One-sigma uncertainty (estimated corrections only).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sigma: Option<CorrectionSigma>,
    /// The reference tileset (estimated corrections only) and its fingerprint
    /// ([`crate::lod::tiles3d::fingerprint`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub tileset: Option<String>,
    /// SHA-256 fingerprint of the reference tileset.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub tileset_sha256: Option<String>,
    /// ECEF-from-ENU of the LoD model as prepared (equal to the manifest's `ecef_from_enu`).
    #[serde(with = "crate::util::row_major")]
    pub ecef_from_lod_original: DMat4,
    /// ECEF-from-ENU of the LoD model after the correction: `ecef_from_enu · enu_from_lod`.
    #[serde(with = "crate::util::row_major")]
    pub ecef_from_lod_corrected: DMat4,
    /// Agreement with the reference before and after (estimated corrections only).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub before: Option<Agreement>,
    /// Agreement after the correction.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub after: Option<Agreement>,
}

impl AlignmentRecord {
    /// A record for `correction` on an area whose ENU frame is `ecef_from_enu`.
    pub fn new(source: CorrectionSource, correction: Correction, ecef_from_enu: DMat4) -> AlignmentRecord {
        AlignmentRecord {
            source,
            correction,
            sigma: None,
            tileset: None,
            tileset_sha256: None,
            ecef_from_lod_original: ecef_from_enu,
            ecef_from_lod_corrected: ecef_from_enu * correction.enu_from_lod(),
            before: None,
            after: None,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn c() -> Correction {
        Correction { east_m: 1.5, north_m: -2.0, up_m: 0.7, yaw_deg: 0.8, pivot_enu_m: [120.0, -40.0] }
    }

    #[test]
    fn matrix_and_point_forms_agree() {
        let m = c().enu_from_lod();
        for p in [[0.0, 0.0, 0.0], [300.0, 200.0, 50.0], [-500.0, 80.0, -3.0]] {
            let p = DVec3::from_array(p);
            assert!(m.transform_point3(p).distance(c().apply(p)) < 1e-9);
        }
    }

    #[test]
    fn pivot_moves_the_translation_only() {
        let a = c();
        let b = a.with_pivot([-700.0, 900.0]);
        for p in [[0.0, 0.0, 0.0], [300.0, 200.0, 50.0], [-500.0, 80.0, -3.0]] {
            let p = DVec3::from_array(p);
            assert!(a.apply(p).distance(b.apply(p)) < 1e-9);
        }
        // The pivot itself moves by exactly the translation (hand computation).
        let piv = DVec3::new(120.0, -40.0, 0.0);
        assert!(a.apply(piv).distance(piv + DVec3::new(1.5, -2.0, 0.7)) < 1e-12);
    }

    #[test]
    fn yaw_turns_east_towards_north() {
        let r = Correction { yaw_deg: 90.0, ..Correction::IDENTITY };
        assert!(r.apply(DVec3::X).distance(DVec3::Y) < 1e-12);
    }

    #[test]
    fn non_finite_values_are_named() {
        let bad = Correction { yaw_deg: f64::NAN, ..Correction::IDENTITY };
        assert!(bad.validate().unwrap_err().to_string().contains("yaw_deg"));
    }
}
