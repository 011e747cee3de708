//! `insgen eval-loc` end to end on the held-out demo district: prepare → sample (cam2, grid) →
//! render-masks → eval-loc from the default priors must localize every query to (2 m, 2°) with the
//! oracle masks; the same queries given as a COCO results file (predictions) or as LoD-Loc/COLMAP
//! lists must give the same estimates; outputs validate against their schemas; a results file for
//! another dataset fails with a clear error.

use crate::util;

use std::path::Path;

use serde_json::Value;
use util::{assert_schema, insgen, repo_scene, scratch_with_scenes, stderr};

const QUERIES: &str = "3";

fn ok(cwd: &Path, args: &[&str]) {
    let out = insgen(cwd, args);
    assert!(out.status.success(), "insgen {}: {}", args.join(" "), stderr(&out));
}

/// `eval-loc --area demo-test --camera cam2` followed by `extra`.
fn eval_loc<'a>(extra: &[&'a str]) -> Vec<&'a str> {
    [&["eval-loc", "--area", "demo-test", "--camera", "cam2"][..], extra].concat()
}

fn results(path: &Path) -> Vec<Value> {
    std::fs::read_to_string(path)
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
        .lines()
        .map(|l| serde_json::from_str(l).expect("JSON line"))
        .collect()
}

fn estimates(rows: &[Value]) -> Vec<(String, Vec<f64>)> {
    rows.iter()
        .map(|r| {
            let est = r["estimate"].as_array().unwrap().iter().map(|v| v.as_f64().unwrap()).collect();
            (r["name"].as_str().unwrap().to_string(), est)
        })
        .collect()
}

#[test]
fn eval_loc_localizes_the_held_out_district_from_every_input_kind() {
    let copy = repo_scene("demo-test").replace("name = \"demo-test\"", "name = \"demo-test-copy\"");
    let moved = repo_scene("demo-test")
        .replace("name = \"demo-test\"", "name = \"demo-test-moved\"")
        .replace("easting_m = -3400.0", "easting_m = -3000.0");
    let dir = scratch_with_scenes(&[
        ("demo-test", repo_scene("demo-test")),
        ("demo-test-copy", copy),
        ("demo-test-moved", moved),
    ]);
    let cwd = dir.path();
    ok(cwd, &["prepare", "--area", "demo-test"]);
    ok(cwd, &["sample", "--area", "demo-test", "--camera", "cam2", "--count", QUERIES]);
    ok(cwd, &["render-masks", "--area", "demo-test", "--camera", "cam2"]);
    let cam = cwd.join("runs/demo-test/cam2");

    // 1. Oracle masks from poses.jsonl / priors.jsonl.
    ok(
        cwd,
        &[
            "--no-progress",
            "eval-loc",
            "--area",
            "demo-test",
            "--camera",
            "cam2",
            "--oracle",
            "--overlays",
            "1",
        ],
    );
    let out = cam.join("loc/oracle");
    let oracle = results(&out.join("results.jsonl"));
    assert_eq!(oracle.len(), 3);
    for r in &oracle {
        assert_schema("loc_result.schema.json", r);
        let (t, rot) =
            (r["translation_error_m"].as_f64().unwrap(), r["rotation_error_deg"].as_f64().unwrap());
        let (pt, prot) = (
            r["prior_translation_error_m"].as_f64().unwrap(),
            r["prior_rotation_error_deg"].as_f64().unwrap(),
        );
        assert!(t < 2.0 && rot < 2.0, "{}: {t} m / {rot}° from a prior {pt} m / {prot}° off", r["name"]);
        assert!(t < pt, "{}: the estimate must beat the prior", r["name"]);
        // The sampler keeps views whose rays hit buildings for 15 % of the frame: some cell holds them.
        let cells = r["covered_frame_cells"].as_u64().unwrap();
        assert!((1..=16).contains(&cells), "{}: {cells} cells", r["name"]);
        // The search never scores below what it started from: its best is at least the cost at the
        // ground truth minus the sampling gap.
        assert!(r["best_cost"].as_f64().unwrap() > 0.9, "{r}");
        // The stages account for every hypothesis scored, and the coarse grid and both widths ran.
        let stages = r["stages"].as_object().unwrap();
        let per_stage: Vec<u64> = stages.values().map(|s| s["hypotheses"].as_u64().unwrap()).collect();
        assert_eq!(per_stage.iter().sum::<u64>(), r["hypotheses"].as_u64().unwrap(), "{r}");
        for s in ["coarse", "filter_coarse_width", "filter_render_width", "polish"] {
            assert!(stages[s]["hypotheses"].as_u64().unwrap() > 0, "{s}: {r}");
        }
    }
    let summary: Value = serde_json::from_slice(&std::fs::read(out.join("summary.json")).unwrap()).unwrap();
    assert_schema("loc_summary.schema.json", &summary);
    let rows = summary["rows"].as_array().unwrap();
    assert_eq!(rows[0]["method"], "prior");
    // Every query in exactly one instance-count bucket.
    let buckets = summary["instance_buckets"].as_array().unwrap();
    assert_eq!(buckets.iter().map(|b| b["queries"].as_u64().unwrap()).sum::<u64>(), 3, "{buckets:?}");
    // And in exactly one bucket of the frame's cells holding buildings, the one of its count.
    let coverage = summary["coverage_buckets"].as_array().unwrap();
    assert_eq!(coverage.iter().map(|b| b["queries"].as_u64().unwrap()).sum::<u64>(), 3, "{coverage:?}");
    let cells = oracle[0]["covered_frame_cells"].as_u64().unwrap();
    let bucket = coverage.iter().find(|b| {
        b["method"] == rows[1]["method"] && {
            let range: Vec<u64> =
                b["bucket"].as_str().unwrap().split('–').map(|v| v.parse().unwrap()).collect();
            range[0] <= cells && cells <= range[range.len() - 1]
        }
    });
    assert!(bucket.is_some_and(|b| b["queries"].as_u64().unwrap() >= 1), "{cells} cells: {coverage:?}");
    assert_eq!(summary["map"]["area"], "demo-test");
    assert!(summary["map"]["perturbation"].is_null());
    assert_eq!(summary["search"]["fine"]["beams_mode"]["kind"], "basins");
    assert_eq!(summary["search"]["fine"]["beams_mode"]["prior_basin"], true);
    // Issue 40: the search volume around the prior is recorded; no estimate ends on its boundary.
    // By default it comes from the prior noise model sampling.json records: a radius of 4.4σ of the
    // noisier horizontal axis plus the bias (at least 10 m), 4σ in height and yaw.
    let sampling: Value = serde_json::from_slice(&std::fs::read(cam.join("sampling.json")).unwrap()).unwrap();
    let noise = &sampling["config"]["prior"];
    let n = |key: &str, i: usize| noise[key][i].as_f64().unwrap();
    let radius_m = (n("bias_enu_m", 0).hypot(n("bias_enu_m", 1))
        + 4.4 * n("sigma_enu_m", 0).max(n("sigma_enu_m", 1)))
    .max(10.0);
    let bounds = &summary["search"]["bounds"];
    assert!((bounds["radius_m"].as_f64().unwrap() - radius_m).abs() < 1e-9, "{radius_m}: {bounds}");
    let height_m = (n("bias_enu_m", 2).abs() + 4.0 * n("sigma_enu_m", 2)).max(5.0);
    assert!((bounds["height_m"].as_f64().unwrap() - height_m).abs() < 1e-9, "{height_m}: {bounds}");
    // The coarse grid comes from the same model: the bias plus 2.5σ east/north and in yaw, 2σ in
    // height, in whole steps of 5 m and 2.5° (at least one, no further than the volume).
    let whole = |cover: f64, bound: f64, step: f64| {
        ((cover / step - 1e-9).ceil().max(1.0)).min((bound / step - 1e-9).ceil().max(1.0)) * step
    };
    let coarse = &summary["search"]["coarse"];
    let xy_m = whole(
        n("bias_enu_m", 0).hypot(n("bias_enu_m", 1)) + 2.5 * n("sigma_enu_m", 0).max(n("sigma_enu_m", 1)),
        radius_m,
        5.0,
    );
    let z_m = whole(n("bias_enu_m", 2).abs() + 2.0 * n("sigma_enu_m", 2), height_m, 5.0);
    let yaw_deg = whole(
        n("bias_ypr_deg", 0).abs() + 2.5 * n("sigma_ypr_deg", 0),
        bounds["yaw_deg"].as_f64().unwrap(),
        2.5,
    );
    let got = ["xy_range_m", "z_range_m", "yaw_range_deg"].map(|k| coarse[k].as_f64().unwrap());
    assert_eq!(got, [xy_m, z_m, yaw_deg], "{coarse}");
    assert!(oracle.iter().all(|r| r["on_search_boundary"] == false), "{oracle:?}");
    assert_eq!(summary["boundary_rows"][0]["on_search_boundary"], 0, "{}", summary["boundary_rows"]);
    assert_eq!(rows[1]["recall_pct"][0].as_f64().unwrap(), 100.0, "{}", rows[1]);
    let md = std::fs::read_to_string(out.join("summary.md")).unwrap();
    assert!(md.contains("| prior |") && md.contains("| frame cells with buildings |"), "{md}");
    assert!(md.contains(&format!("the coarse grid ±{xy_m} m east and north")), "{md}");
    assert!(!md.lines().any(|l| l.starts_with("    ")), "no line of prose indented into a code block:\n{md}");
    // est_poses: NAME qw qx qy qz tx ty tz, unit quaternions.
    let est = std::fs::read_to_string(out.join("est_poses_instance.txt")).unwrap();
    assert_eq!(est.lines().count(), 3);
    for line in est.lines() {
        let f: Vec<f64> = line.split_whitespace().skip(1).map(|v| v.parse().unwrap()).collect();
        assert_eq!(f.len(), 7, "{line}");
        assert!((f[..4].iter().map(|q| q * q).sum::<f64>() - 1.0).abs() < 1e-9, "{line}");
    }
    assert!(out.join("overlays").read_dir().unwrap().count() == 1, "one overlay PNG");
    // Issue 39: oracle masks make the figures an upper bound, and summary.md says so.
    assert_eq!(summary["source"]["kind"], "oracle", "{}", summary["source"]);
    assert!(md.contains("**Upper bound.** The query masks are oracle masks"), "{md}");
    // The overlay: three panels at the render width (640 px by default) under a title band, captioned
    // below; the title of a success (every query here is within 2 m, 2°) is drawn in green.
    let overlay = std::fs::read_dir(out.join("overlays")).unwrap().next().unwrap().unwrap().path();
    let img = insgen::export::raster::read_png_rgb(&overlay).unwrap();
    let panel_h = (640.0 * 9.0f64 / 16.0).round() as u32; // cam2's 16:9 frames
    assert_eq!((img.width, img.height), (3 * 640 + 2 * 8, 60 + panel_h + 30));
    let green = (0..60)
        .flat_map(|y| (0..img.width).map(move |x| (x, y)))
        .filter(|&(x, y)| img.get(x, y) == [20, 130, 50]);
    assert!(green.count() > 100, "the title of a success is green");
    let caption_ink = (60 + panel_h..img.height)
        .flat_map(|y| (0..img.width).map(move |x| (x, y)))
        .filter(|&(x, y)| img.get(x, y)[0] < 100)
        .count();
    assert!(caption_ink > 300, "the panels are captioned");
    if let Some(keep) = std::env::var_os("INSGEN_FIGURES_PREVIEW") {
        std::fs::create_dir_all(&keep).unwrap();
        std::fs::copy(&overlay, std::path::Path::new(&keep).join("eval_loc_overlay.png")).unwrap();
    }

    // Issue 40: a search that ends on the boundary of its volume reports the prior. A 1 m radius
    // leaves every truth (the priors are metres off) outside: the cost improves up to the boundary.
    let tight = ["--oracle", "--cost", "instance", "--overlays", "0", "--search-radius-m", "1"];
    let (prior_out, keep_out) = (cam.join("loc/tight_prior"), cam.join("loc/tight_keep"));
    let prior_dir = prior_out.to_str().unwrap();
    ok(cwd, &[&["--no-progress"][..], &eval_loc(&tight), &["--out", prior_dir]].concat());
    let keep_dir = keep_out.to_str().unwrap();
    ok(
        cwd,
        &[&["--no-progress"][..], &eval_loc(&tight), &["--out", keep_dir, "--keep-boundary-estimates"]]
            .concat(),
    );
    let (reported, kept) =
        (results(&prior_out.join("results.jsonl")), results(&keep_out.join("results.jsonl")));
    let on_boundary: Vec<&Value> = reported.iter().filter(|r| r["on_search_boundary"] == true).collect();
    assert!(!on_boundary.is_empty(), "a 1 m volume: some search ends on its boundary: {reported:?}");
    for r in &reported {
        assert_schema("loc_result.schema.json", r);
        assert_eq!(r["kept_prior"], r["on_search_boundary"], "{r}");
    }
    for r in on_boundary {
        let (t, pt) =
            (r["translation_error_m"].as_f64().unwrap(), r["prior_translation_error_m"].as_f64().unwrap());
        assert!((t - pt).abs() < 1e-6, "the prior is reported: {t} m vs the prior's {pt} m: {r}");
        let k = kept.iter().find(|k| k["name"] == r["name"]).unwrap();
        assert!(k["on_search_boundary"] == true && k["kept_prior"] == false, "{k}");
        assert_ne!(k["estimate"], r["estimate"], "--keep-boundary-estimates reports the pose found");
    }
    let tight_summary: Value =
        serde_json::from_slice(&std::fs::read(prior_out.join("summary.json")).unwrap()).unwrap();
    assert_schema("loc_summary.schema.json", &tight_summary);
    assert_eq!(tight_summary["search"]["on_boundary"], "prior");
    let row = &tight_summary["boundary_rows"][0];
    assert_eq!(row["kept_prior"], row["on_search_boundary"], "{row}");
    // The truths lie outside the 1 m volume, where the oracle masks score best: every failure is one
    // the search missed (its estimate scores below the truth), none is the cost's.
    let keep_summary: Value =
        serde_json::from_slice(&std::fs::read(keep_out.join("summary.json")).unwrap()).unwrap();
    assert_schema("loc_summary.schema.json", &keep_summary);
    let axis = &keep_summary["axis_rows"][0];
    let failures = axis["failures"].as_u64().unwrap();
    assert!(failures > 0, "{axis}");
    assert_eq!(axis["failures_search_missed"].as_u64(), Some(failures), "{axis}");
    let missed_in_results = kept
        .iter()
        .filter(|r| {
            r["translation_error_m"].as_f64().unwrap() >= 2.0
                || r["rotation_error_deg"].as_f64().unwrap() >= 2.0
        })
        .filter(|r| r["cost_at_gt"].as_f64().unwrap() > r["best_cost"].as_f64().unwrap())
        .count() as u64;
    assert_eq!(missed_in_results, failures, "the summary counts what results.jsonl shows");
    let ahead_in_results = kept.iter().filter(|r| r["axial_error_m"].as_f64().unwrap() > 0.0).count() as u64;
    assert_eq!(axis["estimates_ahead"].as_u64(), Some(ahead_in_results), "{axis}");
    let md = std::fs::read_to_string(keep_out.join("summary.md")).unwrap();
    assert!(md.contains("of which the search missed") && md.contains("median axial, signed"), "{md}");

    // 2. The ground truth as a segmentation model's COCO results (score 1, compressed RLE); no RGB
    //    frames were rendered, so the export is label-only.
    ok(cwd, &["export-coco", "--label-only"]);
    let coco: Value =
        serde_json::from_slice(&std::fs::read(cwd.join("runs/coco/instances_test.json")).unwrap()).unwrap();
    let preds: Vec<Value> = coco["annotations"]
        .as_array()
        .unwrap()
        .iter()
        .map(|a| {
            serde_json::json!({
                "image_id": a["image_id"], "category_id": a["category_id"],
                "segmentation": a["segmentation"], "bbox": a["bbox"], "score": 1.0
            })
        })
        .collect();
    let preds_path = cwd.join("preds.json");
    std::fs::write(&preds_path, serde_json::to_vec(&preds).unwrap()).unwrap();
    ok(cwd, &eval_loc(&["--predictions", "preds.json", "--overlays", "0"]));
    let predicted = results(&cam.join("loc/predictions/results.jsonl"));
    let md = std::fs::read_to_string(cam.join("loc/predictions/summary.md")).unwrap();
    assert!(
        md.contains("The query masks are a segmentation model's predictions") && !md.contains("Upper bound"),
        "{md}"
    );
    for (p, o) in predicted.iter().zip(&oracle) {
        assert_eq!(p["name"], o["name"]);
        assert!(p["translation_error_m"].as_f64().unwrap() < 2.0, "{p}");
        // The same masks (COCO drops components below 16 px, the oracle keeps them): close results.
        assert!(
            (p["translation_error_m"].as_f64().unwrap() - o["translation_error_m"].as_f64().unwrap()).abs()
                < 1.0
        );
    }

    // 2b. --prediction-zoom undoes a segmenter's measured zoom: given the true masks, scaling them by
    //     1/1.02 about the principal point makes every building look farther away, so every estimate
    //     lands behind the truth along the camera's axis; the run records the zoom.
    ok(cwd, &eval_loc(&["--predictions", "preds.json", "--prediction-zoom", "1.02", "--overlays", "0"]));
    let zoomed_dir = cam.join("loc/predictions-zoom1.02");
    let zoomed = results(&zoomed_dir.join("results.jsonl"));
    assert_eq!(zoomed.len(), predicted.len());
    for r in &zoomed {
        assert!(r["axial_error_m"].as_f64().unwrap() < -0.5, "shrunk masks, yet not behind: {r}");
    }
    let summary: Value =
        serde_json::from_slice(&std::fs::read(zoomed_dir.join("summary.json")).unwrap()).unwrap();
    assert_schema("loc_summary.schema.json", &summary);
    assert_eq!(summary["source"]["zoom"], 1.02, "{}", summary["source"]);
    let md = std::fs::read_to_string(zoomed_dir.join("summary.md")).unwrap();
    assert!(md.contains("scaled by 1/1.02 about the principal point"), "{md}");
    let out =
        insgen(cwd, &eval_loc(&["--predictions", "preds.json", "--prediction-zoom", "1.5", "--tag", "z"]));
    assert!(!out.status.success() && stderr(&out).contains("--prediction-zoom 1.5"), "{}", stderr(&out));
    assert!(!cam.join("loc/z").exists(), "nothing written on error");

    // 3. The LoD-Loc lists (intrinsics, ground truth, priors) instead of poses.jsonl: same estimates.
    let lists = |file: &str| -> (String, String) {
        let (mut k, mut p) = (String::new(), String::new());
        for line in std::fs::read_to_string(cam.join(file)).unwrap().lines() {
            let r: Value = serde_json::from_str(line).unwrap();
            let i = &r["intrinsics"];
            k.push_str(&format!(
                "{} PINHOLE {} {} {} {} {} {}\n",
                r["name"].as_str().unwrap(),
                i["width_px"],
                i["height_px"],
                i["fx_px"],
                i["fy_px"],
                i["cx_px"],
                i["cy_px"]
            ));
            let q = r["colmap_qvec"].as_array().unwrap();
            let t = r["colmap_tvec"].as_array().unwrap();
            p.push_str(&format!(
                "{} {} {} {} {} {} {} {}\n",
                r["name"].as_str().unwrap(),
                q[0],
                q[1],
                q[2],
                q[3],
                t[0],
                t[1],
                t[2]
            ));
        }
        (k, p)
    };
    let (intrinsics, gt) = lists("poses.jsonl");
    let (_, prior) = lists("priors.jsonl");
    std::fs::write(cwd.join("queries.txt"), intrinsics).unwrap();
    std::fs::write(cwd.join("gt.txt"), gt).unwrap();
    std::fs::write(cwd.join("prior.txt"), prior).unwrap();
    ok(
        cwd,
        &eval_loc(&[
            "--oracle",
            "--query-list",
            "queries.txt",
            "--gt-poses",
            "gt.txt",
            "--prior-poses",
            "prior.txt",
            "--out",
            "colmap-loc",
            "--overlays",
            "0",
        ]),
    );
    let colmap = results(&cwd.join("colmap-loc/results.jsonl"));
    assert_eq!(colmap[0]["group"], "query");
    for ((n1, e1), (n2, e2)) in estimates(&colmap).iter().zip(&estimates(&oracle)) {
        assert_eq!(n1, n2);
        // Poses round-trip through the COLMAP text exactly up to the quaternion's last bits.
        for (a, b) in e1.iter().zip(e2) {
            assert!((a - b).abs() < 1e-3, "{n1}: {e1:?} vs {e2:?}");
        }
    }

    // 4. A results file whose image ids belong to another dataset: a clear error, no output.
    std::fs::write(
        cwd.join("other.json"),
        r#"[{"image_id": 999, "category_id": 1, "segmentation": {"size": [4, 4], "counts": "52203"}, "score": 0.9}]"#,
    )
    .unwrap();
    let out = insgen(cwd, &eval_loc(&["--predictions", "other.json", "--tag", "bad"]));
    assert!(!out.status.success());
    let e = stderr(&out);
    assert!(e.contains("other.json") && e.contains("none of its image ids"), "{e}");
    assert!(!cam.join("loc/bad").exists(), "nothing written on error");

    // 5. Map ≠ query: another area in another ENU frame is refused, naming both; the same district
    //    prepared under another name (same frame) is accepted, coarsened to LoD1, and recorded.
    ok(cwd, &["prepare", "--area", "demo-test-moved"]);
    let out = insgen(cwd, &eval_loc(&["--oracle", "--map-area", "demo-test-moved"]));
    assert!(!out.status.success());
    let e = stderr(&out);
    assert!(
        e.contains("another ENU frame") && e.contains("demo-test-moved") && e.contains("[origin]"),
        "{e}"
    );
    ok(cwd, &["prepare", "--area", "demo-test-copy"]);
    let out = insgen(cwd, &eval_loc(&["--oracle", "--map-lod1", "--map-lod1-percentile", "120"]));
    assert!(!out.status.success());
    assert!(stderr(&out).contains("--map-lod1-percentile 120"), "{}", stderr(&out));
    ok(
        cwd,
        &eval_loc(&[
            "--oracle",
            "--map-area",
            "demo-test-copy",
            "--map-lod1",
            "--map-lod1-percentile",
            "70",
            "--map-offset",
            "0.5,-0.5,0",
            "--limit",
            "1",
            "--overlays",
            "0",
            "--tag",
            "lod1",
        ]),
    );
    let summary: Value =
        serde_json::from_slice(&std::fs::read(cam.join("loc/lod1/summary.json")).unwrap()).unwrap();
    assert_schema("loc_summary.schema.json", &summary);
    assert_eq!(summary["map"]["area"], "demo-test-copy");
    assert_eq!(summary["map"]["perturbation"]["lod1"], true);
    assert_eq!(summary["map"]["perturbation"]["lod1_roof_percentile"], 70.0);
    assert_eq!(summary["map"]["perturbation"]["offset_enu_m"], serde_json::json!([0.5, -0.5, 0.0]));
}
