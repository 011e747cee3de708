//! The rim tolerance (issue 40): every rendered building's rim free to move by a pixel, in or out,
//! each building its own way, so that a segmenter's instance a pixel fatter or thinner than its
//! building is explained by that building's rim instead of by a camera moved along its axis.
//!
//! - the union's overlap ([`Scorer::rim_tolerant_overlap`]): one choice per building (as rendered,
//!   eroded or dilated where it meets the background) for the whole frame, the best set found exactly
//!   by Dinkelbach's iteration;
//! - the best-match Dice ([`Scorer::rim_tolerant_instance_cost`]): per pair of query instance and
//!   rendered building, the building as rendered, eroded by a pixel wherever it meets another ID, or
//!   dilated by a pixel into the background, whichever matches that instance best (the pairs are
//!   independent in the paper's best match, so no joint choice is needed);
//! - the grouped cost's union Dice ([`Scorer::rim_tolerant_grouped_instance_cost`]): per query
//!   instance, the best set of rendered buildings and one choice per building in it (as rendered,
//!   eroded, or dilated into the background pixels it owns), found exactly by Dinkelbach's iteration,
//!   and never below the rim-tolerant best match.
//!
//! A building displaced by a pixel is not explained by its rim (growing it covers the query on one
//! side but spills on the other), so the outlines' positions, and with them the depth, still count.
//! The polish's second pass uses both ([`crate::loc::search::PolishCost::rim_tolerance`]).

use super::{weight_of, Query, QueryInstance, Scorer, Weighting, BLOCK, DICE_EPS};

/// Rounds of Dinkelbach's iteration in [`Scorer::rim_tolerant_overlap`] at most (it converges in two
/// or three: each round's choices are optimal for the ratio reached so far).
const MAX_RIM_ROUNDS: usize = 16;

/// One rendered building's pixels for [`Scorer::rim_tolerant_overlap`], each as (inside the query's
/// union, outside it): as rendered, those its erosion by a pixel removes (on the background's
/// 4-neighbourhood), and those its dilation by a pixel adds (background pixels with it as their
/// lowest-ID 4-neighbour).
#[derive(Debug, Default, Clone, Copy)]
pub(super) struct RimCounts {
    rendered: [u64; 2],
    eroded: [u64; 2],
    dilated: [u64; 2],
}

/// [`InstanceRims::class`] of a building pixel with a 4-neighbour of another ID (background or another
/// building): its building's erosion by a pixel removes it.
const INNER: u8 = 1;
/// [`InstanceRims::class`] of a background pixel with a building among its 4-neighbours: the dilation
/// by a pixel of each such building adds it.
const OUTER: u8 = 2;

/// Buffers of [`Scorer::rim_tolerant_instance_cost`] and [`Scorer::rim_tolerant_grouped_instance_cost`].
#[derive(Debug, Default)]
pub(super) struct InstanceRims {
    /// Per pixel of the rendered frame: [`INNER`], [`OUTER`] or 0.
    class: Vec<u8>,
    /// Per rendered building: [the pixels its erosion removes, the pixels its dilation adds, those
    /// of them it owns]. A background pixel next to several buildings is added by each one's dilation
    /// but owned by the lowest ID's alone, so that owned dilations never overlap (the grouped cost
    /// adds them up over a set of buildings).
    totals: Vec<[u32; 3]>,
    /// One query instance's row: per rendered building, the same three counts for the pixels inside
    /// the instance; all zero between instances (only the IDs in `touched` are read and reset).
    row: Vec<[u32; 3]>,
    touched: Vec<u32>,
}

/// The lowest building ID among `ids` (0 when none): the owner of a background pixel's dilation.
#[inline]
fn owner(ids: [usize; 4]) -> usize {
    ids.into_iter().filter(|&k| k != 0).min().unwrap_or(0)
}

/// The building ID of a rendered value: IDs ≥ `k1` read as background (0).
#[inline]
fn building_id(v: u32, k1: usize) -> usize {
    if (v as usize) < k1 {
        v as usize
    } else {
        0
    }
}

/// The IDs of the 4-neighbours of pixel `i` of a `w` × `h` frame (IDs ≥ `k1` read as background; a
/// neighbour outside the frame reads as the pixel itself).
#[inline]
fn neighbour_ids(rendered: &[u32], w: usize, h: usize, i: usize, k1: usize) -> [usize; 4] {
    let id = |v: u32| building_id(v, k1);
    let (x, y, k) = (i % w, i / w, id(rendered[i]));
    [
        if x > 0 { id(rendered[i - 1]) } else { k },
        if x + 1 < w { id(rendered[i + 1]) } else { k },
        if y > 0 { id(rendered[i - w]) } else { k },
        if y + 1 < h { id(rendered[i + w]) } else { k },
    ]
}

/// Calls `f` once for every distinct building (non-zero) ID among `ids`.
#[inline]
fn for_each_building(ids: [usize; 4], mut f: impl FnMut(usize)) {
    for (n, &k) in ids.iter().enumerate() {
        if k != 0 && !ids[..n].contains(&k) {
            f(k);
        }
    }
}

impl InstanceRims {
    /// Classifies every pixel of `rendered` ([`INNER`], [`OUTER`]) and counts each building's rims;
    /// clears the row for `k1` IDs.
    pub(super) fn classify(&mut self, rendered: &[u32], w: usize, h: usize, k1: usize) {
        self.class.clear();
        self.class.resize(w * h, 0);
        self.totals.clear();
        self.totals.resize(k1, [0; 3]);
        self.row.clear();
        self.row.resize(k1, [0; 3]);
        let totals = &mut self.totals;
        for (y, classes) in self.class.chunks_exact_mut(w).enumerate() {
            let row = &rendered[y * w..(y + 1) * w];
            // The rows above and below; at the frame's edge the row itself (a neighbour outside the
            // frame reads as the pixel).
            let up = if y > 0 { &rendered[(y - 1) * w..y * w] } else { row };
            let down = if y + 1 < h { &rendered[(y + 1) * w..(y + 2) * w] } else { row };
            let mut x = 0;
            while x < w {
                // Inside a region of one value (a building's interior, open background), a block of
                // pixels is skipped with one branch-free comparison of the block and its neighbours.
                if x > 0 && x + BLOCK < w {
                    let v = row[x];
                    let same = |s: &[u32]| s.iter().fold(true, |same, &r| same & (r == v));
                    if same(&row[x - 1..x + BLOCK + 1])
                        && same(&up[x..x + BLOCK])
                        && same(&down[x..x + BLOCK])
                    {
                        x += BLOCK;
                        continue;
                    }
                }
                let k = building_id(row[x], k1);
                let around = neighbour_ids(rendered, w, h, y * w + x, k1);
                if k != 0 {
                    if around.iter().any(|&n| n != k) {
                        classes[x] = INNER;
                        totals[k][0] += 1;
                    }
                } else if around != [0; 4] {
                    classes[x] = OUTER;
                    for_each_building(around, |n| totals[n][1] += 1);
                    totals[owner(around)][2] += 1;
                }
                x += 1;
            }
        }
    }

    /// Fills the row of `inst` from the classes of its pixels, listing the IDs met in `touched`.
    fn fill_row(&mut self, inst: &QueryInstance, rendered: &[u32], w: usize, h: usize) {
        let (row, touched) = (&mut self.row, &mut self.touched);
        let k1 = row.len();
        touched.clear();
        let mut add = |k: usize, side: usize| {
            if row[k] == [0; 3] {
                touched.push(k as u32);
            }
            row[k][side] += 1;
        };
        for &[a, b] in inst.spans() {
            let (a, b) = (a as usize, b as usize);
            // Most of an instance is no rim: blocks of unclassified pixels are skipped at once.
            for (start, block) in (a..).step_by(BLOCK).zip(self.class[a..b].chunks(BLOCK)) {
                if block.iter().fold(0, |any, &c| any | c) == 0 {
                    continue;
                }
                for (i, &class) in (start..).zip(block) {
                    if class == INNER {
                        add(rendered[i] as usize, 0);
                    } else if class == OUTER {
                        let around = neighbour_ids(rendered, w, h, i, k1);
                        for_each_building(around, |n| add(n, 1));
                        add(owner(around), 2);
                    }
                }
            }
        }
    }
}

/// The best Dice of a query instance of `query_px` pixels with one rendered building of `area_px`,
/// `inter_px` of them inside the instance, taken as rendered, eroded by a pixel (`rims[0]` of its
/// pixels gone, `inside[0]` of them inside the instance) or dilated by one (`rims[1]` pixels added,
/// `inside[1]` inside the instance).
fn rim_tolerant_dice(query_px: f64, inter_px: u32, area_px: u32, inside: [u32; 3], rims: [u32; 3]) -> f64 {
    let dice = |inter: u32, area: u32| 2.0 * inter as f64 / (query_px + area as f64 + DICE_EPS);
    let eroded = dice(inter_px - inside[0], area_px - rims[0]);
    let dilated = dice(inter_px + inside[1], area_px + rims[1]);
    dice(inter_px, area_px).max(eroded).max(dilated)
}

/// One rendered building's choices in the grouped cost's union with the rims free, each as (pixels
/// inside the query instance, pixels): as rendered, eroded by a pixel, dilated by a pixel into the
/// background pixels it owns.
pub(super) type Choices = [(u32, u32); 3];

/// The largest Dice 2 Σ h / (`query_px` + Σ r + ε) of a query instance with a union of buildings,
/// each building in it taking one of its `choices` (h, r), or `start` (the Dice of a union found
/// otherwise) where none is larger. Dinkelbach's iteration for a ratio of sums: with θ the best Dice
/// so far, each building takes the choice with the largest positive 2h − θ·r, or stays out; the
/// union's Dice is then above θ unless θ is the optimum (the choices are independent).
fn best_union_dice(query_px: f64, choices: &[Choices], start: f64) -> f64 {
    let mut best = start;
    for _ in 0..MAX_RIM_ROUNDS {
        let (mut inter, mut area) = (0u64, 0u64);
        for c in choices {
            let gain = |&(h, r): &(u32, u32)| 2.0 * h as f64 - best * r as f64;
            let pick = c.iter().fold(None, |acc: Option<((u32, u32), f64)>, o| {
                let g = gain(o);
                if g > acc.map_or(0.0, |a| a.1) {
                    Some((*o, g))
                } else {
                    acc
                }
            });
            if let Some(((h, r), _)) = pick {
                inter += h as u64;
                area += r as u64;
            }
        }
        let next = 2.0 * inter as f64 / (query_px + area as f64 + DICE_EPS);
        if next <= best {
            break;
        }
        best = next;
    }
    best
}

impl Scorer {
    /// [`Scorer::instance_cost`] with every rendered building's rim free to move by a pixel for each
    /// query instance on its own: the best-match Dice of instance j is the largest of
    /// 2|M_q^j ∩ M'| / (|M_q^j| + |M'| + ε) over the rendered buildings k and M' ∈ {M_hyp^k, M_hyp^k
    /// eroded by a pixel (its pixels with a 4-neighbour of another ID removed), M_hyp^k dilated by a
    /// pixel (the background pixels with it among their 4-neighbours added)}. At least the paper's
    /// cost; an instance a pixel fatter or thinner than its building (the segmenter's rim) matches it
    /// exactly. One more pass over the frame (each pixel's class) and over the query's rim pixels.
    pub fn rim_tolerant_instance_cost(
        &mut self,
        q: &Query,
        rendered: &[u32],
        k_max: u32,
        weighting: Weighting,
    ) -> f64 {
        debug_assert_eq!(rendered.len(), (q.width * q.height) as usize);
        let Some(total_w) = self.start(q, rendered, k_max, weighting) else { return 0.0 };
        let (w, h) = (q.width as usize, q.height as usize);
        self.instance_rims.classify(rendered, w, h, self.render_area.len());
        let mut c = 0.0;
        for inst in &q.instances {
            self.fill_row(inst, rendered);
            let qa = inst.area_px() as f64;
            let mut best = 0.0f64;
            self.for_each_rim_pair(inst, rendered, w, h, |inter, area, inside, rims| {
                best = best.max(rim_tolerant_dice(qa, inter, area, inside, rims));
            });
            c += weight_of(inst, weighting) / total_w * best;
        }
        c
    }

    /// [`Scorer::grouped_instance_cost`] with every rendered building's rim free to move by a pixel:
    /// each query instance's union Dice is the largest of
    /// 2 Σ_S |M_q^j ∩ M'_k| / (|M_q^j| + Σ_S |M'_k| + ε)
    /// over the sets S of rendered buildings and, for each building in S, M'_k as rendered, eroded
    /// by a pixel (its pixels with a 4-neighbour of another ID removed) or dilated by a pixel into the
    /// background pixels it owns (those with it as their lowest-ID building 4-neighbour: owned
    /// dilations never overlap, so the sums count the union), found exactly by Dinkelbach's iteration;
    /// and never below [`Scorer::rim_tolerant_instance_cost`]'s best match (a single building,
    /// dilated into every background pixel next to it). A split is scored as in the grouped cost, the
    /// building as rendered. At least the grouped cost; a merged row of houses a pixel fatter or
    /// thinner than the houses matches them exactly.
    pub fn rim_tolerant_grouped_instance_cost(
        &mut self,
        q: &Query,
        rendered: &[u32],
        k_max: u32,
        weighting: Weighting,
    ) -> f64 {
        self.grouped(q, rendered, k_max, weighting, true)
    }

    /// The union Dice of `inst` with the rims free ([`Scorer::rim_tolerant_grouped_instance_cost`]),
    /// from the row [`Scorer::fill_row`] filled for it and the classes of the `w` × `h` frame
    /// ([`InstanceRims::classify`]); resets both rows.
    pub(super) fn rim_tolerant_union_dice(
        &mut self,
        inst: &QueryInstance,
        rendered: &[u32],
        w: usize,
        h: usize,
    ) -> f64 {
        let qa = inst.area_px() as f64;
        let mut choices = std::mem::take(&mut self.groups.choices);
        choices.clear();
        let mut single = 0.0f64;
        self.for_each_rim_pair(inst, rendered, w, h, |inter, area, inside, rims| {
            single = single.max(rim_tolerant_dice(qa, inter, area, inside, rims));
            choices.push([
                (inter, area),
                (inter - inside[0], area - rims[0]),
                (inter + inside[2], area + rims[2]),
            ]);
        });
        let best = best_union_dice(qa, &choices, single);
        self.groups.choices = choices;
        best
    }

    /// Calls `f(inter, area, inside, rims)` with [`rim_tolerant_dice`]'s terms for every rendered
    /// building that `inst` overlaps as rendered, then for every one only a dilation reaches (`inter`
    /// 0), from the row [`Scorer::fill_row`] filled for it and the classes of the `w` × `h` frame
    /// ([`InstanceRims::classify`]); resets both rows.
    fn for_each_rim_pair(
        &mut self,
        inst: &QueryInstance,
        rendered: &[u32],
        w: usize,
        h: usize,
        mut f: impl FnMut(u32, u32, [u32; 3], [u32; 3]),
    ) {
        let rims = &mut self.instance_rims;
        rims.fill_row(inst, rendered, w, h);
        for &k in &self.touched {
            let k = k as usize;
            f(self.row[k], self.render_area[k], rims.row[k], rims.totals[k]);
        }
        for &k in &rims.touched {
            let k = k as usize;
            if self.row[k] == 0 {
                f(0, self.render_area[k], rims.row[k], rims.totals[k]);
            }
            rims.row[k] = [0; 3];
        }
        for &k in &self.touched {
            self.row[k as usize] = 0;
        }
    }

    /// [`Scorer::semantic_overlap`] with every rendered building's rim free to move by a pixel: each
    /// building is taken as rendered, eroded by a pixel where it meets the background, or dilated by
    /// a pixel into the background around it (a background pixel next to several buildings belongs
    /// to the lowest ID's ring), whichever set of choices makes the overlap largest. The choices are
    /// independent, so Dinkelbach's iteration for a ratio of sums finds that set exactly in a few
    /// rounds of per-building decisions.
    ///
    /// A segmenter's instance a pixel fatter or thinner than its building, each its own way, is then
    /// explained by that building's rim instead of by a camera moved along its axis, while a building
    /// displaced by a pixel is not (dilating it covers the query on one side but spills on the
    /// other), so the outlines' positions, and with them the depth, still count. The exact render
    /// scores 1. `k_max` is the largest rendered ID (larger ones count as background).
    pub fn rim_tolerant_overlap(
        &mut self,
        q: &Query,
        rendered: &[u32],
        k_max: u32,
        spill_weight: f64,
    ) -> f64 {
        let query_px = self.count_rims(q, rendered, k_max);
        let rims = &self.rims;
        let total = rims.iter().fold([0u64; 2], |t, r| [t[0] + r.rendered[0], t[1] + r.rendered[1]]);
        let ratio = |[inter, spill]: [f64; 2]| {
            let d = query_px as f64 + spill_weight * spill;
            if d <= 0.0 {
                0.0
            } else {
                inter / d
            }
        };
        let as_f64 = |c: [u64; 2]| [c[0] as f64, c[1] as f64];
        let mut best = ratio(as_f64(total));
        // Dinkelbach: with θ the best ratio so far, each building takes the choice that adds most
        // to inter − θ·λ·spill; the ratio of the choices is ≥ θ, equal only at the optimum.
        for _ in 0..MAX_RIM_ROUNDS {
            let mut sum = as_f64(total);
            for r in rims {
                let gain = |c: [u64; 2]| c[0] as f64 - best * spill_weight * c[1] as f64;
                let (erode, dilate) = (-gain(r.eroded), gain(r.dilated));
                let change = if dilate > 0.0 && dilate >= erode {
                    as_f64(r.dilated)
                } else if erode > 0.0 {
                    as_f64(r.eroded).map(|v| -v)
                } else {
                    continue;
                };
                sum = [sum[0] + change[0], sum[1] + change[1]];
            }
            let next = ratio(sum);
            if next <= best {
                break;
            }
            best = next;
        }
        best
    }

    /// Fills [`Scorer::rims`] for `rendered` against the union of `q`; returns |Q|.
    fn count_rims(&mut self, q: &Query, rendered: &[u32], k_max: u32) -> u64 {
        let (w, h) = (q.width as usize, q.height as usize);
        debug_assert_eq!(rendered.len(), w * h);
        let n = k_max as usize + 1;
        // IDs above k_max count as background, like the other costs'.
        let id = |v: u32| if (v as usize) < n { v as usize } else { 0 };
        let rims = &mut self.rims;
        rims.clear();
        rims.resize(n, RimCounts::default());
        // The union's runs are ascending: a cursor tells whether pixel i (visited in order) is in it.
        let mut runs = q.union.iter().peekable();
        let mut query_px = 0u64;
        for y in 0..h {
            let row = &rendered[y * w..(y + 1) * w];
            for x in 0..w {
                let i = y * w + x;
                while runs.next_if(|&&[_, end]| end as usize <= i).is_some() {}
                let inq = runs.peek().is_some_and(|&&[start, _]| start as usize <= i);
                query_px += inq as u64;
                let side = (!inq) as usize;
                let k = id(row[x]);
                // The 4-neighbours inside the image; one outside stands for the pixel itself.
                let l = if x > 0 { id(row[x - 1]) } else { k };
                let r = if x + 1 < w { id(row[x + 1]) } else { k };
                let u = if y > 0 { id(rendered[i - w]) } else { k };
                let d = if y + 1 < h { id(rendered[i + w]) } else { k };
                if k != 0 {
                    rims[k].rendered[side] += 1;
                    if l == 0 || r == 0 || u == 0 || d == 0 {
                        rims[k].eroded[side] += 1;
                    }
                } else if (l | r | u | d) != 0 {
                    let owner = [l, r, u, d].into_iter().filter(|&v| v != 0).min().unwrap_or(0);
                    rims[owner].dilated[side] += 1;
                }
            }
        }
        query_px
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::loc::cost::{Blend, CostKind, Weighting, SPLIT_FACTOR};

    /// A seeded stream of draws below `n` (a linear congruential generator: the random-frame tests
    /// need no more).
    fn draws(mut seed: u64) -> impl FnMut(usize) -> usize {
        move |n| {
            seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (seed >> 33) as usize % n
        }
    }

    /// A `w`-wide label image: `ids[k]` painted over `rects[k]` = (x0, x1, y0, y1), in order.
    fn paint(w: usize, h: usize, rects: &[(usize, usize, usize, usize)], ids: &[u32]) -> Vec<u32> {
        let mut out = vec![0u32; w * h];
        for (&(x0, x1, y0, y1), &id) in rects.iter().zip(ids) {
            for y in y0..y1.min(h) {
                for x in x0..x1.min(w) {
                    out[y * w + x] = id;
                }
            }
        }
        out
    }

    #[test]
    fn the_rim_tolerance_explains_rims_a_pixel_off_but_not_a_shift() {
        // Two buildings in a 20 × 12 frame; the query's instances: A a pixel fatter on every side
        // (4-neighbourhood), B a pixel thinner, as a segmenter's rims; then both moved a pixel.
        let (w, h) = (20usize, 12usize);
        let (a, b) = ((2, 6, 2, 6), (10, 16, 3, 8));
        let render = paint(w, h, &[a, b], &[1, 2]);
        let query = |labels: Vec<u32>| Query::from_labels(w as u32, h as u32, &labels, &[1.0, 1.0]);
        let rims = query(paint(w, h, &[(1, 7, 2, 6), (2, 6, 1, 7), (11, 15, 4, 7)], &[1, 1, 2]));
        let exact = query(render.clone());
        let shifted = query(paint(w, h, &[(3, 7, 2, 6), (11, 17, 3, 8)], &[1, 2]));
        let mut s = Scorer::default();
        for lambda in [1.0, 0.3] {
            assert_eq!(s.rim_tolerant_overlap(&exact, &render, 2, lambda), 1.0);
            assert_eq!(s.rim_tolerant_overlap(&rims, &render, 2, lambda), 1.0, "λ {lambda}");
            assert!(s.semantic_overlap(&rims, &render, lambda) < 0.9);
            // A pixel sideways: no building's rim explains it (a dilation covers the column it
            // left uncovered and spills on three sides). With the IoU no choice beats the render
            // as it is; with cheap spill the dilations score better, but far from 1.
            let moved = s.rim_tolerant_overlap(&shifted, &render, 2, lambda);
            if lambda == 1.0 {
                assert_eq!(moved, s.semantic_overlap(&shifted, &render, lambda));
            }
            assert!(moved < 0.85, "λ {lambda}: {moved}");
        }
        // Through the blend: the rims move only when it says so.
        let free = Blend { semantic_weight: 1.0, spill_weight: 0.3, rim_tolerance: true };
        assert_eq!(s.cost(CostKind::Semantic, &rims, &render, 2, Weighting::Area, free), 1.0);
        let fixed = Blend { rim_tolerance: false, ..free };
        assert!(s.cost(CostKind::Semantic, &rims, &render, 2, Weighting::Area, fixed) < 0.9);
    }

    /// The overlap of [`Scorer::rim_tolerant_overlap`] by its definition: every building's
    /// choice (−1 eroded, 0 as rendered, +1 dilated) tried, the image changed accordingly.
    fn rims_by_brute_force(q: &Query, rendered: &[u32], k_max: u32, lambda: f64) -> f64 {
        let (w, h) = (q.width as usize, q.height as usize);
        let building = |i: usize| rendered[i] != 0 && rendered[i] <= k_max;
        let neighbours = |i: usize| {
            let (x, y) = (i % w, i / w);
            [(x > 0, i.wrapping_sub(1)), (x + 1 < w, i + 1), (y > 0, i.wrapping_sub(w)), (y + 1 < h, i + w)]
                .into_iter()
                .filter_map(|(inside, j)| inside.then_some(j))
                .collect::<Vec<_>>()
        };
        let mut inq = vec![false; w * h];
        for &[a, b] in &q.union {
            inq[a as usize..b as usize].fill(true);
        }
        let query_px = inq.iter().filter(|&&v| v).count() as f64;
        let mut best = 0.0f64;
        for code in 0..3usize.pow(k_max) {
            let choice = |k: u32| (code / 3usize.pow(k - 1)) % 3; // 0 kept, 1 eroded, 2 dilated
            let (mut inter, mut spill) = (0.0, 0.0);
            for i in 0..w * h {
                let covered = if building(i) {
                    !(choice(rendered[i]) == 1 && neighbours(i).iter().any(|&j| !building(j)))
                } else {
                    let owner = neighbours(i).into_iter().filter(|&j| building(j)).map(|j| rendered[j]).min();
                    owner.is_some_and(|k| choice(k) == 2)
                };
                if covered {
                    if inq[i] {
                        inter += 1.0;
                    } else {
                        spill += 1.0;
                    }
                }
            }
            let d = query_px + lambda * spill;
            best = best.max(if d > 0.0 { inter / d } else { 0.0 });
        }
        best
    }

    #[test]
    fn the_rim_tolerance_finds_the_best_choice_of_every_building() {
        // Random 9 × 7 frames of up to four overlapping or touching boxes against random query
        // boxes: the Dinkelbach rounds reach the best of the 3^K choices.
        let mut next = draws(0x5eed);
        let (w, h) = (9usize, 7usize);
        let boxes =
            |count: usize, next: &mut dyn FnMut(usize) -> usize| -> Vec<(usize, usize, usize, usize)> {
                (0..count)
                    .map(|_| {
                        let (x0, y0) = (next(w), next(h));
                        (x0, x0 + 1 + next(4), y0, y0 + 1 + next(4))
                    })
                    .collect()
            };
        let mut s = Scorer::default();
        for case in 0..300 {
            let k = 1 + case % 4;
            let ids: Vec<u32> = (1..=k as u32).collect();
            let render = paint(w, h, &boxes(k, &mut next), &ids);
            let query_boxes = boxes(1 + next(3), &mut next);
            let labels = paint(w, h, &query_boxes, &vec![1; query_boxes.len()]);
            let q = Query::from_labels(w as u32, h as u32, &labels, &[1.0]);
            for lambda in [1.0, 0.3] {
                let fast = s.rim_tolerant_overlap(&q, &render, k as u32, lambda);
                let slow = rims_by_brute_force(&q, &render, k as u32, lambda);
                assert!((fast - slow).abs() < 1e-12, "case {case}, λ {lambda}: {fast} vs {slow}");
                assert!(fast >= s.semantic_overlap(&q, &render, lambda) - 1e-12);
            }
        }
    }

    #[test]
    fn the_instance_rims_match_each_instance_a_pixel_off_but_not_a_shift() {
        // A and B touch along a column, C stands apart. The query: A a pixel thinner wherever it
        // meets another ID (the background and B), B as rendered, C a pixel fatter on every side
        // (4-neighbourhood); then every instance moved a pixel sideways.
        let (w, h) = (22usize, 10usize);
        let render = paint(w, h, &[(2, 8, 2, 8), (8, 14, 2, 8), (16, 19, 3, 7)], &[1, 2, 3]);
        let query = |labels: Vec<u32>| Query::from_labels(w as u32, h as u32, &labels, &[1.0; 3]);
        let rims =
            query(paint(w, h, &[(3, 7, 3, 7), (8, 14, 2, 8), (15, 20, 3, 7), (16, 19, 2, 8)], &[1, 2, 3, 3]));
        let shifted = query(paint(w, h, &[(3, 9, 2, 8), (9, 15, 2, 8), (17, 20, 3, 7)], &[1, 2, 3]));
        let mut s = Scorer::default();
        let one = 1.0 - 1e-6;
        assert!(s.rim_tolerant_instance_cost(&query(render.clone()), &render, 3, Weighting::Area) > one);
        assert!(s.rim_tolerant_instance_cost(&rims, &render, 3, Weighting::Area) > one);
        assert!(s.instance_cost(&rims, &render, 3, Weighting::Area) < 0.85);
        // A pixel sideways: growing a building covers the column it left but spills on three sides,
        // thinning it leaves the moved column uncovered: the rendered building stays the best match.
        let moved = s.rim_tolerant_instance_cost(&shifted, &render, 3, Weighting::Area);
        assert!(moved < 0.85, "{moved}");
        assert_eq!(moved, s.instance_cost(&shifted, &render, 3, Weighting::Area));
        // Through the blend (the pure instance cost): the rims move only when it says so.
        let free = Blend { semantic_weight: 0.0, spill_weight: 1.0, rim_tolerance: true };
        assert!(s.cost(CostKind::Instance, &rims, &render, 3, Weighting::Area, free) > one);
        let fixed = Blend { rim_tolerance: false, ..free };
        assert!(s.cost(CostKind::Instance, &rims, &render, 3, Weighting::Area, fixed) < 0.85);
    }

    /// The building ID of pixel `i` (IDs above `k_max` read as background).
    fn id_by_definition(rendered: &[u32], k_max: u32, i: usize) -> u32 {
        if rendered[i] <= k_max {
            rendered[i]
        } else {
            0
        }
    }

    /// The IDs of the 4-neighbours of pixel `i` of a `w` × `h` frame (IDs above `k_max` read as
    /// background; a neighbour outside the frame reads as the pixel itself).
    fn neighbours_by_definition(rendered: &[u32], k_max: u32, w: usize, h: usize, i: usize) -> Vec<u32> {
        let (x, y) = (i % w, i / w);
        [(x > 0, i.wrapping_sub(1)), (x + 1 < w, i + 1), (y > 0, i.wrapping_sub(w)), (y + 1 < h, i + w)]
            .into_iter()
            .map(|(inside, j)| id_by_definition(rendered, k_max, if inside { j } else { i }))
            .collect()
    }

    /// [`Scorer::rim_tolerant_instance_cost`] by its definition: every query instance against every
    /// rendered building as rendered, eroded and dilated, the images made pixel by pixel.
    fn instance_rims_by_brute_force(q: &Query, rendered: &[u32], k_max: u32) -> f64 {
        let (w, h) = (q.width as usize, q.height as usize);
        let id = |i: usize| id_by_definition(rendered, k_max, i);
        let neighbours = |i: usize| neighbours_by_definition(rendered, k_max, w, h, i);
        let total_w: f64 = q.instances.iter().map(|i| i.bbox_area_px).sum();
        let mut cost = 0.0;
        for inst in &q.instances {
            let mut mine = vec![false; w * h];
            inst.pixels().for_each(|i| mine[i as usize] = true);
            let mut best = 0.0f64;
            for k in 1..=k_max {
                let variants: [Box<dyn Fn(usize) -> bool>; 3] = [
                    Box::new(|i| id(i) == k),
                    Box::new(|i| id(i) == k && neighbours(i).iter().all(|&n| n == k)),
                    Box::new(|i| id(i) == k || (id(i) == 0 && neighbours(i).contains(&k))),
                ];
                for inside in &variants {
                    let area = (0..w * h).filter(|&i| inside(i)).count() as f64;
                    let inter = (0..w * h).filter(|&i| inside(i) && mine[i]).count() as f64;
                    best = best.max(2.0 * inter / (inst.area_px() as f64 + area + DICE_EPS));
                }
            }
            cost += inst.bbox_area_px / total_w * best;
        }
        cost
    }

    /// Random frames of up to four overlapping or touching boxes, one ID beyond k_max, against up to
    /// three random (overlapping) query instances: 9 × 7 frames of small boxes, and every other case
    /// 45 × 20 frames of boxes up to 24 px wide (interiors and open background that the
    /// classification skips a block at a time). Returns the query, the render and k_max.
    fn random_case(case: usize, next: &mut dyn FnMut(usize) -> usize) -> (Query, Vec<u32>, u32) {
        let (w, h, size) = if case.is_multiple_of(2) { (9usize, 7usize, 4) } else { (45, 20, 24) };
        let mut random_box = || {
            let (x0, y0) = (next(w), next(h));
            (x0, x0 + 1 + next(size), y0, y0 + 1 + next(size / 2))
        };
        let k = 1 + case % 4;
        let rects: Vec<_> = (0..=k).map(|_| random_box()).collect();
        let ids: Vec<u32> = (1..=k as u32 + 1).collect();
        let render = paint(w, h, &rects, &ids);
        let instances: Vec<QueryInstance> = (0..1 + case % 3)
            .map(|_| {
                let (x0, x1, y0, y1) = random_box();
                let pixels: Vec<u32> =
                    (y0..y1.min(h)).flat_map(|y| (x0..x1.min(w)).map(move |x| (y * w + x) as u32)).collect();
                QueryInstance::new(&pixels, 1.0, super::super::bbox_area(&pixels, w as u32))
            })
            .collect();
        (Query::new(w as u32, h as u32, instances), render, k as u32)
    }

    #[test]
    fn the_instance_rims_are_the_best_variant_of_every_pair() {
        let mut next = draws(0x0b5e);
        let mut s = Scorer::default();
        for case in 0..300 {
            let (q, render, k) = random_case(case, &mut next);
            let fast = s.rim_tolerant_instance_cost(&q, &render, k, Weighting::Area);
            let slow = instance_rims_by_brute_force(&q, &render, k);
            assert!((fast - slow).abs() < 1e-12, "case {case}: {fast} vs {slow}");
            assert!(fast >= s.instance_cost(&q, &render, k, Weighting::Area) - 1e-12);
        }
    }

    /// [`Scorer::rim_tolerant_grouped_instance_cost`] by its definition, the images made pixel by
    /// pixel: per query instance the best of every single building as rendered, eroded or dilated
    /// (into all the background next to it), every set of buildings each as rendered, eroded or
    /// dilated into the background it owns (the union taken pixel by pixel), and the split term.
    fn grouped_rims_by_brute_force(q: &Query, rendered: &[u32], k_max: u32) -> f64 {
        let (w, h) = (q.width as usize, q.height as usize);
        let id = |i: usize| id_by_definition(rendered, k_max, i);
        let neighbours = |i: usize| neighbours_by_definition(rendered, k_max, w, h, i);
        let owner = |i: usize| neighbours(i).into_iter().filter(|&n| n != 0).min();
        // Per building: as rendered, eroded, dilated into its own background, dilated into all.
        let masks: Vec<[Vec<bool>; 4]> = (1..=k_max)
            .map(|k| {
                let px = |f: &dyn Fn(usize) -> bool| (0..w * h).map(f).collect::<Vec<bool>>();
                [
                    px(&|i| id(i) == k),
                    px(&|i| id(i) == k && neighbours(i).iter().all(|&n| n == k)),
                    px(&|i| id(i) == k || (id(i) == 0 && owner(i) == Some(k))),
                    px(&|i| id(i) == k || (id(i) == 0 && neighbours(i).contains(&k))),
                ]
            })
            .collect();
        let dice = |mine: &[bool], union: &[bool]| {
            let area = union.iter().filter(|&&v| v).count() as f64;
            let inter = union.iter().zip(mine).filter(|(&u, &m)| u && m).count() as f64;
            let qa = mine.iter().filter(|&&v| v).count() as f64;
            2.0 * inter / (qa + area + DICE_EPS)
        };
        let mine: Vec<Vec<bool>> = q
            .instances
            .iter()
            .map(|inst| {
                let mut m = vec![false; w * h];
                inst.pixels().for_each(|i| m[i as usize] = true);
                m
            })
            .collect();
        // The split term's "inside": more than half of an instance on one building as rendered.
        let on = |j: usize, k: usize| mine[j].iter().zip(&masks[k][0]).filter(|(&a, &b)| a && b).count();
        let inside: Vec<Option<usize>> = (0..mine.len())
            .map(|j| (0..k_max as usize).find(|&k| on(j, k) as f64 > 0.5 * q.instances[j].area_px() as f64))
            .collect();
        let total_w: f64 = q.instances.iter().map(|i| i.bbox_area_px).sum();
        let mut cost = 0.0;
        for (j, inst) in q.instances.iter().enumerate() {
            let mut best = 0.0f64;
            for m in &masks {
                for v in [0, 1, 3] {
                    best = best.max(dice(&mine[j], &m[v]));
                }
            }
            let n = k_max as usize;
            for code in 0..4usize.pow(n as u32) {
                // Per building: 0 out, 1 as rendered, 2 eroded, 3 dilated into its own background.
                let mut union = vec![false; w * h];
                for (k, m) in masks.iter().enumerate() {
                    let choice = (code / 4usize.pow(k as u32)) % 4;
                    if choice > 0 {
                        union.iter_mut().zip(&m[choice - 1]).for_each(|(u, &v)| *u |= v);
                    }
                }
                best = best.max(dice(&mine[j], &union));
            }
            if let Some(k) = inside[j] {
                let group: Vec<usize> = (0..mine.len()).filter(|&i| inside[i] == Some(k)).collect();
                if group.len() > 1 {
                    let i: usize = group.iter().map(|&i| on(i, k)).sum();
                    let a: u32 = group.iter().map(|&i| q.instances[i].area_px()).sum();
                    let area_k = masks[k][0].iter().filter(|&&v| v).count();
                    let split = (2.0 * i as f64 / ((a as usize + area_k) as f64 + DICE_EPS)).min(1.0);
                    best = best.max(SPLIT_FACTOR * split);
                }
            }
            cost += inst.bbox_area_px / total_w * best;
        }
        cost
    }

    #[test]
    fn the_grouped_rims_are_the_best_union_of_variants() {
        let mut next = draws(0x9a0b);
        let mut s = Scorer::default();
        for case in 0..200 {
            let (q, render, k) = random_case(case, &mut next);
            let fast = s.rim_tolerant_grouped_instance_cost(&q, &render, k, Weighting::Area);
            let slow = grouped_rims_by_brute_force(&q, &render, k);
            assert!((fast - slow).abs() < 1e-12, "case {case}: {fast} vs {slow}");
            assert!(fast >= s.grouped_instance_cost(&q, &render, k, Weighting::Area) - 1e-12);
            assert!(fast >= s.rim_tolerant_instance_cost(&q, &render, k, Weighting::Area) - 1e-12);
        }
    }

    #[test]
    fn the_grouped_rims_match_a_merged_row_a_pixel_fat_but_not_a_shift() {
        // Three touching houses in a row (x 2..14, y 2..6), the segmenter's instance one merged
        // blob a pixel fatter on every side (4-neighbourhood), then the same blob moved a pixel.
        let (w, h) = (20usize, 9usize);
        let render = paint(w, h, &[(2, 6, 2, 6), (6, 10, 2, 6), (10, 14, 2, 6)], &[1, 2, 3]);
        let query = |labels: Vec<u32>| Query::from_labels(w as u32, h as u32, &labels, &[1.0]);
        let fat = query(paint(w, h, &[(1, 15, 2, 6), (2, 14, 1, 7)], &[1, 1]));
        let shifted = query(paint(w, h, &[(3, 15, 2, 6)], &[1]));
        let mut s = Scorer::default();
        let one = 1.0 - 1e-6;
        let rims =
            |s: &mut Scorer, q: &Query| s.rim_tolerant_grouped_instance_cost(q, &render, 3, Weighting::Area);
        assert!(rims(&mut s, &fat) > one);
        assert!(s.grouped_instance_cost(&fat, &render, 3, Weighting::Area) < 0.85);
        // The best single house, even with its rim free, matches the row far worse: the end house
        // dilated, 28 of its 80 pixels, Dice 56 / 108.
        let single = s.rim_tolerant_instance_cost(&fat, &render, 3, Weighting::Area);
        assert!((single - 56.0 / 108.0).abs() < 1e-6, "{single}");
        // A pixel sideways: no choice of rims explains it as well as a fat row is explained.
        let moved = rims(&mut s, &shifted);
        assert!(moved < 0.96, "{moved}");
        // Through the blend (the pure grouped cost): the rims move only when it says so.
        let free = Blend { semantic_weight: 0.0, spill_weight: 1.0, rim_tolerance: true };
        assert!(s.cost(CostKind::Grouped, &fat, &render, 3, Weighting::Area, free) > one);
        let fixed = Blend { rim_tolerance: false, ..free };
        assert!(s.cost(CostKind::Grouped, &fat, &render, 3, Weighting::Area, fixed) < 0.85);
    }
}
