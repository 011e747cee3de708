//! The dataset manifest, `dataset.json` next to the COCO files: what a dataset holds and how it was
//! made, enough to reproduce and audit it (schema: `schemas/dataset.schema.json`).
//!
//! It records the tool (version, git commit), every COCO file with its SHA-256 and counts, the areas
//! (split, building count, source files with their SHA-256, attributions) and their cameras (frames,
//! RGB frames, render settings), the export's options, and the command log of the workdir
//! ([`crate::util::provenance`]: every command line with its seed and options, its duration). The
//! command durations make it the one file that differs between two otherwise identical runs;
//! [`super::verify`] checks everything else in it.

use std::collections::BTreeMap;
use std::path::Path;

use serde::{Deserialize, Serialize};

use super::coco::{ExportPlan, Split};
use super::format::{AnnotationUnit, Dataset, Filters, SourceInfo};
use crate::util::provenance::{self, CommandRecord};

/// File name of the manifest in a dataset directory.
pub use crate::layout::DATASET_FILE as MANIFEST_FILE;
/// Value of `format`.
pub const MANIFEST_FORMAT: &str = "insgen-dataset";
/// Version of the layout.
pub const MANIFEST_VERSION: u32 = 1;

/// `dataset.json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DatasetManifest {
    /// Always [`MANIFEST_FORMAT`].
    pub format: String,
    /// Always [`MANIFEST_VERSION`].
    pub version: u32,
    /// The insgen that wrote the dataset.
    pub tool: Tool,
    /// The COCO files, relative to the dataset directory.
    pub files: Vec<FileEntry>,
    /// The areas in the dataset.
    pub areas: Vec<AreaEntry>,
    /// The export's options.
    pub export: ExportSettings,
    /// The workdir's command log at export time, oldest first.
    pub commands: Vec<CommandRecord>,
    /// `SHA256SUMS` of a self-contained export (absent under `--link-root`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub checksums: Option<ChecksumsEntry>,
}

/// The checksums file of a self-contained export: every placed photo, ID map, instance list and ignore
/// mask, and the COCO files, with their SHA-256 (`sha256sum -c SHA256SUMS` in the export folder).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ChecksumsEntry {
    /// `SHA256SUMS`, relative to the dataset directory.
    pub path: String,
    /// SHA-256 of that file.
    pub sha256: String,
    /// Files it lists.
    pub files: u64,
}

/// The program that wrote the dataset.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Tool {
    /// `insgen`.
    pub name: String,
    /// insgen's version.
    pub version: String,
    /// The commit insgen was built from (empty when unknown).
    pub git_commit: String,
}

/// One COCO file.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FileEntry {
    /// Relative to the dataset directory.
    pub path: String,
    /// `train`, `val` or `test`.
    pub split: String,
    /// SHA-256 of the file, hex.
    pub sha256: String,
    /// Images it lists.
    pub images: u64,
    /// Annotations it lists.
    pub annotations: u64,
}

/// One area of the dataset.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct AreaEntry {
    /// Area (scene) name.
    pub name: String,
    /// The split its images are in (after `--holdout`).
    pub split: String,
    /// Whether `--holdout` moved it to `test`.
    pub held_out: bool,
    /// Buildings in the area's building table.
    pub buildings: u64,
    /// The area's source files.
    pub sources: Vec<SourceInfo>,
    /// Attribution lines of its sources.
    pub attributions: Vec<String>,
    /// Its cameras with images in the dataset.
    pub cameras: Vec<CameraEntry>,
}

/// One camera of an area.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CameraEntry {
    /// Camera directory name.
    pub name: String,
    /// The preset the poses were sampled with.
    pub preset: String,
    /// Images in the dataset.
    pub images: u64,
    /// Annotations on its images.
    pub annotations: u64,
    /// Frame size, pixels.
    pub width_px: u32,
    /// Frame height, pixels.
    pub height_px: u32,
    /// How its RGB frames were rendered: each distinct setting of their `rgb/<frame>.render.json`
    /// (engine, device, samples, denoiser, bounces, Blender version — the look), with how many frames
    /// used it. Empty for a label-only export or frames rendered before the metadata existed.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub rgb_render: Vec<RenderSettings>,
}

/// One RGB render setting of a camera and the frames rendered with it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RenderSettings {
    /// Frames rendered with these settings.
    pub frames: u64,
    /// The frame metadata without what differs per frame (`frame`, `fingerprint`).
    pub settings: serde_json::Value,
}

/// Reads the render metadata next to each image's RGB frame (`<frame>.render.json`, written by
/// `render-rgb`) and groups it per (area, camera) into distinct settings. Unreadable or absent
/// metadata is skipped: the manifest records what is known.
pub fn rgb_render_settings(
    workdir: &Path,
    datasets: &[(Split, Dataset)],
) -> BTreeMap<(String, String), Vec<RenderSettings>> {
    let mut out: BTreeMap<(String, String), BTreeMap<String, (u64, serde_json::Value)>> = BTreeMap::new();
    for (_, ds) in datasets {
        for im in &ds.images {
            let meta = workdir.join(&im.file_name).with_extension(crate::layout::RGB_META_SUFFIX);
            let Ok(bytes) = std::fs::read(&meta) else { continue };
            let Ok(serde_json::Value::Object(mut m)) = serde_json::from_slice(&bytes) else { continue };
            m.remove("frame");
            m.remove("fingerprint");
            // Drawn per frame; recorded in each image record instead.
            m.remove("look");
            let v = serde_json::Value::Object(m);
            let e = out.entry((im.area_name.clone(), im.camera.clone())).or_default();
            e.entry(v.to_string()).or_insert((0, v)).0 += 1;
        }
    }
    out.into_iter()
        .map(|(k, m)| {
            (k, m.into_values().map(|(frames, settings)| RenderSettings { frames, settings }).collect())
        })
        .collect()
}

/// The export's options.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ExportSettings {
    /// One annotation per component or per building.
    pub annotation_unit: AnnotationUnit,
    /// Whether `segmentation` holds polygons (`--polygons`).
    pub polygons: bool,
    /// The filters applied.
    pub filters: Filters,
    /// Areas moved to `test` (`--holdout`).
    pub holdout: Vec<String>,
}

impl DatasetManifest {
    /// The manifest of the datasets just written: `files` are (split, file name in the dataset
    /// directory, SHA-256).
    /// `rgb_render` comes from [`rgb_render_settings`].
    pub fn new(
        plan: &ExportPlan,
        datasets: &[(Split, Dataset)],
        files: &[(Split, String, String)],
        mut rgb_render: BTreeMap<(String, String), Vec<RenderSettings>>,
    ) -> Self {
        let mut areas: BTreeMap<String, AreaEntry> = BTreeMap::new();
        let mut cameras: BTreeMap<(String, String), CameraEntry> = BTreeMap::new();
        for (split, ds) in datasets {
            for a in &ds.info.areas {
                areas.entry(a.name.clone()).or_insert_with(|| AreaEntry {
                    name: a.name.clone(),
                    split: split.as_str().to_string(),
                    held_out: a.held_out,
                    buildings: a.buildings,
                    sources: a.sources.clone(),
                    attributions: a.attributions.clone(),
                    cameras: Vec::new(),
                });
            }
            let mut anns_per_image: BTreeMap<u64, u64> = BTreeMap::new();
            for a in &ds.annotations {
                *anns_per_image.entry(a.image_id).or_default() += 1;
            }
            for im in &ds.images {
                let c =
                    cameras.entry((im.area_name.clone(), im.camera.clone())).or_insert_with(|| CameraEntry {
                        name: im.camera.clone(),
                        preset: im.preset.clone(),
                        images: 0,
                        annotations: 0,
                        width_px: im.width,
                        height_px: im.height,
                        rgb_render: rgb_render
                            .remove(&(im.area_name.clone(), im.camera.clone()))
                            .unwrap_or_default(),
                    });
                c.images += 1;
                c.annotations += anns_per_image.get(&im.id).copied().unwrap_or(0);
            }
        }
        for ((area, _), c) in cameras {
            if let Some(a) = areas.get_mut(&area) {
                a.cameras.push(c);
            }
        }
        let counts: BTreeMap<Split, (u64, u64)> =
            datasets.iter().map(|(s, d)| (*s, (d.images.len() as u64, d.annotations.len() as u64))).collect();
        DatasetManifest {
            format: MANIFEST_FORMAT.into(),
            version: MANIFEST_VERSION,
            tool: Tool {
                name: "insgen".into(),
                version: provenance::VERSION.into(),
                git_commit: provenance::GIT_COMMIT.into(),
            },
            files: files
                .iter()
                .map(|(split, path, sha256)| {
                    let (images, annotations) = counts.get(split).copied().unwrap_or_default();
                    FileEntry {
                        path: path.clone(),
                        split: split.as_str().into(),
                        sha256: sha256.clone(),
                        images,
                        annotations,
                    }
                })
                .collect(),
            areas: areas.into_values().collect(),
            export: ExportSettings {
                annotation_unit: plan.unit,
                polygons: plan.polygons,
                filters: plan.filters,
                holdout: plan.holdout.clone(),
            },
            commands: provenance::read_commands(&plan.workdir),
            checksums: None,
        }
    }

    /// Writes the manifest into `dir` atomically.
    ///
    /// # Errors
    /// [`crate::util::FileError`] naming the file.
    pub fn write(&self, dir: &Path) -> Result<(), crate::util::FileError> {
        crate::util::write_json_atomic(&dir.join(MANIFEST_FILE), self)
    }
}
