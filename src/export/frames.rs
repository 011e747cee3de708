//! The frames of an existing COCO export, read back for the formats derived from it (panoptic, YOLO).
//!
//! Takes in what `export-coco` wrote — `instances_{train,val,test}.json` in one directory — and, for each
//! image record, the instance-ID map its `mask_file` names (relative to `info.image_root`, itself
//! relative to the COCO directory). Hands on, per image, its annotations with their exact masks
//! (the RLE of `segmentation`, or of `mask_rle` when the export wrote polygons), each checked against
//! the ID map: every pixel of an annotation's mask holds the annotation's `building_id`, its pixel count
//! is `area` and its box is `bbox`. The derived formats therefore describe the same images, the same
//! instances and the same pixels as the COCO files, filters included, and a stale COCO file (masks
//! re-rendered since) is an error naming both files rather than a silently different dataset.

use std::path::{Path, PathBuf};

use crate::scene::IdMap;

use super::coco::{read_json, Split};
use super::error::{LayoutProblem, MismatchProblem};
use super::format::{Annotation, Dataset, Image, Segmentation};
use super::rle::Rle;
use super::CocoError;

/// One split file of a COCO export.
#[derive(Debug, Clone)]
pub struct ExportSplit {
    /// The split.
    pub split: Split,
    /// `instances_<split>.json`.
    pub file: PathBuf,
    /// The file's contents.
    pub dataset: Dataset,
    /// The directory `images[].file_name` and `mask_file` are relative to.
    pub image_root: PathBuf,
}

impl ExportSplit {
    /// The annotations of every image, in image order (annotation order kept within an image).
    pub fn annotations_by_image(&self) -> Vec<(&Image, Vec<&Annotation>)> {
        annotations_by_image(&self.dataset)
    }
}

/// The annotations of every image of `ds`, in image order (annotation order kept within an image).
pub fn annotations_by_image(ds: &Dataset) -> Vec<(&Image, Vec<&Annotation>)> {
    let mut by_id: std::collections::HashMap<u64, Vec<&Annotation>> = std::collections::HashMap::new();
    for a in &ds.annotations {
        by_id.entry(a.image_id).or_default().push(a);
    }
    ds.images.iter().map(|im| (im, by_id.remove(&im.id).unwrap_or_default())).collect()
}

/// Reads the split files present in `coco_dir` (at least one), in [`Split::ALL`] order.
///
/// # Errors
/// [`CocoError::Layout`] when none is there (with the command that writes them), [`CocoError::File`] /
/// [`CocoError::Json`] for a file that cannot be read or parsed.
pub fn read_splits(coco_dir: &Path) -> Result<Vec<ExportSplit>, CocoError> {
    let mut out = Vec::new();
    for split in Split::ALL {
        let file = coco_dir.join(split.file_name());
        if !file.is_file() {
            continue;
        }
        let dataset: Dataset = read_json(&file)?;
        let root = Path::new(&dataset.info.image_root);
        let image_root = if root.is_absolute() { root.to_path_buf() } else { coco_dir.join(root) };
        out.push(ExportSplit { split, file, dataset, image_root });
    }
    if out.is_empty() {
        return Err(CocoError::Layout { path: coco_dir.to_path_buf(), problem: LayoutProblem::NoSplits });
    }
    Ok(out)
}

/// An image with its ID map and its annotations' masks, all checked against each other.
#[derive(Debug)]
pub struct VerifiedFrame<'a> {
    /// The image.
    pub image: &'a Image,
    /// Its ID map.
    pub ids: IdMap,
    /// Each annotation with its exact mask.
    pub annotations: Vec<(&'a Annotation, Rle)>,
}

/// Calls `f(x, y)` for every pixel of `rle` (column-major runs, as COCO stores them).
pub fn for_each_pixel(rle: &Rle, mut f: impl FnMut(u32, u32)) {
    let h = rle.height() as u64;
    if h == 0 {
        return;
    }
    let mut pos = 0u64;
    for (k, &c) in rle.counts.iter().enumerate() {
        if k % 2 == 1 {
            for p in pos..pos + c as u64 {
                f((p / h) as u32, (p % h) as u32);
            }
        }
        pos += c as u64;
    }
}

/// Loads `image`'s ID map and checks `annotations` (those of this image) against it.
///
/// # Errors
/// [`CocoError::Ids`] for an unreadable ID map, [`CocoError::Rle`] for a malformed RLE,
/// [`CocoError::Mismatch`] naming the COCO file and the ID map when a mask's size, pixels, area or box
/// disagree with the ID map or the annotation.
pub fn load_frame<'a>(
    split: &ExportSplit,
    image: &'a Image,
    annotations: &[&'a Annotation],
) -> Result<VerifiedFrame<'a>, CocoError> {
    let id_path = split.image_root.join(&image.mask_file);
    let ids = IdMap::read_png(&id_path)?;
    let mismatch = |problem: MismatchProblem| CocoError::Mismatch {
        instances: split.file.clone(),
        id_map: id_path.clone(),
        problem: Box::new(problem),
    };
    if (ids.width(), ids.height()) != (image.width, image.height) {
        return Err(mismatch(MismatchProblem::ImageSize {
            image_id: image.id,
            listed: [image.width, image.height],
            id_map: [ids.width(), ids.height()],
        }));
    }
    let mut out = Vec::with_capacity(annotations.len());
    for &a in annotations {
        let json = match (&a.segmentation, &a.mask_rle) {
            (Segmentation::Rle(r), _) | (Segmentation::Polygons(_), Some(r)) => r,
            (Segmentation::Polygons(_), None) => {
                return Err(mismatch(MismatchProblem::NoExactMask { annotation_id: a.id }))
            }
        };
        let rle = json.to_rle().map_err(|source| CocoError::Rle {
            path: split.file.clone(),
            context: format!("annotations[id={}]", a.id),
            source,
        })?;
        if rle.size != [image.height, image.width] {
            return Err(mismatch(MismatchProblem::RleSize {
                annotation_id: a.id,
                rle_size: rle.size,
                image_size: [image.height, image.width],
            }));
        }
        let mut wrong = 0u64;
        let mut first_wrong = None;
        for_each_pixel(&rle, |x, y| {
            if ids.get(x, y) != a.building_id {
                wrong += 1;
                first_wrong.get_or_insert((x, y));
            }
        });
        if let Some((x, y)) = first_wrong {
            return Err(mismatch(MismatchProblem::ForeignPixels {
                annotation_id: a.id,
                building_id: a.building_id,
                wrong_px: wrong,
                first: [x, y],
                first_found: ids.get(x, y),
            }));
        }
        if rle.area() != a.area || rle.to_bbox() != a.bbox {
            return Err(mismatch(MismatchProblem::AreaBox {
                annotation_id: a.id,
                area: a.area,
                bbox: a.bbox,
                mask_area: rle.area(),
                mask_bbox: rle.to_bbox(),
            }));
        }
        out.push((a, rle));
    }
    Ok(VerifiedFrame { image, ids, annotations: out })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pixels_of_an_rle_are_visited_column_major() {
        // 3×2 (h × w) image, pixels (x=0,y=1), (x=1,y=0), (x=1,y=1): column-major positions 1, 3, 4.
        let rle = Rle::from_counts([3, 2], vec![1, 1, 1, 2, 1]).unwrap();
        let mut seen = Vec::new();
        for_each_pixel(&rle, |x, y| seen.push((x, y)));
        assert_eq!(seen, [(0, 1), (1, 0), (1, 1)]);
    }
}
