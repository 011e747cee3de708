//! Photogrammetry-like reference models made from insgen's own buildings, for testing `align` and the
//! tileset-aware masks without shipping third-party tilesets.
//!
//! [`perturb`] takes the buildings of a prepared scene (ENU metres, see
//! [`crate::scene::mesh::buildings_from_scene`]) and returns what a photogrammetry mesh of the
//! same place might hold: the buildings moved by a known rigid [`Correction`] (the "offset" `align`
//! must recover), every vertex jittered by a seeded uniform amount (the same for coincident vertices,
//! so surfaces stay closed), a ground surface of jittered quads under the whole area, and clutter the
//! LoD model does not have: box "trees" and one tall "crane". The result is written as a tileset by
//! [`crate::export::city_tileset::generate_city_tileset`]. Same inputs and seed, same output.

use glam::DVec3;

use super::correction::Correction;
pub use super::error::PerturbError;
use super::ids::BuildingId;
use crate::scene::mesh::CityBuilding;

/// What to add to and how to disturb the buildings.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Perturbation {
    /// Applied to every building vertex (not to the ground and clutter, which stand on their own).
    pub offset: Correction,
    /// Half-width of the uniform per-vertex jitter, metres (each axis).
    pub jitter_m: f64,
    /// Box trees to scatter (4 × 4 m, 6–12 m tall) and whether to add the 45 m crane.
    pub trees: usize,
    /// Whether to add the 45 m crane.
    pub crane: bool,
    /// Height of the ground surface to add (ENU metres), or none.
    pub ground_enu_m: Option<f64>,
    /// Seed of the jitter and the clutter placement.
    pub seed: u64,
}

impl Perturbation {
    /// Photogrammetry-like defaults: ±5 cm jitter, 40 trees, a crane, a ground at `ground_enu_m`.
    pub fn photogrammetry_like(offset: Correction, ground_enu_m: f64, seed: u64) -> Perturbation {
        Perturbation {
            offset,
            jitter_m: 0.05,
            trees: 40,
            crane: true,
            ground_enu_m: Some(ground_enu_m),
            seed,
        }
    }
}

/// SplitMix64 (Steele, Lea & Flood 2014): a seeded hash to uniform bits.
fn splitmix(mut x: u64) -> u64 {
    x = x.wrapping_add(0x9e37_79b9_7f4a_7c15);
    x = (x ^ (x >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    x = (x ^ (x >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    x ^ (x >> 31)
}

/// Uniform in [−1, 1) from a hash.
fn unit(h: u64) -> f64 {
    (h >> 11) as f64 / (1u64 << 52) as f64 - 1.0
}

fn jitter(p: [f64; 3], half_m: f64, seed: u64) -> [f64; 3] {
    if half_m == 0.0 {
        return p;
    }
    let mut h = seed;
    for c in p {
        h = splitmix(h ^ c.to_bits());
    }
    [0, 1, 2].map(|k| p[k] + half_m * unit(splitmix(h.wrapping_add(k as u64))))
}

/// An axis-aligned box as a building (closed, 12 triangles, outward winding).
pub fn box_building(id: BuildingId, lo: [f64; 3], hi: [f64; 3]) -> CityBuilding {
    let positions: Vec<[f64; 3]> = (0..8)
        .map(|k| {
            [
                if k & 1 == 0 { lo[0] } else { hi[0] },
                if k & 2 == 0 { lo[1] } else { hi[1] },
                if k & 4 == 0 { lo[2] } else { hi[2] },
            ]
        })
        .collect();
    let faces = [[0, 2, 3, 1], [4, 5, 7, 6], [0, 1, 5, 4], [2, 6, 7, 3], [0, 4, 6, 2], [1, 3, 7, 5]];
    let mut triangles = Vec::new();
    for f in faces {
        triangles.push([f[0], f[1], f[2]]);
        triangles.push([f[0], f[2], f[3]]);
    }
    CityBuilding { id, positions_enu_m: positions, triangles }
}

/// The perturbed buildings plus ground and clutter (see the module doc). New pieces get IDs above the
/// largest input ID.
///
/// # Errors
/// [`PerturbError::IdSpace`] when the new pieces would need IDs beyond 24 bits.
pub fn perturb(buildings: &[CityBuilding], p: &Perturbation) -> Result<Vec<CityBuilding>, PerturbError> {
    let mut out: Vec<CityBuilding> = buildings
        .iter()
        .map(|b| CityBuilding {
            id: b.id,
            positions_enu_m: b
                .positions_enu_m
                .iter()
                .map(|q| jitter(p.offset.apply(DVec3::from_array(*q)).to_array(), p.jitter_m, p.seed))
                .collect(),
            triangles: b.triangles.clone(),
        })
        .collect();
    let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
    for b in &out {
        for q in &b.positions_enu_m {
            for k in 0..2 {
                lo[k] = lo[k].min(q[k]);
                hi[k] = hi[k].max(q[k]);
            }
        }
    }
    if !lo[0].is_finite() {
        return Ok(out);
    }
    let mut next = buildings.iter().map(|b| b.id.get()).max().unwrap_or(0) + 1;
    let mut new_id = || -> Result<BuildingId, PerturbError> {
        let id = BuildingId::new(next).map_err(|_| PerturbError::IdSpace { id: next })?;
        next += 1;
        Ok(id)
    };
    let base = p.ground_enu_m.unwrap_or_else(|| {
        buildings.iter().flat_map(|b| b.positions_enu_m.iter().map(|q| q[2])).fold(f64::INFINITY, f64::min)
    });
    if let Some(g) = p.ground_enu_m {
        // Quads of 25 m, each its own piece so the tileset's quadtree spreads them over its tiles.
        const QUAD_M: f64 = 25.0;
        let (nx, ny) =
            (((hi[0] - lo[0]) / QUAD_M).ceil() as usize + 2, ((hi[1] - lo[1]) / QUAD_M).ceil() as usize + 2);
        for j in 0..ny {
            for i in 0..nx {
                let (x, y) = (lo[0] - QUAD_M + i as f64 * QUAD_M, lo[1] - QUAD_M + j as f64 * QUAD_M);
                let corners = [[x, y], [x + QUAD_M, y], [x + QUAD_M, y + QUAD_M], [x, y + QUAD_M]];
                out.push(CityBuilding {
                    id: new_id()?,
                    positions_enu_m: corners
                        .iter()
                        .map(|c| jitter([c[0], c[1], g], p.jitter_m, p.seed))
                        .collect(),
                    triangles: vec![[0, 1, 2], [0, 2, 3]],
                });
            }
        }
    }
    let mut h = splitmix(p.seed ^ 0x7472_6565);
    let mut draw = |lo: f64, hi: f64| {
        h = splitmix(h);
        lo + (hi - lo) * 0.5 * (unit(h) + 1.0)
    };
    for _ in 0..p.trees {
        let (x, y, tall) = (draw(lo[0], hi[0]), draw(lo[1], hi[1]), draw(6.0, 12.0));
        out.push(box_building(new_id()?, [x - 2.0, y - 2.0, base], [x + 2.0, y + 2.0, base + tall]));
    }
    if p.crane {
        let (x, y) = (draw(lo[0], hi[0]), draw(lo[1], hi[1]));
        out.push(box_building(new_id()?, [x - 1.0, y - 1.0, base], [x + 1.0, y + 1.0, base + 45.0]));
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn one() -> Vec<CityBuilding> {
        vec![box_building(BuildingId::new(7).unwrap(), [0.0, 0.0, 0.0], [10.0, 8.0, 12.0])]
    }

    #[test]
    fn offset_only_moves_the_buildings_exactly() {
        let c = Correction { east_m: 1.0, north_m: 2.0, up_m: 3.0, ..Correction::IDENTITY };
        let p =
            Perturbation { offset: c, jitter_m: 0.0, trees: 0, crane: false, ground_enu_m: None, seed: 1 };
        let out = perturb(&one(), &p).unwrap();
        assert_eq!(out.len(), 1);
        assert_eq!(out[0].positions_enu_m[0], [1.0, 2.0, 3.0]);
    }

    #[test]
    fn jitter_is_bounded_seeded_and_shared_by_coincident_vertices() {
        let p = Perturbation::photogrammetry_like(Correction::IDENTITY, 0.0, 5);
        let a = perturb(&one(), &p).unwrap();
        assert_eq!(a, perturb(&one(), &p).unwrap());
        let b = perturb(&one(), &Perturbation { seed: 6, ..p }).unwrap();
        assert_ne!(a[0].positions_enu_m, b[0].positions_enu_m);
        for (q, r) in a[0].positions_enu_m.iter().zip(&one()[0].positions_enu_m) {
            assert!((0..3).all(|k| (q[k] - r[k]).abs() <= 0.05));
        }
        assert_eq!(jitter([1.0, 2.0, 3.0], 0.05, 9), jitter([1.0, 2.0, 3.0], 0.05, 9));
        // Ground quads, 40 trees and a crane, with fresh IDs.
        assert!(a.len() > 42);
        assert!(a[1..].iter().all(|b| b.id.get() > 7));
    }
}
