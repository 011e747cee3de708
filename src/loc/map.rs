//! The map the queries are localized against, and seeded perturbations of it that model real LoD
//! error (issue 15): the query masks come from one model, the map is another, as with a segmenter's
//! masks of real buildings against a city model.
//!
//! Input: a [`PreparedScene`] (mesh in the area's ENU frame, building records); output: a perturbed
//! copy with the building records (boxes, triangle counts) recomputed from the perturbed mesh, and
//! what changed ([`PerturbationReport`]). Same scene, parameters and seed → identical map.
//!
//! Per building (in the order of the building table, each drawing the same random numbers whatever
//! is enabled, so turning one perturbation on does not change another's draws):
//! 1. LoD2 → LoD1 ([`MapPerturbation::lod1`]): the footprint extruded to one roof height — every
//!    vertex more than [`LOD1_GROUND_BAND_M`] above the building's bottom moves to that height, so
//!    walls reach it and the roof becomes flat over the footprint. The height is the building's top
//!    (its highest vertex), or with [`MapPerturbation::lod1_roof_percentile`] a percentile of its roof
//!    surface heights weighted by horizontal area, as LoD1 products derived from point clouds use
//!    (3DBAG's LoD1.2 blocks stand at the 70th percentile);
//! 2. height error: the building's extent above its bottom scaled so that its top moves by
//!    N(0, `height_sigma_m`) metres (the building keeps at least 1 m);
//! 3. footprint scale by 1 + N(0, `scale_sigma`) about the centre of its box, then a shift by
//!    N(0, `shift_sigma_m`) metres east and north;
//! 4. dropped with probability `drop_fraction` (gone from the map);
//! 5. merged with probability `merge_fraction` into the nearest remaining building (box centres,
//!    horizontally): both render as one instance;
//!
//! and finally the whole map moves by `offset_enu_m` (the paper's "slight misalignment").

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};
use serde::{Deserialize, Serialize};

use crate::scene::{BuildingId, BuildingRecord, PreparedScene, SceneMesh};

/// Vertices within this height above a building's lowest vertex are its ground outline and stay put
/// when the building is coarsened to LoD1, metres. Wider than the numeric noise of real footprints,
/// narrower than a storey.
pub const LOD1_GROUND_BAND_M: f64 = 1.0;

/// Smallest building height a height error leaves, metres.
const MIN_HEIGHT_M: f64 = 1.0;

/// Seeded map perturbations (all off by default). See the module doc for the order they apply in.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, Default)]
#[serde(default)]
pub struct MapPerturbation {
    /// Coarsen LoD2 to LoD1: footprint extruded to the building's top, or to the given percentile
    /// (0–100) of its roof heights.
    pub lod1: bool,
    /// With `lod1`: the percentile (0–100) of the building's roof surface heights, weighted by
    /// horizontal area, its LoD1 block stands at; `None`: its highest vertex.
    pub lod1_roof_percentile: Option<f64>,
    /// σ of the per-building error of the top's height above the bottom, metres.
    pub height_sigma_m: f64,
    /// σ of the per-building horizontal footprint shift, metres (east and north independently).
    pub shift_sigma_m: f64,
    /// σ of the per-building footprint scale factor − 1 (0.05: about ±5 %).
    pub scale_sigma: f64,
    /// Share (0..1) of buildings dropped from the map.
    pub drop_fraction: f64,
    /// Share (0..1) of buildings merged into their nearest neighbour.
    pub merge_fraction: f64,
    /// Offset of the whole map, ENU metres.
    pub offset_enu_m: [f64; 3],
    /// Seed of the random draws.
    pub seed: u64,
}

impl MapPerturbation {
    /// Whether the map is left as it is.
    pub fn is_identity(&self) -> bool {
        let zero = MapPerturbation { seed: self.seed, ..MapPerturbation::default() };
        *self == zero
    }
}

/// What a perturbation did.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, Default)]
pub struct PerturbationReport {
    /// Buildings in the map before and after (drops and merges remove some).
    pub buildings_before: usize,
    /// Buildings in the map after the perturbation.
    pub buildings_after: usize,
    /// Buildings dropped.
    pub dropped: usize,
    /// Buildings merged into a neighbour.
    pub merged: usize,
}

/// One building's random draws (always all of them, in this order).
struct Draws {
    height_m: f64,
    scale: f64,
    shift_m: [f64; 2],
    drop_u: f64,
    merge_u: f64,
}

impl Draws {
    /// The draws of `n` buildings from a generator seeded with `seed`, building by building.
    fn all(n: usize, seed: u64) -> Vec<Draws> {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let unit = Normal::new(0.0, 1.0).expect("σ = 1 is valid");
        (0..n)
            .map(|_| Draws {
                height_m: unit.sample(&mut rng),
                scale: unit.sample(&mut rng),
                shift_m: [unit.sample(&mut rng), unit.sample(&mut rng)],
                drop_u: rng.gen_range(0.0..1.0),
                merge_u: rng.gen_range(0.0..1.0),
            })
            .collect()
    }
}

/// Returns `scene` with `p` applied (the manifest is kept; building records are recomputed).
pub fn perturb(scene: &PreparedScene, p: &MapPerturbation) -> (PreparedScene, PerturbationReport) {
    let (mesh, buildings, report) = perturb_mesh(&scene.mesh, &scene.buildings, p);
    (
        PreparedScene { manifest: scene.manifest.clone(), buildings, mesh, clutter: scene.clutter.clone() },
        report,
    )
}

/// The LoD1 roof height of every building (indexed like `lo`/`hi`): the `percentile` (0–100) of the
/// heights of its roof surface, each upward-facing triangle above the ground band weighted by its
/// horizontal area (its centroid's height standing for it). A building without such triangles keeps
/// its top; no height falls below the ground band.
fn lod1_roof_heights(
    positions: &[[f64; 3]],
    mesh: &SceneMesh,
    slot: &[usize],
    lo: &[[f64; 3]],
    hi: &[[f64; 3]],
    percentile: f64,
) -> Vec<f64> {
    // Steeper faces than this (normal's up component below it) are walls, not roof.
    const MIN_ROOF_NORMAL_UP: f64 = 0.3;
    let mut samples: Vec<Vec<(f64, f64)>> = vec![Vec::new(); lo.len()];
    for t in mesh.indices.chunks_exact(3) {
        let i = slot.get(mesh.building_ids[t[0] as usize].get() as usize).copied().unwrap_or(usize::MAX);
        if i == usize::MAX {
            continue;
        }
        let [a, b, c] = [t[0], t[1], t[2]].map(|k| glam::DVec3::from_array(positions[k as usize]));
        let n = (b - a).cross(c - a);
        let len = n.length();
        let z = (a.z + b.z + c.z) / 3.0;
        if len > 0.0 && n.z / len >= MIN_ROOF_NORMAL_UP && z > lo[i][2] + LOD1_GROUND_BAND_M {
            samples[i].push((z, n.z / 2.0));
        }
    }
    samples
        .into_iter()
        .enumerate()
        .map(|(i, mut s)| {
            if s.is_empty() {
                return hi[i][2];
            }
            s.sort_by(|x, y| x.0.total_cmp(&y.0));
            let total: f64 = s.iter().map(|x| x.1).sum();
            let want = total * (percentile / 100.0).clamp(0.0, 1.0);
            let mut acc = 0.0;
            let h = s.iter().find(|x| {
                acc += x.1;
                acc >= want
            });
            h.map_or(hi[i][2], |x| x.0).max(lo[i][2] + LOD1_GROUND_BAND_M)
        })
        .collect()
}

/// [`perturb`] on a mesh and its building records (every vertex's ID must have a record).
pub fn perturb_mesh(
    scene_mesh: &SceneMesh,
    records: &[BuildingRecord],
    p: &MapPerturbation,
) -> (SceneMesh, Vec<BuildingRecord>, PerturbationReport) {
    let draws = Draws::all(records.len(), p.seed);
    let slot = record_slots(records);
    let mut positions: Vec<[f64; 3]> =
        scene_mesh.positions_m.iter().map(|v| [v[0] as f64, v[1] as f64, v[2] as f64]).collect();
    let ids = &scene_mesh.building_ids;
    let (lo, hi) = building_bounds(&positions, ids, &slot, records.len());
    // Each building's top: its highest vertex, or its LoD1 roof height.
    let tops: Vec<f64> = match (p.lod1, p.lod1_roof_percentile) {
        (true, Some(pct)) => lod1_roof_heights(&positions, scene_mesh, &slot, &lo, &hi, pct),
        _ => hi.iter().map(|h| h[2]).collect(),
    };
    for (v, id) in positions.iter_mut().zip(ids) {
        let i = slot[id.get() as usize];
        move_vertex(v, lo[i], hi[i], tops[i], &draws[i], p);
    }
    // Drops, then merges into the nearest building still in the map.
    let dropped: Vec<bool> = draws.iter().map(|d| d.drop_u < p.drop_fraction).collect();
    let (lo, hi) = building_bounds(&positions, ids, &slot, records.len());
    let (parent, merged) = merge_groups(&lo, &hi, &draws, &dropped, p.merge_fraction);
    let mesh =
        kept_mesh(scene_mesh, &positions, &slot, &dropped, |i| records[root(&parent, i)].id, p.offset_enu_m);
    let buildings = recompute_records(records, &mesh);
    let report = PerturbationReport {
        buildings_before: records.len(),
        buildings_after: buildings.len(),
        dropped: dropped.iter().filter(|&&d| d).count(),
        merged,
    };
    (mesh, buildings, report)
}

/// The record index of every building ID (`usize::MAX` for IDs without a record).
fn record_slots(records: &[BuildingRecord]) -> Vec<usize> {
    let max_id = records.iter().map(|b| b.id.get()).max().unwrap_or(0) as usize;
    let mut slot = vec![usize::MAX; max_id + 1];
    for (i, b) in records.iter().enumerate() {
        slot[b.id.get() as usize] = i;
    }
    slot
}

/// Vertex bounds (lowest, highest corner) per building record, from the mesh itself (the records'
/// boxes are rounded the same way); infinite for a record without vertices.
fn building_bounds(
    positions: &[[f64; 3]],
    ids: &[BuildingId],
    slot: &[usize],
    n_records: usize,
) -> (Vec<[f64; 3]>, Vec<[f64; 3]>) {
    let mut lo = vec![[f64::INFINITY; 3]; n_records];
    let mut hi = vec![[f64::NEG_INFINITY; 3]; n_records];
    for (v, id) in positions.iter().zip(ids) {
        let i = slot.get(id.get() as usize).copied().unwrap_or(usize::MAX);
        if i == usize::MAX {
            continue;
        }
        for k in 0..3 {
            lo[i][k] = lo[i][k].min(v[k]);
            hi[i][k] = hi[i][k].max(v[k]);
        }
    }
    (lo, hi)
}

/// Applies steps 1–3 of the module doc (LoD1, height error, footprint scale and shift) to one
/// vertex of the building with bounds `l`/`h`, top `top` and draws `d`.
fn move_vertex(v: &mut [f64; 3], l: [f64; 3], h: [f64; 3], top: f64, d: &Draws, p: &MapPerturbation) {
    if p.lod1 && v[2] > l[2] + LOD1_GROUND_BAND_M {
        v[2] = top;
    }
    if p.height_sigma_m > 0.0 {
        let height = top - l[2];
        if height > 0.0 {
            let new_height = (height + p.height_sigma_m * d.height_m).max(MIN_HEIGHT_M.min(height));
            v[2] = l[2] + (v[2] - l[2]) * new_height / height;
        }
    }
    let centre = [(l[0] + h[0]) / 2.0, (l[1] + h[1]) / 2.0];
    let scale = (1.0 + p.scale_sigma * d.scale).max(0.1);
    for k in 0..2 {
        v[k] = centre[k] + (v[k] - centre[k]) * scale + p.shift_sigma_m * d.shift_m[k];
    }
}

/// Merges each building drawn for it (not dropped, with vertices) into the nearest other remaining
/// building by box centre. Returns the union-find parents (see [`root`]) and the number of merges.
fn merge_groups(
    lo: &[[f64; 3]],
    hi: &[[f64; 3]],
    draws: &[Draws],
    dropped: &[bool],
    merge_fraction: f64,
) -> (Vec<usize>, usize) {
    let n = lo.len();
    let centre = |i: usize| [(lo[i][0] + hi[i][0]) / 2.0, (lo[i][1] + hi[i][1]) / 2.0];
    let mut parent: Vec<usize> = (0..n).collect();
    let mut merged = 0;
    for i in 0..n {
        if dropped[i] || draws[i].merge_u >= merge_fraction || !lo[i][0].is_finite() {
            continue;
        }
        let c = centre(i);
        let nearest = (0..n).filter(|&j| j != i && !dropped[j] && lo[j][0].is_finite()).min_by(|&a, &b| {
            let d = |j: usize| {
                let cj = centre(j);
                (cj[0] - c[0]).powi(2) + (cj[1] - c[1]).powi(2)
            };
            d(a).total_cmp(&d(b))
        });
        if let Some(j) = nearest {
            // Merge into j's group, avoiding cycles (i's root becomes j's root unless they already are one).
            let (ri, rj) = (root(&parent, i), root(&parent, j));
            if ri != rj {
                parent[ri] = rj;
                merged += 1;
            }
        }
    }
    (parent, merged)
}

/// The kept vertices (of buildings not dropped) in their order, moved by `offset` (ENU metres)
/// and labelled with `id_of(record index)`, then the triangles of kept buildings.
fn kept_mesh(
    scene_mesh: &SceneMesh,
    positions: &[[f64; 3]],
    slot: &[usize],
    dropped: &[bool],
    id_of: impl Fn(usize) -> BuildingId,
    offset: [f64; 3],
) -> SceneMesh {
    let mut mesh = SceneMesh::default();
    let mut remap = vec![u32::MAX; positions.len()];
    let ids = &scene_mesh.building_ids;
    for (v, q) in positions.iter().enumerate() {
        let i = slot[ids[v].get() as usize];
        if dropped[i] {
            continue;
        }
        remap[v] = mesh.positions_m.len() as u32;
        mesh.positions_m.push([
            (q[0] + offset[0]) as f32,
            (q[1] + offset[1]) as f32,
            (q[2] + offset[2]) as f32,
        ]);
        mesh.building_ids.push(id_of(i));
    }
    for tri in scene_mesh.indices.chunks_exact(3) {
        if tri.iter().any(|&v| remap[v as usize] == u32::MAX) {
            continue;
        }
        mesh.indices.extend(tri.iter().map(|&v| remap[v as usize]));
    }
    mesh
}

/// The representative of `i`'s merge group in the union-find `parent`.
fn root(parent: &[usize], mut i: usize) -> usize {
    while parent[i] != i {
        i = parent[i];
    }
    i
}

/// The records of the buildings present in `mesh`, with boxes and triangle counts from it (other
/// fields from the original record of the same ID).
fn recompute_records(records: &[BuildingRecord], mesh: &SceneMesh) -> Vec<BuildingRecord> {
    let max_id = records.iter().map(|b| b.id.get()).max().unwrap_or(0) as usize;
    let mut lo = vec![[f64::INFINITY; 3]; max_id + 1];
    let mut hi = vec![[f64::NEG_INFINITY; 3]; max_id + 1];
    let mut triangles = vec![0u64; max_id + 1];
    for (v, id) in mesh.positions_m.iter().zip(&mesh.building_ids) {
        let i = id.get() as usize;
        for k in 0..3 {
            lo[i][k] = lo[i][k].min(v[k] as f64);
            hi[i][k] = hi[i][k].max(v[k] as f64);
        }
    }
    for tri in mesh.indices.chunks_exact(3) {
        triangles[mesh.building_ids[tri[0] as usize].get() as usize] += 1;
    }
    records
        .iter()
        .filter(|b| triangles[b.id.get() as usize] > 0)
        .map(|b| {
            let i = b.id.get() as usize;
            BuildingRecord {
                bbox_min_enu_m: lo[i],
                bbox_max_enu_m: hi[i],
                height_m: hi[i][2] - lo[i][2],
                triangles: triangles[i],
                ..b.clone()
            }
        })
        .collect()
}

/// Largest difference between two areas' ENU origins for them to share a frame: 1 mm in ECEF (the
/// `ecef_from_enu` translations compared), 1e-9 in the rotation entries.
const SAME_FRAME_TOLERANCE_M: f64 = 1e-3;

/// The map of a run, as the summary records it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct MapSummary {
    /// The prepared area the map comes from (the query area unless `--map-area`).
    pub area: String,
    /// The perturbation applied (`None`: the map as prepared).
    pub perturbation: Option<MapPerturbation>,
    /// What it changed.
    #[serde(skip_serializing_if = "Option::is_none", default)]
    pub changes: Option<PerturbationReport>,
}

/// Errors of choosing a map.
#[derive(Debug, thiserror::Error)]
pub enum MapError {
    #[error(
        "the map area {map_area} is in another ENU frame than the query area {query_area}: origins \
         ({map_lat_deg:.9}°, {map_lon_deg:.9}°, {map_h_m:.3} m) vs ({query_lat_deg:.9}°, \
         {query_lon_deg:.9}°, {query_h_m:.3} m) (lat, lon, ellipsoidal height); give both scene files the \
         same [origin] and prepare them again"
    )]
    /// The map scene's ENU origin differs from the query scene's.
    DifferentFrame {
        /// The query area's name.
        query_area: String,
        /// The map area's name.
        map_area: String,
        /// Latitude of the query area's ENU origin, degrees.
        query_lat_deg: f64,
        /// Longitude of the query area's ENU origin, degrees.
        query_lon_deg: f64,
        /// Ellipsoidal height of the query area's ENU origin, metres.
        query_h_m: f64,
        /// Latitude of the map area's ENU origin, degrees.
        map_lat_deg: f64,
        /// Longitude of the map area's ENU origin, degrees.
        map_lon_deg: f64,
        /// Ellipsoidal height of the map area's ENU origin, metres.
        map_h_m: f64,
    },
}

/// Checks that `map` is in the ENU frame of `query` (same `ecef_from_enu` to
/// [`SAME_FRAME_TOLERANCE_M`]).
///
/// # Errors
/// [`MapError::DifferentFrame`] naming both areas and their origins.
pub fn check_same_frame(query: &PreparedScene, map: &PreparedScene) -> Result<(), MapError> {
    let (a, b) = (&query.manifest.ecef_from_enu, &map.manifest.ecef_from_enu);
    let translation = (a.w_axis.truncate() - b.w_axis.truncate()).length();
    let rotation = [
        (a.x_axis - b.x_axis).abs().max_element(),
        (a.y_axis - b.y_axis).abs().max_element(),
        (a.z_axis - b.z_axis).abs().max_element(),
    ]
    .into_iter()
    .fold(0.0, f64::max);
    if translation <= SAME_FRAME_TOLERANCE_M && rotation <= 1e-9 {
        return Ok(());
    }
    let (q, m) = (query.manifest.origin, map.manifest.origin);
    Err(MapError::DifferentFrame {
        query_area: query.manifest.area.clone(),
        map_area: map.manifest.area.clone(),
        query_lat_deg: q.lat_deg,
        query_lon_deg: q.lon_deg,
        query_h_m: q.h_m,
        map_lat_deg: m.lat_deg,
        map_lon_deg: m.lon_deg,
        map_h_m: m.h_m,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::BuildingId;

    /// A gable house (ID `id`): a 10 × 6 m box with 6 m walls and a ridge at 9 m along x, its
    /// south-west corner at (x0, 0, 0), as 8 box corners + 2 ridge points.
    fn house(mesh: &mut SceneMesh, records: &mut Vec<BuildingRecord>, id: u32, x0: f32) {
        let base = mesh.positions_m.len() as u32;
        let id = BuildingId::new(id).unwrap();
        for z in [0.0, 6.0] {
            for (x, y) in [(0.0, 0.0), (10.0, 0.0), (10.0, 6.0), (0.0, 6.0)] {
                mesh.positions_m.push([x0 + x, y, z]);
            }
        }
        mesh.positions_m.extend([[x0, 3.0, 9.0], [x0 + 10.0, 3.0, 9.0]]);
        mesh.building_ids.extend([id; 10]);
        // Walls (two triangles each), gables, roof planes.
        let tris: [[u32; 3]; 12] = [
            [0, 1, 5],
            [0, 5, 4],
            [1, 2, 6],
            [1, 6, 5],
            [2, 3, 7],
            [2, 7, 6],
            [3, 0, 4],
            [3, 4, 7],
            [4, 5, 9],
            [4, 9, 8],
            [7, 6, 9],
            [7, 9, 8],
        ];
        mesh.indices.extend(tris.iter().flatten().map(|i| base + i));
        records.push(BuildingRecord {
            id,
            source_id: format!("b{}", id.get()),
            source_file: "test".into(),
            lod: "2".into(),
            height_m: 9.0,
            measured_height_m: None,
            footprint_area_m2: 60.0,
            centroid_lat_deg: 0.0,
            centroid_lon_deg: 0.0,
            bbox_min_enu_m: [x0 as f64, 0.0, 0.0],
            bbox_max_enu_m: [x0 as f64 + 10.0, 6.0, 9.0],
            triangles: 12,
        });
    }

    fn town() -> (SceneMesh, Vec<BuildingRecord>) {
        let (mut mesh, mut records) = (SceneMesh::default(), Vec::new());
        house(&mut mesh, &mut records, 1, 0.0);
        house(&mut mesh, &mut records, 2, 20.0);
        house(&mut mesh, &mut records, 3, 60.0);
        (mesh, records)
    }

    #[test]
    fn identity_leaves_the_map_as_it_is() {
        let (mesh, records) = town();
        let (m, r, report) = perturb_mesh(&mesh, &records, &MapPerturbation::default());
        assert_eq!(m, mesh);
        assert_eq!(r, records);
        assert_eq!(report.buildings_after, 3);
        assert!(MapPerturbation { seed: 5, ..Default::default() }.is_identity());
    }

    #[test]
    fn lod1_extrudes_the_footprint_to_the_top() {
        let (mesh, records) = town();
        let (m, r, _) = perturb_mesh(&mesh, &records, &MapPerturbation { lod1: true, ..Default::default() });
        // Every vertex at the bottom (0 m) or the top (9 m): eaves rise from 6 m to 9 m, the ridge stays.
        assert!(m.positions_m.iter().all(|v| v[2] == 0.0 || v[2] == 9.0), "{:?}", m.positions_m);
        assert_eq!(m.positions_m.iter().filter(|v| v[2] == 9.0).count(), 3 * 6);
        // Footprints and boxes unchanged.
        assert_eq!(
            r.iter().map(|b| (b.bbox_min_enu_m, b.bbox_max_enu_m)).collect::<Vec<_>>(),
            records.iter().map(|b| (b.bbox_min_enu_m, b.bbox_max_enu_m)).collect::<Vec<_>>()
        );
    }

    #[test]
    fn lod1_at_a_roof_percentile_stands_between_eaves_and_ridge() {
        let (mesh, records) = town();
        let at = |pct: f64| {
            let p = MapPerturbation { lod1: true, lod1_roof_percentile: Some(pct), ..Default::default() };
            let (m, _, _) = perturb_mesh(&mesh, &records, &p);
            let mut heights: Vec<f32> = m.positions_m.iter().map(|v| v[2]).filter(|&z| z != 0.0).collect();
            heights.dedup();
            heights
        };
        // The roof planes rise evenly from the eaves (6 m) to the ridge (9 m), each as two triangles
        // whose centroids stand at 7 m and 8 m: half the roof area below 7.5 m, half above.
        assert_eq!(at(30.0), vec![7.0], "30th percentile: the lower triangles");
        assert_eq!(at(70.0), vec![8.0], "70th percentile: the upper triangles");
        assert_eq!(at(100.0), vec![8.0], "the highest roof sample, not the ridge vertex");
        // Percentile 0 still keeps a block above the ground band.
        assert!(at(0.0).iter().all(|&z| z > LOD1_GROUND_BAND_M as f32));
    }

    #[test]
    fn height_error_moves_tops_only_and_is_seeded() {
        let (mesh, records) = town();
        let p = MapPerturbation { height_sigma_m: 2.0, seed: 7, ..Default::default() };
        let (a, ra, _) = perturb_mesh(&mesh, &records, &p);
        let (b, _, _) = perturb_mesh(&mesh, &records, &p);
        assert_eq!(a, b, "same seed, same map");
        let (c, _, _) = perturb_mesh(&mesh, &records, &MapPerturbation { seed: 8, ..p.clone() });
        assert_ne!(a, c, "another seed, another map");
        for (before, after) in records.iter().zip(&ra) {
            assert_eq!(after.bbox_min_enu_m, before.bbox_min_enu_m, "bottoms and footprints stay");
            assert_eq!(after.bbox_max_enu_m[..2], before.bbox_max_enu_m[..2]);
            assert_ne!(after.bbox_max_enu_m[2], 9.0, "the top moved");
            assert!(after.bbox_max_enu_m[2] >= MIN_HEIGHT_M);
        }
    }

    #[test]
    fn shift_and_scale_move_footprints() {
        let (mesh, records) = town();
        let (_, r, _) = perturb_mesh(
            &mesh,
            &records,
            &MapPerturbation { shift_sigma_m: 1.0, seed: 1, ..Default::default() },
        );
        for (before, after) in records.iter().zip(&r) {
            let w = |b: &BuildingRecord| b.bbox_max_enu_m[0] - b.bbox_min_enu_m[0];
            assert!((w(after) - w(before)).abs() < 1e-5, "a shift keeps the size");
            assert_ne!(after.bbox_min_enu_m[0], before.bbox_min_enu_m[0]);
            assert_eq!(after.bbox_min_enu_m[2], 0.0);
        }
        let (_, r, _) = perturb_mesh(
            &mesh,
            &records,
            &MapPerturbation { scale_sigma: 0.1, seed: 1, ..Default::default() },
        );
        for (before, after) in records.iter().zip(&r) {
            let c = |b: &BuildingRecord| (b.bbox_max_enu_m[0] + b.bbox_min_enu_m[0]) / 2.0;
            assert!((c(after) - c(before)).abs() < 1e-4, "a scale keeps the centre");
            let ratio = (after.bbox_max_enu_m[0] - after.bbox_min_enu_m[0]) / 10.0;
            let ratio_y = (after.bbox_max_enu_m[1] - after.bbox_min_enu_m[1]) / 6.0;
            assert!((ratio - ratio_y).abs() < 1e-5 && (ratio - 1.0).abs() > 1e-4, "{ratio} {ratio_y}");
        }
    }

    #[test]
    fn drops_merges_and_offset() {
        let (mesh, records) = town();
        let (m, r, report) =
            perturb_mesh(&mesh, &records, &MapPerturbation { drop_fraction: 1.0, ..Default::default() });
        assert!(m.indices.is_empty() && r.is_empty());
        assert_eq!((report.dropped, report.buildings_after), (3, 0));
        // Everything merged: one instance left, its box covering all three houses.
        let (m, r, report) =
            perturb_mesh(&mesh, &records, &MapPerturbation { merge_fraction: 1.0, ..Default::default() });
        assert_eq!(report.buildings_after, 1, "{report:?}");
        assert_eq!(m.triangle_count(), mesh.triangle_count());
        assert_eq!((r[0].bbox_min_enu_m[0], r[0].bbox_max_enu_m[0]), (0.0, 70.0));
        assert_eq!(r[0].triangles, 36);
        let (m, _, _) = perturb_mesh(
            &mesh,
            &records,
            &MapPerturbation { offset_enu_m: [1.5, -2.0, 0.25], ..Default::default() },
        );
        for (a, b) in mesh.positions_m.iter().zip(&m.positions_m) {
            assert_eq!([b[0] - a[0], b[1] - a[1], b[2] - a[2]], [1.5, -2.0, 0.25]);
        }
    }
}
