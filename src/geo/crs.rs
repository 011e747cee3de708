//! CRS parsing and source → WGS84 latitude/longitude with PROJ.
//!
//! Takes the CRS name a file or the user gives (an EPSG code in any of the usual spellings) and hands on
//! a [`Crs`] (what the name means: kind, axes, height convention) and a [`CrsTransform`] that turns the
//! file's coordinates into WGS84 [`Geodetic`] positions. The scene stage then goes on with
//! [`geodetic_to_ecef`](super::geodetic_to_ecef), adds the geoid undulation to orthometric heights and
//! builds the ENU frame.
//!
//! # Accepted names
//! `EPSG:6697`, `epsg:28992`, `EPSG::6697`, a bare `6677`, OGC URNs (`urn:ogc:def:crs:EPSG::6697`,
//! `urn:ogc:def:crs:EPSG:6.12:4979`, `urn:x-ogc:def:crs:EPSG:…`), OGC URLs
//! (`http(s)://www.opengis.net/def/crs/EPSG/0/6697`, `http://www.opengis.net/gml/srs/epsg.xml#6697`) and
//! compound CRSs spelled as two codes (`urn:ogc:def:crs,crs:EPSG::6668,crs:EPSG::6695`,
//! `http://www.opengis.net/def/crs-compound?1=…/EPSG/0/28992&2=…/EPSG/0/5709`, PROJ's `EPSG:6668+6695`).
//! Only the EPSG authority is supported; every code in PROJ's `proj.db` that is geographic, projected,
//! geocentric or compound (horizontal + vertical) works. One other register is translated to EPSG
//! codes: the AdV names of German CityGML (`urn:adv:crs:ETRS89_UTM32*DE_DHHN2016_NH` = EPSG:25832 +
//! EPSG:7837; the ETRS89 UTM zones 31–33 and latitude/longitude, DHDN Gauss-Krüger zones 2–5 and
//! latitude/longitude, the DHHN2016, DHHN92, DHHN12, DHHN85 and SNN76 heights).
//!
//! # Heights
//! [`Crs::heights`] decides what the third coordinate is; the rule is:
//! - geocentric CRSs (EPSG:4978) and 3D geographic/projected CRSs (EPSG:4979, 4937): **ellipsoidal**;
//! - compound CRSs with a vertical part (EPSG:6697 = JGD2011 + JGD2011 height, EPSG:7415 = RD New +
//!   NAP): **orthometric** (gravity-related, the vertical CRS's datum);
//! - 2D CRSs (EPSG:4326, EPSG:6668, EPSG:28992, UTM, …) carry no height axis, so the file's third
//!   coordinate is taken as **orthometric**: city models store heights above sea level. This includes
//!   EPSG:4326 — use EPSG:4979 for WGS84 ellipsoidal heights.
//!
//! The height is passed through unchanged apart from unit conversion to metres (a vertical axis in
//! feet is scaled; a 2D projected CRS's heights are taken to be in its horizontal unit); only for
//! geocentric input does the height come out of the conversion.
//!
//! National geoids: [`Crs::transform_with_heights`] instead hands a compound CRS to PROJ whole
//! (→ EPSG:4979), so PROJ applies the vertical transformation its database names — e.g. GSIGEO2011
//! (`jp_gsi_gsigeo2011.tif`) for JGD2011 height, NLGEO2018 (`nl_nsgi_nlgeo2018.tif`) for NAP —
//! when that grid is installed in its search path (`projsync --file NAME`, or a `PROJ_DATA`
//! directory). Without the grid PROJ falls back to a "ballpark" step (h = H);
//! [`CrsTransform::vertical_choice_at`] says which happened, which grids were opened and which were
//! wanted, so the caller can fall back to EGM96 instead (the scene stage's `[geoid] model = "proj"`).
//!
//! # Axis order
//! [`AxisConvention::Authority`] means the EPSG axis order (GML: EPSG:6697 and EPSG:4326 are latitude,
//! longitude; the Japanese plane rectangular CRSs EPSG:6669–6687 are X = northing, Y = easting);
//! [`AxisConvention::EastNorth`] means easting/longitude first whatever the CRS says (CityJSON, OBJ).
//! Both are delegated to PROJ: the authority-order operation as created, the east/north one through
//! `proj_normalize_for_visualization`.
//!
//! # Operation choice
//! The horizontal CRS is converted to EPSG:4326 with `proj_create_crs_to_crs`, which lists every
//! candidate operation and picks, per point, the best one whose area of use contains it (grids that
//! are not installed rule their operation out). This is exactly what pyproj's
//! `Transformer.from_crs(src, 4326)` does, so with the same `proj.db` content and grids both agree;
//! network grid download is disabled.

use std::fmt;

use proj_sys as sys;

use super::ellipsoid::{ecef_to_geodetic, geodetic_to_ecef};
use super::pj::{AxisInfo, Context, Obj};
use super::{CrsError, GeoError, Geodetic, ProjError};

/// How a format orders coordinate axes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum AxisConvention {
    /// The CRS authority's order (GML: EPSG:6697 is latitude, longitude, height).
    Authority,
    /// Always easting/longitude first (CityJSON, OBJ).
    EastNorth,
}

/// What the third coordinate of a CRS means.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum HeightKind {
    /// Height above the ellipsoid (geographic 3D, geocentric).
    Ellipsoidal,
    /// Height above a geoid/vertical datum (compound CRSs with a vertical part, and by convention the
    /// heights of 2D projected CRSs in city models).
    Orthometric,
}

/// What kind of CRS the horizontal (or geocentric) part is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CrsKind {
    /// Latitude, longitude (EPSG:4326, EPSG:6668).
    Geographic2D,
    /// Latitude, longitude, ellipsoidal height (EPSG:4979).
    Geographic3D,
    /// Easting, northing in a map projection (EPSG:28992, UTM, EPSG:6677).
    Projected2D,
    /// A projected CRS with an ellipsoidal height axis.
    Projected3D,
    /// Earth-centred X, Y, Z (EPSG:4978).
    Geocentric,
}

impl fmt::Display for CrsKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            CrsKind::Geographic2D => "geographic 2D",
            CrsKind::Geographic3D => "geographic 3D",
            CrsKind::Projected2D => "projected",
            CrsKind::Projected3D => "projected 3D",
            CrsKind::Geocentric => "geocentric",
        })
    }
}

/// One axis of a CRS as its authority defines it.
#[derive(Debug, Clone, PartialEq)]
pub struct CrsAxis {
    /// Short name ("Lat", "X", "E", "H").
    pub abbrev: String,
    /// Direction ("north", "east", "up", "geocentricX", …).
    pub direction: String,
    /// Unit name ("degree", "metre", "US survey foot").
    pub unit: String,
    /// Size of one unit in SI units (metres, or radians for angles).
    pub unit_si: f64,
}

impl From<AxisInfo> for CrsAxis {
    fn from(a: AxisInfo) -> Self {
        CrsAxis { abbrev: a.abbrev, direction: a.direction, unit: a.unit, unit_si: a.unit_factor }
    }
}

/// A parsed and resolved coordinate reference system (EPSG codes known to PROJ's database).
#[derive(Debug, Clone, PartialEq)]
pub struct Crs {
    /// The EPSG code of the horizontal (or geocentric) part: 6668 for EPSG:6697.
    pub horizontal_epsg: u32,
    /// The EPSG code of the vertical part of a compound CRS, if any: 6695 for EPSG:6697.
    pub vertical_epsg: Option<u32>,
    /// The name as the user or file gave it.
    pub given: String,
    /// The single EPSG code naming the whole CRS (6697, 7415, 28992), or `None` for a compound
    /// spelled as two codes.
    pub epsg: Option<u32>,
    /// PROJ's name of the whole CRS ("JGD2011 + JGD2011 (vertical) height").
    pub name: String,
    /// Kind of the horizontal (or geocentric) part.
    pub kind: CrsKind,
    /// All axes in authority order (horizontal part first, then the vertical part).
    pub axes: Vec<CrsAxis>,
    /// Metres per unit of the file's third coordinate (1 for metres; see the module doc).
    ///
    /// # Units
    /// metres per height unit.
    pub height_unit_m: f64,
    /// The CRS's area of use `[west, south, east, north]` in degrees (west > east when it crosses the
    /// antimeridian), if the database gives one.
    pub area_of_use_deg: Option<[f64; 4]>,
}

impl Crs {
    /// Parses a CRS name (see the module doc for the accepted spellings) and resolves it in PROJ's
    /// database.
    ///
    /// # Errors
    /// [`GeoError::UnknownCrs`] naming the input when the text is not a recognised spelling, the code
    /// is not in `proj.db` (e.g. EPSG:999999), or the CRS is of a kind that cannot be placed on the globe
    /// (vertical-only, engineering, …).
    pub fn parse(name: &str) -> Result<Crs, GeoError> {
        let parsed = parse_codes(name).and_then(|codes| resolve(&Context::new()?, name, &codes));
        parsed.map_err(|e| GeoError::UnknownCrs { name: name.to_string(), source: Box::new(e) })
    }

    /// The CRS with this EPSG code.
    ///
    /// # Errors
    /// As [`Crs::parse`].
    pub fn from_epsg(code: u32) -> Result<Crs, GeoError> {
        let given = format!("EPSG:{code}");
        let resolved = Context::new().map_err(CrsError::from).and_then(|ctx| resolve(&ctx, &given, &[code]));
        resolved.map_err(|e| GeoError::UnknownCrs { name: given, source: Box::new(e) })
    }

    /// What the third coordinate means (rule in the module doc): ellipsoidal for geocentric and 3D
    /// CRSs, orthometric for compound CRSs and, by the city-model convention, for 2D CRSs.
    pub fn heights(&self) -> HeightKind {
        if self.vertical_epsg.is_some() {
            return HeightKind::Orthometric;
        }
        match self.kind {
            CrsKind::Geocentric | CrsKind::Geographic3D | CrsKind::Projected3D => HeightKind::Ellipsoidal,
            CrsKind::Geographic2D | CrsKind::Projected2D => HeightKind::Orthometric,
        }
    }

    /// The CRS as an identifier: `EPSG:6697`, or `EPSG:6668+6695` for a compound given as two codes.
    pub fn id(&self) -> String {
        match (self.epsg, self.vertical_epsg) {
            (Some(c), _) => format!("EPSG:{c}"),
            (None, Some(v)) => format!("EPSG:{}+{v}", self.horizontal_epsg),
            (None, None) => format!("EPSG:{}", self.horizontal_epsg),
        }
    }

    /// A one-line description: identifier, PROJ's name and the authority axis order, e.g.
    /// `EPSG:6697 JGD2011 + JGD2011 (vertical) height (Lat, Lon, H)`; 2D CRSs add `+ height`.
    pub fn describe(&self) -> String {
        let mut axes: Vec<&str> = self.axes.iter().map(|a| a.abbrev.as_str()).collect();
        let two_d =
            matches!(self.kind, CrsKind::Geographic2D | CrsKind::Projected2D) && self.vertical_epsg.is_none();
        if two_d {
            axes.push("+ height");
        }
        format!("{} {} ({})", self.id(), self.name, axes.join(", ").replace(", + height", " + height"))
    }

    /// Builds the converter to WGS84 for this CRS (one PROJ context of its own).
    ///
    /// # Errors
    /// [`GeoError::UnknownCrs`] when PROJ finds no operation to WGS84.
    pub fn transform(&self) -> Result<CrsTransform, GeoError> {
        CrsTransform::new(self.clone())
    }

    /// Builds a converter that lets PROJ handle the heights too: the compound CRS (horizontal +
    /// vertical) to WGS 84 3D (EPSG:4979), with PROJ's own choice of vertical transformation — a
    /// national geoid grid (`jp_gsi_gsigeo2011.tif`, `nl_nsgi_nlgeo2018.tif`, …) when it is installed
    /// in PROJ's search path, else PROJ's "ballpark" step that leaves the height unchanged (see
    /// [`CrsTransform::vertical_choice_at`] to tell which). Its [`to_geodetic`](CrsTransform::to_geodetic)
    /// returns **ellipsoidal** heights.
    ///
    /// # Errors
    /// [`GeoError::UnknownCrs`] when the CRS has no vertical part or PROJ finds no operation.
    pub fn transform_with_heights(&self) -> Result<CrsTransform, GeoError> {
        CrsTransform::new_3d(self.clone())
    }
}

impl fmt::Display for Crs {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.describe())
    }
}

/// Splits a CRS name into one EPSG code (simple or compound CRS) or two (horizontal + vertical).
fn parse_codes(name: &str) -> Result<Vec<u32>, CrsError> {
    let s = name.trim();
    if s.is_empty() {
        return Err(CrsError::Empty);
    }
    let l = s.to_ascii_lowercase();
    let codes = if let Some(rest) =
        l.strip_prefix("urn:ogc:def:crs,").or_else(|| l.strip_prefix("urn:x-ogc:def:crs,"))
    {
        // Compound URN: "crs:EPSG::6668,crs:EPSG::6695".
        rest.split(',')
            .map(|part| {
                let part = part.trim();
                let p = part.strip_prefix("crs:").ok_or_else(|| CrsError::UrnComponent(part.to_string()))?;
                urn_code(p)
            })
            .collect::<Result<Vec<_>, _>>()?
    } else if let Some(rest) = strip_url(&l, "www.opengis.net/def/crs-compound?") {
        // "1=http://www.opengis.net/def/crs/EPSG/0/28992&2=http://…/5709".
        let mut parts = Vec::new();
        for kv in rest.split('&') {
            let (k, v) = kv.split_once('=').ok_or_else(|| CrsError::UrlPart(kv.to_string()))?;
            let k: u32 = k.trim().parse().map_err(|_| CrsError::UrlKey(k.to_string()))?;
            parts.push((k, url_code(v.trim())?));
        }
        parts.sort_by_key(|&(k, _)| k);
        parts.into_iter().map(|(_, c)| c).collect()
    } else if l.starts_with("http://") || l.starts_with("https://") {
        vec![url_code(&l)?]
    } else if let Some(rest) =
        l.strip_prefix("urn:ogc:def:crs:").or_else(|| l.strip_prefix("urn:x-ogc:def:crs:"))
    {
        vec![urn_code(rest)?]
    } else if let Some(rest) = l.strip_prefix("urn:adv:crs:") {
        adv_codes(rest)?
    } else if let Some(rest) = l.strip_prefix("epsg:") {
        // "EPSG:25832+7837" (PROJ's and GDAL's compound spelling, and [`Crs::id`]'s) is two codes.
        rest.trim_start_matches(':').split('+').map(epsg_code).collect::<Result<Vec<_>, _>>()?
    } else if l.bytes().all(|b| b.is_ascii_digit() || b == b'+') {
        l.split('+').map(epsg_code).collect::<Result<Vec<_>, _>>()?
    } else {
        return Err(CrsError::NotRecognised);
    };
    match codes.len() {
        1 | 2 => Ok(codes),
        n => Err(CrsError::ComponentCount(n)),
    }
}

/// Why a UTM easting PROJ refused may still be right: German and other European files often write it
/// with the zone number in front (32 691 000 m for 691 000 m in zone 32), which the plain UTM CRS
/// cannot take. `None` unless the CRS `name` is a UTM zone and the first coordinate carries that
/// zone's number in its millions.
fn zone_prefix_hint(name: &str, point: [f64; 3]) -> Option<String> {
    let digits: String = name.split("UTM zone ").nth(1)?.chars().take_while(char::is_ascii_digit).collect();
    let zone: f64 = digits.parse().ok()?;
    let easting = point[0];
    ((easting / 1e6).floor() == zone && zone >= 1.0).then(|| {
        format!(
            "the easting {easting} looks like UTM zone {zone} with the zone number in front ({} m): such \
             files need the zone's zE-N CRS (ETRS89: EPSG:5649, EPSG:4647, EPSG:5650 for zones 31, 32, 33; \
             e.g. crs = \"EPSG:4647+7837\" with DHHN2016 heights)",
            easting - zone * 1e6
        )
    })
}

/// The names of the AdV CRS register (Germany's surveying authorities: the LoD2 CityGML every state
/// publishes, ALKIS) that insgen knows, lower-cased, with their EPSG codes: horizontal systems, then
/// height systems.
const ADV_NAMES: [(&str, u32); 14] = [
    ("etrs89_utm31", 25831),
    ("etrs89_utm32", 25832),
    ("etrs89_utm33", 25833),
    ("etrs89_lat-lon", 4258),
    ("de_dhdn_3gk2", 31466),
    ("de_dhdn_3gk3", 31467),
    ("de_dhdn_3gk4", 31468),
    ("de_dhdn_3gk5", 31469),
    ("de_dhdn_lat-lon", 4314),
    ("de_dhhn2016_nh", 7837),
    ("de_dhhn92_nh", 5783),
    ("de_dhhn12_noh", 7699),
    ("de_dhhn85_noh", 5784),
    ("de_snn76_nh", 5785),
];

/// The part of an AdV name after `urn:adv:crs:` (lower-cased) → its codes: `ETRS89_UTM32` → 25832,
/// `ETRS89_UTM32*DE_DHHN2016_NH` → 25832 + 7837. A third part names the quasigeoid the heights were
/// reduced with (`*GCG2016`); it is not a CRS, and PROJ chooses the height system's own
/// transformation, so it is ignored.
fn adv_codes(rest: &str) -> Result<Vec<u32>, CrsError> {
    let code = |part: &str| {
        ADV_NAMES
            .iter()
            .find(|(name, _)| *name == part.trim())
            .map(|&(_, code)| code)
            .ok_or_else(|| CrsError::AdvName(part.trim().to_uppercase()))
    };
    rest.split('*').take(2).map(code).collect()
}

/// "EPSG:<version>:<code>" (version may be empty) → code.
fn urn_code(rest: &str) -> Result<u32, CrsError> {
    let mut it = rest.splitn(3, ':');
    let auth = it.next().unwrap_or("");
    let (version, code) = (it.next(), it.next());
    if auth != "epsg" {
        return Err(CrsError::Authority(auth.to_uppercase()));
    }
    match (version, code) {
        (Some(_), Some(code)) => epsg_code(code),
        // "urn:ogc:def:crs:EPSG:6697" (no version field) is a common slip; accept it.
        (Some(code), None) => epsg_code(code),
        _ => Err(CrsError::UrnWithoutCode),
    }
}

/// Strips "http(s)://" + `prefix`, returning the rest.
fn strip_url<'a>(l: &'a str, prefix: &str) -> Option<&'a str> {
    l.strip_prefix("http://").or_else(|| l.strip_prefix("https://"))?.strip_prefix(prefix)
}

/// "http://www.opengis.net/def/crs/EPSG/0/6697" or "http://www.opengis.net/gml/srs/epsg.xml#6697" → code.
fn url_code(l: &str) -> Result<u32, CrsError> {
    let l = l.to_ascii_lowercase();
    if let Some(rest) = strip_url(&l, "www.opengis.net/def/crs/") {
        let segs: Vec<&str> = rest.trim_end_matches('/').split('/').collect();
        return match segs.as_slice() {
            ["epsg", _version, code] => epsg_code(code),
            [auth, _, _] => Err(CrsError::Authority(auth.to_uppercase())),
            _ => Err(CrsError::UrlPath(rest.to_string())),
        };
    }
    if let Some(code) = strip_url(&l, "www.opengis.net/gml/srs/epsg.xml#") {
        return epsg_code(code);
    }
    Err(CrsError::NotOgcUrl)
}

fn epsg_code(s: &str) -> Result<u32, CrsError> {
    let s = s.trim();
    if s.is_empty() || !s.bytes().all(|b| b.is_ascii_digit()) {
        return Err(CrsError::NotACode(s.to_string()));
    }
    match s.parse::<u32>() {
        Ok(c) if c > 0 => Ok(c),
        _ => Err(CrsError::CodeOutOfRange(s.to_string())),
    }
}

fn type_name(t: sys::PJ_TYPE) -> &'static str {
    match t {
        sys::PJ_TYPE_PJ_TYPE_VERTICAL_CRS => "vertical",
        sys::PJ_TYPE_PJ_TYPE_ENGINEERING_CRS => "engineering",
        sys::PJ_TYPE_PJ_TYPE_TEMPORAL_CRS => "temporal",
        sys::PJ_TYPE_PJ_TYPE_BOUND_CRS => "bound",
        sys::PJ_TYPE_PJ_TYPE_COMPOUND_CRS => "compound",
        sys::PJ_TYPE_PJ_TYPE_GEODETIC_CRS => "geodetic (neither geographic nor geocentric)",
        _ => "unsupported",
    }
}

/// The code of a CRS object, if its identifier is an EPSG one.
fn epsg_of(obj: &Obj) -> Option<u32> {
    match obj.id() {
        Some((auth, code)) if auth.eq_ignore_ascii_case("EPSG") => code.parse().ok(),
        _ => None,
    }
}

/// Kind and axes of a horizontal (or geocentric) CRS object; `None` kind if it is something else.
fn horizontal_kind(ctx: &Context, obj: &Obj) -> Result<(Option<CrsKind>, Vec<AxisInfo>), ProjError> {
    let axes = ctx.axes(obj)?;
    let kind = match obj.kind() {
        sys::PJ_TYPE_PJ_TYPE_GEOGRAPHIC_2D_CRS => Some(CrsKind::Geographic2D),
        sys::PJ_TYPE_PJ_TYPE_GEOGRAPHIC_3D_CRS => Some(CrsKind::Geographic3D),
        sys::PJ_TYPE_PJ_TYPE_GEOCENTRIC_CRS => Some(CrsKind::Geocentric),
        sys::PJ_TYPE_PJ_TYPE_PROJECTED_CRS if axes.len() == 3 => Some(CrsKind::Projected3D),
        sys::PJ_TYPE_PJ_TYPE_PROJECTED_CRS => Some(CrsKind::Projected2D),
        _ => None,
    };
    Ok((kind, axes))
}

/// Resolves parsed codes in PROJ's database into a [`Crs`].
fn resolve(ctx: &Context, given: &str, codes: &[u32]) -> Result<Crs, CrsError> {
    let area = |o: &Obj| ctx.area_of_use(o);
    match *codes {
        [code] => {
            let obj = ctx.crs_from_database("EPSG", code)?;
            let t = obj.kind();
            if t == sys::PJ_TYPE_PJ_TYPE_COMPOUND_CRS {
                let h = ctx.sub_crs(&obj, 0)?;
                let v = ctx.sub_crs(&obj, 1)?;
                let mut crs = compound(ctx, given, &h, &v)?;
                crs.epsg = Some(code);
                crs.name = obj.name();
                crs.area_of_use_deg = area(&obj).or(crs.area_of_use_deg);
                return Ok(crs);
            }
            let (kind, axes) = horizontal_kind(ctx, &obj)?;
            let Some(kind) = kind else {
                return Err(CrsError::Unsupported {
                    code,
                    name: obj.name(),
                    kind: type_name(t),
                    vertical: t == sys::PJ_TYPE_PJ_TYPE_VERTICAL_CRS,
                });
            };
            let height_unit_m = match kind {
                CrsKind::Geographic2D => 1.0,
                CrsKind::Projected2D => axes[0].unit_factor,
                CrsKind::Geographic3D | CrsKind::Projected3D | CrsKind::Geocentric => axes[2].unit_factor,
            };
            Ok(Crs {
                horizontal_epsg: code,
                vertical_epsg: None,
                given: given.to_string(),
                epsg: Some(code),
                name: obj.name(),
                kind,
                axes: axes.into_iter().map(CrsAxis::from).collect(),
                height_unit_m,
                area_of_use_deg: area(&obj),
            })
        }
        [hc, vc] => {
            let h = ctx.crs_from_database("EPSG", hc)?;
            let v = ctx.crs_from_database("EPSG", vc)?;
            compound(ctx, given, &h, &v)
        }
        _ => Err(CrsError::ComponentCount(codes.len())),
    }
}

/// A compound CRS from its horizontal and vertical components.
fn compound(ctx: &Context, given: &str, h: &Obj, v: &Obj) -> Result<Crs, CrsError> {
    let (kind, h_axes) = horizontal_kind(ctx, h)?;
    let kind = match kind {
        Some(k @ (CrsKind::Geographic2D | CrsKind::Projected2D)) => k,
        _ => {
            return Err(CrsError::CompoundHorizontal {
                name: h.name(),
                kind: kind.map(|k| k.to_string()).unwrap_or_else(|| type_name(h.kind()).to_string()),
            })
        }
    };
    if v.kind() != sys::PJ_TYPE_PJ_TYPE_VERTICAL_CRS {
        return Err(CrsError::CompoundVertical { name: v.name() });
    }
    let v_axes = ctx.axes(v)?;
    let no_code = |part, o: &Obj| CrsError::NoEpsgCode { part, name: o.name() };
    let horizontal_epsg = epsg_of(h).ok_or_else(|| no_code("horizontal", h))?;
    let vertical_epsg = epsg_of(v).ok_or_else(|| no_code("vertical", v))?;
    let height_unit_m = v_axes.first().map(|a| a.unit_factor).unwrap_or(1.0);
    Ok(Crs {
        horizontal_epsg,
        vertical_epsg: Some(vertical_epsg),
        given: given.to_string(),
        epsg: None,
        name: format!("{} + {}", h.name(), v.name()),
        kind,
        axes: h_axes.into_iter().chain(v_axes).map(CrsAxis::from).collect(),
        height_unit_m,
        area_of_use_deg: ctx.area_of_use(h),
    })
}

/// The conversion engine of a [`CrsTransform`].
enum Engine {
    /// EPSG:4978 (metres): the closed form of [`ecef_to_geodetic`], no PROJ involved.
    Wgs84Ecef,
    /// Another geocentric CRS: PROJ to EPSG:4979 in normalised order (X, Y, Z in; lon, lat, h out).
    Geocentric { op: Obj },
    /// PROJ from the horizontal CRS to EPSG:4326. `authority` takes the CRS's authority order and
    /// returns (lat, lon); `east_north` takes easting/longitude first and returns (lon, lat).
    Horizontal { authority: Obj, east_north: Obj },
    /// PROJ from a compound CRS to EPSG:4979, heights included: `authority` returns (lat, lon, h),
    /// `east_north` (lon, lat, h). `src`/`dst` are kept to list the candidate operations.
    Compound3D { authority: Obj, east_north: Obj, src: Obj, dst: Obj },
}

/// What PROJ did with the heights of a compound CRS at one point ([`CrsTransform::vertical_choice_at`]).
#[derive(Debug, Clone, PartialEq)]
pub struct VerticalChoice {
    /// PROJ's description of the operation it used there.
    pub operation: String,
    /// Whether the vertical step is PROJ's "ballpark" one (no geoid model: h = H), which it takes when
    /// no real transformation can run (typically: the geoid grid is not installed).
    pub ballpark: bool,
    /// The grids the operation used, as files PROJ opened (full paths).
    pub grids: Vec<String>,
    /// With `ballpark`: the grids of PROJ's best-ranked operation that are not installed, by the name
    /// PROJ's database gives them (`jp_gsi_gsigeo2011.tif`); install one with `projsync --file NAME`.
    pub missing_grids: Vec<String>,
}

/// The marker PROJ puts in the name of a vertical step that applies no geoid model (PROJ 7–9).
const BALLPARK_VERTICAL: &str = "ballpark vertical transformation";

/// A ready converter from one CRS to WGS84 geodetic.
///
/// Owns its PROJ context and operations: not `Sync` (make one per thread), but `Send`.
pub struct CrsTransform {
    /// The CRS converted from.
    pub crs: Crs,
    engine: Engine,
    /// Declared last so that the operations in `engine` are destroyed before their context.
    ctx: Context,
}

impl fmt::Debug for CrsTransform {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("CrsTransform").field("crs", &self.crs.id()).finish_non_exhaustive()
    }
}

impl CrsTransform {
    fn new(crs: Crs) -> Result<CrsTransform, GeoError> {
        let err = |e: ProjError| GeoError::UnknownCrs { name: crs.given.clone(), source: Box::new(e.into()) };
        let ctx = Context::new().map_err(err)?;
        let engine = match crs.kind {
            CrsKind::Geocentric if crs.horizontal_epsg == 4978 && crs.height_unit_m == 1.0 => {
                Engine::Wgs84Ecef
            }
            CrsKind::Geocentric => {
                let src = ctx.crs_from_database("EPSG", crs.horizontal_epsg).map_err(err)?;
                let dst = ctx.crs_from_database("EPSG", 4979).map_err(err)?;
                let raw = ctx.crs_to_crs(&src, &dst).map_err(err)?;
                Engine::Geocentric { op: ctx.normalize_for_visualization(&raw).map_err(err)? }
            }
            _ => {
                let src = ctx.crs_from_database("EPSG", crs.horizontal_epsg).map_err(err)?;
                let dst = ctx.crs_from_database("EPSG", 4326).map_err(err)?;
                let authority = ctx.crs_to_crs(&src, &dst).map_err(err)?;
                let east_north = ctx.normalize_for_visualization(&authority).map_err(err)?;
                Engine::Horizontal { authority, east_north }
            }
        };
        Ok(CrsTransform { crs, engine, ctx })
    }

    fn new_3d(crs: Crs) -> Result<CrsTransform, GeoError> {
        let err = |e: CrsError| GeoError::UnknownCrs { name: crs.given.clone(), source: Box::new(e) };
        let ctx = Context::new().map_err(|e| err(e.into()))?;
        let src = match (crs.epsg, crs.vertical_epsg) {
            (_, None) => {
                return Err(err(CrsError::CompoundVertical { name: crs.name.clone() }));
            }
            (Some(code), Some(_)) => ctx.crs_from_database("EPSG", code),
            (None, Some(v)) => ctx.create(&format!("EPSG:{}+{v}", crs.horizontal_epsg)),
        }
        .map_err(|e| err(e.into()))?;
        let dst = ctx.crs_from_database("EPSG", 4979).map_err(|e| err(e.into()))?;
        let authority = ctx.crs_to_crs(&src, &dst).map_err(|e| err(e.into()))?;
        let east_north = ctx.normalize_for_visualization(&authority).map_err(|e| err(e.into()))?;
        Ok(CrsTransform { crs, engine: Engine::Compound3D { authority, east_north, src, dst }, ctx })
    }

    /// For a converter made by [`Crs::transform_with_heights`]: the operation PROJ uses at `p`, whether
    /// its vertical step is a real one (a geoid grid) or PROJ's ballpark (h = H), the grids it opened,
    /// and — for the ballpark — the not-installed grids of the operation PROJ would rank first.
    /// `None` for other converters.
    ///
    /// # Errors
    /// As [`to_geodetic`](Self::to_geodetic).
    pub fn vertical_choice_at(
        &self,
        p: [f64; 3],
        axes: AxisConvention,
    ) -> Result<Option<VerticalChoice>, GeoError> {
        let Engine::Compound3D { authority, east_north, src, dst } = &self.engine else {
            return Ok(None);
        };
        self.to_geodetic(p, axes)?;
        let op = match axes {
            AxisConvention::Authority => authority,
            AxisConvention::EastNorth => east_north,
        };
        let used = self.ctx.last_used_operation_obj(op);
        let used_ref = used.as_ref().unwrap_or(op);
        let operation = used_ref.description();
        let ballpark = operation.contains(BALLPARK_VERTICAL);
        let grids: Vec<String> = self
            .ctx
            .grids_used(used_ref)
            .into_iter()
            .filter(|g| g.available)
            .map(|g| if g.full_name.is_empty() { g.short_name } else { g.full_name })
            .collect();
        let missing_grids = if ballpark {
            // PROJ's ranking with availability ignored: the first operation that cannot run here is
            // the one a user would get by installing its grids.
            let ops = self.ctx.operations_ignoring_grids(src, dst);
            ops.iter()
                .find(|o| !self.ctx.is_instantiable(o))
                .map(|o| {
                    self.ctx
                        .grids_used(o)
                        .into_iter()
                        .filter(|g| !g.available)
                        .map(|g| g.short_name)
                        .collect()
                })
                .unwrap_or_default()
        } else {
            Vec::new()
        };
        Ok(Some(VerticalChoice { operation, ballpark, grids, missing_grids }))
    }

    fn transform_error(&self, point: [f64; 3], why: impl Into<String>) -> GeoError {
        let mut why = why.into();
        if let Some(hint) = zone_prefix_hint(&self.crs.name, point) {
            why = format!("{why}; {hint}");
        }
        GeoError::Transform { crs: self.crs.describe(), point, why }
    }

    /// Converts a source point to WGS84 latitude/longitude; the height is passed through as given
    /// (orthometric or ellipsoidal, see [`Crs::heights`]; converted to metres), except for geocentric
    /// input, whose WGS84 ellipsoidal height is computed.
    ///
    /// # Units
    /// `p` in the CRS's units (metres, degrees, feet…) and the order `axes` says; output degrees and
    /// metres.
    ///
    /// # Errors
    /// [`GeoError::Transform`] with the point and CRS for NaN/infinite input or when PROJ cannot
    /// convert the point (e.g. outside the projection's domain).
    pub fn to_geodetic(&self, p: [f64; 3], axes: AxisConvention) -> Result<Geodetic, GeoError> {
        let mut out = [Geodetic::new(0.0, 0.0, 0.0)];
        self.convert(std::slice::from_ref(&p), axes, &mut out)?;
        Ok(out[0])
    }

    /// Batch form of [`to_geodetic`](Self::to_geodetic) with the same semantics (one PROJ call).
    ///
    /// # Errors
    /// As [`to_geodetic`](Self::to_geodetic), for the first point that fails.
    pub fn to_geodetic_many(
        &self,
        pts: &[[f64; 3]],
        axes: AxisConvention,
    ) -> Result<Vec<Geodetic>, GeoError> {
        let mut out = vec![Geodetic::new(0.0, 0.0, 0.0); pts.len()];
        self.convert(pts, axes, &mut out)?;
        Ok(out)
    }

    fn convert(&self, pts: &[[f64; 3]], axes: AxisConvention, out: &mut [Geodetic]) -> Result<(), GeoError> {
        if let Some(p) = pts.iter().find(|p| !p.iter().all(|v| v.is_finite())) {
            return Err(self.transform_error(*p, "the coordinate is not finite"));
        }
        let n = pts.len();
        match &self.engine {
            Engine::Wgs84Ecef => {
                for (o, p) in out.iter_mut().zip(pts) {
                    *o = ecef_to_geodetic(*p);
                }
            }
            Engine::Geocentric { op } => {
                let mut x: Vec<f64> = pts.iter().map(|p| p[0]).collect();
                let mut y: Vec<f64> = pts.iter().map(|p| p[1]).collect();
                let mut z: Vec<f64> = pts.iter().map(|p| p[2]).collect();
                self.ctx
                    .trans(op, false, &mut x, &mut y, &mut z)
                    .map_err(|(i, why)| self.transform_error(pts[i], why))?;
                for i in 0..n {
                    out[i] = Geodetic::new(y[i], x[i], z[i]);
                }
            }
            Engine::Horizontal { authority, east_north } => {
                let op = match axes {
                    AxisConvention::Authority => authority,
                    AxisConvention::EastNorth => east_north,
                };
                let mut x: Vec<f64> = pts.iter().map(|p| p[0]).collect();
                let mut y: Vec<f64> = pts.iter().map(|p| p[1]).collect();
                // 2D operation: the height is not PROJ's business (see the module doc).
                self.ctx
                    .trans(op, false, &mut x, &mut y, &mut [])
                    .map_err(|(i, why)| self.transform_error(pts[i], why))?;
                for i in 0..n {
                    let (lat, lon) = match axes {
                        // EPSG:4326 authority order is latitude, longitude.
                        AxisConvention::Authority => (x[i], y[i]),
                        AxisConvention::EastNorth => (y[i], x[i]),
                    };
                    if !(-90.0..=90.0).contains(&lat) {
                        // A no-op operation (EPSG:4326 → 4326) would pass an impossible latitude on.
                        return Err(self.transform_error(pts[i], format!("latitude {lat}° is outside ±90°")));
                    }
                    out[i] = Geodetic::new(lat, lon, pts[i][2] * self.crs.height_unit_m);
                }
            }
            Engine::Compound3D { authority, east_north, .. } => {
                let op = match axes {
                    AxisConvention::Authority => authority,
                    AxisConvention::EastNorth => east_north,
                };
                let mut x: Vec<f64> = pts.iter().map(|p| p[0]).collect();
                let mut y: Vec<f64> = pts.iter().map(|p| p[1]).collect();
                let mut z: Vec<f64> = pts.iter().map(|p| p[2]).collect();
                self.ctx
                    .trans(op, false, &mut x, &mut y, &mut z)
                    .map_err(|(i, why)| self.transform_error(pts[i], why))?;
                for i in 0..n {
                    let (lat, lon) = match axes {
                        // EPSG:4979 authority order is latitude, longitude, height.
                        AxisConvention::Authority => (x[i], y[i]),
                        AxisConvention::EastNorth => (y[i], x[i]),
                    };
                    out[i] = Geodetic::new(lat, lon, z[i]);
                }
            }
        }
        Ok(())
    }

    /// The inverse of [`to_geodetic`](Self::to_geodetic): a WGS84 position to source coordinates in
    /// the order `axes` says (the height divided by the height unit; for geocentric output the
    /// ellipsoidal height is used).
    ///
    /// # Errors
    /// [`GeoError::Transform`] for non-finite input or when PROJ cannot convert the point.
    pub fn from_geodetic(&self, g: Geodetic, axes: AxisConvention) -> Result<[f64; 3], GeoError> {
        let gp = [g.lat_deg, g.lon_deg, g.h_m];
        if !gp.iter().all(|v| v.is_finite()) {
            return Err(self.transform_error(gp, "the geodetic position is not finite"));
        }
        let inv_err = |(_, why): (usize, String)| self.transform_error(gp, format!("inverse: {why}"));
        match &self.engine {
            Engine::Wgs84Ecef => Ok(geodetic_to_ecef(g)),
            Engine::Geocentric { op } => {
                let (mut x, mut y, mut z) = ([g.lon_deg], [g.lat_deg], [g.h_m]);
                self.ctx.trans(op, true, &mut x, &mut y, &mut z).map_err(inv_err)?;
                Ok([x[0], y[0], z[0]])
            }
            Engine::Horizontal { authority, east_north } => {
                let (op, mut x, mut y) = match axes {
                    AxisConvention::Authority => (authority, [g.lat_deg], [g.lon_deg]),
                    AxisConvention::EastNorth => (east_north, [g.lon_deg], [g.lat_deg]),
                };
                self.ctx.trans(op, true, &mut x, &mut y, &mut []).map_err(inv_err)?;
                Ok([x[0], y[0], g.h_m / self.crs.height_unit_m])
            }
            Engine::Compound3D { authority, east_north, .. } => {
                // g.h_m is ellipsoidal here; PROJ returns the height in the vertical CRS.
                let (op, mut x, mut y) = match axes {
                    AxisConvention::Authority => (authority, [g.lat_deg], [g.lon_deg]),
                    AxisConvention::EastNorth => (east_north, [g.lon_deg], [g.lat_deg]),
                };
                let mut z = [g.h_m];
                self.ctx.trans(op, true, &mut x, &mut y, &mut z).map_err(inv_err)?;
                Ok([x[0], y[0], z[0]])
            }
        }
    }

    /// Describes the coordinate operation used for the point `p` (for a CRS with several candidate
    /// operations, the one PROJ picks there), e.g. "Inverse of UTM zone 54N + axis order change (2D)".
    ///
    /// # Errors
    /// As [`to_geodetic`](Self::to_geodetic).
    pub fn operation_for(&self, p: [f64; 3], axes: AxisConvention) -> Result<String, GeoError> {
        self.to_geodetic(p, axes)?;
        Ok(match &self.engine {
            Engine::Wgs84Ecef => "WGS 84 geocentric to geographic (closed form, insgen)".to_string(),
            Engine::Geocentric { op } => self.ctx.last_used_operation(op),
            Engine::Horizontal { authority, east_north }
            | Engine::Compound3D { authority, east_north, .. } => match axes {
                AxisConvention::Authority => self.ctx.last_used_operation(authority),
                AxisConvention::EastNorth => self.ctx.last_used_operation(east_north),
            },
        })
    }
}

/// The version of the PROJ library insgen is linked against (e.g. "9.1.1").
pub fn proj_version() -> String {
    super::pj::proj_version()
}

/// The directories the linked PROJ searches for `proj.db` and grids.
pub fn proj_search_paths() -> Vec<String> {
    super::pj::proj_search_paths()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::util::error_chain;

    fn codes(s: &str) -> Vec<u32> {
        parse_codes(s).unwrap_or_else(|e| panic!("{s:?}: {e}"))
    }

    mod parse_names {
        use super::*;

        #[test]
        fn every_spelling_gives_the_code() {
            for (s, want) in [
                ("EPSG:6697", vec![6697]),
                ("epsg:28992", vec![28992]),
                ("EPSG::6697", vec![6697]),
                ("  6677 ", vec![6677]),
                ("urn:ogc:def:crs:EPSG::6697", vec![6697]),
                ("urn:ogc:def:crs:EPSG:6.12:4979", vec![4979]),
                ("urn:x-ogc:def:crs:EPSG:6.3:4326", vec![4326]),
                ("urn:ogc:def:crs:EPSG:6697", vec![6697]),
                ("http://www.opengis.net/def/crs/EPSG/0/6697", vec![6697]),
                ("https://www.opengis.net/def/crs/EPSG/0/7415", vec![7415]),
                ("HTTP://WWW.OPENGIS.NET/DEF/CRS/EPSG/9.8.15/2056/", vec![2056]),
                ("http://www.opengis.net/gml/srs/epsg.xml#28992", vec![28992]),
                ("urn:ogc:def:crs,crs:EPSG::6668,crs:EPSG::6695", vec![6668, 6695]),
                ("urn:ogc:def:crs,crs:EPSG:6.12:6668,crs:EPSG:6.12:6695", vec![6668, 6695]),
                (
                    "http://www.opengis.net/def/crs-compound?1=http://www.opengis.net/def/crs/EPSG/0/28992\
                     &2=http://www.opengis.net/def/crs/EPSG/0/5709",
                    vec![28992, 5709],
                ),
                ("urn:adv:crs:ETRS89_UTM32*DE_DHHN2016_NH", vec![25832, 7837]),
                ("urn:adv:crs:ETRS89_UTM33*DE_DHHN92_NH", vec![25833, 5783]),
                ("urn:adv:crs:ETRS89_UTM32*DE_DHHN2016_NH*GCG2016", vec![25832, 7837]),
                ("URN:ADV:CRS:DE_DHDN_3GK3*DE_DHHN12_NOH", vec![31467, 7699]),
                ("urn:adv:crs:ETRS89_UTM32", vec![25832]),
                ("EPSG:25832+7837", vec![25832, 7837]),
                ("epsg:6668+6695", vec![6668, 6695]),
                ("6668+6695", vec![6668, 6695]),
                (
                    "http://www.opengis.net/def/crs-compound?2=http://www.opengis.net/def/crs/EPSG/0/5709\
                     &1=http://www.opengis.net/def/crs/EPSG/0/28992",
                    vec![28992, 5709],
                ),
            ] {
                assert_eq!(codes(s), want, "{s:?}");
            }
        }

        #[test]
        fn garbage_is_rejected_with_the_reason() {
            for (s, why) in [
                ("", "empty"),
                ("   ", "empty"),
                ("WGS84", "not a recognised"),
                ("EPSG:", "not a positive integer"),
                ("EPSG:abc", "not a positive integer"),
                ("EPSG:-4326", "not a positive integer"),
                ("EPSG:0", "out of range"),
                ("EPSG:99999999999", "out of range"),
                ("urn:ogc:def:crs:OGC:1.3:CRS84", "authority \"OGC\""),
                ("http://www.opengis.net/def/crs/OGC/1.3/CRS84", "authority \"OGC\""),
                ("http://example.com/crs/4326", "not an OGC CRS URL"),
                ("urn:ogc:def:crs,crs:EPSG::6668,crs:EPSG::6695,crs:EPSG::5703", "1 or 2 components"),
                ("urn:ogc:def:crs,EPSG::6668", "does not start with crs:"),
                ("urn:adv:crs:ETRS89_UTM99*DE_DHHN2016_NH", "AdV name \"ETRS89_UTM99\""),
                ("urn:adv:crs:ETRS89_UTM32*DE_NOWHERE_NH", "AdV name \"DE_NOWHERE_NH\""),
                ("urn:adv:crs:", "AdV name \"\""),
                ("EPSG:25832+", "not a positive integer"),
                ("EPSG:6668+6695+5703", "1 or 2 components"),
            ] {
                let e = parse_codes(s).expect_err(s).to_string();
                assert!(e.contains(why), "{s:?}: {e}");
            }
        }
    }

    mod resolve_in_proj_db {
        use super::*;

        #[test]
        fn compound_6697_splits_into_jgd2011_and_its_height() {
            let c = Crs::parse("http://www.opengis.net/def/crs/EPSG/0/6697").unwrap();
            assert_eq!((c.horizontal_epsg, c.vertical_epsg, c.epsg), (6668, Some(6695), Some(6697)));
            assert_eq!(c.kind, CrsKind::Geographic2D);
            assert_eq!(c.heights(), HeightKind::Orthometric);
            let dirs: Vec<&str> = c.axes.iter().map(|a| a.direction.as_str()).collect();
            assert_eq!(dirs, ["north", "east", "up"]);
            assert_eq!(c.describe(), "EPSG:6697 JGD2011 + JGD2011 (vertical) height (Lat, Lon, H)");
            assert_eq!(c.height_unit_m, 1.0);
        }

        #[test]
        fn compound_as_two_codes_equals_the_named_compound_but_for_the_id() {
            let a = Crs::parse("urn:ogc:def:crs,crs:EPSG::6668,crs:EPSG::6695").unwrap();
            let b = Crs::parse("EPSG:6697").unwrap();
            assert_eq!(
                (a.horizontal_epsg, a.vertical_epsg, a.kind),
                (b.horizontal_epsg, b.vertical_epsg, b.kind)
            );
            assert_eq!(a.axes, b.axes);
            assert_eq!(a.epsg, None);
            assert_eq!(a.id(), "EPSG:6668+6695");
            // The id it prints reads back as the same CRS.
            let again = Crs::parse(&a.id()).unwrap();
            assert_eq!(again, Crs { given: again.given.clone(), ..a.clone() });
            assert_eq!(a.heights(), HeightKind::Orthometric);
        }

        /// German CityGML's AdV name is the compound of its two EPSG codes: the same CRS, the same
        /// positions, orthometric heights.
        #[test]
        fn an_adv_name_is_its_epsg_compound() {
            let adv = Crs::parse("urn:adv:crs:ETRS89_UTM32*DE_DHHN2016_NH").unwrap();
            let epsg = Crs::parse("urn:ogc:def:crs,crs:EPSG::25832,crs:EPSG::7837").unwrap();
            assert_eq!(adv, Crs { given: adv.given.clone(), ..epsg });
            assert_eq!(adv.id(), "EPSG:25832+7837");
            assert_eq!((adv.kind, adv.heights()), (CrsKind::Projected2D, HeightKind::Orthometric));
            // A point in Munich (E 691 000 m, N 5 334 000 m, 520 m above sea level).
            let p = [691_000.0, 5_334_000.0, 520.0];
            let (a, b) = (adv.transform().unwrap(), Crs::from_epsg(25832).unwrap().transform().unwrap());
            let axes = AxisConvention::Authority;
            let (ga, gb) = (a.to_geodetic(p, axes).unwrap(), b.to_geodetic(p, axes).unwrap());
            assert_eq!(ga, gb);
            // pyproj 3.7 (EPSG:25832 → 4326): 48.130570417°, 11.567052874°.
            assert!((ga.lat_deg - 48.130_570_417).abs() < 1e-8, "{ga:?}");
            assert!((ga.lon_deg - 11.567_052_874).abs() < 1e-8, "{ga:?}");
        }

        #[test]
        fn height_rules() {
            for (code, kind, heights) in [
                (4326, CrsKind::Geographic2D, HeightKind::Orthometric),
                (4979, CrsKind::Geographic3D, HeightKind::Ellipsoidal),
                (4937, CrsKind::Geographic3D, HeightKind::Ellipsoidal),
                (4978, CrsKind::Geocentric, HeightKind::Ellipsoidal),
                (28992, CrsKind::Projected2D, HeightKind::Orthometric),
                (7415, CrsKind::Projected2D, HeightKind::Orthometric),
                (6677, CrsKind::Projected2D, HeightKind::Orthometric),
                (32654, CrsKind::Projected2D, HeightKind::Orthometric),
            ] {
                let c = Crs::from_epsg(code).unwrap();
                assert_eq!((c.kind, c.heights()), (kind, heights), "EPSG:{code}");
            }
        }

        #[test]
        fn plane_rectangular_crs_is_northing_first() {
            // EPSG: "X" is the northing axis of the Japan Plane Rectangular CSs.
            for code in 6669..=6687 {
                let c = Crs::from_epsg(code).unwrap();
                let dirs: Vec<&str> = c.axes.iter().map(|a| a.direction.as_str()).collect();
                assert_eq!(dirs, ["north", "east"], "EPSG:{code}");
                assert_eq!(c.axes[0].abbrev, "X");
            }
        }

        #[test]
        fn feet_heights_are_scaled() {
            // EPSG:2230 NAD83 / California zone 6 (ftUS): 1 US survey foot = 1200/3937 m.
            let c = Crs::from_epsg(2230).unwrap();
            assert!((c.height_unit_m - 1200.0 / 3937.0).abs() < 1e-12, "{}", c.height_unit_m);
        }

        #[test]
        fn unknown_and_unsupported_codes_are_errors_naming_them() {
            let chain = |name: &str| error_chain(&Crs::parse(name).unwrap_err());
            let e = Crs::parse("EPSG:999999").unwrap_err();
            let GeoError::UnknownCrs { source, .. } = &e else { panic!("{e:?}") };
            assert!(
                matches!(**source, CrsError::Proj(ProjError::NotInDatabase { code: 999999, .. })),
                "{e:?}"
            );
            let msg = error_chain(&e);
            assert!(msg.contains("EPSG:999999") && msg.contains("proj.db"), "{msg}");
            // A vertical CRS alone (EPSG:5703 NAVD88 height) cannot be placed on the globe.
            let msg = chain("EPSG:5703");
            assert!(msg.contains("vertical") && msg.contains("compound"), "{msg}");
            // A compound with the parts swapped.
            let msg = chain("urn:ogc:def:crs,crs:EPSG::6695,crs:EPSG::6668");
            assert!(msg.contains("first component"), "{msg}");
            let msg = chain("urn:ogc:def:crs,crs:EPSG::6668,crs:EPSG::4326");
            assert!(msg.contains("second component"), "{msg}");
            assert_eq!(
                chain("garbage"),
                "unknown or unsupported CRS \"garbage\" (set an explicit `crs = \"EPSG:NNNN\"` for this \
                 source in the scene file): not a recognised CRS name; expected an EPSG code such as \
                 EPSG:6697, urn:ogc:def:crs:EPSG::6697, http://www.opengis.net/def/crs/EPSG/0/6697 or a \
                 compound urn:ogc:def:crs,crs:EPSG::6668,crs:EPSG::6695 or EPSG:6668+6695"
            );
        }
    }

    mod convert {
        use super::*;

        fn close(g: Geodetic, lat: f64, lon: f64, h: f64, tol_deg: f64) {
            assert!(
                (g.lat_deg - lat).abs() < tol_deg
                    && (g.lon_deg - lon).abs() < tol_deg
                    && (g.h_m - h).abs() < 1e-6,
                "{g:?} vs ({lat}, {lon}, {h})"
            );
        }

        #[test]
        fn epsg_6697_is_lat_lon_in_authority_order() {
            // JGD2011 → WGS 84 is a null transformation (EPSG:15580 "JGD2011 to WGS 84 (1)").
            let t = Crs::from_epsg(6697).unwrap().transform().unwrap();
            let a = t.to_geodetic([35.658, 139.7016, 40.0], AxisConvention::Authority).unwrap();
            let e = t.to_geodetic([139.7016, 35.658, 40.0], AxisConvention::EastNorth).unwrap();
            close(a, 35.658, 139.7016, 40.0, 1e-12);
            close(e, 35.658, 139.7016, 40.0, 1e-12);
        }

        #[test]
        fn plane_rectangular_origin_and_axis_orders() {
            // Zone IX (EPSG:6677) origin: φ0 = 36°N, λ0 = 139°50'E, X = Y = 0 there (hand value).
            let t = Crs::from_epsg(6677).unwrap().transform().unwrap();
            let o = t.to_geodetic([0.0, 0.0, 12.5], AxisConvention::Authority).unwrap();
            close(o, 36.0, 139.0 + 50.0 / 60.0, 12.5, 1e-12);
            // Shibuya-ish: X = −37 900 m (north), Y = −7 900 m (east).
            let a = t.to_geodetic([-37_900.0, -7_900.0, 30.0], AxisConvention::Authority).unwrap();
            let e = t.to_geodetic([-7_900.0, -37_900.0, 30.0], AxisConvention::EastNorth).unwrap();
            close(a, e.lat_deg, e.lon_deg, 30.0, 1e-12);
            // South of and west of the origin.
            assert!(
                a.lat_deg < 36.0 && a.lat_deg > 35.6 && a.lon_deg < 139.8333 && a.lon_deg > 139.7,
                "{a:?}"
            );
        }

        #[test]
        fn utm_central_meridian_on_the_equator() {
            // UTM: E = 500 000 m on the central meridian; on the equator N = 0 (north zones) or
            // 10 000 000 m (south zones).
            for (code, lon0, northing) in
                [(32631, 3.0, 0.0), (32654, 141.0, 0.0), (32733, 15.0, 10_000_000.0)]
            {
                let t = Crs::from_epsg(code).unwrap().transform().unwrap();
                for axes in [AxisConvention::Authority, AxisConvention::EastNorth] {
                    let g = t.to_geodetic([500_000.0, northing, 0.0], axes).unwrap();
                    close(g, 0.0, lon0, 0.0, 1e-9);
                }
            }
        }

        #[test]
        fn geocentric_uses_the_closed_form() {
            let t = Crs::from_epsg(4978).unwrap().transform().unwrap();
            let want = Geodetic::new(35.658, 139.7016, 77.0);
            let p = geodetic_to_ecef(want);
            for axes in [AxisConvention::Authority, AxisConvention::EastNorth] {
                close(t.to_geodetic(p, axes).unwrap(), want.lat_deg, want.lon_deg, 77.0, 1e-11);
            }
        }

        #[test]
        fn non_wgs84_geocentric_goes_through_proj() {
            // EPSG:4936 ETRS89 geocentric → WGS 84: PROJ's choice (a null/ballpark transformation here).
            let t = Crs::from_epsg(4936).unwrap().transform().unwrap();
            let p = geodetic_to_ecef(Geodetic::new(52.0, 5.0, 10.0));
            let g = t.to_geodetic(p, AxisConvention::Authority).unwrap();
            assert!((g.lat_deg - 52.0).abs() < 1e-5 && (g.lon_deg - 5.0).abs() < 1e-5, "{g:?}");
            assert!((g.h_m - 10.0).abs() < 1.0, "{g:?}");
        }

        #[test]
        fn round_trips_through_the_inverse() {
            // Projections alone invert to f64 noise (1e-6 source units, 1e-9° ≈ 0.1 mm). A 7-parameter
            // Helmert shift (Amersfoort, CH1903+ → WGS 84) is inverted by PROJ with the transposed
            // rotation, which neglects second-order terms: rotation² × R ≈ (2e-5)² × 6.4e6 m ≈ 1 mm.
            const EXACT: (f64, f64) = (1e-6, 1e-9);
            const HELMERT: (f64, f64) = (2e-3, 2e-8);
            for (code, g, (tol_src, tol_deg)) in [
                (6677, Geodetic::new(35.66, 139.70, 40.0), EXACT),
                (28992, Geodetic::new(52.08, 4.31, -2.0), HELMERT),
                (7415, Geodetic::new(52.01, 4.36, 3.0), HELMERT),
                (2056, Geodetic::new(46.95, 7.44, 540.0), HELMERT),
                (32754, Geodetic::new(-35.3, 149.1, 600.0), EXACT),
                (4547, Geodetic::new(30.5, 114.3, 25.0), EXACT),
                (4326, Geodetic::new(-12.0, -77.0, 150.0), EXACT),
                (4978, Geodetic::new(64.1, -21.9, 20.0), EXACT),
                (2230, Geodetic::new(33.0, -117.1, 100.0), EXACT),
            ] {
                let t = Crs::from_epsg(code).unwrap().transform().unwrap();
                for axes in [AxisConvention::Authority, AxisConvention::EastNorth] {
                    let p = t.from_geodetic(g, axes).unwrap();
                    let back = t.to_geodetic(p, axes).unwrap();
                    let p2 = t.from_geodetic(back, axes).unwrap();
                    for k in 0..3 {
                        assert!((p[k] - p2[k]).abs() < tol_src, "EPSG:{code} {axes:?} {p:?} {p2:?}");
                    }
                    close(back, g.lat_deg, g.lon_deg, g.h_m, tol_deg);
                }
            }
        }

        #[test]
        fn authority_and_east_north_agree_for_every_plane_rectangular_zone() {
            for code in 6669..=6687 {
                let t = Crs::from_epsg(code).unwrap().transform().unwrap();
                let a = t.to_geodetic([12_345.0, -23_456.0, 5.0], AxisConvention::Authority).unwrap();
                let e = t.to_geodetic([-23_456.0, 12_345.0, 5.0], AxisConvention::EastNorth).unwrap();
                close(a, e.lat_deg, e.lon_deg, 5.0, 1e-12);
            }
        }

        #[test]
        fn batch_equals_single() {
            let t = Crs::from_epsg(28992).unwrap().transform().unwrap();
            let pts: Vec<[f64; 3]> = (0..50)
                .map(|i| [80_000.0 + 1000.0 * i as f64, 450_000.0 - 700.0 * i as f64, i as f64])
                .collect();
            let many = t.to_geodetic_many(&pts, AxisConvention::EastNorth).unwrap();
            for (p, m) in pts.iter().zip(&many) {
                assert_eq!(*m, t.to_geodetic(*p, AxisConvention::EastNorth).unwrap());
            }
        }

        /// An easting with the zone number in front (as German ALKIS and some CityGML write it) is
        /// refused by the plain UTM CRS with a hint, and its zE-N CRS places it where the plain CRS
        /// places the easting without the prefix.
        #[test]
        fn a_zone_prefixed_easting_gets_a_hint_and_its_ze_n_crs_takes_it() {
            let utm = Crs::parse("EPSG:25832+7837").unwrap().transform().unwrap();
            let e =
                utm.to_geodetic([32_691_000.0, 5_334_000.0, 520.0], AxisConvention::Authority).unwrap_err();
            let msg = e.to_string();
            assert!(msg.contains("zone number in front (691000 m)") && msg.contains("EPSG:4647"), "{msg}");
            let ze_n = Crs::parse("EPSG:4647+7837").unwrap().transform().unwrap();
            let axes = AxisConvention::Authority;
            let a = ze_n.to_geodetic([32_691_000.0, 5_334_000.0, 520.0], axes).unwrap();
            let b = utm.to_geodetic([691_000.0, 5_334_000.0, 520.0], axes).unwrap();
            assert!(
                (a.lat_deg - b.lat_deg).abs() < 1e-9 && (a.lon_deg - b.lon_deg).abs() < 1e-9,
                "{a:?} {b:?}"
            );
            // Other failures get no such hint.
            let e = utm.to_geodetic([f64::NAN, 5_334_000.0, 0.0], axes).unwrap_err();
            assert!(!e.to_string().contains("zone number"), "{e}");
        }

        #[test]
        fn non_finite_and_impossible_points_are_errors() {
            let t = Crs::from_epsg(6677).unwrap().transform().unwrap();
            for p in [[f64::NAN, 0.0, 0.0], [0.0, f64::INFINITY, 0.0], [0.0, 0.0, f64::NAN]] {
                let e = t.to_geodetic(p, AxisConvention::Authority).unwrap_err();
                assert!(matches!(e, GeoError::Transform { .. }), "{e}");
                assert!(e.to_string().contains("EPSG:6677") && e.to_string().contains("not finite"), "{e}");
            }
            let e = t.to_geodetic_many(&[[0.0; 3], [f64::NAN; 3]], AxisConvention::Authority).unwrap_err();
            assert!(e.to_string().contains("NaN"), "{e}");
            // Latitude 95° does not exist.
            let g = Crs::from_epsg(4326).unwrap().transform().unwrap();
            let e = g.to_geodetic([95.0, 10.0, 0.0], AxisConvention::Authority).unwrap_err();
            assert!(matches!(e, GeoError::Transform { .. }), "{e}");
        }

        #[test]
        fn operation_names_what_proj_chose() {
            let t = Crs::from_epsg(32654).unwrap().transform().unwrap();
            let op = t.operation_for([500_000.0, 3_900_000.0, 0.0], AxisConvention::EastNorth).unwrap();
            assert!(op.contains("UTM zone 54N"), "{op}");
            let t = Crs::from_epsg(28992).unwrap().transform().unwrap();
            let op = t.operation_for([85_000.0, 446_000.0, 0.0], AxisConvention::EastNorth).unwrap();
            assert!(op.contains("Amersfoort"), "{op}");
        }

        #[test]
        fn compound_heights_through_proj_without_the_grid_are_ballpark_and_name_it() {
            // Skipped where the real GSIGEO2011 grid is installed (PROJ would then use it).
            let installed = proj_search_paths()
                .iter()
                .any(|d| std::path::Path::new(d).join("jp_gsi_gsigeo2011.tif").is_file());
            let t = Crs::from_epsg(6697).unwrap().transform_with_heights().unwrap();
            let p = [139.7016, 35.658, 40.0];
            let c = t.vertical_choice_at(p, AxisConvention::EastNorth).unwrap().expect("compound converter");
            if installed {
                assert!(!c.ballpark, "{c:?}");
                return;
            }
            assert!(c.ballpark, "{c:?}");
            assert_eq!(c.missing_grids, ["jp_gsi_gsigeo2011.tif"], "{c:?}");
            // The ballpark step leaves H as h; the horizontal part is a null transformation.
            close(t.to_geodetic(p, AxisConvention::EastNorth).unwrap(), 35.658, 139.7016, 40.0, 1e-9);
            let a = t.to_geodetic([35.658, 139.7016, 40.0], AxisConvention::Authority).unwrap();
            close(a, 35.658, 139.7016, 40.0, 1e-9);
            // The same for the compound spelled as two codes; the inverse returns H.
            let two = Crs::parse("urn:ogc:def:crs,crs:EPSG::6668,crs:EPSG::6695").unwrap();
            let t2 = two.transform_with_heights().unwrap();
            let back =
                t2.from_geodetic(Geodetic::new(35.658, 139.7016, 40.0), AxisConvention::EastNorth).unwrap();
            assert!((back[2] - 40.0).abs() < 1e-6 && (back[0] - 139.7016).abs() < 1e-9, "{back:?}");
            // Other converters report no choice; 2D CRSs have no heights for PROJ to convert.
            let h = Crs::from_epsg(6677).unwrap().transform().unwrap();
            assert_eq!(h.vertical_choice_at([0.0, 0.0, 0.0], AxisConvention::Authority).unwrap(), None);
            assert!(Crs::from_epsg(6677).unwrap().transform_with_heights().is_err());
        }

        #[test]
        fn transform_moves_to_another_thread() {
            let t = Crs::from_epsg(6677).unwrap().transform().unwrap();
            let g = std::thread::spawn(move || {
                t.to_geodetic([0.0, 0.0, 0.0], AxisConvention::Authority).unwrap()
            })
            .join()
            .unwrap();
            close(g, 36.0, 139.0 + 50.0 / 60.0, 0.0, 1e-12);
        }
    }
}
