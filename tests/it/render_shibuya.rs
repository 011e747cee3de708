//! Real data: the prepared Shibuya scene (PLATEAU 3D Tiles, `insgen prepare --area tokyo`) rendered
//! building by building must agree with the camera's own f64 projection of the building's triangles:
//! every pixel whose centre is more than 0.5 px from all projected triangle edges must be covered
//! exactly when the f64 projection covers it, i.e. the rendered silhouette lies within 0.5 px of the
//! projected one.
//!
//! It also holds the Shibuya half of the CPU-rasteriser agreement check (`render_cpu_agreement.rs`).
//! The scene is prepared once per test binary from `scenes/tokyo.toml` (../shared/data; skipped with
//! a printed reason when absent, a failure under CI=true).

use crate::render_common;
use crate::util;

use std::sync::OnceLock;

use insgen::camera::{Intrinsics, Pose};
use insgen::render::{RenderOptions, View};
use insgen::scene::{BuildingId, PreparedScene, SceneMesh};
use render_common::{assert_cpu_agrees_with_wgpu, poses_at_tallest, renderer};

/// The prepared Shibuya scene, shared by the tests of this binary (None when the data is absent).
fn shibuya() -> Option<&'static PreparedScene> {
    static SCENE: OnceLock<Option<PreparedScene>> = OnceLock::new();
    SCENE
        .get_or_init(|| {
            util::shared_data("jp_tokyo_shibuya_plateau_3dtiles/tileset.json")?;
            let dir = tempfile::tempdir().expect("temp dir");
            Some(util::prepare_repo_scene("tokyo", &dir.path().join("scene")))
        })
        .as_ref()
}

fn dist_to_segment(p: [f64; 2], a: [f64; 2], b: [f64; 2]) -> f64 {
    let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
    let l2 = dx * dx + dy * dy;
    let t = if l2 > 0.0 { (((p[0] - a[0]) * dx + (p[1] - a[1]) * dy) / l2).clamp(0.0, 1.0) } else { 0.0 };
    ((a[0] + t * dx - p[0]).powi(2) + (a[1] + t * dy - p[1]).powi(2)).sqrt()
}

fn inside(p: [f64; 2], t: &[[f64; 2]; 3]) -> bool {
    let s = |a: [f64; 2], b: [f64; 2]| (b[0] - a[0]) * (p[1] - a[1]) - (b[1] - a[1]) * (p[0] - a[0]);
    let (d0, d1, d2) = (s(t[0], t[1]), s(t[1], t[2]), s(t[2], t[0]));
    (d0 >= 0.0 && d1 >= 0.0 && d2 >= 0.0) || (d0 <= 0.0 && d1 <= 0.0 && d2 <= 0.0)
}

/// Checks one building alone in one view; returns (covered pixels, pixels checked).
fn check_building(mesh: &SceneMesh, id: BuildingId, view: &View) -> (usize, usize) {
    let alone = mesh.filter_buildings(|b| b == id);
    let r = renderer();
    let img = r.render(&r.upload(&alone).unwrap(), view, &RenderOptions::default()).unwrap();
    let k = &view.intrinsics;
    let tris: Vec<[[f64; 2]; 3]> = alone
        .indices
        .chunks_exact(3)
        .map(|t| {
            [0, 1, 2].map(|j| {
                let p = alone.positions_m[t[j] as usize].map(f64::from);
                k.project(view.pose.world_to_cam(p.into()))
                    .expect("test setup: building in front of the camera")
            })
        })
        .collect();
    let (w, h) = (k.width_px as usize, k.height_px as usize);
    // Per pixel: within 0.5 px of a projected edge (not checked), and inside a projected triangle.
    // Each triangle and edge only visits the pixels of its own bounding box.
    let mut near_edge = vec![false; w * h];
    let mut expected = vec![false; w * h];
    let span = |lo: f64, hi: f64, n: usize| {
        let a = (lo - 1.0).floor().max(0.0) as usize;
        let b = ((hi + 1.0).ceil().max(0.0) as usize).min(n);
        a..b
    };
    for t in &tris {
        let (xs, ys) = (t.map(|p| p[0]), t.map(|p| p[1]));
        let min = |v: [f64; 3]| v[0].min(v[1]).min(v[2]);
        let max = |v: [f64; 3]| v[0].max(v[1]).max(v[2]);
        for y in span(min(ys), max(ys), h) {
            for x in span(min(xs), max(xs), w) {
                let c = [x as f64 + 0.5, y as f64 + 0.5];
                if (0..3).any(|e| dist_to_segment(c, t[e], t[(e + 1) % 3]) <= 0.5) {
                    near_edge[y * w + x] = true;
                }
                if inside(c, t) {
                    expected[y * w + x] = true;
                }
            }
        }
    }
    let (mut covered, mut checked) = (0, 0);
    for y in 0..h {
        for x in 0..w {
            let i = y * w + x;
            if near_edge[i] {
                continue;
            }
            let got = img.ids.ids()[i] == id;
            assert_eq!(got, expected[i], "building {id}, pixel ({x}, {y})");
            covered += got as usize;
            checked += 1;
        }
    }
    (covered, checked)
}

#[test]
fn shibuya_silhouettes_match_the_f64_projection() {
    let Some(scene) = shibuya() else { return };
    let mut tallest: Vec<_> = scene.buildings.iter().collect();
    tallest.sort_by(|a, b| b.height_m.total_cmp(&a.height_m).then(a.id.cmp(&b.id)));
    let k = Intrinsics::from_hfov(1920, 1080, 25.0).scaled_to(480, 270);
    for b in tallest.iter().take(5) {
        let centre = [0, 1].map(|a| 0.5 * (b.bbox_min_enu_m[a] + b.bbox_max_enu_m[a]));
        let top = b.bbox_max_enu_m[2];
        for (yaw, pitch, back) in [(0.0, 0.0, 0.0), (135.0, 45.0, 350.0)] {
            let yr = f64::to_radians(yaw);
            let c = [centre[0] - back * yr.sin(), centre[1] - back * yr.cos(), top + 350.0];
            let view = View { intrinsics: k, pose: Pose::from_ypr_deg(yaw, pitch, 0.0, c) };
            let (covered, checked) = check_building(&scene.mesh, b.id, &view);
            eprintln!("{} ({}): {covered} px covered, {checked} px checked", b.id, b.source_id);
            assert!(covered > 20, "building {} should be visible", b.id);
        }
    }
}

#[test]
fn cpu_rasteriser_agrees_with_wgpu_on_shibuya() {
    let Some(scene) = shibuya() else { return };
    assert_cpu_agrees_with_wgpu("tokyo", scene, &poses_at_tallest(scene, 8));
}
