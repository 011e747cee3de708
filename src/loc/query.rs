//! Where the localizer's query instances come from, at the resolution the hypotheses are rendered:
//! - the **oracle**: the ground-truth ID map of the frame (`masks/<frame>.png` from `render-masks`),
//!   resized nearest-neighbour and split into connected components; degradations
//!   ([`super::oracle`]) apply at the mask's own resolution (a segmenter errs in image pixels) before
//!   the resize;
//! - **predictions**: a segmentation model's COCO results file (RLE + score at any resolution), each
//!   mask resized nearest-neighbour to the render resolution, optionally scaled back by the model's
//!   measured zoom ([`FramePredictions::zoom`]); image ids are mapped to frames through the COCO
//!   instances file(s) that `export-coco` wrote (their `images[]` carry `area_name`, `camera` and
//!   `frame`).

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use serde::Deserialize;

use super::cost::{bbox_area, Query, QueryInstance};
use super::oracle::{self, Degradation};
use super::resample::{resize_nearest, resize_scaled};
use crate::camera::Intrinsics;
use crate::export::results::{read_results, Prediction};
use crate::label::{label_components, Connectivity};
use crate::scene::IdMap;

/// Errors while building queries.
#[derive(Debug, thiserror::Error)]
pub enum QueryError {
    /// The predictions file cannot be read as COCO results.
    #[error(transparent)]
    Coco(#[from] crate::export::CocoError),
    /// The COCO instances file(s) hold no image of the area and camera evaluated.
    #[error("{}: no image of area {area:?}, camera {camera:?} in the COCO instances file(s)", path.display())]
    NoImages {
        /// The first instances file given (empty when none was).
        path: PathBuf,
        /// The area evaluated.
        area: String,
        /// The camera evaluated.
        camera: String,
    },
    /// None of the predictions' image ids is an image of the area and camera evaluated.
    #[error(
        "{}: none of its image ids belongs to area {area:?}, camera {camera:?} (ids come from the COCO \
         instances file the predictions were made for)",
        path.display()
    )]
    NoPredictions {
        /// The predictions (COCO results) file.
        path: PathBuf,
        /// The area evaluated.
        area: String,
        /// The camera evaluated.
        camera: String,
    },
    /// An oracle query's ID map cannot be read.
    #[error("query mask unavailable (run `insgen render-masks` for this camera first)")]
    Mask(#[source] crate::scene::IdError),
    /// A file given as COCO instances does not parse as one.
    #[error("{}: not a COCO instances file", path.display())]
    Instances {
        /// The file given as COCO instances.
        path: PathBuf,
        /// The parser's complaint.
        #[source]
        source: serde_json::Error,
    },
}

/// The predictions of one area/camera, by frame name.
#[derive(Debug, Clone, Default)]
pub struct FramePredictions {
    /// Predicted instances by frame name.
    pub by_frame: BTreeMap<String, Vec<Prediction>>,
    /// The results file (for messages).
    pub path: PathBuf,
    /// Predictions below this score are ignored.
    pub min_score: f64,
    /// The segmenter's zoom: how much larger than the buildings its masks are, about the principal
    /// point, as measured on frames with known poses (`baseline.py score` reports it as `mask_zoom`).
    /// The masks are scaled by 1/zoom before they are used; 1 leaves them as they are.
    pub zoom: f64,
}

/// Where queries come from.
#[derive(Debug, Clone)]
pub enum QuerySource {
    /// Ground-truth masks, degraded.
    Oracle {
        /// The camera's `masks/` directory (`<frame>.png` ID maps from `render-masks`).
        masks_dir: PathBuf,
        /// What is done to the true instances before they are used as the query.
        degradation: Degradation,
    },
    /// A segmentation model's predictions.
    Predictions(FramePredictions),
}

impl QuerySource {
    /// The query of `frame` at each of the intrinsics `ks` (e.g. the fine and the coarse resolution);
    /// the mask is read and degraded once. `seed` drives the oracle's degradations.
    ///
    /// # Errors
    /// A missing or unreadable mask (oracle), naming the file and the command that writes it.
    pub fn queries(&self, frame: &str, ks: &[Intrinsics], seed: u64) -> Result<Vec<Query>, QueryError> {
        match self {
            QuerySource::Oracle { masks_dir, degradation } => {
                oracle_queries(masks_dir, frame, ks, degradation, seed)
            }
            QuerySource::Predictions(p) => {
                let preds = p.by_frame.get(frame).map(Vec::as_slice).unwrap_or(&[]);
                Ok(ks.iter().map(|k| predictions_query(preds, k, p.min_score, p.zoom)).collect())
            }
        }
    }
}

fn oracle_queries(
    masks_dir: &Path,
    frame: &str,
    ks: &[Intrinsics],
    d: &Degradation,
    seed: u64,
) -> Result<Vec<Query>, QueryError> {
    let path = masks_dir.join(format!("{frame}.png"));
    let map = IdMap::read_png(&path).map_err(QueryError::Mask)?;
    let (w, h) = (map.width(), map.height());
    if d.is_perfect() {
        // What a perfect segmenter run at the render resolution would output.
        return Ok(ks
            .iter()
            .map(|k| {
                let ids = resize_nearest(map.ids(), w, h, k.width_px, k.height_px);
                let resized = IdMap::new(k.width_px, k.height_px, ids).expect("resized to k's size");
                let lab = label_components(&resized, Connectivity::Eight);
                oracle::degrade(k.width_px, k.height_px, &lab.labels, lab.components.len() as u32, d, seed)
            })
            .collect());
    }
    // A segmenter's errors are in image pixels: degrade once at the mask's own resolution, then
    // resize to each target.
    let lab = label_components(&map, Connectivity::Eight);
    let q = oracle::degrade(w, h, &lab.labels, lab.components.len() as u32, d, seed);
    if log::log_enabled!(log::Level::Debug) {
        let a = oracle::agreement(&lab.labels, lab.components.len() as u32, &q);
        log::debug!("{frame}: degraded masks against the truth: {}", serde_json::json!(a));
    }
    let mut labels = vec![0u32; map.ids().len()];
    for (j, inst) in q.instances.iter().enumerate() {
        for p in inst.pixels() {
            labels[p as usize] = j as u32 + 1;
        }
    }
    let scores: Vec<f64> = q.instances.iter().map(|i| i.score).collect();
    Ok(ks
        .iter()
        .map(|k| {
            let small = resize_nearest(&labels, w, h, k.width_px, k.height_px);
            Query::from_labels(k.width_px, k.height_px, &small, &scores)
        })
        .collect())
}

/// The query made of `preds` (any resolution) resized to `k`, scaled by 1/`zoom` about the principal
/// point (the segmenter's measured zoom undone; 1: none); predictions scoring below `min_score` or
/// vanishing at the target resolution are left out. Box areas are the predictions' own, scaled to
/// the target resolution and by 1/zoom².
pub fn predictions_query(preds: &[Prediction], k: &Intrinsics, min_score: f64, zoom: f64) -> Query {
    let (tw, th) = (k.width_px, k.height_px);
    let mut instances = Vec::new();
    for p in preds.iter().filter(|p| p.score >= min_score) {
        let [h, w] = p.size();
        if h == 0 || w == 0 {
            continue;
        }
        let centre_px = [k.cx_px, k.cy_px];
        let mask = resize_scaled(&p.mask(), [w, h], [tw, th], centre_px, 1.0 / zoom);
        let pixels: Vec<u32> =
            mask.iter().enumerate().filter(|(_, &m)| m != 0).map(|(i, _)| i as u32).collect();
        if pixels.is_empty() {
            continue;
        }
        let scale = (tw as f64 / w as f64) * (th as f64 / h as f64) / (zoom * zoom);
        let bbox_area_px = if p.bbox_area_px > 0.0 { p.bbox_area_px * scale } else { bbox_area(&pixels, tw) };
        instances.push(QueryInstance::new(&pixels, p.score, bbox_area_px));
    }
    Query::new(tw, th, instances)
}

/// The part of a COCO instances file that maps image ids to frames.
#[derive(Debug, Deserialize)]
struct ImagesOnly {
    images: Vec<ImageRef>,
}

#[derive(Debug, Deserialize)]
struct ImageRef {
    id: u64,
    #[serde(default)]
    area_name: Option<String>,
    #[serde(default)]
    camera: Option<String>,
    #[serde(default)]
    frame: Option<String>,
}

/// Reads a results file and keeps the predictions of `area`/`camera`, keyed by frame name, using the
/// image lists of `instances_files` (COCO files written by `export-coco`).
///
/// # Errors
/// Unreadable or invalid files, or a results file none of whose image ids belong to the area/camera
/// (almost always the wrong file).
pub fn load_predictions(
    results_path: &Path,
    instances_files: &[PathBuf],
    area: &str,
    camera: &str,
    min_score: f64,
) -> Result<FramePredictions, QueryError> {
    let results = read_results(results_path)?;
    let mut frames: BTreeMap<u64, String> = BTreeMap::new();
    for f in instances_files {
        let bytes = crate::util::read_file(f).map_err(crate::export::CocoError::from)?;
        let images: ImagesOnly = serde_json::from_slice(&bytes)
            .map_err(|source| QueryError::Instances { path: f.clone(), source })?;
        for im in images.images {
            if im.area_name.as_deref() == Some(area) && im.camera.as_deref() == Some(camera) {
                if let Some(frame) = im.frame {
                    frames.insert(im.id, frame);
                }
            }
        }
    }
    if frames.is_empty() {
        return Err(QueryError::NoImages {
            path: instances_files.first().cloned().unwrap_or_default(),
            area: area.to_string(),
            camera: camera.to_string(),
        });
    }
    let mut by_frame: BTreeMap<String, Vec<Prediction>> = BTreeMap::new();
    for (image_id, preds) in results.by_image {
        if let Some(frame) = frames.get(&image_id) {
            by_frame.entry(frame.clone()).or_default().extend(preds);
        }
    }
    if by_frame.is_empty() {
        return Err(QueryError::NoPredictions {
            path: results_path.to_path_buf(),
            area: area.to_string(),
            camera: camera.to_string(),
        });
    }
    Ok(FramePredictions { by_frame, path: results_path.to_path_buf(), min_score, zoom: 1.0 })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::export::rle::encode;

    fn pred(mask: &[u8], h: u32, w: u32, score: f64) -> Prediction {
        Prediction { index: 0, category_id: 1, score, rle: encode(mask, h, w).unwrap(), bbox_area_px: 0.0 }
    }

    #[test]
    fn predictions_are_resized_filtered_and_scaled() {
        // 4×4 prediction, left half set → at 2×2 the left column.
        let mut m = vec![0u8; 16];
        for y in 0..4 {
            m[y * 4] = 1;
            m[y * 4 + 1] = 1;
        }
        let k = Intrinsics { width_px: 2, height_px: 2, fx_px: 2.0, fy_px: 2.0, cx_px: 1.0, cy_px: 1.0 };
        let mut with_box = pred(&m, 4, 4, 0.9);
        with_box.bbox_area_px = 8.0;
        let q = predictions_query(&[with_box, pred(&m, 4, 4, 0.2)], &k, 0.5, 1.0);
        assert_eq!(q.instances.len(), 1, "the 0.2 prediction is below --min-score");
        assert_eq!(q.instances[0].pixels().collect::<Vec<_>>(), vec![0, 2]);
        assert_eq!(q.instances[0].score, 0.9);
        // 8 px² at 4×4 → 2 px² at 2×2.
        assert!((q.instances[0].bbox_area_px - 2.0).abs() < 1e-12);
        // A one-pixel prediction that no target pixel centre samples vanishes.
        let mut dot = vec![0u8; 16];
        dot[0] = 1;
        assert!(predictions_query(&[pred(&dot, 4, 4, 1.0)], &k, 0.0, 1.0).instances.is_empty());
    }

    #[test]
    fn a_measured_zoom_is_undone_about_the_principal_point() {
        // A 200 × 100 prediction (principal point 100, 50) with a 22 × 11 block at x 155..177,
        // y 61..72: the block of x 150..170, y 60..70 grown by 1.1 about the principal point. Undoing
        // the zoom samples source x = 100 + (x + 0.5 − 100)·1.1 for target pixel x: x 150..169 map
        // into 155..177, so the block comes back as 20 × 10 px at x 150..170, y 60..70.
        let (w, h) = (200u32, 100u32);
        let mut m = vec![0u8; (w * h) as usize];
        for y in 61..72 {
            for x in 155..177 {
                m[y * w as usize + x] = 1;
            }
        }
        let k =
            Intrinsics { width_px: w, height_px: h, fx_px: 200.0, fy_px: 200.0, cx_px: 100.0, cy_px: 50.0 };
        let mut boxed = pred(&m, h, w, 1.0);
        boxed.bbox_area_px = 242.0;
        let q = predictions_query(&[boxed], &k, 0.0, 1.1);
        let px: Vec<u32> = q.instances[0].pixels().collect();
        let (xs, ys): (Vec<u32>, Vec<u32>) = px.iter().map(|p| (p % w, p / w)).unzip();
        assert_eq!((xs.iter().min(), xs.iter().max()), (Some(&150), Some(&169)));
        assert_eq!((ys.iter().min(), ys.iter().max()), (Some(&60), Some(&69)));
        assert_eq!(px.len(), 20 * 10);
        // The box area given with the prediction follows: 22 · 11 / 1.1².
        assert!((q.instances[0].bbox_area_px - 200.0).abs() < 1e-9, "{}", q.instances[0].bbox_area_px);
        // At half the resolution the principal point is k's (50, 25): the same block, halved.
        let k2 =
            Intrinsics { width_px: 100, height_px: 50, fx_px: 100.0, fy_px: 100.0, cx_px: 50.0, cy_px: 25.0 };
        let q2 = predictions_query(&[pred(&m, h, w, 1.0)], &k2, 0.0, 1.1);
        let px2: Vec<u32> = q2.instances[0].pixels().collect();
        assert_eq!(px2.len(), 10 * 5);
        assert_eq!((px2[0] % 100, px2[0] / 100), (75, 30));
        // Zoom 1 is the plain resize.
        assert_eq!(
            predictions_query(&[pred(&m, h, w, 1.0)], &k, 0.0, 1.0).instances[0].pixels().count(),
            22 * 11
        );
    }
}
