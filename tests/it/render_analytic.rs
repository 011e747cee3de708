//! The GPU ID pass against an independent f64 reference rasteriser (tests/render_common): boxes of known
//! size seen from nadir and at 45° must give the same building at every pixel centre, except on pixels
//! whose centre lies within 1 px of a projected edge. Beyond that contract the tests also bound how far
//! from an edge a difference may be (0.1 px: the rasteriser's sub-pixel snapping is 1/256 px) and how
//! many edge pixels may differ (2 %: a half-pixel shift of the projection would flip about half).

use crate::render_common;

use insgen::camera::{Intrinsics, Pose};
use insgen::render::{RenderOptions, View};
use render_common::{box_mesh, compare, count, reference, renderer, Box3};

fn city() -> Vec<Box3> {
    vec![
        // A 20 m × 30 m footprint, 15 m tall.
        Box3 { id: 1, min_m: [-40.0, 5.0, 0.0], max_m: [-20.0, 35.0, 15.0] },
        // A 40 m × 20 m tower, 60 m tall, that hides part of box 1 at 45°.
        Box3 { id: 2, min_m: [-5.0, -25.0, 0.0], max_m: [35.0, -5.0, 60.0] },
        // A big ID (all three bytes used) on a small box.
        Box3 { id: 0x00AB_CDEF, min_m: [-70.0, -20.0, 0.0], max_m: [-57.5, -12.5, 8.0] },
    ]
}

/// An off-centre principal point and fx ≠ fy, so a swapped or dropped term cannot pass.
fn intrinsics() -> Intrinsics {
    Intrinsics { width_px: 320, height_px: 240, fx_px: 300.0, fy_px: 290.0, cx_px: 150.3, cy_px: 131.7 }
}

fn check(view: &View, boxes: &[Box3]) {
    let r = renderer();
    let scene = r.upload(&box_mesh(boxes)).unwrap();
    let img = r.render(&scene, view, &RenderOptions::default()).unwrap();
    assert_eq!((img.ids.width(), img.ids.height()), (view.intrinsics.width_px, view.intrinsics.height_px));
    let reference = reference(boxes, &view.intrinsics, &view.pose);
    let c = compare(img.ids.raw(), &reference);
    eprintln!("{c:?}");
    for b in boxes {
        let (g, r) = (count(img.ids.raw(), b.id), count(&reference.ids, b.id));
        eprintln!("building {}: GPU {g} px, reference {r} px", b.id);
        assert!(r > 50, "test setup: building {} should be clearly visible", b.id);
        assert!(g.abs_diff(r) <= c.mismatches, "building {}: {g} vs {r} px", b.id);
    }
    assert!(
        c.worst_mismatch_edge_distance_px <= 0.1,
        "a pixel {} px from every projected edge differs",
        c.worst_mismatch_edge_distance_px
    );
    assert!(
        c.mismatches * 50 <= c.near_edge_pixels,
        "{} of {} edge pixels differ: the projection is shifted",
        c.mismatches,
        c.near_edge_pixels
    );
}

mod nadir {
    use super::*;

    #[test]
    fn boxes_match_the_reference() {
        let view =
            View { intrinsics: intrinsics(), pose: Pose::from_ypr_deg(0.0, 0.0, 0.0, [0.0, 0.0, 250.0]) };
        check(&view, &city());
    }

    #[test]
    fn roof_area_matches_hand_computation() {
        // A 20 m × 30 m roof 235 m below the camera (250 − 15): 20·300/235 by 30·290/235 px
        // = 25.53 × 37.02 px ≈ 945 px (hand computation), ± one perimeter of pixels.
        let boxes = [Box3 { id: 7, min_m: [-10.0, -15.0, 0.0], max_m: [10.0, 15.0, 15.0] }];
        let view =
            View { intrinsics: intrinsics(), pose: Pose::from_ypr_deg(0.0, 0.0, 0.0, [0.0, 0.0, 250.0]) };
        let r = renderer();
        let scene = r.upload(&box_mesh(&boxes)).unwrap();
        let img = r.render(&scene, &view, &RenderOptions::default()).unwrap();
        let expected = (20.0 * 300.0 / 235.0) * (30.0 * 290.0 / 235.0);
        let got = count(img.ids.raw(), 7) as f64;
        let perimeter = 2.0 * (20.0 * 300.0 / 235.0 + 30.0 * 290.0 / 235.0);
        assert!((got - expected).abs() <= perimeter / 2.0, "{got} px vs {expected:.1} px");
        // Its columns: centres x + ½ in [cx − fx·10/235, cx + fx·10/235) = [137.53, 163.07) → 138..=162
        // (the walls project inside the roof from straight above).
        let cols: Vec<usize> =
            (0..320).filter(|&x| (0..240).any(|y| img.ids.raw()[y * 320 + x] == 7)).collect();
        assert_eq!((cols[0], *cols.last().unwrap()), (138, 162));
    }

    #[test]
    fn north_is_up_and_east_is_right() {
        // A box north-east of the nadir point appears in the upper-right quadrant (yaw 0 = north up).
        // 1 m tall, so the visible walls add under 0.2 px to the roof's outline.
        let boxes = [Box3 { id: 3, min_m: [30.0, 30.0, 0.0], max_m: [50.0, 50.0, 1.0] }];
        let view =
            View { intrinsics: intrinsics(), pose: Pose::from_ypr_deg(0.0, 0.0, 0.0, [0.0, 0.0, 250.0]) };
        let r = renderer();
        let img = r.render(&r.upload(&box_mesh(&boxes)).unwrap(), &view, &RenderOptions::default()).unwrap();
        let (mut sx, mut sy, mut n) = (0.0, 0.0, 0.0);
        for y in 0..240 {
            for x in 0..320 {
                if img.ids.raw()[y * 320 + x] == 3 {
                    sx += x as f64 + 0.5;
                    sy += y as f64 + 0.5;
                    n += 1.0;
                }
            }
        }
        assert!(n > 0.0);
        // The roof centre (40, 40, 1), 249 m below: u = 150.3 + 300·40/249 = 198.49,
        // v = 131.7 − 290·40/249 = 85.11 (hand computation; north is −v).
        assert!(
            (sx / n - 198.49).abs() < 0.5 && (sy / n - 85.11).abs() < 0.5,
            "centroid ({}, {})",
            sx / n,
            sy / n
        );
    }
}

mod oblique {
    use super::*;

    #[test]
    fn boxes_at_45_degrees_match_the_reference() {
        // 45° from nadir looking north-east-ish, from 180 m south-west of the boxes and 200 m up.
        let view = View {
            intrinsics: intrinsics(),
            pose: Pose::from_ypr_deg(30.0, 45.0, 0.0, [-100.0, -170.0, 200.0]),
        };
        check(&view, &city());
    }

    #[test]
    fn rolled_camera_far_from_the_origin_matches_the_reference() {
        // Everything 3 km from the area origin: the camera-relative transform must keep edges sharp.
        let shift = [2500.0, -1700.0, 0.0];
        let boxes: Vec<Box3> = city()
            .into_iter()
            .map(|b| Box3 {
                id: b.id,
                min_m: [0, 1, 2].map(|a| b.min_m[a] + shift[a]),
                max_m: [0, 1, 2].map(|a| b.max_m[a] + shift[a]),
            })
            .collect();
        let view = View {
            intrinsics: intrinsics(),
            pose: Pose::from_ypr_deg(200.0, 40.0, 7.0, [shift[0] + 60.0, shift[1] + 150.0, 210.0]),
        };
        check(&view, &boxes);
    }
}
