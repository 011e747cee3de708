//! CityJSON 1.1 / 2.0 and CityJSONSeq reader: `Building` objects → [`SourceBuilding`] polygons.
//!
//! Takes one `.json` file (a CityJSON document) or one `.jsonl` file (CityJSONSeq: a `CityJSON`
//! header line with `transform`/`metadata`, then one `CityJSONFeature` per line, each with its own
//! vertices) and hands on a [`SourceModel`] in the file's CRS, easting first
//! ([`AxisConvention::EastNorth`]).
//!
//! The JSON is deserialised into typed structs that mirror the spec (no `serde_json::Value` for the
//! document): vertices as `[f64; 3]`, geometry boundaries as a compact flat form (every vertex index
//! once as `u32`, plus one child count per array), attributes other than `measuredHeight` skipped.
//! CityJSONSeq is read line by line, so memory is proportional to one feature.
//!
//! What is read:
//! - `Building` objects; their `BuildingPart` and `BuildingInstallation` descendants (through
//!   `children` and `parents`, recursively) are folded into them and share the Building's key.
//!   Interior objects (rooms, storeys, units, furniture, constructive elements) are ignored; all
//!   other city objects are counted in [`ReadStats::skipped_non_building`]. A part without any
//!   Building ancestor is read as a building of its own (with a warning);
//! - geometry types `MultiSurface`, `CompositeSurface`, `Solid`, `MultiSolid`, `CompositeSolid` and
//!   `GeometryInstance` (a template from `geometry-templates`, transformed by its
//!   `transformationMatrix` and placed at its reference point); points and lines are ignored;
//! - `transform` (`scale`, `translate`) turns the quantised vertices into coordinates;
//!   `metadata.referenceSystem` is kept verbatim as the frame name (absent → `None`);
//! - `attributes.measuredHeight` of the Building (metres);
//! - `appearance` of a document or CityJSONSeq header (`textures` → the model's images, resolved
//!   against the file's folder; `materials[].diffuseColor`; `vertices-texture`) and each geometry's
//!   `texture` / `material` values (nested like the boundaries; `value` for all surfaces). Theme:
//!   [`ReadOptions::theme`], else the first theme of each kind in file order. Texture coordinates follow
//!   the ring clean-up ([`super::clean_ring_indices`]); a texture value that does not fit its ring is
//!   counted ([`super::ModelAppearance::unusable_targets`]). Appearances of geometry templates and of
//!   individual CityJSONSeq features are not read.
//!
//! LoD choice: [`ReadOptions::lod`] forces one (exact match, `"2"` equals `"2.0"`; a building lacking
//! it counts as without geometry). By default each building gets the highest LoD in [1, 2.2] it has
//! usable geometry for, or its LoD0 (footprint, roof edges: flat) when it has nothing better; a part
//! lacking that LoD contributes its best lower one. The chosen LoD is reported as the file spells it.
//! Degenerate faces of geometry that was not chosen are counted in
//! [`ReadStats::degenerate_faces_unused`] with a warning, and unusable coordinates (non-finite,
//! |v| > 1e9) that no building uses in [`ReadStats::bad_coordinates_unused`], also with a warning.
//!
//! Checks: rings lose their closing vertex and consecutive duplicates; degenerate rings (< 3
//! distinct points, zero area) are dropped ([`ReadStats::degenerate_faces`]; a degenerate hole is
//! dropped alone). A vertex index out of range, a non-finite or absurd (|v| > 1e9) coordinate, or a
//! boundary array nested to the wrong depth for its type is an [`LodError::Invalid`] with the JSON
//! path (`CityObjects["id"].geometry[0].boundaries[0][2][0][3]`); truncated or malformed JSON is an
//! [`LodError::Malformed`] with line and column.

use std::collections::BTreeMap;
use std::fmt;
use std::fs::File;
use std::io::{BufRead, BufReader};
use std::path::Path;

use serde::de::{self, DeserializeSeed, Deserializer, MapAccess, SeqAccess, Visitor};
use serde::Deserialize;

use super::error::{short, CityJsonProblem, NoBuildings, SyntaxProblem};
use super::{
    clean_ring_indices, AxisConvention, FaceAppearance, Frame, Geometry, LodError, ModelAppearance, Polygon,
    ReadOptions, ReadStats, SourceBuilding, SourceModel, MAX_ABS_COORDINATE,
};
use crate::util::FileError;

/// Highest LoD the default choice takes (CityJSON LoDs are "1", "1.2", "2.2", …).
pub(crate) const MAX_DEFAULT_LOD: f64 = 2.2;
/// Lowest LoD the default choice prefers; LoD0 (flat footprints, roof edges) is taken only for a
/// building that has nothing in [1, 2.2] (or with `lod = "0"`).
pub(crate) const MIN_DEFAULT_LOD: f64 = 1.0;

/// Reads one CityJSON (`.json`) or CityJSONSeq (`.jsonl`) file.
///
/// A file with another extension that turns out to hold one JSON object per line is read as
/// CityJSONSeq too.
///
/// # Errors
/// - [`LodError::File`] if the file cannot be opened or read;
/// - [`LodError::Malformed`] for truncated or malformed JSON (line and column) or JSON of the wrong
///   shape (e.g. a vertex with two numbers);
/// - [`LodError::Invalid`] with a JSON path for a vertex index out of range, a non-finite or absurd
///   coordinate, a boundary array of the wrong depth, an unknown geometry type, a duplicate object
///   key, a file that is not CityJSON 1.x/2.x, or a file without any building that has usable
///   geometry.
pub fn read(path: &Path, opts: &ReadOptions) -> Result<SourceModel, LodError> {
    let name = path.file_name().map(|n| n.to_string_lossy().to_ascii_lowercase()).unwrap_or_default();
    let mut reader = Reader::new(path, opts);
    if super::sniff(&super::head_of(path, 512)) != "JSON" {
        return Err(super::wrong_format(path, "JSON", "a CityJSON document"));
    }
    if name.ends_with(".jsonl") {
        reader.read_seq()?;
    } else {
        let file = File::open(path).map_err(|e| FileError::new("opening", path, e))?;
        let parsed: Result<Document, _> = serde_json::from_reader(BufReader::with_capacity(1 << 16, file));
        match parsed {
            Ok(doc) => reader.read_document(doc)?,
            // One complete object followed by more JSON: a CityJSONSeq under another name.
            Err(e) if e.is_syntax() && e.line() > 1 && e.to_string().starts_with("trailing characters") => {
                reader.read_seq()?
            }
            Err(e) => return Err(json_error(path, None, e)),
        }
    }
    reader.finish()
}

// ------------------------------------------------------------------------------------------------
// Types mirroring the spec
// ------------------------------------------------------------------------------------------------

/// A CityJSON document, a CityJSONSeq header line, or a `CityJSONFeature` line.
#[derive(Debug, Deserialize)]
struct Document {
    /// `"CityJSON"` (document or Seq header) or `"CityJSONFeature"`.
    #[serde(rename = "type")]
    kind: String,
    /// Spec version, e.g. `"2.0"` (documents and headers only).
    version: Option<String>,
    /// Quantisation: coordinate = vertex · scale + translate.
    transform: Option<Transform>,
    metadata: Option<Metadata>,
    /// The city objects, in file order.
    #[serde(rename = "CityObjects", default)]
    city_objects: CityObjects,
    /// Vertex list (integers when `transform` is given).
    #[serde(default)]
    vertices: Vec<[f64; 3]>,
    #[serde(rename = "geometry-templates")]
    geometry_templates: Option<Templates>,
    /// Materials, textures and texture coordinates the geometries' `material`/`texture` refer to.
    appearance: Option<CjAppearance>,
}

/// `appearance`: the shared lists the geometries index into.
#[derive(Debug, Default, Deserialize)]
struct CjAppearance {
    #[serde(default)]
    materials: Vec<CjMaterial>,
    #[serde(default)]
    textures: Vec<CjTexture>,
    /// (u, v) pairs, indexed by the texture values of the geometries.
    #[serde(rename = "vertices-texture", default)]
    vertices_texture: Vec<[f64; 2]>,
}

/// One X3D-like material (only the colour is used).
#[derive(Debug, Deserialize)]
struct CjMaterial {
    /// Linear RGB in 0..=1.
    #[serde(rename = "diffuseColor")]
    diffuse_color: Option<[f64; 3]>,
}

/// One texture: an image file (relative to the CityJSON file, or a URL).
#[derive(Debug, Deserialize)]
struct CjTexture {
    image: String,
}

/// A geometry's `material` or `texture` member: theme name → values, in file order.
#[derive(Debug, Default)]
struct Themed(Vec<(String, ThemeValues)>);

/// One theme of a geometry: `values` (nested like the boundaries) or one `value` for every surface.
#[derive(Debug, Deserialize)]
struct ThemeValues {
    #[serde(default)]
    values: Option<serde_json::Value>,
    #[serde(default)]
    value: Option<u64>,
}

impl<'de> Deserialize<'de> for Themed {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct V;
        impl<'de> Visitor<'de> for V {
            type Value = Themed;
            fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
                f.write_str("an object of themes")
            }
            fn visit_map<A: MapAccess<'de>>(self, mut map: A) -> Result<Themed, A::Error> {
                let mut out = Vec::new();
                while let Some((k, v)) = map.next_entry::<String, ThemeValues>()? {
                    out.push((k, v));
                }
                Ok(Themed(out))
            }
        }
        d.deserialize_map(V)
    }
}

/// `transform`: real coordinate = `vertex[i] · scale[i] + translate[i]`.
#[derive(Debug, Clone, Copy, Deserialize)]
struct Transform {
    scale: [f64; 3],
    translate: [f64; 3],
}

/// The part of `metadata` this reader uses.
#[derive(Debug, Deserialize)]
struct Metadata {
    /// CRS as a URL (`https://www.opengis.net/def/crs/EPSG/0/7415`) or, in 1.0, an OGC URN.
    #[serde(rename = "referenceSystem")]
    reference_system: Option<String>,
}

/// `geometry-templates`: template geometries over their own (real-valued, untransformed) vertices.
#[derive(Debug, Deserialize)]
struct Templates {
    #[serde(default)]
    templates: Vec<CjGeometry>,
    #[serde(rename = "vertices-templates", default)]
    vertices: Vec<[f64; 3]>,
}

/// One city object.
#[derive(Debug, Deserialize)]
struct CityObject {
    /// `"Building"`, `"BuildingPart"`, `"Road"`, `"+Extension"`, …
    #[serde(rename = "type")]
    kind: String,
    #[serde(default)]
    geometry: Vec<CjGeometry>,
    #[serde(default)]
    parents: Vec<String>,
    #[serde(default)]
    children: Vec<String>,
    attributes: Option<Attributes>,
}

/// The attributes this reader uses.
#[derive(Debug, Deserialize)]
struct Attributes {
    /// Building height in metres (a number, or a numeric string in some exports).
    #[serde(rename = "measuredHeight")]
    measured_height: Option<serde_json::Value>,
    /// Every other attribute; only ground heights ([`super::is_ground_attribute`]) are kept.
    #[serde(flatten)]
    other: BTreeMap<String, serde_json::Value>,
}

/// One geometry object.
#[derive(Debug, Deserialize)]
struct CjGeometry {
    /// `"Solid"`, `"MultiSurface"`, `"GeometryInstance"`, …
    #[serde(rename = "type")]
    kind: String,
    /// Level of detail ("1", "1.2", "2.2"; a number in CityJSON 1.0). Absent on instances.
    lod: Option<LodValue>,
    boundaries: Option<Boundaries>,
    /// `GeometryInstance`: index into `geometry-templates.templates`.
    template: Option<u64>,
    /// `GeometryInstance`: 4×4 row-major matrix applied to the template vertices.
    #[serde(rename = "transformationMatrix")]
    transformation_matrix: Option<Vec<f64>>,
    /// Material per surface, per theme.
    #[serde(default)]
    material: Themed,
    /// Texture and texture coordinates per ring, per theme.
    #[serde(default)]
    texture: Themed,
}

/// A `lod` value, kept as the file spells it.
#[derive(Debug, Clone, PartialEq)]
struct LodValue(String);

impl LodValue {
    fn number(&self) -> Option<f64> {
        self.0.trim().parse::<f64>().ok().filter(|v| v.is_finite())
    }
    /// Exact match for a forced LoD: the same number (`"2"` = `"2.0"`) or the same text.
    fn matches(&self, wanted: &str) -> bool {
        match (self.number(), wanted.trim().parse::<f64>()) {
            (Some(a), Ok(b)) => a == b,
            _ => self.0.trim() == wanted.trim(),
        }
    }
}

impl<'de> Deserialize<'de> for LodValue {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct V;
        impl Visitor<'_> for V {
            type Value = LodValue;
            fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
                f.write_str("a LoD as a string (\"2.2\") or a number")
            }
            fn visit_str<E: de::Error>(self, v: &str) -> Result<LodValue, E> {
                Ok(LodValue(v.to_string()))
            }
            fn visit_u64<E: de::Error>(self, v: u64) -> Result<LodValue, E> {
                Ok(LodValue(v.to_string()))
            }
            fn visit_i64<E: de::Error>(self, v: i64) -> Result<LodValue, E> {
                Ok(LodValue(v.to_string()))
            }
            fn visit_f64<E: de::Error>(self, v: f64) -> Result<LodValue, E> {
                Ok(LodValue(v.to_string()))
            }
        }
        d.deserialize_any(V)
    }
}

/// `CityObjects` in file order (a JSON object; duplicate keys are kept so they can be reported).
#[derive(Debug, Default)]
struct CityObjects(Vec<(String, CityObject)>);

impl<'de> Deserialize<'de> for CityObjects {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct V;
        impl<'de> Visitor<'de> for V {
            type Value = CityObjects;
            fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
                f.write_str("an object of city objects")
            }
            fn visit_map<A: MapAccess<'de>>(self, mut map: A) -> Result<CityObjects, A::Error> {
                let mut out = Vec::with_capacity(map.size_hint().unwrap_or(0));
                while let Some((k, v)) = map.next_entry::<String, CityObject>()? {
                    out.push((k, v));
                }
                Ok(CityObjects(out))
            }
        }
        d.deserialize_map(V)
    }
}

/// A `boundaries` array of any depth in a compact flat form.
///
/// `counts[d]` lists, for every array at nesting depth `d` in document order, how many elements it
/// holds (depth 0 is `boundaries` itself); `leaves` holds all vertex indices in order; `leaf_depth`
/// is the depth of the arrays that hold indices. A consistent array (indices at one depth only,
/// never mixed with arrays) can be walked back from this form.
#[derive(Debug, Default)]
struct Boundaries {
    counts: Vec<Vec<u32>>,
    leaves: Vec<u32>,
    leaf_depth: Option<usize>,
}

impl<'de> Deserialize<'de> for Boundaries {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        let mut b = Boundaries::default();
        d.deserialize_seq(ArrayVisitor { depth: 0, b: &mut b })?;
        Ok(b)
    }
}

/// Deepest boundary nesting accepted (MultiSolid/CompositeSolid need 5 levels of arrays).
const MAX_BOUNDARY_DEPTH: usize = 8;

struct ArrayVisitor<'a> {
    depth: usize,
    b: &'a mut Boundaries,
}

impl<'de> Visitor<'de> for ArrayVisitor<'_> {
    type Value = ();
    fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
        f.write_str("an array of vertex indices, or of such arrays")
    }
    fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<(), A::Error> {
        let (depth, b) = (self.depth, self.b);
        if depth >= MAX_BOUNDARY_DEPTH {
            return Err(de::Error::custom(format!(
                "boundaries are nested deeper than {MAX_BOUNDARY_DEPTH} levels"
            )));
        }
        if b.counts.len() <= depth {
            b.counts.resize_with(depth + 1, Vec::new);
        }
        let slot = b.counts[depth].len();
        b.counts[depth].push(0);
        let mut seen = (false, false); // (indices, arrays)
        let mut n = 0u32;
        while seq.next_element_seed(Element { depth, b: &mut *b, seen: &mut seen })?.is_some() {
            n += 1;
        }
        b.counts[depth][slot] = n;
        Ok(())
    }
}

/// One element of a boundary array: a vertex index or a nested array.
struct Element<'a> {
    depth: usize,
    b: &'a mut Boundaries,
    seen: &'a mut (bool, bool),
}

impl<'de> DeserializeSeed<'de> for Element<'_> {
    type Value = ();
    fn deserialize<D: Deserializer<'de>>(self, d: D) -> Result<(), D::Error> {
        d.deserialize_any(self)
    }
}

impl<'de> Visitor<'de> for Element<'_> {
    type Value = ();
    fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
        f.write_str("a vertex index (a non-negative integer) or an array")
    }
    fn visit_u64<E: de::Error>(self, v: u64) -> Result<(), E> {
        if self.seen.1 {
            return Err(E::custom("a boundary array mixes vertex indices and arrays"));
        }
        self.seen.0 = true;
        match self.b.leaf_depth {
            None => self.b.leaf_depth = Some(self.depth),
            Some(d) if d != self.depth => {
                return Err(E::custom(format!(
                    "vertex indices at two nesting depths ({d} and {}) in one boundaries array",
                    self.depth
                )))
            }
            Some(_) => {}
        }
        let v = u32::try_from(v).map_err(|_| E::custom(format!("vertex index {v} is too large")))?;
        self.b.leaves.push(v);
        Ok(())
    }
    fn visit_i64<E: de::Error>(self, v: i64) -> Result<(), E> {
        match u64::try_from(v) {
            Ok(u) => self.visit_u64(u),
            Err(_) => Err(E::custom(format!("vertex index {v} is negative"))),
        }
    }
    fn visit_f64<E: de::Error>(self, v: f64) -> Result<(), E> {
        Err(E::custom(format!("vertex index {v} is not an integer")))
    }
    fn visit_seq<A: SeqAccess<'de>>(self, seq: A) -> Result<(), A::Error> {
        if self.seen.0 {
            return Err(de::Error::custom("a boundary array mixes vertex indices and arrays"));
        }
        self.seen.1 = true;
        ArrayVisitor { depth: self.depth + 1, b: self.b }.visit_seq(seq)
    }
}

/// Walks a [`Boundaries`] back in document order.
struct Walker<'a> {
    b: &'a Boundaries,
    next: Vec<usize>,
    next_leaf: usize,
}

impl<'a> Walker<'a> {
    fn new(b: &'a Boundaries) -> Self {
        Walker { b, next: vec![0; b.counts.len().max(1)], next_leaf: 0 }
    }
    /// Number of elements of the next array at `depth`.
    fn take(&mut self, depth: usize) -> usize {
        let n = self.b.counts.get(depth).and_then(|c| c.get(self.next[depth])).copied().unwrap_or(0);
        if depth < self.next.len() {
            self.next[depth] += 1;
        }
        n as usize
    }
    fn leaves(&mut self, n: usize) -> &'a [u32] {
        let start = self.next_leaf.min(self.b.leaves.len());
        let end = (start + n).min(self.b.leaves.len());
        self.next_leaf = end;
        &self.b.leaves[start..end]
    }
}

// ------------------------------------------------------------------------------------------------
// Reading
// ------------------------------------------------------------------------------------------------

/// Building-family types folded into their Building.
fn is_folded_part(kind: &str) -> bool {
    matches!(kind, "BuildingPart" | "BuildingInstallation")
}

/// Building-family types whose geometry is ignored (interior or structural detail).
fn is_ignored_building_detail(kind: &str) -> bool {
    matches!(
        kind,
        "BuildingRoom"
            | "BuildingStorey"
            | "BuildingUnit"
            | "BuildingFurniture"
            | "BuildingConstructiveElement"
    )
}

/// Where vertices come from and how to make them coordinates.
struct VertexSource<'a> {
    vertices: &'a [[f64; 3]],
    transform: Option<Transform>,
    /// Name of the vertex list in messages (`vertices`, `vertices-templates`).
    list_name: &'static str,
}

impl VertexSource<'_> {
    fn get(&self, index: u32) -> Option<[f64; 3]> {
        let v = self.vertices.get(index as usize)?;
        Some(match self.transform {
            Some(t) => [
                v[0] * t.scale[0] + t.translate[0],
                v[1] * t.scale[1] + t.translate[1],
                v[2] * t.scale[2] + t.translate[2],
            ],
            None => *v,
        })
    }
}

/// The faces a building keeps at its chosen LoD.
#[derive(Default)]
struct Faces {
    polygons: Vec<Polygon>,
    appearance: Vec<Option<FaceAppearance>>,
    /// Faces of the chosen LoD dropped as degenerate.
    degenerate: u64,
    /// The LoD as the file spells it (a forced "2.0" may match the file's "2").
    lod_name: Option<String>,
}

/// Whether a converted geometry has at least one usable polygon.
fn usable(c: &Converted) -> bool {
    c.polygons.iter().any(|p| p.is_ok())
}

/// Whether a converted geometry's LoD is a number in `[lo, MAX_DEFAULT_LOD]`.
fn lod_in_range(c: &Converted, lo: f64) -> bool {
    c.lod.number().is_some_and(|v| (lo..=MAX_DEFAULT_LOD).contains(&v))
}

/// A number attribute that may be written as a string (`"12.5"`).
fn attribute_number(v: &serde_json::Value) -> Option<f64> {
    match v {
        serde_json::Value::Number(n) => n.as_f64(),
        serde_json::Value::String(s) => s.trim().parse::<f64>().ok(),
        _ => None,
    }
}

/// The object's finite `measuredHeight` attribute, metres.
fn measured_height_m(obj: &CityObject) -> Option<f64> {
    obj.attributes
        .as_ref()
        .and_then(|a| a.measured_height.as_ref())
        .and_then(|v| attribute_number(v).filter(|h| h.is_finite()))
}

/// The object's plausible ground-height attributes (name, metres; finite, |h| < 10 km).
fn ground_heights_m(obj: &CityObject) -> Vec<(String, f64)> {
    obj.attributes
        .iter()
        .flat_map(|a| a.other.iter())
        .filter(|(k, _)| super::is_ground_attribute(k))
        .filter_map(|(k, v)| {
            attribute_number(v).filter(|h| h.is_finite() && h.abs() < 1e4).map(|h| (k.clone(), h))
        })
        .collect()
}

/// One geometry turned into polygons (`Err(())` = dropped as degenerate).
struct Converted {
    lod: LodValue,
    polygons: Vec<Result<Polygon, ()>>,
    /// The appearance of each polygon in the chosen themes (parallel to `polygons`).
    appearance: Vec<Option<FaceAppearance>>,
}

/// The chosen themes' values of one geometry, flattened to one entry per surface (document order).
#[derive(Default)]
struct GeomAppearance<'a> {
    /// Per surface: its rings' `[texture index, uv index, …]` arrays.
    textures: Option<Vec<&'a serde_json::Value>>,
    /// Per surface: the material index (`value` gives one for all).
    materials: Option<Vec<Option<u64>>>,
    all_material: Option<u64>,
}

/// The surfaces of a texture `values` array: arrays whose elements are rings (arrays starting with
/// a texture index or null), found at any depth (MultiSurface, Solid, MultiSolid nesting).
fn texture_surfaces<'a>(v: &'a serde_json::Value, out: &mut Vec<&'a serde_json::Value>) {
    let Some(items) = v.as_array() else { return };
    let is_surface = items
        .first()
        .and_then(|r| r.as_array())
        .is_some_and(|ring| ring.first().is_none_or(|x| x.is_number() || x.is_null()));
    if is_surface || items.is_empty() {
        out.push(v);
    } else {
        items.iter().for_each(|i| texture_surfaces(i, out));
    }
}

/// The leaves (material indices or null) of a material `values` array, in document order.
fn material_leaves(v: &serde_json::Value, out: &mut Vec<Option<u64>>) {
    match v {
        serde_json::Value::Array(items) => items.iter().for_each(|i| material_leaves(i, out)),
        other => out.push(other.as_u64()),
    }
}

struct Reader<'p> {
    path: &'p Path,
    forced_lod: Option<String>,
    transform: Option<Transform>,
    templates: Option<Templates>,
    frame_name: Option<String>,
    buildings: Vec<SourceBuilding>,
    stats: ReadStats,
    buildings_seen: u64,
    buildings_empty: u64,
    buildings_degenerate: u64,
    /// The first unusable coordinate that no building uses: (where, value).
    first_bad_unused: Option<(String, [f64; 3])>,
    /// The document's (or CityJSONSeq header's) `appearance`.
    app_lists: Option<CjAppearance>,
    /// Themes found and chosen, images, counts.
    appearance: ModelAppearance,
    wanted_theme: Option<String>,
    no_appearance: bool,
    no_materials: bool,
    /// Texture values that do not fit their surface (counted while walking, which borrows `self`).
    unusable_targets: std::cell::Cell<u64>,
}

impl<'p> Reader<'p> {
    fn new(path: &'p Path, opts: &ReadOptions) -> Self {
        Reader {
            path,
            forced_lod: opts.lod.clone(),
            transform: None,
            templates: None,
            frame_name: None,
            buildings: Vec::new(),
            stats: ReadStats::default(),
            buildings_seen: 0,
            buildings_empty: 0,
            buildings_degenerate: 0,
            first_bad_unused: None,
            app_lists: None,
            appearance: ModelAppearance::default(),
            wanted_theme: opts.theme.clone(),
            no_appearance: opts.no_appearance,
            no_materials: opts.no_materials,
            unusable_targets: std::cell::Cell::new(0),
        }
    }

    /// Takes a document's `appearance`: its textures become the model's images (same indices),
    /// resolved against the file's folder.
    fn take_appearance(&mut self, app: Option<CjAppearance>) {
        let Some(app) = app else { return };
        if self.no_appearance {
            return;
        }
        let dir = self.path.parent().unwrap_or(Path::new("."));
        self.appearance.images = app.textures.iter().map(|t| dir.join(&t.image)).collect();
        self.app_lists = Some(app);
    }

    /// Records the themes of a geometry and picks the values of the chosen ones (the first theme seen,
    /// or the wanted one).
    fn geometry_appearance<'g>(&mut self, geom: &'g CjGeometry) -> GeomAppearance<'g> {
        let mut out = GeomAppearance::default();
        if self.no_appearance || self.app_lists.is_none() {
            return out;
        }
        for (name, _) in geom.texture.0.iter().chain(geom.material.0.iter()) {
            if !self.appearance.themes.contains(name) {
                self.appearance.themes.push(name.clone());
            }
        }
        if self.appearance.texture_theme.is_none() {
            let first = geom.texture.0.first().map(|(n, _)| n.clone());
            self.appearance.texture_theme = self.wanted_theme.clone().or(first);
        }
        if self.appearance.material_theme.is_none() {
            let first = geom.material.0.first().map(|(n, _)| n.clone());
            self.appearance.material_theme = self.wanted_theme.clone().or(first);
        }
        let pick = |themed: &'g Themed, theme: &Option<String>| {
            theme.as_ref().and_then(|t| themed.0.iter().find(|(n, _)| n == t).map(|(_, v)| v))
        };
        if let Some(v) = pick(&geom.texture, &self.appearance.texture_theme).and_then(|t| t.values.as_ref()) {
            let mut s = Vec::new();
            texture_surfaces(v, &mut s);
            out.textures = Some(s);
        }
        if let Some(m) = pick(&geom.material, &self.appearance.material_theme).filter(|_| !self.no_materials)
        {
            out.all_material = m.value;
            if let Some(v) = &m.values {
                let mut leaves = Vec::new();
                material_leaves(v, &mut leaves);
                out.materials = Some(leaves);
            }
        }
        out
    }

    /// The appearance of surface `s` of a geometry whose rings (as read, before clean-up) are `rings`
    /// and cleaned to `keep` (kept indices per kept ring: exterior first).
    fn face_appearance(
        &self,
        app: &GeomAppearance,
        s: usize,
        keep: &[(usize, Vec<usize>)],
    ) -> Option<FaceAppearance> {
        let lists = self.app_lists.as_ref()?;
        if let Some(surf) = app.textures.as_ref().and_then(|t| t.get(s)).and_then(|v| v.as_array()) {
            let ring_uv = |r: usize, idx: &[usize]| -> Option<(usize, Vec<[f64; 2]>)> {
                let ring = surf.get(r)?.as_array()?;
                let tex = ring.first()?.as_u64()? as usize;
                let uv: Vec<[f64; 2]> = ring[1..]
                    .iter()
                    .map(|i| i.as_u64().and_then(|i| lists.vertices_texture.get(i as usize).copied()))
                    .collect::<Option<_>>()?;
                let picked = idx.iter().map(|&k| uv.get(k).copied()).collect::<Option<Vec<_>>>()?;
                Some((tex, picked))
            };
            let has_texture =
                surf.first().and_then(|r| r.as_array()).and_then(|r| r.first()).is_some_and(|t| t.is_u64());
            if has_texture {
                let ext = keep.first().and_then(|(r, idx)| ring_uv(*r, idx));
                match ext {
                    Some((image, uv_exterior)) if image < lists.textures.len() => {
                        let uv_interiors = keep[1..]
                            .iter()
                            .map(|(r, idx)| {
                                ring_uv(*r, idx)
                                    .map(|(_, uv)| uv)
                                    .unwrap_or_else(|| vec![uv_exterior[0]; idx.len()])
                            })
                            .collect();
                        return Some(FaceAppearance::Texture { image, uv_exterior, uv_interiors });
                    }
                    _ => self.unusable_targets.set(self.unusable_targets.get() + 1),
                }
            }
        }
        let m = match &app.materials {
            Some(leaves) => leaves.get(s).copied().flatten(),
            None => app.all_material,
        }?;
        let rgb = lists.materials.get(m as usize)?.diffuse_color?;
        rgb.iter().all(|c| c.is_finite()).then_some(FaceAppearance::Colour { rgb })
    }

    /// Checks `type`/`version` and takes `transform`, `metadata` and `geometry-templates`.
    fn take_header(&mut self, doc: &mut Document, at: &str) -> Result<(), LodError> {
        if doc.kind != "CityJSON" {
            return Err(LodError::invalid(
                self.path,
                format!("{at}type"),
                CityJsonProblem::NotCityJson { found: doc.kind.clone() },
            ));
        }
        match doc.version.as_deref() {
            Some(v) if v.starts_with("1.") || v.starts_with("2.") => {}
            Some(v) => {
                return Err(LodError::invalid(
                    self.path,
                    format!("{at}version"),
                    CityJsonProblem::Version { version: v.to_string() },
                ))
            }
            None => log::warn!("{}: no CityJSON \"version\"; reading it as 2.0", self.path.display()),
        }
        if let Some(t) = doc.transform {
            if t.scale
                .iter()
                .chain(t.translate.iter())
                .any(|v| !v.is_finite() || v.abs() > MAX_ABS_COORDINATE)
            {
                return Err(LodError::invalid(
                    self.path,
                    format!("{at}transform"),
                    CityJsonProblem::Transform { scale: t.scale, translate: t.translate },
                ));
            }
        }
        self.transform = doc.transform;
        self.frame_name = doc.metadata.take().and_then(|m| m.reference_system);
        self.templates = doc.geometry_templates.take();
        self.take_appearance(doc.appearance.take());
        Ok(())
    }

    fn read_document(&mut self, mut doc: Document) -> Result<(), LodError> {
        self.take_header(&mut doc, "")?;
        let vertices = std::mem::take(&mut doc.vertices);
        self.read_objects(doc.city_objects.0, &vertices, "")
    }

    fn read_seq(&mut self) -> Result<(), LodError> {
        let file = File::open(self.path).map_err(|e| FileError::new("opening", self.path, e))?;
        let mut input = BufReader::with_capacity(1 << 16, file);
        let mut line = String::new();
        let mut line_no = 0usize;
        let mut header_seen = false;
        loop {
            line.clear();
            let n = input.read_line(&mut line).map_err(|e| FileError::new("reading", self.path, e))?;
            if n == 0 {
                break;
            }
            line_no += 1;
            if line.trim().is_empty() {
                continue;
            }
            let mut doc: Document =
                serde_json::from_str(&line).map_err(|e| json_error(self.path, Some(line_no), e))?;
            let at = format!("line {line_no}: ");
            if !header_seen {
                self.take_header(&mut doc, &at)?;
                header_seen = true;
            } else if doc.kind != "CityJSONFeature" {
                return Err(LodError::invalid(
                    self.path,
                    format!("{at}type"),
                    CityJsonProblem::NotFeature { found: doc.kind.clone() },
                ));
            }
            let vertices = std::mem::take(&mut doc.vertices);
            self.read_objects(doc.city_objects.0, &vertices, &at)?;
        }
        if !header_seen {
            return Err(LodError::malformed(self.path, SyntaxProblem::EmptySeq));
        }
        Ok(())
    }

    /// Folds parts into buildings and emits the buildings of one object collection.
    fn read_objects(
        &mut self,
        objects: Vec<(String, CityObject)>,
        vertices: &[[f64; 3]],
        at: &str,
    ) -> Result<(), LodError> {
        let mut index: BTreeMap<&str, usize> = BTreeMap::new();
        for (i, (key, _)) in objects.iter().enumerate() {
            if index.insert(key.as_str(), i).is_some() {
                return Err(LodError::invalid(
                    self.path,
                    format!("{at}CityObjects[{key:?}]"),
                    CityJsonProblem::DuplicateKey,
                ));
            }
        }
        // The Building each folded part belongs to (by object index).
        let mut owner: Vec<Option<usize>> = vec![None; objects.len()];
        let mut members: Vec<Vec<usize>> = vec![Vec::new(); objects.len()];
        for (i, (_, obj)) in objects.iter().enumerate() {
            if obj.kind != "Building" {
                continue;
            }
            owner[i] = Some(i);
            members[i].push(i);
            // Depth-first over `children`.
            let mut stack: Vec<&str> = obj.children.iter().rev().map(String::as_str).collect();
            while let Some(child) = stack.pop() {
                let Some(&c) = index.get(child) else {
                    log::warn!(
                        "{}: {at}CityObjects[{:?}] lists a missing child {child:?}",
                        self.path.display(),
                        objects[i].0
                    );
                    continue;
                };
                if owner[c].is_some() || !is_folded_part(&objects[c].1.kind) {
                    continue;
                }
                owner[c] = Some(i);
                members[i].push(c);
                stack.extend(objects[c].1.children.iter().rev().map(String::as_str));
            }
        }
        // Parts reached only through `parents`.
        for (i, (_, obj)) in objects.iter().enumerate() {
            if owner[i].is_some() || !is_folded_part(&obj.kind) {
                continue;
            }
            let mut cur = i;
            let mut root = None;
            for _ in 0..objects.len() {
                let Some(parent) = objects[cur].1.parents.first().and_then(|p| index.get(p.as_str())) else {
                    break;
                };
                cur = *parent;
                if let Some(o) = owner[cur] {
                    root = Some(o);
                    break;
                }
                if objects[cur].1.kind == "Building" {
                    root = Some(cur);
                    break;
                }
            }
            match root {
                Some(r) => {
                    owner[i] = Some(r);
                    members[r].push(i);
                }
                None => {
                    log::warn!(
                        "{}: {at}CityObjects[{:?}] is a {} without a Building ancestor; read as a building",
                        self.path.display(),
                        objects[i].0,
                        obj.kind
                    );
                    owner[i] = Some(i);
                    members[i].push(i);
                }
            }
        }
        for (_, obj) in &objects {
            let kind = obj.kind.as_str();
            if kind != "Building" && !is_folded_part(kind) && !is_ignored_building_detail(kind) {
                self.stats.skipped_non_building += 1;
            }
        }
        let source = VertexSource { vertices, transform: self.transform, list_name: "vertices" };
        for group in members.iter().filter(|m| !m.is_empty()) {
            self.read_building(&objects, group, &source, at)?;
        }
        // Every vertex a building uses was checked above (an unusable one is an error); the others
        // are counted so that a corrupt value in a road or an unused vertex is still reported.
        for i in 0..vertices.len() {
            let p = source.get(i as u32).unwrap_or([f64::NAN; 3]);
            if p.iter().any(|v| !v.is_finite() || v.abs() > MAX_ABS_COORDINATE) {
                self.stats.bad_coordinates_unused += 1;
                self.first_bad_unused.get_or_insert_with(|| (format!("{at}vertices[{i}]"), p));
            }
        }
        Ok(())
    }

    /// Converts one building's components, chooses the LoD and emits it.
    fn read_building(
        &mut self,
        objects: &[(String, CityObject)],
        members: &[usize],
        source: &VertexSource,
        at: &str,
    ) -> Result<(), LodError> {
        self.buildings_seen += 1;
        let (key, root) = &objects[members[0]];
        let components = self.convert_components(objects, members, source, at)?;
        let top = self.building_lod(&components);
        let faces = match &top {
            Some(top) => self.take_faces(components, top),
            None => Faces::default(),
        };
        let Faces { polygons, mut appearance, degenerate, lod_name } = faces;
        self.stats.degenerate_faces += degenerate;
        if polygons.is_empty() {
            self.stats.buildings_without_geometry += 1;
            if degenerate > 0 {
                self.buildings_degenerate += 1;
            } else {
                self.buildings_empty += 1;
            }
            return Ok(());
        }
        self.stats.faces += polygons.len() as u64;
        let measured_height_m = measured_height_m(root);
        let ground_heights_m = ground_heights_m(root);
        for a in appearance.iter().flatten() {
            match a {
                FaceAppearance::Texture { .. } => self.appearance.textured_faces += 1,
                FaceAppearance::Colour { .. } => self.appearance.coloured_faces += 1,
            }
        }
        if appearance.iter().all(Option::is_none) {
            appearance.clear();
        }
        self.buildings.push(SourceBuilding {
            source_id: key.clone(),
            ground_heights_m,
            lod: lod_name.or(top.map(|t| t.0)).unwrap_or_default(),
            measured_height_m,
            geometry: Geometry::Polygons(polygons),
            appearance,
        });
        Ok(())
    }

    /// Per component (`members` of `objects`), its geometries converted.
    fn convert_components(
        &mut self,
        objects: &[(String, CityObject)],
        members: &[usize],
        source: &VertexSource,
        at: &str,
    ) -> Result<Vec<Vec<Converted>>, LodError> {
        let mut components: Vec<Vec<Converted>> = Vec::with_capacity(members.len());
        for &m in members {
            let (mkey, obj) = &objects[m];
            let mut converted = Vec::new();
            for (g, geom) in obj.geometry.iter().enumerate() {
                let gpath = format!("{at}CityObjects[{mkey:?}].geometry[{g}]");
                let app = self.geometry_appearance(geom);
                if let Some(c) = self.convert(geom, source, &gpath, &app)? {
                    converted.push(c);
                }
            }
            components.push(converted);
        }
        Ok(components)
    }

    /// The building's LoD: forced, else the highest in [1, 2.2] with a usable polygon, else a usable
    /// LoD0 (footprint, roof edges) when nothing better exists, else the highest with any polygon
    /// (so that dropped faces are counted).
    fn building_lod(&self, components: &[Vec<Converted>]) -> Option<LodValue> {
        if let Some(f) = &self.forced_lod {
            return Some(LodValue(f.clone()));
        }
        let best = |lo: f64, need_usable: bool| {
            components
                .iter()
                .flatten()
                .filter(|c| lod_in_range(c, lo) && (!need_usable || usable(c)))
                .max_by(|a, b| {
                    a.lod.number().partial_cmp(&b.lod.number()).unwrap_or(std::cmp::Ordering::Equal)
                })
                .map(|c| c.lod.clone())
        };
        best(MIN_DEFAULT_LOD, true).or_else(|| best(0.0, true)).or_else(|| best(0.0, false))
    }

    /// The faces of LoD `top` from every component (each falls back to its best usable LoD up to
    /// `top` unless the LoD is forced); faces of other LoDs that failed are counted as unused.
    fn take_faces(&mut self, components: Vec<Vec<Converted>>, top: &LodValue) -> Faces {
        let mut faces = Faces::default();
        for comp in components {
            let pick: Option<f64> = match &self.forced_lod {
                Some(_) => None,
                None => {
                    let top_v = top.number().unwrap_or(MAX_DEFAULT_LOD);
                    let lo = if top_v < MIN_DEFAULT_LOD { 0.0 } else { MIN_DEFAULT_LOD };
                    comp.iter()
                        .filter(|c| usable(c) && c.lod.number().is_some_and(|v| v >= lo && v <= top_v))
                        .filter_map(|c| c.lod.number())
                        .fold(None, |acc: Option<f64>, v| Some(acc.map_or(v, |a| a.max(v))))
                        .or(Some(top_v))
                }
            };
            for c in comp {
                let take = match pick {
                    None => c.lod.matches(&top.0),
                    Some(v) => c.lod.number() == Some(v),
                };
                if !take {
                    self.stats.degenerate_faces_unused +=
                        c.polygons.iter().filter(|p| p.is_err()).count() as u64;
                    continue;
                }
                if faces.lod_name.is_none() && c.lod.matches(&top.0) {
                    faces.lod_name = Some(c.lod.0.clone());
                }
                for (p, a) in c.polygons.into_iter().zip(c.appearance) {
                    match p {
                        Ok(p) => {
                            faces.polygons.push(p);
                            faces.appearance.push(a);
                        }
                        Err(()) => faces.degenerate += 1,
                    }
                }
            }
        }
        faces
    }

    /// Turns one geometry object into polygons; `None` for geometry without surfaces (points, lines).
    fn convert(
        &self,
        geom: &CjGeometry,
        source: &VertexSource,
        gpath: &str,
        app: &GeomAppearance,
    ) -> Result<Option<Converted>, LodError> {
        if geom.kind == "GeometryInstance" {
            return self.convert_instance(geom, source, gpath).map(Some);
        }
        let depth = match geom.kind.as_str() {
            "MultiSurface" | "CompositeSurface" => 2,
            "Solid" => 3,
            "MultiSolid" | "CompositeSolid" => 4,
            "MultiPoint" | "MultiLineString" => return Ok(None),
            other => {
                return Err(LodError::invalid(
                    self.path,
                    format!("{gpath}.type"),
                    CityJsonProblem::GeometryType { found: other.to_string() },
                ))
            }
        };
        let Some(lod) = geom.lod.clone() else {
            return Err(LodError::invalid(
                self.path,
                gpath,
                CityJsonProblem::NoLod { kind: geom.kind.clone() },
            ));
        };
        let (polygons, appearance) = match &geom.boundaries {
            Some(b) => self.surfaces(b, depth, &geom.kind, source, gpath, &|p| p, app)?,
            None => (Vec::new(), Vec::new()),
        };
        Ok(Some(Converted { lod, polygons, appearance }))
    }

    /// A `GeometryInstance`: the template's polygons, transformed and placed at the reference point.
    fn convert_instance(
        &self,
        geom: &CjGeometry,
        source: &VertexSource,
        gpath: &str,
    ) -> Result<Converted, LodError> {
        let templates = self.templates.as_ref();
        let t = geom.template.unwrap_or(u64::MAX);
        let Some(template) = templates.and_then(|ts| ts.templates.get(t as usize)) else {
            return Err(LodError::invalid(
                self.path,
                format!("{gpath}.template"),
                CityJsonProblem::Template {
                    template: geom.template,
                    templates: templates.map_or(0, |ts| ts.templates.len()),
                },
            ));
        };
        let m: [f64; 16] = match geom.transformation_matrix.as_deref() {
            Some(m) if m.len() == 16 && m.iter().all(|v| v.is_finite()) => {
                let mut a = [0.0; 16];
                a.copy_from_slice(m);
                a
            }
            None => [1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0],
            Some(m) => {
                return Err(LodError::invalid(
                    self.path,
                    format!("{gpath}.transformationMatrix"),
                    CityJsonProblem::TransformationMatrix { values: m.len() },
                ))
            }
        };
        let reference = geom
            .boundaries
            .as_ref()
            .and_then(|b| (b.leaf_depth == Some(0)).then(|| b.leaves.first()).flatten());
        let Some(&reference) = reference else {
            return Err(LodError::invalid(
                self.path,
                format!("{gpath}.boundaries"),
                CityJsonProblem::NoReferenceVertex,
            ));
        };
        let r = self.vertex(source, reference, &format!("{gpath}.boundaries[0]"))?;
        let depth = match template.kind.as_str() {
            "MultiSurface" | "CompositeSurface" => 2,
            "Solid" => 3,
            "MultiSolid" | "CompositeSolid" => 4,
            _ => 0,
        };
        let tpath = format!("geometry-templates.templates[{t}]");
        let lod = template.lod.clone().unwrap_or(LodValue(String::new()));
        let tsource = VertexSource {
            vertices: templates.map_or(&[][..], |ts| &ts.vertices[..]),
            transform: None,
            list_name: "vertices-templates",
        };
        let place = |p: [f64; 3]| {
            let x = m[0] * p[0] + m[1] * p[1] + m[2] * p[2] + m[3];
            let y = m[4] * p[0] + m[5] * p[1] + m[6] * p[2] + m[7];
            let z = m[8] * p[0] + m[9] * p[1] + m[10] * p[2] + m[11];
            [x + r[0], y + r[1], z + r[2]]
        };
        // Appearances of templates are not read (the instance's faces keep the procedural look).
        let (polygons, appearance) = match (&template.boundaries, depth) {
            (Some(b), 2..=4) => {
                self.surfaces(b, depth, &template.kind, &tsource, &tpath, &place, &GeomAppearance::default())?
            }
            _ => (Vec::new(), Vec::new()),
        };
        Ok(Converted { lod, polygons, appearance })
    }

    /// Walks a surface-based boundaries array (`depth` = depth of the arrays holding indices); returns
    /// the polygons and their appearances.
    #[allow(clippy::too_many_arguments, clippy::type_complexity)]
    fn surfaces(
        &self,
        b: &Boundaries,
        depth: usize,
        kind: &str,
        source: &VertexSource,
        gpath: &str,
        place: &dyn Fn([f64; 3]) -> [f64; 3],
        app: &GeomAppearance,
    ) -> Result<(Vec<Result<Polygon, ()>>, Vec<Option<FaceAppearance>>), LodError> {
        if b.leaf_depth.is_some_and(|d| d != depth) || b.counts.len() > depth + 1 {
            let found = b.leaf_depth.unwrap_or(b.counts.len().saturating_sub(1));
            return Err(LodError::invalid(
                self.path,
                format!("{gpath}.boundaries"),
                CityJsonProblem::BoundaryDepth {
                    kind: kind.to_string(),
                    expected: depth + 1,
                    found: found + 1,
                },
            ));
        }
        let mut out = (Vec::new(), Vec::new());
        let mut walker = Walker::new(b);
        let mut path = Vec::with_capacity(depth + 1);
        self.walk(&mut walker, 0, depth, &mut path, source, gpath, place, app, &mut out)?;
        Ok(out)
    }

    #[allow(clippy::too_many_arguments)]
    fn walk(
        &self,
        w: &mut Walker,
        depth: usize,
        leaf_depth: usize,
        path: &mut Vec<usize>,
        source: &VertexSource,
        gpath: &str,
        place: &dyn Fn([f64; 3]) -> [f64; 3],
        app: &GeomAppearance,
        out: &mut (Vec<Result<Polygon, ()>>, Vec<Option<FaceAppearance>>),
    ) -> Result<(), LodError> {
        let n = w.take(depth);
        if depth + 2 == leaf_depth {
            // This array lists surfaces; each surface lists rings; each ring lists vertex indices.
            for s in 0..n {
                path.push(s);
                let n_rings = w.take(depth + 1);
                let mut rings = Vec::with_capacity(n_rings);
                for r in 0..n_rings {
                    let n_idx = w.take(depth + 2);
                    let idx = w.leaves(n_idx);
                    let mut ring = Vec::with_capacity(idx.len());
                    for (k, &i) in idx.iter().enumerate() {
                        let p = self.vertex(source, i, &index_path(gpath, path, &[r, k]))?;
                        ring.push(place(p));
                    }
                    rings.push(ring);
                }
                path.pop();
                // Clean-up as indices, so that texture coordinates follow the kept vertices.
                let keep: Vec<(usize, Vec<usize>)> = match rings.first().and_then(|r| clean_ring_indices(r)) {
                    Some(ext) => std::iter::once((0, ext))
                        .chain(
                            rings
                                .iter()
                                .enumerate()
                                .skip(1)
                                .filter_map(|(r, ring)| clean_ring_indices(ring).map(|k| (r, k))),
                        )
                        .collect(),
                    None => Vec::new(),
                };
                let ring_of =
                    |(r, idx): &(usize, Vec<usize>)| idx.iter().map(|&i| rings[*r][i]).collect::<Vec<_>>();
                let surface = out.0.len();
                match keep.first() {
                    Some(ext) => {
                        out.0.push(Ok(Polygon {
                            exterior: ring_of(ext),
                            interiors: keep[1..].iter().map(ring_of).collect(),
                        }));
                        out.1.push(self.face_appearance(app, surface, &keep));
                    }
                    None => {
                        out.0.push(Err(()));
                        out.1.push(None);
                    }
                }
            }
        } else {
            for i in 0..n {
                path.push(i);
                self.walk(w, depth + 1, leaf_depth, path, source, gpath, place, app, out)?;
                path.pop();
            }
        }
        Ok(())
    }

    /// The coordinate of a vertex index, checked.
    fn vertex(&self, source: &VertexSource, i: u32, at: &str) -> Result<[f64; 3], LodError> {
        let Some(p) = source.get(i) else {
            return Err(LodError::invalid(
                self.path,
                at,
                CityJsonProblem::VertexIndex {
                    index: i,
                    list: source.list_name,
                    vertices: source.vertices.len(),
                },
            ));
        };
        if p.iter().any(|v| !v.is_finite() || v.abs() > MAX_ABS_COORDINATE) {
            return Err(LodError::invalid(
                self.path,
                at,
                CityJsonProblem::Coordinate { list: source.list_name, index: i, coordinate: p },
            ));
        }
        Ok(p)
    }

    fn finish(self) -> Result<SourceModel, LodError> {
        if self.buildings.is_empty() {
            return Err(LodError::invalid(
                self.path,
                "CityObjects",
                CityJsonProblem::NoBuildings {
                    lod: self.forced_lod.clone(),
                    counts: NoBuildings {
                        found: self.buildings_seen,
                        without_surface: self.buildings_empty,
                        all_degenerate: self.buildings_degenerate,
                        faces_dropped: self.stats.degenerate_faces,
                        others_skipped: self.stats.skipped_non_building,
                    },
                },
            ));
        }
        if let Some((at, p)) = &self.first_bad_unused {
            log::warn!(
                "{}: {} vertex coordinate(s) are not finite or beyond ±{MAX_ABS_COORDINATE:e} (first: {at} = [{}, {}, \
                 {}]); no building uses them (they belong to skipped objects or to none), so they are ignored",
                self.path.display(),
                self.stats.bad_coordinates_unused,
                short(p[0]),
                short(p[1]),
                short(p[2])
            );
        }
        if self.stats.degenerate_faces_unused > 0 {
            log::warn!(
                "{}: {} degenerate face(s) in geometry that was not chosen (another LoD) were ignored",
                self.path.display(),
                self.stats.degenerate_faces_unused
            );
        }
        Ok(SourceModel {
            path: self.path.to_path_buf(),
            frame: Frame::Crs { name: self.frame_name, axes: AxisConvention::EastNorth },
            buildings: self.buildings,
            stats: self.stats,
            appearance: ModelAppearance { unusable_targets: self.unusable_targets.get(), ..self.appearance },
        })
    }
}

/// `gpath.boundaries[a][b]…` for the vertex at `prefix` + `rest`.
fn index_path(gpath: &str, prefix: &[usize], rest: &[usize]) -> String {
    let mut s = format!("{gpath}.boundaries");
    for i in prefix.iter().chain(rest) {
        s.push_str(&format!("[{i}]"));
    }
    s
}

/// A serde_json error as an [`LodError`] with line and column (`line_no` for CityJSONSeq lines).
fn json_error(path: &Path, line_no: Option<usize>, e: serde_json::Error) -> LodError {
    let (line, column) = match line_no {
        Some(l) => (l, e.column()),
        None => (e.line(), e.column()),
    };
    if e.is_io() {
        return LodError::File(FileError::new("reading", path, std::io::Error::from(e)));
    }
    if e.is_eof() {
        return LodError::malformed(path, SyntaxProblem::TruncatedJson { line, column });
    }
    // serde_json's message ends with its own " at line L column C" (relative to the parsed text).
    let msg = e.to_string();
    let message = msg.rsplit_once(" at line ").map_or(msg.as_str(), |(m, _)| m).to_string();
    LodError::malformed(path, SyntaxProblem::Json { line, column, message })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn boundaries(json: &str) -> Result<Boundaries, serde_json::Error> {
        serde_json::from_str(json)
    }

    mod flat_boundaries {
        use super::*;

        #[test]
        fn multisurface_counts_and_leaves() {
            let b = boundaries("[[[0,1,2],[3,4,5]],[[6,7,8,9]]]").unwrap();
            assert_eq!(b.counts, vec![vec![2], vec![2, 1], vec![3, 3, 4]]);
            assert_eq!(b.leaves, (0..10).collect::<Vec<u32>>());
            assert_eq!(b.leaf_depth, Some(2));
        }

        #[test]
        fn empty_arrays_are_kept() {
            let b = boundaries("[[], [[0,1,2]]]").unwrap();
            assert_eq!(b.counts, vec![vec![2], vec![0, 1], vec![3]]);
        }

        #[test]
        fn walker_rebuilds_a_solid() {
            // One shell of two surfaces; the second has a hole.
            let b = boundaries("[[[[0,1,2]],[[3,4,5,6],[7,8,9]]]]").unwrap();
            let mut w = Walker::new(&b);
            assert_eq!(w.take(0), 1); // shells
            assert_eq!(w.take(1), 2); // surfaces of shell 0
            assert_eq!(w.take(2), 1); // rings of surface 0
            let n = w.take(3);
            assert_eq!(w.leaves(n), &[0, 1, 2]);
            assert_eq!(w.take(2), 2); // rings of surface 1
            let n = w.take(3);
            assert_eq!(w.leaves(n), &[3, 4, 5, 6]);
            let n = w.take(3);
            assert_eq!(w.leaves(n), &[7, 8, 9]);
        }

        #[test]
        fn inconsistent_nesting_is_rejected() {
            let e = boundaries("[[0,[1]]]").unwrap_err().to_string();
            assert!(e.contains("mixes vertex indices and arrays"), "{e}");
            let e = boundaries("[[0],[[1]]]").unwrap_err().to_string();
            assert!(e.contains("two nesting depths"), "{e}");
            let e = boundaries("[[1.5]]").unwrap_err().to_string();
            assert!(e.contains("not an integer"), "{e}");
            let e = boundaries("[[4294967296]]").unwrap_err().to_string();
            assert!(e.contains("too large"), "{e}");
        }
    }

    mod lod_values {
        use super::*;

        #[test]
        fn numbers_and_strings() {
            let l: LodValue = serde_json::from_str("2").unwrap();
            assert_eq!(l, LodValue("2".into()));
            let l: LodValue = serde_json::from_str("2.2").unwrap();
            assert_eq!(l, LodValue("2.2".into()));
            let l: LodValue = serde_json::from_str("\"1.3\"").unwrap();
            assert_eq!(l.number(), Some(1.3));
        }

        #[test]
        fn forced_matching_is_numeric_then_textual() {
            assert!(LodValue("2".into()).matches("2.0"));
            assert!(!LodValue("2.2".into()).matches("2"));
            assert!(LodValue("custom".into()).matches("custom"));
        }
    }

    #[test]
    fn short_numbers_in_messages() {
        assert_eq!(short(1e297), "1e297");
        assert_eq!(short(447000.5), "447000.5");
    }
}
