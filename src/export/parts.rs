//! COCO exports in parts: what `export-coco --shard i/N` writes, and how `insgen merge` combines the
//! parts into the export one process writes.
//!
//! A shard exports the frames whose line in each camera's `poses.jsonl` is in the shard (the frames
//! `render-masks --shard i/N` rendered), into `<out>/parts/<i>-of-<N>/`: `instances_<split>.json`
//! (valid COCO files on their own, ids numbered within the part) and [`PART_MARKER`] (this module's
//! [`PartInfo`]: the shard, the export's options, the counters). No report is written there: the
//! statistics, the manifest and the card describe the whole dataset and are recomputed from it.
//!
//! [`combine`] reads the N parts of one export, checks that they are the parts of one run (every shard
//! once, same options, same `info` and licences), puts the images back in the export's order (area,
//! camera, frame, by name) and numbers images and annotations from 1 in that order, as
//! [`super::coco::build`] does — so the combined files are byte for byte those of one process.
//! Parts name the photos and ID maps in the work directory (`info.image_root` relative to the part's
//! folder); the combined export places them in the export folder as one process does
//! ([`super::bundle`]), from the merged work directory.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use super::coco::{read_json, DropCounts, Export, ExportPlan, MissingRgb, Split};
use super::error::PartsProblem;
use super::format::{AnnotationUnit, Dataset, Filters};
use super::stats::ReportOptions;
use super::CocoError;
use crate::util::shard::{PARTS_DIR, PART_MARKER};
use crate::util::Shard;

/// `kind` of a COCO part's [`PART_MARKER`].
pub const PART_KIND: &str = "coco";
/// Version of [`PartInfo`].
pub const PART_VERSION: u32 = 1;

/// The [`PART_MARKER`] of a COCO part: the shard, the options of the export, and its counters.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PartInfo {
    /// Always [`PART_KIND`].
    pub kind: String,
    /// Always [`PART_VERSION`].
    pub version: u32,
    /// `i/N`.
    pub shard: String,
    /// The export's options.
    pub options: PartOptions,
    /// Frames of this shard listed in `poses.jsonl` without an ID map or instance file.
    pub frames_without_masks: u64,
    /// Annotations and images the filters dropped in this shard.
    pub dropped: DropCounts,
    /// Labelled frames of this shard left out for want of an RGB frame.
    pub frames_without_rgb: Vec<MissingRgb>,
}

/// The options of a sharded export; the parts of one export agree on them.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PartOptions {
    /// One annotation per component or per building.
    pub annotation_unit: AnnotationUnit,
    /// `--polygons`.
    pub polygons: bool,
    /// The filters.
    pub filters: Filters,
    /// `--holdout` areas.
    pub holdout: Vec<String>,
    /// `--label-only`.
    pub label_only: bool,
    /// The statistics report the combined export gets (`None`: `--no-stats`).
    pub report: Option<PartReport>,
    /// `--link-root`: the combined export names the files in the work directory instead of placing
    /// them inside the export folder (absent in parts of older versions: placed, the default).
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub link_root: bool,
}

/// The statistics report's options.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct PartReport {
    /// Frames on the contact sheet (0 = none).
    pub contact_sheet_images: usize,
}

/// The directory shard `shard`'s part of an export to `out_dir` goes to: `<out_dir>/parts/<i>-of-<N>`.
pub fn part_dir(out_dir: &Path, shard: Shard) -> PathBuf {
    out_dir.join(PARTS_DIR).join(shard.part_dir_name())
}

/// Writes `ex`, the export of `plan.shard`'s frames, as that shard's part under `plan.out_dir`: its
/// COCO files, then the marker (last, so that a part with a marker is complete). `report` is the
/// statistics report the combined export should get. Returns the files written.
///
/// # Errors
/// I/O errors naming the file.
pub fn write_part(
    plan: &ExportPlan,
    ex: &Export,
    report: Option<ReportOptions>,
) -> Result<Vec<PathBuf>, CocoError> {
    let dir = part_dir(&plan.out_dir, plan.shard);
    crate::util::create_dir_all(&dir)?;
    let root = super::coco::image_root(&plan.workdir, &dir);
    let mut written = Vec::new();
    for (split, ds) in &ex.datasets {
        let mut ds = ds.clone();
        ds.info.image_root = root.clone();
        let path = dir.join(split.file_name());
        super::coco::write_dataset(&path, &ds)?;
        written.push(path);
    }
    let info = PartInfo {
        kind: PART_KIND.into(),
        version: PART_VERSION,
        shard: plan.shard.to_string(),
        options: PartOptions {
            annotation_unit: plan.unit,
            polygons: plan.polygons,
            filters: plan.filters,
            holdout: plan.holdout.clone(),
            label_only: plan.label_only,
            report: report.map(|r| PartReport { contact_sheet_images: r.contact_sheet_images }),
            link_root: plan.link_root,
        },
        frames_without_masks: ex.frames_without_masks,
        dropped: ex.dropped,
        frames_without_rgb: ex.frames_without_rgb.clone(),
    };
    let marker = dir.join(PART_MARKER);
    crate::util::write_json_atomic(&marker, &info)?;
    written.push(marker);
    Ok(written)
}

/// What [`combine`] makes of the parts: the plan one process would have run on the merged work
/// directory, its statistics options, and the export it builds.
#[derive(Debug, Clone)]
pub struct Combined {
    /// The plan of the export the parts make up.
    pub plan: ExportPlan,
    /// The statistics report to write (`None`: `--no-stats`).
    pub report: Option<ReportOptions>,
    /// The combined export.
    pub export: Export,
}

/// One split's dataset combined from every part's file: images in (area, camera, frame) order,
/// ids renumbered, the parts checked to describe the same export.
fn combine_split(
    split: Split,
    infos: &[(Shard, PartInfo, &PathBuf)],
    first_shard: Shard,
    parts_dir: &Path,
) -> Result<Dataset, CocoError> {
    let mut combined: Option<Dataset> = None;
    // (area, camera, frame) → the image and its annotations.
    let mut images = BTreeMap::new();
    for (shard, _, dir) in infos {
        let path = dir.join(split.file_name());
        let mut ds: Dataset = read_json(&path)?;
        let mut anns: BTreeMap<u64, Vec<super::Annotation>> = BTreeMap::new();
        for a in std::mem::take(&mut ds.annotations) {
            anns.entry(a.image_id).or_default().push(a);
        }
        for im in std::mem::take(&mut ds.images) {
            let a = anns.remove(&im.id).unwrap_or_default();
            let key = (im.area_name.clone(), im.camera.clone(), im.frame.clone());
            if images.insert(key, (im, a)).is_some() {
                return Err(CocoError::Parts {
                    dir: path.clone(),
                    problem: PartsProblem::DuplicateFrame { shard: *shard },
                });
            }
        }
        if let Some(orphan) = anns.keys().next() {
            return Err(CocoError::Parts {
                dir: path.clone(),
                problem: PartsProblem::OrphanAnnotations { image_id: *orphan },
            });
        }
        match &combined {
            None => combined = Some(ds),
            Some(c) => {
                let mut info = ds.info.clone();
                info.image_root.clone_from(&c.info.image_root);
                if info != c.info || ds.licenses != c.licenses || ds.categories != c.categories {
                    return Err(CocoError::Parts {
                        dir: path.clone(),
                        problem: PartsProblem::OtherDataset { first_shard },
                    });
                }
            }
        }
    }
    // Every split has a part file in every part, and there is at least one part.
    let mut ds = combined
        .ok_or_else(|| CocoError::Parts { dir: parts_dir.to_path_buf(), problem: PartsProblem::NoParts })?;
    for ((_, _, _), (mut im, anns)) in images {
        im.id = ds.images.len() as u64 + 1;
        for mut a in anns {
            a.id = ds.annotations.len() as u64 + 1;
            a.image_id = im.id;
            ds.annotations.push(a);
        }
        ds.images.push(im);
    }
    Ok(ds)
}

/// Combines the parts of one export (`parts`: each shard's part directory) into the export of all
/// frames, for `out_dir` in the merged work directory `workdir`.
///
/// # Errors
/// [`CocoError::Parts`] when a shard is missing, the parts disagree on the shard count or the options,
/// or their datasets describe different areas; JSON and I/O errors naming the file.
pub fn combine(
    parts: &BTreeMap<Shard, PathBuf>,
    workdir: &Path,
    out_dir: &Path,
) -> Result<Combined, CocoError> {
    let fail = |problem: PartsProblem| CocoError::Parts { dir: out_dir.join(PARTS_DIR), problem };
    let infos: Vec<(Shard, PartInfo, &PathBuf)> = parts
        .iter()
        .map(|(&shard, dir)| {
            let path = dir.join(PART_MARKER);
            let info: PartInfo = read_json(&path)?;
            if info.kind != PART_KIND || info.version != PART_VERSION {
                return Err(CocoError::Parts {
                    dir: dir.clone(),
                    problem: PartsProblem::WrongKind { kind: info.kind, version: info.version },
                });
            }
            if info.shard != shard.to_string() {
                return Err(CocoError::Parts {
                    dir: dir.clone(),
                    problem: PartsProblem::ShardName { said: info.shard, shard },
                });
            }
            Ok((shard, info, dir))
        })
        .collect::<Result<_, _>>()?;
    let Some((first_shard, first, first_dir)) = infos.first() else {
        return Err(fail(PartsProblem::NoParts));
    };
    let count = first_shard.count;
    let missing: Vec<Shard> =
        (0..count).map(|index| Shard { index, count }).filter(|s| !parts.contains_key(s)).collect();
    if let Some((other, _, dir)) = infos.iter().find(|(s, _, _)| s.count != count) {
        return Err(fail(PartsProblem::MixedCounts {
            count,
            first_dir: first_dir.to_path_buf(),
            other_count: other.count,
            other_dir: dir.to_path_buf(),
        }));
    }
    if !missing.is_empty() {
        return Err(fail(PartsProblem::MissingShards { missing, count }));
    }
    if let Some((s, info, _)) = infos.iter().find(|(_, i, _)| i.options != first.options) {
        return Err(fail(PartsProblem::Options {
            shard: *s,
            first_shard: *first_shard,
            options: Box::new(info.options.clone()),
            first_options: Box::new(first.options.clone()),
        }));
    }

    // Per split: the parts' datasets, checked to describe the same areas.
    let mut datasets: Vec<(Split, Dataset)> = Vec::new();
    for split in Split::ALL {
        datasets.push((split, combine_split(split, &infos, *first_shard, &out_dir.join(PARTS_DIR))?));
    }

    let mut dropped = DropCounts::default();
    let mut frames_without_masks = 0;
    let mut missing_rgb: BTreeMap<(String, String), MissingRgb> = BTreeMap::new();
    for (_, info, _) in &infos {
        dropped.add(&info.dropped);
        frames_without_masks += info.frames_without_masks;
        for m in &info.frames_without_rgb {
            let e = missing_rgb.entry((m.area.clone(), m.camera.clone())).or_insert_with(|| MissingRgb {
                area: m.area.clone(),
                camera: m.camera.clone(),
                frames: 0,
                broken: Vec::new(),
            });
            e.frames += m.frames;
            e.broken.extend(m.broken.iter().take(5 - e.broken.len().min(5)).cloned());
        }
    }
    let o = &first.options;
    let plan = ExportPlan {
        workdir: workdir.to_path_buf(),
        out_dir: out_dir.to_path_buf(),
        holdout: o.holdout.clone(),
        unit: o.annotation_unit,
        polygons: o.polygons,
        filters: o.filters,
        label_only: o.label_only,
        shard: Shard::default(),
        link_root: o.link_root,
    };
    Ok(Combined {
        plan,
        report: o.report.map(|r| ReportOptions { contact_sheet_images: r.contact_sheet_images }),
        export: Export {
            datasets,
            frames_without_masks,
            frames_without_rgb: missing_rgb.into_values().collect(),
            dropped,
            stats: None,
        },
    })
}
