//! Rendering a list of frames with Blender: skip finished frames, split the rest into batches (one
//! Blender process each, restarted every N frames to bound memory), write a job per batch, relay
//! progress, verify each output and rename it into place.
//!
//! Outputs are atomic: Blender writes `<out>/.insgen-tmp-<frame>.<ext>`; when it reports the frame
//! done, insgen decodes the file, checks its size, writes `<out>/<frame>.<ext>` atomically (re-encoded,
//! so no render-time metadata breaks byte-identical reruns) and removes the temporary file. On any
//! failure the batch's temporary files are removed, so only complete, verified frames ever appear.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use super::camera::{blender_matrix_world, cam_to_world_enu, BlenderCamera, Mat4};
use super::error::{BlenderError, JobIssue, JobProblem, OutputError};
use super::job::{
    check_writable, DenoiseQuality, Device, Engine, Job, JobFrame, JobModel, Lighting, Look, Mode, ModelKind,
    RgbSettings, JOB_FORMAT, JOB_VERSION,
};
use super::look::{apply_camera_effects, CameraEffects, FrameLook, LookRanges};
use super::process::{run_job, Event, Launcher};
use super::tileset::{prepare_tile, select_tiles, SelectOptions};
use crate::camera::record::check_frame_name;
use crate::camera::{Intrinsics, Pose};
use crate::geo::EnuFrame;
use crate::util::Progress;

/// The Blender-side script, embedded so the binary works from any directory; it is written next to the
/// job files before each run (`scripts/blender/render_rgb.py` in the repository).
pub const RENDER_SCRIPT: &str = include_str!("../../scripts/blender/render_rgb.py");
/// File name of the script copy in the work directory.
pub const SCRIPT_FILE: &str = "render_rgb.py";
/// Prefix of temporary output files.
pub use crate::util::TMP_PREFIX;

/// Where the geometry comes from.
#[derive(Debug, Clone)]
pub enum SceneSource {
    /// The prepared scene's `scene.glb` (the instanced LoD model, procedural look), placed by
    /// `enu_from_gltf` (row-major): [`super::tileset::ENU_FROM_SCENE_GLTF`], preceded by the area's alignment correction
    /// when it has one ([`crate::scene::PreparedScene::enu_from_scene_gltf`]).
    Lod {
        /// The prepared `scene.glb`.
        glb: PathBuf,
        /// ENU-from-glTF transform (row-major, metres).
        enu_from_gltf: Mat4,
    },
    /// A photogrammetry tileset, placed with the area's ENU frame; tiles chosen per frame.
    Tileset {
        /// The tileset JSON.
        tileset: PathBuf,
        /// The area's ENU frame.
        enu: EnuFrame,
        /// How tiles are chosen per frame.
        select: SelectOptions,
    },
}

/// Default settings for the procedural look of the LoD model, chosen by measurement on cam2 1920×1080
/// frames of the demo and of Shibuya on 2 CPU cores (bench/rgb_quality.md, reproduced by
/// scripts/bench_rgb.sh): direct lighting leaves anti-aliasing as the only noise, which one sample and
/// the fast denoiser (albedo and normal guides) remove to ≥ 35 dB PSNR against the converged look.
pub const PROCEDURAL_DEFAULTS: RgbSettings = RgbSettings {
    samples: 1,
    denoise: true,
    denoise_quality: DenoiseQuality::Fast,
    max_bounces: 0,
    lighting: Lighting::Direct,
};

/// Defaults of the path-traced procedural look (`--lighting path`): sky light and two bounces are noisy,
/// so two samples and the balanced denoiser (≈ 35 dB on the demo, bench/rgb_quality.md).
pub const PATH_TRACED_DEFAULTS: RgbSettings = RgbSettings {
    samples: 2,
    denoise: true,
    denoise_quality: DenoiseQuality::Balanced,
    max_bounces: 2,
    lighting: Lighting::Path,
};

/// Default settings for photogrammetry tilesets: their textures are shown unlit (emission), so light
/// bounces and the denoiser buy nothing; the samples only anti-alias edges and texture detail. 3 is
/// the fewest that keep ≥ 35 dB with a margin (36.6–39.0 dB at 2.7 s per frame; 2 samples: 35.2 dB;
/// bench/rgb_quality.md).
pub const UNLIT_DEFAULTS: RgbSettings = RgbSettings {
    samples: 3,
    denoise: false,
    denoise_quality: DenoiseQuality::Fast,
    max_bounces: 0,
    lighting: Lighting::Direct,
};

impl SceneSource {
    /// The measured default RGB settings for this kind of scene (`lighting` chooses between the
    /// procedural looks; tilesets are always unlit).
    pub fn default_rgb_settings(&self, lighting: Lighting) -> RgbSettings {
        match (self, lighting) {
            (SceneSource::Lod { .. }, Lighting::Direct) => PROCEDURAL_DEFAULTS,
            (SceneSource::Lod { .. }, Lighting::Path) => PATH_TRACED_DEFAULTS,
            (SceneSource::Tileset { .. }, _) => UNLIT_DEFAULTS,
        }
    }
}

/// One frame to render.
#[derive(Debug, Clone, PartialEq)]
pub struct FrameRequest {
    /// Frame name (the stem of its output files).
    pub name: String,
    /// The pinhole camera.
    pub intrinsics: Intrinsics,
    /// Camera pose in the area's ENU frame.
    pub pose: Pose,
}

/// Everything a render run needs (built once by the CLI from its flags).
#[derive(Debug, Clone)]
pub struct RenderPlan {
    /// How Blender is started.
    pub launcher: Launcher,
    /// RGB or ID rendering.
    pub mode: Mode,
    /// The render engine.
    pub engine: Engine,
    /// Samples, denoiser, bounces and lighting (RGB mode).
    pub rgb: RgbSettings,
    /// Cycles sampling seed.
    pub seed: u32,
    /// Cycles compute device (`auto` picks the best one Blender reports).
    pub device: Device,
    /// Render threads (0 = all cores).
    pub threads: u32,
    /// RGB mode: also write a linear float32 EXR per frame.
    pub exr: bool,
    /// What is rendered: the prepared scene or a tileset.
    pub source: SceneSource,
    /// Seed of the per-building material variation and of each frame's look.
    pub look_seed: u64,
    /// What each frame's look is drawn from ([`super::look`]).
    pub look: LookRanges,
    /// Ground level in ENU metres.
    pub ground_enu_m: f64,
    /// Directory of the final outputs (`rgb/` or `alignment/`).
    pub out_dir: PathBuf,
    /// Directory for job files, the script copy and the unwrapped tile cache.
    pub work_dir: PathBuf,
    /// Frames per Blender process (≥ 1).
    pub restart_every: usize,
    /// Re-render frames whose outputs already exist.
    pub force: bool,
    /// Camera clipping range, metres.
    pub clip_start_m: f64,
    /// Far clipping distance, metres.
    pub clip_end_m: f64,
    /// Ask the script for each model's ENU bounds (tests).
    pub report_bounds: bool,
    /// ID mode: the clutter layers kept as occluders (background); the scene's other clutter layers
    /// are left out of the ID render. `None` = every clutter layer occludes.
    pub clutter_occluders: Option<Vec<crate::scene::clutter::ClutterLayer>>,
    /// RGB mode, procedural look: contrast classes of touching buildings (`None`: off).
    pub contrast: Option<super::look::BuildingContrast>,
}

/// Time spent on one frame, as Blender reported it.
#[derive(Debug, Clone, PartialEq)]
pub struct FrameTiming {
    /// Frame name.
    pub name: String,
    /// Wall-clock seconds (depends on other load on the machine).
    pub seconds: f64,
    /// CPU seconds of all render threads (about `seconds × cores` on an idle machine).
    pub cpu_seconds: f64,
}

/// What a run did.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct RenderSummary {
    /// Frames rendered in this run, in order.
    pub rendered: Vec<FrameTiming>,
    /// Frames skipped because their outputs already existed and verified.
    pub skipped: Vec<String>,
    /// Blender processes started, and the scene set-up time each reported (seconds).
    pub setup_seconds: Vec<f64>,
    /// Per model of the last job, its ENU bounds [min, max] in metres (when `report_bounds`).
    pub bounds: Vec<Option<[[f64; 3]; 2]>>,
    /// Models of each job (the number of tiles for a tileset).
    pub models_per_job: Vec<usize>,
    /// Tile contents Blender cannot import, skipped, by extension.
    pub skipped_contents: BTreeMap<String, u64>,
    /// The device each Blender process rendered on (`CPU`, `OPTIX`, …; the engine name for Workbench).
    pub devices: Vec<String>,
}

/// Suffix of the per-frame metadata written next to each RGB frame (`rgb/<frame>.render.json`).
pub const META_SUFFIX: &str = crate::layout::RGB_META_SUFFIX;

/// What one Blender process reported about itself.
#[derive(Debug, Clone)]
struct ProcessInfo {
    device: String,
    blender: Option<String>,
}

/// How an RGB frame was rendered (`rgb/<frame>.render.json`). No timings: the same job writes the same
/// bytes.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct FrameMeta {
    /// Frame name.
    pub frame: String,
    /// `cycles` or `workbench`.
    pub engine: String,
    /// The device Blender rendered on (`CPU`, `OPTIX`, `CUDA`, `HIP`, `ONEAPI`, `METAL`), as it reported it.
    pub device: String,
    /// The device asked for (`auto`, `cpu`, …).
    pub device_requested: String,
    /// Samples, denoiser, bounces and lighting.
    #[serde(flatten)]
    pub settings: RgbSettings,
    /// Cycles sampling seed.
    pub seed: u32,
    /// The frame's drawn look (sun, sky, haze, exposure, camera effects).
    pub look: FrameLook,
    /// Blender's version string.
    pub blender: Option<String>,
    /// SHA-256 of the frame's camera and settings (the resume fingerprint).
    pub fingerprint: String,
}

impl FrameMeta {
    fn new(plan: &RenderPlan, f: &FrameRequest, look: FrameLook, info: Option<&ProcessInfo>) -> Self {
        FrameMeta {
            frame: f.name.clone(),
            engine: plan.engine.name().into(),
            device: info.map(|i| i.device.clone()).unwrap_or_else(|| "unknown".into()),
            device_requested: plan.device.name().into(),
            settings: plan.rgb,
            seed: plan.seed,
            look,
            blender: info.and_then(|i| i.blender.clone()),
            fingerprint: frame_fingerprint(plan, f),
        }
    }
}

/// The kind of one output file.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum OutputKind {
    /// 8-bit RGB PNG.
    Png,
    /// Linear float32 EXR of the RGB render.
    RgbExr,
    /// Float32 EXR with building IDs.
    IdExr,
}

/// One output of a frame: final path, temporary path and kind.
#[derive(Debug, Clone, PartialEq)]
pub struct Output {
    /// Final path.
    pub path: PathBuf,
    /// Temporary path Blender writes (renamed to `path` after verification).
    pub tmp: PathBuf,
    /// What the file holds.
    pub kind: OutputKind,
}

/// The outputs a frame gets under `plan`: `<frame>.png` (+ `<frame>.exr`) in RGB mode,
/// `<frame>.ids.exr` in ID mode.
pub fn frame_outputs(plan: &RenderPlan, name: &str) -> Vec<Output> {
    let out = |file: String, kind| Output {
        path: plan.out_dir.join(&file),
        tmp: plan.out_dir.join(format!("{TMP_PREFIX}{file}")),
        kind,
    };
    match plan.mode {
        Mode::Rgb => {
            let mut v = vec![out(format!("{name}.png"), OutputKind::Png)];
            if plan.exr {
                v.push(out(format!("{name}.exr"), OutputKind::RgbExr));
            }
            v
        }
        Mode::Ids => vec![out(format!("{name}.ids.exr"), OutputKind::IdExr)],
    }
}

/// A decoded output image.
enum Decoded {
    /// 8-bit RGB, row-major.
    Png { width: u32, height: u32, rgb: Vec<u8> },
    /// Float32 R, G, B planes, row-major.
    Exr { width: u32, height: u32, planes: [Vec<f32>; 3] },
}

fn decode_output(kind: OutputKind, path: &Path) -> Result<Decoded, OutputError> {
    match kind {
        OutputKind::Png => {
            let file = std::fs::File::open(path).map_err(OutputError::Open)?;
            let mut reader =
                png::Decoder::new(std::io::BufReader::new(file)).read_info().map_err(OutputError::NotPng)?;
            let mut buf = vec![0; reader.output_buffer_size()];
            let info = reader.next_frame(&mut buf).map_err(OutputError::NotPng)?;
            if info.bit_depth != png::BitDepth::Eight || info.color_type != png::ColorType::Rgb {
                return Err(OutputError::PngFormat { bit_depth: info.bit_depth, color: info.color_type });
            }
            buf.truncate(info.buffer_size());
            Ok(Decoded::Png { width: info.width, height: info.height, rgb: buf })
        }
        OutputKind::RgbExr | OutputKind::IdExr => {
            if kind == OutputKind::IdExr {
                // Checks that every value is a building ID.
                crate::scene::IdMap::read_exr(path).map_err(OutputError::Ids)?;
            }
            let img = exr::prelude::read_first_flat_layer_from_file(path).map_err(OutputError::Exr)?;
            let layer = &img.layer_data;
            let plane = |name: &'static str| -> Result<Vec<f32>, OutputError> {
                let c = layer
                    .channel_data
                    .list
                    .iter()
                    .find(|c| c.name.eq(name))
                    .ok_or(OutputError::MissingChannel(name))?;
                match &c.sample_data {
                    exr::prelude::FlatSamples::F32(v) => Ok(v.clone()),
                    _ => Err(OutputError::NotF32(name)),
                }
            };
            Ok(Decoded::Exr {
                width: layer.size.0 as u32,
                height: layer.size.1 as u32,
                planes: [plane("R")?, plane("G")?, plane("B")?],
            })
        }
    }
}

fn check_size(d: &Decoded, k: &Intrinsics) -> Result<(), OutputError> {
    let (w, h) = match d {
        Decoded::Png { width, height, .. } | Decoded::Exr { width, height, .. } => (*width, *height),
    };
    if (w, h) != (k.width_px, k.height_px) {
        return Err(OutputError::Size {
            width_px: w,
            height_px: h,
            expected_width_px: k.width_px,
            expected_height_px: k.height_px,
        });
    }
    Ok(())
}

/// Checks that an output decodes, has the expected kind and the frame's size.
///
/// # Errors
/// [`OutputError`] saying what is wrong with the file.
pub fn verify_output(kind: OutputKind, path: &Path, k: &Intrinsics) -> Result<(), OutputError> {
    check_size(&decode_output(kind, path)?, k)
}

/// Verifies Blender's temporary output and writes the final file atomically, re-encoded by insgen so
/// that it carries no render metadata (Blender stamps render times into PNG and EXR headers): the
/// same job gives byte-identical files. The temporary file is removed afterwards.
fn finalize_output(
    o: &Output,
    k: &Intrinsics,
    effects: Option<(&CameraEffects, u64)>,
) -> Result<(), OutputError> {
    let decoded = decode_output(o.kind, &o.tmp)?;
    check_size(&decoded, k)?;
    match decoded {
        Decoded::Png { width, height, mut rgb } => {
            if let Some((fx, seed)) = effects {
                apply_camera_effects(&mut rgb, width, height, fx, seed).map_err(OutputError::Effects)?;
            }
            let mut bytes = Vec::with_capacity(rgb.len() / 2);
            {
                let mut enc = png::Encoder::new(&mut bytes, width, height);
                enc.set_color(png::ColorType::Rgb);
                enc.set_depth(png::BitDepth::Eight);
                enc.set_compression(png::Compression::Fast);
                let mut w = enc.write_header().map_err(OutputError::EncodePng)?;
                w.write_image_data(&rgb).map_err(OutputError::EncodePng)?;
            }
            crate::util::write_bytes_atomic(&o.path, &bytes).map_err(OutputError::Write)?;
        }
        Decoded::Exr { width, height, planes } => {
            let dir = o.path.parent().unwrap_or(Path::new("."));
            // Locked while open (see `locked_tempfile_in`): a concurrent rerun's cleanup leaves it.
            let tmp = crate::util::locked_tempfile_in(dir).map_err(OutputError::TempFile)?;
            let w = width as usize;
            exr::prelude::write_rgb_file(tmp.path(), w, height as usize, |x, y| {
                let i = y * w + x;
                (planes[0][i], planes[1][i], planes[2][i])
            })
            .map_err(OutputError::EncodeExr)?;
            tmp.persist(&o.path).map_err(|e| {
                OutputError::Rename(tempfile::PathPersistError {
                    error: e.error,
                    path: e.file.into_temp_path(),
                })
            })?;
        }
    }
    std::fs::remove_file(&o.tmp).map_err(OutputError::RemoveTmp)
}

/// Fingerprint of what a frame's outputs depend on: its camera and the plan's render settings (hex
/// SHA-256 of their exact `Debug` text, which round-trips f64).
pub fn frame_fingerprint(plan: &RenderPlan, f: &FrameRequest) -> String {
    use sha2::Digest;
    let source = match &plan.source {
        SceneSource::Lod { glb, .. } => format!("lod {}", glb.display()),
        SceneSource::Tileset { tileset, enu, select } => {
            format!("tileset {} {enu:?} {select:?}", tileset.display())
        }
    };
    let text = format!(
        "{:?} {:?} {:?} {:?} {} {} {} {:?} {} {:?} {} {} {} {} {source} {:?}",
        f.intrinsics,
        f.pose,
        plan.mode,
        plan.engine,
        plan.rgb.samples,
        plan.seed,
        plan.rgb.denoise,
        plan.rgb.denoise_quality,
        plan.rgb.max_bounces,
        plan.rgb.lighting,
        plan.exr,
        plan.look_seed,
        plan.ground_enu_m,
        plan.clip_start_m,
        // ID renders do not depend on the look.
        (plan.mode == Mode::Rgb).then_some((plan.look, &plan.contrast)),
    );
    hex::encode(sha2::Sha256::digest(text.as_bytes()))
}

/// Where the fingerprint of a finished frame is kept (`<work_dir>/done/<mode>/<frame>.sha256`).
fn stamp_path(plan: &RenderPlan, name: &str) -> PathBuf {
    let mode = match plan.mode {
        Mode::Rgb => "rgb",
        Mode::Ids => "ids",
    };
    plan.work_dir.join("done").join(mode).join(format!("{name}.sha256"))
}

/// Records that `f` was rendered under `plan` (after its outputs are in place).
pub fn write_stamp(plan: &RenderPlan, f: &FrameRequest) -> Result<(), crate::util::FileError> {
    crate::util::write_bytes_atomic(&stamp_path(plan, &f.name), frame_fingerprint(plan, f).as_bytes())
}

/// Whether all of a frame's outputs exist, verify, and were rendered from the same camera and
/// settings (the resume test: frames whose pose changed since, e.g. after `sample` ran again, are
/// redone).
pub fn frame_complete(plan: &RenderPlan, f: &FrameRequest) -> bool {
    let stamp_ok = std::fs::read_to_string(stamp_path(plan, &f.name))
        .is_ok_and(|s| s.trim() == frame_fingerprint(plan, f));
    stamp_ok
        && frame_outputs(plan, &f.name)
            .iter()
            .all(|o| o.path.is_file() && verify_output(o.kind, &o.path, &f.intrinsics).is_ok())
}

/// Half side of the ground plane around the area origin, metres: far enough that a camera seeing the
/// horizon from a few hundred metres up still finds ground below it. It is a constant (not derived from
/// the frames) so that a frame renders the same whether it is rendered alone, in a shard or in a batch.
pub const GROUND_HALF_EXTENT_M: f64 = 50_000.0;

/// The look of a plan; depends only on the plan (never on which frames are rendered), so a frame's image
/// is the same in any batch or shard.
fn look_for(plan: &RenderPlan) -> Look {
    let (az, el) = super::look::sun_from_seed(plan.look_seed);
    Look {
        seed: plan.look_seed,
        ground_enu_m: plan.ground_enu_m,
        ground_plane: matches!(plan.source, SceneSource::Lod { .. }),
        ground_centre_enu_m: [0.0, 0.0],
        ground_half_extent_m: GROUND_HALF_EXTENT_M,
        sun_azimuth_deg: az,
        sun_elevation_deg: el,
        sun_strength: super::look::PLAIN_SUN_STRENGTH,
        sky_strength: super::look::PLAIN_SKY_STRENGTH,
        exposure: 0.0,
        contrast: plan.contrast.clone(),
    }
}

fn remove_tmp(outputs: &[Output]) {
    for o in outputs {
        if o.tmp.exists() {
            if let Err(e) = std::fs::remove_file(&o.tmp) {
                log::warn!("cannot remove {}: {e}", o.tmp.display());
            }
        }
    }
}

fn check_request(plan: &RenderPlan, frames: &[FrameRequest]) -> Vec<JobIssue> {
    let mut issues = Vec::new();
    let mut seen = std::collections::BTreeSet::new();
    for (i, f) in frames.iter().enumerate() {
        if let Err(e) = check_frame_name(&f.name) {
            issues.push(JobIssue { path: format!("frames[{i}].name"), problem: JobProblem::FrameName(e) });
        } else if !seen.insert(f.name.as_str()) {
            issues.push(JobIssue {
                path: format!("frames[{i}].name"),
                problem: JobProblem::DuplicateFrame { name: f.name.clone() },
            });
        }
    }
    if plan.mode == Mode::Rgb {
        if let Err(e) = plan.look.check() {
            issues.push(JobIssue { path: "look".into(), problem: JobProblem::Look(e) });
        } else if let Some(Err(e)) =
            frames.iter().map(|f| FrameLook::draw(&plan.look, plan.look_seed, &f.name)).find(Result::is_err)
        {
            issues.push(JobIssue { path: "look.sun".into(), problem: JobProblem::Look(e) });
        }
    }
    if plan.restart_every == 0 {
        issues.push(JobIssue { path: "restart_every".into(), problem: JobProblem::Zero });
    }
    match &plan.source {
        SceneSource::Lod { glb, .. } if !glb.is_file() => {
            issues.push(JobIssue { path: "scene".into(), problem: JobProblem::NoScene { glb: glb.clone() } })
        }
        SceneSource::Tileset { tileset, .. } if !tileset.is_file() => issues.push(JobIssue {
            path: "tileset".into(),
            problem: JobProblem::NoTileset { tileset: tileset.clone() },
        }),
        _ => {}
    }
    issues
}

fn absolute(p: &Path) -> PathBuf {
    if p.is_absolute() {
        p.to_path_buf()
    } else {
        std::env::current_dir().map(|d| d.join(p)).unwrap_or_else(|_| p.to_path_buf())
    }
}

/// Renders `frames` under `plan` (see the module doc), reporting each finished frame to `progress`.
///
/// # Errors
/// [`BlenderError::InvalidJob`] before anything starts (bad names, missing scene, unwritable output);
/// tileset and tile errors; a failed Blender process; an output that does not verify. Frames finished
/// before the failure stay in place (a rerun resumes after them).
pub fn render_frames(
    plan: &RenderPlan,
    frames: &[FrameRequest],
    progress: &dyn Progress,
) -> Result<RenderSummary, BlenderError> {
    let mut plan = plan.clone();
    plan.out_dir = absolute(&plan.out_dir);
    plan.work_dir = absolute(&plan.work_dir);
    let issues = check_request(&plan, frames);
    if !issues.is_empty() {
        return Err(BlenderError::InvalidJob { path: plan.work_dir.clone(), issues });
    }
    for dir in [&plan.out_dir, &plan.work_dir] {
        crate::util::create_dir_all(dir)?;
        check_writable(dir).map_err(|source| BlenderError::NotWritable { dir: dir.clone(), source })?;
    }
    // Temporary files of a killed run: ours (this call's frames) go; Blender's outputs of frames that
    // are not ours may belong to another shard rendering into the same directory right now.
    let ours: std::collections::BTreeSet<String> = frames
        .iter()
        .flat_map(|f| frame_outputs(&plan, &f.name))
        .filter_map(|o| o.tmp.file_name().map(|n| n.to_string_lossy().into_owned()))
        .collect();
    let blender_output = |n: &str| n.strip_prefix(TMP_PREFIX).is_some_and(|rest| rest.contains('.'));
    crate::util::remove_stale_temps(&plan.out_dir, false, &|n| blender_output(n) && !ours.contains(n))?;
    let mut summary = RenderSummary::default();
    let mut todo = Vec::new();
    for f in frames {
        if !plan.force && frame_complete(&plan, f) {
            summary.skipped.push(f.name.clone());
        } else {
            todo.push(f.clone());
        }
    }
    if todo.is_empty() {
        return Ok(summary);
    }
    let script = plan.work_dir.join(SCRIPT_FILE);
    if crate::util::read_file(&script).map(|b| b != RENDER_SCRIPT.as_bytes()).unwrap_or(true) {
        crate::util::write_bytes_atomic(&script, RENDER_SCRIPT.as_bytes())?;
    }
    let look = look_for(&plan);
    progress.start(todo.len() as u64, "frames");
    let result = (|| {
        for batch in todo.chunks(plan.restart_every) {
            crate::util::interrupt::check()?;
            run_batch(&plan, &script, &look, batch, progress, &mut summary)?;
        }
        Ok(())
    })();
    progress.finish();
    result.map(|()| summary)
}

/// A job's models, and the indices of those each frame sees (`None`: all).
type BatchModels = (Vec<JobModel>, Option<Vec<Vec<u32>>>);

/// The models of a batch's job: the prepared scene, or the tiles its frames select (with each frame's
/// share of them; skipped contents are counted in `summary`).
fn batch_models(
    plan: &RenderPlan,
    batch: &[FrameRequest],
    summary: &mut RenderSummary,
) -> Result<BatchModels, BlenderError> {
    Ok(match &plan.source {
        SceneSource::Lod { glb, enu_from_gltf } => {
            (vec![JobModel { glb: absolute(glb), enu_from_gltf: *enu_from_gltf, kind: ModelKind::Lod }], None)
        }
        SceneSource::Tileset { tileset, enu, select } => {
            let cams: Vec<(Intrinsics, Pose)> = batch.iter().map(|f| (f.intrinsics, f.pose)).collect();
            let sel = select_tiles(tileset, enu, &cams, select)?;
            for (k, v) in &sel.skipped {
                *summary.skipped_contents.entry(k.clone()).or_insert(0) += v;
            }
            let cache = plan.work_dir.join("tiles");
            let models =
                sel.tiles.iter().map(|t| prepare_tile(t, enu, &cache)).collect::<Result<Vec<_>, _>>()?;
            (models, Some(sel.per_frame))
        }
    })
}

/// The look of every frame of a batch.
///
/// # Errors
/// [`BlenderError::InvalidJob`] when the sun cannot be drawn for a frame.
fn draw_looks(plan: &RenderPlan, batch: &[FrameRequest]) -> Result<Vec<FrameLook>, BlenderError> {
    batch
        .iter()
        .map(|f| FrameLook::draw(&plan.look, plan.look_seed, &f.name))
        .collect::<Result<_, _>>()
        .map_err(|e| BlenderError::InvalidJob {
            path: plan.work_dir.clone(),
            issues: vec![JobIssue { path: "look.sun".into(), problem: JobProblem::Look(e) }],
        })
}

/// The job's frames: camera, pose, models, look and output files of each frame of the batch.
fn job_frames(
    plan: &RenderPlan,
    batch: &[FrameRequest],
    outputs: &[Vec<Output>],
    looks: &[FrameLook],
    per_frame: Option<&[Vec<u32>]>,
) -> Result<Vec<JobFrame>, BlenderError> {
    let mut job_frames = Vec::with_capacity(batch.len());
    for (i, f) in batch.iter().enumerate() {
        let camera =
            BlenderCamera::from_intrinsics(&f.name, &f.intrinsics, plan.clip_start_m, plan.clip_end_m)?;
        let find = |kind| outputs[i].iter().find(|o| o.kind == kind).map(|o| o.tmp.clone());
        job_frames.push(JobFrame {
            name: f.name.clone(),
            intrinsics: f.intrinsics,
            camera,
            cam_to_world_enu: cam_to_world_enu(&f.pose),
            blender_matrix_world: blender_matrix_world(&f.pose),
            models: per_frame.map(|p| p[i].clone()),
            look: looks[i],
            png: find(OutputKind::Png),
            exr: find(OutputKind::RgbExr).or_else(|| find(OutputKind::IdExr)),
        });
    }
    Ok(job_frames)
}

/// Renders one batch of frames in one Blender process: writes its job, runs Blender, and finalises
/// each frame's outputs as Blender reports it done (temporary files are removed on failure).
fn run_batch(
    plan: &RenderPlan,
    script: &Path,
    look: &Look,
    batch: &[FrameRequest],
    progress: &dyn Progress,
    summary: &mut RenderSummary,
) -> Result<(), BlenderError> {
    let (models, per_frame) = batch_models(plan, batch, summary)?;
    let outputs: Vec<Vec<Output>> = batch.iter().map(|f| frame_outputs(plan, &f.name)).collect();
    let looks = draw_looks(plan, batch)?;
    let job_frames = job_frames(plan, batch, &outputs, &looks, per_frame.as_deref())?;
    let job = Job {
        format: JOB_FORMAT.into(),
        version: JOB_VERSION,
        mode: plan.mode,
        engine: plan.engine,
        rgb: plan.rgb,
        seed: plan.seed,
        device: plan.device,
        threads: plan.threads,
        report_bounds: plan.report_bounds,
        clutter_occluders: plan.clutter_occluders.clone(),
        models,
        look: look.clone(),
        frames: job_frames,
    };
    let mode = match plan.mode {
        Mode::Rgb => "rgb",
        Mode::Ids => "ids",
    };
    let job_path = plan.work_dir.join(format!("job-{mode}-{}.json", batch[0].name));
    let issues = job.validate();
    if !issues.is_empty() {
        return Err(BlenderError::InvalidJob { path: job_path, issues });
    }
    crate::util::write_json_atomic(&job_path, &job)?;
    summary.models_per_job.push(job.models.len());
    for o in outputs.iter().flatten() {
        remove_tmp(std::slice::from_ref(o));
    }
    let index: BTreeMap<&str, usize> = batch.iter().enumerate().map(|(i, f)| (f.name.as_str(), i)).collect();
    let mut done = vec![false; batch.len()];
    let mut process_info: Option<ProcessInfo> = None;
    let result = run_job(&plan.launcher, script, &job_path, |ev| {
        match ev {
            Event::Ready { seconds, bounds, device, blender, .. } => {
                summary.setup_seconds.push(seconds);
                let device = device.unwrap_or_else(|| plan.engine.name().to_string());
                log::info!(
                    "Blender {} renders on {device}",
                    blender.as_deref().unwrap_or("(unknown version)")
                );
                summary.devices.push(device.clone());
                process_info = Some(ProcessInfo { device, blender });
                if let Some(b) = bounds {
                    summary.bounds = b;
                }
            }
            Event::Done { frame, seconds, cpu_seconds } => {
                let i = *index.get(frame.as_str()).ok_or_else(|| BlenderError::Output {
                    frame: frame.clone(),
                    path: job_path.clone(),
                    source: OutputError::NotInJob,
                })?;
                let effects = (plan.mode == Mode::Rgb)
                    .then(|| (&looks[i].camera, FrameLook::noise_seed(plan.look_seed, &frame)));
                for o in &outputs[i] {
                    finalize_output(o, &batch[i].intrinsics, effects).map_err(|source| {
                        BlenderError::Output { frame: frame.clone(), path: o.tmp.clone(), source }
                    })?;
                }
                if plan.mode == Mode::Rgb {
                    let meta = FrameMeta::new(plan, &batch[i], looks[i], process_info.as_ref());
                    crate::util::write_json_atomic(
                        &plan.out_dir.join(format!("{frame}.{META_SUFFIX}")),
                        &meta,
                    )?;
                }
                write_stamp(plan, &batch[i])?;
                done[i] = true;
                summary.rendered.push(FrameTiming { name: frame, seconds, cpu_seconds });
                progress.inc(1);
                // Stop between frames on Ctrl-C: this frame is complete, the next is not started.
                crate::util::interrupt::check()?;
            }
            Event::Error { .. } => {}
        }
        Ok(())
    });
    let result = result.and_then(|()| match done.iter().position(|d| !d) {
        Some(i) => Err(BlenderError::Output {
            frame: batch[i].name.clone(),
            path: job_path.clone(),
            source: OutputError::NotReported,
        }),
        None => Ok(()),
    });
    if result.is_err() {
        for o in outputs.iter().flatten() {
            remove_tmp(std::slice::from_ref(o));
        }
    }
    result
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::blender::tileset::ENU_FROM_SCENE_GLTF;

    fn plan(dir: &Path) -> RenderPlan {
        let glb = dir.join("scene.glb");
        std::fs::write(&glb, b"glTF").unwrap();
        RenderPlan {
            launcher: Launcher::Python { interpreter: "/nonexistent/python".into() },
            mode: Mode::Rgb,
            engine: Engine::Cycles,
            rgb: RgbSettings {
                samples: 4,
                denoise: false,
                denoise_quality: DenoiseQuality::Fast,
                max_bounces: 2,
                lighting: Lighting::Direct,
            },
            seed: 0,
            device: Device::Cpu,
            threads: 0,
            exr: true,
            source: SceneSource::Lod { glb, enu_from_gltf: ENU_FROM_SCENE_GLTF },
            look_seed: 1,
            look: LookRanges::plain(35.0),
            ground_enu_m: 0.0,
            out_dir: dir.join(crate::layout::RGB_DIR),
            work_dir: dir.join(crate::layout::BLENDER_DIR),
            restart_every: 10,
            force: false,
            clip_start_m: 0.1,
            clip_end_m: 1e5,
            report_bounds: false,
            clutter_occluders: None,
            contrast: None,
        }
    }

    fn frame(name: &str) -> FrameRequest {
        FrameRequest {
            name: name.into(),
            intrinsics: Intrinsics::from_hfov(8, 6, 60.0),
            pose: Pose::from_ypr_deg(0.0, 0.0, 0.0, [0.0, 0.0, 100.0]),
        }
    }

    fn write_png(path: &Path, w: u32, h: u32) {
        let mut out = Vec::new();
        {
            let mut enc = png::Encoder::new(&mut out, w, h);
            enc.set_color(png::ColorType::Rgb);
            enc.set_depth(png::BitDepth::Eight);
            enc.write_header().unwrap().write_image_data(&vec![90u8; (w * h * 3) as usize]).unwrap();
        }
        std::fs::write(path, out).unwrap();
    }

    #[test]
    fn outputs_per_mode() {
        let dir = tempfile::tempdir().unwrap();
        let mut p = plan(dir.path());
        let o = frame_outputs(&p, "f1");
        assert_eq!(o.len(), 2);
        assert_eq!(o[0].path, dir.path().join("rgb/f1.png"));
        assert_eq!(o[0].tmp, dir.path().join("rgb/.insgen-tmp-f1.png"));
        assert_eq!(o[1].path, dir.path().join("rgb/f1.exr"));
        p.mode = Mode::Ids;
        assert_eq!(frame_outputs(&p, "f1")[0].path, dir.path().join("rgb/f1.ids.exr"));
    }

    #[test]
    fn resume_needs_every_output_to_decode_at_the_right_size() {
        let dir = tempfile::tempdir().unwrap();
        let mut p = plan(dir.path());
        p.exr = false;
        std::fs::create_dir_all(&p.out_dir).unwrap();
        let f = frame("a");
        assert!(!frame_complete(&p, &f));
        std::fs::write(p.out_dir.join("a.png"), b"\x89PNG truncated").unwrap();
        assert!(!frame_complete(&p, &f));
        write_png(&p.out_dir.join("a.png"), 8, 5);
        assert!(!frame_complete(&p, &f), "wrong height accepted");
        write_png(&p.out_dir.join("a.png"), 8, 6);
        assert!(!frame_complete(&p, &f), "a frame without the fingerprint of its pose was accepted");
        write_stamp(&p, &f).unwrap();
        assert!(frame_complete(&p, &f));
        let mut moved = f.clone();
        moved.pose.centre_m[0] += 0.001;
        assert!(!frame_complete(&p, &moved), "a moved pose was accepted");
        p.exr = true;
        assert!(!frame_complete(&p, &f), "missing EXR accepted");
    }

    #[test]
    fn all_done_means_blender_is_not_started() {
        // The launcher does not exist: reaching it would fail, so success proves the skip.
        let dir = tempfile::tempdir().unwrap();
        let mut p = plan(dir.path());
        p.exr = false;
        std::fs::create_dir_all(&p.out_dir).unwrap();
        write_png(&p.out_dir.join("a.png"), 8, 6);
        write_stamp(&p, &frame("a")).unwrap();
        let s = render_frames(&p, &[frame("a")], &crate::util::NoProgress).unwrap();
        assert_eq!(s.skipped, vec!["a".to_string()]);
        assert!(s.rendered.is_empty());
        p.force = true;
        assert!(matches!(
            render_frames(&p, &[frame("a")], &crate::util::NoProgress),
            Err(BlenderError::Spawn { .. })
        ));
    }

    #[test]
    fn bad_requests_fail_before_anything_is_written() {
        let dir = tempfile::tempdir().unwrap();
        let mut p = plan(dir.path());
        p.source = SceneSource::Lod {
            glb: dir.path().join("missing/scene.glb"),
            enu_from_gltf: ENU_FROM_SCENE_GLTF,
        };
        let e =
            render_frames(&p, &[frame("a"), frame("a"), frame("x/y")], &crate::util::NoProgress).unwrap_err();
        let text = e.to_string();
        assert!(text.contains("frames[1].name") && text.contains("frames[2].name"), "{text}");
        assert!(text.contains("missing/scene.glb") && text.contains("insgen prepare"), "{text}");
        assert!(!p.out_dir.exists(), "outputs created for an invalid request");
    }

    #[cfg(unix)]
    #[test]
    fn unwritable_output_is_reported() {
        use std::os::unix::fs::PermissionsExt;
        let dir = tempfile::tempdir().unwrap();
        let p = plan(dir.path());
        std::fs::create_dir_all(&p.out_dir).unwrap();
        std::fs::set_permissions(&p.out_dir, std::fs::Permissions::from_mode(0o555)).unwrap();
        // Root ignores permissions; only check when the probe really fails.
        if check_writable(&p.out_dir).is_ok() {
            eprintln!("skipping: running as root, directory permissions are not enforced");
            return;
        }
        let e = render_frames(&p, &[frame("a")], &crate::util::NoProgress).unwrap_err().to_string();
        assert!(e.contains("not writable") && e.contains("rgb"), "{e}");
    }

    #[test]
    fn an_interrupted_render_exits_130() {
        // main maps an Interrupted anywhere in the chain to exit status 130.
        let e = BlenderError::from(crate::util::interrupt::Interrupted);
        assert!(crate::util::interrupt::in_chain(&e));
        let e = anyhow::Error::from(e).context("render-rgb");
        assert!(crate::util::interrupt::in_chain(e.as_ref()));
    }
}
