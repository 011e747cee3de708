//! `export-panoptic`: the COCO instance export as COCO panoptic segmentation.
//!
//! Takes in an `export-coco` output directory ([`super::frames`]: the instance files and, through each
//! image's `mask_file`, the ID maps). Hands on, per split present:
//! - `panoptic_<split>/<area>/<camera>/<frame>.png`: 8-bit RGB, one segment id per pixel in the
//!   encoding of the COCO panoptic API (`panopticapi.utils.rgb2id`): id = R + 256·G + 256²·B — the byte
//!   order opposite to insgen's ID maps (R = high byte), so the ID maps are not panoptic PNGs as they are;
//! - `panoptic_<split>.json`: `info`, `licenses`, `images` (the instance file's records, unchanged),
//!   `annotations` (one per image: `image_id`, `file_name`, `segments_info`) and `categories`
//!   (`building`: id 1, `isthing` = 1; `background`: id 2, `isthing` = 0).
//!
//! Segment ids of buildings are the ids of the instance annotations (`instances_<split>.json`
//! `annotations[].id`, unique in the file and < 2²⁴ − 1), not the building IDs: a building seen as two
//! components under the default per-component export is two annotations, hence two segments. Each
//! such segment carries the extension keys `building_id` and `source_id`. The crowd annotations of an
//! image (`export-coco --truncated flag`) are merged into one crowd segment (`iscrowd` = 1, id = the
//! first of them, extension key `annotation_ids`), as COCO panoptic does: `pq_compute` keeps one crowd
//! region per category and image. Every pixel where the ID map shows no building is one `background` segment with id
//! 2²⁴ − 1 (white): the panoptic API's PQ averages over stuff categories too and divides by zero
//! without one (`pq_average`), and so does Detectron2's evaluator, which calls it. Pixels of buildings
//! whose instances the export's filters removed are 0, "void", ignored in PQ.
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
    /// As in the COCO instance file.
    pub licenses: Vec<License>,
    /// The instance file's image records, unchanged (same ids, file names and extension keys).
    pub images: Vec<Image>,
    /// One per image, in image order.
    pub annotations: Vec<PanopticAnnotation>,
    /// `building` and the background category.
    pub categories: Vec<PanopticCategory>,
}

/// `annotations[]`: the segments of one image.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PanopticAnnotation {
    /// The image's id (as in the COCO instance file).
    pub image_id: u64,
    /// The segment PNG, relative to the `panoptic_<split>/` folder: `<area>/<camera>/<frame>.png`.
    pub file_name: String,
    /// The segments of the PNG.
    pub segments_info: Vec<SegmentInfo>,
}

/// `segments_info[]`: one segment.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SegmentInfo {
    /// The segment id in the PNG (R + 256·G + 256²·B): the instance annotation's id.
    pub id: u32,
    /// The segment's category.
    pub category_id: u32,
    /// Pixel count.
    pub area: u64,
    /// `[x, y, width, height]`, pixels.
    pub bbox: [f64; 4],
    /// 0, or 1 for the merged instances the COCO export flagged (`--truncated flag`).
    pub iscrowd: u8,
    /// Extension: the building ID (as in the ID maps and `buildings.json`); absent for background.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub building_id: Option<BuildingId>,
    /// Extension: the building's source identity; absent for background.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub source_id: Option<String>,
    /// Extension, crowd segment only: the instance annotations merged into it (its `id` is the first).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub annotation_ids: Option<Vec<u64>>,
}

/// The stuff category of every pixel without a building.
pub const BACKGROUND_CATEGORY_ID: u32 = 2;
/// The segment id of the background segment: 2²⁴ − 1 (white in the PNG), above every annotation id.
pub const BACKGROUND_SEGMENT_ID: u32 = MAX_BUILDING_ID;

/// `categories[]` of a panoptic file.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct PanopticCategory {
    /// Category id.
    pub id: u32,
    /// Category name.
    pub name: String,
    /// Its supercategory.
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
    /// `train`, `val` or `test`.
    pub split: String,
    /// Images written.
    pub images: u64,
    /// Segments written.
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
    if let Some(a) = s.dataset.annotations.iter().find(|a| a.id >= BACKGROUND_SEGMENT_ID as u64) {
        return Err(CocoError::Invalid {
            path: s.file.clone(),
            problems: vec![format!(
                "annotations[id={}]: 2^24 - 2 or more annotations in one split do not fit panoptic \
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
        categories: vec![
            PanopticCategory {
                id: BUILDING_CATEGORY_ID,
                name: "building".into(),
                supercategory: "building".into(),
                isthing: 1,
                color: [220, 20, 60],
            },
            PanopticCategory {
                id: BACKGROUND_CATEGORY_ID,
                name: "background".into(),
                supercategory: "background".into(),
                isthing: 0,
                color: [128, 128, 128],
            },
        ],
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
    let mut segments_info = Vec::with_capacity(frame.annotations.len() + 2);
    // All crowd annotations of the image form one segment, as in COCO panoptic: pq_compute keeps one
    // crowd segment per category and image, and would count predictions over a second one as false.
    let crowd: Vec<u64> =
        frame.annotations.iter().filter(|(a, _)| a.iscrowd != 0).map(|(a, _)| a.id).collect();
    let mut crowd_px = PixelBox::default();
    for (a, rle) in &frame.annotations {
        // Checked by the caller: every annotation id of the split is below 2^24 - 1.
        let id = if a.iscrowd != 0 { crowd[0] as u32 } else { a.id as u32 };
        let px = id_to_rgb(id);
        let mut overlap = None;
        for_each_pixel(rle, |x, y| {
            let o = (y as usize * w + x as usize) * 3;
            if rgb[o..o + 3] != [0, 0, 0] {
                overlap.get_or_insert((x, y));
            }
            rgb[o..o + 3].copy_from_slice(&px);
            if a.iscrowd != 0 {
                crowd_px.add(x, y);
            }
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
        if a.iscrowd == 0 {
            segments_info.push(SegmentInfo {
                id,
                category_id: a.category_id,
                area: a.area,
                bbox: a.bbox,
                iscrowd: 0,
                building_id: Some(a.building_id),
                source_id: Some(a.source_id.clone()),
                annotation_ids: None,
            });
        }
    }
    if crowd_px.area > 0 {
        segments_info.push(SegmentInfo {
            id: crowd[0] as u32,
            category_id: BUILDING_CATEGORY_ID,
            area: crowd_px.area,
            bbox: crowd_px.bbox(),
            iscrowd: 1,
            building_id: None,
            source_id: None,
            annotation_ids: Some(crowd),
        });
    }
    // Background: every pixel without a building (the annotations cover building pixels only, checked
    // by `load_frame`).
    let mut bg_px = PixelBox::default();
    let bg = id_to_rgb(BACKGROUND_SEGMENT_ID);
    for (i, id) in frame.ids.raw().iter().enumerate() {
        if *id == 0 {
            rgb[i * 3..i * 3 + 3].copy_from_slice(&bg);
            bg_px.add((i % w) as u32, (i / w) as u32);
        }
    }
    if bg_px.area > 0 {
        segments_info.push(SegmentInfo {
            id: BACKGROUND_SEGMENT_ID,
            category_id: BACKGROUND_CATEGORY_ID,
            area: bg_px.area,
            bbox: bg_px.bbox(),
            iscrowd: 0,
            building_id: None,
            source_id: None,
            annotation_ids: None,
        });
    }
    let file_name = format!("{}/{}/{}.png", image.area_name, image.camera, image.frame);
    let path = png_dir.join(&file_name);
    let bytes = super::raster::encode_png_rgb(&rgb, image.width, image.height, &path)?;
    crate::util::write_bytes_atomic(&path, &bytes)?;
    Ok(PanopticAnnotation { image_id: image.id, file_name, segments_info })
}

/// Pixel count and bounding box of a set of pixels, accumulated one pixel at a time.
#[derive(Debug, Clone, Copy)]
struct PixelBox {
    area: u64,
    x0: u32,
    y0: u32,
    x1: u32,
    y1: u32,
}

impl Default for PixelBox {
    fn default() -> Self {
        PixelBox { area: 0, x0: u32::MAX, y0: u32::MAX, x1: 0, y1: 0 }
    }
}

impl PixelBox {
    fn add(&mut self, x: u32, y: u32) {
        self.area += 1;
        (self.x0, self.y0, self.x1, self.y1) =
            (self.x0.min(x), self.y0.min(y), self.x1.max(x), self.y1.max(y));
    }

    /// `[x, y, width, height]` in pixels (COCO); zeros when empty.
    fn bbox(&self) -> [f64; 4] {
        if self.area == 0 {
            return [0.0; 4];
        }
        [self.x0 as f64, self.y0 as f64, (self.x1 - self.x0 + 1) as f64, (self.y1 - self.y0 + 1) as f64]
    }
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
