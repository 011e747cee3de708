//! `insgen prepare` end to end: real areas (building counts, schemas, GLB read-back), determinism, and
//! the bad-input corpus at the scene level (missing/unknown CRS, missing source, no partial output).

use crate::util;

use insgen::scene::PreparedScene;
use util::*;

fn prepare_area(name: &str, data: &str, expect_buildings: u64) {
    if shared_data(data).is_none() {
        return;
    }
    let dir = scratch_with_scenes(&[(name, repo_scene(name))]);
    let out = insgen(dir.path(), &["prepare", "--area", name]);
    assert!(out.status.success(), "prepare {name} failed: {}", stderr(&out));
    let scene_dir = dir.path().join("runs").join(name).join("scene");
    let manifest: serde_json::Value =
        serde_json::from_slice(&std::fs::read(scene_dir.join("manifest.json")).unwrap()).unwrap();
    assert_schema("manifest.schema.json", &manifest);
    let buildings: serde_json::Value =
        serde_json::from_slice(&std::fs::read(scene_dir.join("buildings.json")).unwrap()).unwrap();
    assert_schema("buildings.schema.json", &buildings);
    let scene = PreparedScene::load(&scene_dir).expect("the prepared scene loads");
    assert_eq!(scene.manifest.buildings, expect_buildings, "{name}: building count");
    assert_eq!(scene.buildings.len() as u64, expect_buildings);
    // IDs are 1..=N in source-id order, and every ID in the mesh is in the table.
    for (i, b) in scene.buildings.iter().enumerate() {
        assert_eq!(b.id, i as u32 + 1);
        if i > 0 {
            assert!(scene.buildings[i - 1].source_id < b.source_id, "not sorted by source id");
        }
    }
    let mut seen = vec![false; scene.buildings.len() + 1];
    for &id in &scene.mesh.building_ids {
        let id = id.get() as usize;
        assert!(id >= 1 && id < seen.len(), "mesh ID {id} not in the building table");
        seen[id] = true;
    }
    assert!(seen[1..].iter().all(|&s| s), "a building has no triangles in the mesh");
    // The geometry sits around the origin: within a few km horizontally, and heights plausible.
    let (lo, hi) = scene.mesh.bounds_m().unwrap();
    assert!(lo[0] > -5000.0 && hi[0] < 5000.0 && lo[1] > -5000.0 && hi[1] < 5000.0, "{lo:?} {hi:?}");
    assert!(lo[2] > -100.0 && hi[2] < 700.0, "{lo:?} {hi:?}");
}

#[test]
fn niiza_657_buildings() {
    prepare_area("niiza", "jp_niiza_plateau_lod1/53395404_bldg_6697_op.gml", 657);
}

#[test]
fn denhaag_844_buildings() {
    prepare_area("denhaag", "nl_denhaag_lod2/DenHaag_01.city.json", 844);
}

#[test]
fn delft_160_buildings() {
    prepare_area("delft", "nl_delft_lod1/delft.city.json", 160);
}

#[test]
fn tokyo_3595_buildings() {
    prepare_area("tokyo", "jp_tokyo_shibuya_plateau_3dtiles/tileset.json", 3595);
}

#[test]
fn hertogenbosch_needs_and_accepts_explicit_crs() {
    let Some(file) = shared_data("nl_3dbag_multilod_sample/multi_lod.city.json") else { return };
    // Without `crs` the file declares none: a clear error naming the file, and nothing written.
    let text = format!("name = \"bag\"\n[[sources]]\npath = \"{}\"\n", file.display());
    let dir = scratch_with_scenes(&[("bag", text)]);
    let out = insgen(dir.path(), &["prepare", "--area", "bag"]);
    assert!(!out.status.success());
    let err = stderr(&out);
    assert!(err.contains("declares no CRS") && err.contains("multi_lod.city.json"), "{err}");
    assert!(!dir.path().join("runs/bag/scene").exists(), "partial output left behind");
    // With it (the repo's scene file), 10 buildings at LoD 2.2.
    prepare_area("hertogenbosch", "nl_3dbag_multilod_sample/multi_lod.city.json", 10);
}

#[test]
fn unknown_epsg_and_missing_source_are_clear_errors() {
    let Some(file) = shared_data("nl_delft_lod1/delft.city.json") else { return };
    let bad_crs =
        format!("name = \"x\"\n[[sources]]\npath = \"{}\"\ncrs = \"EPSG:999999\"\n", file.display());
    let missing = "name = \"y\"\n[[sources]]\npath = \"nope/missing.gml\"\n".to_string();
    let dir = scratch_with_scenes(&[("x", bad_crs), ("y", missing)]);
    let out = insgen(dir.path(), &["prepare", "--area", "x"]);
    assert_eq!(out.status.code(), Some(1));
    let err = stderr(&out);
    assert!(err.contains("999999") && err.contains("delft.city.json"), "{err}");
    let out = insgen(dir.path(), &["prepare", "--area", "y"]);
    assert_eq!(out.status.code(), Some(1));
    assert!(
        stderr(&out).contains("missing.gml") && stderr(&out).contains("does not exist"),
        "{}",
        stderr(&out)
    );
    assert!(!dir.path().join("runs").exists(), "partial output left behind");
    // Unknown area lists the available ones.
    let out = insgen(dir.path(), &["prepare", "--area", "z"]);
    assert!(stderr(&out).contains("available: x, y"), "{}", stderr(&out));
}
