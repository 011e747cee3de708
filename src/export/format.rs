//! The COCO instance-segmentation file format as insgen writes it: the subset of the COCO "instances"
//! spec that pycocotools reads, plus extension keys that trainers ignore.
//!
//! Field names are the spec's (<https://cocodataset.org/#format-data>). Extension keys are documented on
//! each field and in `schemas/coco_instances.schema.json`. Conventions (pycocotools):
//! - `bbox` is `[x, y, width, height]` in pixels, floats, (0, 0) the top-left corner of the image;
//! - `area` is the mask's pixel count;
//! - `segmentation` is a compressed RLE (`{"size": [height, width], "counts": "<string>"}`, see
//!   [`super::rle`]) — lossless, holes included — or, with `--polygons`, a list of polygons;
//! - ids start at 1 (COCOeval never matches id 0); `iscrowd` is 0, or 1 for instances flagged to be
//!   ignored in evaluation.

use serde::{Deserialize, Serialize};

use crate::camera::record::{EnuCamera, GeoPose};
use crate::label::Connectivity;
use crate::scene::BuildingId;

use super::rle::{Rle, RleError};

/// The only category: id 1, `building`.
pub const BUILDING_CATEGORY_ID: u32 = 1;

/// A whole COCO instances file (`instances_<split>.json`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Dataset {
    /// What produced the file.
    pub info: Info,
    /// The areas' attribution lines.
    pub licenses: Vec<License>,
    /// The frames, in id order.
    pub images: Vec<Image>,
    /// The building instances, in id order.
    pub annotations: Vec<Annotation>,
    /// The one category, `building`.
    pub categories: Vec<Category>,
}

/// `info`: what produced the file. Date-free, so that equal inputs give byte-identical files.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Info {
    /// What the file is.
    pub description: String,
    /// insgen version that wrote the file.
    pub version: String,
    /// Who made it (insgen).
    pub contributor: String,
    /// insgen's home page.
    pub url: String,
    /// Extension: `train`, `val` or `test`.
    pub split: String,
    /// Extension: the directory `images[].file_name` is relative to, itself relative to the directory of
    /// this JSON file (normally `..`, the insgen workdir that holds the area folders).
    pub image_root: String,
    /// Extension: `component` (one annotation per connected component) or `building` (one per building,
    /// possibly several parts).
    pub annotation_unit: AnnotationUnit,
    /// Extension: the filters applied.
    pub filters: Filters,
    /// Extension: the areas in this split, with their provenance.
    pub areas: Vec<AreaInfo>,
    /// Extension: `true` for a label-only export (`--label-only`): `images[].file_name` names RGB
    /// frames not rendered yet. Absent in normal exports, where every image is on disk.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub images_missing: bool,
}

/// Provenance of one area (from its `scene/manifest.json`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct AreaInfo {
    /// Area (scene) name.
    pub name: String,
    /// Split given by the manifest (before `--holdout`).
    pub manifest_split: String,
    /// Whether `--holdout` moved this area to `test`.
    pub held_out: bool,
    /// Buildings in the area's building table.
    pub buildings: u64,
    /// The area's source files.
    pub sources: Vec<SourceInfo>,
    /// Attribution lines of its sources.
    pub attributions: Vec<String>,
}

/// One source file of an area.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SourceInfo {
    /// The file as the area's manifest names it.
    pub path: String,
    /// SHA-256 of its bytes, hex.
    pub sha256: String,
    /// A generated city: the seed and parameters that define it (the scene manifest's record).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub procedural: Option<crate::scene::procedural::ProceduralCity>,
}

/// One annotation per connected component, or per building.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum AnnotationUnit {
    /// One annotation per connected component (default).
    #[default]
    Component,
    /// One annotation per building, its components merged.
    Building,
}

/// What to do with instances that touch the image border (the building may continue outside).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum TruncatedPolicy {
    /// Export them as ordinary annotations (their `truncated` key says so).
    #[default]
    Keep,
    /// Export them with `iscrowd = 1`: COCOeval then treats them as ignore regions (neither a miss nor a
    /// false positive), and most trainers skip them.
    Flag,
    /// Leave them out.
    Drop,
}

/// Annotation filters.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Filters {
    /// Annotations with fewer pixels are dropped.
    pub min_area_px: u64,
    /// Annotations of buildings less visible than this (visible / amodal pixels) are dropped.
    pub min_visible_fraction: Option<f64>,
    /// What happens to instances touching the image border.
    pub truncated: TruncatedPolicy,
    /// Whether images without any annotation stay in the file (as negatives).
    pub keep_empty_images: bool,
    /// Frames whose LoD/tileset consistency score (`render-masks --tileset`) is below this are left
    /// out (`--min-consistency`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub min_consistency: Option<f64>,
}

impl Default for Filters {
    fn default() -> Self {
        Filters {
            min_area_px: 1,
            min_visible_fraction: None,
            truncated: TruncatedPolicy::Keep,
            keep_empty_images: true,
            min_consistency: None,
        }
    }
}

/// `licenses[]`: one per distinct attribution line of the areas' sources.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct License {
    /// From 1, referred to by `images[].license`.
    pub id: u32,
    /// The attribution text, e.g. "3D city model (Project PLATEAU), MLIT — CC BY 4.0".
    pub name: String,
    /// The licence URL when the text names a Creative Commons licence, else empty.
    pub url: String,
}

/// `images[]`: one rendered frame.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Image {
    /// From 1, in the order areas → cameras → frames (all sorted by name).
    pub id: u64,
    /// Relative to `info.image_root`: `<area>/<camera>/rgb/<frame>.png` when the RGB render exists, else
    /// the ID map `<area>/<camera>/masks/<frame>.png`.
    pub file_name: String,
    /// Pixels.
    pub width: u32,
    /// Pixels.
    pub height: u32,
    /// Id of the first licence of the area's sources, when it has one.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub license: Option<u32>,
    /// Extension: area (scene) name.
    pub area_name: String,
    /// Extension: camera directory name.
    pub camera: String,
    /// Extension: camera preset recorded in `poses.jsonl`.
    pub preset: String,
    /// Extension: frame name (stem of every per-frame file).
    pub frame: String,
    /// Extension: the instance-ID map, relative to `info.image_root`.
    pub mask_file: String,
    /// Extension: connectivity of the connected components.
    pub connectivity: Connectivity,
    /// Extension: the frame's intrinsics (pixels, OpenCV/COLMAP convention, pixel centres at +0.5) and
    /// pose in the area's ENU frame, as in `poses.jsonl`.
    #[serde(flatten)]
    pub view: EnuCamera,
    /// Extension: camera centre (WGS84 degrees, ellipsoidal height in metres) and yaw, pitch, roll
    /// (degrees), as in `poses.jsonl`.
    #[serde(flatten)]
    pub geo: GeoPose,
    /// Extension: the frame's drawn look (sun, sky, haze, exposure, camera effects), from its
    /// `rgb/<frame>.render.json`, when the RGB frame has one.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub look: Option<serde_json::Value>,
    /// Extension: the frame's LoD/tileset consistency score (`render-masks --tileset`, 0–1).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub consistency: Option<f64>,
    /// Extension: the frame's ignore mask (`render-masks --tileset … --occlusion ignore`), relative
    /// to `info.image_root`: 8-bit grey, 255 where the tileset hides a LoD building. Pixels to
    /// exclude from the loss and from evaluation (neither building nor background).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ignore_file: Option<String>,
}

/// `annotations[]`: one building instance in one image.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Annotation {
    /// From 1 within the file.
    pub id: u64,
    /// The image's id.
    pub image_id: u64,
    /// Always [`BUILDING_CATEGORY_ID`].
    pub category_id: u32,
    /// The mask: an RLE, or polygons with `--polygons`.
    pub segmentation: Segmentation,
    /// Pixel count of the mask.
    pub area: u64,
    /// `[x, y, width, height]`, pixels.
    pub bbox: [f64; 4],
    /// 0, or 1 for truncated instances under `--truncated flag`.
    pub iscrowd: u8,
    /// Extension: building ID (as in the ID map and `buildings.json`).
    pub building_id: BuildingId,
    /// Extension: source identity of the building (gml:id, CityJSON key, …).
    pub source_id: String,
    /// Extension: index of the component among the building's components in this frame (component
    /// annotations only).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub component: Option<u32>,
    /// Extension: number of components merged (building annotations only).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub num_components: Option<u32>,
    /// Extension: visible pixels / pixels of the building rendered alone, when `render-masks` computed it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub visible_fraction: Option<f64>,
    /// Extension: the instance touches the image border.
    pub truncated: bool,
    /// Extension: area (scene) name.
    pub area_name: String,
    /// Extension: the lossless mask when `segmentation` holds polygons (`--polygons`), which cannot
    /// represent holes.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mask_rle: Option<RleJson>,
}

/// `categories[]`.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct Category {
    /// Always [`BUILDING_CATEGORY_ID`].
    pub id: u32,
    /// `building`.
    pub name: String,
    /// `building`.
    pub supercategory: String,
}

impl Category {
    /// The single `building` category.
    pub fn building() -> Self {
        Category { id: BUILDING_CATEGORY_ID, name: "building".into(), supercategory: "building".into() }
    }
}

/// A segmentation: an RLE object or a list of polygons (`[x1, y1, x2, y2, …]` in pixel coordinates).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(untagged)]
pub enum Segmentation {
    /// A run-length-encoded mask.
    Rle(RleJson),
    /// Polygons, each `[x0, y0, x1, y1, …]` in pixels.
    Polygons(Vec<Vec<f64>>),
}

/// The JSON form of an RLE: `{"size": [h, w], "counts": "<compressed>" | [run, …]}`.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct RleJson {
    /// `[height, width]`, pixels.
    pub size: [u32; 2],
    /// The run lengths, compressed or not.
    pub counts: RleCounts,
}

/// Compressed (string) or uncompressed (list of runs) counts.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(untagged)]
pub enum RleCounts {
    /// pycocotools' compressed string.
    Compressed(String),
    /// The run lengths, column-major, starting with background.
    Uncompressed(Vec<u32>),
}

impl From<&Rle> for RleJson {
    /// The compressed form, as pycocotools writes it.
    fn from(r: &Rle) -> Self {
        RleJson { size: r.size, counts: RleCounts::Compressed(r.to_string()) }
    }
}

impl RleJson {
    /// The RLE this JSON describes.
    ///
    /// # Errors
    /// [`RleError`] when the counts are malformed or do not cover the image.
    pub fn to_rle(&self) -> Result<Rle, RleError> {
        match &self.counts {
            RleCounts::Compressed(s) => Rle::from_string(s, self.size[0], self.size[1]),
            RleCounts::Uncompressed(c) => Rle::from_counts(self.size, c.clone()),
        }
    }
}

/// The `url` of a licence named in an attribution line (Creative Commons licences only).
pub fn licence_url(attribution: &str) -> String {
    let upper = attribution.to_ascii_uppercase().replace(['-', '_'], " ");
    for (name, path) in [
        ("CC BY SA 4.0", "by-sa/4.0"),
        ("CC BY NC 4.0", "by-nc/4.0"),
        ("CC BY 4.0", "by/4.0"),
        ("CC BY SA 3.0", "by-sa/3.0"),
        ("CC BY 3.0", "by/3.0"),
    ] {
        if upper.contains(name) {
            return format!("https://creativecommons.org/licenses/{path}/");
        }
    }
    if upper.contains("CC0") {
        return "https://creativecommons.org/publicdomain/zero/1.0/".into();
    }
    String::new()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn segmentation_parses_both_rle_forms_and_polygons() {
        let s: Segmentation = serde_json::from_str(r#"{"size":[4,5],"counts":"5220003"}"#).unwrap();
        let Segmentation::Rle(r) = s else { panic!("not an RLE") };
        assert_eq!(r.to_rle().unwrap().counts, [5, 2, 2, 2, 2, 2, 5]);
        let s: Segmentation = serde_json::from_str(r#"{"size":[4,5],"counts":[5,2,2,2,2,2,5]}"#).unwrap();
        let Segmentation::Rle(r) = s else { panic!("not an RLE") };
        assert_eq!(r.to_rle().unwrap().to_string(), "5220003");
        let s: Segmentation = serde_json::from_str("[[0,0,2,0,2,2]]").unwrap();
        assert_eq!(s, Segmentation::Polygons(vec![vec![0.0, 0.0, 2.0, 0.0, 2.0, 2.0]]));
    }

    #[test]
    fn licence_urls_from_attribution_text() {
        assert_eq!(
            licence_url("3D city model (Project PLATEAU), MLIT, CC BY 4.0"),
            "https://creativecommons.org/licenses/by/4.0/"
        );
        assert_eq!(
            licence_url("3DBAG by tudelft3d, CC-BY-SA 4.0"),
            "https://creativecommons.org/licenses/by-sa/4.0/"
        );
        assert_eq!(licence_url("open data, licence unknown"), "");
    }
}

/// Fixtures shared by the COCO stage's unit tests.
#[cfg(test)]
pub(crate) mod testing {
    use super::{AnnotationUnit, AreaInfo, Filters, Image, Info};

    /// The `info` of a train split of one area `a` with 10 buildings, names relative to `..`.
    pub(crate) fn info() -> Info {
        Info {
            description: String::new(),
            version: String::new(),
            contributor: String::new(),
            url: String::new(),
            split: "train".into(),
            image_root: "..".into(),
            images_missing: false,
            annotation_unit: AnnotationUnit::Component,
            filters: Filters::default(),
            areas: vec![AreaInfo {
                name: "a".into(),
                manifest_split: "train".into(),
                held_out: false,
                buildings: 10,
                sources: vec![],
                attributions: vec![],
            }],
        }
    }

    /// Image `id` of area `a`, camera `cam2`, `width × height` px, its ID map at `a/cam2/masks/<id>.png`
    /// (also its `file_name`), at an identity pose.
    pub(crate) fn image(id: u64, width: u32, height: u32) -> Image {
        let pose: crate::camera::PoseRecord = serde_json::from_value(serde_json::json!({
            "name": "f", "area": "a", "preset": "cam2", "trajectory": "grid", "sequence": 0, "index": 0,
            "intrinsics": {"width_px": 4, "height_px": 4, "fx_px": 1.0, "fy_px": 1.0, "cx_px": 2.0, "cy_px": 2.0},
            "cam_to_world_enu": [[1.0,0.0,0.0,0.0],[0.0,1.0,0.0,0.0],[0.0,0.0,1.0,0.0],[0.0,0.0,0.0,1.0]],
            "colmap_qvec": [1.0,0.0,0.0,0.0], "colmap_tvec": [0.0,0.0,0.0], "ecef_m": [0.0,0.0,0.0],
            "lat_deg": 0.0, "lon_deg": 0.0, "h_m": 0.0, "yaw_deg": 0.0, "pitch_deg": 0.0, "roll_deg": 0.0,
            "height_above_ground_m": 0.0
        }))
        .unwrap();
        Image {
            id,
            file_name: format!("a/cam2/masks/{id}.png"),
            width,
            height,
            license: None,
            area_name: "a".into(),
            camera: "cam2".into(),
            preset: "cam2".into(),
            frame: format!("{id}"),
            mask_file: format!("a/cam2/masks/{id}.png"),
            connectivity: crate::label::Connectivity::Eight,
            view: pose.view,
            geo: pose.geo,
            look: None,
            consistency: None,
            ignore_file: None,
        }
    }
}
