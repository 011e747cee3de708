//! The instance-silhouette localizer (InsLoD-Loc) and its evaluation.
//!
//! - [`cost`]: best-match Dice with confidence or area weighting, blended with the semantic IoU by
//!   default, the semantic IoU baseline;
//! - [`search`]: coarse grid + particle filter over x, y, z, yaw;
//! - [`map`]: the map (another prepared area) and its seeded perturbations (LoD1, heights, footprints,
//!   drops, merges, offset);
//! - [`metrics`]: errors, recall at (2 m, 2°)/(3 m, 3°)/(5 m, 5°), medians, the summary table;
//! - [`overlay`]: the overlay pictures of `eval-loc` (prior, estimate, truth, with their errors).

pub mod cost;
pub mod eval;
pub mod map;
pub mod metrics;
pub mod morph;
pub mod oracle;
pub mod overlay;
pub mod query;
pub mod resample;
pub mod search;
#[cfg(test)]
mod sparse_tests;
