//! `insgen prepare`: read an area's sources, geo-reference them into the area's ENU frame, triangulate,
//! instance every building and write the scene artifact (see [`super::artifact`]).
//!
//! The chain per vertex, all f64: source CRS → WGS84 latitude/longitude (PROJ) → + geoid undulation for
//! orthometric heights → ECEF (EPSG:4978) → ENU at the area origin. 3D Tiles are already ECEF. With
//! `[geoid] model = "proj"`, a compound CRS goes to WGS84 3D through PROJ instead, heights included,
//! when PROJ has a real vertical transformation (its national geoid grid is installed); otherwise the
//! EGM96 chain above, with one warning naming the grid PROJ wanted.
//!
//! Defaults when the scene file is silent:
//! - origin: centre of the buildings' latitude/longitude bounds, at the median building base height;
//! - area: the bounding box of all buildings (no building is dropped);
//! - ground level (`manifest.ground_enu_m`): the median of the buildings' lowest vertices — each LoD
//!   building stands on the terrain, so its base samples the ground; the median ignores buildings on
//!   bridges or in pits.
//!
//! Instancing: buildings are merged by source ID (BuildingParts already carry their parent's ID; a
//! building split across tiles or files is one instance), sorted by source ID, and numbered 1, 2, …
//! so reruns agree; more than 2^24 − 1 buildings is an error.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::Instant;

use crate::geo::{self, AxisConvention, Crs, EnuFrame, Geodetic, Geoid, HeightKind};
use crate::lod::{self, Format, Frame, Geometry, ReadOptions, SourceModel};
use crate::util::{self, Progress};

use super::appearance::{AppearanceTable, VertexAppearance};
use super::artifact::{self, BuildingRecord, GeoidUsed, Manifest, Origin, PreparedScene, SourceEntry};
use super::config::{GeoidModel, Heights, SceneConfig, SourceConfig};
use super::error::{AreaProblem, GeorefProblem};
use super::ids::BuildingId;
use super::mesh::SceneMesh;
use super::procedural::ProceduralCity;
use super::triangulate::{triangulate_polygon, triangulate_polygon_uv};
use super::SceneError;

/// A building after geo-referencing: triangles in ECEF (f64), before the ENU frame is known.
struct EcefBuilding {
    source_id: String,
    source_file: String,
    lod: String,
    measured_height_m: Option<f64>,
    positions_ecef: Vec<[f64; 3]>,
    triangles: Vec<[u32; 3]>,
    /// Texture coordinates and appearance per vertex, when a face of the building has one.
    appearance: Option<VertexAppearance>,
    /// Lowest ellipsoidal height of the building (its base), metres.
    base_h_m: f64,
    lat_range: [f64; 2],
    lon_range: [f64; 2],
}

/// Summary of a `prepare` run.
#[derive(Debug, Clone)]
pub struct PrepareReport {
    /// The prepared scene as written.
    pub scene: PreparedScene,
    /// Directory it was written to.
    pub out_dir: PathBuf,
    /// Wall-clock seconds the run took.
    pub seconds: f64,
}

/// Lazily built geoid (only sources with orthometric heights need it), and what `[geoid] model =
/// "proj"` found.
struct GeoidSlot<'a> {
    cfg: &'a SceneConfig,
    scene_file: &'a Path,
    geoid: Option<Geoid>,
    /// The first source whose heights PROJ converted with a real vertical transformation.
    proj: Option<ProjHeights>,
    /// Grids PROJ wanted for a compound CRS but did not find (model = "proj" fell back).
    missing_grids: Vec<String>,
    /// Whether the one fallback warning has been printed.
    warned: bool,
}

/// A source converted by PROJ heights included (`[geoid] model = "proj"`).
struct ProjHeights {
    tf: geo::CrsTransform,
    axes: AxisConvention,
    choice: geo::VerticalChoice,
}

impl GeoidSlot<'_> {
    fn get(&mut self) -> Result<&Geoid, SceneError> {
        if self.geoid.is_none() {
            let g = match self.cfg.geoid.model {
                GeoidModel::None => Geoid::None,
                GeoidModel::Constant => Geoid::Constant(self.cfg.geoid.undulation_m.unwrap_or(0.0)),
                // "proj" falls back to the same grid as "egm96" where PROJ has no geoid of its own.
                GeoidModel::Egm96 | GeoidModel::Proj => {
                    let path = match &self.cfg.geoid.grid {
                        Some(p) => self.scene_file.parent().unwrap_or(Path::new(".")).join(p),
                        None => Geoid::find_egm96().ok_or_else(|| SceneError::Georef {
                            path: self.scene_file.into(),
                            problem: Box::new(GeorefProblem::NoEgm96),
                            source: None,
                        })?,
                    };
                    Geoid::Grid(geo::geoid::GeoidGrid::load(&path).map_err(|e| SceneError::Georef {
                        path: self.scene_file.into(),
                        problem: Box::new(GeorefProblem::GeoidGrid),
                        source: Some(e),
                    })?)
                }
            };
            self.geoid = Some(g);
        }
        Ok(self.geoid.as_ref().expect("set just above"))
    }

    /// The one warning of a `model = "proj"` scene whose heights PROJ could not convert itself.
    fn warn_fallback(&mut self, crs: &Crs, missing: &[String]) -> Result<(), SceneError> {
        let custom_grid = self.cfg.geoid.grid.is_some();
        let fallback = match self.get()? {
            Geoid::Grid(g) if custom_grid => format!("the grid {}", g.path().display()),
            _ => "EGM96".to_string(),
        };
        for m in missing {
            if !self.missing_grids.contains(m) {
                self.missing_grids.push(m.clone());
            }
        }
        if self.warned {
            return Ok(());
        }
        self.warned = true;
        let why = if crs.vertical_epsg.is_none() {
            format!("{} has no vertical CRS, so PROJ cannot choose a geoid", crs.id())
        } else if missing.is_empty() {
            format!("PROJ knows no geoid grid for {}", crs.id())
        } else {
            format!(
                "PROJ's best operation for {} needs grids that are not installed ({}; install with `projsync \
                 --file {}` or put them in a PROJ_DATA directory)",
                crs.id(),
                missing.join(", "),
                missing[0]
            )
        };
        log::warn!(
            "[geoid] model = \"proj\": {why}; using {fallback} instead — national geoids differ from EGM96 by \
             decimetres to a metre"
        );
        Ok(())
    }
}

/// The first vertex of the first building with one (where PROJ's choice of operation is probed).
fn first_vertex(model: &SourceModel) -> Option<[f64; 3]> {
    model.buildings.iter().find_map(|b| match &b.geometry {
        Geometry::Mesh(m) => m.positions.first().copied(),
        Geometry::Polygons(p) => p.iter().find_map(|poly| poly.exterior.first().copied()),
    })
}

/// Reads one file of a source (`path`), or generates a procedural source (`path` = `None`); returns
/// the model, its format's name for the manifest and, for a generated city, what defines it.
fn read_one(
    scene_file: &Path,
    src: &SourceConfig,
    path: Option<&Path>,
) -> Result<(SourceModel, String, Option<ProceduralCity>), SceneError> {
    let Some(path) = path else {
        let (model, city) = procedural_source(scene_file, src.procedural.clone().unwrap_or_default())?;
        return Ok((model, "procedural".into(), Some(city)));
    };
    let format = src.format();
    let opts = ReadOptions {
        lod: src.lod.clone(),
        weld_tolerance_m: src.weld_tolerance_m,
        theme: src.theme.clone(),
        no_appearance: !src.appearance.unwrap_or(true),
        no_materials: !src.materials.unwrap_or(true),
    };
    let model = lod::read_source(path, format, &opts)?;
    let fmt = format
        .or_else(|| Format::from_path(path))
        .map(|f| format!("{f:?}").to_lowercase())
        .unwrap_or_default();
    Ok((model, fmt, None))
}

/// Generates the procedural city of a `format = "procedural"` source: the `[sources.procedural]` table
/// holds any [`ProceduralSpec`](super::procedural::ProceduralSpec) fields plus an optional
/// `origin = { easting_m, northing_m }` in the generator's CRS. Returns the city and its parameters.
fn procedural_source(
    scene_file: &Path,
    mut table: toml::Table,
) -> Result<(SourceModel, ProceduralCity), SceneError> {
    use super::procedural::{generate, PlaneOrigin, ProceduralSpec};
    let toml_err = |origin: bool| {
        move |e: toml::de::Error| SceneError::ProceduralToml {
            path: scene_file.into(),
            origin,
            source: Box::new(e),
        }
    };
    let origin: PlaneOrigin = match table.remove("origin") {
        Some(v) => v.try_into().map_err(toml_err(true))?,
        None => PlaneOrigin::default(),
    };
    let spec: ProceduralSpec = toml::Value::Table(table).try_into().map_err(toml_err(false))?;
    let model = generate(&spec, origin)?;
    Ok((model, ProceduralCity { spec, origin }))
}

/// How one source's coordinates reach ECEF.
#[allow(clippy::large_enum_variant)] // one per source, never copied
enum Conversion {
    /// The source is ECEF already (3D Tiles).
    Ecef,
    /// Through PROJ to geodetic coordinates; `orthometric`: the geoid undulation is added to the heights.
    Crs { tf: geo::CrsTransform, axes: AxisConvention, orthometric: bool },
}

/// A [`SceneError::Georef`] for the source at `path`.
fn georef_err(path: &Path, problem: GeorefProblem, source: Option<geo::GeoError>) -> SceneError {
    SceneError::Georef { path: path.to_path_buf(), problem: Box::new(problem), source }
}

/// Converts one source model's buildings to ECEF. Returns the buildings, the conversion chain as the
/// manifest describes it, and the number of degenerate faces dropped.
fn georeference(
    scene_file: &Path,
    src: &SourceConfig,
    model: SourceModel,
    source_label: &str,
    geoid: &mut GeoidSlot,
    appearance: &mut AppearanceTable,
    progress: &dyn Progress,
) -> Result<(Vec<EcefBuilding>, String, u64), SceneError> {
    let images = model.appearance.images.clone();
    let path = model.path.clone();
    let mut dropped = 0u64;
    let (conv, chain) = match &model.frame {
        Frame::Ecef => (Conversion::Ecef, "EPSG:4978 (ECEF, ellipsoidal) → ENU".to_string()),
        Frame::Crs { name, axes } => crs_conversion(scene_file, src, &model, name.as_ref(), *axes, geoid)?,
    };
    let geoid_ref: Option<Geoid> = match &conv {
        Conversion::Crs { orthometric: true, .. } => Some(geoid.get()?.clone()),
        _ => None,
    };

    let mut out = Vec::with_capacity(model.buildings.len());
    progress.start(model.buildings.len() as u64, "buildings");
    let above_ground = src.heights == Some(Heights::AboveGround);
    for b in model.buildings {
        // heights = "above_ground": the building's ground height is added to every vertex.
        let lift_m = if above_ground { ground_height_m(src, &b) } else { 0.0 };
        let to_ecef =
            ToEcef { conv: &conv, geoid: geoid_ref.as_ref(), lift_m, path: &path, source_id: &b.source_id };
        let (positions_ecef, triangles, vertex_app) = match b.geometry {
            Geometry::Mesh(m) => {
                let pos = m.positions.iter().map(|&p| to_ecef.point(p)).collect::<Result<Vec<_>, _>>()?;
                let n_before = m.triangles.len();
                let tris: Vec<[u32; 3]> = m
                    .triangles
                    .into_iter()
                    .filter(|t| {
                        t.iter().all(|&i| (i as usize) < pos.len()) && triangle_area_m2(&pos, *t) > 1e-9
                    })
                    .collect();
                dropped += (n_before - tris.len()) as u64;
                (pos, tris, None)
            }
            Geometry::Polygons(polys) => {
                let faces = FaceSources { appearance: &b.appearance, images: &images };
                let t = triangulate_faces(&polys, &faces, &to_ecef, appearance)?;
                dropped += t.dropped;
                (t.positions_ecef, t.triangles, t.appearance)
            }
        };
        progress.inc(1);
        if triangles.is_empty() {
            continue;
        }
        let (base_h_m, lat_range, lon_range) = geodetic_extents(&positions_ecef);
        out.push(EcefBuilding {
            source_id: b.source_id,
            source_file: source_label.to_string(),
            lod: b.lod,
            measured_height_m: b.measured_height_m,
            positions_ecef,
            triangles,
            appearance: vertex_app,
            base_h_m,
            lat_range,
            lon_range,
        });
    }
    progress.finish();
    Ok((out, chain, dropped))
}

/// The CRS a source is read in: the scene file's `crs` (warning when the file declares another one),
/// else the file's own.
///
/// # Errors
/// [`SceneError::Georef`] when neither names one.
fn source_crs_name(
    scene_file: &Path,
    src: &SourceConfig,
    path: &Path,
    file_crs: Option<&String>,
) -> Result<String, SceneError> {
    match (&src.crs, file_crs) {
        (Some(over), file) => {
            if let Some(f) = file {
                if f != over {
                    log::warn!("{}: file declares CRS {f}, scene file overrides with {over}", path.display());
                }
            }
            Ok(over.clone())
        }
        (None, Some(f)) => Ok(f.clone()),
        (None, None) => {
            Err(georef_err(path, GeorefProblem::NoCrs { scene_file: scene_file.to_path_buf() }, None))
        }
    }
}

/// The conversion of a source in a CRS, and its chain as the manifest describes it: PROJ heights
/// included when `[geoid] model = "proj"` and PROJ has a real vertical transformation, else PROJ to
/// latitude/longitude plus the geoid for orthometric heights.
fn crs_conversion(
    scene_file: &Path,
    src: &SourceConfig,
    model: &SourceModel,
    file_crs: Option<&String>,
    axes: AxisConvention,
    geoid: &mut GeoidSlot,
) -> Result<(Conversion, String), SceneError> {
    let path = &model.path;
    let name = source_crs_name(scene_file, src, path, file_crs)?;
    let crs_err = |e| georef_err(path, GeorefProblem::Crs { name: name.clone() }, Some(e));
    let crs = Crs::parse(&name).map_err(crs_err)?;
    let orthometric = crs.heights() == HeightKind::Orthometric;
    let axes_s = match axes {
        AxisConvention::Authority => "authority axis order",
        AxisConvention::EastNorth => "east/north axis order",
    };
    let by_proj = if orthometric && geoid.cfg.geoid.model == GeoidModel::Proj {
        proj_vertical(src, model, &crs, &name, axes, geoid)?
    } else {
        None
    };
    Ok(match by_proj {
        Some((tf3, choice)) => {
            let chain = format!(
                "{} ({axes_s}, orthometric heights) → WGS84 3D (PROJ: {}) → EPSG:4978 → ENU",
                crs.describe(),
                choice.operation
            );
            log::info!("{}: heights through PROJ: {}", path.display(), choice.operation);
            if geoid.proj.is_none() {
                let tf_origin = crs.transform_with_heights().map_err(crs_err)?;
                geoid.proj = Some(ProjHeights { tf: tf_origin, axes, choice });
            }
            (Conversion::Crs { tf: tf3, axes, orthometric: false }, chain)
        }
        None => {
            let tf = crs.transform().map_err(crs_err)?;
            let g = if orthometric { geoid.get()?.name() } else { "none" };
            let chain = format!(
                "{} ({axes_s}, {} heights) → WGS84 lat/lon (PROJ){} → EPSG:4978 → ENU",
                crs.describe(),
                if orthometric { "orthometric" } else { "ellipsoidal" },
                if orthometric { format!(" + geoid {g}") } else { String::new() }
            );
            (Conversion::Crs { tf, axes, orthometric }, chain)
        }
    })
}

/// `[geoid] model = "proj"` for a source with orthometric heights: PROJ converts a compound CRS
/// heights included when it has a real vertical transformation (a national geoid grid) for it, probed
/// at the first vertex. `None` (after the one fallback warning) when it has not.
fn proj_vertical(
    src: &SourceConfig,
    model: &SourceModel,
    crs: &Crs,
    name: &str,
    axes: AxisConvention,
    geoid: &mut GeoidSlot,
) -> Result<Option<(geo::CrsTransform, geo::VerticalChoice)>, SceneError> {
    let crs_err = |e| georef_err(&model.path, GeorefProblem::Crs { name: name.to_string() }, Some(e));
    let mut missing = Vec::new();
    let mut by_proj = None;
    if crs.vertical_epsg.is_some() {
        let tf3 = crs.transform_with_heights().map_err(crs_err)?;
        let probe = first_vertex(model).map(|p| {
            let lift = model.buildings.first().map_or(0.0, |b| {
                if src.heights == Some(Heights::AboveGround) {
                    ground_height_m(src, b)
                } else {
                    0.0
                }
            });
            [p[0], p[1], p[2] + lift]
        });
        if let Some(probe) = probe {
            let choice = tf3
                .vertical_choice_at(probe, axes)
                .map_err(crs_err)?
                .expect("a converter made by transform_with_heights reports its choice");
            if choice.ballpark {
                missing = choice.missing_grids;
            } else {
                by_proj = Some((tf3, choice));
            }
        }
    }
    if by_proj.is_none() {
        geoid.warn_fallback(crs, &missing)?;
    }
    Ok(by_proj)
}

/// Converts the points of one building to ECEF.
struct ToEcef<'a> {
    conv: &'a Conversion,
    /// The geoid whose undulation is added to orthometric heights.
    geoid: Option<&'a Geoid>,
    /// Added to every height first (`heights = "above_ground"`), metres.
    lift_m: f64,
    /// The source file and the building, for error messages.
    path: &'a Path,
    source_id: &'a str,
}

impl ToEcef<'_> {
    fn point(&self, p: [f64; 3]) -> Result<[f64; 3], SceneError> {
        let p = [p[0], p[1], p[2] + self.lift_m];
        match self.conv {
            Conversion::Ecef => {
                if p.iter().all(|v| v.is_finite()) {
                    Ok(p)
                } else {
                    Err(georef_err(
                        self.path,
                        GeorefProblem::NonFinite { building: self.source_id.to_string(), coordinate: p },
                        None,
                    ))
                }
            }
            Conversion::Crs { tf, axes, .. } => {
                let mut g = tf.to_geodetic(p, *axes).map_err(|e| {
                    georef_err(
                        self.path,
                        GeorefProblem::Building { building: self.source_id.to_string() },
                        Some(e),
                    )
                })?;
                if let Some(geoid) = self.geoid {
                    g.h_m += geoid.undulation_m(g.lat_deg, g.lon_deg);
                }
                Ok(geo::geodetic_to_ecef(g))
            }
        }
    }

    fn ring(&self, ring: &[[f64; 3]]) -> Result<Vec<[f64; 3]>, SceneError> {
        ring.iter().map(|&p| self.point(p)).collect()
    }
}

/// Where the appearance of a building's faces comes from.
struct FaceSources<'a> {
    /// One entry per polygon.
    appearance: &'a [Option<lod::FaceAppearance>],
    /// The source's texture images (`FaceAppearance::Texture::image` indexes it).
    images: &'a [PathBuf],
}

/// A building's polygons triangulated in ECEF.
struct Triangulated {
    positions_ecef: Vec<[f64; 3]>,
    triangles: Vec<[u32; 3]>,
    /// Per-vertex appearance, when some face has one.
    appearance: Option<VertexAppearance>,
    /// Degenerate polygons (collinear, zero area), dropped.
    dropped: u64,
}

/// Converts a building's rings to ECEF, then triangulates them in ECEF (planarity is preserved by the
/// affine ECEF → ENU step that follows, and the triangulation works relative to each polygon's first
/// vertex, so magnitudes do not cost precision), carrying each face's texture or colour.
fn triangulate_faces(
    polys: &[lod::Polygon],
    faces: &FaceSources,
    to_ecef: &ToEcef,
    appearance: &mut AppearanceTable,
) -> Result<Triangulated, SceneError> {
    let mut pos = Vec::new();
    let mut tris = Vec::new();
    let mut dropped = 0u64;
    let mut va = (!faces.appearance.is_empty()).then(VertexAppearance::default);
    for (k, poly) in polys.iter().enumerate() {
        let ext = to_ecef.ring(&poly.exterior)?;
        let holes = poly.interiors.iter().map(|r| to_ecef.ring(r)).collect::<Result<Vec<_>, _>>()?;
        // Degenerate polygons (collinear, zero area) are dropped and counted.
        let ok = match (va.as_mut(), faces.appearance.get(k).and_then(Option::as_ref)) {
            (Some(va), Some(lod::FaceAppearance::Texture { image, uv_exterior, uv_interiors })) => {
                let ok = triangulate_polygon_uv(
                    &ext,
                    &holes,
                    uv_exterior,
                    uv_interiors,
                    &mut pos,
                    &mut va.uvs,
                    &mut tris,
                );
                // A missing or unreadable image: the face keeps the procedural look.
                let id = faces.images.get(*image).map_or(0, |p| appearance.texture(p));
                va.ids.resize(pos.len(), id);
                ok
            }
            (Some(va), face) => {
                let ok = triangulate_polygon(&ext, &holes, &mut pos, &mut tris);
                let id = match face {
                    Some(lod::FaceAppearance::Colour { rgb }) => appearance.colour(*rgb),
                    _ => 0,
                };
                va.uvs.resize(pos.len(), [0.0, 0.0]);
                va.ids.resize(pos.len(), id);
                ok
            }
            (None, _) => triangulate_polygon(&ext, &holes, &mut pos, &mut tris),
        };
        debug_assert!(va.as_ref().is_none_or(|v| v.uvs.len() == pos.len() && v.ids.len() == pos.len()));
        if !ok {
            dropped += 1;
        }
    }
    Ok(Triangulated {
        positions_ecef: pos,
        triangles: tris,
        appearance: va.filter(|v| v.ids.iter().any(|&i| i != 0)),
        dropped,
    })
}

/// A building's lowest ellipsoidal height (metres) and its latitude and longitude ranges (degrees).
fn geodetic_extents(positions_ecef: &[[f64; 3]]) -> (f64, [f64; 2], [f64; 2]) {
    let mut base_h_m = f64::INFINITY;
    let mut lat_range = [f64::INFINITY, f64::NEG_INFINITY];
    let mut lon_range = [f64::INFINITY, f64::NEG_INFINITY];
    for &p in positions_ecef {
        let g = geo::ecef_to_geodetic(p);
        base_h_m = base_h_m.min(g.h_m);
        lat_range = [lat_range[0].min(g.lat_deg), lat_range[1].max(g.lat_deg)];
        lon_range = [lon_range[0].min(g.lon_deg), lon_range[1].max(g.lon_deg)];
    }
    (base_h_m, lat_range, lon_range)
}

/// The ground height added to a building of a source read with `heights = "above_ground"`, in
/// metres: the constant, the named attribute, or the first ground attribute the building carries
/// (0 when it has none; [`heights_note`] has warned).
fn ground_height_m(src: &SourceConfig, b: &lod::SourceBuilding) -> f64 {
    if let Some(c) = src.ground_height_m {
        return c;
    }
    b.ground_heights_m
        .iter()
        .find(|(name, _)| src.ground_attribute.as_ref().is_none_or(|want| want == name))
        .map_or(0.0, |(_, h)| *h)
}

/// Checks a source's heights setting against what the file holds: warns when the buildings look
/// relative to the ground but are read as absolute (the fix to copy), and describes an
/// `above_ground` reading for the manifest.
///
/// # Errors
/// [`SceneError::Georef`] for `above_ground` on an ECEF source (3D Tiles are absolute by nature).
fn heights_note(src: &SourceConfig, model: &lod::SourceModel) -> Result<Option<String>, SceneError> {
    let path = model.path.display();
    if src.heights != Some(Heights::AboveGround) {
        if let Some(r) = lod::relative_heights(model) {
            log::warn!(
                "{path}: {} of {} building(s) start at z ≈ 0 m although their {} is not 0: the heights look \
                 relative to the ground and would be placed up to a few metres off; if so, set heights = \
                 \"above_ground\" and ground_attribute = \"{}\" for this source in the scene file",
                r.buildings,
                model.buildings.len(),
                r.attribute,
                r.attribute
            );
        }
        return Ok(None);
    }
    if matches!(model.frame, lod::Frame::Ecef) {
        return Err(SceneError::Georef {
            path: model.path.clone(),
            problem: Box::new(GeorefProblem::AboveGroundEcef),
            source: None,
        });
    }
    if let Some(c) = src.ground_height_m {
        return Ok(Some(format!("above_ground: + {c} m")));
    }
    let has = |b: &lod::SourceBuilding| {
        b.ground_heights_m.iter().any(|(n, _)| src.ground_attribute.as_ref().is_none_or(|w| w == n))
    };
    let with = model.buildings.iter().filter(|b| has(b)).count();
    let missing = model.buildings.len() - with;
    let name = src.ground_attribute.clone().unwrap_or_else(|| "its ground attribute".into());
    if missing > 0 {
        log::warn!(
            "{path}: heights = \"above_ground\" but {missing} of {} building(s) have no {name}; they are left \
             as they are",
            model.buildings.len()
        );
    }
    Ok(Some(format!("above_ground: + {name} per building ({with} buildings)")))
}

fn triangle_area_m2(p: &[[f64; 3]], t: [u32; 3]) -> f64 {
    let [a, b, c] = t.map(|i| p[i as usize]);
    // Relative to `a`, so ECEF magnitudes cost no precision.
    let ab = [b[0] - a[0], b[1] - a[1], b[2] - a[2]];
    let ac = [c[0] - a[0], c[1] - a[1], c[2] - a[2]];
    let x = [ab[1] * ac[2] - ab[2] * ac[1], ab[2] * ac[0] - ab[0] * ac[2], ab[0] * ac[1] - ab[1] * ac[0]];
    0.5 * (x[0] * x[0] + x[1] * x[1] + x[2] * x[2]).sqrt()
}

/// Signed area of a 2D ring (positive = counter-clockwise).
fn signed_area(poly: &[[f64; 2]]) -> f64 {
    let n = poly.len();
    (0..n)
        .map(|i| {
            let (a, b) = (poly[i], poly[(i + 1) % n]);
            a[0] * b[1] - b[0] * a[1]
        })
        .sum::<f64>()
        * 0.5
}

/// Footprint of a triangle set: area (m²) and centroid (ENU) of the union of the triangles' ground
/// projections, rasterised on a grid fine enough for ≤ 250 000 cells (at most 5 cm).
pub fn footprint(positions: &[[f64; 3]], triangles: &[[u32; 3]]) -> (f64, [f64; 2]) {
    let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
    for p in positions {
        lo = [lo[0].min(p[0]), lo[1].min(p[1])];
        hi = [hi[0].max(p[0]), hi[1].max(p[1])];
    }
    if !(lo[0].is_finite() && hi[0].is_finite()) {
        return (0.0, [0.0, 0.0]);
    }
    let (w_m, h_m) = (hi[0] - lo[0], hi[1] - lo[1]);
    let cell = (w_m * h_m / 250_000.0).sqrt().max(0.05);
    let nx = ((w_m / cell).ceil() as usize).max(1);
    let ny = ((h_m / cell).ceil() as usize).max(1);
    let mut covered = vec![false; nx * ny];
    for t in triangles {
        let [a, b, c] = t.map(|i| positions[i as usize]);
        let area2 = (b[0] - a[0]) * (c[1] - a[1]) - (c[0] - a[0]) * (b[1] - a[1]);
        if area2.abs() < 1e-12 {
            continue; // vertical (wall) triangle: no footprint
        }
        let tx0 = ((a[0].min(b[0]).min(c[0]) - lo[0]) / cell).floor().max(0.0) as usize;
        let tx1 = (((a[0].max(b[0]).max(c[0]) - lo[0]) / cell).ceil() as usize).min(nx);
        let ty0 = ((a[1].min(b[1]).min(c[1]) - lo[1]) / cell).floor().max(0.0) as usize;
        let ty1 = (((a[1].max(b[1]).max(c[1]) - lo[1]) / cell).ceil() as usize).min(ny);
        let s = area2.signum();
        for iy in ty0..ty1 {
            let y = lo[1] + (iy as f64 + 0.5) * cell;
            for ix in tx0..tx1 {
                let x = lo[0] + (ix as f64 + 0.5) * cell;
                let e0 = s * ((b[0] - a[0]) * (y - a[1]) - (b[1] - a[1]) * (x - a[0]));
                let e1 = s * ((c[0] - b[0]) * (y - b[1]) - (c[1] - b[1]) * (x - b[0]));
                let e2 = s * ((a[0] - c[0]) * (y - c[1]) - (a[1] - c[1]) * (x - c[0]));
                if e0 >= 0.0 && e1 >= 0.0 && e2 >= 0.0 {
                    covered[iy * nx + ix] = true;
                }
            }
        }
    }
    let (mut n, mut sx, mut sy) = (0u64, 0.0, 0.0);
    for iy in 0..ny {
        for ix in 0..nx {
            if covered[iy * nx + ix] {
                n += 1;
                sx += lo[0] + (ix as f64 + 0.5) * cell;
                sy += lo[1] + (iy as f64 + 0.5) * cell;
            }
        }
    }
    if n == 0 {
        let c = [(lo[0] + hi[0]) * 0.5, (lo[1] + hi[1]) * 0.5];
        return (0.0, c);
    }
    (n as f64 * cell * cell, [sx / n as f64, sy / n as f64])
}

/// Runs `prepare` for one scene file, writing the artifact into `out_dir` (`<workdir>/<area>/scene`):
/// reads and geo-references every source, instances the buildings in the area's ENU frame, then
/// writes the GLB, the building table and the manifest.
///
/// # Errors
/// [`SceneError`] naming the scene file or source and what is wrong; nothing is written on error.
///
/// This writes the buildings alone, no clutter (what library users and the older tests expect);
/// `insgen prepare` calls [`prepare_with`] with clutter on.
pub fn prepare(
    scene_file: &Path,
    out_dir: &Path,
    progress: &dyn Progress,
) -> Result<PrepareReport, SceneError> {
    prepare_with(scene_file, out_dir, &PrepareOptions::default(), progress)
}

/// Options of [`prepare_with`].
#[derive(Debug, Clone, Default, PartialEq)]
pub struct PrepareOptions {
    /// Generate clutter layers beside the buildings ([`super::clutter`]); `None` = buildings only.
    pub clutter: Option<super::clutter::ClutterSpec>,
}

/// [`prepare`] with options: with `clutter`, the clutter layers are generated from the instanced
/// buildings and the area polygon, written as extra nodes of `scene.glb`, and listed in the manifest's
/// `clutter` section.
///
/// # Errors
/// As [`prepare`].
pub fn prepare_with(
    scene_file: &Path,
    out_dir: &Path,
    options: &PrepareOptions,
    progress: &dyn Progress,
) -> Result<PrepareReport, SceneError> {
    let started = Instant::now();
    let cfg = SceneConfig::load(scene_file)?;
    if cfg.attribution.as_deref().is_some_and(|a| a.starts_with(super::init::TODO)) {
        log::warn!(
            "{}: the attribution is still the placeholder `insgen init` wrote; name the model's maker and \
             licence before publishing a dataset",
            scene_file.display()
        );
    }
    let sources = read_sources(scene_file, &cfg, progress)?;
    let (mut scene, appearance) = instance(&cfg, sources)?;
    if let Some(spec) = &options.clutter {
        let t0 = Instant::now();
        let (clutter, summary) = super::clutter::generate(
            spec,
            &scene.mesh,
            &scene.buildings,
            &scene.manifest.area_polygon_enu_m,
            scene.manifest.ground_enu_m,
        );
        log::info!(
            "clutter: {} triangles in {} layers ({:.2} s)",
            summary.layers.iter().map(|l| l.triangles).sum::<u64>(),
            summary.layers.len(),
            t0.elapsed().as_secs_f64()
        );
        scene.clutter = clutter;
        scene.manifest.clutter = Some(summary);
    }
    write_artifact(out_dir, &scene, appearance.as_ref())?;
    Ok(PrepareReport { scene, out_dir: out_dir.to_path_buf(), seconds: started.elapsed().as_secs_f64() })
}

/// Every source of an area, geo-referenced to ECEF.
struct Sources {
    buildings: Vec<EcefBuilding>,
    entries: Vec<SourceEntry>,
    degenerate_faces: u64,
    /// The geoid, when a source needed one (orthometric heights).
    geoid: Option<Geoid>,
    /// `[geoid] model = "proj"`: the first source PROJ converted heights included.
    proj: Option<ProjHeights>,
    /// `[geoid] model = "proj"`: grids PROJ wanted but did not find.
    missing_grids: Vec<String>,
    /// The distinct textures and colours of all sources.
    appearance: AppearanceTable,
}

/// Reads and geo-references the sources of `cfg` in order; at least one building.
fn read_sources(
    scene_file: &Path,
    cfg: &SceneConfig,
    progress: &dyn Progress,
) -> Result<Sources, SceneError> {
    let mut geoid =
        GeoidSlot { cfg, scene_file, geoid: None, proj: None, missing_grids: Vec::new(), warned: false };
    let mut out = Sources {
        buildings: Vec::new(),
        entries: Vec::new(),
        degenerate_faces: 0,
        geoid: None,
        proj: None,
        missing_grids: Vec::new(),
        appearance: AppearanceTable::default(),
    };
    let base = scene_file.parent().unwrap_or(Path::new("."));
    for (index, src) in cfg.sources.iter().enumerate() {
        let files: Vec<Option<PathBuf>> = if src.format.as_deref() == Some("procedural") {
            vec![None]
        } else {
            cfg.source_files(scene_file, index)?.into_iter().map(Some).collect()
        };
        if files.len() > 1 {
            log::info!(
                "sources[{index}] {}: {} files",
                src.path.as_deref().unwrap_or(Path::new("")).display(),
                files.len()
            );
        }
        for file in files {
            read_file(scene_file, src, file.as_deref(), base, &mut geoid, &mut out, progress)?;
        }
    }
    if out.buildings.is_empty() {
        return Err(SceneError::Area { area: cfg.name.clone(), problem: AreaProblem::NoBuildings });
    }
    out.geoid = geoid.geoid;
    out.proj = geoid.proj;
    out.missing_grids = geoid.missing_grids;
    Ok(out)
}

/// Reads and geo-references one file of a source (`None`: the procedural city) into `out`.
fn read_file(
    scene_file: &Path,
    src: &SourceConfig,
    file: Option<&Path>,
    base: &Path,
    geoid: &mut GeoidSlot,
    out: &mut Sources,
    progress: &dyn Progress,
) -> Result<(), SceneError> {
    let cfg = geoid.cfg;
    let (model, fmt, procedural) = read_one(scene_file, src, file)?;
    // The file as the manifest names it: relative to the scene file's folder, as written there.
    let label = match file {
        Some(p) => p.strip_prefix(base).unwrap_or(p).display().to_string(),
        None => "procedural".to_string(),
    };
    let sha256 = match file {
        Some(p) => util::sha256_file(p)?,
        None => String::from("procedural"),
    };
    let stats = model.stats.clone();
    let model_path = model.path.clone();
    let heights = heights_note(src, &model)?;
    let model_appearance = model.appearance.clone();
    if let Some(theme) = &src.theme {
        if !model_appearance.themes.contains(theme) {
            log::warn!(
                "{}: theme {theme:?} is not in the file (its themes: {}); no face gets a texture or colour",
                model_path.display(),
                if model_appearance.themes.is_empty() {
                    "none".to_string()
                } else {
                    model_appearance.themes.iter().map(|t| format!("{t:?}")).collect::<Vec<_>>().join(", ")
                }
            );
        }
    }
    let missing_before = out.appearance.missing.len();
    let asked_before = out.appearance.images_asked();
    let (mut bs, chain, dropped_here) =
        georeference(scene_file, src, model, &label, geoid, &mut out.appearance, progress)?;
    let appearance = appearance_entry(
        &model_appearance,
        (out.appearance.images_asked() - asked_before) as u64,
        &out.appearance.missing[missing_before..],
    );
    if let Some(a) = &appearance {
        if a.missing_images > 0 {
            log::warn!(
                "{}: {} of {} texture image(s) are missing or unreadable (first: {}); their faces keep the \
                 procedural look",
                model_path.display(),
                a.missing_images,
                a.images,
                a.missing_examples.first().map_or("", String::as_str)
            );
        }
    }
    log::info!("{}: {} buildings ({chain})", model_path.display(), bs.len());
    let dropped = stats.degenerate_faces + dropped_here;
    out.degenerate_faces += dropped;
    out.entries.push(SourceEntry {
        path: label,
        format: fmt,
        sha256,
        crs_chain: chain,
        buildings: bs.len() as u64,
        degenerate_faces: dropped,
        attribution: cfg.attribution.clone(),
        heights,
        appearance,
        procedural,
    });
    out.buildings.append(&mut bs);
    Ok(())
}

/// What the manifest records of a source's appearances (`None` when it has none).
fn appearance_entry(
    app: &lod::ModelAppearance,
    images_used: u64,
    missing: &[(PathBuf, String)],
) -> Option<artifact::AppearanceEntry> {
    if app.themes.is_empty() && app.images.is_empty() {
        return None;
    }
    Some(artifact::AppearanceEntry {
        themes: app.themes.clone(),
        texture_theme: app.texture_theme.clone(),
        material_theme: app.material_theme.clone(),
        textured_faces: app.textured_faces,
        coloured_faces: app.coloured_faces,
        images: images_used,
        missing_images: missing.len() as u64,
        missing_examples: missing.iter().take(5).map(|(p, why)| format!("{} ({why})", p.display())).collect(),
        unusable_targets: app.unusable_targets,
    })
}

/// The area origin: the scene file's, else the centre of the buildings' latitude/longitude bounds; its
/// height defaults to the median building base.
fn area_origin(cfg: &SceneConfig, buildings: &[EcefBuilding]) -> Geodetic {
    let median_base_h_m =
        util::median(&buildings.iter().map(|b| b.base_h_m).collect::<Vec<_>>()).unwrap_or(0.0);
    match cfg.origin {
        Some(o) => Geodetic::new(o.lat_deg, o.lon_deg, o.h_m.unwrap_or(median_base_h_m)),
        None => {
            let lat = [
                buildings.iter().map(|b| b.lat_range[0]).fold(f64::INFINITY, f64::min),
                buildings.iter().map(|b| b.lat_range[1]).fold(f64::NEG_INFINITY, f64::max),
            ];
            let lon = [
                buildings.iter().map(|b| b.lon_range[0]).fold(f64::INFINITY, f64::min),
                buildings.iter().map(|b| b.lon_range[1]).fold(f64::NEG_INFINITY, f64::max),
            ];
            Geodetic::new(0.5 * (lat[0] + lat[1]), 0.5 * (lon[0] + lon[1]), median_base_h_m)
        }
    }
}

/// The scene file's `[area]` as a counter-clockwise ring in ENU metres (open), if it has one.
fn area_polygon_enu(cfg: &SceneConfig, enu: &EnuFrame) -> Option<Vec<[f64; 2]>> {
    cfg.area.as_ref().map(|a| {
        let pts: Vec<[f64; 2]> = match (&a.bbox_deg, &a.polygon_deg) {
            (Some(b), _) => vec![[b[0], b[1]], [b[2], b[1]], [b[2], b[3]], [b[0], b[3]]],
            (None, Some(p)) => p.clone(),
            (None, None) => unreachable!("validated"),
        };
        let mut ring: Vec<[f64; 2]> = pts
            .iter()
            .map(|ll| {
                let e = enu.geodetic_to_enu(Geodetic::new(ll[1], ll[0], enu.origin.h_m));
                [e[0], e[1]]
            })
            .collect();
        if ring.len() > 3 && ring.first() == ring.last() {
            ring.pop();
        }
        if signed_area(&ring) < 0.0 {
            ring.reverse();
        }
        ring
    })
}

/// One instance before numbering: the parts of every building sharing a source ID, in ENU.
struct Merged {
    source_file: String,
    lod: String,
    measured_height_m: Option<f64>,
    positions: Vec<[f64; 3]>,
    triangles: Vec<[u32; 3]>,
    appearance: Option<VertexAppearance>,
}

/// Converts the buildings to ENU, drops those whose centre lies outside `area_polygon`, and merges
/// them by source ID (sorted, so the numbering is reproducible). Returns the merged buildings and how
/// many were outside.
fn merge_by_source_id(
    buildings: Vec<EcefBuilding>,
    enu: &EnuFrame,
    area_polygon: Option<&[[f64; 2]]>,
) -> (BTreeMap<String, Merged>, u64) {
    let mut merged: BTreeMap<String, Merged> = BTreeMap::new();
    let mut outside = 0u64;
    for b in buildings {
        let positions: Vec<[f64; 3]> =
            b.positions_ecef.iter().map(|&p| enu.ecef_to_enu(p.into()).to_array()).collect();
        if let Some(poly) = area_polygon {
            let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
            for p in &positions {
                lo = [lo[0].min(p[0]), lo[1].min(p[1])];
                hi = [hi[0].max(p[0]), hi[1].max(p[1])];
            }
            if !util::point_in_polygon([0.5 * (lo[0] + hi[0]), 0.5 * (lo[1] + hi[1])], poly) {
                outside += 1;
                continue;
            }
        }
        let m = merged.entry(b.source_id).or_insert_with(|| Merged {
            source_file: b.source_file.clone(),
            lod: b.lod.clone(),
            measured_height_m: b.measured_height_m,
            positions: Vec::new(),
            triangles: Vec::new(),
            appearance: None,
        });
        let base = m.positions.len() as u32;
        // Parts with and without appearance: the ones without get appearance 0.
        match (&mut m.appearance, b.appearance) {
            (Some(a), Some(part)) => {
                a.uvs.extend(part.uvs);
                a.ids.extend(part.ids);
            }
            (Some(a), None) => a.pad(positions.len()),
            (None, Some(part)) => {
                let mut a = VertexAppearance::default();
                a.pad(m.positions.len());
                a.uvs.extend(part.uvs);
                a.ids.extend(part.ids);
                m.appearance = Some(a);
            }
            (None, None) => {}
        }
        m.positions.extend_from_slice(&positions);
        m.triangles.extend(b.triangles.iter().map(|t| t.map(|i| i + base)));
        if m.measured_height_m.is_none() {
            m.measured_height_m = b.measured_height_m;
        }
    }
    (merged, outside)
}

/// Numbers the merged buildings 1, 2, … in source-ID order and builds the scene mesh and the building
/// table.
///
/// # Panics
/// When there are more buildings than 24-bit IDs (the caller checks first).
fn mesh_and_table(
    merged: BTreeMap<String, Merged>,
    enu: &EnuFrame,
) -> (SceneMesh, Vec<BuildingRecord>, Option<VertexAppearance>) {
    let mut mesh = SceneMesh::default();
    let mut records = Vec::with_capacity(merged.len());
    let mut appearance: Option<VertexAppearance> =
        merged.values().any(|m| m.appearance.is_some()).then(VertexAppearance::default);
    for (k, (source_id, m)) in merged.into_iter().enumerate() {
        let id = BuildingId::from_index(k).expect("the count was checked against the ID space");
        let (mut lo, mut hi) = ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]);
        for p in &m.positions {
            for a in 0..3 {
                lo[a] = lo[a].min(p[a]);
                hi[a] = hi[a].max(p[a]);
            }
        }
        let (area_m2, c) = footprint(&m.positions, &m.triangles);
        let g = enu.enu_to_geodetic(glam::DVec3::new(c[0], c[1], lo[2]));
        let base = mesh.positions_m.len() as u32;
        mesh.positions_m.extend(m.positions.iter().map(|p| [p[0] as f32, p[1] as f32, p[2] as f32]));
        mesh.building_ids.extend(std::iter::repeat_n(id, m.positions.len()));
        mesh.indices.extend(m.triangles.iter().flat_map(|t| t.map(|i| i + base)));
        match (&mut appearance, m.appearance) {
            (Some(a), Some(part)) => {
                a.uvs.extend(part.uvs);
                a.ids.extend(part.ids);
            }
            (Some(a), None) => a.pad(m.positions.len()),
            (None, _) => {}
        }
        records.push(BuildingRecord {
            id,
            source_id,
            source_file: m.source_file,
            lod: m.lod,
            height_m: hi[2] - lo[2],
            measured_height_m: m.measured_height_m,
            footprint_area_m2: area_m2,
            centroid_lat_deg: g.lat_deg,
            centroid_lon_deg: g.lon_deg,
            bbox_min_enu_m: lo,
            bbox_max_enu_m: hi,
            triangles: m.triangles.len() as u64,
        });
    }
    (mesh, records, appearance)
}

/// What the manifest records of the geoid used.
fn geoid_used(sources: &Sources, origin: Geodetic) -> GeoidUsed {
    let mut used = match (&sources.proj, sources.geoid.as_ref()) {
        (Some(p), _) => {
            // N at the origin as PROJ applies it: h − H, H from the inverse conversion of the origin.
            let undulation_at_origin_m =
                p.tf.from_geodetic(origin, p.axes)
                    .map(|src| origin.h_m - src[2] * p.tf.crs.height_unit_m)
                    .unwrap_or(f64::NAN);
            GeoidUsed {
                model: "proj".into(),
                grid: p.choice.grids.first().cloned(),
                undulation_at_origin_m,
                ..GeoidUsed::default()
            }
        }
        (None, None | Some(Geoid::None)) => GeoidUsed { model: "none".into(), ..GeoidUsed::default() },
        (None, Some(g @ Geoid::Constant(n))) => {
            GeoidUsed { model: g.name().into(), undulation_at_origin_m: *n, ..GeoidUsed::default() }
        }
        (None, Some(g @ Geoid::Grid(grid))) => GeoidUsed {
            model: g.name().into(),
            grid: Some(grid.path().display().to_string()),
            undulation_at_origin_m: g.undulation_m(origin.lat_deg, origin.lon_deg),
            ..GeoidUsed::default()
        },
    };
    if let Some(p) = &sources.proj {
        used.proj_operation = Some(p.choice.operation.clone());
        used.proj_grids = p.choice.grids.clone();
    }
    used.missing_grids = sources.missing_grids.clone();
    used
}

/// Instances the sources: the area origin and ENU frame, the area filter, one ID per source ID, the
/// mesh, the building table and the manifest.
fn instance(
    cfg: &SceneConfig,
    sources: Sources,
) -> Result<(PreparedScene, Option<SceneAppearance>), SceneError> {
    let origin = area_origin(cfg, &sources.buildings);
    let geoid = geoid_used(&sources, origin);
    let enu = EnuFrame::new(origin);
    let area_polygon = area_polygon_enu(cfg, &enu);
    let (merged, outside) = merge_by_source_id(sources.buildings, &enu, area_polygon.as_deref());
    if outside > 0 {
        log::info!("{outside} buildings lie outside the [area] polygon and were left out");
    }
    if merged.is_empty() {
        return Err(SceneError::Area { area: cfg.name.clone(), problem: AreaProblem::OutsideArea });
    }
    BuildingId::from_index(merged.len() - 1)
        .map_err(|source| SceneError::Ids { area: cfg.name.clone(), source })?;
    let (mesh, records, vertex_appearance) = mesh_and_table(merged, &enu);
    let appearance = vertex_appearance
        .map(|vertices| SceneAppearance { vertices, materials: sources.appearance.materials.clone() });
    let bases: Vec<f64> = records.iter().map(|r| r.bbox_min_enu_m[2]).collect();
    let ground_enu_m = util::median(&bases).unwrap_or(0.0);
    let area_polygon_enu_m = area_polygon.unwrap_or_else(|| {
        let lo = records
            .iter()
            .fold([f64::INFINITY; 2], |a, r| [a[0].min(r.bbox_min_enu_m[0]), a[1].min(r.bbox_min_enu_m[1])]);
        let hi = records.iter().fold([f64::NEG_INFINITY; 2], |a, r| {
            [a[0].max(r.bbox_max_enu_m[0]), a[1].max(r.bbox_max_enu_m[1])]
        });
        vec![[lo[0], lo[1]], [hi[0], lo[1]], [hi[0], hi[1]], [lo[0], hi[1]]]
    });
    let manifest = Manifest {
        insgen_version: env!("CARGO_PKG_VERSION").to_string(),
        area: cfg.name.clone(),
        split: cfg.split.as_str().to_string(),
        origin: Origin { lat_deg: origin.lat_deg, lon_deg: origin.lon_deg, h_m: origin.h_m },
        ecef_from_enu: enu.ecef_from_enu(),
        area_polygon_enu_m,
        ground_enu_m,
        geoid,
        sources: sources.entries,
        buildings: records.len() as u64,
        triangles: mesh.triangle_count() as u64,
        degenerate_faces: sources.degenerate_faces,
        attributions: cfg.attribution.iter().cloned().collect(),
        clutter: None,
        alignment: cfg.alignment.map(|c| {
            use super::correction::{AlignmentRecord, CorrectionSource};
            AlignmentRecord::new(CorrectionSource::SceneConfig, c, enu.ecef_from_enu())
        }),
    };
    Ok((PreparedScene { manifest, buildings: records, mesh, clutter: Default::default() }, appearance))
}

/// The scene's appearances: per vertex, and the distinct images and colours they number.
struct SceneAppearance {
    vertices: VertexAppearance,
    materials: Vec<super::appearance::AppearanceMaterial>,
}

/// Writes the artifact: GLB and building table first, the manifest last (its presence marks a complete
/// artifact).
fn write_artifact(
    out_dir: &Path,
    scene: &PreparedScene,
    appearance: Option<&SceneAppearance>,
) -> Result<(), SceneError> {
    util::create_dir_all(out_dir)?;
    super::appearance::copy_images(appearance.map_or(&[][..], |a| &a.materials[..]), out_dir)?;
    let glb_appearance =
        appearance.map(|a| super::glb::GlbAppearance { vertices: &a.vertices, materials: &a.materials });
    super::glb::write_glb_with_appearance(
        &out_dir.join(artifact::GLB_FILE),
        &scene.mesh,
        &scene.buildings,
        glb_appearance.as_ref(),
    )
    .map_err(|source| SceneError::ArtifactGlb { source })?;
    super::glb::add_layers(&out_dir.join(artifact::GLB_FILE), &scene.clutter)
        .map_err(|source| SceneError::ArtifactGlb { source })?;
    util::write_json_atomic(&out_dir.join(artifact::BUILDINGS_FILE), &scene.buildings)?;
    util::write_json_atomic(&out_dir.join(artifact::MANIFEST_FILE), &scene.manifest)?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn footprint_of_box_with_courtyard() {
        // Two roof rectangles forming an L: 10×4 + 4×6 = 64 m² (hand computation).
        let p = vec![
            [0.0, 0.0, 5.0],
            [10.0, 0.0, 5.0],
            [10.0, 4.0, 5.0],
            [0.0, 4.0, 5.0],
            [0.0, 4.0, 5.0],
            [4.0, 4.0, 5.0],
            [4.0, 10.0, 5.0],
            [0.0, 10.0, 5.0],
        ];
        let t = vec![[0, 1, 2], [0, 2, 3], [4, 5, 6], [4, 6, 7]];
        let (a, c) = footprint(&p, &t);
        assert!((a - 64.0).abs() < 0.5, "{a}");
        // Centroid: (10·4·(5, 2) + 4·6·(2, 7)) / 64 = (3.875, 3.875).
        assert!((c[0] - 3.875).abs() < 0.05 && (c[1] - 3.875).abs() < 0.05, "{c:?}");
    }

    #[test]
    fn signed_area_is_positive_counter_clockwise() {
        let sq = [[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]];
        assert!(signed_area(&sq) > 0.0);
    }
}
