//! Helpers of the Blender integration tests: finding the bpy interpreter, a tiny GLB writer for box
//! buildings (with `_FEATURE_ID_0`), b3dm/tileset writers, and an independent f64 ray-casting reference
//! rasteriser (pixel centres, nearest hit) to compare Blender's ID renders with.

#![allow(dead_code)]

use std::path::{Path, PathBuf};

use glam::DVec3;
use insgen::camera::{Intrinsics, Pose};

/// The interpreter with bpy: `$INSGEN_BLENDER_PYTHON`, else `<repo>/.venv-blender/bin/python`. When
/// missing the test skips with a reason, except under CI=true where it fails.
pub fn blender_python() -> Option<PathBuf> {
    let p = match std::env::var_os("INSGEN_BLENDER_PYTHON").filter(|v| !v.is_empty()) {
        Some(p) => PathBuf::from(p),
        None => Path::new(env!("CARGO_MANIFEST_DIR")).join(".venv-blender/bin/python"),
    };
    if p.is_file() {
        return Some(p);
    }
    if std::env::var("CI").map(|v| v == "true").unwrap_or(false) {
        panic!("CI: no bpy interpreter at {} (run scripts/setup_blender.sh)", p.display());
    }
    eprintln!("skipping: no bpy interpreter at {} (run scripts/setup_blender.sh)", p.display());
    None
}

/// Real data under `../shared/data`, skipping (or failing under CI=true) when absent.
pub use crate::util::shared_data;

/// An axis-aligned box building in ENU metres.
#[derive(Debug, Clone, Copy)]
pub struct BoxBuilding {
    pub id: u32,
    pub min_m: [f64; 3],
    pub max_m: [f64; 3],
}

impl BoxBuilding {
    pub fn new(id: u32, e0: f64, n0: f64, e1: f64, n1: f64, z0: f64, z1: f64) -> Self {
        BoxBuilding { id, min_m: [e0, n0, z0], max_m: [e1, n1, z1] }
    }

    /// The 12 triangles of the box (ENU), outward winding not guaranteed (renderers do not cull).
    pub fn triangles(&self) -> Vec<[[f64; 3]; 3]> {
        let [x0, y0, z0] = self.min_m;
        let [x1, y1, z1] = self.max_m;
        let c = [
            [x0, y0, z0],
            [x1, y0, z0],
            [x1, y1, z0],
            [x0, y1, z0],
            [x0, y0, z1],
            [x1, y0, z1],
            [x1, y1, z1],
            [x0, y1, z1],
        ];
        let quads = [[0, 1, 2, 3], [4, 5, 6, 7], [0, 1, 5, 4], [1, 2, 6, 5], [2, 3, 7, 6], [3, 0, 4, 7]];
        quads.iter().flat_map(|q| [[c[q[0]], c[q[1]], c[q[2]]], [c[q[0]], c[q[2]], c[q[3]]]]).collect()
    }
}

/// A small city of boxes around the origin, with IDs that exercise all 24 bits.
pub fn box_city() -> Vec<BoxBuilding> {
    vec![
        BoxBuilding::new(1, -30.0, -20.0, -5.0, 10.0, 0.0, 25.0),
        BoxBuilding::new(70_000, 5.0, -25.0, 30.0, 5.0, 0.0, 12.0),
        BoxBuilding::new(16_000_000, -10.0, 15.0, 20.0, 35.0, 0.0, 40.0),
        BoxBuilding::new(255, 35.0, 10.0, 50.0, 30.0, 0.0, 18.0),
        BoxBuilding::new(65_536, -55.0, -45.0, -35.0, -25.0, 0.0, 8.0),
        BoxBuilding::new(3, -50.0, 20.0, -35.0, 45.0, 0.0, 60.0),
    ]
}

/// Writes a GLB of `boxes` with POSITION = `to_gltf(ENU point)` (f32), `_FEATURE_ID_0` (float) and u32
/// indices; `extra_json` entries are merged into the top-level glTF object (e.g. CESIUM_RTC).
pub fn glb_bytes(
    boxes: &[BoxBuilding],
    to_gltf: &dyn Fn([f64; 3]) -> [f64; 3],
    extra_json: serde_json::Value,
) -> Vec<u8> {
    let mut pos: Vec<f32> = Vec::new();
    let mut fid: Vec<f32> = Vec::new();
    let mut idx: Vec<u32> = Vec::new();
    for b in boxes {
        for t in b.triangles() {
            for p in t {
                let g = to_gltf(p);
                idx.push((pos.len() / 3) as u32);
                pos.extend(g.map(|v| v as f32));
                fid.push(b.id as f32);
            }
        }
    }
    let n = pos.len() / 3;
    let mut lo = [f32::INFINITY; 3];
    let mut hi = [f32::NEG_INFINITY; 3];
    for p in pos.chunks_exact(3) {
        for k in 0..3 {
            lo[k] = lo[k].min(p[k]);
            hi[k] = hi[k].max(p[k]);
        }
    }
    let mut bin: Vec<u8> = Vec::new();
    bin.extend(pos.iter().flat_map(|v| v.to_le_bytes()));
    bin.extend(fid.iter().flat_map(|v| v.to_le_bytes()));
    bin.extend(idx.iter().flat_map(|v| v.to_le_bytes()));
    let mut json = serde_json::json!({
        "asset": {"version": "2.0", "generator": "insgen tests"},
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": [{"mesh": 0}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0, "_FEATURE_ID_0": 1}, "indices": 2}]}],
        "buffers": [{"byteLength": bin.len()}],
        "bufferViews": [
            {"buffer": 0, "byteOffset": 0, "byteLength": 12 * n},
            {"buffer": 0, "byteOffset": 12 * n, "byteLength": 4 * n},
            {"buffer": 0, "byteOffset": 16 * n, "byteLength": 4 * idx.len()}
        ],
        "accessors": [
            {"bufferView": 0, "componentType": 5126, "count": n, "type": "VEC3", "min": lo, "max": hi},
            {"bufferView": 1, "componentType": 5126, "count": n, "type": "SCALAR"},
            {"bufferView": 2, "componentType": 5125, "count": idx.len(), "type": "SCALAR"}
        ]
    });
    if let (Some(o), Some(extra)) = (json.as_object_mut(), extra_json.as_object()) {
        for (k, v) in extra {
            o.insert(k.clone(), v.clone());
        }
    }
    crate::util::glb(&json, &bin)
}

/// The prepared-scene convention: glTF (x, y, z) = ENU (e, u, −n).
pub fn scene_gltf(p: [f64; 3]) -> [f64; 3] {
    [p[0], p[2], -p[1]]
}

/// A b3dm wrapping `glb`, with an optional feature-table RTC_CENTER.
pub fn b3dm_bytes(glb: &[u8], rtc: Option<[f64; 3]>) -> Vec<u8> {
    let mut ft = match rtc {
        Some(c) => serde_json::to_vec(&serde_json::json!({"BATCH_LENGTH": 0, "RTC_CENTER": c})).unwrap(),
        None => br#"{"BATCH_LENGTH":0}"#.to_vec(),
    };
    while (28 + ft.len()) % 8 != 0 {
        ft.push(b' ');
    }
    let mut out = Vec::new();
    out.extend_from_slice(b"b3dm");
    out.extend_from_slice(&1u32.to_le_bytes());
    out.extend_from_slice(&((28 + ft.len() + glb.len()) as u32).to_le_bytes());
    out.extend_from_slice(&(ft.len() as u32).to_le_bytes());
    out.extend_from_slice(&[0u8; 12]);
    out.extend_from_slice(&ft);
    out.extend_from_slice(glb);
    out
}

/// Independent reference: for each pixel centre, cast the OpenCV ray and keep the nearest triangle's
/// building ID (Möller–Trumbore in f64). Returns row-major IDs.
pub fn reference_ids(boxes: &[BoxBuilding], k: &Intrinsics, pose: &Pose) -> Vec<u32> {
    let tris: Vec<([[f64; 3]; 3], u32)> =
        boxes.iter().flat_map(|b| b.triangles().into_iter().map(move |t| (t, b.id))).collect();
    let r = pose.r_world_from_cam;
    let c = pose.centre_m.to_array();
    let mut ids = vec![0u32; (k.width_px * k.height_px) as usize];
    for j in 0..k.height_px {
        for i in 0..k.width_px {
            let d_cam = [(i as f64 + 0.5 - k.cx_px) / k.fx_px, (j as f64 + 0.5 - k.cy_px) / k.fy_px, 1.0];
            let d = (r * DVec3::from(d_cam)).to_array();
            let mut best = f64::INFINITY;
            let mut id = 0;
            for (t, tid) in &tris {
                if let Some(dist) = ray_triangle(c, d, t) {
                    if dist < best {
                        best = dist;
                        id = *tid;
                    }
                }
            }
            ids[(j * k.width_px + i) as usize] = id;
        }
    }
    ids
}

fn ray_triangle(o: [f64; 3], d: [f64; 3], t: &[[f64; 3]; 3]) -> Option<f64> {
    let (o, d) = (DVec3::from(o), DVec3::from(d));
    let [t0, t1, t2] = t.map(DVec3::from);
    let (e1, e2) = (t1 - t0, t2 - t0);
    let p = d.cross(e2);
    let det = e1.dot(p);
    if det.abs() < 1e-12 {
        return None;
    }
    let inv = 1.0 / det;
    let s = o - t0;
    let u = s.dot(p) * inv;
    if !(0.0..=1.0).contains(&u) {
        return None;
    }
    let q = s.cross(e1);
    let v = d.dot(q) * inv;
    if v < 0.0 || u + v > 1.0 {
        return None;
    }
    let dist = e2.dot(q) * inv;
    (dist > 0.0).then_some(dist)
}

/// Pixels whose 3×3 neighbourhood in `ids` is not uniform: where a sampling tie can flip the ID.
pub fn edge_mask(ids: &[u32], w: u32, h: u32) -> Vec<bool> {
    let (w, h) = (w as i64, h as i64);
    let mut out = vec![false; ids.len()];
    for y in 0..h {
        for x in 0..w {
            let v = ids[(y * w + x) as usize];
            'n: for dy in -1..=1 {
                for dx in -1..=1 {
                    let (nx, ny) = (x + dx, y + dy);
                    if nx >= 0 && ny >= 0 && nx < w && ny < h && ids[(ny * w + nx) as usize] != v {
                        out[(y * w + x) as usize] = true;
                        break 'n;
                    }
                }
            }
        }
    }
    out
}

/// Decodes an 8-bit RGB PNG into (width, height, bytes).
pub fn read_rgb_png(path: &Path) -> (u32, u32, Vec<u8>) {
    read_rgb_png_bytes(&std::fs::read(path).unwrap())
}

/// Decodes 8-bit RGB PNG bytes into (width, height, bytes).
pub fn read_rgb_png_bytes(png_bytes: &[u8]) -> (u32, u32, Vec<u8>) {
    let decoder = png::Decoder::new(std::io::Cursor::new(png_bytes));
    let mut reader = decoder.read_info().unwrap();
    let mut buf = vec![0; reader.output_buffer_size()];
    let info = reader.next_frame(&mut buf).unwrap();
    assert_eq!((info.bit_depth, info.color_type), (png::BitDepth::Eight, png::ColorType::Rgb));
    buf.truncate(info.buffer_size());
    (info.width, info.height, buf)
}
