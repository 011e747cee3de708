//! Splitting an ID-less triangle mesh into buildings: the connected components of its face graph.
//!
//! Meshes without building IDs (OBJ files, glTF content without `_BATCHID` or `EXT_mesh_features`)
//! are turned into buildings the way the paper describes for untextured meshes: two triangles belong
//! to the same building when they share a vertex, transitively. Sharing means sharing a vertex
//! *index*; optionally, vertices closer than a weld tolerance are treated as shared too (many exporters
//! duplicate vertices per face or per material, which would otherwise cut one building into pieces).
//!
//! Welding only changes connectivity: the output keeps every original vertex, positions untouched.

use std::collections::HashMap;

use super::TriMesh;

/// Splits `mesh` into the connected components of its face graph.
///
/// Two triangles are connected when they share a vertex index, or — with `weld_tolerance_m =
/// Some(t)` — when they use vertices at most `t` apart (single linkage: a chain of close vertices
/// links its ends even when they are further apart than `t`). `Some(0.0)` welds exactly coincident
/// positions only; a negative or non-finite tolerance is treated as `0`. Vertices that no triangle
/// uses take no part in welding and are dropped.
///
/// The components come in a deterministic order: by the smallest index of a triangle they contain.
/// Inside a component, triangles keep their original order and vertices are renumbered in order of
/// first use.
///
/// Triangles with an index past the end of `mesh.positions` are ignored (readers validate indices
/// before calling this).
///
/// # Units
/// `weld_tolerance_m` is in the mesh's coordinate units (metres for projected CRSs and ECEF).
pub fn split_connected(mesh: &TriMesh, weld_tolerance_m: Option<f64>) -> Vec<TriMesh> {
    let n_vertices = mesh.positions.len();
    let valid = |t: &[u32; 3]| t.iter().all(|&i| (i as usize) < n_vertices);

    let mut sets = DisjointSets::new(n_vertices);
    let mut used = vec![false; n_vertices];
    for t in mesh.triangles.iter().filter(|t| valid(t)) {
        for &i in t {
            used[i as usize] = true;
        }
        sets.union(t[0] as usize, t[1] as usize);
        sets.union(t[0] as usize, t[2] as usize);
    }
    if let Some(tol) = weld_tolerance_m {
        weld(&mesh.positions, &used, tol, &mut sets);
    }

    // Component numbers in order of the first triangle that reaches them.
    let mut component_of_root: HashMap<usize, usize> = HashMap::new();
    let mut out: Vec<TriMesh> = Vec::new();
    // Per component: original vertex index → new index (filled lazily).
    let mut remaps: Vec<HashMap<u32, u32>> = Vec::new();
    for t in mesh.triangles.iter().filter(|t| valid(t)) {
        let root = sets.find(t[0] as usize);
        let k = *component_of_root.entry(root).or_insert_with(|| {
            out.push(TriMesh::default());
            remaps.push(HashMap::new());
            out.len() - 1
        });
        let (part, remap) = (&mut out[k], &mut remaps[k]);
        let mut tri = [0u32; 3];
        for (slot, &i) in tri.iter_mut().zip(t) {
            *slot = *remap.entry(i).or_insert_with(|| {
                part.positions.push(mesh.positions[i as usize]);
                (part.positions.len() - 1) as u32
            });
        }
        part.triangles.push(tri);
    }
    out
}

/// Unions every pair of used vertices at most `tol` apart, using a uniform grid of cell size `tol`
/// (only the 27 cells around a vertex can hold partners). `tol <= 0` (or NaN/inf) compares exact
/// coordinates instead.
fn weld(positions: &[[f64; 3]], used: &[bool], tol: f64, sets: &mut DisjointSets) {
    let finite = |p: &[f64; 3]| p.iter().all(|c| c.is_finite());
    if !(tol.is_finite() && tol > 0.0) {
        // Exact coincidence; -0.0 and 0.0 are the same point.
        let key = |p: &[f64; 3]| p.map(|c| if c == 0.0 { 0u64 } else { c.to_bits() });
        let mut first_at: HashMap<[u64; 3], usize> = HashMap::new();
        for (i, p) in positions.iter().enumerate() {
            if used[i] && finite(p) {
                let j = *first_at.entry(key(p)).or_insert(i);
                sets.union(i, j);
            }
        }
        return;
    }
    let tol2 = tol * tol;
    // `as i64` saturates for huge quotients; such vertices then share edge cells, which only costs
    // extra distance checks, never a wrong union (the distance test below decides).
    let cell = |p: &[f64; 3]| p.map(|c| (c / tol).floor() as i64);
    let mut grid: HashMap<[i64; 3], Vec<usize>> = HashMap::new();
    for (i, p) in positions.iter().enumerate() {
        if !(used[i] && finite(p)) {
            continue;
        }
        let c = cell(p);
        for dx in -1..=1i64 {
            for dy in -1..=1i64 {
                for dz in -1..=1i64 {
                    let nb = [c[0].saturating_add(dx), c[1].saturating_add(dy), c[2].saturating_add(dz)];
                    if let Some(list) = grid.get(&nb) {
                        for &j in list {
                            let q = &positions[j];
                            let d2 = (p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2) + (p[2] - q[2]).powi(2);
                            if d2 <= tol2 {
                                sets.union(i, j);
                            }
                        }
                    }
                }
            }
        }
        grid.entry(c).or_default().push(i);
    }
}

/// Union–find with path halving and union by size.
struct DisjointSets {
    parent: Vec<usize>,
    size: Vec<usize>,
}

impl DisjointSets {
    fn new(n: usize) -> Self {
        DisjointSets { parent: (0..n).collect(), size: vec![1; n] }
    }

    fn find(&mut self, mut x: usize) -> usize {
        while self.parent[x] != x {
            self.parent[x] = self.parent[self.parent[x]];
            x = self.parent[x];
        }
        x
    }

    fn union(&mut self, a: usize, b: usize) {
        let (mut ra, mut rb) = (self.find(a), self.find(b));
        if ra == rb {
            return;
        }
        if self.size[ra] < self.size[rb] {
            std::mem::swap(&mut ra, &mut rb);
        }
        self.parent[rb] = ra;
        self.size[ra] += self.size[rb];
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Two triangles sharing an edge, plus a separate triangle whose corner coincides with the
    /// first pair's vertex 2 (a duplicated vertex, not a shared index).
    fn sample() -> TriMesh {
        TriMesh {
            positions: vec![
                [0.0, 0.0, 0.0],
                [1.0, 0.0, 0.0],
                [1.0, 1.0, 0.0],
                [0.0, 1.0, 0.0],
                [1.0, 1.0, 0.0], // == vertex 2
                [2.0, 1.0, 0.0],
                [2.0, 2.0, 0.0],
            ],
            triangles: vec![[4, 5, 6], [0, 1, 2], [0, 2, 3]],
        }
    }

    mod connectivity {
        use super::*;

        #[test]
        fn shared_indices_only() {
            let parts = split_connected(&sample(), None);
            assert_eq!(parts.len(), 2);
            // Ordered by smallest triangle index: triangle 0 is [4, 5, 6].
            assert_eq!(parts[0].triangles, vec![[0, 1, 2]]);
            assert_eq!(parts[0].positions, vec![[1.0, 1.0, 0.0], [2.0, 1.0, 0.0], [2.0, 2.0, 0.0]]);
            assert_eq!(parts[1].triangles, vec![[0, 1, 2], [0, 2, 3]]);
            assert_eq!(parts[1].positions.len(), 4);
        }

        #[test]
        fn exact_weld_joins_duplicates() {
            let parts = split_connected(&sample(), Some(0.0));
            assert_eq!(parts.len(), 1);
            // Welding keeps every used vertex (7) and all triangles, in original order.
            assert_eq!(parts[0].positions.len(), 7);
            assert_eq!(parts[0].triangles.len(), 3);
            assert_eq!(parts[0].triangles[0], [0, 1, 2]);
        }

        #[test]
        fn tolerance_is_a_distance() {
            let mut m = sample();
            m.positions[4] = [1.0, 1.0, 0.05]; // 5 cm from vertex 2
            assert_eq!(split_connected(&m, Some(0.049)).len(), 2);
            assert_eq!(split_connected(&m, Some(0.051)).len(), 1);
            assert_eq!(split_connected(&m, Some(0.0)).len(), 2);
        }

        #[test]
        fn weld_across_cell_boundary() {
            // 0.999 and 1.001 fall in different cells of size 0.01 (99 and 100).
            let m = TriMesh {
                positions: vec![
                    [0.999, 0.0, 0.0],
                    [0.0, 0.0, 0.0],
                    [0.0, 1.0, 0.0],
                    [1.001, 0.0, 0.0],
                    [2.0, 0.0, 0.0],
                    [2.0, 1.0, 0.0],
                ],
                triangles: vec![[0, 1, 2], [3, 4, 5]],
            };
            assert_eq!(split_connected(&m, Some(0.01)).len(), 1);
            assert_eq!(split_connected(&m, Some(0.001)).len(), 2);
        }

        #[test]
        fn unused_vertices_do_not_bridge() {
            let m = TriMesh {
                positions: vec![
                    [0.0, 0.0, 0.0],
                    [-1.0, 0.0, 0.0],
                    [-1.0, -1.0, 0.0],
                    [0.6, 0.0, 0.0], // unused, within 0.7 of both vertex 0 and vertex 4
                    [1.2, 0.0, 0.0],
                    [2.0, 0.0, 0.0],
                    [2.0, 1.0, 0.0],
                ],
                triangles: vec![[0, 1, 2], [4, 5, 6]],
            };
            assert_eq!(split_connected(&m, Some(0.7)).len(), 2);
        }
    }

    mod robustness {
        use super::*;

        #[test]
        fn out_of_range_triangles_are_ignored() {
            let mut m = sample();
            m.triangles.push([0, 1, 99]);
            assert_eq!(split_connected(&m, None).len(), 2);
        }

        #[test]
        fn empty_mesh() {
            assert!(split_connected(&TriMesh::default(), Some(0.1)).is_empty());
        }

        #[test]
        fn nan_tolerance_means_exact() {
            assert_eq!(split_connected(&sample(), Some(f64::NAN)).len(), 1);
            assert_eq!(split_connected(&sample(), Some(-1.0)).len(), 1);
        }

        #[test]
        fn deterministic() {
            let a = split_connected(&sample(), Some(0.0));
            let b = split_connected(&sample(), Some(0.0));
            assert_eq!(a, b);
        }
    }
}
