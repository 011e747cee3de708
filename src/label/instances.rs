//! The per-frame instance list written beside each ID map (`<frame>.instances.json`, schema
//! `schemas/instances.schema.json`).

use serde::{Deserialize, Serialize};

use super::Connectivity;
use crate::scene::BuildingId;

/// One connected component of one building in one frame.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct InstanceEntry {
    /// Building ID (as in the ID map and the building table).
    pub building_id: BuildingId,
    /// Source identity of the building (gml:id, CityJSON key…).
    pub source_id: String,
    /// Index of this component among the building's components in this frame.
    pub component: u32,
    /// Pixels in this component.
    pub area_px: u64,
    /// [x, y, w, h] in pixels.
    pub bbox_px: [u32; 4],
    /// Whether the component touches the image border.
    pub truncated: bool,
    /// All visible pixels of the building in this frame (all its components).
    pub building_visible_px: u64,
    /// Visible pixels / pixels of the building rendered alone (amodal), when computed.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub visible_fraction: Option<f64>,
    /// With `render-masks --tileset`: the building's pixels removed because the tileset shows
    /// something in front, its pixels where the tileset sees past it, and whether most of its LoD
    /// pixels do (demolished or misplaced; see [`super::occlusion::BuildingRecord`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub occluded_px: Option<u64>,
    /// With a tileset: the building's pixels where the tileset sees past it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub behind_px: Option<u64>,
    /// With a tileset: whether most of its LoD pixels see past it (demolished or misplaced).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub see_through: Option<bool>,
}

/// `<frame>.instances.json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FrameInstances {
    /// Frame name (as in poses.jsonl).
    pub frame: String,
    /// Frame width, pixels.
    pub width: u32,
    /// Frame height, pixels.
    pub height: u32,
    /// Pixel connectivity the components were labelled with.
    pub connectivity: Connectivity,
    /// Components smaller than this were dropped.
    pub min_component_area_px: u64,
    /// Components in raster order of their first pixel.
    pub instances: Vec<InstanceEntry>,
    /// SHA-256 (hex) of the frame's pose record as `render-masks` read it: a resumed run re-renders
    /// frames whose pose or intrinsics changed since (e.g. after `sample` ran again).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub pose_sha256: Option<String>,
    /// The clutter layers drawn as occluders (background) in this frame's ID map; absent when none.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub occluders: Vec<crate::scene::clutter::ClutterLayer>,
    /// With `render-masks --tileset`: how the LoD model and the tileset compared in this frame.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub occlusion: Option<super::occlusion::OcclusionRecord>,
}
