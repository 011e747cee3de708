//! Photogrammetry tilesets for RGB: pick the tiles the cameras see, unwrap them to GLB, and place them in
//! the area's ENU frame.
//!
//! Input is a 3D Tiles 1.0/1.1 tileset (`tileset.json`, external tilesets followed) whose content is
//! b3dm, glb or glTF. For each frame the tree is traversed as a 3D Tiles renderer would: a tile is kept
//! when its bounding volume intersects the camera frustum, and refined into its children while its
//! screen-space error `geometricError · fy / distance` exceeds a threshold (REPLACE drops the parent's
//! content, ADD keeps it). The union over a batch of frames becomes the job's model list, and each frame
//! lists the tiles it shows.
//!
//! Placement (3D Tiles spec, "glTF transforms" and b3dm `RTC_CENTER`; CesiumJS applies the same order):
//! `ECEF = tile transform · translate(RTC_CENTER or CESIUM_RTC.center) · Y2Z · glTF`, where Y2Z turns
//! glTF's y-up into z-up, (x, y, z) → (x, −z, y) (identity when the tileset says `gltfUpAxis: "Z"`).
//! Hence `ENU_from_glTF = ENU_from_ECEF · tile transform · translate(rtc) · Y2Z`, computed in f64; the
//! translation of the result is small (the tile's position relative to the area origin), so Blender's
//! float32 matrices lose nothing.
//!
//! Unwrapping: a b3dm's embedded GLB is cut out of the b3dm container (legacy headers included); the
//! GLB's JSON loses the `CESIUM_RTC` extension (Blender's importer refuses unknown required extensions;
//! the centre goes into the matrix instead) and relative URIs are made absolute so the cached copy still
//! finds external images and buffers.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use serde::Deserialize;
use serde_json::Value;

use super::camera::Mat4;
use super::error::BlenderError;
use super::job::{JobModel, ModelKind};
use crate::camera::{Intrinsics, Pose};
use crate::geo::{geodetic_to_ecef, EnuFrame, Geodetic};

/// glTF y-up to z-up, (x, y, z) → (x, −z, y): the 3D Tiles convention and Blender's importer conversion.
pub const Y_UP_TO_Z_UP: Mat4 =
    [[1.0, 0.0, 0.0, 0.0], [0.0, 0.0, -1.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0]];

/// ENU-from-glTF of the prepared `scene.glb`, whose glTF (x, y, z) = ENU (e, u, −n).
pub const ENU_FROM_SCENE_GLTF: Mat4 = Y_UP_TO_Z_UP;

/// Mean Earth radius used to pad sampled region bounds for curvature, metres (IUGG mean radius R1).
const EARTH_MEAN_RADIUS_M: f64 = 6_371_008.8;

// ------------------------------------------------------------------------------------------ 4×4 maths

/// Product of two row-major 4×4 matrices.
pub fn mat4_mul(a: &Mat4, b: &Mat4) -> Mat4 {
    let mut c = [[0.0; 4]; 4];
    for i in 0..4 {
        for j in 0..4 {
            c[i][j] = (0..4).map(|k| a[i][k] * b[k][j]).sum();
        }
    }
    c
}

/// Applies a row-major affine 4×4 matrix to a point.
pub fn mat4_point(m: &Mat4, p: [f64; 3]) -> [f64; 3] {
    let mut out = [0.0; 3];
    for (i, o) in out.iter_mut().enumerate() {
        *o = m[i][0] * p[0] + m[i][1] * p[1] + m[i][2] * p[2] + m[i][3];
    }
    out
}

/// Inverse of an affine 4×4 matrix (last row 0 0 0 1), or `None` when its linear part is singular.
pub fn mat4_inverse_affine(m: &Mat4) -> Option<Mat4> {
    let a = |i: usize, j: usize| m[i][j];
    let det = a(0, 0) * (a(1, 1) * a(2, 2) - a(1, 2) * a(2, 1))
        - a(0, 1) * (a(1, 0) * a(2, 2) - a(1, 2) * a(2, 0))
        + a(0, 2) * (a(1, 0) * a(2, 1) - a(1, 1) * a(2, 0));
    if det.abs() < 1e-300 || !det.is_finite() {
        return None;
    }
    let mut inv = IDENTITY;
    for i in 0..3 {
        for j in 0..3 {
            // Adjugate: cofactor of (j, i).
            let (r0, r1) = match j {
                0 => (1, 2),
                1 => (0, 2),
                _ => (0, 1),
            };
            let (c0, c1) = match i {
                0 => (1, 2),
                1 => (0, 2),
                _ => (0, 1),
            };
            let minor = a(r0, c0) * a(r1, c1) - a(r0, c1) * a(r1, c0);
            let sign = if (i + j) % 2 == 0 { 1.0 } else { -1.0 };
            inv[i][j] = sign * minor / det;
        }
    }
    for i in 0..3 {
        inv[i][3] = -(0..3).map(|k| inv[i][k] * m[k][3]).sum::<f64>();
    }
    Some(inv)
}

fn translation(t: [f64; 3]) -> Mat4 {
    [[1.0, 0.0, 0.0, t[0]], [0.0, 1.0, 0.0, t[1]], [0.0, 0.0, 1.0, t[2]], [0.0, 0.0, 0.0, 1.0]]
}

const IDENTITY: Mat4 =
    [[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 1.0]];

/// ENU-from-ECEF of an area frame (the inverse of the rigid ECEF-from-ENU).
pub fn enu_from_ecef(enu: &EnuFrame) -> Mat4 {
    let m = crate::util::row_major::rows(&enu.ecef_from_enu());
    let mut inv = IDENTITY;
    for i in 0..3 {
        for j in 0..3 {
            inv[i][j] = m[j][i];
        }
        inv[i][3] = -(0..3).map(|k| m[k][i] * m[k][3]).sum::<f64>();
    }
    inv
}

fn dist(a: [f64; 3], b: [f64; 3]) -> f64 {
    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
}

// ------------------------------------------------------------------------------------------ spec types

#[derive(Debug, Deserialize)]
struct TilesetJson {
    asset: AssetJson,
    root: TileJson,
}

#[derive(Debug, Deserialize)]
struct AssetJson {
    version: String,
    #[serde(rename = "gltfUpAxis", default)]
    gltf_up_axis: Option<String>,
}

#[derive(Debug, Deserialize)]
struct TileJson {
    #[serde(rename = "boundingVolume")]
    bounding_volume: BoundingVolumeJson,
    #[serde(rename = "geometricError")]
    geometric_error: f64,
    #[serde(default)]
    refine: Option<String>,
    /// Column-major 4×4, as the spec stores it.
    #[serde(default)]
    transform: Option<Vec<f64>>,
    #[serde(default)]
    content: Option<ContentJson>,
    #[serde(default)]
    contents: Vec<ContentJson>,
    #[serde(default)]
    children: Vec<TileJson>,
}

#[derive(Debug, Deserialize)]
struct BoundingVolumeJson {
    #[serde(rename = "box", default)]
    box_: Option<Vec<f64>>,
    #[serde(default)]
    region: Option<Vec<f64>>,
    #[serde(default)]
    sphere: Option<Vec<f64>>,
}

#[derive(Debug, Deserialize)]
struct ContentJson {
    #[serde(default)]
    uri: Option<String>,
    /// 3D Tiles 0.0 / early 1.0 name of `uri`.
    #[serde(default)]
    url: Option<String>,
}

/// Up axis of the glTF content.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub enum UpAxis {
    Y,
    Z,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Refine {
    Add,
    Replace,
}

/// A validated tile in the area's ENU frame.
#[derive(Debug)]
struct Tile {
    /// ECEF-from-tile (the product of the transforms from the root down), row-major.
    ecef_from_tile: Mat4,
    /// Bounding sphere in ENU metres.
    centre_enu_m: [f64; 3],
    radius_m: f64,
    geometric_error_m: f64,
    refine: Refine,
    contents: Vec<PathBuf>,
    children: Vec<Tile>,
}

/// A tileset loaded and converted to bounding spheres in the area's ENU frame.
#[derive(Debug)]
struct LoadedTileset {
    up_axis: UpAxis,
    root: Tile,
}

fn col_major_to_rows(v: &[f64]) -> Mat4 {
    let mut m = [[0.0; 4]; 4];
    for (j, col) in v.chunks_exact(4).enumerate() {
        for i in 0..4 {
            m[i][j] = col[i];
        }
    }
    m
}

/// Bounding sphere (centre, radius) in ENU of a 3D Tiles bounding volume.
fn bounding_sphere_enu(
    bv: &BoundingVolumeJson,
    ecef_from_tile: &Mat4,
    enu: &EnuFrame,
    enu_ecef: &Mat4,
) -> Option<([f64; 3], f64)> {
    let enu_from_tile = mat4_mul(enu_ecef, ecef_from_tile);
    if let Some(b) = &bv.box_ {
        let c = [b[0], b[1], b[2]];
        let axes = [[b[3], b[4], b[5]], [b[6], b[7], b[8]], [b[9], b[10], b[11]]];
        let centre = mat4_point(&enu_from_tile, c);
        let mut r: f64 = 0.0;
        for sx in [-1.0, 1.0] {
            for sy in [-1.0, 1.0] {
                for sz in [-1.0, 1.0] {
                    let p = [0, 1, 2].map(|k| c[k] + sx * axes[0][k] + sy * axes[1][k] + sz * axes[2][k]);
                    r = r.max(dist(mat4_point(&enu_from_tile, p), centre));
                }
            }
        }
        return Some((centre, r));
    }
    if let Some(rg) = &bv.region {
        // Regions are geodetic (EPSG:4979, radians) and ignore tile transforms. Sample a 9×9 grid at
        // both heights, then pad by the sagitta of one grid step so the curved surface stays inside.
        let (w, s, e, n, h0, h1) = (rg[0], rg[1], rg[2], rg[3], rg[4], rg[5]);
        let east = if e < w { e + 2.0 * std::f64::consts::PI } else { e };
        const STEPS: usize = 8;
        let mut pts = Vec::with_capacity(2 * (STEPS + 1) * (STEPS + 1));
        for i in 0..=STEPS {
            for j in 0..=STEPS {
                let lon = w + (east - w) * i as f64 / STEPS as f64;
                let lat = s + (n - s) * j as f64 / STEPS as f64;
                for h in [h0, h1] {
                    let g = Geodetic::new(lat.to_degrees(), lon.to_degrees(), h);
                    pts.push(enu.ecef_to_enu(geodetic_to_ecef(g).into()).to_array());
                }
            }
        }
        let mut lo = pts[0];
        let mut hi = pts[0];
        for p in &pts {
            for k in 0..3 {
                lo[k] = lo[k].min(p[k]);
                hi[k] = hi[k].max(p[k]);
            }
        }
        let centre = [0, 1, 2].map(|k| 0.5 * (lo[k] + hi[k]));
        let step = ((east - w).max(n - s)) / STEPS as f64;
        let sagitta = (EARTH_MEAN_RADIUS_M + h1.max(0.0)) * (1.0 - (0.5 * step).cos());
        let r = pts.iter().map(|p| dist(*p, centre)).fold(0.0, f64::max) + sagitta;
        return Some((centre, r));
    }
    if let Some(sp) = &bv.sphere {
        let centre = mat4_point(&enu_from_tile, [sp[0], sp[1], sp[2]]);
        let scale = (0..3)
            .map(|j| (0..3).map(|i| enu_from_tile[i][j].powi(2)).sum::<f64>().sqrt())
            .fold(0.0, f64::max);
        return Some((centre, sp[3] * scale));
    }
    None
}

/// Strips a query string and decodes `%XX` escapes of a content URI.
fn uri_to_relative_path(uri: &str) -> String {
    let uri = uri.split(['?', '#']).next().unwrap_or(uri);
    let bytes = uri.as_bytes();
    let mut out = Vec::with_capacity(bytes.len());
    let mut i = 0;
    while i < bytes.len() {
        if bytes[i] == b'%' && i + 2 < bytes.len() {
            let hex = |c: u8| (c as char).to_digit(16);
            if let (Some(h), Some(l)) = (hex(bytes[i + 1]), hex(bytes[i + 2])) {
                out.push((h * 16 + l) as u8);
                i += 3;
                continue;
            }
        }
        out.push(bytes[i]);
        i += 1;
    }
    String::from_utf8_lossy(&out).into_owned()
}

struct Loader<'a> {
    enu: &'a EnuFrame,
    enu_ecef: Mat4,
    /// Every tileset file being loaded (to reject cycles of external tilesets).
    stack: Vec<PathBuf>,
}

impl Loader<'_> {
    fn load(&mut self, path: &Path, parent: &Mat4) -> Result<LoadedTileset, BlenderError> {
        let bad = |what: String| BlenderError::Tileset { path: path.to_path_buf(), what };
        let canon = path.canonicalize().map_err(|e| bad(format!("cannot open: {e}")))?;
        if self.stack.contains(&canon) {
            return Err(bad("external tilesets reference each other in a cycle".into()));
        }
        let bytes = crate::util::read_file(path)?;
        let json: TilesetJson =
            serde_json::from_slice(&bytes).map_err(|e| bad(format!("not a 3D Tiles tileset.json: {e}")))?;
        if !json.asset.version.starts_with("1.") && json.asset.version != "0.0" {
            return Err(bad(format!("asset.version {:?} is not a 3D Tiles 1.x version", json.asset.version)));
        }
        let up_axis = match json.asset.gltf_up_axis.as_deref() {
            None | Some("Y") | Some("y") => UpAxis::Y,
            Some("Z") | Some("z") => UpAxis::Z,
            Some(other) => return Err(bad(format!("asset.gltfUpAxis {other:?} is not supported (Y or Z)"))),
        };
        let mut issues = Vec::new();
        validate_tile(&json.root, "root", &mut issues);
        if !issues.is_empty() {
            return Err(bad(issues.join("; ")));
        }
        self.stack.push(canon);
        let dir = path.parent().map(Path::to_path_buf).unwrap_or_default();
        let root = self.convert(&json.root, parent, Refine::Replace, &dir);
        self.stack.pop();
        Ok(LoadedTileset { up_axis, root: root.map_err(|what| bad(what))? })
    }

    fn convert(
        &mut self,
        t: &TileJson,
        parent: &Mat4,
        inherited: Refine,
        dir: &Path,
    ) -> Result<Tile, String> {
        let ecef_from_tile = match &t.transform {
            Some(v) => mat4_mul(parent, &col_major_to_rows(v)),
            None => *parent,
        };
        let (centre_enu_m, radius_m) =
            bounding_sphere_enu(&t.bounding_volume, &ecef_from_tile, self.enu, &self.enu_ecef)
                .ok_or_else(|| "a tile has no bounding volume".to_string())?;
        let refine = match t.refine.as_deref().map(str::to_ascii_uppercase).as_deref() {
            Some("ADD") => Refine::Add,
            Some("REPLACE") => Refine::Replace,
            _ => inherited,
        };
        let mut contents = Vec::new();
        for c in t.content.iter().chain(&t.contents) {
            if let Some(uri) = c.uri.as_ref().or(c.url.as_ref()) {
                contents.push(dir.join(uri_to_relative_path(uri)));
            }
        }
        let children = t
            .children
            .iter()
            .map(|c| self.convert(c, &ecef_from_tile, refine, dir))
            .collect::<Result<Vec<_>, _>>()?;
        Ok(Tile {
            ecef_from_tile,
            centre_enu_m,
            radius_m,
            geometric_error_m: t.geometric_error,
            refine,
            contents,
            children,
        })
    }
}

fn validate_tile(t: &TileJson, at: &str, issues: &mut Vec<String>) {
    let bv = &t.bounding_volume;
    let lens =
        [(bv.box_.as_ref(), 12, "box"), (bv.region.as_ref(), 6, "region"), (bv.sphere.as_ref(), 4, "sphere")];
    if lens.iter().all(|(v, _, _)| v.is_none()) {
        issues.push(format!("{at}.boundingVolume: needs a box, region or sphere"));
    }
    for (v, n, name) in lens {
        if let Some(v) = v {
            if v.len() != n || v.iter().any(|x| !x.is_finite()) {
                issues.push(format!("{at}.boundingVolume.{name}: needs {n} finite numbers, has {}", v.len()));
            }
        }
    }
    if !(t.geometric_error.is_finite() && t.geometric_error >= 0.0) {
        issues
            .push(format!("{at}.geometricError: {} is not a finite non-negative number", t.geometric_error));
    }
    if let Some(r) = &t.refine {
        if !r.eq_ignore_ascii_case("ADD") && !r.eq_ignore_ascii_case("REPLACE") {
            issues.push(format!("{at}.refine: {r:?} is neither ADD nor REPLACE"));
        }
    }
    if let Some(m) = &t.transform {
        if m.len() != 16 || m.iter().any(|x| !x.is_finite()) {
            issues.push(format!("{at}.transform: needs 16 finite numbers, has {}", m.len()));
        }
    }
    for (i, c) in t.children.iter().enumerate() {
        validate_tile(c, &format!("{at}.children[{i}]"), issues);
    }
}

// ------------------------------------------------------------------------------------------ selection

/// Options of the tile selection.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SelectOptions {
    /// Largest screen-space error tolerated before a tile is refined, pixels (CesiumJS default: 16).
    pub max_sse_px: f64,
}

impl Default for SelectOptions {
    fn default() -> Self {
        SelectOptions { max_sse_px: 16.0 }
    }
}

/// One tile content chosen for rendering.
#[derive(Debug, Clone, PartialEq)]
pub struct SelectedTile {
    /// The content file (b3dm, glb or gltf).
    pub content: PathBuf,
    /// ECEF-from-tile transform (row-major), all ancestors' transforms included.
    pub ecef_from_tile: Mat4,
    pub up_axis: UpAxis,
}

/// The tiles a set of cameras sees.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct TileSelection {
    /// Distinct tile contents, in order of first use.
    pub tiles: Vec<SelectedTile>,
    /// For each camera, the indices into `tiles` it shows.
    pub per_frame: Vec<Vec<u32>>,
    /// Contents skipped because Blender cannot import them (pnts, i3dm, cmpt, …), by extension.
    pub skipped: BTreeMap<String, u64>,
}

/// Whether a sphere (ENU) intersects the camera's viewing frustum (no far plane).
pub fn sphere_in_frustum(k: &Intrinsics, pose: &Pose, centre_enu_m: [f64; 3], radius_m: f64) -> bool {
    let p = pose.world_to_cam(centre_enu_m.into()).to_array();
    // Inward normals of the planes through the camera centre bounding the image: x ≥ −cx/fx · z, etc.
    let planes = [
        [1.0, 0.0, k.cx_px / k.fx_px],
        [-1.0, 0.0, (k.width_px as f64 - k.cx_px) / k.fx_px],
        [0.0, 1.0, k.cy_px / k.fy_px],
        [0.0, -1.0, (k.height_px as f64 - k.cy_px) / k.fy_px],
        [0.0, 0.0, 1.0],
    ];
    planes.iter().all(|n| {
        let len = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
        (n[0] * p[0] + n[1] * p[1] + n[2] * p[2]) / len >= -radius_m
    })
}

/// Chooses the tiles each camera sees, refining by screen-space error (see the module doc).
///
/// # Errors
/// [`BlenderError::Tileset`] naming the tileset file and the JSON path of every problem.
pub fn select_tiles(
    tileset: &Path,
    enu: &EnuFrame,
    cameras: &[(Intrinsics, Pose)],
    opts: &SelectOptions,
) -> Result<TileSelection, BlenderError> {
    let mut loader = Loader { enu, enu_ecef: enu_from_ecef(enu), stack: Vec::new() };
    let root = loader.load(tileset, &IDENTITY)?;
    let mut external: BTreeMap<PathBuf, LoadedTileset> = BTreeMap::new();
    let mut sel = TileSelection::default();
    let mut index: BTreeMap<(PathBuf, [u64; 16]), u32> = BTreeMap::new();
    for (k, pose) in cameras {
        let mut chosen: Vec<u32> = Vec::new();
        let mut walk = Walk {
            k,
            pose,
            opts,
            loader: &mut loader,
            external: &mut external,
            out: Vec::new(),
            skipped: &mut sel.skipped,
        };
        walk.visit(&root.root, root.up_axis, 0)?;
        for t in walk.out {
            let key = (t.content.clone(), bits(&t.ecef_from_tile));
            let i = *index.entry(key).or_insert_with(|| {
                sel.tiles.push(t);
                sel.tiles.len() as u32 - 1
            });
            if !chosen.contains(&i) {
                chosen.push(i);
            }
        }
        chosen.sort_unstable();
        sel.per_frame.push(chosen);
    }
    Ok(sel)
}

fn bits(m: &Mat4) -> [u64; 16] {
    let mut b = [0u64; 16];
    for i in 0..4 {
        for j in 0..4 {
            b[i * 4 + j] = m[i][j].to_bits();
        }
    }
    b
}

/// Depth limit of external tileset nesting (guards against pathological trees).
const MAX_EXTERNAL_DEPTH: usize = 32;

struct Walk<'a, 'b> {
    k: &'a Intrinsics,
    pose: &'a Pose,
    opts: &'a SelectOptions,
    loader: &'a mut Loader<'b>,
    external: &'a mut BTreeMap<PathBuf, LoadedTileset>,
    out: Vec<SelectedTile>,
    skipped: &'a mut BTreeMap<String, u64>,
}

impl Walk<'_, '_> {
    fn visit(&mut self, t: &Tile, up: UpAxis, depth: usize) -> Result<(), BlenderError> {
        if !sphere_in_frustum(self.k, self.pose, t.centre_enu_m, t.radius_m) {
            return Ok(());
        }
        let d = (dist(self.pose.centre_m.to_array(), t.centre_enu_m) - t.radius_m).max(1e-3);
        let sse_px = t.geometric_error_m * self.k.fy_px / d;
        let refine = !t.children.is_empty() && sse_px > self.opts.max_sse_px;
        if !refine || t.refine == Refine::Add {
            self.take_contents(t, up, depth)?;
        } else {
            // REPLACE: the children stand in for this tile, but external tilesets are its children too.
            self.follow_external(t, depth)?;
        }
        if refine {
            for c in &t.children {
                self.visit(c, up, depth)?;
            }
        }
        Ok(())
    }

    fn take_contents(&mut self, t: &Tile, up: UpAxis, depth: usize) -> Result<(), BlenderError> {
        for c in &t.contents {
            let ext = c.extension().and_then(|e| e.to_str()).unwrap_or("").to_ascii_lowercase();
            match ext.as_str() {
                "b3dm" | "glb" | "gltf" => self.out.push(SelectedTile {
                    content: c.clone(),
                    ecef_from_tile: t.ecef_from_tile,
                    up_axis: up,
                }),
                "json" => self.visit_external(c, &t.ecef_from_tile, depth)?,
                other => *self.skipped.entry(other.to_string()).or_insert(0) += 1,
            }
        }
        Ok(())
    }

    fn follow_external(&mut self, t: &Tile, depth: usize) -> Result<(), BlenderError> {
        for c in &t.contents {
            if c.extension().is_some_and(|e| e.eq_ignore_ascii_case("json")) {
                self.visit_external(c, &t.ecef_from_tile, depth)?;
            }
        }
        Ok(())
    }

    fn visit_external(&mut self, path: &Path, parent: &Mat4, depth: usize) -> Result<(), BlenderError> {
        if depth >= MAX_EXTERNAL_DEPTH {
            return Err(BlenderError::Tileset {
                path: path.to_path_buf(),
                what: format!("external tilesets nested deeper than {MAX_EXTERNAL_DEPTH}"),
            });
        }
        // External tilesets are keyed by path and parent transform (the same file may hang under
        // differently transformed tiles).
        let mut key = path.as_os_str().to_owned();
        key.push(format!("#{:?}", bits(parent)));
        let key = PathBuf::from(key);
        if !self.external.contains_key(&key) {
            let loaded = self.loader.load(path, parent)?;
            self.external.insert(key.clone(), loaded);
        }
        // Taken out and put back so the walk can borrow `self` mutably meanwhile.
        let ts = self.external.remove(&key).expect("inserted above");
        let r = self.visit(&ts.root, ts.up_axis, depth + 1);
        self.external.insert(key, ts);
        r
    }
}

// ------------------------------------------------------------------------------------------ unwrapping

const GLB_MAGIC: &[u8; 4] = b"glTF";
const CHUNK_JSON: u32 = 0x4E4F_534A;
/// A legacy b3dm header is recognised by a length field that is really the start of the next section
/// (CesiumJS uses the same threshold: 570425344 = 0x22000000, larger than any sane JSON length).
const LEGACY_HEADER_THRESHOLD: u32 = 570_425_344;

fn u32_at(b: &[u8], at: usize) -> u32 {
    u32::from_le_bytes([b[at], b[at + 1], b[at + 2], b[at + 3]])
}

/// The GLB inside a b3dm and the feature table's `RTC_CENTER` (ECEF metres), if any.
///
/// # Errors
/// [`BlenderError::Tile`] when the container is truncated or inconsistent.
pub fn unwrap_b3dm<'a>(path: &Path, b: &'a [u8]) -> Result<(&'a [u8], Option<[f64; 3]>), BlenderError> {
    let bad = |what: String| BlenderError::Tile { path: path.to_path_buf(), what };
    if b.len() < 28 || &b[0..4] != b"b3dm" {
        return Err(bad("not a b3dm file (magic is not \"b3dm\" or the header is truncated)".into()));
    }
    let version = u32_at(b, 4);
    if version != 1 {
        return Err(bad(format!("b3dm version {version} is not supported (expected 1)")));
    }
    let byte_length = u32_at(b, 8) as usize;
    if byte_length > b.len() {
        return Err(bad(format!("header says {byte_length} bytes but the file has {}", b.len())));
    }
    let (ft_json, ft_bin, bt_json, bt_bin) = (u32_at(b, 12), u32_at(b, 16), u32_at(b, 20), u32_at(b, 24));
    let (header_len, ft_json_len, ft_bin_len, bt_len) = if bt_json >= LEGACY_HEADER_THRESHOLD {
        // Legacy 20-byte header: batchLength, batchTableByteLength.
        (20usize, 0usize, 0usize, ft_bin as usize)
    } else if bt_bin >= LEGACY_HEADER_THRESHOLD {
        // Legacy 24-byte header: batchTableJsonByteLength, batchTableBinaryByteLength, batchLength.
        (24, 0, 0, (ft_json + ft_bin) as usize)
    } else {
        (28, ft_json as usize, ft_bin as usize, (bt_json + bt_bin) as usize)
    };
    let glb_start = header_len + ft_json_len + ft_bin_len + bt_len;
    if glb_start > byte_length {
        return Err(bad(format!("tables end at byte {glb_start}, past the b3dm length {byte_length}")));
    }
    let mut rtc = None;
    if ft_json_len > 0 {
        let ft = &b[header_len..header_len + ft_json_len];
        let v: Value = serde_json::from_slice(ft).map_err(|e| bad(format!("feature table JSON: {e}")))?;
        if let Some(c) = v.get("RTC_CENTER") {
            rtc = Some(
                read_rtc_center(c, &b[header_len + ft_json_len..header_len + ft_json_len + ft_bin_len])
                    .ok_or_else(|| bad(format!("feature table RTC_CENTER {c} is not three numbers")))?,
            );
        }
    }
    Ok((&b[glb_start..byte_length], rtc))
}

fn read_rtc_center(v: &Value, ft_bin: &[u8]) -> Option<[f64; 3]> {
    if let Some(a) = v.as_array() {
        if a.len() == 3 {
            return Some([a[0].as_f64()?, a[1].as_f64()?, a[2].as_f64()?]);
        }
        return None;
    }
    // {"byteOffset": n}: three float32 in the feature table binary.
    let off = v.get("byteOffset")?.as_u64()? as usize;
    let f = |i: usize| -> Option<f64> {
        let s = ft_bin.get(off + 4 * i..off + 4 * i + 4)?;
        Some(f32::from_le_bytes([s[0], s[1], s[2], s[3]]) as f64)
    };
    Some([f(0)?, f(1)?, f(2)?])
}

/// Rewrites a GLB for Blender: removes the `CESIUM_RTC` extension (returning its centre, ECEF metres)
/// and makes relative URIs absolute against `base_dir`. Other chunks are copied unchanged.
///
/// # Errors
/// [`BlenderError::Tile`] when the GLB is malformed or glTF 1.0.
pub fn rewrite_glb(
    path: &Path,
    glb: &[u8],
    base_dir: &Path,
) -> Result<(Vec<u8>, Option<[f64; 3]>), BlenderError> {
    let bad = |what: String| BlenderError::Tile { path: path.to_path_buf(), what };
    if glb.len() < 20 || &glb[0..4] != GLB_MAGIC {
        return Err(bad("embedded content is not a GLB (magic is not \"glTF\")".into()));
    }
    let version = u32_at(glb, 4);
    if version != 2 {
        return Err(bad(format!("glTF {version}.0 binary is not supported (glTF 2.0 needed)")));
    }
    let total = (u32_at(glb, 8) as usize).min(glb.len());
    let json_len = u32_at(glb, 12) as usize;
    if u32_at(glb, 16) != CHUNK_JSON || 20 + json_len > total {
        return Err(bad("the first GLB chunk is not a complete JSON chunk".into()));
    }
    let mut json: Value =
        serde_json::from_slice(&glb[20..20 + json_len]).map_err(|e| bad(format!("glTF JSON: {e}")))?;
    let mut rtc = None;
    if let Some(exts) = json.get_mut("extensions").and_then(Value::as_object_mut) {
        if let Some(c) = exts.remove("CESIUM_RTC") {
            let centre = c.get("center").and_then(|v| read_rtc_center(v, &[]));
            rtc = Some(centre.ok_or_else(|| bad(format!("CESIUM_RTC.center {c} is not three numbers")))?);
        }
        if exts.is_empty() {
            json.as_object_mut().map(|o| o.remove("extensions"));
        }
    }
    for key in ["extensionsUsed", "extensionsRequired"] {
        if let Some(list) = json.get_mut(key).and_then(Value::as_array_mut) {
            list.retain(|e| e.as_str() != Some("CESIUM_RTC"));
            if list.is_empty() {
                json.as_object_mut().map(|o| o.remove(key));
            }
        }
    }
    for key in ["images", "buffers"] {
        if let Some(items) = json.get_mut(key).and_then(Value::as_array_mut) {
            for item in items {
                if let Some(uri) = item.get("uri").and_then(Value::as_str) {
                    if !uri.starts_with("data:") && !uri.contains("://") && !Path::new(uri).is_absolute() {
                        let abs = base_dir.join(uri_to_relative_path(uri));
                        item["uri"] = Value::String(abs.to_string_lossy().into_owned());
                    }
                }
            }
        }
    }
    let mut text = serde_json::to_vec(&json).map_err(|e| bad(format!("re-serialising glTF JSON: {e}")))?;
    while text.len() % 4 != 0 {
        text.push(b' ');
    }
    let rest = &glb[20 + json_len..total];
    let mut out = Vec::with_capacity(20 + text.len() + rest.len());
    out.extend_from_slice(GLB_MAGIC);
    out.extend_from_slice(&2u32.to_le_bytes());
    out.extend_from_slice(&((20 + text.len() + rest.len()) as u32).to_le_bytes());
    out.extend_from_slice(&(text.len() as u32).to_le_bytes());
    out.extend_from_slice(&CHUNK_JSON.to_le_bytes());
    out.extend_from_slice(&text);
    out.extend_from_slice(rest);
    Ok((out, rtc))
}

/// Turns a selected tile into a job model: unwraps/rewrites its content into `cache_dir` (b3dm, glb) or
/// uses it in place (glTF JSON), and computes ENU-from-glTF.
///
/// # Errors
/// I/O errors naming the file; [`BlenderError::Tile`] for malformed content.
pub fn prepare_tile(tile: &SelectedTile, enu: &EnuFrame, cache_dir: &Path) -> Result<JobModel, BlenderError> {
    use sha2::{Digest, Sha256};
    let path = &tile.content;
    let ext = path.extension().and_then(|e| e.to_str()).unwrap_or("").to_ascii_lowercase();
    let base_dir = path.parent().map(Path::to_path_buf).unwrap_or_default();
    let base_dir = base_dir.canonicalize().unwrap_or(base_dir);
    let (glb_path, rtc) = if ext == "gltf" {
        (path.canonicalize().map_err(|e| crate::util::FileError::new("opening", path, e))?, None)
    } else {
        let bytes = crate::util::read_file(path)?;
        let (glb, rtc_b3dm) = if ext == "b3dm" { unwrap_b3dm(path, &bytes)? } else { (&bytes[..], None) };
        let (rewritten, rtc_gltf) = rewrite_glb(path, glb, &base_dir)?;
        let abs = path.canonicalize().unwrap_or_else(|_| path.clone());
        let digest = hex::encode(&Sha256::digest(abs.to_string_lossy().as_bytes())[..8]);
        let stem = path.file_stem().and_then(|s| s.to_str()).unwrap_or("tile");
        let out = cache_dir.join(format!("{digest}-{stem}.glb"));
        crate::util::write_bytes_atomic(&out, &rewritten)?;
        // A glTF-level CESIUM_RTC and a b3dm RTC_CENTER never come together in valid data; if they do,
        // both are translations in ECEF and add up.
        let rtc = match (rtc_b3dm, rtc_gltf) {
            (Some(a), Some(b)) => Some([a[0] + b[0], a[1] + b[1], a[2] + b[2]]),
            (a, b) => a.or(b),
        };
        (out, rtc)
    };
    let axis = match tile.up_axis {
        UpAxis::Y => Y_UP_TO_Z_UP,
        UpAxis::Z => IDENTITY,
    };
    let ecef_from_gltf =
        mat4_mul(&mat4_mul(&tile.ecef_from_tile, &translation(rtc.unwrap_or([0.0; 3]))), &axis);
    Ok(JobModel {
        glb: glb_path,
        enu_from_gltf: mat4_mul(&enu_from_ecef(enu), &ecef_from_gltf),
        kind: ModelKind::Photogrammetry,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frame() -> EnuFrame {
        EnuFrame::new(Geodetic::new(35.658, 139.70, 40.0))
    }

    #[test]
    fn enu_from_ecef_inverts_the_frame() {
        let enu = frame();
        let m = enu_from_ecef(&enu);
        for p in [[0.0, 0.0, 0.0], [123.0, -456.0, 78.9], [-2000.0, 3000.0, -50.0]] {
            let ecef = enu.enu_to_ecef(p.into()).to_array();
            let back = mat4_point(&m, ecef);
            assert!(dist(back, p) < 1e-6, "{p:?} → {back:?}");
        }
    }

    #[test]
    fn affine_inverse() {
        let m = [[0.0, -2.0, 0.0, 5.0], [1.0, 0.0, 0.0, -1.0], [0.0, 0.0, 3.0, 2.0], [0.0, 0.0, 0.0, 1.0]];
        let inv = mat4_inverse_affine(&m).unwrap();
        let id = mat4_mul(&m, &inv);
        for i in 0..4 {
            for j in 0..4 {
                assert!((id[i][j] - IDENTITY[i][j]).abs() < 1e-12, "{id:?}");
            }
        }
        let mut singular = m;
        singular[2][2] = 0.0;
        assert!(mat4_inverse_affine(&singular).is_none());
    }

    #[test]
    fn uri_decoding() {
        assert_eq!(uri_to_relative_path("data/a%20b.b3dm?session=1"), "data/a b.b3dm");
        assert_eq!(uri_to_relative_path("x.glb#frag"), "x.glb");
        assert_eq!(uri_to_relative_path("bad%zz.glb"), "bad%zz.glb");
    }

    #[test]
    fn frustum_test_nadir() {
        // Nadir camera 100 m up, 90° HFOV on a square image: the footprint is ±100 m.
        let k = Intrinsics::from_hfov(100, 100, 90.0);
        let pose = Pose::from_ypr_deg(0.0, 0.0, 0.0, [0.0, 0.0, 100.0]);
        assert!(sphere_in_frustum(&k, &pose, [0.0, 0.0, 0.0], 1.0));
        assert!(sphere_in_frustum(&k, &pose, [99.0, 0.0, 0.0], 1.0));
        // 105 m east: outside by 5/√2 ≈ 3.5 m from the plane x = z; a 3 m sphere misses, a 4 m one hits.
        assert!(!sphere_in_frustum(&k, &pose, [105.0, 0.0, 0.0], 3.0));
        assert!(sphere_in_frustum(&k, &pose, [105.0, 0.0, 0.0], 4.0));
        // Behind the camera.
        assert!(!sphere_in_frustum(&k, &pose, [0.0, 0.0, 200.0], 50.0));
    }

    #[test]
    fn region_sphere_contains_its_corners() {
        let enu = frame();
        let bv = BoundingVolumeJson {
            box_: None,
            sphere: None,
            region: Some(vec![
                139.69f64.to_radians(),
                35.65f64.to_radians(),
                139.71f64.to_radians(),
                35.665f64.to_radians(),
                20.0,
                300.0,
            ]),
        };
        let (c, r) = bounding_sphere_enu(&bv, &IDENTITY, &enu, &enu_from_ecef(&enu)).unwrap();
        for lat in [35.65, 35.6575, 35.665] {
            for lon in [139.69, 139.70, 139.71] {
                for h in [20.0, 160.0, 300.0] {
                    let p = enu.geodetic_to_enu(Geodetic::new(lat, lon, h)).to_array();
                    assert!(dist(p, c) <= r, "{lat} {lon} {h}: {} > {r}", dist(p, c));
                }
            }
        }
        // The region is ~1.8 km × 1.7 km × 280 m: the sphere must be tight (< 1.5 km radius).
        assert!(r < 1500.0, "{r}");
    }

    #[test]
    fn b3dm_unwrap_reads_rtc_center() {
        let glb = b"glTF\x02\x00\x00\x00\x14\x00\x00\x00\x00\x00\x00\x00JSON".to_vec();
        let ft = br#"{"BATCH_LENGTH":0,"RTC_CENTER":[1.5,-2.0,3.25]}"#.to_vec();
        let mut ft = ft;
        while (28 + ft.len()) % 8 != 0 {
            ft.push(b' ');
        }
        let mut b = Vec::new();
        b.extend_from_slice(b"b3dm");
        b.extend_from_slice(&1u32.to_le_bytes());
        b.extend_from_slice(&((28 + ft.len() + glb.len()) as u32).to_le_bytes());
        b.extend_from_slice(&(ft.len() as u32).to_le_bytes());
        b.extend_from_slice(&[0; 12]);
        b.extend_from_slice(&ft);
        b.extend_from_slice(&glb);
        let (inner, rtc) = unwrap_b3dm(Path::new("t.b3dm"), &b).unwrap();
        assert_eq!(inner, &glb[..]);
        assert_eq!(rtc, Some([1.5, -2.0, 3.25]));
        // Truncated file.
        let e = unwrap_b3dm(Path::new("t.b3dm"), &b[..40]).unwrap_err().to_string();
        assert!(e.contains("t.b3dm") && e.contains("bytes"), "{e}");
        assert!(unwrap_b3dm(Path::new("x.b3dm"), b"i3dm0000000000000000000000000000").is_err());
    }

    #[test]
    fn glb_rewrite_strips_cesium_rtc() {
        let json = br#"{"asset":{"version":"2.0"},"extensionsUsed":["CESIUM_RTC","KHR_draco_mesh_compression"],"extensionsRequired":["CESIUM_RTC"],"extensions":{"CESIUM_RTC":{"center":[10,20,30]}},"images":[{"uri":"tex/a.jpg"}],"buffers":[{"byteLength":4}]}"#;
        let mut j = json.to_vec();
        while j.len() % 4 != 0 {
            j.push(b' ');
        }
        let bin = [1u8, 2, 3, 4];
        let mut g = Vec::new();
        g.extend_from_slice(b"glTF");
        g.extend_from_slice(&2u32.to_le_bytes());
        g.extend_from_slice(&((20 + j.len() + 8 + 4) as u32).to_le_bytes());
        g.extend_from_slice(&(j.len() as u32).to_le_bytes());
        g.extend_from_slice(&CHUNK_JSON.to_le_bytes());
        g.extend_from_slice(&j);
        g.extend_from_slice(&4u32.to_le_bytes());
        g.extend_from_slice(&0x004E_4942u32.to_le_bytes());
        g.extend_from_slice(&bin);
        let (out, rtc) = rewrite_glb(Path::new("t.glb"), &g, Path::new("/data/tiles")).unwrap();
        assert_eq!(rtc, Some([10.0, 20.0, 30.0]));
        let n = u32_at(&out, 12) as usize;
        let v: Value = serde_json::from_slice(&out[20..20 + n]).unwrap();
        assert_eq!(v["extensionsUsed"], serde_json::json!(["KHR_draco_mesh_compression"]));
        assert!(v.get("extensionsRequired").is_none() && v.get("extensions").is_none());
        assert_eq!(v["images"][0]["uri"], "/data/tiles/tex/a.jpg");
        assert_eq!(&out[out.len() - 4..], &bin);
        assert_eq!(u32_at(&out, 8) as usize, out.len());
        assert_eq!(n % 4, 0);
    }
}
