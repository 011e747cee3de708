//! Errors of the COCO stage. Every variant names the file concerned; causes stay in `#[source]`.
//!
//! What is wrong inside a file is a value of its own ([`LayoutProblem`], [`MismatchProblem`],
//! [`ImageProblem`], [`MissingField`], [`PartsProblem`]) that carries the names, counts and ids
//! involved; its `Display` is the text after the file name.

use std::path::PathBuf;

use crate::label::Connectivity;
use crate::scene::BuildingId;
/// The cause chain on one line (one helper for the whole crate).
pub(crate) use crate::util::error_chain as chain_string;
use crate::util::shard::PART_MARKER;
use crate::util::{FileError, Shard};

use super::parts::{PartOptions, PART_KIND, PART_VERSION};
use super::rle::RleError;

/// What can go wrong while exporting, reading or summarising COCO files.
#[derive(Debug, thiserror::Error)]
pub enum CocoError {
    /// Reading, writing or listing a file failed.
    #[error(transparent)]
    File(#[from] FileError),
    /// A JSON file does not parse into the expected structure.
    #[error("{}: invalid JSON{}", path.display(), line.map(|l| format!(" at line {l}")).unwrap_or_default())]
    Json {
        /// The file.
        path: PathBuf,
        /// 1-based line of a JSON-lines file, when the file is one.
        line: Option<usize>,
        /// The parser's error.
        #[source]
        source: serde_json::Error,
    },
    /// A PNG could not be decoded.
    #[error("{}: cannot decode PNG", path.display())]
    PngDecode {
        /// The PNG.
        path: PathBuf,
        /// The decoder's error.
        #[source]
        source: png::DecodingError,
    },
    /// A PNG could not be encoded.
    #[error("{}: cannot encode PNG", path.display())]
    PngEncode {
        /// The PNG being written.
        path: PathBuf,
        /// The encoder's error.
        #[source]
        source: png::EncodingError,
    },
    /// Stopped by Ctrl-C; nothing was written.
    #[error(transparent)]
    Interrupted(#[from] crate::util::interrupt::Interrupted),
    /// A pose file cannot be read.
    #[error(transparent)]
    Poses(#[from] crate::camera::CameraError),
    /// An instance-ID map cannot be read.
    #[error(transparent)]
    Ids(#[from] crate::scene::IdError),
    /// An image is not of a kind this stage reads.
    #[error("{}: {problem}", path.display())]
    Image {
        /// The image.
        path: PathBuf,
        /// What is wrong with it.
        problem: ImageProblem,
    },
    /// The components recomputed from an ID map disagree with its `<frame>.instances.json` (or a COCO
    /// file's masks with their ID maps).
    #[error("{}: does not match its ID map {}: {problem}", instances.display(), id_map.display())]
    Mismatch {
        /// The instance file (or COCO file).
        instances: PathBuf,
        /// The ID map it describes.
        id_map: PathBuf,
        /// Where they disagree.
        problem: Box<MismatchProblem>,
    },
    /// The working directory does not have the layout the export expects.
    #[error("{}: {problem}", path.display())]
    Layout {
        /// The file or directory that is not as expected.
        path: PathBuf,
        /// What is wrong, with the command that fixes it where there is one.
        problem: LayoutProblem,
    },
    /// A file has the right syntax but wrong content; each problem carries its JSON path.
    #[error("{}: {} problem(s):\n  {}", path.display(), problems.len(), problems.join("\n  "))]
    Invalid {
        /// The file.
        path: PathBuf,
        /// One line per problem, each starting with its JSON path.
        problems: Vec<String>,
    },
    /// An RLE could not be built or parsed.
    #[error("{}: {context}", path.display())]
    Rle {
        /// The file the RLE is read from or written to.
        path: PathBuf,
        /// Where in the file (JSON path or frame) the RLE comes from.
        context: String,
        /// What is wrong with the RLE.
        #[source]
        source: RleError,
    },
    /// The export would list no image at all; nothing was written. Names the command that fills the gap.
    #[error("{}: the export would list no image, so nothing was written: {}", workdir.display(), gap.advice())]
    EmptyExport {
        /// The working directory exported.
        workdir: PathBuf,
        /// Why no image is left.
        gap: EmptyGap,
    },
    /// `--holdout` names an area that is not in the working directory.
    #[error("--holdout {area}: no such area under {}; areas found: {}", workdir.display(), available.join(", "))]
    UnknownHoldout {
        /// The area named.
        area: String,
        /// The working directory.
        workdir: PathBuf,
        /// The areas it holds.
        available: Vec<String>,
    },
    /// Some frames failed; nothing was written. The first failure is the source, the others are listed.
    #[error(
        "{failed} of {total} frames could not be exported, so nothing was written{}\nfirst failure",
        list_others(others)
    )]
    Frames {
        /// Frames that failed.
        failed: usize,
        /// Frames tried.
        total: usize,
        /// The first failure.
        #[source]
        first: Box<CocoError>,
        /// The other failures, each with its cause chain.
        others: Vec<String>,
    },
    /// The parts shards wrote of an export do not make one export (missing or foreign parts).
    #[error("{}: {problem}", dir.display())]
    Parts {
        /// The part directory or part file concerned (the parts directory when all are).
        dir: PathBuf,
        /// Why the parts do not combine.
        problem: PartsProblem,
    },
    /// A filter needs data the instance files do not have.
    #[error("{}: {missing}", path.display())]
    MissingData {
        /// The instance file.
        path: PathBuf,
        /// What it lacks, with the command that writes it.
        missing: MissingField,
    },
}

/// What is wrong with the working directory's (or the COCO directory's) layout: the text after the
/// path of a [`CocoError::Layout`].
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum LayoutProblem {
    /// An area's `manifest.json` names another area than the directory it is in.
    #[error("names area \"{named}\" but lives in directory \"{directory}\"")]
    AreaName {
        /// The area the manifest names.
        named: String,
        /// The directory's name.
        directory: String,
    },
    /// An area's `manifest.json` has a split other than train, val and test.
    #[error("split \"{split}\" is not one of train, val, test")]
    UnknownSplit {
        /// The split as written.
        split: String,
    },
    /// A frame name occurs twice in a `poses.jsonl`.
    #[error("frame name \"{frame}\" appears more than once")]
    DuplicateFrame {
        /// The frame name.
        frame: String,
    },
    /// A `poses.jsonl` lists a frame of another area.
    #[error("frame \"{frame}\" belongs to area \"{belongs_to}\", not \"{area}\"")]
    ForeignFrame {
        /// The frame name.
        frame: String,
        /// The area the pose names.
        belongs_to: String,
        /// The area whose directory holds the file.
        area: String,
    },
    /// The working directory holds no prepared area.
    #[error(
        "no prepared area here (no <area>/scene/manifest.json); run `insgen prepare --area NAME`, \
         `insgen sample` and `insgen render-masks` first, or pass --workdir"
    )]
    NoArea,
    /// The COCO directory holds no split file.
    #[error(
        "no instances_train.json, instances_val.json or instances_test.json here; run `insgen \
         export-coco` first or pass --coco DIR"
    )]
    NoSplits,
    /// An image a COCO file names does not exist.
    #[error("the image named by the COCO file does not exist; run `insgen export-coco` again")]
    MissingImage,
    /// A photo a COCO file names does not exist (the Hugging Face export needs every photo).
    #[error("the photo named by the COCO file does not exist; run `insgen export-coco` again")]
    MissingPhoto,
    /// An image lives outside the export folder, which the Hugging Face export cannot ship.
    #[error(
        "image {image_id} ({file_name}) is not in the export's {folder}/ folder: export-hf needs a \
         self-contained export; run `insgen export-coco` without --link-root"
    )]
    NotSelfContained {
        /// The image's COCO id.
        image_id: u64,
        /// Its `file_name`.
        file_name: String,
        /// The export folder the images should be in (`images/<split>`).
        folder: String,
    },
    /// An annotation has polygons but not the exact mask the Hugging Face export writes.
    #[error("annotation {annotation_id} has polygons but no mask_rle")]
    PolygonsWithoutRle {
        /// The annotation's COCO id.
        annotation_id: u64,
    },
}

/// The facts an instance file gives about one instance, or an ID map about one component.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ComponentFacts {
    /// The building.
    pub building_id: BuildingId,
    /// Pixels.
    pub area_px: u64,
    /// Bounding box `[x, y, w, h]`, pixels.
    pub bbox_px: [u32; 4],
    /// Whether it touches the image border.
    pub truncated: bool,
}

impl std::fmt::Display for ComponentFacts {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "building {} with {} px, bbox {:?}, truncated {}",
            self.building_id, self.area_px, self.bbox_px, self.truncated
        )
    }
}

/// Where an instance file (or a COCO file) and its ID map disagree: the text after the paths of a
/// [`CocoError::Mismatch`].
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum MismatchProblem {
    /// The instance file is for another frame.
    #[error("it is for frame \"{found}\", expected \"{expected}\"")]
    Frame {
        /// The frame the instance file names.
        found: String,
        /// The frame of the pose.
        expected: String,
    },
    /// The instance file gives another frame size than the ID map has.
    #[error("it gives {}×{} px, the ID map is {}×{} px", listed[0], listed[1], id_map[0], id_map[1])]
    InstancesSize {
        /// `[width, height]` in the instance file, pixels.
        listed: [u32; 2],
        /// `[width, height]` of the ID map, pixels.
        id_map: [u32; 2],
    },
    /// `poses.jsonl` gives another frame size than the ID map has.
    #[error("poses.jsonl gives {}×{} px for this frame, the ID map is {}×{} px", pose[0], pose[1], id_map[0], id_map[1])]
    PoseSize {
        /// `[width, height]` of the pose's intrinsics, pixels.
        pose: [u32; 2],
        /// `[width, height]` of the ID map, pixels.
        id_map: [u32; 2],
    },
    /// The instance file lists another number of instances than the ID map has components.
    #[error(
        "it lists {listed} instances, the ID map has {components} components of at least {min_area_px} px \
         ({}-connectivity)",
        neighbours(*connectivity)
    )]
    InstanceCount {
        /// Instances listed.
        listed: usize,
        /// Components of at least `min_area_px` in the ID map.
        components: usize,
        /// The instance file's smallest component, pixels.
        min_area_px: u64,
        /// The connectivity the components were labelled with.
        connectivity: Connectivity,
    },
    /// An instance differs from the ID map's component of the same rank.
    #[error("instances[{index}] is {listed}; the ID map's component #{index} is {found}")]
    Component {
        /// Index in `instances`.
        index: usize,
        /// What the instance file says.
        listed: ComponentFacts,
        /// What the ID map has.
        found: ComponentFacts,
    },
    /// An instance's building is not in the area's building table.
    #[error("instances[{index}]: building {building_id} is not in {}", buildings.display())]
    UnknownBuilding {
        /// Index in `instances`.
        index: usize,
        /// The building.
        building_id: BuildingId,
        /// The area's `buildings.json`.
        buildings: PathBuf,
    },
    /// An instance's `source_id` differs from the building table's.
    #[error(
        "instances[{index}]: building {building_id} has source_id \"{listed}\" here but \"{table}\" in {}",
        buildings.display()
    )]
    SourceId {
        /// Index in `instances`.
        index: usize,
        /// The building.
        building_id: BuildingId,
        /// The `source_id` in the instance file.
        listed: String,
        /// The `source_id` in `buildings.json`.
        table: String,
        /// The area's `buildings.json`.
        buildings: PathBuf,
    },
    /// A COCO image's size differs from its ID map's.
    #[error("image {image_id} is {}×{} in the COCO file, its ID map {}×{}", listed[0], listed[1], id_map[0], id_map[1])]
    ImageSize {
        /// The COCO image id.
        image_id: u64,
        /// `[width, height]` in the COCO file, pixels.
        listed: [u32; 2],
        /// `[width, height]` of the ID map, pixels.
        id_map: [u32; 2],
    },
    /// An annotation has polygons but no `mask_rle`.
    #[error("annotation {annotation_id} has polygons and no `mask_rle`: the exact mask is unknown")]
    NoExactMask {
        /// The annotation id.
        annotation_id: u64,
    },
    /// An annotation's RLE has another size than its image.
    #[error("annotation {annotation_id}: RLE size {rle_size:?} is not the image's [{}, {}]", image_size[0], image_size[1])]
    RleSize {
        /// The annotation id.
        annotation_id: u64,
        /// The RLE's `[height, width]`, pixels.
        rle_size: [u32; 2],
        /// The image's `[height, width]`, pixels.
        image_size: [u32; 2],
    },
    /// Pixels of an annotation's mask hold another building in the ID map.
    #[error(
        "annotation {annotation_id} (building {building_id}): {wrong_px} of its pixels hold another ID in the ID \
         map, first at ({}, {}) holding {first_found}; run `insgen export-coco` again",
        first[0], first[1]
    )]
    ForeignPixels {
        /// The annotation id.
        annotation_id: u64,
        /// The annotation's building.
        building_id: BuildingId,
        /// Pixels of the mask holding another ID.
        wrong_px: u64,
        /// `[x, y]` of the first such pixel (raster order of the RLE).
        first: [u32; 2],
        /// The ID the ID map holds there.
        first_found: BuildingId,
    },
    /// An annotation's `area` or `bbox` differs from its mask's.
    #[error("annotation {annotation_id}: area {area} and bbox {bbox:?} differ from its mask's {mask_area} and {mask_bbox:?}")]
    AreaBox {
        /// The annotation id.
        annotation_id: u64,
        /// The annotation's `area`, pixels.
        area: u64,
        /// The annotation's `bbox` `[x, y, w, h]`, pixels.
        bbox: [f64; 4],
        /// The mask's area, pixels.
        mask_area: u64,
        /// The mask's box `[x, y, w, h]`, pixels.
        mask_bbox: [f64; 4],
    },
}

/// 4 or 8: the neighbours a pixel has under `c`.
fn neighbours(c: Connectivity) -> u8 {
    match c {
        Connectivity::Four => 4,
        Connectivity::Eight => 8,
    }
}

/// Why an image cannot be used: the text after the path of a [`CocoError::Image`].
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum ImageProblem {
    /// A photo's size differs from its ID map's.
    #[error("{}×{} px, but its ID map {} is {}×{} px", size[0], size[1], id_map.display(), id_map_size[0], id_map_size[1])]
    SizeMismatch {
        /// `[width, height]` of the photo, pixels.
        size: [u32; 2],
        /// The ID map.
        id_map: PathBuf,
        /// `[width, height]` of the ID map, pixels.
        id_map_size: [u32; 2],
    },
    /// A palette PNG the decoder did not expand.
    #[error("unexpanded palette PNG")]
    Palette,
}

/// Data a filter needs that an instance file lacks: the text after the path of a
/// [`CocoError::MissingData`], with the command that writes it.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum MissingField {
    /// No consistency score (`occlusion`), which `--min-consistency` needs.
    #[error(
        "it has no consistency score, which --min-consistency needs; rerun `insgen render-masks \
         --area {area} --camera {camera} --tileset FILE`"
    )]
    Consistency {
        /// The frame's area.
        area: String,
        /// The frame's camera.
        camera: String,
    },
    /// An instance without `visible_fraction`, which `--min-visible-fraction` needs.
    #[error(
        "instances[{index}] has no visible_fraction, which --min-visible-fraction needs; rerun \
         `insgen render-masks --area {area} --camera {camera} --visible-fraction --force`"
    )]
    VisibleFraction {
        /// Index in `instances`.
        index: usize,
        /// The frame's area.
        area: String,
        /// The frame's camera.
        camera: String,
    },
}

/// Why the parts of a sharded export do not combine: the text after the path of a
/// [`CocoError::Parts`].
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PartsProblem {
    /// No part was given.
    #[error("no parts")]
    NoParts,
    /// A part's marker is of another kind or version.
    #[error("{PART_MARKER} is a {kind:?} part of version {version}, expected {PART_KIND:?} version {PART_VERSION}")]
    WrongKind {
        /// The marker's `kind`.
        kind: String,
        /// The marker's `version`.
        version: u32,
    },
    /// A part's marker names another shard than its directory.
    #[error("{PART_MARKER} says shard {said}, the directory {shard}")]
    ShardName {
        /// The shard the marker names, as written.
        said: String,
        /// The shard of the directory.
        shard: Shard,
    },
    /// Parts of runs with different shard counts.
    #[error(
        "parts of {count} shards ({}) and of {other_count} ({}) are mixed; merge the parts of one run",
        first_dir.display(),
        other_dir.display()
    )]
    MixedCounts {
        /// The first part's shard count.
        count: u32,
        /// The first part's directory.
        first_dir: PathBuf,
        /// The other shard count.
        other_count: u32,
        /// A part with that count.
        other_dir: PathBuf,
    },
    /// Shards of the export are missing.
    #[error(
        "shard(s) {} of the export are missing; run `insgen export-coco --shard I/{count}` for them \
         and give their work directories to the merge",
        missing.iter().map(Shard::to_string).collect::<Vec<_>>().join(", ")
    )]
    MissingShards {
        /// The missing shards.
        missing: Vec<Shard>,
        /// The shard count.
        count: u32,
    },
    /// A shard was exported with other options than the first.
    #[error("shard {shard} was exported with other options than shard {first_shard} ({options:?} vs {first_options:?})")]
    Options {
        /// The shard.
        shard: Shard,
        /// The first shard.
        first_shard: Shard,
        /// Its options.
        options: Box<PartOptions>,
        /// The first shard's options.
        first_options: Box<PartOptions>,
    },
    /// Two shards export the same frame.
    #[error("shard {shard} exports a frame another shard exports too")]
    DuplicateFrame {
        /// The shard whose part file repeats a frame.
        shard: Shard,
    },
    /// A part file's annotations refer to an image it does not hold.
    #[error("annotations refer to image {image_id}, which the file does not hold")]
    OrphanAnnotations {
        /// The image id referred to.
        image_id: u64,
    },
    /// A part file's info, licences or categories differ from the first shard's.
    #[error(
        "its info, licences or categories differ from shard {first_shard}'s: the shards exported different \
         work directories"
    )]
    OtherDataset {
        /// The first shard.
        first_shard: Shard,
    },
}

impl CocoError {
    pub(crate) fn json(path: &std::path::Path, source: serde_json::Error) -> Self {
        CocoError::Json { path: path.to_path_buf(), line: None, source }
    }
}

fn list_others(others: &[String]) -> String {
    const SHOWN: usize = 20;
    let mut s: String = others.iter().take(SHOWN).map(|o| format!("\n  - {o}")).collect();
    if others.len() > SHOWN {
        s.push_str(&format!("\n  - … and {} more", others.len() - SHOWN));
    }
    if !s.is_empty() {
        s.insert_str(0, "; other failures:");
    }
    s
}

/// Why an export came out empty, most actionable first.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum EmptyGap {
    /// Labelled frames have no RGB frame yet (the first camera without them).
    NoRgb {
        /// The area.
        area: String,
        /// The camera.
        camera: String,
        /// Its labelled frames without an RGB photo.
        frames: u64,
    },
    /// Posed frames have no ID map yet.
    NoMasks {
        /// Posed frames without an ID map.
        frames: u64,
    },
    /// Frames exist but the filters dropped every image: this many scored below `--min-consistency`,
    /// this many had no annotation left (and empty images are dropped).
    Filtered {
        /// Frames scored below `--min-consistency`.
        low_consistency_images: u64,
        /// Images with no annotation left.
        empty_images: u64,
    },
    /// No area holds a posed frame.
    NoFrames,
}

impl EmptyGap {
    /// The sentence that tells what to run.
    pub fn advice(&self) -> String {
        match self {
            EmptyGap::NoRgb { area, camera, frames } => format!(
                "{frames} labelled frame(s) of {area}/{camera} have no RGB photo; run `insgen render-rgb --area \
                 {area} --camera {camera}` (for every area and camera), or export the labels alone with \
                 `insgen export-coco --label-only`"
            ),
            EmptyGap::NoMasks { frames } => format!(
                "{frames} posed frame(s) have no ID map; run `insgen render-masks --area NAME --camera NAME` first"
            ),
            EmptyGap::Filtered { low_consistency_images, empty_images } => format!(
                "the filters left no image: {low_consistency_images} frame(s) scored below --min-consistency, \
                 {empty_images} image(s) had no annotation left (lower --min-consistency, --min-area or \
                 --min-visible-fraction, or keep empty images)"
            ),
            EmptyGap::NoFrames => "no area has posed frames; run `insgen sample --area NAME --camera C` first".into(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn shard(index: u32, count: u32) -> Shard {
        Shard { index, count }
    }

    #[test]
    fn problem_texts() {
        let b = BuildingId::new(7).unwrap();
        let cases: Vec<(String, &str)> = vec![
            (
                LayoutProblem::AreaName { named: "a".into(), directory: "b".into() }.to_string(),
                "names area \"a\" but lives in directory \"b\"",
            ),
            (LayoutProblem::UnknownSplit { split: "x".into() }.to_string(), "split \"x\" is not one of train, val, test"),
            (LayoutProblem::DuplicateFrame { frame: "f".into() }.to_string(), "frame name \"f\" appears more than once"),
            (
                LayoutProblem::ForeignFrame { frame: "f".into(), belongs_to: "a".into(), area: "b".into() }.to_string(),
                "frame \"f\" belongs to area \"a\", not \"b\"",
            ),
            (
                LayoutProblem::NoArea.to_string(),
                "no prepared area here (no <area>/scene/manifest.json); run `insgen prepare --area NAME`, `insgen \
                 sample` and `insgen render-masks` first, or pass --workdir",
            ),
            (
                LayoutProblem::NoSplits.to_string(),
                "no instances_train.json, instances_val.json or instances_test.json here; run `insgen export-coco` \
                 first or pass --coco DIR",
            ),
            (
                MismatchProblem::InstanceCount {
                    listed: 3,
                    components: 2,
                    min_area_px: 10,
                    connectivity: Connectivity::Four,
                }
                .to_string(),
                "it lists 3 instances, the ID map has 2 components of at least 10 px (4-connectivity)",
            ),
            (
                MismatchProblem::Component {
                    index: 1,
                    listed: ComponentFacts { building_id: b, area_px: 5, bbox_px: [1, 2, 3, 4], truncated: false },
                    found: ComponentFacts { building_id: b, area_px: 6, bbox_px: [1, 2, 3, 4], truncated: true },
                }
                .to_string(),
                "instances[1] is building 7 with 5 px, bbox [1, 2, 3, 4], truncated false; the ID map's component #1 \
                 is building 7 with 6 px, bbox [1, 2, 3, 4], truncated true",
            ),
            (
                MismatchProblem::SourceId {
                    index: 0,
                    building_id: b,
                    listed: "x".into(),
                    table: "y".into(),
                    buildings: "s/buildings.json".into(),
                }
                .to_string(),
                "instances[0]: building 7 has source_id \"x\" here but \"y\" in s/buildings.json",
            ),
            (
                MismatchProblem::ImageSize { image_id: 4, listed: [8, 6], id_map: [9, 5] }.to_string(),
                "image 4 is 8×6 in the COCO file, its ID map 9×5",
            ),
            (
                MismatchProblem::RleSize { annotation_id: 2, rle_size: [6, 8], image_size: [5, 9] }.to_string(),
                "annotation 2: RLE size [6, 8] is not the image's [5, 9]",
            ),
            (
                MismatchProblem::ForeignPixels {
                    annotation_id: 2,
                    building_id: b,
                    wrong_px: 3,
                    first: [4, 5],
                    first_found: BuildingId::new(9).unwrap(),
                }
                .to_string(),
                "annotation 2 (building 7): 3 of its pixels hold another ID in the ID map, first at (4, 5) holding \
                 9; run `insgen export-coco` again",
            ),
            (
                MismatchProblem::AreaBox {
                    annotation_id: 2,
                    area: 3,
                    bbox: [0.0, 1.0, 2.0, 3.0],
                    mask_area: 4,
                    mask_bbox: [0.0, 1.0, 2.0, 2.0],
                }
                .to_string(),
                "annotation 2: area 3 and bbox [0.0, 1.0, 2.0, 3.0] differ from its mask's 4 and [0.0, 1.0, 2.0, 2.0]",
            ),
            (
                ImageProblem::SizeMismatch { size: [8, 8], id_map: "m/1.png".into(), id_map_size: [22, 12] }
                    .to_string(),
                "8×8 px, but its ID map m/1.png is 22×12 px",
            ),
            (
                MissingField::Consistency { area: "a".into(), camera: "c".into() }.to_string(),
                "it has no consistency score, which --min-consistency needs; rerun `insgen render-masks --area a \
                 --camera c --tileset FILE`",
            ),
            (
                MissingField::VisibleFraction { index: 2, area: "a".into(), camera: "c".into() }.to_string(),
                "instances[2] has no visible_fraction, which --min-visible-fraction needs; rerun `insgen \
                 render-masks --area a --camera c --visible-fraction --force`",
            ),
            (
                PartsProblem::WrongKind { kind: "yolo".into(), version: 2 }.to_string(),
                "part.json is a \"yolo\" part of version 2, expected \"coco\" version 1",
            ),
            (
                PartsProblem::ShardName { said: "1/3".into(), shard: shard(0, 2) }.to_string(),
                "part.json says shard 1/3, the directory 0/2",
            ),
            (
                PartsProblem::MixedCounts {
                    count: 2,
                    first_dir: "p/0-of-2".into(),
                    other_count: 3,
                    other_dir: "p/0-of-3".into(),
                }
                .to_string(),
                "parts of 2 shards (p/0-of-2) and of 3 (p/0-of-3) are mixed; merge the parts of one run",
            ),
            (
                PartsProblem::MissingShards { missing: vec![shard(1, 3), shard(2, 3)], count: 3 }.to_string(),
                "shard(s) 1/3, 2/3 of the export are missing; run `insgen export-coco --shard I/3` for them and give \
                 their work directories to the merge",
            ),
            (
                PartsProblem::OtherDataset { first_shard: shard(0, 2) }.to_string(),
                "its info, licences or categories differ from shard 0/2's: the shards exported different work \
                 directories",
            ),
        ];
        for (got, want) in cases {
            assert_eq!(got, want);
        }
    }
}
