//! Coplanar triangles of a building merged into convex polygons: a wall quad tessellated into two
//! triangles becomes one quad again, so a frame sets up and walks half as many rows for it.
//! Rasterising the polygon covers exactly the pixels of its triangles (see `raster::raster_convex`);
//! only the 1/z plane is taken from one of them.

use std::collections::HashMap;

use super::raster::MAX_POLYGON;
use glam::{DVec3, Vec3};

/// Normals closer than this (1 − cos) count as parallel: about 0.08°.
const PARALLEL: f64 = 1e-6;
/// A vertex this close to a polygon's plane (metres) lies in it.
const IN_PLANE_M: f64 = 2e-4;

/// Greedily merges edge-adjacent, coplanar triangles (vertices welded: shared vertices have equal
/// indices) into convex polygons of at most [`MAX_POLYGON`] vertices that keep the triangles'
/// winding. Deterministic: triangles are seeded in order and grown across their edges in order.
/// Degenerate triangles stay as they are.
pub(super) fn merge_coplanar(positions: &[[f32; 3]], tris: &[[u32; 3]]) -> Vec<Vec<u32>> {
    let pos = |i: u32| Vec3::from(positions[i as usize]).as_dvec3();
    let mut edges: HashMap<(u32, u32), Vec<u32>> = HashMap::new();
    for (f, t) in tris.iter().enumerate() {
        for k in 0..3 {
            edges.entry((t[k], t[(k + 1) % 3])).or_default().push(f as u32);
        }
    }
    let normals: Vec<Option<DVec3>> = tris
        .iter()
        .map(|t| {
            let [a, b, c] = t.map(pos);
            let n = (b - a).cross(c - a);
            let len = n.length();
            (len > 1e-12).then(|| n / len)
        })
        .collect();
    let mut used = vec![false; tris.len()];
    let mut out = Vec::new();
    for seed in 0..tris.len() {
        if used[seed] {
            continue;
        }
        used[seed] = true;
        let mut poly = tris[seed].to_vec();
        let Some(n) = normals[seed] else {
            out.push(poly);
            continue;
        };
        let origin = pos(poly[0]);
        'grow: while poly.len() < MAX_POLYGON {
            for k in 0..poly.len() {
                let (a, b) = (poly[k], poly[(k + 1) % poly.len()]);
                for &f in edges.get(&(b, a)).map_or(&[][..], Vec::as_slice) {
                    let f = f as usize;
                    if used[f] || normals[f].is_none_or(|m| n.dot(m) < 1.0 - PARALLEL) {
                        continue;
                    }
                    let Some(&c) = tris[f].iter().find(|&&v| v != a && v != b) else { continue };
                    if poly.contains(&c) || (pos(c) - origin).dot(n).abs() > IN_PLANE_M {
                        continue;
                    }
                    let mut grown = poly.clone();
                    grown.insert(k + 1, c);
                    if strictly_convex(&grown, n, &pos) {
                        used[f] = true;
                        poly = grown;
                        continue 'grow;
                    }
                }
            }
            break;
        }
        out.push(poly);
    }
    out
}

/// Whether the polygon turns the same way (about `n`) at every vertex, by a clear margin.
fn strictly_convex(poly: &[u32], n: DVec3, pos: &dyn Fn(u32) -> DVec3) -> bool {
    let m = poly.len();
    (0..m).all(|i| {
        let [p, q, r] = [poly[i], poly[(i + 1) % m], poly[(i + 2) % m]].map(pos);
        let (u, v) = (q - p, r - q);
        u.cross(v).dot(n) > 1e-6 * u.length() * v.length()
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_quad_and_a_fan_merge_but_a_fold_does_not() {
        // A unit square as two triangles, plus a triangle folded up along its right edge.
        let p = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 0.0], [1.5, 0.5, 1.0]];
        let merged = merge_coplanar(&p, &[[0, 1, 2], [0, 2, 3], [2, 1, 4]]);
        assert_eq!(merged, vec![vec![0, 1, 2, 3], vec![2, 1, 4]]);
        // A regular hexagon fanned from its centre: merged into convex pieces of the same winding,
        // the centre vertex (a 180° corner) only where it stays strictly convex.
        let mut p: Vec<[f32; 3]> = vec![[0.0; 3]];
        p.extend((0..6).map(|i| {
            let a = i as f32 * std::f32::consts::FRAC_PI_3;
            [a.cos(), a.sin(), 0.0]
        }));
        let tris: Vec<[u32; 3]> = (0..6).map(|i| [0, 1 + i, 1 + (i + 1) % 6]).collect();
        let merged = merge_coplanar(&p, &tris);
        assert!(merged.len() < 6, "{merged:?}");
        let corners: usize = merged.iter().map(|q| q.len() - 2).sum();
        assert_eq!(corners, 6, "triangle count is preserved: {merged:?}");
        // An inverted neighbour (opposite winding) is never merged.
        let p = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 0.0]];
        assert_eq!(merge_coplanar(&p, &[[0, 1, 2], [0, 3, 2]]).len(), 2);
    }
}
