//! The Hugging Face `datasets` view of a self-contained COCO export: `images/<split>/metadata.jsonl`
//! beside the photos, and the `configs:` block of the dataset card's YAML front matter that names them.
//!
//! Takes in a self-contained `export-coco` folder ([`super::bundle`]: the photos at
//! `images/<split>/<area>/<camera>/<frame>.png`) and hands on, per split with images,
//! `images/<split>/metadata.jsonl` ([`crate::layout::ExportDir::hf_metadata`]): one JSON object per
//! photo, in the `imagefolder` loader's layout (`file_name` relative to the metadata file, the other
//! keys become columns). The card (`README.md`) opens with YAML front matter whose `configs:` lists,
//! per split, the files of `images/<split>/` ([`front_matter`]), which is what `datasets` reads to find
//! a folder's splits: `datasets.load_dataset("<export>")` loads the splits `train`, `validation` (the
//! folder `val`) and `test`, each row the decoded photo and its instances. `objects` holds, per
//! instance, `id`, `bbox` (`[x, y, width, height]`, pixels), `category_id`, `area` (pixels), `iscrowd`,
//! `building_id` and `segmentation` (the exact mask as compressed COCO RLE, `{size: [height, width],
//! counts}`, for `pycocotools.mask.decode`; the polygons of a `--polygons` export are not repeated).
//! The photos are the export's own files: nothing is copied.
//!
//! `export-coco` writes both for every self-contained export that is not label-only
//! ([`write_metadata`]); `export-hf` ([`export_hf`]) rewrites them from the COCO files, for an export
//! made by an older insgen.
//!
//! # References
//! Hugging Face `datasets`, "Create an image dataset" (ImageFolder, metadata.jsonl) and "Manual
//! configuration" (the dataset card's `configs` with `data_files` per split).

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use super::error::LayoutProblem;

use serde::Serialize;

use crate::layout::ExportDir;

use super::coco::Split;
use super::format::{Annotation, Dataset, Image, RleJson, Segmentation};
use super::frames::read_splits;
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
/// the file of a split left without images), then the `configs:` front matter of the dataset card
/// (`README.md`, when there is one) for the splits written.
///
/// # Errors
/// See [`read_splits`]; [`CocoError::Layout`] for an export that is not self-contained (made with
/// `--link-root`, or by an older insgen) or a photo that is not on disk; [`CocoError::Rle`] for a
/// malformed mask; [`CocoError::File`] naming a file that could not be read or written.
pub fn export_hf(plan: &HfPlan) -> Result<Vec<HfSplitSummary>, CocoError> {
    let export = ExportDir::new(&plan.coco_dir);
    let mut out = Vec::new();
    for s in read_splits(&plan.coco_dir)? {
        let files =
            SplitFiles { split: s.split, file: &s.file, dataset: &s.dataset, image_root: &s.image_root };
        out.push(write_split(&export, &files)?);
    }
    let card = export.card();
    if card.is_file() {
        let text =
            std::fs::read_to_string(&card).map_err(|e| crate::util::FileError::new("reading", &card, e))?;
        let updated = with_front_matter(&text, &loadable_splits(&out));
        if updated != text {
            crate::util::write_bytes_atomic(&card, updated.as_bytes())?;
        }
    }
    Ok(out)
}

/// Writes `images/<split>/metadata.jsonl` in the self-contained export `out_dir` for `datasets` as
/// they are written there (`instances_<split>.json`, names relative to `out_dir`), as [`export_hf`]
/// does but from the datasets in memory, and leaves the card to its writer.
///
/// # Errors
/// As [`export_hf`].
pub fn write_metadata(
    out_dir: &Path,
    datasets: &[(Split, Dataset)],
) -> Result<Vec<HfSplitSummary>, CocoError> {
    let export = ExportDir::new(out_dir);
    datasets
        .iter()
        .map(|(split, ds)| {
            let file = export.instances(split.as_str());
            write_split(&export, &SplitFiles { split: *split, file: &file, dataset: ds, image_root: out_dir })
        })
        .collect()
}

/// The splits `datasets` can load (a metadata file was written), in [`Split::ALL`] order.
pub fn loadable_splits(summaries: &[HfSplitSummary]) -> Vec<Split> {
    Split::ALL
        .into_iter()
        .filter(|s| summaries.iter().any(|x| x.split == s.as_str() && x.file.is_some()))
        .collect()
}

/// The name `datasets` gives a split: `validation` for `val` (as its `imagefolder` loader names a
/// folder `val`), the others as they are.
pub fn split_name(split: Split) -> &'static str {
    match split {
        Split::Val => "validation",
        other => other.as_str(),
    }
}

/// The dataset card's YAML front matter for `splits` (none: no front matter): one `configs:` entry
/// whose `data_files` name, per split, the files of `images/<split>/` (the photos and
/// `metadata.jsonl`), so that `datasets.load_dataset("<export>")` needs no other argument.
pub fn front_matter(splits: &[Split]) -> String {
    if splits.is_empty() {
        return String::new();
    }
    let mut s = String::from(
        "---\n# Hugging Face datasets: load_dataset(\"<this folder>\") reads the splits below (photos and \
         their instances,\n# images/<split>/metadata.jsonl).\nconfigs:\n- config_name: default\n  data_files:\n",
    );
    for split in splits {
        let dir = ExportDir::split_images_name(split.as_str());
        let _ = write!(s, "  - split: {}\n    path: {dir}/**\n", split_name(*split));
    }
    s.push_str("---\n\n");
    s
}

/// `card` with its YAML front matter (a first line `---` up to the next line `---`, and the empty
/// line after it) replaced by [`front_matter`] of `splits`.
pub fn with_front_matter(card: &str, splits: &[Split]) -> String {
    let body = card
        .strip_prefix("---\n")
        .and_then(|rest| rest.find("\n---\n").map(|end| &rest[end + 5..]))
        .map(|body| body.strip_prefix('\n').unwrap_or(body))
        .unwrap_or(card);
    format!("{}{body}", front_matter(splits))
}

/// The files of one split as [`write_split`] reads them.
struct SplitFiles<'a> {
    split: Split,
    /// `instances_<split>.json` (named in errors).
    file: &'a Path,
    dataset: &'a Dataset,
    /// The directory `images[].file_name` are relative to.
    image_root: &'a Path,
}

/// Writes the metadata of one split (or removes it when the split has no image).
fn write_split(export: &ExportDir, s: &SplitFiles) -> Result<HfSplitSummary, CocoError> {
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
        return Ok(sum);
    }
    let mut text = String::new();
    for (image, anns) in super::frames::annotations_by_image(s.dataset) {
        let row = row(s, export, image, &anns)?;
        sum.objects += row.objects.id.len() as u64;
        sum.rows += 1;
        text.push_str(&serde_json::to_string(&row).map_err(|e| CocoError::json(&path, e))?);
        text.push('\n');
    }
    crate::util::write_bytes_atomic(&path, text.as_bytes())?;
    sum.file = Some(path);
    Ok(sum)
}

/// The row of one image, checking that its photo lies in `images/<split>/` of the export.
fn row(s: &SplitFiles, export: &ExportDir, image: &Image, anns: &[&Annotation]) -> Result<HfRow, CocoError> {
    let prefix = ExportDir::split_images_name(s.split.as_str());
    let prefix = prefix.as_str();
    let inside = image.file_name.strip_prefix(prefix).and_then(|r| r.strip_prefix('/'));
    let same_root = s.image_root.canonicalize().ok() == export.dir().canonicalize().ok();
    let Some(file_name) = inside.filter(|_| same_root) else {
        return Err(CocoError::Layout {
            path: s.file.to_path_buf(),
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
                    path: s.file.to_path_buf(),
                    problem: LayoutProblem::PolygonsWithoutRle { annotation_id: a.id },
                })
            }
        };
        let rle = json.to_rle().map_err(|source| CocoError::Rle {
            path: s.file.to_path_buf(),
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
