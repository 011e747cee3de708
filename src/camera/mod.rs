//! Cameras: intrinsics and presets, poses and their representations, pose sampling.

pub mod intrinsics;
pub mod pose;
pub mod record;

pub use intrinsics::Intrinsics;
pub use pose::Pose;
pub use record::{PoseRecord, Trajectory};
