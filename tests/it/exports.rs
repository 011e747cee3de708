//! The dataset in other tools' formats, each read back by that format's own client:
//! - COLMAP (`sample`'s `colmap/`): `pycolmap.Reconstruction` (PyPI pycolmap) loads the model; its
//!   cameras, images and poses equal `poses.jsonl` within 1e-9 (quaternion components, metres, pixels —
//!   both sides are the same f64 values printed in shortest round-trip form, so the bound is rounding);
//! - COCO panoptic (`export-panoptic`): panopticapi (PyPI panopticapi-lite: `rgb2id`, `pq_compute`)
//!   decodes every PNG; each segment's pixels, area and box equal the instance annotation's
//!   (pycocotools `decode`) exactly, lie on its building in the ID map, the background segment is
//!   exactly the ID map's 0 pixels, and PQ (things, stuff, all) of the ground truth against itself is 1;
//! - YOLO-seg (`export-yolo`): Ultralytics' label rules (reimplemented in `scripts/exports_check.py` from
//!   `ultralytics/data/utils.py`; the `ultralytics` package pulls in torch, too heavy for this machine)
//!   and an even-odd rasteriser at pixel centres: every label line fills exactly its instance (IoU 1 —
//!   the polygons are traced along pixel edges without simplification);
//! - 3D Tiles (`export-tiles`): 3d-tiles-tools traverses the tileset and sees glTF content; CesiumJS's
//!   engine math (npm @cesium/engine) puts every sampled vertex within 1 cm of where CesiumJS's own ENU
//!   frame at the manifest's origin puts it (measured: ~12 µm, f32 positions); CesiumJS in headless
//!   Chromium (Debian chromium, SwiftShader) loads the tileset, its root transform is the manifest's,
//!   and clicks pick buildings whose `source_id` matches `buildings.json` at positions inside that
//!   building's ENU box (0.25 m tolerance for `pickPosition`'s depth read-back; measured: 0 m over 28
//!   picks at 640 × 480);
//! - the CLI conveniences: completions, man pages and the `--json` outputs, parsed.
//!
//! Python comes from `INSGEN_PYTHON` (default `.venv/bin/python`), Node packages from `node_modules/`;
//! when a client is missing the check prints why and skips, and fails instead under `CI=true`.

use std::path::{Path, PathBuf};
use std::process::Command;

use insgen::export::coco::export;
use insgen::export::format::{AnnotationUnit, TruncatedPolicy};
use insgen::export::panoptic::{export_panoptic, PanopticPlan};
use insgen::export::yolo::{export_yolo, YoloPlan};
use insgen::export::CocoError;
use insgen::scene::{BuildingRecord, Manifest};
use insgen::util::NoProgress;
use serde_json::Value;

use crate::coco_export::{plan, standard_workdir};
use crate::util::{assert_schema, insgen, python_with, repo, repo_scene, scratch_with_scenes, skip, stderr};

fn run_ok(cwd: &Path, args: &[&str]) -> String {
    let o = insgen(cwd, args);
    assert!(o.status.success(), "insgen {args:?} failed:\n{}", stderr(&o));
    String::from_utf8(o.stdout).expect("UTF-8 stdout")
}

/// Runs `scripts/exports_check.py ARGS` with `py`; the JSON it prints.
fn exports_check(py: &Path, args: &[&str]) -> Value {
    let out = Command::new(py).arg(repo().join("scripts/exports_check.py")).args(args).output().unwrap();
    assert!(
        out.status.success(),
        "exports_check.py {args:?} failed:\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).expect("exports_check.py prints JSON")
}

/// `node` with the repository's node_modules holding `package`, or `None` (skip) with the reason.
fn node_with(package: &str) -> Option<PathBuf> {
    let node_ok = Command::new("node").arg("--version").output().map(|o| o.status.success()).unwrap_or(false);
    if !node_ok {
        skip("`node` is not on PATH (scripts/setup.sh installs it)");
        return None;
    }
    if !repo().join("node_modules").join(package).join("package.json").is_file() {
        skip(&format!("node_modules/{package} is missing (run scripts/setup.sh)"));
        return None;
    }
    Some(PathBuf::from("node"))
}

fn read_json<T: serde::de::DeserializeOwned>(p: &Path) -> T {
    serde_json::from_slice(&std::fs::read(p).unwrap_or_else(|e| panic!("{}: {e}", p.display()))).unwrap()
}

// ------------------------------------------------------------------------------------------ COLMAP

#[test]
fn colmap_model_loads_in_pycolmap_with_the_sampled_poses() {
    let dir = scratch_with_scenes(&[("demo", repo_scene("demo"))]);
    run_ok(dir.path(), &["prepare", "--area", "demo"]);
    run_ok(dir.path(), &["sample", "--area", "demo", "--camera", "cam2", "--count", "6"]);
    let cam = dir.path().join("runs/demo/cam2");
    let points = std::fs::read_to_string(cam.join("colmap/points3D.txt")).unwrap();
    assert!(points.lines().all(|l| l.starts_with('#')), "no points expected:\n{points}");
    let Some(py) = python_with(&["pycolmap"]) else { return };
    let r = exports_check(
        &py,
        &["colmap", cam.join("colmap").to_str().unwrap(), cam.join("poses.jsonl").to_str().unwrap()],
    );
    eprintln!("pycolmap: {r}");
    assert_eq!(
        (r["cameras"].as_u64(), r["images"].as_u64(), r["points3D"].as_u64()),
        (Some(1), Some(6), Some(0))
    );
    assert_eq!(r["poses"], 6);
    assert_eq!(r["unmatched"], serde_json::json!([]));
    assert_eq!(r["model"], "PINHOLE");
    for key in
        ["max_quat_diff", "max_t_diff_m", "max_centre_diff_m", "max_rotation_diff", "max_intrinsics_diff_px"]
    {
        let d = r[key].as_f64().unwrap();
        assert!(d <= 1e-9, "{key} = {d} (bound 1e-9)");
    }
}

// ------------------------------------------------------------------------------------------ panoptic

fn assert_panoptic_exact(py: &Path, coco: &Path) -> Value {
    let r = exports_check(py, &["panoptic", coco.to_str().unwrap()]);
    for split in ["train", "val", "test"] {
        let s = &r["files"][split];
        eprintln!(
            "panoptic {split}: {} images, {} segments ({} crowd), PQ {} (things {}, stuff {})",
            s["images"], s["segments"], s["crowd_segments"], s["pq"], s["pq_things"], s["pq_stuff"]
        );
        assert_eq!(s["problems"], serde_json::json!([]), "{split}");
        assert_eq!(s["same_images"], true, "{split}: images differ from the instance file's");
        assert_eq!(s["isthing"], serde_json::json!([1, 0]), "building (thing) and background (stuff)");
        if s["segments"].as_u64().unwrap() > 0 && s["pq_n"].as_u64().unwrap() > 0 {
            for k in ["pq", "sq", "rq"] {
                assert!((s[k].as_f64().unwrap() - 1.0).abs() < 1e-12, "{split} {k} = {}", s[k]);
            }
        }
    }
    r
}

#[test]
fn panoptic_pngs_decode_to_the_instance_masks() {
    let tmp = tempfile::tempdir().unwrap();
    let wd = standard_workdir(tmp.path());
    let mut p = plan(&wd, "coco");
    p.filters.truncated = TruncatedPolicy::Flag;
    export(&p, &NoProgress).unwrap();
    let out = run_ok(tmp.path(), &["--workdir", wd.to_str().unwrap(), "export-panoptic"]);
    assert!(out.contains("train: ") && out.contains("segments"), "{out}");
    let coco = wd.join("coco");
    for split in ["train", "val", "test"] {
        let v: Value = read_json(&coco.join(format!("panoptic_{split}.json")));
        assert_schema("coco_panoptic.schema.json", &v);
        let inst: Value = read_json(&coco.join(format!("instances_{split}.json")));
        let segments: Vec<&Value> = v["annotations"]
            .as_array()
            .unwrap()
            .iter()
            .flat_map(|a| a["segments_info"].as_array().unwrap())
            .collect();
        // One segment per annotation, the crowd ones merged per image.
        let things: usize = segments
            .iter()
            .filter(|s| s["category_id"] == 1)
            .map(|s| s.get("annotation_ids").map_or(1, |ids| ids.as_array().unwrap().len()))
            .sum();
        assert_eq!(things, inst["annotations"].as_array().unwrap().len(), "{split}: every annotation once");
        // Every image has background pixels in the fixture, hence one background segment each.
        let stuff: Vec<_> = segments.iter().filter(|s| s["category_id"] == 2).collect();
        assert_eq!(stuff.len(), v["images"].as_array().unwrap().len(), "{split}");
        assert!(stuff.iter().all(|s| s["id"] == 16_777_215 && s.get("building_id").is_none()));
    }
    let v: Value = read_json(&coco.join("panoptic_train.json"));
    let crowd = v["annotations"]
        .as_array()
        .unwrap()
        .iter()
        .flat_map(|a| a["segments_info"].as_array().unwrap())
        .filter(|s| s["iscrowd"] == 1)
        .count();
    assert!(crowd > 0, "--truncated flag gives crowd segments in the fixture");
    // `stats --json` prints the report's numbers for scripts.
    let st: Value = serde_json::from_str(&run_ok(
        tmp.path(),
        &["stats", "--coco", coco.to_str().unwrap(), "--json", "--contact-sheet", "0"],
    ))
    .unwrap();
    assert_eq!(st["splits"].as_array().unwrap().len(), 3);
    assert!(st["splits"][0]["max_instances_per_image"].as_u64().unwrap() > 0);
    // … with each area's learnability block, read from the ID maps and photos.
    crate::util::assert_schema("stats.schema.json", &st);
    for a in st["areas"].as_array().unwrap() {
        let l = &a["learnability"];
        assert_eq!(l["images_with_id_map"], l["images"], "{}", a["area"]);
        assert!(l["boundary"]["touching_px_per_image"].as_f64().unwrap() >= 0.0 && l["contrast"].is_object());
    }
    let Some(py) = python_with(&["panopticapi", "pycocotools", "PIL"]) else { return };
    assert_panoptic_exact(&py, &coco);
}

#[test]
fn panoptic_of_a_per_building_polygon_export() {
    let tmp = tempfile::tempdir().unwrap();
    let wd = standard_workdir(tmp.path());
    let mut p = plan(&wd, "coco-b");
    p.unit = AnnotationUnit::Building;
    p.polygons = true;
    export(&p, &NoProgress).unwrap();
    let out = wd.join("pan");
    let s = export_panoptic(&PanopticPlan { coco_dir: wd.join("coco-b"), out_dir: out.clone() }, &NoProgress)
        .unwrap();
    assert_eq!(s.iter().map(|s| s.split.as_str()).collect::<Vec<_>>(), ["train", "val", "test"]);
    // The checker reads instances_*.json next to the panoptic files; their image root (the COCO
    // folder itself, ".") is rewritten to point from there into the COCO folder.
    for split in ["train", "val", "test"] {
        let f = format!("instances_{split}.json");
        let mut v: Value = read_json(&wd.join("coco-b").join(&f));
        assert_eq!(v["info"]["image_root"], ".");
        v["info"]["image_root"] = "../coco-b".into();
        std::fs::write(out.join(&f), serde_json::to_vec(&v).unwrap()).unwrap();
    }
    let Some(py) = python_with(&["panopticapi", "pycocotools", "PIL"]) else { return };
    assert_panoptic_exact(&py, &out);
}

#[test]
fn a_stale_coco_export_is_refused_naming_both_files() {
    let tmp = tempfile::tempdir().unwrap();
    let wd = standard_workdir(tmp.path());
    export(&plan(&wd, "coco"), &NoProgress).unwrap();
    // Re-render one frame "after" the export: a different ID map under the same name.
    let mask = wd.join("alpha/cam2/masks/alpha_f000.png");
    let blank = insgen::scene::IdMap::background(96, 72);
    std::fs::write(&mask, blank.encode_png().unwrap()).unwrap();
    let e = export_panoptic(&PanopticPlan { coco_dir: wd.join("coco"), out_dir: wd.join("p") }, &NoProgress)
        .unwrap_err();
    assert!(matches!(e, CocoError::Mismatch { .. }), "{e:?}");
    let msg = e.to_string();
    assert!(msg.contains("instances_train.json") && msg.contains("alpha_f000.png"), "{msg}");
    assert!(msg.contains("run `insgen export-coco` again"), "{msg}");
    let e =
        export_yolo(&YoloPlan { coco_dir: wd.join("coco"), out_dir: wd.join("y") }, &NoProgress).unwrap_err();
    assert!(matches!(e, CocoError::Mismatch { .. }), "{e:?}");
    let o = insgen(tmp.path(), &["--workdir", wd.to_str().unwrap(), "export-panoptic", "--coco", "nowhere"]);
    assert_eq!(o.status.code(), Some(1));
    assert!(stderr(&o).contains("run `insgen export-coco` first or pass --coco DIR"), "{}", stderr(&o));
}

// ------------------------------------------------------------------------------------------ YOLO

fn assert_yolo_exact(py: &Path, yaml: &Path, coco: &Path) {
    let r = exports_check(py, &["yolo", yaml.to_str().unwrap(), coco.to_str().unwrap()]);
    assert_eq!(r["names"], serde_json::json!({"0": "building"}));
    for split in ["train", "val", "test"] {
        let s = &r["splits"][split];
        eprintln!(
            "yolo {split}: {} images, {} instances, min IoU {}, max vertices {}",
            s["images"], s["instances"], s["min_iou"], s["max_vertices"]
        );
        assert_eq!(s["problems"], serde_json::json!([]), "{split}");
        assert_eq!(s["images"], s["coco_images"], "{split}: one image link per COCO image");
        assert_eq!(s["min_iou"].as_f64(), Some(1.0), "{split}: labels fill back exactly");
    }
}

#[test]
fn yolo_labels_fill_back_to_the_instances() {
    let tmp = tempfile::tempdir().unwrap();
    let wd = standard_workdir(tmp.path());
    let mut p = plan(&wd, "coco");
    p.filters.truncated = TruncatedPolicy::Flag;
    export(&p, &NoProgress).unwrap();
    let out = run_ok(tmp.path(), &["--workdir", wd.to_str().unwrap(), "export-yolo"]);
    assert!(out.contains("crowd left out"), "{out}");
    let yolo = wd.join("coco/yolo");
    let yaml = std::fs::read_to_string(yolo.join("data.yaml")).unwrap();
    assert!(
        yaml.contains("\ntrain: images/train\nval: images/val\ntest: images/test\nnames:\n  0: building\n"),
        "{yaml}"
    );
    assert!(!yaml.lines().any(|l| l.starts_with("path:")), "no root: Ultralytics takes the yaml's folder");
    // Images are files (hard links to the COCO export's, not symbolic links); label lines have the
    // Ultralytics shape.
    let image = yolo.join("images/train/alpha/cam2/alpha_f000.png");
    assert!(std::fs::symlink_metadata(&image).unwrap().file_type().is_file());
    assert_eq!(
        std::fs::read(&image).unwrap(),
        std::fs::read(wd.join("alpha/cam2/rgb/alpha_f000.png")).unwrap()
    );
    let label = std::fs::read_to_string(yolo.join("labels/train/alpha/cam2/alpha_f000.txt")).unwrap();
    for line in label.lines() {
        let f: Vec<&str> = line.split(' ').collect();
        assert!(f[0] == "0" && f.len() >= 9 && f.len() % 2 == 1, "{line}");
        assert!(f[1..].iter().all(|v| (0.0..=1.0).contains(&v.parse::<f64>().unwrap())), "{line}");
    }
    let Some(py) = python_with(&["yaml", "pycocotools", "PIL"]) else { return };
    assert_yolo_exact(&py, &yolo.join("data.yaml"), &wd.join("coco"));
}

#[test]
fn yolo_bridges_the_parts_and_holes_of_per_building_instances() {
    let tmp = tempfile::tempdir().unwrap();
    let wd = standard_workdir(tmp.path());
    let mut p = plan(&wd, "coco-b");
    p.unit = AnnotationUnit::Building;
    export(&p, &NoProgress).unwrap();
    let (sum, yaml) =
        export_yolo(&YoloPlan { coco_dir: wd.join("coco-b"), out_dir: wd.join("yolo-b") }, &NoProgress)
            .unwrap();
    assert_eq!(sum.iter().map(|s| s.crowd_skipped).sum::<u64>(), 0);
    let Some(py) = python_with(&["yaml", "pycocotools", "PIL"]) else { return };
    assert_yolo_exact(&py, &yaml, &wd.join("coco-b"));
}

// ------------------------------------------------------------------------------------------ moving

/// The image files under `dir` (recursively), skipping symbolic links.
fn image_files(dir: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    for e in std::fs::read_dir(dir).unwrap() {
        let e = e.unwrap();
        let kind = e.file_type().unwrap();
        if kind.is_dir() {
            out.extend(image_files(&e.path()));
        } else if kind.is_file() && e.path().extension().is_some_and(|x| x == "png") {
            out.push(e.path());
        }
    }
    out
}

#[test]
fn a_moved_export_folder_verifies_and_loads_in_every_client() {
    let tmp = tempfile::tempdir().unwrap();
    let wd = standard_workdir(tmp.path());
    let mut p = plan(&wd, "coco");
    p.filters.truncated = TruncatedPolicy::Flag;
    export(&p, &NoProgress).unwrap();
    let first: Vec<Vec<u8>> = ["train", "val", "test"]
        .iter()
        .map(|s| std::fs::read(p.out_dir.join(format!("instances_{s}.json"))).unwrap())
        .collect();
    let photo = p.out_dir.join("images/train/alpha/cam2/alpha_f000.png");
    #[cfg(unix)]
    let inode = {
        use std::os::unix::fs::MetadataExt;
        let (a, b) = (
            std::fs::metadata(&photo).unwrap(),
            std::fs::metadata(wd.join("alpha/cam2/rgb/alpha_f000.png")).unwrap(),
        );
        assert_eq!((a.dev(), a.ino()), (b.dev(), b.ino()), "a hard link to the work directory's photo");
        a.ino()
    };
    // A rerun rewrites nothing and writes the same bytes; a stale file is removed.
    let hf_files = ["images/train/metadata.jsonl", "images/val/metadata.jsonl", "images/test/metadata.jsonl"];
    let described: Vec<Vec<u8>> = hf_files
        .iter()
        .chain(&["README.md", "SHA256SUMS"])
        .map(|f| std::fs::read(p.out_dir.join(f)).unwrap())
        .collect();
    std::fs::write(p.out_dir.join("images/train/alpha/cam2/gone.png"), b"stale").unwrap();
    export(&p, &NoProgress).unwrap();
    for (s, bytes) in ["train", "val", "test"].iter().zip(&first) {
        assert!(&std::fs::read(p.out_dir.join(format!("instances_{s}.json"))).unwrap() == bytes, "{s}");
    }
    for (f, bytes) in hf_files.iter().chain(&["README.md", "SHA256SUMS"]).zip(&described) {
        assert!(&std::fs::read(p.out_dir.join(f)).unwrap() == bytes, "a rerun changed {f}");
    }
    #[cfg(unix)]
    assert_eq!(std::os::unix::fs::MetadataExt::ino(&std::fs::metadata(&photo).unwrap()), inode);
    assert!(!p.out_dir.join("images/train/alpha/cam2/gone.png").exists());
    // export-coco wrote the Hugging Face metadata and the card's front matter naming it; export-hf
    // rewrites both from the COCO files, byte for byte.
    let hf_written: Vec<Vec<u8>> =
        hf_files.iter().chain(&["README.md"]).map(|f| std::fs::read(p.out_dir.join(f)).unwrap()).collect();
    let card = String::from_utf8(hf_written[3].clone()).unwrap();
    assert!(
        card.starts_with("---\n")
            && card.contains(
                "configs:\n- config_name: default\n  data_files:\n  - split: train\n    path: images/train/**\n  \
                 - split: validation\n    path: images/val/**\n  - split: test\n    path: images/test/**\n---\n"
            ),
        "{card}"
    );
    let sums = std::fs::read_to_string(p.out_dir.join("SHA256SUMS")).unwrap();
    assert!(hf_files.iter().all(|f| sums.contains(&format!("  {f}\n"))), "{sums}");
    let wd_arg = wd.to_str().unwrap();
    run_ok(tmp.path(), &["--workdir", wd_arg, "export-yolo"]);
    run_ok(tmp.path(), &["--workdir", wd_arg, "export-panoptic"]);
    let out = run_ok(tmp.path(), &["--workdir", wd_arg, "export-hf"]);
    assert!(out.contains("train: 5 rows"), "{out}");
    for (f, bytes) in hf_files.iter().chain(&["README.md"]).zip(&hf_written) {
        assert!(&std::fs::read(p.out_dir.join(f)).unwrap() == bytes, "export-hf changed {f}");
    }
    for split in ["train", "val", "test"] {
        let text = std::fs::read_to_string(p.out_dir.join(format!("images/{split}/metadata.jsonl"))).unwrap();
        for line in text.lines() {
            assert_schema("hf_metadata.schema.json", &serde_json::from_str::<Value>(line).unwrap());
        }
    }
    let per_split: Vec<usize> = first
        .iter()
        .map(|b| serde_json::from_slice::<Value>(b).unwrap()["images"].as_array().unwrap().len())
        .collect();
    assert!(per_split.iter().all(|&n| n > 0), "the fixture has images in every split: {per_split:?}");
    let coco_images: usize = per_split.iter().sum();

    // Move the folder alone, then delete the work directory it came from.
    let elsewhere = tempfile::tempdir().unwrap();
    let moved = elsewhere.path().join("buildings");
    std::fs::rename(&p.out_dir, &moved).unwrap();
    std::fs::remove_dir_all(&wd).unwrap();
    assert_moved_export_loads(&moved, coco_images);
}

/// A file system other than the one of `dir` for an export to go to: `/dev/shm` (tmpfs on Linux) when
/// it exists and `stat` gives it another device than `dir`'s, else `None` with the reason. Where there
/// is none (macOS, a container whose temporary directory is on that tmpfs) the test cannot fail over
/// to a copy, so this skips even under `CI=true`: the copy itself is unit-tested with a link that
/// fails as EXDEV does (`util::tests::a_refused_link_falls_back_to_a_copy_of_its_own`).
#[cfg(unix)]
fn other_file_system(dir: &Path) -> Option<tempfile::TempDir> {
    use std::os::unix::fs::MetadataExt;
    let shm = Path::new("/dev/shm");
    let why = match (std::fs::metadata(shm), std::fs::metadata(dir)) {
        (Ok(s), Ok(d)) if s.is_dir() && s.dev() != d.dev() => match tempfile::tempdir_in(shm) {
            Ok(t) => return Some(t),
            Err(e) => format!("/dev/shm is not writable: {e}"),
        },
        (Ok(_), Ok(_)) => format!("/dev/shm is on the file system of {}", dir.display()),
        (Err(e), _) => format!("no /dev/shm: {e}"),
        (_, Err(e)) => format!("{}: {e}", dir.display()),
    };
    eprintln!("skipping: {why} (no second file system to export across)");
    None
}

#[test]
#[cfg(unix)]
fn an_export_on_another_file_system_holds_copies() {
    use std::os::unix::fs::MetadataExt;
    let tmp = tempfile::tempdir().unwrap();
    let Some(shm) = other_file_system(tmp.path()) else { return };
    let wd = standard_workdir(tmp.path());
    let here = plan(&wd, "coco");
    export(&here, &NoProgress).unwrap();
    let mut there = plan(&wd, "coco");
    there.out_dir = shm.path().join("coco");
    export(&there, &NoProgress).unwrap();
    // Every photo and ID map is a file of its own there (a hard link cannot cross file systems), with
    // the work directory's bytes; the COCO files and checksums are those of the export beside it.
    let sums = std::fs::read_to_string(there.out_dir.join("SHA256SUMS")).unwrap();
    let mut placed = 0;
    for rel in image_files(&there.out_dir.join("images"))
        .into_iter()
        .chain(image_files(&there.out_dir.join("masks")))
    {
        let name = rel.strip_prefix(&there.out_dir).unwrap();
        let linked_here = here.out_dir.join(name);
        let (a, b) = (std::fs::metadata(&rel).unwrap(), std::fs::metadata(&linked_here).unwrap());
        assert_ne!(a.dev(), b.dev(), "{}", name.display());
        assert_eq!(std::fs::read(&rel).unwrap(), std::fs::read(&linked_here).unwrap(), "{}", name.display());
        assert!(sums.contains(&format!("  {}\n", name.display())), "{} not in SHA256SUMS", name.display());
        placed += 1;
    }
    assert!(placed > 10, "{placed} files placed");
    for f in ["instances_train.json", "instances_val.json", "instances_test.json", "SHA256SUMS"] {
        assert!(
            std::fs::read(here.out_dir.join(f)).unwrap() == std::fs::read(there.out_dir.join(f)).unwrap(),
            "{f}"
        );
    }
    let report = insgen::export::verify::verify(&there.out_dir, &NoProgress);
    assert!(report.problems.is_empty(), "{:#?}", report.problems);
    // A rerun keeps the copies: same inodes, nothing rewritten.
    let photo = there.out_dir.join("images/train/alpha/cam2/alpha_f000.png");
    let inode = std::fs::metadata(&photo).unwrap().ino();
    export(&there, &NoProgress).unwrap();
    assert_eq!(std::fs::metadata(&photo).unwrap().ino(), inode);
}

/// Checks an export folder that was moved away from its work directory (which is gone): `insgen
/// verify` (the library and the binary), the YOLO folder copied alone (`cp -a`) holding every image,
/// then pycocotools, Ultralytics' label rules, panopticapi and Hugging Face `datasets` on the moved
/// folder (each split with images must load). `coco_images`: the images the COCO files list.
pub(crate) fn assert_moved_export_loads(moved: &Path, coco_images: usize) {
    let elsewhere = moved.parent().expect("the moved folder has a parent");
    let report = insgen::export::verify::verify(moved, &NoProgress);
    assert!(report.problems.is_empty(), "{:#?}", report.problems);
    assert_eq!(report.images, coco_images);
    let o = insgen(elsewhere, &["verify", moved.to_str().unwrap()]);
    assert!(o.status.success(), "{}", stderr(&o));
    // coreutils checks every placed file against SHA256SUMS; a photo changed after export fails both it
    // and `insgen verify` (in a copy, whose files are not links to the moved ones).
    let sums = |dir: &Path| {
        Command::new("sha256sum").args(["-c", "--quiet", "SHA256SUMS"]).current_dir(dir).output().unwrap()
    };
    let o = sums(moved);
    assert!(o.status.success(), "sha256sum -c: {}{}", String::from_utf8_lossy(&o.stdout), stderr(&o));
    let listed = std::fs::read_to_string(moved.join("SHA256SUMS")).unwrap().lines().count();
    assert!(listed > 2 * coco_images, "{listed} files listed for {coco_images} images");
    let copy = elsewhere.join("copy");
    assert!(Command::new("cp").arg("-a").arg(moved).arg(&copy).status().unwrap().success());
    let photo = image_files(&copy.join("images"))[0].clone();
    let mut bytes = std::fs::read(&photo).unwrap();
    let last = bytes.len() - 20;
    bytes[last] ^= 0xff; // inside the IEND-preceding data: still a file of the same size
    std::fs::remove_file(&photo).unwrap();
    std::fs::write(&photo, &bytes).unwrap();
    let o = sums(&copy);
    assert!(
        !o.status.success() && String::from_utf8_lossy(&o.stdout).contains("FAILED"),
        "sha256sum -c passed a changed photo"
    );
    let report = insgen::export::verify::verify(&copy, &NoProgress);
    assert!(
        report.problems.iter().any(|p| p.file == photo && p.what.contains("differs from SHA256SUMS")),
        "{:#?}",
        report.problems
    );
    // The YOLO folder copied alone (`cp -a`) holds every image as a file.
    let yolo_copy = elsewhere.join("yolo-copy");
    let ok = Command::new("cp").arg("-a").arg(moved.join("yolo")).arg(&yolo_copy).status().unwrap();
    assert!(ok.success());
    assert_eq!(image_files(&yolo_copy.join("images")).len(), coco_images, "every YOLO image is in the copy");

    let Some(py) = python_with(&["pycocotools", "panopticapi", "yaml", "PIL"]) else { return };
    let v = crate::util::coco_check(&py, &["dataset", moved.to_str().unwrap()]);
    for split in ["train", "val", "test"] {
        let r = &v["files"][split];
        assert_eq!(r["mismatches"], serde_json::json!([]), "{split}");
        assert_eq!(r["checked"], r["annotations"], "{split}");
    }
    assert_yolo_exact(&py, &yolo_copy.join("data.yaml"), moved);
    assert_panoptic_exact(&py, moved);
    // Hugging Face datasets loads the moved folder by its path alone (the card's front matter names
    // the splits), images with their instances: every split that has images (`val` is `validation`).
    let Some(py) = python_with(&["datasets", "pycocotools"]) else { return };
    let mut with_images: Vec<&str> = [("train", "train"), ("val", "validation"), ("test", "test")]
        .into_iter()
        .filter(|(s, _)| {
            let v: Value = read_json(&moved.join(format!("instances_{s}.json")));
            !v["images"].as_array().unwrap().is_empty()
        })
        .map(|(_, hf)| hf)
        .collect();
    with_images.sort();
    let r = exports_check(&py, &["hf", moved.to_str().unwrap()]);
    assert_eq!(r["loaded_splits"], serde_json::json!(with_images));
    for split in &with_images {
        let columns = &r["columns"][split];
        for c in ["image", "image_id", "objects", "area_name", "camera", "frame"] {
            assert!(columns.as_array().unwrap().iter().any(|x| x == c), "{split}: no column {c}: {columns}");
        }
    }
    for split in ["train", "val", "test"] {
        let s = &r["splits"][split];
        eprintln!("datasets {split}: {} rows, {} objects, {} decoded", s["rows"], s["objects"], s["decoded"]);
        assert_eq!(s["problems"], serde_json::json!([]), "{split}");
        assert_eq!((&s["rows"], &s["decoded"]), (&s["coco_images"], &s["coco_images"]), "{split}");
        if s["coco_images"].as_u64().unwrap() > 0 {
            assert!(s["objects"].as_u64().unwrap() > 0, "{split}");
        }
    }
}

// ------------------------------------------------------------------------------------------ 3D Tiles

/// The demo area prepared in a scratch directory, with its tileset exported by the binary.
fn demo_tileset() -> tempfile::TempDir {
    let dir = scratch_with_scenes(&[("demo", repo_scene("demo"))]);
    run_ok(dir.path(), &["prepare", "--area", "demo"]);
    let out = run_ok(dir.path(), &["export-tiles", "--area", "demo"]);
    assert!(out.contains("tileset.json"), "{out}");
    dir
}

#[test]
fn tileset_places_every_vertex_where_cesium_puts_the_area() {
    let dir = demo_tileset();
    let scene = dir.path().join("runs/demo/scene");
    let tiles = scene.join("tileset");
    let ts: Value = read_json(&tiles.join("tileset.json"));
    assert_schema("tileset.schema.json", &ts);
    let m: Manifest = read_json(&scene.join("manifest.json"));
    let t: Vec<f64> =
        ts["root"]["transform"].as_array().unwrap().iter().map(|v| v.as_f64().unwrap()).collect();
    assert_eq!(t, m.ecef_from_enu.to_cols_array(), "root transform = ecef_from_enu, column-major");
    assert_eq!(
        std::fs::read(tiles.join("scene.glb")).unwrap(),
        std::fs::read(scene.join("scene.glb")).unwrap()
    );
    let Some(node) = node_with("3d-tiles-tools") else { return };
    let out = Command::new(node)
        .arg(repo().join("scripts/tiles_check.mjs"))
        .args([&tiles, &scene])
        .output()
        .unwrap();
    assert!(out.status.success(), "tiles_check.mjs: {}", String::from_utf8_lossy(&out.stderr));
    let r: Value = serde_json::from_slice(&out.stdout).unwrap();
    eprintln!("3d-tiles-tools + @cesium/engine: {r}");
    assert_eq!(r["content_types"], serde_json::json!(["CONTENT_TYPE_GLB"]));
    assert_eq!(r["root_transform_matches_manifest"], true);
    assert!(
        r["max_vertex_error_m"].as_f64().unwrap() <= 0.01,
        "vertex error {} m (bound 1 cm)",
        r["max_vertex_error_m"]
    );
    assert!(r["vertices"].as_u64().unwrap() > 1000);
    assert_eq!(
        r["feature_ids"].as_u64(),
        Some(m.buildings),
        "every building has vertices with its feature ID"
    );
    assert_eq!(r["outside_their_building"], serde_json::json!([]));
    for ext in ["EXT_mesh_features", "EXT_structural_metadata"] {
        assert!(r["extensions_used"].as_array().unwrap().iter().any(|e| e == ext), "{ext} kept");
    }
    assert_eq!(r["property_names"], serde_json::json!(["source_id"]));
}

#[test]
fn cesiumjs_in_chromium_picks_the_buildings_where_they_belong() {
    let dir = demo_tileset();
    let scene = dir.path().join("runs/demo/scene");
    let Some(node) = node_with("cesium") else { return };
    let chromium = ["chromium", "chromium-browser"]
        .into_iter()
        .find(|c| Command::new(c).arg("--version").output().map(|o| o.status.success()).unwrap_or(false));
    let Some(chromium) = chromium else {
        skip("no `chromium` on PATH (scripts/setup.sh installs Debian's)");
        return;
    };
    let out = Command::new(node)
        .arg(repo().join("scripts/cesium_check.mjs"))
        .arg(scene.join("tileset"))
        .arg(chromium)
        .output()
        .unwrap();
    let r: Value = serde_json::from_slice(&out.stdout)
        .unwrap_or_else(|_| panic!("cesium_check.mjs: {}", String::from_utf8_lossy(&out.stdout)));
    assert!(out.status.success() && r.get("error").is_none(), "CesiumJS: {r}");
    eprintln!("CesiumJS {}: {} picks", r["cesium"], r["picks"].as_array().unwrap().len());
    let m: Manifest = read_json(&scene.join("manifest.json"));
    let buildings: Vec<BuildingRecord> = read_json(&scene.join("buildings.json"));
    assert_eq!(r["tiles_loaded"], true);
    let t: Vec<f64> =
        r["root_computed_transform"].as_array().unwrap().iter().map(|v| v.as_f64().unwrap()).collect();
    assert_eq!(t, m.ecef_from_enu.to_cols_array(), "CesiumJS's root transform is the manifest's ENU→ECEF");
    // Background row 0 + one row per building in the property table.
    assert_eq!(r["features_in_root_content"].as_u64(), Some(m.buildings + 1));
    let enu_from_ecef = m.ecef_from_enu.inverse();
    let picks = r["picks"].as_array().unwrap();
    assert!(picks.len() >= 10, "CesiumJS picked only {} buildings", picks.len());
    for p in picks {
        let id = p["feature_id"].as_u64().unwrap() as u32;
        let b = buildings
            .iter()
            .find(|b| b.id == id)
            .unwrap_or_else(|| panic!("picked feature {id}: no such building"));
        assert_eq!(p["source_id"], b.source_id.as_str(), "feature {id}'s source_id");
        let e: Vec<f64> = p["ecef_m"].as_array().unwrap().iter().map(|v| v.as_f64().unwrap()).collect();
        let enu = enu_from_ecef.transform_point3(glam::DVec3::new(e[0], e[1], e[2])).to_array();
        for k in 0..3 {
            assert!(
                enu[k] >= b.bbox_min_enu_m[k] - 0.25 && enu[k] <= b.bbox_max_enu_m[k] + 0.25,
                "pick of building {id} at ENU {enu:?} is outside its box {:?}..{:?}",
                b.bbox_min_enu_m,
                b.bbox_max_enu_m
            );
        }
    }
}

// ------------------------------------------------------------------------------------------ CLI

#[test]
fn completions_man_pages_and_json_outputs() {
    let dir = scratch_with_scenes(&[("demo", repo_scene("demo"))]);
    let bash = run_ok(dir.path(), &["completions", "bash"]);
    assert!(bash.contains("export-panoptic") && bash.contains("complete -F"), "bash completion");
    let zsh = run_ok(dir.path(), &["completions", "zsh"]);
    assert!(zsh.starts_with("#compdef insgen"), "{}", &zsh[..40]);
    let page = run_ok(dir.path(), &["man"]);
    assert!(page.contains(".TH insgen 1"), "man page on stdout");
    run_ok(dir.path(), &["man", "--out", "target/man"]);
    for name in ["insgen.1", "insgen-export-yolo.1", "insgen-completions.1"] {
        assert!(dir.path().join("target/man").join(name).is_file(), "{name}");
    }
    run_ok(dir.path(), &["prepare", "--area", "demo"]);
    let v: Value =
        serde_json::from_str(&run_ok(dir.path(), &["inspect", "--area", "demo", "--json"])).unwrap();
    assert_eq!(v["area"], "demo");
    assert_schema("manifest.schema.json", &v);
    let text = run_ok(dir.path(), &["inspect", "--area", "demo"]);
    assert!(text.starts_with("area:       demo (train split)\n"), "{text}");
}
