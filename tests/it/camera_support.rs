//! Shared fixtures of the camera tests: a synthetic city built from boxes, as a `PreparedScene`.
//!
//! The city: an L-shaped area polygon (1200 × 900 m with the north-west 500 × 350 m cut away), a
//! lattice of box buildings every 60 m over a larger square (so views near the polygon edge still see
//! buildings), blocks 28–46 m wide and 12–117 m tall from a fixed formula, and one
//! 260 m tower replacing the block at (180, 0). Ground level
//! is −2 m ENU. Everything is computed here; no file is read.
#![allow(dead_code)]

use insgen::camera::{CameraSpec, Trajectory};
use insgen::geo::{EnuFrame, Geodetic};
use insgen::scene::artifact::{GeoidUsed, Origin};
use insgen::scene::{BuildingId, BuildingRecord, Manifest, PreparedScene, SceneMesh};

pub const GROUND_M: f64 = -2.0;
pub const TOWER_CENTRE_M: [f64; 2] = [180.0, 0.0];
pub const TOWER_TOP_M: f64 = 258.0;

pub fn origin() -> Geodetic {
    Geodetic { lat_deg: 35.6585, lon_deg: 139.7010, h_m: 40.0 }
}

pub fn area_polygon() -> Vec<[f64; 2]> {
    vec![[-600.0, -450.0], [600.0, -450.0], [600.0, 450.0], [-100.0, 450.0], [-100.0, 100.0], [-600.0, 100.0]]
}

/// Boxes ([min], [max]) of the synthetic city, ENU metres.
pub fn boxes() -> Vec<([f64; 3], [f64; 3])> {
    let mut out = Vec::new();
    for j in -12i32..=12 {
        for i in -14i32..=14 {
            let c = [i as f64 * 60.0, j as f64 * 60.0];
            if (c[0] - TOWER_CENTRE_M[0]).abs() < 1.0 && (c[1] - TOWER_CENTRE_M[1]).abs() < 1.0 {
                continue;
            }
            let k = (i * 7 + j * 13).rem_euclid(22) as f64;
            let half = 14.0 + (k % 4.0) * 3.0;
            let top = GROUND_M + 12.0 + k * 5.0;
            out.push(([c[0] - half, c[1] - half, GROUND_M], [c[0] + half, c[1] + half, top]));
        }
    }
    let t = TOWER_CENTRE_M;
    out.push(([t[0] - 15.0, t[1] - 15.0, GROUND_M], [t[0] + 15.0, t[1] + 15.0, TOWER_TOP_M]));
    out
}

/// The 12 triangles of a box (outward winding irrelevant here).
fn box_mesh(mesh: &mut SceneMesh, lo: [f64; 3], hi: [f64; 3], id: BuildingId) {
    let base = mesh.positions_m.len() as u32;
    for k in 0..8 {
        let p = [
            if k & 1 == 0 { lo[0] } else { hi[0] },
            if k & 2 == 0 { lo[1] } else { hi[1] },
            if k & 4 == 0 { lo[2] } else { hi[2] },
        ];
        mesh.positions_m.push([p[0] as f32, p[1] as f32, p[2] as f32]);
        mesh.building_ids.push(id);
    }
    let quads = [[0, 1, 3, 2], [4, 5, 7, 6], [0, 1, 5, 4], [2, 3, 7, 6], [0, 2, 6, 4], [1, 3, 7, 5]];
    for q in quads {
        mesh.indices.extend([base + q[0], base + q[1], base + q[2], base + q[0], base + q[2], base + q[3]]);
    }
}

pub fn city() -> PreparedScene {
    city_with(area_polygon(), true)
}

pub fn city_with(polygon: Vec<[f64; 2]>, with_mesh: bool) -> PreparedScene {
    let enu = EnuFrame::new(origin());
    let mut mesh = SceneMesh::default();
    let mut buildings = Vec::new();
    for (n, (lo, hi)) in boxes().into_iter().enumerate() {
        let id = BuildingId::from_index(n).unwrap();
        if with_mesh {
            box_mesh(&mut mesh, lo, hi, id);
        }
        let c = enu.enu_to_geodetic(glam::DVec3::new((lo[0] + hi[0]) / 2.0, (lo[1] + hi[1]) / 2.0, lo[2]));
        buildings.push(BuildingRecord {
            id,
            source_id: format!("box{n}"),
            source_file: "synthetic".into(),
            lod: "1".into(),
            height_m: hi[2] - lo[2],
            measured_height_m: None,
            footprint_area_m2: (hi[0] - lo[0]) * (hi[1] - lo[1]),
            centroid_lat_deg: c.lat_deg,
            centroid_lon_deg: c.lon_deg,
            bbox_min_enu_m: lo,
            bbox_max_enu_m: hi,
            triangles: 12,
        });
    }
    let o = origin();
    let manifest = Manifest {
        insgen_version: "test".into(),
        area: "boxcity".into(),
        split: "train".into(),
        origin: Origin { lat_deg: o.lat_deg, lon_deg: o.lon_deg, h_m: o.h_m },
        ecef_from_enu: enu.ecef_from_enu(),
        area_polygon_enu_m: polygon,
        ground_enu_m: GROUND_M,
        geoid: GeoidUsed {
            model: "none".into(),
            grid: None,
            undulation_at_origin_m: 0.0,
            ..Default::default()
        },
        sources: Vec::new(),
        buildings: buildings.len() as u64,
        triangles: mesh.triangle_count() as u64,
        degenerate_faces: 0,
        attributions: Vec::new(),
        clutter: None,
        alignment: None,
    };
    PreparedScene { manifest, buildings, mesh, clutter: Default::default() }
}

pub fn preset(name: &str) -> CameraSpec {
    CameraSpec::preset(name).expect("built-in preset")
}

pub fn with_strategy(name: &str, s: Trajectory) -> CameraSpec {
    let mut c = preset(name);
    c.strategy = s;
    c
}

/// Independent even–odd point-in-polygon test (written separately from `camera::area`).
pub fn inside(poly: &[[f64; 2]], p: [f64; 2]) -> bool {
    let mut c = false;
    let n = poly.len();
    let mut j = n - 1;
    for i in 0..n {
        let (a, b) = (poly[i], poly[j]);
        if ((a[1] > p[1]) != (b[1] > p[1])) && (p[0] < (b[0] - a[0]) * (p[1] - a[1]) / (b[1] - a[1]) + a[0]) {
            c = !c;
        }
        j = i;
    }
    c
}

/// Highest box top within `r` metres (horizontally) of `p`, by brute force over all boxes.
pub fn tallest_near(p: [f64; 2], r: f64) -> f64 {
    boxes()
        .iter()
        .filter(|(lo, hi)| {
            let dx = (lo[0] - p[0]).max(0.0).max(p[0] - hi[0]);
            let dy = (lo[1] - p[1]).max(0.0).max(p[1] - hi[1]);
            dx * dx + dy * dy <= r * r
        })
        .map(|(_, hi)| hi[2])
        .fold(f64::NEG_INFINITY, f64::max)
}
