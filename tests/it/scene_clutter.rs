//! Clutter as occluders in the masks: a building hidden behind a generated tree has no mask pixels,
//! the tree's pixels are background (0), and the same view without occluders shows the building (so
//! the tree, not the framing, hides it). ID maps are compared exactly (integer images, no tolerance).
//! End to end on the demo city prepared with clutter: the masks lose building pixels to the clutter,
//! and Blender's ID render (clutter as ID 0) agrees with them to the alignment targets of issue 6
//! (median IoU ≥ 0.995, 5th percentile ≥ 0.98; `src/blender/align.rs`).

use crate::render_common::{box_mesh, renderer, Box3};

use insgen::camera::{Intrinsics, Pose, PoseRecord, Trajectory};
use insgen::geo::{EnuFrame, Geodetic};
use insgen::label::stage::{self, MaskPlan};
use insgen::label::FrameInstances;
use insgen::render::{RenderOptions, View};
use insgen::scene::artifact::{GeoidUsed, Origin};
use insgen::scene::clutter::{tree_instance, Clutter, ClutterLayer};
use insgen::scene::{BuildingId, BuildingRecord, IdMap, Manifest, PreparedScene, SceneMesh};
use insgen::util::NoProgress;

/// A 2 × 2 × 3 m kiosk 11–13 m north of a broadleaf tree (crown radius 4 m) seen from the south.
const KIOSK: Box3 = Box3 { id: 7, min_m: [-1.0, 11.0, 0.0], max_m: [1.0, 13.0, 3.0] };
/// And a tall building off to the side that stays visible.
const TOWER: Box3 = Box3 { id: 9, min_m: [14.0, 20.0, 0.0], max_m: [24.0, 30.0, 30.0] };

fn tree() -> insgen::scene::clutter::LayerMesh {
    tree_instance(0, [0.0, 0.0, 0.0], 12.0, 4.0)
}

fn scene() -> PreparedScene {
    let origin = Origin { lat_deg: 35.658, lon_deg: 139.701, h_m: 40.0 };
    let enu = EnuFrame::new(Geodetic::new(origin.lat_deg, origin.lon_deg, origin.h_m));
    let boxes = [KIOSK, TOWER];
    let buildings: Vec<BuildingRecord> = boxes
        .iter()
        .map(|b| BuildingRecord {
            id: BuildingId::new(b.id).unwrap(),
            source_id: format!("b{}", b.id),
            source_file: "test".into(),
            lod: "1".into(),
            height_m: b.max_m[2] - b.min_m[2],
            measured_height_m: None,
            footprint_area_m2: (b.max_m[0] - b.min_m[0]) * (b.max_m[1] - b.min_m[1]),
            centroid_lat_deg: 0.0,
            centroid_lon_deg: 0.0,
            bbox_min_enu_m: b.min_m,
            bbox_max_enu_m: b.max_m,
            triangles: 12,
        })
        .collect();
    let mesh = box_mesh(&boxes);
    PreparedScene {
        manifest: Manifest {
            insgen_version: "test".into(),
            area: "clutter".into(),
            split: "test".into(),
            origin,
            ecef_from_enu: enu.ecef_from_enu(),
            area_polygon_enu_m: vec![[-50.0, -50.0], [50.0, -50.0], [50.0, 50.0], [-50.0, 50.0]],
            ground_enu_m: 0.0,
            geoid: GeoidUsed { model: "none".into(), ..Default::default() },
            sources: vec![],
            buildings: 2,
            triangles: mesh.triangle_count() as u64,
            degenerate_faces: 0,
            attributions: vec![],
            clutter: None,
            alignment: None,
        },
        buildings,
        mesh,
        clutter: Clutter { layers: vec![(ClutterLayer::Trees, tree())] },
    }
}

/// 160 × 90, 30° wide, 30 m up and 40 m south of the tree, looking north 29° below the horizon (at
/// the crown's centre, whose line of sight reaches the ground at y ≈ 14 m, behind the kiosk).
fn view() -> View {
    let k = Intrinsics::from_hfov(160, 90, 30.0);
    let depression_deg = (22.2f64 / 40.0).atan().to_degrees();
    View { intrinsics: k, pose: Pose::from_ypr_deg(0.0, 90.0 - depression_deg, 0.0, [0.0, -40.0, 30.0]) }
}

/// The pixels where `mesh` (every triangle given ID 1) is drawn alone.
fn silhouette(mesh: &SceneMesh) -> Vec<bool> {
    let r = renderer();
    let gpu = r.upload(mesh).unwrap();
    let f = r.render(&gpu, &view(), &RenderOptions::default()).unwrap();
    f.ids.raw().iter().map(|&id| id != 0).collect()
}

fn tree_as_building() -> SceneMesh {
    let t = tree();
    SceneMesh {
        building_ids: vec![BuildingId::new(1).unwrap(); t.positions_m.len()],
        positions_m: t.positions_m,
        indices: t.indices,
    }
}

fn run(scene: &PreparedScene, occluders: Vec<ClutterLayer>) -> (IdMap, FrameInstances) {
    let dir = tempfile::tempdir().unwrap();
    let cam = dir.path().join("clutter/test");
    std::fs::create_dir_all(&cam).unwrap();
    let v = view();
    let enu = EnuFrame::new(Geodetic::new(35.658, 139.701, 40.0));
    let rec = PoseRecord::new(
        "f000".into(),
        "clutter",
        "test",
        Trajectory::Grid,
        0,
        0,
        v.intrinsics,
        &v.pose,
        &enu,
        0.0,
    );
    std::fs::write(cam.join("poses.jsonl"), serde_json::to_string(&rec).unwrap() + "\n").unwrap();
    let mut plan = MaskPlan::new(cam.clone());
    plan.min_area_px = 1;
    plan.visible_fraction = true;
    plan.occluders = occluders;
    let report = stage::render_masks(&plan, scene, renderer(), &NoProgress).unwrap();
    assert_eq!(report.rendered, 1, "{:?}", report.failed);
    let ids = IdMap::read_png(&plan.png_path("f000")).unwrap();
    let fi: FrameInstances =
        serde_json::from_slice(&std::fs::read(plan.instances_path("f000")).unwrap()).unwrap();
    (ids, fi)
}

#[test]
fn a_building_behind_a_generated_tree_has_no_mask_pixels_and_the_tree_is_background() {
    let scene = scene();
    let kiosk_alone = silhouette(&box_mesh(&[KIOSK]));
    let tree_alone = silhouette(&tree_as_building());
    let kiosk_px = kiosk_alone.iter().filter(|&&b| b).count();
    assert!(kiosk_px >= 20, "the kiosk covers only {kiosk_px} px in the test view");
    // The set-up: every kiosk pixel lies inside the tree's silhouette (the tree is nearer).
    assert!(kiosk_alone.iter().zip(&tree_alone).all(|(&k, &t)| !k || t), "the tree does not cover the kiosk");

    // Without occluders the kiosk is in the mask …
    let (open, open_fi) = run(&scene, vec![]);
    let kiosk = BuildingId::new(KIOSK.id).unwrap();
    let tower = BuildingId::new(TOWER.id).unwrap();
    assert_eq!(open.raw().iter().filter(|&&id| id == KIOSK.id).count(), kiosk_px);
    assert!(open_fi.instances.iter().any(|e| e.building_id == kiosk));
    assert!(open_fi.occluders.is_empty());

    // … with the tree as an occluder it has no pixel, and every tree pixel is background or the tower
    // (which stands behind the tree's edge in this view, never in front of it).
    let (hidden, fi) = run(&scene, vec![ClutterLayer::Trees]);
    assert_eq!(hidden.raw().iter().filter(|&&id| id == KIOSK.id).count(), 0);
    for (i, (&t, &id)) in tree_alone.iter().zip(hidden.raw()).enumerate() {
        if t {
            assert_eq!(id, 0, "tree pixel {i} holds building {id}");
        }
    }
    assert!(fi.instances.iter().all(|e| e.building_id != kiosk), "{:?}", fi.instances);
    assert_eq!(fi.occluders, vec![ClutterLayer::Trees]);
    // The tower stays, with its visible fraction following the occlusion.
    let tower_entry = fi.instances.iter().find(|e| e.building_id == tower).expect("the tower is visible");
    let open_tower = open_fi.instances.iter().find(|e| e.building_id == tower).unwrap();
    assert!(tower_entry.visible_fraction.unwrap() <= open_tower.visible_fraction.unwrap());
}

/// The demo city prepared with clutter (through the library, as `insgen prepare` does) into
/// `<work>/demo/scene`, with four 160 × 90 oblique views over trees and buildings in
/// `<work>/demo/cam9/poses.jsonl`; returns the loaded scene.
fn demo_with_clutter(work: &std::path::Path) -> PreparedScene {
    use crate::util::{repo_scene, scratch_with_scenes};
    use insgen::scene::clutter::ClutterSpec;
    use insgen::scene::prepare::{prepare_with, PrepareOptions};
    let scenes = scratch_with_scenes(&[("demo", repo_scene("demo"))]);
    let scene_dir = work.join("demo/scene");
    let options = PrepareOptions { clutter: Some(ClutterSpec::default()) };
    prepare_with(&scenes.path().join("scenes/demo.toml"), &scene_dir, &options, &NoProgress).unwrap();
    let scene = PreparedScene::load(&scene_dir).unwrap();
    let cam = work.join("demo/cam9");
    std::fs::create_dir_all(&cam).unwrap();
    let enu = EnuFrame::new(Geodetic::new(
        scene.manifest.origin.lat_deg,
        scene.manifest.origin.lon_deg,
        scene.manifest.origin.h_m,
    ));
    let k = Intrinsics::from_hfov(160, 90, 50.0);
    let mut lines = String::new();
    for (i, (yaw, centre)) in [
        (0.0, [-150.0, -250.0, 90.0]),
        (90.0, [-300.0, 100.0, 80.0]),
        (200.0, [100.0, 300.0, 100.0]),
        (300.0, [250.0, -50.0, 90.0]),
    ]
    .into_iter()
    .enumerate()
    {
        let pose = Pose::from_ypr_deg(yaw, 60.0, 0.0, centre);
        let rec = PoseRecord::new(
            format!("v{i}"),
            "demo",
            "cam9",
            Trajectory::Grid,
            i as u32,
            0,
            k,
            &pose,
            &enu,
            0.0,
        );
        lines.push_str(&(serde_json::to_string(&rec).unwrap() + "\n"));
    }
    std::fs::write(cam.join("poses.jsonl"), lines).unwrap();
    scene
}

#[test]
fn prepared_demo_clutter_occludes_and_blender_ids_agree_with_the_masks() {
    use crate::blender_support::blender_python;
    use clap::Parser;
    use insgen::cli::render_rgb::{run, Args};
    #[derive(Parser)]
    struct Wrap {
        #[command(flatten)]
        args: Args,
    }
    let work = tempfile::tempdir().unwrap();
    let scene = demo_with_clutter(work.path());
    let summary = scene.manifest.clutter.as_ref().expect("the manifest lists the clutter");
    assert_eq!(summary.layers.len(), 7, "{summary:?}");
    assert_eq!(scene.clutter.layers.len(), 7);
    crate::util::assert_schema("manifest.schema.json", &serde_json::to_value(&scene.manifest).unwrap());

    // Masks with the default occluders (trees and cars).
    let mut plan = MaskPlan::new(work.path().join("demo/cam9"));
    plan.min_area_px = 4;
    let report = stage::render_masks(&plan, &scene, renderer(), &NoProgress).unwrap();
    assert_eq!(report.rendered, 4, "{:?}", report.failed);
    // The clutter hides building pixels in these views: fewer than the buildings alone show.
    let gpu = renderer().upload(&scene.mesh).unwrap();
    let (mut with, mut without) = (0usize, 0usize);
    for i in 0..4 {
        let rec: PoseRecord =
            serde_json::from_str(std::fs::read_to_string(plan.poses_path()).unwrap().lines().nth(i).unwrap())
                .unwrap();
        let bare = renderer()
            .render(
                &gpu,
                &View { intrinsics: rec.view.intrinsics, pose: rec.pose() },
                &RenderOptions::default(),
            )
            .unwrap();
        without += bare.ids.raw().iter().filter(|&&id| id != 0).count();
        let masked = IdMap::read_png(&plan.png_path(&rec.name)).unwrap();
        with += masked.raw().iter().filter(|&&id| id != 0).count();
    }
    eprintln!("building pixels: {with} with clutter, {without} without");
    assert!(with > 1000 && with < without, "{with} building pixels with clutter, {without} without");

    // Rooftop units belong to their building by default; as occluders they punch holes in the roofs
    // (background pixels enclosed by one building), which the default masks do not have.
    let cam8 = work.path().join("demo/cam8");
    std::fs::create_dir_all(&cam8).unwrap();
    std::fs::copy(plan.poses_path(), cam8.join("poses.jsonl")).unwrap();
    let mut holed = MaskPlan::new(cam8);
    holed.min_area_px = 4;
    holed.occluders = vec![ClutterLayer::Trees, ClutterLayer::Cars, ClutterLayer::Rooftop];
    assert_eq!(stage::render_masks(&holed, &scene, renderer(), &NoProgress).unwrap().rendered, 4);
    let (mut holes_default, mut holes_rooftop, mut px_rooftop) = (0, 0, 0usize);
    for i in 0..4 {
        let name = format!("v{i}");
        holes_default += enclosed_holes(&IdMap::read_png(&plan.png_path(&name)).unwrap());
        let m = IdMap::read_png(&holed.png_path(&name)).unwrap();
        holes_rooftop += enclosed_holes(&m);
        px_rooftop += m.raw().iter().filter(|&&id| id != 0).count();
    }
    eprintln!("hole pixels: {holes_default} default, {holes_rooftop} with rooftop occluders");
    assert!(
        holes_rooftop > holes_default,
        "{holes_rooftop} holes with rooftop units, {holes_default} without"
    );
    assert!(px_rooftop < with, "rooftop units hid no roof pixels: {px_rooftop} vs {with}");

    // Blender's ID render of the same scene, clutter included as background, agrees with the masks.
    let Some(py) = blender_python() else { return };
    let global = insgen::cli::Global {
        workdir: work.path().to_path_buf(),
        scenes: "scenes".into(),
        verbose: 0,
        quiet: true,
        no_progress: true,
        log_every: 30.0,
    };
    let py_s = py.to_string_lossy().into_owned();
    let argv = [
        "x",
        "--area",
        "demo",
        "--camera",
        "cam9",
        "--blender-python",
        &py_s,
        "--threads",
        "2",
        "--check-alignment",
    ];
    run(&Wrap::try_parse_from(argv).unwrap().args, &global).unwrap();
    let report: serde_json::Value =
        serde_json::from_slice(&std::fs::read(work.path().join("demo/cam9/alignment/report.json")).unwrap())
            .unwrap();
    eprintln!("alignment: {}", report);
    assert_eq!(report["frames"], 4);
    assert_eq!(report["pass"], true);
    assert!(report["median_iou"].as_f64().unwrap() >= 0.995, "{report}");
}

#[test]
fn side_by_side_picture_shows_rgb_outlines_and_the_clutter_layer() {
    use insgen::label::overlay::{read_rgb_png, write_rgb_png, RgbImage};
    use insgen::label::side_by_side::{layer_colour, write_side_by_side, SideFrame, PANEL_WIDTH_PX};
    let scene = scene();
    let dir = tempfile::tempdir().unwrap();
    let rgb = dir.path().join("f000.png");
    write_rgb_png(&rgb, &RgbImage::filled(160, 90, [120, 130, 140])).unwrap();
    let frames = [
        SideFrame { name: "f000".into(), view: view(), rgb_png: rgb, mask_png: dir.path().join("none.png") },
        // No RGB frame: left out.
        SideFrame {
            name: "f001".into(),
            view: view(),
            rgb_png: dir.path().join("missing.png"),
            mask_png: dir.path().join("none.png"),
        },
    ];
    let out = dir.path().join("side_by_side.png");
    assert_eq!(write_side_by_side(&out, &scene, renderer(), &frames, 4).unwrap(), 1);
    let img = read_rgb_png(&out).unwrap();
    // Three panels of 320 px with 4 px gaps; one row of 320 × 180 tiles.
    assert_eq!((img.width, img.height), (4 + 3 * (PANEL_WIDTH_PX + 4), 4 + 180 + 4));
    let px = |x: u32, y: u32| {
        let i = 3 * (y as usize * img.width as usize + x as usize);
        [img.rgb[i], img.rgb[i + 1], img.rgb[i + 2]]
    };
    // The tree fills the middle of the view: the third panel shows it in the trees' colour, the first
    // the RGB frame unchanged.
    let third_centre = (4 + 2 * (PANEL_WIDTH_PX + 4) + PANEL_WIDTH_PX / 2, 4 + 90);
    assert_eq!(px(third_centre.0, third_centre.1), layer_colour(ClutterLayer::Trees));
    assert_eq!(px(4 + 10, 4 + 10), [120, 130, 140]);
}

/// Pixels of background regions (4-connected) that one building encloses: holes in its mask.
fn enclosed_holes(m: &IdMap) -> usize {
    let (w, h) = (m.width() as usize, m.height() as usize);
    let ids = m.raw();
    let mut seen = vec![false; w * h];
    let mut total = 0;
    for start in 0..w * h {
        if ids[start] != 0 || seen[start] {
            continue;
        }
        // Flood one background region; note whether it reaches the border and what surrounds it.
        let (mut stack, mut size, mut border) = (vec![start], 0usize, false);
        let mut around = std::collections::BTreeSet::new();
        seen[start] = true;
        while let Some(i) = stack.pop() {
            size += 1;
            let (x, y) = (i % w, i / w);
            border |= x == 0 || y == 0 || x + 1 == w || y + 1 == h;
            let nbs = [
                (x > 0).then(|| i - 1),
                (x + 1 < w).then(|| i + 1),
                (y > 0).then(|| i - w),
                (y + 1 < h).then(|| i + w),
            ];
            for j in nbs.into_iter().flatten() {
                if ids[j] != 0 {
                    around.insert(ids[j]);
                } else if !seen[j] {
                    seen[j] = true;
                    stack.push(j);
                }
            }
        }
        if !border && around.len() == 1 {
            total += size;
        }
    }
    total
}
