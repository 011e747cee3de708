//! Localization metrics: translation and rotation errors, recall at thresholds, medians, and the
//! paper-style summary table.
//!
//! Translation error = distance between camera centres (m); rotation error = arccos((tr(R_gtᵀ R) − 1)/2)
//! in degrees (../shared/SPEC.md). A query counts at (t m, r°) when both errors are strictly below.

use serde::{Deserialize, Serialize};

/// The paper's thresholds: (2 m, 2°), (3 m, 3°), (5 m, 5°).
pub const THRESHOLDS: [(f64, f64); 3] = [(2.0, 2.0), (3.0, 3.0), (5.0, 5.0)];

/// Whether a pose error is within the tightest threshold, (2 m, 2°) (strictly: the paper's recall).
pub fn within_2m_2deg(translation_m: f64, rotation_deg: f64) -> bool {
    let (t, r) = THRESHOLDS[0];
    translation_m < t && rotation_deg < r
}

/// The median of `values` ([`crate::util::median`]), NaN when there are none: an empty group shows as
/// NaN in the tables and as `null` in JSON.
pub fn median_or_nan(values: &[f64]) -> f64 {
    crate::util::median(values).unwrap_or(f64::NAN)
}

/// NaN: the serde default of a median a summary written before it was reported lacks.
fn nan() -> f64 {
    f64::NAN
}

/// One row of the summary table.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Row {
    /// The method (`prior` or the cost), as named in the table.
    pub method: String,
    /// Query group: `grid`, `sequence`, `query` or `all`.
    pub group: String,
    /// Queries in the row.
    pub queries: usize,
    /// Recall (percent) at each of [`THRESHOLDS`].
    pub recall_pct: [f64; 3],
    /// Median translation error, metres (NaN/null without queries).
    pub median_translation_m: f64,
    /// Median rotation error, degrees (NaN/null without queries).
    pub median_rotation_deg: f64,
}

/// Builds a row from (translation m, rotation °) errors.
pub fn row(method: &str, group: &str, errors: &[(f64, f64)]) -> Row {
    let n = errors.len();
    let recall = |t: f64, r: f64| {
        if n == 0 {
            f64::NAN
        } else {
            100.0 * errors.iter().filter(|e| e.0 < t && e.1 < r).count() as f64 / n as f64
        }
    };
    Row {
        method: method.to_string(),
        group: group.to_string(),
        queries: n,
        recall_pct: THRESHOLDS.map(|(t, r)| recall(t, r)),
        median_translation_m: median_or_nan(&errors.iter().map(|e| e.0).collect::<Vec<_>>()),
        median_rotation_deg: median_or_nan(&errors.iter().map(|e| e.1).collect::<Vec<_>>()),
    }
}

/// Query-instance-count buckets: inclusive lower bounds (the last is open).
pub const INSTANCE_BUCKETS: Buckets = Buckets { lower: &[0, 1, 2, 4, 8, 16], top: None };

/// Buckets of the frame's cells holding buildings ([`crate::loc::cost::Query::covered_frame_cells`],
/// of [`crate::loc::cost::FRAME_CELLS`]): inclusive lower bounds up to all cells.
pub const COVERAGE_BUCKETS: Buckets =
    Buckets { lower: &[0, 5, 9, 13], top: Some(crate::loc::cost::FRAME_CELLS) };

/// Buckets of a per-query count: inclusive lower bounds, ascending from 0, and the largest count the
/// last bucket holds (`None`: open).
#[derive(Debug, Clone, Copy)]
pub struct Buckets {
    /// Inclusive lower bounds of the buckets, ascending from 0.
    pub lower: &'static [u32],
    /// The largest count the last bucket holds (`None`: open).
    pub top: Option<u32>,
}

impl Buckets {
    /// The label of bucket `i`, e.g. `1`, `2–3`, `16+` or `13–16`.
    fn label(&self, i: usize) -> String {
        let lo = self.lower[i];
        match (self.lower.get(i + 1), self.top) {
            (None, None) => format!("{lo}+"),
            (None, Some(top)) if top == lo => format!("{lo}"),
            (None, Some(top)) => format!("{lo}–{top}"),
            (Some(&next), _) if next == lo + 1 => format!("{lo}"),
            (Some(&next), _) => format!("{lo}–{}", next - 1),
        }
    }
}

/// Recall per bucket of a per-query count (instances, covered frame cells), for one method: where
/// silhouettes stop being enough.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct BucketRow {
    /// The method (`prior` or the cost), as named in the table.
    pub method: String,
    /// The bucket's counts, e.g. `2–3` or `16+`.
    #[serde(alias = "instances")]
    pub bucket: String,
    /// Queries in the row.
    pub queries: usize,
    /// Recall (percent) at (2 m, 2°); NaN (null) for an empty bucket.
    pub recall_2m_2deg_pct: f64,
}

/// One row per bucket of `buckets` from (count, translation m, rotation °): every query falls in
/// exactly one bucket, so the rows' counts add up to `errors.len()`.
pub fn bucket_rows(method: &str, buckets: Buckets, errors: &[(usize, f64, f64)]) -> Vec<BucketRow> {
    (0..buckets.lower.len())
        .map(|i| {
            let lo = buckets.lower[i] as usize;
            let hi = buckets.lower.get(i + 1).map_or(usize::MAX, |&h| h as usize);
            let inside: Vec<&(usize, f64, f64)> = errors.iter().filter(|e| e.0 >= lo && e.0 < hi).collect();
            let ok = inside.iter().filter(|e| within_2m_2deg(e.1, e.2)).count();
            BucketRow {
                method: method.to_string(),
                bucket: buckets.label(i),
                queries: inside.len(),
                recall_2m_2deg_pct: if inside.is_empty() {
                    f64::NAN
                } else {
                    100.0 * ok as f64 / inside.len() as f64
                },
            }
        })
        .collect()
}

/// Where one method's translation errors lie: along the camera's axis or across it, and whether its
/// failures are the search's or the cost's.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct AxisRow {
    /// The method (`prior` or the cost), as named in the table.
    pub method: String,
    /// Queries in the row.
    pub queries: usize,
    /// Median |error along the ground truth's viewing direction|, metres (NaN/null without queries).
    pub median_abs_axial_m: f64,
    /// Median signed error along it, metres: positive when the estimate lies ahead of the truth
    /// (towards the scene, so the map renders larger). Near 0 when the errors along the axis are
    /// unbiased, as with oracle masks; far from 0, with most estimates on one side
    /// ([`AxisRow::estimates_ahead`]), when the masks are systematically larger or smaller than the
    /// map renders the buildings (a segmenter that bleeds past the roofs' edges, a map whose blocks
    /// stand taller than the buildings). Absent (NaN) in summaries written before it was reported.
    #[serde(default = "nan")]
    pub median_axial_m: f64,
    /// Estimates ahead of the truth along its viewing direction (signed axial error > 0).
    #[serde(default)]
    pub estimates_ahead: usize,
    /// Median error across it, metres.
    pub median_lateral_m: f64,
    /// Queries outside (2 m, 2°).
    pub failures: usize,
    /// Of those, the ones within 2 m across the axis and 2° in rotation: only the depth along the
    /// axis, which a narrow view constrains least, is off.
    pub failures_along_axis_only: usize,
    /// Of the failures, the ones whose estimate scores below the ground truth's pose in the same
    /// terms: the search stopped short of a better optimum near the truth. The others are the cost's:
    /// it prefers (or ties) a pose away from the truth, and no search would have found the truth.
    /// Absent in summaries written before it was counted.
    #[serde(default)]
    pub failures_search_missed: usize,
}

/// One query's errors and scores, as the [`AxisRow`] counts them.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct QueryOutcome {
    /// Signed error along the ground truth's viewing direction, metres.
    pub axial_m: f64,
    /// Error across it, metres.
    pub lateral_m: f64,
    /// Translation error, metres.
    pub translation_m: f64,
    /// Rotation error, degrees.
    pub rotation_deg: f64,
    /// The estimate's score (higher is better).
    pub best_cost: f64,
    /// The ground truth's score in the same terms.
    pub cost_at_gt: f64,
}

impl QueryOutcome {
    /// Whether the query misses (2 m, 2°).
    fn failed(&self) -> bool {
        !within_2m_2deg(self.translation_m, self.rotation_deg)
    }

    /// Whether the truth scores better than the estimate (beyond rounding): the search missed.
    fn search_missed(&self) -> bool {
        self.cost_at_gt > self.best_cost + SCORE_TIE
    }
}

/// Score differences at most this small count as ties (the scores are ratios of pixel counts).
pub const SCORE_TIE: f64 = 1e-9;

/// The [`AxisRow`] of one method from its queries' outcomes.
pub fn axis_row(method: &str, outcomes: &[QueryOutcome]) -> AxisRow {
    let (t, r) = THRESHOLDS[0];
    let failed: Vec<&QueryOutcome> = outcomes.iter().filter(|o| o.failed()).collect();
    AxisRow {
        method: method.to_string(),
        queries: outcomes.len(),
        median_abs_axial_m: median_or_nan(&outcomes.iter().map(|o| o.axial_m.abs()).collect::<Vec<_>>()),
        median_axial_m: median_or_nan(&outcomes.iter().map(|o| o.axial_m).collect::<Vec<_>>()),
        estimates_ahead: outcomes.iter().filter(|o| o.axial_m > 0.0).count(),
        median_lateral_m: median_or_nan(&outcomes.iter().map(|o| o.lateral_m).collect::<Vec<_>>()),
        failures: failed.len(),
        failures_along_axis_only: failed.iter().filter(|o| o.lateral_m < t && o.rotation_deg < r).count(),
        failures_search_missed: failed.iter().filter(|o| o.search_missed()).count(),
    }
}

/// Rows (the prior's left out) whose estimates lie on one side of the truth along the axis so often
/// that chance is unlikely: at least [`BIAS_MIN_QUERIES`] queries, at least three in four on one side
/// (a sign test's p ≈ 0.04 at 20 queries) and a median signed error of at least
/// [`BIAS_MIN_AXIAL_M`]. A scale error of the masks against the map's renders does this.
pub fn depth_biased(rows: &[AxisRow]) -> Vec<&AxisRow> {
    rows.iter()
        .filter(|r| r.method != "prior" && r.queries >= BIAS_MIN_QUERIES)
        .filter(|r| 4 * r.estimates_ahead.max(r.queries - r.estimates_ahead) >= 3 * r.queries)
        .filter(|r| r.median_axial_m.abs() >= BIAS_MIN_AXIAL_M)
        .collect()
}

/// [`depth_biased`]: fewer queries tell too little.
pub const BIAS_MIN_QUERIES: usize = 20;
/// [`depth_biased`]: a smaller median depth error is noise at (2 m, 2°).
pub const BIAS_MIN_AXIAL_M: f64 = 0.5;

/// The axis rows as Markdown.
pub fn axis_markdown(rows: &[AxisRow]) -> String {
    let mut s = String::from(
        "| method | queries | median axial, absolute (m) | median axial, signed (m) | estimates ahead of the truth | median lateral (m) | failures at (2 m, 2°) | of which along the axis only | of which the search missed |\n|---|---:|---:|---:|---:|---:|---:|---:|---:|\n",
    );
    for r in rows {
        s.push_str(&format!(
            "| {} | {} | {:.2} | {:+.2} | {} | {:.2} | {} | {} | {} |\n",
            r.method,
            r.queries,
            r.median_abs_axial_m,
            r.median_axial_m,
            r.estimates_ahead,
            r.median_lateral_m,
            r.failures,
            r.failures_along_axis_only,
            r.failures_search_missed
        ));
    }
    s
}

/// The bucket rows as Markdown under the bucket column's `heading` (empty buckets left out).
pub fn bucket_markdown(heading: &str, rows: &[BucketRow]) -> String {
    let mut s = format!("| method | {heading} | queries | 2m-2° |\n|---|---|---|---|\n");
    for r in rows.iter().filter(|r| r.queries > 0) {
        s.push_str(&format!(
            "| {} | {} | {} | {:.1} |\n",
            r.method, r.bucket, r.queries, r.recall_2m_2deg_pct
        ));
    }
    s
}

/// The table as Markdown, in the paper's layout.
pub fn markdown(rows: &[Row]) -> String {
    let mut s = String::from(
        "| method | queries | group | 2m-2° | 3m-3° | 5m-5° | T.e. (m) | R.e. (°) |\n|---|---|---|---|---|---|---|---|\n",
    );
    for r in rows {
        s.push_str(&format!(
            "| {} | {} | {} | {:.1} | {:.1} | {:.1} | {:.2} | {:.2} |\n",
            r.method,
            r.queries,
            r.group,
            r.recall_pct[0],
            r.recall_pct[1],
            r.recall_pct[2],
            r.median_translation_m,
            r.median_rotation_deg
        ));
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::camera::Pose;
    use glam::DVec3;

    #[test]
    fn recall_is_strict_and_joint() {
        let e = [(1.0, 1.0), (2.0, 1.0), (1.0, 2.5), (4.0, 4.0)];
        let r = row("x", "all", &e);
        // (2, 2): only (1, 1) — (2, 1) is not strictly below 2 m. (3, 3): (1,1), (2,1), (1,2.5). (5, 5): all.
        assert_eq!(r.recall_pct, [25.0, 75.0, 100.0]);
        assert_eq!(r.median_translation_m, 1.5);
        assert_eq!(r.median_rotation_deg, 1.75);
    }

    #[test]
    fn buckets_partition_the_queries() {
        let e = [(1, 0.1, 0.1), (2, 3.0, 0.1), (3, 0.1, 0.1), (9, 0.1, 0.1), (40, 0.1, 0.1), (0, 9.0, 9.0)];
        let rows = bucket_rows("x", INSTANCE_BUCKETS, &e);
        let labels: Vec<&str> = rows.iter().map(|r| r.bucket.as_str()).collect();
        assert_eq!(labels, ["0", "1", "2–3", "4–7", "8–15", "16+"]);
        assert_eq!(rows.iter().map(|r| r.queries).sum::<usize>(), e.len());
        assert_eq!(rows.iter().map(|r| r.queries).collect::<Vec<_>>(), [1, 1, 2, 0, 1, 1]);
        // 2–3: (2, 3 m) misses, (3, 0.1 m) hits.
        assert_eq!(rows[2].recall_2m_2deg_pct, 50.0);
        assert!(rows[3].recall_2m_2deg_pct.is_nan());
        assert!(!bucket_markdown("query instances", &rows).contains("| 4–7 |"));
    }

    #[test]
    fn coverage_buckets_end_at_every_cell() {
        let e = [(0, 0.1, 0.1), (4, 0.1, 0.1), (5, 3.0, 0.1), (12, 0.1, 0.1), (16, 0.1, 0.1), (13, 0.1, 3.0)];
        let rows = bucket_rows("x", COVERAGE_BUCKETS, &e);
        let labels: Vec<&str> = rows.iter().map(|r| r.bucket.as_str()).collect();
        assert_eq!(labels, ["0–4", "5–8", "9–12", "13–16"]);
        assert_eq!(rows.iter().map(|r| r.queries).collect::<Vec<_>>(), [2, 1, 1, 2]);
        assert_eq!(rows.iter().map(|r| r.recall_2m_2deg_pct).collect::<Vec<_>>()[..2], [100.0, 0.0]);
        assert_eq!(rows[3].recall_2m_2deg_pct, 50.0);
        let md = bucket_markdown("frame cells with buildings", &rows);
        assert!(
            md.starts_with("| method | frame cells with buildings |")
                && md.contains("| x | 13–16 | 2 | 50.0 |")
        );
    }

    #[test]
    fn bucket_rows_read_the_old_field_name() {
        let r: BucketRow =
            serde_json::from_str(r#"{"method":"m","instances":"2–3","queries":4,"recall_2m_2deg_pct":50.0}"#)
                .unwrap();
        assert_eq!(r.bucket, "2–3");
    }

    #[test]
    fn axis_rows_tell_depth_only_failures_apart() {
        // (axial, lateral, translation, rotation, best, at gt): a success, a depth-only failure the
        // search missed, a lateral failure the cost prefers, a rotation failure on a tie.
        let o = |e: (f64, f64, f64, f64), best_cost: f64, cost_at_gt: f64| QueryOutcome {
            axial_m: e.0,
            lateral_m: e.1,
            translation_m: e.2,
            rotation_deg: e.3,
            best_cost,
            cost_at_gt,
        };
        let e = [
            o((0.1, 0.1, 0.14, 0.01), 0.9, 0.95),
            o((-3.0, 0.5, 3.04, 0.02), 0.8, 0.85),
            o((0.5, 2.5, 2.55, 0.02), 0.9, 0.85),
            o((0.1, 0.1, 0.14, 2.5), 0.7, 0.7),
        ];
        let r = axis_row("m", &e);
        assert_eq!(
            (r.queries, r.failures, r.failures_along_axis_only, r.failures_search_missed),
            (4, 3, 1, 1)
        );
        assert!((r.median_abs_axial_m - 0.3).abs() < 1e-12, "{}", r.median_abs_axial_m);
        // Signed: −3.0, 0.1, 0.1, 0.5 → 0.1; three estimates ahead of the truth, one behind.
        assert!((r.median_axial_m - 0.1).abs() < 1e-12, "{}", r.median_axial_m);
        assert_eq!(r.estimates_ahead, 3);
        assert!((r.median_lateral_m - 0.3).abs() < 1e-12);
        assert!(axis_markdown(&[r]).contains("| m | 4 | 0.30 | +0.10 | 3 | 0.30 | 3 | 1 | 1 |"));
    }

    #[test]
    fn a_depth_bias_is_one_sided_large_and_seen_on_enough_queries() {
        let row = |method: &str, queries: usize, ahead: usize, median: f64| AxisRow {
            method: method.to_string(),
            queries,
            median_abs_axial_m: median.abs(),
            median_axial_m: median,
            estimates_ahead: ahead,
            median_lateral_m: 0.2,
            failures: 0,
            failures_along_axis_only: 0,
            failures_search_missed: 0,
        };
        let rows = [
            row("ahead", 40, 37, 1.28),  // the closed loop's U-Net: flagged
            row("behind", 40, 10, -0.9), // 30 of 40 behind: flagged
            row("scatter", 40, 23, 0.02),
            row("one-sided but small", 40, 38, 0.3),
            row("large but mixed", 40, 29, 1.0), // 29 of 40 is under three in four
            row("few queries", 19, 19, 2.0),
            row("prior", 40, 40, 5.0),
            row("unknown", 40, 0, f64::NAN),
        ];
        let flagged: Vec<&str> = depth_biased(&rows).iter().map(|r| r.method.as_str()).collect();
        assert_eq!(flagged, ["ahead", "behind"]);
    }

    #[test]
    fn axis_rows_read_summaries_without_the_search_count() {
        let r: AxisRow = serde_json::from_str(
            r#"{"method":"m","queries":2,"median_abs_axial_m":0.1,"median_lateral_m":0.1,"failures":1,"failures_along_axis_only":1}"#,
        )
        .unwrap();
        assert_eq!(r.failures_search_missed, 0);
        assert!(r.median_axial_m.is_nan() && r.estimates_ahead == 0, "not reported then, not zero");
    }

    #[test]
    fn errors_match_hand_computation() {
        let gt = Pose::from_ypr_deg(30.0, 45.0, 0.0, [0.0, 0.0, 300.0]);
        let est = Pose::from_ypr_deg(31.5, 45.0, 0.0, [3.0, 4.0, 300.0]);
        assert!((gt.translation_error_m(&est) - 5.0).abs() < 1e-12);
        // A pure yaw difference about the vertical: the rotation angle is the yaw difference.
        assert!((gt.rotation_error_deg(&est) - 1.5).abs() < 1e-9);
    }

    #[test]
    fn axial_and_lateral_errors_split_the_translation() {
        // Looking 45° down towards +y (yaw 0): forward is (0, 1, −1)/√2.
        let gt = Pose::from_ypr_deg(0.0, 45.0, 0.0, [0.0, 0.0, 300.0]);
        let f = gt.forward();
        let side = DVec3::new(1.0, 0.0, 0.0);
        assert!(f.dot(side).abs() < 1e-12, "{f}");
        let est = Pose::from_ypr_deg(0.0, 45.0, 0.0, gt.centre_m - 3.0 * f + 0.5 * side);
        let (axial, lateral) = gt.axial_lateral_error_m(&est);
        assert!((axial + 3.0).abs() < 1e-9, "{axial}");
        assert!((lateral - 0.5).abs() < 1e-9, "{lateral}");
        assert!((axial.hypot(lateral) - gt.translation_error_m(&est)).abs() < 1e-9);
    }
}
