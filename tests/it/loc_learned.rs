//! Issue 40, costs that survive learned masks:
//! - the segmenter-like degradation (`eval-loc --segmenter-like`) of real Shibuya masks lands near the
//!   figures of a learned segmenter on an unseen city (0.97 instances per true one, precision/recall
//!   0.50/0.49 at IoU 0.5, building IoU 0.95), within a band: the model is calibrated, not fitted to
//!   these frames (../shared/data; skipped with a printed reason when absent, a failure under CI=true);
//! - eval-loc with those degraded masks localizes the held-out demo district with the default cost and
//!   the grouped cost, and no estimate strays far.

use crate::util;

use std::path::Path;

use insgen::label::{label_components, Connectivity};
use insgen::loc::oracle::{agreement, degrade, Agreement, Degradation, SegmenterLike};
use insgen::scene::IdMap;
use serde_json::Value;
use util::{insgen, repo_scene, scratch_with_scenes, stderr};

fn ok(cwd: &Path, args: &[&str]) {
    let out = insgen(cwd, args);
    assert!(out.status.success(), "insgen {}: {}", args.join(" "), stderr(&out));
}

#[test]
fn segmenter_like_masks_of_shibuya_land_near_a_learned_segmenter() {
    if util::shared_data("jp_tokyo_shibuya_plateau_3dtiles/tileset.json").is_none() {
        return;
    }
    let dir = scratch_with_scenes(&[("tokyo", repo_scene("tokyo"))]);
    let cwd = dir.path();
    ok(cwd, &["prepare", "--area", "tokyo"]);
    ok(cwd, &["sample", "--area", "tokyo", "--camera", "cam2", "--count", "8"]);
    ok(cwd, &["render-masks", "--area", "tokyo", "--camera", "cam2", "--preview", "0"]);
    let masks = cwd.join("runs/tokyo/cam2/masks");
    let d = Degradation { segmenter: Some(SegmenterLike::learned()), ..Default::default() };
    let mut sum = Agreement::default();
    let mut frames = 0;
    let mut paths: Vec<_> = std::fs::read_dir(&masks)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| {
            p.extension().is_some_and(|e| e == "png") && !p.to_string_lossy().ends_with(".ignore.png")
        })
        .collect();
    paths.sort();
    for (i, path) in paths.iter().enumerate() {
        let map = IdMap::read_png(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        let lab = label_components(&map, Connectivity::Eight);
        let n = lab.components.len() as u32;
        let q = degrade(map.width(), map.height(), &lab.labels, n, &d, i as u64);
        sum += agreement(&lab.labels, n, &q);
        frames += 1;
    }
    assert_eq!(frames, 8);
    let (count, p, r, iou) = (sum.count_ratio(), sum.precision(), sum.recall(), sum.building_iou());
    let got = format!("{count:.3} instances per true one, P/R {p:.3}/{r:.3}, building IoU {iou:.3}: {sum:?}");
    assert!(sum.truths >= 100, "{got}");
    // Targets 0.97, 0.50/0.49, 0.95; bands wide enough for eight frames' sampling noise.
    assert!((0.85..=1.15).contains(&count), "{got}");
    assert!((0.40..=0.60).contains(&p), "{got}");
    assert!((0.40..=0.60).contains(&r), "{got}");
    assert!((0.93..=0.98).contains(&iou), "{got}");
    // The outlines, in pixels of these 1920-wide masks: each rim is moved by 3 px (1 px at 640) in or
    // out, or kept, with equal probability, so about a third of the outline stays within 1 or 2 px.
    let (f1, f2) = (sum.outline_f1(1), sum.outline_f1(2));
    assert!(0.2 < f1 && f1 <= f2 && f2 < 0.4, "outline F1 {f1:.3} / {f2:.3}: {got}");
}

#[test]
fn eval_loc_localizes_the_demo_with_segmenter_like_masks() {
    let dir = scratch_with_scenes(&[("demo-test", repo_scene("demo-test"))]);
    let cwd = dir.path();
    ok(cwd, &["prepare", "--area", "demo-test"]);
    ok(cwd, &["sample", "--area", "demo-test", "--camera", "cam2", "--count", "3"]);
    ok(cwd, &["render-masks", "--area", "demo-test", "--camera", "cam2"]);
    let eval_loc = |extra: &[&str]| {
        let base = [
            "--no-progress",
            "eval-loc",
            "--area",
            "demo-test",
            "--camera",
            "cam2",
            "--oracle",
            "--overlays",
            "0",
        ];
        ok(cwd, &[&base[..], extra].concat())
    };
    eval_loc(&["--segmenter-like", "--cost", "instance", "--cost", "grouped", "--tag", "segmenter"]);
    let out = cwd.join("runs/demo-test/cam2/loc/segmenter");
    let rows: Vec<Value> = std::fs::read_to_string(out.join("results.jsonl"))
        .unwrap()
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    assert_eq!(rows.len(), 6, "3 queries × 2 costs");
    for r in &rows {
        util::assert_schema("loc_result.schema.json", r);
        let (t, rot) =
            (r["translation_error_m"].as_f64().unwrap(), r["rotation_error_deg"].as_f64().unwrap());
        assert!(t < 2.0 && rot < 2.0, "{} ({}): {t} m / {rot}°", r["name"], r["cost"]);
    }
    assert!(rows.iter().any(|r| r["cost"] == "grouped"));
    let summary: Value = serde_json::from_slice(&std::fs::read(out.join("summary.json")).unwrap()).unwrap();
    util::assert_schema("loc_summary.schema.json", &summary);

    // A shard of a run with every segmenter key set writes a part marker its schema accepts (the
    // degradation's parameters included), and records them.
    eval_loc(&[
        "--segmenter-like",
        "learned,holes=0.1,zoom=1.001,zoom-sd=0.001",
        "--shard",
        "1/2",
        "--tag",
        "sharded",
    ]);
    let marker = cwd.join("runs/demo-test/cam2/loc/sharded/parts/1-of-2/part.json");
    let part: Value = serde_json::from_slice(&std::fs::read(&marker).unwrap()).unwrap();
    util::assert_schema("part.schema.json", &part);
    let text = part.to_string();
    for field in ["\"hole_share\":0.1", "\"zoom\":1.001", "\"zoom_sd\":0.001"] {
        assert!(text.contains(field), "{field} in {text}");
    }
}
