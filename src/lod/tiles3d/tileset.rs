//! `tileset.json` (3D Tiles 1.0 and 1.1): validation and the traversal that lists the contents to read.
//!
//! # Which contents are read
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
//! not used: nothing is culled.
//!
//! Transforms (`transform`, column-major 4×4) accumulate from the root down in f64. Content URIs
//! (`content.uri`, 1.0's `content.url`, 1.1's `contents[]`) are relative to the JSON that names them,
//! percent-decoded (`%20` → space), without query or fragment; remote (`http://…`) and `data:` URIs
//! are rejected. A missing content file fails the whole read, naming the tileset and the URI.

use std::io::Read;
use std::path::{Component, Path, PathBuf};

use glam::DMat4;
use serde::Deserialize;

use super::gltf::UpAxis;
use crate::lod::LodError;

/// The tileset JSON root.
#[derive(Debug, Deserialize)]
#[serde(rename_all = "camelCase")]
struct TilesetJson {
    asset: AssetJson,
    root: TileJson,
}

/// `asset`: the 3D Tiles version and, for pre-1.0 Cesium tilesets, the glTF up axis.
#[derive(Debug, Deserialize)]
#[serde(rename_all = "camelCase")]
struct AssetJson {
    version: String,
    /// `"X"`, `"Y"` (default) or `"Z"`: CesiumJS's pre-1.0 `asset.gltfUpAxis`.
    gltf_up_axis: Option<String>,
}

/// A tile: transform, refinement, content(s) and children.
#[derive(Debug, Deserialize)]
#[serde(rename_all = "camelCase")]
struct TileJson {
    /// Column-major 4×4 from this tile's frame to its parent's.
    transform: Option<Vec<f64>>,
    /// `"ADD"` or `"REPLACE"`; inherited from the parent when absent.
    refine: Option<String>,
    content: Option<ContentJson>,
    /// 3D Tiles 1.1: several contents per tile.
    contents: Option<Vec<ContentJson>>,
    #[serde(default)]
    children: Vec<TileJson>,
    /// 3D Tiles 1.1 implicit tiling (not supported).
    implicit_tiling: Option<serde_json::Value>,
}

/// `content`: `uri` (1.0 final, 1.1) or `url` (1.0 drafts).
#[derive(Debug, Deserialize)]
struct ContentJson {
    uri: Option<String>,
    url: Option<String>,
}

impl ContentJson {
    fn uri(&self) -> Option<&str> {
        self.uri.as_deref().or(self.url.as_deref())
    }
}

/// One content to decode.
#[derive(Debug, Clone)]
pub(crate) struct ContentJob {
    /// The content file.
    pub file: PathBuf,
    /// The file relative to the root tileset's folder (`/`-separated): names it in synthesized ids.
    pub label: String,
    /// Where it is referenced: `"<tileset.json>: root.children[3].content"`.
    pub at: String,
    /// Tile frame → tileset (ECEF) frame.
    pub world_from_tile: DMat4,
    pub up: UpAxis,
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

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Refine {
    Add,
    Replace,
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
            format!(
                "external tilesets form a cycle: {}",
                stack
                    .iter()
                    .chain([&canonical])
                    .map(|p| p.display().to_string())
                    .collect::<Vec<_>>()
                    .join(" → ")
            ),
        ));
    }
    let bytes = crate::util::read_file(path)?;
    let json = bytes.strip_prefix(b"\xEF\xBB\xBF").unwrap_or(&bytes);
    let tileset: TilesetJson = serde_json::from_slice(json)
        .map_err(|e| LodError::malformed(path, format!("not a valid 3D Tiles tileset JSON: {e}")))?;
    let problems = validate(&tileset);
    if let Some((at, what)) = problems.first() {
        let more = if problems.len() > 1 {
            format!(
                " (and {} more: {})",
                problems.len() - 1,
                problems[1..].iter().map(|(a, w)| format!("{a}: {w}")).collect::<Vec<_>>().join("; ")
            )
        } else {
            String::new()
        };
        return Err(LodError::invalid(path, at.clone(), format!("{what}{more}")));
    }
    let up = match tileset.asset.gltf_up_axis.as_deref().map(str::to_ascii_uppercase).as_deref() {
        Some("X") => UpAxis::X,
        Some("Z") => UpAxis::Z,
        _ => UpAxis::Y,
    };
    out.tilesets_read += 1;
    stack.push(canonical);
    let dir = path.parent().unwrap_or(Path::new("")).to_path_buf();
    let ctx = Ctx { tileset: path, dir: &dir, root_dir, up };
    let r = walk_tile(&tileset.root, "root", world_from_parent, Refine::Replace, &ctx, stack, out);
    stack.pop();
    r
}

struct Ctx<'a> {
    tileset: &'a Path,
    dir: &'a Path,
    root_dir: &'a Path,
    up: UpAxis,
}

fn walk_tile(
    tile: &TileJson,
    at: &str,
    world_from_parent: DMat4,
    inherited: Refine,
    ctx: &Ctx<'_>,
    stack: &mut Vec<PathBuf>,
    out: &mut Traversal,
) -> Result<(), LodError> {
    let world = match &tile.transform {
        // Length 16 was checked by `validate`.
        Some(m) => world_from_parent * DMat4::from_cols_slice(m),
        None => world_from_parent,
    };
    let refine = match tile.refine.as_deref().map(str::to_ascii_uppercase).as_deref() {
        Some("ADD") => Refine::Add,
        Some("REPLACE") => Refine::Replace,
        _ => inherited,
    };
    let contents: Vec<(String, &ContentJson)> = match (&tile.content, &tile.contents) {
        (Some(c), _) => vec![(format!("{at}.content"), c)],
        (None, Some(cs)) => cs.iter().enumerate().map(|(i, c)| (format!("{at}.contents[{i}]"), c)).collect(),
        (None, None) => vec![],
    };
    let read_contents = tile.children.is_empty() || refine == Refine::Add;
    if !read_contents {
        out.contents_skipped += contents.len() as u64;
    }
    for (c_at, c) in contents.iter().filter(|_| read_contents) {
        // `validate` ensured a URI is present.
        let uri = c.uri().unwrap_or_default();
        let file = resolve_uri(ctx.dir, uri).map_err(|e| LodError::invalid(ctx.tileset, c_at.clone(), e))?;
        let head = peek(&file).map_err(|e| {
            LodError::invalid(
                ctx.tileset,
                format!("{c_at}.uri {uri:?}"),
                format!("tile content {} cannot be read: {e}", file.display()),
            )
        })?;
        if head == Peek::Json && is_tileset_json(&file) {
            walk_tileset(&file, world, ctx.root_dir, stack, out)?;
        } else {
            let norm = normalize(&file);
            let label = match norm.strip_prefix(ctx.root_dir) {
                Ok(rel) => {
                    rel.components().map(|c| c.as_os_str().to_string_lossy()).collect::<Vec<_>>().join("/")
                }
                Err(_) => norm.display().to_string(),
            };
            out.jobs.push(ContentJob {
                file,
                label,
                at: format!("{}: {c_at}", ctx.tileset.display()),
                world_from_tile: world,
                up: ctx.up,
            });
        }
    }
    for (i, child) in tile.children.iter().enumerate() {
        walk_tile(child, &format!("{at}.children[{i}]"), world, refine, ctx, stack, out)?;
    }
    Ok(())
}

/// Every problem of a tileset, as (JSON path, what is wrong).
fn validate(t: &TilesetJson) -> Vec<(String, String)> {
    let mut p = Vec::new();
    if !matches!(t.asset.version.as_str(), "0.0" | "1.0" | "1.1") {
        log::warn!("3D Tiles asset.version {:?} is not 0.0, 1.0 or 1.1; reading it as 1.1", t.asset.version);
    }
    if let Some(axis) = &t.asset.gltf_up_axis {
        if !matches!(axis.to_ascii_uppercase().as_str(), "X" | "Y" | "Z") {
            p.push(("asset.gltfUpAxis".to_string(), format!("{axis:?} is not X, Y or Z")));
        }
    }
    validate_tile(&t.root, "root", &mut p);
    p
}

fn validate_tile(tile: &TileJson, at: &str, p: &mut Vec<(String, String)>) {
    if let Some(m) = &tile.transform {
        if m.len() != 16 {
            p.push((format!("{at}.transform"), format!("has {} numbers, not 16", m.len())));
        } else if m.iter().any(|v| !v.is_finite()) {
            p.push((format!("{at}.transform"), "has non-finite numbers".into()));
        }
    }
    if let Some(r) = &tile.refine {
        if !matches!(r.to_ascii_uppercase().as_str(), "ADD" | "REPLACE") {
            p.push((format!("{at}.refine"), format!("{r:?} is not ADD or REPLACE")));
        }
    }
    if tile.content.is_some() && tile.contents.is_some() {
        p.push((at.to_string(), "has both content and contents".into()));
    }
    if let Some(c) = &tile.content {
        if c.uri().is_none() {
            p.push((format!("{at}.content"), "has no uri".into()));
        }
    }
    for (i, c) in tile.contents.iter().flatten().enumerate() {
        if c.uri().is_none() {
            p.push((format!("{at}.contents[{i}]"), "has no uri".into()));
        }
    }
    if tile.implicit_tiling.is_some() {
        p.push((
            format!("{at}.implicitTiling"),
            "implicit tiling (3D Tiles 1.1) is not supported; convert the tileset to explicit tiles, e.g. \
             with `npx 3d-tiles-tools`"
                .into(),
        ));
    }
    for (i, c) in tile.children.iter().enumerate() {
        validate_tile(c, &format!("{at}.children[{i}]"), p);
    }
}

/// Resolves a content/buffer URI against `dir`: query and fragment dropped, percent-decoded; remote
/// and `data:` URIs refused.
///
/// # Errors
/// A message for remote URIs and invalid percent-encoding.
pub(crate) fn resolve_uri(dir: &Path, uri: &str) -> Result<PathBuf, String> {
    let lower = uri.to_ascii_lowercase();
    if lower.contains("://") || lower.starts_with("data:") {
        return Err(format!(
            "URI {uri:?} is not a relative file path; only local tilesets are read (download it first)"
        ));
    }
    let bare = uri.split(['?', '#']).next().unwrap_or("");
    if bare.is_empty() {
        return Err(format!("URI {uri:?} names no file"));
    }
    Ok(dir.join(percent_decode(bare)?))
}

/// `%XX` → byte, the result read as UTF-8.
fn percent_decode(s: &str) -> Result<String, String> {
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
                None => return Err(format!("URI {s:?} has an invalid %-escape at byte {i}")),
            }
        } else {
            out.push(b[i]);
            i += 1;
        }
    }
    String::from_utf8(out).map_err(|_| format!("URI {s:?} does not decode to UTF-8"))
}

/// Lexical normalisation: removes `.` and folds `..` (no file-system access).
fn normalize(p: &Path) -> PathBuf {
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
            r#"{"asset":{"version":"1.0"},"root":{"refine":"MERGE","transform":[1,2,3],
                "children":[{"content":{}},{"implicitTiling":{}}]}}"#,
        )
        .unwrap();
        let p = validate(&t);
        let at: Vec<&str> = p.iter().map(|(a, _)| a.as_str()).collect();
        assert_eq!(
            at,
            ["root.transform", "root.refine", "root.children[0].content", "root.children[1].implicitTiling"]
        );
    }
}
