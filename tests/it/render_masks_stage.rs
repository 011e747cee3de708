//! The render-masks stage end to end on a hand-made box scene: outputs, their agreement with a direct
//! render and with connected components, resumption, --force, --shard, --limit, --depth,
//! --visible-fraction, --preview, and bad poses.

use crate::render_common;

use std::path::Path;

use insgen::camera::{Intrinsics, Pose, PoseRecord, Trajectory};
use insgen::geo::{EnuFrame, Geodetic};
use insgen::label::stage::{self, MaskPlan};
use insgen::label::{label_components, Connectivity, FrameInstances};
use insgen::render::{RenderOptions, View};
use insgen::scene::artifact::{GeoidUsed, Origin};
use insgen::scene::{BuildingId, IdMap};
use insgen::scene::{BuildingRecord, Manifest, PreparedScene};
use insgen::util::NoProgress;
use insgen::util::Shard;
use render_common::{box_mesh, renderer, Box3};

fn boxes() -> Vec<Box3> {
    vec![
        Box3 { id: 1, min_m: [-40.0, -30.0, 0.0], max_m: [-15.0, 0.0, 20.0] },
        Box3 { id: 2, min_m: [-5.0, -20.0, 0.0], max_m: [25.0, 10.0, 55.0] },
        Box3 { id: 3, min_m: [-30.0, 20.0, 0.0], max_m: [0.0, 40.0, 12.0] },
        Box3 { id: 0x01_02_03, min_m: [15.0, 25.0, 0.0], max_m: [35.0, 45.0, 30.0] },
    ]
}

fn scene() -> PreparedScene {
    let origin = Origin { lat_deg: 35.658, lon_deg: 139.701, h_m: 40.0 };
    let enu = EnuFrame::new(Geodetic::new(origin.lat_deg, origin.lon_deg, origin.h_m));
    let buildings = boxes()
        .iter()
        .map(|b| BuildingRecord {
            id: BuildingId::new(b.id).unwrap(),
            source_id: format!("bldg_{:06x}", b.id),
            source_file: "boxes.test".into(),
            lod: "1".into(),
            height_m: b.max_m[2] - b.min_m[2],
            measured_height_m: None,
            footprint_area_m2: (b.max_m[0] - b.min_m[0]) * (b.max_m[1] - b.min_m[1]),
            centroid_lat_deg: origin.lat_deg,
            centroid_lon_deg: origin.lon_deg,
            bbox_min_enu_m: b.min_m,
            bbox_max_enu_m: b.max_m,
            triangles: 12,
        })
        .collect();
    PreparedScene {
        manifest: Manifest {
            insgen_version: "test".into(),
            area: "boxes".into(),
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
            buildings: 4,
            triangles: 48,
            degenerate_faces: 0,
            attributions: vec![],
            clutter: None,
            alignment: None,
        },
        buildings,
        mesh: box_mesh(&boxes()),
        clutter: Default::default(),
    }
}

fn records(n: usize) -> Vec<PoseRecord> {
    let enu = EnuFrame::new(Geodetic::new(35.658, 139.701, 40.0));
    let k = Intrinsics::from_hfov(128, 96, 50.0);
    (0..n)
        .map(|i| {
            let yaw = 360.0 * i as f64 / n as f64;
            let pitch = if i % 2 == 0 { 0.0 } else { 45.0 };
            let back = if pitch > 0.0 { 150.0 } else { 0.0 };
            let centre = [-back * yaw.to_radians().sin(), -back * yaw.to_radians().cos(), 180.0];
            let pose = Pose::from_ypr_deg(yaw, pitch, 0.0, centre);
            PoseRecord::new(
                format!("f{i:03}"),
                "boxes",
                "test",
                Trajectory::Grid,
                i as u32,
                0,
                k,
                &pose,
                &enu,
                0.0,
            )
        })
        .collect()
}

fn write_poses(dir: &Path, recs: &[PoseRecord]) {
    std::fs::create_dir_all(dir).unwrap();
    let text: String = recs.iter().map(|r| serde_json::to_string(r).unwrap() + "\n").collect();
    std::fs::write(dir.join("poses.jsonl"), text).unwrap();
}

fn read_instances(plan: &MaskPlan, frame: &str) -> FrameInstances {
    serde_json::from_slice(&std::fs::read(plan.instances_path(frame)).unwrap()).unwrap()
}

#[test]
fn writes_masks_that_match_a_direct_render_and_resumes() {
    let dir = tempfile::tempdir().unwrap();
    let cam = dir.path().join("boxes/test");
    let recs = records(6);
    write_poses(&cam, &recs);
    let scene = scene();
    let r = renderer();
    let mut plan = MaskPlan::new(cam.clone());
    plan.min_area_px = 4;
    let report = stage::render_masks(&plan, &scene, r, &NoProgress).unwrap();
    assert_eq!((report.frames_total, report.frames_selected, report.rendered, report.skipped), (6, 6, 6, 0));
    assert!(report.failed.is_empty(), "{:?}", report.failed);

    let gpu = r.upload(&scene.mesh).unwrap();
    let mut total_instances = 0;
    for rec in &recs {
        // The PNG holds exactly what a direct render gives.
        let direct = r
            .render(
                &gpu,
                &View { intrinsics: rec.view.intrinsics, pose: rec.pose() },
                &RenderOptions::default(),
            )
            .unwrap();
        let png = IdMap::read_png(&plan.png_path(&rec.name)).unwrap();
        assert_eq!(png, direct.ids, "{}", rec.name);
        assert!(!direct.ids.visible_buildings().is_empty(), "{} shows nothing", rec.name);
        // The JSON lists the components of label_components above the minimum area, in raster order.
        let fi = read_instances(&plan, &rec.name);
        let l = label_components(&direct.ids, Connectivity::Eight);
        let kept: Vec<_> = l.components.iter().filter(|c| c.area_px >= 4).collect();
        assert_eq!(fi.instances.len(), kept.len());
        for (e, c) in fi.instances.iter().zip(kept) {
            assert_eq!(
                (e.building_id, e.component, e.area_px, e.bbox_px, e.truncated),
                (c.building_id, c.index, c.area_px, c.bbox_px, c.touches_border)
            );
            assert_eq!(e.source_id, format!("bldg_{:06x}", e.building_id.get()));
            let all: u64 =
                l.components.iter().filter(|x| x.building_id == e.building_id).map(|x| x.area_px).sum();
            assert_eq!(e.building_visible_px, all);
            assert_eq!(e.visible_fraction, None);
        }
        assert_eq!((fi.width, fi.height, fi.min_component_area_px), (128, 96, 4));
        total_instances += fi.instances.len() as u64;
    }
    assert_eq!(report.instances, total_instances);

    // Second run: everything verifies and is skipped; files untouched.
    let before = std::fs::read(plan.png_path("f002")).unwrap();
    let mtime = std::fs::metadata(plan.instances_path("f002")).unwrap().modified().unwrap();
    let again = stage::render_masks(&plan, &scene, r, &NoProgress).unwrap();
    assert_eq!((again.rendered, again.skipped), (0, 6));
    assert_eq!(std::fs::metadata(plan.instances_path("f002")).unwrap().modified().unwrap(), mtime);

    // A corrupt JSON and a truncated PNG are redone, the rest skipped.
    std::fs::write(plan.instances_path("f001"), b"{").unwrap();
    let png4 = std::fs::read(plan.png_path("f004")).unwrap();
    std::fs::write(plan.png_path("f004"), &png4[..png4.len() - 20]).unwrap();
    let redo = stage::render_masks(&plan, &scene, r, &NoProgress).unwrap();
    assert_eq!((redo.rendered, redo.skipped), (2, 4));
    assert_eq!(std::fs::read(plan.png_path("f004")).unwrap(), png4);

    // Changed settings invalidate; --force redoes everything with byte-identical results.
    plan.force = true;
    plan.min_area_px = 4;
    let forced = stage::render_masks(&plan, &scene, r, &NoProgress).unwrap();
    assert_eq!((forced.rendered, forced.skipped), (6, 0));
    assert_eq!(std::fs::read(plan.png_path("f002")).unwrap(), before);
    plan.force = false;
    plan.connectivity = Connectivity::Four;
    let changed = stage::render_masks(&plan, &scene, r, &NoProgress).unwrap();
    assert_eq!(changed.rendered, 6, "a different connectivity must not reuse old instance lists");

    // Poses sampled again under the same frame names: only the frame whose pose moved is redone.
    let mut recs = recs;
    let moved = Pose::from_ypr_deg(10.0, 0.0, 0.0, [5.0, 0.0, 180.0]);
    recs[3] = PoseRecord::new(
        "f003".into(),
        "boxes",
        "test",
        Trajectory::Grid,
        3,
        0,
        recs[3].view.intrinsics,
        &moved,
        &EnuFrame::new(Geodetic::new(35.658, 139.701, 40.0)),
        0.0,
    );
    write_poses(&plan.camera_dir, &recs);
    let resampled = stage::render_masks(&plan, &scene, r, &NoProgress).unwrap();
    assert_eq!((resampled.rendered, resampled.skipped), (1, 5), "a moved pose must not reuse its old mask");
    let direct = r
        .render(&gpu, &View { intrinsics: recs[3].view.intrinsics, pose: moved }, &RenderOptions::default())
        .unwrap();
    assert_eq!(IdMap::read_png(&plan.png_path("f003")).unwrap(), direct.ids);
}

#[test]
fn shard_limit_depth_visible_fraction_and_preview() {
    let dir = tempfile::tempdir().unwrap();
    let cam = dir.path().join("boxes/test");
    let recs = records(7);
    write_poses(&cam, &recs);
    let scene = scene();
    let r = renderer();
    let mut plan = MaskPlan::new(cam.clone());
    plan.shard = Shard { index: 1, count: 3 };
    plan.limit = Some(2);
    plan.depth = true;
    plan.visible_fraction = true;
    plan.preview = 2;
    let report = stage::render_masks(&plan, &scene, r, &NoProgress).unwrap();
    // Shard 1/3 of 0..7 is {1, 4}; limit 2 keeps both.
    assert_eq!((report.frames_selected, report.rendered), (2, 2));
    let written: Vec<String> = std::fs::read_dir(plan.masks_dir())
        .unwrap()
        .map(|e| e.unwrap().file_name().into_string().unwrap())
        .filter(|n| n.ends_with(".instances.json"))
        .collect();
    let mut written = written;
    written.sort();
    assert_eq!(written, vec!["f001.instances.json", "f004.instances.json"]);

    for name in ["f001", "f004"] {
        let rec = recs.iter().find(|x| x.name == name).unwrap();
        // Depth EXR: one float channel equal to the renderer's linear depth.
        let direct = r
            .render(
                &r.upload(&scene.mesh).unwrap(),
                &View { intrinsics: rec.view.intrinsics, pose: rec.pose() },
                &RenderOptions { linear_depth: true, ..Default::default() },
            )
            .unwrap();
        let exr_img = exr::prelude::read_first_flat_layer_from_file(plan.depth_path(name)).unwrap();
        let layer = &exr_img.layer_data;
        assert_eq!((layer.size.width(), layer.size.height()), (128, 96));
        assert_eq!(layer.channel_data.list.len(), 1);
        assert_eq!(layer.channel_data.list[0].name.to_string(), "Z");
        let z: Vec<f32> = layer.channel_data.list[0].sample_data.values_as_f32().collect();
        assert_eq!(z, direct.depth_m.unwrap());
        // visible_fraction in (0, 1], and below 1 for a building that the frame truncates or hides.
        let fi = read_instances(&plan, name);
        assert!(!fi.instances.is_empty());
        for e in &fi.instances {
            let f = e.visible_fraction.expect("--visible-fraction was given");
            assert!(f > 0.0 && f <= 1.0, "{f}");
        }
    }
    assert_eq!(report.previews.len(), 1);
    let sheet = insgen::label::overlay::read_rgb_png(&report.previews[0]).unwrap();
    assert!(sheet.width > 480 && sheet.height > 100);
    assert!(report.previews[0].file_name().unwrap().to_str().unwrap().starts_with("preview_1of3_"));
}

#[test]
fn bad_poses_are_reported_with_their_line() {
    let dir = tempfile::tempdir().unwrap();
    let cam = dir.path().join("boxes/test");
    let recs = records(2);
    write_poses(&cam, &recs);
    let mut text = std::fs::read_to_string(cam.join("poses.jsonl")).unwrap();
    text.push_str("{\"name\": 3}\n");
    std::fs::write(cam.join("poses.jsonl"), &text).unwrap();
    let e = stage::render_masks(&MaskPlan::new(cam.clone()), &scene(), renderer(), &NoProgress).unwrap_err();
    assert!(e.to_string().contains("poses.jsonl:3: not a valid pose record"), "{e}");
    // The parser's own message stays in the cause chain.
    let cause = std::error::Error::source(&e).map(|c| c.to_string()).unwrap_or_default();
    assert!(cause.contains("invalid type"), "{cause}");

    let dup = format!(
        "{}\n{}\n",
        serde_json::to_string(&recs[0]).unwrap(),
        serde_json::to_string(&recs[0]).unwrap()
    );
    std::fs::write(cam.join("poses.jsonl"), dup).unwrap();
    let e = stage::render_masks(&MaskPlan::new(cam.clone()), &scene(), renderer(), &NoProgress).unwrap_err();
    assert!(e.to_string().contains("poses.jsonl:2: frame name \"f000\" was already used on line 1"), "{e}");
}

#[test]
fn mesh_ids_missing_from_the_building_table_are_an_error() {
    let dir = tempfile::tempdir().unwrap();
    let cam = dir.path().join("boxes/test");
    write_poses(&cam, &records(1));
    let mut s = scene();
    s.buildings.retain(|b| b.id != 3);
    let e = stage::render_masks(&MaskPlan::new(cam), &s, renderer(), &NoProgress).unwrap_err();
    assert!(e.to_string().contains("building ID 3 but buildings.json has no such row"), "{e}");
}
