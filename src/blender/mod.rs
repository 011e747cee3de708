//! Blender (bpy) headless rendering driven by JSON job files: RGB frames pixel-aligned with the masks.
//!
//! Takes the prepared scene (`scene.glb`, ENU, per-vertex building IDs) or a photogrammetry tileset, the
//! frames of `poses.jsonl` (intrinsics + ENU poses), and hands on `rgb/<frame>.png` (optionally a linear
//! `.exr`) or, for the alignment check, float32 ID renders compared against the masks.
//!
//! - [`camera`]: the exact Blender camera (lens, sensor fit, shift, pixel aspect, axis flip) for a pinhole;
//! - [`job`]: the job file (schema `schemas/blender_job.schema.json`) and its validation;
//! - [`look`]: per-frame look variety (sun from date and time, sky, haze, exposure, white balance, camera
//!   effects), drawn from the seed and the frame name;
//! - [`tileset`]: tile selection by frustum and screen-space error over [`crate::lod::tiles3d`]'s tile tree,
//!   plain GLBs of the chosen contents, ENU placement;
//! - [`process`]: finding and running Blender, the stdout protocol, failures with hints;
//! - [`run`]: batches, resume, verification and atomic renames;
//! - [`align`]: per-building IoU between two ID images and the alignment report.
//!
//! The Blender side is `scripts/blender/render_rgb.py` (embedded in the binary as [`run::RENDER_SCRIPT`]).

pub mod align;
pub mod camera;
pub mod error;
pub mod job;
pub mod look;
pub mod process;
pub mod run;
pub mod tileset;

pub use error::{BlenderError, CameraProblem, JobIssue, JobProblem, ProcessFailure};
pub use job::{Engine, Job, Mode};
pub use process::Launcher;
pub use run::{render_frames, FrameRequest, RenderPlan, RenderSummary, SceneSource};
