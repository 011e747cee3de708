//! Morphology of label images (0 = background, ≥ 1 = an instance), one instance at a time, with a
//! square structuring element of radius r (a (2r+1)² window, clipped to the image):
//! - erode: a pixel keeps its label when the whole window has that label, else becomes background, so
//!   touching instances part with a gap between them, as a segmenter's thin masks do;
//! - dilate: a background pixel takes the smallest label in its window; labelled pixels stay (instances
//!   never grow into each other).
//!
//! Both are separable (a row pass, then a column pass over its result), so a call costs O(pixels · r)
//! instead of O(pixels · r²): the localizer applies it to every rendered hypothesis when it estimates a
//! silhouette offset ([`super::eval`]), the oracle to its query masks ([`super::oracle`]).

/// Whether pixel `i` of a `w` × `h` image (row-major) lies on an outline of what `key` tells apart:
/// it has a 4-neighbour inside the image whose key differs from its own: the degraded masks'
/// outlines and the overlays' instance edges.
#[inline]
pub fn on_outline<T: PartialEq>(i: usize, w: usize, h: usize, key: impl Fn(usize) -> T) -> bool {
    let (x, y, k) = (i % w, i / w, key(i));
    (x > 0 && key(i - 1) != k)
        || (x + 1 < w && key(i + 1) != k)
        || (y > 0 && key(i - w) != k)
        || (y + 1 < h && key(i + w) != k)
}

/// Erodes (`k` < 0) or dilates (`k` > 0) each instance of `labels` (`w` × `h`, row-major) by |k|
/// pixels into `out` (resized to fit); `k` = 0 copies. `scratch` is reused between calls.
pub fn morph_into(labels: &[u32], w: usize, h: usize, k: i32, scratch: &mut Vec<u32>, out: &mut Vec<u32>) {
    debug_assert_eq!(labels.len(), w * h);
    out.clear();
    if k == 0 || w == 0 || h == 0 {
        out.extend_from_slice(labels);
        return;
    }
    let r = k.unsigned_abs() as usize;
    scratch.clear();
    scratch.resize(w * h, 0);
    out.resize(w * h, 0);
    // A window's value: erode, the label when every pixel has it, else 0 (NONE for "mixed"); dilate, the
    // smallest non-zero label (NONE when there is none).
    const NONE: u32 = u32::MAX;
    let combine = |acc: u32, v: u32| -> u32 {
        if k < 0 {
            if acc == v {
                acc
            } else {
                NONE
            }
        } else if v == 0 || v == NONE {
            acc
        } else {
            acc.min(v)
        }
    };
    // Rows: scratch[y][x] = the window value of labels[y][x − r ..= x + r].
    for y in 0..h {
        let row = &labels[y * w..(y + 1) * w];
        for x in 0..w {
            let (a, b) = (x.saturating_sub(r), (x + r).min(w - 1));
            let first = if k < 0 { row[x] } else { NONE };
            scratch[y * w + x] = row[a..=b].iter().fold(first, |acc, &v| combine(acc, v));
        }
    }
    // Columns over the row values.
    for y in 0..h {
        let (a, b) = (y.saturating_sub(r), (y + r).min(h - 1));
        for x in 0..w {
            let i = y * w + x;
            let l = labels[i];
            out[i] = if k < 0 {
                if l == 0 {
                    0
                } else {
                    let all = (a..=b).fold(l, |acc, yy| combine(acc, scratch[yy * w + x]));
                    if all == l {
                        l
                    } else {
                        0
                    }
                }
            } else if l != 0 {
                l
            } else {
                let m = (a..=b).fold(NONE, |acc, yy| combine(acc, scratch[yy * w + x]));
                if m == NONE {
                    0
                } else {
                    m
                }
            };
        }
    }
}

/// [`morph_into`], allocating.
pub fn morph(labels: &[u32], w: usize, h: usize, k: i32) -> Vec<u32> {
    let (mut scratch, mut out) = (Vec::new(), Vec::new());
    morph_into(labels, w, h, k, &mut scratch, &mut out);
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    /// The definition, window by window.
    fn naive(labels: &[u32], w: usize, h: usize, k: i32) -> Vec<u32> {
        let r = k.unsigned_abs() as i64;
        let window = |x: usize, y: usize| {
            let mut v = Vec::new();
            for yy in (y as i64 - r).max(0)..=(y as i64 + r).min(h as i64 - 1) {
                for xx in (x as i64 - r).max(0)..=(x as i64 + r).min(w as i64 - 1) {
                    v.push(labels[yy as usize * w + xx as usize]);
                }
            }
            v
        };
        let mut out = labels.to_vec();
        for y in 0..h {
            for x in 0..w {
                let l = labels[y * w + x];
                let win = window(x, y);
                out[y * w + x] = if k < 0 {
                    if l != 0 && win.iter().all(|&v| v == l) {
                        l
                    } else {
                        0
                    }
                } else if l != 0 {
                    l
                } else {
                    win.iter().copied().filter(|&v| v != 0).min().unwrap_or(0)
                };
            }
        }
        out
    }

    /// Blocky random label images: rectangles of a few labels over background.
    fn blocks(w: usize, h: usize, seed: u64) -> Vec<u32> {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let mut img = vec![0u32; w * h];
        for label in 1..=6u32 {
            let (x0, y0) = (rng.gen_range(0..w), rng.gen_range(0..h));
            let (bw, bh) = (rng.gen_range(1..=w / 2), rng.gen_range(1..=h / 2));
            for y in y0..(y0 + bh).min(h) {
                for x in x0..(x0 + bw).min(w) {
                    img[y * w + x] = label;
                }
            }
        }
        img
    }

    #[test]
    fn separable_passes_equal_the_window_definition() {
        for seed in 0..20 {
            let (w, h) = (23, 17);
            let img = blocks(w, h, seed);
            for k in [-3, -2, -1, 0, 1, 2, 3] {
                assert_eq!(morph(&img, w, h, k), naive(&img, w, h, k), "seed {seed}, k {k}");
            }
        }
    }

    #[test]
    fn a_block_erodes_to_its_core_and_touching_blocks_part() {
        // Two 5×5 blocks side by side in a 12×7 image: eroding by 1 leaves two 3×3 cores with a gap.
        let (w, h) = (12, 7);
        let mut img = vec![0u32; w * h];
        for y in 1..6 {
            for x in 1..6 {
                img[y * w + x] = 1;
                img[y * w + x + 5] = 2;
            }
        }
        let e = morph(&img, w, h, -1);
        assert_eq!(e.iter().filter(|&&v| v == 1).count(), 9);
        assert_eq!(e.iter().filter(|&&v| v == 2).count(), 9);
        assert_eq!(e[3 * w + 5], 0, "the shared edge becomes background");
        assert_eq!(e[3 * w + 6], 0);
        // Dilating by 1 grows the pair into the 12×7 frame but never over each other.
        let d = morph(&img, w, h, 1);
        assert_eq!(d[0], 1);
        assert_eq!(d[w - 1], 2);
        assert_eq!(d[3 * w + 6], 2, "a labelled pixel keeps its label");
    }
}
