//! The localizer's CPU rasteriser (`render::cpu`) against the wgpu renderer on the procedural demo
//! district: the two ID images agree on at least 99.9 % of pixels (issue 7). Disagreements can only
//! come from pixel centres within float rounding of an edge and from depth ties between coplanar
//! faces; anything systematic (a half-pixel shift, a flipped axis, a wrong principal point) would fail
//! by orders of magnitude. Culling the back faces of closed buildings must change no pixel at all.
//! The same checks on Shibuya are in `render_shibuya.rs`.

use crate::render_common;
use crate::util;

use render_common::{assert_cpu_agrees_with_wgpu, poses_at_tallest};

#[test]
fn cpu_rasteriser_agrees_with_wgpu_on_the_demo_city() {
    let dir = tempfile::tempdir().unwrap();
    let scene = util::prepare_repo_scene("demo-test", &dir.path().join("scene"));
    assert_cpu_agrees_with_wgpu("demo-test", &scene, &poses_at_tallest(&scene, 12));
}
