//! Same inputs → same outputs: rendering twice gives identical ID maps, the frames-in-flight ring
//! gives the same frame as a lone render, and writing an ID map twice gives byte-identical PNGs.

use crate::render_common;

use insgen::camera::{Intrinsics, Pose};
use insgen::render::{RenderOptions, View};
use insgen::scene::IdMap;
use render_common::{box_mesh, renderer, Box3};

fn boxes() -> Vec<Box3> {
    (0..12)
        .map(|i| {
            let (x, y) = ((i % 4) as f64 * 30.0 - 60.0, (i / 4) as f64 * 35.0 - 50.0);
            Box3 { id: 100 + i * 997, min_m: [x, y, 0.0], max_m: [x + 18.0, y + 22.0, 10.0 + 7.0 * i as f64] }
        })
        .collect()
}

fn views() -> Vec<View> {
    let k = Intrinsics::from_hfov(96, 64, 60.0);
    let k2 = Intrinsics::from_hfov(120, 80, 45.0);
    vec![
        View { intrinsics: k, pose: Pose::from_ypr_deg(0.0, 0.0, 0.0, [0.0, 0.0, 220.0]) },
        View { intrinsics: k, pose: Pose::from_ypr_deg(45.0, 30.0, 0.0, [-90.0, -90.0, 180.0]) },
        View { intrinsics: k2, pose: Pose::from_ypr_deg(300.0, 45.0, 2.0, [120.0, -40.0, 150.0]) },
        View { intrinsics: k2, pose: Pose::from_ypr_deg(180.0, 60.0, 0.0, [0.0, 200.0, 160.0]) },
        View { intrinsics: k, pose: Pose::from_ypr_deg(90.0, 10.0, -3.0, [-10.0, 5.0, 300.0]) },
    ]
}

#[test]
fn rendering_twice_gives_identical_id_maps() {
    let r = renderer();
    let scene = r.upload(&box_mesh(&boxes())).unwrap();
    let opts = RenderOptions { linear_depth: true, ..Default::default() };
    let a = r.render_batch(&scene, &views(), &opts).unwrap();
    let b = r.render_batch(&scene, &views(), &opts).unwrap();
    assert_eq!(a.len(), 5);
    for (i, (x, y)) in a.iter().zip(&b).enumerate() {
        assert_eq!(x.ids, y.ids, "frame {i}");
        let (dx, dy) = (x.depth_m.as_ref().unwrap(), y.depth_m.as_ref().unwrap());
        assert!(dx.iter().zip(dy).all(|(p, q)| p.to_bits() == q.to_bits()), "frame {i} depth");
        assert!(!x.ids.visible_buildings().is_empty(), "frame {i} must show buildings");
    }
}

#[test]
fn batched_frames_equal_lone_renders() {
    // More frames than the ring holds, with a size change in the middle.
    let r = renderer();
    let scene = r.upload(&box_mesh(&boxes())).unwrap();
    let opts = RenderOptions::default();
    let mut vs = views();
    vs.extend(views());
    let batch = r.render_batch(&scene, &vs, &opts).unwrap();
    for (i, v) in vs.iter().enumerate() {
        let lone = r.render(&scene, v, &opts).unwrap();
        assert_eq!(batch[i], lone, "frame {i}");
    }
}

#[test]
fn writing_twice_gives_byte_identical_pngs() {
    let r = renderer();
    let scene = r.upload(&box_mesh(&boxes())).unwrap();
    let img = r.render(&scene, &views()[1], &RenderOptions::default()).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let (p1, p2) = (dir.path().join("a.png"), dir.path().join("b.png"));
    img.ids.write_png(&p1).unwrap();
    let again = r.render(&scene, &views()[1], &RenderOptions::default()).unwrap();
    again.ids.write_png(&p2).unwrap();
    assert_eq!(std::fs::read(&p1).unwrap(), std::fs::read(&p2).unwrap());
    // And the PNG holds exactly the rendered IDs.
    assert_eq!(IdMap::read_png(&p1).unwrap(), img.ids);
}

#[test]
fn a_caller_provided_device_renders_the_same() {
    // Renderer::with_device: the device is created here, as an application sharing its GPU would.
    let (device, queue) = pollster::block_on(async {
        let instance = wgpu::Instance::new(wgpu::InstanceDescriptor::new_without_display_handle_from_env());
        let adapter =
            instance.request_adapter(&wgpu::RequestAdapterOptions::default()).await.expect("adapter");
        adapter.request_device(&wgpu::DeviceDescriptor::default()).await.expect("device")
    });
    let own = insgen::render::Renderer::with_device(device, queue).unwrap();
    let scene_own = own.upload(&box_mesh(&boxes())).unwrap();
    let shared = renderer();
    let scene_shared = shared.upload(&box_mesh(&boxes())).unwrap();
    for v in views() {
        let a = own.render(&scene_own, &v, &RenderOptions::default()).unwrap();
        let b = shared.render(&scene_shared, &v, &RenderOptions::default()).unwrap();
        assert_eq!(a.ids, b.ids);
    }
}
