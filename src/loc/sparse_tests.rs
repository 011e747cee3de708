//! Views with few buildings (issue 40), constructed: what the localizer does with two or three
//! buildings on open ground, and why the sampler refuses a frame filled by one roof
//! (`[sampling] max_building_fraction`, [`crate::camera::config::DEFAULT_MAX_BUILDING_FRACTION`]).

use glam::DVec3;

use super::cost::{Blend, CostKind, Query, Weighting};
use super::eval::{CpuEvaluator, Workspaces};
use super::search::{self, Evaluate, Hypothesis, SearchOptions};
use crate::camera::config::DEFAULT_MAX_BUILDING_FRACTION;
use crate::camera::visibility::BuildingIndex;
use crate::camera::Intrinsics;
use crate::render::cpu::{self as raster, CpuScene, Frame};
use crate::scene::SceneMesh;

/// Nadir views (pitch 0), as in half of the cam2 grid.
const PITCH_DEG: f64 = 0.0;

/// Closed boxes with IDs 1.. from ([min e, n, u], [max e, n, u]) in metres.
fn boxes(b: &[([f32; 3], [f32; 3])]) -> SceneMesh {
    let mut m = SceneMesh::default();
    for (i, (lo, hi)) in b.iter().enumerate() {
        raster::tests::closed_box(&mut m, *lo, *hi, i as u32 + 1, false, true);
    }
    m
}

/// Three houses (24 × 16 m, 16 × 18 m, 14 × 12 m; 6–15 m tall) on open ground, 12–22 m apart.
fn three_houses() -> Vec<([f32; 3], [f32; 3])> {
    vec![
        ([0.0, -2.0, 0.0], [24.0, 14.0, 10.0]),
        ([36.0, 2.0, 0.0], [52.0, 20.0, 15.0]),
        ([10.0, -22.0, 0.0], [24.0, -10.0, 6.0]),
    ]
}

/// One 300 × 300 m block 40 m tall: from 110 m over (128, 134), looking down with yaw 0, its roof
/// fills the frame (about 51 × 38 m at the roof's height) but for the corner at (150, 150).
fn one_block() -> Vec<([f32; 3], [f32; 3])> {
    vec![([-150.0, -150.0, 0.0], [150.0, 150.0, 40.0])]
}

/// The query of `truth` (all instances, oracle) at `k`.
fn query_at(scene: &CpuScene, truth: &Hypothesis, k: &Intrinsics, n: usize) -> Query {
    let mut frame = Frame::default();
    raster::render_ids(scene, &truth.pose(PITCH_DEG, 0.0), k, &mut frame);
    Query::from_labels(k.width_px, k.height_px, &frame.ids, &vec![1.0; n])
}

/// eval-loc's default evaluator terms (instance cost blended with half the semantic IoU).
fn evaluator<'a>(scene: &'a CpuScene, k: Intrinsics, query: &'a Query, n: usize) -> CpuEvaluator<'a> {
    CpuEvaluator {
        scene,
        k,
        pitch_deg: PITCH_DEG,
        roll_deg: 0.0,
        query,
        kind: CostKind::Instance,
        weighting: Weighting::Area,
        blend: Blend::semantic(0.5),
        k_max: n as u32,
        silhouette_offset_px: 0,
        yaw_fan: false,
        workspaces: Workspaces::default(),
    }
}

/// The sampler's ray census of the view (the boxes as the index).
fn census(b: &[([f32; 3], [f32; 3])], k: &Intrinsics, at: &Hypothesis) -> (f64, u32) {
    let index =
        BuildingIndex::from_boxes(b.iter().map(|(lo, hi)| (lo.map(f64::from), hi.map(f64::from))).collect());
    let v = index.view_census(k, &at.pose(PITCH_DEG, 0.0), [16, 12], 0.0);
    (v.building_fraction, v.visible_buildings)
}

#[test]
fn three_houses_on_open_ground_are_localized_from_a_noisy_prior() {
    let b = three_houses();
    let scene = CpuScene::new(&boxes(&b), [0.0; 3]);
    let truth = Hypothesis { centre_m: DVec3::new(26.0, 0.0, 110.0), yaw_deg: 30.0 };
    let (k_fine, k_coarse) = (Intrinsics::from_hfov(320, 240, 40.0), Intrinsics::from_hfov(160, 120, 40.0));
    let (qf, qc) = (query_at(&scene, &truth, &k_fine, 3), query_at(&scene, &truth, &k_coarse, 3));
    assert_eq!(qf.instances.len(), 3, "every house in view");
    // The sampler keeps the view: three buildings, ground between them.
    let (share, visible) = census(&b, &k_fine, &truth);
    assert_eq!(visible, 3);
    assert!((0.15..DEFAULT_MAX_BUILDING_FRACTION).contains(&share), "building share {share}");
    // A prior 7 m and 2° off (the default noise model's median error): the default search.
    let prior = Hypothesis { centre_m: truth.centre_m + DVec3::new(5.0, -4.0, 3.0), yaw_deg: 32.0 };
    let (mut fine, mut coarse) = (evaluator(&scene, k_fine, &qf, 3), evaluator(&scene, k_coarse, &qc, 3));
    let r = search::search(&mut coarse, &mut fine, prior, &SearchOptions::default(), 1, None).unwrap();
    let error_m = r.best.centre_m.distance(truth.centre_m);
    assert!(error_m < 0.5, "translation error {error_m} m ({:?})", r.best);
    assert!((r.best.yaw_deg - truth.yaw_deg).abs() < 0.2, "yaw {}", r.best.yaw_deg);
}

#[test]
fn a_frame_filled_by_one_roof_leaves_the_depth_unpinned_and_the_sampler_refuses_it() {
    let k = Intrinsics::from_hfov(320, 240, 40.0);
    // Moving the camera 5 m along its ray through a roof corner keeps every line through that corner
    // where it was in the image: with only that corner's two edges in view the cost cannot tell the
    // poses apart; with three whole houses in view it can.
    let flatness = |b: &[([f32; 3], [f32; 3])], truth: Hypothesis, corner_m: DVec3| {
        let scene = CpuScene::new(&boxes(b), [0.0; 3]);
        let q = query_at(&scene, &truth, &k, b.len());
        let mut ev = evaluator(&scene, k, &q, b.len());
        let towards = (corner_m - truth.centre_m).normalize() * 5.0;
        let moved = Hypothesis { centre_m: truth.centre_m + towards, ..truth };
        let s = ev.evaluate(&[truth, moved]).unwrap();
        assert!(s[0] > 0.999, "the truth scores {}", s[0]);
        s[0] - s[1]
    };
    let filled = Hypothesis { centre_m: DVec3::new(128.0, 134.0, 110.0), yaw_deg: 0.0 };
    let drop_filled = flatness(&one_block(), filled, DVec3::new(150.0, 150.0, 40.0));
    let houses = Hypothesis { centre_m: DVec3::new(26.0, 0.0, 110.0), yaw_deg: 30.0 };
    let drop_houses = flatness(&three_houses(), houses, DVec3::new(24.0, 14.0, 10.0));
    assert!(drop_filled < 0.01, "the filled view's cost drops by {drop_filled}");
    assert!(drop_houses > 0.05, "the houses' cost drops by only {drop_houses}");
    // The sampler's census sees the roof fill the frame: refused by the default cap.
    let (share, _) = census(&one_block(), &k, &filled);
    assert!(share > DEFAULT_MAX_BUILDING_FRACTION, "building share {share}");
}
