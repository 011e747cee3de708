//! The cost of a pose hypothesis: how well the rendered building instances explain the query instances.
//!
//! Query instances M_q^j (predicted masks with scores s_j and box areas A_j) against the instances
//! rendered at the hypothesis, M_hyp^k (../shared/SPEC.md, the paper's equations):
//! - best-match Dice per query instance: d_j* = max_k 2|M_q^j ∩ M_hyp^k| / (|M_q^j| + |M_hyp^k| + ε);
//! - confidence weighting: c = Σ_j (s_j / Σ_i s_i) d_j*; area weighting: c = Σ_j (A_j / Σ_i A_i) d_j*;
//! - the LoD-Loc v2 semantic baseline: IoU of the union of the query masks with the union of the rendered
//!   buildings;
//! - the paper's ablation "merged": the query instances merged into one mask before instance scoring;
//! - the grouped instance cost (issue 40), best-match Dice made robust to what segmenters do: a query
//!   instance that merges several buildings (a row of touching houses) is matched to the *union* of the
//!   rendered instances that best explains it, d_j = max_{S ⊆ K} 2 Σ_{k∈S} |M_q^j ∩ M_hyp^k| /
//!   (|M_q^j| + Σ_{k∈S} |M_hyp^k| + ε) (the best subset is a prefix of the rendered instances sorted by
//!   the share of them the query instance covers: [`Scorer::grouped_instance_cost`]); query instances
//!   that are pieces of one rendered building (a split) are scored together, as that building's Dice with
//!   the union of its pieces, times [`SPLIT_FACTOR`] (a mild penalty: a render that needs no grouping
//!   stays better); blended with the semantic IoU like the instance cost; in the polish's second pass
//!   with every building's rim free to move by a pixel ([`Scorer::rim_tolerant_grouped_instance_cost`]);
//! - the blended instance cost (1 − w)·c + w·IoU_sem (w = [`DEFAULT_SEMANTIC_WEIGHT`] by default, 0 with
//!   `--paper`): against a map coarser than the query's buildings (an LoD1 map for LoD2 queries), taller
//!   blocks hide more of the buildings behind them, so the per-instance boundaries move while the union's
//!   outline (the skyline) stays; the semantic term anchors the optimum to that outline (issue 15);
//! - in the semantic term, rendered building pixels outside the query's union may count less than query
//!   pixels left uncovered, |Q ∩ R| / (|Q| + λ·|R \ Q|) (λ = 1: the IoU; a Tversky index), which the
//!   polish uses ([`Blend::spill_weight`]).
//!
//! All intersections come from one pass over the query pixels, accumulating a joint histogram of
//! (query instance, rendered instance). Rendered IDs must be *dense* (1..=K, 0 = background): the
//! localizer renders a culled sub-scene renumbered that way, so the histogram is a flat array.
//!
//! Query instances are stored as runs of consecutive pixels, and the histograms count runs of equal
//! rendered IDs rather than single pixels: a rendered frame is long spans of one building or of
//! background, so this is about one comparison per pixel instead of a dependent memory increment.

use serde::{Deserialize, Serialize};

mod rims;
use rims::{InstanceRims, RimCounts};

/// ε in the Dice denominator.
pub const DICE_EPS: f64 = 1e-6;

/// Factor on the Dice of a rendered building with the union of the query instances lying mostly inside
/// it, in the grouped cost ([`Scorer::grouped_instance_cost`]): a split is penalised mildly, so that a
/// building cut in two by the segmenter still explains both pieces, but a render whose buildings each
/// match one query instance stays preferred.
pub const SPLIT_FACTOR: f64 = 0.9;

/// A query instance lies "mostly inside" a rendered building (it may be one piece of it) when more
/// than this share of its pixels fall on that building. Above one half, the building is unique.
const INSIDE_SHARE: f64 = 0.5;

/// Weight of the semantic IoU in the blended instance cost when none is given (issue 15: on Den Haag
/// with an LoD1 map, recall at (2 m, 2°) rises from 80 % to the semantic baseline's level; see
/// bench/loc_issue15.md).
pub const DEFAULT_SEMANTIC_WEIGHT: f64 = 0.5;

/// The terms of the blended instance cost ([`Scorer::blended_cost`]).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Blend {
    /// Weight w of the semantic term: (1 − w)·instance + w·semantic.
    pub semantic_weight: f64,
    /// Weight λ of the rendered building pixels outside the query's union in the semantic term,
    /// |Q ∩ R| / (|Q| + λ·|R \ Q|) ([`Scorer::semantic_overlap`]); 1 is the IoU.
    pub spill_weight: f64,
    /// Whether every rendered building's rim may move by a pixel: in the semantic term
    /// ([`Scorer::rim_tolerant_overlap`]) and in the instance cost's best-match Dice
    /// ([`Scorer::rim_tolerant_instance_cost`]); the grouped cost and the merged ablation keep theirs.
    #[serde(default)]
    pub rim_tolerance: bool,
}

impl Blend {
    /// Weight `w` of the semantic IoU (spill weight 1).
    pub fn semantic(w: f64) -> Blend {
        Blend { semantic_weight: w, spill_weight: 1.0, rim_tolerance: false }
    }
}

/// How per-instance Dice scores are combined.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "lowercase")]
pub enum Weighting {
    /// By the instance's confidence score.
    Conf,
    /// By the instance's bounding-box area (the paper's main tables).
    #[default]
    Area,
    /// By the product of the two: the paper's area weighting, each instance trusted as far as its
    /// score says. With a segmenter whose scores rank its masks (`baseline.py score` reports
    /// `score_honesty`) a large merged or misplaced instance weighs less than a large exact one; with
    /// scores all 1 (oracle masks) it is [`Weighting::Area`].
    #[serde(rename = "area-conf")]
    AreaConf,
}

impl Weighting {
    /// How summaries name the weighting: `area`, `conf`, `area × conf`.
    pub fn label(self) -> &'static str {
        match self {
            Weighting::Conf => "conf",
            Weighting::Area => "area",
            Weighting::AreaConf => "area × conf",
        }
    }
}

/// Which cost to use.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Serialize, Deserialize, Default)]
#[serde(rename_all = "lowercase")]
pub enum CostKind {
    /// Best-match Dice per query instance (InsLoD-Loc).
    #[default]
    Instance,
    /// IoU of the merged query mask with all rendered buildings (LoD-Loc v2 baseline).
    Semantic,
    /// Query instances merged into one mask, then instance scoring (the paper's ablation).
    Merged,
    /// Each query instance matched to the union of rendered instances that best explains it, split
    /// pieces of one building scored together ([`Scorer::grouped_instance_cost`]), blended with the
    /// semantic IoU like [`CostKind::Instance`] (issue 40: robust to learned masks).
    Grouped,
}

/// One query instance: its pixels as runs of consecutive row-major indices, score and box area.
#[derive(Debug, Clone, PartialEq)]
pub struct QueryInstance {
    /// `[start, end)` index ranges into the query image, ascending and disjoint.
    spans: Vec<[u32; 2]>,
    area_px: u32,
    /// Confidence score in [0, 1] (1 for oracle masks).
    pub score: f64,
    /// Bounding-box area in pixels (w × h).
    pub bbox_area_px: f64,
}

impl QueryInstance {
    /// An instance from its pixel indices (ascending, no repeats).
    pub fn new(pixels: &[u32], score: f64, bbox_area_px: f64) -> QueryInstance {
        debug_assert!(pixels.windows(2).all(|w| w[0] < w[1]), "pixels must be ascending");
        let mut spans: Vec<[u32; 2]> = Vec::new();
        for &p in pixels {
            match spans.last_mut() {
                Some(last) if last[1] == p => last[1] = p + 1,
                _ => spans.push([p, p + 1]),
            }
        }
        QueryInstance { spans, area_px: pixels.len() as u32, score, bbox_area_px }
    }

    /// The runs of consecutive pixels, `[start, end)`.
    pub fn spans(&self) -> &[[u32; 2]] {
        &self.spans
    }

    /// The pixel indices, ascending.
    pub fn pixels(&self) -> impl Iterator<Item = u32> + '_ {
        self.spans.iter().flat_map(|&[a, b]| a..b)
    }

    /// Number of pixels.
    pub fn area_px(&self) -> u32 {
        self.area_px
    }
}

use crate::camera::visibility::cell_is_covered;
pub use crate::camera::visibility::{COVERED_CELL_SHARE, FRAME_CELLS, FRAME_GRID};

/// The query: instances at a fixed resolution (built with [`Query::new`]).
#[derive(Debug, Clone, PartialEq)]
pub struct Query {
    /// Image width, pixels.
    pub width: u32,
    /// Image height, pixels.
    pub height: u32,
    /// The query's instances.
    pub instances: Vec<QueryInstance>,
    /// The union of the instances' pixels as runs (predicted instances may overlap).
    union: Vec<[u32; 2]>,
}

impl Query {
    /// A query from its instances (any overlap allowed).
    pub fn new(width: u32, height: u32, instances: Vec<QueryInstance>) -> Query {
        let mut spans: Vec<[u32; 2]> = instances.iter().flat_map(|i| i.spans().iter().copied()).collect();
        spans.sort_unstable();
        let mut union: Vec<[u32; 2]> = Vec::with_capacity(spans.len());
        for [a, b] in spans {
            match union.last_mut() {
                Some(last) if a <= last[1] => last[1] = last[1].max(b),
                _ => union.push([a, b]),
            }
        }
        Query { width, height, instances, union }
    }

    /// Builds a query from a label image (0 = background, j ≥ 1 = instance j − 1) and per-instance
    /// scores (`scores[j]` for label j + 1). Box areas are computed from the pixels.
    pub fn from_labels(width: u32, height: u32, labels: &[u32], scores: &[f64]) -> Query {
        let mut pixels: Vec<Vec<u32>> = vec![Vec::new(); scores.len()];
        for (i, &l) in labels.iter().enumerate() {
            if l > 0 && (l as usize) <= pixels.len() {
                pixels[l as usize - 1].push(i as u32);
            }
        }
        let instances = pixels
            .iter()
            .zip(scores)
            .filter(|(p, _)| !p.is_empty())
            .map(|(p, &s)| QueryInstance::new(p, s, bbox_area(p, width)))
            .collect();
        Query::new(width, height, instances)
    }

    /// How many of the frame's [`FRAME_CELLS`] cells ([`FRAME_GRID`] × [`FRAME_GRID`], split at
    /// integer pixel boundaries) hold at least [`COVERED_CELL_SHARE`] building pixels: the
    /// pixel-exact counterpart of the sampler's census ([`crate::camera::visibility::ViewCensus`]).
    /// Where the silhouettes crowd into a few cells, errors in the map move the optimum along the
    /// axis (see [`FRAME_GRID`]).
    pub fn covered_frame_cells(&self) -> u32 {
        let (w, h) = (self.width as usize, self.height as usize);
        if w == 0 || h == 0 {
            return 0;
        }
        let g = FRAME_GRID as usize;
        // Cell column of every x, and each cell's first x / y (cell c spans [c·w/g, (c+1)·w/g)).
        let col_of: Vec<usize> =
            (0..w).map(|x| (0..g).rev().find(|&c| x >= c * w / g).unwrap_or(0)).collect();
        let row_of = |y: usize| (0..g).rev().find(|&r| y >= r * h / g).unwrap_or(0);
        let mut covered = vec![0u64; g * g];
        for &[a, b] in &self.union {
            let (mut p, b) = (a as usize, b as usize);
            while p < b {
                let (y, x) = (p / w, p % w);
                let end = b.min((y + 1) * w);
                let cell_row = row_of(y);
                for x in x..x + (end - p) {
                    covered[cell_row * g + col_of[x]] += 1;
                }
                p = end;
            }
        }
        let size = |n: usize, i: usize| ((i + 1) * n / g - i * n / g) as u64;
        (0..g * g).filter(|&c| cell_is_covered(covered[c], size(w, c % g) * size(h, c / g))).count() as u32
    }

    /// All query instances merged into one (score = mean score) — the "merged" ablation's query.
    pub fn merged(&self) -> Query {
        let mut seen = vec![false; (self.width * self.height) as usize];
        let mut pixels = Vec::new();
        for inst in &self.instances {
            for p in inst.pixels() {
                if !seen[p as usize] {
                    seen[p as usize] = true;
                    pixels.push(p);
                }
            }
        }
        pixels.sort_unstable();
        if pixels.is_empty() {
            return Query::new(self.width, self.height, Vec::new());
        }
        let score = self.instances.iter().map(|i| i.score).sum::<f64>() / self.instances.len() as f64;
        let bbox_area_px = bbox_area(&pixels, self.width);
        Query::new(self.width, self.height, vec![QueryInstance::new(&pixels, score, bbox_area_px)])
    }
}

/// Bounding-box area (pixels) of a pixel-index list.
pub fn bbox_area(pixels: &[u32], width: u32) -> f64 {
    if pixels.is_empty() {
        return 0.0;
    }
    let (mut x0, mut y0, mut x1, mut y1) = (u32::MAX, u32::MAX, 0, 0);
    for &p in pixels {
        let (x, y) = (p % width, p / width);
        x0 = x0.min(x);
        x1 = x1.max(x);
        y0 = y0.min(y);
        y1 = y1.max(y);
    }
    ((x1 - x0 + 1) as f64) * ((y1 - y0 + 1) as f64)
}

/// Reusable buffers for scoring many hypotheses against one query.
#[derive(Debug, Default)]
pub struct Scorer {
    /// One query instance's row of the joint histogram (indexed by rendered ID), all zero between
    /// instances: only the IDs in `touched` are read and reset, so a score costs O(pixels), not
    /// O(instances × buildings).
    row: Vec<u32>,
    touched: Vec<u32>,
    render_area: Vec<u32>,
    /// The grouped cost's buffers ([`Scorer::grouped_instance_cost`]).
    groups: GroupBuffers,
    /// Per rendered building, the pixels [`Scorer::rim_tolerant_overlap`] counts ([`RimCounts`]).
    rims: Vec<RimCounts>,
    /// The buffers of [`Scorer::rim_tolerant_instance_cost`].
    instance_rims: InstanceRims,
}

/// Buffers of [`Scorer::grouped_instance_cost`]: per rendered building, the query instances lying
/// mostly inside it (all zero between calls: only the IDs in `claimed` are read and reset), and per
/// query instance its union Dice and the building it lies inside (0: none).
#[derive(Debug, Default)]
struct GroupBuffers {
    /// Σ |M_q^j ∩ M_hyp^k| over the query instances j inside building k.
    inside_px: Vec<u32>,
    /// Σ |M_q^j| over the query instances j inside building k.
    inside_area_px: Vec<u32>,
    /// How many query instances lie inside building k.
    inside_count: Vec<u32>,
    claimed: Vec<u32>,
    /// Per query instance: (union Dice, the building it lies inside or 0).
    per_instance: Vec<(f64, u32)>,
    /// One row's (|M_q^j ∩ M_hyp^k|, |M_hyp^k|) pairs, sorted by coverage.
    pairs: Vec<(u32, u32)>,
    /// One row's choices per building with the rims free ([`Scorer::rim_tolerant_grouped_instance_cost`]).
    choices: Vec<rims::Choices>,
}

/// Adds the length of every run of equal values in `ids` to `counts[value]`; values ≥ `counts.len()`
/// are not counted.
#[inline]
fn count_runs(ids: &[u32], counts: &mut [u32]) {
    for_each_run(ids, |value, run| {
        if let Some(c) = counts.get_mut(value as usize) {
            *c += run;
        }
    });
}

/// Calls `f(value, length)` for every run of equal values in `ids`, in order.
///
/// Rendered frames are long runs of one building or of background: blocks of [`BLOCK`] pixels that
/// all continue the current run are skipped with one branch-free (vectorised) comparison, so the
/// per-pixel branch, mispredicted at every run boundary, is taken only in blocks where a run ends.
#[inline]
fn for_each_run(ids: &[u32], mut f: impl FnMut(u32, u32)) {
    let Some(&first) = ids.first() else { return };
    let (mut cur, mut run) = (first, 0u32);
    let mut blocks = ids.chunks_exact(BLOCK);
    for block in &mut blocks {
        if block.iter().fold(true, |same, &r| same & (r == cur)) {
            run += BLOCK as u32;
            continue;
        }
        for &r in block {
            if r == cur {
                run += 1;
            } else {
                f(cur, run);
                (cur, run) = (r, 1);
            }
        }
    }
    for &r in blocks.remainder() {
        if r == cur {
            run += 1;
        } else {
            f(cur, run);
            (cur, run) = (r, 1);
        }
    }
    f(cur, run);
}

/// Pixels compared at once by [`for_each_run`].
const BLOCK: usize = 16;

/// The weight of a query instance under `weighting`.
fn weight_of(i: &QueryInstance, weighting: Weighting) -> f64 {
    match weighting {
        Weighting::Conf => i.score,
        Weighting::Area => i.bbox_area_px,
        Weighting::AreaConf => i.bbox_area_px * i.score,
    }
}

impl Scorer {
    /// Instance cost (higher is better, in [0, 1]) of a rendered dense-ID image with `k_max` instances.
    /// An empty query scores 0.
    pub fn instance_cost(&mut self, q: &Query, rendered: &[u32], k_max: u32, weighting: Weighting) -> f64 {
        debug_assert_eq!(rendered.len(), (q.width * q.height) as usize);
        let Some(total_w) = self.start(q, rendered, k_max, weighting) else { return 0.0 };
        let mut c = 0.0;
        for inst in &q.instances {
            self.fill_row(inst, rendered);
            let qa = inst.area_px() as f64;
            let mut best = 0.0f64;
            for &k in self.touched.iter() {
                let k = k as usize;
                let d = 2.0 * self.row[k] as f64 / (qa + self.render_area[k] as f64 + DICE_EPS);
                best = best.max(d);
                self.row[k] = 0;
            }
            c += weight_of(inst, weighting) / total_w * best;
        }
        c
    }

    /// The grouped instance cost (higher is better, in [0, 1]): like [`Scorer::instance_cost`], but
    /// each query instance j scores the larger of
    /// - its Dice with the union of the rendered instances that best explains it (a merged row of
    ///   houses against the houses rendered one by one): among all subsets S of the rendered instances,
    ///   2 Σ_S |M_q^j ∩ M_hyp^k| / (|M_q^j| + Σ_S |M_hyp^k| + ε) is largest on a prefix of them sorted by
    ///   the share |M_q^j ∩ M_hyp^k| / |M_hyp^k| (adding k raises the Dice d exactly when that share is
    ///   above d / 2), at least the best single match;
    /// - when more than half of its pixels lie on one rendered building k that holds at least one
    ///   other such query instance (the segmenter split k): [`SPLIT_FACTOR`] × the Dice of k with the
    ///   union of those instances.
    ///
    /// Still one pass over the query pixels: the rows of the joint histogram the paper's cost builds,
    /// and one sort of each row's (few) rendered IDs. An empty query scores 0.
    pub fn grouped_instance_cost(
        &mut self,
        q: &Query,
        rendered: &[u32],
        k_max: u32,
        weighting: Weighting,
    ) -> f64 {
        self.grouped(q, rendered, k_max, weighting, false)
    }

    /// [`Scorer::grouped_instance_cost`], its union Dice with the rims free when `rims`
    /// ([`Scorer::rim_tolerant_grouped_instance_cost`]).
    fn grouped(&mut self, q: &Query, rendered: &[u32], k_max: u32, weighting: Weighting, rims: bool) -> f64 {
        debug_assert_eq!(rendered.len(), (q.width * q.height) as usize);
        let Some(total_w) = self.start(q, rendered, k_max, weighting) else { return 0.0 };
        let (w, h) = (q.width as usize, q.height as usize);
        let k1 = self.render_area.len();
        if rims {
            self.instance_rims.classify(rendered, w, h, k1);
        }
        let g = &mut self.groups;
        for v in [&mut g.inside_px, &mut g.inside_area_px, &mut g.inside_count] {
            v.clear();
            v.resize(k1, 0);
        }
        g.claimed.clear();
        g.per_instance.clear();
        for inst in &q.instances {
            self.fill_row(inst, rendered);
            let qa = inst.area_px();
            // The building holding most of the instance as rendered (the first on ties).
            let inside = self.touched.iter().fold((0u32, 0u32), |best, &k| {
                let h = self.row[k as usize];
                if h > best.1 {
                    (k, h)
                } else {
                    best
                }
            });
            let best =
                if rims { self.rim_tolerant_union_dice(inst, rendered, w, h) } else { self.union_dice(qa) };
            let g = &mut self.groups;
            let (k, h) = inside;
            let k = if h as f64 > INSIDE_SHARE * qa as f64 {
                if g.inside_count[k as usize] == 0 {
                    g.claimed.push(k);
                }
                g.inside_px[k as usize] += h;
                g.inside_area_px[k as usize] += qa;
                g.inside_count[k as usize] += 1;
                k
            } else {
                0
            };
            g.per_instance.push((best, k));
        }
        let g = &mut self.groups;
        let mut c = 0.0;
        for (inst, &(union_dice, k)) in q.instances.iter().zip(&g.per_instance) {
            let k = k as usize;
            let d = if k != 0 && g.inside_count[k] > 1 {
                let split = 2.0 * g.inside_px[k] as f64
                    / (g.inside_area_px[k] as f64 + self.render_area[k] as f64 + DICE_EPS);
                union_dice.max(SPLIT_FACTOR * split.min(1.0))
            } else {
                union_dice
            };
            c += weight_of(inst, weighting) / total_w * d;
        }
        for &k in &g.claimed {
            let k = k as usize;
            (g.inside_px[k], g.inside_area_px[k], g.inside_count[k]) = (0, 0, 0);
        }
        c
    }

    /// The union Dice of a query instance of `query_px` pixels as rendered, from the row
    /// [`Scorer::fill_row`] filled for it (which it resets): the best union of rendered instances is a
    /// prefix of them sorted by the share of each the instance covers.
    fn union_dice(&mut self, query_px: u32) -> f64 {
        let g = &mut self.groups;
        g.pairs.clear();
        for &k in self.touched.iter() {
            let h = std::mem::take(&mut self.row[k as usize]);
            g.pairs.push((h, self.render_area[k as usize]));
        }
        // Descending coverage h / r, compared exactly as h_a · r_b against h_b · r_a.
        g.pairs.sort_unstable_by(|a, b| (b.0 as u64 * a.1 as u64).cmp(&(a.0 as u64 * b.1 as u64)));
        let (mut inter, mut union, mut best) = (0u64, query_px as u64, 0.0f64);
        for &(h, r) in &g.pairs {
            let d = 2.0 * (inter + h as u64) as f64 / ((union + r as u64) as f64 + DICE_EPS);
            if d <= best {
                break;
            }
            (inter, union, best) = (inter + h as u64, union + r as u64, d);
        }
        best
    }

    /// Counts the rendered instances' areas and clears the row for a cost pass over `q`; the total
    /// weight of the query's instances, or `None` when the query scores 0 (no instance, no weight).
    fn start(&mut self, q: &Query, rendered: &[u32], k_max: u32, weighting: Weighting) -> Option<f64> {
        let total_w: f64 = q.instances.iter().map(|i| weight_of(i, weighting)).sum();
        if q.instances.is_empty() || total_w <= 0.0 {
            return None;
        }
        let k1 = k_max as usize + 1;
        // IDs above k_max (should not happen) count as background.
        self.render_area.clear();
        self.render_area.resize(k1, 0);
        count_runs(rendered, &mut self.render_area);
        self.row.clear();
        self.row.resize(k1, 0);
        Some(total_w)
    }

    /// Fills the joint histogram's row of `inst`, sparse: `row[k]` for the rendered IDs it meets,
    /// listed in `touched` (the caller reads and resets them).
    fn fill_row(&mut self, inst: &QueryInstance, rendered: &[u32]) {
        let (row, touched) = (&mut self.row, &mut self.touched);
        let k1 = row.len();
        touched.clear();
        for &[a, b] in inst.spans() {
            for_each_run(&rendered[a as usize..b as usize], |k, run| {
                if k != 0 && (k as usize) < k1 {
                    if row[k as usize] == 0 {
                        touched.push(k);
                    }
                    row[k as usize] += run;
                }
            });
        }
    }

    /// Semantic IoU of the union of the query masks with the union of rendered buildings; 0 when both
    /// are empty.
    pub fn semantic_iou(&mut self, q: &Query, rendered: &[u32]) -> f64 {
        self.semantic_overlap(q, rendered, 1.0)
    }

    /// Overlap of the union Q of the query masks with the union R of the rendered buildings, with the
    /// rendered pixels outside Q weighted by `spill_weight` λ: |Q ∩ R| / (|Q| + λ·|R \ Q|), in [0, 1];
    /// 0 when the denominator is. λ = 1 is the IoU; λ < 1 counts a render larger than the query less
    /// than one that leaves query pixels uncovered (the same render at the exact outline scores 1
    /// either way).
    pub fn semantic_overlap(&mut self, q: &Query, rendered: &[u32], spill_weight: f64) -> f64 {
        let covered = |ids: &[u32]| ids.iter().map(|&r| (r != 0) as u64).sum::<u64>();
        let (mut query_px, mut inter) = (0u64, 0u64);
        for &[a, b] in &q.union {
            query_px += (b - a) as u64;
            inter += covered(&rendered[a as usize..b as usize]);
        }
        let denominator = query_px as f64 + spill_weight * (covered(rendered) - inter) as f64;
        if denominator <= 0.0 {
            0.0
        } else {
            inter as f64 / denominator
        }
    }

    /// The semantic term of `blend`: [`Scorer::semantic_overlap`] with its spill weight, with the
    /// rims free ([`Scorer::rim_tolerant_overlap`]) when it says so.
    fn union_term(&mut self, q: &Query, rendered: &[u32], k_max: u32, blend: Blend) -> f64 {
        if blend.rim_tolerance {
            self.rim_tolerant_overlap(q, rendered, k_max, blend.spill_weight)
        } else {
            self.semantic_overlap(q, rendered, blend.spill_weight)
        }
    }

    /// The blended instance cost (1 − w)·instance + w·semantic, in [0, 1], with w and the semantic
    /// term's spill weight and rim tolerance from `blend` ([`Scorer::semantic_overlap`]); w = 0 is the
    /// pure instance cost (and skips the semantic pass; without the rim tolerance, the paper's), 1 the
    /// semantic term alone (and skips the instance pass).
    pub fn blended_cost(
        &mut self,
        q: &Query,
        rendered: &[u32],
        k_max: u32,
        weighting: Weighting,
        blend: Blend,
    ) -> f64 {
        self.blended(false, q, rendered, k_max, weighting, blend)
    }

    /// [`Scorer::blended_cost`] with the instance term of [`Scorer::grouped_instance_cost`] when
    /// `grouped`, else of [`Scorer::instance_cost`] ([`Scorer::rim_tolerant_instance_cost`] with the
    /// rim tolerance).
    fn blended(
        &mut self,
        grouped: bool,
        q: &Query,
        rendered: &[u32],
        k_max: u32,
        weighting: Weighting,
        blend: Blend,
    ) -> f64 {
        let w = blend.semantic_weight;
        if w == 1.0 {
            // The union's outline alone (the polish's second pass by default): no instance pass.
            return self.union_term(q, rendered, k_max, blend);
        }
        let instance = if grouped {
            self.grouped(q, rendered, k_max, weighting, blend.rim_tolerance)
        } else if blend.rim_tolerance {
            self.rim_tolerant_instance_cost(q, rendered, k_max, weighting)
        } else {
            self.instance_cost(q, rendered, k_max, weighting)
        };
        if w == 0.0 {
            return instance;
        }
        (1.0 - w) * instance + w * self.union_term(q, rendered, k_max, blend)
    }

    /// The cost of `kind` (the merged ablation expects `q` already merged with [`Query::merged`]).
    /// `blend` applies to [`CostKind::Instance`] ([`Scorer::blended_cost`]) and [`CostKind::Grouped`]
    /// (the same blend around [`Scorer::grouped_instance_cost`]) and its spill weight to
    /// [`CostKind::Semantic`] (1, the IoU, but in the polish); the merged ablation stays the paper's.
    pub fn cost(
        &mut self,
        kind: CostKind,
        q: &Query,
        rendered: &[u32],
        k_max: u32,
        weighting: Weighting,
        blend: Blend,
    ) -> f64 {
        match kind {
            CostKind::Instance => self.blended(false, q, rendered, k_max, weighting, blend),
            CostKind::Grouped => self.blended(true, q, rendered, k_max, weighting, blend),
            CostKind::Merged => self.instance_cost(q, rendered, k_max, weighting),
            CostKind::Semantic => self.union_term(q, rendered, k_max, blend),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    // A 4×2 image; query instances: A = pixels {0, 1} (score 0.9), B = pixels {6, 7} (score 0.1).
    fn query() -> Query {
        let labels = [1, 1, 0, 0, 0, 0, 2, 2];
        Query::from_labels(4, 2, &labels, &[0.9, 0.1])
    }

    #[test]
    fn perfect_render_scores_one() {
        let q = query();
        let r = [1, 1, 0, 0, 0, 0, 2, 2];
        let mut s = Scorer::default();
        for w in [Weighting::Conf, Weighting::Area] {
            let c = s.instance_cost(&q, &r, 2, w);
            // d = 2·2 / (2 + 2 + ε) for both instances.
            assert!((c - 4.0 / (4.0 + DICE_EPS)).abs() < 1e-12, "{c}");
        }
        assert_eq!(s.semantic_iou(&q, &r), 1.0);
    }

    #[test]
    fn hand_computed_partial_overlap() {
        let q = query();
        // Rendered building 1 covers pixels 1, 2 (overlaps A in 1 pixel); building 2 covers 5, 6, 7.
        let r = [0, 1, 1, 0, 0, 2, 2, 2];
        let mut s = Scorer::default();
        let d_a = 2.0 * 1.0 / (2.0 + 2.0 + DICE_EPS);
        let d_b = 2.0 * 2.0 / (2.0 + 3.0 + DICE_EPS);
        let conf = s.instance_cost(&q, &r, 2, Weighting::Conf);
        assert!((conf - (0.9 * d_a + 0.1 * d_b)).abs() < 1e-12, "{conf}");
        // Box areas: A = 2×1, B = 2×1 → equal weights.
        let area = s.instance_cost(&q, &r, 2, Weighting::Area);
        assert!((area - 0.5 * (d_a + d_b)).abs() < 1e-12, "{area}");
        // Union of query {0,1,6,7}, rendered {1,2,5,6,7}: ∩ = {1,6,7} = 3, ∪ = {0,1,2,5,6,7} = 6.
        assert!((s.semantic_iou(&q, &r) - 0.5).abs() < 1e-12);
    }

    #[test]
    fn area_conf_weights_by_box_area_times_score() {
        // Two instances, one matched exactly (Dice 1), one not at all: the cost is the first's share of
        // the weights, area × score under area-conf.
        let w = 4u32;
        let a = QueryInstance::new(&[0, 1, 4, 5], 0.5, 4.0);
        let b = QueryInstance::new(&[2, 3], 0.9, 2.0);
        let q = Query::new(w, 2, vec![a, b]);
        let r = [1, 1, 0, 0, 1, 1, 0, 0];
        let mut s = Scorer::default();
        let cost = |s: &mut Scorer, wt| s.instance_cost(&q, &r, 1, wt);
        assert!((cost(&mut s, Weighting::Area) - 4.0 / 6.0).abs() < 1e-6);
        assert!((cost(&mut s, Weighting::Conf) - 0.5 / 1.4).abs() < 1e-6);
        assert!((cost(&mut s, Weighting::AreaConf) - 2.0 / (2.0 + 1.8)).abs() < 1e-6);
        // Scores all 1: area × conf is the area weighting.
        let ones =
            Query::new(w, 2, q.instances.iter().map(|i| QueryInstance { score: 1.0, ..i.clone() }).collect());
        assert_eq!(
            s.instance_cost(&ones, &r, 1, Weighting::AreaConf),
            s.instance_cost(&ones, &r, 1, Weighting::Area)
        );
        assert_eq!(Weighting::AreaConf.label(), "area × conf");
        assert_eq!(serde_json::to_string(&Weighting::AreaConf).unwrap(), "\"area-conf\"");
    }

    #[test]
    fn best_match_takes_the_maximum() {
        // Query instance covers pixels 0..4; building 1 covers 0..1, building 2 covers 0..4 exactly.
        let q = Query::from_labels(4, 1, &[1, 1, 1, 1], &[1.0]);
        let r = [1, 2, 2, 2];
        let mut s = Scorer::default();
        let d1 = 2.0 * 1.0 / (4.0 + 1.0 + DICE_EPS);
        let d2 = 2.0 * 3.0 / (4.0 + 3.0 + DICE_EPS);
        assert!((s.instance_cost(&q, &r, 2, Weighting::Conf) - d1.max(d2)).abs() < 1e-12);
    }

    #[test]
    fn empty_cases() {
        let mut s = Scorer::default();
        let empty = Query::from_labels(2, 2, &[0; 4], &[]);
        assert_eq!(s.instance_cost(&empty, &[1, 1, 0, 0], 1, Weighting::Conf), 0.0);
        assert_eq!(s.semantic_iou(&empty, &[0; 4]), 0.0);
        // No building rendered: every instance scores 0.
        let q = Query::from_labels(2, 2, &[1, 0, 0, 0], &[0.5]);
        assert_eq!(s.instance_cost(&q, &[0; 4], 0, Weighting::Area), 0.0);
    }

    #[test]
    fn semantic_iou_counts_overlapping_predictions_once() {
        // Two predictions overlapping in pixels 2 and 3 of a 6×1 image: union {1, 2, 3, 4}.
        let q = Query::new(
            6,
            1,
            vec![QueryInstance::new(&[1, 2, 3], 0.9, 3.0), QueryInstance::new(&[2, 3, 4], 0.8, 3.0)],
        );
        let mut s = Scorer::default();
        // Rendered {3, 4, 5}: ∩ = {3, 4} = 2, ∪ = {1, …, 5} = 5.
        assert!((s.semantic_iou(&q, &[0, 0, 0, 1, 1, 1]) - 0.4).abs() < 1e-12);
    }

    #[test]
    fn runs_are_counted_per_value() {
        let mut counts = vec![0u32; 3];
        // Runs 0×2, 2×3, 1×1, 7×2 (out of range: not counted), 2×1.
        count_runs(&[0, 0, 2, 2, 2, 1, 7, 7, 2], &mut counts);
        assert_eq!(counts, vec![2, 1, 4]);
        count_runs(&[], &mut counts);
        assert_eq!(counts, vec![2, 1, 4]);
    }

    #[test]
    fn runs_are_found_across_and_within_blocks() {
        // Against the plain definition, on runs shorter and longer than a block.
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
        for _ in 0..200 {
            let mut ids = Vec::new();
            while ids.len() < rng.gen_range(0..300) {
                let (v, n) = (rng.gen_range(0..4u32), rng.gen_range(1..40));
                ids.extend(std::iter::repeat_n(v, n));
            }
            let mut runs = Vec::new();
            for_each_run(&ids, |v, n| runs.push((v, n)));
            let mut expected: Vec<(u32, u32)> = Vec::new();
            for &v in &ids {
                match expected.last_mut() {
                    Some((last, n)) if *last == v => *n += 1,
                    _ => expected.push((v, 1)),
                }
            }
            assert_eq!(runs, expected);
        }
    }

    #[test]
    fn merged_query_is_the_union() {
        let q = query().merged();
        assert_eq!(q.instances.len(), 1);
        assert_eq!(q.instances[0].pixels().collect::<Vec<_>>(), vec![0, 1, 6, 7]);
        assert_eq!(q.instances[0].spans(), &[[0, 2], [6, 8]]);
        assert_eq!(q.instances[0].bbox_area_px, 8.0);
    }

    #[test]
    fn covered_frame_cells_count_the_cells_holding_buildings() {
        // 8 × 8 frame: cells of 2 × 2 pixels. One pixel of a cell is 25 % of it (covered); the
        // union counts overlapping instances once.
        let (w, h) = (8u32, 8u32);
        let mut labels = vec![0u32; 64];
        // Instance 1: the whole top row of cells (y 0..2), a run crossing cell columns.
        for p in labels.iter_mut().take(16) {
            *p = 1;
        }
        // Instance 2: one pixel in the bottom-right cell, and one in the cell left of it.
        labels[63] = 2;
        labels[7 * 8 + 4] = 2;
        let q = Query::from_labels(w, h, &labels, &[1.0, 1.0]);
        assert_eq!(q.covered_frame_cells(), 4 + 2);
        assert_eq!(Query::from_labels(w, h, &[0; 64], &[]).covered_frame_cells(), 0);
        assert_eq!(Query::from_labels(w, h, &[1; 64], &[1.0]).covered_frame_cells(), FRAME_CELLS);
        // A run wrapping from the end of one row to the start of the next lands in both rows' cells.
        let mut wrap = vec![0u32; 64];
        wrap[8 + 7] = 1;
        wrap[16] = 1;
        assert_eq!(Query::from_labels(w, h, &wrap, &[1.0]).covered_frame_cells(), 2);
        // Below the share: one pixel of a 10 × 10 cell (1 %) does not count.
        let mut sparse = vec![0u32; 40 * 40];
        sparse[0] = 1;
        assert_eq!(Query::from_labels(40, 40, &sparse, &[1.0]).covered_frame_cells(), 0);
    }

    #[test]
    fn instance_cost_separates_what_semantic_cannot() {
        // Two adjacent buildings; the query sees them as two instances. A hypothesis that renders one
        // building over both has the same semantic IoU but a lower instance cost.
        let q = Query::from_labels(4, 1, &[1, 1, 2, 2], &[1.0, 1.0]);
        let right = [1, 1, 2, 2];
        let merged = [1, 1, 1, 1];
        let mut s = Scorer::default();
        assert_eq!(s.semantic_iou(&q, &right), s.semantic_iou(&q, &merged));
        assert!(
            s.instance_cost(&q, &right, 2, Weighting::Conf)
                > s.instance_cost(&q, &merged, 1, Weighting::Conf) + 0.2
        );
    }

    mod grouped {
        use super::*;
        use rand::{Rng, SeedableRng};

        /// The definition, naïvely: per query instance the best Dice over every subset of the rendered
        /// instances, or SPLIT_FACTOR × the Dice of the building it lies inside with all the query
        /// instances inside it when there are several; weighted by box area.
        fn reference(q: &Query, r: &[u32], k_max: u32) -> f64 {
            let k1 = k_max as usize + 1;
            let area_r: Vec<u64> =
                (0..k1).map(|k| r.iter().filter(|&&v| v as usize == k).count() as u64).collect();
            let hist: Vec<Vec<u64>> = q
                .instances
                .iter()
                .map(|i| {
                    (0..k1)
                        .map(|k| i.pixels().filter(|&p| r[p as usize] as usize == k).count() as u64)
                        .collect()
                })
                .collect();
            let inside: Vec<Option<usize>> = q
                .instances
                .iter()
                .zip(&hist)
                .map(|(i, h)| (1..k1).find(|&k| h[k] as f64 > 0.5 * i.area_px() as f64))
                .collect();
            let total: f64 = q.instances.iter().map(|i| i.bbox_area_px).sum();
            let mut c = 0.0;
            for (j, inst) in q.instances.iter().enumerate() {
                let qa = inst.area_px() as u64;
                let mut best = 0.0f64;
                for set in 1u32..(1 << (k1 - 1)) {
                    let ks = (1..k1).filter(|k| set & (1 << (k - 1)) != 0);
                    let (i, u) = ks.fold((0, qa), |(i, u), k| (i + hist[j][k], u + area_r[k]));
                    if i > 0 {
                        best = best.max(2.0 * i as f64 / (u as f64 + DICE_EPS));
                    }
                }
                if let Some(k) = inside[j] {
                    let group: Vec<usize> =
                        (0..q.instances.len()).filter(|&i| inside[i] == Some(k)).collect();
                    if group.len() > 1 {
                        let i: u64 = group.iter().map(|&i| hist[i][k]).sum();
                        let a: u64 = group.iter().map(|&i| q.instances[i].area_px() as u64).sum();
                        let split = (2.0 * i as f64 / ((a + area_r[k]) as f64 + DICE_EPS)).min(1.0);
                        best = best.max(SPLIT_FACTOR * split);
                    }
                }
                c += inst.bbox_area_px / total * best;
            }
            c
        }

        #[test]
        fn equals_the_definition_on_random_frames() {
            let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(40);
            let mut s = Scorer::default();
            for _ in 0..300 {
                let (w, h) = (7u32, 5u32);
                let n = rng.gen_range(0..5usize);
                let k_max = rng.gen_range(0..6u32);
                let labels: Vec<u32> = (0..w * h).map(|_| rng.gen_range(0..=n as u32)).collect();
                let q = Query::from_labels(w, h, &labels, &vec![1.0; n]);
                let r: Vec<u32> = (0..w * h).map(|_| rng.gen_range(0..=k_max)).collect();
                let got = s.grouped_instance_cost(&q, &r, k_max, Weighting::Area);
                let want = reference(&q, &r, k_max);
                assert!((got - want).abs() < 1e-9, "{got} vs {want}: {labels:?} / {r:?}");
                // Never below the paper's best match.
                assert!(got >= s.instance_cost(&q, &r, k_max, Weighting::Area) - 1e-12);
            }
        }

        #[test]
        fn one_to_one_frames_score_as_the_paper_cost() {
            let q = query();
            let mut s = Scorer::default();
            for r in [[1, 1, 0, 0, 0, 0, 2, 2], [0, 1, 0, 0, 0, 0, 2, 2], [0; 8]] {
                assert_eq!(
                    s.grouped_instance_cost(&q, &r, 2, Weighting::Area),
                    s.instance_cost(&q, &r, 2, Weighting::Area)
                );
            }
            let empty = Query::from_labels(2, 2, &[0; 4], &[]);
            assert_eq!(s.grouped_instance_cost(&empty, &[1, 1, 0, 0], 1, Weighting::Area), 0.0);
        }

        #[test]
        fn a_merged_row_prefers_the_true_pose_where_the_paper_cost_prefers_a_shifted_one() {
            // A 12 × 2 frame. The segmenter merged a row of three touching houses into one instance
            // (x 0..9, both rows). At the true pose the map renders the three houses (3 px wide each);
            // at a pose shifted sideways, one larger building behind them (x 2..11) fills most of the
            // row. Paper: truth d = 2·6 / (18 + 6) = 0.5, shifted d = 2·14 / (18 + 18) = 0.78, so it
            // prefers the shifted pose; grouped: truth 1 (the union of the three), shifted 0.78.
            let row = |f: &dyn Fn(usize) -> u32| -> Vec<u32> { (0..24).map(|p| f(p % 12)).collect() };
            let q = Query::from_labels(12, 2, &row(&|x| (x < 9) as u32), &[1.0]);
            let truth = row(&|x| if x < 9 { x as u32 / 3 + 1 } else { 0 });
            let shifted = row(&|x| if (2..11).contains(&x) { 4 } else { 0 });
            let mut s = Scorer::default();
            let paper = |s: &mut Scorer, r: &[u32]| s.instance_cost(&q, r, 4, Weighting::Area);
            let grouped = |s: &mut Scorer, r: &[u32]| s.grouped_instance_cost(&q, r, 4, Weighting::Area);
            assert!((paper(&mut s, &truth) - 0.5).abs() < 1e-6);
            assert!((paper(&mut s, &shifted) - 28.0 / 36.0).abs() < 1e-6);
            assert!((grouped(&mut s, &truth) - 1.0).abs() < 1e-6);
            assert!((grouped(&mut s, &shifted) - 28.0 / 36.0).abs() < 1e-6);
            let paper_margin = paper(&mut s, &truth) - paper(&mut s, &shifted);
            let grouped_margin = grouped(&mut s, &truth) - grouped(&mut s, &shifted);
            assert!(paper_margin < 0.0 && grouped_margin > 0.2, "{paper_margin} {grouped_margin}");
            // The blend keeps the order (the semantic term is the same for both costs).
            let b = Blend::semantic(DEFAULT_SEMANTIC_WEIGHT);
            let blended = |s: &mut Scorer, r: &[u32]| s.cost(CostKind::Grouped, &q, r, 4, Weighting::Area, b);
            assert!(blended(&mut s, &truth) > blended(&mut s, &shifted));
        }

        #[test]
        fn a_split_building_scores_its_pieces_together_with_a_mild_penalty() {
            // The segmenter cut one building (x 0..6) in two instances (0..3 and 3..6). Rendered as
            // that building: each piece alone has Dice 2·3 / (3 + 6) = 0.67, together 1, × SPLIT_FACTOR.
            // A render with two buildings exactly at the pieces still scores higher (1).
            let q = Query::from_labels(6, 1, &[1, 1, 1, 2, 2, 2], &[1.0, 1.0]);
            let one = [1, 1, 1, 1, 1, 1];
            let two = [1, 1, 1, 2, 2, 2];
            let mut s = Scorer::default();
            assert!((s.instance_cost(&q, &one, 1, Weighting::Area) - 6.0 / 9.0).abs() < 1e-6);
            assert!((s.grouped_instance_cost(&q, &one, 1, Weighting::Area) - SPLIT_FACTOR).abs() < 1e-6);
            assert!((s.grouped_instance_cost(&q, &two, 2, Weighting::Area) - 1.0).abs() < 1e-6);
            // A single piece inside a building is no split: the paper's Dice.
            let lone = Query::from_labels(6, 1, &[1, 1, 1, 0, 0, 0], &[1.0]);
            assert!((s.grouped_instance_cost(&lone, &one, 1, Weighting::Area) - 6.0 / 9.0).abs() < 1e-6);
            // Buffers are reset between calls: the same frame scores the same twice.
            let again = s.grouped_instance_cost(&q, &one, 1, Weighting::Area);
            assert!((again - SPLIT_FACTOR).abs() < 1e-6);
        }
    }

    mod blended {
        use super::*;

        // A 6×1 strip seen by the query as two buildings, A = pixels 0..3 and B = 3..6. `SHIFTED`
        // renders the same union (semantic IoU 1) with the boundary between them one pixel to the
        // right (A = 0..4, B = 4..6), as a taller front block hiding more of the one behind does.
        fn query() -> Query {
            Query::from_labels(6, 1, &[1, 1, 1, 2, 2, 2], &[1.0, 1.0])
        }
        const SHIFTED: [u32; 6] = [1, 1, 1, 1, 2, 2];

        #[test]
        fn zero_weight_is_the_pure_instance_cost() {
            let q = query();
            let mut s = Scorer::default();
            for r in [SHIFTED, [1, 2, 2, 2, 2, 2], [0, 1, 1, 1, 2, 2]] {
                let pure = s.instance_cost(&q, &r, 2, Weighting::Area);
                assert_eq!(s.blended_cost(&q, &r, 2, Weighting::Area, Blend::semantic(0.0)), pure);
                assert_eq!(
                    s.cost(CostKind::Instance, &q, &r, 2, Weighting::Area, Blend::semantic(0.0)),
                    pure
                );
            }
        }

        #[test]
        fn hand_computed_blend() {
            let q = query();
            let mut s = Scorer::default();
            // Shifted boundary: A meets building 1 (4 px) in 3 → d = 6/7; B meets building 2 (2 px) in
            // 2 → d = 4/5; equal box areas (3×1). Semantic IoU = 1 (same union).
            let instance = 0.5 * (6.0 / (7.0 + DICE_EPS) + 4.0 / (5.0 + DICE_EPS));
            assert_eq!(s.semantic_iou(&q, &SHIFTED), 1.0);
            let blended = s.blended_cost(&q, &SHIFTED, 2, Weighting::Area, Blend::semantic(0.5));
            assert!((blended - (0.5 * instance + 0.5)).abs() < 1e-12, "{blended}");
            // The ends: the pure instance cost and the semantic IoU alone.
            assert_eq!(
                s.blended_cost(&q, &SHIFTED, 2, Weighting::Area, Blend::semantic(0.0)),
                s.instance_cost(&q, &SHIFTED, 2, Weighting::Area)
            );
            assert_eq!(s.blended_cost(&q, &SHIFTED, 2, Weighting::Area, Blend::semantic(1.0)), 1.0);
        }

        #[test]
        fn a_shifted_boundary_with_the_same_union_loses_half_as_much_under_the_blend() {
            // The loss (1 − cost) of the shifted boundary halves with w = 0.5: only the instance term
            // sees it.
            let q = query();
            let mut s = Scorer::default();
            let pure = s.instance_cost(&q, &SHIFTED, 2, Weighting::Area);
            let blended = s.blended_cost(&q, &SHIFTED, 2, Weighting::Area, Blend::semantic(0.5));
            assert!(pure < 0.84, "{pure}");
            assert!(((1.0 - blended) - 0.5 * (1.0 - pure)).abs() < 1e-12, "{pure} {blended}");
        }

        #[test]
        fn the_true_outline_wins_over_better_matched_boundaries() {
            // The ground truth against an LoD1 map: A's block is taller and hides all of B but its last
            // pixel (A = 0..5, B = 5..6): d_A = 6/8, d_B = 2/4, instance 0.625, semantic IoU 1.
            // A wrong pose one pixel to the side (0 | A = 1..4 | B = 4..6) matches the boundary better:
            // d_A = 4/6, d_B = 4/5, instance 0.7333, semantic IoU 5/6. The pure instance cost prefers
            // the wrong pose (the optimum moves, issue 15); blended with w = 0.5 the ground truth
            // scores 0.8125 and the wrong pose 0.7833 (hand computation).
            let q = query();
            let mut s = Scorer::default();
            let truth = [1, 1, 1, 1, 1, 2];
            let wrong = [0, 1, 1, 1, 2, 2];
            let pure = |s: &mut Scorer, r: &[u32]| s.instance_cost(&q, r, 2, Weighting::Area);
            let blend =
                |s: &mut Scorer, r: &[u32]| s.blended_cost(&q, r, 2, Weighting::Area, Blend::semantic(0.5));
            assert!((pure(&mut s, &truth) - 0.625).abs() < 1e-6);
            assert!((pure(&mut s, &wrong) - 0.5 * (4.0 / 6.0 + 0.8)).abs() < 1e-6);
            assert!(pure(&mut s, &wrong) > pure(&mut s, &truth) + 0.1);
            assert!((blend(&mut s, &truth) - 0.8125).abs() < 1e-6);
            assert!(blend(&mut s, &truth) > blend(&mut s, &wrong) + 0.025);
        }

        #[test]
        fn spill_weight_counts_a_larger_render_less_than_a_smaller_one() {
            // Query union 3 px (A = 0..3). A render one pixel larger (0..4) and one pixel smaller
            // (0..2): the IoU ranks them 3/4 and 2/3; with λ = 0.3 the larger scores 3/3.3, the smaller
            // still 2/3; the exact outline scores 1 for every λ. Semantic-only blends use it, w = 0
            // does not.
            let q = Query::from_labels(6, 1, &[1, 1, 1, 0, 0, 0], &[1.0]);
            let (larger, smaller, exact) = ([1, 1, 1, 1, 0, 0], [1, 1, 0, 0, 0, 0], [1, 1, 1, 0, 0, 0]);
            let mut s = Scorer::default();
            assert!((s.semantic_overlap(&q, &larger, 1.0) - 0.75).abs() < 1e-12);
            assert_eq!(s.semantic_overlap(&q, &larger, 1.0), s.semantic_iou(&q, &larger));
            assert!((s.semantic_overlap(&q, &larger, 0.3) - 3.0 / 3.3).abs() < 1e-12);
            for lambda in [1.0, 0.3, 0.0] {
                assert!((s.semantic_overlap(&q, &smaller, lambda) - 2.0 / 3.0).abs() < 1e-12);
                assert_eq!(s.semantic_overlap(&q, &exact, lambda), 1.0);
            }
            let tversky = Blend { semantic_weight: 1.0, spill_weight: 0.3, rim_tolerance: false };
            assert_eq!(
                s.blended_cost(&q, &larger, 1, Weighting::Area, tversky),
                s.semantic_overlap(&q, &larger, 0.3)
            );
            assert_eq!(s.cost(CostKind::Semantic, &q, &larger, 1, Weighting::Area, tversky), 3.0 / 3.3);
            let pure = Blend { semantic_weight: 0.0, spill_weight: 0.3, rim_tolerance: false };
            assert_eq!(
                s.blended_cost(&q, &larger, 1, Weighting::Area, pure),
                s.instance_cost(&q, &larger, 1, Weighting::Area)
            );
            // Nothing rendered and nothing queried: 0.
            assert_eq!(s.semantic_overlap(&Query::new(6, 1, Vec::new()), &[0; 6], 0.3), 0.0);
        }

        #[test]
        fn merged_and_semantic_ignore_the_weight() {
            let q = query();
            let mut s = Scorer::default();
            let m = q.merged();
            let r = [0, 1, 1, 1, 1, 0];
            assert_eq!(
                s.cost(CostKind::Merged, &m, &r, 1, Weighting::Area, Blend::semantic(0.5)),
                s.instance_cost(&m, &r, 1, Weighting::Area)
            );
            assert_eq!(
                s.cost(CostKind::Semantic, &q, &r, 1, Weighting::Area, Blend::semantic(0.5)),
                s.semantic_iou(&q, &r)
            );
        }
    }
}
