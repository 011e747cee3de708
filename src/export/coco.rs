//! `export-coco`: rendered ID maps → COCO instance files, one per geographic split.
//!
//! Reads, for every area directory `<workdir>/<area>/` that has a `scene/manifest.json`:
//! - `scene/manifest.json` (the area's split, attributions, provenance) and `scene/buildings.json`;
//! - every camera directory `<area>/<camera>/` holding a `poses.jsonl`, and for each frame listed there
//!   `masks/<frame>.png` (24-bit ID map) and `masks/<frame>.instances.json` (optional `rgb/<frame>.png`).
//!
//! Every ID map is decoded and its connected components recomputed with the connectivity its instance
//! file records; the export stops with an error naming both files if they disagree (count, building,
//! area, box, truncation), so a COCO file never describes masks other than the ones on disk.
//!
//! Writes `instances_train.json`, `instances_val.json` and `instances_test.json` (see [`super::format`])
//! into the output directory — always all three, possibly empty, so that downstream tools find the same
//! layout — and places the photos and ID maps they name inside the output directory ([`super::bundle`];
//! `--link-root` names the work directory's files instead). Splits are by area, never by frame; `--holdout` moves whole areas to `test`. The output is
//! deterministic: areas, cameras and frames are sorted by name, ids are assigned in that order, no dates.
//! Frames are processed in parallel (rayon); files are written atomically and only when every frame
//! succeeded.

use crate::layout::AreaDir;
use std::collections::{BTreeMap, BTreeSet};
use std::fmt;
use std::path::{Path, PathBuf};

use rayon::prelude::*;

use crate::camera::PoseRecord;
use crate::label::{label_components, FrameInstances, Labelling};
use crate::scene::{BuildingId, BuildingRecord, IdMap, Manifest};
use crate::util::{FileError, Progress, Shard};

use super::error::{chain_string, ComponentFacts, LayoutProblem, MismatchProblem, MissingField};
use super::format::{
    licence_url, Annotation, AnnotationUnit, AreaInfo, Category, Dataset, Filters, Image, Info, License,
    RleJson, Segmentation, SourceInfo, TruncatedPolicy, BUILDING_CATEGORY_ID,
};
use super::rle::{encode_labels, Rle};
use super::CocoError;

/// A geographic split.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum Split {
    /// Training split (`instances_train.json`).
    Train,
    /// Validation split (`instances_val.json`).
    Val,
    /// Test split (`instances_test.json`); `--holdout` areas go here.
    Test,
}

impl Split {
    /// All splits in file order.
    pub const ALL: [Split; 3] = [Split::Train, Split::Val, Split::Test];

    /// `train`, `val` or `test`.
    pub fn as_str(self) -> &'static str {
        match self {
            Split::Train => "train",
            Split::Val => "val",
            Split::Test => "test",
        }
    }

    /// Parses `train`, `val` or `test`.
    pub fn parse(s: &str) -> Option<Split> {
        Split::ALL.into_iter().find(|x| x.as_str() == s)
    }

    /// The file name of this split's COCO file: `instances_<split>.json`.
    pub fn file_name(self) -> String {
        format!("instances_{}.json", self.as_str())
    }
}

impl fmt::Display for Split {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

/// Everything the export needs, resolved from the command line.
#[derive(Debug, Clone)]
pub struct ExportPlan {
    /// The insgen workdir holding the area directories (and the image root of the COCO files).
    pub workdir: PathBuf,
    /// Where the COCO files go (default `<workdir>/coco`).
    pub out_dir: PathBuf,
    /// Areas moved to the test split whatever their manifests say.
    pub holdout: Vec<String>,
    /// One annotation per connected component or per building.
    pub unit: AnnotationUnit,
    /// Write polygons (outer boundaries; holes are lost) in `segmentation`, keeping the exact RLE in
    /// the `mask_rle` extension key.
    pub polygons: bool,
    /// Annotation and image filters.
    pub filters: Filters,
    /// List every labelled frame, rendered or not (`info.images_missing`); by default only frames whose
    /// RGB image exists and decodes at the frame's size are images.
    pub label_only: bool,
    /// The frames to export: per camera, those whose line in `poses.jsonl` is in this shard (as
    /// `render-masks` splits them). A shard other than the whole list writes a part
    /// ([`super::parts`]) that `insgen merge` combines with the others.
    pub shard: Shard,
    /// Name the photos and ID maps where they lie in the work directory (`info.image_root` = the path
    /// to it, `..` by default: the export needs the work directory) instead of placing them inside the
    /// export folder ([`super::bundle`], the default: a self-contained folder).
    pub link_root: bool,
}

impl ExportPlan {
    /// The folder the names of the written COCO files are relative to: the export folder itself, or
    /// the work directory under [`ExportPlan::link_root`].
    pub fn names_root(&self) -> &Path {
        if self.link_root {
            &self.workdir
        } else {
            &self.out_dir
        }
    }
}

/// Counts of what the filters removed.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct DropCounts {
    /// Annotations below `--min-area`.
    pub small: u64,
    /// Annotations below `--min-visible-fraction`.
    pub low_visibility: u64,
    /// Truncated annotations under `--truncated drop`.
    pub truncated: u64,
    /// Images left without annotations under `--drop-empty-images`.
    pub empty_images: u64,
    /// Images whose consistency score is below `--min-consistency`.
    #[serde(default)]
    pub low_consistency_images: u64,
}

impl DropCounts {
    pub(crate) fn add(&mut self, o: &DropCounts) {
        self.small += o.small;
        self.low_visibility += o.low_visibility;
        self.truncated += o.truncated;
        self.empty_images += o.empty_images;
        self.low_consistency_images += o.low_consistency_images;
    }
}

/// The result of building the datasets.
#[derive(Debug, Clone)]
pub struct Export {
    /// One dataset per split, in [`Split::ALL`] order.
    pub datasets: Vec<(Split, Dataset)>,
    /// Frames listed in `poses.jsonl` whose ID map or instance file does not exist (not rendered yet).
    pub frames_without_masks: u64,
    /// Per (area, camera): labelled frames left out because their RGB frame is missing, does not
    /// decode, or has another size (not in a `--label-only` export).
    pub frames_without_rgb: Vec<MissingRgb>,
    /// Annotations and images the filters dropped.
    pub dropped: DropCounts,
    /// The statistics of `datasets`, once [`write_export`] has computed them for the card (they read
    /// every ID map and photo, so the report reuses them).
    pub stats: Option<super::stats::Stats>,
}

/// Labelled frames of one camera left out for want of an RGB frame.
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct MissingRgb {
    /// The area.
    pub area: String,
    /// The camera.
    pub camera: String,
    /// Labelled frames left out.
    pub frames: u64,
    /// Up to a few frames whose RGB file exists but is broken (undecodable or of another size).
    pub broken: Vec<PathBuf>,
}

struct AreaInput {
    name: String,
    manifest: Manifest,
    manifest_split: Split,
    split: Split,
    buildings_path: PathBuf,
    source_ids: BTreeMap<BuildingId, String>,
    cameras: Vec<CameraInput>,
}

struct CameraInput {
    name: String,
    frames: Vec<FrameInput>,
}

struct FrameInput {
    pose: PoseRecord,
    mask: PathBuf,
    instances: PathBuf,
    /// `rgb/<frame>.png`, the image (whether rendered or not).
    rgb: PathBuf,
}

/// Reads a JSON file into `T`, naming the file in errors.
pub(crate) fn read_json<T: serde::de::DeserializeOwned>(path: &Path) -> Result<T, CocoError> {
    let bytes = crate::util::read_file(path)?;
    serde_json::from_slice(&bytes).map_err(|e| CocoError::json(path, e))
}

fn list_dirs(dir: &Path) -> Result<Vec<(String, PathBuf)>, CocoError> {
    let rd = std::fs::read_dir(dir).map_err(|e| FileError::new("listing", dir, e))?;
    let mut out = Vec::new();
    for entry in rd {
        let entry = entry.map_err(|e| FileError::new("listing", dir, e))?;
        let path = entry.path();
        if path.is_dir() {
            if let Some(name) = entry.file_name().to_str() {
                out.push((name.to_string(), path));
            }
        }
    }
    out.sort();
    Ok(out)
}

/// Finds the prepared areas, their cameras and rendered frames under `workdir` (of each camera, the
/// frames of `shard`, by line of `poses.jsonl`).
fn discover(workdir: &Path, shard: Shard) -> Result<(Vec<AreaInput>, u64), CocoError> {
    let mut areas = Vec::new();
    let mut missing = 0u64;
    for (name, dir) in list_dirs(workdir)? {
        let area = AreaDir::new(&dir);
        let manifest_path = area.scene().join(crate::layout::MANIFEST_FILE);
        if !manifest_path.is_file() {
            continue;
        }
        let manifest: Manifest = read_json(&manifest_path)?;
        if manifest.area != name {
            return Err(CocoError::Layout {
                path: manifest_path,
                problem: LayoutProblem::AreaName { named: manifest.area, directory: name },
            });
        }
        let Some(split) = Split::parse(&manifest.split) else {
            return Err(CocoError::Layout {
                path: manifest_path,
                problem: LayoutProblem::UnknownSplit { split: manifest.split },
            });
        };
        let buildings_path = area.scene().join(crate::layout::BUILDINGS_FILE);
        let buildings: Vec<BuildingRecord> = read_json(&buildings_path)?;
        let source_ids = buildings.into_iter().map(|b| (b.id, b.source_id)).collect();
        let mut cameras = Vec::new();
        let sampled = area.sampled_cameras().map_err(|e| FileError::new("listing", &dir, e))?;
        for (cam_name, cam_dir) in sampled {
            let poses_path = cam_dir.poses();
            let mut poses = crate::camera::record::read_jsonl(&poses_path)?;
            let mut names: Vec<&str> = poses.iter().map(|p| p.name.as_str()).collect();
            names.sort_unstable();
            if let Some(w) = names.windows(2).find(|w| w[0] == w[1]) {
                return Err(CocoError::Layout {
                    path: poses_path,
                    problem: LayoutProblem::DuplicateFrame { frame: w[0].to_string() },
                });
            }
            // The shard by line, as render-masks takes its frames; then by name, the export's order.
            poses =
                poses.into_iter().enumerate().filter(|(i, _)| shard.contains(*i)).map(|(_, p)| p).collect();
            poses.sort_by(|a, b| a.name.cmp(&b.name));
            let mut frames = Vec::new();
            for pose in poses {
                if pose.area != name {
                    return Err(CocoError::Layout {
                        path: poses_path,
                        problem: LayoutProblem::ForeignFrame {
                            frame: pose.name,
                            belongs_to: pose.area,
                            area: name,
                        },
                    });
                }
                let mask = cam_dir.mask_png(&pose.name);
                let instances = cam_dir.instances(&pose.name);
                if !mask.is_file() || !instances.is_file() {
                    missing += 1;
                    continue;
                }
                let rgb = cam_dir.rgb().join(format!("{}.png", pose.name));
                frames.push(FrameInput { pose, mask, instances, rgb });
            }
            cameras.push(CameraInput { name: cam_name, frames });
        }
        areas.push(AreaInput {
            name,
            manifest,
            manifest_split: split,
            split,
            buildings_path,
            source_ids,
            cameras,
        });
    }
    Ok((areas, missing))
}

/// One annotation before filtering and id assignment.
struct Draft {
    rle: Rle,
    building_id: BuildingId,
    source_id: String,
    component: Option<u32>,
    num_components: Option<u32>,
    visible_fraction: Option<f64>,
    truncated: bool,
}

struct FrameResult {
    image: Image,
    annotations: Vec<Annotation>,
    dropped: DropCounts,
}

/// What became of one frame.
enum Outcome {
    Annotated(Box<FrameResult>),
    /// Left out: its RGB frame is missing (`false`) or broken (`true`).
    NoRgb {
        broken: bool,
    },
    /// Left out: its consistency score is below `--min-consistency`.
    LowConsistency,
}

/// Whether `frame`'s RGB image exists, decodes, and has the frame's size: `Some(false)` missing,
/// `Some(true)` broken, `None` fine.
fn rgb_problem(frame: &FrameInput) -> Option<bool> {
    if !frame.rgb.is_file() {
        return Some(false);
    }
    let k = &frame.pose.view.intrinsics;
    match super::raster::read_png_rgb(&frame.rgb) {
        Ok(img) if (img.width, img.height) == (k.width_px, k.height_px) => None,
        _ => Some(true),
    }
}

/// Decodes, verifies and annotates one frame (ids are assigned later): checks its RGB frame (unless
/// `--label-only`), reads the instance list and the ID map, checks that they agree, makes one draft per
/// component (or building), filters and encodes them, and describes the image.
fn process_frame(
    area: &AreaInput,
    camera: &CameraInput,
    frame: &FrameInput,
    plan: &ExportPlan,
    licence: Option<u32>,
) -> Result<Outcome, CocoError> {
    if !plan.label_only {
        if let Some(broken) = rgb_problem(frame) {
            return Ok(Outcome::NoRgb { broken });
        }
    }
    let inst: FrameInstances = read_json(&frame.instances)?;
    if let Some(min) = plan.filters.min_consistency {
        let Some(o) = &inst.occlusion else {
            return Err(CocoError::MissingData {
                path: frame.instances.clone(),
                missing: MissingField::Consistency { area: area.name.clone(), camera: camera.name.clone() },
            });
        };
        if o.consistency < min {
            return Ok(Outcome::LowConsistency);
        }
    }
    let map = IdMap::read_png(&frame.mask)?;
    let (lab, kept) = verified_components(area, camera, frame, plan, &inst, &map)?;
    let drafts = drafts(plan.unit, frame, &inst, &lab, &kept)?;
    let (annotations, dropped) = annotations(drafts, plan, area, map.width(), map.height());
    let image = image_record(area, camera, frame, &inst, [map.width(), map.height()], licence);
    Ok(Outcome::Annotated(Box::new(FrameResult { image, annotations, dropped })))
}

/// The connected components of `map` and the indices of those `inst` lists, after checking that the
/// instance list, `poses.jsonl` and the ID map agree (frame, size, components, building table).
fn verified_components(
    area: &AreaInput,
    camera: &CameraInput,
    frame: &FrameInput,
    plan: &ExportPlan,
    inst: &FrameInstances,
    map: &IdMap,
) -> Result<(Labelling, Vec<usize>), CocoError> {
    let mismatch = |problem: MismatchProblem| CocoError::Mismatch {
        instances: frame.instances.clone(),
        id_map: frame.mask.clone(),
        problem: Box::new(problem),
    };
    let pose = &frame.pose;
    if inst.frame != pose.name {
        return Err(mismatch(MismatchProblem::Frame {
            found: inst.frame.clone(),
            expected: pose.name.clone(),
        }));
    }
    let (w, h) = (map.width(), map.height());
    if (inst.width, inst.height) != (w, h) {
        return Err(mismatch(MismatchProblem::InstancesSize {
            listed: [inst.width, inst.height],
            id_map: [w, h],
        }));
    }
    let k = &pose.view.intrinsics;
    if (k.width_px, k.height_px) != (w, h) {
        return Err(mismatch(MismatchProblem::PoseSize { pose: [k.width_px, k.height_px], id_map: [w, h] }));
    }
    let lab = label_components(map, inst.connectivity);
    let kept: Vec<usize> = (0..lab.components.len())
        .filter(|&i| lab.components[i].area_px >= inst.min_component_area_px)
        .collect();
    if kept.len() != inst.instances.len() {
        return Err(mismatch(MismatchProblem::InstanceCount {
            listed: inst.instances.len(),
            components: kept.len(),
            min_area_px: inst.min_component_area_px,
            connectivity: inst.connectivity,
        }));
    }
    for (n, (&ci, e)) in kept.iter().zip(&inst.instances).enumerate() {
        let c = &lab.components[ci];
        if (c.building_id, c.area_px, c.bbox_px, c.touches_border)
            != (e.building_id, e.area_px, e.bbox_px, e.truncated)
        {
            return Err(mismatch(MismatchProblem::Component {
                index: n,
                listed: ComponentFacts {
                    building_id: e.building_id,
                    area_px: e.area_px,
                    bbox_px: e.bbox_px,
                    truncated: e.truncated,
                },
                found: ComponentFacts {
                    building_id: c.building_id,
                    area_px: c.area_px,
                    bbox_px: c.bbox_px,
                    truncated: c.touches_border,
                },
            }));
        }
        match area.source_ids.get(&e.building_id) {
            None => {
                return Err(mismatch(MismatchProblem::UnknownBuilding {
                    index: n,
                    building_id: e.building_id,
                    buildings: area.buildings_path.clone(),
                }))
            }
            Some(s) if *s != e.source_id => {
                return Err(mismatch(MismatchProblem::SourceId {
                    index: n,
                    building_id: e.building_id,
                    listed: e.source_id.clone(),
                    table: s.clone(),
                    buildings: area.buildings_path.clone(),
                }))
            }
            Some(_) => {}
        }
        if plan.filters.min_visible_fraction.is_some() && e.visible_fraction.is_none() {
            return Err(CocoError::MissingData {
                path: frame.instances.clone(),
                missing: MissingField::VisibleFraction {
                    index: n,
                    area: area.name.clone(),
                    camera: camera.name.clone(),
                },
            });
        }
    }
    Ok((lab, kept))
}

/// One draft per listed component, or per building with its components merged.
fn drafts(
    unit: AnnotationUnit,
    frame: &FrameInput,
    inst: &FrameInstances,
    lab: &Labelling,
    kept: &[usize],
) -> Result<Vec<Draft>, CocoError> {
    let (w, h) = (lab.width, lab.height);
    let rles = encode_labels(&lab.labels, h, w, lab.components.len()).map_err(|source| CocoError::Rle {
        path: frame.mask.clone(),
        context: "encoding the connected components".into(),
        source,
    })?;
    Ok(match unit {
        AnnotationUnit::Component => kept
            .iter()
            .zip(&inst.instances)
            .map(|(&ci, e)| Draft {
                rle: rles[ci].clone(),
                building_id: e.building_id,
                source_id: e.source_id.clone(),
                component: Some(e.component),
                num_components: None,
                visible_fraction: e.visible_fraction,
                truncated: e.truncated,
            })
            .collect(),
        AnnotationUnit::Building => {
            let mut groups: BTreeMap<BuildingId, Vec<usize>> = BTreeMap::new();
            for (n, e) in inst.instances.iter().enumerate() {
                groups.entry(e.building_id).or_default().push(n);
            }
            let mut out = Vec::with_capacity(groups.len());
            for (bid, members) in groups {
                let parts: Vec<Rle> = members.iter().map(|&n| rles[kept[n]].clone()).collect();
                let rle = Rle::union(&parts).map_err(|source| CocoError::Rle {
                    path: frame.mask.clone(),
                    context: format!("merging the components of building {bid}"),
                    source,
                })?;
                let first = &inst.instances[members[0]];
                out.push(Draft {
                    rle,
                    building_id: bid,
                    source_id: first.source_id.clone(),
                    component: None,
                    num_components: Some(members.len() as u32),
                    visible_fraction: first.visible_fraction,
                    truncated: members.iter().any(|&n| inst.instances[n].truncated),
                });
            }
            out
        }
    })
}

/// The drafts that pass the filters, encoded (RLE, or polygons with `--polygons`), and what the
/// filters dropped.
fn annotations(
    drafts: Vec<Draft>,
    plan: &ExportPlan,
    area: &AreaInput,
    w: u32,
    h: u32,
) -> (Vec<Annotation>, DropCounts) {
    let f = &plan.filters;
    let mut dropped = DropCounts::default();
    let mut annotations = Vec::with_capacity(drafts.len());
    for d in drafts {
        let area_px = d.rle.area();
        if area_px < f.min_area_px {
            dropped.small += 1;
            continue;
        }
        if let (Some(min), Some(v)) = (f.min_visible_fraction, d.visible_fraction) {
            if v < min {
                dropped.low_visibility += 1;
                continue;
            }
        }
        if d.truncated && f.truncated == TruncatedPolicy::Drop {
            dropped.truncated += 1;
            continue;
        }
        let iscrowd = (d.truncated && f.truncated == TruncatedPolicy::Flag) as u8;
        let rle_json = RleJson::from(&d.rle);
        let (segmentation, mask_rle) = if plan.polygons {
            let mask = d.rle.decode();
            let polys = super::polygon::mask_to_polygons(&mask, w, h);
            if polys.is_empty() {
                (Segmentation::Rle(rle_json), None)
            } else {
                (Segmentation::Polygons(polys), Some(rle_json))
            }
        } else {
            (Segmentation::Rle(rle_json), None)
        };
        annotations.push(Annotation {
            id: 0,
            image_id: 0,
            category_id: BUILDING_CATEGORY_ID,
            segmentation,
            area: area_px,
            bbox: d.rle.to_bbox(),
            iscrowd,
            building_id: d.building_id,
            source_id: d.source_id,
            component: d.component,
            num_components: d.num_components,
            visible_fraction: d.visible_fraction,
            truncated: d.truncated,
            area_name: area.name.clone(),
            mask_rle,
        });
    }

    (annotations, dropped)
}

/// The image record of a frame (ids are assigned later).
fn image_record(
    area: &AreaInput,
    camera: &CameraInput,
    frame: &FrameInput,
    inst: &FrameInstances,
    [w, h]: [u32; 2],
    licence: Option<u32>,
) -> Image {
    let pose = &frame.pose;
    let base = format!("{}/{}", area.name, camera.name);
    let mask_file = format!("{base}/masks/{}.png", pose.name);
    let file_name = format!("{base}/rgb/{}.png", pose.name);
    Image {
        id: 0,
        file_name,
        width: w,
        height: h,
        license: licence,
        area_name: area.name.clone(),
        camera: camera.name.clone(),
        preset: pose.preset.clone(),
        frame: pose.name.clone(),
        mask_file,
        connectivity: inst.connectivity,
        view: pose.view,
        geo: pose.geo,
        look: frame_look(&frame.rgb),
        consistency: inst.occlusion.as_ref().map(|o| o.consistency),
        ignore_file: inst
            .occlusion
            .as_ref()
            .filter(|o| o.mode == crate::label::occlusion::OcclusionMode::Ignore)
            .map(|_| format!("{base}/masks/{}.ignore.png", pose.name)),
    }
}

/// The `look` of an RGB frame's render metadata (`rgb/<frame>.render.json`), when there is one.
fn frame_look(rgb: &Path) -> Option<serde_json::Value> {
    let meta = rgb.with_extension(crate::layout::RGB_META_SUFFIX);
    let bytes = std::fs::read(meta).ok()?;
    match serde_json::from_slice::<serde_json::Value>(&bytes).ok()? {
        serde_json::Value::Object(mut m) => m.remove("look"),
        _ => None,
    }
}

/// `image_root` for files in `out_dir`: the relative path from `out_dir` to `workdir` when the output
/// lies inside the workdir (`..` by default), else the workdir's absolute path.
pub(crate) fn image_root(workdir: &Path, out_dir: &Path) -> String {
    let (Ok(wd), Ok(out)) = (workdir.canonicalize(), out_dir.canonicalize()) else {
        return workdir.display().to_string();
    };
    match out.strip_prefix(&wd) {
        Ok(rel) => {
            let n = rel.components().count();
            if n == 0 {
                ".".to_string()
            } else {
                vec![".."; n].join("/")
            }
        }
        Err(_) => wd.display().to_string(),
    }
}

/// Builds the three datasets without writing anything; `info.image_root` is set to `image_root`.
///
/// # Errors
/// [`CocoError::Layout`] when there is no prepared area, for an unknown split or inconsistent names;
/// [`CocoError::UnknownHoldout`]; [`CocoError::Frames`] when frames fail (ID map and instance file
/// disagree, unreadable files, …), listing every failing frame.
pub fn build(plan: &ExportPlan, image_root: &str, progress: &dyn Progress) -> Result<Export, CocoError> {
    let (mut areas, frames_without_masks) = discover(&plan.workdir, plan.shard)?;
    if areas.is_empty() {
        return Err(CocoError::Layout { path: plan.workdir.clone(), problem: LayoutProblem::NoArea });
    }
    for h in &plan.holdout {
        match areas.iter_mut().find(|a| &a.name == h) {
            Some(a) => a.split = Split::Test,
            None => {
                return Err(CocoError::UnknownHoldout {
                    area: h.clone(),
                    workdir: plan.workdir.clone(),
                    available: areas.iter().map(|a| a.name.clone()).collect(),
                })
            }
        }
    }
    // Licences: one per distinct attribution over all areas, ids in sorted order of the text.
    let attributions: BTreeSet<&str> =
        areas.iter().flat_map(|a| a.manifest.attributions.iter().map(String::as_str)).collect();
    let licence_id: BTreeMap<&str, u32> =
        attributions.iter().enumerate().map(|(i, &s)| (s, i as u32 + 1)).collect();

    let jobs: Vec<(&AreaInput, &CameraInput, &FrameInput)> = areas
        .iter()
        .flat_map(|a| a.cameras.iter().flat_map(move |c| c.frames.iter().map(move |f| (a, c, f))))
        .collect();
    progress.start(jobs.len() as u64, "frames");
    let results: Vec<Result<Outcome, CocoError>> = jobs
        .par_iter()
        .map(|&(a, c, f)| {
            let licence = a.manifest.attributions.first().and_then(|s| licence_id.get(s.as_str()).copied());
            crate::util::interrupt::check()?;
            let r = process_frame(a, c, f, plan, licence);
            progress.inc(1);
            r
        })
        .collect();
    progress.finish();
    crate::util::interrupt::check()?;

    let total = results.len();
    let mut frames = Vec::with_capacity(total);
    let mut errors = Vec::new();
    for r in results {
        match r {
            Ok(f) => frames.push(f),
            Err(e) => errors.push(e),
        }
    }
    if !errors.is_empty() {
        let failed = errors.len();
        let mut it = errors.into_iter();
        let first = Box::new(it.next().expect("errors is not empty"));
        let others = it.map(|e| chain_string(&e)).collect();
        return Err(CocoError::Frames { failed, total, first, others });
    }

    let mut dropped = DropCounts::default();
    let mut datasets = empty_datasets(&areas, plan, image_root, &licence_id);
    let frames_without_rgb = fill_datasets(&areas, frames, plan, &mut datasets, &mut dropped);
    Ok(Export { datasets, frames_without_masks, frames_without_rgb, dropped, stats: None })
}

/// One empty dataset per split: its info (areas, sources, filters, image root) and licences.
fn empty_datasets(
    areas: &[AreaInput],
    plan: &ExportPlan,
    image_root: &str,
    licence_id: &BTreeMap<&str, u32>,
) -> Vec<(Split, Dataset)> {
    Split::ALL
        .into_iter()
        .map(|split| {
            let split_areas: Vec<&AreaInput> = areas.iter().filter(|a| a.split == split).collect();
            let used: BTreeSet<&str> =
                split_areas.iter().flat_map(|a| a.manifest.attributions.iter().map(String::as_str)).collect();
            let licenses = used
                .into_iter()
                .map(|s| License { id: licence_id[s], name: s.to_string(), url: licence_url(s) })
                .collect();
            let info = Info {
                description: format!(
                    "insgen synthetic building instances ({} split) for UAV localization against LoD models",
                    split
                ),
                version: env!("CARGO_PKG_VERSION").to_string(),
                contributor: "insgen".into(),
                url: String::new(),
                split: split.as_str().into(),
                image_root: image_root.to_string(),
                images_missing: plan.label_only,
                annotation_unit: plan.unit,
                filters: plan.filters,
                areas: split_areas
                    .iter()
                    .map(|a| AreaInfo {
                        name: a.name.clone(),
                        manifest_split: a.manifest_split.as_str().into(),
                        held_out: a.split != a.manifest_split,
                        buildings: a.source_ids.len() as u64,
                        sources: a
                            .manifest
                            .sources
                            .iter()
                            .map(|s| SourceInfo {
                                path: s.path.clone(),
                                sha256: s.sha256.clone(),
                                procedural: s.procedural.clone(),
                            })
                            .collect(),
                        attributions: a.manifest.attributions.clone(),
                    })
                    .collect(),
            };
            let ds = Dataset {
                info,
                licenses,
                images: Vec::new(),
                annotations: Vec::new(),
                categories: vec![Category::building()],
            };
            (split, ds)
        })
        .collect()
}

/// Puts each frame's image and annotations into its split's dataset (ids in order), counting what
/// the filters dropped; returns the cameras whose frames have no RGB photo.
fn fill_datasets(
    areas: &[AreaInput],
    frames: Vec<Outcome>,
    plan: &ExportPlan,
    datasets: &mut [(Split, Dataset)],
    dropped: &mut DropCounts,
) -> Vec<MissingRgb> {
    // Frames are in job order: areas, cameras, frames sorted by name.
    let mut frame_iter = frames.into_iter();
    let mut frames_without_rgb = Vec::new();
    for a in areas {
        let ds = &mut datasets.iter_mut().find(|(s, _)| *s == a.split).expect("every split has a dataset").1;
        for c in &a.cameras {
            let mut missing =
                MissingRgb { area: a.name.clone(), camera: c.name.clone(), frames: 0, broken: Vec::new() };
            for frame in &c.frames {
                let f = match frame_iter.next().expect("one result per frame") {
                    Outcome::Annotated(f) => *f,
                    Outcome::NoRgb { broken } => {
                        missing.frames += 1;
                        if broken && missing.broken.len() < 5 {
                            missing.broken.push(frame.rgb.clone());
                        }
                        continue;
                    }
                    Outcome::LowConsistency => {
                        dropped.low_consistency_images += 1;
                        continue;
                    }
                };
                dropped.add(&f.dropped);
                if f.annotations.is_empty() && !plan.filters.keep_empty_images {
                    dropped.empty_images += 1;
                    continue;
                }
                let image_id = ds.images.len() as u64 + 1;
                let mut image = f.image;
                image.id = image_id;
                ds.images.push(image);
                for mut ann in f.annotations {
                    ann.id = ds.annotations.len() as u64 + 1;
                    ann.image_id = image_id;
                    ds.annotations.push(ann);
                }
            }
            if missing.frames > 0 {
                frames_without_rgb.push(missing);
            }
        }
    }
    frames_without_rgb
}

/// Builds the datasets and writes `instances_{train,val,test}.json`, `dataset.json` and `README.md`
/// into `plan.out_dir` (atomically, compact JSON with a trailing newline) — or, for a shard of the
/// frames, its part ([`super::parts::write_part`], asking the combined export for the default
/// statistics report). Returns the export and the files written.
///
/// # Errors
/// As [`build`], plus I/O errors naming the file.
pub fn export(plan: &ExportPlan, progress: &dyn Progress) -> Result<(Export, Vec<PathBuf>), CocoError> {
    // What a killed export left in the output directory and its parts (a live shard's temporary
    // files are locked and stay). Not deeper: `--out` may be any directory.
    crate::util::remove_stale_temps(&plan.out_dir, false, &|_| false)?;
    crate::util::remove_stale_temps(&plan.out_dir.join(crate::util::shard::PARTS_DIR), true, &|_| false)?;
    // Build first, so that a failing export leaves no empty output directory behind.
    let ex = build(plan, "..", progress)?;
    if plan.shard.is_whole() && ex.datasets.iter().all(|(_, ds)| ds.images.is_empty()) {
        return Err(CocoError::EmptyExport { workdir: plan.workdir.clone(), gap: empty_gap(&ex) });
    }
    if !plan.shard.is_whole() {
        let written = super::parts::write_part(plan, &ex, Some(super::stats::ReportOptions::default()))?;
        return Ok((ex, written));
    }
    write_export(plan, ex)
}

/// Why `ex` lists no image.
fn empty_gap(ex: &Export) -> super::error::EmptyGap {
    use super::error::EmptyGap;
    if let Some(m) = ex.frames_without_rgb.iter().find(|m| m.frames > 0) {
        return EmptyGap::NoRgb { area: m.area.clone(), camera: m.camera.clone(), frames: m.frames };
    }
    if ex.frames_without_masks > 0 {
        return EmptyGap::NoMasks { frames: ex.frames_without_masks };
    }
    let d = &ex.dropped;
    if d.empty_images > 0 || d.low_consistency_images > 0 {
        return EmptyGap::Filtered {
            low_consistency_images: d.low_consistency_images,
            empty_images: d.empty_images,
        };
    }
    EmptyGap::NoFrames
}

/// Writes built datasets as [`export`] does: the photos and ID maps placed in `plan.out_dir`
/// ([`super::bundle`]; under `plan.link_root`, `info.image_root` pointing at the work directory
/// instead), the COCO files, then the manifest and the card that describe them (the card's
/// learnability table reads the frames' ID maps and photos).
///
/// # Errors
/// I/O errors naming the file, and an ID map or photo that is on disk but unreadable.
pub fn write_export(plan: &ExportPlan, mut ex: Export) -> Result<(Export, Vec<PathBuf>), CocoError> {
    crate::util::create_dir_all(&plan.out_dir)?;
    // Read beside the photos in the work directory, before their names move into the export.
    let rgb_render = super::manifest::rgb_render_settings(&plan.workdir, &ex.datasets);
    let mut placed = Vec::new();
    if plan.link_root {
        let root = image_root(&plan.workdir, &plan.out_dir);
        for (_, ds) in &mut ex.datasets {
            ds.info.image_root = root.clone();
        }
    } else {
        let (count, names) = super::bundle::place_files(&plan.workdir, &plan.out_dir, &mut ex.datasets)?;
        log::debug!("placed {count} photo and ID map file(s) in {}", plan.out_dir.display());
        placed = names;
    }
    let mut written = Vec::new();
    let mut files = Vec::new();
    for (split, ds) in &ex.datasets {
        let path = plan.out_dir.join(split.file_name());
        write_dataset(&path, ds)?;
        files.push((*split, split.file_name(), crate::util::sha256_file(&path)?));
        written.push(path);
    }
    // Hugging Face `datasets` metadata beside the photos of a self-contained export whose photos are
    // all there (not label-only); the card's front matter names it.
    let mut hf_splits = Vec::new();
    if !plan.link_root && !ex.datasets.iter().any(|(_, ds)| ds.info.images_missing) {
        let hf = super::hf::write_metadata(&plan.out_dir, &ex.datasets)?;
        hf_splits = super::hf::loadable_splits(&hf);
        for f in hf.into_iter().filter_map(|h| h.file) {
            placed.push(relative_name(&plan.out_dir, &f));
            written.push(f);
        }
    }
    // The manifest and the card last: they describe the files above.
    let mut manifest = super::manifest::DatasetManifest::new(plan, &ex.datasets, &files, rgb_render);
    if !plan.link_root {
        placed.extend(files.iter().map(|(_, name, _)| name.clone()));
        let (sha256, count) = super::bundle::write_checksums(&plan.out_dir, &placed)?;
        let path = crate::layout::CHECKSUMS_FILE.to_string();
        written.push(plan.out_dir.join(&path));
        manifest.checksums = Some(super::manifest::ChecksumsEntry { path, sha256, files: count });
    }
    manifest.write(&plan.out_dir)?;
    written.push(plan.out_dir.join(super::manifest::MANIFEST_FILE));
    let refs: Vec<(Split, &Dataset)> = ex.datasets.iter().map(|(s, d)| (*s, d)).collect();
    let stats = super::stats::compute(&refs, plan.names_root())?;
    let card = super::card::card_markdown(&manifest, &stats, &hf_splits);
    let card_path = plan.out_dir.join(super::card::CARD_FILE);
    crate::util::write_bytes_atomic(&card_path, card.as_bytes())?;
    written.push(card_path);
    ex.stats = Some(stats);
    Ok((ex, written))
}

/// `path` (inside `dir`) relative to `dir`, `/`-separated, as `SHA256SUMS` names files.
fn relative_name(dir: &Path, path: &Path) -> String {
    let rel = path.strip_prefix(dir).unwrap_or(path);
    rel.components().map(|c| c.as_os_str().to_string_lossy()).collect::<Vec<_>>().join("/")
}

/// Writes a dataset as compact JSON atomically.
///
/// # Errors
/// I/O or serialisation errors naming `path`.
pub fn write_dataset(path: &Path, ds: &Dataset) -> Result<(), CocoError> {
    let mut bytes = serde_json::to_vec(ds).map_err(|e| CocoError::json(path, e))?;
    bytes.push(b'\n');
    crate::util::write_bytes_atomic(path, &bytes)?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn split_names_round_trip() {
        for s in Split::ALL {
            assert_eq!(Split::parse(s.as_str()), Some(s));
        }
        assert_eq!(Split::parse("validation"), None);
        assert_eq!(Split::Val.file_name(), "instances_val.json");
    }

    #[test]
    fn image_root_is_relative_inside_the_workdir() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("coco");
        std::fs::create_dir_all(&out).unwrap();
        assert_eq!(image_root(dir.path(), &out), "..");
        let deep = dir.path().join("a/b");
        std::fs::create_dir_all(&deep).unwrap();
        assert_eq!(image_root(dir.path(), &deep), "../..");
        let other = tempfile::tempdir().unwrap();
        assert_eq!(
            image_root(dir.path(), other.path()),
            dir.path().canonicalize().unwrap().display().to_string()
        );
    }
}
