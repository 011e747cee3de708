//! `insgen verify DATASET`: checks an exported dataset against itself and its manifest, and lists every
//! problem with the file it is in.
//!
//! A dataset is the directory `export-coco` writes (`<workdir>/coco` by default): the COCO files
//! `instances_{train,val,test}.json`, the dataset manifest [`super::manifest::MANIFEST_FILE`] and the
//! card; images and ID maps are found through each file's `info.image_root`. The checks:
//! - the manifest parses, every file it lists exists and has the SHA-256 and the counts it records;
//! - every COCO file parses; image and annotation ids are unique, annotations name existing images and
//!   the `building` category;
//! - every image is an RGB frame on disk (never the ID map), decodes as a PNG of the size the record
//!   gives; its ID map exists and decodes at the same size;
//! - every annotation's mask (its RLE, or `mask_rle` next to polygons) is exactly the connected
//!   component (or, for `annotation_unit = building`, the union of the components) of its building in
//!   the ID map, with the record's connectivity, and its `area` and `bbox` are the mask's.
//!
//! Problems are collected, not returned one at a time: a user fixing a dataset wants the whole list.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

use rayon::prelude::*;

use super::format::{AnnotationUnit, Dataset, Segmentation, BUILDING_CATEGORY_ID};
use super::manifest::{DatasetManifest, MANIFEST_FILE};
use super::rle::{encode_labels, Rle};
use crate::label::label_components;
use crate::scene::{BuildingId, IdMap};
use crate::util::Progress;

/// One problem found, with the file it concerns.
#[derive(Debug, Clone, PartialEq, Eq, PartialOrd, Ord)]
pub struct Problem {
    /// The file concerned.
    pub file: PathBuf,
    /// What is wrong, with the JSON path where there is one.
    pub what: String,
}

impl std::fmt::Display for Problem {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}: {}", self.file.display(), self.what)
    }
}

/// What `verify` checked and found.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct VerifyReport {
    /// COCO files checked.
    pub coco_files: usize,
    /// Images checked.
    pub images: usize,
    /// Annotations checked.
    pub annotations: usize,
    /// Every problem found (empty: the dataset is sound).
    pub problems: Vec<Problem>,
}

/// The dataset folder a user's path means: the folder itself, its `dataset.json`, or the work
/// directory that holds the export in `coco/`.
pub fn dataset_dir(path: &Path) -> PathBuf {
    if path.file_name().is_some_and(|n| n == MANIFEST_FILE) && path.is_file() {
        return path.parent().map(Path::to_path_buf).unwrap_or_default();
    }
    let in_workdir = path.join("coco");
    if !path.join(MANIFEST_FILE).exists() && in_workdir.join(MANIFEST_FILE).is_file() {
        return in_workdir;
    }
    path.to_path_buf()
}

/// Checks the dataset in `dir` (see the module doc). Never fails: every problem, unreadable files
/// included, is a [`Problem`] in the report.
pub fn verify(dir: &Path, progress: &dyn Progress) -> VerifyReport {
    let mut report = VerifyReport::default();
    let problem = |file: &Path, what: String| Problem { file: file.to_path_buf(), what };
    let manifest_path = dir.join(MANIFEST_FILE);
    let manifest = match crate::util::read_file(&manifest_path) {
        Ok(bytes) => match serde_json::from_slice::<DatasetManifest>(&bytes) {
            Ok(m) => Some(m),
            Err(e) => {
                report.problems.push(problem(&manifest_path, format!("not a dataset manifest: {e}")));
                None
            }
        },
        Err(_) => {
            report.problems.push(problem(
                &manifest_path,
                "missing: a dataset is the directory `insgen export-coco` writes".into(),
            ));
            None
        }
    };
    // The COCO files: those the manifest lists, else those present.
    let files: Vec<PathBuf> = match &manifest {
        Some(m) => m.files.iter().map(|f| dir.join(&f.path)).collect(),
        None => {
            super::coco::Split::ALL.iter().map(|s| dir.join(s.file_name())).filter(|p| p.exists()).collect()
        }
    };
    if let Some(m) = &manifest {
        for f in &m.files {
            let path = dir.join(&f.path);
            match crate::util::sha256_file(&path) {
                Ok(h) if h == f.sha256 => {}
                Ok(h) => report.problems.push(problem(
                    &path,
                    format!("SHA-256 {h} differs from the manifest's {} (changed after export)", f.sha256),
                )),
                Err(_) => report.problems.push(problem(&path, "listed in the manifest but missing".into())),
            }
        }
    }
    if let Some(c) = manifest.as_ref().and_then(|m| m.checksums.as_ref()) {
        report.problems.extend(check_checksums(dir, c));
    }
    for path in files {
        let bytes = match crate::util::read_file(&path) {
            Ok(b) => b,
            Err(_) => continue, // already reported against the manifest
        };
        let ds: Dataset = match serde_json::from_slice(&bytes) {
            Ok(d) => d,
            Err(e) => {
                report.problems.push(problem(&path, format!("not a COCO instances file: {e}")));
                continue;
            }
        };
        report.coco_files += 1;
        report.images += ds.images.len();
        report.annotations += ds.annotations.len();
        if let Some(entry) =
            manifest.as_ref().and_then(|m| m.files.iter().find(|f| dir.join(&f.path) == path))
        {
            if (entry.images, entry.annotations) != (ds.images.len() as u64, ds.annotations.len() as u64) {
                report.problems.push(problem(
                    &path,
                    format!(
                        "{} images and {} annotations, the manifest says {} and {}",
                        ds.images.len(),
                        ds.annotations.len(),
                        entry.images,
                        entry.annotations
                    ),
                ));
            }
        }
        report.problems.extend(check_ids(&path, &ds));
        let root = path.parent().unwrap_or(Path::new(".")).join(&ds.info.image_root);
        progress.start(ds.images.len() as u64, "images");
        let per_image: Vec<Vec<Problem>> = ds
            .images
            .par_iter()
            .map(|im| {
                let anns: Vec<&super::format::Annotation> =
                    ds.annotations.iter().filter(|a| a.image_id == im.id).collect();
                let p = check_image(&path, &root, ds.info.annotation_unit, im, &anns);
                progress.inc(1);
                p
            })
            .collect();
        progress.finish();
        report.problems.extend(per_image.into_iter().flatten());
    }
    report.problems.sort();
    report
}

/// Unique ids, annotations pointing at images of this file, the one category.
/// `SHA256SUMS` against the manifest's digest of it, then every file it lists against its line.
fn check_checksums(dir: &Path, entry: &super::manifest::ChecksumsEntry) -> Vec<Problem> {
    use rayon::prelude::*;
    let path = dir.join(&entry.path);
    let problem = |file: &Path, what: String| Problem { file: file.to_path_buf(), what };
    let text = match crate::util::read_file(&path) {
        Ok(bytes) => String::from_utf8_lossy(&bytes).into_owned(),
        Err(_) => return vec![problem(&path, "listed in the manifest but missing".into())],
    };
    let mut out = Vec::new();
    let digest = crate::util::sha256_file(&path).unwrap_or_default();
    if digest != entry.sha256 {
        out.push(problem(
            &path,
            format!("SHA-256 {digest} differs from the manifest's {} (changed after export)", entry.sha256),
        ));
    }
    let lines = super::bundle::parse_checksums(&text);
    if lines.len() as u64 != entry.files {
        out.push(problem(&path, format!("{} lines, the manifest says {} files", lines.len(), entry.files)));
    }
    let found: Vec<Option<Problem>> = lines
        .par_iter()
        .map(|line| match line {
            Err(n) => Some(problem(&path, format!("line {n} is not `<SHA-256>  <file>`"))),
            Ok((hex, name)) => {
                let file = dir.join(name);
                match crate::util::sha256_file(&file) {
                    Ok(h) if &h == hex => None,
                    Ok(h) => Some(problem(
                        &file,
                        format!("SHA-256 {h} differs from {}'s {hex} (changed after export)", entry.path),
                    )),
                    Err(_) => Some(problem(&file, format!("listed in {} but missing", entry.path))),
                }
            }
        })
        .collect();
    out.extend(found.into_iter().flatten());
    out
}

fn check_ids(path: &Path, ds: &Dataset) -> Vec<Problem> {
    let mut out = Vec::new();
    let mut p = |what: String| out.push(Problem { file: path.to_path_buf(), what });
    let mut seen = BTreeSet::new();
    for im in &ds.images {
        if !seen.insert(im.id) {
            p(format!("image id {} is used twice", im.id));
        }
    }
    let mut ann_ids = BTreeSet::new();
    for a in &ds.annotations {
        if !ann_ids.insert(a.id) {
            p(format!("annotation id {} is used twice", a.id));
        }
        if !seen.contains(&a.image_id) {
            p(format!("annotation {} refers to image {}, which is not in the file", a.id, a.image_id));
        }
        if a.category_id != BUILDING_CATEGORY_ID {
            p(format!(
                "annotation {} has category {}, not building ({BUILDING_CATEGORY_ID})",
                a.id, a.category_id
            ));
        }
    }
    out
}

/// The checks of one image and its annotations.
fn check_image(
    coco: &Path,
    root: &Path,
    unit: AnnotationUnit,
    im: &super::format::Image,
    anns: &[&super::format::Annotation],
) -> Vec<Problem> {
    let mut out = Vec::new();
    let image_path = root.join(&im.file_name);
    let mask_path = root.join(&im.mask_file);
    if im.file_name == im.mask_file {
        out.push(Problem {
            file: coco.to_path_buf(),
            what: format!("image {} names its ID map as the image ({}): not a photo", im.id, im.file_name),
        });
    }
    match super::raster::read_png_rgb(&image_path).map(|i| [i.width, i.height]) {
        Ok(size) if size == [im.width, im.height] => {}
        Ok(size) => out.push(Problem {
            file: image_path.clone(),
            what: format!("{}×{} px, the COCO record says {}×{}", size[0], size[1], im.width, im.height),
        }),
        Err(e) => out.push(Problem {
            file: image_path.clone(),
            what: format!("missing or unreadable: {}", crate::util::error_chain(&e)),
        }),
    }
    let map = match IdMap::read_png(&mask_path) {
        Ok(m) => m,
        Err(e) => {
            out.push(Problem { file: mask_path, what: crate::util::error_chain(&e) });
            return out;
        }
    };
    if (map.width(), map.height()) != (im.width, im.height) {
        out.push(Problem {
            file: mask_path,
            what: format!("{}×{} px, the image is {}×{}", map.width(), map.height(), im.width, im.height),
        });
        return out;
    }
    // The masks the annotations must have: per (building, component) and per building.
    let lab = label_components(&map, im.connectivity);
    let rles = match encode_labels(&lab.labels, im.height, im.width, lab.components.len()) {
        Ok(r) => r,
        Err(e) => {
            out.push(Problem { file: mask_path, what: format!("cannot encode its components: {e}") });
            return out;
        }
    };
    let mut by_building: BTreeMap<BuildingId, Vec<usize>> = BTreeMap::new();
    for (k, c) in lab.components.iter().enumerate() {
        by_building.entry(c.building_id).or_default().push(k);
    }
    let expected = Expected { by_building, lab: &lab, rles: &rles };
    for a in anns {
        out.extend(check_annotation(coco, im, unit, a, &expected));
    }
    out
}

/// The masks an image's annotations must have, from its ID map: the components' RLEs and which
/// components each building has.
struct Expected<'a> {
    by_building: BTreeMap<BuildingId, Vec<usize>>,
    lab: &'a crate::label::Labelling,
    rles: &'a [Rle],
}

/// Checks one annotation's mask, area and box against the ID map.
fn check_annotation(
    coco: &Path,
    im: &super::format::Image,
    unit: AnnotationUnit,
    a: &super::format::Annotation,
    e: &Expected,
) -> Vec<Problem> {
    let (by_building, lab, rles) = (&e.by_building, e.lab, e.rles);
    let mut out = Vec::new();
    let at =
        |what: String| Problem { file: coco.to_path_buf(), what: format!("annotation {}: {what}", a.id) };
    let stored = match (&a.segmentation, &a.mask_rle) {
        (Segmentation::Rle(r), _) | (Segmentation::Polygons(_), Some(r)) => r.to_rle(),
        (Segmentation::Polygons(_), None) => {
            out.push(at("polygons without `mask_rle`: the exact mask cannot be checked".into()));
            return out;
        }
    };
    let stored = match stored {
        Ok(r) => r,
        Err(e) => {
            out.push(at(format!("its RLE does not decode: {e}")));
            return out;
        }
    };
    let Some(parts) = by_building.get(&a.building_id) else {
        out.push(at(format!("building {} does not appear in the ID map {}", a.building_id, im.mask_file)));
        return out;
    };
    let expected = match (unit, a.component) {
        (AnnotationUnit::Component, Some(c)) => match parts.iter().find(|&&k| lab.components[k].index == c) {
            Some(&k) => rles[k].clone(),
            None => {
                out.push(at(format!("building {} has no component {c} in the ID map", a.building_id)));
                return out;
            }
        },
        (AnnotationUnit::Component, None) => {
            out.push(at("no `component` in a per-component file".to_string()));
            return out;
        }
        (AnnotationUnit::Building, _) => {
            let all: Vec<Rle> = parts.iter().map(|&k| rles[k].clone()).collect();
            match Rle::union(&all) {
                Ok(r) => r,
                Err(e) => {
                    out.push(at(e.to_string()));
                    return out;
                }
            }
        }
    };
    match expected {
        e if e != stored => out.push(at(format!(
            "its mask ({} px) is not building {}'s in the ID map {} ({} px)",
            stored.area(),
            a.building_id,
            im.mask_file,
            e.area()
        ))),
        e => {
            if a.area != e.area() {
                out.push(at(format!("area {} but the mask has {} px", a.area, e.area())));
            }
            if a.bbox != e.to_bbox() {
                out.push(at(format!("bbox {:?} but the mask's is {:?}", a.bbox, e.to_bbox())));
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn dataset_dir_takes_the_folder_its_manifest_or_the_workdir() {
        let work = tempfile::tempdir().unwrap();
        let coco = work.path().join("coco");
        std::fs::create_dir_all(&coco).unwrap();
        std::fs::write(coco.join(MANIFEST_FILE), "{}").unwrap();
        assert_eq!(dataset_dir(&coco), coco);
        assert_eq!(dataset_dir(&coco.join(MANIFEST_FILE)), coco);
        assert_eq!(dataset_dir(work.path()), coco);
        // Anything else is taken as given (verify then names what is missing there).
        let other = work.path().join("elsewhere");
        assert_eq!(dataset_dir(&other), other);
    }
}
