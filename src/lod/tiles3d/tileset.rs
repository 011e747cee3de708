//! `tileset.json` (3D Tiles 1.0 and 1.1): the spec types, their validation, the tile tree with
//! accumulated transforms, implicit tiling, and the traversal that lists the contents to read.
//!
//! This is insgen's one reader of tileset JSON: [`Tileset::load`] parses and validates one file
//! (reporting every problem with its JSON path), accumulates `transform`s from the root down in f64
//! ([`Tile::world_from_tile`]), resolves content URIs, expands 3D Tiles 1.1 implicit tiling
//! ([`super::implicit`]) into explicit tiles, and hands on a [`Tile`] tree. External tilesets (a
//! content that is itself a tileset JSON) are not followed by `load`: callers load them when they
//! reach them ([`ContentRef::is_external_tileset`]), the LoD reader always, the Blender tile
//! selection only when the camera sees them.
//!
//! # Which contents the LoD reader reads ([`traverse`])
//! insgen wants every building once, at the finest geometry the tileset has:
//! - a tile whose refinement is `ADD` (given or inherited) contributes its content *and* its
//!   children's: ADD children add to the parent;
//! - a tile whose refinement is `REPLACE` contributes its content only when it has no children:
//!   REPLACE children supersede the parent's (coarser) content;
//! - leaves are always read; a content that is itself a tileset JSON (an external tileset) is always
//!   followed, its root's transform applied on top of the referencing tile's.
//!
//! A root without `refine` is taken as `REPLACE`. For the PLATEAU Shibuya subset (an ADD root over
//! REPLACE leaves holding b3dm), this reads all 56 leaves. Bounding volumes and geometric errors are
//! not used there: nothing is culled.
//!
//! Transforms (`transform`, column-major 4×4, converted to [`DMat4`] here, at the file edge)
//! accumulate from the root down in f64. Content URIs (`content.uri`, 1.0's `content.url`, 1.1's
//! `contents[]`) are relative to the JSON that names them, percent-decoded (`%20` → space), without
//! query or fragment; remote (`http://…`) and `data:` URIs are rejected. A tileset JSON may be
//! gzip-compressed (as some Cesium ion exports are). `asset.gltfUpAxis` (pre-1.0 Cesium) is honoured.
//! Extensions: `3DTILES_content_gltf` (glTF contents; nothing to do) and `3DTILES_implicit_tiling`
//! (the pre-1.1 name of `implicitTiling`) are read; other `extensionsRequired` stop the read with
//! their name.

use std::io::Read;
use std::path::{Component, Path, PathBuf};

use glam::{DMat3, DMat4, DVec3};
use serde::Deserialize;

use super::error::{ContentError, UriError};
use super::gltf::UpAxis;
use super::implicit::{self, ImplicitTilingJson};
use crate::lod::error::{TilesetIssue, TilesetProblem};
use crate::lod::LodError;

/// Tileset extensions insgen reads (or that need nothing from a reader of geometry).
pub(crate) const HANDLED_TILESET_EXTENSIONS: &[&str] =
    &["3DTILES_content_gltf", "3DTILES_implicit_tiling", "3DTILES_metadata", "3DTILES_multiple_contents"];

/// The tileset JSON root.
#[derive(Debug, Deserialize)]
#[serde(rename_all = "camelCase")]
pub(crate) struct TilesetJson {
    pub asset: AssetJson,
    pub root: TileJson,
    #[serde(default)]
    pub extensions_required: Vec<String>,
}

/// `asset`: the 3D Tiles version and, for pre-1.0 Cesium tilesets, the glTF up axis.
#[derive(Debug, Deserialize)]
#[serde(rename_all = "camelCase")]
pub(crate) struct AssetJson {
    pub version: String,
    /// `"X"`, `"Y"` (default) or `"Z"`: CesiumJS's pre-1.0 `asset.gltfUpAxis`.
    pub gltf_up_axis: Option<String>,
}

/// A tile: bounding volume, geometric error, transform, refinement, content(s) and children.
#[derive(Debug, Deserialize)]
#[serde(rename_all = "camelCase")]
pub(crate) struct TileJson {
    /// Required by the spec; absent volumes are reported by [`validate`].
    pub bounding_volume: Option<BoundingVolumeJson>,
    /// Metres of error when this tile is rendered and its children are not (required).
    pub geometric_error: Option<f64>,
    /// Column-major 4×4 from this tile's frame to its parent's.
    pub transform: Option<Vec<f64>>,
    /// `"ADD"` or `"REPLACE"`; inherited from the parent when absent.
    pub refine: Option<String>,
    pub content: Option<ContentJson>,
    /// 3D Tiles 1.1: several contents per tile.
    pub contents: Option<Vec<ContentJson>>,
    #[serde(default)]
    pub children: Vec<TileJson>,
    /// 3D Tiles 1.1 implicit tiling.
    pub implicit_tiling: Option<ImplicitTilingJson>,
    #[serde(default)]
    pub extensions: serde_json::Map<String, serde_json::Value>,
}

/// `boundingVolume`: one of box (12 numbers), region (6, radians and metres), sphere (4).
#[derive(Debug, Clone, Deserialize)]
pub(crate) struct BoundingVolumeJson {
    #[serde(rename = "box")]
    pub box_: Option<Vec<f64>>,
    pub region: Option<Vec<f64>>,
    pub sphere: Option<Vec<f64>>,
}

/// `content`: `uri` (1.0 final, 1.1) or `url` (1.0 drafts).
#[derive(Debug, Deserialize)]
pub(crate) struct ContentJson {
    pub uri: Option<String>,
    pub url: Option<String>,
}

impl ContentJson {
    pub(crate) fn uri(&self) -> Option<&str> {
        self.uri.as_deref().or(self.url.as_deref())
    }
}

/// Refinement of a tile's children.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Refine {
    /// Children add to the parent's content.
    Add,
    /// Children replace the parent's content.
    Replace,
}

/// A validated bounding volume, in the tile's frame (box, sphere) or geodetic (region).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum BoundingVolume {
    /// Centre and the three half-axes (columns), tile-frame metres.
    Box {
        /// Centre, tile-frame metres.
        centre: DVec3,
        /// The three half-axes as columns, metres.
        half_axes: DMat3,
    },
    /// West, south, east, north in radians (EPSG:4979), minimum and maximum ellipsoidal height in
    /// metres. Regions ignore tile transforms.
    Region {
        /// Westernmost longitude, radians.
        west_rad: f64,
        /// Southernmost latitude, radians.
        south_rad: f64,
        /// Easternmost longitude, radians.
        east_rad: f64,
        /// Northernmost latitude, radians.
        north_rad: f64,
        /// Lowest ellipsoidal height, metres.
        min_h_m: f64,
        /// Highest ellipsoidal height, metres.
        max_h_m: f64,
    },
    /// Centre and radius, tile-frame metres.
    Sphere {
        /// Centre, tile-frame metres.
        centre: DVec3,
        /// Radius, metres.
        radius_m: f64,
    },
}

/// Mean Earth radius used to pad sampled region bounds for curvature, metres (IUGG mean radius R1).
const EARTH_MEAN_RADIUS_M: f64 = 6_371_008.8;

impl BoundingVolume {
    /// From its JSON form (lengths and finiteness checked by [`validate`]).
    pub(crate) fn from_json(bv: &BoundingVolumeJson) -> Option<BoundingVolume> {
        if let Some(b) = bv.box_.as_deref().filter(|b| b.len() == 12) {
            return Some(BoundingVolume::Box {
                centre: DVec3::new(b[0], b[1], b[2]),
                half_axes: DMat3::from_cols(
                    DVec3::new(b[3], b[4], b[5]),
                    DVec3::new(b[6], b[7], b[8]),
                    DVec3::new(b[9], b[10], b[11]),
                ),
            });
        }
        if let Some(r) = bv.region.as_deref().filter(|r| r.len() == 6) {
            return Some(BoundingVolume::Region {
                west_rad: r[0],
                south_rad: r[1],
                east_rad: r[2],
                north_rad: r[3],
                min_h_m: r[4],
                max_h_m: r[5],
            });
        }
        if let Some(s) = bv.sphere.as_deref().filter(|s| s.len() == 4) {
            return Some(BoundingVolume::Sphere { centre: DVec3::new(s[0], s[1], s[2]), radius_m: s[3] });
        }
        None
    }

    /// A sphere (centre, radius) in the world (ECEF) frame that contains the volume, given the tile's
    /// world-from-tile transform (ignored by regions, which are geodetic).
    ///
    /// Regions: a 9 × 9 grid at both heights, padded by the sagitta of one grid step so the curved
    /// surface between samples stays inside.
    pub fn world_sphere(&self, world_from_tile: &DMat4) -> (DVec3, f64) {
        match *self {
            BoundingVolume::Box { centre, half_axes } => {
                let c = world_from_tile.transform_point3(centre);
                let mut r: f64 = 0.0;
                for sx in [-1.0, 1.0] {
                    for sy in [-1.0, 1.0] {
                        for sz in [-1.0, 1.0] {
                            let p = centre + half_axes * DVec3::new(sx, sy, sz);
                            r = r.max(world_from_tile.transform_point3(p).distance(c));
                        }
                    }
                }
                (c, r)
            }
            BoundingVolume::Sphere { centre, radius_m } => {
                let c = world_from_tile.transform_point3(centre);
                let scale = [world_from_tile.x_axis, world_from_tile.y_axis, world_from_tile.z_axis]
                    .iter()
                    .map(|a| a.truncate().length())
                    .fold(0.0, f64::max);
                (c, radius_m * scale)
            }
            BoundingVolume::Region { west_rad, south_rad, east_rad, north_rad, min_h_m, max_h_m } => {
                use crate::geo::{geodetic_to_ecef, Geodetic};
                let east = if east_rad < west_rad { east_rad + std::f64::consts::TAU } else { east_rad };
                const STEPS: usize = 8;
                let mut pts = Vec::with_capacity(2 * (STEPS + 1) * (STEPS + 1));
                for i in 0..=STEPS {
                    for j in 0..=STEPS {
                        let lon = west_rad + (east - west_rad) * i as f64 / STEPS as f64;
                        let lat = south_rad + (north_rad - south_rad) * j as f64 / STEPS as f64;
                        for h in [min_h_m, max_h_m] {
                            let g = Geodetic::new(lat.to_degrees(), lon.to_degrees(), h);
                            pts.push(DVec3::from_array(geodetic_to_ecef(g)));
                        }
                    }
                }
                let lo = pts.iter().fold(DVec3::INFINITY, |a, p| a.min(*p));
                let hi = pts.iter().fold(DVec3::NEG_INFINITY, |a, p| a.max(*p));
                let c = 0.5 * (lo + hi);
                let step = (east - west_rad).max(north_rad - south_rad) / STEPS as f64;
                let sagitta = (EARTH_MEAN_RADIUS_M + max_h_m.max(0.0)) * (1.0 - (0.5 * step).cos());
                let r = pts.iter().map(|p| p.distance(c)).fold(0.0, f64::max) + sagitta;
                (c, r)
            }
        }
    }
}

/// One content of a tile, its URI resolved to a file.
#[derive(Debug, Clone, PartialEq)]
pub struct ContentRef {
    /// The URI as written (after template substitution for implicit tiles).
    pub uri: String,
    /// The file it names (relative URIs resolved against the tileset JSON's folder).
    pub file: PathBuf,
    /// The tileset JSON that references it.
    pub tileset: PathBuf,
    /// JSON path of the reference in that file: `root.children[3].content`.
    pub at: String,
}

impl ContentRef {
    /// `"<tileset.json>: root.children[3].content"`: where the content is referenced.
    pub fn location(&self) -> String {
        format!("{}: {}", self.tileset.display(), self.at)
    }

    /// [`LodError::Tile`]: this content cannot be read or decoded, because of `source`.
    pub(crate) fn error(&self, source: ContentError) -> LodError {
        LodError::Tile {
            tileset: self.tileset.clone(),
            at: self.at.clone(),
            uri: self.uri.clone(),
            content: self.file.clone(),
            source: Box::new(source),
        }
    }

    /// Whether the content is an external tileset: a `.json` file name, or a file whose JSON has a
    /// `root` (a glTF JSON has none). A file that cannot be read is not one (its reader reports it).
    pub fn is_external_tileset(&self) -> bool {
        if self.file.extension().is_some_and(|e| e.eq_ignore_ascii_case("json")) {
            return true;
        }
        matches!(peek(&self.file), Ok(Peek::Json)) && is_tileset_json(&self.file)
    }
}

/// A tile with its transform accumulated from the root of the tileset chain.
#[derive(Debug, Clone, PartialEq)]
pub struct Tile {
    /// JSON path in its tileset (`root.children[2]`; implicit tiles: `root{level 2, x 1, y 3}`).
    pub at: String,
    /// Tile frame → world (ECEF) frame: every ancestor's transform, external tilesets included.
    pub world_from_tile: DMat4,
    /// The validated bounding volume.
    pub bounding_volume: BoundingVolume,
    /// Geometric error, metres.
    pub geometric_error_m: f64,
    /// This tile's refinement (given, or inherited from its parent).
    pub refine: Refine,
    /// The contents to read (one, several with `contents`, or none).
    pub contents: Vec<ContentRef>,
    /// Child tiles (explicit or expanded from implicit tiling).
    pub children: Vec<Tile>,
}

impl Tile {
    /// Number of tiles in this subtree (this one included).
    pub fn count(&self) -> usize {
        1 + self.children.iter().map(Tile::count).sum::<usize>()
    }
}

/// One tileset JSON file, validated, as a tile tree.
#[derive(Debug, Clone, PartialEq)]
pub struct Tileset {
    /// The JSON file.
    pub path: PathBuf,
    /// The up axis of its glTF contents.
    pub up: UpAxis,
    /// The root tile.
    pub root: Tile,
}

/// Largest number of tiles implicit tiling may expand to in one tileset file (a guard against a
/// hostile or mistaken `availableLevels`).
pub const MAX_IMPLICIT_TILES: usize = 1 << 20;

impl Tileset {
    /// Reads and validates the tileset JSON at `path` and builds its tile tree; `world_from_parent`
    /// is the transform of the tile that references it (identity for a root tileset).
    ///
    /// # Errors
    /// The file is unreadable ([`LodError::File`]), not a tileset JSON ([`LodError::Tiles3d`] with
    /// the gzip or JSON error), invalid ([`LodError::Invalid`], every problem listed with its JSON
    /// path), requires an unsupported extension (named), names a URI that is not a local file
    /// ([`LodError::Tiles3d`] with the [`UriError`]), or its implicit tiling is broken (subtree file
    /// named, [`LodError::Subtree`]).
    pub fn load(path: &Path, world_from_parent: DMat4) -> Result<Tileset, LodError> {
        let bytes = crate::util::read_file(path)?;
        let tiles3d_error = |source| LodError::Tiles3d { path: path.to_path_buf(), source: Box::new(source) };
        let bytes = super::maybe_gunzip(&bytes).map_err(tiles3d_error)?;
        let json = bytes.strip_prefix(b"\xEF\xBB\xBF").unwrap_or(&bytes);
        let tileset: TilesetJson =
            serde_json::from_slice(json).map_err(|e| tiles3d_error(ContentError::TilesetJson(e)))?;
        let issues = validate(&tileset);
        if !issues.is_empty() {
            return Err(LodError::InvalidTileset { path: path.to_path_buf(), issues });
        }
        let up = match tileset.asset.gltf_up_axis.as_deref().map(str::to_ascii_uppercase).as_deref() {
            Some("X") => UpAxis::X,
            Some("Z") => UpAxis::Z,
            _ => UpAxis::Y,
        };
        let dir = path.parent().unwrap_or(Path::new("")).to_path_buf();
        let mut budget = MAX_IMPLICIT_TILES;
        let b = Builder { tileset: path, dir: &dir };
        let root = b.tile(&tileset.root, "root", world_from_parent, Refine::Replace, &mut budget)?;
        Ok(Tileset { path: path.to_path_buf(), up, root })
    }
}

struct Builder<'a> {
    tileset: &'a Path,
    dir: &'a Path,
}

impl Builder<'_> {
    fn tile(
        &self,
        t: &TileJson,
        at: &str,
        world_from_parent: DMat4,
        inherited: Refine,
        budget: &mut usize,
    ) -> Result<Tile, LodError> {
        let world = match &t.transform {
            // Length 16 was checked by `validate`; column-major as the spec stores it.
            Some(m) => world_from_parent * DMat4::from_cols_slice(m),
            None => world_from_parent,
        };
        let refine = parse_refine(t.refine.as_deref()).unwrap_or(inherited);
        // `validate` ensured a volume and a geometric error exist and are well-formed.
        let bounding_volume = t
            .bounding_volume
            .as_ref()
            .and_then(BoundingVolume::from_json)
            .ok_or_else(|| LodError::invalid(self.tileset, at, TilesetProblem::UnusableBoundingVolume))?;
        let geometric_error_m = t.geometric_error.unwrap_or(0.0);
        let content_jsons: Vec<(String, &ContentJson)> = match (&t.content, &t.contents) {
            (Some(c), _) => vec![(format!("{at}.content"), c)],
            (None, Some(cs)) => {
                cs.iter().enumerate().map(|(i, c)| (format!("{at}.contents[{i}]"), c)).collect()
            }
            (None, None) => vec![],
        };
        let implicit = implicit_of(t).map_err(|source| LodError::Tiles3d {
            path: self.tileset.to_path_buf(),
            source: Box::new(ContentError::Json {
                at: format!("{at}.extensions.3DTILES_implicit_tiling"),
                source,
            }),
        })?;
        if let Some(it) = implicit {
            let templates: Vec<(String, String)> = content_jsons
                .iter()
                .map(|(a, c)| (a.clone(), c.uri().unwrap_or_default().to_string()))
                .collect();
            let root = implicit::Root {
                tileset: self.tileset,
                dir: self.dir,
                at,
                world_from_tile: world,
                bounding_volume,
                geometric_error_m,
                refine,
                content_templates: &templates,
            };
            return implicit::expand(&root, &it, budget);
        }
        let mut contents = Vec::with_capacity(content_jsons.len());
        for (c_at, c) in content_jsons {
            let uri = c.uri().unwrap_or_default();
            contents.push(self.content(uri, &c_at)?);
        }
        let mut children = Vec::with_capacity(t.children.len());
        for (i, c) in t.children.iter().enumerate() {
            children.push(self.tile(c, &format!("{at}.children[{i}]"), world, refine, budget)?);
        }
        Ok(Tile {
            at: at.to_string(),
            world_from_tile: world,
            bounding_volume,
            geometric_error_m,
            refine,
            contents,
            children,
        })
    }

    fn content(&self, uri: &str, at: &str) -> Result<ContentRef, LodError> {
        let file = resolve_uri(self.dir, uri).map_err(|e| uri_error(self.tileset, at, e))?;
        Ok(ContentRef { uri: uri.to_string(), file, tileset: self.tileset.to_path_buf(), at: at.to_string() })
    }
}

pub(crate) fn parse_refine(r: Option<&str>) -> Option<Refine> {
    match r.map(str::to_ascii_uppercase).as_deref() {
        Some("ADD") => Some(Refine::Add),
        Some("REPLACE") => Some(Refine::Replace),
        _ => None,
    }
}

/// [`LodError::Tiles3d`] for a URI at JSON path `at` of `tileset` that names no local file.
pub(crate) fn uri_error(tileset: &Path, at: &str, e: UriError) -> LodError {
    LodError::Tiles3d { path: tileset.to_path_buf(), source: Box::new(ContentError::Uri(e).at(at)) }
}

/// The tile's implicit tiling: 1.1's `implicitTiling` or the `3DTILES_implicit_tiling` extension
/// (whose JSON error is returned when it is malformed).
fn implicit_of(t: &TileJson) -> Result<Option<ImplicitTilingJson>, serde_json::Error> {
    if let Some(it) = &t.implicit_tiling {
        return Ok(Some(it.clone()));
    }
    match t.extensions.get("3DTILES_implicit_tiling") {
        None => Ok(None),
        Some(v) => serde_json::from_value(v.clone()).map(Some),
    }
}

/// One content to decode.
#[derive(Debug, Clone)]
pub(crate) struct ContentJob {
    /// The content file.
    pub file: PathBuf,
    /// The file relative to the root tileset's folder (`/`-separated): names it in synthesized ids.
    pub label: String,
    /// Where it is referenced; `None` for a content read on its own.
    pub referenced_by: Option<ContentRef>,
    /// Tile frame → tileset (ECEF) frame.
    pub world_from_tile: DMat4,
    pub up: UpAxis,
}

impl ContentJob {
    /// The error for this content failing with `source`: [`LodError::Tile`] when a tileset references
    /// it, [`LodError::Tiles3d`] naming the file otherwise.
    pub(crate) fn error(&self, source: ContentError) -> LodError {
        match &self.referenced_by {
            Some(c) => c.error(source),
            None => LodError::Tiles3d { path: self.file.clone(), source: Box::new(source) },
        }
    }
}

/// The traversal's result.
#[derive(Debug, Default)]
pub(crate) struct Traversal {
    pub jobs: Vec<ContentJob>,
    /// Tileset JSON files read (root + external).
    pub tilesets_read: u64,
    /// Contents of REPLACE tiles with children, not read.
    pub contents_skipped: u64,
}

/// Walks the tileset at `path` (and its external tilesets) and lists the contents to read.
///
/// # Errors
/// The tileset (or an external one) is unreadable, not JSON, invalid (all problems listed), refers
/// to a missing file, or references itself.
pub(crate) fn traverse(path: &Path) -> Result<Traversal, LodError> {
    let root_dir = normalize(path.parent().unwrap_or(Path::new("")));
    let mut out = Traversal::default();
    let mut stack = Vec::new();
    walk_tileset(path, DMat4::IDENTITY, &root_dir, &mut stack, &mut out)?;
    Ok(out)
}

fn walk_tileset(
    path: &Path,
    world_from_parent: DMat4,
    root_dir: &Path,
    stack: &mut Vec<PathBuf>,
    out: &mut Traversal,
) -> Result<(), LodError> {
    let canonical = std::fs::canonicalize(path).unwrap_or_else(|_| normalize(path));
    if stack.contains(&canonical) {
        return Err(LodError::invalid(
            path,
            "root",
            TilesetProblem::Cycle { chain: stack.iter().cloned().chain([canonical]).collect() },
        ));
    }
    let tileset = Tileset::load(path, world_from_parent)?;
    out.tilesets_read += 1;
    stack.push(canonical);
    let r = walk_tile(&tileset.root, &tileset, root_dir, stack, out);
    stack.pop();
    r
}

fn walk_tile(
    tile: &Tile,
    ts: &Tileset,
    root_dir: &Path,
    stack: &mut Vec<PathBuf>,
    out: &mut Traversal,
) -> Result<(), LodError> {
    let read_contents = tile.children.is_empty() || tile.refine == Refine::Add;
    if !read_contents {
        out.contents_skipped += tile.contents.len() as u64;
    }
    for c in tile.contents.iter().filter(|_| read_contents) {
        let head = peek(&c.file).map_err(|e| c.error(ContentError::Unreadable(e)))?;
        if head == Peek::Json && is_tileset_json(&c.file) {
            walk_tileset(&c.file, tile.world_from_tile, root_dir, stack, out)?;
        } else {
            let norm = normalize(&c.file);
            let label = match norm.strip_prefix(root_dir) {
                Ok(rel) => {
                    rel.components().map(|c| c.as_os_str().to_string_lossy()).collect::<Vec<_>>().join("/")
                }
                Err(_) => norm.display().to_string(),
            };
            out.jobs.push(ContentJob {
                file: c.file.clone(),
                label,
                referenced_by: Some(c.clone()),
                world_from_tile: tile.world_from_tile,
                up: ts.up,
            });
        }
    }
    for child in &tile.children {
        walk_tile(child, ts, root_dir, stack, out)?;
    }
    Ok(())
}

/// Every problem of a tileset, each with its JSON path.
pub(crate) fn validate(t: &TilesetJson) -> Vec<TilesetIssue> {
    let mut p = Vec::new();
    if !matches!(t.asset.version.as_str(), "0.0" | "1.0" | "1.1") {
        log::warn!("3D Tiles asset.version {:?} is not 0.0, 1.0 or 1.1; reading it as 1.1", t.asset.version);
    }
    if let Some(axis) = &t.asset.gltf_up_axis {
        if !matches!(axis.to_ascii_uppercase().as_str(), "X" | "Y" | "Z") {
            p.push(TilesetIssue {
                at: "asset.gltfUpAxis".into(),
                problem: TilesetProblem::UpAxis { axis: axis.clone() },
            });
        }
    }
    for (i, e) in t.extensions_required.iter().enumerate() {
        if !HANDLED_TILESET_EXTENSIONS.contains(&e.as_str()) {
            p.push(TilesetIssue {
                at: format!("extensionsRequired[{i}]"),
                problem: TilesetProblem::RequiredExtension { extension: e.clone() },
            });
        }
    }
    validate_tile(&t.root, "root", &mut p);
    p
}

fn validate_tile(tile: &TileJson, at: &str, p: &mut Vec<TilesetIssue>) {
    let mut push = |at: String, problem| p.push(TilesetIssue { at, problem });
    match &tile.bounding_volume {
        None => push(format!("{at}.boundingVolume"), TilesetProblem::NoBoundingVolume),
        Some(bv) => {
            let lens = [
                (bv.box_.as_ref(), 12, "box"),
                (bv.region.as_ref(), 6, "region"),
                (bv.sphere.as_ref(), 4, "sphere"),
            ];
            if lens.iter().all(|(v, _, _)| v.is_none()) {
                push(format!("{at}.boundingVolume"), TilesetProblem::EmptyBoundingVolume);
            }
            for (v, n, name) in lens {
                if let Some(v) = v {
                    if v.len() != n || v.iter().any(|x| !x.is_finite()) {
                        push(
                            format!("{at}.boundingVolume.{name}"),
                            TilesetProblem::BoundingVolume { needed: n, found: v.len() },
                        );
                    }
                }
            }
        }
    }
    match tile.geometric_error {
        None => push(format!("{at}.geometricError"), TilesetProblem::NoGeometricError),
        Some(g) if !(g.is_finite() && g >= 0.0) => {
            push(format!("{at}.geometricError"), TilesetProblem::GeometricError { value: g })
        }
        Some(_) => {}
    }
    if let Some(m) = &tile.transform {
        if m.len() != 16 {
            push(format!("{at}.transform"), TilesetProblem::TransformLength { found: m.len() });
        } else if m.iter().any(|v| !v.is_finite()) {
            push(format!("{at}.transform"), TilesetProblem::TransformNotFinite);
        }
    }
    if let Some(r) = &tile.refine {
        if parse_refine(Some(r)).is_none() {
            push(format!("{at}.refine"), TilesetProblem::Refine { found: r.clone() });
        }
    }
    if tile.content.is_some() && tile.contents.is_some() {
        push(at.to_string(), TilesetProblem::ContentAndContents);
    }
    if let Some(c) = &tile.content {
        if c.uri().is_none() {
            push(format!("{at}.content"), TilesetProblem::NoUri);
        }
    }
    for (i, c) in tile.contents.iter().flatten().enumerate() {
        if c.uri().is_none() {
            push(format!("{at}.contents[{i}]"), TilesetProblem::NoUri);
        }
    }
    if let Some(it) = &tile.implicit_tiling {
        implicit::validate(it, tile, &format!("{at}.implicitTiling"), p);
    }
    for (i, c) in tile.children.iter().enumerate() {
        validate_tile(c, &format!("{at}.children[{i}]"), p);
    }
}

/// Resolves a content/buffer URI against `dir`: query and fragment dropped, percent-decoded; remote
/// and `data:` URIs refused.
///
/// # Errors
/// [`UriError`] for remote and `data:` URIs, URIs without a path, and invalid percent-encoding.
pub(crate) fn resolve_uri(dir: &Path, uri: &str) -> Result<PathBuf, UriError> {
    let lower = uri.to_ascii_lowercase();
    if lower.contains("://") || lower.starts_with("data:") {
        return Err(UriError::NotLocal { uri: uri.to_string() });
    }
    let bare = uri.split(['?', '#']).next().unwrap_or("");
    if bare.is_empty() {
        return Err(UriError::NoFile { uri: uri.to_string() });
    }
    Ok(dir.join(percent_decode(bare)?))
}

/// `%XX` → byte, the result read as UTF-8.
fn percent_decode(s: &str) -> Result<String, UriError> {
    let b = s.as_bytes();
    let mut out = Vec::with_capacity(b.len());
    let mut i = 0;
    while i < b.len() {
        if b[i] == b'%' {
            let hex = b.get(i + 1..i + 3).and_then(|h| std::str::from_utf8(h).ok());
            let v = hex.and_then(|h| u8::from_str_radix(h, 16).ok());
            match v {
                Some(v) => {
                    out.push(v);
                    i += 3;
                }
                None => return Err(UriError::PercentEscape { uri: s.to_string(), at: i }),
            }
        } else {
            out.push(b[i]);
            i += 1;
        }
    }
    String::from_utf8(out).map_err(|source| UriError::NotUtf8 { uri: s.to_string(), source })
}

/// Lexical normalisation: removes `.` and folds `..` (no file-system access).
pub(crate) fn normalize(p: &Path) -> PathBuf {
    let mut out = PathBuf::new();
    for c in p.components() {
        match c {
            Component::CurDir => {}
            Component::ParentDir => {
                if !out.pop() {
                    out.push("..");
                }
            }
            c => out.push(c.as_os_str()),
        }
    }
    out
}

#[derive(Debug, PartialEq, Eq)]
enum Peek {
    Json,
    Binary,
}

/// Opens `file` and tells JSON (first non-blank byte `{`) from binary content.
fn peek(file: &Path) -> std::io::Result<Peek> {
    let mut f = std::fs::File::open(file)?;
    if !f.metadata()?.is_file() {
        return Err(std::io::Error::other("not a regular file"));
    }
    let mut head = [0u8; 64];
    let n = f.read(&mut head)?;
    let head = &head[..n];
    let head = head.strip_prefix(b"\xEF\xBB\xBF").unwrap_or(head);
    Ok(match head.iter().find(|b| !b.is_ascii_whitespace()) {
        Some(b'{') => Peek::Json,
        _ => Peek::Binary,
    })
}

/// A JSON content is an external tileset when it has a `root` (a glTF JSON has none).
fn is_tileset_json(file: &Path) -> bool {
    #[derive(Deserialize)]
    struct Probe {
        root: Option<serde_json::Value>,
        asset: Option<serde_json::Value>,
    }
    let Ok(bytes) = std::fs::read(file) else { return false };
    let json = bytes.strip_prefix(b"\xEF\xBB\xBF").unwrap_or(&bytes);
    // An unparsable JSON is handed to the tileset parser, which reports it properly.
    match serde_json::from_slice::<Probe>(json) {
        Ok(p) => p.root.is_some() || p.asset.is_none(),
        Err(_) => file.extension().is_some_and(|e| e.eq_ignore_ascii_case("json")),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn uris() {
        let d = Path::new("/t");
        assert_eq!(resolve_uri(d, "data/a%20b.b3dm?v=2#x").unwrap(), PathBuf::from("/t/data/a b.b3dm"));
        assert_eq!(resolve_uri(d, "x.glb#frag").unwrap(), PathBuf::from("/t/x.glb"));
        assert_eq!(resolve_uri(d, "%E6%B8%8B.glb").unwrap(), PathBuf::from("/t/渋.glb"));
        assert!(resolve_uri(d, "https://x/y.b3dm").is_err());
        assert!(resolve_uri(d, "data:application/octet-stream;base64,AAAA").is_err());
        assert!(resolve_uri(d, "a%2").is_err());
        assert!(resolve_uri(d, "a%ZZ").is_err());
    }

    #[test]
    fn normalisation() {
        assert_eq!(normalize(Path::new("a/./b/../c")), PathBuf::from("a/c"));
        assert_eq!(normalize(Path::new("../x")), PathBuf::from("../x"));
    }

    #[test]
    fn validation_lists_all_problems() {
        let t: TilesetJson = serde_json::from_str(
            r#"{"asset":{"version":"1.0"},"extensionsRequired":["3DTILES_content_gltf","VENDOR_x"],
                "root":{"refine":"MERGE","transform":[1,2,3],"boundingVolume":{"sphere":[0,0,0,1]},"geometricError":1,
                "children":[{"content":{},"boundingVolume":{"box":[1]},"geometricError":-1},
                            {"boundingVolume":{"region":[0,0,1,1,0,1]}}]}}"#,
        )
        .unwrap();
        let p = validate(&t);
        let at: Vec<&str> = p.iter().map(|i| i.at.as_str()).collect();
        assert_eq!(
            at,
            [
                "extensionsRequired[1]",
                "root.transform",
                "root.refine",
                "root.children[0].boundingVolume.box",
                "root.children[0].geometricError",
                "root.children[0].content",
                "root.children[1].geometricError"
            ]
        );
        assert_eq!(p[0].problem, TilesetProblem::RequiredExtension { extension: "VENDOR_x".into() });
        assert_eq!(p[1].problem, TilesetProblem::TransformLength { found: 3 });
        assert_eq!(p[2].problem, TilesetProblem::Refine { found: "MERGE".into() });
        assert_eq!(p[4].problem, TilesetProblem::GeometricError { value: -1.0 });
        assert_eq!(p[5].problem, TilesetProblem::NoUri);
        assert_eq!(p[6].problem, TilesetProblem::NoGeometricError);
    }

    #[test]
    fn region_sphere_contains_its_corners() {
        use crate::geo::{geodetic_to_ecef, Geodetic};
        let bv = BoundingVolume::Region {
            west_rad: 139.69f64.to_radians(),
            south_rad: 35.65f64.to_radians(),
            east_rad: 139.71f64.to_radians(),
            north_rad: 35.665f64.to_radians(),
            min_h_m: 20.0,
            max_h_m: 300.0,
        };
        let (c, r) = bv.world_sphere(&DMat4::IDENTITY);
        for lat in [35.65, 35.6575, 35.665] {
            for lon in [139.69, 139.70, 139.71] {
                for h in [20.0, 160.0, 300.0] {
                    let p = DVec3::from_array(geodetic_to_ecef(Geodetic::new(lat, lon, h)));
                    assert!(p.distance(c) <= r, "{lat} {lon} {h}: {} > {r}", p.distance(c));
                }
            }
        }
        // The region is ~1.8 km × 1.7 km × 280 m: the sphere must be tight (< 1.5 km radius).
        assert!(r < 1500.0, "{r}");
    }

    #[test]
    fn box_and_sphere_under_a_scaled_transform() {
        let m = DMat4::from_scale_rotation_translation(
            DVec3::splat(2.0),
            glam::DQuat::from_rotation_z(0.3),
            DVec3::new(10.0, 0.0, 0.0),
        );
        let b = BoundingVolume::Box {
            centre: DVec3::new(1.0, 0.0, 0.0),
            half_axes: DMat3::from_diagonal(DVec3::new(1.0, 2.0, 2.0)),
        };
        let (c, r) = b.world_sphere(&m);
        assert!((c - m.transform_point3(DVec3::X)).length() < 1e-12);
        assert!((r - 2.0 * 3.0).abs() < 1e-12, "{r}");
        let s = BoundingVolume::Sphere { centre: DVec3::ZERO, radius_m: 5.0 };
        assert!((s.world_sphere(&m).1 - 10.0).abs() < 1e-12);
    }
}
