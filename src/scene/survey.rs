//! What source files hold, before anything is prepared: format, CRS, extent, centre, LoDs and counts.
//!
//! `insgen inspect` prints a [`Survey`]; `insgen init` writes a scene file from one. Each file is read
//! by the same reader `prepare` uses ([`crate::lod::read_source`]) and its CRS is resolved the same
//! way ([`crate::geo::Crs::parse`] and a PROJ converter), so a file `inspect` accepts is one `prepare`
//! can place, and a CRS it cannot place fails here already. The extent in latitude/longitude is that
//! of every building vertex converted to WGS84 (as `prepare` converts them); its centre is the
//! `[origin]` `prepare` takes when the scene file gives none.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use rayon::prelude::*;
use serde::Serialize;

use crate::geo::{self, AxisConvention, Crs, EnuFrame, Geodetic, HeightKind};
use crate::lod::{self, Format, Frame, Geometry, ReadOptions, ReadStats, SourceModel};
use crate::util::Progress;

use super::error::GeorefProblem;
use super::SceneError;

/// How to read the files of a survey (what a scene file's source would say).
#[derive(Debug, Clone, Default)]
pub struct SurveyOptions {
    /// LoD to read (`None`: each reader's default, as `prepare`).
    pub lod: Option<String>,
    /// A CRS overriding what the files declare (the source's `crs`).
    pub crs: Option<String>,
    /// The reader to use (`None`: from each file's name).
    pub format: Option<Format>,
}

/// A bounding box in WGS84 degrees.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct LonLatBox {
    /// Westernmost longitude, degrees.
    pub lon_min_deg: f64,
    /// Southernmost latitude, degrees.
    pub lat_min_deg: f64,
    /// Easternmost longitude, degrees.
    pub lon_max_deg: f64,
    /// Northernmost latitude, degrees.
    pub lat_max_deg: f64,
}

impl LonLatBox {
    const EMPTY: LonLatBox = LonLatBox {
        lon_min_deg: f64::INFINITY,
        lat_min_deg: f64::INFINITY,
        lon_max_deg: f64::NEG_INFINITY,
        lat_max_deg: f64::NEG_INFINITY,
    };

    fn add(&mut self, lon_deg: f64, lat_deg: f64) {
        self.lon_min_deg = self.lon_min_deg.min(lon_deg);
        self.lat_min_deg = self.lat_min_deg.min(lat_deg);
        self.lon_max_deg = self.lon_max_deg.max(lon_deg);
        self.lat_max_deg = self.lat_max_deg.max(lat_deg);
    }

    fn union(mut self, o: &LonLatBox) -> LonLatBox {
        self.add(o.lon_min_deg, o.lat_min_deg);
        self.add(o.lon_max_deg, o.lat_max_deg);
        self
    }

    /// The centre of the box: the midpoints of the latitude and longitude ranges (what `prepare`
    /// takes as the area origin when the scene file gives none), degrees.
    pub fn centre(&self) -> LonLat {
        LonLat {
            lat_deg: 0.5 * (self.lat_min_deg + self.lat_max_deg),
            lon_deg: 0.5 * (self.lon_min_deg + self.lon_max_deg),
        }
    }

    /// West–east and south–north size through the centre, metres (in the ENU frame at the centre).
    pub fn size_m(&self) -> [f64; 2] {
        let c = self.centre();
        let enu = EnuFrame::new(Geodetic::new(c.lat_deg, c.lon_deg, 0.0));
        let at = |lat_deg, lon_deg| enu.geodetic_to_enu(Geodetic::new(lat_deg, lon_deg, 0.0));
        let we = at(c.lat_deg, self.lon_max_deg) - at(c.lat_deg, self.lon_min_deg);
        let sn = at(self.lat_max_deg, c.lon_deg) - at(self.lat_min_deg, c.lon_deg);
        [we.length(), sn.length()]
    }
}

/// A point in WGS84 degrees.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct LonLat {
    /// Latitude, degrees.
    pub lat_deg: f64,
    /// Longitude, degrees.
    pub lon_deg: f64,
}

/// The bounding box of a file's building vertices in the file's own coordinates.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SourceExtent {
    /// The axes in the file's order (`E`, `N`, `h`; `Lat`, `Lon`, `h`; `X`, `Y`, `Z`).
    pub axes: [String; 3],
    /// The unit of each axis (`metre`, `degree`, `US survey foot`; metres without a CRS).
    pub units: [String; 3],
    /// Smallest coordinate per axis, in the CRS's units.
    pub min: [f64; 3],
    /// Largest coordinate per axis.
    pub max: [f64; 3],
}

/// Textures and colours of a file's buildings.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct AppearanceCounts {
    /// Appearance themes the file names.
    pub themes: Vec<String>,
    /// Texture images the faces refer to.
    pub images: u64,
    /// Faces with a texture.
    pub textured_faces: u64,
    /// Faces with a flat colour.
    pub coloured_faces: u64,
}

/// Buildings whose heights look relative to the ground (see [`lod::relative_heights`]).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct RelativeHeightsNote {
    /// Buildings starting at z ≈ 0 although their ground attribute is not 0.
    pub buildings: usize,
    /// The attribute they carry (the `ground_attribute` to set).
    pub attribute: String,
}

/// What one file holds.
#[derive(Debug, Clone, Serialize)]
pub struct FileSurvey {
    /// The file read.
    pub file: PathBuf,
    /// The reader that read it.
    pub format: Format,
    /// The CRS the coordinates are read in (the override, else the file's; `EPSG:4978` for 3D Tiles);
    /// `None` when the file declares none and none was given (its extent in degrees is then unknown).
    pub crs: Option<String>,
    /// The CRS the file itself declares, if any.
    pub crs_declared: Option<String>,
    /// PROJ's description of the CRS and the axis order, in words.
    pub frame: String,
    /// What the third coordinate means.
    pub heights: HeightKind,
    /// Buildings read.
    pub buildings: usize,
    /// Buildings per LoD.
    pub lod: BTreeMap<String, u64>,
    /// Surfaces (polygons) of the buildings; meshes have none.
    pub polygons: u64,
    /// Triangles of the meshes, plus those the polygons make when triangulated (V + 2H − 2 each).
    pub triangles: u64,
    /// Textures and colours.
    pub appearance: AppearanceCounts,
    /// The reader's counters.
    pub stats: ReadStats,
    /// The buildings' bounding box in the file's coordinates (absent when it has no building).
    pub extent_source: Option<SourceExtent>,
    /// The buildings' bounding box in WGS84 degrees (absent when it has no building).
    pub extent_deg: Option<LonLatBox>,
    /// The first five source IDs.
    pub first_source_ids: Vec<String>,
    /// Heights that look relative to the ground; absent when none do.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub relative_heights: Option<RelativeHeightsNote>,
}

/// What a set of files holds, per file and in total.
#[derive(Debug, Clone, Serialize)]
pub struct Survey {
    /// Every file, in the order of the inputs and, within a folder or glob, sorted.
    pub files: Vec<FileSurvey>,
    /// Buildings over all files.
    pub buildings: usize,
    /// Buildings per LoD over all files.
    pub lod: BTreeMap<String, u64>,
    /// Polygons over all files.
    pub polygons: u64,
    /// Triangles over all files.
    pub triangles: u64,
    /// Texture images over all files.
    pub images: u64,
    /// The distinct CRSs of the files, in order of appearance.
    pub crs: Vec<String>,
    /// The bounding box of every building vertex, WGS84 degrees (absent without buildings).
    pub extent_deg: Option<LonLatBox>,
    /// Its centre: the default area origin of `prepare`.
    pub centre_deg: Option<LonLat>,
    /// Its west–east and south–north size through the centre, metres.
    pub size_m: Option<[f64; 2]>,
}

/// Surveys `files` (already expanded: see [`super::sources::expand`]) in parallel; the result keeps
/// their order.
///
/// # Errors
/// The first file (in order) that cannot be read ([`SceneError::Lod`]) or whose CRS cannot be placed
/// on the globe ([`SceneError::Georef`] naming the file and the CRS). A file without any CRS is no
/// error: its [`FileSurvey::crs`] is `None`.
pub fn survey(
    files: &[PathBuf],
    opts: &SurveyOptions,
    progress: &dyn Progress,
) -> Result<Survey, SceneError> {
    progress.start(files.len() as u64, "files");
    let surveyed: Result<Vec<FileSurvey>, SceneError> = files
        .par_iter()
        .map(|f| {
            let s = survey_file(f, opts);
            progress.inc(1);
            s
        })
        .collect();
    progress.finish();
    let files = surveyed?;
    let mut lod: BTreeMap<String, u64> = BTreeMap::new();
    let mut crs: Vec<String> = Vec::new();
    for f in &files {
        for (k, n) in &f.lod {
            *lod.entry(k.clone()).or_default() += n;
        }
        if let Some(c) = f.crs.as_ref().filter(|c| !crs.contains(c)) {
            crs.push(c.clone());
        }
    }
    let extent_deg = files.iter().filter_map(|f| f.extent_deg).reduce(|a, b| a.union(&b));
    Ok(Survey {
        buildings: files.iter().map(|f| f.buildings).sum(),
        lod,
        polygons: files.iter().map(|f| f.polygons).sum(),
        triangles: files.iter().map(|f| f.triangles).sum(),
        images: files.iter().map(|f| f.appearance.images).sum(),
        crs,
        centre_deg: extent_deg.map(|e| e.centre()),
        size_m: extent_deg.map(|e| e.size_m()),
        extent_deg,
        files,
    })
}

/// Reads one file and measures it.
///
/// # Errors
/// As [`survey`].
pub fn survey_file(file: &Path, opts: &SurveyOptions) -> Result<FileSurvey, SceneError> {
    let read = ReadOptions { lod: opts.lod.clone(), ..ReadOptions::default() };
    let model = lod::read_source(file, opts.format, &read)?;
    let format =
        opts.format.or_else(|| Format::from_path(file)).expect("read_source refuses unknown formats");
    let frame = SourceFrame::resolve(&model, opts.crs.as_deref())?;
    let mut lods: BTreeMap<String, u64> = BTreeMap::new();
    let (mut polygons, mut triangles) = (0u64, 0u64);
    let (mut lo, mut hi) = ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]);
    let mut extent_deg = LonLatBox::EMPTY;
    for b in &model.buildings {
        *lods.entry(b.lod.clone()).or_default() += 1;
        let points: Vec<[f64; 3]> = match &b.geometry {
            Geometry::Polygons(p) => {
                polygons += p.len() as u64;
                triangles += p.iter().map(polygon_triangles).sum::<u64>();
                p.iter()
                    .flat_map(|p| p.exterior.iter().chain(p.interiors.iter().flatten()))
                    .copied()
                    .collect()
            }
            Geometry::Mesh(m) => {
                triangles += m.triangles.len() as u64;
                m.positions.clone()
            }
        };
        for p in &points {
            for k in 0..3 {
                lo[k] = lo[k].min(p[k]);
                hi[k] = hi[k].max(p[k]);
            }
        }
        for g in frame.to_geodetic(&points, &model.path, &b.source_id)?.into_iter().flatten() {
            extent_deg.add(g.lon_deg, g.lat_deg);
        }
    }
    let has = !model.buildings.is_empty();
    let app = &model.appearance;
    Ok(FileSurvey {
        file: model.path.clone(),
        format,
        crs: frame.crs_id.clone(),
        crs_declared: match &model.frame {
            Frame::Crs { name, .. } => name.clone(),
            Frame::Ecef => Some("EPSG:4978".into()),
        },
        frame: frame.describe.clone(),
        heights: frame.heights,
        buildings: model.buildings.len(),
        lod: lods,
        polygons,
        triangles,
        appearance: AppearanceCounts {
            themes: app.themes.clone(),
            images: app.images.len() as u64,
            textured_faces: app.textured_faces,
            coloured_faces: app.coloured_faces,
        },
        stats: model.stats.clone(),
        extent_source: has.then(|| SourceExtent {
            axes: frame.axes.clone(),
            units: frame.units.clone(),
            min: lo,
            max: hi,
        }),
        extent_deg: (has && frame.crs_id.is_some()).then_some(extent_deg),
        first_source_ids: model.buildings.iter().take(5).map(|b| b.source_id.clone()).collect(),
        relative_heights: lod::relative_heights(&model)
            .map(|r| RelativeHeightsNote { buildings: r.buildings, attribute: r.attribute }),
    })
}

/// The triangles a triangulation of a simple polygon with holes has: V + 2H − 2 for V vertices in
/// all rings and H holes (Euler's formula; what earcut gives in `prepare` for a valid polygon).
pub fn polygon_triangles(p: &lod::Polygon) -> u64 {
    let v = p.exterior.len() + p.interiors.iter().map(Vec::len).sum::<usize>();
    (v + 2 * p.interiors.len()).saturating_sub(2) as u64
}

/// A file's coordinates as `prepare` reads them: ECEF, or a CRS through PROJ.
struct SourceFrame {
    /// `None`: the file declares no CRS and none was given.
    crs_id: Option<String>,
    describe: String,
    heights: HeightKind,
    axes: [String; 3],
    units: [String; 3],
    conversion: Option<(geo::CrsTransform, AxisConvention)>,
}

impl SourceFrame {
    /// The file's frame, with `over` (a source's `crs`) replacing the CRS it declares.
    fn resolve(model: &SourceModel, over: Option<&str>) -> Result<SourceFrame, SceneError> {
        let unplaced = |crs_id: Option<String>, describe: &str, heights, axes: [&str; 3]| SourceFrame {
            crs_id,
            describe: describe.into(),
            heights,
            axes: axes.map(String::from),
            units: ["metre", "metre", "metre"].map(String::from),
            conversion: None,
        };
        let (name, axes) = match (&model.frame, over) {
            (Frame::Ecef, _) => {
                let d = "EPSG:4978 (ECEF, X, Y, Z; ellipsoidal heights)";
                return Ok(unplaced(Some("EPSG:4978".into()), d, HeightKind::Ellipsoidal, ["X", "Y", "Z"]));
            }
            (Frame::Crs { axes, .. }, Some(o)) => (o.to_string(), *axes),
            (Frame::Crs { name: Some(n), axes }, None) => (n.clone(), *axes),
            (Frame::Crs { name: None, .. }, None) => {
                let d = "none declared (give one: `crs = \"EPSG:NNNN\"` in the scene file, --crs here)";
                // Orthometric: what `prepare` assumes of a projected CRS without a vertical one.
                return Ok(unplaced(None, d, HeightKind::Orthometric, ["x", "y", "z"]));
            }
        };
        let err = |e| SceneError::Georef {
            path: model.path.clone(),
            problem: Box::new(GeorefProblem::Crs { name: name.clone() }),
            source: Some(e),
        };
        let crs = Crs::parse(&name).map_err(err)?;
        let tf = crs.transform().map_err(err)?;
        let heights = crs.heights();
        let mut names: Vec<(String, String)> =
            crs.axes.iter().map(|a| (a.abbrev.clone(), a.unit.clone())).collect();
        if axes == AxisConvention::EastNorth && names.len() >= 2 && crs.axes[0].direction.starts_with("north")
        {
            names.swap(0, 1);
        }
        // A 2D CRS: the heights are metres above its (implied) vertical datum.
        names.resize(3, ("h".into(), "metre".into()));
        let axes_words = match axes {
            AxisConvention::Authority => "authority axis order",
            AxisConvention::EastNorth => "east/north axis order",
        };
        let heights_words = match heights {
            HeightKind::Orthometric => "orthometric heights",
            HeightKind::Ellipsoidal => "ellipsoidal heights",
        };
        Ok(SourceFrame {
            crs_id: Some(crs.id()),
            describe: format!("{} ({axes_words}, {heights_words})", crs.describe()),
            heights,
            axes: [names[0].0.clone(), names[1].0.clone(), names[2].0.clone()],
            units: [names[0].1.clone(), names[1].1.clone(), names[2].1.clone()],
            conversion: Some((tf, axes)),
        })
    }

    /// Latitudes and longitudes of `points` (their heights are not used); `None` without a CRS.
    fn to_geodetic(
        &self,
        points: &[[f64; 3]],
        file: &Path,
        id: &str,
    ) -> Result<Option<Vec<Geodetic>>, SceneError> {
        match &self.conversion {
            None if self.crs_id.is_none() => Ok(None),
            None => Ok(Some(points.iter().map(|&p| geo::ecef_to_geodetic(p)).collect())),
            Some((tf, axes)) => {
                tf.to_geodetic_many(points, *axes).map(Some).map_err(|e| SceneError::Georef {
                    path: file.into(),
                    problem: Box::new(GeorefProblem::Building { building: id.to_string() }),
                    source: Some(e),
                })
            }
        }
    }
}
