//! `export-panoptic`: the COCO instance export as COCO panoptic segmentation.
//!
//! Takes in an `export-coco` output directory ([`super::frames`]: the instance files and, through each
//! image's `mask_file`, the ID maps). Hands on, per split present:
//! - `panoptic_<split>/<area>/<camera>/<frame>.png`: 8-bit RGB, one segment id per pixel in the
//!   encoding of the COCO panoptic API (`panopticapi.utils.rgb2id`): id = R + 256·G + 256²·B — the byte
//!   order opposite to insgen's ID maps (R = high byte), so the ID maps are not panoptic PNGs as they are;
//! - `panoptic_<split>.json`: `info`, `licenses`, `images` (the instance file's records, unchanged),
//!   `annotations` (one per image: `image_id`, `file_name`, `segments_info`) and `categories`
//!   (`building`, `isthing` = 1).
//!
//! Segment ids are the ids of the instance annotations (`instances_<split>.json` `annotations[].id`,
//! unique in the file and < 2²⁴), not the building IDs: a building seen as two components under the
//! default per-component export is two annotations, hence two segments, each with the annotation's
//! `iscrowd`. Each segment carries the extension keys `building_id` and `source_id`. Pixels outside
//! every kept annotation (background, and instances removed by the export's filters) are 0, "void"
//! in the panoptic API, which ignores them in PQ. There is no stuff category: the dataset labels
//! buildings only.
//!
//! # References
//! COCO panoptic format (<https://cocodataset.org/#format-data>, "Panoptic Segmentation");
//! `panopticapi/utils.py` (`rgb2id`, `id2rgb`) and `panopticapi/evaluation.py` of cocodataset/panopticapi.

use std::path::{Path, PathBuf};

use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::scene::{BuildingId, MAX_BUILDING_ID};
use crate::util::Progress;

use super::format::{Image, Info, License, BUILDING_CATEGORY_ID};
use super::frames::{for_each_pixel, load_frame, read_splits, ExportSplit};
use super::CocoError;

/// A whole `panoptic_<split>.json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PanopticDataset {
    /// The instance file's `info`, unchanged.
    pub info: Info,
    pub licenses: Vec<License>,
    /// The instance file's image records, unchanged (same ids, file names and extension keys).
    pub images: Vec<Image>,
    /// One per image, in image order.
    pub annotations: Vec<PanopticAnnotation>,
    pub categories: Vec<PanopticCategory>,
}

/// `annotations[]`: the segments of one image.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PanopticAnnotation {
    pub image_id: u64,
    /// The segment PNG, relative to the `panoptic_<split>/` folder: `<area>/<camera>/<frame>.png`.
    pub file_name: String,
    pub segments_info: Vec<SegmentInfo>,
}

/// `segments_info[]`: one segment.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SegmentInfo {
    /// The segment id in the PNG (R + 256·G + 256²·B): the instance annotation's id.
    pub id: u32,
    pub category_id: u32,
    /// Pixel count.
    pub area: u64,
    /// `[x, y, width, height]`, pixels.
    pub bbox: [f64; 4],
    /// 0, or 1 for instances the COCO export flagged (`--truncated flag`).
    pub iscrowd: u8,
    /// Extension: the building ID (as in the ID maps and `buildings.json`).
    pub building_id: BuildingId,
    /// Extension: the building's source identity.
    pub source_id: String,
}

/// `categories[]` of a panoptic file.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct PanopticCategory {
    pub id: u32,
    pub name: String,
    pub supercategory: String,
    /// 1 for countable objects ("things"), 0 for amorphous regions ("stuff").
    pub isthing: u8,
    /// Display colour (the panoptic API's visualisation reads it).
    pub color: [u8; 3],
}

/// The panoptic API's encoding of a segment id as a pixel: R = bits 0–7, G = bits 8–15, B = bits 16–23
/// (`panopticapi.utils.id2rgb`).
pub fn id_to_rgb(id: u32) -> [u8; 3] {
    [id as u8, (id >> 8) as u8, (id >> 16) as u8]
}

/// The segment id of a panoptic pixel (`panopticapi.utils.rgb2id`: R + 256·G + 256²·B).
pub fn rgb_to_id(rgb: [u8; 3]) -> u32 {
    rgb[0] as u32 | (rgb[1] as u32) << 8 | (rgb[2] as u32) << 16
}

/// What `export-panoptic` reads and writes.
#[derive(Debug, Clone)]
pub struct PanopticPlan {
    /// The `export-coco` output directory (instance files).
    pub coco_dir: PathBuf,
    /// Where `panoptic_<split>.json` and `panoptic_<split>/` go.
    pub out_dir: PathBuf,
}

/// Counts of one split, for the summary.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct PanopticSplitSummary {
    pub split: String,
    pub images: u64,
    pub segments: u64,
    /// The JSON file written.
    pub file: PathBuf,
}

/// Writes the panoptic export of every split present in `plan.coco_dir`; returns one summary per split.
///
/// Every PNG and JSON is written atomically; the JSON of a split is written after all its PNGs.
///
/// # Errors
/// See [`read_splits`] and [`load_frame`]; [`CocoError::Invalid`] when an annotation id does not fit
/// 24 bits; [`CocoError::PngEncode`] / [`CocoError::File`] naming the file that could not be written;
/// [`CocoError::Interrupted`] after Ctrl-C.
pub fn export_panoptic(
    plan: &PanopticPlan,
    progress: &dyn Progress,
) -> Result<Vec<PanopticSplitSummary>, CocoError> {
    let splits = read_splits(&plan.coco_dir)?;
    let total: usize = splits.iter().map(|s| s.dataset.images.len()).sum();
    progress.start(total as u64, "frames");
    let mut out = Vec::new();
    for s in &splits {
        out.push(export_split(s, &plan.out_dir, progress)?);
    }
    progress.finish();
    Ok(out)
}

fn export_split(
    s: &ExportSplit,
    out_dir: &Path,
    progress: &dyn Progress,
) -> Result<PanopticSplitSummary, CocoError> {
    if let Some(a) = s.dataset.annotations.iter().find(|a| a.id > MAX_BUILDING_ID as u64) {
        return Err(CocoError::Invalid {
            path: s.file.clone(),
            problems: vec![format!(
                "annotations[id={}]: more than 2^24 - 1 annotations in one split do not fit panoptic \
                 segment ids; split the export (`insgen export-coco --holdout`)",
                a.id
            )],
        });
    }
    let png_dir = out_dir.join(format!("panoptic_{}", s.split));
    let frames = s.annotations_by_image();
    let annotations: Vec<PanopticAnnotation> = frames
        .par_iter()
        .map(|(image, anns)| {
            crate::util::interrupt::check()?;
            let ann = write_frame(s, image, anns, &png_dir)?;
            progress.inc(1);
            Ok(ann)
        })
        .collect::<Result<_, CocoError>>()?;
    let segments = annotations.iter().map(|a| a.segments_info.len() as u64).sum();
    let ds = PanopticDataset {
        info: s.dataset.info.clone(),
        licenses: s.dataset.licenses.clone(),
        images: s.dataset.images.clone(),
        annotations,
        categories: vec![PanopticCategory {
            id: BUILDING_CATEGORY_ID,
            name: "building".into(),
            supercategory: "building".into(),
            isthing: 1,
            color: [220, 20, 60],
        }],
    };
    let file = out_dir.join(format!("panoptic_{}.json", s.split));
    crate::util::write_json_atomic(&file, &ds)?;
    Ok(PanopticSplitSummary { split: s.split.to_string(), images: ds.images.len() as u64, segments, file })
}

/// The segment PNG of one image (written) and its annotation record.
fn write_frame(
    s: &ExportSplit,
    image: &Image,
    anns: &[&super::format::Annotation],
    png_dir: &Path,
) -> Result<PanopticAnnotation, CocoError> {
    let frame = load_frame(s, image, anns)?;
    let w = image.width as usize;
    let mut rgb = vec![0u8; w * image.height as usize * 3];
    let mut segments_info = Vec::with_capacity(frame.annotations.len());
    for (a, rle) in &frame.annotations {
        // Checked by the caller: every annotation id of the split is below 2^24.
        let id = a.id as u32;
        let px = id_to_rgb(id);
        let mut overlap = None;
        for_each_pixel(rle, |x, y| {
            let o = (y as usize * w + x as usize) * 3;
            if rgb[o..o + 3] != [0, 0, 0] {
                overlap.get_or_insert((x, y));
            }
            rgb[o..o + 3].copy_from_slice(&px);
        });
        if let Some((x, y)) = overlap {
            return Err(CocoError::Invalid {
                path: s.file.clone(),
                problems: vec![format!(
                    "annotations[id={}]: overlaps another annotation of image {} at ({x}, {y}); panoptic \
                     segments cannot overlap",
                    a.id, image.id
                )],
            });
        }
        segments_info.push(SegmentInfo {
            id,
            category_id: a.category_id,
            area: a.area,
            bbox: a.bbox,
            iscrowd: a.iscrowd,
            building_id: a.building_id,
            source_id: a.source_id.clone(),
        });
    }
    let file_name = format!("{}/{}/{}.png", image.area_name, image.camera, image.frame);
    let path = png_dir.join(&file_name);
    let bytes = super::raster::encode_png_rgb(&rgb, image.width, image.height, &path)?;
    crate::util::write_bytes_atomic(&path, &bytes)?;
    Ok(PanopticAnnotation { image_id: image.id, file_name, segments_info })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ids_round_trip_in_the_panoptic_byte_order() {
        // panopticapi: rgb2id([1, 0, 0]) = 1, rgb2id([0, 0, 1]) = 65536.
        assert_eq!(id_to_rgb(1), [1, 0, 0]);
        assert_eq!(rgb_to_id([0, 0, 1]), 65_536);
        for id in [0, 1, 255, 256, 65_535, 65_536, 0x12_34_56, MAX_BUILDING_ID] {
            assert_eq!(rgb_to_id(id_to_rgb(id)), id);
        }
        // The opposite of the ID maps' order (R = high byte).
        let b = BuildingId::new(0x01_02_03).unwrap();
        assert_eq!(b.to_rgb(), [1, 2, 3]);
        assert_eq!(id_to_rgb(b.get()), [3, 2, 1]);
    }
}
