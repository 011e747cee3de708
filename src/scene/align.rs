//! Estimating the rigid residual between a prepared LoD model and a reference surface (a
//! photogrammetry tileset): `insgen align`.
//!
//! Both models are triangle meshes in the area's ENU frame ([`TriMesh`], f64 metres): the LoD model
//! as `prepare` wrote it, the tileset read by [`crate::lod::tiles3d::read`] (every content of the
//! finest level, ECEF → ENU). The estimate is a [`Correction`] (east, north, up shift and yaw about
//! the centre of the LoD footprint) in three steps:
//!
//! 1. **Height maps.** Orthographic nadir height maps of both models ([`HeightMap`]: the highest
//!    surface over each cell centre, NaN where nothing is) on a common grid.
//! 2. **Coarse search.** LoD roof cells (points `(e, n, h)`) are moved by every candidate yaw and
//!    horizontal shift on a grid and looked up in the tileset's height map; a candidate's score is the
//!    number of points whose height difference falls within ±`tol` of the most common difference
//!    (a histogram mode, which also gives the vertical shift). Trees, cranes, terrain and missing
//!    buildings only lower every candidate's score alike. Two passes: 2 m cells, 1 m steps, 0.2°
//!    steps over the whole window, then 0.5 m cells, 0.25 m and 0.05° steps around the best.
//! 3. **Refinement.** Point-to-plane ICP, solved by Gauss–Newton: points sampled uniformly on the LoD
//!    surface (roofs and walls; floors, which photogrammetry never sees, left out) are matched to the
//!    closest point of the tileset mesh; the residual is the distance along the tileset triangle's
//!    normal, weighted by Tukey's biweight (scale 4.685 · 1.4826 · MAD) and gated by distance and by
//!    the angle between the two normals (≤ 45°), so clutter and surfaces the other model lacks drop
//!    out. Walls fix the horizontal shift and the yaw, roofs the vertical shift; the result is not
//!    limited by the cell size.
//!
//! The one-sigma uncertainty is `σ² (Jᵀ W J)⁻¹` of the last step, with `σ²` the weighted residual
//! variance; neighbouring samples' residuals are correlated (a jittered vertex moves a patch), so it
//! is a lower bound. Agreement before and after ([`Agreement`]) is measured on 0.5 m height maps:
//! the median |Δh| over LoD roof cells that the tileset covers, and the IoU of the LoD's building cells
//! with the tileset's cells more than [`ABOVE_GROUND_M`] above the local ground (the lowest tileset
//! height within ±[`GROUND_WINDOW_M`]).
//!
//! # References
//! Chen & Medioni 1992, "Object modelling by registration of multiple range images" (point-to-plane);
//! Holland & Welsch 1977 (biweight IRLS).

use glam::{DMat4, DVec3};
use rayon::prelude::*;

use super::correction::{Agreement, Correction, CorrectionSigma};
use crate::lod::TriMesh;

/// Height above the local ground from which a tileset cell counts as a structure, metres.
pub const ABOVE_GROUND_M: f64 = 2.5;
/// Half-width of the window in which the local ground is the lowest tileset height, metres.
pub const GROUND_WINDOW_M: f64 = 40.0;

/// Options of [`estimate`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AlignOptions {
    /// Largest horizontal shift searched, metres (each axis).
    pub search_m: f64,
    /// Largest yaw searched, degrees.
    pub search_deg: f64,
    /// Cell of the agreement height maps, metres.
    pub cell_m: f64,
    /// Most LoD surface samples the refinement uses.
    pub max_samples: usize,
}

impl Default for AlignOptions {
    fn default() -> Self {
        AlignOptions { search_m: 6.0, search_deg: 1.5, cell_m: 0.5, max_samples: 60_000 }
    }
}

/// Errors of the estimate.
#[derive(Debug, thiserror::Error)]
pub enum AlignError {
    /// The model (named) has no surface over the area.
    #[error("the {what} model has no surface over the area: the models do not overlap")]
    Empty {
        /// "LoD" or "reference".
        what: &'static str,
    },
    /// Too few LoD roof cells find the tileset at a common height in the coarse search.
    #[error(
        "the models do not overlap: only {:.1} % of the LoD roof cells find the tileset at a common height \
         within ±{search_m} m / ±{search_deg}°",
        100.0 * inlier_fraction
    )]
    NoCommonHeight {
        /// The fraction of roof cells that do.
        inlier_fraction: f64,
        /// The search window, metres.
        search_m: f64,
        /// The search window, degrees.
        search_deg: f64,
    },
    /// Too few LoD surface samples lie near the tileset during the refinement.
    #[error(
        "the models do not overlap: only {samples} LoD surface samples lie within {gate_m} m of the tileset"
    )]
    FewSamples {
        /// Samples within the gate.
        samples: usize,
        /// The gate, metres.
        gate_m: f64,
    },
    /// The refinement is degenerate.
    #[error(
        "the refinement is degenerate (normal matrix determinant {determinant:e}): the surfaces do not fix all \
         four parameters"
    )]
    Degenerate {
        /// The determinant of the normal equations.
        determinant: f64,
    },
    /// The search window is out of range.
    #[error(
        "invalid option: search window {search_m} m / {search_deg}° (expected 0 < m ≤ 100, 0 ≤ deg ≤ 20)"
    )]
    SearchWindow {
        /// The window, metres.
        search_m: f64,
        /// The window, degrees.
        search_deg: f64,
    },
}

/// The estimate and how it was reached.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct Estimate {
    /// The estimated correction.
    pub correction: Correction,
    /// Its one-sigma uncertainty.
    pub sigma: CorrectionSigma,
    /// Result of the coarse search (before the refinement).
    pub coarse: Correction,
    /// Fraction of the coarse points within the tolerance at the best candidate.
    pub coarse_inlier_fraction: f64,
    /// Refinement iterations, LoD samples, and correspondences kept in the last step.
    pub iterations: u32,
    /// LoD samples of the last step.
    pub samples: u64,
    /// Correspondences kept in the last step.
    pub correspondences: u64,
    /// Robust scale of the point-to-plane residuals in the last step, metres.
    pub residual_sigma_m: f64,
}

// ------------------------------------------------------------------------------------------ meshes

/// The scene mesh as an f64 triangle mesh (ENU metres).
pub fn scene_surface(mesh: &super::SceneMesh) -> TriMesh {
    TriMesh {
        positions: mesh.positions_m.iter().map(|p| p.map(f64::from)).collect(),
        triangles: mesh.indices.chunks_exact(3).map(|t| [t[0], t[1], t[2]]).collect(),
    }
}

/// Reads a tileset's surface (every content of the finest level) into the ENU frame `enu`, keeping
/// the triangles that reach into `[min, max]` (ENU metres, horizontal).
///
/// # Errors
/// The reader's [`crate::lod::LodError`], naming the file and what is wrong.
pub fn tileset_surface(
    path: &std::path::Path,
    enu: &crate::geo::EnuFrame,
    min_m: [f64; 2],
    max_m: [f64; 2],
) -> Result<TriMesh, crate::lod::LodError> {
    let model = crate::lod::tiles3d::read(path, &crate::lod::ReadOptions::default())?;
    let m = enu.enu_from_ecef();
    let mut out = TriMesh::default();
    for b in model.buildings {
        let crate::lod::Geometry::Mesh(mesh) = b.geometry else { continue };
        let p: Vec<[f64; 3]> =
            mesh.positions.iter().map(|q| m.transform_point3(DVec3::from_array(*q)).to_array()).collect();
        for t in &mesh.triangles {
            let v = t.map(|i| p[i as usize]);
            let lo = [0, 1].map(|k| v[0][k].min(v[1][k]).min(v[2][k]));
            let hi = [0, 1].map(|k| v[0][k].max(v[1][k]).max(v[2][k]));
            if hi[0] < min_m[0] || lo[0] > max_m[0] || hi[1] < min_m[1] || lo[1] > max_m[1] {
                continue;
            }
            let base = out.positions.len() as u32;
            out.positions.extend_from_slice(&v);
            out.triangles.push([base, base + 1, base + 2]);
        }
    }
    Ok(out)
}

/// A tileset's whole surface (every content of the finest level, see [`tileset_surface`]) in the ENU
/// frame `enu` as a renderable [`super::SceneMesh`] whose triangles all carry `id` (render-masks
/// `--tileset` renders its depth at every frame).
///
/// # Errors
/// The reader's [`crate::lod::LodError`], naming the file and what is wrong.
pub fn tileset_scene_mesh(
    path: &std::path::Path,
    enu: &crate::geo::EnuFrame,
    id: super::BuildingId,
) -> Result<super::SceneMesh, crate::lod::LodError> {
    let all = tileset_surface(path, enu, [f64::NEG_INFINITY; 2], [f64::INFINITY; 2])?;
    Ok(super::SceneMesh {
        positions_m: all.positions.iter().map(|p| p.map(|v| v as f32)).collect(),
        building_ids: vec![id; all.positions.len()],
        indices: all.triangles.iter().flatten().copied().collect(),
    })
}

/// Horizontal bounds of a mesh, metres (`None` when empty).
pub fn bounds_2d(mesh: &TriMesh) -> Option<([f64; 2], [f64; 2])> {
    let mut lo = [f64::INFINITY; 2];
    let mut hi = [f64::NEG_INFINITY; 2];
    for t in &mesh.triangles {
        for &i in t {
            let p = mesh.positions[i as usize];
            for k in 0..2 {
                lo[k] = lo[k].min(p[k]);
                hi[k] = hi[k].max(p[k]);
            }
        }
    }
    lo[0].is_finite().then_some((lo, hi))
}

/// The pivot `align` rotates about: the centre of the LoD model's horizontal bounds, metres.
pub fn pivot_of(lod: &TriMesh) -> [f64; 2] {
    bounds_2d(lod).map(|(lo, hi)| [0.5 * (lo[0] + hi[0]), 0.5 * (lo[1] + hi[1])]).unwrap_or([0.0; 2])
}

// ------------------------------------------------------------------------------------------ height maps

/// An orthographic nadir height map: the highest surface over each cell centre, ENU metres; NaN
/// where no triangle covers the centre. Cell `(i, j)` has its centre at
/// `(min_e + (i + ½)·cell, min_n + (j + ½)·cell)`; rows go north.
#[derive(Debug, Clone, PartialEq)]
pub struct HeightMap {
    /// East and north of the map's south-west corner, metres.
    pub min_m: [f64; 2],
    /// Cell size, metres.
    pub cell_m: f64,
    /// Cells along east.
    pub nx: usize,
    /// Cells along north.
    pub ny: usize,
    /// Height of each cell, ENU metres, row-major from the south row (NaN where nothing covers it).
    pub h_m: Vec<f32>,
}

impl HeightMap {
    /// An empty map covering `[min, max]` with square cells.
    pub fn new(min_m: [f64; 2], max_m: [f64; 2], cell_m: f64) -> HeightMap {
        let nx = (((max_m[0] - min_m[0]) / cell_m).ceil() as usize).max(1);
        let ny = (((max_m[1] - min_m[1]) / cell_m).ceil() as usize).max(1);
        HeightMap { min_m, cell_m, nx, ny, h_m: vec![f32::NAN; nx * ny] }
    }

    /// Draws `mesh` moved by `c` (the top surface wins). Vertical triangles cover no cell centre.
    pub fn rasterise(&mut self, mesh: &TriMesh, c: &Correction) {
        let moved: Vec<[f64; 3]> = if c.is_identity() {
            mesh.positions.clone()
        } else {
            mesh.positions.iter().map(|p| c.apply(DVec3::from_array(*p)).to_array()).collect()
        };
        let cell = self.cell_m;
        for t in &mesh.triangles {
            let [a, b, d] = t.map(|i| moved[i as usize]);
            let area2 = (b[0] - a[0]) * (d[1] - a[1]) - (d[0] - a[0]) * (b[1] - a[1]);
            if area2.abs() < 1e-9 {
                continue;
            }
            let range = |k: usize, n: usize| {
                let lo = ((a[k].min(b[k]).min(d[k]) - self.min_m[k]) / cell - 0.5).ceil().max(0.0) as usize;
                let hi = ((a[k].max(b[k]).max(d[k]) - self.min_m[k]) / cell - 0.5).floor();
                if hi < 0.0 {
                    return 0..0;
                }
                lo..(hi as usize + 1).min(n)
            };
            let (rx, ry) = (range(0, self.nx), range(1, self.ny));
            let inv = 1.0 / area2;
            for j in ry {
                let y = self.min_m[1] + (j as f64 + 0.5) * cell;
                for i in rx.clone() {
                    let x = self.min_m[0] + (i as f64 + 0.5) * cell;
                    let w0 = ((b[0] - x) * (d[1] - y) - (d[0] - x) * (b[1] - y)) * inv;
                    let w1 = ((d[0] - x) * (a[1] - y) - (a[0] - x) * (d[1] - y)) * inv;
                    let w2 = 1.0 - w0 - w1;
                    if w0 < 0.0 || w1 < 0.0 || w2 < 0.0 {
                        continue;
                    }
                    let z = (w0 * a[2] + w1 * b[2] + w2 * d[2]) as f32;
                    let h = &mut self.h_m[j * self.nx + i];
                    // NaN (empty) or lower: the new surface is on top.
                    if h.is_nan() || *h < z {
                        *h = z;
                    }
                }
            }
        }
    }

    /// The height of the cell holding `(e, n)` (NaN outside or empty).
    #[inline]
    pub fn at(&self, e: f64, n: f64) -> f32 {
        let i = ((e - self.min_m[0]) / self.cell_m).floor();
        let j = ((n - self.min_m[1]) / self.cell_m).floor();
        if i < 0.0 || j < 0.0 || i >= self.nx as f64 || j >= self.ny as f64 {
            return f32::NAN;
        }
        self.h_m[j as usize * self.nx + i as usize]
    }

    /// Centre of cell `(i, j)`, metres.
    pub fn centre(&self, i: usize, j: usize) -> [f64; 2] {
        [self.min_m[0] + (i as f64 + 0.5) * self.cell_m, self.min_m[1] + (j as f64 + 0.5) * self.cell_m]
    }

    /// The local ground under each cell: the lowest height within ±`window_m` (blocks of ~`window_m`/4
    /// whose minima are spread over a 9 × 9 block neighbourhood).
    pub fn ground(&self, window_m: f64) -> Vec<f32> {
        let block = ((window_m / 4.0 / self.cell_m).round() as usize).max(1);
        let (bx, by) = (self.nx.div_ceil(block), self.ny.div_ceil(block));
        let mut mins = vec![f32::INFINITY; bx * by];
        for j in 0..self.ny {
            for i in 0..self.nx {
                let h = self.h_m[j * self.nx + i];
                if h.is_finite() {
                    let m = &mut mins[(j / block) * bx + i / block];
                    *m = m.min(h);
                }
            }
        }
        let mut spread = vec![f32::INFINITY; bx * by];
        for j in 0..by {
            for i in 0..bx {
                let mut m = f32::INFINITY;
                for jj in j.saturating_sub(4)..(j + 5).min(by) {
                    for ii in i.saturating_sub(4)..(i + 5).min(bx) {
                        m = m.min(mins[jj * bx + ii]);
                    }
                }
                spread[j * bx + i] = m;
            }
        }
        (0..self.nx * self.ny).map(|k| spread[(k / self.nx / block) * bx + (k % self.nx) / block]).collect()
    }
}

/// Agreement of the LoD model moved by `c` with the tileset over `[min, max]` (see the module doc).
pub fn agreement(lod: &TriMesh, tiles: &HeightMap, tiles_ground: &[f32], c: &Correction) -> Agreement {
    let mut l = HeightMap { h_m: vec![f32::NAN; tiles.h_m.len()], ..*tiles };
    l.rasterise(lod, c);
    let mut dh = Vec::new();
    let (mut inter, mut union) = (0u64, 0u64);
    for ((&hl, &ht), &g) in l.h_m.iter().zip(&tiles.h_m).zip(tiles_ground) {
        let building = hl.is_finite();
        let above = ht.is_finite() && (ht - g) as f64 > ABOVE_GROUND_M;
        if building && ht.is_finite() {
            dh.push((ht - hl).abs() as f64);
        }
        inter += u64::from(building && above);
        union += u64::from(building || above);
    }
    Agreement {
        median_abs_dh_roofs_m: crate::util::median(&dh).unwrap_or(f64::NAN),
        footprint_iou: if union > 0 { inter as f64 / union as f64 } else { 0.0 },
        roof_cells: dh.len() as u64,
    }
}

// ------------------------------------------------------------------------------------------ coarse search

/// Points `(e, n, h)` of the map's covered cells, at most `max` of them (every k-th).
fn roof_points(map: &HeightMap, max: usize) -> Vec<[f64; 3]> {
    let mut all = Vec::new();
    for j in 0..map.ny {
        for i in 0..map.nx {
            let h = map.h_m[j * map.nx + i];
            if h.is_finite() {
                let c = map.centre(i, j);
                all.push([c[0], c[1], h as f64]);
            }
        }
    }
    let step = all.len().div_ceil(max.max(1)).max(1);
    all.into_iter().step_by(step).collect()
}

/// Score of one candidate: (inliers, vertical shift) by the histogram mode of the height differences.
fn score(points: &[[f64; 3]], tiles: &HeightMap, c: &Correction, tol_m: f64) -> (u32, f64) {
    const RANGE_M: f64 = 30.0;
    let bin = tol_m;
    let nb = (2.0 * RANGE_M / bin) as usize + 1;
    let mut hist = vec![0u32; nb];
    let (s, co) = c.yaw_deg.to_radians().sin_cos();
    for p in points {
        let (dx, dy) = (p[0] - c.pivot_enu_m[0], p[1] - c.pivot_enu_m[1]);
        let e = co * dx - s * dy + c.pivot_enu_m[0] + c.east_m;
        let n = s * dx + co * dy + c.pivot_enu_m[1] + c.north_m;
        let h = tiles.at(e, n);
        if h.is_finite() {
            let r = h as f64 - p[2];
            if r.abs() < RANGE_M {
                hist[((r + RANGE_M) / bin) as usize] += 1;
            }
        }
    }
    // Window of two bins (±tol around its middle): the best pair and its weighted centre.
    let mut best = (0u32, 0.0);
    for b in 0..nb - 1 {
        let n = hist[b] + hist[b + 1];
        if n > best.0 {
            best = (n, -RANGE_M + (b as f64 + 1.0) * bin);
        }
    }
    best
}

/// Grid search over yaw × east × north around `centre`; the best candidate (ties: the first in order)
/// with its inlier count.
fn search(
    points: &[[f64; 3]],
    tiles: &HeightMap,
    centre: &Correction,
    (half_m, step_m): (f64, f64),
    (half_deg, step_deg): (f64, f64),
    tol_m: f64,
) -> (Correction, u32) {
    let ns = (half_m / step_m).round() as i64;
    let nd = (half_deg / step_deg).round() as i64;
    let mut cands = Vec::new();
    for a in -nd..=nd {
        for y in -ns..=ns {
            for x in -ns..=ns {
                cands.push(Correction {
                    east_m: centre.east_m + x as f64 * step_m,
                    north_m: centre.north_m + y as f64 * step_m,
                    up_m: 0.0,
                    yaw_deg: centre.yaw_deg + a as f64 * step_deg,
                    pivot_enu_m: centre.pivot_enu_m,
                });
            }
        }
    }
    let scored: Vec<(u32, f64)> = cands.par_iter().map(|c| score(points, tiles, c, tol_m)).collect();
    let mut best = 0usize;
    for (k, s) in scored.iter().enumerate() {
        if s.0 > scored[best].0 {
            best = k;
        }
    }
    let mut c = cands[best];
    c.up_m = scored[best].1;
    (c, scored[best].0)
}

// ------------------------------------------------------------------------------------------ refinement

/// Points sampled uniformly (about one per `spacing_m²`) on the triangles not facing down, with their
/// unit normals; deterministic (a fixed low-discrepancy pattern per triangle).
fn surface_samples(mesh: &TriMesh, spacing_m: f64) -> Vec<(DVec3, DVec3)> {
    let mut out = Vec::new();
    let mut carry = 0.0;
    // R2 sequence (Roberts 2018): plastic-number increments.
    let (g1, g2) = (0.754_877_666_246_692_7, 0.569_840_290_998_053_3);
    for t in &mesh.triangles {
        let [a, b, c] = t.map(|i| DVec3::from_array(mesh.positions[i as usize]));
        let n = (b - a).cross(c - a);
        let area = 0.5 * n.length();
        if area < 1e-9 {
            continue;
        }
        let n = n.normalize();
        if n.z < -0.5 {
            continue;
        }
        carry += area / (spacing_m * spacing_m);
        let mut k = 0u32;
        while carry >= 1.0 {
            carry -= 1.0;
            k += 1;
            let (mut u, mut v) = ((0.5 + g1 * k as f64).fract(), (0.5 + g2 * k as f64).fract());
            if u + v > 1.0 {
                (u, v) = (1.0 - u, 1.0 - v);
            }
            out.push((a + (b - a) * u + (c - a) * v, n));
        }
    }
    out
}

/// A uniform horizontal grid of triangle indices for closest-point queries.
struct TriangleGrid<'a> {
    mesh: &'a TriMesh,
    normals: Vec<DVec3>,
    min_m: [f64; 2],
    cell_m: f64,
    nx: usize,
    ny: usize,
    starts: Vec<u32>,
    items: Vec<u32>,
}

impl<'a> TriangleGrid<'a> {
    fn new(mesh: &'a TriMesh, cell_m: f64) -> TriangleGrid<'a> {
        let (lo, hi) = bounds_2d(mesh).unwrap_or(([0.0; 2], [1.0; 2]));
        let nx = (((hi[0] - lo[0]) / cell_m).ceil() as usize).max(1);
        let ny = (((hi[1] - lo[1]) / cell_m).ceil() as usize).max(1);
        let cell_of =
            |v: f64, k: usize, n: usize| (((v - lo[k]) / cell_m).floor().max(0.0) as usize).min(n - 1);
        let span = |t: &[u32; 3]| {
            let p = t.map(|i| mesh.positions[i as usize]);
            let r = |k: usize, n: usize| {
                cell_of(p[0][k].min(p[1][k]).min(p[2][k]), k, n)
                    ..=cell_of(p[0][k].max(p[1][k]).max(p[2][k]), k, n)
            };
            (r(0, nx), r(1, ny))
        };
        let mut counts = vec![0u32; nx * ny + 1];
        for t in &mesh.triangles {
            let (rx, ry) = span(t);
            for j in ry {
                for i in rx.clone() {
                    counts[j * nx + i + 1] += 1;
                }
            }
        }
        for k in 1..counts.len() {
            counts[k] += counts[k - 1];
        }
        let mut fill = counts.clone();
        let mut items = vec![0u32; *counts.last().expect("nx·ny + 1 ≥ 1 entries") as usize];
        for (ti, t) in mesh.triangles.iter().enumerate() {
            let (rx, ry) = span(t);
            for j in ry {
                for i in rx.clone() {
                    let slot = &mut fill[j * nx + i];
                    items[*slot as usize] = ti as u32;
                    *slot += 1;
                }
            }
        }
        let normals = mesh
            .triangles
            .iter()
            .map(|t| {
                let [a, b, c] = t.map(|i| DVec3::from_array(mesh.positions[i as usize]));
                (b - a).cross(c - a).normalize_or_zero()
            })
            .collect();
        TriangleGrid { mesh, normals, min_m: lo, cell_m, nx, ny, starts: counts, items }
    }

    /// The closest point of the mesh to `p` within `radius_m` (horizontally searched cells), with the
    /// triangle's unit normal.
    fn closest(&self, p: DVec3, radius_m: f64) -> Option<(DVec3, DVec3, f64)> {
        let r = |v: f64, k: usize, n: usize| -> Option<std::ops::RangeInclusive<usize>> {
            let lo = ((v - radius_m - self.min_m[k]) / self.cell_m).floor();
            let hi = ((v + radius_m - self.min_m[k]) / self.cell_m).floor();
            if hi < 0.0 || lo >= n as f64 {
                return None;
            }
            Some(lo.max(0.0) as usize..=(hi as usize).min(n - 1))
        };
        let (rx, ry) = (r(p.x, 0, self.nx)?, r(p.y, 1, self.ny)?);
        let mut best: Option<(DVec3, usize, f64)> = None;
        for j in ry {
            for i in rx.clone() {
                let c = j * self.nx + i;
                for &ti in &self.items[self.starts[c] as usize..self.starts[c + 1] as usize] {
                    let t = self.mesh.triangles[ti as usize];
                    let [a, b, cc] = t.map(|k| DVec3::from_array(self.mesh.positions[k as usize]));
                    let q = closest_on_triangle(p, a, b, cc);
                    let d2 = q.distance_squared(p);
                    if d2 <= radius_m * radius_m && best.is_none_or(|b| d2 < b.2) {
                        best = Some((q, ti as usize, d2));
                    }
                }
            }
        }
        best.map(|(q, ti, d2)| (q, self.normals[ti], d2.sqrt()))
    }
}

/// Closest point of triangle `abc` to `p` (Ericson, Real-Time Collision Detection, §5.1.5).
fn closest_on_triangle(p: DVec3, a: DVec3, b: DVec3, c: DVec3) -> DVec3 {
    let (ab, ac, ap) = (b - a, c - a, p - a);
    let (d1, d2) = (ab.dot(ap), ac.dot(ap));
    if d1 <= 0.0 && d2 <= 0.0 {
        return a;
    }
    let bp = p - b;
    let (d3, d4) = (ab.dot(bp), ac.dot(bp));
    if d3 >= 0.0 && d4 <= d3 {
        return b;
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        return a + ab * (d1 / (d1 - d3));
    }
    let cp = p - c;
    let (d5, d6) = (ab.dot(cp), ac.dot(cp));
    if d6 >= 0.0 && d5 <= d6 {
        return c;
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        return a + ac * (d2 / (d2 - d6));
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0 {
        return b + (c - b) * ((d4 - d3) / ((d4 - d3) + (d5 - d6)));
    }
    let denom = 1.0 / (va + vb + vc);
    a + ab * (vb * denom) + ac * (vc * denom)
}

/// One correspondence: the Jacobian row (∂r/∂(e, n, u, yaw_rad)) and the residual, metres.
type Row = ([f64; 4], f64);

fn correspondences(samples: &[(DVec3, DVec3)], grid: &TriangleGrid, c: &Correction, gate_m: f64) -> Vec<Row> {
    let (s, co) = c.yaw_deg.to_radians().sin_cos();
    samples
        .par_iter()
        .filter_map(|(p, n_lod)| {
            let q = c.apply(*p);
            let n_l = DVec3::new(co * n_lod.x - s * n_lod.y, s * n_lod.x + co * n_lod.y, n_lod.z);
            let (on, n_t, _) = grid.closest(q, gate_m)?;
            if n_t.dot(n_l).abs() < std::f64::consts::FRAC_1_SQRT_2 {
                return None;
            }
            let lever = q - DVec3::new(c.pivot_enu_m[0] + c.east_m, c.pivot_enu_m[1] + c.north_m, q.z);
            let r = n_t.dot(q - on);
            Some(([n_t.x, n_t.y, n_t.z, -n_t.x * lever.y + n_t.y * lever.x], r))
        })
        .collect()
}

/// Tukey biweight weights with scale `4.685 · σ`.
fn tukey(rows: &[Row], sigma_m: f64) -> Vec<f64> {
    let c = 4.685 * sigma_m;
    rows.iter()
        .map(|(_, r)| {
            let u = r / c;
            if u.abs() < 1.0 {
                (1.0 - u * u).powi(2)
            } else {
                0.0
            }
        })
        .collect()
}

/// Weighted normal equations: (JᵀWJ, JᵀWr) as a glam 4 × 4 (symmetric) and a 4-vector.
fn normal_equations(rows: &[Row], w: &[f64]) -> (DMat4, [f64; 4]) {
    let mut a = [[0.0; 4]; 4];
    let mut g = [0.0; 4];
    for ((j, r), &wi) in rows.iter().zip(w) {
        for (x, ax) in a.iter_mut().enumerate() {
            for (y, axy) in ax.iter_mut().enumerate() {
                *axy += wi * j[x] * j[y];
            }
            g[x] += wi * j[x] * r;
        }
    }
    (DMat4::from_cols_array_2d(&a), g)
}

/// Estimates the correction that moves `lod` onto `tiles` (see the module doc).
///
/// # Errors
/// [`AlignError`] when a model is empty over the area, nothing overlaps, or the refinement cannot
/// fix all four parameters.
pub fn estimate(lod: &TriMesh, tiles: &TriMesh, opts: &AlignOptions) -> Result<Estimate, AlignError> {
    let window_ok = opts.search_m > 0.0 && opts.search_m <= 100.0;
    if !(window_ok && opts.search_deg >= 0.0 && opts.search_deg <= 20.0) {
        return Err(AlignError::SearchWindow { search_m: opts.search_m, search_deg: opts.search_deg });
    }
    let (lo, hi) = bounds_2d(lod).ok_or(AlignError::Empty { what: "LoD" })?;
    bounds_2d(tiles).ok_or(AlignError::Empty { what: "tileset" })?;
    let pivot = [0.5 * (lo[0] + hi[0]), 0.5 * (lo[1] + hi[1])];
    let margin = opts.search_m + 0.02 * (hi[0] - lo[0]).max(hi[1] - lo[1]) * opts.search_deg + 2.0;
    let (mlo, mhi) = ([lo[0] - margin, lo[1] - margin], [hi[0] + margin, hi[1] + margin]);
    let start = Correction { pivot_enu_m: pivot, ..Correction::IDENTITY };

    // Coarse pass 1: 2 m cells, 1 m / 0.2° steps, ±1 m tolerance.
    let map = |mesh: &TriMesh, cell: f64| {
        let mut m = HeightMap::new(mlo, mhi, cell);
        m.rasterise(mesh, &Correction::IDENTITY);
        m
    };
    let clock = std::time::Instant::now();
    let (t2, l2) = (map(tiles, 2.0), map(lod, 2.0));
    let pts = roof_points(&l2, 6000);
    if pts.is_empty() {
        return Err(AlignError::Empty { what: "LoD" });
    }
    log::debug!("align: 2 m height maps in {:.2} s", clock.elapsed().as_secs_f64());
    let (c1, _) = search(&pts, &t2, &start, (opts.search_m, 1.0), (opts.search_deg, 0.2), 1.0);
    log::debug!("align: coarse pass 1 done at {:.2} s: {c1:?}", clock.elapsed().as_secs_f64());
    // Coarse pass 2: 0.5 m cells around the best, 0.25 m / 0.05° steps, ±0.4 m.
    let (t05, l05) = (map(tiles, 0.5), map(lod, 0.5));
    let pts = roof_points(&l05, 8000);
    log::debug!("align: 0.5 m height maps at {:.2} s", clock.elapsed().as_secs_f64());
    let (coarse, inliers) = search(&pts, &t05, &c1, (1.0, 0.25), (0.2, 0.05), 0.4);
    let coarse_inlier_fraction = inliers as f64 / pts.len() as f64;
    log::debug!("align: coarse pass 2 done at {:.2} s: {coarse:?}", clock.elapsed().as_secs_f64());
    if coarse_inlier_fraction < 0.05 {
        return Err(AlignError::NoCommonHeight {
            inlier_fraction: coarse_inlier_fraction,
            search_m: opts.search_m,
            search_deg: opts.search_deg,
        });
    }

    // Refinement.
    let total_area: f64 = lod
        .triangles
        .iter()
        .map(|t| {
            let [a, b, c] = t.map(|i| DVec3::from_array(lod.positions[i as usize]));
            0.5 * (b - a).cross(c - a).length()
        })
        .sum();
    let spacing = (total_area / opts.max_samples.max(100) as f64).sqrt().max(0.25);
    let samples = surface_samples(lod, spacing);
    let grid = TriangleGrid::new(tiles, 2.0);
    log::debug!("align: {} samples, grid built at {:.2} s", samples.len(), clock.elapsed().as_secs_f64());
    let mut c = coarse;
    let mut sigma_m: f64 = 0.3;
    let mut last = None;
    let mut iterations = 0;
    for it in 0..40u32 {
        iterations = it + 1;
        let gate = if it < 4 { 1.5 } else { (6.0 * sigma_m).clamp(0.3, 1.0) };
        let rows = correspondences(&samples, &grid, &c, gate);
        if rows.len() < 50 {
            return Err(AlignError::FewSamples { samples: rows.len(), gate_m: gate });
        }
        let abs: Vec<f64> = rows.iter().map(|r| r.1.abs()).collect();
        sigma_m = (1.4826 * crate::util::median(&abs).unwrap_or(0.0)).max(0.005);
        let w = tukey(&rows, sigma_m);
        let (a, g) = normal_equations(&rows, &w);
        let det = a.determinant();
        // Relative to the diagonal's product (1 for an orthogonal design, 0 for a degenerate one).
        let diag = a.col(0).x * a.col(1).y * a.col(2).z * a.col(3).w;
        if !(det.is_finite() && diag > 0.0 && det / diag > 1e-9) {
            return Err(AlignError::Degenerate { determinant: det });
        }
        let inv = a.inverse();
        let d = inv * glam::DVec4::from_array(g);
        c.east_m -= d.x;
        c.north_m -= d.y;
        c.up_m -= d.z;
        c.yaw_deg -= d.w.to_degrees();
        let wsum: f64 = w.iter().sum();
        let wr2: f64 = rows.iter().zip(&w).map(|(r, wi)| wi * r.1 * r.1).sum();
        last = Some((inv, wr2 / (wsum - 4.0).max(1.0), rows.len()));
        let lever = (hi[0] - lo[0]).max(hi[1] - lo[1]);
        if it >= 6 && d.x.abs().max(d.y.abs()).max(d.z.abs()) < 1e-4 && d.w.abs() * lever < 1e-4 {
            break;
        }
    }
    log::debug!("align: refined in {iterations} iterations at {:.2} s", clock.elapsed().as_secs_f64());
    let (inv, var, kept) = last.expect("the loop runs at least once");
    let sd = |k: usize| (var * inv.col(k)[k]).max(0.0).sqrt();
    Ok(Estimate {
        correction: c,
        sigma: CorrectionSigma { east_m: sd(0), north_m: sd(1), up_m: sd(2), yaw_deg: sd(3).to_degrees() },
        coarse,
        coarse_inlier_fraction,
        iterations,
        samples: samples.len() as u64,
        correspondences: kept as u64,
        residual_sigma_m: sigma_m,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Axis-aligned box (closed, 12 triangles) appended to `m`.
    pub(crate) fn push_box(m: &mut TriMesh, lo: [f64; 3], hi: [f64; 3]) {
        let base = m.positions.len() as u32;
        for k in 0..8 {
            m.positions.push([
                if k & 1 == 0 { lo[0] } else { hi[0] },
                if k & 2 == 0 { lo[1] } else { hi[1] },
                if k & 4 == 0 { lo[2] } else { hi[2] },
            ]);
        }
        let faces = [[0, 2, 3, 1], [4, 5, 7, 6], [0, 1, 5, 4], [2, 6, 7, 3], [0, 4, 6, 2], [1, 3, 7, 5]];
        for f in faces {
            m.triangles.push([base + f[0], base + f[1], base + f[2]]);
            m.triangles.push([base + f[0], base + f[2], base + f[3]]);
        }
    }

    /// A small irregular town of boxes (sizes and spacing from a fixed table).
    fn town() -> TriMesh {
        let mut m = TriMesh::default();
        for i in 0..6 {
            for j in 0..5 {
                let (x, y) = (i as f64 * 31.0 + (j * 7 % 5) as f64, j as f64 * 27.0 + (i * 3 % 4) as f64);
                let (w, d, h) = (
                    12.0 + (i + j) as f64 % 7.0,
                    9.0 + (i * j) as f64 % 6.0,
                    8.0 + (i * 5 + j * 3) as f64 % 23.0,
                );
                push_box(&mut m, [x, y, 0.0], [x + w, y + d, h]);
            }
        }
        m
    }

    fn moved(m: &TriMesh, c: &Correction) -> TriMesh {
        TriMesh {
            positions: m.positions.iter().map(|p| c.apply(DVec3::from_array(*p)).to_array()).collect(),
            triangles: m.triangles.clone(),
        }
    }

    #[test]
    fn height_map_of_a_box_covers_its_cells() {
        let mut m = TriMesh::default();
        push_box(&mut m, [1.0, 1.0, 0.0], [3.0, 2.0, 5.0]);
        let mut h = HeightMap::new([0.0, 0.0], [4.0, 4.0], 0.5);
        h.rasterise(&m, &Correction::IDENTITY);
        // Cell centres 1.25, 1.75, …, 2.75 (4) × 1.25, 1.75 (2) lie inside the 2 × 1 m roof.
        assert_eq!(h.h_m.iter().filter(|v| v.is_finite()).count(), 8);
        assert_eq!(h.at(2.0, 1.5), 5.0);
        assert!(h.at(0.2, 0.2).is_nan());
    }

    #[test]
    fn closest_point_on_a_triangle() {
        let (a, b, c) = (DVec3::ZERO, DVec3::X, DVec3::Y);
        // Hand computation: above the face, beyond a vertex, beyond an edge; 1e-12 m rounding.
        let near = |p: DVec3, q: DVec3| closest_on_triangle(p, a, b, c).distance(q) < 1e-12;
        assert!(near(DVec3::new(0.2, 0.2, 3.0), DVec3::new(0.2, 0.2, 0.0)));
        assert!(near(DVec3::new(-1.0, -1.0, 0.0), a));
        assert!(near(DVec3::new(0.5, -2.0, 0.0), DVec3::new(0.5, 0.0, 0.0)));
        assert!(near(DVec3::new(1.0, 1.0, 0.0), DVec3::new(0.5, 0.5, 0.0)));
    }

    #[test]
    fn recovers_a_known_offset_exactly_without_noise() {
        let lod = town();
        let pivot = pivot_of(&lod);
        let truth = Correction { east_m: 3.3, north_m: -2.7, up_m: 1.1, yaw_deg: 0.6, pivot_enu_m: pivot };
        let est = estimate(&lod, &moved(&lod, &truth), &AlignOptions::default()).unwrap();
        let c = est.correction;
        assert!((c.east_m - 3.3).abs() < 1e-3, "{c:?}");
        assert!((c.north_m + 2.7).abs() < 1e-3, "{c:?}");
        assert!((c.up_m - 1.1).abs() < 1e-3, "{c:?}");
        assert!((c.yaw_deg - 0.6).abs() < 1e-4, "{c:?}");
    }

    #[test]
    fn zero_offset_gives_zero() {
        let lod = town();
        let est = estimate(&lod, &lod, &AlignOptions::default()).unwrap();
        let c = est.correction;
        assert!(c.east_m.abs().max(c.north_m.abs()).max(c.up_m.abs()) < 1e-4, "{c:?}");
        assert!(c.yaw_deg.abs() < 1e-5, "{c:?}");
        assert!(est.sigma.east_m < 0.01);
    }

    #[test]
    fn disjoint_models_are_refused() {
        let lod = town();
        let far = moved(&lod, &Correction { east_m: 5000.0, ..Correction::IDENTITY });
        assert!(matches!(
            estimate(&lod, &far, &AlignOptions::default()),
            Err(AlignError::NoCommonHeight { .. } | AlignError::FewSamples { .. })
        ));
    }

    #[test]
    fn agreement_is_perfect_for_identical_models() {
        let lod = town();
        let mut ground = TriMesh::default();
        push_box(&mut ground, [-20.0, -20.0, -1.0], [220.0, 170.0, 0.0]);
        let mut tiles = lod.clone();
        let base = tiles.positions.len() as u32;
        tiles.positions.extend(&ground.positions);
        tiles.triangles.extend(ground.triangles.iter().map(|t| t.map(|i| i + base)));
        let mut t = HeightMap::new([-20.0, -20.0], [220.0, 170.0], 0.5);
        t.rasterise(&tiles, &Correction::IDENTITY);
        let g = t.ground(GROUND_WINDOW_M);
        let a = agreement(&lod, &t, &g, &Correction::IDENTITY);
        assert_eq!(a.median_abs_dh_roofs_m, 0.0);
        assert!(a.footprint_iou > 0.999, "{a:?}");
        let b = agreement(&lod, &t, &g, &Correction { east_m: 3.0, ..Correction::IDENTITY });
        // 3 m east: most roof cells still land on the same roof (median 0), the footprints part.
        assert!(b.footprint_iou < 0.9, "{b:?}");
        let up = agreement(&lod, &t, &g, &Correction { up_m: 1.0, ..Correction::IDENTITY });
        assert_eq!(up.median_abs_dh_roofs_m, 1.0);
    }
}
