//! Blender integration tests: real renders of tiny scenes through bpy (`.venv-blender`).
//!
//! - ID renders of box buildings match an independent f64 ray-casting reference (pixel centres), with
//!   off-centre principal points, fx ≠ fy, tilt and roll: every differing pixel lies on an edge of the
//!   reference, and per-building IoU passes the issue-6 targets (median ≥ 0.995, p5 ≥ 0.98);
//! - the same check through a generated 3D Tiles tileset (b3dm RTC_CENTER, glTF CESIUM_RTC, tile
//!   transforms, an external tileset, REPLACE refinement, a culled tile whose file does not exist);
//! - a small RGB job: sizes, non-flat content, restarts, byte-identical reruns, resume without Blender;
//! - failures: a corrupt model surfaces Blender's stderr and leaves no partial frame;
//! - real data: the Shibuya b3dm tiles land inside their region bounding volumes;
//! - `#[ignore]` benchmark: seconds per frame for cam2 at 1920×1080.
//!
//! Tests skip with a reason when the bpy interpreter is missing (and fail under CI=true).

use crate::blender_support;

use std::path::{Path, PathBuf};

use blender_support::*;
use glam::{DMat4, DVec3};
use insgen::blender::align::{building_ious, summarise, FrameAlignment};
use insgen::blender::job::{Device, Lighting};
use insgen::blender::run::frame_outputs;
use insgen::blender::tileset::{SelectOptions, ENU_FROM_SCENE_GLTF};
use insgen::blender::{render_frames, Engine, FrameRequest, Launcher, Mode, RenderPlan, SceneSource};
use insgen::camera::{Intrinsics, Pose};
use insgen::geo::{EnuFrame, Geodetic};
use insgen::lod::tiles3d::UpAxis;
use insgen::scene::IdMap;
use insgen::util::NoProgress;

fn plan(python: &Path, dir: &Path, mode: Mode, source: SceneSource) -> RenderPlan {
    RenderPlan {
        launcher: Launcher::Python { interpreter: python.to_path_buf() },
        mode,
        engine: Engine::Cycles,
        rgb: insgen::blender::job::RgbSettings {
            samples: 4,
            denoise: false,
            denoise_quality: insgen::blender::job::DenoiseQuality::Fast,
            max_bounces: 2,
            lighting: insgen::blender::job::Lighting::Direct,
        },
        seed: 1,
        device: insgen::blender::job::Device::Cpu,
        // Two render threads: the test machine is shared.
        threads: 2,
        exr: false,
        source,
        look_seed: 11,
        look: insgen::blender::look::LookRanges::plain(35.0),
        ground_enu_m: 0.0,
        out_dir: dir.join("out"),
        work_dir: dir.join("work"),
        restart_every: 50,
        force: false,
        clip_start_m: 0.5,
        clip_end_m: 100_000.0,
        report_bounds: false,
        clutter_occluders: None,
        contrast: None,
    }
}

fn write_scene_glb(dir: &Path, boxes: &[BoxBuilding]) -> PathBuf {
    let p = dir.join("scene.glb");
    std::fs::write(&p, glb_bytes(boxes, &scene_gltf, serde_json::json!({}))).unwrap();
    p
}

/// Frames exercising the camera model: off-centre principal point, fx ≠ fy, tilt, roll.
fn test_frames() -> Vec<FrameRequest> {
    let k1 =
        Intrinsics { width_px: 160, height_px: 120, fx_px: 150.0, fy_px: 170.0, cx_px: 70.3, cy_px: 66.8 };
    let mut k2 = Intrinsics::from_hfov(160, 120, 50.0);
    k2.cx_px = 85.0;
    k2.fx_px *= 0.9;
    vec![
        FrameRequest {
            name: "nadir_offcentre".into(),
            intrinsics: k1,
            pose: Pose::from_ypr_deg(20.0, 0.0, 0.0, [0.0, 0.0, 150.0]),
        },
        FrameRequest {
            name: "tilt45".into(),
            intrinsics: k1,
            pose: Pose::from_ypr_deg(200.0, 45.0, 0.0, [40.0, 60.0, 110.0]),
        },
        FrameRequest {
            name: "tilt60_roll".into(),
            intrinsics: k2,
            pose: Pose::from_ypr_deg(75.0, 60.0, 4.0, [-120.0, -30.0, 90.0]),
        },
    ]
}

/// Compares Blender's ID renders of `frames` with the reference of `boxes`; returns the report.
fn check_ids_against_reference(
    plan: &RenderPlan,
    frames: &[FrameRequest],
    boxes: &[BoxBuilding],
) -> insgen::blender::align::AlignmentReport {
    let mut per_frame = Vec::new();
    for f in frames {
        let path = frame_outputs(plan, &f.name)[0].path.clone();
        let got = IdMap::read_exr(&path).unwrap();
        let k = &f.intrinsics;
        assert_eq!((got.width(), got.height()), (k.width_px, k.height_px));
        let want = IdMap::from_raw(k.width_px, k.height_px, reference_ids(boxes, k, &f.pose)).unwrap();
        let edges = edge_mask(want.raw(), k.width_px, k.height_px);
        let mut differ = 0;
        for (i, (&a, &b)) in got.raw().iter().zip(want.raw()).enumerate() {
            if a != b {
                differ += 1;
                assert!(
                    edges[i],
                    "{}: pixel ({}, {}) is {a} but the reference says {b} away from any edge",
                    f.name,
                    i as u32 % k.width_px,
                    i as u32 / k.width_px
                );
            }
        }
        let present = want.visible_buildings();
        assert!(present.len() >= 3, "{}: only {present:?} visible; the test frame is badly placed", f.name);
        eprintln!(
            "{}: {differ} differing pixels of {} ({} edge pixels)",
            f.name,
            got.raw().len(),
            edges.iter().filter(|&&e| e).count()
        );
        let agreement = insgen::blender::align::pixel_agreement(&got, &want);
        per_frame.push(FrameAlignment {
            frame: f.name.clone(),
            pixel_agreement: agreement,
            buildings: building_ious(&got, &want, &path).unwrap(),
        });
    }
    summarise(per_frame, 64)
}

#[test]
fn ids_render_matches_f64_reference() {
    let Some(py) = blender_python() else { return };
    let dir = tempfile::tempdir().unwrap();
    let boxes = box_city();
    let glb = write_scene_glb(dir.path(), &boxes);
    let p = plan(&py, dir.path(), Mode::Ids, SceneSource::Lod { glb, enu_from_gltf: ENU_FROM_SCENE_GLTF });
    let frames = test_frames();
    let s = render_frames(&p, &frames, &NoProgress).unwrap();
    assert_eq!(s.rendered.len(), 3);
    let report = check_ids_against_reference(&p, &frames, &boxes);
    eprintln!("median IoU {:?}, p5 {:?}, min {:?}", report.median_iou, report.p5_iou, report.min_iou);
    assert!(report.pairs_counted >= 12, "{}", report.pairs_counted);
    assert!(report.pass, "{}", report.to_markdown());
    // No temporary file is left behind.
    let leftovers: Vec<_> = std::fs::read_dir(&p.out_dir)
        .unwrap()
        .filter_map(|e| e.ok())
        .filter(|e| e.file_name().to_string_lossy().starts_with('.'))
        .collect();
    assert!(leftovers.is_empty(), "{leftovers:?}");
}

/// Column-major 16 numbers (3D Tiles `transform`) of a row-major 4×4 or a [`DMat4`].
fn col_major(m: &impl ColMajor) -> Vec<f64> {
    m.col_major()
}

trait ColMajor {
    fn col_major(&self) -> Vec<f64>;
}
impl ColMajor for [[f64; 4]; 4] {
    fn col_major(&self) -> Vec<f64> {
        (0..4).flat_map(|j| (0..4).map(move |i| self[i][j])).collect()
    }
}
impl ColMajor for DMat4 {
    fn col_major(&self) -> Vec<f64> {
        self.to_cols_array().to_vec()
    }
}

#[test]
fn tileset_tiles_are_placed_exactly() {
    let Some(py) = blender_python() else { return };
    let dir = tempfile::tempdir().unwrap();
    let ts_dir = dir.path().join("tiles");
    std::fs::create_dir_all(ts_dir.join("ext")).unwrap();
    let enu = EnuFrame::new(Geodetic::new(35.0, 139.0, 50.0));
    let ecef_from_enu_m = enu.ecef_from_enu();
    let boxes = box_city();
    let (a_boxes, rest) = boxes.split_at(2);
    let (b_boxes, c_boxes) = rest.split_at(2);
    let y2z_inv = UpAxis::Y.to_z_up().inverse();
    let point = |m: &DMat4, p: [f64; 3]| m.transform_point3(DVec3::from_array(p)).to_array();

    // Tile A1: b3dm with RTC_CENTER under a tile transform = the ENU frame of a point 300 m east,
    // rotated by that frame's own axes (a realistic "local ENU" tile transform).
    let a_origin = enu.enu_to_geodetic(DVec3::new(300.0, 0.0, 0.0));
    let t_a = EnuFrame::new(a_origin).ecef_from_enu();
    let rtc_a = [5.0, -3.0, 2.0];
    let local_a = t_a.inverse() * ecef_from_enu_m;
    let to_gltf_a = |p: [f64; 3]| {
        let l = point(&local_a, p);
        point(&y2z_inv, [l[0] - rtc_a[0], l[1] - rtc_a[1], l[2] - rtc_a[2]])
    };
    std::fs::write(
        ts_dir.join("a1.b3dm"),
        b3dm_bytes(&glb_bytes(a_boxes, &to_gltf_a, serde_json::json!({})), Some(rtc_a)),
    )
    .unwrap();
    // A's own (coarse) content must be replaced by A1: a decoy building that is not in the reference.
    let decoy = [BoxBuilding::new(999, -20.0, -20.0, 20.0, 20.0, 0.0, 100.0)];
    std::fs::write(
        ts_dir.join("a_coarse.b3dm"),
        b3dm_bytes(&glb_bytes(&decoy, &to_gltf_a, serde_json::json!({})), Some(rtc_a)),
    )
    .unwrap();

    // Tile B: a glb with CESIUM_RTC (ECEF centre) and no transform.
    let centre_b = enu.enu_to_ecef(DVec3::new(10.0, 10.0, 0.0)).to_array();
    let to_gltf_b = |p: [f64; 3]| {
        let e = enu.enu_to_ecef(p.into());
        point(&y2z_inv, [e[0] - centre_b[0], e[1] - centre_b[1], e[2] - centre_b[2]])
    };
    let rtc_ext = serde_json::json!({"extensionsUsed": ["CESIUM_RTC"], "extensionsRequired": ["CESIUM_RTC"], "extensions": {"CESIUM_RTC": {"center": centre_b}}});
    std::fs::write(ts_dir.join("b.glb"), glb_bytes(b_boxes, &to_gltf_b, rtc_ext)).unwrap();

    // Tile C: an external tileset whose root carries a second transform (a pure translation) under a
    // parent tile with the ENU-frame transform of the area origin.
    let t_c_parent = ecef_from_enu_m;
    let t_c_root = [[1.0, 0.0, 0.0, -7.0], [0.0, 1.0, 0.0, 4.0], [0.0, 0.0, 1.0, 1.5], [0.0, 0.0, 0.0, 1.0]];
    let to_gltf_c = |p: [f64; 3]| point(&y2z_inv, [p[0] + 7.0, p[1] - 4.0, p[2] - 1.5]);
    std::fs::write(
        ts_dir.join("ext/c.b3dm"),
        b3dm_bytes(&glb_bytes(c_boxes, &to_gltf_c, serde_json::json!({})), None),
    )
    .unwrap();
    let ext = serde_json::json!({
        "asset": {"version": "1.0"},
        "geometricError": 0,
        "root": {"transform": col_major(&t_c_root), "boundingVolume": {"sphere": [0, 0, 0, 200]}, "geometricError": 0, "refine": "ADD", "content": {"uri": "c.b3dm"}}
    });
    std::fs::write(ts_dir.join("ext/sub.json"), serde_json::to_vec_pretty(&ext).unwrap()).unwrap();

    let deg = |v: f64| v.to_radians();
    let tileset = serde_json::json!({
        "asset": {"version": "1.0"},
        "geometricError": 500,
        "root": {
            "boundingVolume": {"region": [deg(138.99), deg(34.99), deg(139.12), deg(35.01), -10, 200]},
            "geometricError": 500,
            "refine": "ADD",
            "children": [
                {"transform": col_major(&t_a), "boundingVolume": {"box": [-300, 0, 50, 200, 0, 0, 0, 200, 0, 0, 0, 60]},
                 "geometricError": 50, "refine": "REPLACE", "content": {"uri": "a_coarse.b3dm"},
                 "children": [{"boundingVolume": {"box": [-300, 0, 50, 200, 0, 0, 0, 200, 0, 0, 0, 60]}, "geometricError": 0, "content": {"uri": "a1.b3dm"}}]},
                {"boundingVolume": {"region": [deg(138.999), deg(34.999), deg(139.001), deg(35.001), -10, 100]}, "geometricError": 0, "content": {"uri": "b.glb"}},
                {"transform": col_major(&t_c_parent), "boundingVolume": {"sphere": [0, 0, 0, 300]}, "geometricError": 0, "content": {"uri": "ext/sub.json"}},
                {"transform": col_major(&EnuFrame::new(enu.enu_to_geodetic(DVec3::new(10_000.0, 0.0, 0.0))).ecef_from_enu()),
                 "boundingVolume": {"box": [0, 0, 0, 100, 0, 0, 0, 100, 0, 0, 0, 100]}, "geometricError": 0, "content": {"uri": "far_away_missing.b3dm"}}
            ]
        }
    });
    let ts_path = ts_dir.join("tileset.json");
    std::fs::write(&ts_path, serde_json::to_vec_pretty(&tileset).unwrap()).unwrap();

    let source = SceneSource::Tileset { tileset: ts_path, enu, select: SelectOptions::default() };
    let p = plan(&py, dir.path(), Mode::Ids, source);
    let frames = test_frames();
    let s = render_frames(&p, &frames, &NoProgress).unwrap();
    assert_eq!(s.rendered.len(), 3);
    assert_eq!(s.models_per_job, vec![3], "A1, B and C, without the coarse A or the far tile");
    let report = check_ids_against_reference(&p, &frames, &boxes);
    eprintln!("tileset: median IoU {:?}, p5 {:?}", report.median_iou, report.p5_iou);
    assert!(report.pass, "{}", report.to_markdown());
}

/// `--device cpu` is what the frame metadata records, and `auto` falls back to the CPU on this machine
/// (no GPU; Blender reports no OptiX/CUDA/HIP/oneAPI device). A machine with a GPU would record that GPU
/// for `auto`: the test then only checks that the device is named.
#[test]
fn device_is_chosen_logged_and_recorded() {
    let Some(py) = blender_python() else { return };
    let dir = tempfile::tempdir().unwrap();
    let glb = write_scene_glb(dir.path(), &box_city());
    let frame = FrameRequest {
        name: "d".into(),
        intrinsics: Intrinsics::from_hfov(32, 24, 50.0),
        pose: Pose::from_ypr_deg(0.0, 0.0, 0.0, [0.0, 0.0, 120.0]),
    };
    let meta_schema: serde_json::Value = serde_json::from_slice(
        &std::fs::read(Path::new(env!("CARGO_MANIFEST_DIR")).join("schemas/rgb_render.schema.json")).unwrap(),
    )
    .unwrap();
    let meta_schema = jsonschema::validator_for(&meta_schema).unwrap();
    for (device, word) in [(Device::Cpu, "cpu"), (Device::Auto, "auto")] {
        let mut p = plan(
            &py,
            dir.path(),
            Mode::Rgb,
            SceneSource::Lod { glb: glb.clone(), enu_from_gltf: ENU_FROM_SCENE_GLTF },
        );
        p.device = device;
        p.force = true;
        let s = render_frames(&p, std::slice::from_ref(&frame), &NoProgress).unwrap();
        let bytes = std::fs::read(p.out_dir.join("d.render.json")).unwrap();
        let json: serde_json::Value = serde_json::from_slice(&bytes).unwrap();
        let errors: Vec<String> = meta_schema.iter_errors(&json).map(|e| e.to_string()).collect();
        assert!(errors.is_empty(), "d.render.json against schemas/rgb_render.schema.json: {errors:?}");
        let meta: insgen::blender::run::FrameMeta = serde_json::from_slice(&bytes).unwrap();
        assert_eq!(meta.device_requested, word);
        assert_eq!(meta.settings.lighting, insgen::blender::job::Lighting::Direct);
        assert_eq!(s.devices, vec![meta.device.clone()]);
        if device == Device::Cpu || std::env::var_os("INSGEN_TEST_HAS_GPU").is_none() {
            assert_eq!(meta.device, "CPU", "{word}");
        } else {
            assert!(!meta.device.is_empty());
        }
        assert_eq!((meta.settings.samples, meta.engine.as_str()), (4, "cycles"));
    }
}

/// Luma mean and mean absolute deviation, and the mean blue/red ratio, of an 8-bit RGB image.
fn picture_stats(rgb: &[u8]) -> (f64, f64, f64) {
    let luma: Vec<f64> = rgb
        .chunks_exact(3)
        .map(|c| 0.2126 * c[0] as f64 + 0.7152 * c[1] as f64 + 0.0722 * c[2] as f64)
        .collect();
    let mean = luma.iter().sum::<f64>() / luma.len() as f64;
    let mad = luma.iter().map(|v| (v - mean).abs()).sum::<f64>() / luma.len() as f64;
    let (r, b) = rgb.chunks_exact(3).fold((0.0, 0.0), |(r, b), c| (r + c[0] as f64, b + c[2] as f64));
    (mean, mad, b / r.max(1.0))
}

/// The frame look is defined once per schema that carries it (the validator resolves no cross-file
/// references): the job's, the render metadata's and the COCO image record's copies must stay equal.
#[test]
fn frame_look_schema_copies_agree() {
    let def = |file: &str| {
        let v: serde_json::Value = serde_json::from_slice(
            &std::fs::read(Path::new(env!("CARGO_MANIFEST_DIR")).join("schemas").join(file)).unwrap(),
        )
        .unwrap();
        v["$defs"]["frame_look"].clone()
    };
    let job = def("blender_job.schema.json");
    assert!(job.is_object());
    assert_eq!(def("rgb_render.schema.json"), job);
    assert_eq!(def("coco_instances.schema.json"), job);
}

/// Mean HSV saturation of an 8-bit RGB image.
fn saturation(rgb: &[u8]) -> f64 {
    let s: f64 = rgb
        .chunks_exact(3)
        .map(|c| {
            let (max, min) = (c.iter().max().copied().unwrap_or(0), c.iter().min().copied().unwrap_or(0));
            if max == 0 {
                0.0
            } else {
                (max - min) as f64 / max as f64
            }
        })
        .sum();
    s / (rgb.len() / 3) as f64
}

/// The varied look: each frame's drawn values are in its metadata (schema-valid, equal to
/// `FrameLook::draw` of the seed and frame name), they change the picture the way they say (an overcast
/// sky gives a darker, greyer picture; a camera white-balanced for 4000 K turns a frame blue, for 9000 K
/// red), and a rerender with sensor noise reproduces the bytes.
#[test]
fn varied_look_is_drawn_per_frame_recorded_and_reproducible() {
    use insgen::blender::look::{FrameLook, LookRanges, Sky, SunRange};
    let Some(py) = blender_python() else { return };
    let dir = tempfile::tempdir().unwrap();
    let glb = write_scene_glb(dir.path(), &box_city());
    let frame = FrameRequest {
        name: "v".into(),
        intrinsics: Intrinsics::from_hfov(96, 72, 50.0),
        pose: Pose::from_ypr_deg(200.0, 40.0, 0.0, [40.0, 60.0, 110.0]),
    };
    let meta_schema: serde_json::Value = serde_json::from_slice(
        &std::fs::read(Path::new(env!("CARGO_MANIFEST_DIR")).join("schemas/rgb_render.schema.json")).unwrap(),
    )
    .unwrap();
    let meta_schema = jsonschema::validator_for(&meta_schema).unwrap();
    let render = |name: &str, ranges: LookRanges| {
        let mut p = plan(
            &py,
            &dir.path().join(name),
            Mode::Rgb,
            SceneSource::Lod { glb: glb.clone(), enu_from_gltf: ENU_FROM_SCENE_GLTF },
        );
        p.look = ranges;
        p.force = true;
        render_frames(&p, std::slice::from_ref(&frame), &NoProgress).unwrap();
        let bytes = std::fs::read(p.out_dir.join("v.render.json")).unwrap();
        let json: serde_json::Value = serde_json::from_slice(&bytes).unwrap();
        let errors: Vec<String> = meta_schema.iter_errors(&json).map(|e| e.to_string()).collect();
        assert!(errors.is_empty(), "{name}: v.render.json against the schema: {errors:?}");
        let meta: insgen::blender::run::FrameMeta = serde_json::from_slice(&bytes).unwrap();
        assert_eq!(meta.look, FrameLook::draw(&ranges, p.look_seed, "v").unwrap(), "{name}");
        (meta.look, std::fs::read(p.out_dir.join("v.png")).unwrap(), p)
    };
    let mut base = LookRanges::defaults(35.0);
    base.sun = SunRange::Angles { azimuth_deg: [150.0, 150.0], elevation_deg: [45.0, 45.0] };
    base.camera_effects = false;
    base.exposure_jitter_ev = 0.0;
    base.white_balance_k = [6500.0, 6500.0];
    let clear = LookRanges { sky_weights: [1.0, 0.0, 0.0], ..base };
    let overcast = LookRanges { sky_weights: [0.0, 0.0, 1.0], ..base };
    let (lc, png_clear, _) = render("clear", clear);
    let (lo, png_overcast, _) = render("overcast", overcast);
    assert_eq!((lc.sky, lo.sky), (Sky::Clear, Sky::Overcast));
    let (_, _, rgb_clear) = read_rgb_png_bytes(&png_clear);
    let (_, _, rgb_overcast) = read_rgb_png_bytes(&png_overcast);
    let (mc, sc) = (picture_stats(&rgb_clear).0, saturation(&rgb_clear));
    let (mo, so) = (picture_stats(&rgb_overcast).0, saturation(&rgb_overcast));
    eprintln!("clear: mean {mc:.1}, saturation {sc:.3}; overcast: mean {mo:.1}, saturation {so:.3}");
    // Grey cloud light and haze: a darker, greyer picture.
    assert!(mo < mc - 5.0 && so < 0.9 * sc, "overcast {mo} {so} vs clear {mc} {sc}");
    // White balance: the same clear frame through a camera set to 4000 K and to 9000 K.
    let (_, cool, _) = render("cool", LookRanges { white_balance_k: [4000.0, 4000.0], ..clear });
    let (_, warm, _) = render("warm", LookRanges { white_balance_k: [9000.0, 9000.0], ..clear });
    let (_, _, br_clear) = picture_stats(&rgb_clear);
    let (_, _, br_cool) = picture_stats(&read_rgb_png_bytes(&cool).2);
    let (_, _, br_warm) = picture_stats(&read_rgb_png_bytes(&warm).2);
    eprintln!("blue/red: 4000 K {br_cool:.3}, neutral {br_clear:.3}, 9000 K {br_warm:.3}");
    assert!(br_cool > 1.1 * br_clear && br_warm < 0.93 * br_clear, "{br_cool} {br_clear} {br_warm}");
    // All effects on (noise, blur, vignetting, JPEG): a rerender reproduces the bytes; plain differs.
    let all = LookRanges { camera_effects: true, jpeg_quality: Some([70, 90]), ..LookRanges::defaults(35.0) };
    let (la, first, mut p) = render("all", all);
    assert!(la.camera.noise_sigma > 0.0 && la.camera.jpeg_quality.is_some());
    render_frames(&p, std::slice::from_ref(&frame), &NoProgress).unwrap();
    assert!(
        std::fs::read(p.out_dir.join("v.png")).unwrap() == first,
        "the varied look must rerender exactly"
    );
    p.look = LookRanges::plain(35.0);
    render_frames(&p, std::slice::from_ref(&frame), &NoProgress).unwrap();
    assert!(std::fs::read(p.out_dir.join("v.png")).unwrap() != first);
}

#[test]
fn rgb_job_renders_resumes_and_repeats_exactly() {
    let Some(py) = blender_python() else { return };
    let dir = tempfile::tempdir().unwrap();
    let boxes = box_city();
    let glb = write_scene_glb(dir.path(), &boxes);
    let mut p =
        plan(&py, dir.path(), Mode::Rgb, SceneSource::Lod { glb, enu_from_gltf: ENU_FROM_SCENE_GLTF });
    p.restart_every = 1;
    p.exr = true;
    let k = Intrinsics::from_hfov(64, 48, 50.0);
    let frames = vec![
        FrameRequest {
            name: "a".into(),
            intrinsics: k,
            pose: Pose::from_ypr_deg(0.0, 0.0, 0.0, [0.0, 0.0, 120.0]),
        },
        FrameRequest {
            name: "b".into(),
            intrinsics: k,
            pose: Pose::from_ypr_deg(200.0, 45.0, 0.0, [40.0, 60.0, 110.0]),
        },
    ];
    let s = render_frames(&p, &frames, &NoProgress).unwrap();
    assert_eq!(s.rendered.len(), 2);
    assert_eq!(s.setup_seconds.len(), 2, "restart_every = 1 must start one process per frame");
    for f in &frames {
        let (w, h, rgb) = read_rgb_png(&p.out_dir.join(format!("{}.png", f.name)));
        assert_eq!((w, h), (64, 48));
        // Not flat: buildings, ground and sky differ. Mean absolute deviation of luma above 5 levels.
        let luma: Vec<f64> = rgb
            .chunks_exact(3)
            .map(|c| 0.2126 * c[0] as f64 + 0.7152 * c[1] as f64 + 0.0722 * c[2] as f64)
            .collect();
        let mean = luma.iter().sum::<f64>() / luma.len() as f64;
        let mad = luma.iter().map(|v| (v - mean).abs()).sum::<f64>() / luma.len() as f64;
        assert!(mad > 5.0 && mean > 20.0 && mean < 235.0, "{}: mean {mean}, deviation {mad}", f.name);
        // The picture is aligned with the buildings: neighbouring pixels on either side of a reference ID
        // boundary differ in colour much more than neighbours within one ID region, and less so when the
        // reference is shifted by 2 px (a misaligned camera).
        let ids = reference_ids(&boxes, &f.intrinsics, &f.pose);
        let aligned = boundary_contrast(&rgb, &ids, w as usize, h as usize);
        let shifted: Vec<u32> =
            (0..ids.len()).map(|i| if i % w as usize >= 2 { ids[i - 2] } else { ids[i] }).collect();
        let misaligned = boundary_contrast(&rgb, &shifted, w as usize, h as usize);
        eprintln!("{}: boundary contrast {aligned:.2} aligned, {misaligned:.2} shifted by 2 px", f.name);
        assert!(aligned > 1.5 && aligned > misaligned + 0.3, "{}: {aligned} vs {misaligned}", f.name);
        assert!(p.out_dir.join(format!("{}.exr", f.name)).is_file());
    }
    let first = std::fs::read(p.out_dir.join("b.png")).unwrap();
    let first_exr = std::fs::read(p.out_dir.join("b.exr")).unwrap();
    // Resume: nothing to do, Blender is not started.
    let s = render_frames(&p, &frames, &NoProgress).unwrap();
    assert_eq!((s.rendered.len(), s.skipped.len(), s.setup_seconds.len()), (0, 2, 0));
    // Determinism: forcing a rerender reproduces the bytes.
    p.force = true;
    render_frames(&p, &frames[1..], &NoProgress).unwrap();
    assert!(std::fs::read(p.out_dir.join("b.png")).unwrap() == first, "PNG rerender differs");
    assert!(std::fs::read(p.out_dir.join("b.exr")).unwrap() == first_exr, "EXR rerender differs");
    // Resume after the poses changed (e.g. `sample` ran again): only the moved frame is redone.
    p.force = false;
    let mut moved = frames.clone();
    moved[0].pose = Pose::from_ypr_deg(30.0, 0.0, 0.0, [5.0, 0.0, 120.0]);
    let s = render_frames(&p, &moved, &NoProgress).unwrap();
    assert_eq!((s.rendered.len(), s.skipped.len()), (1, 1), "a moved pose must not reuse its old frame");
    assert_eq!(s.rendered[0].name, "a");
}

/// Mean colour step (sum of |ΔR|, |ΔG|, |ΔB|) between neighbours with different IDs, divided by the
/// mean step between neighbours with the same ID.
fn boundary_contrast(rgb: &[u8], ids: &[u32], w: usize, h: usize) -> f64 {
    let (mut across, mut within) = ((0.0, 0u32), (0.0, 0u32));
    for y in 0..h {
        for x in 0..w {
            for (nx, ny) in [(x + 1, y), (x, y + 1)] {
                if nx >= w || ny >= h {
                    continue;
                }
                let (i, j) = (y * w + x, ny * w + nx);
                let d: f64 = (0..3).map(|c| (rgb[3 * i + c] as f64 - rgb[3 * j + c] as f64).abs()).sum();
                let acc = if ids[i] != ids[j] { &mut across } else { &mut within };
                acc.0 += d;
                acc.1 += 1;
            }
        }
    }
    (across.0 / across.1.max(1) as f64) / (within.0 / within.1.max(1) as f64).max(1e-9)
}

#[test]
fn workbench_engine_renders() {
    let Some(py) = blender_python() else { return };
    let dir = tempfile::tempdir().unwrap();
    let glb = write_scene_glb(dir.path(), &box_city());
    let mut p =
        plan(&py, dir.path(), Mode::Rgb, SceneSource::Lod { glb, enu_from_gltf: ENU_FROM_SCENE_GLTF });
    p.engine = Engine::Workbench;
    let k = Intrinsics::from_hfov(64, 48, 50.0);
    let f = FrameRequest {
        name: "w".into(),
        intrinsics: k,
        pose: Pose::from_ypr_deg(0.0, 0.0, 0.0, [0.0, 0.0, 120.0]),
    };
    render_frames(&p, &[f], &NoProgress).unwrap();
    let (w, h, rgb) = read_rgb_png(&p.out_dir.join("w.png"));
    assert_eq!((w, h), (64, 48));
    assert!(rgb.iter().any(|&v| v != rgb[0]), "flat image");
}

#[test]
fn corrupt_model_fails_with_blender_output_and_no_partial_frame() {
    let Some(py) = blender_python() else { return };
    let dir = tempfile::tempdir().unwrap();
    let glb = dir.path().join("scene.glb");
    std::fs::write(&glb, b"glTF\x02\x00\x00\x00garbage that is not a glb").unwrap();
    let p = plan(&py, dir.path(), Mode::Ids, SceneSource::Lod { glb, enu_from_gltf: ENU_FROM_SCENE_GLTF });
    let f = &test_frames()[0];
    let e = render_frames(&p, std::slice::from_ref(f), &NoProgress).unwrap_err();
    let text = e.to_string();
    assert!(text.starts_with("Blender failed: `"), "{text}");
    assert!(text.contains("render_rgb.py") && text.contains("job-ids-nadir_offcentre.json"), "{text}");
    assert!(text.contains("exit status 1") && text.contains("stderr (last"), "{text}");
    let files: Vec<_> = std::fs::read_dir(&p.out_dir).unwrap().collect();
    assert!(files.is_empty(), "partial outputs left: {files:?}");
}

#[test]
fn missing_tile_content_fails_before_blender_starts() {
    // No interpreter needed: the error comes from preparing the tiles.
    let dir = tempfile::tempdir().unwrap();
    let enu = EnuFrame::new(Geodetic::new(35.0, 139.0, 50.0));
    let ts = serde_json::json!({
        "asset": {"version": "1.0"}, "geometricError": 0,
        "root": {"transform": col_major(&enu.ecef_from_enu()), "boundingVolume": {"sphere": [0, 0, 0, 100]}, "geometricError": 0, "content": {"uri": "gone.b3dm"}}
    });
    let ts_path = dir.path().join("tileset.json");
    std::fs::write(&ts_path, serde_json::to_vec(&ts).unwrap()).unwrap();
    let mut p = plan(
        Path::new("/nonexistent/python"),
        dir.path(),
        Mode::Rgb,
        SceneSource::Tileset { tileset: ts_path, enu, select: SelectOptions::default() },
    );
    p.restart_every = 1;
    let e = render_frames(&p, &test_frames()[..1], &NoProgress).unwrap_err().to_string();
    assert!(e.contains("gone.b3dm"), "{e}");
    assert_eq!(std::fs::read_dir(&p.out_dir).unwrap().count(), 0);
}

#[test]
fn shibuya_tiles_land_inside_their_regions() {
    let Some(ts_path) = shared_data("jp_tokyo_shibuya_plateau_3dtiles/tileset.json") else { return };
    let Some(py) = blender_python() else { return };
    let dir = tempfile::tempdir().unwrap();
    // Area origin near Shibuya station; a nadir camera 600 m above it sees a handful of tiles.
    let enu = EnuFrame::new(Geodetic::new(35.6580, 139.7016, 40.0));
    let k = Intrinsics::from_hfov(32, 24, 40.0);
    let f = FrameRequest {
        name: "shibuya".into(),
        intrinsics: k,
        pose: Pose::from_ypr_deg(0.0, 0.0, 0.0, [0.0, 0.0, 600.0]),
    };
    let mut p = plan(
        &py,
        dir.path(),
        Mode::Ids,
        SceneSource::Tileset { tileset: ts_path.clone(), enu, select: SelectOptions::default() },
    );
    p.report_bounds = true;
    let s = render_frames(&p, std::slice::from_ref(&f), &NoProgress).unwrap();
    let job: insgen::blender::Job =
        serde_json::from_slice(&std::fs::read(p.work_dir.join("job-ids-shibuya.json")).unwrap()).unwrap();
    assert!(job.models.len() >= 3, "only {} tiles selected", job.models.len());
    assert_eq!(s.bounds.len(), job.models.len());
    // Region of each selected tile, from tileset.json, as an ENU box (corners of the geodetic region).
    let ts: serde_json::Value = serde_json::from_slice(&std::fs::read(&ts_path).unwrap()).unwrap();
    let mut checked = 0;
    for (model, bounds) in job.models.iter().zip(&s.bounds) {
        let stem = model.glb.file_stem().unwrap().to_string_lossy().into_owned();
        let name = stem.split_once('-').unwrap().1.to_string();
        let child = ts["root"]["children"]
            .as_array()
            .unwrap()
            .iter()
            .find(|c| c["content"]["uri"].as_str().unwrap().ends_with(&format!("{name}.b3dm")))
            .unwrap();
        let r: Vec<f64> = child["boundingVolume"]["region"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_f64().unwrap())
            .collect();
        let mut lo = [f64::INFINITY; 3];
        let mut hi = [f64::NEG_INFINITY; 3];
        for lat in [r[1], r[3], 0.5 * (r[1] + r[3])] {
            for lon in [r[0], r[2], 0.5 * (r[0] + r[2])] {
                for h in [r[4], r[5]] {
                    let e = enu.geodetic_to_enu(Geodetic::new(lat.to_degrees(), lon.to_degrees(), h));
                    for a in 0..3 {
                        lo[a] = lo[a].min(e[a]);
                        hi[a] = hi[a].max(e[a]);
                    }
                }
            }
        }
        let [bmin, bmax] = bounds.expect("tile has vertices");
        // 1 m tolerance: float32 vertices and the region's own rounding.
        for a in 0..3 {
            assert!(
                bmin[a] >= lo[a] - 1.0 && bmax[a] <= hi[a] + 1.0,
                "{name} axis {a}: [{}, {}] outside region [{}, {}]",
                bmin[a],
                bmax[a],
                lo[a],
                hi[a]
            );
        }
        // And it fills its region (the region is the tight box of the tile's content).
        assert!(
            bmax[2] - bmin[2] > 0.8 * (hi[2] - lo[2]) - 2.0,
            "{name}: height {} vs region {}",
            bmax[2] - bmin[2],
            hi[2] - lo[2]
        );
        checked += 1;
    }
    eprintln!("{checked} Shibuya tiles inside their regions");
}

/// Seconds per frame for cam2 (1920×1080, 25° HFOV) over a dense box city, Cycles CPU.
/// `INSGEN_BENCH_SAMPLES` (default 32) sets the samples; the first frame includes shader compilation.
#[test]
#[ignore = "benchmark: several minutes on 2 cores"]
fn bench_cam2_full_resolution() {
    let Some(py) = blender_python() else { return };
    let samples: u32 = std::env::var("INSGEN_BENCH_SAMPLES").ok().and_then(|v| v.parse().ok()).unwrap_or(32);
    let out = std::env::var_os("INSGEN_BENCH_DIR").map(PathBuf::from);
    let tmp = tempfile::tempdir().unwrap();
    let dir = out.as_deref().unwrap_or(tmp.path());
    std::fs::create_dir_all(dir).unwrap();
    // 20 × 20 blocks of varied boxes, 40 m pitch.
    let mut boxes = Vec::new();
    let mut id = 1;
    for i in 0..20 {
        for j in 0..20 {
            let (e, n) = (-400.0 + 40.0 * i as f64, -400.0 + 40.0 * j as f64);
            let h =
                8.0 + ((i * 7 + j * 13) % 17) as f64 * 4.0 + if (i + 2 * j) % 23 == 0 { 80.0 } else { 0.0 };
            let w = 18.0 + ((i * 3 + j) % 5) as f64 * 3.0;
            boxes.push(BoxBuilding::new(id, e, n, e + w, n + 24.0, 0.0, h));
            id += 1;
        }
    }
    let glb = write_scene_glb(dir, &boxes);
    let mut p = plan(&py, dir, Mode::Rgb, SceneSource::Lod { glb, enu_from_gltf: ENU_FROM_SCENE_GLTF });
    p.rgb.samples = samples;
    p.rgb.denoise = std::env::var("INSGEN_BENCH_DENOISE").map(|v| v == "1").unwrap_or(false);
    p.threads = 0;
    p.force = true;
    // INSGEN_BENCH_RES=WxH renders the same camera at another resolution (for quick looks).
    let (w, h) = std::env::var("INSGEN_BENCH_RES")
        .ok()
        .and_then(|v| v.split_once('x').and_then(|(a, b)| Some((a.parse().ok()?, b.parse().ok()?))))
        .unwrap_or((1920, 1080));
    let k = Intrinsics::from_hfov(1920, 1080, 25.0).scaled_to(w, h);
    let frames = vec![
        FrameRequest {
            name: "cam2_nadir".into(),
            intrinsics: k,
            pose: Pose::from_ypr_deg(30.0, 0.0, 0.0, [0.0, 0.0, 350.0]),
        },
        FrameRequest {
            name: "cam2_tilt45".into(),
            intrinsics: k,
            pose: Pose::from_ypr_deg(30.0, 45.0, 0.0, [-200.0, -300.0, 300.0]),
        },
    ];
    let s = render_frames(&p, &frames, &NoProgress).unwrap();
    for t in &s.rendered {
        eprintln!(
            "bench cam2 {}x{} cycles cpu {samples} spp denoise={}: {} {:.1} s wall, {:.1} s cpu",
            k.width_px, k.height_px, p.rgb.denoise, t.name, t.seconds, t.cpu_seconds
        );
    }
    eprintln!("scene set-up {:?} s; outputs in {}", s.setup_seconds, p.out_dir.display());
}

#[test]
fn job_files_follow_the_schema() {
    // The launcher does not exist, so the run stops right after writing the job file; the job is then
    // checked against schemas/blender_job.schema.json (ID mode with a scene, RGB mode with a tileset).
    let schema: serde_json::Value = serde_json::from_slice(
        &std::fs::read(Path::new(env!("CARGO_MANIFEST_DIR")).join("schemas/blender_job.schema.json"))
            .unwrap(),
    )
    .unwrap();
    let validator = jsonschema::validator_for(&schema).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let glb = write_scene_glb(dir.path(), &box_city());
    let no_python = Path::new("/nonexistent/python");
    let mut jobs = Vec::new();
    for mode in [Mode::Ids, Mode::Rgb] {
        let mut p = plan(
            no_python,
            dir.path(),
            mode,
            SceneSource::Lod { glb: glb.clone(), enu_from_gltf: ENU_FROM_SCENE_GLTF },
        );
        p.exr = true;
        if mode == Mode::Rgb {
            p.contrast = Some(insgen::blender::look::BuildingContrast {
                classes: 4,
                building_classes: vec![[1, 0], [3, 2], [70_000, 1]],
            });
        }
        assert!(render_frames(&p, &test_frames(), &NoProgress).is_err());
        let name =
            if mode == Mode::Ids { "job-ids-nadir_offcentre.json" } else { "job-rgb-nadir_offcentre.json" };
        jobs.push(p.work_dir.join(name));
    }
    for path in jobs {
        let job: serde_json::Value = serde_json::from_slice(&std::fs::read(&path).unwrap()).unwrap();
        let errors: Vec<String> =
            validator.iter_errors(&job).map(|e| format!("{} at {}", e, e.instance_path)).collect();
        assert!(errors.is_empty(), "{}: {errors:#?}", path.display());
        assert_eq!(job["frames"].as_array().unwrap().len(), 3);
    }
    // And the schema rejects what the script would refuse.
    let mut bad: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.path().join("work/job-ids-nadir_offcentre.json")).unwrap())
            .unwrap();
    bad["frames"][0]["camera"]["pixel_aspect_x"] = serde_json::json!(0.5);
    bad["mode"] = serde_json::json!("depth");
    assert_eq!(validator.iter_errors(&bad).count(), 2);
}

/// Writes a 24-bit ID PNG (R = bits 16–23, G = 8–15, B = 0–7), the mask renderer's format.
fn write_id_png(path: &Path, w: u32, h: u32, ids: &[u32]) {
    let bytes: Vec<u8> = ids.iter().flat_map(|v| [(v >> 16) as u8, (v >> 8) as u8, *v as u8]).collect();
    let mut out = Vec::new();
    {
        let mut enc = png::Encoder::new(&mut out, w, h);
        enc.set_color(png::ColorType::Rgb);
        enc.set_depth(png::BitDepth::Eight);
        enc.write_header().unwrap().write_image_data(&bytes).unwrap();
    }
    std::fs::write(path, out).unwrap();
}

#[test]
fn cli_renders_rgb_and_checks_alignment_against_masks() {
    use clap::Parser;
    use insgen::camera::{PoseRecord, Trajectory};
    use insgen::cli::render_rgb::{run, Args};
    use insgen::scene::artifact::{GeoidUsed, Manifest, Origin};

    #[derive(Parser)]
    struct Wrap {
        #[command(flatten)]
        args: Args,
    }
    let Some(py) = blender_python() else { return };
    let work = tempfile::tempdir().unwrap();
    let scene_dir = work.path().join("demo/scene");
    let cam_dir = work.path().join("demo/cam9");
    std::fs::create_dir_all(&scene_dir).unwrap();
    std::fs::create_dir_all(cam_dir.join("masks")).unwrap();
    let boxes = box_city();
    write_scene_glb(&scene_dir, &boxes);
    let origin = Origin { lat_deg: 35.0, lon_deg: 139.0, h_m: 40.0 };
    let enu = EnuFrame::new(Geodetic::new(origin.lat_deg, origin.lon_deg, origin.h_m));
    let manifest = Manifest {
        insgen_version: "test".into(),
        area: "demo".into(),
        split: "test".into(),
        origin,
        ecef_from_enu: enu.ecef_from_enu(),
        area_polygon_enu_m: vec![[-100.0, -100.0], [100.0, -100.0], [100.0, 100.0], [-100.0, 100.0]],
        ground_enu_m: 0.0,
        geoid: GeoidUsed {
            model: "none".into(),
            grid: None,
            undulation_at_origin_m: 0.0,
            ..Default::default()
        },
        sources: vec![],
        buildings: boxes.len() as u64,
        triangles: 12 * boxes.len() as u64,
        degenerate_faces: 0,
        attributions: vec![],
        clutter: None,
        alignment: None,
    };
    std::fs::write(scene_dir.join("manifest.json"), serde_json::to_vec_pretty(&manifest).unwrap()).unwrap();
    // Poses and the "masks" (the f64 reference standing in for the wgpu renderer's ID maps).
    let mut lines = String::new();
    for (i, f) in test_frames().iter().enumerate() {
        let rec = PoseRecord::new(
            f.name.clone(),
            "demo",
            "cam9",
            Trajectory::Grid,
            i as u32,
            0,
            f.intrinsics,
            &f.pose,
            &enu,
            0.0,
        );
        lines.push_str(&serde_json::to_string(&rec).unwrap());
        lines.push('\n');
        let ids = reference_ids(&boxes, &f.intrinsics, &f.pose);
        write_id_png(
            &cam_dir.join(format!("masks/{}.png", f.name)),
            f.intrinsics.width_px,
            f.intrinsics.height_px,
            &ids,
        );
    }
    std::fs::write(cam_dir.join("poses.jsonl"), lines).unwrap();
    let global = insgen::cli::Global {
        workdir: work.path().to_path_buf(),
        scenes: "scenes".into(),
        verbose: 0,
        quiet: true,
        no_progress: true,
        log_every: 30.0,
    };
    let py_s = py.to_string_lossy().into_owned();
    let parse = |extra: &[&str]| {
        let mut v =
            vec!["x", "--area", "demo", "--camera", "cam9", "--blender-python", &py_s, "--threads", "2"];
        v.extend_from_slice(extra);
        Wrap::try_parse_from(v).unwrap().args
    };
    // Alignment: IDs from Blender against the masks, report written, targets met.
    run(&parse(&["--check-alignment"]), &global).unwrap();
    let report: serde_json::Value =
        serde_json::from_slice(&std::fs::read(cam_dir.join("alignment/report.json")).unwrap()).unwrap();
    assert_eq!(report["frames"], 3);
    assert_eq!(report["pass"], true);
    assert!(std::fs::read_to_string(cam_dir.join("alignment/report.md"))
        .unwrap()
        .contains("**Result: PASS**"));
    // A corrupted mask makes the check fail with the report's path in the message.
    let f0 = &test_frames()[0];
    let mut ids = reference_ids(&boxes, &f0.intrinsics, &f0.pose);
    for v in ids.iter_mut().step_by(3) {
        *v = 0;
    }
    write_id_png(
        &cam_dir.join("masks/nadir_offcentre.png"),
        f0.intrinsics.width_px,
        f0.intrinsics.height_px,
        &ids,
    );
    let e = run(&parse(&["--check-alignment"]), &global).unwrap_err().to_string();
    assert!(e.contains("alignment below target") && e.contains("report.md"), "{e}");
    // RGB through the CLI: the second shard of two gets frame 1 only.
    run(&parse(&["--shard", "1/2", "--samples", "2", "--no-denoise"]), &global).unwrap();
    let mut rgb: Vec<String> = std::fs::read_dir(cam_dir.join("rgb"))
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    rgb.sort();
    assert_eq!(rgb, ["tilt45.png", "tilt45.render.json"], "the frame and its render metadata");
}

/// PSNR (dB, 8-bit RGB, peak 255) between two PNGs of the same size.
fn psnr_db(a: &Path, b: &Path) -> f64 {
    let a = insgen::export::raster::read_png_rgb(a).unwrap();
    let b = insgen::export::raster::read_png_rgb(b).unwrap();
    assert_eq!((a.width, a.height), (b.width, b.height));
    let n = a.data.len() as f64;
    let mse = a.data.iter().zip(&b.data).map(|(&x, &y)| (x as f64 - y as f64).powi(2)).sum::<f64>() / n;
    10.0 * (255.0f64 * 255.0 / mse.max(1e-12)).log10()
}

/// The direct-lighting look has no stochastic term but anti-aliasing: two 1-sample renders with
/// different seeds agree far better than two path-traced ones, whose sky light and bounces are noise.
/// And the two looks are different images (the switch reaches the script).
#[test]
fn direct_lighting_is_noise_free_but_for_anti_aliasing() {
    let Some(py) = blender_python() else { return };
    let dir = tempfile::tempdir().unwrap();
    let glb = write_scene_glb(dir.path(), &box_city());
    let frame = FrameRequest {
        name: "f".into(),
        intrinsics: Intrinsics::from_hfov(160, 120, 60.0),
        pose: Pose::from_ypr_deg(30.0, 50.0, 0.0, [-40.0, -60.0, 90.0]),
    };
    let mut png = std::collections::BTreeMap::new();
    for lighting in [Lighting::Direct, Lighting::Path] {
        for seed in [1u32, 2] {
            let run = dir.path().join(format!("{}-{seed}", lighting.name()));
            let mut p = plan(
                &py,
                &run,
                Mode::Rgb,
                SceneSource::Lod { glb: glb.clone(), enu_from_gltf: ENU_FROM_SCENE_GLTF },
            );
            (p.rgb.samples, p.seed, p.rgb.lighting, p.rgb.max_bounces) = (1, seed, lighting, 2);
            render_frames(&p, std::slice::from_ref(&frame), &NoProgress).unwrap();
            png.insert((lighting.name(), seed), p.out_dir.join("f.png"));
        }
    }
    let direct = psnr_db(&png[&("direct", 1)], &png[&("direct", 2)]);
    let path = psnr_db(&png[&("path", 1)], &png[&("path", 2)]);
    let looks = psnr_db(&png[&("direct", 1)], &png[&("path", 1)]);
    eprintln!("seed-to-seed PSNR: direct {direct:.1} dB, path {path:.1} dB; direct vs path {looks:.1} dB");
    assert!(direct > path + 8.0, "direct {direct:.1} dB vs path {path:.1} dB");
    assert!(looks < direct - 3.0, "the looks differ: {looks:.1} dB vs {direct:.1} dB between direct seeds");
}

/// Neighbour contrast (issue 37's data fix): a row of identical touching houses, nadir. With contrast
/// classes 0 1 2 3 0 1 2 3 along the row, each roof's mean luma follows its class (the palette band and a
/// brightness step), so every shared wall is an edge in the photo.
#[test]
fn touching_houses_get_roofs_of_their_contrast_class() {
    let Some(py) = blender_python() else { return };
    let dir = tempfile::tempdir().unwrap();
    let row: Vec<BoxBuilding> = (0..8)
        .map(|k| {
            BoxBuilding::new(k + 1, -40.0 + 10.0 * k as f64, -6.0, -30.0 + 10.0 * k as f64, 6.0, 0.0, 10.0)
        })
        .collect();
    let glb = write_scene_glb(dir.path(), &row);
    let mut p =
        plan(&py, dir.path(), Mode::Rgb, SceneSource::Lod { glb, enu_from_gltf: ENU_FROM_SCENE_GLTF });
    p.contrast = Some(insgen::blender::look::BuildingContrast {
        classes: 4,
        building_classes: (0..8).map(|k| [k + 1, k % 4]).collect(),
    });
    let k = Intrinsics::from_hfov(160, 48, 40.0);
    let f = FrameRequest {
        name: "row".into(),
        intrinsics: k,
        pose: Pose::from_ypr_deg(0.0, 0.0, 0.0, [0.0, 0.0, 130.0]),
    };
    render_frames(&p, std::slice::from_ref(&f), &NoProgress).unwrap();
    let (w, _h, rgb) = read_rgb_png(&p.out_dir.join("row.png"));
    let ids = reference_ids(&row, &f.intrinsics, &f.pose);
    // Mean luma of each roof, away from its edges (2 px inside).
    let mut sum = [(0.0f64, 0u32); 9];
    for (i, &id) in ids.iter().enumerate() {
        let (x, y) = ((i % w as usize) as i64, (i / w as usize) as i64);
        let inside = (-2..=2).all(|d: i64| {
            let (xx, yy) =
                ((x + d).clamp(0, w as i64 - 1), (y + d).clamp(0, ids.len() as i64 / w as i64 - 1));
            ids[(y * w as i64 + xx) as usize] == id && ids[(yy * w as i64 + x) as usize] == id
        });
        if id != 0 && inside {
            let c = &rgb[3 * i..3 * i + 3];
            sum[id as usize].0 += 0.2126 * c[0] as f64 + 0.7152 * c[1] as f64 + 0.0722 * c[2] as f64;
            sum[id as usize].1 += 1;
        }
    }
    let luma: Vec<f64> = (1..=8).map(|id| sum[id].0 / sum[id].1.max(1) as f64).collect();
    eprintln!("roof luma along the row (classes 0 1 2 3 0 1 2 3): {luma:.1?}");
    assert!(sum[1..].iter().all(|s| s.1 > 20), "roofs not seen: {sum:?}");
    for pair in luma.windows(2).take(3).chain(luma[4..].windows(2)) {
        assert!(pair[1] > pair[0] + 3.0, "a higher class must be lighter: {luma:.1?}");
    }
    assert!(luma.windows(2).all(|p| (p[1] - p[0]).abs() > 3.0), "touching roofs alike: {luma:.1?}");
}
