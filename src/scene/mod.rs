//! Scenes: area definitions, triangulation, instancing, and the prepared scene artifact.

pub mod artifact;
pub mod error;
pub mod mesh;

pub use artifact::{BuildingRecord, Manifest, PreparedScene};
pub use error::SceneError;
pub use mesh::{SceneMesh, MAX_BUILDING_ID};
pub mod glb;
pub mod procedural;
