//! `scene.glb` writer and reader: round trips, the Khronos validator, the EXT_mesh_features /
//! EXT_structural_metadata content decoded independently of the reader, and error reporting.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};
use std::process::Command;

use insgen::scene::glb::{read_glb, write_glb, GlbError};
use insgen::scene::{BuildingId, BuildingRecord, SceneMesh};
use rand::{Rng, SeedableRng};
use serde_json::{json, Value};

fn record(id: u32, source_id: &str) -> BuildingRecord {
    BuildingRecord {
        id: BuildingId::new(id).unwrap(),
        source_id: source_id.to_string(),
        source_file: "test.gml".into(),
        lod: "1".into(),
        height_m: 0.0,
        measured_height_m: None,
        footprint_area_m2: 0.0,
        centroid_lat_deg: 0.0,
        centroid_lon_deg: 0.0,
        bbox_min_enu_m: [0.0; 3],
        bbox_max_enu_m: [0.0; 3],
        triangles: 0,
    }
}

/// Appends a closed axis-aligned box (12 triangles, 8 own vertices) for building `id`.
fn push_box(mesh: &mut SceneMesh, id: u32, lo: [f32; 3], hi: [f32; 3]) {
    let id = BuildingId::new(id).unwrap();
    let base = mesh.positions_m.len() as u32;
    for k in 0..8u32 {
        let p = [
            if k & 1 == 0 { lo[0] } else { hi[0] },
            if k & 2 == 0 { lo[1] } else { hi[1] },
            if k & 4 == 0 { lo[2] } else { hi[2] },
        ];
        mesh.positions_m.push(p);
        mesh.building_ids.push(id);
    }
    // Faces of the cube over corner bits (x = 1, y = 2, z = 4), outward-facing.
    const TRIS: [[u32; 3]; 12] = [
        [0, 2, 1],
        [1, 2, 3], // bottom (z = lo)
        [4, 5, 6],
        [5, 7, 6], // top
        [0, 1, 4],
        [1, 5, 4], // south (y = lo)
        [2, 6, 3],
        [3, 6, 7], // north
        [0, 4, 2],
        [2, 4, 6], // west
        [1, 3, 5],
        [3, 7, 5], // east
    ];
    for t in TRIS {
        mesh.indices.extend(t.map(|v| base + v));
    }
}

/// Three buildings with awkward (non-round) f32 coordinates and IDs that are not contiguous, one of
/// them at the 24-bit limit.
fn small_scene() -> (SceneMesh, Vec<BuildingRecord>) {
    let mut mesh = SceneMesh::default();
    push_box(&mut mesh, 1, [-120.1, 35.3, -0.7], [-100.07, 60.9, 12.3]);
    push_box(&mut mesh, 7, [0.1, -0.2, 0.0], [17.3, 9.9, 183.25]);
    push_box(&mut mesh, 16_777_215, [250.0, -310.5, 1.5], [271.3, -290.1, 44.4]);
    let buildings = vec![record(1, "bldg_0001"), record(7, "bldg_ö7"), record(16_777_215, "gml_UUID_ffffff")];
    (mesh, buildings)
}

/// A pseudo-random city of `n` boxes (deterministic), for the larger round trip and timing.
fn random_scene(n: u32, seed: u64) -> (SceneMesh, Vec<BuildingRecord>) {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let mut mesh = SceneMesh::default();
    let mut buildings = Vec::new();
    for id in 1..=n {
        let x: f32 = rng.gen_range(-3000.0..3000.0);
        let y: f32 = rng.gen_range(-3000.0..3000.0);
        let z: f32 = rng.gen_range(-5.0..40.0);
        let (w, d, h): (f32, f32, f32) =
            (rng.gen_range(5.0..40.0), rng.gen_range(5.0..40.0), rng.gen_range(3.0..200.0));
        push_box(&mut mesh, id, [x, y, z], [x + w, y + d, z + h]);
        buildings.push(record(id, &format!("b{id:07}")));
    }
    (mesh, buildings)
}

fn assert_bit_identical(a: &SceneMesh, b: &SceneMesh) {
    assert_eq!(a.positions_m.len(), b.positions_m.len());
    for (k, (p, q)) in a.positions_m.iter().zip(&b.positions_m).enumerate() {
        assert_eq!(p.map(f32::to_bits), q.map(f32::to_bits), "vertex {k}: {p:?} vs {q:?}");
    }
    assert_eq!(a.building_ids, b.building_ids);
    assert_eq!(a.indices, b.indices);
}

/// The JSON chunk and the BIN chunk of a GLB, split by hand (independent of the reader under test).
fn split_glb(bytes: &[u8]) -> (Value, Vec<u8>) {
    let u32_at = |o: usize| u32::from_le_bytes(bytes[o..o + 4].try_into().unwrap()) as usize;
    assert_eq!(&bytes[0..4], b"glTF");
    assert_eq!(u32_at(4), 2, "GLB version");
    assert_eq!(u32_at(8), bytes.len(), "GLB header length");
    let json_len = u32_at(12);
    assert_eq!(&bytes[16..20], b"JSON");
    assert_eq!(json_len % 4, 0);
    let json: Value = serde_json::from_slice(&bytes[20..20 + json_len]).unwrap();
    let bin_at = 20 + json_len;
    let bin_len = u32_at(bin_at);
    assert_eq!(&bytes[bin_at + 4..bin_at + 8], b"BIN\0");
    assert_eq!(bin_at + 8 + bin_len, bytes.len());
    (json, bytes[bin_at + 8..].to_vec())
}

/// The bytes of accessor `i` (tightly packed views only, as the writer produces).
fn accessor_slice<'a>(json: &Value, bin: &'a [u8], i: usize, elem: usize) -> &'a [u8] {
    let acc = &json["accessors"][i];
    let view = &json["bufferViews"][acc["bufferView"].as_u64().unwrap() as usize];
    assert!(view.get("byteStride").is_none());
    let start = view["byteOffset"].as_u64().unwrap() as usize
        + acc.get("byteOffset").map_or(0, |v| v.as_u64().unwrap() as usize);
    let count = acc["count"].as_u64().unwrap() as usize;
    assert!(count * elem <= view["byteLength"].as_u64().unwrap() as usize);
    &bin[start..start + count * elem]
}

mod round_trip {
    use super::*;

    #[test]
    fn small_scene_is_bit_exact() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("scene.glb");
        let (mesh, buildings) = small_scene();
        write_glb(&path, &mesh, &buildings).unwrap();
        let back = read_glb(&path).unwrap();
        assert_bit_identical(&mesh, &back);
    }

    #[test]
    fn positions_are_stored_y_up() {
        // Independent check of the axis convention: decode POSITION from the raw bytes and compare with
        // (east, up, −north) of the input.
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("scene.glb");
        let (mesh, buildings) = small_scene();
        write_glb(&path, &mesh, &buildings).unwrap();
        let (json, bin) = split_glb(&std::fs::read(&path).unwrap());
        let pos_acc = json["meshes"][0]["primitives"][0]["attributes"]["POSITION"].as_u64().unwrap() as usize;
        let raw = accessor_slice(&json, &bin, pos_acc, 12);
        for (k, p) in mesh.positions_m.iter().enumerate() {
            let f =
                |c: usize| f32::from_le_bytes(raw[k * 12 + c * 4..k * 12 + c * 4 + 4].try_into().unwrap());
            assert_eq!([f(0), f(1), f(2)], [p[0], p[2], -p[1]], "vertex {k}");
        }
        // min/max cover exactly the stored values (glTF requires them for POSITION).
        let acc = &json["accessors"][pos_acc];
        let min: Vec<f64> = acc["min"].as_array().unwrap().iter().map(|v| v.as_f64().unwrap()).collect();
        let max: Vec<f64> = acc["max"].as_array().unwrap().iter().map(|v| v.as_f64().unwrap()).collect();
        // By hand: min/max over the boxes of (east, up, −north).
        assert_eq!(min, vec![f64::from(-120.1f32), f64::from(-0.7f32), -f64::from(60.9f32)]);
        assert_eq!(max, vec![f64::from(271.3f32), f64::from(183.25f32), f64::from(310.5f32)]);
    }

    #[test]
    fn ten_thousand_buildings_round_trip_and_timing() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("scene.glb");
        let (mesh, buildings) = random_scene(10_000, 42);
        let t0 = std::time::Instant::now();
        write_glb(&path, &mesh, &buildings).unwrap();
        let t1 = std::time::Instant::now();
        let back = read_glb(&path).unwrap();
        let t2 = std::time::Instant::now();
        assert_bit_identical(&mesh, &back);
        eprintln!(
            "{} vertices, {} triangles, {} bytes: write {:.1} ms, read {:.1} ms",
            mesh.positions_m.len(),
            mesh.triangle_count(),
            std::fs::metadata(&path).unwrap().len(),
            (t1 - t0).as_secs_f64() * 1e3,
            (t2 - t1).as_secs_f64() * 1e3
        );
    }

    #[test]
    fn identical_input_gives_identical_bytes() {
        let dir = tempfile::tempdir().unwrap();
        let (mesh, buildings) = random_scene(300, 7);
        let a = dir.path().join("a.glb");
        let b = dir.path().join("sub/b.glb");
        write_glb(&a, &mesh, &buildings).unwrap();
        // The order of the building table does not matter either.
        let mut reversed = buildings.clone();
        reversed.reverse();
        write_glb(&b, &mesh, &reversed).unwrap();
        assert_eq!(std::fs::read(&a).unwrap(), std::fs::read(&b).unwrap());
    }
}

mod features {
    use super::*;

    #[test]
    fn feature_ids_map_back_to_the_building_table() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("scene.glb");
        let (mesh, buildings) = small_scene();
        write_glb(&path, &mesh, &buildings).unwrap();
        let (json, bin) = split_glb(&std::fs::read(&path).unwrap());

        assert!(json["extensionsUsed"].as_array().unwrap().contains(&json!("EXT_mesh_features")));
        assert!(
            json.get("extensionsRequired").is_none(),
            "viewers without the extensions must still load it"
        );
        let prim = &json["meshes"][0]["primitives"][0];
        let sets = prim["extensions"]["EXT_mesh_features"]["featureIds"].as_array().unwrap();
        assert_eq!(sets.len(), 1);
        let set = &sets[0];
        assert_eq!(set["label"], "building");
        assert_eq!(set["attribute"], 0);
        assert_eq!(set["featureCount"], 3, "three distinct buildings");
        assert_eq!(set["nullFeatureId"], 0);

        // The attribute EXT_mesh_features names: SCALAR, FLOAT, not normalized (the spec's rules).
        let fid_acc = prim["attributes"]["_FEATURE_ID_0"].as_u64().unwrap() as usize;
        let acc = &json["accessors"][fid_acc];
        assert_eq!(acc["type"], "SCALAR");
        assert_eq!(acc["componentType"], 5126);
        assert!(acc.get("normalized").is_none_or(|v| v == false));
        let raw = accessor_slice(&json, &bin, fid_acc, 4);
        let ids: Vec<u32> = raw
            .chunks_exact(4)
            .map(|c| {
                let v = f32::from_le_bytes(c.try_into().unwrap());
                assert_eq!(v.fract(), 0.0);
                v as u32
            })
            .collect();
        assert_eq!(ids, mesh.building_ids.iter().map(|b| b.get()).collect::<Vec<_>>());

        // Every ID in the file is in the building table, and every building has triangles.
        let table: BTreeSet<u32> = buildings.iter().map(|b| b.id.get()).collect();
        let idx_acc = prim["indices"].as_u64().unwrap() as usize;
        let idx: Vec<u32> = accessor_slice(&json, &bin, idx_acc, 4)
            .chunks_exact(4)
            .map(|c| u32::from_le_bytes(c.try_into().unwrap()))
            .collect();
        let mut triangles: BTreeMap<u32, usize> = BTreeMap::new();
        for t in idx.chunks_exact(3) {
            let id = ids[t[0] as usize];
            assert!(t.iter().all(|&v| ids[v as usize] == id), "a triangle spans two buildings");
            *triangles.entry(id).or_default() += 1;
        }
        assert!(ids.iter().all(|id| table.contains(id)));
        assert_eq!(triangles.keys().copied().collect::<BTreeSet<_>>(), table);
        assert!(triangles.values().all(|&n| n == 12));

        // IDs this sparse (up to 2^24 − 1 for three buildings) get no property table.
        assert!(set.get("propertyTable").is_none());
        assert!(json.get("extensions").is_none());
        assert!(!json["extensionsUsed"].as_array().unwrap().contains(&json!("EXT_structural_metadata")));
    }

    #[test]
    fn property_table_maps_ids_to_source_ids() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("scene.glb");
        // Dense IDs 1, 2, 4 (3 unused): a table of rows 0..=4.
        let mut mesh = SceneMesh::default();
        push_box(&mut mesh, 4, [0.0, 0.0, 0.0], [1.0, 1.0, 1.0]);
        push_box(&mut mesh, 1, [2.0, 0.0, 0.0], [3.0, 1.0, 1.0]);
        push_box(&mut mesh, 2, [4.0, 0.0, 0.0], [5.0, 1.0, 1.0]);
        let buildings = vec![record(1, "gml_a"), record(2, "bldg_ö2"), record(4, "x")];
        write_glb(&path, &mesh, &buildings).unwrap();
        let (json, bin) = split_glb(&std::fs::read(&path).unwrap());
        let set = &json["meshes"][0]["primitives"][0]["extensions"]["EXT_mesh_features"]["featureIds"][0];
        assert_eq!(set["featureCount"], 3);

        // EXT_structural_metadata: row = ID, STRING column source_id with UINT32 offsets.
        assert!(json["extensionsUsed"].as_array().unwrap().contains(&json!("EXT_structural_metadata")));
        let meta = &json["extensions"]["EXT_structural_metadata"];
        assert_eq!(meta["schema"]["classes"]["building"]["properties"]["source_id"]["type"], "STRING");
        let pt = &meta["propertyTables"][set["propertyTable"].as_u64().unwrap() as usize];
        assert_eq!(pt["class"], "building");
        let rows = pt["count"].as_u64().unwrap() as usize;
        assert_eq!(rows, 5);
        let col = &pt["properties"]["source_id"];
        assert_eq!(col["stringOffsetType"], "UINT32");
        let view = |k: &str| {
            let v = &json["bufferViews"][col[k].as_u64().unwrap() as usize];
            let o = v["byteOffset"].as_u64().unwrap() as usize;
            assert_eq!(o % 8, 0, "EXT_structural_metadata needs 8-byte aligned views");
            assert!(v.get("target").is_none() && v.get("byteStride").is_none());
            &bin[o..o + v["byteLength"].as_u64().unwrap() as usize]
        };
        let (values, offsets) = (view("values"), view("stringOffsets"));
        assert_eq!(offsets.len(), (rows + 1) * 4);
        let off = |r: usize| u32::from_le_bytes(offsets[r * 4..r * 4 + 4].try_into().unwrap()) as usize;
        let row = |r: usize| std::str::from_utf8(&values[off(r)..off(r + 1)]).unwrap().to_string();
        let all: Vec<String> = (0..rows).map(row).collect();
        assert_eq!(all, vec!["", "gml_a", "bldg_ö2", "", "x"], "row 0 is the background, row 3 unused");
        assert_eq!(off(rows), values.len());
    }

    #[test]
    fn colours_are_flat_per_building() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("scene.glb");
        let (mesh, buildings) = small_scene();
        write_glb(&path, &mesh, &buildings).unwrap();
        let (json, bin) = split_glb(&std::fs::read(&path).unwrap());
        let prim = &json["meshes"][0]["primitives"][0];
        let c_acc = prim["attributes"]["COLOR_0"].as_u64().unwrap() as usize;
        assert_eq!(json["accessors"][c_acc]["normalized"], true);
        let raw = accessor_slice(&json, &bin, c_acc, 4);
        for (k, &id) in mesh.building_ids.iter().enumerate() {
            let [r, g, b] = insgen::scene::glb::building_colour(id);
            assert_eq!(&raw[k * 4..k * 4 + 4], &[r, g, b, 255]);
        }
        let mat = &json["materials"][prim["material"].as_u64().unwrap() as usize];
        assert!(mat["extensions"].get("KHR_materials_unlit").is_some());
    }
}

mod validator {
    use super::*;

    /// `node` and the repository's node_modules/gltf-validator, or `None` (skip) with the reason.
    fn validator_setup() -> Option<(PathBuf, PathBuf)> {
        let root = Path::new(env!("CARGO_MANIFEST_DIR"));
        let script = root.join("scripts/validate_gltf.js");
        let module = root.join("node_modules/gltf-validator");
        let node = Command::new("node").arg("--version").output().ok().filter(|o| o.status.success());
        let why = if node.is_none() {
            Some("`node` is not on PATH".to_string())
        } else if !module.exists() {
            Some(format!("{} is absent (run `npm ci` at the repository root)", module.display()))
        } else {
            None
        };
        if let Some(why) = why {
            if std::env::var("CI").map(|v| v == "true").unwrap_or(false) {
                panic!("CI: cannot run the glTF validator: {why}");
            }
            eprintln!("skipping: {why}");
            return None;
        }
        Some((PathBuf::from("node"), script))
    }

    fn validate(glb: &Path) -> Option<Value> {
        let (node, script) = validator_setup()?;
        let out = Command::new(node).arg(&script).arg(glb).output().unwrap();
        assert!(
            out.status.success(),
            "validator failed ({}):\n{}",
            out.status,
            String::from_utf8_lossy(&out.stderr)
        );
        Some(serde_json::from_slice(&out.stdout).unwrap())
    }

    fn assert_no_errors(report: &Value) {
        let issues = &report["issues"];
        for m in issues["messages"].as_array().unwrap() {
            eprintln!(
                "validator: severity {} {} at {}: {}",
                m["severity"], m["code"], m["pointer"], m["message"]
            );
        }
        assert_eq!(issues["numErrors"], 0, "{:#}", issues);
    }

    #[test]
    fn khronos_validator_reports_no_errors() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("scene.glb");
        let (mesh, buildings) = small_scene();
        write_glb(&path, &mesh, &buildings).unwrap();
        let Some(report) = validate(&path) else { return };
        assert_no_errors(&report);
        let info = &report["info"];
        assert_eq!(info["totalTriangleCount"], 36);
        assert_eq!(info["totalVertexCount"], 24);
        // Warnings would point at real problems (misaligned data, wrong bounds): allow none.
        assert_eq!(report["issues"]["numWarnings"], 0, "{:#}", report["issues"]);
    }

    /// A scene GLB with clutter layers appended (`glb::add_layers`) stays valid glTF: no errors, no
    /// warnings, the buildings' data untouched and the layers' triangles counted.
    #[test]
    fn khronos_validator_accepts_clutter_layers() {
        use insgen::scene::clutter::{tree_instance, Clutter, ClutterLayer};
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("scene.glb");
        let (mesh, buildings) = small_scene();
        write_glb(&path, &mesh, &buildings).unwrap();
        let trees = tree_instance(0, [40.0, 40.0, 0.0], 10.0, 3.0);
        let conifer = tree_instance(1, [-40.0, 40.0, 0.0], 12.0, 2.0);
        let clutter =
            Clutter { layers: vec![(ClutterLayer::Trees, trees.clone()), (ClutterLayer::Cars, conifer)] };
        insgen::scene::glb::add_layers(&path, &clutter).unwrap();
        assert_eq!(insgen::scene::glb::read_glb(&path).unwrap(), mesh);
        assert_eq!(insgen::scene::glb::read_layers(&path).unwrap(), clutter);
        let Some(report) = validate(&path) else { return };
        assert_no_errors(&report);
        assert_eq!(report["issues"]["numWarnings"], 0, "{:#}", report["issues"]);
        let layer_tris: usize = clutter.layers.iter().map(|(_, m)| m.triangle_count()).sum();
        assert_eq!(report["info"]["totalTriangleCount"], 36 + layer_tris as u64);
    }

    /// The procedural demo city, triangulated here (walls as two triangles, roofs and grounds with
    /// earcut) in a plain local frame (EPSG:6677 minus the plane origin, H as up): validates with no
    /// errors or warnings and reads back exactly. Also left in target/test-output/demo_city.glb for
    /// viewing in any glTF viewer (not committed).
    #[test]
    fn khronos_validator_accepts_the_demo_city() {
        use insgen::lod::Geometry;
        use insgen::scene::procedural::{default_spec, generate, PlaneOrigin};
        let o = PlaneOrigin::TOKYO_BAY;
        let model = generate(&default_spec(), o).unwrap();
        let mut mesh = SceneMesh::default();
        let mut buildings = Vec::new();
        let mut ear = earcut::Earcut::new();
        let mut tris: Vec<u32> = Vec::new();
        for (k, b) in model.buildings.iter().enumerate() {
            let id = BuildingId::from_index(k).unwrap();
            let Geometry::Polygons(polys) = &b.geometry else { panic!("LoD1 polygons expected") };
            let before = mesh.indices.len();
            for p in polys {
                let base = mesh.positions_m.len() as u32;
                let ring_pts: Vec<[f64; 3]> =
                    p.exterior.iter().chain(p.interiors.iter().flatten()).copied().collect();
                for v in &ring_pts {
                    mesh.positions_m.push([
                        (v[0] - o.easting_m) as f32,
                        (v[1] - o.northing_m) as f32,
                        v[2] as f32,
                    ]);
                    mesh.building_ids.push(id);
                }
                if p.exterior.iter().all(|v| v[2] == p.exterior[0][2]) {
                    let mut holes = Vec::new();
                    let mut at = p.exterior.len() as u32;
                    for h in &p.interiors {
                        holes.push(at);
                        at += h.len() as u32;
                    }
                    ear.earcut(
                        ring_pts.iter().map(|v| [v[0] - o.easting_m, v[1] - o.northing_m]),
                        &holes,
                        &mut tris,
                    );
                    assert!(!tris.is_empty(), "{}: roof/ground did not triangulate", b.source_id);
                    mesh.indices.extend(tris.iter().map(|&t| base + t));
                } else {
                    assert_eq!(p.exterior.len(), 4, "walls are quads");
                    mesh.indices.extend([0, 1, 2, 0, 2, 3].map(|t| base + t));
                }
            }
            let mut r = record(id.get(), &b.source_id);
            r.triangles = ((mesh.indices.len() - before) / 3) as u64;
            buildings.push(r);
        }
        let out_dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("target/test-output");
        let path = out_dir.join("demo_city.glb");
        write_glb(&path, &mesh, &buildings).unwrap();
        eprintln!(
            "demo city: {} buildings, {} triangles, {} bytes -> {}",
            buildings.len(),
            mesh.triangle_count(),
            std::fs::metadata(&path).unwrap().len(),
            path.display()
        );
        assert_bit_identical(&mesh, &read_glb(&path).unwrap());
        let Some(report) = validate(&path) else { return };
        assert_no_errors(&report);
        assert_eq!(report["issues"]["numWarnings"], 0, "{:#}", report["issues"]);
        assert_eq!(report["info"]["totalTriangleCount"], mesh.triangle_count());
    }

    #[test]
    fn khronos_validator_accepts_a_random_city() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("scene.glb");
        let (mesh, buildings) = random_scene(500, 3);
        write_glb(&path, &mesh, &buildings).unwrap();
        let Some(report) = validate(&path) else { return };
        assert_no_errors(&report);
        assert_eq!(report["info"]["totalTriangleCount"], 6000);
    }
}

/// Hand-made GLBs for the reader's general paths and its errors.
mod reader {
    use super::*;

    /// One triangle primitive: positions (glTF axes), u16 feature IDs, u16 indices, interleaved
    /// position + padding (stride 16) to exercise byteStride.
    fn other_writer_glb(with_features: bool, ids: [u16; 3], translation: [f32; 3]) -> Vec<u8> {
        let pos = [[0.0f32, 0.0, 0.0], [4.0, 0.0, 0.0], [0.0, 2.0, -3.0]];
        let mut bin = Vec::new();
        for p in pos {
            for c in p {
                bin.extend_from_slice(&c.to_le_bytes());
            }
            bin.extend_from_slice(&[0xAB; 4]); // padding inside the stride
        }
        for id in ids {
            bin.extend_from_slice(&id.to_le_bytes());
            bin.extend_from_slice(&[0; 2]); // 4-byte aligned elements (stride 4)
        }
        for i in [0u16, 1, 2, 0] {
            bin.extend_from_slice(&i.to_le_bytes()); // the last one is padding
        }
        let mut prim = json!({"attributes": {"POSITION": 0, "_FEATURE_ID_0": 1}, "indices": 2});
        if with_features {
            prim["extensions"] = json!({"EXT_mesh_features": {"featureIds": [
                {"featureCount": 1, "offset": 0, "repeat": 1},
                {"featureCount": 2, "attribute": 0}
            ]}});
        }
        let doc = json!({
            "asset": {"version": "2.0"},
            "scene": 0,
            "scenes": [{"nodes": [0]}],
            "nodes": [{"children": [1], "translation": translation}, {"mesh": 0}],
            "meshes": [{"primitives": [prim]}],
            "accessors": [
                {"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3",
                 "min": [0.0, 0.0, -3.0], "max": [4.0, 2.0, 0.0]},
                {"bufferView": 1, "componentType": 5123, "count": 3, "type": "SCALAR"},
                {"bufferView": 2, "componentType": 5123, "count": 3, "type": "SCALAR"}
            ],
            "bufferViews": [
                {"buffer": 0, "byteOffset": 0, "byteLength": 48, "byteStride": 16},
                {"buffer": 0, "byteOffset": 48, "byteLength": 12, "byteStride": 4},
                {"buffer": 0, "byteOffset": 60, "byteLength": 6}
            ],
            "buffers": [{"byteLength": 68}],
            "extensionsUsed": ["EXT_mesh_features"]
        });
        crate::util::glb(&doc, &bin)
    }

    #[test]
    fn reads_strided_u16_data_and_applies_node_transforms() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("other.glb");
        std::fs::write(&path, other_writer_glb(true, [5, 5, 9], [10.0, 1.0, -2.0])).unwrap();
        let mesh = read_glb(&path).unwrap();
        // glTF (x, y, z) + (10, 1, −2) → ENU (x, −z, y), by hand.
        assert_eq!(mesh.positions_m, vec![[10.0, 2.0, 1.0], [14.0, 2.0, 1.0], [10.0, 5.0, 3.0]]);
        assert_eq!(mesh.building_ids, [5, 5, 9]);
        assert_eq!(mesh.indices, vec![0, 1, 2]);
    }

    #[test]
    fn missing_feature_ids_is_an_error_with_a_hint() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("plain.glb");
        std::fs::write(&path, other_writer_glb(false, [1, 1, 1], [0.0; 3])).unwrap();
        let e = read_glb(&path).unwrap_err();
        assert!(matches!(e, GlbError::Invalid { .. }));
        let msg = e.to_string();
        assert!(msg.contains("plain.glb") && msg.contains("meshes[0].primitives[0]"), "{msg}");
        assert!(msg.contains("insgen prepare"), "{msg}");
    }

    #[test]
    fn background_id_in_the_mesh_is_an_error() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("zero.glb");
        std::fs::write(&path, other_writer_glb(true, [3, 0, 3], [0.0; 3])).unwrap();
        let msg = read_glb(&path).unwrap_err().to_string();
        assert!(
            msg.contains("_FEATURE_ID_0") && msg.contains("vertex 1") && msg.contains("feature ID 0"),
            "{msg}"
        );
    }

    #[test]
    fn not_a_glb_and_truncated_glb_are_parse_errors() {
        let dir = tempfile::tempdir().unwrap();
        let text = dir.path().join("text.glb");
        std::fs::write(&text, b"hello, this is not a GLB").unwrap();
        let e = read_glb(&text).unwrap_err();
        assert!(
            matches!(
                &e,
                GlbError::Container { source: insgen::util::glb::GlbError::NotGlb { length: 24, .. }, .. }
            ),
            "{e:?}"
        );
        assert!(e.to_string().contains("text.glb"));

        let (mesh, buildings) = small_scene();
        let good = dir.path().join("good.glb");
        write_glb(&good, &mesh, &buildings).unwrap();
        let bytes = std::fs::read(&good).unwrap();
        let cut = dir.path().join("cut.glb");
        std::fs::write(&cut, &bytes[..bytes.len() - 100]).unwrap();
        let e = read_glb(&cut).unwrap_err();
        // The header promises 100 bytes more than the file holds.
        assert!(
            matches!(&e, GlbError::Container { source: insgen::util::glb::GlbError::Length { length, available }, .. }
                if *length == *available + 100),
            "{e:?}"
        );
        assert!(e.to_string().contains("cut.glb"));

        let missing = dir.path().join("missing.glb");
        let e = read_glb(&missing).unwrap_err();
        assert!(matches!(e, GlbError::File(_)) && e.to_string().contains("missing.glb"), "{e}");
    }

    #[test]
    fn index_out_of_range_is_reported_with_its_location() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("badidx.glb");
        let mut bytes = other_writer_glb(true, [1, 1, 1], [0.0; 3]);
        // The third index (u16 at BIN offset 64) → 7, beyond the 3 vertices.
        let bin_start = bytes.len() - 68;
        bytes[bin_start + 64..bin_start + 66].copy_from_slice(&7u16.to_le_bytes());
        std::fs::write(&path, bytes).unwrap();
        let msg = read_glb(&path).unwrap_err().to_string();
        assert!(msg.contains("meshes[0].primitives[0].indices") && msg.contains("is 7"), "{msg}");
    }
}

mod writer_errors {
    use super::*;

    #[test]
    fn id_missing_from_the_table_is_refused_and_nothing_is_written() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("scene.glb");
        let (mesh, mut buildings) = small_scene();
        buildings.remove(1);
        let e = write_glb(&path, &mesh, &buildings).unwrap_err();
        assert!(matches!(e, GlbError::BadInput { .. }));
        assert!(e.to_string().contains("building ID 7"), "{e}");
        assert!(!path.exists());
    }

    #[test]
    fn inconsistent_meshes_are_refused() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("scene.glb");
        let (mesh, buildings) = small_scene();
        let mut m = mesh.clone();
        m.indices.push(0);
        assert!(write_glb(&path, &m, &buildings).unwrap_err().to_string().contains("multiple of 3"));
        let mut m = mesh.clone();
        m.indices[5] = 99;
        assert!(write_glb(&path, &m, &buildings).unwrap_err().to_string().contains("index 5 is 99"));
        let mut m = mesh.clone();
        m.positions_m[3][1] = f32::NAN;
        assert!(write_glb(&path, &m, &buildings).unwrap_err().to_string().contains("vertex 3"));
        let mut m = mesh.clone();
        m.building_ids.pop();
        assert!(write_glb(&path, &m, &buildings).unwrap_err().to_string().contains("building IDs"));
        let empty = SceneMesh::default();
        assert!(write_glb(&path, &empty, &buildings).unwrap_err().to_string().contains("no triangles"));
        let mut dup = buildings.clone();
        dup[1].id = BuildingId::new(1).unwrap();
        assert!(write_glb(&path, &mesh, &dup).unwrap_err().to_string().contains("used by both"));
        assert!(!path.exists());
    }
}
