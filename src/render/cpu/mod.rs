//! A specialised CPU rasteriser for instance-ID images, for the localizer's many small frames.
//!
//! It follows the GPU conventions of `render` exactly where they matter for agreement: pinhole
//! projection u = fx·x/z + cx, v = fy·y/z + cy in pixel units; a pixel is covered when its centre
//! (i + 0.5, j + 0.5) is inside the triangle, with the top-left rule deciding centres exactly on an
//! edge (as Vulkan implementations do); the nearest surface wins (depth interpolated as 1/z, which is
//! linear in screen space); triangles are clipped at the near plane. Back faces are culled only where
//! that provably changes no pixel: buildings whose surface is a union of closed, consistently wound
//! shells (`solid`). Coplanar neighbours are drawn as one convex polygon (`polygons`), which covers
//! exactly their pixels with fewer rows to walk (`raster`).
//!
//! Geometry is transformed to the camera frame in f64 relative to the camera centre and only then
//! rounded to f32 screen coordinates, so nothing jitters at any magnitude.

mod polygons;
mod raster;
mod solid;

use crate::camera::{Intrinsics, Pose};
use crate::scene::SceneMesh;
use glam::DVec3;
use raster::{project, raster_convex, ClipVert, Screen, MAX_POLYGON, SUBPIXEL_BITS};
use solid::solid_winding;

/// Near clipping distance in metres (as the GPU renderer's default).
pub const NEAR_M: f64 = 0.1;

/// A mesh prepared for repeated CPU rasterisation: positions relative to an anchor (f64 → f32 after
/// subtracting), grouped by building (contiguous vertices and triangles with a bounding box each), so
/// a frame transforms only the buildings its frustum can see.
#[derive(Debug, Clone)]
pub struct CpuScene {
    anchor_m: DVec3,
    /// Positions relative to `anchor_m`, metres, building by building.
    positions: Vec<[f32; 3]>,
    triangles: Vec<[u32; 3]>,
    /// Convex polygons (vertex indices, in winding order) drawn instead of the triangles: polygon p
    /// is `polygon_vertices[polygon_starts[p]..polygon_starts[p + 1]]`.
    polygon_vertices: Vec<u32>,
    polygon_starts: Vec<u32>,
    groups: Vec<Group>,
    /// Skip the back faces of closed buildings (on by default; exact, see `solid_winding`).
    back_face_culling: bool,
}

/// One building's share of a [`CpuScene`].
#[derive(Debug, Clone)]
struct Group {
    id: u32,
    vertices: std::ops::Range<usize>,
    triangles: std::ops::Range<usize>,
    /// Indices into `polygon_starts`.
    polygons: std::ops::Range<usize>,
    /// Bounding box relative to the anchor, metres.
    min: [f32; 3],
    max: [f32; 3],
    /// Closed shells with consistent winding: +1 when its triangles wind counter-clockwise seen from
    /// outside (positive volume), −1 when clockwise, 0 otherwise (no culling). See `solid_winding`.
    solid: i8,
}

impl CpuScene {
    /// Builds a CPU scene from a mesh; `anchor_m` should be near the cameras (e.g. the prior centre).
    /// Vertices are welded by position within a building and duplicated where two buildings share one
    /// (IDs are per vertex).
    pub fn new(mesh: &SceneMesh, anchor_m: impl Into<DVec3>) -> CpuScene {
        let anchor_m = anchor_m.into();
        let rel = |p: [f32; 3]| (glam::Vec3::from(p).as_dvec3() - anchor_m).as_vec3().to_array();
        // Triangles by building (stable, so the draw order within a building is the mesh's).
        let mut order: Vec<usize> = (0..mesh.indices.len() / 3).collect();
        let tri_id = |t: usize| mesh.building_ids[mesh.indices[3 * t] as usize].get();
        order.sort_by_key(|&t| tri_id(t));
        let mut positions = Vec::new();
        let mut triangles = Vec::with_capacity(order.len());
        let mut groups: Vec<Group> = Vec::new();
        // Within a building, vertices are shared by position (bit for bit), so a triangle soup (glTF
        // tiles repeat corners per face) transforms each corner once per frame.
        let mut remap: std::collections::HashMap<[u32; 3], u32> = std::collections::HashMap::new();
        for &t in &order {
            let id = tri_id(t);
            if groups.last().is_none_or(|g| g.id != id) {
                remap.clear();
                groups.push(Group {
                    id,
                    vertices: positions.len()..positions.len(),
                    triangles: triangles.len()..triangles.len(),
                    polygons: 0..0,
                    min: [f32::INFINITY; 3],
                    max: [f32::NEG_INFINITY; 3],
                    solid: 0,
                });
            }
            let g = groups.last_mut().expect("pushed above");
            let tri = [0, 1, 2].map(|j| {
                let v = mesh.positions_m[mesh.indices[3 * t + j] as usize];
                *remap.entry(v.map(f32::to_bits)).or_insert_with(|| {
                    let p = rel(v);
                    for ((lo, hi), c) in g.min.iter_mut().zip(&mut g.max).zip(p) {
                        *lo = lo.min(c);
                        *hi = hi.max(c);
                    }
                    positions.push(p);
                    (positions.len() - 1) as u32
                })
            });
            triangles.push(tri);
            g.vertices.end = positions.len();
            g.triangles.end = triangles.len();
        }
        for g in &mut groups {
            g.solid = solid_winding(&positions, &triangles[g.triangles.clone()]);
        }
        let scene = CpuScene {
            anchor_m,
            positions,
            triangles,
            polygon_vertices: Vec::new(),
            polygon_starts: vec![0],
            groups,
            back_face_culling: true,
        };
        scene.with_merged_polygons(true)
    }

    /// Draws coplanar neighbours merged into convex polygons (`true`, the default) or every triangle
    /// on its own (for comparisons): the covered pixels are the same, the 1/z values may differ in
    /// the last bits.
    pub fn with_merged_polygons(mut self, on: bool) -> CpuScene {
        self.polygon_vertices.clear();
        self.polygon_starts = vec![0];
        for g in &mut self.groups {
            let tris = &self.triangles[g.triangles.clone()];
            let polys = if on {
                polygons::merge_coplanar(&self.positions, tris)
            } else {
                tris.iter().map(|t| t.to_vec()).collect()
            };
            let first = self.polygon_starts.len() - 1;
            for p in polys {
                self.polygon_vertices.extend(p);
                self.polygon_starts.push(self.polygon_vertices.len() as u32);
            }
            g.polygons = first..self.polygon_starts.len() - 1;
        }
        self
    }

    /// Triangles of the mesh (after welding; the polygons draw them).
    pub fn triangle_count(&self) -> usize {
        self.triangles.len()
    }

    /// Primitives a frame draws: convex polygons and the triangles left unmerged.
    pub fn polygon_count(&self) -> usize {
        self.polygon_starts.len() - 1
    }

    /// Triangles of the buildings recognised as closed and consistently wound, whose back faces are
    /// culled (see `solid_winding`).
    pub fn closed_triangle_count(&self) -> usize {
        self.groups.iter().filter(|g| g.solid != 0).map(|g| g.triangles.len()).sum()
    }

    /// Turns the culling of closed buildings' back faces on or off (for comparisons).
    pub fn with_back_face_culling(mut self, on: bool) -> CpuScene {
        self.back_face_culling = on;
        self
    }
}

/// A rendered ID image and the buffers that made it, reused frame after frame (one per thread). Every
/// renderer of [`crate::render::IdScene`] fills `ids`; the rest is the CPU rasteriser's scratch.
#[derive(Debug, Default)]
pub struct Frame {
    /// Building IDs of the last render, row-major (width × height pixels of its intrinsics),
    /// 0 = background.
    pub ids: Vec<u32>,
    inv_z: Vec<f32>,
    cam: Vec<[f32; 3]>,
    /// Per vertex in front of the near plane: snapped screen position and 1/z.
    screen: Vec<Screen>,
}

impl Frame {
    /// Linear depth along the optical axis of the last render, metres, row-major (1/(1/z) of the
    /// nearest surface drawn, occluders included; 0 where nothing was drawn), as the wgpu renderer's
    /// R32Float target holds it.
    pub fn depth_m(&self) -> impl Iterator<Item = f32> + '_ {
        self.inv_z.iter().map(|&q| if q > 0.0 { 1.0 / q } else { 0.0 })
    }
}

/// Renders building IDs of `scene` seen by `pose`/`k` into `frame.ids` (row-major, 0 = background).
pub fn render_ids(scene: &CpuScene, pose: &Pose, k: &Intrinsics, frame: &mut Frame) {
    render_groups(scene, pose, k, frame, |_| true);
}

/// Renders only building `id` of `scene` (drawn alone, nothing in front of it), as
/// [`render_ids`] does: the pixels it covers on its own (amodal coverage).
pub fn render_building_alone(scene: &CpuScene, pose: &Pose, k: &Intrinsics, id: u32, frame: &mut Frame) {
    render_groups(scene, pose, k, frame, |g| g == id);
}

/// [`render_ids`] restricted to the buildings whose ID `keep` accepts.
fn render_groups(
    scene: &CpuScene,
    pose: &Pose,
    k: &Intrinsics,
    frame: &mut Frame,
    keep: impl Fn(u32) -> bool,
) {
    let (w, h) = (k.width_px as usize, k.height_px as usize);
    frame.ids.clear();
    frame.ids.resize(w * h, 0);
    frame.inv_z.clear();
    frame.inv_z.resize(w * h, 0.0);
    // Camera-frame vertices: R_cw (p + anchor − C), with (anchor − C) computed in f64.
    let r = pose.r_cam_from_world();
    let rt = r * (scene.anchor_m - pose.centre_m);
    let (rf, rtf) = (r.as_mat3(), rt.as_vec3());
    let to_cam = |p: &[f32; 3]| (rf * glam::Vec3::from(*p) + rtf).to_array();
    let near = NEAR_M as f32;
    let n = scene.positions.len();
    frame.cam.resize(n, [0.0; 3]);
    frame.screen.resize(n, Screen::default());
    // Pixel centres span [half, (n − 1)·one + half] in sub-pixel units.
    let (one, half) = (1i64 << SUBPIXEL_BITS, 1i64 << (SUBPIXEL_BITS - 1));
    let (xmax, ymax) = ((w as i64 - 1) * one + half, (h as i64 - 1) * one + half);
    let mut poly: Vec<ClipVert> = Vec::with_capacity(4);
    let frustum = Frustum::new(k, near);
    for g in scene.groups.iter().filter(|g| keep(g.id)) {
        // Building-level frustum test on the 8 box corners: invisible when all of them lie outside
        // one plane of the frustum (the near plane, or a side plane one pixel beyond the image).
        let mut outside = [true; 5];
        let mut in_front = 0;
        for c in 0..8 {
            let p = [
                if c & 1 == 0 { g.min[0] } else { g.max[0] },
                if c & 2 == 0 { g.min[1] } else { g.max[1] },
                if c & 4 == 0 { g.min[2] } else { g.max[2] },
            ];
            let q = to_cam(&p);
            let inside = frustum.inside(q);
            in_front += inside[0] as u32;
            for (o, i) in outside.iter_mut().zip(inside) {
                *o &= !i;
            }
        }
        if outside.iter().any(|&o| o) {
            continue;
        }
        // Transform and project this building's vertices once (shared by its triangles).
        for vi in g.vertices.clone() {
            let q = to_cam(&scene.positions[vi]);
            frame.cam[vi] = q;
            frame.screen[vi] = if q[2] >= near {
                project(k, ClipVert { x: q[0] as f64, y: q[1] as f64, z: q[2] as f64 })
            } else {
                Screen::default()
            };
        }
        let id = g.id;
        // Back faces of a closed building entirely in front of the camera are hidden by its front
        // faces (see `solid_winding`). On screen (y down) a face wound counter-clockwise seen from
        // outside has a negative signed area when it faces the camera.
        let cull = if scene.back_face_culling && in_front == 8 { g.solid as i64 } else { 0 };
        // With the whole box in front of the near plane no triangle needs clipping.
        let all_in_front = in_front == 8;
        for p in g.polygons.clone() {
            let vs = &scene.polygon_vertices
                [scene.polygon_starts[p] as usize..scene.polygon_starts[p + 1] as usize];
            let clipped = !all_in_front && vs.iter().any(|&i| frame.cam[i as usize][2] < near);
            if !clipped {
                let mut s = [Screen::default(); MAX_POLYGON];
                for (d, &i) in s.iter_mut().zip(vs) {
                    *d = frame.screen[i as usize];
                }
                let s = &s[..vs.len()];
                // Off-screen polygons leave before any set-up.
                let (mut x_lo, mut x_hi, mut y_lo, mut y_hi) = (i64::MAX, i64::MIN, i64::MAX, i64::MIN);
                for v in s {
                    (x_lo, x_hi, y_lo, y_hi) = (x_lo.min(v.x), x_hi.max(v.x), y_lo.min(v.y), y_hi.max(v.y));
                }
                if x_hi < half || x_lo > xmax || y_hi < half || y_lo > ymax {
                    continue;
                }
                raster_convex(s, id, cull, &mut frame.ids, &mut frame.inv_z, w, h);
                continue;
            }
            // Crossing the near plane: triangle by triangle (the polygon's fan), clipped.
            for i in 1..vs.len() - 1 {
                let v = [vs[0], vs[i], vs[i + 1]].map(|i| frame.cam[i as usize]);
                draw_clipped(v, id, k, &frustum, &mut poly, frame, w, h);
            }
        }
    }
}

/// Draws a camera-frame triangle that may cross the near plane: clipped against it (Sutherland–
/// Hodgman) and fan-triangulated; never culled.
#[allow(clippy::too_many_arguments)]
fn draw_clipped(
    v: [[f32; 3]; 3],
    id: u32,
    k: &Intrinsics,
    frustum: &Frustum,
    poly: &mut Vec<ClipVert>,
    frame: &mut Frame,
    w: usize,
    h: usize,
) {
    let near = frustum.near;
    if v.iter().all(|p| p[2] < near) {
        return;
    }
    if v.iter().all(|p| p[2] >= near) {
        let [a, b, c] = v.map(|p| project(k, ClipVert { x: p[0] as f64, y: p[1] as f64, z: p[2] as f64 }));
        raster_convex(&[a, b, c], id, 0, &mut frame.ids, &mut frame.inv_z, w, h);
        return;
    }
    // A triangle crossing the camera plane far outside the view (below the camera of an
    // oblique view, say) is dropped when its corners all lie beyond one side plane.
    let ins = v.map(|p| frustum.inside(p));
    if (1..5).any(|n| ins.iter().all(|i| !i[n])) {
        return;
    }
    // Clip against z = near (Sutherland–Hodgman) and fan-triangulate.
    poly.clear();
    for e in 0..3 {
        let (p, q) = (v[e], v[(e + 1) % 3]);
        let (pin, qin) = (p[2] >= near, q[2] >= near);
        if pin {
            poly.push(ClipVert { x: p[0] as f64, y: p[1] as f64, z: p[2] as f64 });
        }
        if pin != qin {
            let s = (NEAR_M - p[2] as f64) / (q[2] as f64 - p[2] as f64);
            poly.push(ClipVert {
                x: p[0] as f64 + s * (q[0] as f64 - p[0] as f64),
                y: p[1] as f64 + s * (q[1] as f64 - p[1] as f64),
                z: NEAR_M,
            });
        }
    }
    for i in 1..poly.len().saturating_sub(1) {
        let [a, b, c] = [poly[0], poly[i], poly[i + 1]].map(|p| project(k, p));
        raster_convex(&[a, b, c], id, 0, &mut frame.ids, &mut frame.inv_z, w, h);
    }
}

/// The view frustum in camera coordinates as five half-spaces: z ≥ near and the four side planes
/// through the camera centre one pixel beyond the image border (u ≥ −1, u ≤ w + 1, v ≥ −1, v ≤ h + 1,
/// written without the division by z so they hold for points behind the camera too).
struct Frustum {
    near: f32,
    fx: f32,
    fy: f32,
    left: f32,
    right: f32,
    top: f32,
    bottom: f32,
}

impl Frustum {
    fn new(k: &Intrinsics, near: f32) -> Frustum {
        Frustum {
            near,
            fx: k.fx_px as f32,
            fy: k.fy_px as f32,
            left: k.cx_px as f32 + 1.0,
            right: k.width_px as f32 + 1.0 - k.cx_px as f32,
            top: k.cy_px as f32 + 1.0,
            bottom: k.height_px as f32 + 1.0 - k.cy_px as f32,
        }
    }

    /// Per half-space (near, left, right, top, bottom): whether `q` lies inside it.
    #[inline]
    fn inside(&self, q: [f32; 3]) -> [bool; 5] {
        let (fx, fy) = (self.fx * q[0], self.fy * q[1]);
        [
            q[2] >= self.near,
            fx + self.left * q[2] >= 0.0,
            self.right * q[2] - fx >= 0.0,
            fy + self.top * q[2] >= 0.0,
            self.bottom * q[2] - fy >= 0.0,
        ]
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::scene::BuildingId;

    fn quad(mesh: &mut SceneMesh, corners: [[f32; 3]; 4], id: u32) {
        let base = mesh.positions_m.len() as u32;
        mesh.positions_m.extend_from_slice(&corners);
        mesh.building_ids.extend([BuildingId::new(id).unwrap(); 4]);
        mesh.indices.extend([base, base + 1, base + 2, base, base + 2, base + 3]);
    }

    #[test]
    fn nadir_square_has_exact_pixel_count() {
        // A 20 m × 20 m roof at z = 0 seen from 100 m at nadir with f = 100 px: it spans 20 px × 20 px
        // centred on the principal point (32, 24) → exactly 400 pixel centres inside.
        let mut m = SceneMesh::default();
        quad(&mut m, [[-10.0, -10.0, 0.0], [10.0, -10.0, 0.0], [10.0, 10.0, 0.0], [-10.0, 10.0, 0.0]], 7);
        let k =
            Intrinsics { width_px: 64, height_px: 48, fx_px: 100.0, fy_px: 100.0, cx_px: 32.0, cy_px: 24.0 };
        let pose = Pose::from_ypr_deg(0.0, 0.0, 0.0, [0.0, 0.0, 100.0]);
        let scene = CpuScene::new(&m, [0.0, 0.0, 50.0]);
        let mut f = Frame::default();
        render_ids(&scene, &pose, &k, &mut f);
        assert_eq!(f.ids.iter().filter(|&&i| i == 7).count(), 400);
        // Columns 22..42 and rows 14..34 (pixel centres 22.5 … 41.5 lie inside [22, 42]).
        assert_eq!(f.ids[14 * 64 + 22], 7);
        assert_eq!(f.ids[13 * 64 + 22], 0);
        assert_eq!(f.ids[33 * 64 + 41], 7);
        assert_eq!(f.ids[34 * 64 + 41], 0);
    }

    /// A closed box, triangles counter-clockwise seen from outside (`flip` reverses them), corners
    /// repeated per face as in glTF tiles; optionally without its floor (open).
    pub(crate) fn closed_box(
        m: &mut SceneMesh,
        lo: [f32; 3],
        hi: [f32; 3],
        id: u32,
        flip: bool,
        floor: bool,
    ) {
        let p = |i: usize| {
            [
                if i & 1 == 0 { lo[0] } else { hi[0] },
                if i & 2 == 0 { lo[1] } else { hi[1] },
                if i & 4 == 0 { lo[2] } else { hi[2] },
            ]
        };
        // Faces as corner indices, counter-clockwise seen from outside.
        let faces = [[0, 2, 3, 1], [4, 5, 7, 6], [0, 1, 5, 4], [2, 6, 7, 3], [0, 4, 6, 2], [1, 3, 7, 5]];
        for (f, q) in faces.iter().enumerate() {
            if f == 0 && !floor {
                continue;
            }
            for t in [[q[0], q[1], q[2]], [q[0], q[2], q[3]]] {
                let t = if flip { [t[0], t[2], t[1]] } else { t };
                let base = m.positions_m.len() as u32;
                for c in t {
                    m.positions_m.push(p(c));
                    m.building_ids.push(BuildingId::new(id).unwrap());
                }
                m.indices.extend([base, base + 1, base + 2]);
            }
        }
    }

    #[test]
    fn closed_buildings_are_recognised_with_their_winding() {
        let mut m = SceneMesh::default();
        closed_box(&mut m, [0.0; 3], [10.0, 10.0, 10.0], 1, false, true);
        closed_box(&mut m, [20.0, 0.0, 0.0], [30.0, 10.0, 10.0], 2, true, true);
        closed_box(&mut m, [40.0, 0.0, 0.0], [50.0, 10.0, 10.0], 3, false, false);
        let scene = CpuScene::new(&m, [0.0; 3]);
        assert_eq!(scene.groups.iter().map(|g| g.solid).collect::<Vec<_>>(), vec![1, -1, 0]);
        // Welded: 8 corners per closed box, 8 for the open one too.
        assert_eq!(scene.positions.len(), 24);
    }

    #[test]
    fn buildings_of_several_parts_are_recognised() {
        let solid = |boxes: &[([f32; 3], [f32; 3], bool)]| {
            let mut m = SceneMesh::default();
            for &(lo, hi, flip) in boxes {
                closed_box(&mut m, lo, hi, 1, flip, true);
            }
            CpuScene::new(&m, [0.0; 3]).groups[0].solid
        };
        let a = ([0.0; 3], [10.0, 10.0, 10.0]);
        // Two parts sharing a wall (its triangles coincide, opposite), or only an edge.
        assert_eq!(solid(&[(a.0, a.1, false), ([10.0, 0.0, 0.0], [20.0, 10.0, 10.0], false)]), 1);
        assert_eq!(solid(&[(a.0, a.1, true), ([10.0, 0.0, 0.0], [20.0, 10.0, 10.0], true)]), -1);
        assert_eq!(solid(&[(a.0, a.1, false), ([10.0, 10.0, 0.0], [20.0, 20.0, 10.0], false)]), 1);
        // A part inside out, glued at a wall or an edge or apart; a cavity: not culled.
        assert_eq!(solid(&[(a.0, a.1, false), ([10.0, 0.0, 0.0], [20.0, 10.0, 10.0], true)]), 0);
        assert_eq!(solid(&[(a.0, a.1, false), ([10.0, 10.0, 0.0], [20.0, 20.0, 10.0], true)]), 0);
        assert_eq!(solid(&[(a.0, a.1, false), ([30.0, 0.0, 0.0], [40.0, 10.0, 10.0], true)]), 0);
        assert_eq!(solid(&[(a.0, a.1, false), ([2.0; 3], [8.0; 3], true)]), 0);
        // A tower standing on a podium's roof shares no vertex with it: two closed shells.
        assert_eq!(solid(&[(a.0, a.1, false), ([2.0, 2.0, 10.0], [8.0, 8.0, 30.0], false)]), 1);
        // The same tower with its floor missing: open.
        let mut m = SceneMesh::default();
        closed_box(&mut m, a.0, a.1, 1, false, true);
        closed_box(&mut m, [2.0, 2.0, 10.0], [8.0, 8.0, 30.0], 1, false, false);
        assert_eq!(CpuScene::new(&m, [0.0; 3]).groups[0].solid, 0);
    }

    /// 60 boxes scattered over ±120 m, of both windings, every fifth open (never culled), intersecting
    /// in view; with `parts`, every third building has a second part sharing a wall or an edge.
    fn random_boxes(seed: u64, parts: bool) -> SceneMesh {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let mut m = SceneMesh::default();
        for id in 1..=60u32 {
            let (x, y) = (rng.gen_range(-120.0..120.0f32), rng.gen_range(-120.0..120.0f32));
            let (sx, sy, h) =
                (rng.gen_range(5.0..30.0f32), rng.gen_range(5.0..30.0f32), rng.gen_range(5.0..80.0f32));
            closed_box(&mut m, [x, y, 0.0], [x + sx, y + sy, h], id, id % 3 == 1, id % 5 != 0);
            if parts && id % 3 == 0 {
                let (x2, y2) = if id % 2 == 0 { (x + sx, y) } else { (x + sx, y + sy) };
                closed_box(&mut m, [x2, y2, 0.0], [x2 + sx, y2 + sy, h], id, false, id % 5 != 0);
            }
        }
        m
    }

    fn view_200x150() -> Intrinsics {
        Intrinsics { width_px: 200, height_px: 150, fx_px: 180.0, fy_px: 180.0, cx_px: 100.0, cy_px: 75.0 }
    }

    #[test]
    fn culling_back_faces_of_closed_buildings_changes_no_pixel() {
        // Every third building has a second part sharing a wall or an edge with the first.
        let culled = CpuScene::new(&random_boxes(3, true), [0.0, 0.0, 100.0]);
        assert!(culled.groups.iter().filter(|g| g.solid != 0).count() >= 40);
        let unculled = culled.clone().with_back_face_culling(false);
        let k = view_200x150();
        let (mut a, mut b) = (Frame::default(), Frame::default());
        let mut drawn = 0;
        for i in 0..24 {
            let pose = Pose::from_ypr_deg(
                i as f64 * 15.0,
                (i % 4) as f64 * 22.0,
                0.0,
                [0.0, -150.0 + i as f64 * 5.0, 160.0],
            );
            render_ids(&culled, &pose, &k, &mut a);
            render_ids(&unculled, &pose, &k, &mut b);
            assert!(a.ids == b.ids, "view {i}: culling changed the ID image");
            drawn += a.ids.iter().filter(|&&id| id != 0).count();
        }
        assert!(drawn > 100_000, "the views see the boxes ({drawn} px)");
    }

    #[test]
    fn merged_polygons_cover_the_pixels_of_their_triangles() {
        // The boxes' walls cross, so the depth order decides many pixels.
        let merged = CpuScene::new(&random_boxes(9, false), [0.0, 0.0, 100.0]);
        let triangles = merged.clone().with_merged_polygons(false);
        assert_eq!(merged.polygon_count() * 2, triangles.polygon_count(), "every face is one quad");
        let k = view_200x150();
        let (mut a, mut b) = (Frame::default(), Frame::default());
        let (mut drawn, mut differ) = (0usize, 0usize);
        for i in 0..24 {
            // Some views from inside a box's footprint and low, so walls cross the near plane.
            let pose = Pose::from_ypr_deg(
                i as f64 * 15.0,
                (i % 4) as f64 * 25.0,
                0.0,
                [-60.0 + i as f64 * 5.0, -150.0 + i as f64 * 12.0, [160.0, 40.0, 3.0][i % 3]],
            );
            render_ids(&merged, &pose, &k, &mut a);
            render_ids(&triangles, &pose, &k, &mut b);
            let mask = |f: &Frame| f.ids.iter().map(|&id| id != 0).collect::<Vec<_>>();
            assert!(mask(&a) == mask(&b), "view {i}: the covered pixels differ");
            drawn += a.ids.iter().filter(|&&id| id != 0).count();
            differ += a.ids.iter().zip(&b.ids).filter(|(x, y)| x != y).count();
        }
        assert!(drawn > 100_000, "the views see the boxes ({drawn} px)");
        // 1/z comes from one triangle of the polygon: where two buildings' walls cross, the last
        // bits may decide a pixel the other way.
        assert!(differ * 10_000 <= drawn, "{differ} of {drawn} pixels change their ID");
    }

    #[test]
    fn culling_keeps_the_roof_not_the_floor() {
        // Seen from above, a closed box shows its roof: the depth is the roof's (1/z = 1/90).
        for flip in [false, true] {
            let mut m = SceneMesh::default();
            closed_box(&mut m, [-10.0, -10.0, 0.0], [10.0, 10.0, 10.0], 1, flip, true);
            let scene = CpuScene::new(&m, [0.0; 3]);
            assert_ne!(scene.groups[0].solid, 0);
            let k = Intrinsics {
                width_px: 64,
                height_px: 48,
                fx_px: 100.0,
                fy_px: 100.0,
                cx_px: 32.0,
                cy_px: 24.0,
            };
            let mut f = Frame::default();
            render_ids(&scene, &Pose::from_ypr_deg(0.0, 0.0, 0.0, [0.0, 0.0, 100.0]), &k, &mut f);
            let centre = 24 * 64 + 32;
            assert_eq!(f.ids[centre], 1);
            assert!((f.inv_z[centre] - 1.0 / 90.0).abs() < 1e-6, "flip {flip}: 1/z = {}", f.inv_z[centre]);
        }
    }

    #[test]
    fn nearer_surface_wins_and_shared_edges_cover_once() {
        let mut m = SceneMesh::default();
        quad(&mut m, [[-10.0, -10.0, 0.0], [10.0, -10.0, 0.0], [10.0, 10.0, 0.0], [-10.0, 10.0, 0.0]], 1);
        quad(&mut m, [[-5.0, -5.0, 30.0], [5.0, -5.0, 30.0], [5.0, 5.0, 30.0], [-5.0, 5.0, 30.0]], 2);
        let k =
            Intrinsics { width_px: 64, height_px: 48, fx_px: 100.0, fy_px: 100.0, cx_px: 32.0, cy_px: 24.0 };
        let pose = Pose::from_ypr_deg(0.0, 0.0, 0.0, [0.0, 0.0, 100.0]);
        let mut f = Frame::default();
        render_ids(&CpuScene::new(&m, [0.0; 3]), &pose, &k, &mut f);
        // The upper square (70 m away, half-width 5 m) projects to 5/70·100 ≈ 7.14 px half-width:
        // centres with |u − 32| < 7.14 → 14 columns × 14 rows = 196, its diagonal (through pixel
        // centres) covered exactly once. The lower one keeps 400 − 196 pixels.
        assert_eq!(f.ids.iter().filter(|&&i| i == 2).count(), 196);
        assert_eq!(f.ids.iter().filter(|&&i| i == 1).count(), 400 - 196);
    }

    #[test]
    fn geometry_behind_the_camera_is_clipped() {
        // A wall crossing the camera plane: half in front, half behind; nothing wraps around.
        let mut m = SceneMesh::default();
        quad(&mut m, [[-50.0, 10.0, -50.0], [50.0, 10.0, -50.0], [50.0, 10.0, 50.0], [-50.0, 10.0, 50.0]], 3);
        let k =
            Intrinsics { width_px: 32, height_px: 32, fx_px: 16.0, fy_px: 16.0, cx_px: 16.0, cy_px: 16.0 };
        // Looking north, horizontal: the wall at y = 10 fills the view.
        let pose = Pose::from_ypr_deg(0.0, 90.0, 0.0, [0.0, 0.0, 0.0]);
        let mut f = Frame::default();
        render_ids(&CpuScene::new(&m, [0.0; 3]), &pose, &k, &mut f);
        assert!(f.ids.iter().all(|&i| i == 3), "the wall covers the whole view");
    }
}
