//! Blender (bpy) headless rendering driven by JSON job files: RGB frames pixel-aligned with the masks.
//!
//! Takes the prepared scene (`scene.glb`, ENU, per-vertex building IDs) or a photogrammetry tileset, the
//! frames of `poses.jsonl` (intrinsics + ENU poses), and hands on `rgb/<frame>.png` (optionally a linear
//! `.exr`) or, for the alignment check, float32 ID renders compared against the masks.
//!
//! - [`camera`]: the exact Blender camera (lens, sensor fit, shift, pixel aspect, axis flip) for a pinhole;
//! - [`job`]: the job file (schema `schemas/blender_job.schema.json`) and its validation;
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
pub mod process;
pub mod run;
pub mod tileset;

pub use error::{BlenderError, JobIssue, ProcessFailure};
pub use job::{Engine, Job, Mode};
pub use process::Launcher;
pub use run::{render_frames, FrameRequest, RenderPlan, RenderSummary, SceneSource};

/// A slice of the frames for parallel runs: frame `i` (its index in `poses.jsonl`) belongs to shard
/// `i % count == index`, the same rule as `render-masks`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Shard {
    pub index: u32,
    pub count: u32,
}

impl Shard {
    /// Parses `"i/N"` with 0 ≤ i < N.
    ///
    /// # Errors
    /// A message quoting the text when it is not of that form.
    pub fn parse(text: &str) -> Result<Shard, String> {
        let bad = || format!("shard {text:?} is not i/N with 0 ≤ i < N (e.g. 0/4)");
        let (i, n) = text.split_once('/').ok_or_else(bad)?;
        let index: u32 = i.trim().parse().map_err(|_| bad())?;
        let count: u32 = n.trim().parse().map_err(|_| bad())?;
        if count == 0 || index >= count {
            return Err(bad());
        }
        Ok(Shard { index, count })
    }

    /// Whether the frame at `position` in `poses.jsonl` belongs to this shard.
    pub fn contains(&self, position: usize) -> bool {
        position % self.count as usize == self.index as usize
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shard_parse_and_partition() {
        assert_eq!(Shard::parse("1/4"), Ok(Shard { index: 1, count: 4 }));
        for bad in ["4/4", "1", "a/2", "0/0", "-1/3"] {
            assert!(Shard::parse(bad).unwrap_err().contains(bad), "{bad}");
        }
        // Every frame lands in exactly one of N shards.
        let shards: Vec<Shard> = (0..3).map(|i| Shard { index: i, count: 3 }).collect();
        for pos in 0..20 {
            assert_eq!(shards.iter().filter(|s| s.contains(pos)).count(), 1);
        }
    }
}
