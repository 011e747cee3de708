//! Errors of the scene stage.

use std::path::PathBuf;

/// Errors of the scene stage.
#[derive(Debug, thiserror::Error)]
pub enum SceneError {
    /// A file could not be read or written.
    #[error(transparent)]
    File(#[from] crate::util::FileError),
    /// A source could not be read.
    #[error(transparent)]
    Lod(#[from] crate::lod::LodError),
    /// The scene file breaks a rule (name mismatch, no sources, bad geoid settings, an invalid area).
    #[error("{}: {problem}", path.display())]
    Config {
        /// The scene file.
        path: PathBuf,
        /// The rule broken.
        problem: ConfigProblem,
    },
    /// A `[sources.procedural]` table (or its `origin`) does not parse into the generator's parameters.
    #[error("{}: [sources.procedural]{}", path.display(), if *origin { " origin" } else { "" })]
    ProceduralToml {
        /// The scene file.
        path: PathBuf,
        /// Whether the `origin` key is the one at fault.
        origin: bool,
        /// Boxed: TOML's error is large, and errors travel by value.
        #[source]
        source: Box<toml::de::Error>,
    },
    /// A `[[sources]] path` names nothing to read: a missing path, a folder without readable files, a
    /// glob that matches no file.
    #[error("{}: sources[{index}].path", scene.display())]
    Sources {
        /// The scene file.
        scene: PathBuf,
        /// The source's index in `[[sources]]`.
        index: usize,
        /// What the path names (or does not).
        #[source]
        source: super::sources::SourcesError,
    },
    /// The scene file is not TOML, or has unknown keys, missing keys or wrong types.
    #[error("{}: invalid scene file", path.display())]
    ConfigToml {
        /// The scene file.
        path: PathBuf,
        /// Boxed: TOML's error is large, and errors travel by value.
        #[source]
        source: Box<toml::de::Error>,
    },
    /// A source could not be geo-referenced.
    #[error("{}: {problem}", path.display())]
    Georef {
        /// The source file (the scene file for the geoid).
        path: PathBuf,
        /// What could not be done (boxed: errors travel by value).
        problem: Box<GeorefProblem>,
        /// The geo stage's error, when it is the cause.
        #[source]
        source: Option<crate::geo::GeoError>,
    },
    /// The area has no buildings, or otherwise cannot be instanced.
    #[error("area {area}: {problem}")]
    Area {
        /// The area's name.
        area: String,
        /// Why it cannot be instanced.
        problem: AreaProblem,
    },
    /// The area's buildings cannot all get a 24-bit ID.
    #[error("area {area}")]
    Ids {
        /// The area's name.
        area: String,
        /// The ID error.
        #[source]
        source: crate::scene::IdError,
    },
    /// The alignment record of a prepared scene's manifest (`path`) is unusable.
    #[error("{}", path.display())]
    Correction {
        /// The manifest.
        path: PathBuf,
        /// What is wrong with the record.
        #[source]
        source: CorrectionError,
    },
    /// A prepared scene on disk is missing or inconsistent.
    #[error("{}: {problem}; run `insgen prepare --area <name>` {}", path.display(), problem.when())]
    Artifact {
        /// The file (or folder) of the prepared scene.
        path: PathBuf,
        /// What is missing or inconsistent.
        problem: ArtifactProblem,
    },
    /// A JSON file of a prepared scene (`what`: manifest, building table) does not parse.
    #[error("{}: not a valid {what}; run `insgen prepare --area <name>` again", path.display())]
    ArtifactJson {
        /// The JSON file.
        path: PathBuf,
        /// What the file is (manifest, building table).
        what: &'static str,
        /// The JSON parser's error.
        #[source]
        source: serde_json::Error,
    },
    /// The prepared scene's mesh (`scene.glb`) cannot be read; the source names the file.
    #[error("the prepared scene's mesh cannot be read; run `insgen prepare --area <name>` again")]
    ArtifactGlb {
        /// The GLB reader's error (it names the file).
        #[source]
        source: super::glb::GlbError,
    },
}

/// A rule of the scene file that it breaks: the text after the file name of a [`SceneError::Config`].
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ConfigProblem {
    /// `name` differs from the file name.
    #[error("name = {name:?} does not match the file name {stem:?}")]
    NameMismatch {
        /// `name` as written.
        name: String,
        /// The file name without `.toml`.
        stem: String,
    },
    /// The file lists no source.
    #[error("no [[sources]]: an area needs at least one source of building models")]
    NoSources,
    /// An `[alignment]` number is not finite.
    #[error("[alignment]: {0}")]
    Alignment(CorrectionError),
    /// An `[alignment]` too large to be a residual correction.
    #[error(
        "[alignment]: shift ({east_m}, {north_m}, {up_m}) m / yaw {yaw_deg}° is not a residual correction \
         (limits: 1000 m, 180°)"
    )]
    AlignmentTooLarge {
        /// Shift east, metres.
        east_m: f64,
        /// Shift north, metres.
        north_m: f64,
        /// Shift up, metres.
        up_m: f64,
        /// Rotation about the vertical, degrees.
        yaw_deg: f64,
    },
    /// A non-procedural source without `path`.
    #[error("sources[{index}] has no `path`")]
    NoPath {
        /// The source's index in `[[sources]]`.
        index: usize,
    },
    /// An unknown `format`.
    #[error(
        "sources[{index}].format = {format:?}: expected one of citygml, cityjson, obj, 3dtiles, procedural"
    )]
    Format {
        /// The source's index in `[[sources]]`.
        index: usize,
        /// `format` as written.
        format: String,
    },
    /// `ground_attribute` / `ground_height_m` without `heights = "above_ground"`.
    #[error("sources[{index}]: ground_attribute / ground_height_m need heights = \"above_ground\"")]
    GroundWithoutAboveGround {
        /// The source's index in `[[sources]]`.
        index: usize,
    },
    /// Both `ground_attribute` and `ground_height_m`.
    #[error("sources[{index}]: give ground_attribute or ground_height_m, not both")]
    GroundTwice {
        /// The source's index in `[[sources]]`.
        index: usize,
    },
    /// A `ground_height_m` that is not a height (non-finite, beyond ±10 km).
    #[error("sources[{index}].ground_height_m = {value_m}: must be a height in metres")]
    GroundHeight {
        /// The source's index in `[[sources]]`.
        index: usize,
        /// The value, metres.
        value_m: f64,
    },
    /// A negative or non-finite `weld_tolerance_m`.
    #[error("sources[{index}].weld_tolerance_m = {value_m}: must be a non-negative number")]
    WeldTolerance {
        /// The source's index in `[[sources]]`.
        index: usize,
        /// The value, metres.
        value_m: f64,
    },
    /// `[geoid] model = "constant"` without `undulation_m`.
    #[error("[geoid] model = \"constant\" needs `undulation_m`")]
    NoUndulation,
    /// An undulation no geoid has.
    #[error("[geoid] undulation_m = {value_m}: geoid undulations lie within ±110 m")]
    Undulation {
        /// The value, metres.
        value_m: f64,
    },
    /// An `[origin]` outside ±90° latitude or ±180° longitude.
    #[error("[origin] lat_deg/lon_deg out of range: {lat_deg}, {lon_deg}")]
    Origin {
        /// Latitude, degrees.
        lat_deg: f64,
        /// Longitude, degrees.
        lon_deg: f64,
    },
    /// `[area]` with both `bbox_deg` and `polygon_deg`.
    #[error("[area] give either bbox_deg or polygon_deg, not both")]
    AreaTwice,
    /// `[area]` with neither `bbox_deg` nor `polygon_deg`.
    #[error("[area] needs bbox_deg or polygon_deg")]
    AreaEmpty,
    /// A `bbox_deg` that is not `[lon_min, lat_min, lon_max, lat_max]`.
    #[error("[area] bbox_deg = {bbox_deg:?}: expected [lon_min, lat_min, lon_max, lat_max]")]
    Bbox {
        /// The box as written, degrees.
        bbox_deg: [f64; 4],
    },
    /// A `polygon_deg` of fewer than 3 points.
    #[error("[area] polygon_deg needs at least 3 points")]
    PolygonPoints,
    /// No scene file `<area>.toml` (the path is the one looked for).
    #[error(
        "no such area{}",
        if available.is_empty() {
            format!(", and {} holds no scene files (--scenes DIR)", scenes_dir.display())
        } else {
            format!(" {area:?}; available: {}", available.join(", "))
        }
    )]
    NoSuchArea {
        /// The area asked for.
        area: String,
        /// The folder of scene files.
        scenes_dir: PathBuf,
        /// The areas it holds, sorted.
        available: Vec<String>,
    },
    /// A source file that does not exist.
    #[error("source {} does not exist", file.display())]
    SourceMissing {
        /// The source's path, resolved.
        file: PathBuf,
    },
}

/// Why a source cannot be geo-referenced: the text after the file name of a [`SceneError::Georef`].
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum GeorefProblem {
    /// Orthometric heights and no EGM96 grid installed.
    #[error(
        "orthometric source heights need a geoid, but the EGM96 grid (egm96_15.gtx, Debian package proj-data) \
         was not found: run scripts/setup.sh, or set [geoid] model = \"constant\" with undulation_m"
    )]
    NoEgm96,
    /// The geoid grid cannot be loaded (the cause says why).
    #[error("loading the geoid grid")]
    GeoidGrid,
    /// The source's CRS cannot be used (the cause says why).
    #[error("CRS {name:?}")]
    Crs {
        /// The CRS as named.
        name: String,
    },
    /// The source declares no CRS and the scene file sets none.
    #[error("the file declares no CRS; set `crs = \"EPSG:NNNN\"` for this source in {}", scene_file.display())]
    NoCrs {
        /// The scene file.
        scene_file: PathBuf,
    },
    /// A building's coordinate cannot be converted (the cause says why).
    #[error("building {building}")]
    Building {
        /// The building's source id.
        building: String,
    },
    /// An ECEF building coordinate is NaN or infinite.
    #[error("building {building}: non-finite coordinate {coordinate:?}")]
    NonFinite {
        /// The building's source id.
        building: String,
        /// The coordinate, ECEF metres.
        coordinate: [f64; 3],
    },
    /// `heights = "above_ground"` on an ECEF source.
    #[error("heights = \"above_ground\" does not apply to an ECEF (3D Tiles) source")]
    AboveGroundEcef,
}

/// Why an area cannot be instanced: the text after the area of a [`SceneError::Area`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum AreaProblem {
    /// No source yields a building.
    #[error("no building with usable geometry in any source")]
    NoBuildings,
    /// Every building lies outside the `[area]` polygon.
    #[error("no building lies inside the [area] polygon")]
    OutsideArea,
}

/// What is wrong with a prepared scene on disk: the text after the path of a [`SceneError::Artifact`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum ArtifactProblem {
    /// The folder holds no `manifest.json`.
    #[error("no prepared scene here")]
    NotPrepared,
    /// The files disagree on the counts.
    #[error(
        "inconsistent scene: manifest says {manifest_buildings} buildings / {manifest_triangles} triangles, \
         files hold {buildings} / {triangles}"
    )]
    Inconsistent {
        /// Buildings the manifest lists.
        manifest_buildings: u64,
        /// Triangles the manifest lists.
        manifest_triangles: u64,
        /// Rows of the building table.
        buildings: u64,
        /// Triangles of the mesh.
        triangles: u64,
    },
}

impl ArtifactProblem {
    /// "first" (nothing prepared yet) or "again".
    fn when(&self) -> &'static str {
        match self {
            ArtifactProblem::NotPrepared => "first",
            ArtifactProblem::Inconsistent { .. } => "again",
        }
    }
}

/// An alignment correction that cannot be applied (see [`crate::scene::correction::Correction::validate`]).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CorrectionError {
    /// A number of the correction is NaN or infinite.
    #[error("alignment {field} = {value} is not a finite number")]
    NotFinite {
        /// The field ("east_m", "yaw_deg", "pivot_enu_m[0]", …).
        field: &'static str,
        /// Its value.
        value: f64,
    },
}

/// Why synthetic photogrammetry could not be made from the buildings (see
/// [`crate::scene::photogrammetry::perturb`]).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PerturbError {
    /// The ground and clutter pieces need building IDs beyond the 24-bit ID space.
    #[error(
        "clutter needs more building IDs: ID {id} does not fit the 24-bit ID space (max {})",
        crate::scene::MAX_BUILDING_ID
    )]
    IdSpace {
        /// The first ID that does not fit.
        id: u32,
    },
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The texts are the ones the scene stage wrote before its problems were typed.
    #[test]
    fn problem_texts() {
        let cases: Vec<(String, &str)> = vec![
            (
                SceneError::Config {
                    path: "scenes/x.toml".into(),
                    problem: ConfigProblem::NameMismatch { name: "y".into(), stem: "x".into() },
                }
                .to_string(),
                "scenes/x.toml: name = \"y\" does not match the file name \"x\"",
            ),
            (
                ConfigProblem::GroundWithoutAboveGround { index: 0 }.to_string(),
                "sources[0]: ground_attribute / ground_height_m need heights = \"above_ground\"",
            ),
            (
                ConfigProblem::NoSuchArea {
                    area: "z".into(),
                    scenes_dir: "scenes".into(),
                    available: vec!["x".into(), "y".into()],
                }
                .to_string(),
                "no such area \"z\"; available: x, y",
            ),
            (
                ConfigProblem::NoSuchArea { area: "z".into(), scenes_dir: "s".into(), available: vec![] }.to_string(),
                "no such area, and s holds no scene files (--scenes DIR)",
            ),
            (
                ConfigProblem::Alignment(CorrectionError::NotFinite { field: "east_m", value: f64::NAN }).to_string(),
                "[alignment]: alignment east_m = NaN is not a finite number",
            ),
            (
                ConfigProblem::AlignmentTooLarge { east_m: 2000.0, north_m: 0.0, up_m: 0.0, yaw_deg: 5.0 }.to_string(),
                "[alignment]: shift (2000, 0, 0) m / yaw 5° is not a residual correction (limits: 1000 m, 180°)",
            ),
            (
                SceneError::Georef {
                    path: "a.json".into(),
                    problem: Box::new(GeorefProblem::NoCrs { scene_file: "scenes/a.toml".into() }),
                    source: None,
                }
                .to_string(),
                "a.json: the file declares no CRS; set `crs = \"EPSG:NNNN\"` for this source in scenes/a.toml",
            ),
            (
                SceneError::Area { area: "a".into(), problem: AreaProblem::OutsideArea }.to_string(),
                "area a: no building lies inside the [area] polygon",
            ),
            (
                SceneError::Artifact { path: "w/a/scene/manifest.json".into(), problem: ArtifactProblem::NotPrepared }
                    .to_string(),
                "w/a/scene/manifest.json: no prepared scene here; run `insgen prepare --area <name>` first",
            ),
            (
                SceneError::Artifact {
                    path: "w/a/scene".into(),
                    problem: ArtifactProblem::Inconsistent {
                        manifest_buildings: 3,
                        manifest_triangles: 10,
                        buildings: 2,
                        triangles: 10,
                    },
                }
                .to_string(),
                "w/a/scene: inconsistent scene: manifest says 3 buildings / 10 triangles, files hold 2 / 10; run \
                 `insgen prepare --area <name>` again",
            ),
        ];
        for (got, want) in cases {
            assert_eq!(got, want);
        }
    }
}
