//! Linear depth, amodal coverage (the denominator of visible_fraction), clipping and input validation
//! of the renderer, against the f64 reference of tests/render_common.

use crate::render_common;

use insgen::camera::{Intrinsics, Pose};
use insgen::render::{DepthRange, RenderError, RenderOptions, View};
use insgen::scene::{BuildingId, SceneMesh};
use render_common::{box_mesh, compare, count, reference, renderer, Box3};

fn ids(v: &[u32]) -> Vec<BuildingId> {
    v.iter().map(|&i| BuildingId::new(i).unwrap()).collect()
}

fn k() -> Intrinsics {
    Intrinsics { width_px: 160, height_px: 120, fx_px: 150.0, fy_px: 150.0, cx_px: 80.0, cy_px: 60.0 }
}

mod depth {
    use super::*;

    #[test]
    fn linear_depth_matches_the_reference_away_from_edges() {
        let boxes = [
            Box3 { id: 1, min_m: [-30.0, -20.0, 0.0], max_m: [0.0, 10.0, 40.0] },
            Box3 { id: 2, min_m: [10.0, -5.0, 0.0], max_m: [30.0, 25.0, 12.0] },
        ];
        let view =
            View { intrinsics: k(), pose: Pose::from_ypr_deg(20.0, 45.0, 0.0, [-60.0, -150.0, 130.0]) };
        let r = renderer();
        let scene = r.upload(&box_mesh(&boxes)).unwrap();
        let img =
            r.render(&scene, &view, &RenderOptions { linear_depth: true, ..Default::default() }).unwrap();
        let depth = img.depth_m.as_ref().unwrap();
        let reference = reference(&boxes, &view.intrinsics, &view.pose);
        let mut checked = 0;
        for (i, &d) in depth.iter().enumerate() {
            if reference.edge_distance_px[i] <= 1.0 {
                continue;
            }
            if reference.ids[i] == 0 {
                assert_eq!(d, 0.0, "pixel {i}: background depth is 0");
                continue;
            }
            // f32 depth of a ~200 m surface: well under 1 mm, allow 1e-5 relative (2 mm).
            let (g, e) = (d as f64, reference.depth_m[i]);
            assert!((g - e).abs() <= 1e-5 * e, "pixel {i}: {g} m vs {e} m");
            checked += 1;
        }
        assert!(checked > 500, "only {checked} pixels checked");
    }

    #[test]
    fn nadir_roof_depth_is_height_difference() {
        let boxes = [Box3 { id: 9, min_m: [-10.0, -10.0, 0.0], max_m: [10.0, 10.0, 23.5] }];
        let view = View { intrinsics: k(), pose: Pose::from_ypr_deg(0.0, 0.0, 0.0, [0.0, 0.0, 300.0]) };
        let r = renderer();
        let img = r
            .render(
                &r.upload(&box_mesh(&boxes)).unwrap(),
                &view,
                &RenderOptions { linear_depth: true, ..Default::default() },
            )
            .unwrap();
        // Centre pixel sees the roof 300 − 23.5 = 276.5 m below (hand computation).
        let c = 60 * 160 + 80;
        assert_eq!(img.ids.raw()[c], 9);
        assert!((img.depth_m.as_ref().unwrap()[c] - 276.5).abs() < 1e-3);
    }
}

mod coverage {
    use super::*;

    #[test]
    fn occluded_building_alone_covers_what_the_reference_predicts() {
        // Building 1 stands behind tower 2 as seen from the camera.
        let b1 = Box3 { id: 1, min_m: [-20.0, 40.0, 0.0], max_m: [20.0, 70.0, 25.0] };
        let b2 = Box3 { id: 2, min_m: [-10.0, 0.0, 0.0], max_m: [10.0, 20.0, 80.0] };
        let view = View { intrinsics: k(), pose: Pose::from_ypr_deg(0.0, 50.0, 0.0, [0.0, -180.0, 170.0]) };
        let r = renderer();
        let scene = r.upload(&box_mesh(&[b1, b2])).unwrap();
        let img = r.render(&scene, &view, &RenderOptions::default()).unwrap();
        let visible = count(img.ids.raw(), 1) as u64;
        let cov = r.isolated_coverage_px(&scene, &view, &ids(&[1, 2, 77]), &DepthRange::default()).unwrap();
        let alone = reference(&[b1], &view.intrinsics, &view.pose);
        let c1 = compare(
            r.render(&r.upload(&box_mesh(&[b1])).unwrap(), &view, &RenderOptions::default())
                .unwrap()
                .ids
                .raw(),
            &alone,
        );
        let expected = count(&alone.ids, 1) as u64;
        eprintln!("building 1: visible {visible} px, alone {} px (reference {expected} px)", cov[0]);
        assert!(cov[0].abs_diff(expected) as usize <= c1.mismatches.max(1), "{} vs {expected}", cov[0]);
        assert!(visible < cov[0], "building 1 must be partly hidden ({visible} vs {})", cov[0]);
        // The tower is in front of everything: alone it covers exactly what it covers in the scene.
        assert_eq!(cov[1], count(img.ids.raw(), 2) as u64);
        assert_eq!(cov[2], 0, "an ID absent from the scene covers nothing");
    }

    #[test]
    fn coverage_equals_lone_render_for_every_building() {
        // Exact equality with a render of the building's sub-mesh (SceneMesh::filter_buildings).
        let boxes: Vec<Box3> = (0..6)
            .map(|i| {
                let x = i as f64 * 14.0 - 40.0;
                Box3 {
                    id: 10 + i,
                    min_m: [x, -10.0 + 6.0 * i as f64, 0.0],
                    max_m: [x + 12.0, 15.0 + 6.0 * i as f64, 20.0 + 9.0 * i as f64],
                }
            })
            .collect();
        let mesh = box_mesh(&boxes);
        let view =
            View { intrinsics: k(), pose: Pose::from_ypr_deg(340.0, 55.0, 0.0, [20.0, -160.0, 120.0]) };
        let r = renderer();
        let scene = r.upload(&mesh).unwrap();
        let ids: Vec<BuildingId> = boxes.iter().map(|b| BuildingId::new(b.id).unwrap()).collect();
        let cov = r.isolated_coverage_px(&scene, &view, &ids, &DepthRange::default()).unwrap();
        for (b, &c) in boxes.iter().zip(&cov) {
            let alone = mesh.filter_buildings(|id| id.get() == b.id);
            let img = r.render(&r.upload(&alone).unwrap(), &view, &RenderOptions::default()).unwrap();
            assert_eq!(c, count(img.ids.raw(), b.id) as u64, "building {}", b.id);
            assert!(c > 0);
        }
    }

    #[test]
    fn building_outside_the_frame_covers_nothing() {
        let boxes = [Box3 { id: 4, min_m: [900.0, 900.0, 0.0], max_m: [910.0, 910.0, 10.0] }];
        let view = View { intrinsics: k(), pose: Pose::from_ypr_deg(0.0, 0.0, 0.0, [0.0, 0.0, 200.0]) };
        let r = renderer();
        let scene = r.upload(&box_mesh(&boxes)).unwrap();
        assert_eq!(
            r.isolated_coverage_px(&scene, &view, &ids(&[4]), &DepthRange::default()).unwrap(),
            vec![0]
        );
    }
}

mod clipping {
    use super::*;

    #[test]
    fn geometry_beyond_the_far_plane_is_not_drawn() {
        let boxes = [Box3 { id: 5, min_m: [-10.0, -10.0, 0.0], max_m: [10.0, 10.0, 10.0] }];
        let view = View { intrinsics: k(), pose: Pose::from_ypr_deg(0.0, 0.0, 0.0, [0.0, 0.0, 200.0]) };
        let r = renderer();
        let scene = r.upload(&box_mesh(&boxes)).unwrap();
        let near = RenderOptions { range: DepthRange { near_m: 0.1, far_m: 150.0 }, linear_depth: false };
        assert!(r.render(&scene, &view, &near).unwrap().ids.raw().iter().all(|&id| id == 0));
        let far = RenderOptions { range: DepthRange { near_m: 0.1, far_m: 250.0 }, linear_depth: false };
        assert!(r.render(&scene, &view, &far).unwrap().ids.raw().contains(&5));
    }

    #[test]
    fn empty_scene_renders_background() {
        let r = renderer();
        let scene = r.upload(&SceneMesh::default()).unwrap();
        let view = View { intrinsics: k(), pose: Pose::from_ypr_deg(0.0, 0.0, 0.0, [0.0, 0.0, 200.0]) };
        let img = r.render(&scene, &view, &RenderOptions::default()).unwrap();
        assert!(img.ids.raw().iter().all(|&id| id == 0));
    }
}

mod validation {
    use super::*;

    #[test]
    fn invalid_view_is_an_error_naming_the_view() {
        let r = renderer();
        let scene = r.upload(&box_mesh(&[Box3 { id: 1, min_m: [0.0; 3], max_m: [1.0; 3] }])).unwrap();
        let good = View { intrinsics: k(), pose: Pose::from_ypr_deg(0.0, 0.0, 0.0, [0.0, 0.0, 200.0]) };
        let mut bad = good;
        bad.intrinsics.height_px = 0;
        let e = r.render_batch(&scene, &[good, bad], &RenderOptions::default()).unwrap_err();
        assert!(matches!(e, RenderError::InvalidView { .. }), "{e}");
        assert!(e.to_string().contains("view 1"), "{e}");
    }

    #[test]
    fn invalid_meshes_are_rejected() {
        let r = renderer();
        let mut m = box_mesh(&[Box3 { id: 1, min_m: [0.0; 3], max_m: [1.0; 3] }]);
        m.building_ids[0] = BuildingId::BACKGROUND;
        assert!(r.upload(&m).unwrap_err().to_string().contains("building ID 0"));
        let mut m = box_mesh(&[Box3 { id: 1, min_m: [0.0; 3], max_m: [1.0; 3] }]);
        m.indices.push(1000);
        m.indices.push(0);
        m.indices.push(1);
        assert!(r.upload(&m).unwrap_err().to_string().contains("refers to vertex 1000"));
        let mut m = box_mesh(&[Box3 { id: 1, min_m: [0.0; 3], max_m: [1.0; 3] }]);
        m.building_ids[0] = BuildingId::new(2).unwrap();
        assert!(r.upload(&m).unwrap_err().to_string().contains("joins vertices of buildings"));
        let mut m = box_mesh(&[Box3 { id: 1, min_m: [0.0; 3], max_m: [1.0; 3] }]);
        m.positions_m[3][1] = f32::NAN;
        assert!(r.upload(&m).unwrap_err().to_string().contains("non-finite"));
    }
}
