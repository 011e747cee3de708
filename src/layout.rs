//! The one layout of a work directory: every file and folder the stages read and write, named once.
//!
//! ```text
//! <workdir>/
//!   commands.jsonl                     every command run on this work directory (provenance)
//!   <area>/
//!     scene/                           prepare: scene.glb, manifest.json, buildings.json,
//!                                      textures/, tileset/ (export-tiles)
//!     <camera>/                        one folder per camera (preset or file stem)
//!       poses.jsonl, priors.jsonl      sample: ground truth and prior poses
//!       camera.json, sampling.json, flight_plan.png, colmap/
//!       masks/<frame>.png              render-masks: ID maps
//!       masks/<frame>.instances.json   render-masks: instance lists
//!       rgb/<frame>.{png,jpg}          render-rgb: photos, rgb/<frame>.render.json beside each
//!       blender/                       render-rgb: job files and done markers
//! ```
//!
//! A stage asks a [`WorkDir`] for an [`AreaDir`] and a [`CameraDir`] and those for paths; no stage
//! spells a folder name itself, so a file moved here moves for every stage, `merge` and `verify`.
//! The names of an export's files are in [`ExportDir`]:
//!
//! ```text
//! <export>/                            export-coco --out (default <workdir>/coco)
//!   dataset.json, README.md            the manifest and the dataset card
//!   index.html                         the dataset in a browser: summary, statistics, figures, links
//!   stats.md, stats.json, hist_*.png, contact_sheet.png                 the statistics report
//!   figures/<area>/contact_sheet.png, figures/<area>/<camera>/flight_plan.png    shown by index.html
//!   instances_<split>.json             COCO files; names relative to the folder (image_root ".")
//!   images/<split>/<area>/<camera>/<frame>.png         photos (hard links or copies)
//!   images/<split>/metadata.jsonl      export-hf: the Hugging Face imagefolder metadata
//!   masks/<split>/<area>/<camera>/<frame>.png          ID maps, <frame>.instances.json (and .ignore.png)
//!   parts/<i>-of-<N>/                  what shards write before `merge`
//! ```

use std::path::{Path, PathBuf};

/// The provenance log at the work directory's root.
pub const COMMANDS_FILE: &str = "commands.jsonl";
/// An area's prepared scene folder.
pub const SCENE_DIR: &str = "scene";
/// The instanced scene mesh (binary glTF) inside the scene folder.
pub const GLB_FILE: &str = "scene.glb";
/// The scene manifest (origin, frames, extents, attributions) inside the scene folder.
pub const MANIFEST_FILE: &str = "manifest.json";
/// The building table (ID ↔ source ID) inside the scene folder.
pub const BUILDINGS_FILE: &str = "buildings.json";
/// Texture images of the scene's appearances, inside the scene folder.
pub const TEXTURES_DIR: &str = "textures";
/// The scene's 3D Tiles export, inside the scene folder (`export-tiles` default).
pub const TILESET_DIR: &str = "tileset";
/// Ground-truth poses, one JSON object per frame, in a camera folder.
pub const POSES_FILE: &str = "poses.jsonl";
/// Prior (noisy) poses, in a camera folder.
pub const PRIORS_FILE: &str = "priors.jsonl";
/// The COLMAP model of the poses, in a camera folder.
pub const COLMAP_DIR: &str = "colmap";
/// The camera's intrinsics and preset, in a camera folder.
pub const CAMERA_FILE: &str = "camera.json";
/// The sampler's settings and counts, in a camera folder.
pub const SAMPLING_FILE: &str = "sampling.json";
/// The picture of the sampled poses over the area, in a camera folder.
pub const FLIGHT_PLAN_FILE: &str = "flight_plan.png";
/// ID maps and instance lists, in a camera folder.
pub const MASKS_DIR: &str = "masks";
/// Photos (and their render metadata), in a camera folder.
pub const RGB_DIR: &str = "rgb";
/// Suffix of the metadata the RGB stage writes beside each frame (`rgb/<frame>.render.json`).
pub const RGB_META_SUFFIX: &str = "render.json";
/// Blender job files, logs and done markers, in a camera folder.
pub const BLENDER_DIR: &str = "blender";
/// The parts shards write before `merge` (in an export folder or a work directory).
pub const PARTS_DIR: &str = "parts";
/// An export's manifest.
pub const DATASET_FILE: &str = "dataset.json";
/// An export's dataset card.
pub const CARD_FILE: &str = "README.md";
/// A self-contained export's checksums, in the format of coreutils' `sha256sum -c`.
pub const CHECKSUMS_FILE: &str = "SHA256SUMS";
/// The photos inside a self-contained export: `images/<split>/<area>/<camera>/<frame>.png`.
pub const EXPORT_IMAGES_DIR: &str = "images";
/// The ID maps inside a self-contained export: `masks/<split>/<area>/<camera>/<frame>.png`.
pub const EXPORT_MASKS_DIR: &str = "masks";
/// The Hugging Face `imagefolder` metadata of a split, in `images/<split>/` (`export-hf`).
pub const HF_METADATA_FILE: &str = "metadata.jsonl";

/// `hist_instances_per_image.png`: images by their number of instances, per split.
pub const HIST_INSTANCES_FILE: &str = "hist_instances_per_image.png";
/// `hist_sizes.png`: instances by COCO size class, per split.
pub const HIST_SIZES_FILE: &str = "hist_sizes.png";
/// `hist_consistency.png`: images by LoD/tileset consistency score, per split (only when scored).
pub const HIST_CONSISTENCY_FILE: &str = "hist_consistency.png";
/// `contact_sheet.png`: annotated frames of every split (`export-coco`, `insgen stats`).
pub const CONTACT_SHEET_FILE: &str = "contact_sheet.png";
/// `stats.md`, the statistics report.
pub const STATS_MD_FILE: &str = "stats.md";
/// `stats.json`, the statistics.
pub const STATS_JSON_FILE: &str = "stats.json";

/// `index.html`, the page that shows an export in a browser (`export-coco`).
pub const INDEX_FILE: &str = "index.html";
/// The figures the index shows beside the report's: `figures/<area>/contact_sheet.png` and
/// `figures/<area>/<camera>/flight_plan.png`.
pub const FIGURES_DIR: &str = "figures";

/// A work directory (`--workdir`): one folder per area, and the provenance log.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct WorkDir(PathBuf);

impl WorkDir {
    /// The work directory at `root`.
    pub fn new(root: impl Into<PathBuf>) -> WorkDir {
        WorkDir(root.into())
    }

    /// Its root folder.
    pub fn root(&self) -> &Path {
        &self.0
    }

    /// `<workdir>/<area>/`.
    pub fn area(&self, area: &str) -> AreaDir {
        AreaDir(self.0.join(area))
    }

    /// `<workdir>/commands.jsonl`.
    pub fn commands_log(&self) -> PathBuf {
        self.0.join(COMMANDS_FILE)
    }
}

/// An area's folder: its prepared scene and one folder per camera.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct AreaDir(PathBuf);

impl AreaDir {
    /// An area folder at `dir` (normally [`WorkDir::area`]).
    pub fn new(dir: impl Into<PathBuf>) -> AreaDir {
        AreaDir(dir.into())
    }

    /// The folder itself.
    pub fn dir(&self) -> &Path {
        &self.0
    }

    /// `<area>/scene/`, the prepared scene.
    pub fn scene(&self) -> PathBuf {
        self.0.join(SCENE_DIR)
    }

    /// `<area>/<camera>/`.
    pub fn camera(&self, camera: &str) -> CameraDir {
        CameraDir(self.0.join(camera))
    }

    /// The camera folders that hold sampled poses, sorted by name (the scene folder is not one).
    ///
    /// # Errors
    /// The I/O error of listing the folder.
    pub fn sampled_cameras(&self) -> std::io::Result<Vec<(String, CameraDir)>> {
        let mut out = Vec::new();
        for entry in std::fs::read_dir(&self.0)? {
            let entry = entry?;
            let name = entry.file_name().to_string_lossy().into_owned();
            let camera = CameraDir(entry.path());
            if name != SCENE_DIR && camera.poses().is_file() {
                out.push((name, camera));
            }
        }
        out.sort_by(|a, b| a.0.cmp(&b.0));
        Ok(out)
    }
}

/// A camera's folder inside an area: poses, masks, photos and the Blender jobs of one camera.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct CameraDir(PathBuf);

impl CameraDir {
    /// A camera folder at `dir` (normally [`AreaDir::camera`]).
    pub fn new(dir: impl Into<PathBuf>) -> CameraDir {
        CameraDir(dir.into())
    }

    /// The folder itself.
    pub fn dir(&self) -> &Path {
        &self.0
    }

    /// `poses.jsonl`.
    pub fn poses(&self) -> PathBuf {
        self.0.join(POSES_FILE)
    }

    /// `priors.jsonl`.
    pub fn priors(&self) -> PathBuf {
        self.0.join(PRIORS_FILE)
    }

    /// `masks/`.
    pub fn masks(&self) -> PathBuf {
        self.0.join(MASKS_DIR)
    }

    /// `masks/<frame>.png`, a frame's ID map.
    pub fn mask_png(&self, frame: &str) -> PathBuf {
        self.masks().join(format!("{frame}.png"))
    }

    /// `masks/<frame>.instances.json`, a frame's instance list.
    pub fn instances(&self, frame: &str) -> PathBuf {
        self.masks().join(format!("{frame}.instances.json"))
    }

    /// `rgb/`.
    pub fn rgb(&self) -> PathBuf {
        self.0.join(RGB_DIR)
    }

    /// `rgb/<frame>.render.json`, what the RGB stage recorded about a frame.
    pub fn rgb_meta(&self, frame: &str) -> PathBuf {
        self.rgb().join(format!("{frame}.{RGB_META_SUFFIX}"))
    }

    /// `flight_plan.png`, the picture of the sampled poses.
    pub fn flight_plan(&self) -> PathBuf {
        self.0.join(FLIGHT_PLAN_FILE)
    }

    /// `blender/`.
    pub fn blender(&self) -> PathBuf {
        self.0.join(BLENDER_DIR)
    }
}

/// An export folder (`export-coco --out`): the dataset manifest, the card, the COCO files per split
/// and the parts of sharded runs.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ExportDir(PathBuf);

impl ExportDir {
    /// The export folder at `dir`.
    pub fn new(dir: impl Into<PathBuf>) -> ExportDir {
        ExportDir(dir.into())
    }

    /// The folder itself.
    pub fn dir(&self) -> &Path {
        &self.0
    }

    /// `dataset.json`.
    pub fn manifest(&self) -> PathBuf {
        self.0.join(DATASET_FILE)
    }

    /// `README.md`, the dataset card.
    pub fn card(&self) -> PathBuf {
        self.0.join(CARD_FILE)
    }

    /// `SHA256SUMS`: every placed file and COCO file with its SHA-256 (`sha256sum -c SHA256SUMS`).
    pub fn checksums(&self) -> PathBuf {
        self.0.join(CHECKSUMS_FILE)
    }

    /// `instances_<split>.json`.
    pub fn instances(&self, split: &str) -> PathBuf {
        self.0.join(format!("instances_{split}.json"))
    }

    /// `index.html`, the dataset's page.
    pub fn index(&self) -> PathBuf {
        self.0.join(INDEX_FILE)
    }

    /// The name, relative to the export folder, of the contact sheet of one area:
    /// `figures/<area>/contact_sheet.png`.
    pub fn contact_sheet_name(area: &str) -> String {
        format!("{FIGURES_DIR}/{area}/{CONTACT_SHEET_FILE}")
    }

    /// The name, relative to the export folder, of the copy of a camera's flight plan:
    /// `figures/<area>/<camera>/flight_plan.png`.
    pub fn flight_plan_name(area: &str, camera: &str) -> String {
        format!("{FIGURES_DIR}/{area}/{camera}/{FLIGHT_PLAN_FILE}")
    }

    /// `parts/`, where shards write before `merge`.
    pub fn parts(&self) -> PathBuf {
        self.0.join(PARTS_DIR)
    }

    /// `images/`, the photos of a self-contained export.
    pub fn images(&self) -> PathBuf {
        self.0.join(EXPORT_IMAGES_DIR)
    }

    /// `masks/`, the ID maps of a self-contained export.
    pub fn masks(&self) -> PathBuf {
        self.0.join(EXPORT_MASKS_DIR)
    }

    /// `images/<split>/`, the photos of one split (and its Hugging Face metadata).
    pub fn split_images(&self, split: &str) -> PathBuf {
        self.images().join(split)
    }

    /// `images/<split>/metadata.jsonl`, the Hugging Face `imagefolder` metadata of a split.
    pub fn hf_metadata(&self, split: &str) -> PathBuf {
        self.split_images(split).join(HF_METADATA_FILE)
    }

    /// The name, relative to the export folder (`/`-separated), of the photos' folder of one split:
    /// `images/<split>`.
    pub fn split_images_name(split: &str) -> String {
        format!("{EXPORT_IMAGES_DIR}/{split}")
    }

    /// The name, relative to the export folder (`/`-separated, as COCO files hold it), of a frame's
    /// photo: `images/<split>/<area>/<camera>/<file>`.
    pub fn image_name(split: &str, area: &str, camera: &str, file: &str) -> String {
        format!("{EXPORT_IMAGES_DIR}/{split}/{area}/{camera}/{file}")
    }

    /// The name, relative to the export folder, of a frame's ID map (or another per-frame mask):
    /// `masks/<split>/<area>/<camera>/<file>`.
    pub fn mask_name(split: &str, area: &str, camera: &str, file: &str) -> String {
        format!("{EXPORT_MASKS_DIR}/{split}/{area}/{camera}/{file}")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn paths_follow_the_documented_tree() {
        let w = WorkDir::new("runs");
        let cam = w.area("demo").camera("cam2");
        assert_eq!(w.area("demo").scene(), Path::new("runs/demo/scene"));
        assert_eq!(cam.poses(), Path::new("runs/demo/cam2/poses.jsonl"));
        assert_eq!(cam.mask_png("f_0001"), Path::new("runs/demo/cam2/masks/f_0001.png"));
        assert_eq!(cam.instances("f_0001"), Path::new("runs/demo/cam2/masks/f_0001.instances.json"));
        assert_eq!(cam.rgb_meta("f_0001"), Path::new("runs/demo/cam2/rgb/f_0001.render.json"));
        assert_eq!(cam.blender(), Path::new("runs/demo/cam2/blender"));
        assert_eq!(w.commands_log(), Path::new("runs/commands.jsonl"));
        let e = ExportDir::new("runs/coco");
        assert_eq!(e.instances("val"), Path::new("runs/coco/instances_val.json"));
        assert_eq!(e.manifest(), Path::new("runs/coco/dataset.json"));
        assert_eq!(e.hf_metadata("val"), Path::new("runs/coco/images/val/metadata.jsonl"));
        assert_eq!(ExportDir::image_name("train", "demo", "cam2", "f.png"), "images/train/demo/cam2/f.png");
        assert_eq!(ExportDir::split_images_name("val"), "images/val");
        assert_eq!(ExportDir::mask_name("test", "demo", "cam2", "f.png"), "masks/test/demo/cam2/f.png");
        assert_eq!(e.index(), Path::new("runs/coco/index.html"));
        assert_eq!(ExportDir::contact_sheet_name("demo"), "figures/demo/contact_sheet.png");
        assert_eq!(ExportDir::flight_plan_name("demo", "cam2"), "figures/demo/cam2/flight_plan.png");
        assert_eq!(cam.flight_plan(), Path::new("runs/demo/cam2/flight_plan.png"));
    }

    #[test]
    fn sampled_cameras_skip_the_scene_and_unsampled_folders() {
        let d = tempfile::tempdir().unwrap();
        let area = AreaDir::new(d.path());
        for (name, poses) in [("scene", true), ("cam2", true), ("cam1", true), ("empty", false)] {
            std::fs::create_dir_all(d.path().join(name)).unwrap();
            if poses {
                std::fs::write(d.path().join(name).join(POSES_FILE), b"").unwrap();
            }
        }
        let names: Vec<String> = area.sampled_cameras().unwrap().into_iter().map(|(n, _)| n).collect();
        assert_eq!(names, ["cam1", "cam2"]);
    }
}
