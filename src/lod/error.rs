//! Errors of the LoD readers: each names the file and, where known, the object and what is wrong.

use std::path::PathBuf;

use super::tiles3d::ContentError;

/// Why a LoD model file (or tileset) cannot be read.
#[derive(Debug, thiserror::Error)]
pub enum LodError {
    /// The file cannot be opened or read.
    #[error(transparent)]
    File(#[from] crate::util::FileError),

    /// A 3D Tiles file read on its own (a `.b3dm`/`.glb`/`.cmpt` content, or the gzip or JSON layer of
    /// a tileset JSON) cannot be decoded; `source` says what is wrong where.
    #[error("{}", path.display())]
    Tiles3d {
        /// The file.
        path: PathBuf,
        /// What is wrong where inside it.
        #[source]
        source: Box<ContentError>,
    },

    /// A tile content that a tileset references cannot be read or decoded: the tileset JSON, the JSON
    /// path of the reference (`root.children[3].content`), the URI as written and the file it names.
    #[error("{}: {at}.uri {uri:?} ({})", tileset.display(), content.display())]
    Tile {
        /// The tileset JSON that references the content.
        tileset: PathBuf,
        /// JSON path of the reference (`root.children[3].content`).
        at: String,
        /// The URI as written.
        uri: String,
        /// The content file it names.
        content: PathBuf,
        /// What is wrong where inside the content.
        #[source]
        source: Box<ContentError>,
    },

    /// An implicit-tiling subtree file of the tile at `at` (in `tileset`) is malformed.
    #[error("{}: {at}: subtree {}", tileset.display(), subtree.display())]
    Subtree {
        /// The tileset JSON.
        tileset: PathBuf,
        /// JSON path of the implicit tile.
        at: String,
        /// The subtree file.
        subtree: PathBuf,
        /// What is wrong with it.
        #[source]
        source: Box<ContentError>,
    },

    /// The format cannot be told from the file name.
    #[error("{}: cannot tell the format from the file name; set `format` (citygml, cityjson, obj, 3dtiles) in the scene file", path.display())]
    UnknownFormat {
        /// The file.
        path: PathBuf,
    },

    /// The file is not well-formed (truncated XML/JSON, bad binary header…); `source` is the parser's
    /// own error when there is one.
    #[error("{}: {problem}", path.display())]
    Malformed {
        /// The file.
        path: PathBuf,
        /// What is wrong, with the line and column where known (boxed: errors travel by value).
        problem: Box<SyntaxProblem>,
        /// The parser's error, when there is one.
        #[source]
        source: Option<ParseError>,
    },

    /// [`super::ReadOptions::weld_tolerance_m`] is negative or not finite.
    #[error("{}: weld_tolerance_m: weld tolerance {tolerance_m} m must be a finite number ≥ 0", path.display())]
    WeldTolerance {
        /// The file being read.
        path: PathBuf,
        /// The tolerance given, metres.
        tolerance_m: f64,
    },

    /// A specific object (building, geometry, tile, option) is invalid; `at` locates it (gml:id, JSON
    /// path, line, tile URI, the option's name).
    #[error("{}: {at}: {problem}", path.display())]
    Invalid {
        /// The file.
        path: PathBuf,
        /// Where in it: gml:id, JSON path, line, tile URI, or the option's name.
        at: String,
        /// What is wrong there (boxed: errors travel by value).
        problem: Box<LodProblem>,
    },

    /// A tileset JSON breaks the 3D Tiles rules; every problem is listed with its JSON path.
    #[error("{}: {}", path.display(), tileset_issues(issues))]
    InvalidTileset {
        /// The tileset JSON.
        path: PathBuf,
        /// Every problem (at least one), in document order.
        issues: Vec<TilesetIssue>,
    },
}

/// "first (and N more: second; third)".
fn tileset_issues(issues: &[TilesetIssue]) -> String {
    let mut text = issues.first().map(ToString::to_string).unwrap_or_default();
    if issues.len() > 1 {
        let rest: Vec<String> = issues[1..].iter().map(ToString::to_string).collect();
        text.push_str(&format!(" (and {} more: {})", issues.len() - 1, rest.join("; ")));
    }
    text
}

/// Why a file is not well-formed: the text after the file name of a [`LodError::Malformed`].
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SyntaxProblem {
    /// The file is not in the syntax its reader expects at all (not JSON, not XML).
    #[error("not {expected}: {}, not {document}", holds(looks))]
    WrongFormat {
        /// The syntax expected ("JSON", "XML").
        expected: &'static str,
        /// What the first bytes look like ([`super::sniff`]: "empty", "XML", "a glTF binary (glb)", …).
        looks: &'static str,
        /// The document expected ("a CityJSON document").
        document: &'static str,
    },
    /// The JSON ends before the document is complete.
    #[error("truncated JSON: the file ends at line {line}, column {column} before the document is complete")]
    TruncatedJson {
        /// 1-based line.
        line: usize,
        /// 1-based column.
        column: usize,
    },
    /// The JSON does not parse (or has the wrong shape).
    #[error(
        "malformed JSON at line {line}, column {column}: {message}{}",
        if message == "expected value" { " (NaN and Infinity are not JSON numbers)" } else { "" }
    )]
    Json {
        /// 1-based line (of the file, also in a CityJSONSeq file).
        line: usize,
        /// 1-based column.
        column: usize,
        /// serde_json's message without its own position (relative to the parsed line).
        message: String,
    },
    /// A CityJSONSeq file without its header line.
    #[error("empty CityJSONSeq file: no header line")]
    EmptySeq,
    /// The XML does not parse at `at`.
    #[error("malformed XML at {at}")]
    Xml {
        /// "line L, column C (byte B)".
        at: String,
    },
    /// The file ends inside a tag, comment or CDATA section.
    #[error("truncated XML: the file ends inside markup that starts at {at}")]
    XmlCut {
        /// "line L, column C (byte B)" of the markup.
        at: String,
    },
    /// The file ends with elements still open.
    #[error(
        "truncated XML: the file ends at {at}{} with {open} element(s) still open (innermost <{innermost}>, \
         outermost <{outermost}>)",
        building.as_ref().map(|b| format!(" inside building gml:id {b:?}")).unwrap_or_default()
    )]
    TruncatedXml {
        /// "line L, column C (byte B)" of the end.
        at: String,
        /// The gml:id of the building being read, if any.
        building: Option<String>,
        /// Elements still open.
        open: usize,
        /// The innermost open element.
        innermost: String,
        /// The outermost open element.
        outermost: String,
    },
    /// An attribute of an element does not parse.
    #[error("malformed XML attribute at {at}")]
    XmlAttribute {
        /// "line L, column C (byte B)" of the element.
        at: String,
    },
    /// An attribute's value does not parse (a bad entity or character reference).
    #[error("malformed XML attribute value at {at}")]
    XmlAttributeValue {
        /// "line L, column C (byte B)" of the element.
        at: String,
    },
    /// The OBJ sidecar JSON does not parse into a sidecar.
    #[error("not a valid OBJ sidecar (crs, offset, axes, lod)")]
    ObjSidecar,
    /// The OBJ parser refused the file.
    #[error("cannot parse OBJ")]
    Obj,
}

/// "the file holds JSON (CityJSON or a tileset? …)" for [`SyntaxProblem::WrongFormat`].
fn holds(looks: &str) -> String {
    let hint = match looks {
        "JSON" => " (CityJSON or a tileset? name it .json / tileset.json or set `format` in the scene file)",
        "XML" => " (CityGML? name it .gml or set format = \"citygml\" in the scene file)",
        "a glTF binary (glb)" | "a 3D Tiles content (b3dm/cmpt/i3dm/pnts)" => {
            " (3D Tiles? name it .glb/.b3dm or set format = \"3dtiles\" in the scene file)"
        }
        "a Wavefront OBJ" => " (name it .obj or set format = \"obj\" in the scene file)",
        _ => "",
    };
    match looks {
        "empty" => "the file is empty".to_string(),
        other => format!("the file holds {other}{hint}"),
    }
}

/// What is wrong at a place in a LoD file: the text after "<file>: <where>: " of a
/// [`LodError::Invalid`].
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum LodProblem {
    /// In a CityJSON file.
    #[error(transparent)]
    CityJson(#[from] CityJsonProblem),
    /// In a CityGML file.
    #[error(transparent)]
    CityGml(#[from] CityGmlProblem),
    /// In an OBJ file or its sidecar.
    #[error(transparent)]
    Obj(#[from] ObjProblem),
    /// In a 3D Tiles tileset.
    #[error(transparent)]
    Tileset(#[from] TilesetProblem),
    /// In the parameters of the procedural demo city.
    #[error(transparent)]
    Procedural(#[from] ProceduralProblem),
}

/// The counts of a file in which no building has usable geometry.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct NoBuildings {
    /// Buildings (and building parts folded into them) found.
    pub found: u64,
    /// Of those, buildings without any surface of the LoDs read.
    pub without_surface: u64,
    /// Of those, buildings whose surfaces were all degenerate.
    pub all_degenerate: u64,
    /// Degenerate faces dropped.
    pub faces_dropped: u64,
    /// City objects that are not buildings, skipped.
    pub others_skipped: u64,
}

impl NoBuildings {
    /// The message, `lods` naming the LoDs read and `degenerate` what makes a face degenerate.
    fn text(&self, lods: &str, degenerate: &str) -> String {
        format!(
            "no buildings with geometry: {} building(s) found, {} without any {lods} surface, {} whose {lods} \
             surfaces are all degenerate ({} face(s) dropped: {degenerate}); {} other city object(s) skipped",
            self.found, self.without_surface, self.all_degenerate, self.faces_dropped, self.others_skipped
        )
    }
}

/// A number for a message: plain when moderate, in exponent form when huge (`1e297`, not 298 digits).
pub(crate) fn short(v: f64) -> String {
    if v.is_finite() && v.abs() >= 1e15 {
        format!("{v:e}")
    } else {
        v.to_string()
    }
}

/// What is wrong in a CityJSON (or CityJSONSeq) file.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CityJsonProblem {
    /// The document's `type` is not `CityJSON`.
    #[error("expected \"CityJSON\", found {found:?}: not a CityJSON file")]
    NotCityJson {
        /// The `type` found.
        found: String,
    },
    /// A CityJSONSeq line after the header is not a `CityJSONFeature`.
    #[error("expected \"CityJSONFeature\" after the header line, found {found:?}")]
    NotFeature {
        /// The `type` found.
        found: String,
    },
    /// The `version` is not 1.x or 2.x.
    #[error("CityJSON version {version:?} is not supported (1.0, 1.1, 2.0 are)")]
    Version {
        /// The version as written.
        version: String,
    },
    /// The `transform` has a non-finite or absurd number.
    #[error("scale {scale:?} / translate {translate:?} must be finite numbers")]
    Transform {
        /// `transform.scale`.
        scale: [f64; 3],
        /// `transform.translate`.
        translate: [f64; 3],
    },
    /// A key occurs twice in `CityObjects`.
    #[error("this key appears twice in CityObjects")]
    DuplicateKey,
    /// A geometry's `type` is not a CityJSON geometry type.
    #[error(
        "unknown geometry type {found:?} (expected MultiSurface, CompositeSurface, Solid, MultiSolid, \
         CompositeSolid, GeometryInstance, MultiPoint or MultiLineString)"
    )]
    GeometryType {
        /// The `type` found.
        found: String,
    },
    /// A geometry has no `lod`.
    #[error("{kind} geometry without \"lod\"")]
    NoLod {
        /// The geometry's type.
        kind: String,
    },
    /// A `GeometryInstance` names a template that does not exist.
    #[error(
        "template {} does not exist (the file has {templates} geometry template(s))",
        template.map_or("(missing)".to_string(), |t| t.to_string())
    )]
    Template {
        /// The template index (`None` when missing).
        template: Option<u64>,
        /// Templates in the file.
        templates: usize,
    },
    /// A `transformationMatrix` is not 16 finite numbers.
    #[error("expected 16 finite numbers, found {values} value(s)")]
    TransformationMatrix {
        /// Values found.
        values: usize,
    },
    /// A `GeometryInstance` has no reference vertex.
    #[error("a GeometryInstance needs boundaries [reference vertex index]")]
    NoReferenceVertex,
    /// A boundary array is nested to the wrong depth for its geometry type.
    #[error("a {kind} needs vertex indices at nesting depth {expected}, found depth {found}")]
    BoundaryDepth {
        /// The geometry type.
        kind: String,
        /// The depth the type needs (1-based).
        expected: usize,
        /// The depth found (1-based).
        found: usize,
    },
    /// A vertex index is past the end of its vertex list.
    #[error("vertex index {index} is out of range ({list} has {vertices} vertices)")]
    VertexIndex {
        /// The index.
        index: u32,
        /// The list: `vertices` or `vertices-templates`.
        list: &'static str,
        /// Vertices in the list.
        vertices: usize,
    },
    /// A vertex used by a building has a non-finite or absurd coordinate.
    #[error(
        "{list}[{index}] gives the coordinate [{}, {}, {}], which is not finite or beyond ±{:e}",
        short(coordinate[0]),
        short(coordinate[1]),
        short(coordinate[2]),
        super::MAX_ABS_COORDINATE
    )]
    Coordinate {
        /// The list: `vertices` or `vertices-templates`.
        list: &'static str,
        /// The vertex index.
        index: u32,
        /// The coordinate (after the `transform`).
        coordinate: [f64; 3],
    },
    /// No building has usable geometry.
    #[error(
        "{}",
        counts.text(
            &lod.as_ref().map_or_else(
                || format!("LoD {}–{}", super::cityjson::MIN_DEFAULT_LOD, super::cityjson::MAX_DEFAULT_LOD),
                |l| format!("LoD {l:?}")
            ),
            "fewer than 3 distinct points or zero area"
        )
    )]
    NoBuildings {
        /// The LoD asked for (`lod` of the scene file), if any.
        lod: Option<String>,
        /// What was found.
        counts: NoBuildings,
    },
}

/// What is wrong in a CityGML file.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CityGmlProblem {
    /// The `lod` option is not one the CityGML reader reads.
    #[error("CityGML buildings are read at LoD \"0\", \"1\" or \"2\", not {given:?}")]
    LodOption {
        /// The option as given.
        given: String,
    },
    /// The root element is not a `CityModel`.
    #[error("no CityModel element: this XML is not CityGML (its root must be <core:CityModel>)")]
    NotCityGml,
    /// Two buildings share a gml:id.
    #[error("this gml:id is used by two buildings; gml:ids must be unique in a document")]
    DuplicateId,
    /// An `srsDimension` other than 2 or 3.
    #[error("srsDimension {given:?} is not supported (expected 2 or 3)")]
    SrsDimension {
        /// The attribute as written.
        given: String,
    },
    /// A coordinate token is not a number.
    #[error("{token:?} is not a number")]
    NotANumber {
        /// The token.
        token: String,
    },
    /// A coordinate is not finite or absurdly large.
    #[error("coordinate {token} is not finite or beyond ±{:e}", super::MAX_ABS_COORDINATE)]
    Coordinate {
        /// The token as written.
        token: String,
    },
    /// A coordinate list does not hold whole points.
    #[error("{element} holds {numbers} number(s), which is not a whole number of {dimension}-D points")]
    PointCount {
        /// `gml:posList`, `gml:pos` or `gml:coordinates`.
        element: &'static str,
        /// Numbers found.
        numbers: usize,
        /// The dimension in force.
        dimension: usize,
    },
    /// No building has usable geometry.
    #[error(
        "{}",
        counts.text(
            &lod.map_or_else(|| "LoD 0, 1 or 2".to_string(), |l| format!("LoD {l}")),
            "fewer than 3 distinct points, zero area, or outside the document envelope"
        )
    )]
    NoBuildings {
        /// The LoD asked for (`lod` of the scene file), if any.
        lod: Option<&'static str>,
        /// What was found.
        counts: NoBuildings,
    },
}

/// What is wrong with an OBJ file or its sidecar.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ObjProblem {
    /// Neither sidecar file exists.
    #[error(
        "an OBJ needs a sidecar JSON giving its CRS, offset and up axis, but neither {} nor {} exists; create \
         one, e.g. {{\"crs\": \"EPSG:6677\", \"offset\": [0, 0, 0], \"axes\": \"z_up\"}} (schema: \
         schemas/obj_sidecar.schema.json)",
        tried[0].display(),
        tried[1].display()
    )]
    NoSidecar {
        /// The two paths tried (`<name>.obj.json`, `<name>.json`).
        tried: [PathBuf; 2],
    },
    /// A sidecar offset component is NaN or infinite.
    #[error("offset component {value} is not finite")]
    Offset {
        /// The component.
        value: f64,
    },
    /// No face survives.
    #[error("the OBJ has no (non-degenerate) faces")]
    NoFaces,
    /// A vertex is NaN or infinite.
    #[error("is not finite: {position:?}")]
    Vertex {
        /// The vertex as read.
        position: [f64; 3],
    },
}

/// One problem of a tileset JSON, at a JSON path.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{at}: {problem}")]
pub struct TilesetIssue {
    /// JSON path (`root.children[2].boundingVolume`).
    pub at: String,
    /// What is wrong there.
    pub problem: TilesetProblem,
}

/// What is wrong in a 3D Tiles tileset.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum TilesetProblem {
    /// `asset.gltfUpAxis` is not X, Y or Z.
    #[error("{axis:?} is not X, Y or Z")]
    UpAxis {
        /// The axis as written.
        axis: String,
    },
    /// The tileset requires an extension the reader does not handle.
    #[error(
        "the tileset requires extension {extension}, which insgen does not read (it reads {})",
        super::tiles3d::tileset::HANDLED_TILESET_EXTENSIONS.join(", ")
    )]
    RequiredExtension {
        /// The extension.
        extension: String,
    },
    /// A tile has no `boundingVolume`.
    #[error("is missing (needs a box, region or sphere)")]
    NoBoundingVolume,
    /// A `boundingVolume` has none of box, region and sphere.
    #[error("needs a box, region or sphere")]
    EmptyBoundingVolume,
    /// A box, region or sphere has the wrong count of numbers (or a non-finite one).
    #[error("needs {needed} finite numbers, has {found}")]
    BoundingVolume {
        /// Numbers the volume needs (12, 6, 4).
        needed: usize,
        /// Numbers found.
        found: usize,
    },
    /// A tile's `boundingVolume` cannot be used (validation lets none through).
    #[error("no usable boundingVolume")]
    UnusableBoundingVolume,
    /// A tile has no `geometricError`.
    #[error("is missing")]
    NoGeometricError,
    /// A `geometricError` is negative or not finite.
    #[error("{value} is not a finite number ≥ 0")]
    GeometricError {
        /// The value.
        value: f64,
    },
    /// A `transform` does not have 16 numbers.
    #[error("has {found} numbers, not 16")]
    TransformLength {
        /// Numbers found.
        found: usize,
    },
    /// A `transform` has a NaN or infinite number.
    #[error("has non-finite numbers")]
    TransformNotFinite,
    /// A `refine` other than ADD and REPLACE.
    #[error("{found:?} is not ADD or REPLACE")]
    Refine {
        /// The value as written.
        found: String,
    },
    /// A tile has both `content` and `contents`.
    #[error("has both content and contents")]
    ContentAndContents,
    /// A content has no `uri`.
    #[error("has no uri")]
    NoUri,
    /// An implicit tiling's `subdivisionScheme` is neither QUADTREE nor OCTREE.
    #[error("{found:?} is not QUADTREE or OCTREE")]
    SubdivisionScheme {
        /// The value as written.
        found: String,
    },
    /// `subtreeLevels` is 0.
    #[error("must be at least 1")]
    SubtreeLevels,
    /// `availableLevels` is missing or 0.
    #[error("is missing or 0")]
    NoAvailableLevels,
    /// More levels than the reader handles.
    #[error("{levels} levels exceed the 31 insgen reads")]
    TooManyLevels {
        /// `availableLevels`.
        levels: u32,
    },
    /// An implicit root tile bounded by a sphere.
    #[error("implicit tiling needs a box or region; a sphere cannot be subdivided")]
    ImplicitSphere,
    /// An implicit root tile with explicit children.
    #[error("an implicit root tile may not list children")]
    ImplicitChildren,
    /// The root subtree marks the root tile unavailable.
    #[error("the root subtree marks the implicit root tile unavailable")]
    RootUnavailable,
    /// The implicit tiling expands to more tiles than the reader accepts.
    #[error("implicit tiling expands to more than {max} tiles")]
    TooManyTiles {
        /// The limit.
        max: usize,
    },
    /// External tilesets reference each other in a cycle.
    #[error(
        "external tilesets form a cycle: {}",
        chain.iter().map(|p| p.display().to_string()).collect::<Vec<_>>().join(" → ")
    )]
    Cycle {
        /// The tilesets from the root, the last one repeating an earlier one.
        chain: Vec<PathBuf>,
    },
}

/// A parameter of the procedural demo city out of its range.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ProceduralProblem {
    /// A count outside its range.
    #[error("{value} is outside {min}..={max}")]
    Count {
        /// The value.
        value: u32,
        /// Smallest accepted.
        min: u32,
        /// Largest accepted.
        max: u32,
    },
    /// A length outside its range, metres.
    #[error("{value_m} m is outside [{min_m}, {max_m}] m")]
    Length {
        /// The value, metres.
        value_m: f64,
        /// Smallest accepted, metres.
        min_m: f64,
        /// Largest accepted, metres.
        max_m: f64,
    },
    /// The avenue is narrower than the street or wider than 200 m.
    #[error("{avenue_width_m} m is outside [street_width_m = {street_width_m}, 200] m")]
    AvenueWidth {
        /// `avenue_width_m`.
        avenue_width_m: f64,
        /// `street_width_m`.
        street_width_m: f64,
    },
    /// An angle outside its range, degrees.
    #[error("{value_deg} is outside [{min_deg}, {max_deg}] degrees")]
    Angle {
        /// The value, degrees.
        value_deg: f64,
        /// Smallest accepted, degrees.
        min_deg: f64,
        /// Largest accepted, degrees.
        max_deg: f64,
    },
    /// More tower and plaza blocks than blocks.
    #[error("tower_blocks + plaza_blocks = {special} exceeds the {blocks} blocks")]
    SpecialBlocks {
        /// `tower_blocks + plaza_blocks`.
        special: u64,
        /// `blocks_x × blocks_y`.
        blocks: u64,
    },
    /// A height range that is not an ordered pair within its bounds.
    #[error("{range_m:?} must be an ordered pair [min, max] within [{min_m}, {max_m}] m")]
    HeightRange {
        /// The pair, metres.
        range_m: [f64; 2],
        /// Smallest accepted, metres.
        min_m: f64,
        /// Largest accepted, metres.
        max_m: f64,
    },
    /// The plane origin is not finite.
    #[error("not finite: easting {easting_m} m, northing {northing_m} m")]
    Origin {
        /// Easting, metres.
        easting_m: f64,
        /// Northing, metres.
        northing_m: f64,
    },
}

/// The error of the parser a reader delegates to, kept as the cause of a [`LodError::Malformed`].
#[derive(Debug, thiserror::Error)]
pub enum ParseError {
    /// serde_json's error (CityJSON, sidecars).
    #[error(transparent)]
    Json(#[from] serde_json::Error),
    /// quick-xml's error (CityGML).
    #[error(transparent)]
    Xml(#[from] quick_xml::Error),
    /// tobj's error (OBJ).
    #[error(transparent)]
    Obj(#[from] tobj::LoadError),
}

impl LodError {
    /// A [`LodError::Malformed`] without a parser error.
    pub fn malformed(path: impl Into<PathBuf>, problem: SyntaxProblem) -> Self {
        LodError::Malformed { path: path.into(), problem: Box::new(problem), source: None }
    }

    /// A [`LodError::Malformed`] caused by the parser error `source`.
    pub fn unparsable(
        path: impl Into<PathBuf>,
        problem: SyntaxProblem,
        source: impl Into<ParseError>,
    ) -> Self {
        LodError::Malformed { path: path.into(), problem: Box::new(problem), source: Some(source.into()) }
    }

    /// A [`LodError::Invalid`]: `problem` is wrong at `at` in the file `path`.
    pub fn invalid(path: impl Into<PathBuf>, at: impl Into<String>, problem: impl Into<LodProblem>) -> Self {
        LodError::Invalid { path: path.into(), at: at.into(), problem: Box::new(problem.into()) }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn counts() -> NoBuildings {
        NoBuildings { found: 1, without_surface: 1, all_degenerate: 0, faces_dropped: 2, others_skipped: 3 }
    }

    /// The texts are the ones the readers wrote before their problems were typed.
    #[test]
    fn problem_texts() {
        let cases: Vec<(String, &str)> = vec![
            (
                LodError::invalid("a.json", "CityObjects[\"b\"].geometry[0].boundaries[1][0][2]", CityJsonProblem::VertexIndex {
                    index: 99,
                    list: "vertices",
                    vertices: 3,
                })
                .to_string(),
                "a.json: CityObjects[\"b\"].geometry[0].boundaries[1][0][2]: vertex index 99 is out of range \
                 (vertices has 3 vertices)",
            ),
            (
                CityJsonProblem::Coordinate { list: "vertices", index: 1, coordinate: [1e297, 447000.5, f64::NAN] }
                    .to_string(),
                "vertices[1] gives the coordinate [1e297, 447000.5, NaN], which is not finite or beyond ±1e9",
            ),
            (
                CityJsonProblem::NoBuildings { lod: None, counts: counts() }.to_string(),
                "no buildings with geometry: 1 building(s) found, 1 without any LoD 1–2.2 surface, 0 whose LoD 1–2.2 \
                 surfaces are all degenerate (2 face(s) dropped: fewer than 3 distinct points or zero area); 3 other \
                 city object(s) skipped",
            ),
            (
                CityJsonProblem::NoBuildings { lod: Some("2.2".into()), counts: counts() }.to_string(),
                "no buildings with geometry: 1 building(s) found, 1 without any LoD \"2.2\" surface, 0 whose LoD \
                 \"2.2\" surfaces are all degenerate (2 face(s) dropped: fewer than 3 distinct points or zero area); \
                 3 other city object(s) skipped",
            ),
            (
                CityGmlProblem::NoBuildings { lod: None, counts: counts() }.to_string(),
                "no buildings with geometry: 1 building(s) found, 1 without any LoD 0, 1 or 2 surface, 0 whose LoD 0, \
                 1 or 2 surfaces are all degenerate (2 face(s) dropped: fewer than 3 distinct points, zero area, or \
                 outside the document envelope); 3 other city object(s) skipped",
            ),
            (
                CityJsonProblem::Template { template: None, templates: 2 }.to_string(),
                "template (missing) does not exist (the file has 2 geometry template(s))",
            ),
            (
                CityJsonProblem::BoundaryDepth { kind: "Solid".into(), expected: 4, found: 2 }.to_string(),
                "a Solid needs vertex indices at nesting depth 4, found depth 2",
            ),
            (
                CityJsonProblem::NotCityJson { found: "FeatureCollection".into() }.to_string(),
                "expected \"CityJSON\", found \"FeatureCollection\": not a CityJSON file",
            ),
            (
                LodError::malformed("a.json", SyntaxProblem::TruncatedJson { line: 244, column: 3 }).to_string(),
                "a.json: truncated JSON: the file ends at line 244, column 3 before the document is complete",
            ),
            (
                SyntaxProblem::Json { line: 3, column: 7, message: "expected value".into() }.to_string(),
                "malformed JSON at line 3, column 7: expected value (NaN and Infinity are not JSON numbers)",
            ),
            (
                SyntaxProblem::Json { line: 3, column: 7, message: "vertex index -2 is negative".into() }.to_string(),
                "malformed JSON at line 3, column 7: vertex index -2 is negative",
            ),
            (
                SyntaxProblem::WrongFormat { expected: "JSON", looks: "XML", document: "a CityJSON document" }
                    .to_string(),
                "not JSON: the file holds XML (CityGML? name it .gml or set format = \"citygml\" in the scene file), \
                 not a CityJSON document",
            ),
            (
                SyntaxProblem::WrongFormat { expected: "XML", looks: "empty", document: "a CityGML document" }
                    .to_string(),
                "not XML: the file is empty, not a CityGML document",
            ),
            (
                SyntaxProblem::TruncatedXml {
                    at: "line 21, column 1 (byte 700)".into(),
                    building: Some("cut".into()),
                    open: 5,
                    innermost: "gml:posList".into(),
                    outermost: "core:CityModel".into(),
                }
                .to_string(),
                "truncated XML: the file ends at line 21, column 1 (byte 700) inside building gml:id \"cut\" with 5 \
                 element(s) still open (innermost <gml:posList>, outermost <core:CityModel>)",
            ),
            (
                CityGmlProblem::Coordinate { token: "NaN".into() }.to_string(),
                "coordinate NaN is not finite or beyond ±1e9",
            ),
            (
                CityGmlProblem::PointCount { element: "gml:posList", numbers: 11, dimension: 3 }.to_string(),
                "gml:posList holds 11 number(s), which is not a whole number of 3-D points",
            ),
            (
                CityGmlProblem::LodOption { given: "3".into() }.to_string(),
                "CityGML buildings are read at LoD \"0\", \"1\" or \"2\", not \"3\"",
            ),
            (
                ObjProblem::NoSidecar { tried: ["m.obj.json".into(), "m.json".into()] }.to_string(),
                "an OBJ needs a sidecar JSON giving its CRS, offset and up axis, but neither m.obj.json nor m.json \
                 exists; create one, e.g. {\"crs\": \"EPSG:6677\", \"offset\": [0, 0, 0], \"axes\": \"z_up\"} \
                 (schema: schemas/obj_sidecar.schema.json)",
            ),
            (
                LodError::InvalidTileset {
                    path: "t/tileset.json".into(),
                    issues: vec![
                        TilesetIssue { at: "root.geometricError".into(), problem: TilesetProblem::NoGeometricError },
                        TilesetIssue {
                            at: "root.children[0].boundingVolume.box".into(),
                            problem: TilesetProblem::BoundingVolume { needed: 12, found: 3 },
                        },
                        TilesetIssue {
                            at: "root.children[1].refine".into(),
                            problem: TilesetProblem::Refine { found: "MERGE".into() },
                        },
                    ],
                }
                .to_string(),
                "t/tileset.json: root.geometricError: is missing (and 2 more: root.children[0].boundingVolume.box: \
                 needs 12 finite numbers, has 3; root.children[1].refine: \"MERGE\" is not ADD or REPLACE)",
            ),
            (
                TilesetProblem::Cycle { chain: vec!["a/tileset.json".into(), "b/x.json".into(), "a/tileset.json".into()] }
                    .to_string(),
                "external tilesets form a cycle: a/tileset.json → b/x.json → a/tileset.json",
            ),
            (
                LodError::invalid("procedural", "procedural.avenue_width_m", ProceduralProblem::AvenueWidth {
                    avenue_width_m: 5.0,
                    street_width_m: 12.0,
                })
                .to_string(),
                "procedural: procedural.avenue_width_m: 5 m is outside [street_width_m = 12, 200] m",
            ),
            (
                ProceduralProblem::HeightRange { range_m: [30.0, 10.0], min_m: 3.0, max_m: 100.0 }.to_string(),
                "[30.0, 10.0] must be an ordered pair [min, max] within [3, 100] m",
            ),
            (
                ProceduralProblem::Count { value: 0, min: 1, max: 200 }.to_string(),
                "0 is outside 1..=200",
            ),
        ];
        for (got, want) in cases {
            assert_eq!(got, want);
        }
    }
}
