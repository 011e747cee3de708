//! City clutter: streets, pavements, lane markings, ground cover, trees, cars and rooftop equipment,
//! generated from the building footprints and the area polygon, seeded and deterministic.
//!
//! The generator works on a plan grid over the area (cells of [`ClutterSpec::cell_m`], coarsened so the
//! grid stays under [`MAX_CELLS`]):
//!
//! 1. the buildings' up-facing triangles are rasterised (cell centre inside) into a footprint mask;
//! 2. a two-pass chamfer distance transform gives every open cell its distance to the nearest footprint,
//!    in metres, and carries that building's base height (the local ground level);
//! 3. each open cell inside the area gets a class from its distance `d`: nothing within
//!    [`CLEARANCE_M`] of a facade; pavement up to [`PAVEMENT_WIDTH_M`]; ground cover (parks) where a
//!    second distance transform puts it within [`PARK_REACH_M`] of a cell farther than
//!    [`PARK_CORE_M`] from every building; road elsewhere. Road cells on the distance ridge (the
//!    street's centre line) of streets at least 2 × [`MARKING_MIN_HALF_WIDTH_M`] wide get dashed lane
//!    markings;
//! 4. trees (three species, sizes drawn per tree) on a jittered lattice in parks and along pavements,
//!    each crown kept [`CLEARANCE_M`] clear of every footprint; cars parked along the kerb and driving
//!    in the lanes, oriented along the street (perpendicular to the distance gradient), each on road
//!    cells only and never overlapping another car or a tree; rooftop units (boxes and tanks) on the
//!    flat top of each building whose flat roof has at least [`ROOF_MIN_AREA_M2`], inside the roof.
//!
//! Ground layers are merged rectangles of same-class, same-height cells, a few centimetres above the
//! local ground so they cover the RGB ground plane. Every layer is one triangle mesh with a per-vertex
//! sRGB colour (tree shades, car paint, asphalt, grass …). Trees, cars and units are instances of a few
//! templates (species, car body, unit shape) scaled and rotated per instance, then baked into their
//! layer's mesh (one mesh per layer keeps the scene GLB and the Blender import small); the manifest
//! counts the instances per layer and species.
//!
//! # Determinism
//! Every random draw comes from one ChaCha8 stream seeded with [`ClutterSpec::seed`], consumed in a
//! fixed order (cells row-major, buildings by ID), so the same scene and seed give the same bytes.
//!
//! # Units
//! ENU metres relative to the area origin (x east, y north, z up), like [`SceneMesh`].

use std::collections::BTreeMap;

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use super::artifact::BuildingRecord;
use super::mesh::SceneMesh;

/// Most cells of the plan grid; the cell grows past [`ClutterSpec::cell_m`] for larger areas.
pub const MAX_CELLS: usize = 8_000_000;
/// Open space kept between any clutter on the ground and a building footprint, metres.
pub const CLEARANCE_M: f64 = 0.6;
/// Pavement width along facades, metres (measured from the footprint).
pub const PAVEMENT_WIDTH_M: f64 = 3.0;
/// A cell this far from every building seeds a park, metres.
pub const PARK_CORE_M: f64 = 14.0;
/// Parks extend this far from their core cells, metres.
pub const PARK_REACH_M: f64 = 10.0;
/// Lane markings only on streets whose centre is at least this far from the facades, metres.
pub const MARKING_MIN_HALF_WIDTH_M: f64 = 6.5;
/// Smallest flat roof (highest flat part of a building) that gets rooftop units, m².
pub const ROOF_MIN_AREA_M2: f64 = 40.0;

/// Height of each ground layer above the local ground, metres (pavements stand as kerbs).
const ROAD_Z_M: f64 = 0.02;
const GROUND_COVER_Z_M: f64 = 0.03;
const MARKING_Z_M: f64 = 0.05;
const PAVEMENT_Z_M: f64 = 0.12;

/// The clutter layers, in the order they are written.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ClutterLayer {
    /// Asphalt in the open space between buildings.
    Roads,
    /// Dashed centre lines of wide roads.
    Markings,
    /// Raised pavements along the facades.
    Pavements,
    /// Grass and dry patches of parks.
    GroundCover,
    /// Trees (trunk and crown).
    Trees,
    /// Parked and driving cars.
    Cars,
    /// Units and tanks on flat roofs.
    Rooftop,
}

impl ClutterLayer {
    /// Every layer, in file order.
    pub const ALL: [ClutterLayer; 7] = [
        ClutterLayer::Roads,
        ClutterLayer::Markings,
        ClutterLayer::Pavements,
        ClutterLayer::GroundCover,
        ClutterLayer::Trees,
        ClutterLayer::Cars,
        ClutterLayer::Rooftop,
    ];
    /// The layers that hide buildings in the masks unless told otherwise: the ones that stand up
    /// beside the buildings. Rooftop units are not among them: they stand on their building's roof and
    /// belong to it, as a segmenter should learn (as occluders they punched holes in the roof masks).
    pub const DEFAULT_OCCLUDERS: [ClutterLayer; 2] = [ClutterLayer::Trees, ClutterLayer::Cars];

    /// The layer's name in files and on the command line.
    pub fn name(self) -> &'static str {
        match self {
            ClutterLayer::Roads => "roads",
            ClutterLayer::Markings => "markings",
            ClutterLayer::Pavements => "pavements",
            ClutterLayer::GroundCover => "ground_cover",
            ClutterLayer::Trees => "trees",
            ClutterLayer::Cars => "cars",
            ClutterLayer::Rooftop => "rooftop",
        }
    }

    /// The layer of a name (see [`ClutterLayer::name`]).
    pub fn from_name(name: &str) -> Option<ClutterLayer> {
        ClutterLayer::ALL.into_iter().find(|l| l.name() == name)
    }

    /// Whether the layer lies flat on the ground (its geometry must stay off the footprints).
    pub fn is_ground(self) -> bool {
        matches!(
            self,
            ClutterLayer::Roads
                | ClutterLayer::Markings
                | ClutterLayer::Pavements
                | ClutterLayer::GroundCover
        )
    }
}

impl std::fmt::Display for ClutterLayer {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// Parses a comma-separated layer list: layer names, `all` or `none`.
///
/// # Errors
/// [`UnknownLayer`] naming the unknown word (its message lists the accepted names).
pub fn parse_layers(list: &str) -> Result<Vec<ClutterLayer>, UnknownLayer> {
    let mut out = Vec::new();
    for word in list.split(',').map(str::trim).filter(|w| !w.is_empty()) {
        match word {
            "all" => out.extend(ClutterLayer::ALL),
            "none" => {}
            _ => out
                .push(ClutterLayer::from_name(word).ok_or_else(|| UnknownLayer { word: word.to_string() })?),
        }
    }
    out.sort();
    out.dedup();
    Ok(out)
}

/// A word of a layer list that is not a layer name, `all` or `none`.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error(
    "unknown clutter layer {word:?}; expected all, none or any of {}",
    ClutterLayer::ALL.map(ClutterLayer::name).join(", ")
)]
pub struct UnknownLayer {
    /// The word as given.
    pub word: String,
}

/// What to generate.
#[derive(Debug, Clone, PartialEq)]
pub struct ClutterSpec {
    /// Seed of every random draw.
    pub seed: u64,
    /// Plan grid cell, metres (grown for large areas, see [`MAX_CELLS`]).
    pub cell_m: f64,
    /// Trees per 100 m² of park (on a jittered lattice; 1 ≈ one tree every 10 m).
    pub park_trees_per_100m2: f64,
    /// Chance that a lattice point along a pavement gets a street tree.
    pub street_tree_chance: f64,
    /// Chance per kerb-side road cell that a parked car is tried there.
    pub parked_car_chance: f64,
    /// Chance per lane road cell that a driving car is tried there.
    pub driving_car_chance: f64,
}

impl Default for ClutterSpec {
    fn default() -> Self {
        ClutterSpec {
            seed: 16,
            cell_m: 0.5,
            park_trees_per_100m2: 0.6,
            street_tree_chance: 0.55,
            parked_car_chance: 0.05,
            driving_car_chance: 0.012,
        }
    }
}

/// One layer's triangles: ENU metres relative to the area origin, one sRGB colour per vertex.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct LayerMesh {
    /// Vertex positions, ENU metres relative to the area origin.
    pub positions_m: Vec<[f32; 3]>,
    /// Vertex colours, sRGB.
    pub colors_srgb: Vec<[u8; 3]>,
    /// Triangle vertex indices, three per triangle.
    pub indices: Vec<u32>,
}

impl LayerMesh {
    /// Number of triangles.
    pub fn triangle_count(&self) -> usize {
        self.indices.len() / 3
    }

    fn vertex(&mut self, p: [f64; 3], c: [u8; 3]) -> u32 {
        self.positions_m.push([p[0] as f32, p[1] as f32, p[2] as f32]);
        self.colors_srgb.push(c);
        (self.positions_m.len() - 1) as u32
    }

    /// A horizontal quad (counter-clockwise seen from above).
    fn quad(&mut self, corners: [[f64; 2]; 4], z: f64, c: [u8; 3]) {
        let v = corners.map(|p| self.vertex([p[0], p[1], z], c));
        self.indices.extend_from_slice(&[v[0], v[1], v[2], v[0], v[2], v[3]]);
    }

    /// A prism: a convex ring (counter-clockwise, z = z0) extruded to z1, with a cap on top, optionally
    /// tapering to `top_scale` of its size at the top (0 = a cone).
    fn prism(&mut self, ring: &[[f64; 2]], centre: [f64; 2], z0: f64, z1: f64, top_scale: f64, c: [u8; 3]) {
        let n = ring.len();
        let top = |p: [f64; 2]| {
            [centre[0] + (p[0] - centre[0]) * top_scale, centre[1] + (p[1] - centre[1]) * top_scale]
        };
        for i in 0..n {
            let (a, b) = (ring[i], ring[(i + 1) % n]);
            let (ta, tb) = (top(a), top(b));
            let v0 = self.vertex([a[0], a[1], z0], c);
            let v1 = self.vertex([b[0], b[1], z0], c);
            let v2 = self.vertex([tb[0], tb[1], z1], c);
            let v3 = self.vertex([ta[0], ta[1], z1], c);
            self.indices.extend_from_slice(&[v0, v1, v2, v0, v2, v3]);
        }
        if top_scale > 0.0 {
            let first = self.vertex([top(ring[0])[0], top(ring[0])[1], z1], c);
            for i in 1..n - 1 {
                let a = self.vertex([top(ring[i])[0], top(ring[i])[1], z1], c);
                let b = self.vertex([top(ring[i + 1])[0], top(ring[i + 1])[1], z1], c);
                self.indices.extend_from_slice(&[first, a, b]);
            }
        }
    }

    /// A low-poly spheroid (8 segments, 4 bands) centred at `c_m` with radii `r_m` (horizontal) and
    /// `h_m` (vertical).
    fn spheroid(&mut self, c_m: [f64; 3], r_m: f64, h_m: f64, colour: [u8; 3], shade: [u8; 3]) {
        const SEG: usize = 8;
        const BANDS: usize = 4;
        let mut rows: Vec<Vec<u32>> = Vec::with_capacity(BANDS + 1);
        for b in 0..=BANDS {
            let phi = std::f64::consts::PI * b as f64 / BANDS as f64; // 0 = top
            let (s, z) = (phi.sin(), phi.cos());
            // Lower bands darker: a cheap self-shadowing cue that survives flat shading.
            let t = b as f64 / BANDS as f64;
            let col = [0, 1, 2].map(|k| (colour[k] as f64 * (1.0 - t) + shade[k] as f64 * t).round() as u8);
            let count = if b == 0 || b == BANDS { 1 } else { SEG };
            let row = (0..count)
                .map(|i| {
                    let a = std::f64::consts::TAU * (i as f64 + 0.5 * (b % 2) as f64) / SEG as f64;
                    self.vertex(
                        [c_m[0] + r_m * s * a.cos(), c_m[1] + r_m * s * a.sin(), c_m[2] + h_m * z],
                        col,
                    )
                })
                .collect();
            rows.push(row);
        }
        for b in 0..BANDS {
            let (up, down) = (&rows[b], &rows[b + 1]);
            for i in 0..SEG {
                let j = (i + 1) % SEG;
                match (up.len(), down.len()) {
                    (1, _) => self.indices.extend_from_slice(&[up[0], down[i], down[j]]),
                    (_, 1) => self.indices.extend_from_slice(&[up[i], down[0], up[j]]),
                    _ => self.indices.extend_from_slice(&[up[i], down[i], down[j], up[i], down[j], up[j]]),
                }
            }
        }
    }

    /// An oriented box: centre (x, y), base z0, half lengths along `dir` and across it, height.
    #[allow(clippy::too_many_arguments)]
    fn oriented_box(
        &mut self,
        centre: [f64; 2],
        dir: [f64; 2],
        half_len_m: f64,
        half_wid_m: f64,
        z0: f64,
        height_m: f64,
        c: [u8; 3],
    ) {
        let ring = rectangle(centre, dir, half_len_m, half_wid_m);
        self.prism(&ring, centre, z0, z0 + height_m, 1.0, c);
    }
}

/// The four corners (counter-clockwise) of a rectangle along unit `dir`.
fn rectangle(centre: [f64; 2], dir: [f64; 2], half_len_m: f64, half_wid_m: f64) -> [[f64; 2]; 4] {
    let n = [-dir[1], dir[0]];
    let at = |a: f64, b: f64| [centre[0] + a * dir[0] + b * n[0], centre[1] + a * dir[1] + b * n[1]];
    [
        at(-half_len_m, -half_wid_m),
        at(half_len_m, -half_wid_m),
        at(half_len_m, half_wid_m),
        at(-half_len_m, half_wid_m),
    ]
}

/// What the manifest records of one layer.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LayerSummary {
    /// Layer name ([`ClutterLayer::name`]); also the glTF node `insgen_clutter_<name>`.
    pub name: ClutterLayer,
    /// Triangles in the layer.
    pub triangles: u64,
    /// Objects in the layer (trees, cars, units; merged rectangles for ground layers).
    pub instances: u64,
    /// Whether the masks treat the layer as an occluder unless told otherwise.
    pub default_occluder: bool,
}

/// The manifest's `clutter` section.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ClutterSummary {
    /// Seed of every random draw.
    pub seed: u64,
    /// Plan grid cell used, metres.
    pub cell_m: f64,
    /// The non-empty layers, in file order.
    pub layers: Vec<LayerSummary>,
    /// Trees per species.
    pub tree_species: BTreeMap<String, u64>,
    /// Open area per ground class, m².
    pub ground_area_m2: BTreeMap<String, f64>,
}

/// The generated layers (non-empty ones only, in [`ClutterLayer::ALL`] order) and their summary.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Clutter {
    /// The non-empty layers and their meshes, in [`ClutterLayer::ALL`] order.
    pub layers: Vec<(ClutterLayer, LayerMesh)>,
}

impl Clutter {
    /// The mesh of one layer, if present.
    pub fn layer(&self, layer: ClutterLayer) -> Option<&LayerMesh> {
        self.layers.iter().find(|(l, _)| *l == layer).map(|(_, m)| m)
    }

    /// The chosen layers appended to `mesh` as occluders: their triangles with the background ID 0, so
    /// an ID renderer draws them into the depth test and writes "no building" where they are in front.
    pub fn append_occluders(&self, mesh: &mut SceneMesh, layers: &[ClutterLayer]) {
        for (layer, m) in &self.layers {
            if !layers.contains(layer) {
                continue;
            }
            let base = mesh.positions_m.len() as u32;
            mesh.positions_m.extend_from_slice(&m.positions_m);
            mesh.building_ids.extend(std::iter::repeat_n(super::BuildingId::BACKGROUND, m.positions_m.len()));
            mesh.indices.extend(m.indices.iter().map(|i| i + base));
        }
    }
}

/// Cell classes of the plan grid.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
#[repr(u8)]
enum Class {
    None = 0,
    Road,
    Pavement,
    Park,
}

/// The plan grid: cell (i, j) covers x ∈ [x0 + i·cell, x0 + (i+1)·cell), likewise y.
struct Grid {
    x0_m: f64,
    y0_m: f64,
    cell_m: f64,
    nx: usize,
    ny: usize,
}

impl Grid {
    fn centre(&self, i: usize, j: usize) -> [f64; 2] {
        [self.x0_m + (i as f64 + 0.5) * self.cell_m, self.y0_m + (j as f64 + 0.5) * self.cell_m]
    }
    fn cell_of(&self, p: [f64; 2]) -> Option<(usize, usize)> {
        let i = ((p[0] - self.x0_m) / self.cell_m).floor();
        let j = ((p[1] - self.y0_m) / self.cell_m).floor();
        (i >= 0.0 && j >= 0.0 && (i as usize) < self.nx && (j as usize) < self.ny)
            .then_some((i as usize, j as usize))
    }
}

/// Two-pass chamfer distance (metres) to the nearest source cell, carrying a value from that source.
/// `dist` holds 0 at sources and +∞ elsewhere on entry.
fn chamfer(g: &Grid, dist: &mut [f32], carry: &mut [f32]) {
    let a = g.cell_m as f32;
    let b = a * std::f32::consts::SQRT_2;
    let (nx, ny) = (g.nx, g.ny);
    let relax = |dist: &mut [f32], carry: &mut [f32], k: usize, n: usize, w: f32| {
        let d = dist[n] + w;
        if d < dist[k] {
            dist[k] = d;
            carry[k] = carry[n];
        }
    };
    for j in 0..ny {
        for i in 0..nx {
            let k = j * nx + i;
            if i > 0 {
                relax(dist, carry, k, k - 1, a);
            }
            if j > 0 {
                relax(dist, carry, k, k - nx, a);
                if i > 0 {
                    relax(dist, carry, k, k - nx - 1, b);
                }
                if i + 1 < nx {
                    relax(dist, carry, k, k - nx + 1, b);
                }
            }
        }
    }
    for j in (0..ny).rev() {
        for i in (0..nx).rev() {
            let k = j * nx + i;
            if i + 1 < nx {
                relax(dist, carry, k, k + 1, a);
            }
            if j + 1 < ny {
                relax(dist, carry, k, k + nx, a);
                if i + 1 < nx {
                    relax(dist, carry, k, k + nx + 1, b);
                }
                if i > 0 {
                    relax(dist, carry, k, k + nx - 1, b);
                }
            }
        }
    }
}

/// Cells of row `j` inside the polygon (even-odd rule at the cell centres).
fn row_inside(g: &Grid, poly: &[[f64; 2]], j: usize, out: &mut [bool]) {
    out.fill(false);
    let y = g.centre(0, j)[1];
    let mut xs = Vec::new();
    for k in 0..poly.len() {
        let (a, b) = (poly[k], poly[(k + 1) % poly.len()]);
        if (a[1] > y) != (b[1] > y) {
            xs.push(a[0] + (y - a[1]) / (b[1] - a[1]) * (b[0] - a[0]));
        }
    }
    xs.sort_by(f64::total_cmp);
    for pair in xs.chunks_exact(2) {
        let i0 = ((pair[0] - g.x0_m) / g.cell_m - 0.5).ceil().max(0.0) as usize;
        let i1 = (((pair[1] - g.x0_m) / g.cell_m - 0.5).floor() + 1.0).clamp(0.0, g.nx as f64) as usize;
        for v in out.iter_mut().take(i1).skip(i0) {
            *v = true;
        }
    }
}

/// Colours (sRGB).
const ASPHALT: [[u8; 3]; 3] = [[58, 58, 60], [66, 65, 66], [50, 51, 54]];
const PAVEMENT: [[u8; 3]; 2] = [[150, 146, 140], [168, 164, 156]];
const GRASS: [[u8; 3]; 4] = [[74, 104, 44], [88, 118, 52], [104, 118, 58], [128, 124, 78]];
const MARKING: [u8; 3] = [226, 226, 220];
const TRUNK: [u8; 3] = [84, 62, 44];
const CAR_PAINT: [[u8; 3]; 8] = [
    [236, 236, 236],
    [28, 28, 30],
    [170, 172, 176],
    [110, 112, 116],
    [150, 24, 28],
    [30, 60, 130],
    [210, 210, 204],
    [60, 80, 60],
];
const GLASS: [u8; 3] = [40, 48, 58];
const UNIT: [[u8; 3]; 3] = [[190, 192, 194], [160, 162, 160], [120, 124, 128]];

/// A tree species: crown shape, height and crown-radius ranges (metres), crown colours.
struct Species {
    name: &'static str,
    conifer: bool,
    height_m: [f64; 2],
    crown_r_m: [f64; 2],
    crown: [[u8; 3]; 3],
}

const SPECIES: [Species; 3] = [
    Species {
        name: "broadleaf",
        conifer: false,
        height_m: [7.0, 15.0],
        crown_r_m: [2.5, 5.0],
        crown: [[52, 92, 36], [70, 108, 40], [88, 112, 46]],
    },
    Species {
        name: "conifer",
        conifer: true,
        height_m: [8.0, 16.0],
        crown_r_m: [1.6, 3.0],
        crown: [[30, 64, 38], [38, 74, 44], [46, 70, 36]],
    },
    Species {
        name: "small_round",
        conifer: false,
        height_m: [3.5, 6.0],
        crown_r_m: [1.3, 2.3],
        crown: [[80, 116, 48], [98, 128, 56], [110, 120, 50]],
    },
];

/// Generates the clutter of an area.
///
/// `mesh` and `buildings` are the instanced scene; `area_polygon_enu_m` bounds the ground layers;
/// `ground_enu_m` is the ground level where no building is near.
pub fn generate(
    spec: &ClutterSpec,
    mesh: &SceneMesh,
    buildings: &[BuildingRecord],
    area_polygon_enu_m: &[[f64; 2]],
    ground_enu_m: f64,
) -> (Clutter, ClutterSummary) {
    let mut rng = ChaCha8Rng::seed_from_u64(spec.seed);
    let mut summary = ClutterSummary {
        seed: spec.seed,
        cell_m: spec.cell_m,
        layers: Vec::new(),
        tree_species: BTreeMap::new(),
        ground_area_m2: BTreeMap::new(),
    };
    let Some(g) = plan_grid(spec, buildings, area_polygon_enu_m) else {
        return (Clutter::default(), summary);
    };
    summary.cell_m = g.cell_m;
    let plan = Plan::new(g, mesh, buildings, area_polygon_enu_m, ground_enu_m);
    let ground = GroundLayers::build(&plan, spec.seed);
    let (markings, n_mark) = lane_markings(&plan);
    summary.ground_area_m2 = plan.ground_areas_m2();
    let mut occupied = vec![false; plan.class.len()]; // cells taken by a tree trunk zone or a car
    let (trees, n_trees) = plant_trees(&plan, spec, &mut rng, &mut occupied, &mut summary.tree_species);
    let (cars, n_cars) = place_cars(&plan, spec, &mut rng, &mut occupied);
    let (rooftop, n_units) = place_rooftop_units(mesh, buildings, &mut rng);

    let mut clutter = Clutter::default();
    let counts = [
        (ClutterLayer::Roads, ground.roads, ground.n_road),
        (ClutterLayer::Markings, markings, n_mark),
        (ClutterLayer::Pavements, ground.pavements, ground.n_pave),
        (ClutterLayer::GroundCover, ground.cover, ground.n_cover),
        (ClutterLayer::Trees, trees, n_trees),
        (ClutterLayer::Cars, cars, n_cars),
        (ClutterLayer::Rooftop, rooftop, n_units),
    ];
    for (layer, m, count) in counts {
        if m.indices.is_empty() {
            continue;
        }
        summary.layers.push(LayerSummary {
            name: layer,
            triangles: m.triangle_count() as u64,
            instances: count,
            default_occluder: ClutterLayer::DEFAULT_OCCLUDERS.contains(&layer),
        });
        clutter.layers.push((layer, m));
    }
    (clutter, summary)
}

/// The plan grid spanning the area polygon and the buildings (plus 1 m on every side), its cell grown
/// past [`ClutterSpec::cell_m`] so it stays under [`MAX_CELLS`]; `None` when there is nothing to span.
fn plan_grid(
    spec: &ClutterSpec,
    buildings: &[BuildingRecord],
    area_polygon_enu_m: &[[f64; 2]],
) -> Option<Grid> {
    let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
    for p in area_polygon_enu_m {
        lo = [lo[0].min(p[0]), lo[1].min(p[1])];
        hi = [hi[0].max(p[0]), hi[1].max(p[1])];
    }
    for b in buildings {
        lo = [lo[0].min(b.bbox_min_enu_m[0]), lo[1].min(b.bbox_min_enu_m[1])];
        hi = [hi[0].max(b.bbox_max_enu_m[0]), hi[1].max(b.bbox_max_enu_m[1])];
    }
    if !(lo[0].is_finite() && hi[0].is_finite() && hi[0] > lo[0] && hi[1] > lo[1]) {
        return None;
    }
    let (w, h) = (hi[0] - lo[0] + 2.0, hi[1] - lo[1] + 2.0);
    let cell_m = spec.cell_m.max((w * h / MAX_CELLS as f64).sqrt());
    Some(Grid {
        x0_m: lo[0] - 1.0,
        y0_m: lo[1] - 1.0,
        cell_m,
        nx: (w / cell_m).ceil() as usize,
        ny: (h / cell_m).ceil() as usize,
    })
}

/// The classified plan grid (steps 1–3 of the module doc), row-major like [`Grid`].
struct Plan {
    g: Grid,
    /// Chamfer distance to the (dilated) footprints, metres; 0 on them.
    dist: Vec<f32>,
    /// The local ground level: the nearest building's base height, metres.
    ground: Vec<f32>,
    class: Vec<Class>,
}

impl Plan {
    fn new(
        g: Grid,
        mesh: &SceneMesh,
        buildings: &[BuildingRecord],
        area_polygon_enu_m: &[[f64; 2]],
        ground_enu_m: f64,
    ) -> Plan {
        let (mut dist, mut ground) = rasterise_footprints(&g, mesh, buildings, ground_enu_m);
        dilate_footprints(&g, &mut dist, &mut ground);
        // 2. Distance to the (dilated) footprints, and the nearest building's base as the local ground.
        chamfer(&g, &mut dist, &mut ground);
        let mut plan = Plan { class: vec![Class::None; g.nx * g.ny], g, dist, ground };
        plan.classify(area_polygon_enu_m);
        plan
    }

    /// Distance of cell `k` to the nearest footprint, metres. The dilation already took one cell:
    /// distances are from its outer edge, so it is added back.
    fn d_at(&self, k: usize) -> f64 {
        if self.dist[k] == 0.0 {
            0.0
        } else {
            self.dist[k] as f64 + 0.5 * self.g.cell_m
        }
    }

    /// Step 3, classes: pavement, road and park cells inside the area, clear of the facades.
    fn classify(&mut self, area_polygon_enu_m: &[[f64; 2]]) {
        let g = &self.g;
        let n = g.nx * g.ny;
        let mut inside = vec![false; g.nx];
        let mut core = vec![f32::INFINITY; n];
        let mut core_carry = vec![0f32; n];
        for j in 0..g.ny {
            row_inside(g, area_polygon_enu_m, j, &mut inside);
            for (i, &in_area) in inside.iter().enumerate() {
                let k = j * g.nx + i;
                if !in_area || self.d_at(k) < CLEARANCE_M {
                    continue;
                }
                self.class[k] = if self.d_at(k) < PAVEMENT_WIDTH_M { Class::Pavement } else { Class::Road };
                if self.d_at(k) >= PARK_CORE_M {
                    core[k] = 0.0;
                }
            }
        }
        chamfer(g, &mut core, &mut core_carry);
        for (k, &core_m) in core.iter().enumerate() {
            if self.class[k] == Class::Road && self.d_at(k) >= 4.0 && (core_m as f64) <= PARK_REACH_M {
                self.class[k] = Class::Park;
            }
        }
    }

    /// Open area per ground class, m² (rounded), as the manifest records it.
    fn ground_areas_m2(&self) -> BTreeMap<String, f64> {
        let cell_area = self.g.cell_m * self.g.cell_m;
        let mut out = BTreeMap::new();
        for (name, c) in
            [("roads", Class::Road), ("pavements", Class::Pavement), ("ground_cover", Class::Park)]
        {
            let cells = self.class.iter().filter(|&&x| x == c).count();
            out.insert(name.into(), (cells as f64 * cell_area).round());
        }
        out
    }
}

/// Step 1, footprints: cell centres inside an up-facing triangle get distance 0 and their building's base
/// height; every other cell gets +∞ and `ground_enu_m`. Returns (distance, ground).
fn rasterise_footprints(
    g: &Grid,
    mesh: &SceneMesh,
    buildings: &[BuildingRecord],
    ground_enu_m: f64,
) -> (Vec<f32>, Vec<f32>) {
    let (cell_m, n) = (g.cell_m, g.nx * g.ny);
    let base_of: BTreeMap<u32, f64> = buildings.iter().map(|b| (b.id.get(), b.bbox_min_enu_m[2])).collect();
    let mut dist = vec![f32::INFINITY; n];
    let mut ground = vec![ground_enu_m as f32; n];
    for tri in mesh.indices.chunks_exact(3) {
        let [a, b, c] = [tri[0], tri[1], tri[2]].map(|i| mesh.positions_m[i as usize].map(f64::from));
        let area2 = (b[0] - a[0]) * (c[1] - a[1]) - (c[0] - a[0]) * (b[1] - a[1]);
        if area2.abs() < 1e-6 {
            continue;
        }
        let base = base_of.get(&mesh.building_ids[tri[0] as usize].get()).copied().unwrap_or(ground_enu_m);
        let s = area2.signum();
        let i0 = ((a[0].min(b[0]).min(c[0]) - g.x0_m) / cell_m - 0.5).floor().max(0.0) as usize;
        let i1 = (((a[0].max(b[0]).max(c[0]) - g.x0_m) / cell_m).ceil() as usize).min(g.nx);
        let j0 = ((a[1].min(b[1]).min(c[1]) - g.y0_m) / cell_m - 0.5).floor().max(0.0) as usize;
        let j1 = (((a[1].max(b[1]).max(c[1]) - g.y0_m) / cell_m).ceil() as usize).min(g.ny);
        for j in j0..j1 {
            for i in i0..i1 {
                let [x, y] = g.centre(i, j);
                let e =
                    |p: [f64; 3], q: [f64; 3]| s * ((q[0] - p[0]) * (y - p[1]) - (q[1] - p[1]) * (x - p[0]));
                if e(a, b) >= 0.0 && e(b, c) >= 0.0 && e(c, a) >= 0.0 {
                    dist[j * g.nx + i] = 0.0;
                    ground[j * g.nx + i] = base as f32;
                }
            }
        }
    }
    (dist, ground)
}

/// Dilates the footprints by one cell so a footprint edge between two cell centres still counts as
/// taken (the new cells carry their neighbour's ground).
fn dilate_footprints(g: &Grid, dist: &mut [f32], ground: &mut [f32]) {
    let footprint: Vec<bool> = dist.iter().map(|&d| d == 0.0).collect();
    for j in 0..g.ny {
        for i in 0..g.nx {
            if footprint[j * g.nx + i] {
                for (di, dj) in [(-1i64, 0i64), (1, 0), (0, -1), (0, 1), (-1, -1), (1, 1), (-1, 1), (1, -1)] {
                    let (ii, jj) = (i as i64 + di, j as i64 + dj);
                    if ii >= 0 && jj >= 0 && (ii as usize) < g.nx && (jj as usize) < g.ny {
                        let k = jj as usize * g.nx + ii as usize;
                        if !footprint[k] {
                            dist[k] = 0.0;
                            ground[k] = ground[j * g.nx + i];
                        }
                    }
                }
            }
        }
    }
}

/// A run of same-class cells in one row: (x0, x1, class, z (decimetres), tone).
type Run = (usize, usize, Class, i64, usize);

/// The flat ground layers, made of merged rectangles of (class, height, tone) runs, and the number of
/// rectangles in each.
#[derive(Default)]
struct GroundLayers {
    roads: LayerMesh,
    pavements: LayerMesh,
    cover: LayerMesh,
    n_road: u64,
    n_pave: u64,
    n_cover: u64,
}

impl GroundLayers {
    /// Merges the runs of every row with the identical runs of the rows below into rectangles.
    fn build(plan: &Plan, seed: u64) -> GroundLayers {
        let g = &plan.g;
        let mut layers = GroundLayers::default();
        // Open rectangles keyed by their run → the row they started at.
        let mut open: BTreeMap<Run, usize> = BTreeMap::new();
        for j in 0..=g.ny {
            let runs = if j < g.ny { row_runs(plan, j, seed) } else { Vec::new() };
            let mut next: BTreeMap<Run, usize> = BTreeMap::new();
            for r in runs {
                let j0 = open.remove(&r).unwrap_or(j);
                next.insert(r, j0);
            }
            for (r, j0) in std::mem::take(&mut open) {
                layers.emit(g, r, j0, j);
            }
            open = next;
        }
        layers
    }

    /// Adds the rectangle of `run` over rows `j0..j1` to its layer.
    fn emit(&mut self, g: &Grid, run: Run, j0: usize, j1: usize) {
        let cell_m = g.cell_m;
        let (i0, i1, c, zq, tone) = run;
        let x0 = g.x0_m + i0 as f64 * cell_m;
        let x1 = g.x0_m + i1 as f64 * cell_m;
        let y0 = g.y0_m + j0 as f64 * cell_m;
        let y1 = g.y0_m + j1 as f64 * cell_m;
        let z = zq as f64 / 10.0;
        let corners = [[x0, y0], [x1, y0], [x1, y1], [x0, y1]];
        match c {
            Class::Road => {
                self.roads.quad(corners, z + ROAD_Z_M, ASPHALT[tone % ASPHALT.len()]);
                self.n_road += 1;
            }
            Class::Pavement => {
                self.pavements.quad(corners, z + PAVEMENT_Z_M, PAVEMENT[tone % PAVEMENT.len()]);
                self.n_pave += 1;
            }
            Class::Park => {
                self.cover.quad(corners, z + GROUND_COVER_Z_M, GRASS[tone % GRASS.len()]);
                self.n_cover += 1;
            }
            Class::None => {}
        }
    }
}

/// Ground height quantised to decimetres (cells of one run share it).
fn quantise_z(z: f32) -> i64 {
    (z as f64 * 10.0).round() as i64
}

/// The colour tone of cell (i, j) of class `c`: low-frequency value noise, ~12 m patches for grass
/// (ground-cover variety), 64 cells for asphalt and pavement.
fn tone_at(c: Class, i: usize, j: usize, seed: u64, cell_m: f64) -> usize {
    match c {
        Class::Park => {
            let cell = (12.0 / cell_m).max(1.0) as usize;
            hash3(i / cell, j / cell, seed) as usize % GRASS.len()
        }
        Class::Road => hash3(i / 64, j / 64, seed ^ 1) as usize % ASPHALT.len(),
        _ => hash3(i / 64, j / 64, seed ^ 2) as usize % PAVEMENT.len(),
    }
}

/// The runs of row `j`: maximal spans of cells with the same class, height and tone.
fn row_runs(plan: &Plan, j: usize, seed: u64) -> Vec<Run> {
    let g = &plan.g;
    let mut runs = Vec::new();
    let mut i = 0;
    while i < g.nx {
        let k = j * g.nx + i;
        let c = plan.class[k];
        if c == Class::None {
            i += 1;
            continue;
        }
        let zq = quantise_z(plan.ground[k]);
        let tone = tone_at(c, i, j, seed, g.cell_m);
        let start = i;
        while i < g.nx {
            let k2 = j * g.nx + i;
            let tone2 = tone_at(plan.class[k2], i, j, seed, g.cell_m);
            if plan.class[k2] != c || quantise_z(plan.ground[k2]) != zq || tone2 != tone {
                break;
            }
            i += 1;
        }
        runs.push((start, i, c, zq, tone));
    }
    runs
}

/// Lane markings: dashes on the distance ridge of wide roads, along the street. Returns the layer and
/// the number of dashes.
fn lane_markings(plan: &Plan) -> (LayerMesh, u64) {
    let (g, dist) = (&plan.g, &plan.dist);
    let cell_m = g.cell_m;
    let mut markings = LayerMesh::default();
    let mut n_mark = 0u64;
    let dash_m = 3.0;
    for j in 1..g.ny.saturating_sub(1) {
        for i in 1..g.nx.saturating_sub(1) {
            let k = j * g.nx + i;
            if plan.class[k] != Class::Road || plan.d_at(k) < MARKING_MIN_HALF_WIDTH_M {
                continue;
            }
            let d = dist[k];
            let ridge_y = d >= dist[k - g.nx] && d > dist[k + g.nx]; // street runs along x
            let ridge_x = d >= dist[k - 1] && d > dist[k + 1]; // street runs along y
            let [x, y] = g.centre(i, j);
            let z = plan.ground[k] as f64 + MARKING_Z_M;
            if ridge_y && !ridge_x && ((x / dash_m).floor() as i64).rem_euclid(2) == 0 {
                markings.quad(
                    [
                        [x - 0.5 * cell_m, y - 0.08],
                        [x + 0.5 * cell_m, y - 0.08],
                        [x + 0.5 * cell_m, y + 0.08],
                        [x - 0.5 * cell_m, y + 0.08],
                    ],
                    z,
                    MARKING,
                );
                n_mark += 1;
            } else if ridge_x && !ridge_y && ((y / dash_m).floor() as i64).rem_euclid(2) == 0 {
                markings.quad(
                    [
                        [x - 0.08, y - 0.5 * cell_m],
                        [x + 0.08, y - 0.5 * cell_m],
                        [x + 0.08, y + 0.5 * cell_m],
                        [x - 0.08, y + 0.5 * cell_m],
                    ],
                    z,
                    MARKING,
                );
                n_mark += 1;
            }
        }
    }
    (markings, n_mark)
}

/// Step 4a, trees: a jittered lattice in parks and along pavements, crowns clear of every footprint. Marks
/// the trunk zones in `occupied`, counts the species in `species`; returns the layer and the tree count.
fn plant_trees(
    plan: &Plan,
    spec: &ClutterSpec,
    rng: &mut ChaCha8Rng,
    occupied: &mut [bool],
    species: &mut BTreeMap<String, u64>,
) -> (LayerMesh, u64) {
    let (g, cell_m) = (&plan.g, plan.g.cell_m);
    let mut trees = LayerMesh::default();
    let mut n_trees = 0u64;
    let spacing_m = (10.0 / spec.park_trees_per_100m2.max(0.01).sqrt()).max(3.0);
    let street_spacing_m = 9.0;
    let lattice = |step_m: f64| -> (usize, usize) {
        (((g.nx as f64 * cell_m) / step_m).ceil() as usize, ((g.ny as f64 * cell_m) / step_m).ceil() as usize)
    };
    for (step_m, park) in [(spacing_m, true), (street_spacing_m, false)] {
        let (lx, ly) = lattice(step_m);
        for b in 0..ly {
            for a in 0..lx {
                let jitter: [f64; 2] = [rng.gen_range(-0.35..0.35), rng.gen_range(-0.35..0.35)];
                let species_pick: f64 = rng.gen();
                let size: [f64; 2] = [rng.gen(), rng.gen()];
                let tone = rng.gen_range(0..3usize);
                let keep: f64 = rng.gen();
                let p = [
                    g.x0_m + (a as f64 + 0.5 + jitter[0]) * step_m,
                    g.y0_m + (b as f64 + 0.5 + jitter[1]) * step_m,
                ];
                let Some((i, j)) = g.cell_of(p) else { continue };
                let k = j * g.nx + i;
                let d = plan.d_at(k);
                let ok = if park {
                    // One lattice point in four stays empty: glades, not a plantation.
                    plan.class[k] == Class::Park && keep < 0.75
                } else {
                    plan.class[k] == Class::Pavement && d >= 1.8 && keep < spec.street_tree_chance
                };
                if !ok || occupied[k] {
                    continue;
                }
                let sp = tree_species(park, species_pick);
                // The crown must stay CLEARANCE_M clear of the footprints (d is from the nearest one).
                let max_r = d - CLEARANCE_M - cell_m;
                let r = (sp.crown_r_m[0] + size[0] * (sp.crown_r_m[1] - sp.crown_r_m[0])).min(max_r);
                if r < 1.0 {
                    continue;
                }
                let height = (sp.height_m[0] + size[1] * (sp.height_m[1] - sp.height_m[0])).max(2.2 * r);
                let z0 = plan.ground[k] as f64;
                add_tree(&mut trees, sp, p, z0, height, r, tone);
                *species.entry(sp.name.to_string()).or_insert(0) += 1;
                n_trees += 1;
                stamp(g, occupied, p, 1.5);
            }
        }
    }
    (trees, n_trees)
}

/// The species of a tree from a uniform draw in [0, 1): parks mix all three, streets have broadleaf
/// and small round trees only.
fn tree_species(park: bool, pick: f64) -> &'static Species {
    if park {
        &SPECIES[if pick < 0.55 {
            0
        } else if pick < 0.8 {
            1
        } else {
            2
        }]
    } else {
        &SPECIES[if pick < 0.7 { 0 } else { 2 }]
    }
}

/// Step 4b, cars: parked at the kerb, driving in the lanes; on free road cells only (marked in `occupied`),
/// never overlapping. Returns the layer and the car count.
fn place_cars(
    plan: &Plan,
    spec: &ClutterSpec,
    rng: &mut ChaCha8Rng,
    occupied: &mut [bool],
) -> (LayerMesh, u64) {
    let (g, dist, class) = (&plan.g, &plan.dist, &plan.class);
    let mut cars = LayerMesh::default();
    let mut n_cars = 0u64;
    for j in 1..g.ny.saturating_sub(1) {
        for i in 1..g.nx.saturating_sub(1) {
            let k = j * g.nx + i;
            if class[k] != Class::Road {
                continue;
            }
            let d = plan.d_at(k);
            let parked = (PAVEMENT_WIDTH_M + 0.3..PAVEMENT_WIDTH_M + 1.0).contains(&d);
            let driving = (5.0..5.8).contains(&d);
            if !parked && !driving {
                continue;
            }
            let chance = if parked { spec.parked_car_chance } else { spec.driving_car_chance };
            let roll: f64 = rng.gen();
            let dims: [f64; 3] = [rng.gen(), rng.gen(), rng.gen()];
            let paint = rng.gen_range(0..CAR_PAINT.len());
            if roll >= chance {
                continue;
            }
            // Along the street: perpendicular to the distance gradient.
            let gx = dist[k + 1] - dist[k - 1];
            let gy = dist[k + g.nx] - dist[k - g.nx];
            let len = ((gx * gx + gy * gy) as f64).sqrt();
            if len < 1e-6 {
                continue;
            }
            let dir = [-(gy as f64) / len, gx as f64 / len];
            let p = g.centre(i, j);
            let (half_len, half_wid) = (2.0 + 0.5 * dims[0], 0.85 + 0.1 * dims[1]);
            // Every cell under the car (plus 0.3 m) must be free road.
            let ring = rectangle(p, dir, half_len + 0.3, half_wid + 0.3);
            let Some(under) = rect_cells(g, &ring) else { continue };
            if !under.iter().all(|&kk| class[kk] == Class::Road && !occupied[kk]) {
                continue;
            }
            for kk in under {
                occupied[kk] = true;
            }
            let z0 = plan.ground[k] as f64 + ROAD_Z_M;
            let body_h = 0.75 + 0.2 * dims[2];
            cars.oriented_box(p, dir, half_len, half_wid, z0 + 0.2, body_h, CAR_PAINT[paint]);
            let cabin_c = [p[0] - 0.2 * half_len * dir[0], p[1] - 0.2 * half_len * dir[1]];
            cars.oriented_box(cabin_c, dir, 0.55 * half_len, half_wid - 0.08, z0 + 0.2 + body_h, 0.5, GLASS);
            n_cars += 1;
        }
    }
    (cars, n_cars)
}

/// Step 4c: rooftop units on the highest flat part of each building with at least [`ROOF_MIN_AREA_M2`] of
/// it. Returns the layer and the unit count.
fn place_rooftop_units(
    mesh: &SceneMesh,
    buildings: &[BuildingRecord],
    rng: &mut ChaCha8Rng,
) -> (LayerMesh, u64) {
    let mut rooftop = LayerMesh::default();
    let mut n_units = 0u64;
    let roofs = flat_roofs(mesh);
    for b in buildings {
        let Some(roof) = roofs.get(&b.id.get()) else { continue };
        let area: f64 = roof.iter().map(tri_area).sum();
        if area < ROOF_MIN_AREA_M2 {
            continue;
        }
        n_units += roof_units(roof, area, rng, &mut rooftop);
    }
    (rooftop, n_units)
}

/// The unit direction of the longest edge of a roof (units are aligned with it); +x for no edge.
fn longest_edge_dir(roof: &[[[f64; 3]; 3]]) -> [f64; 2] {
    roof.iter()
        .flat_map(|t| [(t[0], t[1]), (t[1], t[2]), (t[2], t[0])])
        .map(|(a, b)| [b[0] - a[0], b[1] - a[1]])
        .max_by(|u, v| (u[0] * u[0] + u[1] * u[1]).total_cmp(&(v[0] * v[0] + v[1] * v[1])))
        .map(|v| {
            let l = (v[0] * v[0] + v[1] * v[1]).sqrt();
            [v[0] / l, v[1] / l]
        })
        .unwrap_or([1.0, 0.0])
}

/// Places up to one unit per 180 m² (1 to 6) on one flat roof of `area_m2`, in at most four tries per
/// unit; returns how many were placed.
fn roof_units(roof: &[[[f64; 3]; 3]], area_m2: f64, rng: &mut ChaCha8Rng, rooftop: &mut LayerMesh) -> u64 {
    let area = area_m2;
    let z_roof = roof.iter().map(|t| t[0][2].max(t[1][2]).max(t[2][2])).fold(f64::NEG_INFINITY, f64::max);
    let dir = longest_edge_dir(roof);
    let want = ((area / 180.0).ceil() as usize).clamp(1, 6);
    let mut placed: Vec<([f64; 2], f64)> = Vec::new();
    for _ in 0..want * 4 {
        if placed.len() >= want {
            break;
        }
        let pick: f64 = rng.gen::<f64>() * area;
        let (u, v): (f64, f64) = (rng.gen(), rng.gen());
        let dims: [f64; 3] = [rng.gen(), rng.gen(), rng.gen()];
        let tank = rng.gen::<f64>() < 0.25;
        let shade = rng.gen_range(0..UNIT.len());
        let mut acc = 0.0;
        let t = roof
            .iter()
            .find(|t| {
                acc += tri_area(t);
                acc >= pick
            })
            .unwrap_or(&roof[roof.len() - 1]);
        let (u, v) = if u + v > 1.0 { (1.0 - u, 1.0 - v) } else { (u, v) };
        let p = [
            t[0][0] + u * (t[1][0] - t[0][0]) + v * (t[2][0] - t[0][0]),
            t[0][1] + u * (t[1][1] - t[0][1]) + v * (t[2][1] - t[0][1]),
        ];
        let (hl, hw, hh) = (0.6 + 1.0 * dims[0], 0.5 + 0.8 * dims[1], 0.8 + 1.2 * dims[2]);
        let reach = (hl * hl + hw * hw).sqrt();
        if placed
            .iter()
            .any(|(q, r)| ((q[0] - p[0]).powi(2) + (q[1] - p[1]).powi(2)).sqrt() < r + reach + 0.5)
        {
            continue;
        }
        // The whole unit, plus 0.5 m, stands on the roof.
        let corners = rectangle(p, dir, hl + 0.5, hw + 0.5);
        if !corners.iter().all(|c| roof.iter().any(|t| in_triangle(*c, t))) {
            continue;
        }
        if tank {
            let ring: Vec<[f64; 2]> = (0..8)
                .map(|s| {
                    let a = std::f64::consts::TAU * s as f64 / 8.0;
                    [p[0] + hw * a.cos(), p[1] + hw * a.sin()]
                })
                .collect();
            rooftop.prism(&ring, p, z_roof, z_roof + hh * 1.3, 1.0, UNIT[shade]);
        } else {
            rooftop.oriented_box(p, dir, hl, hw, z_roof, hh, UNIT[shade]);
        }
        placed.push((p, reach));
    }
    placed.len() as u64
}

/// Tree species names, in the order [`tree_instance`] takes them.
pub const TREE_SPECIES: [&str; 3] = [SPECIES[0].name, SPECIES[1].name, SPECIES[2].name];

/// One tree as the generator builds it (species by index into [`TREE_SPECIES`], base point, height
/// and crown radius in metres), on its own: for tests and previews of the templates.
///
/// # Panics
/// If `species` is not below `TREE_SPECIES.len()`.
pub fn tree_instance(species: usize, base_m: [f64; 3], height_m: f64, crown_r_m: f64) -> LayerMesh {
    let mut m = LayerMesh::default();
    add_tree(&mut m, &SPECIES[species], [base_m[0], base_m[1]], base_m[2], height_m, crown_r_m, 0);
    m
}

/// A tree: a pentagonal trunk and a spheroid (broadleaf) or two stacked cones (conifer).
fn add_tree(m: &mut LayerMesh, sp: &Species, p: [f64; 2], z0: f64, height_m: f64, r_m: f64, tone: usize) {
    let trunk_r = (0.12 * r_m).clamp(0.15, 0.4);
    let ring: Vec<[f64; 2]> = (0..5)
        .map(|s| {
            let a = std::f64::consts::TAU * s as f64 / 5.0;
            [p[0] + trunk_r * a.cos(), p[1] + trunk_r * a.sin()]
        })
        .collect();
    let c = sp.crown[tone % sp.crown.len()];
    let dark = c.map(|v| (v as f64 * 0.6) as u8);
    if sp.conifer {
        let crown_base = z0 + 0.25 * height_m;
        m.prism(&ring, p, z0, crown_base + 0.1, 1.0, TRUNK);
        let cone = |r: f64| -> Vec<[f64; 2]> {
            (0..8)
                .map(|s| {
                    let a = std::f64::consts::TAU * s as f64 / 8.0;
                    [p[0] + r * a.cos(), p[1] + r * a.sin()]
                })
                .collect()
        };
        let mid = crown_base + 0.45 * (z0 + height_m - crown_base);
        m.prism(&cone(r_m), p, crown_base, mid + 0.3 * (height_m - mid + z0), 0.0, dark);
        m.prism(&cone(0.75 * r_m), p, mid, z0 + height_m, 0.0, c);
    } else {
        let crown_h = (height_m * 0.35).max(r_m * 0.8);
        let centre_z = z0 + height_m - crown_h;
        m.prism(&ring, p, z0, centre_z, 1.0, TRUNK);
        m.spheroid([p[0], p[1], centre_z], r_m, crown_h, c, dark);
    }
}

/// Marks the cells within `r_m` of `p`.
fn stamp(g: &Grid, occupied: &mut [bool], p: [f64; 2], r_m: f64) {
    let ring = rectangle(p, [1.0, 0.0], r_m, r_m);
    for k in rect_cells(g, &ring).unwrap_or_default() {
        occupied[k] = true;
    }
}

/// Cells whose centre lies inside a convex quad (plus the cell of each corner); `None` when a corner
/// is off the grid (callers then refuse the placement).
fn rect_cells(g: &Grid, ring: &[[f64; 2]; 4]) -> Option<Vec<usize>> {
    let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
    for p in ring {
        lo = [lo[0].min(p[0]), lo[1].min(p[1])];
        hi = [hi[0].max(p[0]), hi[1].max(p[1])];
    }
    let mut out = Vec::new();
    for p in ring {
        let (i, j) = g.cell_of(*p)?;
        out.push(j * g.nx + i);
    }
    let (i0, j0) = g.cell_of(lo)?;
    let (i1, j1) = g.cell_of(hi)?;
    for j in j0..=j1 {
        for i in i0..=i1 {
            let c = g.centre(i, j);
            let inside = (0..4).all(|e| {
                let (a, b) = (ring[e], ring[(e + 1) % 4]);
                (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]) >= 0.0
            });
            if inside {
                out.push(j * g.nx + i);
            }
        }
    }
    Some(out)
}

/// The highest flat part of each building's roof: its up-facing horizontal triangles within 0.3 m of
/// the highest one, by building ID.
fn flat_roofs(mesh: &SceneMesh) -> BTreeMap<u32, Vec<[[f64; 3]; 3]>> {
    let mut flat: BTreeMap<u32, Vec<[[f64; 3]; 3]>> = BTreeMap::new();
    for tri in mesh.indices.chunks_exact(3) {
        let t = [tri[0], tri[1], tri[2]].map(|i| mesh.positions_m[i as usize].map(f64::from));
        let u = [t[1][0] - t[0][0], t[1][1] - t[0][1], t[1][2] - t[0][2]];
        let v = [t[2][0] - t[0][0], t[2][1] - t[0][1], t[2][2] - t[0][2]];
        let nrm = [u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0]];
        let len = (nrm[0] * nrm[0] + nrm[1] * nrm[1] + nrm[2] * nrm[2]).sqrt();
        // Horizontal (either winding: LoD sources mix them).
        if len < 1e-9 || nrm[2].abs() / len < 0.995 {
            continue;
        }
        flat.entry(mesh.building_ids[tri[0] as usize].get()).or_default().push(t);
    }
    for tris in flat.values_mut() {
        let top = tris.iter().map(|t| t[0][2]).fold(f64::NEG_INFINITY, f64::max);
        tris.retain(|t| t[0][2] >= top - 0.3);
    }
    flat
}

fn tri_area(t: &[[f64; 3]; 3]) -> f64 {
    0.5 * ((t[1][0] - t[0][0]) * (t[2][1] - t[0][1]) - (t[2][0] - t[0][0]) * (t[1][1] - t[0][1])).abs()
}

/// Whether `p` lies inside the triangle's ground projection (boundary included).
pub fn in_triangle(p: [f64; 2], t: &[[f64; 3]; 3]) -> bool {
    let e = |a: [f64; 3], b: [f64; 3]| (b[0] - a[0]) * (p[1] - a[1]) - (b[1] - a[1]) * (p[0] - a[0]);
    let (e0, e1, e2) = (e(t[0], t[1]), e(t[1], t[2]), e(t[2], t[0]));
    (e0 >= 0.0 && e1 >= 0.0 && e2 >= 0.0) || (e0 <= 0.0 && e1 <= 0.0 && e2 <= 0.0)
}

/// A 64-bit hash of a cell and the seed (splitmix64 finaliser).
fn hash3(i: usize, j: usize, seed: u64) -> u64 {
    let mut z = (i as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15)
        ^ (j as u64).wrapping_mul(0xC2B2_AE3D_27D4_EB4F)
        ^ seed.wrapping_mul(0x1656_67B1_9E37_79F9);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::BuildingId;

    /// A closed box building (roof, floor, four walls) as the scene mesh holds it, footprint given as a
    /// counter-clockwise quad.
    fn add_building(mesh: &mut SceneMesh, records: &mut Vec<BuildingRecord>, quad: [[f64; 2]; 4], h_m: f64) {
        let id = BuildingId::new(records.len() as u32 + 1).unwrap();
        let base = mesh.positions_m.len() as u32;
        for z in [0.0, h_m] {
            for p in quad {
                mesh.positions_m.push([p[0] as f32, p[1] as f32, z as f32]);
                mesh.building_ids.push(id);
            }
        }
        let (b, t) = (base, base + 4);
        mesh.indices.extend_from_slice(&[t, t + 1, t + 2, t, t + 2, t + 3, b, b + 2, b + 1, b, b + 3, b + 2]);
        for k in 0..4 {
            let (i, j) = (k, (k + 1) % 4);
            mesh.indices.extend_from_slice(&[b + i, b + j, t + j, b + i, t + j, t + i]);
        }
        let xs = quad.map(|p| p[0]);
        let ys = quad.map(|p| p[1]);
        let min = |a: [f64; 4]| a.iter().copied().fold(f64::INFINITY, f64::min);
        let max = |a: [f64; 4]| a.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        records.push(BuildingRecord {
            id,
            source_id: format!("b{}", id.get()),
            source_file: "test".into(),
            lod: "1".into(),
            height_m: h_m,
            measured_height_m: None,
            footprint_area_m2: 0.0,
            centroid_lat_deg: 0.0,
            centroid_lon_deg: 0.0,
            bbox_min_enu_m: [min(xs), min(ys), 0.0],
            bbox_max_enu_m: [max(xs), max(ys), h_m],
            triangles: 12,
        });
    }

    /// A block of axis-aligned buildings along two streets, one rotated tower and an open park corner.
    fn city() -> (SceneMesh, Vec<BuildingRecord>, Vec<[f64; 2]>) {
        let mut mesh = SceneMesh::default();
        let mut rec = Vec::new();
        let rect = |x0: f64, y0: f64, x1: f64, y1: f64| [[x0, y0], [x1, y0], [x1, y1], [x0, y1]];
        for i in 0..4 {
            let x = -90.0 + 45.0 * i as f64;
            add_building(&mut mesh, &mut rec, rect(x, -60.0, x + 30.0, -20.0), 12.0 + 4.0 * i as f64);
            add_building(&mut mesh, &mut rec, rect(x, 0.0, x + 30.0, 25.0), 20.0);
        }
        // A tower rotated by 30°, centred at (60, 70).
        let (c, s) = (30f64.to_radians().cos(), 30f64.to_radians().sin());
        let tower = [[-10.0, -10.0], [10.0, -10.0], [10.0, 10.0], [-10.0, 10.0]]
            .map(|p: [f64; 2]| [60.0 + c * p[0] - s * p[1], 70.0 + s * p[0] + c * p[1]]);
        add_building(&mut mesh, &mut rec, tower, 40.0);
        let area = vec![[-120.0, -90.0], [120.0, -90.0], [120.0, 120.0], [-120.0, 120.0]];
        (mesh, rec, area)
    }

    fn footprint_triangles(mesh: &SceneMesh) -> Vec<[[f64; 3]; 3]> {
        mesh.indices
            .chunks_exact(3)
            .map(|t| [t[0], t[1], t[2]].map(|i| mesh.positions_m[i as usize].map(f64::from)))
            .filter(|t| tri_area(t) > 1e-6)
            .collect()
    }

    /// Whether `p` is strictly inside a footprint triangle (by more than 1 mm: shared edges are fine).
    fn strictly_inside(p: [f64; 2], t: &[[f64; 3]; 3]) -> bool {
        let e = |a: [f64; 3], b: [f64; 3]| {
            let l = ((b[0] - a[0]).powi(2) + (b[1] - a[1]).powi(2)).sqrt();
            ((b[0] - a[0]) * (p[1] - a[1]) - (b[1] - a[1]) * (p[0] - a[0])) / l
        };
        let d = [e(t[0], t[1]), e(t[1], t[2]), e(t[2], t[0])];
        d.iter().all(|&v| v > 1e-3) || d.iter().all(|&v| v < -1e-3)
    }

    mod determinism {
        use super::*;

        fn glb_bytes(seed: u64, dir: &std::path::Path, name: &str) -> Vec<u8> {
            let (mesh, rec, area) = city();
            let spec = ClutterSpec { seed, ..ClutterSpec::default() };
            let (clutter, _) = generate(&spec, &mesh, &rec, &area, 0.0);
            let path = dir.join(name);
            crate::scene::glb::write_glb(&path, &mesh, &rec).unwrap();
            crate::scene::glb::add_layers(&path, &clutter).unwrap();
            std::fs::read(&path).unwrap()
        }

        #[test]
        fn same_seed_gives_the_same_bytes_and_another_seed_does_not() {
            let dir = tempfile::tempdir().unwrap();
            let a = glb_bytes(7, dir.path(), "a.glb");
            let b = glb_bytes(7, dir.path(), "b.glb");
            let c = glb_bytes(8, dir.path(), "c.glb");
            assert!(a == b, "same seed, different bytes");
            assert!(a != c, "another seed gave the same bytes");
        }

        #[test]
        fn every_layer_is_generated_and_reads_back_exactly() {
            let (mesh, rec, area) = city();
            let (clutter, summary) = generate(&ClutterSpec::default(), &mesh, &rec, &area, 0.0);
            let names: Vec<ClutterLayer> = summary.layers.iter().map(|l| l.name).collect();
            assert_eq!(names, ClutterLayer::ALL.to_vec(), "{summary:#?}");
            for l in &summary.layers {
                assert!(l.instances > 0 && l.triangles > 0, "{l:?}");
            }
            let dir = tempfile::tempdir().unwrap();
            let path = dir.path().join("scene.glb");
            crate::scene::glb::write_glb(&path, &mesh, &rec).unwrap();
            crate::scene::glb::add_layers(&path, &clutter).unwrap();
            assert_eq!(crate::scene::glb::read_layers(&path).unwrap(), clutter);
            // The building reader still sees exactly the buildings.
            assert_eq!(crate::scene::glb::read_glb(&path).unwrap(), mesh);
        }
    }

    mod placement {
        use super::*;

        #[test]
        fn nothing_on_the_ground_intersects_a_building_footprint() {
            let (mesh, rec, area) = city();
            let feet = footprint_triangles(&mesh);
            for seed in [1, 2, 3] {
                let (clutter, _) =
                    generate(&ClutterSpec { seed, ..ClutterSpec::default() }, &mesh, &rec, &area, 0.0);
                for (layer, m) in &clutter.layers {
                    if *layer == ClutterLayer::Rooftop {
                        continue;
                    }
                    // Sample each triangle on a barycentric grid (vertices, edges and inside).
                    for t in m.indices.chunks_exact(3) {
                        let [a, b, c] = [t[0], t[1], t[2]].map(|i| m.positions_m[i as usize].map(f64::from));
                        for u in 0..=6 {
                            for v in 0..=(6 - u) {
                                let (u, v) = (u as f64 / 6.0, v as f64 / 6.0);
                                let p = [
                                    a[0] + u * (b[0] - a[0]) + v * (c[0] - a[0]),
                                    a[1] + u * (b[1] - a[1]) + v * (c[1] - a[1]),
                                ];
                                if let Some(f) = feet.iter().find(|f| strictly_inside(p, f)) {
                                    panic!("seed {seed}: {layer} point {p:?} lies inside footprint triangle {f:?}");
                                }
                            }
                        }
                    }
                }
            }
        }

        #[test]
        fn rooftop_units_stand_on_their_roofs() {
            let (mesh, rec, area) = city();
            let roofs: Vec<[[f64; 3]; 3]> =
                footprint_triangles(&mesh).into_iter().filter(|t| t[0][2] > 0.0).collect();
            let (clutter, _) = generate(&ClutterSpec::default(), &mesh, &rec, &area, 0.0);
            let m = clutter.layer(ClutterLayer::Rooftop).expect("flat roofs get units");
            for p in &m.positions_m {
                let q = [p[0] as f64, p[1] as f64];
                let roof = roofs.iter().find(|t| in_triangle(q, t));
                let roof = roof.unwrap_or_else(|| panic!("unit vertex {p:?} is off every roof"));
                assert!(p[2] as f64 >= roof[0][2] - 1e-3, "unit vertex {p:?} below its roof");
            }
        }

        #[test]
        fn cars_and_markings_lie_in_the_open_space() {
            let (mesh, rec, area) = city();
            let (clutter, summary) = generate(&ClutterSpec::default(), &mesh, &rec, &area, 0.0);
            for layer in [ClutterLayer::Cars, ClutterLayer::Trees, ClutterLayer::Roads] {
                let m = clutter.layer(layer).unwrap();
                assert!(m.positions_m.iter().all(|p| p[2] >= 0.0), "{layer} below the ground");
            }
            let species = summary.tree_species.len();
            assert!(species >= 2, "only {species} tree species: {:?}", summary.tree_species);
        }
    }

    mod layers {
        use super::*;

        #[test]
        fn names_round_trip_and_lists_parse() {
            for l in ClutterLayer::ALL {
                assert_eq!(ClutterLayer::from_name(l.name()), Some(l));
            }
            assert_eq!(parse_layers("cars, trees").unwrap(), vec![ClutterLayer::Trees, ClutterLayer::Cars]);
            assert_eq!(parse_layers("none").unwrap(), vec![]);
            assert!(parse_layers("tree")
                .unwrap_err()
                .to_string()
                .contains("expected all, none or any of roads"));
        }
    }
}
