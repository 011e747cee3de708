//! The JSON job file handed to Blender (schema: `schemas/blender_job.schema.json`).
//!
//! A job is everything one Blender process needs: the models to import with their ENU placement, the look
//! (procedural materials, ground, sky and sun), the render settings, and the frames with their cameras
//! (both as OpenCV pose and as Blender settings, derived in [`super::camera`]) and temporary output paths.
//! The Blender-side script (`scripts/blender/render_rgb.py`) reads it; no value ever becomes Python
//! source.
//!
//! [`Job::validate`] checks a job before Blender starts and lists every problem with its JSON path
//! (`models[2].glb: file does not exist`), so a bad path or a missing tile fails in milliseconds and
//! without leaving partial frames.

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use super::camera::{BlenderCamera, Mat4};
use super::error::{JobIssue, JobProblem};
use super::look::FrameLook;
use crate::camera::record::check_frame_name;
use crate::camera::Intrinsics;

/// Value of the `format` field.
pub const JOB_FORMAT: &str = "insgen-blender-job";
/// Version of the job layout; the script refuses other versions (2: `device`, `max_bounces`,
/// `denoise_quality`; 3: `lighting`; 4: each frame's `look`).
pub const JOB_VERSION: u32 = 4;

/// What the frames show.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Mode {
    /// Shaded colour images (PNG 8-bit, optional linear EXR).
    Rgb,
    /// Building IDs as flat emission into a float32 EXR (R = G = B = ID), for the alignment check.
    Ids,
}

/// The Blender render engine.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Engine {
    /// Path tracing on the CPU (the default; the only engine used for ID renders).
    Cycles,
    /// Blender's fast preview engine (flat per-building colours, studio light), for smoke tests.
    Workbench,
}

impl Engine {
    /// The engine's name in job files and on the command line.
    pub fn name(self) -> &'static str {
        match self {
            Engine::Cycles => "cycles",
            Engine::Workbench => "workbench",
        }
    }
}

/// The Cycles compute device.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Device {
    /// The best device Blender reports (OptiX, then CUDA, HIP, oneAPI, Metal), else the CPU.
    Auto,
    /// The CPU (the default, and the one the tests use).
    Cpu,
    /// NVIDIA GPUs through CUDA.
    Cuda,
    /// NVIDIA RTX GPUs through OptiX.
    Optix,
    /// AMD GPUs through HIP.
    Hip,
    /// Intel GPUs through oneAPI.
    Oneapi,
}

impl Device {
    /// The device's name in job files and on the command line.
    pub fn name(self) -> &'static str {
        match self {
            Device::Auto => "auto",
            Device::Cpu => "cpu",
            Device::Cuda => "cuda",
            Device::Optix => "optix",
            Device::Hip => "hip",
            Device::Oneapi => "oneapi",
        }
    }
}

/// OpenImageDenoise quality (Blender's `denoising_quality`); the prefilter of the albedo and normal
/// guides follows it (`FAST` for fast and balanced, `ACCURATE` for high).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum DenoiseQuality {
    /// `FAST` denoising and prefilter.
    Fast,
    /// `BALANCED` denoising, `FAST` prefilter.
    Balanced,
    /// `HIGH` denoising, `ACCURATE` prefilter.
    High,
}

/// The light transport of the procedural look (RGB mode, LoD models).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Lighting {
    /// Direct sun light with a hard shadow, plus a constant sky ambient and a Fresnel sky reflection on
    /// glass, both as non-sampled emission; Lambertian surfaces, no bounces. Every term but
    /// anti-aliasing is noise-free, so one sample and a fast denoiser suffice.
    #[default]
    Direct,
    /// Path tracing: the sky as an environment light, a soft sun, Principled BSDFs with glossy glass,
    /// `max_bounces` bounces; noisy, needs samples and the denoiser.
    Path,
}

impl Lighting {
    /// The lighting's name in job files and on the command line.
    pub fn name(self) -> &'static str {
        match self {
            Lighting::Direct => "direct",
            Lighting::Path => "path",
        }
    }
}

/// How a model is shaded in RGB mode.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ModelKind {
    /// The instanced LoD model: procedural facade/roof materials varied per building (`_FEATURE_ID_0`).
    Lod,
    /// A photogrammetry tile: its own textures shown unlit (they already carry the lighting).
    Photogrammetry,
}

/// One glTF/GLB file to import.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct JobModel {
    /// Absolute path of the .glb/.gltf file.
    pub glb: PathBuf,
    /// ENU-from-glTF transform (row-major, metres): maps the file's glTF coordinates (y-up, before
    /// any importer axis conversion) to the area's ENU frame. For the prepared `scene.glb` it is the
    /// axis swap ENU (e, n, u) = glTF (x, −z, y).
    pub enu_from_gltf: Mat4,
    /// How the model is shaded.
    pub kind: ModelKind,
}

/// The procedural look (RGB mode).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Look {
    /// Seed of the per-building material variation.
    pub seed: u64,
    /// Ground level in ENU metres (the ground plane sits 5 cm below it; window rows start at it).
    pub ground_enu_m: f64,
    /// Whether to add the textured ground plane (off for photogrammetry, which has its own ground).
    pub ground_plane: bool,
    /// Centre (east, north) and half side of the square ground plane, metres.
    pub ground_centre_enu_m: [f64; 2],
    /// Half side of the square ground plane, metres.
    pub ground_half_extent_m: f64,
    /// Sun direction: azimuth clockwise from north and elevation above the horizon, degrees.
    pub sun_azimuth_deg: f64,
    /// Sun elevation above the horizon, degrees.
    pub sun_elevation_deg: f64,
    /// Sun lamp irradiance (W/m², Blender's sun strength) and sky background strength.
    pub sun_strength: f64,
    /// Sky background strength.
    pub sky_strength: f64,
    /// Exposure of the Standard view transform, in stops.
    pub exposure: f64,
    /// Contrast classes of touching buildings (procedural look); `None`: colours drawn per building alone.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub contrast: Option<super::look::BuildingContrast>,
}

/// One frame to render.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct JobFrame {
    /// Frame name (the stem of its output files).
    pub name: String,
    /// The pinhole camera of the frame.
    pub intrinsics: Intrinsics,
    /// The Blender camera reproducing `intrinsics`.
    pub camera: BlenderCamera,
    /// Camera-to-world in the area's ENU frame, OpenCV camera axes (as in `poses.jsonl`), for provenance.
    pub cam_to_world_enu: Mat4,
    /// The Blender camera object's world matrix (OpenCV axes × diag(1, −1, −1)), the one the script uses.
    pub blender_matrix_world: Mat4,
    /// Indices into `models` visible in this frame; `None` = all.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub models: Option<Vec<u32>>,
    /// The frame's drawn look (sun, sky, haze, exposure; the camera effects are insgen's, after Blender).
    pub look: FrameLook,
    /// Temporary output paths (renamed into place by insgen after verification).
    #[serde(default)]
    pub png: Option<PathBuf>,
    /// Temporary path of the EXR (linear RGB, or building IDs in ID mode).
    #[serde(default)]
    pub exr: Option<PathBuf>,
}

/// The sampling, denoising and bounce settings of RGB renders: one record, carried by the render plan,
/// the job file and each frame's metadata (flattened into the latter two, as their JSON fields).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct RgbSettings {
    /// Cycles samples per pixel.
    pub samples: u32,
    /// Denoise RGB renders (OpenImageDenoise with albedo and normal guides).
    pub denoise: bool,
    /// Denoiser quality when `denoise` is set.
    pub denoise_quality: DenoiseQuality,
    /// Total light bounces (0 = direct light only; diffuse and glossy bounces are capped by it too).
    pub max_bounces: u32,
    /// Light transport of the procedural look (photogrammetry is always shown unlit).
    pub lighting: Lighting,
}

/// A complete job for one Blender process.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Job {
    /// Always [`JOB_FORMAT`].
    pub format: String,
    /// Always [`JOB_VERSION`].
    pub version: u32,
    /// RGB or ID rendering.
    pub mode: Mode,
    /// The render engine.
    pub engine: Engine,
    /// Samples, denoiser, bounces and lighting of RGB renders (ID renders always take 1 sample).
    #[serde(flatten)]
    pub rgb: RgbSettings,
    /// Cycles sampling seed.
    pub seed: u32,
    /// Cycles compute device.
    pub device: Device,
    /// Render threads; 0 = all cores.
    pub threads: u32,
    /// Print each model's ENU bounds after import (the `ready` protocol line); used by tests.
    #[serde(default)]
    pub report_bounds: bool,
    /// ID mode: the clutter layers (glTF nodes `insgen_clutter_<layer>` of the scene GLB) kept as
    /// occluders, drawn with ID 0; the other clutter layers are removed before rendering. Absent = all
    /// clutter layers occlude. RGB mode draws every layer with its material.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub clutter_occluders: Option<Vec<crate::scene::clutter::ClutterLayer>>,
    /// The glTF/GLB files to import.
    pub models: Vec<JobModel>,
    /// The procedural look (RGB mode).
    pub look: Look,
    /// The frames to render, in order.
    pub frames: Vec<JobFrame>,
}

fn is_finite_mat(m: &Mat4) -> bool {
    m.iter().flatten().all(|v| v.is_finite())
}

fn is_affine(m: &Mat4) -> bool {
    m[3] == [0.0, 0.0, 0.0, 1.0]
}

impl Job {
    /// Checks the job as Blender will see it; returns every problem with its JSON path (empty = fine).
    ///
    /// Checked: format/version; samples ≥ 1 in RGB mode; every model file exists; transforms are finite
    /// and affine; frame names are unique file stems; intrinsics are positive; model indices are in
    /// range; each frame has the outputs its mode needs, in existing directories.
    pub fn validate(&self) -> Vec<JobIssue> {
        let mut issues = Vec::new();
        let mut issue = |path: String, problem: JobProblem| issues.push(JobIssue { path, problem });
        if self.format != JOB_FORMAT {
            issue("format".into(), JobProblem::Format { found: self.format.clone(), expected: JOB_FORMAT });
        }
        if self.version != JOB_VERSION {
            issue("version".into(), JobProblem::Version { found: self.version, expected: JOB_VERSION });
        }
        if self.mode == Mode::Rgb && self.rgb.samples == 0 {
            issue("samples".into(), JobProblem::Zero);
        }
        if self.mode == Mode::Ids && self.engine != Engine::Cycles {
            issue("engine".into(), JobProblem::IdsNeedCycles);
        }
        if self.models.is_empty() {
            issue("models".into(), JobProblem::NoModel);
        }
        for (i, m) in self.models.iter().enumerate() {
            if !m.glb.is_absolute() {
                issue(format!("models[{i}].glb"), JobProblem::Relative { path: m.glb.clone() });
            }
            if !m.glb.is_file() {
                issue(format!("models[{i}].glb"), JobProblem::NoModelFile { path: m.glb.clone() });
            }
            if !is_finite_mat(&m.enu_from_gltf) || !is_affine(&m.enu_from_gltf) {
                issue(format!("models[{i}].enu_from_gltf"), JobProblem::Matrix);
            }
        }
        let l = &self.look;
        for (name, v) in [
            ("ground_enu_m", l.ground_enu_m),
            ("ground_half_extent_m", l.ground_half_extent_m),
            ("sun_azimuth_deg", l.sun_azimuth_deg),
            ("sun_elevation_deg", l.sun_elevation_deg),
            ("sun_strength", l.sun_strength),
            ("sky_strength", l.sky_strength),
            ("exposure", l.exposure),
        ] {
            if !v.is_finite() {
                issue(format!("look.{name}"), JobProblem::NotFinite { value: v });
            }
        }
        if self.frames.is_empty() {
            issue("frames".into(), JobProblem::NoFrame);
        }
        let mut names = BTreeSet::new();
        for (i, f) in self.frames.iter().enumerate() {
            let at = |field: &str| format!("frames[{i}].{field}");
            if let Err(e) = check_frame_name(&f.name) {
                issue(at("name"), JobProblem::FrameName(e));
            } else if !names.insert(f.name.as_str()) {
                issue(at("name"), JobProblem::DuplicateFrame { name: f.name.clone() });
            }
            let k = &f.intrinsics;
            if k.width_px == 0
                || k.height_px == 0
                || !(k.fx_px.is_finite() && k.fx_px > 0.0)
                || !(k.fy_px.is_finite() && k.fy_px > 0.0)
            {
                issue(at("intrinsics"), JobProblem::Intrinsics { intrinsics: *k });
            }
            let fl = &f.look;
            let vis = fl.visibility_m.unwrap_or(1.0);
            if ![
                fl.sun_azimuth_deg,
                fl.sun_elevation_deg,
                fl.sun_strength,
                fl.sky_strength,
                fl.exposure_ev,
                vis,
            ]
            .iter()
            .chain(&fl.haze_rgb)
            .all(|v| v.is_finite())
                || vis <= 0.0
            {
                issue(at("look"), JobProblem::FrameLook);
            }
            if !is_finite_mat(&f.blender_matrix_world) || !is_affine(&f.blender_matrix_world) {
                issue(at("blender_matrix_world"), JobProblem::Matrix);
            }
            if let Some(ms) = &f.models {
                for (j, &m) in ms.iter().enumerate() {
                    if m as usize >= self.models.len() {
                        issue(
                            format!("frames[{i}].models[{j}]"),
                            JobProblem::ModelIndex { index: m, models: self.models.len() },
                        );
                    }
                }
            }
            let mut check_out = |field: &str, p: &Option<PathBuf>, needed: bool| match p {
                None if needed => issue(at(field), JobProblem::NoOutput),
                None => {}
                Some(p) => {
                    if !p.is_absolute() {
                        issue(at(field), JobProblem::Relative { path: p.clone() });
                    }
                    match p.parent() {
                        Some(d) if d.is_dir() => {}
                        _ => issue(at(field), JobProblem::NoOutputDir { path: p.clone() }),
                    }
                }
            };
            check_out("png", &f.png, self.mode == Mode::Rgb);
            check_out("exr", &f.exr, self.mode == Mode::Ids);
        }
        issues
    }
}

/// Checks that `dir` accepts new files by creating and removing a probe file.
///
/// # Errors
/// The I/O error of creating the probe file.
pub(crate) fn check_writable(dir: &Path) -> std::io::Result<()> {
    tempfile::Builder::new().prefix(".insgen-probe-").tempfile_in(dir).map(drop)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::blender::camera::{blender_matrix_world, cam_to_world_enu};
    use crate::camera::Pose;

    pub(crate) fn sample_job(dir: &Path) -> Job {
        let glb = dir.join("scene.glb");
        std::fs::write(&glb, b"glTF").unwrap();
        let k = Intrinsics::from_hfov(64, 48, 40.0);
        let pose = Pose::from_ypr_deg(10.0, 30.0, 0.0, [1.0, 2.0, 200.0]);
        Job {
            format: JOB_FORMAT.into(),
            version: JOB_VERSION,
            mode: Mode::Rgb,
            engine: Engine::Cycles,
            rgb: RgbSettings {
                samples: 4,
                denoise: false,
                denoise_quality: DenoiseQuality::Fast,
                max_bounces: 2,
                lighting: Lighting::Direct,
            },
            seed: 7,
            device: Device::Cpu,
            threads: 0,
            report_bounds: false,
            clutter_occluders: None,
            models: vec![JobModel {
                glb,
                enu_from_gltf: crate::blender::tileset::ENU_FROM_SCENE_GLTF,
                kind: ModelKind::Lod,
            }],
            look: Look {
                seed: 1,
                ground_enu_m: 0.0,
                ground_plane: true,
                ground_centre_enu_m: [0.0, 0.0],
                ground_half_extent_m: 1000.0,
                sun_azimuth_deg: 120.0,
                sun_elevation_deg: 40.0,
                sun_strength: 4.0,
                sky_strength: 0.3,
                exposure: 0.0,
                contrast: None,
            },
            frames: vec![JobFrame {
                name: "f0".into(),
                intrinsics: k,
                camera: BlenderCamera::from_intrinsics("f0", &k, 0.1, 1e5).unwrap(),
                cam_to_world_enu: cam_to_world_enu(&pose),
                blender_matrix_world: blender_matrix_world(&pose),
                models: None,
                look: crate::blender::look::FrameLook::draw(
                    &crate::blender::look::LookRanges::defaults(35.0),
                    1,
                    "f0",
                )
                .unwrap(),
                png: Some(dir.join(".insgen-tmp-f0.png")),
                exr: None,
            }],
        }
    }

    #[test]
    fn valid_job_has_no_issues() {
        let dir = tempfile::tempdir().unwrap();
        assert_eq!(sample_job(dir.path()).validate(), vec![]);
    }

    #[test]
    fn every_problem_is_listed_with_its_path() {
        let dir = tempfile::tempdir().unwrap();
        let mut job = sample_job(dir.path());
        job.models[0].glb = dir.path().join("missing.glb");
        job.frames.push(job.frames[0].clone());
        job.frames[1].models = Some(vec![3]);
        job.frames[1].png = Some(dir.path().join("no/such/dir/x.png"));
        job.frames.push(job.frames[0].clone());
        job.frames[2].name = "../evil".into();
        let paths: Vec<String> = job.validate().into_iter().map(|i| i.path).collect();
        assert_eq!(
            paths,
            ["models[0].glb", "frames[1].name", "frames[1].models[0]", "frames[1].png", "frames[2].name"],
        );
    }

    #[test]
    fn ids_mode_needs_exr_and_cycles() {
        let dir = tempfile::tempdir().unwrap();
        let mut job = sample_job(dir.path());
        job.mode = Mode::Ids;
        job.engine = Engine::Workbench;
        let paths: Vec<String> = job.validate().into_iter().map(|i| i.path).collect();
        assert_eq!(paths, ["engine", "frames[0].exr"]);
    }

    #[test]
    fn json_round_trip() {
        let dir = tempfile::tempdir().unwrap();
        let job = sample_job(dir.path());
        let text = serde_json::to_string_pretty(&job).unwrap();
        let back: Job = serde_json::from_str(&text).unwrap();
        assert_eq!(job, back);
    }
}
