//! The closed loop on CPU, small (issue 37): insgen renders a dataset of the demo districts (masks and
//! Blender photos), the reference baseline (`scripts/train/baseline.py`, PyTorch) trains on it from
//! scratch for real steps, predicts the held-out district, pycocotools scores the predictions and
//! `insgen eval-loc --predictions` localizes with them.
//!
//! Checks real outcomes: the loss falls, the model finds building pixels on a district it never saw, the
//! results file passes insgen's schema, pycocotools' `loadRes` and eval-loc; the same seed and steps give
//! the same weights and the same predictions byte for byte; bad input is an error naming the file.
//! Skips (fails under CI=true) without bpy or the training venv (`scripts/setup_train.sh`).

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use crate::blender_support::blender_python;
use crate::util::{assert_schema, insgen, repo, repo_scene, scratch_with_scenes, skip, stderr};

/// The training interpreter: `$INSGEN_TRAIN_PYTHON`, else `<repo>/.venv-train/bin/python`, if it imports
/// torch; else `None` with a printed reason (a failure under CI=true).
fn train_python() -> Option<PathBuf> {
    let p = std::env::var_os("INSGEN_TRAIN_PYTHON")
        .map(PathBuf::from)
        .unwrap_or_else(|| repo().join(".venv-train/bin/python"));
    let ok = Command::new(&p)
        .args(["-c", "import torch, torchvision, skimage, pycocotools"])
        .output()
        .map(|o| o.status.success())
        .unwrap_or(false);
    if ok {
        return Some(p);
    }
    skip(&format!("{} cannot import torch (run scripts/setup_train.sh)", p.display()));
    None
}

fn baseline(py: &Path, cwd: &Path, args: &[&str]) -> Output {
    Command::new(py)
        .arg(repo().join("scripts/train/baseline.py"))
        .args(args)
        .current_dir(cwd)
        .output()
        .expect("python runs")
}

fn ok(o: Output, what: &str) -> Output {
    assert!(o.status.success(), "{what} failed:\n{}", stderr(&o));
    o
}

fn json(path: &Path) -> serde_json::Value {
    let bytes = std::fs::read(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    serde_json::from_slice(&bytes).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// demo (train, 8 frames) and demo-test (held out, 4 frames) at 320×180, masks + photos, exported.
fn demo_dataset(dir: &Path, bpy: &Path) {
    std::fs::write(
        dir.join("small.toml"),
        "name = \"small\"\nwidth_px = 320\nheight_px = 180\nsensor_width_mm = 23.76\n\
         sensor_height_mm = 13.365\nhfov_deg = 25.0\nstrategy = \"grid\"\n",
    )
    .unwrap();
    for (area, count) in [("demo", "8"), ("demo-test", "4")] {
        for step in [
            vec!["prepare", "--area", area],
            vec!["sample", "--area", area, "--camera", "small.toml", "--count", count],
            vec!["render-masks", "--area", area, "--camera", "small"],
        ] {
            let o = insgen(dir, &[&["--no-progress"], step.as_slice()].concat());
            ok(o, &step.join(" "));
        }
        let o = Command::new(env!("CARGO_BIN_EXE_insgen"))
            .args(["--no-progress", "render-rgb", "--area", area, "--camera", "small"])
            .current_dir(dir)
            .env("INSGEN_BLENDER_PYTHON", bpy)
            .env("RUST_LOG", "warn")
            .output()
            .expect("insgen runs");
        ok(o, "render-rgb");
    }
    ok(insgen(dir, &["--no-progress", "export-coco"]), "export-coco");
}

/// `baseline.py train` on the demo export, small: a U-Net of width 8 on 128×224 crops, on the CPU.
fn train_args(out: &str, steps: &str, seed: &str, log_every: &str) -> Vec<String> {
    [
        "train",
        "--coco",
        "runs/coco",
        "--out",
        out,
        "--device",
        "cpu",
        "--steps",
        steps,
        "--batch",
        "4",
        "--width",
        "8",
        "--crop",
        "128x224",
        "--seed",
        seed,
        "--log-every",
        log_every,
    ]
    .iter()
    .map(|s| s.to_string())
    .collect()
}

fn train(py: &Path, dir: &Path, out: &str, steps: &str) -> serde_json::Value {
    let args = train_args(out, steps, "3", "5");
    let o = ok(baseline(py, dir, &strs(&args)), "baseline train");
    let log = stderr(&o);
    assert!(log.contains("device: cpu") && log.contains("trained"), "no progress lines:\n{log}");
    json(&dir.join(out).join("model.json"))
}

#[test]
fn baseline_trains_predicts_and_its_masks_are_scored_and_localized() {
    let Some(bpy) = blender_python() else { return };
    let Some(py) = train_python() else { return };
    let scratch =
        scratch_with_scenes(&[("demo", repo_scene("demo")), ("demo-test", repo_scene("demo-test"))]);
    let dir = scratch.path();
    demo_dataset(dir, &bpy);

    // Real training steps: the loss falls; the checkpoint and the log are written.
    let model = train(&py, dir, "model", "150");
    assert_schema("baseline_model.schema.json", &model);
    assert_eq!(model["steps"], 150);
    let (first, last) = (model["first_loss"].as_f64().unwrap(), model["final_loss"].as_f64().unwrap());
    assert!(last < 0.8 * first, "the loss did not fall: {first} → {last}");
    assert!(dir.join("model/checkpoint.pt").is_file());
    let log = std::fs::read_to_string(dir.join("model/train_log.jsonl")).unwrap();
    assert!(log.lines().count() >= 1, "empty train log");

    // Predictions on the held-out district, read by insgen's schema, pycocotools and eval-loc.
    let predict = |out: &str| {
        let args = [
            "predict",
            "--checkpoint",
            "model/checkpoint.pt",
            "--coco",
            "runs/coco/instances_test.json",
            "--area",
            "demo-test",
            "--device",
            "cpu",
            "--out",
            out,
        ];
        ok(baseline(&py, dir, &args), "baseline predict");
        std::fs::read(dir.join(out)).unwrap()
    };
    let results_bytes = predict("results.json");
    let results: serde_json::Value = serde_json::from_slice(&results_bytes).unwrap();
    assert_schema("coco_results.schema.json", &results);
    let test = json(&dir.join("runs/coco/instances_test.json"));
    let sizes: std::collections::BTreeMap<u64, [u64; 2]> = test["images"]
        .as_array()
        .unwrap()
        .iter()
        .map(|im| {
            (im["id"].as_u64().unwrap(), [im["height"].as_u64().unwrap(), im["width"].as_u64().unwrap()])
        })
        .collect();
    let entries = results.as_array().unwrap();
    assert!(!entries.is_empty(), "no instance predicted");
    for e in entries {
        let size = sizes.get(&e["image_id"].as_u64().unwrap()).expect("a test image id");
        assert_eq!(e["segmentation"]["size"], serde_json::json!(size), "mask size differs from the image");
    }
    // Same checkpoint → the same file byte for byte.
    assert_eq!(predict("results_again.json"), results_bytes, "prediction is not deterministic");

    let o = ok(
        baseline(
            &py,
            dir,
            &[
                "score",
                "--coco",
                "runs/coco/instances_test.json",
                "--results",
                "results.json",
                "--out",
                "score.json",
            ],
        ),
        "baseline score",
    );
    drop(o);
    let score = json(&dir.join("score.json"));
    assert_schema("baseline_score.schema.json", &score);
    eprintln!("trained: {model}\nscored: {score}");
    let iou = score["building_iou"].as_f64().unwrap();
    let trivial = score["all_building_iou"].as_f64().unwrap();
    assert!(
        iou > trivial + 0.05,
        "building-pixel IoU {iou} on the held-out district, {trivial} for calling every pixel a building: the \
         model learned no buildings"
    );
    assert!(score["predictions"].as_u64().unwrap() as usize == entries.len());

    let o = insgen(
        dir,
        &[
            "--no-progress",
            "eval-loc",
            "--area",
            "demo-test",
            "--camera",
            "small",
            "--predictions",
            "results.json",
            "--limit",
            "2",
            "--cost",
            "instance",
            "--cost",
            "semantic",
            "--render-width",
            "320",
            "--coarse-width",
            "160",
            "--tag",
            "loop",
        ],
    );
    ok(o, "eval-loc --predictions");
    let summary = json(&dir.join("runs/demo-test/small/loc/loop/summary.json"));
    assert_schema("loc_summary.schema.json", &summary);
    assert_eq!(summary["queries"], 2);
    let methods: Vec<&str> =
        summary["rows"].as_array().unwrap().iter().filter_map(|r| r["method"].as_str()).collect();
    assert!(
        methods.iter().any(|m| m.starts_with("instance"))
            && methods.iter().any(|m| m.starts_with("semantic")),
        "{methods:?}"
    );
    seeded_and_strict(&py, dir);
    packed_for_a_device(&py, dir);
}

/// The GPU half of the loop as a lent device runs it, here on the CPU: `baseline.py pack` makes a
/// self-contained copy of the export (and of a calibration area's, here the held-out split standing in),
/// and `scripts/train/device_run.sh` trains on it and predicts every file the loop's `score` stage
/// reads — the held-out, validation and calibration frames — and hands back no checkpoint.
fn packed_for_a_device(py: &Path, dir: &Path) {
    let pack =
        |args: &[&str]| ok(baseline(py, dir, &[&["pack", "--coco", "runs/coco"], args].concat()), "pack");
    pack(&["--out", "pack"]);
    pack(&["--split", "test", "--out", "pack/calibration"]);
    // The demo export has no validation split; the packed test split stands in for it.
    std::fs::copy(dir.join("pack/instances_test.json"), dir.join("pack/instances_val.json")).unwrap();
    let test = json(&dir.join("pack/instances_test.json"));
    for im in test["images"].as_array().unwrap() {
        let photo = dir.join("pack").join(im["file_name"].as_str().unwrap());
        assert!(photo.is_file(), "{} is not in the pack", photo.display());
        assert!(im.get("mask_file").is_none(), "the pack carries ID maps");
    }
    let o = Command::new("bash")
        .arg(repo().join("scripts/train/device_run.sh"))
        .args(["pack", "device", "demo-test", "0.02", "unet"])
        .current_dir(dir)
        .env("PYTHON", py)
        .env("DEVICE", "cpu")
        .output()
        .expect("bash runs");
    ok(o, "device_run.sh");
    let m = dir.join("device/model/unet");
    assert_schema("baseline_model.schema.json", &json(&m.join("model.json")));
    assert!(!m.join("checkpoint.pt").exists(), "the device run handed back its checkpoint");
    for name in ["results_demo-test.json", "results_val.json", "results_calibration.json"] {
        let results = json(&m.join(name));
        assert_schema("coco_results.schema.json", &results);
        // Scored here, against the loop's own export, as `... score loc report` does: the pack keeps
        // the image ids.
        let o = baseline(
            py,
            dir,
            &[
                "score",
                "--coco",
                "runs/coco/instances_test.json",
                "--results",
                &m.join(name).to_string_lossy(),
            ],
        );
        let score: serde_json::Value = serde_json::from_slice(&ok(o, name).stdout).unwrap();
        assert_eq!(score["images"], test["images"].as_array().unwrap().len(), "{name}: {score}");
    }
}

/// The same seed and steps give the same weights; bad input is an error naming the file, nothing written.
fn seeded_and_strict(py: &Path, dir: &Path) {
    let a = train(py, dir, "a", "4");
    let b = train(py, dir, "b", "4");
    assert_eq!(a["weights_sha256"], b["weights_sha256"], "same seed and steps, other weights");
    assert_ne!(a["weights_sha256"], serde_json::Value::Null);

    interrupted_and_resumed(py, dir);

    let o =
        baseline(py, dir, &["train", "--coco", "no/such/instances_train.json", "--out", "c", "--steps", "1"]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("no/such/instances_train.json"), "{}", stderr(&o));
    assert!(!dir.join("c/model.json").exists(), "a failed run left a model");
    let o = baseline(
        py,
        dir,
        &[
            "predict",
            "--checkpoint",
            "missing.pt",
            "--coco",
            "runs/coco/instances_test.json",
            "--out",
            "r.json",
        ],
    );
    assert!(!o.status.success() && stderr(&o).contains("missing.pt"), "{}", stderr(&o));
    assert!(!dir.join("r.json").exists());
}

/// Ctrl-C ends a run between two steps with a checkpoint; `--resume` then gives the weights of a run
/// that was never stopped.
fn interrupted_and_resumed(py: &Path, dir: &Path) {
    let args = |out: &str| train_args(out, "40", "5", "0");
    ok(baseline(py, dir, &strs(&args("straight"))), "straight run");
    let straight = json(&dir.join("straight/model.json"));
    let mut child = Command::new(py)
        .arg(repo().join("scripts/train/baseline.py"))
        .args(args("stopped"))
        .current_dir(dir)
        .stderr(std::process::Stdio::null())
        .spawn()
        .expect("python runs");
    // Stop it once it has logged a few steps.
    let log = dir.join("stopped/train_log.jsonl");
    let started = std::time::Instant::now();
    while std::fs::read_to_string(&log).map(|t| t.lines().count()).unwrap_or(0) < 3 {
        assert!(started.elapsed().as_secs() < 120, "no training step within 2 minutes");
        std::thread::sleep(std::time::Duration::from_millis(50));
    }
    let kill = Command::new("kill").args(["-INT", &child.id().to_string()]).status().expect("kill runs");
    assert!(kill.success());
    let status = child.wait().unwrap();
    assert_eq!(status.code(), Some(130), "a stopped run exits 130");
    assert!(!dir.join("stopped/model.json").exists(), "a stopped run wrote its final model.json");
    let mut resume = args("stopped");
    resume.push("--resume".into());
    let o = ok(baseline(py, dir, &strs(&resume)), "resumed run");
    assert!(stderr(&o).contains("resumed from"), "{}", stderr(&o));
    let resumed = json(&dir.join("stopped/model.json"));
    assert_eq!(resumed["steps"], 40);
    assert_eq!(
        resumed["weights_sha256"], straight["weights_sha256"],
        "stopped + resumed differs from straight"
    );
}

fn strs(v: &[String]) -> Vec<&str> {
    v.iter().map(String::as_str).collect()
}

/// Runs the self-check `scripts/train/<name>` with seed 7 and returns the JSON object it prints.
fn check_script(py: &Path, name: &str) -> serde_json::Value {
    let o = ok(
        Command::new(py).arg(repo().join("scripts/train").join(name)).arg("7").output().expect("python runs"),
        name,
    );
    serde_json::from_slice(&o.stdout).unwrap_or_else(|e| panic!("{name} does not print JSON: {e}"))
}

#[test]
fn score_says_whether_scores_rank_the_masks() {
    // `score_honesty` decides whether eval-loc --weighting conf may trust the scores: scores that fall
    // with a mask's shift from its building are honest, the same scores shuffled or all alike are not.
    let Some(py) = train_python() else { return };
    let reports = check_script(&py, "honesty_check.py");
    for report in reports.as_object().expect("one report per file").values() {
        assert_schema("baseline_score.schema.json", report);
        let bands = report["score_honesty"]["bands"].as_array().unwrap();
        let counted: u64 = bands.iter().map(|b| b["predictions"].as_u64().unwrap()).sum();
        assert_eq!(
            counted,
            report["predictions"].as_u64().unwrap(),
            "every prediction in one band: {report}"
        );
    }
    let honesty = |name: &str| reports[name]["score_honesty"].clone();
    let honest = honesty("honest");
    assert_eq!(honest["honest"], true, "{honest}");
    assert!(honest["spearman"].as_f64().unwrap() > 0.8, "{honest}");
    let means: Vec<f64> =
        honest["bands"].as_array().unwrap().iter().filter_map(|b| b["mean_iou"].as_f64()).collect();
    assert!(means.windows(2).all(|w| w[0] <= w[1]) && means.len() == 4, "{honest}");
    let shuffled = honesty("shuffled");
    assert_eq!(shuffled["honest"], false, "{shuffled}");
    assert!(shuffled["spearman"].as_f64().unwrap().abs() < 0.25, "{shuffled}");
    let constant = honesty("constant");
    assert_eq!(
        (constant["honest"].clone(), constant["spearman"].clone()),
        (false.into(), serde_json::Value::Null)
    );
}

#[test]
fn the_sheet_marks_missed_and_extra_building_pixels() {
    // `baseline.py sheet`'s last panel: a 10 × 10 true building whose prediction misses its bottom
    // two rows (a facade) and spills one column to the right.
    let Some(py) = train_python() else { return };
    let code = r#"
import json, sys
import numpy as np
sys.path.insert(0, sys.argv[1])
import scoring
truth, pred = np.zeros((20, 20), bool), np.zeros((20, 20), bool)
truth[5:15, 5:15] = True
pred[5:13, 5:16] = True
rgb = np.full((20, 20, 3), 100, np.uint8)
pic, missed, extra = scoring.building_errors([truth], [pred], rgb)
print(json.dumps({"missed": missed, "extra": extra, "both": pic[6, 6].tolist(),
                  "miss": pic[14, 6].tolist(), "spill": pic[6, 15].tolist(), "ground": pic[0, 0].tolist(),
                  "none": scoring.building_errors([], [], rgb)[1:]}))
# A crowd region over half the missed facade and the spilled column: counted neither way.
crowd = np.zeros((20, 20), bool)
crowd[13:15, 5:10] = True
crowd[:, 15] = True
pic, missed, extra = scoring.building_errors([truth], [pred], rgb, crowd)
print(json.dumps({"missed": missed, "extra": extra, "crowd": pic[14, 6].tolist(), "miss": pic[14, 12].tolist()}))
"#;
    let o = ok(
        Command::new(&py).args(["-c", code]).arg(repo().join("scripts/train")).output().expect("python runs"),
        "building_errors",
    );
    let out = String::from_utf8(o.stdout).unwrap();
    let (v, c) = out.trim().split_once('\n').expect("two lines");
    let v: serde_json::Value = serde_json::from_str(v).unwrap();
    assert_eq!(v["missed"].as_f64().unwrap(), 0.2, "{v}");
    assert_eq!(v["extra"].as_f64().unwrap(), 0.08, "{v}");
    assert_eq!(v["both"], serde_json::json!([200, 200, 200]));
    assert_eq!(v["miss"], serde_json::json!([255, 60, 60]));
    assert_eq!(v["spill"], serde_json::json!([60, 120, 255]));
    assert_eq!(v["ground"], serde_json::json!([50, 50, 50]), "the photo darkened elsewhere");
    assert_eq!(v["none"], serde_json::json!([0.0, 0.0]), "no building: nothing missed");
    let c: serde_json::Value = serde_json::from_str(c).unwrap();
    assert_eq!(c["missed"].as_f64().unwrap(), 10.0 / 90.0, "10 of the 90 counted true pixels: {c}");
    assert_eq!(c["extra"].as_f64().unwrap(), 0.0, "the spill lies in the crowd region: {c}");
    assert_eq!(c["crowd"], serde_json::json!([20, 20, 20]), "crowd drawn darker");
    assert_eq!(c["miss"], serde_json::json!([255, 60, 60]));
}

#[test]
fn numpy_rle_equals_pycocotools() {
    // Training and prediction encode masks without pycocotools (a GPU machine may lack it): the
    // strings, the decoded masks and the boxes must be pycocotools' own.
    let Some(py) = train_python() else { return };
    let report = check_script(&py, "rle_check.py");
    assert_eq!(report["masks"], 400);
    assert_eq!(report["mismatches"], serde_json::json!([]), "{report}");
}

#[test]
fn score_measures_the_zoom_of_predicted_masks() {
    // `mask_zoom` is what eval-loc --prediction-zoom undoes: on rectangles scaled by a known factor
    // about an off-centre principal point it must find that factor (the rasterisation moves each edge
    // by at most half a pixel, 2·10⁻⁴ of the frame's scale at 240 px from the centre), and exactly 1
    // for masks equal to the truth.
    let Some(py) = train_python() else { return };
    let reports = check_script(&py, "zoom_check.py");
    for (zoom, report) in reports.as_object().expect("one report per zoom") {
        assert_schema("baseline_score.schema.json", report);
        let zoom: f64 = zoom.parse().unwrap();
        let measured = &report["mask_zoom"];
        assert_eq!(measured["images"], 4, "{report}");
        let median = measured["median"].as_f64().unwrap();
        if zoom == 1.0 {
            assert_eq!(median, 1.0, "{report}");
        } else {
            assert!((median - zoom).abs() <= 6e-4, "zoom {zoom} measured as {median}: {report}");
        }
        // The outlines: identical masks agree at 1 px; a zoom of 0.3 % moves no edge by more than a
        // pixel; 1 % moves the far edges (up to 280 px from the centre) by 2–3 px.
        let f = |d: &str| report["outline_f1"][d].as_f64().unwrap();
        match zoom {
            1.0 => assert_eq!((f("1px"), f("2px")), (1.0, 1.0), "{report}"),
            z if (z - 1.0).abs() < 0.005 => assert!(f("1px") >= 0.99, "{report}"),
            _ => assert!(f("1px") < 0.95 && f("1px") < f("2px") && f("2px") < 1.0, "{report}"),
        }
    }
    assert_eq!(reports.as_object().unwrap().len(), 4);
}
