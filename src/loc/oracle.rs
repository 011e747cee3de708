//! Oracle queries: ground-truth instance masks with seeded degradations that mimic a real segmenter
//! (`eval-loc --oracle`): erode/dilate by k px, drop a fraction of instances, merge touching
//! instances, split instances, add false positives, jitter scores.
//!
//! Degradations apply in a fixed order (morphology → merge → split → drop → false positives → scores)
//! on a label image (0 = background, j ≥ 1 = instance j − 1), and the result is a [`Query`].

use std::collections::BTreeSet;

use rand::seq::SliceRandom;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use super::cost::Query;

/// The degradations to apply (all off by default: a perfect oracle).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct Degradation {
    /// Positive: dilate by this many pixels; negative: erode (square structuring element).
    pub morph_px: i32,
    /// Fraction of instances dropped.
    pub drop_fraction: f64,
    /// Fraction of instances merged with a touching neighbour.
    pub merge_fraction: f64,
    /// Fraction of instances split in two (along their longer box side).
    pub split_fraction: f64,
    /// Number of false-positive blobs added.
    pub false_positives: u32,
    /// Scores are 1 − |N(0, σ)| clamped to [0.05, 1].
    pub score_jitter: f64,
}

impl Degradation {
    /// Whether nothing is degraded (a perfect oracle).
    pub fn is_perfect(&self) -> bool {
        *self == Degradation::default()
    }
}

/// Applies `d` to a ground-truth label image with `n` instances, seeded.
pub fn degrade(width: u32, height: u32, labels: &[u32], n: u32, d: &Degradation, seed: u64) -> Query {
    let (w, h) = (width as usize, height as usize);
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut img = LabelImage { lab: super::morph::morph(labels, w, h, d.morph_px), w, h, n };
    if d.merge_fraction > 0.0 {
        img.merge(d.merge_fraction, &mut rng);
    }
    if d.split_fraction > 0.0 {
        img.split(d.split_fraction, &mut rng);
    }
    if d.drop_fraction > 0.0 {
        img.drop_instances(d.drop_fraction, &mut rng);
    }
    for _ in 0..d.false_positives {
        img.add_false_positive(&mut rng);
    }
    let scores: Vec<f64> = (0..img.n)
        .map(|_| {
            if d.score_jitter > 0.0 {
                let z: f64 = rand_distr::Distribution::sample(&rand_distr::StandardNormal, &mut rng);
                (1.0 - (z * d.score_jitter).abs()).clamp(0.05, 1.0)
            } else {
                1.0
            }
        })
        .collect();
    Query::from_labels(width, height, &img.lab, &scores)
}

/// A label image being degraded: `w × h` pixels, row-major, 0 = background, labels `1..=n`.
struct LabelImage {
    lab: Vec<u32>,
    w: usize,
    h: usize,
    /// Highest label in use (new instances take `n + 1`).
    n: u32,
}

impl LabelImage {
    /// For each label, the labels it touches (4-neighbourhood).
    fn touching(&self) -> Vec<BTreeSet<u32>> {
        let (w, h, lab) = (self.w, self.h, &self.lab);
        let mut touching: Vec<BTreeSet<u32>> = vec![Default::default(); self.n as usize + 1];
        for y in 0..h {
            for x in 0..w {
                let a = lab[y * w + x];
                if a == 0 {
                    continue;
                }
                for (xx, yy) in [(x + 1, y), (x, y + 1)] {
                    if xx < w && yy < h {
                        let b = lab[yy * w + xx];
                        if b != 0 && b != a {
                            touching[a as usize].insert(b);
                            touching[b as usize].insert(a);
                        }
                    }
                }
            }
        }
        touching
    }

    /// Merge: relabels a `fraction` of the instances (in shuffled order) to a touching neighbour's
    /// label.
    fn merge(&mut self, fraction: f64, rng: &mut ChaCha8Rng) {
        let n = self.n;
        let touching = self.touching();
        let mut target: Vec<u32> = (0..=n).collect();
        let mut order: Vec<u32> = (1..=n).collect();
        order.shuffle(rng);
        let count = (fraction * n as f64).round() as usize;
        let mut merged = 0;
        for a in order {
            if merged >= count {
                break;
            }
            if target[a as usize] != a {
                continue;
            }
            if let Some(&b) = touching[a as usize].iter().find(|&&b| target[b as usize] == b) {
                target[a as usize] = b;
                merged += 1;
            }
        }
        for l in self.lab.iter_mut() {
            *l = target[*l as usize];
        }
    }

    /// Bounding box `[x0, y0, x1, y1]` (inclusive, pixels) of each label; `usize::MAX` corners for
    /// absent labels.
    fn boxes(&self) -> Vec<[usize; 4]> {
        let w = self.w;
        let mut boxes = vec![[usize::MAX, usize::MAX, 0usize, 0usize]; self.n as usize + 1];
        for y in 0..self.h {
            for x in 0..w {
                let l = self.lab[y * w + x] as usize;
                if l != 0 {
                    let b = &mut boxes[l];
                    *b = [b[0].min(x), b[1].min(y), b[2].max(x), b[3].max(y)];
                }
            }
        }
        boxes
    }

    /// Split: in a `fraction` of the instances, the pixels beyond the box midline (of the longer
    /// side) get a new label.
    fn split(&mut self, fraction: f64, rng: &mut ChaCha8Rng) {
        let boxes = self.boxes();
        let mut order: Vec<u32> = (1..=self.n).filter(|&l| boxes[l as usize][0] != usize::MAX).collect();
        order.shuffle(rng);
        let count = (fraction * self.n as f64).round() as usize;
        let w = self.w;
        for &l in order.iter().take(count) {
            let b = boxes[l as usize];
            let vertical = b[2] - b[0] >= b[3] - b[1];
            let mid = if vertical { (b[0] + b[2]) / 2 } else { (b[1] + b[3]) / 2 };
            self.n += 1;
            for y in b[1]..=b[3] {
                for x in b[0]..=b[2] {
                    let i = y * w + x;
                    if self.lab[i] == l && (if vertical { x > mid } else { y > mid }) {
                        self.lab[i] = self.n;
                    }
                }
            }
        }
    }

    /// Drop: a `fraction` of the labels (chosen in shuffled order) become background.
    fn drop_instances(&mut self, fraction: f64, rng: &mut ChaCha8Rng) {
        let n = self.n;
        let mut order: Vec<u32> = (1..=n).collect();
        order.shuffle(rng);
        let count = (fraction * n as f64).round() as usize;
        let mut dropped = vec![false; n as usize + 1];
        for &l in order.iter().take(count) {
            dropped[l as usize] = true;
        }
        for l in self.lab.iter_mut() {
            if dropped[*l as usize] {
                *l = 0;
            }
        }
    }

    /// False positive: a new label on the background pixels of a rectangle of 2–6 % of the image
    /// side.
    fn add_false_positive(&mut self, rng: &mut ChaCha8Rng) {
        let (w, h) = (self.w, self.h);
        let bw = ((w as f64) * rng.gen_range(0.02..0.06)).max(2.0) as usize;
        let bh = ((h as f64) * rng.gen_range(0.02..0.06)).max(2.0) as usize;
        let x0 = rng.gen_range(0..w.saturating_sub(bw).max(1));
        let y0 = rng.gen_range(0..h.saturating_sub(bh).max(1));
        self.n += 1;
        for y in y0..(y0 + bh).min(h) {
            for x in x0..(x0 + bw).min(w) {
                if self.lab[y * w + x] == 0 {
                    self.lab[y * w + x] = self.n;
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    // 8×4 image, two touching 4×4 instances side by side.
    fn two_blocks() -> Vec<u32> {
        (0..32).map(|i| if i % 8 < 4 { 1 } else { 2 }).collect()
    }

    #[test]
    fn perfect_oracle_is_identity() {
        let q = degrade(8, 4, &two_blocks(), 2, &Degradation::default(), 0);
        assert_eq!(q.instances.len(), 2);
        assert_eq!(q.instances[0].area_px(), 16);
        assert!(q.instances.iter().all(|i| i.score == 1.0));
    }

    #[test]
    fn erosion_by_one_pixel() {
        // A 5×5 block in a 7×7 image erodes to its 3×3 core.
        let mut lab = vec![0u32; 49];
        for y in 1..6 {
            for x in 1..6 {
                lab[y * 7 + x] = 1;
            }
        }
        let q = degrade(7, 7, &lab, 1, &Degradation { morph_px: -1, ..Default::default() }, 0);
        assert_eq!(q.instances[0].area_px(), 9);
        let q = degrade(7, 7, &lab, 1, &Degradation { morph_px: 1, ..Default::default() }, 0);
        assert_eq!(q.instances[0].area_px(), 49);
    }

    #[test]
    fn merge_split_drop_fp() {
        let merged =
            degrade(8, 4, &two_blocks(), 2, &Degradation { merge_fraction: 0.5, ..Default::default() }, 3);
        assert_eq!(merged.instances.len(), 1);
        assert_eq!(merged.instances[0].area_px(), 32);
        let split =
            degrade(8, 4, &two_blocks(), 2, &Degradation { split_fraction: 0.5, ..Default::default() }, 3);
        assert_eq!(split.instances.len(), 3);
        let dropped =
            degrade(8, 4, &two_blocks(), 2, &Degradation { drop_fraction: 0.5, ..Default::default() }, 3);
        assert_eq!(dropped.instances.len(), 1);
        let mut bg = vec![0u32; 100 * 100];
        bg[0] = 1;
        let fp = degrade(100, 100, &bg, 1, &Degradation { false_positives: 3, ..Default::default() }, 3);
        assert_eq!(fp.instances.len(), 4);
    }

    #[test]
    fn seeded() {
        let d = Degradation { drop_fraction: 0.5, score_jitter: 0.2, ..Default::default() };
        assert_eq!(degrade(8, 4, &two_blocks(), 2, &d, 9), degrade(8, 4, &two_blocks(), 2, &d, 9));
    }
}
