//! Which buildings touch in plan, and contrast classes that tell touching buildings apart.
//!
//! A segmenter cannot learn a boundary that nothing in the photo shows: two row houses with the same
//! roof membrane and facade colour look like one building, while their masks say two (issue 37). The
//! procedural look therefore gives touching buildings different *contrast classes* — bands of the
//! palette sorted by lightness — so every shared wall is a visible edge.
//!
//! - [`plan_neighbours`] rasterises every building's up- and down-facing triangles (roofs, floors,
//!   footprints) on a plan grid and calls two buildings neighbours when cells of both lie within
//!   `reach_m` of each other: buildings that share a wall, or stand closer than a pixel of a UAV view;
//! - [`contrast_classes`] colours that graph greedily in building-ID order (deterministic), each building
//!   taking the class its neighbours use least, the smallest such class on ties. Plan graphs of cities are
//!   close to planar, so with four classes touching buildings almost always differ.

use std::collections::{BTreeMap, BTreeSet};

use super::SceneMesh;

/// Grid cells above this count make [`plan_neighbours`] coarsen its cell (memory stays ≤ 4 bytes × this).
pub const MAX_PLAN_CELLS: usize = 64 << 20;

/// The plan grid: cell size and extent.
struct PlanGrid {
    cell_m: f64,
    x0_m: f64,
    y0_m: f64,
    nx: usize,
    ny: usize,
}

impl PlanGrid {
    fn covering(mesh: &SceneMesh, cell_m: f64) -> Option<PlanGrid> {
        let (lo, hi) = mesh.bounds_m()?;
        let (w_m, h_m) = (f64::from(hi[0] - lo[0]), f64::from(hi[1] - lo[1]));
        let mut cell_m = cell_m;
        while ((w_m / cell_m).ceil() + 1.0) * ((h_m / cell_m).ceil() + 1.0) > MAX_PLAN_CELLS as f64 {
            cell_m *= 2.0;
        }
        let nx = (w_m / cell_m).ceil() as usize + 1;
        let ny = (h_m / cell_m).ceil() as usize + 1;
        Some(PlanGrid { cell_m, x0_m: f64::from(lo[0]), y0_m: f64::from(lo[1]), nx, ny })
    }

    /// Cell index range [i0, i1) covering the span [a, b] metres on an axis starting at `origin_m`.
    fn span(&self, a: f64, b: f64, origin_m: f64, n: usize) -> (usize, usize) {
        let i0 = ((a - origin_m) / self.cell_m - 0.5).floor().max(0.0) as usize;
        let i1 = (((b - origin_m) / self.cell_m).ceil().max(0.0) as usize).min(n);
        (i0, i1)
    }
}

/// Marks the cells whose centres lie inside the plan projection of one triangle with `id`; a cell
/// another building already holds makes the two neighbours.
fn rasterise_triangle(
    g: &PlanGrid,
    tri: [[f64; 2]; 3],
    id: u32,
    cells: &mut [u32],
    pairs: &mut BTreeSet<(u32, u32)>,
) {
    let [a, b, c] = tri;
    let area2 = (b[0] - a[0]) * (c[1] - a[1]) - (c[0] - a[0]) * (b[1] - a[1]);
    if area2.abs() < 1e-9 {
        return; // a wall: no plan area
    }
    let s = area2.signum();
    let (i0, i1) = g.span(a[0].min(b[0]).min(c[0]), a[0].max(b[0]).max(c[0]), g.x0_m, g.nx);
    let (j0, j1) = g.span(a[1].min(b[1]).min(c[1]), a[1].max(b[1]).max(c[1]), g.y0_m, g.ny);
    let edge = |p: [f64; 2], q: [f64; 2], x: f64, y: f64| {
        s * ((q[0] - p[0]) * (y - p[1]) - (q[1] - p[1]) * (x - p[0]))
    };
    for j in j0..j1 {
        let y = g.y0_m + (j as f64 + 0.5) * g.cell_m;
        for i in i0..i1 {
            let x = g.x0_m + (i as f64 + 0.5) * g.cell_m;
            if edge(a, b, x, y) >= 0.0 && edge(b, c, x, y) >= 0.0 && edge(c, a, x, y) >= 0.0 {
                let cell = &mut cells[j * g.nx + i];
                if *cell != 0 && *cell != id {
                    pairs.insert((id.min(*cell), id.max(*cell)));
                }
                *cell = id;
            }
        }
    }
}

/// The buildings that touch in plan: for every building ID of `mesh`, the IDs of the buildings with
/// plan cells (of `cell_m`, coarsened above [`MAX_PLAN_CELLS`]) within `reach_m` of its own. Every
/// building of the mesh has an entry, possibly empty.
pub fn plan_neighbours(mesh: &SceneMesh, cell_m: f64, reach_m: f64) -> BTreeMap<u32, BTreeSet<u32>> {
    let mut out: BTreeMap<u32, BTreeSet<u32>> =
        mesh.building_ids.iter().map(|b| (b.get(), BTreeSet::new())).collect();
    let Some(g) = PlanGrid::covering(mesh, cell_m) else { return out };
    let mut cells = vec![0u32; g.nx * g.ny];
    let mut pairs = BTreeSet::new();
    for tri in mesh.indices.chunks_exact(3) {
        let id = mesh.building_ids[tri[0] as usize].get();
        let plan = [tri[0], tri[1], tri[2]].map(|v| {
            let p = mesh.positions_m[v as usize];
            [f64::from(p[0]), f64::from(p[1])]
        });
        rasterise_triangle(&g, plan, id, &mut cells, &mut pairs);
    }
    let reach = (reach_m / g.cell_m).ceil().max(1.0) as usize;
    for j in 0..g.ny {
        for i in 0..g.nx {
            let id = cells[j * g.nx + i];
            if id == 0 {
                continue;
            }
            // Half of the (2·reach + 1)² window: each unordered pair of cells is visited once.
            for dj in 0..=reach {
                let jj = j + dj;
                if jj >= g.ny {
                    break;
                }
                let (lo, hi) =
                    if dj == 0 { (i + 1, i + reach) } else { (i.saturating_sub(reach), i + reach) };
                for ii in lo..=hi.min(g.nx - 1) {
                    let other = cells[jj * g.nx + ii];
                    if other != 0 && other != id {
                        pairs.insert((id.min(other), id.max(other)));
                    }
                }
            }
        }
    }
    for (a, b) in pairs {
        out.entry(a).or_default().insert(b);
        out.entry(b).or_default().insert(a);
    }
    out
}

/// A contrast class in `0..classes` for every building of `neighbours`. Greedy in ID order: each building
/// takes the class its already-classed neighbours use least (the smallest on ties), which separates the
/// neighbours of near-planar graphs with four classes. Greedy favours the low classes, so the classes of
/// each connected group of touching buildings are then permuted by a hash of the group's smallest ID, and
/// a building that touches nothing takes a class by a hash of its own ID: every class is about equally
/// common, and the result depends on the buildings only.
pub fn contrast_classes(neighbours: &BTreeMap<u32, BTreeSet<u32>>, classes: u8) -> BTreeMap<u32, u8> {
    let classes = classes.max(1);
    let mut out: BTreeMap<u32, u8> = BTreeMap::new();
    for (&id, near) in neighbours {
        let mut used = vec![0usize; usize::from(classes)];
        for n in near {
            if let Some(&c) = out.get(n) {
                used[usize::from(c)] += 1;
            }
        }
        let best = (0..classes).min_by_key(|&c| (used[usize::from(c)], c)).unwrap_or(0);
        out.insert(id, best);
    }
    for group in groups(neighbours) {
        let perm = permutation(classes, splitmix64(u64::from(group[0])));
        for id in group {
            let c = out.get_mut(&id).expect("every building is classed");
            *c = perm[usize::from(*c)];
        }
    }
    out
}

/// Connected groups of touching buildings, each sorted, in order of their smallest ID.
fn groups(neighbours: &BTreeMap<u32, BTreeSet<u32>>) -> Vec<Vec<u32>> {
    let mut seen = BTreeSet::new();
    let mut out = Vec::new();
    for &start in neighbours.keys() {
        if !seen.insert(start) {
            continue;
        }
        let mut group = vec![start];
        let mut stack = vec![start];
        while let Some(id) = stack.pop() {
            for &n in neighbours.get(&id).into_iter().flatten() {
                if seen.insert(n) {
                    group.push(n);
                    stack.push(n);
                }
            }
        }
        group.sort_unstable();
        out.push(group);
    }
    out
}

/// A permutation of `0..n` drawn from `hash` (Fisher–Yates on its bits).
fn permutation(n: u8, mut hash: u64) -> Vec<u8> {
    let mut p: Vec<u8> = (0..n).collect();
    for i in (1..p.len()).rev() {
        let j = (hash % (i as u64 + 1)) as usize;
        hash = splitmix64(hash);
        p.swap(i, j);
    }
    p
}

/// SplitMix64's finaliser: a well-mixed 64-bit hash of `x`.
fn splitmix64(x: u64) -> u64 {
    let mut z = x.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// Touching pairs whose classes are equal, and all touching pairs (a measure of how well the classes
/// separate neighbours).
pub fn clashes(neighbours: &BTreeMap<u32, BTreeSet<u32>>, classes: &BTreeMap<u32, u8>) -> (usize, usize) {
    let mut same = 0;
    let mut all = 0;
    for (a, near) in neighbours {
        for b in near.range(a + 1..) {
            all += 1;
            if classes.get(a) == classes.get(b) {
                same += 1;
            }
        }
    }
    (same, all)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::BuildingId;

    /// A mesh of axis-aligned roof rectangles [x0, y0, x1, y1] (two triangles each) with IDs 1, 2, ….
    fn roofs(rects: &[[f32; 4]]) -> SceneMesh {
        let mut m = SceneMesh { positions_m: vec![], building_ids: vec![], indices: vec![] };
        for (k, r) in rects.iter().enumerate() {
            let id = BuildingId::new(k as u32 + 1).unwrap();
            let base = m.positions_m.len() as u32;
            for p in [[r[0], r[1]], [r[2], r[1]], [r[2], r[3]], [r[0], r[3]]] {
                m.positions_m.push([p[0], p[1], 10.0]);
                m.building_ids.push(id);
            }
            m.indices.extend([base, base + 1, base + 2, base, base + 2, base + 3]);
        }
        m
    }

    #[test]
    fn a_row_of_houses_sharing_walls_are_neighbours_in_a_chain_and_a_detached_house_is_alone() {
        // Three row houses sharing walls at x = 8 and x = 16, and one 5 m away.
        let m = roofs(&[
            [0.0, 0.0, 8.0, 10.0],
            [8.0, 0.0, 16.0, 10.0],
            [16.0, 0.0, 24.0, 10.0],
            [29.0, 0.0, 35.0, 10.0],
        ]);
        let n = plan_neighbours(&m, 0.5, 1.0);
        assert_eq!(n[&1], BTreeSet::from([2]));
        assert_eq!(n[&2], BTreeSet::from([1, 3]));
        assert_eq!(n[&3], BTreeSet::from([2]));
        assert!(n[&4].is_empty(), "{n:?}");
        // A gap of 0.6 m is within a reach of 1 m, not within 0.25 m.
        let m = roofs(&[[0.0, 0.0, 8.0, 10.0], [8.6, 0.0, 16.0, 10.0]]);
        assert_eq!(plan_neighbours(&m, 0.25, 1.0)[&1], BTreeSet::from([2]));
        assert!(plan_neighbours(&m, 0.25, 0.25)[&1].is_empty());
    }

    #[test]
    fn four_classes_separate_every_neighbour_of_a_block_grid() {
        // A 6 × 6 block of touching 10 m houses: 8-neighbourhood touching at corners (within reach).
        let mut rects = vec![];
        for j in 0..6 {
            for i in 0..6 {
                let (x, y) = (i as f32 * 10.0, j as f32 * 10.0);
                rects.push([x, y, x + 10.0, y + 10.0]);
            }
        }
        let n = plan_neighbours(&roofs(&rects), 0.5, 1.0);
        assert_eq!(n[&8].len(), 8, "an inner house touches 8: {:?}", n[&8]);
        let c = contrast_classes(&n, 4);
        let (same, all) = clashes(&n, &c);
        assert_eq!(all, 2 * 6 * 5 + 2 * 5 * 5, "edges and diagonals of a 6 × 6 grid");
        assert_eq!(same, 0, "classes {c:?}");
        // With one class everything clashes: the measure can fail.
        assert_eq!(clashes(&n, &contrast_classes(&n, 1)), (all, all));
        // Deterministic.
        assert_eq!(c, contrast_classes(&plan_neighbours(&roofs(&rects), 0.5, 1.0), 4));
    }

    #[test]
    fn classes_are_about_equally_common() {
        // 400 detached houses and 100 touching pairs: greedy alone would put 500 of 600 in class 0.
        let mut rects = vec![];
        for k in 0..400 {
            let x = (k % 20) as f32 * 20.0;
            let y = (k / 20) as f32 * 20.0;
            rects.push([x, y, x + 8.0, y + 8.0]);
        }
        for k in 0..100 {
            let y = 1000.0 + k as f32 * 20.0;
            rects.push([0.0, y, 8.0, y + 8.0]);
            rects.push([8.0, y, 16.0, y + 8.0]);
        }
        let n = plan_neighbours(&roofs(&rects), 0.5, 1.0);
        let c = contrast_classes(&n, 4);
        assert_eq!(clashes(&n, &c), (0, 100));
        let mut count = [0usize; 4];
        c.values().for_each(|&k| count[usize::from(k)] += 1);
        assert!(count.iter().all(|&k| (110..=190).contains(&k)), "{count:?} of 600");
    }
}
