//! insgen: synthetic building-instance datasets for UAV visual localization against LoD city models.
//!
//! The modules read as the pipeline, data flowing forward; a stage never reaches back into a later one:
//!
//! | module    | stage                                                                   |
//! |-----------|-------------------------------------------------------------------------|
//! | [`geo`]    | CRS conversion (f64): source CRS → geodetic → ECEF (EPSG:4978) → ENU, geoid |
//! | [`lod`]    | readers for CityGML 2.0, CityJSON, OBJ and 3D Tiles, in source coordinates |
//! | [`scene`]  | area definitions, triangulation, instancing, the scene artifact (GLB + manifest) |
//! | [`camera`] | camera presets, pose sampling strategies, priors, COLMAP and JSON output |
//! | [`render`] | wgpu offscreen instance-ID renderer                                     |
//! | [`label`]  | connected components and per-frame instance lists                       |
//! | [`export`] | COCO (RLE as pycocotools writes it), panoptic, YOLO and 3D Tiles exports |
//! | [`blender`]| Blender (bpy) headless RGB rendering driven by JSON job files            |
//! | [`loc`]    | the instance-silhouette localizer and its evaluation                    |
//! | [`cli`]    | the `insgen` command line                                               |
//!
//! [`layout`] names every file and folder of a work directory and of an export, for every stage; [`util`]
//! holds what every stage shares (atomic writes, progress, the GLB container, sharding).
//!
//! Conventions used everywhere:
//! - Names carry units (`height_m`, `yaw_deg`); angles are radians inside functions and degrees at the
//!   user's edge (files, flags).
//! - Geometry stays f64 until it reaches the GPU, expressed relative to the area origin (ENU metres).
//! - Image coordinates: (0, 0) is the top-left corner of the top-left pixel; pixel (i, j) covers
//!   [i, i+1) × [j, j+1) and its centre is (i + 0.5, j + 0.5) — the COLMAP and rasteriser convention.
//! - Camera axes are OpenCV's (x right, y down, z forward).

#![warn(missing_docs)]

pub mod blender;
pub mod camera;
pub mod cli;
pub mod export;
pub mod geo;
pub mod label;
pub mod layout;
pub mod loc;
pub mod lod;
pub mod render;
pub mod scene;
pub mod util;
