//! Alignment check between two building-ID images of the same pose: Blender's float32 ID render and the
//! mask renderer's 24-bit ID PNG (or any other pair).
//!
//! For every building present in either image the IoU of its two pixel sets is computed; a report
//! gathers them over frames with the median and the 5th percentile (linear interpolation between order
//! statistics, numpy's default), the worst cases and the overall pixel agreement. Buildings whose union
//! covers fewer than `min_union_px` pixels are listed but left out of the statistics: a 3-pixel sliver's
//! IoU says more about sampling than about alignment.

use std::collections::BTreeMap;
use std::path::Path;

use serde::{Deserialize, Serialize};

use super::error::BlenderError;
use crate::scene::{BuildingId, IdMap};

/// Targets of issue 6: median IoU ≥ 0.995 and 5th percentile ≥ 0.98.
pub const TARGET_MEDIAN_IOU: f64 = 0.995;
/// 5th-percentile IoU target of the alignment check.
pub const TARGET_P5_IOU: f64 = 0.98;

/// Overlap of one building between two ID images.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct BuildingIou {
    /// The building compared.
    pub building_id: BuildingId,
    /// Pixels of the building in image A (Blender), in image B (reference), in both, in either.
    pub a_px: u64,
    /// Pixels of the building in image B (reference).
    pub b_px: u64,
    /// Pixels of the building in both images.
    pub intersection_px: u64,
    /// Pixels of the building in either image.
    pub union_px: u64,
    /// Intersection over union, 0..=1.
    pub iou: f64,
}

/// Per-building IoU between `a` and `b` (same size), ordered by building ID; background is skipped.
///
/// # Errors
/// [`BlenderError::SizeMismatch`] (naming `what`) when the sizes differ.
pub fn building_ious(a: &IdMap, b: &IdMap, what: &Path) -> Result<Vec<BuildingIou>, BlenderError> {
    if (a.width(), a.height()) != (b.width(), b.height()) {
        return Err(BlenderError::SizeMismatch {
            path: what.to_path_buf(),
            a: [a.width(), a.height()],
            b: [b.width(), b.height()],
        });
    }
    // [a_px, b_px, intersection]
    let mut counts: BTreeMap<BuildingId, [u64; 3]> = BTreeMap::new();
    for (&x, &y) in a.ids().iter().zip(b.ids()) {
        if x == y {
            if !x.is_background() {
                let c = counts.entry(x).or_default();
                c[0] += 1;
                c[1] += 1;
                c[2] += 1;
            }
        } else {
            if !x.is_background() {
                counts.entry(x).or_default()[0] += 1;
            }
            if !y.is_background() {
                counts.entry(y).or_default()[1] += 1;
            }
        }
    }
    Ok(counts
        .into_iter()
        .map(|(id, [a_px, b_px, inter])| {
            let union = a_px + b_px - inter;
            BuildingIou {
                building_id: id,
                a_px,
                b_px,
                intersection_px: inter,
                union_px: union,
                iou: inter as f64 / union as f64,
            }
        })
        .collect())
}

/// Fraction of pixels carrying the same ID (background included) in both images of equal size.
pub fn pixel_agreement(a: &IdMap, b: &IdMap) -> f64 {
    if a.ids().is_empty() {
        return 1.0;
    }
    a.ids().iter().zip(b.ids()).filter(|(x, y)| x == y).count() as f64 / a.ids().len() as f64
}

/// The `q`-quantile (0..=1) of ascending `sorted` values, interpolating linearly between order
/// statistics (numpy's default `linear` method); `None` for no values.
pub fn quantile(sorted: &[f64], q: f64) -> Option<f64> {
    if sorted.is_empty() {
        return None;
    }
    let pos = q.clamp(0.0, 1.0) * (sorted.len() - 1) as f64;
    let lo = pos.floor() as usize;
    let hi = pos.ceil() as usize;
    Some(sorted[lo] + (sorted[hi] - sorted[lo]) * (pos - lo as f64))
}

/// One frame's comparison.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FrameAlignment {
    /// Frame name.
    pub frame: String,
    /// Fraction of pixels with the same ID in both images (background included), 0..=1.
    pub pixel_agreement: f64,
    /// Per-building overlaps, ordered by building ID.
    pub buildings: Vec<BuildingIou>,
}

/// A building of a frame, for the worst-case list.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct WorstCase {
    /// Frame name.
    pub frame: String,
    /// The building's overlap in that frame.
    #[serde(flatten)]
    pub building: BuildingIou,
}

/// The alignment report (written as `alignment/report.json` and `report.md`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct AlignmentReport {
    /// Frames compared.
    pub frames: usize,
    /// (frame, building) pairs seen, and those with a union of at least `min_union_px` (the statistics).
    pub pairs_total: usize,
    /// Pairs with a union of at least `min_union_px` (those the statistics use).
    pub pairs_counted: usize,
    /// Smallest union, pixels, for a pair to be counted.
    pub min_union_px: u64,
    /// Median IoU of the counted pairs (`None` when none was counted).
    pub median_iou: Option<f64>,
    /// 5th-percentile IoU of the counted pairs.
    pub p5_iou: Option<f64>,
    /// Lowest IoU of the counted pairs.
    pub min_iou: Option<f64>,
    /// Mean IoU of the counted pairs.
    pub mean_iou: Option<f64>,
    /// Pixel agreement over all frames (background included).
    pub pixel_agreement: f64,
    /// Median IoU target ([`TARGET_MEDIAN_IOU`]).
    pub target_median_iou: f64,
    /// 5th-percentile IoU target ([`TARGET_P5_IOU`]).
    pub target_p5_iou: f64,
    /// Whether both targets are met (false when nothing was counted).
    pub pass: bool,
    /// The counted pairs with the lowest IoU (up to 20).
    pub worst: Vec<WorstCase>,
    /// Every frame's comparison.
    pub per_frame: Vec<FrameAlignment>,
}

/// Gathers per-frame comparisons into a report.
pub fn summarise(per_frame: Vec<FrameAlignment>, min_union_px: u64) -> AlignmentReport {
    let mut counted: Vec<WorstCase> = Vec::new();
    let mut total = 0;
    let mut agree_weighted = 0.0;
    let mut px_total = 0u64;
    for f in &per_frame {
        total += f.buildings.len();
        for b in &f.buildings {
            if b.union_px >= min_union_px {
                counted.push(WorstCase { frame: f.frame.clone(), building: b.clone() });
            }
        }
        let px: u64 = f.buildings.iter().map(|b| b.union_px).sum::<u64>().max(1);
        agree_weighted += f.pixel_agreement * px as f64;
        px_total += px;
    }
    let mut ious: Vec<f64> = counted.iter().map(|w| w.building.iou).collect();
    ious.sort_by(f64::total_cmp);
    counted.sort_by(|a, b| {
        a.building
            .iou
            .total_cmp(&b.building.iou)
            .then(a.frame.cmp(&b.frame))
            .then(a.building.building_id.cmp(&b.building.building_id))
    });
    counted.truncate(20);
    let median = quantile(&ious, 0.5);
    let p5 = quantile(&ious, 0.05);
    let mean = if ious.is_empty() { None } else { Some(ious.iter().sum::<f64>() / ious.len() as f64) };
    let pass = matches!((median, p5), (Some(m), Some(p)) if m >= TARGET_MEDIAN_IOU && p >= TARGET_P5_IOU);
    AlignmentReport {
        frames: per_frame.len(),
        pairs_total: total,
        pairs_counted: ious.len(),
        min_union_px,
        median_iou: median,
        p5_iou: p5,
        min_iou: ious.first().copied(),
        mean_iou: mean,
        pixel_agreement: if px_total == 0 { 1.0 } else { agree_weighted / px_total as f64 },
        target_median_iou: TARGET_MEDIAN_IOU,
        target_p5_iou: TARGET_P5_IOU,
        pass,
        worst: counted,
        per_frame,
    }
}

fn fmt_opt(v: Option<f64>) -> String {
    v.map(|x| format!("{x:.4}")).unwrap_or_else(|| "–".into())
}

impl AlignmentReport {
    /// The report as Markdown.
    pub fn to_markdown(&self) -> String {
        let mut s = String::new();
        s.push_str("# Blender ↔ mask alignment\n\n");
        s.push_str(&format!(
            "Per-building IoU between Blender's ID render and the ID masks of the same poses, over {} frame(s); \
             {} of {} (frame, building) pairs have a union of at least {} px and enter the statistics.\n\n",
            self.frames, self.pairs_counted, self.pairs_total, self.min_union_px
        ));
        s.push_str("| statistic | value | target |\n|---|---|---|\n");
        s.push_str(&format!(
            "| median IoU | {} | ≥ {} |\n",
            fmt_opt(self.median_iou),
            self.target_median_iou
        ));
        s.push_str(&format!(
            "| 5th percentile IoU | {} | ≥ {} |\n",
            fmt_opt(self.p5_iou),
            self.target_p5_iou
        ));
        s.push_str(&format!("| minimum IoU | {} | |\n", fmt_opt(self.min_iou)));
        s.push_str(&format!("| mean IoU | {} | |\n", fmt_opt(self.mean_iou)));
        s.push_str(&format!("| pixel agreement | {:.5} | |\n\n", self.pixel_agreement));
        s.push_str(&format!("**Result: {}**\n\n", if self.pass { "PASS" } else { "FAIL" }));
        if !self.worst.is_empty() {
            s.push_str("## Lowest IoU\n\n| frame | building | IoU | Blender px | mask px | union px |\n|---|---|---|---|---|---|\n");
            for w in &self.worst {
                let b = &w.building;
                s.push_str(&format!(
                    "| {} | {} | {:.4} | {} | {} | {} |\n",
                    w.frame, b.building_id, b.iou, b.a_px, b.b_px, b.union_px
                ));
            }
            s.push('\n');
        }
        s.push_str("## Frames\n\n| frame | buildings | pixel agreement |\n|---|---|---|\n");
        for f in &self.per_frame {
            s.push_str(&format!("| {} | {} | {:.5} |\n", f.frame, f.buildings.len(), f.pixel_agreement));
        }
        s
    }
}

/// File names of the alignment report in the RGB output folder.
pub const REPORT_JSON: &str = "report.json";
/// The report as Markdown, next to [`REPORT_JSON`].
pub const REPORT_MD: &str = "report.md";

/// `render-rgb --check-alignment`: compares every frame's Blender ID render (the `IdExr` output of
/// `plan`) with its mask in `camera` (`masks/<frame>.png`), writes [`REPORT_JSON`] and [`REPORT_MD`]
/// into the plan's output folder and returns the report (its `pass` says whether the targets hold).
///
/// # Errors
/// [`BlenderError::MaskMissing`] when a frame has no mask yet (naming the command that makes it),
/// [`BlenderError::Ids`] for an ID render or mask that cannot be read,
/// [`BlenderError::SizeMismatch`] when their sizes differ, [`BlenderError::File`] when the report
/// cannot be written.
pub fn check_frames(
    plan: &super::run::RenderPlan,
    frames: &[super::run::FrameRequest],
    camera: &crate::layout::CameraDir,
    min_union_px: u64,
) -> Result<AlignmentReport, BlenderError> {
    let mut per_frame = Vec::with_capacity(frames.len());
    for f in frames {
        let ids_path = super::run::frame_outputs(plan, &f.name)
            .into_iter()
            .find(|o| o.kind == super::run::OutputKind::IdExr)
            .map(|o| o.path)
            .ok_or_else(|| BlenderError::NoIdOutput { frame: f.name.clone() })?;
        let mask_path = camera.mask_png(&f.name);
        if !mask_path.is_file() {
            return Err(BlenderError::MaskMissing { path: mask_path });
        }
        let a = IdMap::read_exr(&ids_path)?;
        let b = IdMap::read_png(&mask_path)?;
        let buildings = building_ious(&a, &b, &mask_path)?;
        per_frame.push(FrameAlignment {
            frame: f.name.clone(),
            pixel_agreement: pixel_agreement(&a, &b),
            buildings,
        });
    }
    let report = summarise(per_frame, min_union_px);
    crate::util::write_json_atomic(&plan.out_dir.join(REPORT_JSON), &report)?;
    crate::util::write_bytes_atomic(&plan.out_dir.join(REPORT_MD), report.to_markdown().as_bytes())?;
    Ok(report)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn img(w: u32, rows: &[&[u32]]) -> IdMap {
        IdMap::from_raw(w, rows.len() as u32, rows.iter().flat_map(|r| r.iter().copied()).collect()).unwrap()
    }

    fn id(n: u32) -> BuildingId {
        BuildingId::new(n).unwrap()
    }

    #[test]
    fn ious_by_hand() {
        let a = img(4, &[&[1, 1, 0, 2], &[1, 1, 0, 2]]);
        let b = img(4, &[&[1, 1, 1, 0], &[1, 0, 0, 2]]);
        let r = building_ious(&a, &b, Path::new("x")).unwrap();
        // Building 1: A has 4 px, B has 4 px, 3 shared → IoU 3/5. Building 2: 2 vs 1, 1 shared → 1/2.
        assert_eq!(r.len(), 2);
        assert_eq!(
            (r[0].building_id, r[0].a_px, r[0].b_px, r[0].intersection_px, r[0].union_px),
            (id(1), 4, 4, 3, 5)
        );
        assert!((r[0].iou - 0.6).abs() < 1e-15);
        assert_eq!((r[1].building_id, r[1].intersection_px, r[1].union_px), (id(2), 1, 2));
        assert!((pixel_agreement(&a, &b) - 5.0 / 8.0).abs() < 1e-15);
    }

    #[test]
    fn size_mismatch_is_an_error() {
        let a = img(2, &[&[1, 1]]);
        let b = img(1, &[&[1], &[1]]);
        assert!(building_ious(&a, &b, Path::new("f.png")).unwrap_err().to_string().contains("f.png"));
    }

    #[test]
    fn quantiles_match_numpy_linear() {
        // numpy.quantile([0.1, 0.5, 0.9, 1.0], [0.05, 0.5]) = [0.16, 0.7] (hand: pos 0.15 and 1.5).
        let v = [0.1, 0.5, 0.9, 1.0];
        assert!((quantile(&v, 0.05).unwrap() - 0.16).abs() < 1e-12);
        assert!((quantile(&v, 0.5).unwrap() - 0.7).abs() < 1e-12);
        assert_eq!(quantile(&[], 0.5), None);
        assert_eq!(quantile(&[0.3], 0.05), Some(0.3));
    }

    #[test]
    fn summary_filters_small_unions_and_judges_targets() {
        let b = |n, inter, union| BuildingIou {
            building_id: id(n),
            a_px: union,
            b_px: inter,
            intersection_px: inter,
            union_px: union,
            iou: inter as f64 / union as f64,
        };
        let frames = vec![
            FrameAlignment {
                frame: "a".into(),
                pixel_agreement: 0.99,
                buildings: vec![b(1, 100, 100), b(2, 1, 3)],
            },
            FrameAlignment {
                frame: "b".into(),
                pixel_agreement: 1.0,
                buildings: vec![b(1, 199, 200), b(3, 98, 100)],
            },
        ];
        let r = summarise(frames, 10);
        assert_eq!((r.pairs_total, r.pairs_counted), (4, 3));
        // Counted IoUs: 0.98, 0.995, 1.0 → median 0.995, p5 = 0.98 + 0.1·(0.995 − 0.98) = 0.9815.
        assert!((r.median_iou.unwrap() - 0.995).abs() < 1e-12);
        assert!((r.p5_iou.unwrap() - 0.9815).abs() < 1e-12);
        assert!(r.pass);
        assert_eq!(r.worst[0].frame, "b");
        assert_eq!(r.worst[0].building.building_id, id(3));
        let md = r.to_markdown();
        assert!(md.contains("PASS") && md.contains("| median IoU | 0.9950 |"), "{md}");
        let r = summarise(vec![], 10);
        assert!(!r.pass && r.median_iou.is_none());
    }
}
