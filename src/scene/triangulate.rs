//! Triangulation of planar polygons with holes (CityGML/CityJSON boundary surfaces).
//!
//! Each polygon is projected onto its own plane — the plane through its first vertex with the Newell
//! normal of the exterior ring — and triangulated there with earcut (holes supported); the triangles
//! index the original 3D vertices, so nothing is moved off the surface. Coordinates are taken relative
//! to the polygon's first vertex before projecting, so f64 precision is kept at any magnitude.
//!
//! A polygon is *degenerate* (dropped and counted by the caller) when its exterior ring has fewer than
//! 3 distinct points, a (near-)zero Newell normal (collinear points, zero area), or non-finite
//! coordinates. Degenerate holes are dropped silently (the face itself is still valid).

/// Area (m²) below which a polygon counts as degenerate.
pub const MIN_POLYGON_AREA_M2: f64 = 1e-6;

fn newell_normal(ring: &[[f64; 3]]) -> [f64; 3] {
    let o = ring[0];
    let mut n = [0.0; 3];
    for i in 0..ring.len() {
        let a = ring[i];
        let b = ring[(i + 1) % ring.len()];
        let (ax, ay, az) = (a[0] - o[0], a[1] - o[1], a[2] - o[2]);
        let (bx, by, bz) = (b[0] - o[0], b[1] - o[1], b[2] - o[2]);
        n[0] += (ay - by) * (az + bz);
        n[1] += (az - bz) * (ax + bx);
        n[2] += (ax - bx) * (ay + by);
    }
    n
}

fn distinct_points(ring: &[[f64; 3]]) -> usize {
    let mut pts: Vec<[u64; 3]> = ring.iter().map(|p| p.map(f64::to_bits)).collect();
    pts.sort_unstable();
    pts.dedup();
    pts.len()
}

/// Area of a planar ring in m² (half the Newell normal's length).
pub fn ring_area_m2(ring: &[[f64; 3]]) -> f64 {
    if ring.len() < 3 {
        return 0.0;
    }
    let n = newell_normal(ring);
    0.5 * (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt()
}

fn usable_ring(ring: &[[f64; 3]]) -> bool {
    ring.len() >= 3
        && ring.iter().all(|p| p.iter().all(|v| v.is_finite()))
        && distinct_points(ring) >= 3
        && ring_area_m2(ring) > MIN_POLYGON_AREA_M2
}

/// Triangulates one polygon (exterior + holes, open rings, metres). On success appends its vertices to
/// `positions` and its triangles (indices into `positions`) to `triangles` and returns `true`; returns
/// `false` (appending nothing) for a degenerate polygon.
pub fn triangulate_polygon(
    exterior: &[[f64; 3]],
    interiors: &[Vec<[f64; 3]>],
    positions: &mut Vec<[f64; 3]>,
    triangles: &mut Vec<[u32; 3]>,
) -> bool {
    if !usable_ring(exterior) {
        return false;
    }
    let n = newell_normal(exterior);
    let len = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
    let n = [n[0] / len, n[1] / len, n[2] / len];
    // An orthonormal basis (u, v) of the plane.
    let helper = if n[0].abs() < 0.9 { [1.0, 0.0, 0.0] } else { [0.0, 1.0, 0.0] };
    let mut u = [
        helper[1] * n[2] - helper[2] * n[1],
        helper[2] * n[0] - helper[0] * n[2],
        helper[0] * n[1] - helper[1] * n[0],
    ];
    let ul = (u[0] * u[0] + u[1] * u[1] + u[2] * u[2]).sqrt();
    u = [u[0] / ul, u[1] / ul, u[2] / ul];
    let v = [n[1] * u[2] - n[2] * u[1], n[2] * u[0] - n[0] * u[2], n[0] * u[1] - n[1] * u[0]];
    let o = exterior[0];
    let project = |p: &[f64; 3]| {
        let d = [p[0] - o[0], p[1] - o[1], p[2] - o[2]];
        [d[0] * u[0] + d[1] * u[1] + d[2] * u[2], d[0] * v[0] + d[1] * v[1] + d[2] * v[2]]
    };

    let mut pts3: Vec<[f64; 3]> = exterior.to_vec();
    let mut holes: Vec<u32> = Vec::new();
    for ring in interiors {
        if usable_ring(ring) {
            holes.push(pts3.len() as u32);
            pts3.extend_from_slice(ring);
        }
    }
    let pts2: Vec<[f64; 2]> = pts3.iter().map(project).collect();
    let mut out: Vec<u32> = Vec::new();
    earcut::Earcut::new().earcut(pts2.iter().copied(), &holes, &mut out);
    if out.is_empty() {
        return false;
    }
    let base = positions.len() as u32;
    positions.extend_from_slice(&pts3);
    for t in out.chunks_exact(3) {
        triangles.push([base + t[0], base + t[1], base + t[2]]);
    }
    true
}

/// [`triangulate_polygon`] carrying one texture coordinate per vertex: `uv_exterior` parallel to
/// `exterior`, `uv_interiors[k]` parallel to `interiors[k]`. On success the vertices' coordinates are
/// appended to `uvs` in the order their positions are appended to `positions` (holes that are
/// dropped as degenerate take their coordinates with them), so `uvs` stays parallel to `positions`.
/// A coordinate list shorter than its ring (the readers build them parallel) is padded with (0, 0).
pub fn triangulate_polygon_uv(
    exterior: &[[f64; 3]],
    interiors: &[Vec<[f64; 3]>],
    uv_exterior: &[[f64; 2]],
    uv_interiors: &[Vec<[f64; 2]>],
    positions: &mut Vec<[f64; 3]>,
    uvs: &mut Vec<[f32; 2]>,
    triangles: &mut Vec<[u32; 3]>,
) -> bool {
    if !triangulate_polygon(exterior, interiors, positions, triangles) {
        return false;
    }
    let ring_uvs = |ring: &[[f64; 3]], uv: &[[f64; 2]], uvs: &mut Vec<[f32; 2]>| {
        for k in 0..ring.len() {
            let c = uv.get(k).copied().unwrap_or([0.0, 0.0]);
            uvs.push([c[0] as f32, c[1] as f32]);
        }
    };
    ring_uvs(exterior, uv_exterior, uvs);
    // The same holes `triangulate_polygon` kept, in the same order.
    for (k, ring) in interiors.iter().enumerate() {
        if usable_ring(ring) {
            ring_uvs(ring, uv_interiors.get(k).map_or(&[][..], Vec::as_slice), uvs);
        }
    }
    true
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tri_area(p: &[[f64; 3]], t: [u32; 3]) -> f64 {
        let (a, b, c) = (p[t[0] as usize], p[t[1] as usize], p[t[2] as usize]);
        let ab = [b[0] - a[0], b[1] - a[1], b[2] - a[2]];
        let ac = [c[0] - a[0], c[1] - a[1], c[2] - a[2]];
        let x = [ab[1] * ac[2] - ab[2] * ac[1], ab[2] * ac[0] - ab[0] * ac[2], ab[0] * ac[1] - ab[1] * ac[0]];
        0.5 * (x[0] * x[0] + x[1] * x[1] + x[2] * x[2]).sqrt()
    }

    #[test]
    fn wall_with_window_keeps_area() {
        // A vertical 10 m × 6 m wall (plane y = 5) with a 2 m × 1 m hole: area 58 m².
        let ext = vec![[0.0, 5.0, 0.0], [10.0, 5.0, 0.0], [10.0, 5.0, 6.0], [0.0, 5.0, 6.0]];
        let hole = vec![[4.0, 5.0, 2.0], [4.0, 5.0, 3.0], [6.0, 5.0, 3.0], [6.0, 5.0, 2.0]];
        let (mut p, mut t) = (Vec::new(), Vec::new());
        assert!(triangulate_polygon(&ext, &[hole], &mut p, &mut t));
        let area: f64 = t.iter().map(|&tr| tri_area(&p, tr)).sum();
        assert!((area - 58.0).abs() < 1e-9, "{area}");
        assert!(p.iter().all(|q| (q[1] - 5.0).abs() < 1e-12), "vertices left the plane");
    }

    #[test]
    fn far_from_origin_courtyard() {
        // Roof at ECEF-like magnitudes: a 30 m square with a 10 m courtyard → 800 m².
        let o = [-3_957_000.0, 3_310_000.0, 3_700_000.0];
        let sq = |s: f64, c: f64| {
            vec![
                [o[0] + c, o[1] + c, o[2]],
                [o[0] + c + s, o[1] + c, o[2]],
                [o[0] + c + s, o[1] + c + s, o[2]],
                [o[0] + c, o[1] + c + s, o[2]],
            ]
        };
        let (mut p, mut t) = (Vec::new(), Vec::new());
        assert!(triangulate_polygon(&sq(30.0, 0.0), &[sq(10.0, 10.0)], &mut p, &mut t));
        let area: f64 = t.iter().map(|&tr| tri_area(&p, tr)).sum();
        assert!((area - 800.0).abs() < 1e-6, "{area}");
    }

    #[test]
    fn uvs_follow_vertices_and_skip_dropped_holes() {
        // A 10 m × 10 m roof (z = 3) with texture coordinates u = x / 10, v = y / 10, one usable hole
        // and one degenerate (collinear) hole: every output vertex keeps its own (u, v).
        let ext = vec![[0.0, 0.0, 3.0], [10.0, 0.0, 3.0], [10.0, 10.0, 3.0], [0.0, 10.0, 3.0]];
        let hole = vec![[2.0, 2.0, 3.0], [2.0, 4.0, 3.0], [4.0, 4.0, 3.0], [4.0, 2.0, 3.0]];
        let flat = vec![[6.0, 6.0, 3.0], [7.0, 6.0, 3.0], [8.0, 6.0, 3.0]];
        let uv_of = |r: &[[f64; 3]]| r.iter().map(|p| [p[0] / 10.0, p[1] / 10.0]).collect::<Vec<_>>();
        let (mut p, mut uv, mut t) = (Vec::new(), Vec::new(), Vec::new());
        let holes = [hole.clone(), flat.clone()];
        assert!(triangulate_polygon_uv(
            &ext,
            &holes,
            &uv_of(&ext),
            &[uv_of(&hole), uv_of(&flat)],
            &mut p,
            &mut uv,
            &mut t
        ));
        assert_eq!(p.len(), 8, "exterior + the usable hole");
        assert_eq!(uv.len(), p.len());
        for (q, c) in p.iter().zip(&uv) {
            assert_eq!(*c, [(q[0] / 10.0) as f32, (q[1] / 10.0) as f32], "{q:?}");
        }
    }

    #[test]
    fn degenerate_polygons_are_rejected() {
        let (mut p, mut t) = (Vec::new(), Vec::new());
        let two_points = vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 0.0]];
        let collinear = vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [2.0, 0.0, 0.0]];
        let nan = vec![[0.0, 0.0, 0.0], [1.0, f64::NAN, 0.0], [0.0, 1.0, 0.0]];
        for ring in [two_points, collinear, nan] {
            assert!(!triangulate_polygon(&ring, &[], &mut p, &mut t));
        }
        assert!(p.is_empty() && t.is_empty());
    }
}
