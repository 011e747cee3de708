//! Cameras: presets and intrinsics, poses and their representations, pose sampling, priors and the
//! files that describe a flight.
//!
//! Takes a prepared scene ([`crate::scene::PreparedScene`]: area polygon, ground level, building
//! boxes, mesh) and hands on, per area and camera, `poses.jsonl` (ground truth, [`PoseRecord`] per
//! line), `priors.jsonl`, a COLMAP text model and a flight-plan picture, all in the area's ENU frame
//! (metres relative to the area origin, f64).
//!
//! - [`intrinsics`], [`preset`]: pinhole intrinsics, the paper's presets cam1–cam3, custom camera TOML;
//! - [`pose`], [`record`]: poses (ENU, OpenCV camera axes, yaw/pitch/roll convention) and records;
//! - [`config`]: the scene file's `[sampling]` table;
//! - [`area`], [`visibility`]: polygon queries, building-box clearance and ray visibility checks;
//! - [`grid`], [`regular`], [`irregular`]: the three strategies; [`sample`]: the stage entry point;
//! - [`prior`]: noisy priors; [`colmap`]: COLMAP text I/O; [`flight_plan`]: the top-view PNG.

pub mod area;
pub mod colmap;
pub mod config;
pub mod error;
pub mod flight_plan;
pub mod grid;
pub mod hints;
pub mod intrinsics;
pub mod irregular;
pub mod pose;
pub mod preset;
pub mod prior;
pub mod record;
pub mod regular;
pub mod sample;
pub mod visibility;

pub use config::SamplingConfig;
pub use error::{AreaProblem, CameraError, ColmapIssue, ConfigIssue};
pub use intrinsics::Intrinsics;
pub use pose::Pose;
pub use preset::CameraSpec;
pub use record::{EnuCamera, GeoPose, PoseRecord, Trajectory};
pub use sample::{sample_area, write_sample, SampleOutput, SampleStats};
