//! Which buildings are closed solids whose back faces may be culled without changing a pixel.

use glam::{DVec3, Vec3};

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
pub(super) fn solid_winding(positions: &[[f32; 3]], tris: &[[u32; 3]]) -> i8 {
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
    let pos = |i: u32| Vec3::from(positions[i as usize]).as_dvec3();
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
        // Six times the signed volume of the tetrahedron (0, a, b, c).
        let det = a.dot(b.cross(c));
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
    pa: DVec3,
    pb: DVec3,
    tris: &[[u32; 3]],
    a: u32,
    b: u32,
    fwd: &[u32],
    back: &[u32],
    pos: &dyn Fn(u32) -> DVec3,
) -> bool {
    let d = pb - pa;
    // A basis (e1, e2) of the plane normal to the edge.
    let helper = if d.x.abs() <= d.y.abs() && d.x.abs() <= d.z.abs() {
        DVec3::X
    } else if d.y.abs() <= d.z.abs() {
        DVec3::Y
    } else {
        DVec3::Z
    };
    let e1 = d.cross(helper);
    let e2 = d.cross(e1);
    let mut around: Vec<(f64, i32)> = fwd
        .iter()
        .map(|&f| (f, 1))
        .chain(back.iter().map(|&f| (f, -1)))
        .map(|(f, o)| {
            let t = tris[f as usize];
            let c = t.into_iter().find(|&v| v != a && v != b).expect("a triangle has a third vertex");
            let u = pos(c) - pa;
            (u.dot(e2).atan2(u.dot(e1)), o)
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
