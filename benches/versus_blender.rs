//! insgen against Blender on the real areas, side by side in one run (issues 4, 6 and 7):
//!
//! - **masks** (issue 4): frames/s of the wgpu ID renderer for cam2 (1920×1080) and 640×360 on the
//!   held-out demo district and on Shibuya (PLATEAU 3D Tiles, with ../shared/data), render alone and
//!   the whole render-masks stage (render + connected components + PNG + JSON), next to Blender (`bpy`,
//!   Cycles, 1 sample, flat emission IDs — the fastest exact ID render it has) on the same poses;
//! - **localizer** (issue 7): hypotheses scored per second (CPU rasteriser + best-match Dice) at the
//!   fine (640×360) and coarse (320×180) resolutions, against Blender rendering the same hypotheses;
//! - **alignment** (issue 6): `insgen render-rgb --check-alignment` on both areas (Blender's flat ID
//!   render vs the masks: median and 5th-percentile per-building IoU);
//! - **RGB** (issue 6, optional with `--rgb`): seconds per frame of a cam2 full-resolution Cycles RGB
//!   frame.
//!
//! Writes `bench/versus_blender.md`. Run: `cargo bench --bench versus_blender` (or `--profile dev` to
//! reuse the test build; add `-- --quick` for
//! fewer frames, `-- --rgb` for the full-resolution RGB timing). Work files go to
//! `target/bench-work/` and are reused between runs (prepare/sample/masks are resumable).

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

use insgen::blender::{render_frames, Engine, FrameRequest, Launcher, Mode, RenderPlan, SceneSource};
use insgen::camera::{Intrinsics, PoseRecord};
use insgen::label::stage::{self, MaskPlan};
use insgen::loc::cost::{Blend, CostKind, Weighting};
use insgen::loc::eval::{at_width, cull, dense_subscene, CpuEvaluator};
use insgen::loc::metrics::median_or_nan;
use insgen::loc::oracle::Degradation;
use insgen::loc::query::QuerySource;
use insgen::loc::search::{Evaluate, Hypothesis};
use insgen::render::cpu::CpuScene;
use insgen::render::{RenderOptions, Renderer, View};
use insgen::scene::artifact::GLB_FILE;
use insgen::scene::PreparedScene;
use insgen::util::NoProgress;

fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// Runs the insgen binary; returns whether it succeeded and its stdout + stderr.
fn insgen_status(work: &Path, args: &[&str]) -> (bool, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_insgen"))
        .arg("--workdir")
        .arg(work)
        .arg("--scenes")
        .arg(repo().join("scenes"))
        .arg("--no-progress")
        .args(args)
        .output()
        .expect("insgen runs");
    let stderr = String::from_utf8_lossy(&out.stderr);
    (out.status.success(), String::from_utf8_lossy(&out.stdout).into_owned() + &stderr)
}

/// Runs the insgen binary; panics with its output on failure.
fn insgen(work: &Path, args: &[&str]) -> String {
    let (ok, text) = insgen_status(work, args);
    assert!(ok, "insgen {}: {text}", args.join(" "));
    text
}

fn read_poses(path: &Path) -> Vec<PoseRecord> {
    std::fs::read_to_string(path)
        .expect("poses.jsonl")
        .lines()
        .filter(|l| !l.trim().is_empty())
        .map(|l| serde_json::from_str(l).expect("pose record"))
        .collect()
}

/// Writes `records` with intrinsics scaled to `width` into `<area>/<camera>/poses.jsonl`.
fn write_scaled(work: &Path, area: &str, camera: &str, records: &[PoseRecord], width: u32) -> PathBuf {
    let dir = work.join(area).join(camera);
    std::fs::create_dir_all(&dir).unwrap();
    let mut text = String::new();
    for r in records {
        let mut r = r.clone();
        r.view.intrinsics = at_width(&r.view.intrinsics, width);
        text.push_str(&serde_json::to_string(&r).unwrap());
        text.push('\n');
    }
    std::fs::write(dir.join("poses.jsonl"), text).unwrap();
    dir
}

/// Seconds per frame of Blender rendering exact IDs (Cycles, 1 sample, emission) for `frames`, and
/// the one-off scene set-up time of its process.
fn blender_ids(
    launcher: &Launcher,
    scene_dir: &Path,
    ground_m: f64,
    frames: &[FrameRequest],
    out: &Path,
) -> (f64, f64) {
    let plan = RenderPlan {
        launcher: launcher.clone(),
        mode: Mode::Ids,
        engine: Engine::Cycles,
        rgb: insgen::blender::job::RgbSettings {
            samples: 1,
            denoise: false,
            denoise_quality: insgen::blender::job::DenoiseQuality::Fast,
            max_bounces: 2,
            lighting: insgen::blender::job::Lighting::Direct,
        },
        seed: 0,
        device: insgen::blender::job::Device::Cpu,
        threads: 0,
        exr: false,
        source: SceneSource::Lod {
            glb: scene_dir.join(GLB_FILE),
            enu_from_gltf: insgen::blender::tileset::ENU_FROM_SCENE_GLTF,
        },
        look_seed: 0,
        look: insgen::blender::look::LookRanges::plain(35.0),
        ground_enu_m: ground_m,
        out_dir: out.join("ids"),
        work_dir: out.join("work"),
        restart_every: 1000,
        force: true,
        clip_start_m: 0.5,
        clip_end_m: 100_000.0,
        report_bounds: false,
        clutter_occluders: None,
        contrast: None,
    };
    let summary = render_frames(&plan, frames, &NoProgress).expect("Blender renders the IDs");
    let secs = median_or_nan(&summary.rendered.iter().map(|t| t.seconds).collect::<Vec<_>>());
    (secs, summary.setup_seconds.iter().sum())
}

struct AreaNumbers {
    area: String,
    buildings: usize,
    triangles: usize,
    rows: Vec<(String, f64, f64)>, // (what, insgen frames/s, blender frames/s or NaN)
    loc: Vec<(String, f64, f64)>,  // (resolution, insgen hyp/s, blender hyp/s)
    alignment: String,
}

fn bench_area(
    work: &Path,
    area: &str,
    n_frames: usize,
    n_blender: usize,
    launcher: &Launcher,
) -> AreaNumbers {
    eprintln!("== {area}");
    insgen(work, &["prepare", "--area", area]);
    let cam_dir = work.join(area).join("cam2");
    if !cam_dir.join("poses.jsonl").is_file() {
        insgen(work, &["sample", "--area", area, "--camera", "cam2", "--count", &n_frames.to_string()]);
    }
    let scene = PreparedScene::load(&work.join(area).join("scene")).expect("prepared scene");
    let records: Vec<PoseRecord> =
        read_poses(&cam_dir.join("poses.jsonl")).into_iter().take(n_frames).collect();
    let renderer = Renderer::new().expect("a wgpu adapter (scripts/setup.sh installs lavapipe)");
    let gpu = renderer.upload(&scene.mesh).expect("upload");
    let mut rows = Vec::new();
    let mut loc = Vec::new();
    let blender_out = work.join(area).join("bench-blender");
    for (label, width) in [("cam2 1920×1080", 1920u32), ("640×360", 640)] {
        let views: Vec<View> = records
            .iter()
            .map(|r| View { intrinsics: at_width(&r.view.intrinsics, width), pose: r.pose() })
            .collect();
        // Render alone: warm up, then enough repetitions for ≥ 2 s.
        renderer.render_batch(&gpu, &views[..1], &RenderOptions::default()).unwrap();
        let (mut frames, t0) = (0usize, Instant::now());
        while t0.elapsed().as_secs_f64() < 2.0 {
            frames += renderer.render_batch(&gpu, &views, &RenderOptions::default()).unwrap().len();
        }
        let render_fps = frames as f64 / t0.elapsed().as_secs_f64();
        // The whole stage (CC, PNG, instance JSON, atomic writes) on a scaled copy of the poses.
        let dir = write_scaled(work, area, &format!("bench-{width}"), &records, width);
        let mut plan = MaskPlan::new(dir);
        plan.force = true;
        let t0 = Instant::now();
        stage::render_masks(&plan, &scene, &renderer, &NoProgress).expect("render-masks stage");
        let stage_fps = records.len() as f64 / t0.elapsed().as_secs_f64();
        // Blender on the first frames.
        let frames: Vec<FrameRequest> = views
            .iter()
            .zip(&records)
            .take(n_blender)
            .map(|(v, r)| FrameRequest { name: r.name.clone(), intrinsics: v.intrinsics, pose: v.pose })
            .collect();
        let (b_secs, b_setup) = blender_ids(
            launcher,
            &work.join(area).join("scene"),
            scene.manifest.ground_enu_m,
            &frames,
            &blender_out.join(width.to_string()),
        );
        eprintln!("{label}: wgpu {render_fps:.1} fps, stage {stage_fps:.1} fps, Blender {b_secs:.2} s/frame (+{b_setup:.1} s set-up)");
        rows.push((format!("{label}: render IDs"), render_fps, 1.0 / b_secs));
        rows.push((format!("{label}: render + CC + PNG + JSON"), stage_fps, f64::NAN));
        if width == 640 {
            // Localizer hypotheses at 640×360 and 320×180 around the first frame's pose.
            let r0 = &records[0];
            let pose = r0.pose();
            let [yaw, pitch, roll] = pose.ypr_deg();
            for w in [640u32, 320] {
                let k: Intrinsics = at_width(&r0.view.intrinsics, w);
                let source = QuerySource::Oracle {
                    masks_dir: cam_dir.join("masks"),
                    degradation: Degradation::default(),
                };
                if !cam_dir.join("masks").join(format!("{}.png", r0.name)).is_file() {
                    insgen(work, &["render-masks", "--area", area, "--camera", "cam2", "--limit", "1"]);
                }
                let q = source.queries(&r0.name, &[k], 0).expect("oracle query").remove(0);
                let kept = cull(&scene.buildings, &pose, &k, 0.5);
                let sub = dense_subscene(&scene.mesh, &kept);
                let cpu = CpuScene::new(&sub, pose.centre_m);
                let mut ev = CpuEvaluator {
                    scene: &cpu,
                    k,
                    pitch_deg: pitch,
                    roll_deg: roll,
                    query: &q,
                    kind: CostKind::Instance,
                    weighting: Weighting::Conf,
                    // The paper's pure instance cost: this bench times the raster, not the blend.
                    blend: Blend::semantic(0.0),
                    k_max: kept.len() as u32,
                    silhouette_offset_px: 0,
                    // Distinct centres, as in the particle filter: one render per hypothesis.
                    yaw_fan: false,
                    workspaces: Default::default(),
                };
                let hyps: Vec<Hypothesis> = (0..208)
                    .map(|i| {
                        let f = i as f64;
                        Hypothesis {
                            centre_m: glam::DVec3::new(
                                pose.centre_m[0] + (f * 0.37).sin() * 6.0,
                                pose.centre_m[1] + (f * 0.73).cos() * 6.0,
                                pose.centre_m[2] + (f * 0.11).sin() * 3.0,
                            ),
                            yaw_deg: yaw + (f * 0.53).sin() * 2.0,
                        }
                    })
                    .collect();
                ev.evaluate(&hyps[..8]).unwrap();
                let (mut n, t0) = (0usize, Instant::now());
                while t0.elapsed().as_secs_f64() < 2.0 {
                    n += ev.evaluate(&hyps).unwrap().len();
                }
                let hyp_s = n as f64 / t0.elapsed().as_secs_f64();
                // Blender rendering the same hypotheses at this resolution.
                let bl_frames: Vec<FrameRequest> = hyps
                    .iter()
                    .take(n_blender)
                    .enumerate()
                    .map(|(i, h)| FrameRequest {
                        name: format!("hyp{i:03}"),
                        intrinsics: k,
                        pose: h.pose(pitch, roll),
                    })
                    .collect();
                let (bs, _) = blender_ids(
                    launcher,
                    &work.join(area).join("scene"),
                    scene.manifest.ground_enu_m,
                    &bl_frames,
                    &blender_out.join(format!("hyp{w}")),
                );
                eprintln!("loc {w}: {hyp_s:.0} hyp/s vs Blender {:.2} hyp/s", 1.0 / bs);
                loc.push((format!("{}×{}", k.width_px, k.height_px), hyp_s, 1.0 / bs));
            }
        }
    }
    // Alignment of Blender's ID render with the masks (issue 6), at the masks' full resolution.
    insgen(work, &["render-masks", "--area", area, "--camera", "cam2", "--limit", &n_blender.to_string()]);
    let out = insgen(
        work,
        &[
            "render-rgb",
            "--area",
            area,
            "--camera",
            "cam2",
            "--check-alignment",
            "--limit",
            &n_blender.to_string(),
        ],
    );
    let alignment = out
        .lines()
        .find(|l| l.starts_with("alignment:"))
        .unwrap_or("alignment: (no summary line)")
        .to_string();
    AreaNumbers {
        area: area.into(),
        buildings: scene.buildings.len(),
        triangles: scene.mesh.triangle_count(),
        rows,
        loc,
        alignment,
    }
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let quick = args.iter().any(|a| a == "--quick");
    let rgb = args.iter().any(|a| a == "--rgb");
    let (n_frames, n_blender) = if quick { (6, 2) } else { (12, 4) };
    let work = repo().join("target/bench-work");
    std::fs::create_dir_all(&work).unwrap();
    let launcher =
        Launcher::find(None, None, &[repo()]).expect("Blender's bpy (scripts/setup.sh installs it)");
    let mut areas = vec!["demo-test"];
    if repo().join("../shared/data/jp_tokyo_shibuya_plateau_3dtiles/tileset.json").is_file() {
        areas.push("tokyo");
    } else {
        eprintln!("skipping Shibuya: ../shared/data/jp_tokyo_shibuya_plateau_3dtiles is absent");
    }
    let numbers: Vec<AreaNumbers> =
        areas.iter().map(|a| bench_area(&work, a, n_frames, n_blender, &launcher)).collect();

    let mut rgb_line = String::new();
    if rgb {
        let t0 = Instant::now();
        let out = insgen(
            &work,
            &[
                "render-rgb",
                "--area",
                "demo-test",
                "--camera",
                "cam2",
                "--limit",
                "1",
                "--samples",
                "32",
                "--force",
            ],
        );
        let line = out.lines().find(|l| l.contains("s/frame in Blender")).unwrap_or("").to_string();
        rgb_line = format!("- cam2 full resolution (1920×1080), Cycles CPU, 32 samples + denoise, demo-test: {line} (wall {:.1} s with start-up)\n", t0.elapsed().as_secs_f64());
    }

    let profile = if cfg!(debug_assertions) {
        "dev profile (debug assertions on; insgen at opt-level 1)"
    } else {
        "release profile"
    };
    let load = std::fs::read_to_string("/proc/loadavg").unwrap_or_default();
    let adapter = Renderer::new().map(|r| r.adapter().to_string()).unwrap_or_default();
    let mut md = String::new();
    let _ = writeln!(md, "# insgen vs Blender, side by side\n");
    let _ = writeln!(
        md,
        "Generated by `cargo bench{} --bench versus_blender{}`.\n",
        if cfg!(debug_assertions) { " --profile dev" } else { "" },
        match (quick, rgb) {
            (false, false) => "",
            (true, false) => " -- --quick",
            (false, true) => " -- --rgb",
            (true, true) => " -- --quick --rgb",
        }
    );
    let _ = writeln!(
        md,
        "- build: {profile}; CPU threads: {}; load average at the end: {}",
        std::thread::available_parallelism().map(|n| n.get()).unwrap_or(0),
        load.trim()
    );
    let _ = writeln!(md, "- wgpu adapter: {adapter}");
    let _ = writeln!(md, "- Blender: bpy 5.0.1 (`.venv-blender`), Cycles CPU, 1 sample, flat emission IDs into float32 EXR (the alignment check's render); seconds per frame are Blender's own render time per frame (median), without the process start and scene import");
    let _ = writeln!(
        md,
        "- poses: `insgen sample --camera cam2 --count {n_frames}` (first {n_blender} frames for Blender)\n"
    );
    for a in &numbers {
        let _ = writeln!(md, "## {} ({} buildings, {} triangles)\n", a.area, a.buildings, a.triangles);
        let _ = writeln!(md, "| what | insgen frames/s | Blender frames/s | ratio |\n|---|---:|---:|---:|");
        for (what, ours, theirs) in &a.rows {
            let (b, r) = if theirs.is_nan() {
                ("—".into(), "—".into())
            } else {
                (format!("{theirs:.3}"), format!("{:.0}×", ours / theirs))
            };
            let _ = writeln!(md, "| {what} | {ours:.1} | {b} | {r} |");
        }
        let _ = writeln!(md, "\nLocalizer hypotheses (CPU rasteriser + best-match Dice, all cores) vs Blender rendering the same hypotheses:\n");
        let _ = writeln!(
            md,
            "| resolution | insgen hypotheses/s | Blender hypotheses/s | ratio |\n|---|---:|---:|---:|"
        );
        for (res, ours, theirs) in &a.loc {
            let _ = writeln!(md, "| {res} | {ours:.0} | {theirs:.3} | {:.0}× |", ours / theirs);
        }
        let _ = writeln!(
            md,
            "\nAlignment (Blender ID render vs masks, full resolution, first {n_blender} frames): `{}`\n",
            a.alignment
        );
    }
    if !rgb_line.is_empty() {
        let _ = writeln!(md, "## RGB\n\n{rgb_line}");
    }
    let path = repo().join("bench/versus_blender.md");
    std::fs::write(&path, &md).unwrap();
    println!("{md}\nwritten to {}", path.display());
}
