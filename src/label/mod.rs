//! Labels from instance-ID maps: connected components and per-frame instance lists.

pub mod components;
pub mod instances;
pub mod occlusion;
pub mod overlay;
pub mod side_by_side;
pub mod stage;

pub use components::{label_components, Component, Connectivity, Labelling};
pub use instances::{FrameInstances, InstanceEntry};
