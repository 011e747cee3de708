//! Tileset-aware masks (issue 17, items 2 and 3) at the frame level: the LoD model and a
//! photogrammetry-like tileset are rendered by the same wgpu renderer at the same view, and
//! `label::occlusion::occlude` compares their depths.
//!
//! Scene (ENU metres): one LoD building, a 20 × 20 × 30 m box; the tileset holds the same box, a
//! ground plane and a 6 × 4 × 20 m box "tree" 20 m in front of the building, between it and the
//! camera (60 m up, 100 m south, looking north 30° below the horizon). Expected values come from the
//! tileset's own ID render: the removed pixels must be exactly the building pixels where the tileset
//! shows the tree (the tree is ≥ 16 m in front, far beyond the 1.5 m threshold, so no pixel is
//! borderline). Images are 160 × 120.

use insgen::camera::{Intrinsics, Pose};
use insgen::label::occlusion::{occlude, OcclusionMode};
use insgen::render::{RenderOptions, View};

use crate::render_common::{box_mesh, renderer, Box3};

const TREE: u32 = 99;

fn view() -> View {
    View {
        intrinsics: Intrinsics {
            width_px: 160,
            height_px: 120,
            fx_px: 150.0,
            fy_px: 150.0,
            cx_px: 80.0,
            cy_px: 60.0,
        },
        pose: Pose::from_ypr_deg(0.0, 60.0, 0.0, [0.0, -100.0, 60.0]),
    }
}

fn building(shift_east_m: f64) -> Box3 {
    Box3 { id: 1, min_m: [-10.0 + shift_east_m, -10.0, 0.0], max_m: [10.0 + shift_east_m, 10.0, 30.0] }
}

fn tileset() -> Vec<Box3> {
    vec![
        building(0.0),
        Box3 { id: 50, min_m: [-300.0, -300.0, -1.0], max_m: [300.0, 300.0, 0.0] },
        Box3 { id: TREE, min_m: [-3.0, -32.0, 0.0], max_m: [3.0, -28.0, 20.0] },
    ]
}

fn depth_render(boxes: &[Box3]) -> insgen::render::RenderedFrame {
    let r = renderer();
    let opts = RenderOptions { linear_depth: true, ..Default::default() };
    r.render(&r.upload(&box_mesh(boxes)).unwrap(), &view(), &opts).unwrap()
}

#[test]
fn a_tree_in_front_of_a_building_is_removed_from_its_mask() {
    let lod = depth_render(&[building(0.0)]);
    let tiles = depth_render(&tileset());
    let (lod_d, tiles_d) = (lod.depth_m.as_ref().unwrap(), tiles.depth_m.as_ref().unwrap());
    let (out, ignore, f) = occlude(&lod.ids, lod_d, tiles_d, 1.5, OcclusionMode::Ignore).unwrap();
    let ignore = ignore.unwrap();
    let mut expected = 0;
    let pixels = lod.ids.ids().iter().zip(tiles.ids.ids()).zip(out.ids()).zip(&ignore);
    for (i, (((l, t), o), &ig)) in pixels.enumerate() {
        let hidden = l.get() == 1 && t.get() == TREE;
        expected += usize::from(hidden);
        assert_eq!(o.get(), if hidden { 0 } else { l.get() }, "pixel {i}");
        assert_eq!(ig, hidden, "pixel {i}");
    }
    assert!(expected > 100, "the tree hides only {expected} px of the building: test setup");
    assert_eq!(f.occluded_px as usize, expected);
    let b = f.buildings[&insgen::scene::BuildingId::new(1).unwrap()];
    assert_eq!(b.occluded_px as usize, expected);
    assert_eq!(b.behind_px, 0);
    // Every other building pixel agrees with the tileset.
    assert_eq!(f.agree_px + f.occluded_px, b.lod_px);
}

#[test]
fn the_consistency_score_drops_when_the_lod_is_shifted_by_3_m() {
    let tiles = depth_render(&tileset());
    let score = |shift: f64| {
        let lod = depth_render(&[building(shift)]);
        occlude(
            &lod.ids,
            lod.depth_m.as_ref().unwrap(),
            tiles.depth_m.as_ref().unwrap(),
            1.5,
            OcclusionMode::Remove,
        )
        .unwrap()
        .2
    };
    let (aligned, shifted) = (score(0.0), score(3.0));
    // Aligned: only the tree's pixels disagree.
    assert!(aligned.consistency > 0.85, "{aligned:?}");
    assert_eq!(aligned.behind_px, 0);
    // Shifted 3 m east: the LoD's east side lands on ground far behind (flagged), its west side
    // misses the building's west wall.
    assert!(shifted.behind_px > 50, "{shifted:?}");
    assert!(
        shifted.consistency < aligned.consistency - 0.05,
        "{} vs {}",
        shifted.consistency,
        aligned.consistency
    );
}
