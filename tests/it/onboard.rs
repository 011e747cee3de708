//! A city the repository does not ship, onboarded as the README's "Your own city" walks through it.
//!
//! The fixture is written at test time: a town of 36 LoD1 buildings as four CityJSON tiles in
//! EPSG:25832 (ETRS89 / UTM zone 32N, orthometric heights; no shipped scene uses a UTM zone), in two
//! sub-folders beside a stray text file and picture. From that folder alone the binary runs
//! `init` → `inspect` → `prepare` → `sample` → `render-masks` → `render-rgb` (Blender, 3 frames at
//! 192 × 108) → `export-coco`, `export-yolo`, `export-panoptic` (not `export-hf`: `export-coco`'s folder
//! is what `datasets` loads); the export folder is then moved elsewhere, the work directory deleted, and
//! the folder checked by `insgen verify` and loaded by pycocotools, Ultralytics' label rules,
//! panopticapi and `datasets.load_dataset(<folder>)`
//! ([`crate::exports::assert_moved_export_loads`], the moved-export test's checks).
//!
//! The origin `init` writes is checked against `prepare`'s own default (the same scene without
//! `[origin]`): equal within 1e-8° (init rounds to 8 decimals, ≤ 5e-9°; about 1 mm).
//! Skips (fails under CI=true) without the bpy interpreter.

use std::path::Path;
use std::process::{Command, Output};

use insgen::scene::config::SceneConfig;
use insgen::scene::Manifest;
use serde_json::Value;

use crate::blender_support::blender_python;
use crate::util::{assert_schema, stderr, stdout};

/// Easting and northing of the town's south-west corner, EPSG:25832 metres (Munich); heights above
/// the German vertical datum start at `GROUND_M`.
const ORIGIN_EN_M: [f64; 2] = [690_000.0, 5_335_000.0];
const GROUND_M: f64 = 520.0;

/// One CityJSON 2.0 tile `(ti, tj)` (300 m square) of 3 × 3 box buildings, 50 m wide on a 100 m pitch,
/// 12–45 m tall, vertices in millimetres from the town's corner (CityJSON `transform`).
fn tile(ti: usize, tj: usize) -> Value {
    let mut objects = serde_json::Map::new();
    let mut vertices: Vec<[i64; 3]> = Vec::new();
    for i in 0..3 {
        for j in 0..3 {
            let e0 = (ti * 300 + i * 100 + 25) as i64 * 1000;
            let n0 = (tj * 300 + j * 100 + 25) as i64 * 1000;
            let h = (12 + ((ti * 3 + i) * 7 + (tj * 3 + j) * 11) % 34) as i64 * 1000;
            let z0 = (GROUND_M * 1000.0) as i64;
            let b = vertices.len();
            for (dz, ring) in [(0, [(0, 0), (1, 0), (1, 1), (0, 1)]), (h, [(0, 0), (1, 0), (1, 1), (0, 1)])] {
                for (de, dn) in ring {
                    vertices.push([e0 + de * 50_000, n0 + dn * 50_000, z0 + dz]);
                }
            }
            let faces = [[0, 3, 2, 1], [4, 5, 6, 7], [0, 1, 5, 4], [1, 2, 6, 5], [2, 3, 7, 6], [3, 0, 4, 7]];
            let shell: Vec<Value> = faces.iter().map(|f| serde_json::json!([f.map(|k| k + b)])).collect();
            objects.insert(
                format!("town_{ti}{tj}_{i}{j}"),
                serde_json::json!({"type": "Building", "geometry": [{"type": "Solid", "lod": "1", "boundaries": [shell]}]}),
            );
        }
    }
    serde_json::json!({
        "type": "CityJSON", "version": "2.0",
        "metadata": {"referenceSystem": "https://www.opengis.net/def/crs/EPSG/0/25832"},
        "transform": {"scale": [0.001, 0.001, 0.001], "translate": [ORIGIN_EN_M[0], ORIGIN_EN_M[1], 0.0]},
        "CityObjects": objects,
        "vertices": vertices,
    })
}

/// The town as a newcomer's folder: `south/` and `north/` tiles, a README and a picture.
fn write_town(dir: &Path) {
    for (ti, tj) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
        let sub = dir.join(if tj == 0 { "south" } else { "north" });
        std::fs::create_dir_all(&sub).unwrap();
        std::fs::write(sub.join(format!("tile_{ti}{tj}.city.json")), tile(ti, tj).to_string()).unwrap();
    }
    std::fs::write(dir.join("README.txt"), "Town tiles, EPSG:25832\n").unwrap();
    std::fs::write(dir.join("north/overview.png"), b"not read").unwrap();
}

/// `insgen ARGS` in `cwd` with Blender's interpreter in the environment.
fn run(cwd: &Path, bpy: &Path, args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_insgen"))
        .args(args)
        .current_dir(cwd)
        .env("RUST_LOG", "warn")
        .env("INSGEN_BLENDER_PYTHON", bpy)
        .output()
        .expect("the insgen binary runs")
}

fn run_ok(cwd: &Path, bpy: &Path, args: &[&str]) -> String {
    let o = run(cwd, bpy, args);
    assert!(o.status.success(), "insgen {args:?} failed:\n{}", stderr(&o));
    stdout(&o)
}

fn read_json(p: &Path) -> Value {
    serde_json::from_slice(&std::fs::read(p).unwrap_or_else(|e| panic!("{}: {e}", p.display()))).unwrap()
}

/// `init` writes a scene file `prepare` takes, refuses to overwrite it, and `inspect` agrees with it.
/// Returns the origin written, (lat, lon) in degrees.
fn init_and_inspect(root: &Path, bpy: &Path) -> [f64; 2] {
    let out = run_ok(root, bpy, &["--no-progress", "init", "town", "town/"]);
    assert!(out.starts_with("scenes/town.toml: 36 buildings in 4 file(s), EPSG:25832, "), "{out}");
    let scene = root.join("scenes/town.toml");
    let cfg = SceneConfig::load(&scene).unwrap();
    assert_eq!(cfg.sources.len(), 1);
    assert_eq!(cfg.sources[0].path.as_deref(), Some(Path::new("../town")), "relative to scenes/");
    assert!(cfg.attribution.as_deref().unwrap().starts_with(insgen::scene::init::TODO));
    let o = cfg.origin.expect("init writes [origin]");
    let again = run(root, bpy, &["init", "town", "town/"]);
    assert_eq!(again.status.code(), Some(1));
    assert!(
        stderr(&again).contains("scenes/town.toml exists; pass --force to replace it"),
        "{}",
        stderr(&again)
    );

    let text = run_ok(root, bpy, &["--no-progress", "inspect", "town/"]);
    eprintln!("{text}");
    for want in [
        "files:      4 (cityjson)\n".to_string(),
        "            town/north/tile_01.city.json  9 buildings\n".into(),
        "CRS:        EPSG:25832 ETRS89 / UTM zone 32N".into(),
        "extent:     E 690025.000 … 690575.000, N 5335025.000 … 5335575.000, h 520.000 … 565.000 (source CRS)\n"
            .into(),
        format!("centre:     lat {:.8}°, lon {:.8}°", o.lat_deg, o.lon_deg),
        "buildings:  36 (LoD1: 36)\n".into(),
        "triangles:  432\n".into(),
    ] {
        assert!(text.contains(&want), "inspect lacks {want:?}:\n{text}");
    }
    let j: Value =
        serde_json::from_str(&run_ok(root, bpy, &["--no-progress", "inspect", "town/", "--json"])).unwrap();
    assert_schema("inspect.schema.json", &j);
    assert_eq!(j["files"].as_array().unwrap().len(), 4);
    let c = &j["centre_deg"];
    assert!((c["lat_deg"].as_f64().unwrap() - o.lat_deg).abs() <= 5e-9, "{c}");
    assert!((c["lon_deg"].as_f64().unwrap() - o.lon_deg).abs() <= 5e-9, "{c}");
    [o.lat_deg, o.lon_deg]
}

/// The scene file without its `[origin]`, as another area: `prepare` then takes its own default.
fn prepare_without_origin(root: &Path, bpy: &Path) -> Manifest {
    let text = std::fs::read_to_string(root.join("scenes/town.toml")).unwrap();
    let free: String = text
        .replace("name = \"town\"", "name = \"town-free\"")
        .lines()
        .filter(|l| !l.starts_with("[origin]") && !l.starts_with("lat_deg") && !l.starts_with("lon_deg"))
        .map(|l| format!("{l}\n"))
        .collect();
    std::fs::write(root.join("scenes/town-free.toml"), free).unwrap();
    run_ok(root, bpy, &["--no-progress", "prepare", "--area", "town-free", "--no-clutter"]);
    let m: Manifest =
        serde_json::from_value(read_json(&root.join("runs/town-free/scene/manifest.json"))).unwrap();
    std::fs::remove_dir_all(root.join("runs/town-free")).unwrap();
    std::fs::remove_file(root.join("scenes/town-free.toml")).unwrap();
    m
}

#[test]
fn a_folder_of_utm_cityjson_tiles_becomes_a_dataset_that_moves() {
    let Some(bpy) = blender_python() else { return };
    let home = tempfile::tempdir().unwrap();
    let root = home.path();
    write_town(&root.join("town"));
    std::fs::write(
        root.join("tiny.toml"),
        "name = \"tiny\"\nwidth_px = 192\nheight_px = 108\nsensor_width_mm = 23.76\nsensor_height_mm = 13.365\n\
         hfov_deg = 25.0\nstrategy = \"grid\"\n",
    )
    .unwrap();
    let origin = init_and_inspect(root, &bpy);

    let free = prepare_without_origin(root, &bpy);
    assert!(
        (free.origin.lat_deg - origin[0]).abs() <= 1e-8 && (free.origin.lon_deg - origin[1]).abs() <= 1e-8,
        "init's origin {origin:?} is not prepare's default ({}, {})",
        free.origin.lat_deg,
        free.origin.lon_deg
    );
    run_ok(root, &bpy, &["--no-progress", "prepare", "--area", "town"]);
    let m: Manifest = serde_json::from_value(read_json(&root.join("runs/town/scene/manifest.json"))).unwrap();
    assert_eq!((m.origin.lat_deg, m.origin.lon_deg), (origin[0], origin[1]), "the scene file's [origin]");
    assert_eq!(m.buildings, 36);
    let files: Vec<&str> = m.sources.iter().map(|s| s.path.as_str()).collect();
    assert_eq!(
        files,
        [
            "../town/north/tile_01.city.json",
            "../town/north/tile_11.city.json",
            "../town/south/tile_00.city.json",
            "../town/south/tile_10.city.json"
        ],
        "every tile of the folder, sorted, named relative to the scene file"
    );

    run_ok(
        root,
        &bpy,
        &["--no-progress", "sample", "--area", "town", "--camera", "tiny.toml", "--count", "3"],
    );
    run_ok(root, &bpy, &["--no-progress", "render-masks", "--area", "town", "--camera", "tiny"]);
    run_ok(root, &bpy, &["--no-progress", "render-rgb", "--area", "town", "--camera", "tiny"]);
    run_ok(root, &bpy, &["--no-progress", "export-coco"]);
    for export in ["export-yolo", "export-panoptic"] {
        run_ok(root, &bpy, &["--no-progress", export]);
    }
    let coco = read_json(&root.join("runs/coco/instances_train.json"));
    let images = coco["images"].as_array().unwrap().len();
    assert_eq!(images, 3, "every sampled frame is a photo of the train split");
    assert!(!coco["annotations"].as_array().unwrap().is_empty());
    let card = std::fs::read_to_string(root.join("runs/coco/README.md")).unwrap();
    assert!(card.contains("TODO: the model's maker and licence"), "the placeholder shows in the card");

    let elsewhere = tempfile::tempdir().unwrap();
    let moved = elsewhere.path().join("town-dataset");
    std::fs::rename(root.join("runs/coco"), &moved).unwrap();
    std::fs::remove_dir_all(root.join("runs")).unwrap();
    crate::exports::assert_moved_export_loads(&moved, images);
}
