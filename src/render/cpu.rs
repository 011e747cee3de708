//! A specialised CPU rasteriser for instance-ID images, for the localizer's many small frames.
//!
//! It follows the GPU conventions of `render` exactly where they matter for agreement: pinhole
//! projection u = fx·x/z + cx, v = fy·y/z + cy in pixel units; a pixel is covered when its centre
//! (i + 0.5, j + 0.5) is inside the triangle, with the top-left rule deciding centres exactly on an
//! edge (as Vulkan implementations do); the nearest surface wins (depth interpolated as 1/z, which is
//! linear in screen space); triangles are clipped at the near plane. Back faces are culled only where
//! that provably changes no pixel: buildings whose surface is a union of closed, consistently wound
//! shells (`solid_winding`).
//!
//! Geometry is transformed to the camera frame in f64 relative to the camera centre and only then
//! rounded to f32 screen coordinates, so nothing jitters at any magnitude.

use crate::camera::{Intrinsics, Pose};
use crate::scene::SceneMesh;

/// Near clipping distance in metres (as the GPU renderer's default).
pub const NEAR_M: f64 = 0.1;

/// A mesh prepared for repeated CPU rasterisation: positions relative to an anchor (f64 → f32 after
/// subtracting), grouped by building (contiguous vertices and triangles with a bounding box each), so
/// a frame transforms only the buildings its frustum can see.
#[derive(Debug, Clone)]
pub struct CpuScene {
    anchor_m: [f64; 3],
    /// Positions relative to `anchor_m`, metres, building by building.
    positions: Vec<[f32; 3]>,
    triangles: Vec<[u32; 3]>,
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
    pub fn new(mesh: &SceneMesh, anchor_m: [f64; 3]) -> CpuScene {
        let rel = |p: [f32; 3]| {
            [
                (p[0] as f64 - anchor_m[0]) as f32,
                (p[1] as f64 - anchor_m[1]) as f32,
                (p[2] as f64 - anchor_m[2]) as f32,
            ]
        };
        // Triangles by building (stable, so the draw order within a building is the mesh's).
        let mut order: Vec<usize> = (0..mesh.indices.len() / 3).collect();
        let tri_id = |t: usize| mesh.building_ids[mesh.indices[3 * t] as usize];
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
                    for a in 0..3 {
                        g.min[a] = g.min[a].min(p[a]);
                        g.max[a] = g.max[a].max(p[a]);
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
        CpuScene { anchor_m, positions, triangles, groups, back_face_culling: true }
    }

    pub fn triangle_count(&self) -> usize {
        self.triangles.len()
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

/// Whether `tris` (vertices welded by position) bound solids consistently: returns the orientation
/// (+1 when the triangles wind counter-clockwise seen from outside, −1 when clockwise) if the surface
/// is a union of closed shells that all wind the same way, else 0 (no culling).
///
/// Recognised: every directed edge (a, b) occurs as often as its reverse (b, a) (closed); where more
/// than two triangles meet at an edge (parts of a building sharing an edge or a wall), going round
/// the edge their orientations alternate once coincident opposite pairs (a shared wall) cancel, so
/// no part is glued on inside out; and every edge-connected component encloses a volume of the same
/// sign (no inverted shell elsewhere, no cavity).
///
/// For such a surface the winding number is 0 outside and ≥ 0 everywhere, so along any ray from a
/// camera outside the building the first surface crossed is front-facing: every pixel a back-facing
/// triangle covers is covered by a front-facing one at least as near, with the same ID. At a
/// silhouette edge the two triangles lie on the same side of it, so the top-left rule decides a
/// centre on it alike for both: culling the back faces leaves the ID image unchanged (tested on
/// random boxes and parts, the demo and Shibuya).
fn solid_winding(positions: &[[f32; 3]], tris: &[[u32; 3]]) -> i8 {
    use std::collections::HashMap;
    if tris.len() < 4 {
        return 0;
    }
    // Directed edge → the triangles using it.
    let mut edges: HashMap<(u32, u32), Vec<u32>> = HashMap::new();
    for (f, t) in tris.iter().enumerate() {
        if t[0] == t[1] || t[1] == t[2] || t[0] == t[2] {
            return 0;
        }
        for (a, b) in [(t[0], t[1]), (t[1], t[2]), (t[2], t[0])] {
            edges.entry((a, b)).or_default().push(f as u32);
        }
    }
    let reverse = |a: u32, b: u32| edges.get(&(b, a)).map_or(&[][..], Vec::as_slice);
    if edges.iter().any(|(&(a, b), fs)| reverse(a, b).len() != fs.len()) {
        return 0;
    }
    let pos = |i: u32| positions[i as usize].map(f64::from);
    for (&(a, b), fs) in &edges {
        if a < b
            && fs.len() > 1
            && !alternates_around_edge(pos(a), pos(b), tris, a, b, fs, reverse(a, b), &pos)
        {
            return 0;
        }
    }
    // Edge-connected components (union–find over triangles), each with its signed volume.
    let mut parent: Vec<u32> = (0..tris.len() as u32).collect();
    fn root(parent: &mut [u32], mut i: u32) -> u32 {
        while parent[i as usize] != i {
            parent[i as usize] = parent[parent[i as usize] as usize];
            i = parent[i as usize];
        }
        i
    }
    for (&(a, b), fs) in &edges {
        for &f in fs.iter().chain(reverse(a, b)) {
            let (r0, r1) = (root(&mut parent, fs[0]), root(&mut parent, f));
            parent[r1 as usize] = r0;
        }
    }
    let mut volume: HashMap<u32, f64> = HashMap::new();
    for (f, t) in tris.iter().enumerate() {
        let [a, b, c] = t.map(pos);
        let det = a[0] * (b[1] * c[2] - b[2] * c[1]) - a[1] * (b[0] * c[2] - b[2] * c[0])
            + a[2] * (b[0] * c[1] - b[1] * c[0]);
        *volume.entry(root(&mut parent, f as u32)).or_insert(0.0) += det;
    }
    if volume.values().all(|&v| v > 0.0) {
        1
    } else if volume.values().all(|&v| v < 0.0) {
        -1
    } else {
        0
    }
}

/// Whether the triangles at the non-manifold edge (a, b) — `fwd` using it as (a, b), `back` as
/// (b, a) — alternate in orientation going round the edge, after coincident triangles of opposite
/// orientation (two parts' shared wall) cancel. Two coincident triangles of the same orientation, or
/// two neighbours of the same orientation (a part inside out), fail.
#[allow(clippy::too_many_arguments)]
fn alternates_around_edge(
    pa: [f64; 3],
    pb: [f64; 3],
    tris: &[[u32; 3]],
    a: u32,
    b: u32,
    fwd: &[u32],
    back: &[u32],
    pos: &dyn Fn(u32) -> [f64; 3],
) -> bool {
    let sub = |p: [f64; 3], q: [f64; 3]| [p[0] - q[0], p[1] - q[1], p[2] - q[2]];
    let cross = |p: [f64; 3], q: [f64; 3]| {
        [p[1] * q[2] - p[2] * q[1], p[2] * q[0] - p[0] * q[2], p[0] * q[1] - p[1] * q[0]]
    };
    let dot = |p: [f64; 3], q: [f64; 3]| p[0] * q[0] + p[1] * q[1] + p[2] * q[2];
    let d = sub(pb, pa);
    // A basis (e1, e2) of the plane normal to the edge.
    let helper = if d[0].abs() <= d[1].abs() && d[0].abs() <= d[2].abs() {
        [1.0, 0.0, 0.0]
    } else if d[1].abs() <= d[2].abs() {
        [0.0, 1.0, 0.0]
    } else {
        [0.0, 0.0, 1.0]
    };
    let e1 = cross(d, helper);
    let e2 = cross(d, e1);
    let mut around: Vec<(f64, i32)> = fwd
        .iter()
        .map(|&f| (f, 1))
        .chain(back.iter().map(|&f| (f, -1)))
        .map(|(f, o)| {
            let t = tris[f as usize];
            let c = t.into_iter().find(|&v| v != a && v != b).expect("a triangle has a third vertex");
            let u = sub(pos(c), pa);
            (dot(u, e2).atan2(dot(u, e1)), o)
        })
        .collect();
    around.sort_by(|x, y| x.0.total_cmp(&y.0));
    // Net orientation per direction (coincident triangles grouped), zeros dropped.
    let mut nets: Vec<i32> = Vec::new();
    let mut i = 0;
    while i < around.len() {
        let mut j = i;
        let mut net = 0;
        while j < around.len() && around[j].0 - around[i].0 <= 1e-9 {
            net += around[j].1;
            j += 1;
        }
        if net.abs() > 1 {
            return false;
        }
        if net != 0 {
            nets.push(net);
        }
        i = j;
    }
    (0..nets.len()).all(|i| nets[i] != nets[(i + 1) % nets.len()])
}

/// Reusable per-thread buffers.
#[derive(Debug, Default)]
pub struct Frame {
    pub ids: Vec<u32>,
    inv_z: Vec<f32>,
    cam: Vec<[f32; 3]>,
    /// Per vertex in front of the near plane: snapped screen position and 1/z.
    screen: Vec<Screen>,
}

/// A vertex on screen: position in 1/256 px (integers, so edge functions are exact) and 1/z.
#[derive(Debug, Clone, Copy, Default)]
struct Screen {
    x: i64,
    y: i64,
    inv_z: f64,
}

#[derive(Clone, Copy)]
struct ClipVert {
    x: f64,
    y: f64,
    z: f64,
}

/// Renders building IDs of `scene` seen by `pose`/`k` into `frame.ids` (row-major, 0 = background).
pub fn render_ids(scene: &CpuScene, pose: &Pose, k: &Intrinsics, frame: &mut Frame) {
    let (w, h) = (k.width_px as usize, k.height_px as usize);
    frame.ids.clear();
    frame.ids.resize(w * h, 0);
    frame.inv_z.clear();
    frame.inv_z.resize(w * h, 0.0);
    // Camera-frame vertices: R_cw (p + anchor − C), with (anchor − C) computed in f64.
    let r = pose.r_cam_from_world();
    let t = [
        scene.anchor_m[0] - pose.centre_m[0],
        scene.anchor_m[1] - pose.centre_m[1],
        scene.anchor_m[2] - pose.centre_m[2],
    ];
    let rt = [
        r[0][0] * t[0] + r[0][1] * t[1] + r[0][2] * t[2],
        r[1][0] * t[0] + r[1][1] * t[1] + r[1][2] * t[2],
        r[2][0] * t[0] + r[2][1] * t[1] + r[2][2] * t[2],
    ];
    let rf = r.map(|row| row.map(|v| v as f32));
    let rtf = rt.map(|v| v as f32);
    let to_cam = |p: &[f32; 3]| {
        [
            rf[0][0] * p[0] + rf[0][1] * p[1] + rf[0][2] * p[2] + rtf[0],
            rf[1][0] * p[0] + rf[1][1] * p[1] + rf[1][2] * p[2] + rtf[1],
            rf[2][0] * p[0] + rf[2][1] * p[1] + rf[2][2] * p[2] + rtf[2],
        ]
    };
    let near = NEAR_M as f32;
    let n = scene.positions.len();
    frame.cam.resize(n, [0.0; 3]);
    frame.screen.resize(n, Screen::default());
    // Pixel centres span [half, (n − 1)·one + half] in sub-pixel units.
    let (one, half) = (1i64 << SUBPIXEL_BITS, 1i64 << (SUBPIXEL_BITS - 1));
    let (xmax, ymax) = ((w as i64 - 1) * one + half, (h as i64 - 1) * one + half);
    let mut poly: Vec<ClipVert> = Vec::with_capacity(4);
    let frustum = Frustum::new(k, near);
    for g in &scene.groups {
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
        for tri in &scene.triangles[g.triangles.clone()] {
            let v = tri.map(|i| frame.cam[i as usize]);
            let behind = v.iter().filter(|p| p[2] < near).count();
            if behind == 3 {
                continue;
            }
            if behind == 0 {
                let [a, b, c] = tri.map(|i| frame.screen[i as usize]);
                // Off-screen triangles leave before any set-up.
                if a.x.max(b.x).max(c.x) < half
                    || a.x.min(b.x).min(c.x) > xmax
                    || a.y.max(b.y).max(c.y) < half
                    || a.y.min(b.y).min(c.y) > ymax
                {
                    continue;
                }
                if cull != 0 {
                    // Coordinates are within ±2^50: the products fit in i128.
                    let area =
                        (b.x - a.x) as i128 * (c.y - a.y) as i128 - (c.x - a.x) as i128 * (b.y - a.y) as i128;
                    if area * (cull as i128) > 0 {
                        continue;
                    }
                }
                raster_fixed(a, b, c, id, &mut frame.ids, &mut frame.inv_z, w, h);
                continue;
            }
            // A triangle crossing the camera plane far outside the view (below the camera of an
            // oblique view, say) is dropped when its corners all lie beyond one side plane.
            let ins = v.map(|p| frustum.inside(p));
            if (1..5).any(|n| ins.iter().all(|i| !i[n])) {
                continue;
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
                raster_fixed(a, b, c, id, &mut frame.ids, &mut frame.inv_z, w, h);
            }
        }
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

/// Sub-pixel precision of the snapped screen coordinates (8 bits, as Mesa's rasterisers use).
const SUBPIXEL_BITS: u32 = 8;
const SUBPIXEL: f64 = (1 << SUBPIXEL_BITS) as f64;

/// Screen position snapped to 1/256 px in integers: edge functions are then exact, so a shared edge is
/// decided identically for both triangles (watertight, no double coverage). Saturates far off-screen
/// (points grazing the near plane); such triangles are rejected before integer maths.
#[inline]
fn project(k: &Intrinsics, p: ClipVert) -> Screen {
    let u = k.fx_px * p.x / p.z + k.cx_px;
    let v = k.fy_px * p.y / p.z + k.cy_px;
    Screen { x: round_fixed(u * SUBPIXEL), y: round_fixed(v * SUBPIXEL), inv_z: 1.0 / p.z }
}

/// Rounds to the nearest integer, ties to even (as the GPU's float → fixed-point snapping), without a
/// libm call: adding 1.5·2^52 pushes the fraction out of the mantissa. Values beyond ±2^50 saturate
/// (they are rejected later as absurd projections).
#[inline]
fn round_fixed(x: f64) -> i64 {
    const MAGIC: f64 = 6_755_399_441_055_744.0; // 1.5 · 2^52
    if x.abs() < (1u64 << 50) as f64 {
        ((x + MAGIC) - MAGIC) as i64
    } else if x > 0.0 {
        1 << 50
    } else {
        -(1 << 50)
    }
}

#[allow(clippy::too_many_arguments)]
#[inline]
fn raster_fixed(
    a: Screen,
    b: Screen,
    c: Screen,
    id: u32,
    ids: &mut [u32],
    inv_z: &mut [f32],
    w: usize,
    h: usize,
) {
    let (ax, ay, az) = (a.x, a.y, a.inv_z);
    let (mut bx, mut by, mut bz) = (b.x, b.y, b.inv_z);
    let (mut cx, mut cy, mut cz) = (c.x, c.y, c.inv_z);
    // Reject absurd projections (points grazing the near plane far off-screen) before integer maths.
    let lim = 1i64 << 40;
    if [ax, ay, bx, by, cx, cy].iter().any(|v| v.abs() > lim) {
        return;
    }
    // Coordinates within ±2^24 sub-pixels (±65536 px, the common case) keep every product below
    // 2^50, so the area and the edge functions fit in i64; otherwise (a sliver grazing the near
    // plane) they are evaluated in i128.
    let small = [ax, ay, bx, by, cx, cy].iter().all(|v| v.abs() < 1 << 24);
    let mut area = if small {
        ((bx - ax) * (cy - ay) - (cx - ax) * (by - ay)) as i128
    } else {
        (bx - ax) as i128 * (cy - ay) as i128 - (cx - ax) as i128 * (by - ay) as i128
    };
    if area == 0 {
        return;
    }
    if area < 0 {
        std::mem::swap(&mut bx, &mut cx);
        std::mem::swap(&mut by, &mut cy);
        std::mem::swap(&mut bz, &mut cz);
        area = -area;
    }
    let half = (1i64 << SUBPIXEL_BITS) / 2;
    let one = 1i64 << SUBPIXEL_BITS;
    // Pixel xi's centre is xi·one + half; covered range of centres within the bounding box
    // (exact integer ceil/floor divisions).
    let first = |lo: i64| ((lo - half).div_euclid(one) + ((lo - half).rem_euclid(one) != 0) as i64).max(0);
    let last = |hi: i64, n: usize| (hi - half).div_euclid(one).min(n as i64 - 1);
    let (x0, x1) = (first(ax.min(bx).min(cx)), last(ax.max(bx).max(cx), w));
    let (y0, y1) = (first(ay.min(by).min(cy)), last(ay.max(by).max(cy), h));
    if x0 > x1 || y0 > y1 {
        return;
    }
    // Edge e(p) = d × (p − q0) with d = q1 − q0; the interior is e > 0. Its normal (−dy, dx) points
    // inside, so an edge is "left" when dy < 0 and "top" when dy = 0 and dx > 0 (y down). Centres
    // exactly on an edge are covered only for top and left edges (the top-left rule).
    let edge = |x0: i64, y0: i64, x1: i64, y1: i64| {
        let (dx, dy) = (x1 - x0, y1 - y0);
        let top_left = dy < 0 || (dy == 0 && dx > 0);
        (dx as i128, dy as i128, x0 as i128, y0 as i128, if top_left { 0i128 } else { 1i128 })
    };
    let e = [edge(bx, by, cx, cy), edge(cx, cy, ax, ay), edge(ax, ay, bx, by)];
    let inv_area = 1.0 / if small { area as i64 as f64 } else { area as f64 };
    if small {
        let e64 = e.map(|(dx, dy, ex, ey, bias)| (dx as i64, dy as i64, ex as i64, ey as i64, bias as i64));
        let (px0, py0) = (x0 * one + half, y0 * one + half);
        let mut row_e = e64.map(|(dx, dy, ex, ey, _)| dx * (py0 - ey) - dy * (px0 - ex));
        let step_x = e64.map(|(_, dy, _, _, _)| -dy * one);
        let step_y = e64.map(|(dx, _, _, _, _)| dx * one);
        let bias = e64.map(|t| t.4);
        let (az, bz, cz) = (az * inv_area, bz * inv_area, cz * inv_area);
        for yi in y0..=y1 {
            let row = yi as usize * w;
            // The covered span of this row, solved exactly from the three edge functions
            // e_n(x) = row_e[n] + (x − x0)·step_x[n] ≥ bias[n] (integer arithmetic, no per-pixel test).
            let (mut lo, mut hi) = (0i64, x1 - x0);
            for n in 0..3 {
                let (e0, sx, b) = (row_e[n], step_x[n], bias[n]);
                if sx == 0 {
                    if e0 < b {
                        hi = -1;
                    }
                } else if sx > 0 {
                    // x − x0 ≥ ceil((b − e0) / sx)
                    lo = lo.max((b - e0).div_euclid(sx) + ((b - e0).rem_euclid(sx) != 0) as i64);
                } else {
                    // x − x0 ≤ floor((e0 − b) / −sx)
                    hi = hi.min((e0 - b).div_euclid(-sx));
                }
            }
            if lo <= hi {
                // 1/z is affine in screen space: start exactly at the span's first pixel, then step.
                let v = [0, 1, 2].map(|n| (row_e[n] + lo * step_x[n]) as f64);
                let mut z = v[0] * az + v[1] * bz + v[2] * cz;
                let dz = step_x[0] as f64 * az + step_x[1] as f64 * bz + step_x[2] as f64 * cz;
                let start = row + (x0 + lo) as usize;
                let end = row + (x0 + hi) as usize;
                for (zb, idb) in inv_z[start..=end].iter_mut().zip(&mut ids[start..=end]) {
                    let zf = z as f32;
                    if zf > *zb {
                        *zb = zf;
                        *idb = id;
                    }
                    z += dz;
                }
            }
            row_e[0] += step_y[0];
            row_e[1] += step_y[1];
            row_e[2] += step_y[2];
        }
        return;
    }
    for yi in y0..=y1 {
        let py = (yi * one + half) as i128;
        let row = yi as usize * w;
        for xi in x0..=x1 {
            let px = (xi * one + half) as i128;
            let mut wts = [0i128; 3];
            let mut inside = true;
            for (n, &(dx, dy, ex, ey, bias)) in e.iter().enumerate() {
                let v = dx * (py - ey) - dy * (px - ex);
                if v < bias {
                    inside = false;
                    break;
                }
                wts[n] = v;
            }
            if !inside {
                continue;
            }
            let z = ((wts[0] as f64 * az + wts[1] as f64 * bz + wts[2] as f64 * cz) * inv_area) as f32;
            let i = row + xi as usize;
            if z > inv_z[i] {
                inv_z[i] = z;
                ids[i] = id;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn quad(mesh: &mut SceneMesh, corners: [[f32; 3]; 4], id: u32) {
        let base = mesh.positions_m.len() as u32;
        mesh.positions_m.extend_from_slice(&corners);
        mesh.building_ids.extend([id; 4]);
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
    fn closed_box(m: &mut SceneMesh, lo: [f32; 3], hi: [f32; 3], id: u32, flip: bool, floor: bool) {
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
                    m.building_ids.push(id);
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

    #[test]
    fn culling_back_faces_of_closed_buildings_changes_no_pixel() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        let mut m = SceneMesh::default();
        // Boxes of both windings, some open (never culled), overlapping in view; every third building
        // has a second part sharing a wall or an edge with the first.
        for id in 1..=60u32 {
            let (x, y) = (rng.gen_range(-120.0..120.0f32), rng.gen_range(-120.0..120.0f32));
            let (sx, sy, h) =
                (rng.gen_range(5.0..30.0f32), rng.gen_range(5.0..30.0f32), rng.gen_range(5.0..80.0f32));
            closed_box(&mut m, [x, y, 0.0], [x + sx, y + sy, h], id, id % 3 == 1, id % 5 != 0);
            if id % 3 == 0 {
                let (x2, y2) = if id % 2 == 0 { (x + sx, y) } else { (x + sx, y + sy) };
                closed_box(&mut m, [x2, y2, 0.0], [x2 + sx, y2 + sy, h], id, false, id % 5 != 0);
            }
        }
        let culled = CpuScene::new(&m, [0.0, 0.0, 100.0]);
        assert!(culled.groups.iter().filter(|g| g.solid != 0).count() >= 40);
        let unculled = culled.clone().with_back_face_culling(false);
        let k = Intrinsics {
            width_px: 200,
            height_px: 150,
            fx_px: 180.0,
            fy_px: 180.0,
            cx_px: 100.0,
            cy_px: 75.0,
        };
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

    /// Coverage by the definition: pixel centres with every edge function > 0, or = 0 on a top or
    /// left edge, evaluated in i128 for every pixel of the image.
    fn covered_by_definition(t: [(i64, i64); 3], x: i64, y: i64) -> bool {
        let one = 1i64 << SUBPIXEL_BITS;
        let (px, py) = ((x * one + one / 2) as i128, (y * one + one / 2) as i128);
        let [a, mut b, mut c] = t.map(|(x, y)| (x as i128, y as i128));
        let area = (b.0 - a.0) * (c.1 - a.1) - (c.0 - a.0) * (b.1 - a.1);
        if area == 0 {
            return false;
        }
        if area < 0 {
            std::mem::swap(&mut b, &mut c);
        }
        [(b, c), (c, a), (a, b)].iter().all(|&(p, q)| {
            let (dx, dy) = (q.0 - p.0, q.1 - p.1);
            let e = dx * (py - p.1) - dy * (px - p.0);
            e > 0 || (e == 0 && (dy < 0 || (dy == 0 && dx > 0)))
        })
    }

    #[test]
    fn row_spans_cover_exactly_the_pixel_centres_inside() {
        use rand::{Rng, SeedableRng};
        let (w, h) = (48usize, 40usize);
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        let one = 1i64 << SUBPIXEL_BITS;
        for n in 0..3000 {
            // Small, large, thin and grid-aligned triangles (vertices on pixel centres and edges hit
            // the top-left rule), partly off-screen.
            let span = [3, 20, 80, 400][n % 4] * one;
            let snap = n % 3 == 0;
            let mut vert = || {
                let (x, y) = (
                    rng.gen_range(-span / 2..w as i64 * one + span / 2),
                    rng.gen_range(-span / 2..h as i64 * one + span / 2),
                );
                if snap {
                    (x / (one / 2) * (one / 2), y / (one / 2) * (one / 2))
                } else {
                    (x, y)
                }
            };
            let t = [vert(), vert(), vert()];
            let s = t.map(|(x, y)| Screen { x, y, inv_z: 1.0 });
            let (mut ids, mut inv_z) = (vec![0u32; w * h], vec![0f32; w * h]);
            raster_fixed(s[0], s[1], s[2], 1, &mut ids, &mut inv_z, w, h);
            for y in 0..h {
                for x in 0..w {
                    assert_eq!(
                        ids[y * w + x] == 1,
                        covered_by_definition(t, x as i64, y as i64),
                        "triangle {n} {t:?}, pixel ({x}, {y})"
                    );
                }
            }
        }
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
