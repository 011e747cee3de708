//! The export stage: what trainers and viewers read, made from the rendered work directory.
//!
//! Takes in what the earlier stages left in the work directory — per frame an ID map
//! `masks/<frame>.png` and its `masks/<frame>.instances.json` (`label`), the photo `rgb/<frame>.*`
//! (`blender`), each area's prepared scene (`scene`) and each camera's `poses.jsonl` (`camera`) —
//! and hands on the files a user takes elsewhere. Every export has one module; a new one goes here,
//! reads the COCO export or the prepared scene, and writes through [`crate::util::write_atomic`].
//!
//! COCO instances (`export-coco`), the export the others are made from:
//! - [`coco`]: the `export-coco` stage — COCO instance files per geographic split
//!   (`instances_train.json`, `instances_val.json`, `instances_test.json`);
//! - [`rle`]: run-length encoding, byte-identical to `pycocotools.mask` (encode, string form, decode,
//!   area, bbox, merge), with a one-pass encoder for all components of a frame;
//! - [`format`]: the COCO file types with insgen's extension keys;
//! - [`polygon`]: outer-boundary polygons for `--polygons`;
//! - [`parts`]: the part a shard of the frames writes (`export-coco --shard`), and the parts combined
//!   into the export one process writes (`insgen merge`);
//! - [`bundle`]: the photos and ID maps placed inside the export folder (hard links or copies), so
//!   that the folder alone is the dataset;
//! - [`frames`]: an existing export read back, each image's masks checked against its ID map;
//! - [`results`]: reading and validating COCO results (predictions), which the localizer consumes.
//!
//! What describes and checks an export:
//! - [`stats`]: per-split statistics, histograms and a contact sheet; [`learnability`]: per-area
//!   statistics that predict how learnable the instances are (touching boundaries in the ID maps,
//!   their contrast in the photos, sizes, masks split by occluders);
//! - [`manifest`], [`card`], [`verify`]: the dataset manifest (`dataset.json`), the dataset card
//!   (`README.md`) and the check of a dataset against them (`insgen verify`);
//! - [`table`]: tables written as Markdown and HTML from one definition;
//! - [`index`]: `index.html`, the export in a browser (summary, statistics, charts, contact sheets per
//!   area, flight plans, links to the card and the JSON files);
//! - [`raster`]: PNG input and output of the figures' raster ([`crate::util::figure`] draws them; ID
//!   maps are [`crate::scene::IdMap`]).
//!
//! Made from a COCO export: [`panoptic`] (`export-panoptic`, COCO panoptic PNGs and JSON), [`yolo`]
//! (`export-yolo`, Ultralytics YOLO segmentation labels and `data.yaml`) and [`hf`] (`export-hf`, the
//! Hugging Face `datasets` image folder metadata of a self-contained export).
//!
//! Made from a prepared scene: [`tiles`] (`export-tiles`, the scene as a 3D Tiles 1.1 tileset placed
//! on the globe) and [`city_tileset`] (`export-tiles --style`, textured multi-level tilesets in the
//! styles of real producers, the test tilesets of the photogrammetry path). GLB contents are
//! assembled by [`crate::util::glb::GlbBuilder`], the crate's one GLB writer; their Draco and
//! meshopt geometry is encoded by `compress` (the decoders are the reader's, in `lod/`).

pub mod bundle;
pub mod card;
pub mod city_tileset;
pub mod coco;
pub(crate) mod compress;
pub mod error;
pub mod format;
pub mod frames;
pub mod hf;
pub mod index;
pub mod learnability;
pub mod manifest;
pub mod panoptic;
pub mod parts;
pub mod polygon;
pub mod raster;
pub mod results;
pub mod rle;
pub mod stats;
pub mod table;
pub mod tiles;
pub mod verify;
pub mod yolo;

pub use coco::{ExportPlan, Split};
pub use error::CocoError;
pub use format::{Annotation, AnnotationUnit, Dataset, Filters, Image, TruncatedPolicy};
pub use rle::{encode, encode_labels, Rle, RleError};
