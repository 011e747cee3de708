//! Boundary polygons of a binary mask: outer boundaries for `export-coco --polygons`, all rings (holes
//! too) and rings bridged into one polygon for `export-yolo`.
//!
//! COCO polygons cannot hold holes: a courtyard becomes part of the building. The RLE stays the exact
//! form (and is kept beside the polygons in the `mask_rle` extension key).
//!
//! The tracer follows pixel edges ("cracks"): every edge between a mask pixel and a non-mask pixel is
//! directed so that the mask lies on its right (y pointing down), which makes outer boundaries clockwise
//! on screen (positive shoelace area with y down) and holes counter-clockwise. Where two mask pixels
//! touch only at a corner, the walk turns left, joining them (8-connectivity: every 8-connected blob
//! gives exactly one outer loop). Collinear vertices are removed. Vertices are pixel corners in COCO
//! pixel coordinates, so pycocotools rasterises the polygon of a hole-free blob back onto its pixels
//! (`frPyObjects` covers pixel x when x0 ≤ x < x1 — see the golden vectors `poly_0_0_to_2_2`).

/// Direction codes: east, south, west, north (y down).
const DX: [i64; 4] = [1, 0, -1, 0];
const DY: [i64; 4] = [0, 1, 0, -1];
const NONE: u8 = u8::MAX;

/// The outer boundaries of `mask` (row-major, non-zero = inside, `width × height`) as COCO polygons
/// `[x1, y1, x2, y2, …]` in pixel-corner coordinates, ordered by their first vertex (top-most, then
/// left-most). Empty for an empty mask or a buffer of the wrong size.
pub fn mask_to_polygons(mask: &[u8], width: u32, height: u32) -> Vec<Vec<f64>> {
    mask_to_rings(mask, width, height).outer
}

/// Every boundary loop of a mask, in pixel-corner coordinates (`[x1, y1, x2, y2, …]`).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Rings {
    /// Outer boundaries, clockwise on screen (y down), ordered by their first vertex.
    pub outer: Vec<Vec<f64>>,
    /// Hole boundaries, counter-clockwise on screen, ordered by their first vertex. Holes are
    /// 4-connected background regions enclosed by the mask (the complement of the tracer's
    /// 8-connectivity).
    pub holes: Vec<Vec<f64>>,
}

/// The inclusive pixel bounds `[x0, y0, x1, y1]` of a `w × h` mask's non-zero pixels; `None` when
/// there are none.
fn mask_bounds(mask: &[u8], w: usize, h: usize) -> Option<[usize; 4]> {
    let (mut x0, mut y0, mut x1, mut y1) = (usize::MAX, usize::MAX, 0usize, 0usize);
    for y in 0..h {
        for x in 0..w {
            if mask[y * w + x] != 0 {
                (x0, y0, x1, y1) = (x0.min(x), y0.min(y), x1.max(x), y1.max(y));
            }
        }
    }
    (x0 != usize::MAX).then_some([x0, y0, x1, y1])
}

/// The outer and hole boundaries of `mask` (see [`mask_to_polygons`] for the conventions). Even-odd
/// filling of all rings at pixel centres gives back exactly the mask.
pub fn mask_to_rings(mask: &[u8], width: u32, height: u32) -> Rings {
    let (w, h) = (width as usize, height as usize);
    if mask.len() != w * h {
        return Rings::default();
    }
    // Crop to the bounding box so the edge tables stay small for small instances in large frames.
    let Some([x0, y0, x1, y1]) = mask_bounds(mask, w, h) else {
        return Rings::default();
    };
    let (cw, ch) = (x1 - x0 + 1, y1 - y0 + 1);
    let inside = |x: i64, y: i64| -> bool {
        x >= 0
            && y >= 0
            && (x as usize) < cw
            && (y as usize) < ch
            && mask[(y0 + y as usize) * w + x0 + x as usize] != 0
    };
    // Up to two outgoing edges per crop corner (vertex (x, y), 0 ≤ x ≤ cw, 0 ≤ y ≤ ch).
    let vw = cw + 1;
    let mut out: Vec<[u8; 2]> = vec![[NONE; 2]; vw * (ch + 1)];
    let mut add = |vx: i64, vy: i64, dir: u8| {
        let slot = &mut out[vy as usize * vw + vx as usize];
        if slot[0] == NONE {
            slot[0] = dir;
        } else {
            slot[1] = dir;
        }
    };
    for y in 0..ch as i64 {
        for x in 0..cw as i64 {
            if !inside(x, y) {
                continue;
            }
            if !inside(x, y - 1) {
                add(x, y, 0); // top edge, eastwards
            }
            if !inside(x + 1, y) {
                add(x + 1, y, 1); // right edge, southwards
            }
            if !inside(x, y + 1) {
                add(x + 1, y + 1, 2); // bottom edge, westwards
            }
            if !inside(x - 1, y) {
                add(x, y + 1, 3); // left edge, northwards
            }
        }
    }
    let mut polygons: Vec<(usize, Vec<f64>)> = Vec::new();
    let mut holes: Vec<(usize, Vec<f64>)> = Vec::new();
    for start in 0..out.len() {
        for s in 0..2 {
            let dir0 = out[start][s];
            if dir0 == NONE {
                continue;
            }
            // Walk one loop, consuming its edges; the start edge stays in its slot until the walk would
            // take it again, so a loop pinched at its start vertex is walked through that vertex twice.
            let (sx, sy) = ((start % vw) as i64, (start / vw) as i64);
            let mut pts: Vec<(i64, i64)> = vec![(sx, sy)];
            let (mut x, mut y, mut dir) = (sx + DX[dir0 as usize], sy + DY[dir0 as usize], dir0);
            let mut area2: i64 = sx * y - x * sy;
            loop {
                let v = y as usize * vw + x as usize;
                let slot = out[v];
                let left = (dir + 3) % 4;
                let k = if slot[0] != NONE && slot[1] != NONE {
                    // Corner-touching pixels: turn left to keep them in one loop.
                    if slot[0] == left {
                        0
                    } else {
                        1
                    }
                } else if slot[0] != NONE {
                    0
                } else if slot[1] != NONE {
                    1
                } else {
                    // Unreachable: every vertex on a loop has as many outgoing as incoming edges.
                    break;
                };
                if v == start && k == s {
                    out[start][s] = NONE;
                    break;
                }
                let nd = slot[k];
                out[v][k] = NONE;
                if nd != dir {
                    pts.push((x, y));
                }
                let (nx, ny) = (x + DX[nd as usize], y + DY[nd as usize]);
                area2 += x * ny - nx * y;
                (x, y, dir) = (nx, ny, nd);
            }
            // The start vertex is a corner unless the walk arrives straight through it.
            if dir == dir0 {
                pts.remove(0);
            }
            if area2 != 0 && pts.len() >= 3 {
                let first = pts.iter().map(|&(px, py)| (py, px)).min().unwrap_or((0, 0));
                let flat: Vec<f64> = pts
                    .iter()
                    .flat_map(|&(px, py)| [(px + x0 as i64) as f64, (py + y0 as i64) as f64])
                    .collect();
                let key = (first.0 as usize) << 32 | first.1 as usize;
                if area2 > 0 {
                    polygons.push((key, flat));
                } else {
                    holes.push((key, flat));
                }
            }
        }
    }
    polygons.sort_by_key(|(k, _)| *k);
    holes.sort_by_key(|(k, _)| *k);
    Rings {
        outer: polygons.into_iter().map(|(_, p)| p).collect(),
        holes: holes.into_iter().map(|(_, p)| p).collect(),
    }
}

/// Twice the signed area of a ring `[x1, y1, …]` (shoelace; positive for clockwise on screen).
pub fn ring_area2(ring: &[f64]) -> f64 {
    let n = ring.len() / 2;
    (0..n)
        .map(|i| {
            let j = (i + 1) % n;
            ring[2 * i] * ring[2 * j + 1] - ring[2 * j] * ring[2 * i + 1]
        })
        .sum()
}

/// All rings joined into one by zero-width cuts ("bridges"), for formats whose polygons have no holes
/// and one polygon per instance (YOLO-seg). The largest outer ring is the start; every other ring
/// (further outer rings, then holes) is spliced in at its vertex nearest to the ring built so far, so
/// each cut is a segment walked once in each direction. Even-odd (and non-zero) filling of the result
/// covers exactly the pixel centres the rings cover: a cut is crossed twice by any scanline that
/// crosses it. Empty when there is no outer ring.
pub fn bridge_rings(rings: &Rings) -> Vec<[f64; 2]> {
    let pts = |r: &Vec<f64>| -> Vec<[f64; 2]> { r.chunks_exact(2).map(|c| [c[0], c[1]]).collect() };
    let mut outer: Vec<&Vec<f64>> = rings.outer.iter().collect();
    // Largest first; ties keep the tracer's order (sort is stable).
    outer.sort_by(|a, b| ring_area2(b).total_cmp(&ring_area2(a)));
    let Some((first, rest)) = outer.split_first() else {
        return Vec::new();
    };
    let mut out = pts(first);
    for ring in rest.iter().copied().chain(rings.holes.iter()) {
        let q = pts(ring);
        let (mut best, mut bi, mut bj) = (f64::INFINITY, 0, 0);
        for (i, a) in out.iter().enumerate() {
            for (j, b) in q.iter().enumerate() {
                let d = (a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2);
                if d < best {
                    (best, bi, bj) = (d, i, j);
                }
            }
        }
        // out[..=bi] → q[bj..] → q[..=bj] → out[bi..]: the cut out[bi]–q[bj] is walked both ways.
        let mut merged = Vec::with_capacity(out.len() + q.len() + 2);
        merged.extend_from_slice(&out[..=bi]);
        merged.extend_from_slice(&q[bj..]);
        merged.extend_from_slice(&q[..=bj]);
        merged.extend_from_slice(&out[bi..]);
        out = merged;
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn grid(rows: &[&str]) -> (Vec<u8>, u32, u32) {
        let h = rows.len() as u32;
        let w = rows[0].len() as u32;
        (rows.iter().flat_map(|r| r.bytes().map(|b| (b == b'#') as u8)).collect(), w, h)
    }

    /// Even-odd point-in-polygon at pixel centres: the reference rasteriser for the tests.
    fn rasterise(polys: &[Vec<f64>], w: u32, h: u32) -> Vec<u8> {
        let mut m = vec![0u8; (w * h) as usize];
        for y in 0..h {
            for x in 0..w {
                let (px, py) = (x as f64 + 0.5, y as f64 + 0.5);
                let mut inside = false;
                for p in polys {
                    let n = p.len() / 2;
                    for i in 0..n {
                        let (ax, ay, bx, by) =
                            (p[2 * i], p[2 * i + 1], p[2 * ((i + 1) % n)], p[2 * ((i + 1) % n) + 1]);
                        if (ay > py) != (by > py) && px < ax + (py - ay) * (bx - ax) / (by - ay) {
                            inside = !inside;
                        }
                    }
                }
                m[(y * w + x) as usize] = inside as u8;
            }
        }
        m
    }

    #[test]
    fn rectangle_gives_its_four_corners() {
        let (m, w, h) = grid(&["....", ".##.", ".##.", "...."]);
        assert_eq!(mask_to_polygons(&m, w, h), vec![vec![1.0, 1.0, 3.0, 1.0, 3.0, 3.0, 1.0, 3.0]]);
    }

    #[test]
    fn l_shape_and_border_round_trip() {
        let (m, w, h) = grid(&["##...", "##...", "#####", "#####"]);
        let p = mask_to_polygons(&m, w, h);
        assert_eq!(p.len(), 1);
        assert_eq!(p[0].len(), 12, "six corners: {:?}", p[0]);
        assert_eq!(rasterise(&p, w, h), m);
    }

    #[test]
    fn courtyard_hole_is_filled() {
        let (m, w, h) = grid(&["#####", "#...#", "#...#", "#####"]);
        let p = mask_to_polygons(&m, w, h);
        assert_eq!(p, vec![vec![0.0, 0.0, 5.0, 0.0, 5.0, 4.0, 0.0, 4.0]]);
    }

    #[test]
    fn diagonal_touch_is_one_loop_and_separate_blobs_two() {
        let (m, w, h) = grid(&["#...", ".#..", "...#"]);
        let p = mask_to_polygons(&m, w, h);
        assert_eq!(p.len(), 2, "{p:?}");
        assert_eq!(rasterise(&p[..1], w, h).iter().map(|&v| v as u32).sum::<u32>(), 2);
        assert_eq!(rasterise(&p, w, h), m);
    }

    #[test]
    fn courtyard_rings_and_bridge_keep_the_hole() {
        let (m, w, h) = grid(&["#######", "#.....#", "#.###.#", "#.....#", "#######", "##..###"]);
        let r = mask_to_rings(&m, w, h);
        assert_eq!((r.outer.len(), r.holes.len()), (2, 1), "{r:?}");
        assert!(r.holes.iter().all(|h| ring_area2(h) < 0.0) && r.outer.iter().all(|o| ring_area2(o) > 0.0));
        let mut all = r.outer.clone();
        all.extend(r.holes.iter().cloned());
        assert_eq!(rasterise(&all, w, h), m);
        let one: Vec<f64> = bridge_rings(&r).into_iter().flatten().collect();
        assert_eq!(rasterise(&[one], w, h), m, "bridged ring");
    }

    #[test]
    fn bridge_of_separate_blobs_and_nested_island() {
        let (m, w, h) = grid(&["#####...##", "#...#...##", "#.#.#.....", "#...#...#.", "#####....."]);
        let r = mask_to_rings(&m, w, h);
        let one: Vec<f64> = bridge_rings(&r).into_iter().flatten().collect();
        assert_eq!(rasterise(&[one], w, h), m);
        assert!(bridge_rings(&Rings::default()).is_empty());
    }

    #[test]
    fn empty_mask_has_no_polygon() {
        assert!(mask_to_polygons(&[0; 6], 3, 2).is_empty());
    }
}
