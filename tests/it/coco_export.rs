//! `export-coco` end to end on synthetic workdirs: ID maps drawn from random rectangles, ellipses,
//! courtyards with a building inside, buildings cut in two by another, border-touching blocks, specks
//! and corner touches — written with the png crate exactly as `render-masks` lays them out.
//!
//! References: pycocotools (`COCO`, `annToMask`, `COCOeval`) through `scripts/coco_check.py dataset`,
//! which decodes the ID maps and labels their components with its own code; the JSON Schemas in
//! `schemas/`; and counts recomputed here from the instance files for the filters.
//!
//! Python comes from `INSGEN_PYTHON` (default `<repo>/.venv/bin/python`); when it is missing the
//! pycocotools parts print why and skip, unless `CI=true`, where they fail.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use insgen::camera::{Intrinsics, Pose, PoseRecord, Trajectory};
use insgen::export::coco::{export, ExportPlan};
use insgen::export::format::{AnnotationUnit, Dataset, Filters, Segmentation, TruncatedPolicy};
use insgen::export::results::read_results;
use insgen::export::stats::{self, ReportOptions};
use insgen::export::Split;
use insgen::geo::{EnuFrame, Geodetic};
use insgen::label::{label_components, Connectivity, FrameInstances, InstanceEntry};
use insgen::scene::artifact::{GeoidUsed, Origin, SourceEntry};
use insgen::scene::{BuildingId, BuildingRecord, IdMap, Manifest};
use insgen::util::NoProgress;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde_json::Value;

const W: u32 = 96;
const H: u32 = 72;
const BUILDINGS: u32 = 14;

// ------------------------------------------------------------------------------------------ generator

#[derive(Clone)]
struct AreaSpec {
    name: &'static str,
    split: &'static str,
    frames: usize,
    connectivity: Connectivity,
    min_component_area_px: u64,
    rgb_frames: usize,
    visible_fraction: bool,
    /// A frame with no building at all.
    empty_frame: bool,
    /// A pose listed in poses.jsonl whose masks were never rendered.
    unrendered_frame: bool,
    seed: u64,
}

impl AreaSpec {
    fn new(name: &'static str, split: &'static str, seed: u64) -> Self {
        AreaSpec {
            name,
            split,
            frames: 3,
            connectivity: Connectivity::Eight,
            min_component_area_px: 1,
            rgb_frames: usize::MAX,
            visible_fraction: false,
            empty_frame: false,
            unrendered_frame: false,
            seed,
        }
    }
}

fn fill(ids: &mut [u32], x0: i64, y0: i64, x1: i64, y1: i64, id: u32) {
    for y in y0.max(0)..y1.min(H as i64) {
        for x in x0.max(0)..x1.min(W as i64) {
            ids[(y * W as i64 + x) as usize] = id;
        }
    }
}

/// One synthetic ID map. Every feature the exporter must handle appears in every frame.
fn draw_frame(rng: &mut ChaCha8Rng) -> Vec<u32> {
    let mut ids = vec![0u32; (W * H) as usize];
    let mut pick = || rng.gen_range(1..=BUILDINGS);
    let (a, b, c, d, e, f) = (pick(), pick(), pick(), pick(), pick(), pick());
    let mut rng2 = ChaCha8Rng::seed_from_u64(a as u64 * 7919 + b as u64);
    // Random blocks, some past the border.
    for _ in 0..6 {
        let id = rng2.gen_range(1..=BUILDINGS);
        let (x, y) = (rng2.gen_range(-10..W as i64), rng2.gen_range(-10..H as i64));
        fill(&mut ids, x, y, x + rng2.gen_range(3..25), y + rng2.gen_range(3..25), id);
    }
    // A courtyard building (ring) with another building inside the courtyard.
    let (cx, cy) = (rng2.gen_range(5..50), rng2.gen_range(5..35));
    fill(&mut ids, cx, cy, cx + 30, cy + 24, c);
    fill(&mut ids, cx + 6, cy + 6, cx + 24, cy + 18, 0);
    fill(&mut ids, cx + 10, cy + 9, cx + 16, cy + 14, d);
    // A building cut in two by another one drawn across it.
    let (sx, sy) = (rng2.gen_range(0..60), rng2.gen_range(0..50));
    fill(&mut ids, sx, sy, sx + 30, sy + 12, a);
    fill(&mut ids, sx + 12, sy - 3, sx + 17, sy + 15, b);
    // An ellipse.
    let (ex, ey, rx, ry) = (rng2.gen_range(10.0..86.0), rng2.gen_range(10.0..62.0), 9.0, 5.5);
    for y in 0..H {
        for x in 0..W {
            let (dx, dy) = ((x as f64 + 0.5 - ex) / rx, (y as f64 + 0.5 - ey) / ry);
            if dx * dx + dy * dy <= 1.0 {
                ids[(y * W + x) as usize] = e;
            }
        }
    }
    // A one-pixel speck and a pair of pixels touching at a corner, away from everything else.
    let (px, py) = (rng2.gen_range(2..W as i64 - 4), rng2.gen_range(2..H as i64 - 4));
    fill(&mut ids, px - 1, py - 1, px + 4, py + 4, 0);
    fill(&mut ids, px, py, px + 1, py + 1, f);
    fill(&mut ids, px + 2, py + 2, px + 3, py + 3, f);
    fill(&mut ids, px + 3, py + 3, px + 4, py + 4, f);
    ids
}

fn write_json(path: &Path, v: &impl serde::Serialize) {
    std::fs::create_dir_all(path.parent().unwrap()).unwrap();
    std::fs::write(path, serde_json::to_vec_pretty(v).unwrap()).unwrap();
}

fn write_area(workdir: &Path, spec: &AreaSpec) {
    let dir = workdir.join(spec.name);
    let origin = Geodetic::new(35.658, 139.70 + spec.seed as f64 * 0.01, 40.0);
    let enu = EnuFrame::new(origin);
    let manifest = Manifest {
        insgen_version: "test".into(),
        area: spec.name.into(),
        split: spec.split.into(),
        origin: Origin { lat_deg: origin.lat_deg, lon_deg: origin.lon_deg, h_m: origin.h_m },
        ecef_from_enu: enu.ecef_from_enu(),
        area_polygon_enu_m: vec![[-100.0, -100.0], [100.0, -100.0], [100.0, 100.0], [-100.0, 100.0]],
        ground_enu_m: 0.0,
        geoid: GeoidUsed {
            model: "none".into(),
            grid: None,
            undulation_at_origin_m: 0.0,
            ..Default::default()
        },
        sources: vec![SourceEntry {
            path: format!("{}.gml", spec.name),
            format: "citygml".into(),
            sha256: format!("{:064x}", spec.seed),
            crs_chain: "EPSG:6697 → EPSG:4978 → ENU".into(),
            buildings: BUILDINGS as u64,
            degenerate_faces: 0,
            attribution: Some("3D city model (Project PLATEAU), MLIT, CC BY 4.0".into()),
            heights: None,
            appearance: None,
            procedural: None,
        }],
        buildings: BUILDINGS as u64,
        triangles: 0,
        degenerate_faces: 0,
        attributions: vec!["3D city model (Project PLATEAU), MLIT, CC BY 4.0".into()],
        clutter: None,
        alignment: None,
    };
    write_json(&dir.join("scene/manifest.json"), &manifest);
    let buildings: Vec<BuildingRecord> = (1..=BUILDINGS)
        .map(|id| BuildingRecord {
            id: BuildingId::new(id).unwrap(),
            source_id: format!("bldg_{}_{id:03}", spec.name),
            source_file: format!("{}.gml", spec.name),
            lod: "1".into(),
            height_m: 10.0,
            measured_height_m: None,
            footprint_area_m2: 100.0,
            centroid_lat_deg: origin.lat_deg,
            centroid_lon_deg: origin.lon_deg,
            bbox_min_enu_m: [0.0; 3],
            bbox_max_enu_m: [1.0; 3],
            triangles: 12,
        })
        .collect();
    write_json(&dir.join("scene/buildings.json"), &buildings);

    let cam = dir.join("cam2");
    let k = Intrinsics::from_hfov(W, H, 25.0);
    let mut rng = ChaCha8Rng::seed_from_u64(spec.seed);
    let mut poses = String::new();
    let n_frames = spec.frames + spec.unrendered_frame as usize;
    for i in 0..n_frames {
        let name = format!("{}_f{i:03}", spec.name);
        let pose = Pose::from_ypr_deg(30.0 * i as f64, 20.0, 0.0, [i as f64 * 10.0, 5.0, 300.0]);
        let rec = PoseRecord::new(
            name.clone(),
            spec.name,
            "cam2",
            Trajectory::Grid,
            i as u32,
            0,
            k,
            &pose,
            &enu,
            0.0,
        );
        poses.push_str(&serde_json::to_string(&rec).unwrap());
        poses.push('\n');
        if i >= spec.frames {
            continue; // listed, never rendered
        }
        let ids = if spec.empty_frame && i == 1 { vec![0; (W * H) as usize] } else { draw_frame(&mut rng) };
        let map = IdMap::from_raw(W, H, ids).unwrap();
        let png = map.encode_png().unwrap();
        std::fs::create_dir_all(cam.join("masks")).unwrap();
        std::fs::write(cam.join(format!("masks/{name}.png")), png).unwrap();
        let lab = label_components(&map, spec.connectivity);
        let mut visible_px: BTreeMap<BuildingId, u64> = BTreeMap::new();
        for c in &lab.components {
            *visible_px.entry(c.building_id).or_default() += c.area_px;
        }
        let instances = lab
            .components
            .iter()
            .filter(|c| c.area_px >= spec.min_component_area_px)
            .map(|c| InstanceEntry {
                building_id: c.building_id,
                source_id: format!("bldg_{}_{:03}", spec.name, c.building_id),
                component: c.index,
                area_px: c.area_px,
                bbox_px: c.bbox_px,
                truncated: c.touches_border,
                building_visible_px: visible_px[&c.building_id],
                visible_fraction: spec
                    .visible_fraction
                    .then(|| (c.building_id.get() as f64 * 0.37).fract().max(0.05)),
                occluded_px: None,
                behind_px: None,
                see_through: None,
            })
            .collect();
        let fi = FrameInstances {
            frame: name.clone(),
            width: W,
            height: H,
            connectivity: spec.connectivity,
            min_component_area_px: spec.min_component_area_px,
            instances,
            pose_sha256: None,
            occluders: Vec::new(),
            occlusion: None,
        };
        write_json(&cam.join(format!("masks/{name}.instances.json")), &fi);
        if i < spec.rgb_frames {
            let rgb: Vec<u8> = (0..W * H).flat_map(|p| [(p % W * 2) as u8, (p / W * 3) as u8, 128]).collect();
            let mut bytes = Vec::new();
            {
                let mut enc = png::Encoder::new(&mut bytes, W, H);
                enc.set_color(png::ColorType::Rgb);
                enc.set_depth(png::BitDepth::Eight);
                enc.write_header().unwrap().write_image_data(&rgb).unwrap();
            }
            std::fs::create_dir_all(cam.join("rgb")).unwrap();
            std::fs::write(cam.join(format!("rgb/{name}.png")), bytes).unwrap();
        }
    }
    std::fs::write(cam.join("poses.jsonl"), poses).unwrap();
}

/// The standard workdir: four areas over three splits, with every special case somewhere.
pub(crate) fn standard_workdir(root: &Path) -> PathBuf {
    let wd = root.join("runs");
    let mut alpha = AreaSpec::new("alpha", "train", 1);
    alpha.rgb_frames = 2; // its third frame has masks but no RGB frame yet
    alpha.visible_fraction = true;
    alpha.unrendered_frame = true;
    let mut bravo = AreaSpec::new("bravo", "val", 2);
    bravo.connectivity = Connectivity::Four;
    bravo.min_component_area_px = 3;
    let mut charlie = AreaSpec::new("charlie", "test", 3);
    charlie.empty_frame = true;
    let delta = AreaSpec::new("delta", "train", 4);
    for a in [alpha, bravo, charlie, delta] {
        write_area(&wd, &a);
    }
    wd
}

pub(crate) fn plan(wd: &Path, out: &str) -> ExportPlan {
    ExportPlan {
        workdir: wd.to_path_buf(),
        out_dir: wd.join(out),
        holdout: vec![],
        unit: AnnotationUnit::Component,
        polygons: false,
        filters: Filters::default(),
        label_only: false,
        shard: insgen::util::Shard::default(),
        link_root: false,
    }
}

fn load(path: &Path) -> Dataset {
    serde_json::from_slice(&std::fs::read(path).unwrap()).unwrap()
}

/// Touching-neighbour pairs of an ID map PNG (8-bit RGB, ID = R·2¹⁶ + G·2⁸ + B), decoded here with the
/// png crate: 4-neighbours holding two different non-zero IDs.
fn touching_pairs(path: &Path) -> u64 {
    let mut r =
        png::Decoder::new(std::io::BufReader::new(std::fs::File::open(path).unwrap())).read_info().unwrap();
    let mut buf = vec![0u8; r.output_buffer_size()];
    let info = r.next_frame(&mut buf).unwrap();
    let (w, h) = (info.width as usize, info.height as usize);
    let id = |x: usize, y: usize| {
        let p = &buf[(y * w + x) * 3..];
        (p[0] as u32) << 16 | (p[1] as u32) << 8 | p[2] as u32
    };
    let mut n = 0;
    for y in 0..h {
        for x in 0..w {
            let a = id(x, y);
            for (nx, ny) in [(x + 1, y), (x, y + 1)] {
                if nx < w && ny < h && a != 0 && id(nx, ny) != 0 && id(nx, ny) != a {
                    n += 1;
                }
            }
        }
    }
    n
}

fn validate_schema(schema_file: &str, instance: &Value) {
    let schema_path = Path::new(env!("CARGO_MANIFEST_DIR")).join("schemas").join(schema_file);
    let schema: Value = serde_json::from_slice(&std::fs::read(&schema_path).unwrap()).unwrap();
    let validator = jsonschema::validator_for(&schema).expect("schema compiles");
    let errors: Vec<String> =
        validator.iter_errors(instance).map(|e| format!("{}: {e}", e.instance_path)).collect();
    assert!(errors.is_empty(), "{schema_file}: {errors:#?}");
}

/// Instance entries of the frames of an area that have an RGB frame (the images of an export), read
/// back from disk (the filters' reference).
fn all_entries(wd: &Path, area: &str) -> Vec<(String, InstanceEntry)> {
    let masks = wd.join(area).join("cam2/masks");
    let has_rgb = |p: &Path| {
        let frame = p.file_name().unwrap().to_str().unwrap().trim_end_matches(".instances.json").to_string();
        wd.join(area).join("cam2/rgb").join(format!("{frame}.png")).is_file()
    };
    let mut files: Vec<_> = std::fs::read_dir(&masks)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.to_str().unwrap().ends_with(".instances.json") && has_rgb(p))
        .collect();
    files.sort();
    files
        .iter()
        .flat_map(|p| {
            let fi: FrameInstances = serde_json::from_slice(&std::fs::read(p).unwrap()).unwrap();
            fi.instances.into_iter().map(move |e| (fi.frame.clone(), e))
        })
        .collect()
}

fn assert_pycocotools_exact(py: &Path, out: &Path, expect_polygons: bool) -> Value {
    let v = crate::util::coco_check(py, &["dataset", out.to_str().unwrap()]);
    for split in ["train", "val", "test"] {
        let r = &v["files"][split];
        eprintln!(
            "pycocotools {split}: {} images, {} annotations checked, segm AP {}, bbox AP {}, polygons {} ({} exact)",
            r["images"], r["checked"], r["segm"]["AP"], r["bbox"]["AP"], r["polygon_annotations"], r["polygon_exact"]
        );
    }
    for split in ["train", "val", "test"] {
        let r = &v["files"][split];
        assert_eq!(r["mismatches"], serde_json::json!([]), "{split}: annToMask differs from the ID map");
        assert_eq!(r["checked"], r["annotations"], "{split}: every annotation checked");
        if r["annotations"].as_u64().unwrap() > 0 {
            for kind in ["segm", "bbox"] {
                let ap = r[kind]["AP"].as_f64().unwrap();
                assert!(
                    (ap - 1.0).abs() < 1e-12,
                    "{split} {kind}: AP {ap} with the ground truth as predictions"
                );
            }
        }
        if expect_polygons {
            assert_eq!(r["polygon_annotations"], r["annotations"]);
        }
    }
    v
}

// ---------------------------------------------------------------------------------------------- tests

#[test]
fn component_export_agrees_with_pycocotools_and_the_id_maps() {
    let tmp = tempfile::tempdir().unwrap();
    let wd = standard_workdir(tmp.path());
    let p = plan(&wd, "coco");
    let (ex, written) = export(&p, &NoProgress).unwrap();
    assert_eq!(
        written.len(),
        9,
        "three COCO files, three Hugging Face metadata files, SHA256SUMS, dataset.json, README.md"
    );
    assert_eq!(ex.frames_without_masks, 1, "alpha lists one frame it never rendered");
    // alpha's third frame has masks but no RGB frame: it is left out and counted, never listed.
    assert_eq!(ex.frames_without_rgb.len(), 1);
    let m = &ex.frames_without_rgb[0];
    assert_eq!((m.area.as_str(), m.camera.as_str(), m.frames, m.broken.len()), ("alpha", "cam2", 1, 0));

    // Splits by area, from the manifests.
    let files: Vec<Dataset> = ["train", "val", "test"]
        .iter()
        .map(|s| load(&p.out_dir.join(format!("instances_{s}.json"))))
        .collect();
    let areas_of =
        |d: &Dataset| d.images.iter().map(|i| i.area_name.clone()).collect::<std::collections::BTreeSet<_>>();
    assert_eq!(areas_of(&files[0]).into_iter().collect::<Vec<_>>(), ["alpha", "delta"]);
    assert_eq!(areas_of(&files[1]).into_iter().collect::<Vec<_>>(), ["bravo"]);
    assert_eq!(areas_of(&files[2]).into_iter().collect::<Vec<_>>(), ["charlie"]);
    // One annotation per listed instance (bravo dropped its 1–2 px specks in its instance files).
    for (d, areas) in files.iter().zip([&["alpha", "delta"][..], &["bravo"], &["charlie"]]) {
        let expected: usize = areas.iter().map(|a| all_entries(&wd, a).len()).sum();
        assert_eq!(d.annotations.len(), expected);
        let with_rgb = if areas.contains(&"alpha") { areas.len() * 3 - 1 } else { areas.len() * 3 };
        assert_eq!(d.images.len(), with_rgb, "empty images are kept by default");
        // Ids from 1, consecutive.
        assert!(d.images.iter().enumerate().all(|(i, im)| im.id == i as u64 + 1));
        assert!(d.annotations.iter().enumerate().all(|(i, a)| a.id == i as u64 + 1));
    }
    // Every image is an RGB frame placed in the export (a hard link to the work directory's); its ID
    // map is `mask_file`, beside its instance list.
    let train = &files[0];
    assert_eq!(train.images[0].file_name, "images/train/alpha/cam2/alpha_f000.png");
    assert_eq!(train.images[0].mask_file, "masks/train/alpha/cam2/alpha_f000.png");
    assert_eq!(train.images[2].file_name, "images/train/delta/cam2/delta_f000.png");
    for d in &files {
        assert!(!d.info.images_missing);
        for im in &d.images {
            let (rgb, mask) = (p.out_dir.join(&im.file_name), p.out_dir.join(&im.mask_file));
            assert!(im.file_name.starts_with("images/") && rgb.is_file(), "{}", im.file_name);
            let source =
                wd.join(&im.area_name).join(&im.camera).join("rgb").join(format!("{}.png", im.frame));
            assert_eq!(std::fs::read(&rgb).unwrap(), std::fs::read(&source).unwrap(), "{}", im.file_name);
            assert!(mask.is_file() && mask.with_extension("instances.json").is_file(), "{}", im.mask_file);
        }
    }
    assert_eq!(train.info.image_root, ".");
    assert_eq!(train.licenses[0].url, "https://creativecommons.org/licenses/by/4.0/");
    assert_eq!(train.images[0].license, Some(1));
    assert!(train
        .annotations
        .iter()
        .all(|a| matches!(a.segmentation, Segmentation::Rle(_)) && a.component.is_some()));
    assert!(train.annotations.iter().any(|a| a.truncated) && train.annotations.iter().any(|a| !a.truncated));

    for f in written.iter().filter(|f| f.file_name().unwrap().to_str().unwrap().starts_with("instances_")) {
        validate_schema(
            "coco_instances.schema.json",
            &serde_json::from_slice(&std::fs::read(f).unwrap()).unwrap(),
        );
    }

    // Deterministic: a second export is byte-identical.
    let p2 = plan(&wd, "coco2");
    export(&p2, &NoProgress).unwrap();
    for s in ["train", "val", "test"] {
        let name = format!("instances_{s}.json");
        assert!(
            std::fs::read(p.out_dir.join(&name)).unwrap() == std::fs::read(p2.out_dir.join(&name)).unwrap(),
            "{name}"
        );
    }

    // Statistics report from the same datasets.
    let refs: Vec<(Split, &Dataset)> = ex.datasets.iter().map(|(s, d)| (*s, d)).collect();
    let st = stats::compute(&refs, &p.out_dir).unwrap();
    let files_written =
        stats::write_report(&st, &refs, &p.out_dir, &p.out_dir, ReportOptions::default()).unwrap();
    assert_eq!(files_written.len(), 5);
    let sj: Value = serde_json::from_slice(&std::fs::read(p.out_dir.join("stats.json")).unwrap()).unwrap();
    for (i, d) in files.iter().enumerate() {
        let sp = &sj["splits"][i];
        assert_eq!(sp["annotations"].as_u64().unwrap() as usize, d.annotations.len());
        let small = d.annotations.iter().filter(|a| a.area < 1024).count();
        assert_eq!(sp["sizes"]["small"].as_u64().unwrap() as usize, small);
    }
    assert_eq!(st.splits[2].images_without_annotations, 1, "charlie's empty frame");
    validate_schema("stats.schema.json", &sj);
    // Learnability: every frame's ID map and photo were read; the touching boundary equals the pairs
    // counted here straight from the PNGs (4-neighbours, two different non-zero IDs).
    for a in sj["areas"].as_array().unwrap() {
        let l = &a["learnability"];
        let name = a["area"].as_str().unwrap();
        let ds = files.iter().find(|d| d.images.iter().any(|im| im.area_name == name)).unwrap();
        let images: Vec<_> = ds.images.iter().filter(|im| im.area_name == name).collect();
        let n = images.len() as u64;
        assert_eq!(
            (l["images_with_id_map"].as_u64(), l["images_with_rgb"].as_u64()),
            (Some(n), Some(n)),
            "{name}"
        );
        let touching: u64 = images.iter().map(|im| touching_pairs(&p.out_dir.join(&im.mask_file))).sum();
        let got = l["boundary"]["touching_px_per_image"].as_f64().unwrap();
        assert!((got - touching as f64 / n as f64).abs() < 1e-9, "{name}: {got} vs {touching} / {n}");
        let anns = ds.annotations.iter().filter(|x| x.area_name == name).count() as u64;
        assert_eq!(l["sizes"]["instances"].as_u64(), Some(anns), "{name}");
    }
    let sheet = insgen::export::raster::read_png_rgb(&p.out_dir.join("contact_sheet.png")).unwrap();
    assert_eq!((sheet.width, sheet.height), (4 * 320, 3 * 240));
    if let Some(keep) = std::env::var_os("INSGEN_COCO_PREVIEW") {
        // For looking at the figures by eye: INSGEN_COCO_PREVIEW=target/coco-preview cargo test ...
        std::fs::create_dir_all(&keep).unwrap();
        for f in &files_written {
            std::fs::copy(f, Path::new(&keep).join(f.file_name().unwrap())).unwrap();
        }
    }
    let md = std::fs::read_to_string(p.out_dir.join("stats.md")).unwrap();
    assert!(md.contains("| alpha | train |"), "{md}");

    let Some(py) = crate::util::python_with(&["numpy", "pycocotools"]) else { return };
    let v = assert_pycocotools_exact(&py, &p.out_dir, false);
    for split in ["train", "val", "test"] {
        assert_eq!(
            v["files"][split]["unannotated"],
            serde_json::json!([]),
            "{split}: a component has no annotation"
        );
    }
}

#[test]
fn per_building_export_merges_the_parts_of_each_building() {
    let tmp = tempfile::tempdir().unwrap();
    let wd = standard_workdir(tmp.path());
    let mut p = plan(&wd, "coco");
    p.unit = AnnotationUnit::Building;
    let (ex, _) = export(&p, &NoProgress).unwrap();
    let train = &ex.datasets[0].1;
    assert!(train.annotations.iter().all(|a| a.component.is_none() && a.num_components.is_some()));
    assert!(train.annotations.iter().any(|a| a.num_components > Some(1)), "some building is split in two");
    // One annotation per (image, building).
    let mut expected = std::collections::BTreeSet::new();
    for area in ["alpha", "delta"] {
        for (frame, e) in all_entries(&wd, area) {
            expected.insert((frame, e.building_id));
        }
    }
    assert_eq!(train.annotations.len(), expected.len());
    for (_, d) in &ex.datasets {
        validate_schema("coco_instances.schema.json", &serde_json::to_value(d).unwrap());
    }
    let Some(py) = crate::util::python_with(&["numpy", "pycocotools"]) else { return };
    let v = assert_pycocotools_exact(&py, &p.out_dir, false);
    assert_eq!(v["files"]["train"]["unannotated"], serde_json::json!([]));
}

#[test]
fn polygons_lose_only_the_holes() {
    let tmp = tempfile::tempdir().unwrap();
    let wd = standard_workdir(tmp.path());
    let mut p = plan(&wd, "coco");
    p.polygons = true;
    let (ex, _) = export(&p, &NoProgress).unwrap();
    let train = &ex.datasets[0].1;
    assert!(train
        .annotations
        .iter()
        .all(|a| matches!(a.segmentation, Segmentation::Polygons(_)) && a.mask_rle.is_some()));
    for (_, d) in &ex.datasets {
        validate_schema("coco_instances.schema.json", &serde_json::to_value(d).unwrap());
    }
    let Some(py) = crate::util::python_with(&["numpy", "pycocotools"]) else { return };
    // The exact mask (mask_rle) matches the ID map; pycocotools rasterises each polygon to the component
    // with its holes filled.
    let v = assert_pycocotools_exact(&py, &p.out_dir, true);
    for split in ["train", "val", "test"] {
        let r = &v["files"][split];
        assert_eq!(r["polygon_pixel_errors"], 0, "{split}: {r}");
    }
}

#[test]
fn filters_keep_exactly_what_they_should() {
    let tmp = tempfile::tempdir().unwrap();
    let wd = standard_workdir(tmp.path());
    let entries: Vec<(String, InstanceEntry)> =
        ["alpha", "delta"].iter().flat_map(|a| all_entries(&wd, a)).collect();

    // --min-area 20 --truncated drop --drop-empty-images
    let mut p = plan(&wd, "f1");
    p.filters = Filters {
        min_area_px: 20,
        truncated: TruncatedPolicy::Drop,
        keep_empty_images: false,
        ..Filters::default()
    };
    let (ex, _) = export(&p, &NoProgress).unwrap();
    let kept: Vec<_> = entries.iter().filter(|(_, e)| e.area_px >= 20 && !e.truncated).collect();
    let train = &ex.datasets[0].1;
    assert_eq!(train.annotations.len(), kept.len());
    let frames: std::collections::BTreeSet<&str> = kept.iter().map(|(f, _)| f.as_str()).collect();
    assert_eq!(train.images.len(), frames.len());
    assert!(train.annotations.iter().all(|a| a.area >= 20 && !a.truncated));
    let charlie_frames: std::collections::BTreeSet<String> = all_entries(&wd, "charlie")
        .into_iter()
        .filter(|(_, e)| e.area_px >= 20 && !e.truncated)
        .map(|(f, _)| f)
        .collect();
    assert!(charlie_frames.len() <= 2, "charlie's frame 1 is empty");
    assert_eq!(ex.datasets[2].1.images.len(), charlie_frames.len(), "empty images are dropped");
    assert!(ex.dropped.small > 0 && ex.dropped.truncated > 0 && ex.dropped.empty_images >= 1);

    // --truncated flag: iscrowd marks exactly the truncated instances; COCOeval still gives AP 1.
    let mut p = plan(&wd, "f2");
    p.filters.truncated = TruncatedPolicy::Flag;
    let (ex, _) = export(&p, &NoProgress).unwrap();
    let train = &ex.datasets[0].1;
    assert_eq!(train.annotations.len(), entries.len());
    assert!(train.annotations.iter().all(|a| (a.iscrowd == 1) == a.truncated));

    // --min-visible-fraction on alpha alone (the only area with visible fractions).
    let wd2 = tmp.path().join("vf");
    let mut a = AreaSpec::new("alpha", "train", 1);
    a.visible_fraction = true;
    write_area(&wd2, &a);
    let mut p3 = plan(&wd2, "coco");
    p3.filters.min_visible_fraction = Some(0.5);
    let (ex3, _) = export(&p3, &NoProgress).unwrap();
    let want = all_entries(&wd2, "alpha").iter().filter(|(_, e)| e.visible_fraction.unwrap() >= 0.5).count();
    assert_eq!(ex3.datasets[0].1.annotations.len(), want);
    assert!(ex3.dropped.low_visibility > 0);

    let Some(py) = crate::util::python_with(&["numpy", "pycocotools"]) else { return };
    assert_pycocotools_exact(&py, &p.out_dir, false);
}

#[test]
fn label_only_lists_unrendered_frames_by_their_rgb_name_and_says_so() {
    let tmp = tempfile::tempdir().unwrap();
    let wd = standard_workdir(tmp.path());
    // A broken RGB frame (truncated PNG) counts as missing too, and is named.
    let delta_rgb = wd.join("delta/cam2/rgb/delta_f001.png");
    let bytes = std::fs::read(&delta_rgb).unwrap();
    std::fs::write(&delta_rgb, &bytes[..bytes.len() / 2]).unwrap();
    let (ex, _) = export(&plan(&wd, "coco"), &NoProgress).unwrap();
    let broken: Vec<_> = ex.frames_without_rgb.iter().flat_map(|m| m.broken.clone()).collect();
    assert_eq!(broken, vec![delta_rgb.clone()]);
    assert_eq!(ex.datasets[0].1.images.len(), 4, "alpha 2 + delta 2");

    let mut p = plan(&wd, "labels");
    p.label_only = true;
    let (ex, _) = export(&p, &NoProgress).unwrap();
    assert!(ex.frames_without_rgb.is_empty());
    let train = load(&p.out_dir.join("instances_train.json"));
    assert!(train.info.images_missing);
    assert_eq!(train.images.len(), 6);
    let f002 = train.images.iter().find(|i| i.frame == "alpha_f002").unwrap();
    assert_eq!(
        f002.file_name, "images/train/alpha/cam2/alpha_f002.png",
        "the frame to come, never the ID map"
    );
    assert!(!p.out_dir.join(&f002.file_name).exists());
    assert!(p.out_dir.join(&f002.mask_file).is_file(), "its ID map is placed");
    let json: Value =
        serde_json::from_slice(&std::fs::read(p.out_dir.join("instances_train.json")).unwrap()).unwrap();
    assert_eq!(json["info"]["images_missing"], Value::Bool(true));
    validate_schema("coco_instances.schema.json", &json);
}

#[test]
fn verify_passes_an_export_and_reports_each_kind_of_damage() {
    use insgen::export::verify::verify;
    let tmp = tempfile::tempdir().unwrap();
    let wd = standard_workdir(tmp.path());
    let p = plan(&wd, "coco");
    export(&p, &NoProgress).unwrap();
    let clean = verify(&p.out_dir, &NoProgress);
    assert!(clean.problems.is_empty(), "{:#?}", clean.problems);
    assert_eq!(clean.coco_files, 3);
    assert!(clean.images > 0 && clean.annotations > 0);
    let manifest: Value =
        serde_json::from_slice(&std::fs::read(p.out_dir.join("dataset.json")).unwrap()).unwrap();
    validate_schema("dataset.schema.json", &manifest);
    let card = std::fs::read_to_string(p.out_dir.join("README.md")).unwrap();
    assert!(card.contains("| train | `instances_train.json` |") && card.contains("CC BY 4.0"), "{card}");

    let problems = |dir: &Path| -> Vec<String> {
        verify(dir, &NoProgress).problems.iter().map(|x| x.to_string()).collect()
    };
    // Each damage on a fresh copy of the export, each reported with its file.
    let damaged = |name: &str, damage: &dyn Fn(&Path, &Path)| -> Vec<String> {
        let wd2 = tmp.path().join(name);
        copy_dir(&wd, &wd2);
        damage(&wd2, &wd2.join("coco"));
        problems(&wd2.join("coco"))
    };
    // 1. A truncated ID map.
    let got = damaged("truncated_png", &|_, coco| {
        let f = coco.join("masks/train/delta/cam2/delta_f000.png");
        let b = std::fs::read(&f).unwrap();
        std::fs::write(&f, &b[..b.len() / 3]).unwrap();
    });
    assert!(got.iter().any(|p| p.contains("delta_f000.png") && p.contains("not a readable PNG")), "{got:#?}");
    // 2. A deleted RGB frame.
    let got = damaged("deleted_rgb", &|_, coco| {
        std::fs::remove_file(coco.join("images/val/bravo/cam2/bravo_f001.png")).unwrap()
    });
    assert!(
        got.iter().any(|p| p.contains("images/val/bravo/cam2/bravo_f001.png") && p.contains("missing")),
        "{got:#?}"
    );
    // 3. An annotation whose RLE does not match its ID map (and 4. a duplicated annotation id), edited
    //    in the JSON, so the manifest's hash no longer matches either.
    let got = damaged("bad_rle_dup_id", &|_, coco| {
        let f = coco.join("instances_train.json");
        let mut d: Value = serde_json::from_slice(&std::fs::read(&f).unwrap()).unwrap();
        let anns = d["annotations"].as_array_mut().unwrap();
        let (a, b) = (anns[0].clone(), anns[1].clone());
        anns[0]["segmentation"] = b["segmentation"].clone();
        anns[1]["id"] = a["id"].clone();
        std::fs::write(&f, serde_json::to_vec(&d).unwrap()).unwrap();
    });
    assert!(got.iter().any(|p| p.contains("instances_train.json: annotation 1: its mask")), "{got:#?}");
    assert!(got.iter().any(|p| p.contains("annotation id 1 is used twice")), "{got:#?}");
    assert!(got.iter().any(|p| p.contains("SHA-256") && p.contains("changed after export")), "{got:#?}");
    // Through the binary: each problem printed, non-zero exit.
    let o = crate::util::insgen(
        tmp.path(),
        &["verify", tmp.path().join("bad_rle_dup_id/coco").to_str().unwrap()],
    );
    assert_eq!(o.status.code(), Some(1));
    assert!(crate::util::stderr(&o).contains("problem: "), "{}", crate::util::stderr(&o));
    let o = crate::util::insgen(tmp.path(), &["verify", p.out_dir.to_str().unwrap()]);
    assert!(o.status.success(), "{}", crate::util::stderr(&o));
}

fn copy_dir(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).unwrap();
    for e in std::fs::read_dir(from).unwrap() {
        let e = e.unwrap();
        let t = to.join(e.file_name());
        if e.file_type().unwrap().is_dir() {
            copy_dir(&e.path(), &t);
        } else {
            std::fs::copy(e.path(), &t).unwrap();
        }
    }
}

#[test]
fn holdout_moves_whole_areas_to_test_and_unknown_areas_are_named() {
    let tmp = tempfile::tempdir().unwrap();
    let wd = standard_workdir(tmp.path());
    let mut p = plan(&wd, "coco");
    p.holdout = vec!["delta".into()];
    let (ex, _) = export(&p, &NoProgress).unwrap();
    let names = |s: usize| {
        ex.datasets[s]
            .1
            .images
            .iter()
            .map(|i| i.area_name.as_str())
            .collect::<std::collections::BTreeSet<_>>()
    };
    assert_eq!(names(0).into_iter().collect::<Vec<_>>(), ["alpha"]);
    assert_eq!(names(2).into_iter().collect::<Vec<_>>(), ["charlie", "delta"]);
    let delta = ex.datasets[2].1.info.areas.iter().find(|a| a.name == "delta").unwrap();
    assert!(delta.held_out && delta.manifest_split == "train");

    p.holdout = vec!["echo".into()];
    let err = export(&p, &NoProgress).unwrap_err().to_string();
    assert!(err.contains("--holdout echo") && err.contains("alpha, bravo, charlie, delta"), "{err}");
}

#[test]
fn an_instance_file_that_disagrees_with_its_id_map_is_reported() {
    let tmp = tempfile::tempdir().unwrap();
    let wd = standard_workdir(tmp.path());
    let path = wd.join("delta/cam2/masks/delta_f001.instances.json");
    let mut fi: FrameInstances = serde_json::from_slice(&std::fs::read(&path).unwrap()).unwrap();
    fi.instances[0].area_px += 1;
    write_json(&path, &fi);
    let p = plan(&wd, "coco");
    let err = export(&p, &NoProgress).unwrap_err();
    let msg = format!("{:#}", anyhow::Error::from(err));
    assert!(msg.contains("1 of 12 frames could not be exported, so nothing was written"), "{msg}");
    assert!(msg.contains("delta_f001.instances.json") && msg.contains("delta_f001.png"), "{msg}");
    assert!(msg.contains("instances[0] is building"), "{msg}");
    assert!(!p.out_dir.exists(), "a failed export leaves no output directory");
}

#[test]
fn missing_visible_fraction_and_empty_workdir_explain_the_fix() {
    let tmp = tempfile::tempdir().unwrap();
    let wd = standard_workdir(tmp.path());
    let mut p = plan(&wd, "coco");
    p.filters.min_visible_fraction = Some(0.3);
    let msg = format!("{:#}", anyhow::Error::from(export(&p, &NoProgress).unwrap_err()));
    assert!(msg.contains("no visible_fraction") && msg.contains("--visible-fraction --force"), "{msg}");

    let empty = tmp.path().join("nothing");
    std::fs::create_dir_all(&empty).unwrap();
    let msg = export(&plan(&empty, "coco"), &NoProgress).unwrap_err().to_string();
    assert!(msg.contains("no prepared area") && msg.contains("insgen prepare"), "{msg}");
}

#[test]
fn an_export_without_photos_is_an_error_naming_render_rgb_and_writes_nothing() {
    // Issue 39: following prepare → sample → render-masks → export-coco (no render-rgb) used to write
    // 0 images, a card and charts, and exit 0.
    let tmp = tempfile::tempdir().unwrap();
    let wd = tmp.path().join("runs");
    let mut alpha = AreaSpec::new("alpha", "train", 1);
    alpha.rgb_frames = 0;
    write_area(&wd, &alpha);
    let p = plan(&wd, "coco");
    let msg = format!("{:#}", anyhow::Error::from(export(&p, &NoProgress).unwrap_err()));
    assert!(msg.contains("no image") && msg.contains("insgen render-rgb --area alpha --camera"), "{msg}");
    assert!(msg.contains("--label-only"), "{msg}");
    assert!(!p.out_dir.exists(), "an empty export left {}", p.out_dir.display());
    // The labels alone are still an export.
    let mut labels = plan(&wd, "coco");
    labels.label_only = true;
    let (ex, _) = export(&labels, &NoProgress).unwrap();
    assert!(ex.datasets.iter().any(|(_, ds)| !ds.images.is_empty()));
}

#[test]
fn results_written_by_pycocotools_read_back_exactly() {
    let tmp = tempfile::tempdir().unwrap();
    let wd = standard_workdir(tmp.path());
    let p = plan(&wd, "coco");
    let (ex, _) = export(&p, &NoProgress).unwrap();
    let Some(py) = crate::util::python_with(&["numpy", "pycocotools"]) else { return };
    let gt = p.out_dir.join("instances_train.json");
    let res_path = tmp.path().join("results.json");
    crate::util::coco_check(&py, &["results", gt.to_str().unwrap(), res_path.to_str().unwrap()]);
    let raw: Value = serde_json::from_slice(&std::fs::read(&res_path).unwrap()).unwrap();
    validate_schema("coco_results.schema.json", &raw);
    let results = read_results(&res_path).unwrap();
    let train = &ex.datasets[0].1;
    assert_eq!(results.len(), train.annotations.len());
    for preds in results.by_image.values() {
        for pr in preds {
            // pycocotools wrote the entries in annotation order.
            let ann = &train.annotations[pr.index];
            let Segmentation::Rle(r) = &ann.segmentation else { panic!("RLE expected") };
            let gt_rle = r.to_rle().unwrap();
            assert_eq!(pr.rle, gt_rle, "entry {}", pr.index);
            assert_eq!(pr.mask(), gt_rle.decode());
            assert_eq!(pr.bbox_area_px, ann.bbox[2] * ann.bbox[3]);
            assert_eq!(raw[pr.index]["image_id"].as_u64().unwrap(), ann.image_id);
        }
    }
}

fn schema_errors(schema_file: &str, instance: &Value) -> Vec<String> {
    let schema_path = Path::new(env!("CARGO_MANIFEST_DIR")).join("schemas").join(schema_file);
    let schema: Value = serde_json::from_slice(&std::fs::read(&schema_path).unwrap()).unwrap();
    let validator = jsonschema::validator_for(&schema).expect("schema compiles");
    validator.iter_errors(instance).map(|e| e.instance_path.to_string()).collect()
}

#[test]
fn schemas_reject_broken_files() {
    let tmp = tempfile::tempdir().unwrap();
    let wd = tmp.path().join("runs");
    write_area(&wd, &AreaSpec::new("alpha", "train", 1));
    let (ex, _) = export(&plan(&wd, "coco"), &NoProgress).unwrap();
    let good = serde_json::to_value(&ex.datasets[0].1).unwrap();
    assert!(schema_errors("coco_instances.schema.json", &good).is_empty());
    let mut bad = good.clone();
    bad["annotations"][0]["bbox"] = serde_json::json!([1.0, 2.0, 3.0]);
    bad["annotations"][1]["category_id"] = serde_json::json!(2);
    bad["annotations"][2]["segmentation"]["counts"] = serde_json::json!("12z");
    bad["images"][0]["connectivity"] = serde_json::json!("6");
    let mut errs = schema_errors("coco_instances.schema.json", &bad);
    errs.sort();
    errs.dedup();
    assert_eq!(
        errs,
        [
            "/annotations/0/bbox",
            "/annotations/1/category_id",
            "/annotations/2/segmentation",
            "/images/0/connectivity"
        ]
    );

    let results = serde_json::json!([
        {"image_id": 1, "category_id": 1, "score": 0.5, "segmentation": {"size": [2, 2], "counts": "4"}},
        {"image_id": 1, "category_id": 0, "score": 0.5, "segmentation": {"size": [2, 2], "counts": "4"}},
        {"image_id": 1, "category_id": 1, "segmentation": {"size": [2, 2], "counts": [4]}}
    ]);
    assert_eq!(schema_errors("coco_results.schema.json", &results), ["/1/category_id", "/2"]);
}
