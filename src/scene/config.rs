//! Area definitions: `scenes/<area>.toml` (schema: `schemas/scene.schema.json`).
//!
//! ```toml
//! name = "tokyo"                 # must match the file stem
//! split = "test"                 # train | val | test: the geographic split of this area
//! description = "Shibuya, PLATEAU 3D Tiles"
//! attribution = "3D city model (Project PLATEAU), MLIT — CC BY 4.0"
//!
//! [[sources]]
//! path = "../../shared/data/jp_tokyo_shibuya_plateau_3dtiles/tileset.json"  # relative to this file
//! # path = "plateau/udx/bldg/*.gml"  # or a glob, or a folder (see scene::sources)
//! format = "3dtiles"             # optional: citygml | cityjson | obj | 3dtiles | procedural
//! crs = "EPSG:6697"              # optional override; required when the file declares none
//! lod = "2"                      # optional LoD choice
//! weld_tolerance_m = 0.01        # optional, ID-less meshes only
//! heights = "above_ground"       # optional: absolute (default) | above_ground
//! ground_attribute = "TerrainHeight"  # with above_ground: the ground-height attribute (or ground_height_m = 2.5)
//!
//! [geoid]                        # orthometric → ellipsoidal heights, for sources with orthometric heights
//! model = "egm96"                # egm96 (default) | proj | constant | none
//! undulation_m = 36.7            # with model = "constant"
//! grid = "geoid/gsigeo2011.tif"  # optional: a .gtx or GeoTIFF grid instead of EGM96 (proj: its fallback)
//!
//! [origin]                       # optional; default: centre of the buildings, at the lowest ground
//! lat_deg = 35.658
//! lon_deg = 139.7016
//! h_m = 40.0                     # ellipsoidal
//!
//! [area]                         # optional; default: bounding box of all buildings
//! bbox_deg = [139.695, 35.653, 139.709, 35.663]   # lon_min, lat_min, lon_max, lat_max
//! # polygon_deg = [[lon, lat], ...]
//!
//! [sampling]                     # camera sampling parameters, read by `insgen sample`
//!
//! [alignment]                    # optional: pin a rigid correction of the LoD model (see scene::correction)
//! east_m = 0.4
//! north_m = -1.2
//! up_m = 0.3
//! yaw_deg = 0.15
//! pivot_enu_m = [120.0, -35.0]   # optional, default [0, 0] (the area origin)
//! ```

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use super::error::ConfigProblem;
use super::SceneError;

/// One area definition.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SceneConfig {
    /// The area's name (must match the scene file's name).
    pub name: String,
    /// The geographic split the area belongs to.
    #[serde(default = "default_split")]
    pub split: Split,
    /// Free text describing the area.
    #[serde(default)]
    pub description: Option<String>,
    /// Attribution carried into datasets (e.g. PLATEAU requires CC BY 4.0 attribution).
    #[serde(default)]
    pub attribution: Option<String>,
    /// The sources of building models (at least one).
    pub sources: Vec<SourceConfig>,
    /// How orthometric heights become ellipsoidal (`[geoid]`).
    #[serde(default)]
    pub geoid: GeoidConfig,
    /// An explicit area origin (default: the centre of the buildings).
    #[serde(default)]
    pub origin: Option<OriginConfig>,
    /// The area's extent (default: the bounding box of the buildings).
    #[serde(default)]
    pub area: Option<AreaConfig>,
    /// Camera sampling parameters; parsed by the camera stage.
    #[serde(default)]
    pub sampling: Option<toml::Table>,
    /// A rigid correction of the LoD model pinned by hand (`[alignment]`: `east_m`, `north_m`, `up_m`,
    /// `yaw_deg`, optional `pivot_enu_m`, default the area origin); `prepare` records it in the
    /// manifest and every later stage applies it (see [`super::correction`]).
    #[serde(default)]
    pub alignment: Option<super::correction::Correction>,
}

/// The geographic split an area belongs to.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Split {
    /// Training data.
    Train,
    /// Validation data.
    Val,
    /// Test data.
    Test,
}

impl Split {
    /// The split's name in files (`train`, `val`, `test`).
    pub fn as_str(self) -> &'static str {
        match self {
            Split::Train => "train",
            Split::Val => "val",
            Split::Test => "test",
        }
    }
}

fn default_split() -> Split {
    Split::Train
}

/// One source of building models.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SourceConfig {
    /// Path of the file (or tileset.json), a folder or a glob (`udx/bldg/*.gml`; see
    /// [`super::sources`]), relative to the scene file's directory. Not used by `format = "procedural"`.
    #[serde(default)]
    pub path: Option<PathBuf>,
    /// `citygml`, `cityjson`, `obj`, `3dtiles` or `procedural` (default: from the file name).
    #[serde(default)]
    pub format: Option<String>,
    /// The source's CRS (`EPSG:NNNN`, URN or URL), overriding the one the file declares.
    #[serde(default)]
    pub crs: Option<String>,
    /// The LoD to read (`"2"`, `"1"`, …; default: the highest the file has).
    #[serde(default)]
    pub lod: Option<String>,
    /// Vertices closer than this are welded when reading, metres.
    #[serde(default)]
    pub weld_tolerance_m: Option<f64>,
    /// Parameters of the procedural generator (`format = "procedural"`).
    #[serde(default)]
    pub procedural: Option<toml::Table>,
    /// What the source's heights are measured from: `absolute` (default: the CRS's vertical datum)
    /// or `above_ground` (geometry starts at z ≈ 0; the ground height is added back per building).
    #[serde(default)]
    pub heights: Option<Heights>,
    /// With `heights = "above_ground"`: the building attribute holding the ground height in metres
    /// (e.g. `"TerrainHeight"`, `"h_maaiveld"`); default: the ground attribute each building carries.
    #[serde(default)]
    pub ground_attribute: Option<String>,
    /// With `heights = "above_ground"`: one ground height for every building, in metres (instead of
    /// an attribute).
    #[serde(default)]
    pub ground_height_m: Option<f64>,
    /// Appearance theme for textures and materials (CityGML `app:theme`, CityJSON theme name);
    /// default: the first theme the file names. Recorded in the manifest.
    #[serde(default)]
    pub theme: Option<String>,
    /// `false` ignores the source's textures and materials (default `true`).
    #[serde(default)]
    pub appearance: Option<bool>,
    /// `false` ignores the source's materials (flat colours: X3DMaterial, CityJSON `materials`) but
    /// keeps its textures (default `true`). Some models colour faces by their class only (red roofs,
    /// white walls); the procedural look is then closer to a photograph.
    #[serde(default)]
    pub materials: Option<bool>,
}

impl SourceConfig {
    /// The reader `format` names (`None`: from each file's name, or procedural).
    pub fn format(&self) -> Option<crate::lod::Format> {
        use crate::lod::Format;
        match self.format.as_deref() {
            Some("citygml") => Some(Format::CityGml),
            Some("cityjson") => Some(Format::CityJson),
            Some("obj") => Some(Format::Obj),
            Some("3dtiles") => Some(Format::Tiles3d),
            _ => None,
        }
    }
}

/// What a source's heights are measured from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Heights {
    /// Heights in the CRS's vertical datum (or ellipsoidal), as the file says.
    Absolute,
    /// Heights above the local ground; the ground height comes from an attribute or a constant.
    AboveGround,
}

/// Which geoid turns orthometric source heights into ellipsoidal ones.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GeoidConfig {
    /// Which geoid.
    #[serde(default = "default_geoid_model")]
    pub model: GeoidModel,
    /// The undulation of `model = "constant"`, metres.
    #[serde(default)]
    pub undulation_m: Option<f64>,
    /// Path of a vertical grid PROJ can read (`.gtx` or GeoTIFF `.tif`) to use instead of the EGM96
    /// grid found in PROJ's data directory (with `model = "proj"`: the fallback where PROJ has none).
    #[serde(default)]
    pub grid: Option<PathBuf>,
}

impl Default for GeoidConfig {
    fn default() -> Self {
        GeoidConfig { model: GeoidModel::Egm96, undulation_m: None, grid: None }
    }
}

fn default_geoid_model() -> GeoidModel {
    GeoidModel::Egm96
}

/// `[geoid] model`: how orthometric heights become ellipsoidal.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum GeoidModel {
    /// h = H + N with N from EGM96 15' (or from `grid`).
    Egm96,
    /// h = H + `undulation_m`.
    Constant,
    /// h = H (heights are already ellipsoidal).
    None,
    /// PROJ converts compound CRSs (EPSG:6697, EPSG:7415, …) to WGS 84 3D itself, with the national
    /// geoid grid its database names, when that grid is installed in PROJ's search path; otherwise,
    /// and for CRSs without a vertical part, as `egm96` with one warning.
    Proj,
}

/// An explicit area origin (WGS84, ellipsoidal height).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct OriginConfig {
    /// Latitude, degrees (WGS84).
    pub lat_deg: f64,
    /// Longitude, degrees (WGS84).
    pub lon_deg: f64,
    /// Ellipsoidal height, metres (default: the median building base).
    #[serde(default)]
    pub h_m: Option<f64>,
}

/// The area's extent, in WGS84 degrees.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AreaConfig {
    /// [lon_min, lat_min, lon_max, lat_max].
    #[serde(default)]
    pub bbox_deg: Option<[f64; 4]>,
    /// [[lon, lat], ...], open or closed.
    #[serde(default)]
    pub polygon_deg: Option<Vec<[f64; 2]>>,
}

impl SceneConfig {
    /// Reads and checks a scene file.
    ///
    /// # Errors
    /// [`SceneError::File`] when it cannot be read; [`SceneError::ConfigToml`] when it is not TOML or
    /// has unknown keys (TOML's error as the source); [`SceneError::Config`] naming the file: name
    /// mismatch, no sources, a source without path, bad geoid settings, an invalid area.
    pub fn load(path: &Path) -> Result<SceneConfig, SceneError> {
        let text = std::fs::read_to_string(path)
            .map_err(|e| SceneError::File(crate::util::FileError::new("reading", path, e)))?;
        SceneConfig::parse(&text, path)
    }

    /// Parses and checks the text of a scene file that is (or will be) at `path`.
    ///
    /// # Errors
    /// As [`SceneConfig::load`], less the reading.
    pub fn parse(text: &str, path: &Path) -> Result<SceneConfig, SceneError> {
        let cfg: SceneConfig = toml::from_str(text)
            .map_err(|e| SceneError::ConfigToml { path: path.into(), source: Box::new(e) })?;
        cfg.validate(path)?;
        Ok(cfg)
    }

    fn validate(&self, path: &Path) -> Result<(), SceneError> {
        let err = |problem: ConfigProblem| Err(SceneError::Config { path: path.into(), problem });
        if let Some(stem) = path.file_stem().and_then(|s| s.to_str()) {
            if stem != self.name {
                return err(ConfigProblem::NameMismatch { name: self.name.clone(), stem: stem.to_string() });
            }
        }
        if self.sources.is_empty() {
            return err(ConfigProblem::NoSources);
        }
        if let Some(c) = &self.alignment {
            c.validate().or_else(|e| err(ConfigProblem::Alignment(e)))?;
            if c.east_m.abs().max(c.north_m.abs()).max(c.up_m.abs()) > 1000.0 || c.yaw_deg.abs() > 180.0 {
                return err(ConfigProblem::AlignmentTooLarge {
                    east_m: c.east_m,
                    north_m: c.north_m,
                    up_m: c.up_m,
                    yaw_deg: c.yaw_deg,
                });
            }
        }
        for (index, s) in self.sources.iter().enumerate() {
            let procedural = s.format.as_deref() == Some("procedural");
            if !procedural && s.path.is_none() {
                return err(ConfigProblem::NoPath { index });
            }
            if let Some(f) = &s.format {
                if !["citygml", "cityjson", "obj", "3dtiles", "procedural"].contains(&f.as_str()) {
                    return err(ConfigProblem::Format { index, format: f.clone() });
                }
            }
            let above = s.heights == Some(Heights::AboveGround);
            if !above && (s.ground_attribute.is_some() || s.ground_height_m.is_some()) {
                return err(ConfigProblem::GroundWithoutAboveGround { index });
            }
            if s.ground_attribute.is_some() && s.ground_height_m.is_some() {
                return err(ConfigProblem::GroundTwice { index });
            }
            if let Some(g) = s.ground_height_m {
                if !(g.is_finite() && g.abs() <= 1e4) {
                    return err(ConfigProblem::GroundHeight { index, value_m: g });
                }
            }
            if let Some(t) = s.weld_tolerance_m {
                if !(t.is_finite() && t >= 0.0) {
                    return err(ConfigProblem::WeldTolerance { index, value_m: t });
                }
            }
        }
        match (self.geoid.model, self.geoid.undulation_m) {
            (GeoidModel::Constant, None) => return err(ConfigProblem::NoUndulation),
            (GeoidModel::Constant, Some(n)) if !n.is_finite() || n.abs() > 200.0 => {
                return err(ConfigProblem::Undulation { value_m: n });
            }
            _ => {}
        }
        if let Some(o) = &self.origin {
            if !(o.lat_deg.abs() <= 90.0 && o.lon_deg.abs() <= 180.0) {
                return err(ConfigProblem::Origin { lat_deg: o.lat_deg, lon_deg: o.lon_deg });
            }
        }
        if let Some(a) = &self.area {
            match (&a.bbox_deg, &a.polygon_deg) {
                (Some(_), Some(_)) => return err(ConfigProblem::AreaTwice),
                (Some(b), None) => {
                    if !(b[0] < b[2] && b[1] < b[3]) || b.iter().any(|v| !v.is_finite()) {
                        return err(ConfigProblem::Bbox { bbox_deg: *b });
                    }
                }
                (None, Some(p)) => {
                    if p.len() < 3 {
                        return err(ConfigProblem::PolygonPoints);
                    }
                }
                (None, None) => return err(ConfigProblem::AreaEmpty),
            }
        }
        Ok(())
    }

    /// The files of `sources[index]` (one, or those its folder or glob names; see [`super::sources`]),
    /// resolved against the scene file's directory, in their sorted order. Empty for a procedural
    /// source.
    ///
    /// # Errors
    /// [`SceneError::Sources`] naming the scene file, the source and the path or pattern when it names
    /// nothing to read.
    pub fn source_files(&self, scene_file: &Path, index: usize) -> Result<Vec<PathBuf>, SceneError> {
        let src = &self.sources[index];
        let Some(path) = &src.path else { return Ok(Vec::new()) };
        let base = scene_file.parent().unwrap_or(Path::new("."));
        super::sources::expand(base, path, src.format()).map_err(|source| SceneError::Sources {
            scene: scene_file.into(),
            index,
            source,
        })
    }

    /// The absolute path of a source, resolved against the scene file's directory.
    pub fn resolve(&self, scene_file: &Path, source: &SourceConfig) -> Option<PathBuf> {
        let p = source.path.as_ref()?;
        if p.is_absolute() {
            Some(p.clone())
        } else {
            Some(scene_file.parent().unwrap_or(Path::new(".")).join(p))
        }
    }
}

/// Finds `<scenes>/<area>.toml`, or explains which areas exist.
///
/// # Errors
/// [`SceneError::Config`] listing the available areas when the file does not exist.
pub fn find_scene(scenes_dir: &Path, area: &str) -> Result<PathBuf, SceneError> {
    let path = scenes_dir.join(format!("{area}.toml"));
    if path.is_file() {
        return Ok(path);
    }
    let mut names: Vec<String> = std::fs::read_dir(scenes_dir)
        .into_iter()
        .flatten()
        .flatten()
        .filter_map(|e| {
            let p = e.path();
            (p.extension()? == "toml").then(|| p.file_stem()?.to_str().map(str::to_string))?
        })
        .collect();
    names.sort();
    Err(SceneError::Config {
        path,
        problem: ConfigProblem::NoSuchArea {
            area: area.to_string(),
            scenes_dir: scenes_dir.to_path_buf(),
            available: names,
        },
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(text: &str) -> Result<SceneConfig, SceneError> {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("x.toml");
        std::fs::write(&p, text).unwrap();
        SceneConfig::load(&p)
    }

    #[test]
    fn minimal_scene() {
        let c = parse("name = \"x\"\n[[sources]]\npath = \"a.gml\"\n").unwrap();
        assert_eq!(c.split, Split::Train);
        assert_eq!(c.geoid.model, GeoidModel::Egm96);
    }

    #[test]
    fn errors_name_the_problem() {
        let e = parse("name = \"y\"\n[[sources]]\npath = \"a.gml\"\n").unwrap_err().to_string();
        assert!(e.contains("does not match the file name"), "{e}");
        let e = parse("name = \"x\"\nsources = []\n").unwrap_err().to_string();
        assert!(e.contains("no [[sources]]"), "{e}");
        let e = parse("name = \"x\"\n[[sources]]\npath = \"a\"\n[geoid]\nmodel = \"constant\"\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("undulation_m"), "{e}");
        let e = parse("name = \"x\"\n[[sources]]\npath = \"a\"\nfromat = \"x\"\n").unwrap_err();
        assert!(matches!(e, SceneError::ConfigToml { .. }), "{e:?}");
        let e = crate::util::error_chain(&e);
        assert!(e.contains("x.toml: invalid scene file: TOML parse error") && e.contains("fromat"), "{e}");
        let e = parse("name = \"x\"\n[[sources]]\npath = \"a\"\n[area]\nbbox_deg = [1, 1, 0, 0]\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("bbox_deg"), "{e}");
    }

    #[test]
    fn geoid_models_parse() {
        for (m, want) in
            [("egm96", GeoidModel::Egm96), ("proj", GeoidModel::Proj), ("none", GeoidModel::None)]
        {
            let c = parse(&format!("name = \"x\"\n[[sources]]\npath = \"a\"\n[geoid]\nmodel = \"{m}\"\n"))
                .unwrap();
            assert_eq!(c.geoid.model, want);
        }
        let c =
            parse("name = \"x\"\n[[sources]]\npath = \"a\"\n[geoid]\nmodel = \"proj\"\ngrid = \"g.tif\"\n")
                .unwrap();
        assert_eq!(c.geoid.grid.as_deref(), Some(Path::new("g.tif")));
        let e = parse("name = \"x\"\n[[sources]]\npath = \"a\"\n[geoid]\nmodel = \"gsigeo\"\n").unwrap_err();
        assert!(crate::util::error_chain(&e).contains("proj"), "{}", crate::util::error_chain(&e));
    }

    #[test]
    fn unknown_area_lists_available() {
        let dir = tempfile::tempdir().unwrap();
        std::fs::write(dir.path().join("demo.toml"), "").unwrap();
        std::fs::write(dir.path().join("tokyo.toml"), "").unwrap();
        let e = find_scene(dir.path(), "tokio").unwrap_err().to_string();
        assert!(e.contains("available: demo, tokyo"), "{e}");
    }
}
