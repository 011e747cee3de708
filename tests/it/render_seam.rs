//! The renderer seam (`render::seam`) seen from outside: the localizer's hypotheses rendered by wgpu
//! and by the CPU rasteriser through `IdScene` agree on ≥ 99 % of pixels on the demo district, at
//! eval-loc's two render widths (640 px fine, 160 px coarse); and `eval-loc --renderer gpu` runs on the
//! software Vulkan rasteriser (lavapipe, selected with NODEVICE_SELECT=1 as in every wgpu test), says
//! which renderer and adapter it uses, localizes the demo's queries and records the renderer in
//! summary.json.
//!
//! Tolerance: the two rasterisers follow the same conventions (pixel centres, top-left rule, nearest
//! surface), so they differ only at pixel centres within float rounding of an edge and at depth ties;
//! `render_cpu_agreement.rs` bounds that at 0.1 % at 640 px. Here 1 % (the brief's bound for hypotheses),
//! since at 160 px an edge pixel weighs 16 times as much of the frame.

use std::ops::ControlFlow;
use std::path::Path;

use insgen::camera::Intrinsics;
use insgen::render::cpu::Frame;
use insgen::render::{CpuRenderer, IdRenderer, RenderOptions, View};
use serde_json::Value;

use crate::render_common;
use crate::util::{self, assert_schema, insgen, repo_scene, scratch_with_scenes, stderr};

#[test]
fn wgpu_and_cpu_hypotheses_agree_through_the_seam() {
    let dir = tempfile::tempdir().unwrap();
    let scene = util::prepare_repo_scene("demo-test", &dir.path().join("scene"));
    let poses = render_common::poses_at_tallest(&scene, 6);
    let (gpu, cpu) = (render_common::renderer(), CpuRenderer);
    let anchor_m = poses[0].centre_m;
    let g = gpu.prepare(&scene.mesh, anchor_m).expect("upload");
    let c = cpu.prepare(&scene.mesh, anchor_m).expect("CPU scene");
    assert!(!g.renders_in_parallel() && c.renders_in_parallel());
    let cam2 = Intrinsics::from_hfov(1920, 1080, 25.0);
    for width_px in [640, 160] {
        let k = insgen::loc::eval::at_width(&cam2, width_px);
        let views: Vec<View> = poses.iter().map(|&pose| View { intrinsics: k, pose }).collect();
        // The batch (frames in flight) gives the frames one render at a time gives.
        let mut batch = Vec::new();
        g.render_each(&views, &RenderOptions::default(), &mut |_, image| {
            batch.push(image.ids.raw().to_vec());
            ControlFlow::Continue(())
        })
        .expect("wgpu batch");
        let (mut gf, mut cf) = (Frame::default(), Frame::default());
        let (mut diff, mut total, mut building) = (0usize, 0usize, 0usize);
        for (view, batched) in views.iter().zip(&batch) {
            g.render_into(view, &mut gf).expect("wgpu frame");
            c.render_into(view, &mut cf).expect("CPU frame");
            assert_eq!(&gf.ids, batched, "{width_px} px: batched and single wgpu frames differ");
            assert_eq!(gf.ids.len(), cf.ids.len());
            diff += gf.ids.iter().zip(&cf.ids).filter(|(a, b)| a != b).count();
            total += gf.ids.len();
            building += gf.ids.iter().filter(|&&i| i != 0).count();
        }
        let agreement = 1.0 - diff as f64 / total as f64;
        eprintln!("{width_px} px: {diff} of {total} pixels differ → agreement {agreement:.5}");
        assert!(building > total / 4, "{width_px} px: the views must see buildings ({building} of {total})");
        assert!(agreement >= 0.99, "{width_px} px: wgpu and CPU agree on {:.3} %", 100.0 * agreement);
    }
}

fn ok(cwd: &Path, args: &[&str]) {
    let out = insgen(cwd, args);
    assert!(out.status.success(), "insgen {}: {}", args.join(" "), stderr(&out));
}

#[test]
fn eval_loc_localizes_the_demo_with_wgpu_hypotheses() {
    let dir = scratch_with_scenes(&[("demo-test", repo_scene("demo-test"))]);
    let cwd = dir.path();
    ok(cwd, &["prepare", "--area", "demo-test"]);
    ok(cwd, &["sample", "--area", "demo-test", "--camera", "cam2", "--count", "2"]);
    ok(cwd, &["render-masks", "--area", "demo-test", "--camera", "cam2"]);
    let out_dir = cwd.join("loc-gpu");
    let args = [
        "--no-progress",
        "eval-loc",
        "--area",
        "demo-test",
        "--camera",
        "cam2",
        "--oracle",
        "--renderer",
        "gpu",
        "--overlays",
        "1",
        "--out",
        out_dir.to_str().unwrap(),
    ];
    // The log line is at info level, which `util::insgen` silences (RUST_LOG=warn).
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_insgen"))
        .args(args)
        .current_dir(cwd)
        .env("RUST_LOG", "info")
        .output()
        .expect("the insgen binary runs");
    let log = stderr(&out);
    assert!(out.status.success(), "{log}");
    assert!(log.contains("eval-loc renders its hypotheses with wgpu on "), "{log}");
    let summary: Value =
        serde_json::from_slice(&std::fs::read(out_dir.join("summary.json")).unwrap()).unwrap();
    assert_schema("loc_summary.schema.json", &summary);
    assert_eq!(summary["renderer"]["kind"], "gpu", "{}", summary["renderer"]);
    assert!(!summary["renderer"]["adapter"].as_str().unwrap().is_empty());
    let results = std::fs::read_to_string(out_dir.join("results.jsonl")).unwrap();
    let rows: Vec<Value> = results.lines().map(|l| serde_json::from_str(l).unwrap()).collect();
    assert_eq!(rows.len(), 2);
    for r in &rows {
        let (t, rot) =
            (r["translation_error_m"].as_f64().unwrap(), r["rotation_error_deg"].as_f64().unwrap());
        assert!(t < 2.0 && rot < 2.0, "{}: {t} m / {rot}°", r["name"]);
    }
    assert!(out_dir.join("overlays").read_dir().unwrap().next().is_some(), "an overlay was written");
}
