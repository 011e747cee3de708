//! COCO export: instance annotations from the rendered ID maps, RLE exactly as pycocotools writes it.
//!
//! Takes in what `render-masks` left in the workdir — per frame an ID map `masks/<frame>.png` and its
//! `masks/<frame>.instances.json` — plus each area's scene manifest and building table and each
//! camera's `poses.jsonl`. Hands on COCO instance files per geographic split (`instances_train.json`,
//! `instances_val.json`, `instances_test.json`), a statistics report, and a reader for prediction
//! files (`results`) that the localizer consumes.
//!
//! - [`rle`]: run-length encoding, byte-identical to `pycocotools.mask` (encode, string form, decode,
//!   area, bbox, merge), with a one-pass encoder for all components of a frame;
//! - [`format`]: the COCO file types with insgen's extension keys;
//! - [`export`]: the `export-coco` stage;
//! - [`stats`]: per-split statistics, histograms and a contact sheet;
//! - [`learnability`]: per-area statistics that predict how learnable the instances are (touching
//!   boundaries in the ID maps, their contrast in the photos, sizes, masks split by occluders);
//! - [`manifest`], [`card`], [`verify`]: the dataset manifest (`dataset.json`), the dataset card
//!   (`README.md`) and the check of a dataset against them (`insgen verify`);
//! - [`results`]: reading and validating COCO results (predictions);
//! - [`polygon`]: outer-boundary polygons for `--polygons`;
//! - [`raster`]: a tiny raster for figures (ID maps are [`crate::scene::IdMap`]);
//! - [`parts`]: the part a shard of the frames writes (`export-coco --shard`), and the parts combined
//!   into the export one process writes (`insgen merge`);
//! - [`frames`]: an existing export read back, each image's masks checked against its ID map;
//! - [`panoptic`]: `export-panoptic`, COCO panoptic PNGs and JSON from an export;
//! - [`yolo`]: `export-yolo`, Ultralytics YOLO segmentation labels and `data.yaml` from an export.

pub mod card;
pub mod error;
pub mod export;
pub mod format;
pub mod frames;
pub mod learnability;
pub mod manifest;
pub mod panoptic;
pub mod parts;
pub mod polygon;
pub mod raster;
pub mod results;
pub mod rle;
pub mod stats;
pub mod verify;
pub mod yolo;

pub use error::CocoError;
pub use export::{ExportPlan, Split};
pub use format::{Annotation, AnnotationUnit, Dataset, Filters, Image, TruncatedPolicy};
pub use rle::{encode, encode_labels, Rle, RleError};
