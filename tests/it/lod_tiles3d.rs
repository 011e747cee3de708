//! 3D Tiles reader: tileset traversal and frame maths against hand computations, Draco content
//! encoded by Google's C++ Draco, bad-input errors, and the PLATEAU Shibuya tileset checked against
//! the per-feature lon/lat boxes its own batch table carries.
//!
//! Fixtures: `tests/fixtures/tiles3d/` (made by `make_fixtures.py` there, with DracoPy); the
//! hand-computed tileset below is generated into a temporary folder by [`write_hand_tileset`].

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

use insgen::geo::ecef_to_geodetic;
use insgen::lod::tiles3d::{self, TilesReport};
use insgen::lod::{read_source, Format, Frame, Geometry, LodError, ReadOptions, SourceModel, TriMesh};
use serde_json::json;

use crate::util::{error_chain, shared_data};

fn fixture(name: &str) -> PathBuf {
    crate::util::fixture("tiles3d", name)
}

fn mesh(g: &Geometry) -> &TriMesh {
    match g {
        Geometry::Mesh(m) => m,
        Geometry::Polygons(_) => panic!("3D Tiles buildings are meshes"),
    }
}

fn building<'m>(model: &'m SourceModel, id: &str) -> &'m insgen::lod::SourceBuilding {
    model.buildings.iter().find(|b| b.source_id == id).unwrap_or_else(|| {
        panic!("no building {id:?} in {:?}", model.buildings.iter().map(|b| &b.source_id).collect::<Vec<_>>())
    })
}

/// Asserts that `m`'s vertices are exactly the points of `expected` (each within `tol_m`, each
/// expected point hit).
fn assert_vertices(m: &TriMesh, expected: &[[f64; 3]], tol_m: f64) {
    let close = |a: &[f64; 3], b: &[f64; 3]| (0..3).all(|k| (a[k] - b[k]).abs() <= tol_m);
    for p in &m.positions {
        assert!(expected.iter().any(|e| close(p, e)), "unexpected vertex {p:?}; expected {expected:?}");
    }
    for e in expected {
        assert!(m.positions.iter().any(|p| close(p, e)), "no vertex at {e:?}; got {:?}", m.positions);
    }
}

// ---------------------------------------------------------------------------------------------
// A hand-built tileset (no Draco): every transform of the chain, ADD/REPLACE, an external 1.1
// tileset with EXT_mesh_features + EXT_structural_metadata, merging by gml_id, ID-less content.
// ---------------------------------------------------------------------------------------------

fn f32_bytes(v: &[f32]) -> Vec<u8> {
    v.iter().flat_map(|x| x.to_le_bytes()).collect()
}

use crate::util::glb;

fn pad_to(mut v: Vec<u8>, n: usize, fill: u8) -> Vec<u8> {
    while !v.len().is_multiple_of(n) {
        v.push(fill);
    }
    v
}

/// A b3dm around a GLB (tables padded to 8 bytes, as the spec asks).
fn b3dm(feature_table: &serde_json::Value, batch_table: &serde_json::Value, glb: &[u8]) -> Vec<u8> {
    let ft = pad_to(serde_json::to_vec(feature_table).unwrap(), 8, b' ');
    let bt = pad_to(serde_json::to_vec(batch_table).unwrap(), 8, b' ');
    let total = 28 + ft.len() + bt.len() + glb.len();
    let mut out = b"b3dm".to_vec();
    for w in [1, total, ft.len(), 0, bt.len(), 0] {
        out.extend_from_slice(&(w as u32).to_le_bytes());
    }
    out.extend_from_slice(&ft);
    out.extend_from_slice(&bt);
    out.extend_from_slice(glb);
    out
}

/// A one-primitive glTF: f32 positions, u16 indices, optional f32 scalar feature attribute
/// `feature_attr`; `extra` is merged into the root JSON; `node` is the single node's JSON.
fn simple_glb(
    positions: &[[f32; 3]],
    indices: &[u16],
    feature: Option<(&str, &[f32])>,
    node: serde_json::Value,
    prim_ext: serde_json::Value,
    root_ext: serde_json::Value,
    extra_views: &[Vec<u8>],
) -> Vec<u8> {
    let mut bin = Vec::new();
    let mut views = Vec::new();
    let mut push = |bytes: &[u8], bin: &mut Vec<u8>| {
        let off = bin.len();
        bin.extend_from_slice(bytes);
        while !bin.len().is_multiple_of(4) {
            bin.push(0);
        }
        views.push(json!({"buffer": 0, "byteOffset": off, "byteLength": bytes.len()}));
        views.len() - 1
    };
    let flat: Vec<f32> = positions.iter().flatten().copied().collect();
    let pos_view = push(&f32_bytes(&flat), &mut bin);
    let idx: Vec<u8> = indices.iter().flat_map(|i| i.to_le_bytes()).collect();
    let idx_view = push(&idx, &mut bin);
    let mut accessors = vec![
        json!({"bufferView": pos_view, "componentType": 5126, "count": positions.len(), "type": "VEC3"}),
        json!({"bufferView": idx_view, "componentType": 5123, "count": indices.len(), "type": "SCALAR"}),
    ];
    let mut attributes = json!({"POSITION": 0});
    if let Some((name, values)) = feature {
        let v = push(&f32_bytes(values), &mut bin);
        accessors
            .push(json!({"bufferView": v, "componentType": 5126, "count": values.len(), "type": "SCALAR"}));
        attributes[name] = json!(2);
    }
    for extra in extra_views {
        push(extra, &mut bin);
    }
    let mut node = node;
    node["mesh"] = json!(0);
    let gltf = json!({
        "asset": {"version": "2.0"},
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": [node],
        "meshes": [{"primitives": [{"attributes": attributes, "indices": 1, "extensions": prim_ext}]}],
        "accessors": accessors,
        "bufferViews": views,
        "buffers": [{"byteLength": bin.len()}],
        "extensions": root_ext,
    });
    glb(&gltf, &bin)
}

/// Writes the hand-computed tileset into `dir` and returns the root tileset path.
///
/// ```text
/// tileset.json   root: transform T1 = translate(1000, 2000, 3000), refine ADD, no content
///  ├─ children[0]: transform T2 = scale 2, content.url "a%20b.b3dm" (1.0 key, %-escaped)
///  │     b3dm: RTC_CENTER (10, 20, 30); node matrix translate(1, 2, 3); _BATCHID 0/1;
///  │     batch table gml_id [bldg_a, bldg_b], lod [2, 1], measuredHeight [12.5, null]
///  ├─ children[1]: refine REPLACE, content coarse.glb (superseded: must not be read)
///  │     └─ children[0]: content ext/tileset.json (external 1.1 tileset)
///  │           root: transform translate(0, 0, 500), contents [f.glb]
///  │           f.glb: EXT_mesh_features _FEATURE_ID_0 → property table gml_id [ext_1, bldg_a],
///  │                  lod [2, 1], height [6.5, 8.5] (FLOAT32 with scale and offset)
///  └─ children[2]: contents [idless.glb] — three triangles, no feature IDs
/// ```
fn write_hand_tileset(dir: &Path) -> PathBuf {
    // b3dm: two triangles in glTF (y-up) coordinates.
    let positions = [
        [0.0, 0.0, 0.0],
        [4.0, 0.0, 0.0],
        [4.0, 3.0, 0.0],
        [10.0, 0.0, 0.0],
        [12.0, 0.0, 0.0],
        [12.0, 0.0, -2.0],
    ];
    let node = json!({"matrix": [1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 1, 2, 3, 1]});
    let g = simple_glb(
        &positions,
        &[0, 1, 2, 3, 4, 5],
        Some(("_BATCHID", &[0.0, 0.0, 0.0, 1.0, 1.0, 1.0])),
        node,
        json!({}),
        json!({}),
        &[],
    );
    let ft = json!({"BATCH_LENGTH": 2, "RTC_CENTER": [10.0, 20.0, 30.0]});
    let bt = json!({"gml_id": ["bldg_a", "bldg_b"], "lod": [2, 1], "measuredHeight": [12.5, null]});
    std::fs::write(dir.join("a b.b3dm"), b3dm(&ft, &bt, &g)).unwrap();

    // coarse.glb: valid, but its tile is refined away.
    let g = simple_glb(&positions[..3], &[0, 1, 2], None, json!({}), json!({}), json!({}), &[]);
    std::fs::write(dir.join("coarse.glb"), g).unwrap();

    // ext/f.glb: 3D Tiles 1.1 glTF with feature IDs and a property table of two strings.
    std::fs::create_dir_all(dir.join("ext")).unwrap();
    let strings = b"ext_1bldg_a".to_vec();
    let offsets: Vec<u8> = [0u32, 5, 11].iter().flat_map(|o| o.to_le_bytes()).collect();
    let mf = json!({"EXT_mesh_features": {"featureIds": [{"featureCount": 2, "attribute": 0, "propertyTable": 0}]}});
    // Properties: gml_id (STRING), lod (UINT8 [2, 1]), height (FLOAT32 [3, 4] with scale 2 and
    // offset 0.5 → 6.5, 8.5 m).
    let lod = vec![2u8, 1];
    let height = f32_bytes(&[3.0, 4.0]);
    let sm = json!({"EXT_structural_metadata": {
        "schema": {"id": "s", "classes": {"building": {"properties": {
            "gml_id": {"type": "STRING"},
            "lod": {"type": "SCALAR", "componentType": "UINT8"},
            "height": {"type": "SCALAR", "componentType": "FLOAT32", "scale": 2.0, "offset": 0.5}}}}},
        "propertyTables": [{"class": "building", "count": 2, "properties": {
            "gml_id": {"values": 3, "stringOffsets": 4}, "lod": {"values": 5}, "height": {"values": 6}}}]
    }});
    let g = simple_glb(
        &[
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            [5.0, 0.0, 0.0],
            [6.0, 0.0, 0.0],
            [5.0, 1.0, 0.0],
        ],
        &[0, 1, 2, 3, 4, 5],
        Some(("_FEATURE_ID_0", &[0.0, 0.0, 0.0, 1.0, 1.0, 1.0])),
        json!({}),
        mf,
        sm,
        &[strings, offsets, lod, height],
    );
    std::fs::write(dir.join("ext/f.glb"), g).unwrap();
    let ext = json!({"asset": {"version": "1.1"}, "geometricError": 0,
        "root": {"transform": [1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 500, 1], "geometricError": 0,
                 "boundingVolume": {"sphere": [0, 0, 0, 100]}, "refine": "REPLACE", "contents": [{"uri": "f.glb"}]}});
    std::fs::write(dir.join("ext/tileset.json"), serde_json::to_vec_pretty(&ext).unwrap()).unwrap();

    // idless.glb: triangles 0 and 1 separate; triangle 2 touches triangle 1 through a repeated vertex.
    let g = simple_glb(
        &[
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            [10.0, 0.0, 0.0],
            [11.0, 0.0, 0.0],
            [10.0, 1.0, 0.0],
            [11.0, 0.0, 0.0],
            [12.0, 0.0, 0.0],
            [12.0, 1.0, 0.0],
        ],
        &[0, 1, 2, 3, 4, 5, 6, 7, 8],
        None,
        json!({}),
        json!({}),
        json!({}),
        &[],
    );
    std::fs::write(dir.join("idless.glb"), g).unwrap();

    let root = json!({
        "asset": {"version": "1.0"}, "geometricError": 100,
        "root": {
            "transform": [1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 1000, 2000, 3000, 1],
            "refine": "ADD", "geometricError": 100, "boundingVolume": {"sphere": [0, 0, 0, 1e4]},
            "children": [
                {"transform": [2, 0, 0, 0, 0, 2, 0, 0, 0, 0, 2, 0, 0, 0, 0, 1], "geometricError": 0,
                 "boundingVolume": {"sphere": [0, 0, 0, 1e4]}, "content": {"url": "a%20b.b3dm"}},
                {"refine": "REPLACE", "geometricError": 10, "boundingVolume": {"sphere": [0, 0, 0, 1e4]},
                 "content": {"uri": "coarse.glb"},
                 "children": [{"geometricError": 0, "boundingVolume": {"sphere": [0, 0, 0, 1e4]},
                               "content": {"uri": "ext/tileset.json"}}]},
                {"geometricError": 0, "boundingVolume": {"sphere": [0, 0, 0, 1e4]}, "contents": [{"uri": "idless.glb"}]}
            ]
        }
    });
    let path = dir.join("tileset.json");
    std::fs::write(&path, serde_json::to_vec_pretty(&root).unwrap()).unwrap();
    path
}

#[test]
fn hand_tileset_frame_maths() {
    let dir = tempfile::tempdir().unwrap();
    let path = write_hand_tileset(dir.path());
    let (model, report) = tiles3d::read_with_report(&path, &ReadOptions::default()).unwrap();
    assert_eq!(model.frame, Frame::Ecef);

    // world = T1 · T2 · (RTC + Y2Z(node · p)), with Y2Z(x, y, z) = (x, −z, y). By hand:
    // p0 (0,0,0) → node (1,2,3) → Y2Z (1,−3,2) → +RTC (11,17,32) → ×2 (22,34,64) → +T1 (1022,2034,3064)
    // p1 (4,0,0) → (5,2,3) → (5,−3,2) → (15,17,32) → (30,34,64) → (1030,2034,3064)
    // p2 (4,3,0) → (5,5,3) → (5,−3,5) → (15,17,35) → (30,34,70) → (1030,2034,3070)
    let a = building(&model, "bldg_a");
    assert_eq!(a.lod, "2");
    assert_eq!(a.measured_height_m, Some(12.5));
    // bldg_a also appears in ext/f.glb (feature 1), merged: its triangle (5,0,0),(6,0,0),(5,1,0)
    // → Y2Z (5,0,0),(6,0,0),(5,0,1) → +ext root (0,0,500) → +T1:
    assert_vertices(
        mesh(&a.geometry),
        &[
            [1022.0, 2034.0, 3064.0],
            [1030.0, 2034.0, 3064.0],
            [1030.0, 2034.0, 3070.0],
            [1005.0, 2000.0, 3500.0],
            [1006.0, 2000.0, 3500.0],
            [1005.0, 2000.0, 3501.0],
        ],
        1e-9,
    );
    assert_eq!(mesh(&a.geometry).triangles.len(), 2);
    // p3 (10,0,0) → (11,2,3) → (11,−3,2) → (21,17,32) → (42,34,64) → (1042,2034,3064)
    // p4 (12,0,0) → (13,2,3) → (13,−3,2) → (23,17,32) → (46,34,64) → (1046,2034,3064)
    // p5 (12,0,−2) → (13,2,1) → (13,−1,2) → (23,19,32) → (46,38,64) → (1046,2038,3064)
    let b = building(&model, "bldg_b");
    assert_eq!(b.lod, "1");
    assert_eq!(b.measured_height_m, None);
    assert_vertices(
        mesh(&b.geometry),
        &[[1042.0, 2034.0, 3064.0], [1046.0, 2034.0, 3064.0], [1046.0, 2038.0, 3064.0]],
        1e-9,
    );

    // ext_1: (0,0,0),(1,0,0),(0,1,0) → Y2Z (0,0,0),(1,0,0),(0,0,1) → +(0,0,500) → +T1.
    let e = building(&model, "ext_1");
    assert_eq!((e.lod.as_str(), e.measured_height_m), ("2", Some(6.5)));
    assert_vertices(
        mesh(&e.geometry),
        &[[1000.0, 2000.0, 3500.0], [1001.0, 2000.0, 3500.0], [1000.0, 2000.0, 3501.0]],
        1e-9,
    );

    // The REPLACE parent's coarse.glb is not read; idless.glb splits into three components: its
    // repeated vertex connects nothing without welding (see below).
    let ids: Vec<&str> = model.buildings.iter().map(|b| b.source_id.as_str()).collect();
    assert_eq!(ids, ["bldg_a", "bldg_b", "ext_1", "idless.glb#cc0", "idless.glb#cc1", "idless.glb#cc2"]);
    assert_eq!(
        report,
        TilesReport {
            tilesets_read: 2,
            contents_read: 3,
            contents_refined_away: 1,
            merged_features: 1,
            connected_component_buildings: 3,
            ..Default::default()
        }
    );
    assert_eq!(model.stats.faces, 7);

    // Welding joins triangles 1 and 2 of idless.glb.
    let welded =
        tiles3d::read(&path, &ReadOptions { weld_tolerance_m: Some(0.01), ..Default::default() }).unwrap();
    let ids: Vec<&str> = welded.buildings.iter().map(|b| b.source_id.as_str()).collect();
    assert_eq!(ids, ["bldg_a", "bldg_b", "ext_1", "idless.glb#cc0", "idless.glb#cc1"]);
    assert_eq!(mesh(&welded.buildings[4].geometry).triangles.len(), 2);

    // Deterministic: same input, same model.
    assert_eq!(tiles3d::read(&path, &ReadOptions::default()).unwrap(), model);
}

#[test]
fn hand_tileset_missing_content_names_tileset_and_uri() {
    let dir = tempfile::tempdir().unwrap();
    let path = write_hand_tileset(dir.path());
    std::fs::remove_file(dir.path().join("ext/f.glb")).unwrap();
    let err = tiles3d::read(&path, &ReadOptions::default()).unwrap_err();
    let msg = err.to_string();
    assert!(
        matches!(&err, LodError::Tile { source, .. } if matches!(**source, tiles3d::ContentError::Unreadable(_))),
        "{err:?}"
    );
    assert!(msg.contains("ext/tileset.json") && msg.contains("\"f.glb\""), "{msg}");
    assert!(msg.contains("root.contents[0].uri"), "{msg}");
}

#[test]
fn external_tileset_cycle_is_an_error() {
    let dir = tempfile::tempdir().unwrap();
    let t = json!({"asset": {"version": "1.0"}, "geometricError": 0,
        "root": {"refine": "ADD", "geometricError": 0, "boundingVolume": {"sphere": [0, 0, 0, 1]},
                 "content": {"uri": "tileset.json"}}});
    std::fs::write(dir.path().join("tileset.json"), serde_json::to_vec(&t).unwrap()).unwrap();
    let err = tiles3d::read(&dir.path().join("tileset.json"), &ReadOptions::default()).unwrap_err();
    assert!(err.to_string().contains("cycle"), "{err}");
}

// ---------------------------------------------------------------------------------------------
// Draco: a b3dm encoded by Google's C++ Draco (DracoPy), decoded by draco-core.
// ---------------------------------------------------------------------------------------------

/// The eight corners of an axis-aligned box.
fn corners(lo: [f64; 3], hi: [f64; 3]) -> Vec<[f64; 3]> {
    let mut v = Vec::new();
    for x in [lo[0], hi[0]] {
        for y in [lo[1], hi[1]] {
            for z in [lo[2], hi[2]] {
                v.push([x, y, z]);
            }
        }
    }
    v
}

#[test]
fn draco_b3dm_matches_hand_computation() {
    let model = read_source(&fixture("draco/tileset.json"), None, &ReadOptions::default()).unwrap();
    let ids: Vec<&str> = model.buildings.iter().map(|b| b.source_id.as_str()).collect();
    assert_eq!(ids, ["box_a", "box_b"]);
    // make_fixtures.py: glTF box A x 0..10, y(up) 0..20, z −6..0; node translation (0.5, 0, 0);
    // CESIUM_RTC C = (−3957000, 3355000, 3698000); tile transform: +90° about z, then (100, 200, 300).
    // Y2Z(x, y, z) = (x, −z, y): A → x 0.5..10.5, y 0..6, z 0..20; + C; R_z(90°)(x, y, z) = (−y, x, z):
    //   x' = −(C.y + y) + 100 ∈ [−3354906, −3354900], y' = C.x + x + 200 ∈ [−3956799.5, −3956789.5],
    //   z' = C.z + z + 300 ∈ [3698300, 3698320].
    // Box B (x 20..24, y 0..8, z −4..0) → x 20.5..24.5, y 0..4, z 0..8 → as above:
    //   x' ∈ [−3354904, −3354900], y' ∈ [−3956779.5, −3956775.5], z' ∈ [3698300, 3698308].
    // Tolerance: 16-bit Draco quantisation over a 24 m range, 24/65535 m ≈ 0.4 mm.
    let a = &model.buildings[0];
    assert_vertices(
        mesh(&a.geometry),
        &corners([-3354906.0, -3956799.5, 3698300.0], [-3354900.0, -3956789.5, 3698320.0]),
        1e-3,
    );
    assert_eq!(mesh(&a.geometry).triangles.len(), 12);
    assert_eq!((a.lod.as_str(), a.measured_height_m), ("2", Some(20.0)));
    let b = &model.buildings[1];
    assert_vertices(
        mesh(&b.geometry),
        &corners([-3354904.0, -3956779.5, 3698300.0], [-3354900.0, -3956775.5, 3698308.0]),
        1e-3,
    );
    assert_eq!(mesh(&b.geometry).triangles.len(), 12);
    assert_eq!((b.lod.as_str(), b.measured_height_m), ("1", Some(8.0)));

    // The b3dm alone: same content, identity tile transform.
    let alone = read_source(&fixture("draco/two_boxes.b3dm"), None, &ReadOptions::default()).unwrap();
    let (ox, oy, oz) = (-3957000.0, 3355000.0, 3698000.0);
    assert_vertices(
        mesh(&alone.buildings[1].geometry),
        &corners([ox + 20.5, oy, oz], [ox + 24.5, oy + 4.0, oz + 8.0]),
        1e-3,
    );
}

// ---------------------------------------------------------------------------------------------
// Bad input: every error names the file and what is wrong.
// ---------------------------------------------------------------------------------------------

fn read_err(rel: &str) -> (PathBuf, LodError) {
    let path = fixture(rel);
    let err = read_source(&path, Some(Format::Tiles3d), &ReadOptions::default()).unwrap_err();
    (path, err)
}

#[test]
fn b3dm_with_wrong_header_length() {
    let (path, err) = read_err("bad_header_length.b3dm");
    assert!(
        matches!(&err, LodError::Tiles3d { source, .. }
            if matches!(**source, tiles3d::ContentError::ByteLength { byte_length: 1264, length: 1256, .. })),
        "{err:?}"
    );
    let msg = error_chain(&err);
    assert!(msg.starts_with(&path.display().to_string()), "{msg}");
    assert!(msg.contains("byteLength is 1264 but the tile has 1256 bytes"), "{msg}");
}

#[test]
fn truncated_b3dm() {
    let (path, err) = read_err("truncated.b3dm");
    let msg = error_chain(&err);
    assert!(matches!(err, LodError::Tiles3d { .. }), "{err:?}");
    assert!(msg.starts_with(&path.display().to_string()) && msg.contains("truncated"), "{msg}");
}

#[test]
fn b3dm_section_past_the_end() {
    let (path, err) = read_err("bad_section_length.b3dm");
    let msg = error_chain(&err);
    assert!(msg.starts_with(&path.display().to_string()), "{msg}");
    assert!(msg.contains("batchTableJSONByteLength = 1000000 runs past the end"), "{msg}");
}

#[test]
fn tileset_with_missing_tile() {
    let (path, err) = read_err("missing_tile/tileset.json");
    assert!(matches!(err, LodError::Tile { .. }), "{err:?}");
    let msg = err.to_string();
    assert!(msg.starts_with(&path.display().to_string()), "{msg}");
    assert!(msg.contains("root.content.uri \"data/absent.b3dm\"") && msg.contains("absent.b3dm"), "{msg}");
}

#[test]
fn malformed_tileset_json() {
    let (path, err) = read_err("malformed_tileset/tileset.json");
    assert!(
        matches!(&err, LodError::Tiles3d { source, .. } if matches!(**source, tiles3d::ContentError::TilesetJson(_))),
        "{err:?}"
    );
    let msg = error_chain(&err);
    assert!(
        msg.starts_with(&path.display().to_string()) && msg.contains("not a valid 3D Tiles tileset JSON"),
        "{msg}"
    );
}

// ---------------------------------------------------------------------------------------------
// Real data: PLATEAU Shibuya (3D Tiles 1.0, b3dm, Draco, CESIUM_RTC).
// ---------------------------------------------------------------------------------------------

/// Per-feature reference boxes written by the FME export into each b3dm's batch table (binary
/// DOUBLE columns `_xmin/_xmax` = longitude, `_ymin/_ymax` = latitude, degrees), read here with a
/// parser independent of the library's: gml_id → (lon_min, lon_max, lat_min, lat_max).
fn reference_boxes(tileset: &Path) -> BTreeMap<String, [f64; 4]> {
    let t: serde_json::Value = serde_json::from_slice(&std::fs::read(tileset).unwrap()).unwrap();
    let dir = tileset.parent().unwrap();
    let mut out = BTreeMap::new();
    for child in t["root"]["children"].as_array().unwrap() {
        let bytes = std::fs::read(dir.join(child["content"]["uri"].as_str().unwrap())).unwrap();
        let w = |i: usize| u32::from_le_bytes(bytes[i..i + 4].try_into().unwrap()) as usize;
        let (ftj, ftb, btj) = (w(12), w(16), w(20));
        let ft: serde_json::Value = serde_json::from_slice(&bytes[28..28 + ftj]).unwrap();
        let n = ft["BATCH_LENGTH"].as_u64().unwrap() as usize;
        let bt_start = 28 + ftj + ftb;
        let bt: serde_json::Value =
            serde_json::from_slice(bytes[bt_start..bt_start + btj].trim_ascii_end()).unwrap();
        let body = &bytes[bt_start + btj..];
        let col = |k: &str| -> Vec<f64> {
            let off = bt[k]["byteOffset"].as_u64().unwrap() as usize;
            (0..n)
                .map(|i| f64::from_le_bytes(body[off + 8 * i..off + 8 * i + 8].try_into().unwrap()))
                .collect()
        };
        let (x0, x1, y0, y1) = (col("_xmin"), col("_xmax"), col("_ymin"), col("_ymax"));
        for i in 0..n {
            out.insert(bt["gml_id"][i].as_str().unwrap().to_string(), [x0[i], x1[i], y0[i], y1[i]]);
        }
    }
    out
}

#[test]
fn shibuya_plateau_tileset() {
    let Some(path) = shared_data("jp_tokyo_shibuya_plateau_3dtiles/tileset.json") else { return };
    let (model, report) = tiles3d::read_with_report(&path, &ReadOptions::default()).unwrap();
    assert_eq!(model.frame, Frame::Ecef);
    assert_eq!(report.contents_read, 56);
    assert_eq!(report.merged_features, 0);
    assert_eq!(report.connected_component_buildings, 0);
    assert_eq!(report.mixed_feature_triangles, 0);
    // Every batch id of the 56 tiles (ΣBATCH_LENGTH = 3,595) has triangles.
    assert_eq!(model.stats.buildings_without_geometry, 0);
    // README: 3,595 features, each with a unique gml_id.
    assert_eq!(model.buildings.len(), 3595);
    let unique: BTreeSet<&str> = model.buildings.iter().map(|b| b.source_id.as_str()).collect();
    assert_eq!(unique.len(), 3595);
    assert!(model.buildings.iter().all(|b| b.source_id.starts_with("bldg_")));
    // README: 2,474 LoD2 and 1,121 LoD1 (batch-table `_lod`).
    let mut lods: BTreeMap<&str, usize> = BTreeMap::new();
    for b in &model.buildings {
        *lods.entry(b.lod.as_str()).or_default() += 1;
    }
    assert_eq!(lods, BTreeMap::from([("1", 1121), ("2", 2474)]));
    // Reference (Python over the 56 batch tables, JSON and binary columns): 3,395 features have a
    // positive `bldg:measuredHeight`.
    let with_height = model.buildings.iter().filter(|b| b.measured_height_m.is_some()).count();
    assert_eq!(with_height, 3395);

    // README extent: 139.6942–139.7102 E, 35.6520–35.6637 N, heights 47.6–282.4 m ellipsoidal.
    let refs = reference_boxes(&path);
    assert_eq!(refs.len(), 3595);
    // Extent over all vertices: [lon_min, lon_max, lat_min, lat_max, h_min, h_max].
    let mut ext = [
        f64::INFINITY,
        f64::NEG_INFINITY,
        f64::INFINITY,
        f64::NEG_INFINITY,
        f64::INFINITY,
        f64::NEG_INFINITY,
    ];
    let mut worst_deg: f64 = 0.0;
    for b in &model.buildings {
        let m = mesh(&b.geometry);
        assert!(!m.triangles.is_empty(), "{} has no triangles", b.source_id);
        let mut bb = [f64::INFINITY, f64::NEG_INFINITY, f64::INFINITY, f64::NEG_INFINITY];
        for p in &m.positions {
            let g = ecef_to_geodetic(*p);
            for (k, v) in [g.lon_deg, g.lat_deg, g.h_m].into_iter().enumerate() {
                ext[2 * k] = ext[2 * k].min(v);
                ext[2 * k + 1] = ext[2 * k + 1].max(v);
            }
            bb = [bb[0].min(g.lon_deg), bb[1].max(g.lon_deg), bb[2].min(g.lat_deg), bb[3].max(g.lat_deg)];
        }
        let r = refs[&b.source_id];
        for k in 0..4 {
            worst_deg = worst_deg.max((bb[k] - r[k]).abs());
        }
    }
    // The README's extent is the vertices' extent rounded to 4 decimals (degrees) and 0.1 m.
    let round = |x: f64, unit: f64| (x / unit).round() * unit;
    let stated = [139.6942, 139.7102, 35.6520, 35.6637, 47.6, 282.4];
    for k in 0..6 {
        let unit = if k < 4 { 1e-4 } else { 0.1 };
        assert!(
            (round(ext[k], unit) - stated[k]).abs() < unit / 10.0,
            "extent[{k}] = {} vs {}",
            ext[k],
            stated[k]
        );
    }
    // Each building's lon/lat box agrees with the batch table's own box to 1e-8° (≈ 1 mm; observed
    // 7e-11°): the whole chain (Draco, CESIUM_RTC, y-up, ECEF → geodetic) is right per building.
    assert!(worst_deg < 1e-8, "worst lon/lat box difference {worst_deg}°");
    eprintln!(
        "shibuya: {} buildings, LoD {lods:?}, {with_height} with measured height, {} triangles, \
         lon {:.6}..{:.6}°, lat {:.6}..{:.6}°, heights {:.3}..{:.3} m, worst box difference {worst_deg:.2e}°; \
         {} mixed-feature and {} degenerate triangles, {} features without geometry",
        model.buildings.len(),
        model.stats.faces,
        ext[0],
        ext[1],
        ext[2],
        ext[3],
        ext[4],
        ext[5],
        report.mixed_feature_triangles,
        model.stats.degenerate_faces,
        model.stats.buildings_without_geometry
    );
}

// ---------------------------------------------------------------------------------------------
// Content edge cases, each against a hand computation.
// ---------------------------------------------------------------------------------------------

/// One triangle (glTF y-up) per batch id in `ids`, triangle k at x offset 10·k.
fn batched_glb(ids: &[f32]) -> Vec<u8> {
    let mut positions = Vec::new();
    let mut per_vertex = Vec::new();
    for (k, &id) in ids.iter().enumerate() {
        let x = 10.0 * k as f32;
        positions.extend([[x, 0.0, 0.0], [x + 1.0, 0.0, 0.0], [x, 1.0, 0.0]]);
        per_vertex.extend([id; 3]);
    }
    let indices: Vec<u16> = (0..positions.len() as u16).collect();
    simple_glb(&positions, &indices, Some(("_BATCHID", &per_vertex)), json!({}), json!({}), json!({}), &[])
}

#[test]
fn cmpt_with_b3dm_and_i3dm_inner_tiles() {
    let dir = tempfile::tempdir().unwrap();
    let inner_a = b3dm(&json!({"BATCH_LENGTH": 1}), &json!({"gml_id": ["in_a"]}), &batched_glb(&[0.0]));
    let inner_b = b3dm(&json!({"BATCH_LENGTH": 1}), &json!({"gml_id": ["in_b"]}), &batched_glb(&[0.0]));
    // A minimal i3dm-shaped inner tile (magic, version, byteLength): skipped and counted.
    let mut i3dm = b"i3dm".to_vec();
    i3dm.extend_from_slice(&1u32.to_le_bytes());
    i3dm.extend_from_slice(&12u32.to_le_bytes());
    let total = 16 + inner_a.len() + i3dm.len() + inner_b.len();
    let mut cmpt = b"cmpt".to_vec();
    for w in [1, total, 3] {
        cmpt.extend_from_slice(&(w as u32).to_le_bytes());
    }
    for t in [&inner_a, &i3dm, &inner_b] {
        cmpt.extend_from_slice(t);
    }
    let path = dir.path().join("c.cmpt");
    std::fs::write(&path, &cmpt).unwrap();
    let (model, report) = tiles3d::read_with_report(&path, &ReadOptions::default()).unwrap();
    let ids: Vec<&str> = model.buildings.iter().map(|b| b.source_id.as_str()).collect();
    assert_eq!(ids, ["in_a", "in_b"]);
    assert_eq!((report.contents_read, report.unsupported_contents), (2, 1));
    // (0,1,0) → Y2Z (0,0,1).
    assert_vertices(
        mesh(&model.buildings[1].geometry),
        &[[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]],
        0.0,
    );
}

#[test]
fn gltf_up_axis_z_skips_the_rotation() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("t.glb"), batched_glb(&[0.0])).unwrap();
    let t = json!({"asset": {"version": "1.0", "gltfUpAxis": "Z"}, "geometricError": 0,
        "root": {"refine": "ADD", "geometricError": 0, "boundingVolume": {"sphere": [0, 0, 0, 1]},
                 "content": {"uri": "t.glb"}}});
    std::fs::write(dir.path().join("tileset.json"), serde_json::to_vec(&t).unwrap()).unwrap();
    let model = tiles3d::read(&dir.path().join("tileset.json"), &ReadOptions::default()).unwrap();
    // No batch table: the feature keeps a synthesized id; the vertices stay as written.
    assert_eq!(model.buildings[0].source_id, "t.glb#batch0");
    assert_vertices(
        mesh(&model.buildings[0].geometry),
        &[[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
        0.0,
    );
}

#[test]
fn batch_id_past_batch_length_is_an_error() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("bad_ids.b3dm");
    let tile = b3dm(&json!({"BATCH_LENGTH": 2}), &json!({"gml_id": ["a", "b"]}), &batched_glb(&[0.0, 2.0]));
    std::fs::write(&path, tile).unwrap();
    let err = tiles3d::read(&path, &ReadOptions::default()).unwrap_err();
    let msg = error_chain(&err);
    assert!(
        msg.contains("bad_ids.b3dm")
            && msg.contains("_BATCHID 2 is not below")
            && msg.contains("BATCH_LENGTH 2"),
        "{msg}"
    );
}

#[test]
fn unsupported_required_extension_is_named() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("meshopt.glb");
    let g = simple_glb(
        &[[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
        &[0, 1, 2],
        None,
        json!({}),
        json!({}),
        json!({}),
        &[],
    );
    // Re-write the JSON chunk with an extensionsRequired entry.
    let jlen = u32::from_le_bytes(g[12..16].try_into().unwrap()) as usize;
    let mut gltf: serde_json::Value = serde_json::from_slice(g[20..20 + jlen].trim_ascii_end()).unwrap();
    gltf["extensionsRequired"] = json!(["EXT_mesh_gpu_instancing", "KHR_materials_unlit"]);
    let bin_len = u32::from_le_bytes(g[20 + jlen..24 + jlen].try_into().unwrap()) as usize;
    std::fs::write(&path, glb(&gltf, &g[28 + jlen..28 + jlen + bin_len])).unwrap();
    let msg = error_chain(&tiles3d::read(&path, &ReadOptions::default()).unwrap_err());
    assert!(msg.contains("meshopt.glb") && msg.contains("EXT_mesh_gpu_instancing"), "{msg}");
    assert!(
        !msg.contains("requires extension(s) EXT_mesh_gpu_instancing, KHR"),
        "material extensions are harmless: {msg}"
    );
}

#[test]
fn null_feature_ids_are_dropped() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("n.glb");
    let mf = json!({"EXT_mesh_features": {"featureIds": [{"featureCount": 1, "attribute": 0, "nullFeatureId": 7}]}});
    let g = simple_glb(
        &[
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            [5.0, 0.0, 0.0],
            [6.0, 0.0, 0.0],
            [5.0, 1.0, 0.0],
        ],
        &[0, 1, 2, 3, 4, 5],
        Some(("_FEATURE_ID_0", &[0.0, 0.0, 0.0, 7.0, 7.0, 7.0])),
        json!({}),
        mf,
        json!({}),
        &[],
    );
    std::fs::write(&path, g).unwrap();
    let (model, report) = tiles3d::read_with_report(&path, &ReadOptions::default()).unwrap();
    let ids: Vec<&str> = model.buildings.iter().map(|b| b.source_id.as_str()).collect();
    assert_eq!(ids, ["n.glb#ids0.feature0"]);
    assert_eq!(report.null_feature_triangles, 1);
}

#[test]
fn shibuya_komaba_neighbors_tileset() {
    let Some(path) = shared_data("jp_tokyo_shibuya_plateau_3dtiles/tileset_komaba_neighbors.json") else {
        return;
    };
    let model = tiles3d::read(&path, &ReadOptions::default()).unwrap();
    // Reference (Python over the 9 batch tables): 427 unique gml_ids, all `_lod` 1.
    assert_eq!(model.buildings.len(), 427);
    assert_eq!(model.buildings.iter().map(|b| b.source_id.as_str()).collect::<BTreeSet<_>>().len(), 427);
    assert!(model.buildings.iter().all(|b| b.lod == "1"));
    // ~1.6 km west of the station block: every vertex west of 139.6942 E.
    for b in &model.buildings {
        for p in &mesh(&b.geometry).positions {
            assert!(ecef_to_geodetic(*p).lon_deg < 139.6942, "{}", b.source_id);
        }
    }
}
