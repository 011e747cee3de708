//! The prepared scene artifact, as later stages load it.
//!
//! `insgen prepare --area NAME` writes, under `<workdir>/<area>/scene/`:
//! - `scene.glb`: the instanced model in the area's ENU frame (f32 positions relative to the origin,
//!   glTF y-up axes as the format requires: glTF (x, y, z) = ENU (east, up, −north)), a per-vertex
//!   `_FEATURE_ID_0` following `EXT_mesh_features` holding the building ID, and a flat colour per building;
//! - `manifest.json`: origin, ENU↔ECEF transform, CRS chain, geoid, counts, source hashes, area
//!   polygon ([`Manifest`]);
//! - `buildings.json`: the building table ([`BuildingRecord`]s ordered by ID).
//!
//! With clutter (the default of `insgen prepare`), `scene.glb` also holds one node per clutter layer
//! (`insgen_clutter_roads`, `…_trees`, …, see [`super::clutter`]) and the manifest's `clutter` section
//! lists them.
//!
//! Later stages (sample, render-masks, export-coco, render-rgb, eval-loc) only read these three files
//! through [`PreparedScene::load`], which applies the manifest's alignment correction (if any) to the
//! mesh and the building table, so every stage sees the LoD model where the reference model puts it.

use serde::{Deserialize, Serialize};

use super::ids::BuildingId;
use super::mesh::SceneMesh;

/// File names inside a scene directory (see [`crate::layout`]).
pub use crate::layout::{BUILDINGS_FILE, GLB_FILE, MANIFEST_FILE};

/// One row of the building table.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct BuildingRecord {
    /// Instance ID (never the background), assigned in order of `source_id`.
    pub id: BuildingId,
    /// Source identity (gml:id, CityJSON key, batch-table gml_id, or `<file>#cc<N>`).
    pub source_id: String,
    /// The source file the building came from (as given in the scene file).
    pub source_file: String,
    /// LoD of the geometry used ("1", "2", "1.2", …).
    pub lod: String,
    /// Height from the lowest to the highest vertex, in metres.
    pub height_m: f64,
    /// `measuredHeight` (or equivalent) from the source when present, in metres.
    #[serde(skip_serializing_if = "Option::is_none", default)]
    pub measured_height_m: Option<f64>,
    /// Area of the footprint (union of the triangles' projections on the ground), in m².
    pub footprint_area_m2: f64,
    /// Footprint centroid, WGS84 degrees.
    pub centroid_lat_deg: f64,
    /// Footprint centroid longitude, WGS84 degrees.
    pub centroid_lon_deg: f64,
    /// Bounds in the area's ENU frame, metres: [min_e, min_n, min_u], [max_e, max_n, max_u].
    pub bbox_min_enu_m: [f64; 3],
    /// Upper bounds in the area's ENU frame, metres.
    pub bbox_max_enu_m: [f64; 3],
    /// Triangles in the scene mesh.
    pub triangles: u64,
}

/// The area's geodetic origin (WGS84, ellipsoidal height).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Origin {
    /// Latitude, degrees.
    pub lat_deg: f64,
    /// Longitude, degrees.
    pub lon_deg: f64,
    /// Ellipsoidal height, metres.
    pub h_m: f64,
}

/// Where a source came from, for provenance and reruns.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SourceEntry {
    /// The source file (or tileset.json) as the scene file gives it.
    pub path: String,
    /// The format it was read as (`citygml`, `cityjson`, `obj`, `tiles3d`, `procedural`).
    pub format: String,
    /// SHA-256 of the file (for a tileset: of tileset.json).
    pub sha256: String,
    /// The CRS chain applied, e.g. "EPSG:6697 (lat, lon, h; orthometric) → EPSG:4979 → EPSG:4978 → ENU".
    pub crs_chain: String,
    /// Buildings read from it.
    pub buildings: u64,
    /// Faces dropped as degenerate (collinear, zero area).
    pub degenerate_faces: u64,
    /// The source's attribution line, if the scene file gives one.
    #[serde(default)]
    pub attribution: Option<String>,
    /// How the source's heights were read when not absolute, e.g. `"above_ground: + TerrainHeight per
    /// building (120 buildings)"` or `"above_ground: + 2.5 m"`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub heights: Option<String>,
    /// Textures and materials the source has (absent when it has none).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub appearance: Option<AppearanceEntry>,
    /// A generated city (`format = "procedural"`): the seed and parameters that define it (there is
    /// no file to hash). Absent for every other source.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub procedural: Option<super::procedural::ProceduralCity>,
}

/// A source's appearances as `prepare` used them.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct AppearanceEntry {
    /// Every theme the file names (CityGML `app:theme`, CityJSON theme keys; unnamed = `""`).
    pub themes: Vec<String>,
    /// The theme textures / materials were taken from (the scene file's `theme`, else the first).
    pub texture_theme: Option<String>,
    /// The theme flat colours were taken from.
    pub material_theme: Option<String>,
    /// Faces of the read buildings with a texture / a colour in the chosen themes.
    pub textured_faces: u64,
    /// Faces with a flat colour in the chosen theme.
    pub coloured_faces: u64,
    /// Distinct images the textured faces of the read buildings use.
    pub images: u64,
    /// Of those, missing or unreadable: their faces keep the procedural look.
    pub missing_images: u64,
    /// The first few missing images, with why.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub missing_examples: Vec<String>,
    /// Appearance targets that fit no read face (unknown polygon, coordinate count mismatch).
    pub unusable_targets: u64,
}

/// The geoid used to turn orthometric heights into ellipsoidal ones.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct GeoidUsed {
    /// "none" (heights already ellipsoidal), "egm96" (the EGM96 15' grid), "grid" (another `.gtx` or
    /// GeoTIFF grid given as `[geoid] grid`), "constant", or "proj" (PROJ converted the compound CRS's
    /// heights itself, with the grid in `proj_grids`).
    pub model: String,
    /// The grid file read: the one insgen interpolated, or for "proj" the first grid PROJ opened.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub grid: Option<String>,
    /// Undulation at the origin (the constant for "constant"; h − H as PROJ converts the origin for
    /// "proj"), metres.
    pub undulation_at_origin_m: f64,
    /// "proj": PROJ's description of the coordinate operation it used (at the first vertex).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub proj_operation: Option<String>,
    /// "proj": every grid file that operation opened (the geoid, and any horizontal grid).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub proj_grids: Vec<String>,
    /// `[geoid] model = "proj"` that fell back: the grids PROJ would have used but could not find
    /// (PROJ's database names, e.g. `jp_gsi_gsigeo2011.tif`).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub missing_grids: Vec<String>,
}

/// `manifest.json` of a prepared scene.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Manifest {
    /// Version of insgen that prepared the scene.
    pub insgen_version: String,
    /// The area's name.
    pub area: String,
    /// "train", "val" or "test": the geographic split this area belongs to.
    pub split: String,
    /// The area's geodetic origin (the ENU frame's).
    pub origin: Origin,
    /// ECEF-from-ENU transform (metres); rows in the file.
    #[serde(with = "crate::util::row_major")]
    pub ecef_from_enu: glam::DMat4,
    /// The area polygon in ENU metres (counter-clockwise, open ring).
    pub area_polygon_enu_m: Vec<[f64; 2]>,
    /// Estimated ground level of the area in ENU metres (see `scene::prepare` for how).
    pub ground_enu_m: f64,
    /// The geoid used.
    pub geoid: GeoidUsed,
    /// The sources read.
    pub sources: Vec<SourceEntry>,
    /// Building instances.
    pub buildings: u64,
    /// Triangles in the scene mesh.
    pub triangles: u64,
    /// Faces dropped as degenerate, over all sources.
    pub degenerate_faces: u64,
    /// Attribution lines to carry into datasets (e.g. PLATEAU's CC BY 4.0 notice).
    pub attributions: Vec<String>,
    /// The clutter layers written beside the buildings in `scene.glb` (nodes `insgen_clutter_<layer>`),
    /// absent when `prepare` ran with `--no-clutter`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub clutter: Option<super::clutter::ClutterSummary>,
    /// The rigid correction of the LoD model, when one was estimated (`insgen align`) or pinned in the
    /// scene file (`[alignment]`); [`PreparedScene::load`] applies it (see [`super::correction`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub alignment: Option<super::correction::AlignmentRecord>,
}

/// A loaded scene: manifest, building table and mesh.
#[derive(Debug, Clone)]
pub struct PreparedScene {
    /// `manifest.json`.
    pub manifest: Manifest,
    /// `buildings.json`, ordered by ID.
    pub buildings: Vec<BuildingRecord>,
    /// The instanced building mesh (ENU metres, one building ID per vertex).
    pub mesh: SceneMesh,
    /// Clutter layers (empty when the scene has none); never part of `mesh`.
    pub clutter: super::clutter::Clutter,
}

impl PreparedScene {
    /// Loads a prepared scene directory (`<workdir>/<area>/scene`).
    ///
    /// # Errors
    /// [`super::SceneError::Artifact`] naming the file that is missing or inconsistent,
    /// [`super::SceneError::ArtifactJson`] / [`super::SceneError::ArtifactGlb`] for a file that does not
    /// parse (the parser's error as the source), each with a hint to run `insgen prepare`; an
    /// alignment record with a non-finite number.
    pub fn load(dir: &std::path::Path) -> Result<PreparedScene, super::SceneError> {
        let mut scene = PreparedScene::load_as_prepared(dir)?;
        if let Some(rec) = &scene.manifest.alignment {
            let c = rec.correction;
            c.validate()
                .map_err(|source| super::SceneError::Correction { path: dir.join(MANIFEST_FILE), source })?;
            if !c.is_identity() {
                let o = scene.manifest.origin;
                let enu = crate::geo::EnuFrame::new(crate::geo::Geodetic::new(o.lat_deg, o.lon_deg, o.h_m));
                c.apply_to_mesh(&mut scene.mesh);
                c.apply_to_buildings(&scene.mesh, &mut scene.buildings, &enu);
                // The clutter was laid out from the LoD footprints: it moves with them.
                for (_, layer) in &mut scene.clutter.layers {
                    c.apply_to_points(&mut layer.positions_m);
                }
            }
        }
        Ok(scene)
    }

    /// As [`PreparedScene::load`] but without applying the alignment correction: the LoD model as
    /// `prepare` wrote it (what `insgen align` measures).
    ///
    /// # Errors
    /// As [`PreparedScene::load`].
    pub fn load_as_prepared(dir: &std::path::Path) -> Result<PreparedScene, super::SceneError> {
        use super::{ArtifactProblem, SceneError};
        let manifest_path = dir.join(MANIFEST_FILE);
        if !manifest_path.is_file() {
            return Err(SceneError::Artifact { path: manifest_path, problem: ArtifactProblem::NotPrepared });
        }
        let read_json =
            |name: &str| -> Result<Vec<u8>, SceneError> { Ok(crate::util::read_file(&dir.join(name))?) };
        let json_err = |name: &str, what| {
            let path = dir.join(name);
            move |source| SceneError::ArtifactJson { path, what, source }
        };
        let manifest: Manifest = serde_json::from_slice(&read_json(MANIFEST_FILE)?)
            .map_err(json_err(MANIFEST_FILE, "manifest"))?;
        let buildings: Vec<BuildingRecord> = serde_json::from_slice(&read_json(BUILDINGS_FILE)?)
            .map_err(json_err(BUILDINGS_FILE, "building table"))?;
        let glb_path = dir.join(GLB_FILE);
        let mesh = super::glb::read_glb(&glb_path).map_err(|source| SceneError::ArtifactGlb { source })?;
        if buildings.len() as u64 != manifest.buildings || mesh.triangle_count() as u64 != manifest.triangles
        {
            return Err(SceneError::Artifact {
                path: dir.to_path_buf(),
                problem: ArtifactProblem::Inconsistent {
                    manifest_buildings: manifest.buildings,
                    manifest_triangles: manifest.triangles,
                    buildings: buildings.len() as u64,
                    triangles: mesh.triangle_count() as u64,
                },
            });
        }
        let clutter = match &manifest.clutter {
            Some(_) => {
                super::glb::read_layers(&glb_path).map_err(|source| SceneError::ArtifactGlb { source })?
            }
            None => super::clutter::Clutter::default(),
        };
        Ok(PreparedScene { manifest, buildings, mesh, clutter })
    }

    /// The LoD model's ENU-from-glTF transform for the scene GLB as written by `prepare` (glTF y-up
    /// turned z-up, then the alignment correction if any), in glam's column-major form.
    pub fn enu_from_scene_gltf(manifest: &Manifest) -> glam::DMat4 {
        let y_up_to_z_up = crate::lod::tiles3d::UpAxis::Y.to_z_up();
        let m =
            manifest.alignment.as_ref().map(|r| r.correction.enu_from_lod()).unwrap_or(glam::DMat4::IDENTITY);
        m * y_up_to_z_up
    }
}
