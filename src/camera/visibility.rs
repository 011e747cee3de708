//! Cheap geometric checks on candidate poses: clearance (how tall are the buildings near the camera,
//! from the bounding boxes of `buildings.json`) and visibility (what share of a coarse grid of viewing
//! rays hits a building, and how many distinct buildings those rays hit first).
//!
//! Rays are traced through a uniform 2-D grid of cells over the boxes (Amanatides–Woo traversal), so a
//! ray only tests the boxes of the cells it crosses. With the scene's triangles
//! ([`BuildingIndex::with_mesh`], what the sampler uses), a ray that enters a box is tested against
//! that building's triangles (Möller–Trumbore), and the census estimates the share of building pixels
//! a render shows. Boxes alone over-approximate the buildings: an L-shaped block or a row of houses
//! along a curved street fills a fraction of its box, and views with a tenth of their pixels on
//! buildings passed a 15 % box share (issue 15).
//!
//! # References
//! J. Amanatides, A. Woo (1987), *A fast voxel traversal algorithm for ray tracing*.
//! T. Möller, B. Trumbore (1997), *Fast, minimum storage ray-triangle intersection*.

use super::{Intrinsics, Pose};
use crate::scene::{BuildingRecord, SceneMesh};

/// Building boxes in the area's ENU frame, bucketed in a uniform horizontal grid, with each building's
/// triangles when the index was built with the mesh.
#[derive(Debug, Clone)]
pub struct BuildingIndex {
    boxes: Vec<([f64; 3], [f64; 3])>,
    /// Per box, its building's triangles (ENU metres, in the mesh's precision); `None`, or a building
    /// without triangles: the box itself stands for the building.
    triangles: Option<Vec<Vec<[[f32; 3]; 3]>>>,
    /// South-west corner of the grid, ENU metres.
    grid_origin_m: [f64; 2],
    cell_m: f64,
    nx: usize,
    ny: usize,
    cells: Vec<Vec<u32>>,
    /// Lowest box bottom, ENU metres: rays stop there.
    floor_m: f64,
    /// Convex hull of the boxes' footprints (counter-clockwise, ENU metres): the ground the map
    /// models. Fewer than 3 vertices: no map ground.
    map_hull_m: Vec<[f64; 2]>,
}

/// Upper bound on grid cells per axis (keeps the index small for huge, sparse areas).
const MAX_CELLS_PER_AXIS: f64 = 256.0;
/// Smallest cell edge, metres.
const MIN_CELL_M: f64 = 10.0;

impl BuildingIndex {
    /// Indexes the bounding boxes of `buildings` (records with non-finite or inverted boxes are skipped).
    pub fn new(buildings: &[BuildingRecord]) -> Self {
        Self::from_boxes(valid_boxes(buildings).map(|b| (b.bbox_min_enu_m, b.bbox_max_enu_m)).collect())
    }

    /// Indexes the boxes of `buildings` as [`BuildingIndex::new`] does, and `mesh`'s triangles under
    /// their buildings' boxes: a ray hits a building where it hits one of its triangles (a building
    /// without triangles, as in a scene without its mesh, stays a box). Triangles of buildings without
    /// a (valid) record are left out.
    pub fn with_mesh(buildings: &[BuildingRecord], mesh: &SceneMesh) -> Self {
        let valid: Vec<&BuildingRecord> = valid_boxes(buildings).collect();
        let mut index =
            Self::from_boxes(valid.iter().map(|b| (b.bbox_min_enu_m, b.bbox_max_enu_m)).collect());
        let slot: std::collections::HashMap<u32, usize> =
            valid.iter().enumerate().map(|(i, b)| (b.id.get(), i)).collect();
        let mut triangles = vec![Vec::new(); valid.len()];
        let vertex = |i: u32| mesh.positions_m[i as usize];
        for t in mesh.indices.chunks_exact(3) {
            if let Some(&i) = slot.get(&mesh.building_ids[t[0] as usize].get()) {
                triangles[i].push([vertex(t[0]), vertex(t[1]), vertex(t[2])]);
            }
        }
        index.triangles = Some(triangles);
        index
    }

    /// Indexes explicit boxes ([min_e, min_n, min_u], [max_e, max_n, max_u]) in ENU metres.
    pub fn from_boxes(boxes: Vec<([f64; 3], [f64; 3])>) -> Self {
        let mut lo = [f64::INFINITY; 3];
        let mut hi = [f64::NEG_INFINITY; 3];
        for (a, b) in &boxes {
            for k in 0..3 {
                lo[k] = lo[k].min(a[k]);
                hi[k] = hi[k].max(b[k]);
            }
        }
        if boxes.is_empty() {
            return BuildingIndex {
                boxes,
                triangles: None,
                grid_origin_m: [0.0; 2],
                cell_m: 1.0,
                nx: 0,
                ny: 0,
                cells: Vec::new(),
                floor_m: 0.0,
                map_hull_m: Vec::new(),
            };
        }
        let extent = (hi[0] - lo[0]).max(hi[1] - lo[1]);
        let cell_m = (extent / MAX_CELLS_PER_AXIS).max(MIN_CELL_M);
        let nx = (((hi[0] - lo[0]) / cell_m).floor() as usize + 1).max(1);
        let ny = (((hi[1] - lo[1]) / cell_m).floor() as usize + 1).max(1);
        let mut cells = vec![Vec::new(); nx * ny];
        for (i, (a, b)) in boxes.iter().enumerate() {
            let ix0 = (((a[0] - lo[0]) / cell_m).floor() as usize).min(nx - 1);
            let ix1 = (((b[0] - lo[0]) / cell_m).floor() as usize).min(nx - 1);
            let iy0 = (((a[1] - lo[1]) / cell_m).floor() as usize).min(ny - 1);
            let iy1 = (((b[1] - lo[1]) / cell_m).floor() as usize).min(ny - 1);
            for iy in iy0..=iy1 {
                for ix in ix0..=ix1 {
                    cells[iy * nx + ix].push(i as u32);
                }
            }
        }
        let corners: Vec<[f64; 2]> = boxes
            .iter()
            .flat_map(|(a, b)| [[a[0], a[1]], [b[0], a[1]], [b[0], b[1]], [a[0], b[1]]])
            .collect();
        let map_hull_m = crate::util::convex_hull(&corners);
        BuildingIndex {
            boxes,
            map_hull_m,
            triangles: None,
            grid_origin_m: [lo[0], lo[1]],
            cell_m,
            nx,
            ny,
            cells,
            floor_m: lo[2],
        }
    }

    /// Number of indexed boxes.
    pub fn len(&self) -> usize {
        self.boxes.len()
    }

    /// Whether there are no boxes.
    pub fn is_empty(&self) -> bool {
        self.boxes.is_empty()
    }

    /// The ground the map models: the convex hull of the building boxes' footprints, counter-clockwise
    /// (ENU metres); fewer than 3 vertices when the boxes span no area.
    pub fn map_hull_m(&self) -> &[[f64; 2]] {
        &self.map_hull_m
    }

    /// Whether the ray `o + t·d` (t > 0) that hits no building ends on the map: it meets the ground
    /// plane at height `ground_m` inside [`BuildingIndex::map_hull_m`]. A ray at or above the horizon
    /// does not.
    fn lands_on_map(&self, o: [f64; 3], d: [f64; 3], ground_m: f64) -> bool {
        if self.map_hull_m.len() < 3 || d[2] >= 0.0 || o[2] <= ground_m {
            return false;
        }
        let t = (ground_m - o[2]) / d[2];
        crate::util::point_in_polygon([o[0] + t * d[0], o[1] + t * d[1]], &self.map_hull_m)
    }

    /// The highest box top of all, ENU metres (`None` without boxes).
    pub fn max_top_m(&self) -> Option<f64> {
        self.boxes.iter().map(|b| b.1[2]).reduce(f64::max)
    }

    /// The highest box top (ENU metres) among boxes whose horizontal extent comes within `radius_m`
    /// of `p_m`, or `None` when there is none.
    pub fn tallest_top_near_m(&self, p_m: [f64; 2], radius_m: f64) -> Option<f64> {
        if self.is_empty() {
            return None;
        }
        let r = radius_m.max(0.0);
        let cell = |v: f64, k: usize, n: usize| -> Option<usize> {
            let i = ((v - self.grid_origin_m[k]) / self.cell_m).floor();
            if i < 0.0 {
                Some(0)
            } else if i >= n as f64 {
                Some(n - 1)
            } else {
                Some(i as usize)
            }
        };
        // Entirely outside the grid (further than r from it): nothing near.
        let g_hi = [
            self.grid_origin_m[0] + self.nx as f64 * self.cell_m,
            self.grid_origin_m[1] + self.ny as f64 * self.cell_m,
        ];
        if p_m[0] + r < self.grid_origin_m[0]
            || p_m[1] + r < self.grid_origin_m[1]
            || p_m[0] - r > g_hi[0]
            || p_m[1] - r > g_hi[1]
        {
            return None;
        }
        let (ix0, ix1) = (cell(p_m[0] - r, 0, self.nx)?, cell(p_m[0] + r, 0, self.nx)?);
        let (iy0, iy1) = (cell(p_m[1] - r, 1, self.ny)?, cell(p_m[1] + r, 1, self.ny)?);
        let mut best: Option<f64> = None;
        for iy in iy0..=iy1 {
            for ix in ix0..=ix1 {
                for &b in &self.cells[iy * self.nx + ix] {
                    let (lo, hi) = &self.boxes[b as usize];
                    let dx = (lo[0] - p_m[0]).max(0.0).max(p_m[0] - hi[0]);
                    let dy = (lo[1] - p_m[1]).max(0.0).max(p_m[1] - hi[1]);
                    if dx * dx + dy * dy <= r * r {
                        best = Some(best.map_or(hi[2], |t| t.max(hi[2])));
                    }
                }
            }
        }
        best
    }

    /// Whether the ray `o + t·d` (t ≥ 0, ENU metres) hits any building (its triangles, or its box
    /// without them) before it falls below the lowest box bottom.
    pub fn ray_hits_building(&self, o: [f64; 3], d: [f64; 3]) -> bool {
        self.first_building_hit(o, d).is_some()
    }

    /// The building the ray `o + t·d` (t ≥ 0, ENU metres) hits first before it falls below the lowest
    /// box bottom: its index among the indexed boxes (in the order given to [`BuildingIndex::new`],
    /// records with invalid boxes skipped). With triangles, the first building whose triangles it
    /// hits; without, the first box it enters.
    pub fn first_building_hit(&self, o: [f64; 3], d: [f64; 3]) -> Option<u32> {
        if self.is_empty() {
            return None;
        }
        let t_max = if d[2] < -1e-12 { ((self.floor_m - o[2]) / d[2]).max(0.0) } else { f64::INFINITY };
        // Clip the ray's horizontal trace to the grid.
        let g_lo = self.grid_origin_m;
        let g_hi = [g_lo[0] + self.nx as f64 * self.cell_m, g_lo[1] + self.ny as f64 * self.cell_m];
        let (mut t0, mut t1) = (0.0f64, t_max);
        for k in 0..2 {
            if d[k].abs() < 1e-15 {
                if o[k] < g_lo[k] || o[k] > g_hi[k] {
                    return None;
                }
            } else {
                let (a, b) = ((g_lo[k] - o[k]) / d[k], (g_hi[k] - o[k]) / d[k]);
                t0 = t0.max(a.min(b));
                t1 = t1.min(a.max(b));
            }
        }
        if t0 > t1 {
            return None;
        }
        let start = [o[0] + d[0] * t0, o[1] + d[1] * t0];
        let n = [self.nx as i64, self.ny as i64];
        let mut idx = [0i64; 2];
        let mut step = [0i64; 2];
        let mut t_next = [f64::INFINITY; 2];
        let mut t_delta = [f64::INFINITY; 2];
        for k in 0..2 {
            idx[k] = (((start[k] - g_lo[k]) / self.cell_m).floor() as i64).clamp(0, n[k] - 1);
            if d[k] > 1e-15 {
                step[k] = 1;
                t_next[k] = (g_lo[k] + (idx[k] + 1) as f64 * self.cell_m - o[k]) / d[k];
                t_delta[k] = self.cell_m / d[k];
            } else if d[k] < -1e-15 {
                step[k] = -1;
                t_next[k] = (g_lo[k] + idx[k] as f64 * self.cell_m - o[k]) / d[k];
                t_delta[k] = -self.cell_m / d[k];
            }
        }
        // The nearest entry so far; boxes of cells not yet visited are entered after the current
        // cell's exit, so the walk stops once the nearest entry lies before that exit.
        let mut best: Option<(f64, u32)> = None;
        loop {
            for &b in &self.cells[(idx[1] * n[0] + idx[0]) as usize] {
                let (lo, hi) = &self.boxes[b as usize];
                // The box's entry bounds its triangles' hits from below: a box entered after the best
                // hit so far cannot do better.
                let entry = ray_box_entry(o, d, lo, hi, t_max)
                    .filter(|&t| best.is_none_or(|(bt, bi)| t < bt || (t == bt && b < bi)));
                let hit = match (&self.triangles, entry) {
                    (_, None) => None,
                    (None, Some(t)) => Some(t),
                    (Some(tris), Some(t)) => match tris[b as usize].as_slice() {
                        [] => Some(t),
                        tris => first_triangle_hit(o, d, tris, t_max),
                    },
                };
                if let Some(t) = hit {
                    if best.is_none_or(|(bt, bi)| t < bt || (t == bt && b < bi)) {
                        best = Some((t, b));
                    }
                }
            }
            let k = if t_next[0] <= t_next[1] { 0 } else { 1 };
            if let Some((t, b)) = best {
                if t <= t_next[k] {
                    return Some(b);
                }
            }
            if t_next[k] > t1 {
                return best.map(|(_, b)| b);
            }
            idx[k] += step[k];
            t_next[k] += t_delta[k];
            if idx[k] < 0 || idx[k] >= n[k] {
                return best.map(|(_, b)| b);
            }
        }
    }

    /// What a coarse grid of `rays[0]` × `rays[1]` viewing rays (through the centres of an evenly
    /// divided image) sees: the share that hits a building, the number of distinct buildings hit
    /// first by at least one ray, the cells of the frame's [`FRAME_GRID`] × [`FRAME_GRID`] grid in
    /// which at least [`COVERED_CELL_SHARE`] of the rays (and at least one) hit a building (estimates
    /// of the share of building pixels, of the buildings visible and of how far they spread across
    /// the frame; with boxes alone, upper bounds), and the share of rays that hit no building and
    /// end beyond the map: on the ground plane at `ground_m` outside [`BuildingIndex::map_hull_m`],
    /// or at or above the horizon.
    pub fn view_census(&self, k: &Intrinsics, pose: &Pose, rays: [u32; 2], ground_m: f64) -> ViewCensus {
        let (nx, ny) = (rays[0].max(1), rays[1].max(1));
        let (mut hits, mut off_map) = (0u32, 0u32);
        let mut seen: Vec<u32> = Vec::new();
        let g = FRAME_GRID;
        let (mut cell_rays, mut cell_hits) = ([0u32; FRAME_CELLS as usize], [0u32; FRAME_CELLS as usize]);
        for j in 0..ny {
            for i in 0..nx {
                // The ray's cell: the one holding its pixel position.
                let cell = ((j * g / ny) * g + i * g / nx) as usize;
                cell_rays[cell] += 1;
                let u = (i as f64 + 0.5) * k.width_px as f64 / nx as f64;
                let v = (j as f64 + 0.5) * k.height_px as f64 / ny as f64;
                let (o, d) = (pose.centre_m.to_array(), pixel_ray_enu(k, pose, u, v));
                if let Some(b) = self.first_building_hit(o, d) {
                    hits += 1;
                    cell_hits[cell] += 1;
                    seen.push(b);
                } else if !self.lands_on_map(o, d, ground_m) {
                    off_map += 1;
                }
            }
        }
        seen.sort_unstable();
        seen.dedup();
        let covered_cells = (0..FRAME_CELLS as usize)
            .filter(|&c| cell_is_covered(cell_hits[c] as u64, cell_rays[c] as u64))
            .count() as u32;
        ViewCensus {
            building_fraction: hits as f64 / (nx * ny) as f64,
            visible_buildings: seen.len() as u32,
            covered_cells,
            off_map_share: off_map as f64 / (nx * ny) as f64,
        }
    }
}

/// The frame is cut into `FRAME_GRID` × `FRAME_GRID` cells to measure how far a view's buildings
/// spread across it (the sampler's `min_covered_cells`, eval-loc's `covered_frame_cells`).
/// Silhouettes spread across the frame pin the camera's depth along its axis; crowded into one part
/// of it (a view past the map's edge), moving along the axis looks much like moving sideways and
/// turning.
pub const FRAME_GRID: u32 = 4;
/// Cells of the [`FRAME_GRID`] grid.
pub const FRAME_CELLS: u32 = FRAME_GRID * FRAME_GRID;
/// Share of a cell that must show buildings for the cell to count as covered (a sliver of a
/// building in a cell's corner does not).
pub const COVERED_CELL_SHARE: f64 = 0.05;

/// Whether a cell in which `building` of `total` samples (rays or pixels) show buildings counts as
/// covered: at least one, and at least [`COVERED_CELL_SHARE`] of them.
pub fn cell_is_covered(building: u64, total: u64) -> bool {
    building > 0 && building as f64 >= COVERED_CELL_SHARE * total as f64
}

/// The viewing direction (ENU, not normalised: its camera-frame z component is 1) through pixel
/// coordinates (u, v) (see [`Intrinsics`] for the pixel convention).
pub fn pixel_ray_enu(k: &Intrinsics, pose: &Pose, u: f64, v: f64) -> [f64; 3] {
    let d_cam = glam::DVec3::new((u - k.cx_px) / k.fx_px, (v - k.cy_px) / k.fy_px, 1.0);
    (pose.r_world_from_cam * d_cam).to_array()
}

/// What [`BuildingIndex::view_census`] counts for one view.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct ViewCensus {
    /// Share (0..1) of the rays that hit a building.
    pub building_fraction: f64,
    /// Distinct buildings hit first by at least one ray.
    pub visible_buildings: u32,
    /// Cells of the frame's [`FRAME_GRID`] × [`FRAME_GRID`] grid whose rays hit buildings (at least
    /// [`COVERED_CELL_SHARE`] of them).
    pub covered_cells: u32,
    /// Share (0..1) of the rays that hit no building and end beyond the map (the ground outside the
    /// hull of the building footprints, or the sky): what the frame shows of land the map does not
    /// model.
    pub off_map_share: f64,
}

/// The records whose boxes are finite and not inverted, in order.
fn valid_boxes(buildings: &[BuildingRecord]) -> impl Iterator<Item = &BuildingRecord> {
    buildings.iter().filter(|b| {
        let (lo, hi) = (b.bbox_min_enu_m, b.bbox_max_enu_m);
        (0..3).all(|k| lo[k].is_finite() && hi[k].is_finite() && lo[k] <= hi[k])
    })
}

/// The smallest t in [0, t_max] at which `o + t·d` crosses one of `triangles` (either side), if any
/// (Möller–Trumbore).
fn first_triangle_hit(o: [f64; 3], d: [f64; 3], triangles: &[[[f32; 3]; 3]], t_max: f64) -> Option<f64> {
    use glam::DVec3;
    let (o, d) = (DVec3::from(o), DVec3::from(d));
    let v = |p: &[f32; 3]| DVec3::new(p[0] as f64, p[1] as f64, p[2] as f64);
    let mut best: Option<f64> = None;
    for [a, b, c] in triangles {
        let a = v(a);
        let (e1, e2) = (v(b) - a, v(c) - a);
        let p = d.cross(e2);
        let det = e1.dot(p);
        if det.abs() < 1e-12 * e1.length() * e2.length() * d.length() {
            continue; // parallel to the triangle's plane (or a degenerate triangle)
        }
        let inv = 1.0 / det;
        let s = o - a;
        let u = s.dot(p) * inv;
        if !(0.0..=1.0).contains(&u) {
            continue;
        }
        let q = s.cross(e1);
        let v = d.dot(q) * inv;
        if v < 0.0 || u + v > 1.0 {
            continue;
        }
        let t = e2.dot(q) * inv;
        if t >= 0.0 && t <= t_max && best.is_none_or(|bt| t < bt) {
            best = Some(t);
        }
    }
    best
}

/// Slab test: the smallest t in [0, t_max] at which `o + t·d` is inside the box, if any.
fn ray_box_entry(o: [f64; 3], d: [f64; 3], lo: &[f64; 3], hi: &[f64; 3], t_max: f64) -> Option<f64> {
    let (mut t0, mut t1) = (0.0f64, t_max);
    for k in 0..3 {
        if d[k].abs() < 1e-15 {
            if o[k] < lo[k] || o[k] > hi[k] {
                return None;
            }
        } else {
            let (a, b) = ((lo[k] - o[k]) / d[k], (hi[k] - o[k]) / d[k]);
            t0 = t0.max(a.min(b));
            t1 = t1.min(a.max(b));
            if t0 > t1 {
                return None;
            }
        }
    }
    Some(t0)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::BuildingId;

    fn index() -> BuildingIndex {
        // Two towers: 20 × 20 m, 100 m tall at the origin; 10 × 10 m, 30 m tall 300 m east.
        BuildingIndex::from_boxes(vec![
            ([-10.0, -10.0, 0.0], [10.0, 10.0, 100.0]),
            ([295.0, -5.0, 0.0], [305.0, 5.0, 30.0]),
        ])
    }

    #[test]
    fn tallest_near() {
        let ix = index();
        assert_eq!(ix.tallest_top_near_m([0.0, 0.0], 1.0), Some(100.0));
        assert_eq!(ix.tallest_top_near_m([40.0, 0.0], 29.0), None);
        assert_eq!(ix.tallest_top_near_m([40.0, 0.0], 30.0), Some(100.0));
        assert_eq!(ix.tallest_top_near_m([300.0, 50.0], 50.0), Some(30.0));
        assert_eq!(ix.tallest_top_near_m([5000.0, 0.0], 50.0), None);
    }

    #[test]
    fn census_counts_the_buildings_hit_first() {
        let ix = index();
        let k = Intrinsics::from_hfov(640, 480, 90.0);
        // Straight down from 1000 m over the midpoint: a 90° view spans ±1000 m, both towers in it.
        let both = Pose::from_ypr_deg(0.0, 0.0, 0.0, [150.0, 0.0, 1000.0]);
        let c = ix.view_census(&k, &both, [256, 192], 0.0);
        assert_eq!(c.visible_buildings, 2, "{c:?}");
        assert!(c.building_fraction > 0.0 && c.building_fraction < 0.01, "{c:?}");
        // Two small towers: each covers a sliver of the cell it lies in, below the covered share.
        assert_eq!(c.covered_cells, 0, "{c:?}");
        // Low over the big tower, looking down: only it (the east tower is outside the view).
        let one = Pose::from_ypr_deg(0.0, 0.0, 0.0, [0.0, 0.0, 110.0]);
        let c = ix.view_census(&k, &one, [16, 12], 0.0);
        assert_eq!(c.visible_buildings, 1, "{c:?}");
        assert_eq!(c.building_fraction, 1.0);
        assert_eq!(c.covered_cells, FRAME_CELLS, "{c:?}");
        // A ray through both towers (west face of the big one first) counts only the first.
        assert_eq!(ix.first_building_hit([-500.0, 0.0, 20.0], [1.0, 0.0, 0.0]), Some(0));
        assert_eq!(ix.first_building_hit([1000.0, 0.0, 20.0], [-1.0, 0.0, 0.0]), Some(1));
    }

    #[test]
    fn census_counts_the_rays_that_land_beyond_the_map() {
        // Four 10 m houses in the corners of a 200 m square: the map's ground is that square.
        let ix = BuildingIndex::from_boxes(
            [[0.0, 0.0], [190.0, 0.0], [0.0, 190.0], [190.0, 190.0]]
                .iter()
                .map(|&[e, n]| ([e, n, 0.0], [e + 10.0, n + 10.0, 10.0]))
                .collect(),
        );
        assert_eq!(ix.map_hull_m(), &[[0.0, 0.0], [200.0, 0.0], [200.0, 200.0], [0.0, 200.0]]);
        // Straight down with a 90° view from 100 m over the centre: the frame is the square.
        let k = Intrinsics::from_hfov(400, 400, 90.0);
        let centre = Pose::from_ypr_deg(0.0, 0.0, 0.0, [100.0, 100.0, 100.0]);
        let c = ix.view_census(&k, &centre, [16, 16], 0.0);
        assert_eq!(c.off_map_share, 0.0, "{c:?}");
        // 100 m east: the frame's eastern half (8 of 16 ray columns) is ground beyond the map.
        let east = Pose::from_ypr_deg(0.0, 0.0, 0.0, [200.0, 100.0, 100.0]);
        let c = ix.view_census(&k, &east, [16, 16], 0.0);
        assert_eq!(c.off_map_share, 0.5, "{c:?}");
        // The ground 50 m higher: the frame shrinks to 100 m around the camera, and its eastern half
        // is still beyond the map.
        let c = ix.view_census(&k, &east, [16, 16], 50.0);
        assert_eq!(c.off_map_share, 0.5, "{c:?}");
        let corner = Pose::from_ypr_deg(0.0, 0.0, 0.0, [200.0, 200.0, 100.0]);
        let c = ix.view_census(&k, &corner, [16, 16], 0.0);
        assert_eq!(c.off_map_share, 0.75, "{c:?}");
        // Looking at the horizon: the rays at and above it leave the map too.
        let level = Pose::from_ypr_deg(0.0, 90.0, 0.0, [100.0, 100.0, 100.0]);
        let c = ix.view_census(&k, &level, [16, 16], 0.0);
        assert!(c.off_map_share >= 0.5, "{c:?}");
        // No buildings, no map: every ray is off it.
        let empty = BuildingIndex::from_boxes(Vec::new());
        assert_eq!(empty.view_census(&k, &centre, [4, 4], 0.0).off_map_share, 1.0);
    }

    /// An L-shaped building (id 1: a 20 × 5 m wing along x and a 5 × 20 m wing along y, 10 m tall,
    /// whose box is 20 × 20 m) and a 10 m cube (id 2) 10 m north-east of the L's empty corner.
    fn l_and_cube() -> (Vec<BuildingRecord>, SceneMesh) {
        let mut mesh = SceneMesh { positions_m: Vec::new(), building_ids: Vec::new(), indices: Vec::new() };
        let mut cuboid = |id: u32, lo: [f32; 3], hi: [f32; 3]| {
            let base = mesh.positions_m.len() as u32;
            for c in 0..8 {
                let pick = |k: usize| if c >> k & 1 == 1 { hi[k] } else { lo[k] };
                mesh.positions_m.push([pick(0), pick(1), pick(2)]);
                mesh.building_ids.push(BuildingId::new(id).unwrap());
            }
            // Six faces, two triangles each (corner c has bit k set when at hi[k]).
            for [a, b, c, d] in
                [[0, 1, 3, 2], [4, 5, 7, 6], [0, 1, 5, 4], [2, 3, 7, 6], [0, 2, 6, 4], [1, 3, 7, 5]]
            {
                mesh.indices.extend([a, b, c, a, c, d].map(|v: u32| base + v));
            }
        };
        cuboid(1, [0.0, 0.0, 0.0], [20.0, 5.0, 10.0]);
        cuboid(1, [0.0, 0.0, 0.0], [5.0, 20.0, 10.0]);
        cuboid(2, [30.0, 30.0, 0.0], [40.0, 40.0, 10.0]);
        let record = |id: u32, lo: [f64; 3], hi: [f64; 3]| BuildingRecord {
            id: BuildingId::new(id).unwrap(),
            source_id: format!("b{id}"),
            source_file: "test".into(),
            lod: "1".into(),
            height_m: 10.0,
            measured_height_m: None,
            footprint_area_m2: 0.0,
            centroid_lat_deg: 0.0,
            centroid_lon_deg: 0.0,
            bbox_min_enu_m: lo,
            bbox_max_enu_m: hi,
            triangles: 12,
        };
        (
            vec![record(1, [0.0; 3], [20.0, 20.0, 10.0]), record(2, [30.0, 30.0, 0.0], [40.0, 40.0, 10.0])],
            mesh,
        )
    }

    #[test]
    fn triangles_decide_what_a_ray_hits() {
        let (records, mesh) = l_and_cube();
        let (boxes, tris) = (BuildingIndex::new(&records), BuildingIndex::with_mesh(&records, &mesh));
        let down = [0.0, 0.0, -1.0];
        // Into a wing, both agree; into the L's empty corner only the box is hit.
        for ix in [&boxes, &tris] {
            assert_eq!(ix.first_building_hit([2.0, 15.0, 100.0], down), Some(0));
            assert_eq!(ix.first_building_hit([15.0, 2.0, 100.0], down), Some(0));
            assert_eq!(ix.first_building_hit([35.0, 35.0, 100.0], down), Some(1));
        }
        assert_eq!(boxes.first_building_hit([15.0, 15.0, 100.0], down), Some(0));
        assert_eq!(tris.first_building_hit([15.0, 15.0, 100.0], down), None);
        // A ray from the south-west at 2 m height through the empty corner, on to the cube: the box
        // index stops it at the L's box, the triangles let it through to the cube behind.
        let (o, d) = ([6.0, 6.0, 2.0], [1.0, 1.0, 0.0]);
        assert_eq!(boxes.first_building_hit(o, d), Some(0));
        assert_eq!(tris.first_building_hit(o, d), Some(1));
        // The same ray from outside the L (west of it) meets its y wing first.
        assert_eq!(tris.first_building_hit([-10.0, 6.0, 2.0], [1.0, 0.0, 0.0]), Some(0));

        // Straight down from 1 km over the L's box centre with a narrow view covering exactly the box's
        // top: the box census sees it full, the triangle census sees the L's share of the roof,
        // (20·5 + 5·15) / 400 = 43.75 % (plus the inner walls, 1 % of their 10 m height: 0.1 m).
        let k = Intrinsics::from_hfov(400, 400, 2.0 * (10.0f64 / 1000.0).atan().to_degrees());
        let pose = Pose::from_ypr_deg(0.0, 0.0, 0.0, [10.0, 10.0, 1010.0]);
        let rays = [80, 80];
        assert_eq!(boxes.view_census(&k, &pose, rays, 0.0).building_fraction, 1.0);
        let c = tris.view_census(&k, &pose, rays, 0.0);
        assert!((c.building_fraction - 0.4375).abs() < 0.015, "{c:?}");
        assert_eq!(c.visible_buildings, 1);
        // Cells are 5 m of the 20 m box: the L's wings, 5 m wide along two sides of the box, fill one
        // row and one column of cells (7 cells; its inner walls' 0.1 m are below the covered
        // share). The box fills all 16.
        assert_eq!(c.covered_cells, 7, "{c:?}");
        assert_eq!(boxes.view_census(&k, &pose, rays, 0.0).covered_cells, FRAME_CELLS);
    }

    #[test]
    fn rays_hit_only_what_they_cross() {
        let ix = index();
        // Straight down onto each tower, and between them.
        assert!(ix.ray_hits_building([0.0, 0.0, 500.0], [0.0, 0.0, -1.0]));
        assert!(ix.ray_hits_building([300.0, 0.0, 500.0], [0.0, 0.0, -1.0]));
        assert!(!ix.ray_hits_building([150.0, 0.0, 500.0], [0.0, 0.0, -1.0]));
        // From (150, 0, 200) at 45° down towards the east tower: reaches the ground (z = 0) at x = 350,
        // but is at z = 55 > 30 over x = 295 and at z = 45 over x = 305: it passes over the tower.
        assert!(!ix.ray_hits_building([150.0, 0.0, 200.0], [1.0, 0.0, -1.0]));
        // From (150, 0, 40) with slope −0.05: z = 40 − 0.05 · 145 = 32.75 at x = 295, over the tower.
        assert!(!ix.ray_hits_building([150.0, 0.0, 40.0], [1.0, 0.0, -0.05]));
        // From (150, 0, 35): z = 27.75 at x = 295, into the tower's west face.
        assert!(ix.ray_hits_building([150.0, 0.0, 35.0], [1.0, 0.0, -0.05]));
        // Horizontal ray above everything, and one pointing away from the grid.
        assert!(!ix.ray_hits_building([-500.0, 0.0, 150.0], [1.0, 0.0, 0.0]));
        assert!(ix.ray_hits_building([-500.0, 0.0, 50.0], [1.0, 0.0, 0.0]));
        assert!(!ix.ray_hits_building([-500.0, 0.0, 50.0], [-1.0, 0.0, 0.0]));
    }
}
