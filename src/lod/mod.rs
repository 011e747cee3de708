//! Readers for LoD building models, producing buildings in their *source* coordinates.
//!
//! Every reader turns one file (or one tileset) into a [`SourceModel`]: a list of [`SourceBuilding`]s,
//! each keeping its source identity (gml:id, CityJSON key, batch-table `gml_id`) and its geometry either
//! as planar polygons with holes (CityGML, CityJSON; triangulated later by [`crate::scene`]) or as a
//! triangle mesh (OBJ, 3D Tiles). Coordinates stay f64 and stay in the frame the file declares
//! ([`Frame`]); converting them to ECEF/ENU is the scene stage's job, with [`crate::geo`].
//!
//! Readers are streaming or memory-frugal: XML is read with quick-xml's pull parser (no DOM), JSON
//! into typed structs; only the geometry that is kept is held in memory.
//!
//! Formats: [`citygml`] (CityGML 2.0 incl. PLATEAU), [`cityjson`] (CityJSON 1.1/2.0, CityJSONSeq),
//! [`obj`] (Wavefront OBJ + sidecar), [`tiles3d`] (3D Tiles 1.0/1.1: b3dm, glb, Draco).

pub mod citygml;
pub mod cityjson;
pub mod error;
pub mod obj;
pub mod split;
pub mod tiles3d;

pub use error::{
    CityGmlProblem, CityJsonProblem, LodError, LodProblem, NoBuildings, ObjProblem, ParseError,
    ProceduralProblem, SyntaxProblem, TilesetIssue, TilesetProblem,
};

use std::path::{Path, PathBuf};

/// A planar polygon: one exterior ring and any number of interior rings (holes).
///
/// Rings are stored *open* (the closing vertex equal to the first is removed by the reader) and hold
/// at least 3 points; coordinates are in the model's [`Frame`], in the axis order the file uses.
#[derive(Debug, Clone, PartialEq)]
pub struct Polygon {
    /// The outer boundary (open ring, ≥ 3 points).
    pub exterior: Vec<[f64; 3]>,
    /// The holes (open rings).
    pub interiors: Vec<Vec<[f64; 3]>>,
}

/// An indexed triangle mesh (f64 positions in the model's [`Frame`]).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct TriMesh {
    /// Vertex positions in the model's frame.
    pub positions: Vec<[f64; 3]>,
    /// Triangles as indices into `positions`.
    pub triangles: Vec<[u32; 3]>,
}

/// Geometry of one building as the source gives it.
#[derive(Debug, Clone, PartialEq)]
pub enum Geometry {
    /// Boundary surfaces to be triangulated (CityGML, CityJSON).
    Polygons(Vec<Polygon>),
    /// Already triangulated (OBJ, glTF, 3D Tiles).
    Mesh(TriMesh),
}

/// One building read from a source.
#[derive(Debug, Clone, PartialEq)]
pub struct SourceBuilding {
    /// Source identity: gml:id of the `bldg:Building` (parts folded in), CityJSON key of the parent
    /// `Building`, batch-table `gml_id`, or a synthesized `"<file>#cc<N>"` for ID-less meshes.
    pub source_id: String,
    /// The LoD the geometry was taken from, as the source names it ("1", "2", "1.2", "2.2").
    pub lod: String,
    /// `measuredHeight` or an equivalent attribute when the source gives one, in metres.
    pub measured_height_m: Option<f64>,
    /// Ground (terrain) heights the source gives for the building, in metres, as (attribute, value):
    /// CityJSON attributes named in [`GROUND_ATTRIBUTES`] or containing "maaiveld", "terrain" or
    /// "ground". With heights relative to the ground (geometry starting at z ≈ 0) they are what
    /// `heights = "above_ground"` adds back; see [`relative_heights`].
    pub ground_heights_m: Vec<(String, f64)>,
    /// The building's surfaces or mesh.
    pub geometry: Geometry,
    /// The appearance of each polygon of [`Geometry::Polygons`] in the chosen theme (parallel to the
    /// polygon list; `None` = the source gives none for that face). Empty when the building has no
    /// appearance at all (and always for meshes).
    pub appearance: Vec<Option<FaceAppearance>>,
}

/// How one face looks in the source: a texture with per-vertex coordinates, or a flat colour.
///
/// From CityGML `app:ParameterizedTexture` (`textureCoordinates` per ring) and `app:X3DMaterial`
/// (`diffuseColor`), or CityJSON `appearance` (`textures` + `vertices-texture`, `materials`).
#[derive(Debug, Clone, PartialEq)]
pub enum FaceAppearance {
    /// A texture: `image` indexes [`ModelAppearance::images`]; one (u, v) per vertex of the polygon's
    /// exterior and of each of its interiors, parallel to [`Polygon::exterior`] / [`Polygon::interiors`]
    /// after the ring clean-up. Texture space as the sources define it: (0, 0) is the image's
    /// lower-left corner, v up.
    Texture {
        /// Index into [`ModelAppearance::images`].
        image: usize,
        /// (u, v) per vertex of the exterior ring.
        uv_exterior: Vec<[f64; 2]>,
        /// (u, v) per vertex of each interior ring.
        uv_interiors: Vec<Vec<[f64; 2]>>,
    },
    /// A flat diffuse colour, linear RGB in 0..=1 (X3D `diffuseColor`).
    Colour {
        /// Linear RGB, each in 0..=1.
        rgb: [f64; 3],
    },
}

/// A model's appearances: the themes found, the ones chosen, and the images faces refer to.
#[derive(Debug, Clone, Default, PartialEq, serde::Serialize)]
pub struct ModelAppearance {
    /// Every theme that holds a texture or a material, in the order the file first names them
    /// (CityJSON's unnamed theme is `""`).
    pub themes: Vec<String>,
    /// The theme textures were taken from ([`ReadOptions::theme`], else the first texture theme).
    pub texture_theme: Option<String>,
    /// The theme materials were taken from ([`ReadOptions::theme`], else the first material theme).
    pub material_theme: Option<String>,
    /// Image files, resolved against the model file's folder (they may not exist: the scene stage
    /// checks them, counts the missing ones and lets their faces keep the procedural look).
    pub images: Vec<std::path::PathBuf>,
    /// Faces of the emitted buildings with a texture / with a colour.
    pub textured_faces: u64,
    /// Faces of the emitted buildings with a colour.
    pub coloured_faces: u64,
    /// Texture targets dropped because their coordinates do not fit the ring (count mismatch) or
    /// point at no emitted face of the chosen geometry.
    pub unusable_targets: u64,
}

impl ModelAppearance {
    /// Chooses the theme of one kind: the wanted one when given (even if absent: then none), else the
    /// first of `available`.
    pub fn choose(wanted: Option<&str>, available: &[String]) -> Option<String> {
        match wanted {
            Some(w) => available.iter().find(|t| t.as_str() == w).cloned(),
            None => available.first().cloned(),
        }
    }
}

/// Attribute names of a building's ground height in the wild: `TerrainHeight` (Dutch municipal
/// models), `h_maaiveld`/`b3_h_maaiveld` (BAG/3DBAG), `groundHeight`, `ground_height`.
///
/// PLATEAU has none: i-UR (`uro:`) 2.0/3.0 `BuildingDetailAttribute/buildingHeight` and `eaveHeight`
/// are heights measured *from* the ground surface, not its elevation, and PLATEAU geometry is absolute.
pub const GROUND_ATTRIBUTES: &[&str] =
    &["TerrainHeight", "h_maaiveld", "b3_h_maaiveld", "groundHeight", "ground_height"];

/// Whether an attribute name looks like a ground height (see [`SourceBuilding::ground_heights_m`]).
pub fn is_ground_attribute(name: &str) -> bool {
    let l = name.to_ascii_lowercase();
    GROUND_ATTRIBUTES.contains(&name)
        || l.contains("maaiveld")
        || l.contains("terrain")
        || l.contains("ground")
}

/// Buildings whose heights look relative to the ground: see [`relative_heights`].
#[derive(Debug, Clone, PartialEq)]
pub struct RelativeHeights {
    /// Buildings whose lowest vertex is within [`RELATIVE_BASE_M`] of z = 0 while their ground
    /// attribute is farther than that from 0.
    pub buildings: usize,
    /// Buildings that carry a ground attribute at all.
    pub with_ground_attribute: usize,
    /// The attribute most of them carry.
    pub attribute: String,
}

/// How close to z = 0 (metres) a building's lowest vertex must be to count as starting at the ground
/// of a relative-height model.
pub const RELATIVE_BASE_M: f64 = 0.5;

/// Detects heights given above the ground: buildings whose geometry starts at z ≈ 0 (within
/// [`RELATIVE_BASE_M`]) although they carry a ground attribute that is not ≈ 0 (e.g. `TerrainHeight`
/// = 2.4 m in a Dutch municipal model). `None` when no building looks like that.
pub fn relative_heights(model: &SourceModel) -> Option<RelativeHeights> {
    let mut counts: std::collections::BTreeMap<&str, usize> = std::collections::BTreeMap::new();
    let (mut relative, mut with_attr) = (0, 0);
    for b in &model.buildings {
        let Some((name, ground_m)) = b.ground_heights_m.first() else { continue };
        with_attr += 1;
        let min_z = match &b.geometry {
            Geometry::Polygons(ps) => ps
                .iter()
                .flat_map(|p| p.exterior.iter().chain(p.interiors.iter().flatten()))
                .map(|p| p[2])
                .fold(f64::INFINITY, f64::min),
            Geometry::Mesh(m) => m.positions.iter().map(|p| p[2]).fold(f64::INFINITY, f64::min),
        };
        if min_z.abs() < RELATIVE_BASE_M && ground_m.abs() >= RELATIVE_BASE_M {
            relative += 1;
            *counts.entry(name.as_str()).or_default() += 1;
        }
    }
    let attribute = counts.iter().max_by_key(|(_, n)| **n)?.0.to_string();
    Some(RelativeHeights { buildings: relative, with_ground_attribute: with_attr, attribute })
}

/// Which frame a model's coordinates are in.
#[derive(Debug, Clone, PartialEq)]
pub enum Frame {
    /// A coordinate reference system as the file names it (e.g. `"EPSG:6697"`,
    /// `"urn:ogc:def:crs:EPSG::7415"`, `"http://www.opengis.net/def/crs/EPSG/0/28992"`), or `None` when
    /// the file declares none (the scene file must then give `crs`). Axis order: see [`AxisConvention`].
    Crs {
        /// The CRS as the file names it; `None` when it declares none.
        name: Option<String>,
        /// The axis order of the coordinates.
        axes: AxisConvention,
    },
    /// Earth-centred, earth-fixed metres (EPSG:4978), as 3D Tiles use after tile transforms.
    Ecef,
}

pub use crate::geo::AxisConvention;

/// Counters a reader reports besides the buildings.
#[derive(Debug, Clone, Default, PartialEq, serde::Serialize)]
pub struct ReadStats {
    /// City objects seen that are not buildings (roads, water, …) and were skipped.
    pub skipped_non_building: u64,
    /// Buildings without any geometry at the chosen LoD (skipped, counted).
    pub buildings_without_geometry: u64,
    /// Faces dropped as degenerate by the reader (rings with < 3 distinct points, zero area).
    pub degenerate_faces: u64,
    /// Triangles or polygons read.
    pub faces: u64,
    /// Coordinates that are not finite or beyond ±[`MAX_ABS_COORDINATE`] in objects that were *not*
    /// read (non-building objects, unused vertices): reported with a warning, since nothing built
    /// from the file uses them. Such a coordinate in a building is an error.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub bad_coordinates_unused: u64,
    /// Faces dropped as degenerate in geometry that was not chosen (e.g. a LoD0 footprint of a
    /// building read at LoD2): reported with a warning.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub degenerate_faces_unused: u64,
}

fn is_zero(n: &u64) -> bool {
    *n == 0
}

/// What one reader produced from one source.
#[derive(Debug, Clone, PartialEq)]
pub struct SourceModel {
    /// The file (or tileset.json) that was read.
    pub path: PathBuf,
    /// The frame the coordinates are in.
    pub frame: Frame,
    /// The buildings read, in file order.
    pub buildings: Vec<SourceBuilding>,
    /// What the reader counted besides the buildings.
    pub stats: ReadStats,
    /// Appearances (themes, images) the buildings' [`SourceBuilding::appearance`] refer to.
    pub appearance: ModelAppearance,
}

/// The formats insgen reads.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Format {
    /// CityGML 1.0/2.0/3.0 (`.gml`, `.xml`).
    CityGml,
    /// CityJSON 1.x/2.x and CityJSONSeq (`.json`, `.city.json`, `.jsonl`).
    CityJson,
    /// Wavefront OBJ with a JSON sidecar (CRS, offset, axes).
    Obj,
    /// 3D Tiles: a `tileset.json` or one `.b3dm`/`.glb`/`.cmpt` content.
    #[serde(rename = "3dtiles")]
    Tiles3d,
}

impl Format {
    /// Guesses the format from a file name: `.gml`/`.xml` → CityGML, `.json` (not `tileset.json`) and
    /// `.jsonl` → CityJSON, `.obj` → OBJ, `tileset.json`/`.b3dm`/`.glb` → 3D Tiles.
    pub fn from_path(path: &Path) -> Option<Format> {
        let name = path.file_name()?.to_str()?.to_ascii_lowercase();
        if name.ends_with(".gml") || name.ends_with(".xml") {
            Some(Format::CityGml)
        } else if name.starts_with("tileset") && name.ends_with(".json")
            || name.ends_with(".b3dm")
            || name.ends_with(".glb")
        {
            Some(Format::Tiles3d)
        } else if name.ends_with(".json") || name.ends_with(".jsonl") {
            Some(Format::CityJson)
        } else if name.ends_with(".obj") {
            Some(Format::Obj)
        } else {
            None
        }
    }
}

/// Reader options shared by all formats.
#[derive(Debug, Clone, Default)]
pub struct ReadOptions {
    /// For meshes without building IDs (OBJ, ID-less glTF): weld vertices closer than this (metres)
    /// before splitting the mesh into connected components; `None` = connect by shared indices only.
    pub weld_tolerance_m: Option<f64>,
    /// LoD to take (e.g. "2", "1.2"); `None` picks the format's default (the highest available LoD
    /// that is ≤ 2.2 for CityJSON; LoD2 then LoD1 for CityGML).
    pub lod: Option<String>,
    /// Appearance theme to take textures and materials from (CityGML `app:theme`, CityJSON theme
    /// name); `None` takes the first theme the file names for each kind.
    pub theme: Option<String>,
    /// Skip appearances altogether (faces get no texture or colour).
    pub no_appearance: bool,
    /// Skip materials (flat colours) but keep textures.
    pub no_materials: bool,
}

impl ReadOptions {
    /// Checks the weld tolerance before a mesh reader uses it; `path` is the file being read.
    ///
    /// # Errors
    /// [`LodError::WeldTolerance`] when it is negative or not finite.
    pub fn check_weld_tolerance(&self, path: &Path) -> Result<(), LodError> {
        match self.weld_tolerance_m {
            Some(t) if !(t.is_finite() && t >= 0.0) => {
                Err(LodError::WeldTolerance { path: path.to_path_buf(), tolerance_m: t })
            }
            _ => Ok(()),
        }
    }
}

/// Reads one source in the given (or guessed) format.
///
/// # Errors
/// [`LodError`] naming the file and what is wrong with it.
pub fn read_source(path: &Path, format: Option<Format>, opts: &ReadOptions) -> Result<SourceModel, LodError> {
    let format = match format.or_else(|| Format::from_path(path)) {
        Some(f) => f,
        None => return Err(LodError::UnknownFormat { path: path.to_path_buf() }),
    };
    match format {
        Format::CityGml => citygml::read(path, opts),
        Format::CityJson => cityjson::read(path, opts),
        Format::Obj => obj::read(path, opts),
        Format::Tiles3d => tiles3d::read(path, opts),
    }
}

/// What the first bytes of a file look like, for messages about a file given in the wrong format
/// (`"JSON"`, `"XML"`, `"a glTF binary (glb)"`, …).
pub fn sniff(head: &[u8]) -> &'static str {
    let head = head.strip_prefix(b"\xEF\xBB\xBF").unwrap_or(head);
    let text = head.iter().position(|b| !b.is_ascii_whitespace()).map_or(&[][..], |i| &head[i..]);
    if head.is_empty() {
        return "empty";
    }
    if head.starts_with(b"glTF") {
        return "a glTF binary (glb)";
    }
    if head.starts_with(b"b3dm")
        || head.starts_with(b"cmpt")
        || head.starts_with(b"i3dm")
        || head.starts_with(b"pnts")
    {
        return "a 3D Tiles content (b3dm/cmpt/i3dm/pnts)";
    }
    if head.starts_with(&[0x1f, 0x8b]) {
        return "gzip-compressed data";
    }
    let probe = &head[..head.len().min(512)];
    if probe.contains(&0)
        || std::str::from_utf8(probe).is_err()
            && std::str::from_utf8(&probe[..probe.len().saturating_sub(4)]).is_err()
    {
        return "binary data";
    }
    match text.first() {
        None => "only white space",
        Some(b'{') | Some(b'[') => "JSON",
        Some(b'<') => "XML",
        Some(_) if text.starts_with(b"v ") || text.starts_with(b"mtllib") || text.starts_with(b"o ") => {
            "a Wavefront OBJ"
        }
        Some(_) => "text",
    }
}

/// A [`LodError::Malformed`] for a file that is not `expected` at all ("not JSON", "not XML"), naming
/// what it looks like instead and, when that is another format insgen reads, how to read it as that.
pub(crate) fn wrong_format(path: &Path, expected: &'static str, document: &'static str) -> LodError {
    let looks = sniff(&head_of(path, 512));
    LodError::malformed(path, error::SyntaxProblem::WrongFormat { expected, looks, document })
}

/// The first bytes of a file (at most `n`), for [`sniff`]; empty when unreadable.
pub(crate) fn head_of(path: &Path, n: usize) -> Vec<u8> {
    use std::io::Read;
    let mut buf = Vec::with_capacity(n);
    if let Ok(f) = std::fs::File::open(path) {
        let _ = f.take(n as u64).read_to_end(&mut buf);
    }
    buf
}

/// Largest coordinate magnitude a reader accepts, in source units (metres or degrees): anything
/// beyond is a corrupt value (e.g. `1e300`), not a place on Earth.
pub const MAX_ABS_COORDINATE: f64 = 1e9;

/// [`clean_ring`] as indices: which points of `points` the cleaned ring keeps, in order (so that
/// per-vertex data such as texture coordinates can follow), or `None` when the ring is degenerate.
/// `clean_ring(points)` equals the points at these indices.
pub fn clean_ring_indices(points: &[[f64; 3]]) -> Option<Vec<usize>> {
    let mut keep: Vec<usize> = Vec::with_capacity(points.len());
    for (i, p) in points.iter().enumerate() {
        if keep.last().is_none_or(|&k| points[k] != *p) {
            keep.push(i);
        }
    }
    while keep.len() > 1 && points[keep[0]] == points[keep[keep.len() - 1]] {
        keep.pop();
    }
    clean_ring(keep.iter().map(|&i| points[i]).collect())?;
    Some(keep)
}

/// Cleans one ring as read from a file: removes the closing vertex (equal to the first) and
/// consecutive duplicates (exact equality, wrap-around included).
///
/// Returns `None` when the ring is degenerate: fewer than 3 distinct points left, or zero area, i.e.
/// twice its vector area (Newell's method, relative to the first vertex) is within rounding noise,
/// `1e-12·L² + 64·ε·M·L` where `L` is the ring's largest distance from its first vertex and `M` its
/// largest coordinate magnitude. The test works in any units (metres, degrees, or both mixed as in
/// EPSG:6697 latitude/longitude/height).
pub fn clean_ring(mut points: Vec<[f64; 3]>) -> Option<Vec<[f64; 3]>> {
    points.dedup();
    while points.len() > 1 && points.first() == points.last() {
        points.pop();
    }
    if points.len() < 3 {
        return None;
    }
    let p0 = points[0];
    let rel = |p: &[f64; 3]| [p[0] - p0[0], p[1] - p0[1], p[2] - p0[2]];
    let mut normal = [0.0_f64; 3];
    let mut reach_sq = 0.0_f64;
    let mut magnitude = 0.0_f64;
    for (i, p) in points.iter().enumerate() {
        let a = rel(p);
        let b = rel(&points[(i + 1) % points.len()]);
        normal[0] += a[1] * b[2] - a[2] * b[1];
        normal[1] += a[2] * b[0] - a[0] * b[2];
        normal[2] += a[0] * b[1] - a[1] * b[0];
        reach_sq = reach_sq.max(a[0] * a[0] + a[1] * a[1] + a[2] * a[2]);
        magnitude = magnitude.max(p[0].abs()).max(p[1].abs()).max(p[2].abs());
    }
    let twice_area = (normal[0] * normal[0] + normal[1] * normal[1] + normal[2] * normal[2]).sqrt();
    let reach = reach_sq.sqrt();
    let noise = 1e-12 * reach_sq + 64.0 * f64::EPSILON * magnitude * reach;
    // NaN area (from non-finite input) counts as degenerate too.
    if twice_area.is_nan() || twice_area <= noise {
        return None;
    }
    Some(points)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `clean_ring_indices` keeps exactly the points `clean_ring` keeps (closing vertex, consecutive
    /// duplicates, wrap-around duplicates), so per-vertex data can follow them.
    #[test]
    fn clean_ring_indices_agree_with_clean_ring() {
        let a = [0.0, 0.0, 0.0];
        let b = [1.0, 0.0, 0.0];
        let c = [1.0, 1.0, 0.0];
        let d = [0.0, 1.0, 0.0];
        let cases: Vec<Vec<[f64; 3]>> = vec![
            vec![a, b, c, d, a],
            vec![a, a, b, b, c, d, d, a, a],
            vec![a, b, c, d],
            vec![a, b, a],
            vec![a, b, [2.0, 0.0, 0.0], a],
        ];
        for ring in cases {
            let by_index = clean_ring_indices(&ring).map(|k| k.iter().map(|&i| ring[i]).collect::<Vec<_>>());
            assert_eq!(by_index, clean_ring(ring.clone()), "{ring:?}");
        }
        assert_eq!(clean_ring_indices(&[a, a, b, b, c, d, d, a, a]), Some(vec![0, 2, 4, 5]));
    }
}
