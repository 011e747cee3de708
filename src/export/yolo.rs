//! `export-yolo`: the COCO instance export as an Ultralytics YOLO segmentation dataset.
//!
//! Takes in an `export-coco` output directory ([`super::frames`]: the instance files and, through each
//! image's `mask_file`, the ID maps, checked against each other). Hands on, under the output directory:
//! - `images/<split>/<area>/<camera>/<frame>.<ext>`: the image the COCO file names (`file_name`), as a
//!   hard link (a copy across file systems), so that the folder holds its images; it sits there since
//!   Ultralytics finds a label by replacing the last `/images/` of the image path by `/labels/`;
//! - `labels/<split>/<area>/<camera>/<frame>.txt`: one line per instance, `0 x1 y1 x2 y2 …` (class 0 =
//!   building), the polygon's vertices normalised by the image width and height to [0, 1] and written
//!   with 6 decimals (≤ 0.001 px at 1920 px); an empty file for an image without instances (a negative);
//! - `data.yaml`: `train`/`val`/`test` (the image folders, all three always present, possibly empty)
//!   and `names` (`0: building`), and no `path`, so that Ultralytics takes the folder of `data.yaml` as
//!   the root wherever the folder is moved.
//!
//! # Polygons and holes
//! Ultralytics polygons have no holes and one polygon per line. Every instance's exact mask is traced
//! along pixel edges ([`super::polygon::mask_to_rings`]: vertices at pixel corners, collinear vertices
//! removed, no other simplification), and all its rings — the outer boundary of each part and each
//! hole — are joined into one polygon by zero-width cuts ([`super::polygon::bridge_rings`]), the way
//! Ultralytics' own COCO converter joins the parts of an instance (`merge_multi_segment`). Filling the
//! polygon even-odd at pixel centres gives back exactly the instance's pixels (tested; IoU 1). A
//! rasteriser that also paints the pixels an edge passes through (OpenCV's `fillPoly`, which
//! Ultralytics uses) adds at most the one-pixel-wide line of each cut and of the boundary.
//!
//! Crowd annotations (`iscrowd` = 1, from `export-coco --truncated flag`) are left out, as Ultralytics'
//! converter does: YOLO has no ignore regions.
//!
//! # References
//! Ultralytics dataset format (docs.ultralytics.com/datasets/segment); `ultralytics/data/utils.py`
//! (`img2label_paths`, `verify_image_label`, `check_det_dataset`).

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use rayon::prelude::*;
use serde::Serialize;

use crate::util::Progress;

use super::frames::{for_each_pixel, load_frame, read_splits, ExportSplit};
use super::polygon::{bridge_rings, mask_to_rings};
use super::CocoError;

/// The YOLO class of buildings (the only one).
pub const BUILDING_CLASS: u32 = 0;

/// What `export-yolo` reads and writes.
#[derive(Debug, Clone)]
pub struct YoloPlan {
    /// The `export-coco` output directory (instance files).
    pub coco_dir: PathBuf,
    /// Where `data.yaml`, `images/` and `labels/` go.
    pub out_dir: PathBuf,
}

/// Counts of one split.
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize)]
pub struct YoloSplitSummary {
    /// `train`, `val` or `test`.
    pub split: String,
    /// Images written.
    pub images: u64,
    /// Label lines written.
    pub instances: u64,
    /// Crowd annotations left out.
    pub crowd_skipped: u64,
    /// The most vertices of one polygon.
    pub max_vertices: u64,
}

/// Writes the YOLO dataset of every split present in `plan.coco_dir`; returns one summary per split
/// and the path of `data.yaml` (written last).
///
/// # Errors
/// See [`read_splits`] and [`load_frame`]; [`CocoError::Layout`] for an image that does not exist;
/// [`CocoError::File`] naming a file or link that could not be written; [`CocoError::Interrupted`].
pub fn export_yolo(
    plan: &YoloPlan,
    progress: &dyn Progress,
) -> Result<(Vec<YoloSplitSummary>, PathBuf), CocoError> {
    let splits = read_splits(&plan.coco_dir)?;
    let total: usize = splits.iter().map(|s| s.dataset.images.len()).sum();
    progress.start(total as u64, "frames");
    let mut out = Vec::new();
    for s in &splits {
        out.push(export_split(s, &plan.out_dir, progress)?);
    }
    progress.finish();
    for split in super::Split::ALL {
        crate::util::create_dir_all(&plan.out_dir.join("images").join(split.as_str()))?;
    }
    let yaml = data_yaml(&plan.coco_dir);
    let path = plan.out_dir.join("data.yaml");
    crate::util::write_bytes_atomic(&path, yaml.as_bytes())?;
    Ok((out, path))
}

/// The text of `data.yaml`. It has no `path`: Ultralytics then takes the folder of `data.yaml` as the
/// dataset root (`check_det_dataset`), so the folder can move; a relative `path` would be resolved
/// against Ultralytics' own datasets directory instead.
pub fn data_yaml(coco_dir: &Path) -> String {
    format!(
        "# YOLO segmentation dataset written by `insgen export-yolo` from the COCO export in {}.\n\
         # Labels: labels/<split>/<area>/<camera>/<frame>.txt, polygons normalised to [0, 1]; images:\n\
         # images/<split>/… (hard links or copies). No `path:` key: Ultralytics takes the folder of\n\
         # this file as the root, so this folder can be moved or copied alone.\n\
         train: images/train\n\
         val: images/val\n\
         test: images/test\n\
         names:\n  {BUILDING_CLASS}: building\n",
        yaml_comment(&coco_dir.display().to_string())
    )
}

/// `s` on one comment line (line breaks replaced).
fn yaml_comment(s: &str) -> String {
    s.replace(['\n', '\r'], " ")
}

fn export_split(
    s: &ExportSplit,
    out_dir: &Path,
    progress: &dyn Progress,
) -> Result<YoloSplitSummary, CocoError> {
    let frames = s.annotations_by_image();
    let per_frame: Vec<YoloSplitSummary> = frames
        .par_iter()
        .map(|(image, anns)| {
            crate::util::interrupt::check()?;
            let r = write_frame(s, image, anns, out_dir)?;
            progress.inc(1);
            Ok(r)
        })
        .collect::<Result<_, CocoError>>()?;
    let mut sum = YoloSplitSummary { split: s.split.to_string(), ..Default::default() };
    for f in per_frame {
        sum.images += 1;
        sum.instances += f.instances;
        sum.crowd_skipped += f.crowd_skipped;
        sum.max_vertices = sum.max_vertices.max(f.max_vertices);
    }
    Ok(sum)
}

/// A coordinate normalised to [0, 1] with 6 decimals, trailing zeros trimmed.
fn coord(v: f64) -> String {
    let s = format!("{:.6}", v.clamp(0.0, 1.0));
    let s = s.trim_end_matches('0').trim_end_matches('.');
    if s.is_empty() {
        "0".into()
    } else {
        s.to_string()
    }
}

/// The label line of one instance mask (row-major 0/1 bytes of the crop at `(x0, y0)`, `cw × ch`).
fn label_line(crop: &[u8], cw: u32, ch: u32, x0: u32, y0: u32, width: u32, height: u32) -> (String, u64) {
    let rings = mask_to_rings(crop, cw, ch);
    let ring = bridge_rings(&rings);
    let mut line = BUILDING_CLASS.to_string();
    for [x, y] in &ring {
        let _ = write!(
            line,
            " {} {}",
            coord((x + x0 as f64) / width as f64),
            coord((y + y0 as f64) / height as f64)
        );
    }
    (line, ring.len() as u64)
}

/// Writes one image's label file and image link.
fn write_frame(
    s: &ExportSplit,
    image: &super::format::Image,
    anns: &[&super::format::Annotation],
    out_dir: &Path,
) -> Result<YoloSplitSummary, CocoError> {
    let frame = load_frame(s, image, anns)?;
    let mut text = String::new();
    let mut sum = YoloSplitSummary::default();
    for (a, rle) in &frame.annotations {
        if a.iscrowd != 0 {
            sum.crowd_skipped += 1;
            continue;
        }
        let [bx, by, bw, bh] = a.bbox.map(|v| v as u32);
        // One pixel of margin so that the tracer sees the outside of the crop's border pixels.
        let (x0, y0) = (bx.saturating_sub(1), by.saturating_sub(1));
        let (cw, ch) = (bx + bw + 1 - x0, by + bh + 1 - y0);
        let mut crop = vec![0u8; cw as usize * ch as usize];
        for_each_pixel(rle, |x, y| crop[(y - y0) as usize * cw as usize + (x - x0) as usize] = 1);
        let (line, n) = label_line(&crop, cw, ch, x0, y0, image.width, image.height);
        text.push_str(&line);
        text.push('\n');
        sum.instances += 1;
        sum.max_vertices = sum.max_vertices.max(n);
    }
    let rel = Path::new(&image.area_name).join(&image.camera);
    let label = out_dir.join("labels").join(s.split.as_str()).join(&rel).join(format!("{}.txt", image.frame));
    crate::util::write_bytes_atomic(&label, text.as_bytes())?;
    let target = s.image_root.join(&image.file_name);
    let ext = Path::new(&image.file_name).extension().and_then(|e| e.to_str()).unwrap_or("png");
    let link =
        out_dir.join("images").join(s.split.as_str()).join(&rel).join(format!("{}.{ext}", image.frame));
    link_image(&target, &link)?;
    Ok(sum)
}

/// Places the image `target` at `link`: a hard link, or a copy across file systems, so that the YOLO
/// folder holds its images and can be copied or moved alone.
fn link_image(target: &Path, link: &Path) -> Result<(), CocoError> {
    if !target.is_file() {
        return Err(CocoError::Layout {
            path: target.to_path_buf(),
            problem: super::error::LayoutProblem::MissingImage,
        });
    }
    crate::util::link_or_copy(target, link)?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn coordinates_have_six_decimals_without_trailing_zeros() {
        assert_eq!(coord(0.5), "0.5");
        assert_eq!(coord(1.0), "1");
        assert_eq!(coord(0.0), "0");
        assert_eq!(coord(1.0 / 3.0), "0.333333");
        assert_eq!(coord(-1e-12), "0");
    }

    #[test]
    fn a_label_line_is_the_instance_polygon_normalised() {
        // A 2×2 block at (1, 1) of a 4×4 image, crop with the one-pixel margin at (0, 0).
        let crop = [0, 0, 0, 0, 0, 1, 1, 0, 0, 1, 1, 0, 0, 0, 0, 0];
        let (line, n) = label_line(&crop, 4, 4, 0, 0, 4, 4);
        assert_eq!(line, "0 0.25 0.25 0.75 0.25 0.75 0.75 0.25 0.75");
        assert_eq!(n, 4);
    }

    #[test]
    fn data_yaml_names_the_splits_and_the_class_and_no_root() {
        let y = data_yaml(Path::new("runs/coco"));
        assert!(
            y.contains("\ntrain: images/train\nval: images/val\ntest: images/test\nnames:\n  0: building\n")
        );
        assert!(!y.lines().any(|l| l.starts_with("path:")), "{y}");
        assert!(!data_yaml(Path::new("a\nb")).contains("\nb"), "a path cannot break out of its comment");
    }
}
