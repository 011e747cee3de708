//! OBJ reader: buildings as connected components, welding, sidecar geo-referencing and its schema.
//!
//! Fixture `tests/fixtures/obj/three_boxes.obj` (hand-made, commented in the file): box 1 written as
//! two groups sharing vertices by index, box 2, and box 3 touching box 2 at the corner (30, 10, 0)
//! through a repeated (not shared) vertex. Expected values are hand computations from the file.

use std::path::{Path, PathBuf};

use insgen::lod::obj::{self, ObjAxes, ObjSidecar};
use insgen::lod::{read_source, AxisConvention, Format, Frame, Geometry, LodError, ReadOptions, TriMesh};

fn fixture(name: &str) -> PathBuf {
    crate::util::fixture("obj", name)
}

fn mesh(g: &Geometry) -> &TriMesh {
    match g {
        Geometry::Mesh(m) => m,
        Geometry::Polygons(_) => panic!("OBJ buildings are meshes"),
    }
}

/// (min, max) of each axis.
fn bbox(m: &TriMesh) -> [[f64; 2]; 3] {
    let mut b = [[f64::INFINITY, f64::NEG_INFINITY]; 3];
    for p in &m.positions {
        for k in 0..3 {
            b[k][0] = b[k][0].min(p[k]);
            b[k][1] = b[k][1].max(p[k]);
        }
    }
    b
}

#[test]
fn three_boxes_without_weld_are_three_buildings() {
    let model = read_source(&fixture("three_boxes.obj"), None, &ReadOptions::default()).unwrap();
    assert_eq!(model.frame, Frame::Crs { name: Some("EPSG:6677".into()), axes: AxisConvention::EastNorth });
    let ids: Vec<&str> = model.buildings.iter().map(|b| b.source_id.as_str()).collect();
    assert_eq!(ids, ["three_boxes.obj#cc0", "three_boxes.obj#cc1", "three_boxes.obj#cc2"]);
    // 6 quads per box → 12 triangles; 8 corners each.
    for b in &model.buildings {
        assert_eq!(mesh(&b.geometry).triangles.len(), 12, "{}", b.source_id);
        assert_eq!(mesh(&b.geometry).positions.len(), 8, "{}", b.source_id);
        assert_eq!(b.lod, "1");
        assert_eq!(b.measured_height_m, None);
    }
    assert_eq!(model.stats.faces, 36);
    // Hand computation: box 1 spans x 0..10, y 0..10, z 0..5 in the file; offset (−5000, −35000, 40).
    assert_eq!(
        bbox(mesh(&model.buildings[0].geometry)),
        [[-5000.0, -4990.0], [-35000.0, -34990.0], [40.0, 45.0]]
    );
    assert_eq!(
        bbox(mesh(&model.buildings[2].geometry)),
        [[-4970.0, -4960.0], [-34990.0, -34980.0], [40.0, 46.0]]
    );
}

#[test]
fn welding_joins_the_touching_boxes() {
    let opts = ReadOptions { weld_tolerance_m: Some(0.001), ..Default::default() };
    let model = obj::read(&fixture("three_boxes.obj"), &opts).unwrap();
    assert_eq!(model.buildings.len(), 2);
    let joined = mesh(&model.buildings[1].geometry);
    // Boxes 2 and 3 together: 24 triangles and all 16 vertices (welding does not merge vertices).
    assert_eq!(joined.triangles.len(), 24);
    assert_eq!(joined.positions.len(), 16);
    assert_eq!(bbox(joined), [[-4980.0, -4960.0], [-35000.0, -34980.0], [40.0, 48.0]]);
    // Exact-coincidence welding finds the same corner.
    let exact = obj::read(
        &fixture("three_boxes.obj"),
        &ReadOptions { weld_tolerance_m: Some(0.0), ..Default::default() },
    );
    assert_eq!(exact.unwrap().buildings.len(), 2);
}

#[test]
fn y_up_sidecar_given_by_the_caller() {
    let sidecar = ObjSidecar { crs: None, offset: [0.0, 0.0, 0.0], axes: ObjAxes::YUp, lod: None };
    let model =
        obj::read_with_sidecar(&fixture("three_boxes.obj"), &sidecar, &ReadOptions::default()).unwrap();
    assert_eq!(model.frame, Frame::Crs { name: None, axes: AxisConvention::EastNorth });
    assert_eq!(model.buildings[0].lod, "unknown");
    // (x, y, z) ↦ (x, −z, y): box 1's file z 0..5 becomes north −5..0, file y 0..10 becomes up.
    assert_eq!(bbox(mesh(&model.buildings[0].geometry)), [[0.0, 10.0], [-5.0, 0.0], [0.0, 10.0]]);
}

#[test]
fn missing_sidecar_is_a_clear_error() {
    let path = fixture("no_sidecar.obj");
    let err = obj::read(&path, &ReadOptions::default()).unwrap_err();
    assert!(matches!(err, LodError::Invalid { .. }), "{err:?}");
    let msg = err.to_string();
    assert!(msg.starts_with(&path.display().to_string()), "{msg}");
    assert!(msg.contains("no_sidecar.obj.json") && msg.contains("no_sidecar.json"), "{msg}");
    assert!(msg.contains("\"crs\""), "the message shows an example sidecar: {msg}");
}

#[test]
fn bad_weld_tolerance_is_rejected() {
    let opts = ReadOptions { weld_tolerance_m: Some(-1.0), ..Default::default() };
    let err = read_source(&fixture("three_boxes.obj"), Some(Format::Obj), &opts).unwrap_err();
    assert!(err.to_string().contains("weld tolerance -1"), "{err}");
}

#[test]
fn invalid_sidecar_names_the_sidecar() {
    let dir = tempfile::tempdir().unwrap();
    let obj_path = dir.path().join("m.obj");
    std::fs::copy(fixture("no_sidecar.obj"), &obj_path).unwrap();
    std::fs::write(dir.path().join("m.json"), r#"{"crs": "EPSG:6677", "axes": "up"}"#).unwrap();
    let err = obj::read(&obj_path, &ReadOptions::default()).unwrap_err();
    assert!(matches!(err, LodError::Malformed { .. }), "{err:?}");
    assert!(err.to_string().contains("m.json"), "{err}");
    // `<file>.obj.json` wins over `<stem>.json`.
    std::fs::write(dir.path().join("m.obj.json"), r#"{"crs": "EPSG:6677"}"#).unwrap();
    assert_eq!(obj::read(&obj_path, &ReadOptions::default()).unwrap().buildings.len(), 1);
}

#[test]
fn sidecar_schema_agrees_with_the_reader() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let schema: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(root.join("schemas/obj_sidecar.schema.json")).unwrap())
            .unwrap();
    let validator = jsonschema::validator_for(&schema).unwrap();
    let good: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(fixture("three_boxes.obj.json")).unwrap()).unwrap();
    assert!(validator.is_valid(&good));
    for (text, ok) in [
        (r#"{}"#, true),
        (r#"{"crs": null, "axes": "y_up"}"#, true),
        (r#"{"crs": "EPSG:6677", "offset": [1, 2]}"#, false),
        (r#"{"crs": "EPSG:6677", "axes": "x_up"}"#, false),
        (r#"{"crs": "EPSG:6677", "ofset": [1, 2, 3]}"#, false),
    ] {
        let v: serde_json::Value = serde_json::from_str(text).unwrap();
        assert_eq!(validator.is_valid(&v), ok, "schema on {text}");
        assert_eq!(serde_json::from_value::<ObjSidecar>(v).is_ok(), ok, "reader on {text}");
    }
}
