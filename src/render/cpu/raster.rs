//! Exact fixed-point rasterisation of one triangle or convex polygon into an ID and a 1/z buffer.

use crate::camera::Intrinsics;

/// A vertex on screen: position in 1/256 px (integers, so edge functions are exact) and 1/z.
#[derive(Debug, Clone, Copy, Default)]
pub(super) struct Screen {
    pub(super) x: i64,
    pub(super) y: i64,
    pub(super) inv_z: f64,
}

#[derive(Clone, Copy)]
/// A camera-frame point (metres, z forward) to project.
pub(super) struct ClipVert {
    pub(super) x: f64,
    pub(super) y: f64,
    pub(super) z: f64,
}

/// ceil(n_k / d) along an arithmetic sequence n_k = n_0 + k·s (d > 0), stepped without a division:
/// n_k = q·d − r with 0 ≤ r < d, and s = sq·d + sr with 0 ≤ sr < d.
#[derive(Clone, Copy)]
struct CeilWalk {
    q: i64,
    r: i64,
    sq: i64,
    sr: i64,
    d: i64,
}

impl CeilWalk {
    #[inline]
    fn new(n: i64, s: i64, d: i64) -> CeilWalk {
        let q = ceil_div(n, d);
        CeilWalk { q, r: q * d - n, sq: s.div_euclid(d), sr: s.rem_euclid(d), d }
    }

    const ZERO: CeilWalk = CeilWalk { q: 0, r: 0, sq: 0, sr: 0, d: 1 };

    /// Moves to n_{k+1} = n_k + s: (q + sq)·d − (r − sr), borrowing one d when r − sr < 0 (without
    /// a branch: the borrow is data-dependent and would mispredict).
    #[inline]
    fn step(&mut self) {
        self.q += self.sq;
        self.r -= self.sr;
        let borrow = self.r >> 63;
        self.r += self.d & borrow;
        self.q -= borrow;
    }
}

/// Sub-pixel precision of the snapped screen coordinates (8 bits, as Mesa's rasterisers use).
pub(super) const SUBPIXEL_BITS: u32 = 8;
const SUBPIXEL: f64 = (1 << SUBPIXEL_BITS) as f64;

/// Screen position snapped to 1/256 px in integers: edge functions are then exact, so a shared edge is
/// decided identically for both triangles (watertight, no double coverage). Saturates far off-screen
/// (points grazing the near plane); such triangles are rejected before integer maths.
#[inline]
pub(super) fn project(k: &Intrinsics, p: ClipVert) -> Screen {
    let inv_z = 1.0 / p.z;
    let u = k.fx_px * p.x * inv_z + k.cx_px;
    let v = k.fy_px * p.y * inv_z + k.cy_px;
    Screen { x: round_fixed(u * SUBPIXEL), y: round_fixed(v * SUBPIXEL), inv_z }
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

/// The most vertices a polygon of a `CpuScene` has.
pub(super) const MAX_POLYGON: usize = 8;

/// Rasterises a convex polygon (a triangle, or vertices of a planar convex polygon in order; either
/// orientation; at most [`MAX_POLYGON`]) exactly as its fan of triangles (0, i, i + 1) would be: the
/// top-left rule amounts to sampling each pixel centre nudged by the same infinitesimal offset, so
/// the triangles of a tiling cover the same centres as their union. It is drawn at once when its
/// snapped screen vertices form a strictly convex polygon; otherwise (vertices collapsed or a reflex
/// corner after snapping) triangle by triangle. Skipped when its signed area has the sign of `cull`
/// (see `render_ids`). Returns whether it was handled as one polygon.
#[allow(clippy::too_many_arguments)]
#[inline]
pub(super) fn raster_convex(
    s: &[Screen],
    id: u32,
    cull: i64,
    ids: &mut [u32],
    inv_z: &mut [f32],
    w: usize,
    h: usize,
) -> bool {
    let n = s.len();
    if n < 3 {
        return false;
    }
    // Coordinates within ±2^24 sub-pixels (±65536 px, the common case) keep every product below
    // 2^50, so areas and edge functions fit in i64; otherwise (a sliver grazing the near plane)
    // they are evaluated in i128, pixel by pixel.
    if n > MAX_POLYGON || s.iter().any(|v| v.x.abs() >= 1 << 24 || v.y.abs() >= 1 << 24) {
        for i in 1..n - 1 {
            raster_large(s[0], s[i], s[i + 1], id, cull, ids, inv_z, w, h);
        }
        return false;
    }
    let sign = cross(&s[0], &s[1], &s[2]).signum();
    if n > 3 {
        // Strictly convex: every turn has the same, non-zero sign, and (beyond four vertices, where
        // a star could turn twice) every vertex lies strictly inside every edge's half-plane.
        let turns = (0..n).all(|i| cross(&s[i], &s[(i + 1) % n], &s[(i + 2) % n]).signum() == sign);
        let inside = n == 4
            || (0..n).all(|i| {
                let (p, q) = (&s[i], &s[(i + 1) % n]);
                (0..n).all(|j| j == i || j == (i + 1) % n || cross(p, q, &s[j]).signum() == sign)
            });
        if sign == 0 || !turns || !inside {
            for i in 1..n - 1 {
                raster_convex(&[s[0], s[i], s[i + 1]], id, cull, ids, inv_z, w, h);
            }
            return false;
        }
    }
    // Degenerate, or a back face of a closed building (the fan's triangles all share the sign).
    if sign == 0 || sign * cull > 0 {
        return true;
    }
    // Positive orientation (interior where every edge function is > 0): v[0] first, then the rest
    // in order or reversed.
    let mut v = [Screen::default(); MAX_POLYGON];
    v[0] = s[0];
    for i in 1..n {
        v[i] = if sign > 0 { s[i] } else { s[n - i] };
    }
    fill_convex(&v[..n], id, ids, inv_z, w, h);
    true
}

/// Twice the signed area of the screen triangle (a, b, c), in sub-pixels squared (> 0: clockwise on
/// screen, y down).
#[inline]
fn cross(a: &Screen, b: &Screen, c: &Screen) -> i64 {
    (b.x - a.x) * (c.y - a.y) - (b.y - a.y) * (c.x - a.x)
}

/// Fills a strictly convex, positively oriented polygon (see [`raster_convex`]): the rows its pixel
/// centres span, each row's span bounded by the left and right edges, 1/z affine along it.
#[inline]
fn fill_convex(v: &[Screen], id: u32, ids: &mut [u32], inv_z: &mut [f32], w: usize, h: usize) {
    let n = v.len();
    let half = (1i64 << SUBPIXEL_BITS) / 2;
    let one = 1i64 << SUBPIXEL_BITS;
    // Pixel xi's centre is xi·one + half; the range of centres within the bounding box.
    let (mut xmin, mut xmax, mut ymin, mut ymax) = (v[0].x, v[0].x, v[0].y, v[0].y);
    for p in &v[1..] {
        (xmin, xmax, ymin, ymax) = (xmin.min(p.x), xmax.max(p.x), ymin.min(p.y), ymax.max(p.y));
    }
    let (x0, x1) = (ceil_div(xmin - half, one).max(0), (xmax - half).div_euclid(one).min(w as i64 - 1));
    let (mut y0, mut y1) =
        (ceil_div(ymin - half, one).max(0), (ymax - half).div_euclid(one).min(h as i64 - 1));
    if x0 > x1 || y0 > y1 {
        return;
    }
    // Edge i runs from v[i] to v[i + 1]: e(p) = dx·(py − y_i) − dy·(px − x_i), interior e > 0. Its
    // normal (−dy, dx) points inside, so it is "left" when dy < 0 and "top" when dy = 0 and dx > 0
    // (y down); centres exactly on an edge are covered only for top and left edges (the top-left
    // rule: e ≥ bias with bias 0 there, 1 elsewhere). At pixel (x0 + x, y0 + k):
    // e = e0 − x·dy·one + k·dx·one ≥ bias. Horizontal edges bound the rows, once.
    let edge = |i: usize, px: i64, py: i64| {
        let (p, q) = (v[i], v[(i + 1) % n]);
        let (dx, dy) = (q.x - p.x, q.y - p.y);
        let bias = !(dy < 0 || (dy == 0 && dx > 0)) as i64;
        (dx, dy, dx * (py - p.y) - dy * (px - p.x), bias)
    };
    let top = y0;
    for i in 0..n {
        let (dx, dy, e0, bias) = edge(i, x0 * one + half, top * one + half);
        if dy == 0 && dx > 0 {
            y0 = y0.max(top + ceil_div(bias - e0, dx * one));
        } else if dy == 0 && dx < 0 {
            y1 = y1.min(top + (e0 - bias).div_euclid(-dx * one));
        }
    }
    if y0 > y1 {
        return;
    }
    let (px0, py0) = (x0 * one + half, y0 * one + half);
    // Left edges (dy < 0) bound the span below: x ≥ ceil((bias − e0 − k·dx·one) / (−dy·one)); right
    // edges (dy > 0) above: x ≤ −ceil((bias − e0 − k·dx·one) / (dy·one)). Walked row by row without
    // a division ([`CeilWalk`]).
    let mut left = [CeilWalk::ZERO; MAX_POLYGON];
    let mut right = [CeilWalk::ZERO; MAX_POLYGON];
    let (mut nl, mut nr) = (0, 0);
    for i in 0..n {
        let (dx, dy, e0, bias) = edge(i, px0, py0);
        if dy < 0 {
            left[nl] = CeilWalk::new(bias - e0, -dx * one, -dy * one);
            nl += 1;
        } else if dy > 0 {
            right[nr] = CeilWalk::new(bias - e0, -dx * one, dy * one);
            nr += 1;
        }
    }
    let (left, right) = (&mut left[..nl], &mut right[..nr]);
    // 1/z is affine in screen space: interpolated from the largest triangle of the fan (for a
    // triangle, itself) by its exact integer edge functions at the span's first pixel.
    let r =
        if n == 3 { 1 } else { (1..n - 1).max_by_key(|&i| cross(&v[0], &v[i], &v[i + 1])).expect("n > 3") };
    let (a, b, c) = (v[0], v[r], v[r + 1]);
    let inv_area = 1.0 / cross(&a, &b, &c) as f64;
    let tri = [(b, c), (c, a), (a, b)];
    let zw = [a.inv_z * inv_area, b.inv_z * inv_area, c.inv_z * inv_area];
    let mut tri_e = tri.map(|(p, q)| (q.x - p.x) * (py0 - p.y) - (q.y - p.y) * (px0 - p.x));
    let tri_sx = tri.map(|(p, q)| -(q.y - p.y) * one);
    let tri_sy = tri.map(|(p, q)| (q.x - p.x) * one);
    let dz = tri_sx[0] as f64 * zw[0] + tri_sx[1] as f64 * zw[1] + tri_sx[2] as f64 * zw[2];
    for yi in y0..=y1 {
        let mut lo = 0i64;
        for walk in left.iter_mut() {
            lo = lo.max(walk.q);
            walk.step();
        }
        let mut hi = x1 - x0;
        for walk in right.iter_mut() {
            hi = hi.min(-walk.q);
            walk.step();
        }
        if lo <= hi {
            let e = [0, 1, 2].map(|j| (tri_e[j] + lo * tri_sx[j]) as f64);
            let z = e[0] * zw[0] + e[1] * zw[1] + e[2] * zw[2];
            let row = yi as usize * w;
            let (start, end) = (row + (x0 + lo) as usize, row + (x0 + hi) as usize);
            fill_span(&mut inv_z[start..=end], &mut ids[start..=end], z, dz, id);
        }
        for j in 0..3 {
            tri_e[j] += tri_sy[j];
        }
    }
}

/// ceil(n / d) for d > 0.
#[inline]
fn ceil_div(n: i64, d: i64) -> i64 {
    n.div_euclid(d) + (n.rem_euclid(d) != 0) as i64
}

/// Writes `id` where 1/z (starting at `z`, stepping by `dz` per pixel) beats the buffer.
#[inline(always)]
fn fill_span(inv_z: &mut [f32], ids: &mut [u32], mut z: f64, dz: f64, id: u32) {
    for (zb, idb) in inv_z.iter_mut().zip(ids) {
        let zf = z as f32;
        if zf > *zb {
            *zb = zf;
            *idb = id;
        }
        z += dz;
    }
}

/// A triangle with coordinates beyond the fast path's range (a sliver grazing the near plane): edge
/// functions in i128, pixel by pixel over its (clamped) bounding box.
#[allow(clippy::too_many_arguments)]
fn raster_large(
    a: Screen,
    b: Screen,
    c: Screen,
    id: u32,
    cull: i64,
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
    let mut area = (bx - ax) as i128 * (cy - ay) as i128 - (cx - ax) as i128 * (by - ay) as i128;
    if area == 0 || area * cull as i128 > 0 {
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
    let (x0, x1) = (
        ceil_div(ax.min(bx).min(cx) - half, one).max(0),
        (ax.max(bx).max(cx) - half).div_euclid(one).min(w as i64 - 1),
    );
    let (y0, y1) = (
        ceil_div(ay.min(by).min(cy) - half, one).max(0),
        (ay.max(by).max(cy) - half).div_euclid(one).min(h as i64 - 1),
    );
    if x0 > x1 || y0 > y1 {
        return;
    }
    // As in `raster_convex`: e = d × (p − q0), covered when e > 0 or e = 0 on a top or left edge.
    let edge = |x0: i64, y0: i64, x1: i64, y1: i64| {
        let (dx, dy) = (x1 - x0, y1 - y0);
        let top_left = dy < 0 || (dy == 0 && dx > 0);
        (dx as i128, dy as i128, x0 as i128, y0 as i128, if top_left { 0i128 } else { 1i128 })
    };
    let e = [edge(bx, by, cx, cy), edge(cx, cy, ax, ay), edge(ax, ay, bx, by)];
    let inv_area = 1.0 / area as f64;
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
            raster_convex(&s, 1, 0, &mut ids, &mut inv_z, w, h);
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
    fn ceil_walk_matches_division() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
        for _ in 0..2000 {
            let scale = [10i64, 1000, 1 << 40][rng.gen_range(0..3)];
            let (n0, s) = (rng.gen_range(-scale..=scale), rng.gen_range(-scale..=scale) / 64);
            let d = rng.gen_range(1..=scale.min(1 << 30));
            let mut walk = CeilWalk::new(n0, s, d);
            for k in 0..40 {
                let n = n0 + k * s;
                let want = n.div_euclid(d) + (n.rem_euclid(d) != 0) as i64;
                assert_eq!(walk.q, want, "n0 {n0} s {s} d {d} k {k}");
                walk.step();
            }
        }
    }

    #[test]
    fn convex_polygons_cover_exactly_their_fans_pixels() {
        use rand::{Rng, SeedableRng};
        let (w, h) = (48usize, 40usize);
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
        let one = 1i64 << SUBPIXEL_BITS;
        let (mut drawn, mut whole) = (0, 0);
        for n in 0..3000 {
            // Points on an ellipse at sorted random angles (convex), either orientation, small to
            // larger than the image, snapped to half pixels every third time (edges through centres),
            // with an occasional vertex pushed inwards (reflex: drawn as the fan).
            let m = 4 + n % (MAX_POLYGON - 3);
            let (rx, ry) = (
                [0.7, 4.0, 20.0, 60.0][n % 4] * one as f64,
                rng.gen_range(0.3..1.5) * [0.7, 4.0, 20.0, 60.0][n % 4] * one as f64,
            );
            let (cx, cy) = (rng.gen_range(-8.0..56.0) * one as f64, rng.gen_range(-8.0..48.0) * one as f64);
            let mut angles: Vec<f64> = (0..m).map(|_| rng.gen_range(0.0..std::f64::consts::TAU)).collect();
            angles.sort_by(f64::total_cmp);
            if n % 2 == 1 {
                angles.reverse();
            }
            let snap = n % 3 == 0;
            let dent = n % 7 == 0;
            if n % 5 == 0 {
                // An axis-aligned rectangle: horizontal edges at the top and the bottom.
                angles = [0.25, 0.75, 1.25, 1.75].map(|q| q * std::f64::consts::PI).to_vec();
                if n % 2 == 1 {
                    angles.reverse();
                }
            }
            let m = angles.len();
            let pts: Vec<(i64, i64)> = angles
                .iter()
                .enumerate()
                .map(|(i, a)| {
                    let r = if dent && i == 0 { 0.3 } else { 1.0 };
                    let (x, y) = ((cx + r * rx * a.cos()) as i64, (cy + r * ry * a.sin()) as i64);
                    if snap {
                        (x / (one / 2) * (one / 2), y / (one / 2) * (one / 2))
                    } else {
                        (x, y)
                    }
                })
                .collect();
            let s: Vec<Screen> = pts.iter().map(|&(x, y)| Screen { x, y, inv_z: 1.0 }).collect();
            let (mut ids, mut inv_z) = (vec![0u32; w * h], vec![0f32; w * h]);
            whole += raster_convex(&s, 1, 0, &mut ids, &mut inv_z, w, h) as usize;
            for y in 0..h {
                for x in 0..w {
                    let fan = (1..m - 1)
                        .any(|i| covered_by_definition([pts[0], pts[i], pts[i + 1]], x as i64, y as i64));
                    assert_eq!(ids[y * w + x] == 1, fan, "polygon {n} {pts:?}, pixel ({x}, {y})");
                    drawn += (ids[y * w + x] == 1) as usize;
                }
            }
        }
        assert!(drawn > 100_000, "the polygons cover pixels ({drawn})");
        assert!(whole > 2000, "most are drawn as one polygon ({whole} of 3000)");
    }
}
