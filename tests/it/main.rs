//! The integration tests, in one binary so that the suite links once.
//!
//! Each module is one part of the pipeline seen from outside the crate (its public API, the `insgen`
//! binary, and real components: pyproj, pycocotools, Blender, the Khronos validator, lavapipe). The
//! support modules hold what several of them share: real-data lookup with the CI rule, running the
//! binary, schema checks (`util`), small scenes and reference renders (`render_common`), camera fixtures
//! (`camera_support`) and bpy discovery (`blender_support`).

mod blender_support;
mod camera_support;
mod render_common;
mod util;

mod align;
mod blender_render;
mod blender_render_tiles;
mod camera_io;
mod camera_sampling;
mod cli_run;
mod closed_loop;
mod coco_export;
mod coco_rle;
mod crash;
mod demo_dataset;
mod export_index;
mod exports;
mod fuzz;
mod geo_geoid_grids;
mod geo_pyproj;
mod label_occlusion;
mod loc_eval;
mod loc_learned;
mod lod_citygml;
mod lod_cityjson;
mod lod_issue20;
mod lod_obj;
mod lod_tiles3d;
mod lod_tiles3d_generated;
mod masks_tileset;
mod metadata;
mod onboard;
mod render_analytic;
mod render_cpu_agreement;
mod render_depth_coverage;
mod render_determinism;
mod render_masks_stage;
mod render_seam;
mod render_shibuya;
mod scene_appearance;
mod scene_clutter;
mod scene_glb;
mod scene_prepare;
mod scene_procedural;
mod slurm;
