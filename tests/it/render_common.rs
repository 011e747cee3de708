//! Shared helpers of the render tests: one renderer per test binary, box scenes, and an independent
//! CPU f64 reference rasteriser ("which building does the pixel centre see?").
#![allow(dead_code)]

use std::sync::OnceLock;

use insgen::camera::{Intrinsics, Pose};
use insgen::render::Renderer;
use insgen::scene::SceneMesh;

/// The renderer shared by the tests of one binary. A missing adapter fails the test with the hint
/// (the setup script installs lavapipe; rendering tests are the point of these files).
pub fn renderer() -> &'static Renderer {
    static R: OnceLock<Renderer> = OnceLock::new();
    R.get_or_init(|| match Renderer::new() {
        Ok(r) => r,
        Err(e) => panic!("{e}"),
    })
}

/// An axis-aligned box in ENU metres with its building ID.
#[derive(Debug, Clone, Copy)]
pub struct Box3 {
    pub id: u32,
    pub min_m: [f64; 3],
    pub max_m: [f64; 3],
}

impl Box3 {
    pub fn corner(&self, c: usize) -> [f64; 3] {
        [0, 1, 2].map(|a| if c >> a & 1 == 0 { self.min_m[a] } else { self.max_m[a] })
    }

    /// The 6 faces as corner-index quads (in order around each face).
    pub fn faces() -> [[usize; 4]; 6] {
        [
            [0, 2, 6, 4], // x = min
            [1, 3, 7, 5], // x = max
            [0, 1, 5, 4], // y = min
            [2, 3, 7, 6], // y = max
            [0, 1, 3, 2], // z = min
            [4, 5, 7, 6], // z = max (roof)
        ]
    }
}

/// A triangle soup of boxes (each box its own 8 vertices, 12 triangles; mixed winding on purpose:
/// culling is off).
pub fn box_mesh(boxes: &[Box3]) -> SceneMesh {
    let mut m = SceneMesh::default();
    for b in boxes {
        let base = m.positions_m.len() as u32;
        for c in 0..8 {
            m.positions_m.push(b.corner(c).map(|v| v as f32));
            m.building_ids.push(insgen::scene::BuildingId::new(b.id).expect("test boxes have 24-bit IDs"));
        }
        for f in Box3::faces() {
            let [a, b_, c, d] = f.map(|i| base + i as u32);
            m.indices.extend_from_slice(&[a, b_, c, a, c, d]);
        }
    }
    m
}

/// Per pixel: the ID the f64 reference sees, and the distance (px) from the pixel centre to the nearest
/// projected face edge of any box (how close the pixel is to a boundary).
pub struct Reference {
    pub ids: Vec<u32>,
    pub edge_distance_px: Vec<f64>,
    /// Camera-frame z of the visible surface in metres (infinite where there is none).
    pub depth_m: Vec<f64>,
}

fn point_segment_distance(p: [f64; 2], a: [f64; 2], b: [f64; 2]) -> f64 {
    let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
    let len2 = dx * dx + dy * dy;
    let t = if len2 > 0.0 { (((p[0] - a[0]) * dx + (p[1] - a[1]) * dy) / len2).clamp(0.0, 1.0) } else { 0.0 };
    let (qx, qy) = (a[0] + t * dx - p[0], a[1] + t * dy - p[1]);
    (qx * qx + qy * qy).sqrt()
}

/// Whether `p` is inside the convex polygon `poly` (any orientation).
fn inside_convex(p: [f64; 2], poly: &[[f64; 2]]) -> bool {
    let mut sign = 0.0f64;
    for i in 0..poly.len() {
        let (a, b) = (poly[i], poly[(i + 1) % poly.len()]);
        let cross = (b[0] - a[0]) * (p[1] - a[1]) - (b[1] - a[1]) * (p[0] - a[0]);
        if cross == 0.0 {
            continue;
        }
        if sign == 0.0 {
            sign = cross.signum();
        } else if cross.signum() != sign {
            return false;
        }
    }
    sign != 0.0
}

/// The independent reference: every box face is projected with the camera's f64 maths (pose →
/// camera frame → u = fx x/z + cx, v = fy y/z + cy); a pixel centre (i + ½, j + ½) inside a projected
/// face sees that face at the depth where the pixel's ray meets the face's plane; the nearest face wins.
/// All box corners must be in front of the camera.
pub fn reference(boxes: &[Box3], k: &Intrinsics, pose: &Pose) -> Reference {
    let (w, h) = (k.width_px as usize, k.height_px as usize);
    let mut ids = vec![0u32; w * h];
    let mut depth = vec![f64::INFINITY; w * h];
    let mut edge = vec![f64::INFINITY; w * h];
    for b in boxes {
        let cam: Vec<glam::DVec3> = (0..8).map(|c| pose.world_to_cam(b.corner(c).into())).collect();
        assert!(cam.iter().all(|c| c.z > 0.1), "test setup: box {} must be in front of the camera", b.id);
        let uv: Vec<[f64; 2]> = cam.iter().map(|&c| k.project(c).unwrap()).collect();
        for f in Box3::faces() {
            let poly: Vec<[f64; 2]> = f.iter().map(|&i| uv[i]).collect();
            // Face plane in camera coordinates: n·X = d.
            let (p0, p1, p3) = (cam[f[0]], cam[f[1]], cam[f[3]]);
            let e1 = [p1[0] - p0[0], p1[1] - p0[1], p1[2] - p0[2]];
            let e2 = [p3[0] - p0[0], p3[1] - p0[1], p3[2] - p0[2]];
            let n =
                [e1[1] * e2[2] - e1[2] * e2[1], e1[2] * e2[0] - e1[0] * e2[2], e1[0] * e2[1] - e1[1] * e2[0]];
            let d = n[0] * p0[0] + n[1] * p0[1] + n[2] * p0[2];
            let (mut u0, mut v0, mut u1, mut v1) = (f64::MAX, f64::MAX, f64::MIN, f64::MIN);
            for p in &poly {
                u0 = u0.min(p[0]);
                v0 = v0.min(p[1]);
                u1 = u1.max(p[0]);
                v1 = v1.max(p[1]);
            }
            let x0 = (u0 - 2.0).floor().max(0.0) as usize;
            let y0 = (v0 - 2.0).floor().max(0.0) as usize;
            let x1 = ((u1 + 2.0).ceil().max(0.0) as usize).min(w);
            let y1 = ((v1 + 2.0).ceil().max(0.0) as usize).min(h);
            for y in y0..y1 {
                for x in x0..x1 {
                    let c = [x as f64 + 0.5, y as f64 + 0.5];
                    let i = y * w + x;
                    for e in 0..4 {
                        edge[i] = edge[i].min(point_segment_distance(c, poly[e], poly[(e + 1) % 4]));
                    }
                    if !inside_convex(c, &poly) {
                        continue;
                    }
                    // Ray X = t·((u − cx)/fx, (v − cy)/fy, 1): t is the camera-frame z of the hit.
                    let ray = [(c[0] - k.cx_px) / k.fx_px, (c[1] - k.cy_px) / k.fy_px, 1.0];
                    let denom = n[0] * ray[0] + n[1] * ray[1] + n[2] * ray[2];
                    if denom.abs() < 1e-12 {
                        continue; // seen edge-on: covers no pixel centre in the limit
                    }
                    let z = d / denom;
                    if z > 0.0 && z < depth[i] {
                        depth[i] = z;
                        ids[i] = b.id;
                    }
                }
            }
        }
    }
    Reference { ids, edge_distance_px: edge, depth_m: depth }
}

/// Pixel-by-pixel comparison of a rendered ID map with the reference.
#[derive(Debug)]
pub struct Comparison {
    pub mismatches: usize,
    /// Largest reference edge distance among mismatching pixels (px).
    pub worst_mismatch_edge_distance_px: f64,
    /// Pixels within 1 px of a projected edge (where a difference is tolerated).
    pub near_edge_pixels: usize,
}

pub fn compare(rendered: &[u32], reference: &Reference) -> Comparison {
    let mut c = Comparison { mismatches: 0, worst_mismatch_edge_distance_px: 0.0, near_edge_pixels: 0 };
    for (i, (&g, &r)) in rendered.iter().zip(&reference.ids).enumerate() {
        if reference.edge_distance_px[i] <= 1.0 {
            c.near_edge_pixels += 1;
        }
        if g != r {
            c.mismatches += 1;
            c.worst_mismatch_edge_distance_px =
                c.worst_mismatch_edge_distance_px.max(reference.edge_distance_px[i]);
        }
    }
    c
}

pub fn count(ids: &[u32], id: u32) -> usize {
    ids.iter().filter(|&&v| v == id).count()
}

/// Poses looking at the tallest buildings of a prepared scene: nadir and oblique (20°, 35°, 45°),
/// several yaws and heights, so depth order and perspective both matter.
pub fn poses_at_tallest(scene: &insgen::scene::PreparedScene, n: usize) -> Vec<Pose> {
    let mut tallest: Vec<_> = scene.buildings.iter().collect();
    tallest.sort_by(|a, b| b.height_m.total_cmp(&a.height_m).then(a.id.cmp(&b.id)));
    (0..n)
        .map(|i| {
            let b = tallest[i % tallest.len().min(8)];
            let target = [0, 1].map(|a| 0.5 * (b.bbox_min_enu_m[a] + b.bbox_max_enu_m[a]));
            let yaw = 37.0 * i as f64 + 11.0;
            let pitch: f64 = [0.0, 20.0, 35.0, 45.0][i % 4];
            let height = b.bbox_max_enu_m[2] + 120.0 + 40.0 * (i % 3) as f64;
            // Back off along the viewing direction so the target stays near the image centre.
            let back = (height - b.bbox_min_enu_m[2]) * f64::tan(pitch.to_radians());
            let yr = f64::to_radians(yaw);
            Pose::from_ypr_deg(
                yaw,
                pitch,
                0.0,
                [target[0] - back * yr.sin(), target[1] - back * yr.cos(), height],
            )
        })
        .collect()
}

/// Renders every pose with wgpu and with the CPU rasteriser (`render::cpu`) at 640×360 (cam2's field
/// of view) and asserts they agree on ≥ 99.9 % of all pixels; prints the per-pose counts.
pub fn assert_cpu_agrees_with_wgpu(name: &str, scene: &insgen::scene::PreparedScene, poses: &[Pose]) {
    use insgen::render::cpu::{render_ids, CpuScene, Frame};
    use insgen::render::{RenderOptions, View};
    let k = Intrinsics::from_hfov(1920, 1080, 25.0).scaled_to(640, 360);
    let r = renderer();
    let gpu_scene = r.upload(&scene.mesh).expect("upload");
    let views: Vec<View> = poses.iter().map(|&pose| View { intrinsics: k, pose }).collect();
    let gpu = r.render_batch(&gpu_scene, &views, &RenderOptions::default()).expect("wgpu render");
    let (mut diff, mut total, mut building) = (0usize, 0usize, 0usize);
    let mut frame = Frame::default();
    for (pose, g) in poses.iter().zip(&gpu) {
        let cpu = CpuScene::new(&scene.mesh, pose.centre_m);
        render_ids(&cpu.clone().with_back_face_culling(false), pose, &k, &mut frame);
        let unculled = frame.ids.clone();
        render_ids(&cpu, pose, &k, &mut frame);
        // Culling the back faces of closed buildings is exact: not one pixel may change.
        let culling_diff = frame.ids.iter().zip(&unculled).filter(|(a, b)| a != b).count();
        assert_eq!(culling_diff, 0, "{name} pose {:?}: back-face culling changed pixels", pose.ypr_deg());
        assert_eq!(frame.ids.len(), g.ids.raw().len());
        let d = frame.ids.iter().zip(g.ids.raw()).filter(|(a, b)| a != b).count();
        eprintln!("{name} pose {:?}: {d} of {} pixels differ", pose.ypr_deg(), g.ids.raw().len());
        diff += d;
        total += g.ids.raw().len();
        building += g.ids.raw().iter().filter(|&&i| i != 0).count();
    }
    let agreement = 1.0 - diff as f64 / total as f64;
    eprintln!("{name}: {diff} of {total} pixels differ → agreement {agreement:.6}");
    assert!(building > total / 4, "{name}: the poses must see buildings ({building} of {total} px)");
    assert!(agreement >= 0.999, "{name}: CPU and wgpu agree on {:.4} % of pixels", 100.0 * agreement);
}
