//! Instance-ID rendering throughput (issue 4): frames/s at 1920×1080 and 640×360 on a synthetic dense
//! city, for the render alone (frames in flight, read back to the CPU) and for the whole render-masks
//! stage (render + connected components + PNG + JSON, written atomically). Also the CPU costs per frame
//! of labelling and PNG encoding. Writes `bench/render_report.md`.
//!
//! `cargo bench --bench render_ids` (add `-- --quick` for a short run). The timing hook used here,
//! `insgen::render::time_render`, is what a side-by-side comparison with Blender calls.

use std::hint::black_box;
use std::path::Path;
use std::time::Instant;

use insgen::camera::{Intrinsics, Pose, PoseRecord, Trajectory};
use insgen::geo::{EnuFrame, Geodetic};
use insgen::label::stage::{self, MaskPlan};
use insgen::label::{label_components, Connectivity};
use insgen::render::{time_render, RenderOptions, Renderer, View};
use insgen::scene::artifact::{GeoidUsed, Origin};
use insgen::scene::{BuildingId, BuildingRecord, Manifest, PreparedScene, SceneMesh};
use insgen::util::NoProgress;

/// Deterministic pseudo-random numbers (SplitMix64) so every run renders the same city.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> f64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        ((z ^ (z >> 31)) >> 11) as f64 / (1u64 << 53) as f64
    }
}

fn push_box(m: &mut SceneMesh, id: BuildingId, min: [f64; 3], max: [f64; 3]) {
    let base = m.positions_m.len() as u32;
    for c in 0..8usize {
        m.positions_m.push([0, 1, 2].map(|a| if c >> a & 1 == 0 { min[a] as f32 } else { max[a] as f32 }));
        m.building_ids.push(id);
    }
    for f in [[0, 2, 6, 4], [1, 3, 7, 5], [0, 1, 5, 4], [2, 3, 7, 6], [0, 1, 3, 2], [4, 5, 7, 6]] {
        let [a, b, c, d] = f.map(|i: u32| base + i);
        m.indices.extend_from_slice(&[a, b, c, a, c, d]);
    }
}

/// A dense synthetic city: `side × side` blocks of 25 m pitch, each building a podium plus a tower
/// (two boxes, 24 triangles), heights 8–120 m with a few landmarks.
fn city(side: u32) -> (SceneMesh, Vec<BuildingRecord>) {
    let mut rng = Rng(42);
    let mut m = SceneMesh::default();
    let mut table = Vec::new();
    let half = side as f64 * 25.0 / 2.0;
    for j in 0..side {
        for i in 0..side {
            let id = BuildingId::from_index((j * side + i) as usize).expect("a small synthetic city");
            let (x, y) = (i as f64 * 25.0 - half, j as f64 * 25.0 - half);
            let (w, d) = (14.0 + 8.0 * rng.next(), 14.0 + 8.0 * rng.next());
            let h = 8.0 + 40.0 * rng.next() + if rng.next() < 0.05 { 80.0 } else { 0.0 };
            push_box(&mut m, id, [x, y, 0.0], [x + w, y + d, 0.4 * h]);
            push_box(&mut m, id, [x + 0.2 * w, y + 0.2 * d, 0.4 * h], [x + 0.8 * w, y + 0.8 * d, h]);
            table.push(BuildingRecord {
                id,
                source_id: format!("synthetic_{id}"),
                source_file: "synthetic".into(),
                lod: "1".into(),
                height_m: h,
                measured_height_m: None,
                footprint_area_m2: w * d,
                centroid_lat_deg: 0.0,
                centroid_lon_deg: 0.0,
                bbox_min_enu_m: [x, y, 0.0],
                bbox_max_enu_m: [x + w, y + d, h],
                triangles: 24,
            });
        }
    }
    (m, table)
}

/// `n` poses over the city: 300 m up, alternating nadir and 45°, yaw turning.
fn poses(n: usize, spread_m: f64) -> Vec<Pose> {
    let mut rng = Rng(7);
    (0..n)
        .map(|i| {
            let c = [(rng.next() - 0.5) * spread_m, (rng.next() - 0.5) * spread_m, 300.0];
            Pose::from_ypr_deg(rng.next() * 360.0, if i % 2 == 0 { 0.0 } else { 45.0 }, 0.0, c)
        })
        .collect()
}

fn prepared(mesh: SceneMesh, buildings: Vec<BuildingRecord>, enu: &EnuFrame) -> PreparedScene {
    let n = buildings.len() as u64;
    let t = mesh.triangle_count() as u64;
    PreparedScene {
        manifest: Manifest {
            insgen_version: env!("CARGO_PKG_VERSION").into(),
            area: "synthetic".into(),
            split: "test".into(),
            origin: Origin { lat_deg: 35.658, lon_deg: 139.701, h_m: 40.0 },
            ecef_from_enu: enu.ecef_from_enu(),
            area_polygon_enu_m: vec![],
            ground_enu_m: 0.0,
            geoid: GeoidUsed {
                model: "none".into(),
                grid: None,
                undulation_at_origin_m: 0.0,
                ..Default::default()
            },
            sources: vec![],
            buildings: n,
            triangles: t,
            degenerate_faces: 0,
            attributions: vec![],
            clutter: None,
            alignment: None,
        },
        buildings,
        mesh,
        clutter: Default::default(),
    }
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn main() {
    let quick = std::env::args().any(|a| a == "--quick");
    let renderer = Renderer::new().expect("a GPU adapter (lavapipe is enough)");
    let (mesh, table) = city(if quick { 20 } else { 36 });
    let triangles = mesh.triangle_count();
    let buildings = table.len();
    let gpu = renderer.upload(&mesh).expect("upload");
    let enu = EnuFrame::new(Geodetic::new(35.658, 139.701, 40.0));
    let cam2 = Intrinsics::from_hfov(1920, 1080, 25.0);
    // 640×360 with a wider lens (eval-loc style small masks of a cam1-like view).
    let small = Intrinsics::from_hfov(640, 360, 45.0);
    let (n_big, n_small) = if quick { (6, 12) } else { (24, 60) };
    let spread = 25.0 * if quick { 20.0 } else { 36.0 } * 0.6;
    let mut rows = Vec::new();
    let mut notes = Vec::new();

    for (label, k, n) in [("1920×1080 (cam2, 25°)", cam2, n_big), ("640×360 (45°)", small, n_small)] {
        let views: Vec<View> =
            poses(n, spread).into_iter().map(|pose| View { intrinsics: k, pose }).collect();
        // Warm-up: pipeline compilation, target allocation.
        time_render(&renderer, &gpu, &views[..2], &RenderOptions::default()).expect("render");
        let t = time_render(&renderer, &gpu, black_box(&views), &RenderOptions::default()).expect("render");
        black_box(t.building_px);
        rows.push(format!(
            "| render IDs only | {label} | {n} | {:.2} | {:.1} |",
            t.frames_per_s(),
            1e3 * t.median_frame_s()
        ));

        // CPU work per frame: labelling and PNG encoding of a rendered frame.
        let img = renderer.render(&gpu, &views[1], &RenderOptions::default()).expect("render");
        let mut cc = Vec::new();
        let mut enc = Vec::new();
        let mut png_bytes = 0;
        for _ in 0..5 {
            let s = Instant::now();
            black_box(label_components(black_box(&img.ids), Connectivity::Eight));
            cc.push(s.elapsed().as_secs_f64());
            let s = Instant::now();
            png_bytes = black_box(img.ids.encode_png().expect("png")).len();
            enc.push(s.elapsed().as_secs_f64());
        }
        notes.push(format!(
            "- {label}: connected components {:.1} ms/frame, ID PNG encode {:.1} ms/frame ({} kB)",
            1e3 * median(cc),
            1e3 * median(enc),
            png_bytes / 1000
        ));

        // The whole stage: render + CC + PNG + JSON (atomic writes), CPU work overlapped with rendering.
        let dir = tempfile::tempdir().expect("temp dir");
        let cam_dir = dir.path().join("synthetic/bench");
        std::fs::create_dir_all(&cam_dir).expect("mkdir");
        let lines: String = views
            .iter()
            .enumerate()
            .map(|(i, v)| {
                let rec = PoseRecord::new(
                    format!("f{i:04}"),
                    "synthetic",
                    "bench",
                    Trajectory::Grid,
                    i as u32,
                    0,
                    k,
                    &v.pose,
                    &enu,
                    0.0,
                );
                serde_json::to_string(&rec).expect("json") + "\n"
            })
            .collect();
        std::fs::write(cam_dir.join("poses.jsonl"), lines).expect("write poses");
        let scene = prepared(mesh.clone(), table.clone(), &enu);
        let report =
            stage::render_masks(&MaskPlan::new(cam_dir), &scene, &renderer, &NoProgress).expect("stage");
        assert_eq!(report.rendered, n);
        rows.push(format!(
            "| render + CC + PNG + JSON (stage) | {label} | {n} | {:.2} | {:.1} |",
            report.frames_per_s,
            1e3 / report.frames_per_s
        ));
    }

    let load = std::fs::read_to_string("/proc/loadavg").unwrap_or_default();
    let cpus = std::thread::available_parallelism().map(|n| n.get()).unwrap_or(0);
    let report = format!(
        "# Instance-ID rendering benchmark\n\n\
         Generated by `cargo bench --bench render_ids{}`.\n\n\
         - adapter: {}\n- build: {}\n- CPU threads: {cpus}; load average at the end: {}\
         - scene: synthetic dense city, {buildings} buildings, {triangles} triangles (podium + tower per \
         block, 25 m pitch)\n- poses: 300 m above ground, alternating nadir and 45° tilt, random yaw\n\n\
         | what | frame size | frames | frames/s | ms/frame |\n|---|---|---|---|---|\n{}\n\n\
         CPU work per frame (single thread, median of 5):\n{}\n\n\
         Blender side by side on the real areas: `cargo bench --bench versus_blender` \
         (bench/versus_blender.md).\n",
        if quick { " -- --quick" } else { "" },
        renderer.adapter(),
        if cfg!(debug_assertions) {
            "test/dev profile (debug assertions on; insgen opt-level 1, dependencies opt-level 2)"
        } else {
            "bench profile (release)"
        },
        load.trim_end().to_string() + "\n",
        rows.join("\n"),
        notes.join("\n"),
    );
    let out = Path::new(env!("CARGO_MANIFEST_DIR")).join("bench/render_report.md");
    insgen::util::write_bytes_atomic(&out, report.as_bytes()).expect("write report");
    println!("{report}");
    println!("written to {}", out.display());
}
