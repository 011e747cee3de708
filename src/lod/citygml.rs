//! CityGML 2.0 reader (PLATEAU included): `bldg:Building` → [`SourceBuilding`] with LoD1/LoD2 polygons.
//!
//! Takes one `.gml` file and hands on a [`SourceModel`] in the file's own CRS (axis order as GML
//! writes it, [`AxisConvention::Authority`]: EPSG:6697 is latitude, longitude, height).
//!
//! The file is streamed with quick-xml's pull parser; no DOM is built, so memory is proportional to
//! one building's geometry (a 1 GB file is fine). Elements are matched by *local name*, so any
//! namespace prefix works (`bldg:`, `core:`, `gml:`, PLATEAU's `uro:` 1.4/2.x/3.x extensions).
//!
//! What is read:
//! - every top-level `Building` (usually a `cityObjectMember` child); its `BuildingPart`s (inside
//!   `consistsOfBuildingPart`, any depth) are folded into it and share its `gml:id`; other city
//!   objects are counted in [`ReadStats::skipped_non_building`];
//! - geometry from `lod0FootPrint`, `lod0RoofEdge`, `lod0MultiSurface` (flat LoD0, used only for a
//!   building that has no usable LoD1/LoD2 geometry), `lod1Solid`, `lod1MultiSurface`, `lod2Solid`, `lod2MultiSurface` (also inside
//!   `boundedBy` surfaces: `WallSurface`, `RoofSurface`, `GroundSurface`, …) and `lod2Geometry`
//!   (outer `BuildingInstallation`s). LoD3/4 are ignored. Degenerate faces of LoDs that were not
//!   chosen (e.g. a broken footprint of a building read at LoD2) are counted in
//!   [`ReadStats::degenerate_faces_unused`] with a warning;
//! - GML surfaces: `Solid`/`Shell`/`CompositeSurface`/`MultiSurface`/`OrientableSurface` are walked
//!   down to `Polygon`/`PolygonPatch`/`Triangle`/`Rectangle` with `exterior`/`interior`
//!   (`outerBoundaryIs`/`innerBoundaryIs`) `LinearRing`s given as `posList` (with `srsDimension` 2
//!   or 3, on the element or an ancestor), `pos` lists or `coordinates`;
//! - `xlink:href="#id"` references to surfaces defined elsewhere *in the same building* (PLATEAU
//!   `lod2Solid`s reference their `boundedBy` polygons): resolved at the end of the building, and
//!   each polygon is emitted once however often it is referenced;
//! - `bldg:measuredHeight` of the building (metres);
//! - appearances (`app:Appearance`, at the city-model level as PLATEAU writes them or inside a
//!   building): `app:ParameterizedTexture` (`imageURI`; `target uri="#polygon"` with `TexCoordList/
//!   textureCoordinates ring="#ring"`, matched to the ring's gml:id, else by position) and
//!   `app:X3DMaterial` (`diffuseColor`, `target` text). Theme: [`ReadOptions::theme`], else the first
//!   `app:theme` of each kind in document order; texture coordinates follow the ring clean-up below
//!   ([`super::clean_ring_indices`]). A texture wins over a colour on the same face. Targets that name
//!   no read polygon, or whose coordinates do not cover its ring, are counted
//!   ([`super::ModelAppearance::unusable_targets`]); `TexCoordGen` and `GeoreferencedTexture` are not read.
//!
//! LoD choice: [`ReadOptions::lod`] `"1"` or `"2"` forces one; by default a building gets the highest
//! LoD ≤ 2 it has. A building part that lacks the chosen LoD contributes its best lower LoD instead,
//! so a part never vanishes; [`SourceBuilding::lod`] names the chosen (highest) LoD.
//!
//! Clean-up and checks: rings lose their closing vertex and consecutive duplicates; rings with
//! fewer than 3 distinct points or zero area are dropped ([`ReadStats::degenerate_faces`]; a
//! degenerate hole is dropped alone). A polygon with a vertex far outside the document's declared
//! `gml:Envelope` (by more than the envelope's own horizontal size) is dropped as well and counted
//! with the degenerate faces, with a warning naming the building and the value — real PLATEAU data
//! has such stray coordinates (a latitude of 135.53 in a file spanning 35.532–35.534).
//! Non-finite or absurd (|v| > 1e9) numbers are an error naming the building and the value;
//! malformed or truncated XML is an error with line and column.

use std::collections::{HashMap, HashSet};
use std::fs::File;
use std::io::{BufRead, BufReader, Read};
use std::path::Path;

use quick_xml::events::{BytesStart, Event};
use quick_xml::Reader;

use super::error::{CityGmlProblem, NoBuildings, SyntaxProblem};
use super::{
    clean_ring_indices, AxisConvention, FaceAppearance, Frame, Geometry, LodError, ModelAppearance, Polygon,
    ReadOptions, ReadStats, SourceBuilding, SourceModel, MAX_ABS_COORDINATE,
};
use crate::util::FileError;

/// An XML attribute's unescaped value.
type AttrValue = String;

/// LoDs this reader takes geometry from, by index: 0 = LoD1, 1 = LoD2.
const LOD_NAMES: [&str; 3] = ["0", "1", "2"];

/// Reads one CityGML 2.0 file.
///
/// # Errors
/// - [`LodError::File`] if the file cannot be opened or read;
/// - [`LodError::Malformed`] for ill-formed or truncated XML (with line and column);
/// - [`LodError::Invalid`] for a bad coordinate (not a number, non-finite, |v| > 1e9, a `posList`
///   whose length is not a multiple of `srsDimension`), a `gml:id` used by two buildings, an
///   unsupported [`ReadOptions::lod`], or a file without any building that has usable geometry
///   (the message says how many buildings were empty or entirely degenerate).
pub fn read(path: &Path, opts: &ReadOptions) -> Result<SourceModel, LodError> {
    let forced_lod = match opts.lod.as_deref().map(str::trim) {
        None => None,
        Some("0") | Some("0.0") => Some(0),
        Some("1") | Some("1.0") => Some(1),
        Some("2") | Some("2.0") => Some(2),
        Some(other) => {
            return Err(LodError::invalid(
                path,
                "option lod",
                CityGmlProblem::LodOption { given: other.to_string() },
            ))
        }
    };
    let file = File::open(path).map_err(|e| FileError::new("opening", path, e))?;
    let mut parser = Parser::new(path, forced_lod);
    parser.wanted_theme = opts.theme.clone();
    parser.no_appearance = opts.no_appearance;
    parser.no_materials = opts.no_materials;
    parser.file_len = file.metadata().ok().map(|m| m.len());
    parser.run(BufReader::with_capacity(1 << 16, file))?;
    parser.finish()
}

/// Why a polygon read from the file is not used.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Dropped {
    /// Fewer than 3 distinct points, or zero area.
    Degenerate,
    /// A vertex lies far outside the document envelope; the offending (x, y).
    OutsideEnvelope([f64; 2]),
}

/// One item of a building component's surface list at one LoD.
#[derive(Debug)]
enum Entry {
    /// A polygon defined here (index into [`Building::polygons`]).
    Inline(usize),
    /// `xlink:href="#id"`: the polygons of the element with that `gml:id`.
    Ref(String),
}

/// The building itself or one of its parts: surface lists per LoD.
#[derive(Debug, Default)]
struct Component {
    entries: [Vec<Entry>; 3],
}

/// The building being read.
#[derive(Debug)]
struct Building {
    id: String,
    measured_height_m: Option<f64>,
    components: Vec<Component>,
    /// Index into `components` of the part being read (innermost last; `[0]` = the building).
    component_stack: Vec<usize>,
    polygons: Vec<Result<Polygon, Dropped>>,
    /// Per polygon of `polygons`: its ring ids and kept vertex indices, for texture coordinates.
    poly_meta: Vec<Option<PolyMeta>>,
    /// `gml:id` → range of `polygons` defined inside that element.
    id_ranges: HashMap<String, (usize, usize)>,
    /// LoD index of the geometry property being read, if any.
    geom_lod: Option<usize>,
    polygon: Option<PolygonAcc>,
    ring: Option<RingAcc>,
}

/// Per LoD and component: polygon indices into [`Building::polygons`].
type LodLists = [Vec<Vec<usize>>; 3];

/// A building's surface lists with references resolved.
struct SurfaceLists {
    /// Per LoD and component: the polygon indices, each polygon once per building and LoD.
    lists: LodLists,
    /// Per LoD: the `xlink:href` ids that name no element of the building.
    unresolved: [Vec<String>; 3],
}

impl Building {
    /// Resolves every component's entries to polygon indices.
    fn surface_lists(&self) -> SurfaceLists {
        let n = self.polygons.len();
        let mut lists: LodLists = [Vec::new(), Vec::new(), Vec::new()];
        let mut unresolved: [Vec<String>; 3] = [Vec::new(), Vec::new(), Vec::new()];
        for lod in 0..3 {
            let mut seen = vec![false; n];
            for comp in &self.components {
                let mut list = Vec::new();
                for entry in &comp.entries[lod] {
                    let range = match entry {
                        Entry::Inline(i) => *i..*i + 1,
                        Entry::Ref(id) => match self.id_ranges.get(id) {
                            Some(&(s, e)) => s..e,
                            None => {
                                unresolved[lod].push(id.clone());
                                0..0
                            }
                        },
                    };
                    for i in range {
                        if !seen[i] {
                            seen[i] = true;
                            list.push(i);
                        }
                    }
                }
                lists[lod].push(list);
            }
        }
        SurfaceLists { lists, unresolved }
    }

    /// Whether any polygon of `list` is usable.
    fn any_usable(&self, list: &[usize]) -> bool {
        list.iter().any(|&i| self.polygons[i].is_ok())
    }
}

#[derive(Debug, Default)]
struct PolygonAcc {
    id: Option<String>,
    exterior: Option<Vec<[f64; 3]>>,
    exterior_id: Option<String>,
    interiors: Vec<Vec<[f64; 3]>>,
    interior_ids: Vec<Option<String>>,
    outlier: Option<[f64; 2]>,
}

#[derive(Debug)]
struct RingAcc {
    exterior: bool,
    /// The `LinearRing`'s gml:id (what `textureCoordinates/@ring` names).
    id: Option<String>,
    points: Vec<[f64; 3]>,
}

/// What texture coordinates need of an emitted polygon: per kept ring (exterior first), its gml:id and
/// the indices of the points kept by the clean-up.
#[derive(Debug, Clone)]
struct PolyMeta {
    /// The polygon's gml:id.
    id: String,
    rings: Vec<(Option<String>, Vec<usize>)>,
}

/// The texture coordinates of one ring: the `ring` it names (gml:id) and the (u, v) pairs.
type RingCoords = (Option<String>, Vec<[f64; 2]>);

/// One `app:ParameterizedTexture` of the chosen or any theme, as read.
#[derive(Debug, Default)]
struct TextureAcc {
    theme: String,
    image_uri: String,
    /// (polygon gml:id, [(ring gml:id, coordinates)]).
    targets: Vec<(String, Vec<RingCoords>)>,
}

/// One `app:X3DMaterial`, as read.
#[derive(Debug, Default)]
struct MaterialAcc {
    theme: String,
    rgb: Option<[f64; 3]>,
    /// Polygon gml:ids.
    targets: Vec<String>,
}

/// The `app:Appearance` being read.
#[derive(Debug, Default)]
struct AppearanceAcc {
    theme: String,
    texture: Option<TextureAcc>,
    material: Option<MaterialAcc>,
}

/// What an open element means to the reader.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Role {
    Other,
    /// `cityObjectMember` / `featureMember(s)`: its children are city objects.
    Member,
    /// The document's `gml:Envelope`.
    DocEnvelope,
    LowerCorner,
    UpperCorner,
    Building,
    Part,
    MeasuredHeight,
    GeomProp,
    Polygon,
    Exterior,
    Interior,
    Ring,
    PosList,
    Pos,
    Coordinates,
    /// A `posList`/`pos`/`coordinates` outside any building (roads, relief, …): only checked.
    SkippedCoords,
    /// `app:Appearance` and the elements inside it.
    Appearance,
    AppTheme,
    AppImageUri,
    AppDiffuse,
    /// `app:target` of an X3DMaterial (the polygon's URI is the text).
    AppTargetText,
    /// `app:target uri="…"` of a ParameterizedTexture (coordinates inside).
    AppTarget,
    AppTexCoords,
}

/// One open element.
#[derive(Debug)]
struct Open {
    role: Role,
    /// `gml:id` of an element inside a geometry property, with the polygon count at its start.
    id_scope: Option<(String, usize)>,
    /// `srsDimension` declared on this element.
    srs_dim: Option<usize>,
}

/// The document envelope (`CityModel/boundedBy/Envelope`).
#[derive(Debug, Default)]
struct Envelope {
    srs_name: Option<String>,
    lower: Option<Vec<f64>>,
    upper: Option<Vec<f64>>,
}

impl Envelope {
    /// The accepted horizontal box `[min_x, min_y, max_x, max_y]`: the envelope grown on every side
    /// by its larger horizontal size, or `None` when the envelope is absent or unusable.
    fn accepted_box(&self) -> Option<[f64; 4]> {
        let (lo, hi) = (self.lower.as_ref()?, self.upper.as_ref()?);
        if lo.len() < 2 || hi.len() < 2 || lo[0] > hi[0] || lo[1] > hi[1] {
            return None;
        }
        let margin = (hi[0] - lo[0]).max(hi[1] - lo[1]);
        let b = [lo[0] - margin, lo[1] - margin, hi[0] + margin, hi[1] + margin];
        b.iter().all(|v| v.is_finite()).then_some(b)
    }
}

/// Qualified names of the open elements, for messages (one string buffer, no allocation per element).
#[derive(Debug, Default)]
struct NameStack {
    buf: String,
    ends: Vec<usize>,
}

impl NameStack {
    fn push(&mut self, name: &str) {
        self.buf.push_str(name);
        self.ends.push(self.buf.len());
    }
    fn pop(&mut self) {
        self.ends.pop();
        self.buf.truncate(self.ends.last().copied().unwrap_or(0));
    }
    fn len(&self) -> usize {
        self.ends.len()
    }
    fn get(&self, i: usize) -> &str {
        let start = if i == 0 { 0 } else { self.ends[i - 1] };
        &self.buf[start..self.ends[i]]
    }
}

/// Counts of why buildings or faces were dropped (for the warnings and the final error message).
#[derive(Debug, Default)]
struct Dropping {
    buildings_seen: u64,
    buildings_empty: u64,
    buildings_degenerate: u64,
    outside_envelope: u64,
    unresolved_refs: u64,
}

struct Parser<'p> {
    path: &'p Path,
    forced_lod: Option<usize>,
    names: NameStack,
    open: Vec<Open>,
    envelope: Envelope,
    accepted_box: Option<[f64; 4]>,
    /// First `srsName` on any geometry, used when the document envelope names none.
    first_srs_name: Option<String>,
    /// Whether text is being collected (`text` holds it).
    capturing: bool,
    text: String,
    building: Option<Building>,
    seen_ids: HashSet<String>,
    buildings: Vec<SourceBuilding>,
    stats: ReadStats,
    dropping: Dropping,
    /// Byte offset of the event being handled (for line numbers in messages).
    event_pos: u64,
    /// Size of the file, to tell a truncated file from other syntax errors.
    file_len: Option<u64>,
    /// Whether the root element (`CityModel`) has been seen.
    root_seen: bool,
    /// Where the first unusable coordinate outside any building is (for the warning).
    first_bad_unused: Option<String>,
    /// `ReadOptions::theme` / `no_appearance`.
    wanted_theme: Option<String>,
    no_appearance: bool,
    no_materials: bool,
    /// The appearance being read, and all read so far.
    appearance: Option<AppearanceAcc>,
    textures: Vec<TextureAcc>,
    materials: Vec<MaterialAcc>,
    /// Themes in document order.
    themes: Vec<String>,
    /// `ring` attribute of the `textureCoordinates` being read.
    tex_ring: Option<String>,
    /// Emitted polygons by gml:id: (index in `buildings`, polygon index), and their ring data.
    poly_refs: HashMap<String, (usize, usize)>,
    poly_meta: Vec<Vec<Option<PolyMeta>>>,
}

fn local(name: &str) -> &str {
    name.rsplit_once(':').map_or(name, |(_, l)| l)
}

impl<'p> Parser<'p> {
    fn new(path: &'p Path, forced_lod: Option<usize>) -> Self {
        Parser {
            path,
            forced_lod,
            names: NameStack::default(),
            open: Vec::new(),
            envelope: Envelope::default(),
            accepted_box: None,
            first_srs_name: None,
            capturing: false,
            text: String::new(),
            building: None,
            seen_ids: HashSet::new(),
            buildings: Vec::new(),
            stats: ReadStats::default(),
            dropping: Dropping::default(),
            event_pos: 0,
            file_len: None,
            root_seen: false,
            first_bad_unused: None,
            wanted_theme: None,
            no_appearance: false,
            no_materials: false,
            appearance: None,
            textures: Vec::new(),
            materials: Vec::new(),
            themes: Vec::new(),
            tex_ring: None,
            poly_refs: HashMap::new(),
            poly_meta: Vec::new(),
        }
    }

    fn run<R: BufRead>(&mut self, input: R) -> Result<(), LodError> {
        let mut reader = Reader::from_reader(input);
        let mut buf = Vec::with_capacity(1 << 16);
        loop {
            self.event_pos = reader.buffer_position();
            let event = match reader.read_event_into(&mut buf) {
                Ok(ev) => ev,
                // Garbage before any element (random bytes, a binary file): not XML at all.
                Err(_) if !self.root_seen => return Err(self.not_xml()),
                Err(e) => {
                    let at = self.locate(reader.error_position());
                    // A tag, comment or CDATA left open at the very end: the file was cut.
                    let at_end = self.file_len.is_some_and(|n| reader.buffer_position() >= n);
                    let problem = if at_end && matches!(e, quick_xml::Error::Syntax(_)) {
                        SyntaxProblem::XmlCut { at }
                    } else {
                        SyntaxProblem::Xml { at }
                    };
                    return Err(LodError::unparsable(self.path, problem, e));
                }
            };
            match event {
                Event::Start(e) => {
                    self.check_root(&e)?;
                    self.start(&e)?;
                    self.names.push(e.name().0);
                }
                Event::Empty(e) => {
                    self.check_root(&e)?;
                    self.start(&e)?;
                    self.names.push(e.name().0);
                    self.end()?;
                    self.names.pop();
                }
                Event::End(_) => {
                    self.end()?;
                    self.names.pop();
                }
                Event::Text(t) if self.capturing => self.text.push_str(&t),
                Event::Text(t) if !self.root_seen && !t.trim().is_empty() => return Err(self.not_xml()),
                Event::CData(t) if self.capturing => self.text.push_str(&t),
                Event::GeneralRef(r) if self.capturing => {
                    let c = match r.resolve_char_ref() {
                        Ok(Some(c)) => Some(c),
                        _ => match &*r {
                            "lt" => Some('<'),
                            "gt" => Some('>'),
                            "amp" => Some('&'),
                            "apos" => Some('\''),
                            "quot" => Some('"'),
                            _ => None,
                        },
                    };
                    // An unknown entity inside a number list cannot be a number: keep it visible.
                    match c {
                        Some(c) => self.text.push(c),
                        None => {
                            self.text.push('&');
                            self.text.push_str(&r);
                            self.text.push(';');
                        }
                    }
                }
                Event::Eof => break,
                _ => {}
            }
            buf.clear();
        }
        if !self.root_seen {
            return Err(self.not_xml());
        }
        if self.names.len() > 0 {
            let at = self.locate(self.event_pos);
            return Err(LodError::malformed(
                self.path,
                SyntaxProblem::TruncatedXml {
                    at,
                    building: self.building.as_ref().map(|b| b.id.clone()),
                    open: self.names.len(),
                    innermost: self.names.get(self.names.len() - 1).to_string(),
                    outermost: self.names.get(0).to_string(),
                },
            ));
        }
        Ok(())
    }

    /// Checks the document's root element: a CityGML `CityModel` (or a WFS/GML `FeatureCollection`
    /// of city objects).
    fn check_root(&mut self, e: &BytesStart) -> Result<(), LodError> {
        if self.root_seen || self.names.len() > 0 {
            return Ok(());
        }
        self.root_seen = true;
        let qname = e.name();
        let name = qname.0.to_string();
        if matches!(local(&name), "CityModel" | "FeatureCollection") {
            return Ok(());
        }
        let at = self.locate(self.event_pos);
        Err(LodError::invalid(self.path, format!("root element <{name}> ({at})"), CityGmlProblem::NotCityGml))
    }

    /// The error for a file that is not XML at all, naming what it looks like.
    fn not_xml(&self) -> LodError {
        super::wrong_format(self.path, "XML", "a CityGML document (no CityModel element)")
    }

    /// Handles a start tag (also the start half of an empty element).
    fn start(&mut self, e: &BytesStart) -> Result<(), LodError> {
        let qname = e.name();
        let name = local(qname.0);
        let depth = self.names.len();
        let parent = self.open.last().map_or(Role::Other, |o| o.role);
        let mut open = Open { role: Role::Other, id_scope: None, srs_dim: None };

        if name == "Appearance" && !self.no_appearance || self.appearance.is_some() {
            self.appearance_start(e, name, parent, &mut open)?;
        } else if self.building.is_none() {
            match name {
                "Building" | "BuildingPart" => {
                    self.dropping.buildings_seen += 1;
                    let id = match self.attr(e, "id")? {
                        Some(id) => id,
                        None => format!(
                            "{}#building{}",
                            self.path.file_name().map(|n| n.to_string_lossy()).unwrap_or_default(),
                            self.dropping.buildings_seen
                        ),
                    };
                    if !self.seen_ids.insert(id.clone()) {
                        let at = self.locate(self.event_pos);
                        return Err(LodError::invalid(
                            self.path,
                            format!("gml:id {id:?} ({at})"),
                            CityGmlProblem::DuplicateId,
                        ));
                    }
                    self.building = Some(Building {
                        id,
                        measured_height_m: None,
                        components: vec![Component::default()],
                        component_stack: vec![0],
                        polygons: Vec::new(),
                        poly_meta: Vec::new(),
                        id_ranges: HashMap::new(),
                        geom_lod: None,
                        polygon: None,
                        ring: None,
                    });
                    open.role = Role::Building;
                }
                "cityObjectMember" | "featureMember" | "featureMembers" => open.role = Role::Member,
                "Envelope"
                    if depth == 2 && self.buildings.is_empty() && self.dropping.buildings_seen == 0 =>
                {
                    open.role = Role::DocEnvelope;
                    self.envelope.srs_name = self.attr(e, "srsName")?;
                }
                "lowerCorner" if parent == Role::DocEnvelope => open.role = Role::LowerCorner,
                "posList" | "pos" | "coordinates" => open.role = Role::SkippedCoords,
                "upperCorner" if parent == Role::DocEnvelope => open.role = Role::UpperCorner,
                _ if parent == Role::Member => self.stats.skipped_non_building += 1,
                _ => {}
            }
        } else {
            let in_geom = self.building.as_ref().is_some_and(|b| b.geom_lod.is_some());
            if !in_geom {
                match name {
                    "BuildingPart" => {
                        let b = self.building_mut();
                        b.components.push(Component::default());
                        let k = b.components.len() - 1;
                        b.component_stack.push(k);
                        open.role = Role::Part;
                    }
                    "measuredHeight" if parent == Role::Building => open.role = Role::MeasuredHeight,
                    "lod0FootPrint" | "lod0RoofEdge" | "lod0MultiSurface" => open.role = Role::GeomProp,
                    "lod1Solid" | "lod1MultiSurface" | "lod1Geometry" => open.role = Role::GeomProp,
                    "lod2Solid" | "lod2MultiSurface" | "lod2Geometry" => open.role = Role::GeomProp,
                    _ => {}
                }
                if open.role == Role::GeomProp {
                    let lod = match name.as_bytes().get(3) {
                        Some(b'0') => 0,
                        Some(b'1') => 1,
                        _ => 2,
                    };
                    self.building_mut().geom_lod = Some(lod);
                    if let Some(href) = self.attr(e, "href")? {
                        self.push_ref(href);
                    }
                }
            } else {
                self.geometry_start(e, name, parent, &mut open)?;
            }
        }
        if open.role.is_capture() {
            self.capturing = true;
            self.text.clear();
        }
        self.open.push(open);
        Ok(())
    }

    /// A start tag inside a geometry property.
    fn geometry_start(
        &mut self,
        e: &BytesStart,
        name: &str,
        parent: Role,
        open: &mut Open,
    ) -> Result<(), LodError> {
        let in_polygon = self.building.as_ref().is_some_and(|b| b.polygon.is_some());
        if self.first_srs_name.is_none() {
            self.first_srs_name = self.attr(e, "srsName")?;
        }
        if let Some(dim) = self.attr(e, "srsDimension")? {
            open.srs_dim = Some(self.parse_dim(&dim)?);
        }
        if !in_polygon {
            if let Some(id) = self.attr(e, "id")? {
                let start = self.building_mut().polygons.len();
                open.id_scope = Some((id, start));
            }
            if let Some(href) = self.attr(e, "href")? {
                self.push_ref(href);
            }
        }
        match name {
            "Polygon" | "PolygonPatch" | "Triangle" | "Rectangle" if !in_polygon => {
                let id = open.id_scope.as_ref().map(|(id, _)| id.clone());
                self.building_mut().polygon = Some(PolygonAcc { id, ..PolygonAcc::default() });
                open.role = Role::Polygon;
            }
            "exterior" | "outerBoundaryIs" if in_polygon && parent == Role::Polygon => {
                open.role = Role::Exterior
            }
            "interior" | "innerBoundaryIs" if in_polygon && parent == Role::Polygon => {
                open.role = Role::Interior
            }
            "LinearRing" if matches!(parent, Role::Exterior | Role::Interior) => {
                let exterior = parent == Role::Exterior;
                let id = self.attr(e, "id")?;
                self.building_mut().ring = Some(RingAcc { exterior, id, points: Vec::new() });
                open.role = Role::Ring;
            }
            "posList" if parent == Role::Ring => open.role = Role::PosList,
            "pos" if parent == Role::Ring => open.role = Role::Pos,
            "coordinates" if parent == Role::Ring => open.role = Role::Coordinates,
            _ => {}
        }
        Ok(())
    }

    /// A start tag inside `app:Appearance` (CityGML 2.0 appearance module): theme, textures with
    /// their targets and coordinates, X3D materials with their colour and targets.
    fn appearance_start(
        &mut self,
        e: &BytesStart,
        name: &str,
        parent: Role,
        open: &mut Open,
    ) -> Result<(), LodError> {
        match name {
            "Appearance" if self.appearance.is_none() => {
                self.appearance = Some(AppearanceAcc::default());
                open.role = Role::Appearance;
            }
            "theme" if parent == Role::Appearance => open.role = Role::AppTheme,
            "ParameterizedTexture" => {
                let theme = self.appearance.as_ref().map(|a| a.theme.clone()).unwrap_or_default();
                if let Some(a) = self.appearance.as_mut() {
                    a.texture = Some(TextureAcc { theme, ..TextureAcc::default() });
                }
            }
            "X3DMaterial" => {
                let theme = self.appearance.as_ref().map(|a| a.theme.clone()).unwrap_or_default();
                if let Some(a) = self.appearance.as_mut() {
                    a.material = Some(MaterialAcc { theme, ..MaterialAcc::default() });
                }
            }
            "imageURI" => open.role = Role::AppImageUri,
            "diffuseColor" => open.role = Role::AppDiffuse,
            "target" => {
                let in_texture = self.appearance.as_ref().is_some_and(|a| a.texture.is_some());
                if in_texture {
                    let uri = self.attr(e, "uri")?.unwrap_or_default();
                    let id = uri.strip_prefix('#').unwrap_or(&uri).to_string();
                    if let Some(t) = self.appearance.as_mut().and_then(|a| a.texture.as_mut()) {
                        t.targets.push((id, Vec::new()));
                    }
                    open.role = Role::AppTarget;
                } else {
                    open.role = Role::AppTargetText;
                }
            }
            "textureCoordinates" => {
                let ring = self.attr(e, "ring")?;
                self.tex_ring = ring.map(|r| r.strip_prefix('#').unwrap_or(&r).to_string());
                open.role = Role::AppTexCoords;
            }
            _ => {}
        }
        Ok(())
    }

    /// An end tag inside `app:Appearance`.
    fn appearance_end(&mut self, role: Role) {
        let text = self.text.trim().to_string();
        let Some(a) = self.appearance.as_mut() else { return };
        match role {
            Role::AppTheme => {
                if !self.themes.contains(&text) {
                    self.themes.push(text.clone());
                }
                a.theme = text;
            }
            Role::AppImageUri => {
                if let Some(t) = a.texture.as_mut() {
                    t.image_uri = text;
                }
            }
            Role::AppDiffuse => {
                let v: Vec<f64> = text.split_ascii_whitespace().filter_map(|t| t.parse().ok()).collect();
                if let (Some(m), [r, g, b]) = (a.material.as_mut(), v.as_slice()) {
                    m.rgb = Some([*r, *g, *b]).filter(|c| c.iter().all(|v| v.is_finite()));
                }
            }
            Role::AppTargetText => {
                if let Some(m) = a.material.as_mut() {
                    m.targets.push(text.strip_prefix('#').unwrap_or(&text).to_string());
                }
            }
            Role::AppTexCoords => {
                let uv: Vec<f64> =
                    text.split_ascii_whitespace().map(|t| t.parse().unwrap_or(f64::NAN)).collect();
                let coords: Vec<[f64; 2]> = uv.chunks_exact(2).map(|c| [c[0], c[1]]).collect();
                if let Some((_, rings)) = a.texture.as_mut().and_then(|t| t.targets.last_mut()) {
                    rings.push((self.tex_ring.take(), coords));
                }
            }
            Role::Appearance => {
                // Themes of appearances without an app:theme are "" (as in CityJSON).
                if a.theme.is_empty() && !self.themes.iter().any(String::is_empty) {
                    self.themes.push(String::new());
                }
                self.appearance = None;
            }
            _ => {}
        }
    }

    /// The end of a ParameterizedTexture or X3DMaterial element: keeps what was read.
    fn appearance_surface_end(&mut self, name: &str) {
        let Some(a) = self.appearance.as_mut() else { return };
        match name {
            "ParameterizedTexture" => self.textures.extend(a.texture.take()),
            "X3DMaterial" => self.materials.extend(a.material.take()),
            _ => {}
        }
    }

    /// Applies the chosen themes' textures and materials to the emitted buildings.
    fn resolve_appearances(&mut self) -> ModelAppearance {
        let mut out = ModelAppearance { themes: self.themes.clone(), ..ModelAppearance::default() };
        let first = |list: Vec<&String>| list.first().map(|s| s.to_string());
        out.texture_theme = match &self.wanted_theme {
            Some(w) => Some(w.clone()),
            None => first(self.textures.iter().map(|t| &t.theme).collect()),
        };
        out.material_theme = match &self.wanted_theme {
            Some(w) => Some(w.clone()),
            None => first(self.materials.iter().map(|t| &t.theme).collect()),
        };
        let mut faces: Vec<Vec<Option<FaceAppearance>>> = self
            .buildings
            .iter()
            .map(|b| match &b.geometry {
                Geometry::Polygons(p) => vec![None; p.len()],
                Geometry::Mesh(_) => Vec::new(),
            })
            .collect();
        // Materials first, so that a texture on the same face wins.
        let no_materials = self.no_materials;
        for m in
            self.materials.iter().filter(|m| !no_materials && Some(&m.theme) == out.material_theme.as_ref())
        {
            let Some(rgb) = m.rgb else { continue };
            for t in &m.targets {
                match self.poly_refs.get(t) {
                    Some(&(b, p)) => faces[b][p] = Some(FaceAppearance::Colour { rgb }),
                    None => out.unusable_targets += 1,
                }
            }
        }
        let dir = self.path.parent().unwrap_or(Path::new("."));
        let mut image_index: HashMap<String, usize> = HashMap::new();
        for t in self.textures.iter().filter(|t| Some(&t.theme) == out.texture_theme.as_ref()) {
            let image = *image_index.entry(t.image_uri.clone()).or_insert_with(|| {
                out.images.push(dir.join(&t.image_uri));
                out.images.len() - 1
            });
            for (poly, rings) in &t.targets {
                let Some(&(b, p)) = self.poly_refs.get(poly) else {
                    out.unusable_targets += 1;
                    continue;
                };
                let Some(meta) = self.poly_meta[b][p].as_ref() else { continue };
                // Coordinates of a ring: by its gml:id, else by position.
                let coords_of = |k: usize, id: &Option<String>| {
                    id.as_ref()
                        .and_then(|id| rings.iter().find(|(r, _)| r.as_ref() == Some(id)))
                        .or_else(|| if id.is_none() { rings.get(k) } else { None })
                        .map(|(_, c)| c)
                };
                let pick = |k: usize| -> Option<Vec<[f64; 2]>> {
                    let (id, keep) = &meta.rings[k];
                    let c = coords_of(k, id)?;
                    keep.iter()
                        .map(|&i| c.get(i).copied().filter(|uv| uv.iter().all(|v| v.is_finite())))
                        .collect()
                };
                let Some(uv_exterior) = pick(0) else {
                    out.unusable_targets += 1;
                    continue;
                };
                let uv_interiors = (1..meta.rings.len())
                    .map(|k| pick(k).unwrap_or_else(|| vec![uv_exterior[0]; meta.rings[k].1.len()]))
                    .collect();
                faces[b][p] = Some(FaceAppearance::Texture { image, uv_exterior, uv_interiors });
            }
        }
        for (b, f) in self.buildings.iter_mut().zip(faces) {
            for a in f.iter().flatten() {
                match a {
                    FaceAppearance::Texture { .. } => out.textured_faces += 1,
                    FaceAppearance::Colour { .. } => out.coloured_faces += 1,
                }
            }
            b.appearance = if f.iter().any(Option::is_some) { f } else { Vec::new() };
        }
        out
    }

    /// Handles an end tag (also the end half of an empty element).
    fn end(&mut self) -> Result<(), LodError> {
        let Some(open) = self.open.pop() else {
            return Ok(()); // quick-xml reports unmatched end tags itself
        };
        if open.role.is_capture() {
            self.capturing = false;
        }
        if self.appearance.is_some() {
            let name = self.names.get(self.names.len() - 1);
            let name = local(name).to_string();
            self.appearance_surface_end(&name);
            self.appearance_end(open.role);
            return Ok(());
        }
        match open.role {
            Role::Building => self.finish_building(),
            Role::Part => {
                self.building_mut().component_stack.pop();
            }
            Role::MeasuredHeight => {
                let text = self.text.trim();
                match text.parse::<f64>() {
                    Ok(h) if h.is_finite() => self.building_mut().measured_height_m = Some(h),
                    _ => {
                        let id = &self.building_ref().id;
                        log::warn!(
                            "{}: building {id:?}: measuredHeight {text:?} is not a number; ignored",
                            self.path.display()
                        );
                    }
                }
            }
            Role::LowerCorner => self.envelope.lower = self.parse_envelope_corner()?,
            Role::UpperCorner => self.envelope.upper = self.parse_envelope_corner()?,
            Role::DocEnvelope => self.accepted_box = self.envelope.accepted_box(),
            Role::GeomProp => self.building_mut().geom_lod = None,
            Role::PosList | Role::Pos | Role::Coordinates => self.parse_points(open.role, open.srs_dim)?,
            Role::SkippedCoords => {
                let bad = self
                    .text
                    .split(|c: char| c.is_ascii_whitespace() || c == ',')
                    .filter(|t| !t.is_empty())
                    .filter(|t| {
                        t.parse::<f64>().map_or(true, |v| !v.is_finite() || v.abs() > MAX_ABS_COORDINATE)
                    })
                    .count() as u64;
                if bad > 0 && self.stats.bad_coordinates_unused == 0 {
                    self.first_bad_unused = Some(self.locate(self.event_pos));
                }
                self.stats.bad_coordinates_unused += bad;
            }
            Role::Ring => {
                let b = self.building_mut();
                if let (Some(ring), Some(poly)) = (b.ring.take(), b.polygon.as_mut()) {
                    if ring.exterior && poly.exterior.is_none() {
                        poly.exterior = Some(ring.points);
                        poly.exterior_id = ring.id;
                    } else {
                        poly.interiors.push(ring.points);
                        poly.interior_ids.push(ring.id);
                    }
                }
            }
            Role::Polygon => self.finish_polygon(),
            _ => {}
        }
        if let Some((id, start)) = open.id_scope {
            let b = self.building_mut();
            let end = b.polygons.len();
            b.id_ranges.insert(id, (start, end));
        }
        Ok(())
    }

    fn building_mut(&mut self) -> &mut Building {
        // Only called while a building is open (the callers are reached from building roles).
        self.building.as_mut().expect("a building is open")
    }

    fn building_ref(&self) -> &Building {
        self.building.as_ref().expect("a building is open")
    }

    fn push_ref(&mut self, href: String) {
        let b = self.building_mut();
        let Some(lod) = b.geom_lod else { return };
        let id = href.strip_prefix('#').unwrap_or(&href).to_string();
        let comp = *b.component_stack.last().unwrap_or(&0);
        b.components[comp].entries[lod].push(Entry::Ref(id));
    }

    /// The value of the attribute with this local name (any prefix), unescaped.
    fn attr(&self, e: &BytesStart, local_name: &str) -> Result<Option<AttrValue>, LodError> {
        for attr in e.attributes() {
            let attr = attr.map_err(|err| {
                let at = self.locate(self.event_pos);
                LodError::unparsable(
                    self.path,
                    SyntaxProblem::XmlAttribute { at },
                    quick_xml::Error::from(err),
                )
            })?;
            if local(attr.key.0) == local_name {
                let value = attr.normalized_value(quick_xml::XmlVersion::Implicit1_0).map_err(|err| {
                    let at = self.locate(self.event_pos);
                    LodError::unparsable(self.path, SyntaxProblem::XmlAttributeValue { at }, err)
                })?;
                return Ok(Some(value.into_owned()));
            }
        }
        Ok(None)
    }

    fn parse_dim(&self, text: &str) -> Result<usize, LodError> {
        match text.trim().parse::<usize>() {
            Ok(d @ 2..=3) => Ok(d),
            _ => Err(self.invalid_here(CityGmlProblem::SrsDimension { given: text.to_string() })),
        }
    }

    fn parse_envelope_corner(&self) -> Result<Option<Vec<f64>>, LodError> {
        let mut v = Vec::with_capacity(3);
        for tok in self.text.split_ascii_whitespace() {
            match tok.parse::<f64>() {
                Ok(x) => v.push(x),
                Err(_) => {
                    log::warn!(
                        "{}: gml:Envelope corner {:?} is not a list of numbers; envelope ignored",
                        self.path.display(),
                        self.text.trim()
                    );
                    return Ok(None);
                }
            }
        }
        Ok(Some(v))
    }

    /// Parses the collected text of a `posList`, `pos` or `coordinates` into the current ring.
    fn parse_points(&mut self, role: Role, own_dim: Option<usize>) -> Result<(), LodError> {
        if self.building.as_ref().is_none_or(|b| b.ring.is_none()) {
            return Ok(());
        }
        let inherited = own_dim.or_else(|| self.open.iter().rev().find_map(|o| o.srs_dim));
        let text = std::mem::take(&mut self.text);
        let mut values: Vec<f64> = Vec::new();
        let mut tuple_sizes: Vec<usize> = Vec::new();
        let parse = |tok: &str| -> Result<f64, LodError> {
            let v = tok
                .parse::<f64>()
                .map_err(|_| self.invalid_here(CityGmlProblem::NotANumber { token: tok.to_string() }))?;
            if !v.is_finite() || v.abs() > MAX_ABS_COORDINATE {
                return Err(self.invalid_here(CityGmlProblem::Coordinate { token: tok.to_string() }));
            }
            Ok(v)
        };
        match role {
            Role::Coordinates => {
                for tuple in text.split_ascii_whitespace() {
                    let mut n = 0;
                    for tok in tuple.split(',') {
                        values.push(parse(tok)?);
                        n += 1;
                    }
                    tuple_sizes.push(n);
                }
            }
            _ => {
                for tok in text.split_ascii_whitespace() {
                    values.push(parse(tok)?);
                }
            }
        }
        let dim = match role {
            Role::PosList => inherited.unwrap_or(3),
            Role::Pos => inherited.unwrap_or(values.len()),
            _ => tuple_sizes.first().copied().unwrap_or(3),
        };
        let consistent = match role {
            Role::Coordinates => tuple_sizes.iter().all(|&n| n == dim),
            Role::Pos => values.len() == dim,
            _ => values.len().is_multiple_of(dim),
        };
        if !(2..=3).contains(&dim) || !consistent {
            let element = match role {
                Role::PosList => "gml:posList",
                Role::Pos => "gml:pos",
                _ => "gml:coordinates",
            };
            return Err(self.invalid_here(CityGmlProblem::PointCount {
                element,
                numbers: values.len(),
                dimension: dim,
            }));
        }
        let accepted_box = self.accepted_box;
        let b = self.building_mut();
        let mut outlier = None;
        if let Some(ring) = b.ring.as_mut() {
            for p in values.chunks_exact(dim) {
                let point = [p[0], p[1], if dim == 3 { p[2] } else { 0.0 }];
                if let Some(bx) = accepted_box {
                    if outlier.is_none()
                        && !(point[0] >= bx[0] && point[0] <= bx[2] && point[1] >= bx[1] && point[1] <= bx[3])
                    {
                        outlier = Some([point[0], point[1]]);
                    }
                }
                ring.points.push(point);
            }
        }
        if let (Some(o), Some(poly)) = (outlier, b.polygon.as_mut()) {
            poly.outlier.get_or_insert(o);
        }
        self.text = text;
        Ok(())
    }

    fn finish_polygon(&mut self) {
        let no_appearance = self.no_appearance;
        let b = self.building_mut();
        let Some(acc) = b.polygon.take() else { return };
        let keep_ext = acc.exterior.as_deref().and_then(clean_ring_indices);
        let mut meta = None;
        let slot = match (acc.outlier, keep_ext) {
            (Some(xy), _) => Err(Dropped::OutsideEnvelope(xy)),
            (None, None) => Err(Dropped::Degenerate),
            (None, Some(keep)) => {
                let pick =
                    |ring: &[[f64; 3]], keep: &[usize]| keep.iter().map(|&i| ring[i]).collect::<Vec<_>>();
                let ext = acc.exterior.as_deref().unwrap_or(&[]);
                let mut rings = vec![(acc.exterior_id, keep.clone())];
                let mut interiors = Vec::new();
                for (ring, id) in acc.interiors.iter().zip(acc.interior_ids) {
                    if let Some(k) = clean_ring_indices(ring) {
                        interiors.push(pick(ring, &k));
                        rings.push((id, k));
                    }
                }
                meta = Some(PolyMeta { id: String::new(), rings });
                Ok(Polygon { exterior: pick(ext, &keep), interiors })
            }
        };
        let index = b.polygons.len();
        b.polygons.push(slot);
        // Only polygons with a gml:id can be the target of an appearance.
        b.poly_meta.push(match (acc.id, meta, no_appearance) {
            (Some(id), Some(m), false) => Some(PolyMeta { id, rings: m.rings }),
            _ => None,
        });
        if let Some(lod) = b.geom_lod {
            let comp = *b.component_stack.last().unwrap_or(&0);
            b.components[comp].entries[lod].push(Entry::Inline(index));
        }
    }

    /// Resolves references, chooses the LoD and emits the building (or counts it as empty).
    fn finish_building(&mut self) {
        let Some(mut b) = self.building.take() else { return };
        let SurfaceLists { lists, unresolved } = b.surface_lists();
        let chosen = self.choose_lod(&b, &lists);
        let picks = self.component_picks(&b, &lists, chosen);
        self.count_unused_degenerate(&b, &lists, &picks);
        let (polygons, metas, degenerate) = self.take_picked(&mut b, &lists, &picks);
        self.warn_unresolved(&b, &unresolved, &picks);
        self.stats.degenerate_faces += degenerate;
        if polygons.is_empty() {
            self.stats.buildings_without_geometry += 1;
            if degenerate > 0 {
                self.dropping.buildings_degenerate += 1;
            } else {
                self.dropping.buildings_empty += 1;
            }
            return;
        }
        self.stats.faces += polygons.len() as u64;
        let lod = chosen.map_or("", |l| LOD_NAMES[l]).to_string();
        self.poly_meta.push(metas);
        self.buildings.push(SourceBuilding {
            source_id: b.id,
            lod,
            measured_height_m: b.measured_height_m,
            ground_heights_m: Vec::new(),
            geometry: Geometry::Polygons(polygons),
            appearance: Vec::new(),
        });
    }

    /// The building's LoD: forced, else the highest with a usable polygon, else (to count what was
    /// dropped) the highest with any polygon at all.
    fn choose_lod(&self, b: &Building, lists: &LodLists) -> Option<usize> {
        match self.forced_lod {
            Some(lod) => Some(lod),
            None => (0..3)
                .rev()
                .find(|&lod| lists[lod].iter().any(|l| b.any_usable(l)))
                .or_else(|| (0..3).rev().find(|&lod| lists[lod].iter().any(|l| !l.is_empty()))),
        }
    }

    /// Which LoD each component contributes, as (component, LoD): the chosen one, or (by default)
    /// its best lower one.
    fn component_picks(&self, b: &Building, lists: &LodLists, chosen: Option<usize>) -> Vec<(usize, usize)> {
        let Some(top) = chosen else { return Vec::new() };
        (0..b.components.len())
            .map(|c| match self.forced_lod {
                Some(_) => (c, top),
                // LoD0 (flat) only when the building has nothing better.
                None => (c, (top.min(1)..=top).rev().find(|&l| b.any_usable(&lists[l][c])).unwrap_or(top)),
            })
            .collect()
    }

    /// Counts the degenerate faces of the LoDs not picked: reported, not silently lost.
    fn count_unused_degenerate(&mut self, b: &Building, lists: &LodLists, picks: &[(usize, usize)]) {
        let n = b.polygons.len();
        let mut picked = vec![false; n];
        for &(c, l) in picks {
            lists[l][c].iter().for_each(|&i| picked[i] = true);
        }
        let mut counted = vec![false; n];
        for i in lists.iter().flatten().flatten().copied() {
            if !picked[i] && !counted[i] && matches!(b.polygons[i], Err(Dropped::Degenerate)) {
                counted[i] = true;
                self.stats.degenerate_faces_unused += 1;
            }
        }
    }

    /// Moves the picked polygons out of `b`, registering their `gml:id`s for appearances; returns
    /// them with their metadata and the number dropped (degenerate or outside the envelope).
    fn take_picked(
        &mut self,
        b: &mut Building,
        lists: &LodLists,
        picks: &[(usize, usize)],
    ) -> (Vec<Polygon>, Vec<Option<PolyMeta>>, u64) {
        let mut polygons = Vec::new();
        let mut metas = Vec::new();
        let mut degenerate = 0u64;
        for &(c, l) in picks {
            for &i in &lists[l][c] {
                match std::mem::replace(&mut b.polygons[i], Err(Dropped::Degenerate)) {
                    Ok(p) => {
                        if let Some(m) = &b.poly_meta[i] {
                            self.poly_refs.insert(m.id.clone(), (self.buildings.len(), polygons.len()));
                        }
                        polygons.push(p);
                        metas.push(b.poly_meta[i].take());
                    }
                    Err(Dropped::Degenerate) => degenerate += 1,
                    Err(Dropped::OutsideEnvelope(xy)) => {
                        degenerate += 1;
                        self.dropping.outside_envelope += 1;
                        log::warn!(
                            "{}: building {:?}: dropped a polygon with a vertex at ({}, {}), far outside the \
                             document's gml:Envelope (a stray coordinate)",
                            self.path.display(),
                            b.id,
                            xy[0],
                            xy[1]
                        );
                    }
                }
            }
        }
        (polygons, metas, degenerate)
    }

    /// Warns about (and counts) the unresolved `xlink:href`s of the picked LoDs.
    fn warn_unresolved(&mut self, b: &Building, unresolved: &[Vec<String>; 3], picks: &[(usize, usize)]) {
        let mut picked_lods: Vec<usize> = picks.iter().map(|&(_, l)| l).collect();
        picked_lods.dedup();
        for l in picked_lods {
            for id in &unresolved[l] {
                self.dropping.unresolved_refs += 1;
                log::warn!(
                    "{}: building {:?}: xlink:href \"#{id}\" does not resolve to a surface of this building; ignored",
                    self.path.display(),
                    b.id
                );
            }
        }
    }

    fn finish(mut self) -> Result<SourceModel, LodError> {
        if self.buildings.is_empty() {
            let d = &self.dropping;
            return Err(LodError::invalid(
                self.path,
                "CityModel",
                CityGmlProblem::NoBuildings {
                    lod: self.forced_lod.map(|l| LOD_NAMES[l]),
                    counts: NoBuildings {
                        found: d.buildings_seen,
                        without_surface: d.buildings_empty,
                        all_degenerate: d.buildings_degenerate,
                        faces_dropped: self.stats.degenerate_faces,
                        others_skipped: self.stats.skipped_non_building,
                    },
                },
            ));
        }
        if let Some(at) = &self.first_bad_unused {
            log::warn!(
                "{}: {} coordinate value(s) outside any building are not numbers, not finite or beyond \
                 ±{MAX_ABS_COORDINATE:e} (first at {at}); they belong to objects that are not read, so they are ignored",
                self.path.display(),
                self.stats.bad_coordinates_unused
            );
        }
        if self.stats.degenerate_faces_unused > 0 {
            log::warn!(
                "{}: {} degenerate face(s) (fewer than 3 distinct points or zero area) in LoDs that were not \
                 chosen (e.g. lod0FootPrint of a building read at LoD2) were ignored",
                self.path.display(),
                self.stats.degenerate_faces_unused
            );
        }
        if self.dropping.outside_envelope > 0 || self.dropping.unresolved_refs > 0 {
            log::warn!(
                "{}: {} polygon(s) dropped for vertices outside the document envelope, {} unresolved xlink:href",
                self.path.display(),
                self.dropping.outside_envelope,
                self.dropping.unresolved_refs
            );
        }
        let appearance = self.resolve_appearances();
        let name = self.envelope.srs_name.or(self.first_srs_name);
        Ok(SourceModel {
            path: self.path.to_path_buf(),
            frame: Frame::Crs { name, axes: AxisConvention::Authority },
            buildings: self.buildings,
            stats: self.stats,
            appearance,
        })
    }

    /// An [`LodError::Invalid`] located at the current building (and polygon) and line.
    fn invalid_here(&self, problem: CityGmlProblem) -> LodError {
        let line = self.locate(self.event_pos);
        let at = match &self.building {
            Some(b) => match b.polygon.as_ref().and_then(|p| p.id.as_ref()) {
                Some(pid) => format!("building gml:id {:?}, polygon gml:id {pid:?} ({line})", b.id),
                None => format!("building gml:id {:?} ({line})", b.id),
            },
            None => line,
        };
        LodError::invalid(self.path, at, problem)
    }

    /// "line L, column C (byte B)" of a byte offset, found by re-reading the file (error path only).
    fn locate(&self, offset: u64) -> String {
        match line_column(self.path, offset) {
            Some((line, col)) => format!("line {line}, column {col} (byte {offset})"),
            None => format!("byte {offset}"),
        }
    }
}

impl Role {
    fn is_capture(self) -> bool {
        matches!(
            self,
            Role::MeasuredHeight
                | Role::LowerCorner
                | Role::UpperCorner
                | Role::PosList
                | Role::Pos
                | Role::Coordinates
                | Role::SkippedCoords
                | Role::AppTheme
                | Role::AppImageUri
                | Role::AppDiffuse
                | Role::AppTargetText
                | Role::AppTexCoords
        )
    }
}

/// 1-based line and column (in bytes) of a byte offset of a file.
fn line_column(path: &Path, offset: u64) -> Option<(u64, u64)> {
    let file = File::open(path).ok()?;
    let mut reader = BufReader::new(file.take(offset));
    let mut line = 1u64;
    let mut line_start = 0u64;
    let mut consumed = 0u64;
    loop {
        let chunk = reader.fill_buf().ok()?;
        if chunk.is_empty() {
            break;
        }
        for (i, &byte) in chunk.iter().enumerate() {
            if byte == b'\n' {
                line += 1;
                line_start = consumed + i as u64 + 1;
            }
        }
        let n = chunk.len();
        consumed += n as u64;
        reader.consume(n);
    }
    Some((line, offset - line_start + 1))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn local_names_ignore_the_prefix() {
        assert_eq!(local("gml:Polygon"), "Polygon");
        assert_eq!(local("Polygon"), "Polygon");
        assert_eq!(local("xlink:href"), "href");
    }

    #[test]
    fn envelope_box_grows_by_its_larger_side() {
        let e =
            Envelope { srs_name: None, lower: Some(vec![0.0, 0.0, 5.0]), upper: Some(vec![10.0, 20.0, 9.0]) };
        assert_eq!(e.accepted_box(), Some([-20.0, -20.0, 30.0, 40.0]));
        let inverted = Envelope { srs_name: None, lower: Some(vec![1.0, 0.0]), upper: Some(vec![0.0, 1.0]) };
        assert_eq!(inverted.accepted_box(), None);
        assert_eq!(Envelope::default().accepted_box(), None);
    }

    #[test]
    fn line_and_column_of_an_offset() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("x.gml");
        std::fs::write(&p, "ab\ncd\nef").unwrap();
        assert_eq!(line_column(&p, 0), Some((1, 1)));
        assert_eq!(line_column(&p, 4), Some((2, 2)));
        assert_eq!(line_column(&p, 6), Some((3, 1)));
    }

    #[test]
    fn name_stack_push_pop() {
        let mut s = NameStack::default();
        s.push("core:CityModel");
        s.push("bldg:Building");
        assert_eq!((s.len(), s.get(0), s.get(1)), (2, "core:CityModel", "bldg:Building"));
        s.pop();
        assert_eq!((s.len(), s.get(0)), (1, "core:CityModel"));
        s.pop();
        assert_eq!(s.len(), 0);
    }
}
