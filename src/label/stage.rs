//! The `render-masks` stage: reads the prepared scene and `<camera>/poses.jsonl`, renders every
//! frame's instance-ID map with exactly the frame's intrinsics and pose, and writes per frame
//! (each file atomically):
//!
//! - `masks/<frame>.png`: the 24-bit RGB ID map ([`IdMap::write_png`]);
//! - `masks/<frame>.instances.json`: one entry per connected component ([`FrameInstances`]);
//! - `masks/<frame>.depth.exr` (with `depth`): float32 channel `Z`, metres along the optical axis,
//!   0 where no building was hit;
//!
//! - `masks/<frame>.ignore.png` (with a tileset in [`OcclusionMode::Ignore`]): 8-bit grey, 255 where a
//!   LoD building pixel was removed because the tileset shows something in front of it, 0 elsewhere;
//!
//! and, with `preview = K`, contact sheets `masks/preview_XX.png` of K frames ([`super::overlay`]).
//!
//! # Instances
//! Components come from [`label_components`] with the chosen connectivity (default 8). Components
//! smaller than `min_area_px` are left out of the instance list (they stay in the PNG). The default,
//! [`DEFAULT_MIN_AREA_PX`] = 16 px (a 4 × 4 patch), drops the one-to-few-pixel slivers that appear where
//! a roof edge peeks between two towers or along silhouettes at grazing angles: they are too small to
//! annotate or learn, and at 1920 × 1080 they would otherwise outnumber real instances in dense areas.
//! `component` keeps the index among *all* the building's components in the frame, so a gap means a
//! dropped fragment. `building_visible_px` counts every visible pixel of the building, dropped
//! fragments included. `visible_fraction` (optional, one extra render per visible building) is
//! `building_visible_px` divided by the pixels the building covers in the frame when rendered alone.
//!
//! # Masks that respect a tileset
//! With [`MaskPlan::tileset`], the tileset's surface (finest level, in the area's ENU frame) is
//! uploaded once and its linear depth rendered at every frame by the same renderer; the LoD depth is
//! the mask render's own. [`occlude`] then removes (or marks as ignore) the building pixels where the
//! tileset shows something in front, *before* components are labelled, so the PNG, the instances,
//! `visible_fraction` and everything downstream follow the final masks. The counts and the
//! consistency score go into the instance list ([`OcclusionRecord`]); the tileset's SHA-256, the mode
//! and the threshold are part of the frame fingerprint.
//!
//! # Throughput and resumption
//! Rendering runs on the calling thread with several frames in flight; labelling, PNG encoding and
//! writing run on the rayon pool, fed through a bounded channel, so CPU work overlaps the GPU. A frame
//! whose PNG and JSON exist and verify (PNG header and IEND, JSON parses and matches the frame, size and
//! settings) is skipped unless `force`. `shard = i/N` takes the frames whose line index in poses.jsonl
//! is ≡ i (mod N); `limit` keeps the first frames of the shard.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};
use std::sync::mpsc;
use std::sync::Mutex;
use std::time::Instant;

use rayon::iter::{IntoParallelRefIterator, ParallelBridge, ParallelIterator};

use super::occlusion::{occlude, OcclusionError, OcclusionMode, OcclusionRecord};
use super::overlay::{self, OverlayError};
use super::{label_components, Connectivity, FrameInstances, InstanceEntry};
use crate::camera::record::read_jsonl;
use crate::camera::{CameraError, PoseRecord};
use crate::render::{DepthRange, IdRenderer, IdScene, RenderError, RenderOptions, RenderedFrame, View};
use crate::scene::clutter::ClutterLayer;
use crate::scene::{BuildingId, IdError, IdMap, PreparedScene};
use crate::util::{FileError, Progress, Shard};

/// Default minimum component area kept in the instance lists, pixels (see the module doc).
pub const DEFAULT_MIN_AREA_PX: u64 = 16;

use crate::layout::{MASKS_DIR, POSES_FILE, RGB_DIR};

/// Frames per contact sheet (4 columns × 3 rows) and the width of one tile.
const SHEET_COLUMNS: u32 = 4;
const SHEET_TILES: usize = 12;
const TILE_WIDTH_PX: u32 = 480;

/// Errors of the render-masks stage.
#[derive(Debug, thiserror::Error)]
pub enum StageError {
    /// Reading or writing a file failed.
    #[error(transparent)]
    File(#[from] FileError),
    /// poses.jsonl is malformed.
    #[error(transparent)]
    Poses(#[from] CameraError),
    /// The scene's mesh holds a building ID that its building table (`buildings.json`) lacks.
    #[error(
        "scene: the mesh holds building ID {id} but buildings.json has no such row; re-run `insgen prepare`"
    )]
    UnknownBuilding {
        /// The smallest such ID.
        id: BuildingId,
    },
    /// The thread writing the frames panicked (a bug); the frames it finished are complete.
    #[error("a frame writer thread panicked")]
    WriterPanicked,
    /// The renderer failed.
    #[error(transparent)]
    Render(#[from] RenderError),
    /// A rendered or stored ID map is not an ID map.
    #[error(transparent)]
    Ids(#[from] IdError),
    /// A preview contact sheet cannot be written.
    #[error(transparent)]
    Overlay(#[from] OverlayError),
    /// Stopped by Ctrl-C; the frames written so far are complete.
    #[error(transparent)]
    Interrupted(#[from] crate::util::interrupt::Interrupted),
    /// The tileset of [`MaskPlan::tileset`] could not be read.
    #[error("reading the photogrammetry tileset ({})", path.display())]
    Tileset {
        /// The tileset JSON.
        path: PathBuf,
        /// The reader's or renderer's error.
        #[source]
        source: Box<dyn std::error::Error + Send + Sync>,
    },
    /// The LoD and tileset renders cannot be compared.
    #[error(transparent)]
    Occlusion(#[from] OcclusionError),
    /// Writing the depth EXR failed.
    #[error("{}: writing the depth EXR failed", path.display())]
    Exr {
        /// The EXR being written.
        path: PathBuf,
        /// The EXR encoder's error.
        #[source]
        source: exr::error::Error,
    },
}

/// What the stage does, resolved from the command line (STYLE rule 2).
#[derive(Debug, Clone, PartialEq)]
pub struct MaskPlan {
    /// `<workdir>/<area>/<camera>`: holds poses.jsonl, receives masks/.
    pub camera_dir: PathBuf,
    /// Pixel connectivity of components.
    pub connectivity: Connectivity,
    /// Components below this many pixels are left out of the instance lists.
    pub min_area_px: u64,
    /// Compute `visible_fraction` (one extra render per visible building).
    pub visible_fraction: bool,
    /// Write `<frame>.depth.exr`.
    pub depth: bool,
    /// Frames shown in contact sheets (0 = none).
    pub preview: usize,
    /// Re-render frames whose outputs verify.
    pub force: bool,
    /// Which frames of poses.jsonl this run takes.
    pub shard: Shard,
    /// At most this many frames of the shard.
    pub limit: Option<usize>,
    /// Clip planes.
    pub range: DepthRange,
    /// Clutter layers drawn as occluders (ID 0) when the scene has them
    /// (default [`ClutterLayer::DEFAULT_OCCLUDERS`]: trees and cars).
    pub occluders: Vec<ClutterLayer>,
    /// Compare every frame with a photogrammetry tileset's depth (see the module doc).
    pub tileset: Option<TilesetOcclusion>,
}

/// Default `--occlusion-threshold-m`: how far in front of a LoD surface the tileset must be for the
/// pixel to count as occluded (absorbs photogrammetry noise and the residual misalignment).
pub const DEFAULT_OCCLUSION_THRESHOLD_M: f32 = 1.5;

/// The tileset masks are compared with.
#[derive(Debug, Clone, PartialEq)]
pub struct TilesetOcclusion {
    /// Its tileset.json.
    pub path: PathBuf,
    /// Remove occluded pixels, or also mark them in `<frame>.ignore.png`.
    pub mode: OcclusionMode,
    /// See [`DEFAULT_OCCLUSION_THRESHOLD_M`].
    pub threshold_m: f32,
}

impl MaskPlan {
    /// A plan with the defaults for everything but the directory.
    pub fn new(camera_dir: PathBuf) -> Self {
        MaskPlan {
            camera_dir,
            connectivity: Connectivity::Eight,
            min_area_px: DEFAULT_MIN_AREA_PX,
            visible_fraction: false,
            depth: false,
            preview: 0,
            force: false,
            shard: Shard::default(),
            limit: None,
            range: DepthRange::default(),
            occluders: ClutterLayer::DEFAULT_OCCLUDERS.to_vec(),
            tileset: None,
        }
    }

    /// `poses.jsonl`.
    pub fn poses_path(&self) -> PathBuf {
        self.camera_dir.join(POSES_FILE)
    }

    /// `masks/`.
    pub fn masks_dir(&self) -> PathBuf {
        self.camera_dir.join(MASKS_DIR)
    }

    /// `masks/<frame>.png`.
    pub fn png_path(&self, frame: &str) -> PathBuf {
        self.masks_dir().join(format!("{frame}.png"))
    }

    /// `masks/<frame>.instances.json`.
    pub fn instances_path(&self, frame: &str) -> PathBuf {
        self.masks_dir().join(format!("{frame}.instances.json"))
    }

    /// `masks/<frame>.depth.exr`.
    pub fn depth_path(&self, frame: &str) -> PathBuf {
        self.masks_dir().join(format!("{frame}.depth.exr"))
    }

    /// `masks/<frame>.ignore.png` (with a tileset in ignore mode).
    pub fn ignore_path(&self, frame: &str) -> PathBuf {
        self.masks_dir().join(format!("{frame}.ignore.png"))
    }

    /// `rgb/<frame>.png` (written by the RGB stage, used as the preview backdrop).
    pub fn rgb_path(&self, frame: &str) -> PathBuf {
        self.camera_dir.join(RGB_DIR).join(format!("{frame}.png"))
    }
}

/// A frame that could not be written; the others went on.
#[derive(Debug, Clone, PartialEq)]
pub struct FrameFailure {
    /// Frame name.
    pub frame: String,
    /// The error with its causes, `: `-separated.
    pub error: String,
}

/// What the stage did.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct MaskReport {
    /// Frames in poses.jsonl.
    pub frames_total: usize,
    /// Frames in this shard (after `limit`).
    pub frames_selected: usize,
    /// Frames rendered and written in this run.
    pub rendered: usize,
    /// Frames whose outputs already existed and verified.
    pub skipped: usize,
    /// Frames that could not be written, by name.
    pub failed: Vec<FrameFailure>,
    /// Instances (components above the minimum area) written.
    pub instances: u64,
    /// Wall time of the whole stage, seconds.
    pub seconds: f64,
    /// Rendered frames per second of wall time, including labelling and writing.
    pub frames_per_s: f64,
    /// Contact sheets written.
    pub previews: Vec<PathBuf>,
}

pub use crate::util::error_chain;

/// SHA-256 (hex) of a pose record's JSON: what a frame's outputs were rendered from.
pub fn pose_digest(rec: &PoseRecord) -> String {
    use sha2::Digest;
    let json = serde_json::to_vec(rec).expect("a pose record serialises");
    hex::encode(sha2::Sha256::digest(&json))
}

/// Whether a frame's outputs exist and match what this plan would write (same pose, size and
/// settings).
fn outputs_verify(
    plan: &MaskPlan,
    rec: &PoseRecord,
    occluders: &[ClutterLayer],
    tileset_sha256: Option<&str>,
) -> bool {
    let k = &rec.view.intrinsics;
    match IdMap::read_png_size(&plan.png_path(&rec.name)) {
        Ok(size) if size == (k.width_px, k.height_px) => {}
        _ => return false,
    }
    let Ok(bytes) = std::fs::read(plan.instances_path(&rec.name)) else { return false };
    let Ok(fi) = serde_json::from_slice::<FrameInstances>(&bytes) else { return false };
    let settings_match = fi.frame == rec.name
        && fi.pose_sha256.as_deref() == Some(pose_digest(rec).as_str())
        && (fi.width, fi.height) == (k.width_px, k.height_px)
        && fi.connectivity == plan.connectivity
        && fi.min_component_area_px == plan.min_area_px
        && fi.occluders == occluders
        && match (&plan.tileset, tileset_sha256, &fi.occlusion) {
            (None, _, None) => true,
            (Some(t), Some(sha), Some(o)) => {
                o.tileset_sha256 == sha && o.mode == t.mode && o.threshold_m == t.threshold_m
            }
            _ => false,
        }
        && (plan.tileset.as_ref().is_none_or(|t| t.mode != OcclusionMode::Ignore)
            || plan.ignore_path(&rec.name).is_file())
        && (!plan.visible_fraction || fi.instances.iter().all(|e| e.visible_fraction.is_some()));
    if !settings_match {
        return false;
    }
    if plan.depth {
        match exr::meta::MetaData::read_from_file(plan.depth_path(&rec.name), false) {
            Ok(meta) => {
                let ok = meta.headers.first().is_some_and(|h| {
                    h.layer_size.width() == k.width_px as usize
                        && h.layer_size.height() == k.height_px as usize
                });
                if !ok {
                    return false;
                }
            }
            Err(_) => return false,
        }
    }
    true
}

/// Writes a single-channel float32 EXR (`Z`, metres) atomically.
///
/// # Errors
/// [`StageError::Exr`] or [`StageError::File`], naming `path`.
pub fn write_depth_exr(path: &Path, depth_m: &[f32], width: u32, height: u32) -> Result<(), StageError> {
    use exr::prelude::*;
    let channel = AnyChannel::new("Z", FlatSamples::F32(depth_m.to_vec()));
    let layer = Layer::new(
        (width as usize, height as usize),
        LayerAttributes::default(),
        Encoding::FAST_LOSSLESS,
        AnyChannels::sort(SmallVec::from_vec(vec![channel])),
    );
    let image = Image::from_layer(layer);
    let mut buf = std::io::Cursor::new(Vec::new());
    image
        .write()
        .to_buffered(&mut buf)
        .map_err(|source| StageError::Exr { path: path.to_path_buf(), source })?;
    crate::util::write_bytes_atomic(path, buf.get_ref())?;
    Ok(())
}

/// The instance list of one rendered frame.
pub fn frame_instances(
    frame: &str,
    map: &IdMap,
    connectivity: Connectivity,
    min_area_px: u64,
    source_ids: &BTreeMap<BuildingId, String>,
    amodal_px: Option<&BTreeMap<BuildingId, u64>>,
) -> FrameInstances {
    let labelling = label_components(map, connectivity);
    let mut visible: BTreeMap<BuildingId, u64> = BTreeMap::new();
    for c in &labelling.components {
        *visible.entry(c.building_id).or_insert(0) += c.area_px;
    }
    let instances = labelling
        .components
        .iter()
        .filter(|c| c.area_px >= min_area_px)
        .map(|c| {
            let building_visible_px = visible[&c.building_id];
            InstanceEntry {
                building_id: c.building_id,
                source_id: source_ids.get(&c.building_id).cloned().unwrap_or_default(),
                component: c.index,
                area_px: c.area_px,
                bbox_px: c.bbox_px,
                truncated: c.touches_border,
                building_visible_px,
                occluded_px: None,
                behind_px: None,
                see_through: None,
                visible_fraction: amodal_px.map(|m| match m.get(&c.building_id) {
                    Some(&a) if a > 0 => building_visible_px as f64 / a as f64,
                    _ => 1.0,
                }),
            }
        })
        .collect();
    FrameInstances {
        frame: frame.to_string(),
        width: map.width(),
        height: map.height(),
        connectivity,
        min_component_area_px: min_area_px,
        instances,
        pose_sha256: None,
        occluders: Vec::new(),
        occlusion: None,
    }
}

/// The mesh the masks are rendered from: the buildings, plus the scene's clutter layers in `occluders`
/// as ID-0 triangles (they hide buildings and write background).
pub fn occluded_mesh<'a>(
    scene: &'a PreparedScene,
    occluders: &[ClutterLayer],
) -> std::borrow::Cow<'a, crate::scene::SceneMesh> {
    let present = scene.clutter.layers.iter().any(|(l, _)| occluders.contains(l));
    if !present {
        return std::borrow::Cow::Borrowed(&scene.mesh);
    }
    let mut mesh = scene.mesh.clone();
    scene.clutter.append_occluders(&mut mesh, occluders);
    std::borrow::Cow::Owned(mesh)
}

/// The occluder layers actually present in the scene (recorded in each frame's instance list).
fn occluders_used(scene: &PreparedScene, occluders: &[ClutterLayer]) -> Vec<ClutterLayer> {
    scene.clutter.layers.iter().map(|(l, _)| *l).filter(|l| occluders.contains(l)).collect()
}

/// One rendered frame travelling from the render thread to the writers.
struct Job {
    record: usize,
    image: RenderedFrame,
    /// The tileset's linear depth at the frame (with a tileset).
    tiles_depth_m: Option<Vec<f32>>,
    amodal_px: Option<BTreeMap<BuildingId, u64>>,
}

/// Runs the stage (see the module doc) with `renderer` (wgpu from the CLI unless `--renderer cpu`).
///
/// # Errors
/// [`StageError::Poses`] for unreadable poses, [`StageError::UnknownBuilding`] when the mesh
/// holds IDs absent from the building table, [`StageError::Render`] when the renderer fails (fatal). A
/// frame whose outputs cannot be written is reported in [`MaskReport::failed`] and the others go on.
pub fn render_masks(
    plan: &MaskPlan,
    scene: &PreparedScene,
    renderer: &dyn IdRenderer,
    progress: &dyn Progress,
) -> Result<MaskReport, StageError> {
    let started = Instant::now();
    let records = read_jsonl(&plan.poses_path())?;
    let mut selected: Vec<usize> = (0..records.len()).filter(|&i| plan.shard.contains(i)).collect();
    if let Some(limit) = plan.limit {
        selected.truncate(limit);
    }
    let source_ids: BTreeMap<BuildingId, String> =
        scene.buildings.iter().map(|b| (b.id, b.source_id.clone())).collect();
    let mesh = occluded_mesh(scene, &plan.occluders);
    let unknown =
        mesh.building_ids.iter().filter(|b| !b.is_background() && !source_ids.contains_key(b)).min();
    if let Some(b) = unknown {
        return Err(StageError::UnknownBuilding { id: *b });
    }
    // The area's meshes are relative to its origin, near every camera.
    let id_scene = renderer.prepare(&mesh, glam::DVec3::ZERO)?;
    let occluders = occluders_used(scene, &plan.occluders);
    let tileset_sha256 = match &plan.tileset {
        None => None,
        Some(t) => Some(crate::lod::tiles3d::fingerprint(&t.path).map_err(|e| tileset_err(&t.path, e))?),
    };
    let tileset_sha256 = tileset_sha256.as_deref();
    // Verifying reads every existing PNG header and JSON: spread it over the pool.
    let todo: Vec<usize> = {
        selected
            .par_iter()
            .copied()
            .filter(|&i| plan.force || !outputs_verify(plan, &records[i], &occluders, tileset_sha256))
            .collect()
    };
    let skipped = selected.len() - todo.len();
    if skipped > 0 {
        log::info!("{skipped} frames already rendered (use --force to redo them)");
    }
    let tiles = match &plan.tileset {
        Some(t) if !todo.is_empty() => Some(tileset_scene(scene, t, renderer)?),
        _ => None,
    };
    crate::util::create_dir_all(&plan.masks_dir())?;
    // A killed run's temporary files (a live shard's are locked and stay).
    crate::util::remove_stale_temps(&plan.masks_dir(), false, &|_| false)?;
    let frames = Frames {
        plan,
        records: &records,
        todo: &todo,
        source_ids: &source_ids,
        occluders: &occluders,
        tileset_sha256,
    };
    let render_started = Instant::now();
    let (instances, mut failed) = frames.render_and_write(&*id_scene, tiles.as_deref(), progress)?;
    let rendered_secs = render_started.elapsed().as_secs_f64();
    failed.sort_by(|a, b| a.frame.cmp(&b.frame));

    let previews = if plan.preview > 0 {
        let failed_names: BTreeSet<&str> = failed.iter().map(|f| f.frame.as_str()).collect();
        let candidates: Vec<usize> =
            selected.iter().copied().filter(|&i| !failed_names.contains(records[i].name.as_str())).collect();
        write_previews(plan, &records, &candidates, &*id_scene)?
    } else {
        Vec::new()
    };
    let rendered = todo.len() - failed.len();
    Ok(MaskReport {
        frames_total: records.len(),
        frames_selected: selected.len(),
        rendered,
        skipped,
        failed,
        instances,
        seconds: started.elapsed().as_secs_f64(),
        frames_per_s: if rendered_secs > 0.0 { todo.len() as f64 / rendered_secs } else { 0.0 },
        previews,
    })
}

/// A tileset error naming its file.
fn tileset_err(path: &Path, source: impl Into<Box<dyn std::error::Error + Send + Sync>>) -> StageError {
    StageError::Tileset { path: path.to_path_buf(), source: source.into() }
}

/// The tileset, read and prepared once when some frame needs it (its triangles all carry ID 1: only
/// its depth is used).
fn tileset_scene<'r>(
    scene: &PreparedScene,
    t: &TilesetOcclusion,
    renderer: &'r dyn IdRenderer,
) -> Result<Box<dyn IdScene + 'r>, StageError> {
    let o = scene.manifest.origin;
    let enu = crate::geo::EnuFrame::new(crate::geo::Geodetic::new(o.lat_deg, o.lon_deg, o.h_m));
    let mesh = crate::scene::align::tileset_scene_mesh(&t.path, &enu, BuildingId::new(1)?)
        .map_err(|e| tileset_err(&t.path, e))?;
    if mesh.indices.is_empty() {
        return Err(tileset_err(&t.path, "it holds no triangles"));
    }
    log::info!("tileset {}: {} triangles", t.path.display(), mesh.triangle_count());
    Ok(renderer.prepare(&mesh, glam::DVec3::ZERO)?)
}

/// The frames a run renders and what writing them needs.
struct Frames<'a> {
    plan: &'a MaskPlan,
    records: &'a [PoseRecord],
    /// Indices into `records` of the frames to render, in order.
    todo: &'a [usize],
    source_ids: &'a BTreeMap<BuildingId, String>,
    occluders: &'a [ClutterLayer],
    tileset_sha256: Option<&'a str>,
}

impl Frames<'_> {
    /// Renders the frames on the calling thread (several in flight on wgpu) and labels and writes
    /// them on the rayon pool, fed through a bounded channel. Returns the instances written and the
    /// frames that failed.
    fn render_and_write(
        &self,
        id_scene: &dyn IdScene,
        tiles: Option<&dyn IdScene>,
        progress: &dyn Progress,
    ) -> Result<(u64, Vec<FrameFailure>), StageError> {
        let plan = self.plan;
        let views: Vec<View> = self
            .todo
            .iter()
            .map(|&i| View { intrinsics: self.records[i].view.intrinsics, pose: self.records[i].pose() })
            .collect();
        let options = RenderOptions { range: plan.range, linear_depth: plan.depth || tiles.is_some() };
        let tiles_options = RenderOptions { range: plan.range, linear_depth: true };
        progress.start(self.todo.len() as u64, "frames");
        let failures: Mutex<Vec<FrameFailure>> = Mutex::new(Vec::new());
        let instance_count = std::sync::atomic::AtomicU64::new(0);
        let done = std::sync::atomic::AtomicU64::new(0);
        let render_started = Instant::now();
        let render_result: Result<(), StageError> = std::thread::scope(|s| {
            let (tx, rx) = mpsc::sync_channel::<Job>(2 * crate::render::FRAMES_IN_FLIGHT);
            let writer = s.spawn(|| {
                rx.into_iter().par_bridge().for_each(|job| {
                    let rec = &self.records[job.record];
                    match write_frame(plan, rec, job, self.source_ids, self.occluders, self.tileset_sha256) {
                        Ok(n) => {
                            instance_count.fetch_add(n, std::sync::atomic::Ordering::Relaxed);
                        }
                        Err(e) => {
                            log::error!("frame {}: {}", rec.name, error_chain(&e));
                            failures
                                .lock()
                                .unwrap_or_else(|p| p.into_inner())
                                .push(FrameFailure { frame: rec.name.clone(), error: error_chain(&e) });
                        }
                    }
                    let n = done.fetch_add(1, std::sync::atomic::Ordering::Relaxed) + 1;
                    progress.inc(1);
                    let secs = render_started.elapsed().as_secs_f64();
                    if secs > 0.0 {
                        progress.message(&format!("{:.2} frames/s", n as f64 / secs));
                    }
                });
            });
            // The first error of a frame stops the batch and is kept here.
            let mut stopped: Option<StageError> = None;
            let on_frame = |k: usize, image: RenderedFrame| -> Result<(), StageError> {
                crate::util::interrupt::check()?;
                let amodal_px = if plan.visible_fraction {
                    let ids = image.ids.visible_buildings();
                    let counts = id_scene.isolated_coverage_px(&views[k], &ids, &plan.range)?;
                    Some(ids.into_iter().zip(counts).collect())
                } else {
                    None
                };
                let tiles_depth_m = match tiles {
                    Some(t) => t.render(&views[k], &tiles_options)?.depth_m,
                    None => None,
                };
                // The writer only stops receiving if it panicked; the join below reports that.
                let _ = tx.send(Job { record: self.todo[k], image, tiles_depth_m, amodal_px });
                Ok(())
            };
            let rendered = id_scene.render_each(&views, &options, &mut |k, image| match on_frame(k, image) {
                Ok(()) => std::ops::ControlFlow::Continue(()),
                Err(e) => {
                    stopped = Some(e);
                    std::ops::ControlFlow::Break(())
                }
            });
            drop(tx);
            if writer.join().is_err() {
                return Err(StageError::WriterPanicked);
            }
            rendered?;
            stopped.map_or(Ok(()), Err)
        });
        progress.finish();
        render_result?;
        Ok((instance_count.into_inner(), failures.into_inner().unwrap_or_else(|p| p.into_inner())))
    }
}

/// Labels one frame and writes its files (depth, PNG, then the JSON last: a frame counts as done only
/// when its JSON exists). Returns the number of instances written.
fn write_frame(
    plan: &MaskPlan,
    rec: &PoseRecord,
    mut job: Job,
    source_ids: &BTreeMap<BuildingId, String>,
    occluders: &[ClutterLayer],
    tileset_sha256: Option<&str>,
) -> Result<u64, StageError> {
    let mut occlusion = None;
    if let (Some(t), Some(sha)) = (&plan.tileset, tileset_sha256) {
        let empty = Vec::new();
        let lod_depth = job.image.depth_m.as_ref().unwrap_or(&empty);
        let tiles_depth = job.tiles_depth_m.as_ref().unwrap_or(&empty);
        let (ids, ignore, counts) = occlude(&job.image.ids, lod_depth, tiles_depth, t.threshold_m, t.mode)?;
        job.image.ids = ids;
        if let Some(mask) = ignore {
            write_ignore_png(
                &plan.ignore_path(&rec.name),
                &mask,
                job.image.ids.width(),
                job.image.ids.height(),
            )?;
        }
        occlusion = Some(OcclusionRecord::new(sha, t.mode, t.threshold_m, &counts));
    }
    let image = &job.image;
    let mut instances = frame_instances(
        &rec.name,
        &image.ids,
        plan.connectivity,
        plan.min_area_px,
        source_ids,
        job.amodal_px.as_ref(),
    );
    instances.pose_sha256 = Some(pose_digest(rec));
    instances.occluders = occluders.to_vec();
    if let Some(o) = &occlusion {
        let by_id: BTreeMap<BuildingId, &super::occlusion::BuildingRecord> =
            o.buildings.iter().map(|b| (b.building_id, b)).collect();
        for e in &mut instances.instances {
            if let Some(b) = by_id.get(&e.building_id) {
                e.occluded_px = Some(b.occluded_px);
                e.behind_px = Some(b.behind_px);
                e.see_through = Some(b.see_through);
            }
        }
    }
    instances.occlusion = occlusion;
    if let (true, Some(depth)) = (plan.depth, &image.depth_m) {
        write_depth_exr(&plan.depth_path(&rec.name), depth, image.ids.width(), image.ids.height())?;
    }
    image.ids.write_png(&plan.png_path(&rec.name))?;
    crate::util::write_json_atomic(&plan.instances_path(&rec.name), &instances)?;
    Ok(instances.instances.len() as u64)
}

/// Writes an ignore mask as an 8-bit greyscale PNG (255 = ignore) atomically.
///
/// # Errors
/// [`StageError::File`] naming `path`; encoding a well-sized buffer does not fail otherwise.
pub fn write_ignore_png(path: &Path, mask: &[bool], width: u32, height: u32) -> Result<(), StageError> {
    let mut bytes = Vec::new();
    {
        let mut enc = png::Encoder::new(&mut bytes, width, height);
        enc.set_color(png::ColorType::Grayscale);
        enc.set_depth(png::BitDepth::Eight);
        let encode_err = |e: png::EncodingError| {
            StageError::File(crate::util::FileError::new("encoding", path, std::io::Error::other(e)))
        };
        let mut w = enc.write_header().map_err(encode_err)?;
        let px: Vec<u8> = mask.iter().map(|&m| if m { 255 } else { 0 }).collect();
        w.write_image_data(&px).map_err(encode_err)?;
        w.finish().map_err(encode_err)?;
    }
    crate::util::write_bytes_atomic(path, &bytes)?;
    Ok(())
}

/// Picks `k` of `n` items evenly (first and last included when k ≥ 2).
fn evenly_spaced(n: usize, k: usize) -> Vec<usize> {
    let k = k.min(n);
    match k {
        0 => Vec::new(),
        1 => vec![0],
        _ => (0..k).map(|j| j * (n - 1) / (k - 1)).collect(),
    }
}

/// Writes contact sheets of `plan.preview` frames chosen evenly among `candidates`.
fn write_previews(
    plan: &MaskPlan,
    records: &[PoseRecord],
    candidates: &[usize],
    id_scene: &dyn IdScene,
) -> Result<Vec<PathBuf>, StageError> {
    let chosen: Vec<usize> =
        evenly_spaced(candidates.len(), plan.preview).into_iter().map(|j| candidates[j]).collect();
    let mut tiles = Vec::with_capacity(chosen.len());
    for &i in &chosen {
        let rec = &records[i];
        let ids = IdMap::read_png(&plan.png_path(&rec.name))?;
        let rgb_path = plan.rgb_path(&rec.name);
        let backdrop = if rgb_path.exists() {
            overlay::read_rgb_png(&rgb_path)?
        } else {
            let view = View { intrinsics: rec.view.intrinsics, pose: rec.pose() };
            let options = RenderOptions { range: plan.range, linear_depth: true };
            let img = id_scene.render(&view, &options)?;
            // `linear_depth: true` always yields depth; an empty one would only shade as background.
            overlay::shade_depth(img.depth_m.as_deref().unwrap_or(&[]), &rec.view.intrinsics)
        };
        tiles.push(overlay::overlay_ids(&ids, &backdrop, 0.45));
    }
    let prefix = if plan.shard.count > 1 {
        format!("preview_{}of{}_", plan.shard.index, plan.shard.count)
    } else {
        "preview_".to_string()
    };
    let mut written = Vec::new();
    for (n, chunk) in tiles.chunks(SHEET_TILES).enumerate() {
        let sheet = overlay::contact_sheet(chunk, SHEET_COLUMNS, TILE_WIDTH_PX);
        let path = plan.masks_dir().join(format!("{prefix}{n:02}.png"));
        overlay::write_rgb_png(&path, &sheet)?;
        written.push(path);
    }
    Ok(written)
}

#[cfg(test)]
mod tests {
    use super::*;

    mod instances {
        use super::*;

        fn image(rows: &[&str]) -> IdMap {
            let height = rows.len() as u32;
            let width = rows[0].len() as u32;
            let ids = rows
                .iter()
                .flat_map(|r| r.bytes().map(|b| if b == b'.' { 0 } else { (b - b'0') as u32 }))
                .collect();
            IdMap::from_raw(width, height, ids).unwrap()
        }

        fn id(n: u32) -> BuildingId {
            BuildingId::new(n).unwrap()
        }

        #[test]
        fn small_fragments_are_dropped_but_counted_as_visible() {
            // Building 1: a 3×2 block (6 px) and a 1 px fragment; building 2: 2 px.
            let img = image(&["111..", "111.1", ".....", "22..."]);
            let names: BTreeMap<BuildingId, String> =
                [(id(1), "gml_a".to_string()), (id(2), "gml_b".to_string())].into();
            let fi = frame_instances("f", &img, Connectivity::Four, 2, &names, None);
            assert_eq!(fi.instances.len(), 2);
            let a = &fi.instances[0];
            assert_eq!((a.building_id, a.source_id.as_str(), a.component, a.area_px), (id(1), "gml_a", 0, 6));
            assert_eq!(a.building_visible_px, 7, "the dropped 1 px fragment still counts as visible");
            assert_eq!(a.bbox_px, [0, 0, 3, 2]);
            assert!(a.truncated);
            assert_eq!(a.visible_fraction, None);
            let b = &fi.instances[1];
            assert_eq!((b.building_id, b.area_px, b.building_visible_px), (id(2), 2, 2));
        }

        #[test]
        fn visible_fraction_divides_by_amodal_pixels() {
            let img = image(&["11..", "11..", "...."]);
            let names: BTreeMap<BuildingId, String> = [(id(1), "x".to_string())].into();
            let amodal: BTreeMap<BuildingId, u64> = [(id(1), 8)].into();
            let fi = frame_instances("f", &img, Connectivity::Eight, 1, &names, Some(&amodal));
            assert_eq!(fi.instances[0].visible_fraction, Some(0.5));
        }
    }

    mod preview_choice {
        use super::*;

        #[test]
        fn evenly_spaced_includes_both_ends() {
            assert_eq!(evenly_spaced(10, 3), vec![0, 4, 9]);
            assert_eq!(evenly_spaced(2, 5), vec![0, 1]);
            assert_eq!(evenly_spaced(7, 1), vec![0]);
            assert!(evenly_spaced(0, 3).is_empty());
        }
    }
}
