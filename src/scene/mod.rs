//! Scenes: area definitions, triangulation, instancing, and the prepared scene artifact.
//!
//! - [`config`] — `scenes/<area>.toml`;
//! - [`sources`] — a source path (file, folder or glob) as the list of files it names;
//! - [`survey`] — what source files hold (format, CRS, extent, centre, counts), for `inspect` and `init`;
//! - [`init`] — a commented scene file written from the survey of a new area's files (`insgen init`);
//! - [`appearance`] — textures and colours of LoD faces, carried into the scene GLB;
//! - [`triangulate`] — planar polygons with holes → triangles;
//! - [`prepare`] — the `prepare` stage (read → geo-reference → triangulate → instance → write);
//! - [`artifact`] — the files it writes and [`PreparedScene::load`] for later stages;
//! - [`correction`] — the rigid alignment correction of the LoD model recorded in the manifest;
//! - [`align`] — estimating that correction against a reference tileset (`insgen align`);
//! - [`ids`] — the 24-bit [`BuildingId`] and [`IdMap`], the one image-of-IDs type, with its codecs;
//! - [`mesh`] — the instanced [`SceneMesh`] renderers consume;
//! - [`glb`] — the scene GLB (EXT_mesh_features) writer and reader;
//! - [`procedural`] — the embedded demo city generator;
//! - [`clutter`] — streets, ground cover, trees, cars and rooftop units around the buildings (seeded);
//! - [`adjacency`] — which buildings touch in plan, and contrast classes that tell them apart in photos.

pub mod adjacency;
pub mod align;
pub mod appearance;
pub mod artifact;
pub mod clutter;
pub mod config;
pub mod correction;
pub mod error;
pub mod ids;
pub mod init;
pub mod mesh;
pub mod photogrammetry;
pub mod prepare;
pub mod sources;
pub mod survey;
pub mod triangulate;

pub use artifact::{BuildingRecord, Manifest, PreparedScene};
pub use error::{AreaProblem, ArtifactProblem, ConfigProblem, GeorefProblem, SceneError};
pub use ids::{BuildingId, IdError, IdMap, MAX_BUILDING_ID};
pub use mesh::SceneMesh;
pub mod glb;
pub mod procedural;
