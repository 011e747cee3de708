//! The procedural demo city: insgen's embedded default dataset (nothing to download).
//!
//! [`generate`] turns a [`ProceduralSpec`] (seeded, deterministic) into a [`SourceModel`] of LoD1
//! buildings, exactly as a CityGML reader would hand them on: each building is a closed extrusion of a
//! footprint given as planar [`Polygon`]s (ground face facing down, roof face facing up, one vertical
//! quad per footprint edge, walls of courtyards included), in a real projected CRS so that the whole
//! CRS chain of the scene stage is exercised:
//! EPSG:6677 (JGD2011 / Japan Plane Rectangular CS IX, the Tokyo zone), emitted as
//! (easting, northing, H) with [`AxisConvention::EastNorth`] and orthometric heights H above a flat
//! ground at [`ProceduralSpec::ground_height_m`].
//!
//! # The city
//! A street grid of `blocks_x × blocks_y` rectangular blocks (sizes jittered around `block_size_m`),
//! streets of `street_width_m` and every `avenue_every`-th street an avenue of `avenue_width_m`; the
//! grid is rotated by `grid_rotation_deg` and centred on the given plane origin. Each block gets one
//! layout:
//! - **perimeter**: a terraced perimeter block: rows of adjacent buildings along all four sides,
//!   neighbours sharing wall faces exactly, L-shaped corner buildings, an open yard inside (sometimes
//!   with a low shed); some rows have one height throughout (row houses), others vary lot by lot;
//! - **courtyard**: one mid-rise building around a closed courtyard (a polygon with a hole) or an open,
//!   U-shaped one;
//! - **detached**: a grid of lots with detached rectangles, L- and U-shapes;
//! - **slabs**: parallel mid-rise slabs;
//! - **tower**: one or two towers of 80–200 m (rectangular or L-shaped footprint);
//! - **plaza**: an open square with at most a small pavilion.
//!
//! All lengths inside a block are multiples of 1/4 m, so the coordinates that neighbours share are
//! computed exactly (dyadic rationals) and end up bit-identical after the same final transform.
//!
//! # Determinism
//! One `ChaCha8Rng` seeded with `seed` drives every choice, in a fixed order: the same spec gives the
//! same buildings, bit for bit, in the same order (`source_id` = `demo_b0001`, `demo_b0002`, …,
//! zero-padded so that sorting by ID keeps that order).

use std::path::PathBuf;

use rand::seq::SliceRandom;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use crate::geo::AxisConvention;
use crate::lod::{
    Frame, Geometry, LodError, Polygon, ProceduralProblem, ReadStats, SourceBuilding, SourceModel,
};

/// The CRS the demo city is generated in: JGD2011 / Japan Plane Rectangular CS IX (EPSG:6677), whose
/// authority axis order is (X northing, Y easting); insgen emits (easting, northing) explicitly.
pub const DEMO_CRS: &str = "EPSG:6677";

/// `SourceModel::path` of a generated city (there is no file).
pub const DEMO_SOURCE_PATH: &str = "procedural";

/// Grid step of all in-block lengths, metres (a power of two, so sums and differences are exact).
const STEP_M: f64 = 0.25;

/// Where the city centre lies in EPSG:6677, metres.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PlaneOrigin {
    /// Easting (the CRS's Y axis), metres.
    pub easting_m: f64,
    /// Northing (the CRS's X axis), metres.
    pub northing_m: f64,
}

impl PlaneOrigin {
    /// Toyosu, on Tokyo bay: EPSG:6677 (Y, X) = (−3400 m, −38300 m), which is 35.654777° N,
    /// 139.795783° E (pyproj 3, EPSG:6677 → EPSG:4326).
    pub const TOKYO_BAY: PlaneOrigin = PlaneOrigin { easting_m: -3400.0, northing_m: -38300.0 };
}

impl Default for PlaneOrigin {
    fn default() -> Self {
        PlaneOrigin::TOKYO_BAY
    }
}

/// Parameters of the demo city. Every field has a default ([`default_spec`]), so a scene file may give
/// any subset (`[sources.procedural]` table with `format = "procedural"`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ProceduralSpec {
    /// Seed of the generator; the same spec always gives the same city.
    pub seed: u64,
    /// Blocks along the grid's x axis (east before rotation).
    pub blocks_x: u32,
    /// Blocks along the grid's y axis (north before rotation).
    pub blocks_y: u32,
    /// Mean side length of a block, metres (each row/column is jittered by ±20 %).
    pub block_size_m: f64,
    /// Width of an ordinary street, metres.
    pub street_width_m: f64,
    /// Every `avenue_every`-th street (counting from the first interior one) is an avenue; 0 = none.
    pub avenue_every: u32,
    /// Width of an avenue, metres.
    pub avenue_width_m: f64,
    /// Rotation of the street grid, degrees counter-clockwise from east.
    pub grid_rotation_deg: f64,
    /// Orthometric height H of the (flat) ground, metres.
    pub ground_height_m: f64,
    /// Number of blocks holding towers.
    pub tower_blocks: u32,
    /// Number of open plazas.
    pub plaza_blocks: u32,
    /// Height range of low-rise buildings [min, max], metres.
    pub low_rise_m: [f64; 2],
    /// Height range of mid-rise buildings [min, max], metres.
    pub mid_rise_m: [f64; 2],
    /// Height range of towers [min, max], metres.
    pub tower_m: [f64; 2],
}

impl Default for ProceduralSpec {
    fn default() -> Self {
        ProceduralSpec {
            seed: 2026,
            blocks_x: 10,
            blocks_y: 10,
            block_size_m: 80.0,
            street_width_m: 14.0,
            avenue_every: 4,
            avenue_width_m: 30.0,
            grid_rotation_deg: 17.0,
            ground_height_m: 3.0,
            tower_blocks: 5,
            plaza_blocks: 2,
            low_rise_m: [6.0, 25.0],
            mid_rise_m: [25.0, 60.0],
            tower_m: [80.0, 200.0],
        }
    }
}

/// What defines a generated city: the generator's parameters (the seed among them) and where its
/// centre lies. `prepare` records it in the scene manifest (`sources[].procedural`), and the COCO
/// files, the dataset manifest and the dataset card carry it on, since a generated city has no
/// source file whose hash would identify it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ProceduralCity {
    /// The generator's parameters, defaults filled in.
    pub spec: ProceduralSpec,
    /// The city centre in [`DEMO_CRS`].
    pub origin: PlaneOrigin,
}

impl ProceduralCity {
    /// One line naming every parameter, as the dataset card prints it: seed, blocks, streets,
    /// heights, centre. Lengths in metres, the rotation in degrees.
    pub fn describe(&self) -> String {
        let p = &self.spec;
        let avenues = if p.avenue_every == 0 {
            "no avenues".to_string()
        } else {
            format!("avenues {} m wide every {} streets", p.avenue_width_m, p.avenue_every)
        };
        let range = |r: [f64; 2]| format!("{}–{} m", r[0], r[1]);
        format!(
            "seed {}; {} × {} blocks of {} m, streets {} m wide, {avenues}, grid rotated {}°; ground at {} m; \
             {} tower blocks, {} plazas; heights: low-rise {}, mid-rise {}, towers {}; centre {} E {} m N {} m",
            p.seed,
            p.blocks_x,
            p.blocks_y,
            p.block_size_m,
            p.street_width_m,
            p.grid_rotation_deg,
            p.ground_height_m,
            p.tower_blocks,
            p.plaza_blocks,
            range(p.low_rise_m),
            range(p.mid_rise_m),
            range(p.tower_m),
            DEMO_CRS,
            self.origin.easting_m,
            self.origin.northing_m,
        )
    }
}

/// The default demo city: 10 × 10 blocks of about 80 m near Tokyo bay, several hundred buildings.
pub fn default_spec() -> ProceduralSpec {
    ProceduralSpec::default()
}

impl ProceduralSpec {
    /// Checks every parameter, reporting the first bad one by name.
    ///
    /// # Errors
    /// [`LodError::Invalid`] with `at` = `procedural.<field>` and the accepted range.
    pub fn validate(&self) -> Result<(), LodError> {
        let bad = |field: &str, problem: ProceduralProblem| {
            Err(LodError::invalid(DEMO_SOURCE_PATH, format!("procedural.{field}"), problem))
        };
        let in_range = |v: f64, lo: f64, hi: f64| v.is_finite() && v >= lo && v <= hi;
        let count = |value: u32| ProceduralProblem::Count { value, min: 1, max: 200 };
        let length =
            |value_m: f64, min_m: f64, max_m: f64| ProceduralProblem::Length { value_m, min_m, max_m };
        if !(1..=200).contains(&self.blocks_x) {
            return bad("blocks_x", count(self.blocks_x));
        }
        if !(1..=200).contains(&self.blocks_y) {
            return bad("blocks_y", count(self.blocks_y));
        }
        if !in_range(self.block_size_m, 60.0, 400.0) {
            return bad("block_size_m", length(self.block_size_m, 60.0, 400.0));
        }
        if !in_range(self.street_width_m, 4.0, 100.0) {
            return bad("street_width_m", length(self.street_width_m, 4.0, 100.0));
        }
        if !in_range(self.avenue_width_m, self.street_width_m, 200.0) {
            return bad(
                "avenue_width_m",
                ProceduralProblem::AvenueWidth {
                    avenue_width_m: self.avenue_width_m,
                    street_width_m: self.street_width_m,
                },
            );
        }
        if !in_range(self.grid_rotation_deg, -360.0, 360.0) {
            return bad(
                "grid_rotation_deg",
                ProceduralProblem::Angle {
                    value_deg: self.grid_rotation_deg,
                    min_deg: -360.0,
                    max_deg: 360.0,
                },
            );
        }
        if !in_range(self.ground_height_m, -500.0, 9000.0) {
            return bad("ground_height_m", length(self.ground_height_m, -500.0, 9000.0));
        }
        let blocks = u64::from(self.blocks_x) * u64::from(self.blocks_y);
        let special = u64::from(self.tower_blocks) + u64::from(self.plaza_blocks);
        if special > blocks {
            return bad("tower_blocks", ProceduralProblem::SpecialBlocks { special, blocks });
        }
        for (field, r, lo, hi) in [
            ("low_rise_m", self.low_rise_m, 3.0, 100.0),
            ("mid_rise_m", self.mid_rise_m, 6.0, 300.0),
            ("tower_m", self.tower_m, 20.0, 1000.0),
        ] {
            if !(in_range(r[0], lo, hi) && in_range(r[1], lo, hi) && r[0] <= r[1]) {
                return bad(field, ProceduralProblem::HeightRange { range_m: r, min_m: lo, max_m: hi });
            }
        }
        Ok(())
    }
}

/// Rounds a length to the in-block grid ([`STEP_M`]).
fn q(v: f64) -> f64 {
    (v / STEP_M).round() * STEP_M
}

/// A uniformly drawn length in [lo, hi], on the in-block grid.
fn len(rng: &mut ChaCha8Rng, lo: f64, hi: f64) -> f64 {
    if hi <= lo {
        return q(lo);
    }
    q(rng.gen_range(lo..=hi))
}

/// A height drawn uniformly in the range, rounded to 0.5 m.
fn height(rng: &mut ChaCha8Rng, range: [f64; 2]) -> f64 {
    let h = if range[1] > range[0] { rng.gen_range(range[0]..=range[1]) } else { range[0] };
    ((h * 2.0).round() / 2.0).clamp(range[0], range[1])
}

/// A footprint in block coordinates (metres, x along the block's width, y along its depth): one
/// counter-clockwise exterior ring and clockwise holes, open rings.
#[derive(Debug, Clone)]
struct Footprint {
    exterior: Vec<[f64; 2]>,
    holes: Vec<Vec<[f64; 2]>>,
}

impl Footprint {
    fn rect(x0: f64, y0: f64, x1: f64, y1: f64) -> Footprint {
        Footprint { exterior: vec![[x0, y0], [x1, y0], [x1, y1], [x0, y1]], holes: Vec::new() }
    }
}

/// A building before it is placed: footprint (block coordinates) and height above ground.
struct Lot {
    footprint: Footprint,
    height_m: f64,
}

/// A rectangle [x0, x1] × [y0, y1] with an L-notch of size (nx, ny) cut from one corner
/// (`corner`: 0 = SW, 1 = SE, 2 = NE, 3 = NW). Counter-clockwise.
fn l_shape(x0: f64, y0: f64, x1: f64, y1: f64, nx: f64, ny: f64, corner: u8) -> Footprint {
    let ring = match corner {
        0 => vec![[x0 + nx, y0], [x1, y0], [x1, y1], [x0, y1], [x0, y0 + ny], [x0 + nx, y0 + ny]],
        1 => vec![[x0, y0], [x1 - nx, y0], [x1 - nx, y0 + ny], [x1, y0 + ny], [x1, y1], [x0, y1]],
        2 => vec![[x0, y0], [x1, y0], [x1, y1 - ny], [x1 - nx, y1 - ny], [x1 - nx, y1], [x0, y1]],
        _ => vec![[x0, y0], [x1, y0], [x1, y1], [x0 + nx, y1], [x0 + nx, y1 - ny], [x0, y1 - ny]],
    };
    Footprint { exterior: ring, holes: Vec::new() }
}

/// A U-shape: the rectangle with a notch of width `x1 − x0 − 2·arm` and depth `depth` opened towards
/// `side` (0 = south, 1 = east, 2 = north, 3 = west). Counter-clockwise.
fn u_shape(x0: f64, y0: f64, x1: f64, y1: f64, arm: f64, depth: f64, side: u8) -> Footprint {
    let ring = match side {
        0 => vec![
            [x0, y0],
            [x0 + arm, y0],
            [x0 + arm, y0 + depth],
            [x1 - arm, y0 + depth],
            [x1 - arm, y0],
            [x1, y0],
            [x1, y1],
            [x0, y1],
        ],
        1 => vec![
            [x0, y0],
            [x1, y0],
            [x1, y0 + arm],
            [x1 - depth, y0 + arm],
            [x1 - depth, y1 - arm],
            [x1, y1 - arm],
            [x1, y1],
            [x0, y1],
        ],
        2 => vec![
            [x0, y0],
            [x1, y0],
            [x1, y1],
            [x1 - arm, y1],
            [x1 - arm, y1 - depth],
            [x0 + arm, y1 - depth],
            [x0 + arm, y1],
            [x0, y1],
        ],
        _ => vec![
            [x0, y0],
            [x1, y0],
            [x1, y1],
            [x0, y1],
            [x0, y1 - arm],
            [x0 + depth, y1 - arm],
            [x0 + depth, y0 + arm],
            [x0, y0 + arm],
        ],
    };
    Footprint { exterior: ring, holes: Vec::new() }
}

/// Maps a point of side frame `k` of a `w × h` block to block coordinates.
///
/// Side frame k has side k (0 = south, 1 = east, 2 = north, 3 = west, counter-clockwise) along its
/// x axis, y pointing into the block, origin at the side's start corner. Frame k+1 → frame k is
/// (x, y) ↦ (w_k − y, x), w_k being frame k's width; exact for grid-aligned input.
fn side_to_block(k: usize, p: [f64; 2], w: f64, h: f64) -> [f64; 2] {
    let mut p = p;
    for j in (0..k).rev() {
        let wj = if j % 2 == 0 { w } else { h };
        p = [wj - p[1], p[0]];
    }
    p
}

/// The perimeter (terraced) block layout. `w`, `h`: block size in metres.
fn perimeter_block(rng: &mut ChaCha8Rng, spec: &ProceduralSpec, w: f64, h: f64) -> Vec<Lot> {
    // Depth of the row along each side; corner extensions along the side (e) and up the previous
    // side (f).
    let max_depth = (w.min(h) * 0.22).min(18.0);
    let depth: [f64; 4] = std::array::from_fn(|_| len(rng, 11.0, max_depth));
    let max_ext = w.min(h) * 0.12;
    let mut ext = [[0.0f64; 2]; 4];
    for e in &mut ext {
        if rng.gen_bool(0.5) {
            *e = [len(rng, 4.0, max_ext), len(rng, 4.0, max_ext)];
        }
    }
    let mut lots = Vec::new();
    for k in 0..4 {
        let (wk, _) = if k % 2 == 0 { (w, h) } else { (h, w) };
        let d_prev = depth[(k + 3) % 4];
        let d = depth[k];
        let [e, f] = ext[k];
        let to_block = |fp: Footprint| Footprint {
            exterior: fp.exterior.iter().map(|&p| side_to_block(k, p, w, h)).collect(),
            holes: Vec::new(),
        };
        // The corner building at the side's start: an L when it extends along both sides.
        let corner = if e > 0.0 && f > 0.0 {
            Footprint {
                exterior: vec![
                    [0.0, 0.0],
                    [d_prev + e, 0.0],
                    [d_prev + e, d],
                    [d_prev, d],
                    [d_prev, d + f],
                    [0.0, d + f],
                ],
                holes: Vec::new(),
            }
        } else {
            Footprint::rect(0.0, 0.0, d_prev, d)
        };
        let corner_h =
            if rng.gen_bool(0.5) { height(rng, spec.mid_rise_m) } else { height(rng, spec.low_rise_m) };
        lots.push(Lot { footprint: to_block(corner), height_m: corner_h });

        // The row between this corner and the next one (whose extension up this side is ext[k+1][1]).
        let x_start = d_prev + e;
        let next_f = if ext[(k + 1) % 4][0] > 0.0 { ext[(k + 1) % 4][1] } else { 0.0 };
        let x_end = wk - depth[(k + 1) % 4] - next_f;
        let uniform = rng.gen_bool(0.4);
        let row_h = height(rng, spec.low_rise_m);
        let mut x = x_start;
        while x_end - x > 0.0 {
            let mut lw = len(rng, 7.0, 18.0);
            if x_end - (x + lw) < 6.0 {
                lw = x_end - x; // the last lot takes the remainder
            }
            let gap = !uniform && rng.gen_bool(0.12) && lw < x_end - x;
            let lot_h = if uniform {
                row_h
            } else if rng.gen_bool(0.25) {
                height(rng, spec.mid_rise_m)
            } else {
                height(rng, spec.low_rise_m)
            };
            if !gap {
                lots.push(Lot { footprint: to_block(Footprint::rect(x, 0.0, x + lw, d)), height_m: lot_h });
            }
            x += lw;
        }
    }
    // Sometimes a low shed in the yard, clear of every row and extension by 3 m.
    let inner = [max_depth + max_ext + 3.0, w - max_depth - max_ext - 3.0];
    let inner_y = [max_depth + max_ext + 3.0, h - max_depth - max_ext - 3.0];
    if inner[1] - inner[0] >= 8.0 && inner_y[1] - inner_y[0] >= 8.0 && rng.gen_bool(0.5) {
        let sw = len(rng, 8.0, inner[1] - inner[0]);
        let sh = len(rng, 8.0, inner_y[1] - inner_y[0]);
        let x0 = q((w - sw) / 2.0);
        let y0 = q((h - sh) / 2.0);
        let shed_h = height(rng, [4.0, 8.0]);
        lots.push(Lot { footprint: Footprint::rect(x0, y0, x0 + sw, y0 + sh), height_m: shed_h });
    }
    lots
}

/// One mid-rise building around a courtyard: closed (a hole) or open (U-shape).
fn courtyard_block(rng: &mut ChaCha8Rng, spec: &ProceduralSpec, w: f64, h: f64) -> Vec<Lot> {
    let s = len(rng, 0.0, 4.0);
    let d = len(rng, 12.0, (w.min(h) * 0.28).min(20.0));
    let (x0, y0, x1, y1) = (s, s, w - s, h - s);
    let footprint = if rng.gen_bool(0.65) {
        let mut fp = Footprint::rect(x0, y0, x1, y1);
        // The hole runs clockwise.
        fp.holes.push(vec![[x0 + d, y0 + d], [x0 + d, y1 - d], [x1 - d, y1 - d], [x1 - d, y0 + d]]);
        fp
    } else {
        let side = rng.gen_range(0..4u8);
        let depth = if side % 2 == 0 { y1 - y0 - d } else { x1 - x0 - d };
        u_shape(x0, y0, x1, y1, d, depth, side)
    };
    vec![Lot { footprint, height_m: height(rng, spec.mid_rise_m) }]
}

/// A grid of lots with detached buildings of varied footprints.
fn detached_block(rng: &mut ChaCha8Rng, spec: &ProceduralSpec, w: f64, h: f64) -> Vec<Lot> {
    let nx = rng.gen_range(2..=3usize);
    let ny = rng.gen_range(2..=3usize);
    let path = 4.0;
    let lw = q((w - path * (nx as f64 - 1.0)) / nx as f64);
    let lh = q((h - path * (ny as f64 - 1.0)) / ny as f64);
    let mut lots = Vec::new();
    for j in 0..ny {
        for i in 0..nx {
            if rng.gen_bool(0.1) {
                continue; // an empty lot (parking, garden)
            }
            let (lx, ly) = (i as f64 * (lw + path), j as f64 * (lh + path));
            let inset = len(rng, 1.0, 2.5);
            let (x0, y0, x1, y1) = (lx + inset, ly + inset, lx + lw - inset, ly + lh - inset);
            let (bw, bh) = (x1 - x0, y1 - y0);
            let kind = rng.gen_range(0..100u32);
            let footprint = if kind < 45 {
                // A rectangle, shrunk along one axis for variety.
                let shrink_x = len(rng, 0.0, bw * 0.2);
                let shrink_y = len(rng, 0.0, bh * 0.2);
                Footprint::rect(x0, y0, x1 - shrink_x, y1 - shrink_y)
            } else if kind < 85 || bw < 16.0 || bh < 16.0 {
                let nxl = len(rng, bw * 0.3, bw * 0.6);
                let nyl = len(rng, bh * 0.3, bh * 0.6);
                l_shape(x0, y0, x1, y1, nxl, nyl, rng.gen_range(0..4u8))
            } else {
                let side = rng.gen_range(0..4u8);
                let (across, along) = if side % 2 == 0 { (bw, bh) } else { (bh, bw) };
                let arm = len(rng, across * 0.25, across * 0.35);
                let depth = len(rng, along * 0.35, along * 0.6);
                u_shape(x0, y0, x1, y1, arm, depth, side)
            };
            let height_m =
                if rng.gen_bool(0.2) { height(rng, spec.mid_rise_m) } else { height(rng, spec.low_rise_m) };
            lots.push(Lot { footprint, height_m });
        }
    }
    lots
}

/// Parallel mid-rise slabs across the block, some L-shaped.
fn slab_block(rng: &mut ChaCha8Rng, spec: &ProceduralSpec, w: f64, h: f64) -> Vec<Lot> {
    let along_x = rng.gen_bool(0.5);
    let (span, across) = if along_x { (w, h) } else { (h, w) };
    let depth = len(rng, 14.0, 20.0);
    let margin = len(rng, 2.0, 4.0);
    // Three slabs where they stay at least 10 m apart.
    let n = if across >= 3.0 * depth + 2.0 * 10.0 + 2.0 * margin { 3 } else { 2 };
    let gap = q((across - 2.0 * margin - n as f64 * depth) / (n as f64 - 1.0).max(1.0));
    let mut lots = Vec::new();
    for i in 0..n {
        let c0 = margin + i as f64 * (depth + gap);
        let (s0, s1) = (margin, span - margin);
        let fp = if rng.gen_bool(0.3) {
            let notch_along = len(rng, (s1 - s0) * 0.3, (s1 - s0) * 0.5);
            let notch_across = q(depth / 2.0);
            l_shape(s0, c0, s1, c0 + depth, notch_along, notch_across, rng.gen_range(0..4u8))
        } else {
            Footprint::rect(s0, c0, s1, c0 + depth)
        };
        // Transpose when the slabs run along y (a reflection: reverse to stay counter-clockwise).
        let fp = if along_x {
            fp
        } else {
            let mut ring: Vec<[f64; 2]> = fp.exterior.iter().map(|p| [p[1], p[0]]).collect();
            ring.reverse();
            Footprint { exterior: ring, holes: Vec::new() }
        };
        lots.push(Lot { footprint: fp, height_m: height(rng, spec.mid_rise_m) });
    }
    lots
}

/// One or two towers.
fn tower_block(rng: &mut ChaCha8Rng, spec: &ProceduralSpec, w: f64, h: f64) -> Vec<Lot> {
    let two = w.min(h) >= 75.0 && rng.gen_bool(0.4);
    let mut lots = Vec::new();
    let cells: Vec<(f64, f64, f64, f64)> = if two {
        vec![(0.0, 0.0, w / 2.0, h / 2.0), (w / 2.0, h / 2.0, w, h)]
    } else {
        vec![(0.0, 0.0, w, h)]
    };
    for (cx0, cy0, cx1, cy1) in cells {
        let room = (cx1 - cx0).min(cy1 - cy0) - 8.0;
        let side = len(rng, 24.0f64.min(room), 40.0f64.min(room));
        let side2 = len(rng, (side * 0.7).max(18.0f64.min(room)), side);
        let x0 = q((cx0 + cx1 - side) / 2.0);
        let y0 = q((cy0 + cy1 - side2) / 2.0);
        let fp = if rng.gen_bool(0.3) {
            l_shape(x0, y0, x0 + side, y0 + side2, q(side * 0.4), q(side2 * 0.4), rng.gen_range(0..4u8))
        } else {
            Footprint::rect(x0, y0, x0 + side, y0 + side2)
        };
        lots.push(Lot { footprint: fp, height_m: height(rng, spec.tower_m) });
    }
    lots
}

/// An open plaza, sometimes with a small pavilion in the middle.
fn plaza_block(rng: &mut ChaCha8Rng, w: f64, h: f64) -> Vec<Lot> {
    if !rng.gen_bool(0.5) {
        return Vec::new();
    }
    let s = len(rng, 8.0, 14.0);
    let (x0, y0) = (q((w - s) / 2.0), q((h - s) / 2.0));
    vec![Lot { footprint: Footprint::rect(x0, y0, x0 + s, y0 + s), height_m: height(rng, [4.0, 7.0]) }]
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Layout {
    Perimeter,
    Courtyard,
    Detached,
    Slabs,
    Tower,
    Plaza,
}

/// The extruded LoD1 surfaces of a footprint placed with `place` (block → CRS coordinates): ground
/// (facing down), roof (facing up), and one quad per edge of every ring.
fn extrude(fp: &Footprint, ground_m: f64, top_m: f64, place: &dyn Fn([f64; 2]) -> [f64; 2]) -> Vec<Polygon> {
    let ext: Vec<[f64; 2]> = fp.exterior.iter().map(|&p| place(p)).collect();
    let holes: Vec<Vec<[f64; 2]>> = fp.holes.iter().map(|r| r.iter().map(|&p| place(p)).collect()).collect();
    let at = |ring: &[[f64; 2]], z: f64| ring.iter().map(|p| [p[0], p[1], z]).collect::<Vec<_>>();
    let rev = |ring: &[[f64; 2]]| ring.iter().rev().copied().collect::<Vec<_>>();
    let mut out = Vec::with_capacity(2 + ext.len() + holes.iter().map(Vec::len).sum::<usize>());
    out.push(Polygon {
        exterior: at(&rev(&ext), ground_m),
        interiors: holes.iter().map(|r| at(&rev(r), ground_m)).collect(),
    });
    out.push(Polygon { exterior: at(&ext, top_m), interiors: holes.iter().map(|r| at(r, top_m)).collect() });
    for ring in std::iter::once(&ext).chain(holes.iter()) {
        for i in 0..ring.len() {
            let (a, b) = (ring[i], ring[(i + 1) % ring.len()]);
            out.push(Polygon {
                exterior: vec![
                    [a[0], a[1], ground_m],
                    [b[0], b[1], ground_m],
                    [b[0], b[1], top_m],
                    [a[0], a[1], top_m],
                ],
                interiors: Vec::new(),
            });
        }
    }
    out
}

/// The layout of every block (row-major, `blocks_x` per row): plazas nearest the grid centre first,
/// towers scattered, the rest drawn by weight. `sizes`, `starts` and `extent` are the blocks' widths and
/// depths, their starts and the grid's extent along x and y, metres.
fn block_layouts(
    rng: &mut ChaCha8Rng,
    spec: &ProceduralSpec,
    sizes: [&[f64]; 2],
    starts: [&[f64]; 2],
    extent: [f64; 2],
) -> Vec<Layout> {
    let [widths, depths] = sizes;
    let [x_starts, y_starts] = starts;
    let [extent_x, extent_y] = extent;
    let n_blocks = widths.len() * depths.len();
    let centre_block = |b: usize| {
        let (i, j) = (b % widths.len(), b / widths.len());
        let dx = x_starts[i] + widths[i] / 2.0 - extent_x / 2.0;
        let dy = y_starts[j] + depths[j] / 2.0 - extent_y / 2.0;
        dx * dx + dy * dy
    };
    let mut layouts = vec![Layout::Perimeter; n_blocks];
    let mut order: Vec<usize> = (0..n_blocks).collect();
    order.shuffle(rng);
    let mut by_centre = order.clone();
    by_centre.sort_by(|&a, &b| centre_block(a).total_cmp(&centre_block(b)));
    for &b in by_centre.iter().take(spec.plaza_blocks as usize) {
        layouts[b] = Layout::Plaza;
    }
    let mut towers = 0;
    for &b in &order {
        if towers == spec.tower_blocks {
            break;
        }
        if layouts[b] == Layout::Perimeter {
            layouts[b] = Layout::Tower;
            towers += 1;
        }
    }
    for layout in layouts.iter_mut().filter(|l| **l == Layout::Perimeter) {
        *layout = match rng.gen_range(0..100u32) {
            0..=44 => Layout::Perimeter,
            45..=59 => Layout::Courtyard,
            60..=84 => Layout::Detached,
            _ => Layout::Slabs,
        };
    }
    layouts
}

/// Generates the demo city described by `spec`, centred on `origin` (EPSG:6677).
///
/// # Units
/// Coordinates are EPSG:6677 (easting, northing) metres and orthometric height H in metres.
///
/// # Errors
/// [`LodError::Invalid`] naming the parameter when `spec` is out of range (see
/// [`ProceduralSpec::validate`]) or the origin is not finite.
pub fn generate(spec: &ProceduralSpec, origin: PlaneOrigin) -> Result<SourceModel, LodError> {
    spec.validate()?;
    if !(origin.easting_m.is_finite() && origin.northing_m.is_finite()) {
        return Err(LodError::invalid(
            DEMO_SOURCE_PATH,
            "origin",
            ProceduralProblem::Origin { easting_m: origin.easting_m, northing_m: origin.northing_m },
        ));
    }
    let mut rng = ChaCha8Rng::seed_from_u64(spec.seed);

    // Column widths and row heights (±20 %), and the streets between them.
    let widths: Vec<f64> =
        (0..spec.blocks_x).map(|_| len(&mut rng, spec.block_size_m * 0.8, spec.block_size_m * 1.2)).collect();
    let depths: Vec<f64> =
        (0..spec.blocks_y).map(|_| len(&mut rng, spec.block_size_m * 0.8, spec.block_size_m * 1.2)).collect();
    let street = |i: usize| {
        if spec.avenue_every > 0 && i.is_multiple_of(spec.avenue_every as usize) {
            q(spec.avenue_width_m)
        } else {
            q(spec.street_width_m)
        }
    };
    let starts = |sizes: &[f64]| {
        let mut at = 0.0;
        let mut v = Vec::with_capacity(sizes.len());
        for (i, s) in sizes.iter().enumerate() {
            if i > 0 {
                at += street(i);
            }
            v.push(at);
            at += s;
        }
        (v, at)
    };
    let (x_starts, extent_x) = starts(&widths);
    let (y_starts, extent_y) = starts(&depths);

    let layouts =
        block_layouts(&mut rng, spec, [&widths, &depths], [&x_starts, &y_starts], [extent_x, extent_y]);

    let (sin, cos) = spec.grid_rotation_deg.to_radians().sin_cos();
    let (cx, cy) = (extent_x / 2.0, extent_y / 2.0);
    let mut lots_placed: Vec<(Lot, f64, f64)> = Vec::new();
    for j in 0..depths.len() {
        for i in 0..widths.len() {
            let (w, h) = (widths[i], depths[j]);
            let lots = match layouts[j * widths.len() + i] {
                Layout::Perimeter => perimeter_block(&mut rng, spec, w, h),
                Layout::Courtyard => courtyard_block(&mut rng, spec, w, h),
                Layout::Detached => detached_block(&mut rng, spec, w, h),
                Layout::Slabs => slab_block(&mut rng, spec, w, h),
                Layout::Tower => tower_block(&mut rng, spec, w, h),
                Layout::Plaza => plaza_block(&mut rng, w, h),
            };
            lots_placed.extend(lots.into_iter().map(|l| (l, x_starts[i], y_starts[j])));
        }
    }

    let width = lots_placed.len().to_string().len().max(4);
    let ground = spec.ground_height_m;
    let mut stats = ReadStats::default();
    let buildings: Vec<SourceBuilding> = lots_placed
        .iter()
        .enumerate()
        .map(|(k, (lot, bx, by))| {
            // Block → grid (exact) → rotated about the grid centre → CRS.
            let place = |p: [f64; 2]| {
                let (gx, gy) = (bx + p[0] - cx, by + p[1] - cy);
                [origin.easting_m + cos * gx - sin * gy, origin.northing_m + sin * gx + cos * gy]
            };
            let polygons = extrude(&lot.footprint, ground, ground + lot.height_m, &place);
            stats.faces += polygons.len() as u64;
            SourceBuilding {
                source_id: format!("demo_b{:0width$}", k + 1),
                lod: "1".into(),
                measured_height_m: Some(lot.height_m),
                ground_heights_m: Vec::new(),
                geometry: Geometry::Polygons(polygons),
                appearance: Vec::new(),
            }
        })
        .collect();

    Ok(SourceModel {
        path: PathBuf::from(DEMO_SOURCE_PATH),
        frame: Frame::Crs { name: Some(DEMO_CRS.to_string()), axes: AxisConvention::EastNorth },
        buildings,
        stats,
        appearance: Default::default(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    mod shapes {
        use super::*;

        /// Twice the signed area (shoelace); positive = counter-clockwise.
        fn area2(r: &[[f64; 2]]) -> f64 {
            (0..r.len()).map(|i| r[i][0] * r[(i + 1) % r.len()][1] - r[(i + 1) % r.len()][0] * r[i][1]).sum()
        }

        #[test]
        fn l_and_u_shapes_are_counter_clockwise_with_the_expected_area() {
            // 20 × 10 rectangle minus a 6 × 4 notch = 176 m² (hand computation).
            for c in 0..4 {
                let fp = l_shape(0.0, 0.0, 20.0, 10.0, 6.0, 4.0, c);
                assert_eq!(area2(&fp.exterior), 2.0 * 176.0, "corner {c}");
            }
            // 20 × 10 minus a notch 20 − 2·5 = 10 wide and 4 deep (open south/north) = 160 m²;
            // open east/west with arms of 3: the notch is 10 − 2·3 = 4 wide and 4 deep = 184 m².
            for side in [0, 2] {
                assert_eq!(area2(&u_shape(0.0, 0.0, 20.0, 10.0, 5.0, 4.0, side).exterior), 2.0 * 160.0);
            }
            for side in [1, 3] {
                assert_eq!(area2(&u_shape(0.0, 0.0, 20.0, 10.0, 3.0, 4.0, side).exterior), 2.0 * 184.0);
            }
        }

        #[test]
        fn side_frames_map_the_corners_of_a_block() {
            let (w, h) = (100.0, 60.0);
            // Each side frame's origin is that side's start corner, going counter-clockwise.
            assert_eq!(side_to_block(0, [0.0, 0.0], w, h), [0.0, 0.0]);
            assert_eq!(side_to_block(1, [0.0, 0.0], w, h), [100.0, 0.0]);
            assert_eq!(side_to_block(2, [0.0, 0.0], w, h), [100.0, 60.0]);
            assert_eq!(side_to_block(3, [0.0, 0.0], w, h), [0.0, 60.0]);
            // And its x axis runs along the side: the end of side 1 (length h) is the NE corner.
            assert_eq!(side_to_block(1, [60.0, 0.0], w, h), [100.0, 60.0]);
            assert_eq!(side_to_block(3, [60.0, 0.0], w, h), [0.0, 0.0]);
            // y points into the block.
            assert_eq!(side_to_block(2, [0.0, 5.0], w, h), [100.0, 55.0]);
        }
    }

    mod spec {
        use super::*;

        #[test]
        fn toml_subset_takes_defaults() {
            let s: ProceduralSpec = toml::from_str("seed = 7\nblocks_x = 3").unwrap();
            assert_eq!(s.seed, 7);
            assert_eq!(s.blocks_x, 3);
            assert_eq!(s.blocks_y, default_spec().blocks_y);
        }

        #[test]
        fn unknown_key_is_rejected() {
            let e = toml::from_str::<ProceduralSpec>("blocks = 3").unwrap_err().to_string();
            assert!(e.contains("unknown field `blocks`"), "{e}");
        }

        #[test]
        fn bad_values_name_the_field() {
            let cases: Vec<(ProceduralSpec, &str)> = vec![
                (ProceduralSpec { blocks_x: 0, ..default_spec() }, "procedural.blocks_x"),
                (ProceduralSpec { block_size_m: f64::NAN, ..default_spec() }, "procedural.block_size_m"),
                (ProceduralSpec { avenue_width_m: 5.0, ..default_spec() }, "procedural.avenue_width_m"),
                (ProceduralSpec { tower_m: [200.0, 80.0], ..default_spec() }, "procedural.tower_m"),
                (ProceduralSpec { blocks_x: 1, blocks_y: 2, ..default_spec() }, "procedural.tower_blocks"),
            ];
            for (s, field) in cases {
                let e = generate(&s, PlaneOrigin::TOKYO_BAY).unwrap_err().to_string();
                assert!(e.contains(field), "{e}");
            }
        }
    }
}
