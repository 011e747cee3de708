//! 3D Tiles 1.1 implicit tiling (`implicitTiling`, and its pre-1.1 form, the
//! `3DTILES_implicit_tiling` extension): a quadtree or octree described by availability bitstreams
//! in subtree files, expanded here into explicit [`Tile`]s.
//!
//! For a tile at level `L` with coordinates `(x, y[, z])`: the bounding volume is the root's box or
//! region cut into `2^L` parts along each subdivided axis (x, y; and z or height for octrees), the
//! geometric error is the root's divided by `2^L`, and content and subtree URIs are the templates
//! with `{level}`, `{x}`, `{y}`, `{z}` substituted. Availability bits are numbered in Morton order
//! within each level of a subtree, levels one after the other (`(N^l − 1)/(N − 1) + morton`, N = 4
//! or 8), least significant bit first in each byte; `constant` availabilities stand for all bits.
//! Subtree files are binary (`subt` magic, version 1, JSON and binary chunk lengths as u64) or JSON;
//! their buffers are the binary chunk (no `uri`) or files next to the subtree. Sphere and S2
//! (`3DTILES_bounding_volume_S2`) volumes cannot be subdivided this way and are refused.
//!
//! The whole tree is expanded when the tileset is loaded (at most
//! [`super::tileset::MAX_IMPLICIT_TILES`] tiles per tileset file), which suits the tilesets insgen
//! renders (a district); a city-wide implicit tileset would want lazy expansion.

use std::path::{Path, PathBuf};

use glam::{DMat3, DMat4, DVec3};
use serde::Deserialize;

use super::error::ContentError;
use super::tileset::{resolve_uri, uri_error, BoundingVolume, ContentRef, Refine, Tile, TileJson};
use crate::lod::error::{TilesetIssue, TilesetProblem};
use crate::lod::LodError;

/// `implicitTiling`.
#[derive(Debug, Clone, Deserialize)]
#[serde(rename_all = "camelCase")]
pub(crate) struct ImplicitTilingJson {
    /// `"QUADTREE"` or `"OCTREE"`.
    pub subdivision_scheme: String,
    /// Levels per subtree file (≥ 1).
    pub subtree_levels: u32,
    /// Levels of the whole tree (≥ 1); the draft extension's `maximumLevel` is `availableLevels − 1`.
    pub available_levels: Option<u32>,
    pub maximum_level: Option<u32>,
    /// `{"uri": template}` of the subtree files.
    pub subtrees: SubtreesJson,
}

#[derive(Debug, Clone, Deserialize)]
pub(crate) struct SubtreesJson {
    pub uri: String,
}

impl ImplicitTilingJson {
    fn levels(&self) -> u32 {
        self.available_levels.or(self.maximum_level.map(|m| m + 1)).unwrap_or(0)
    }
    fn octree(&self) -> bool {
        self.subdivision_scheme.eq_ignore_ascii_case("OCTREE")
    }
}

/// Checks an `implicitTiling` object and its tile (volume kind, no children, no transform rules).
pub(crate) fn validate(it: &ImplicitTilingJson, tile: &TileJson, at: &str, p: &mut Vec<TilesetIssue>) {
    let mut push = |at: String, problem| p.push(TilesetIssue { at, problem });
    if !matches!(it.subdivision_scheme.to_ascii_uppercase().as_str(), "QUADTREE" | "OCTREE") {
        push(
            format!("{at}.subdivisionScheme"),
            TilesetProblem::SubdivisionScheme { found: it.subdivision_scheme.clone() },
        );
    }
    if it.subtree_levels == 0 {
        push(format!("{at}.subtreeLevels"), TilesetProblem::SubtreeLevels);
    }
    if it.levels() == 0 {
        push(format!("{at}.availableLevels"), TilesetProblem::NoAvailableLevels);
    }
    if it.levels() > 31 {
        push(format!("{at}.availableLevels"), TilesetProblem::TooManyLevels { levels: it.levels() });
    }
    if let Some(bv) = &tile.bounding_volume {
        if bv.sphere.is_some() && bv.box_.is_none() && bv.region.is_none() {
            push(at.replace(".implicitTiling", ".boundingVolume"), TilesetProblem::ImplicitSphere);
        }
    }
    if !tile.children.is_empty() {
        push(at.replace(".implicitTiling", ".children"), TilesetProblem::ImplicitChildren);
    }
}

/// The implicit root tile as the tileset builder saw it.
pub(crate) struct Root<'a> {
    pub tileset: &'a Path,
    pub dir: &'a Path,
    pub at: &'a str,
    pub world_from_tile: DMat4,
    pub bounding_volume: BoundingVolume,
    pub geometric_error_m: f64,
    pub refine: Refine,
    /// (JSON path, URI template) of each content.
    pub content_templates: &'a [(String, String)],
}

/// Tile coordinates: level, x, y, z.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Coord {
    level: u32,
    x: u64,
    y: u64,
    z: u64,
}

impl Coord {
    fn child(self, c: u64) -> Coord {
        Coord {
            level: self.level + 1,
            x: 2 * self.x + (c & 1),
            y: 2 * self.y + ((c >> 1) & 1),
            z: 2 * self.z + ((c >> 2) & 1),
        }
    }
}

/// Morton index of local coordinates (x in bit 0, y in bit 1, z in bit 2 of each triple).
fn morton(x: u64, y: u64, z: u64, octree: bool) -> u64 {
    let mut m = 0u64;
    for b in 0..21 {
        if octree {
            m |= ((x >> b) & 1) << (3 * b) | ((y >> b) & 1) << (3 * b + 1) | ((z >> b) & 1) << (3 * b + 2);
        } else {
            m |= ((x >> b) & 1) << (2 * b) | ((y >> b) & 1) << (2 * b + 1);
        }
    }
    m
}

/// One availability: every bit the same, or a bitstream.
#[derive(Debug, Clone)]
enum Availability {
    Constant(bool),
    Bits(Vec<u8>),
}

impl Availability {
    fn get(&self, i: u64) -> bool {
        match self {
            Availability::Constant(c) => *c,
            Availability::Bits(b) => b.get((i / 8) as usize).is_some_and(|byte| (byte >> (i % 8)) & 1 == 1),
        }
    }
}

/// A loaded subtree.
#[derive(Debug)]
struct Subtree {
    tiles: Availability,
    contents: Vec<Availability>,
    child_subtrees: Availability,
}

#[derive(Debug, Deserialize)]
#[serde(rename_all = "camelCase")]
struct SubtreeJson {
    #[serde(default)]
    buffers: Vec<SubtreeBuffer>,
    #[serde(default)]
    buffer_views: Vec<SubtreeBufferView>,
    tile_availability: AvailabilityJson,
    #[serde(default)]
    content_availability: Option<OneOrMany>,
    child_subtree_availability: AvailabilityJson,
}

#[derive(Debug, Deserialize)]
#[serde(untagged)]
enum OneOrMany {
    Many(Vec<AvailabilityJson>),
    One(AvailabilityJson),
}

#[derive(Debug, Deserialize)]
#[serde(rename_all = "camelCase")]
struct SubtreeBuffer {
    uri: Option<String>,
    byte_length: usize,
}

#[derive(Debug, Deserialize)]
#[serde(rename_all = "camelCase")]
struct SubtreeBufferView {
    buffer: usize,
    #[serde(default)]
    byte_offset: usize,
    byte_length: usize,
}

#[derive(Debug, Deserialize)]
#[serde(rename_all = "camelCase")]
struct AvailabilityJson {
    /// Index of the bufferView holding the bits (`bufferView` in the draft extension).
    #[serde(alias = "bufferView")]
    bitstream: Option<usize>,
    constant: Option<u8>,
}

/// Parses a subtree file (binary or JSON); `file` locates its external buffers.
///
/// # Errors
/// [`ContentError`] naming the header field, chunk, buffer or availability that is wrong.
fn parse_subtree(bytes: &[u8], file: &Path) -> Result<Subtree, ContentError> {
    let (json, bin): (&[u8], &[u8]) = if bytes.starts_with(b"subt") {
        if bytes.len() < 24 {
            return Err(ContentError::TooShort { what: "subtree header", length: bytes.len(), needed: 24 });
        }
        let u32_at = |i: usize| u32::from_le_bytes(bytes[i..i + 4].try_into().expect("4 bytes"));
        let u64_at = |i: usize| u64::from_le_bytes(bytes[i..i + 8].try_into().expect("8 bytes"));
        let version = u32_at(4);
        if version != 1 {
            return Err(ContentError::Version { container: "subtree", version });
        }
        let (jl, bl) = (u64_at(8), u64_at(16));
        let past_end = |name, len| ContentError::SubtreeChunk { name, len, length: bytes.len() };
        let end_json = 24u64
            .checked_add(jl)
            .filter(|&e| e <= bytes.len() as u64)
            .ok_or_else(|| past_end("jsonByteLength", jl))? as usize;
        let end_bin = (end_json as u64)
            .checked_add(bl)
            .filter(|&e| e <= bytes.len() as u64)
            .ok_or_else(|| past_end("binaryByteLength", bl))? as usize;
        (&bytes[24..end_json], &bytes[end_json..end_bin])
    } else {
        (bytes, &[])
    };
    let end = json.iter().rposition(|&b| b != 0 && b != b' ').map_or(0, |i| i + 1);
    let st: SubtreeJson = serde_json::from_slice(&json[..end])
        .map_err(|source| ContentError::Json { at: "subtree JSON".into(), source })?;
    let dir = file.parent().unwrap_or(Path::new("."));
    let mut buffers: Vec<Vec<u8>> = Vec::with_capacity(st.buffers.len());
    for (i, b) in st.buffers.iter().enumerate() {
        let data = match &b.uri {
            None => bin.to_vec(),
            Some(uri) => {
                let p =
                    resolve_uri(dir, uri).map_err(|e| ContentError::from(e).at(format!("buffers[{i}]")))?;
                std::fs::read(&p).map_err(|source| {
                    ContentError::ReadUri { uri: uri.clone(), path: p, source }.at(format!("buffers[{i}]"))
                })?
            }
        };
        if data.len() < b.byte_length {
            return Err(ContentError::BufferLength {
                index: i,
                byte_length: b.byte_length,
                available: data.len(),
            });
        }
        buffers.push(data);
    }
    let avail = |a: &AvailabilityJson, at: &str| -> Result<Availability, ContentError> {
        match (a.bitstream, a.constant) {
            (Some(v), _) => {
                let view = st.buffer_views.get(v).ok_or_else(|| {
                    ContentError::Missing { what: "bufferView", index: v }.at(format!("{at}.bitstream"))
                })?;
                let buf = buffers.get(view.buffer).ok_or_else(|| {
                    ContentError::Missing { what: "buffer", index: view.buffer }
                        .at(format!("bufferViews[{v}].buffer"))
                })?;
                let bytes = view
                    .byte_offset
                    .checked_add(view.byte_length)
                    .and_then(|e| buf.get(view.byte_offset..e))
                    .ok_or(ContentError::ViewRange { view: v, buffer: view.buffer })?;
                Ok(Availability::Bits(bytes.to_vec()))
            }
            (None, Some(c)) if c <= 1 => Ok(Availability::Constant(c == 1)),
            (None, Some(value)) => Err(ContentError::AvailabilityConstant { at: at.to_string(), value }),
            (None, None) => Err(ContentError::NoAvailability { at: at.to_string() }),
        }
    };
    let tiles = avail(&st.tile_availability, "tileAvailability")?;
    let contents = match &st.content_availability {
        None => vec![],
        Some(OneOrMany::One(a)) => vec![avail(a, "contentAvailability")?],
        Some(OneOrMany::Many(v)) => v
            .iter()
            .enumerate()
            .map(|(i, a)| avail(a, &format!("contentAvailability[{i}]")))
            .collect::<Result<_, _>>()?,
    };
    let child_subtrees = avail(&st.child_subtree_availability, "childSubtreeAvailability")?;
    Ok(Subtree { tiles, contents, child_subtrees })
}

fn substitute(template: &str, c: Coord) -> String {
    template
        .replace("{level}", &c.level.to_string())
        .replace("{x}", &c.x.to_string())
        .replace("{y}", &c.y.to_string())
        .replace("{z}", &c.z.to_string())
}

struct Expander<'a> {
    root: &'a Root<'a>,
    it: &'a ImplicitTilingJson,
    octree: bool,
    levels: u32,
    budget: &'a mut usize,
}

/// Expands an implicit root into explicit tiles.
///
/// # Errors
/// A subtree file that is missing or malformed (named, with the tile it belongs to), or more tiles
/// than [`super::tileset::MAX_IMPLICIT_TILES`].
pub(crate) fn expand(root: &Root<'_>, it: &ImplicitTilingJson, budget: &mut usize) -> Result<Tile, LodError> {
    let octree = it.octree();
    let levels = it.levels();
    let mut e = Expander { root, it, octree, levels, budget };
    let c0 = Coord { level: 0, x: 0, y: 0, z: 0 };
    let st = e.load_subtree(c0)?;
    if !st.tiles.get(0) {
        return Err(LodError::invalid(root.tileset, root.at, TilesetProblem::RootUnavailable));
    }
    e.tile(&st, c0, 0, (0, 0, 0))
}

impl Expander<'_> {
    fn load_subtree(&self, c: Coord) -> Result<Subtree, LodError> {
        let uri = substitute(&self.it.subtrees.uri, c);
        let at = format!(
            "{}.implicitTiling.subtrees {{level {}, x {}, y {}, z {}}}",
            self.root.at, c.level, c.x, c.y, c.z
        );
        let file = resolve_uri(self.root.dir, &uri).map_err(|e| uri_error(self.root.tileset, &at, e))?;
        let bytes = crate::util::read_file(&file)?;
        parse_subtree(&bytes, &file).map_err(|e| LodError::Subtree {
            tileset: self.root.tileset.to_path_buf(),
            at,
            subtree: file,
            source: Box::new(e),
        })
    }

    fn volume(&self, c: Coord) -> BoundingVolume {
        let n = (1u64 << c.level) as f64;
        // Fraction of the root's extent where this tile starts and ends along each axis.
        let span = |i: u64| (i as f64 / n, (i + 1) as f64 / n);
        match self.root.bounding_volume {
            BoundingVolume::Box { centre, half_axes } => {
                let (x0, x1) = span(c.x);
                let (y0, y1) = span(c.y);
                let (z0, z1) = if self.octree { span(c.z) } else { (0.0, 1.0) };
                // Root box spans −1..1 along each half-axis; the tile spans 2t − 1 for t in [t0, t1].
                let mid = |a: f64, b: f64| a + b - 1.0;
                let local = DVec3::new(mid(x0, x1), mid(y0, y1), mid(z0, z1));
                let scale = DVec3::new(x1 - x0, y1 - y0, z1 - z0);
                BoundingVolume::Box {
                    centre: centre + half_axes * local,
                    half_axes: DMat3::from_cols(
                        half_axes.x_axis * scale.x,
                        half_axes.y_axis * scale.y,
                        half_axes.z_axis * scale.z,
                    ),
                }
            }
            BoundingVolume::Region { west_rad, south_rad, east_rad, north_rad, min_h_m, max_h_m } => {
                let east = if east_rad < west_rad { east_rad + std::f64::consts::TAU } else { east_rad };
                let lerp = |a: f64, b: f64, t: f64| a + (b - a) * t;
                let (x0, x1) = span(c.x);
                let (y0, y1) = span(c.y);
                let (z0, z1) = if self.octree { span(c.z) } else { (0.0, 1.0) };
                let wrap = |v: f64| if v > std::f64::consts::PI { v - std::f64::consts::TAU } else { v };
                BoundingVolume::Region {
                    west_rad: wrap(lerp(west_rad, east, x0)),
                    east_rad: wrap(lerp(west_rad, east, x1)),
                    south_rad: lerp(south_rad, north_rad, y0),
                    north_rad: lerp(south_rad, north_rad, y1),
                    min_h_m: lerp(min_h_m, max_h_m, z0),
                    max_h_m: lerp(min_h_m, max_h_m, z1),
                }
            }
            // `validate` refuses spheres on implicit roots.
            sphere @ BoundingVolume::Sphere { .. } => sphere,
        }
    }

    /// Builds the tile at global `c`, local level `l` and local coordinates `lc` of subtree `st`.
    fn tile(&mut self, st: &Subtree, c: Coord, l: u32, lc: (u64, u64, u64)) -> Result<Tile, LodError> {
        if *self.budget == 0 {
            return Err(LodError::invalid(
                self.root.tileset,
                self.root.at,
                TilesetProblem::TooManyTiles { max: super::tileset::MAX_IMPLICIT_TILES },
            ));
        }
        *self.budget -= 1;
        let n: u64 = if self.octree { 8 } else { 4 };
        let level_offset = |l: u32| (n.pow(l) - 1) / (n - 1);
        let index = level_offset(l) + morton(lc.0, lc.1, lc.2, self.octree);
        let at = format!(
            "{}{{level {}, x {}, y {}{}}}",
            self.root.at,
            c.level,
            c.x,
            c.y,
            if self.octree { format!(", z {}", c.z) } else { String::new() }
        );
        let mut contents = Vec::new();
        for (k, (c_at, template)) in self.root.content_templates.iter().enumerate() {
            // A subtree without contentAvailability has no content (the spec requires the array when
            // the tile has content; an absent one is read as "none available").
            if st.contents.get(k).is_some_and(|a| a.get(index)) {
                let uri = substitute(template, c);
                let file =
                    resolve_uri(self.root.dir, &uri).map_err(|e| uri_error(self.root.tileset, c_at, e))?;
                contents.push(ContentRef {
                    uri,
                    file,
                    tileset: self.root.tileset.to_path_buf(),
                    at: format!("{at}.{}", c_at.rsplit('.').next().unwrap_or("content")),
                });
            }
        }
        let mut children = Vec::new();
        if c.level + 1 < self.levels {
            for k in 0..n {
                let child = c.child(k);
                let clc = (2 * lc.0 + (k & 1), 2 * lc.1 + ((k >> 1) & 1), 2 * lc.2 + ((k >> 2) & 1));
                if l + 1 < self.it.subtree_levels {
                    let ci = level_offset(l + 1) + morton(clc.0, clc.1, clc.2, self.octree);
                    if st.tiles.get(ci) {
                        children.push(self.tile(st, child, l + 1, clc)?);
                    }
                } else if st.child_subtrees.get(morton(clc.0, clc.1, clc.2, self.octree)) {
                    let sub = self.load_subtree(child)?;
                    if sub.tiles.get(0) {
                        children.push(self.tile(&sub, child, 0, (0, 0, 0))?);
                    }
                }
            }
        }
        Ok(Tile {
            at,
            world_from_tile: self.root.world_from_tile,
            bounding_volume: self.volume(c),
            geometric_error_m: self.root.geometric_error_m / (1u64 << c.level) as f64,
            refine: self.root.refine,
            contents,
            children,
        })
    }
}

/// Subtree file bytes (binary form) from its JSON and binary chunk, padded to 8 bytes as the spec asks.
pub(crate) fn subtree_bytes(json: &serde_json::Value, bin: &[u8]) -> Vec<u8> {
    let mut j = serde_json::to_vec(json).expect("a JSON value serialises");
    while !j.len().is_multiple_of(8) {
        j.push(b' ');
    }
    let mut b = bin.to_vec();
    while !b.len().is_multiple_of(8) {
        b.push(0);
    }
    let mut out = b"subt".to_vec();
    out.extend_from_slice(&1u32.to_le_bytes());
    out.extend_from_slice(&(j.len() as u64).to_le_bytes());
    out.extend_from_slice(&(b.len() as u64).to_le_bytes());
    out.extend_from_slice(&j);
    out.extend_from_slice(&b);
    out
}

/// Where implicit tile files go, for writers: `template` with the coordinates substituted.
pub(crate) fn template_path(dir: &Path, template: &str, level: u32, x: u64, y: u64, z: u64) -> PathBuf {
    dir.join(substitute(template, Coord { level, x, y, z }))
}

/// Morton index of quadtree/octree coordinates, for writers.
pub(crate) fn morton_index(x: u64, y: u64, z: u64, octree: bool) -> u64 {
    morton(x, y, z, octree)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn morton_order() {
        assert_eq!(morton(0, 0, 0, false), 0);
        assert_eq!(morton(1, 0, 0, false), 1);
        assert_eq!(morton(0, 1, 0, false), 2);
        assert_eq!(morton(3, 3, 0, false), 15);
        assert_eq!(morton(2, 1, 0, false), 6);
        assert_eq!(morton(1, 1, 1, true), 7);
        assert_eq!(morton(2, 0, 0, true), 8);
    }

    #[test]
    fn bits_are_lsb_first() {
        let a = Availability::Bits(vec![0b0000_0101, 0b1000_0000]);
        let on: Vec<u64> = (0..16).filter(|&i| a.get(i)).collect();
        assert_eq!(on, vec![0, 2, 15]);
        assert!(!a.get(1000));
    }

    #[test]
    fn binary_subtree_round_trip_and_truncation() {
        let json = serde_json::json!({
            "buffers": [{"byteLength": 2}],
            "bufferViews": [{"buffer": 0, "byteOffset": 0, "byteLength": 1}, {"buffer": 0, "byteOffset": 1, "byteLength": 1}],
            "tileAvailability": {"bitstream": 0},
            "contentAvailability": [{"bitstream": 1}],
            "childSubtreeAvailability": {"constant": 0}
        });
        let b = subtree_bytes(&json, &[0b11, 0b10]);
        let st = parse_subtree(&b, Path::new("x.subtree")).unwrap();
        assert!(st.tiles.get(0) && st.tiles.get(1) && !st.tiles.get(2));
        assert!(!st.contents[0].get(0) && st.contents[0].get(1));
        assert!(!st.child_subtrees.get(3));
        let e = parse_subtree(&b[..30], Path::new("x.subtree")).unwrap_err();
        assert!(matches!(e, ContentError::SubtreeChunk { name: "jsonByteLength", length: 30, .. }), "{e:?}");
        assert!(e.to_string().contains("runs past the end"), "{e}");
        let e = parse_subtree(b"subt\x01\x00", Path::new("x")).unwrap_err();
        assert!(matches!(e, ContentError::TooShort { length: 6, needed: 24, .. }), "{e:?}");
        assert!(e.to_string().contains("too short"), "{e}");
    }
}
