//! `export-hf`: a self-contained COCO export as a Hugging Face `datasets` image folder.
//!
//! Takes in a self-contained `export-coco` folder ([`super::bundle`]: the photos at
//! `images/<split>/<area>/<camera>/<frame>.png`) and hands on, per split with images,
//! `images/<split>/metadata.jsonl` ([`crate::layout::ExportDir::hf_metadata`]): one JSON object per
//! photo, in the `imagefolder` loader's layout (`file_name` relative to the metadata file, the other
//! keys become columns), so that
//! `datasets.load_dataset("imagefolder", data_dir="<export>/images")` loads the splits `train`,
//! `validation` (from the folder `val`) and `test`, each row the decoded photo and its instances:
//! `objects` holds, per instance, `id`, `bbox` (`[x, y, width, height]`, pixels), `category_id`,
//! `area` (pixels), `iscrowd`, `building_id` and `segmentation` (the exact mask as compressed COCO RLE,
//! `{size: [height, width], counts}`, for `pycocotools.mask.decode`; the polygons of a `--polygons`
//! export are not repeated). The photos are the export's own files: nothing is copied.
//!
//! # References
//! Hugging Face `datasets`, "Create an image dataset" (ImageFolder, metadata.jsonl).

use super::error::LayoutProblem;
use std::path::PathBuf;

use serde::Serialize;

use crate::layout::ExportDir;

use super::format::{Annotation, Image, RleJson, Segmentation};
use super::frames::{read_splits, ExportSplit};
use super::CocoError;

/// What `export-hf` reads and writes: the export folder, in place.
#[derive(Debug, Clone)]
pub struct HfPlan {
    /// The self-contained `export-coco` output directory.
    pub coco_dir: PathBuf,
}

/// One line of `metadata.jsonl`: a photo and its instances.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct HfRow {
    /// The photo, relative to `images/<split>/`: `<area>/<camera>/<frame>.png`.
    pub file_name: String,
    /// The COCO image id (`instances_<split>.json`).
    pub image_id: u64,
    /// Pixels.
    pub width: u32,
    /// Pixels.
    pub height: u32,
    /// The area the photo was taken in.
    pub area_name: String,
    /// The camera (preset) that took it.
    pub camera: String,
    /// The frame's name in the camera's `poses.jsonl`.
    pub frame: String,
    /// The photo's instances.
    pub objects: HfObjects,
}

/// The instances of a photo, one list per key (the layout `datasets` gives object annotations).
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct HfObjects {
    /// COCO annotation ids.
    pub id: Vec<u64>,
    /// `[x, y, width, height]`, pixels.
    pub bbox: Vec<[f64; 4]>,
    /// COCO category ids, as in the COCO file.
    pub category_id: Vec<u32>,
    /// Pixels.
    pub area: Vec<u64>,
    /// COCO `iscrowd` flags, as in the COCO file.
    pub iscrowd: Vec<u8>,
    /// The buildings' 24-bit instance IDs.
    pub building_id: Vec<crate::scene::BuildingId>,
    /// The exact masks, compressed COCO RLE.
    pub segmentation: Vec<RleJson>,
}

/// Counts of one split.
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize)]
pub struct HfSplitSummary {
    /// The split: train, val or test.
    pub split: String,
    /// Rows (photos) written.
    pub rows: u64,
    /// Instances over all rows.
    pub objects: u64,
    /// The metadata file (`None` for a split without images: no file, `datasets` sees no split).
    pub file: Option<PathBuf>,
}

/// Writes `images/<split>/metadata.jsonl` for every split of `plan.coco_dir` with images (and removes
/// the file of a split left without images).
///
/// # Errors
/// See [`read_splits`]; [`CocoError::Layout`] for an export that is not self-contained (made with
/// `--link-root`, or by an older insgen) or a photo that is not on disk; [`CocoError::Rle`] for a
/// malformed mask; [`CocoError::File`] naming a file that could not be written.
pub fn export_hf(plan: &HfPlan) -> Result<Vec<HfSplitSummary>, CocoError> {
    let export = ExportDir::new(&plan.coco_dir);
    let mut out = Vec::new();
    for s in read_splits(&plan.coco_dir)? {
        let split = s.split.as_str();
        let path = export.hf_metadata(split);
        let mut sum = HfSplitSummary { split: split.to_string(), ..Default::default() };
        if s.dataset.images.is_empty() {
            match std::fs::remove_file(&path) {
                Err(e) if e.kind() != std::io::ErrorKind::NotFound => {
                    return Err(crate::util::FileError::new("removing", &path, e).into())
                }
                _ => {}
            }
            out.push(sum);
            continue;
        }
        let mut text = String::new();
        for (image, anns) in s.annotations_by_image() {
            let row = row(&s, &export, image, &anns)?;
            sum.objects += row.objects.id.len() as u64;
            sum.rows += 1;
            text.push_str(&serde_json::to_string(&row).map_err(|e| CocoError::json(&path, e))?);
            text.push('\n');
        }
        crate::util::write_bytes_atomic(&path, text.as_bytes())?;
        sum.file = Some(path);
        out.push(sum);
    }
    Ok(out)
}

/// The row of one image, checking that its photo lies in `images/<split>/` of the export.
fn row(s: &ExportSplit, export: &ExportDir, image: &Image, anns: &[&Annotation]) -> Result<HfRow, CocoError> {
    let prefix = ExportDir::image_name(s.split.as_str(), "", "", "");
    let prefix = prefix.trim_end_matches('/');
    let inside = image.file_name.strip_prefix(prefix).and_then(|r| r.strip_prefix('/'));
    let same_root = s.image_root.canonicalize().ok() == export.dir().canonicalize().ok();
    let Some(file_name) = inside.filter(|_| same_root) else {
        return Err(CocoError::Layout {
            path: s.file.clone(),
            problem: LayoutProblem::NotSelfContained {
                image_id: image.id,
                file_name: image.file_name.clone(),
                folder: prefix.to_string(),
            },
        });
    };
    if !s.image_root.join(&image.file_name).is_file() {
        return Err(CocoError::Layout {
            path: s.image_root.join(&image.file_name),
            problem: LayoutProblem::MissingPhoto,
        });
    }
    let mut objects = HfObjects::default();
    for a in anns {
        let json = match (&a.segmentation, &a.mask_rle) {
            (_, Some(rle)) | (Segmentation::Rle(rle), None) => rle,
            (Segmentation::Polygons(_), None) => {
                return Err(CocoError::Layout {
                    path: s.file.clone(),
                    problem: LayoutProblem::PolygonsWithoutRle { annotation_id: a.id },
                })
            }
        };
        let rle = json.to_rle().map_err(|source| CocoError::Rle {
            path: s.file.clone(),
            context: format!("annotation {}", a.id),
            source,
        })?;
        objects.id.push(a.id);
        objects.bbox.push(a.bbox);
        objects.category_id.push(a.category_id);
        objects.area.push(a.area);
        objects.iscrowd.push(a.iscrowd);
        objects.building_id.push(a.building_id);
        objects.segmentation.push(RleJson::from(&rle));
    }
    Ok(HfRow {
        file_name: file_name.to_string(),
        image_id: image.id,
        width: image.width,
        height: image.height,
        area_name: image.area_name.clone(),
        camera: image.camera.clone(),
        frame: image.frame.clone(),
        objects,
    })
}
