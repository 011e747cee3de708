//! Writing 3D Tiles: GLB contents (with [`GlbBuilder`]), tileset JSON ([`TileOut`], [`write_tileset`]),
//! and a generator of textured multi-level city tilesets from insgen's own buildings
//! ([`generate_city_tileset`]) in the styles of real producers, which the tests render and read back.
//!
//! # Generated tilesets
//! Buildings (ENU metres, one 24-bit ID each, e.g. a prepared `scene.glb` through
//! [`crate::scene::mesh::buildings_from_scene`]) are put in a quadtree over their footprint square by centroid (levels
//! 0, 1, 2; a tile per non-empty cell). Every tile's content holds all of its cell's buildings (the
//! coarse levels are copies, as in real photogrammetry LODs) with a texture of its own: a 4 × 2 image
//! whose left half is the tile's roof colour and right half its wall colour ([`palette_colour`]),
//! sampled NEAREST; roof triangles (normal z > 0.7) map to the left half and the others to the right,
//! so every pixel's colour follows from the geometry and the tile. Every tile calls its image
//! `texture_0` and its material `Material_0` (as Cesium ion does). Geometric errors are
//! `extent / 4^level`, 0 at the leaves.
//!
//! | [`Style`] | container | geometry | surface | tree |
//! |---|---|---|---|---|
//! | `CesiumIon` | 1.1, glb | `KHR_draco_mesh_compression` | unlit, `KHR_texture_transform` | root transform ENU · rotation · scale 1.34, boxes, REPLACE, one ADD tile |
//! | `Google` | 1.1, glb | Draco, no feature IDs | unlit | no transform, boxes in ECEF, REPLACE |
//! | `Plateau` | 1.1, glb | `EXT_mesh_features` + `EXT_structural_metadata` (`gml_id`) | `EXT_texture_webp` | regions, REPLACE |
//! | `Bag3d` | 1.1, glb, implicit quadtree | `EXT_meshopt_compression` + `KHR_mesh_quantization` | plain | root transform ENU, subtree files |
//!
//! In every style but `Google`, vertices carry `_FEATURE_ID_0` = the building ID (with
//! `EXT_mesh_features`), so ID renders of the tileset can be compared with the scene's masks.

use std::path::{Path, PathBuf};

use glam::{DMat3, DMat4, DVec3};
use serde_json::{json, Value};

use crate::geo::EnuFrame;
use crate::lod::tiles3d::gltf::{TextureTransform, UpAxis};
use crate::lod::tiles3d::implicit;
use crate::lod::tiles3d::tileset::{BoundingVolume, Refine};
use crate::scene::mesh::CityBuilding;
use crate::util::glb::{floats, min_max, GlbBuilder, GlbError};
use crate::util::FileError;

/// Errors of the writers.
#[derive(Debug, thiserror::Error)]
pub enum WriteError {
    /// Writing a file failed.
    #[error(transparent)]
    File(#[from] FileError),
    /// A tile's GLB cannot be assembled (past the format's 4 GiB).
    #[error(transparent)]
    Glb(#[from] GlbError),
    /// An encoder refused the data: `what` was being encoded, `source` is the encoder's error.
    #[error("encoding {what}")]
    Encode {
        /// What was being encoded.
        what: &'static str,
        /// The encoder's error.
        #[source]
        source: Box<dyn std::error::Error + Send + Sync>,
    },
    /// The input cannot make a tileset.
    #[error("cannot build a tileset: {0}")]
    Input(&'static str),
}

// ------------------------------------------------------------------------------------------ tileset JSON

/// A tile to write.
#[derive(Debug, Clone)]
pub struct TileOut {
    /// The tile's bounding volume, in the tile's frame.
    pub bounding_volume: BoundingVolume,
    /// Geometric error, metres.
    pub geometric_error_m: f64,
    /// `REPLACE` or `ADD`; `None` inherits the parent's.
    pub refine: Option<Refine>,
    /// Tile frame → parent frame; written column-major (the spec's order) at the file edge.
    pub transform: Option<DMat4>,
    /// Content URI (relative to the tileset JSON) and its bytes.
    pub content: Option<(String, Vec<u8>)>,
    /// Child tiles.
    pub children: Vec<TileOut>,
    /// Extra members merged into the tile object (e.g. `implicitTiling`).
    pub extra: Value,
}

fn volume_json(bv: &BoundingVolume) -> Value {
    match *bv {
        BoundingVolume::Box { centre, half_axes } => json!({"box": [
            centre.x, centre.y, centre.z,
            half_axes.x_axis.x, half_axes.x_axis.y, half_axes.x_axis.z,
            half_axes.y_axis.x, half_axes.y_axis.y, half_axes.y_axis.z,
            half_axes.z_axis.x, half_axes.z_axis.y, half_axes.z_axis.z]}),
        BoundingVolume::Region { west_rad, south_rad, east_rad, north_rad, min_h_m, max_h_m } => {
            json!({"region": [west_rad, south_rad, east_rad, north_rad, min_h_m, max_h_m]})
        }
        BoundingVolume::Sphere { centre, radius_m } => {
            json!({"sphere": [centre.x, centre.y, centre.z, radius_m]})
        }
    }
}

fn tile_json(dir: &Path, t: &TileOut) -> Result<Value, WriteError> {
    let mut v =
        json!({"boundingVolume": volume_json(&t.bounding_volume), "geometricError": t.geometric_error_m});
    if let Some(r) = t.refine {
        v["refine"] = json!(match r {
            Refine::Add => "ADD",
            Refine::Replace => "REPLACE",
        });
    }
    if let Some(m) = t.transform {
        v["transform"] = json!(m.to_cols_array());
    }
    if let Some((uri, bytes)) = &t.content {
        let path = dir.join(uri);
        if let Some(parent) = path.parent() {
            crate::util::create_dir_all(parent)?;
        }
        crate::util::write_bytes_atomic(&path, bytes)?;
        v["content"] = json!({"uri": uri});
    }
    if !t.children.is_empty() {
        v["children"] = json!(t.children.iter().map(|c| tile_json(dir, c)).collect::<Result<Vec<_>, _>>()?);
    }
    if let Some(extra) = t.extra.as_object() {
        for (k, x) in extra {
            v[k] = x.clone();
        }
    }
    Ok(v)
}

/// Writes `tileset.json` (3D Tiles 1.1) and every content under `dir`, atomically file by file.
///
/// # Errors
/// [`WriteError::File`] naming the file that could not be written.
pub fn write_tileset(dir: &Path, root: &TileOut, extensions_used: &[&str]) -> Result<PathBuf, WriteError> {
    crate::util::create_dir_all(dir)?;
    let mut ts = json!({
        "asset": {"version": "1.1", "generator": "insgen"},
        "geometricError": root.geometric_error_m,
        "root": tile_json(dir, root)?,
    });
    if !extensions_used.is_empty() {
        ts["extensionsUsed"] = json!(extensions_used);
    }
    let path = dir.join("tileset.json");
    crate::util::write_json_atomic(&path, &ts)?;
    Ok(path)
}

// ------------------------------------------------------------------------------------------ city tilesets

/// The producer whose output a generated tileset imitates (see the module doc).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Style {
    /// Cesium ion's photogrammetry tilesets (rotated root transform, texture transform).
    CesiumIon,
    /// Google Photorealistic 3D Tiles (deep quadtree of GLB contents).
    Google,
    /// Project PLATEAU's building tilesets (b3dm with batch tables).
    Plateau,
    /// 3D BAG's tilesets (implicit tiling).
    Bag3d,
}

/// One tile of a generated tileset, for tests to predict what a render shows.
#[derive(Debug, Clone, PartialEq)]
pub struct GeneratedTile {
    /// JSON path as [`crate::lod::tiles3d::Tile::at`] names it (`root.children[1]`, `root{level 1, x 0, y 1}`).
    pub at: String,
    /// Depth in the tree (the root is 0).
    pub level: u32,
    /// The tile's refinement.
    pub refine: Refine,
    /// Content URI relative to the tileset JSON.
    pub content_uri: String,
    /// sRGB colours of its roof and wall texels.
    pub roof_rgb: [u8; 3],
    /// sRGB colour of its wall texels (see `roof_rgb`).
    pub wall_rgb: [u8; 3],
    /// Building IDs in its content.
    pub buildings: Vec<u32>,
    /// JSON path of its parent tile (`None` for the root).
    pub parent: Option<String>,
}

/// A written tileset and its tiles.
#[derive(Debug, Clone)]
pub struct GeneratedTileset {
    /// The tileset JSON written.
    pub tileset: PathBuf,
    /// Its tiles, root first.
    pub tiles: Vec<GeneratedTile>,
}

impl GeneratedTileset {
    /// The deepest tile whose content holds building `id` (what a fully refined view draws).
    pub fn finest_tile_of(&self, id: u32) -> Option<&GeneratedTile> {
        self.tiles.iter().filter(|t| t.buildings.contains(&id)).max_by_key(|t| t.level)
    }
    /// The tile at JSON path `at`.
    pub fn tile(&self, at: &str) -> Option<&GeneratedTile> {
        self.tiles.iter().find(|t| t.at == at)
    }
}

/// Colour `k` of the generated tilesets' palette: sRGB triples over {30, 130, 230}³ without the
/// three greys, 24 colours, each at least 100 levels from every other in some channel.
pub fn palette_colour(k: usize) -> [u8; 3] {
    let levels = [30u8, 130, 230];
    let all: Vec<[u8; 3]> = (0..27)
        .map(|i| [levels[i % 3], levels[(i / 3) % 3], levels[i / 9]])
        .filter(|c| !(c[0] == c[1] && c[1] == c[2]))
        .collect();
    all[(k * 7) % all.len()]
}

/// UV of a roof texel centre in the 4 × 2 tile texture.
pub const ROOF_UV: [f64; 2] = [0.25, 0.5];
/// UV of a wall texel centre in the 4 × 2 tile texture.
pub const WALL_UV: [f64; 2] = [0.75, 0.5];

/// The `KHR_texture_transform` the `CesiumIon` style writes (a quarter turn, a half-width scale and
/// an offset), so UVs are only right when the transform is applied.
pub const CESIUM_TEXTURE_TRANSFORM: TextureTransform = TextureTransform {
    offset: [0.5, 1.0],
    rotation: std::f64::consts::FRAC_PI_2,
    scale: [0.5, 1.0],
    tex_coord: None,
};

/// Rotation about up of the `CesiumIon` style's root transform, radians.
pub const CESIUM_ROOT_ROTATION_RAD: f64 = 0.3;
/// Uniform scale of the `CesiumIon` style's root transform.
pub const CESIUM_ROOT_SCALE: f64 = 1.34;

/// A quadtree cell with the buildings whose centroid falls in it.
#[derive(Debug, Clone)]
struct Cell {
    level: u32,
    x: u64,
    y: u64,
    buildings: Vec<usize>,
    children: Vec<Cell>,
}

const LEVELS: u32 = 3;

fn quadtree(buildings: &[CityBuilding]) -> Result<(Cell, [f64; 2], f64), WriteError> {
    let centroids: Vec<[f64; 2]> = buildings
        .iter()
        .map(|b| {
            let n = b.positions_enu_m.len().max(1) as f64;
            let s = b.positions_enu_m.iter().fold([0.0, 0.0], |a, p| [a[0] + p[0], a[1] + p[1]]);
            [s[0] / n, s[1] / n]
        })
        .collect();
    let (lo, hi) = min_max(buildings.iter().flat_map(|b| b.positions_enu_m.iter().copied()));
    if !lo[0].is_finite() {
        return Err(WriteError::Input("no building has triangles"));
    }
    let side = (hi[0] - lo[0]).max(hi[1] - lo[1]).max(1.0) * 1.001;
    let origin = [lo[0], lo[1]];
    fn build(
        level: u32,
        x: u64,
        y: u64,
        members: Vec<usize>,
        c: &[[f64; 2]],
        origin: [f64; 2],
        side: f64,
    ) -> Cell {
        let mut children = Vec::new();
        if level + 1 < LEVELS {
            for k in 0..4u64 {
                let (cx, cy) = (2 * x + (k & 1), 2 * y + (k >> 1));
                let n = (1u64 << (level + 1)) as f64;
                let inside: Vec<usize> = members
                    .iter()
                    .copied()
                    .filter(|&i| {
                        let u = ((c[i][0] - origin[0]) / side * n).floor().clamp(0.0, n - 1.0) as u64;
                        let v = ((c[i][1] - origin[1]) / side * n).floor().clamp(0.0, n - 1.0) as u64;
                        u == cx && v == cy
                    })
                    .collect();
                if !inside.is_empty() {
                    children.push(build(level + 1, cx, cy, inside, c, origin, side));
                }
            }
        }
        Cell { level, x, y, buildings: members, children }
    }
    let root = build(0, 0, 0, (0..buildings.len()).collect(), &centroids, origin, side);
    Ok((root, origin, side))
}

/// How ENU maps to a style's tile frame and what the root carries.
struct Frames {
    /// Tile frame from ENU (affine).
    tile_from_enu: DMat4,
    /// The root tile's transform (parent = ECEF).
    root_transform: Option<DMat4>,
}

fn frames(style: Style, enu: &EnuFrame) -> Frames {
    let ecef = enu.ecef_from_enu();
    match style {
        Style::CesiumIon => {
            let rs = DMat4::from_rotation_z(CESIUM_ROOT_ROTATION_RAD)
                * DMat4::from_scale(DVec3::splat(CESIUM_ROOT_SCALE));
            Frames { tile_from_enu: rs.inverse(), root_transform: Some(ecef * rs) }
        }
        Style::Google | Style::Plateau => Frames { tile_from_enu: ecef, root_transform: None },
        Style::Bag3d => Frames { tile_from_enu: DMat4::IDENTITY, root_transform: Some(ecef) },
    }
}

/// Vertices of one tile's content, in ENU, with UV targets and IDs.
struct TileMesh {
    enu: Vec<DVec3>,
    uv: Vec<[f64; 2]>,
    ids: Vec<u32>,
}

fn tile_mesh(buildings: &[CityBuilding], members: &[usize]) -> TileMesh {
    let mut m = TileMesh { enu: vec![], uv: vec![], ids: vec![] };
    for &i in members {
        let b = &buildings[i];
        for t in &b.triangles {
            let [a, bb, c] = t.map(|k| DVec3::from_array(b.positions_enu_m[k as usize]));
            let n = (bb - a).cross(c - a).normalize_or_zero();
            let uv = if n.z.abs() > 0.7 { ROOF_UV } else { WALL_UV };
            for p in [a, bb, c] {
                m.enu.push(p);
                m.uv.push(uv);
                m.ids.push(b.id.get());
            }
        }
    }
    m
}

fn tile_volume(style: Style, f: &Frames, enu: &EnuFrame, mesh: &TileMesh) -> BoundingVolume {
    let (lo, hi) = min_max(mesh.enu.iter().map(|p| p.to_array()));
    let pad = DVec3::splat(0.5);
    let (lo, hi) = (DVec3::from_array(lo) - pad, DVec3::from_array(hi) + pad);
    if style == Style::Plateau {
        let mut g = (
            f64::INFINITY,
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::NEG_INFINITY,
            f64::INFINITY,
            f64::NEG_INFINITY,
        );
        for x in [lo.x, hi.x] {
            for y in [lo.y, hi.y] {
                for z in [lo.z, hi.z] {
                    let p = enu.enu_to_geodetic(DVec3::new(x, y, z));
                    g = (
                        g.0.min(p.lon_deg),
                        g.1.min(p.lat_deg),
                        g.2.max(p.lon_deg),
                        g.3.max(p.lat_deg),
                        g.4.min(p.h_m),
                        g.5.max(p.h_m),
                    );
                }
            }
        }
        // A metre of margin for the curvature between corners (regions are geodetic boxes).
        let m_deg = 1.0 / 111_000.0;
        return BoundingVolume::Region {
            west_rad: (g.0 - m_deg).to_radians(),
            south_rad: (g.1 - m_deg).to_radians(),
            east_rad: (g.2 + m_deg).to_radians(),
            north_rad: (g.3 + m_deg).to_radians(),
            min_h_m: g.4 - 1.0,
            max_h_m: g.5 + 1.0,
        };
    }
    let c = 0.5 * (lo + hi);
    let h = 0.5 * (hi - lo);
    let lin = DMat3::from_mat4(f.tile_from_enu);
    BoundingVolume::Box {
        centre: f.tile_from_enu.transform_point3(c),
        half_axes: lin * DMat3::from_diagonal(h),
    }
}

/// The texture of a tile: 4 × 2 texels, left half roof, right half wall.
fn tile_texture(roof: [u8; 3], wall: [u8; 3], webp: bool) -> Result<(Vec<u8>, &'static str), WriteError> {
    let mut rgb = Vec::with_capacity(4 * 2 * 3);
    for _y in 0..2 {
        for x in 0..4 {
            rgb.extend_from_slice(if x < 2 { &roof } else { &wall });
        }
    }
    if webp {
        let mut out = Vec::new();
        image_webp::WebPEncoder::new(&mut out)
            .encode(&rgb, 4, 2, image_webp::ColorType::Rgb8)
            .map_err(|e| WriteError::Encode { what: "a WebP texture", source: Box::new(e) })?;
        return Ok((out, "image/webp"));
    }
    let mut out = Vec::new();
    {
        let mut enc = png::Encoder::new(&mut out, 4, 2);
        enc.set_color(png::ColorType::Rgb);
        enc.set_depth(png::BitDepth::Eight);
        let png_error =
            |e: png::EncodingError| WriteError::Encode { what: "a PNG texture", source: Box::new(e) };
        let mut w = enc.write_header().map_err(png_error)?;
        w.write_image_data(&rgb).map_err(png_error)?;
    }
    Ok((out, "image/png"))
}

/// Inverse of [`TextureTransform::apply`].
fn untransform(t: &TextureTransform, uv: [f64; 2]) -> [f64; 2] {
    let (s, c) = t.rotation.sin_cos();
    let (u, v) = (uv[0] - t.offset[0], uv[1] - t.offset[1]);
    // [u; v] = R · [x sx; y sy] with R = [[c, s], [−s, c]], so [x sx; y sy] = Rᵀ · [u; v].
    let (xs, ys) = (c * u - s * v, s * u + c * v);
    [xs / t.scale[0], ys / t.scale[1]]
}

/// A tile's geometry as encoded into a GLB builder: what the primitive and node need.
struct EncodedGeometry {
    b: GlbBuilder,
    attributes: serde_json::Map<String, Value>,
    prim_ext: serde_json::Map<String, Value>,
    indices: usize,
    node: Value,
    used: Vec<&'static str>,
    required: Vec<&'static str>,
}

impl EncodedGeometry {
    fn new(node: Value) -> EncodedGeometry {
        EncodedGeometry {
            b: GlbBuilder::default(),
            attributes: serde_json::Map::new(),
            prim_ext: serde_json::Map::new(),
            indices: 0,
            node,
            used: Vec::new(),
            required: Vec::new(),
        }
    }

    fn attribute(&mut self, name: &str, accessor: usize) {
        self.attributes.insert(name.into(), json!(accessor));
    }
}

/// A tile's vertices in glTF axes, ready to encode: positions relative to the node's translation,
/// texture coordinates (with the style's texture transform undone), feature IDs and indices.
struct TileVertices {
    g: Vec<[f32; 3]>,
    uv: Vec<[f32; 2]>,
    ids: Vec<f32>,
    indices: Vec<u32>,
    node_translation: DVec3,
}

/// What the material and feature IDs of a tile need besides its geometry.
struct TileSurface<'a> {
    style: Style,
    with_ids: bool,
    ids: &'a [u32],
    image: Vec<u8>,
    mime: &'static str,
    transform: Option<TextureTransform>,
}

/// Builds one tile's GLB content.
fn tile_glb(
    style: Style,
    f: &Frames,
    mesh: &TileMesh,
    roof: [u8; 3],
    wall: [u8; 3],
) -> Result<Vec<u8>, WriteError> {
    // Tile frame (z-up) positions, their centre, and glTF (y-up) coordinates relative to it.
    let tile: Vec<DVec3> = mesh.enu.iter().map(|p| f.tile_from_enu.transform_point3(*p)).collect();
    let (lo, hi) = min_max(tile.iter().map(|p| p.to_array()));
    let centre = 0.5 * (DVec3::from_array(lo) + DVec3::from_array(hi));
    let z_to_y = UpAxis::Y.to_z_up().inverse();
    let g: Vec<[f32; 3]> =
        tile.iter().map(|p| z_to_y.transform_point3(*p - centre).as_vec3().to_array()).collect();
    let transform = (style == Style::CesiumIon).then_some(CESIUM_TEXTURE_TRANSFORM);
    let uv: Vec<[f32; 2]> = mesh
        .uv
        .iter()
        .map(|t| {
            let s = transform.as_ref().map_or(*t, |tt| untransform(tt, *t));
            [s[0] as f32, s[1] as f32]
        })
        .collect();
    let with_ids = style != Style::Google;
    let v = TileVertices {
        ids: mesh.ids.iter().map(|&i| i as f32).collect(),
        indices: (0..g.len() as u32).collect(),
        node_translation: z_to_y.transform_point3(centre),
        g,
        uv,
    };
    let (image, mime) = tile_texture(roof, wall, style == Style::Plateau)?;
    let geometry = match style {
        Style::CesiumIon | Style::Google => draco_geometry(&v, with_ids)?,
        Style::Plateau => plain_geometry(&v),
        Style::Bag3d => meshopt_geometry(&v),
    };
    finish_tile_glb(geometry, TileSurface { style, with_ids, ids: &mesh.ids, image, mime, transform })
}

/// `KHR_draco_mesh_compression` (Cesium ion and Google styles): accessors without views, one
/// compressed view.
fn draco_geometry(v: &TileVertices, with_ids: bool) -> Result<EncodedGeometry, WriteError> {
    let mut e = EncodedGeometry::new(json!({"mesh": 0, "translation": v.node_translation.to_array()}));
    let (bytes, n_points, ids_map) =
        super::compress::draco_mesh(&v.g, &v.uv, with_ids.then_some(&v.ids[..]), &v.indices)?;
    let view = e.b.push_view(&bytes, None);
    let (plo, phi) = min_max(v.g.iter().map(|p| p.map(f64::from)));
    let position = e.b.push_accessor(
        json!({"componentType": 5126, "count": n_points, "type": "VEC3", "min": plo, "max": phi}),
    );
    e.attribute("POSITION", position);
    let uv = e.b.push_accessor(json!({"componentType": 5126, "count": n_points, "type": "VEC2"}));
    e.attribute("TEXCOORD_0", uv);
    let mut dattr = json!({"POSITION": 0, "TEXCOORD_0": 1});
    if let Some(fid) = ids_map {
        let ids = e.b.push_accessor(json!({"componentType": 5126, "count": n_points, "type": "SCALAR"}));
        e.attribute("_FEATURE_ID_0", ids);
        dattr["_FEATURE_ID_0"] = json!(fid);
    }
    e.indices = e.b.push_accessor(json!({"componentType": 5125, "count": v.indices.len(), "type": "SCALAR"}));
    e.prim_ext.insert("KHR_draco_mesh_compression".into(), json!({"bufferView": view, "attributes": dattr}));
    e.used.push("KHR_draco_mesh_compression");
    e.required.push("KHR_draco_mesh_compression");
    Ok(e)
}

/// Plain FLOAT attributes and UNSIGNED_INT indices (PLATEAU style).
fn plain_geometry(v: &TileVertices) -> EncodedGeometry {
    let mut e = EncodedGeometry::new(json!({"mesh": 0, "translation": v.node_translation.to_array()}));
    let position = e.b.push_vec3(&v.g);
    e.attribute("POSITION", position);
    let uv = e.b.push_vec2(&v.uv);
    e.attribute("TEXCOORD_0", uv);
    let ids = e.b.push_scalar_f32(&v.ids);
    e.attribute("_FEATURE_ID_0", ids);
    e.indices = e.b.push_indices(&v.indices);
    e
}

/// `EXT_meshopt_compression` + `KHR_mesh_quantization` (3DBAG style): positions as UNSIGNED_SHORT
/// (padded to 8 bytes per vertex), dequantised by the node's scale and translation; UVs as
/// normalised UNSIGNED_SHORT.
fn meshopt_geometry(v: &TileVertices) -> EncodedGeometry {
    use super::compress::{meshopt_attributes, meshopt_triangles};
    let (plo, phi) = min_max(v.g.iter().map(|p| p.map(f64::from)));
    let step: Vec<f64> = (0..3).map(|k| ((phi[k] - plo[k]) / 65535.0).max(1e-9)).collect();
    let mut qpos = Vec::with_capacity(v.g.len() * 8);
    for p in &v.g {
        for k in 0..3 {
            let q = ((p[k] as f64 - plo[k]) / step[k]).round().clamp(0.0, 65535.0) as u16;
            qpos.extend_from_slice(&q.to_le_bytes());
        }
        qpos.extend_from_slice(&[0, 0]);
    }
    let mut quv = Vec::with_capacity(v.uv.len() * 4);
    for t in &v.uv {
        for &c in t {
            let q = (c as f64 * 65535.0).round().clamp(0.0, 65535.0) as u16;
            quv.extend_from_slice(&q.to_le_bytes());
        }
    }
    let qid: Vec<u8> = floats(v.ids.iter());
    let n = v.g.len();
    let t = v.node_translation + DVec3::from_array(plo);
    let mut e = EncodedGeometry::new(json!({"mesh": 0, "translation": t.to_array(), "scale": step}));
    let vp = e.b.push_meshopt_view(&meshopt_attributes(&qpos, 8), n, 8, "ATTRIBUTES", true);
    let vu = e.b.push_meshopt_view(&meshopt_attributes(&quv, 4), n, 4, "ATTRIBUTES", true);
    let vi = e.b.push_meshopt_view(&meshopt_attributes(&qid, 4), n, 4, "ATTRIBUTES", true);
    let ib: Vec<u8> = meshopt_triangles(&v.indices, n);
    let vx = e.b.push_meshopt_view(&ib, v.indices.len(), 4, "TRIANGLES", false);
    let qmax: Vec<u32> = (0..3).map(|k| ((phi[k] - plo[k]) / step[k]).round() as u32).collect();
    let position = e.b.push_accessor(
        json!({"bufferView": vp, "componentType": 5123, "count": n, "type": "VEC3", "min": [0, 0, 0], "max": qmax}),
    );
    e.attribute("POSITION", position);
    let uv = e.b.push_accessor(
        json!({"bufferView": vu, "componentType": 5123, "normalized": true, "count": n, "type": "VEC2"}),
    );
    e.attribute("TEXCOORD_0", uv);
    let ids =
        e.b.push_accessor(json!({"bufferView": vi, "componentType": 5126, "count": n, "type": "SCALAR"}));
    e.attribute("_FEATURE_ID_0", ids);
    e.indices = e.b.push_accessor(
        json!({"bufferView": vx, "componentType": 5125, "count": v.indices.len(), "type": "SCALAR"}),
    );
    e.used.extend(["EXT_meshopt_compression", "KHR_mesh_quantization"]);
    e.required.extend(["EXT_meshopt_compression", "KHR_mesh_quantization"]);
    e
}

/// The tile's GLB: the encoded geometry with its texture, material and feature IDs.
fn finish_tile_glb(geometry: EncodedGeometry, surface: TileSurface) -> Result<Vec<u8>, WriteError> {
    let EncodedGeometry { mut b, attributes, mut prim_ext, indices, node, mut used, mut required } = geometry;
    let TileSurface { style, with_ids, ids, image, mime, transform } = surface;
    let image_view = b.push_view(&image, None);
    let mut distinct: Vec<u32> = ids.to_vec();
    distinct.sort_unstable();
    distinct.dedup();
    let mut root_ext = serde_json::Map::new();
    if with_ids {
        // Feature IDs are the building IDs themselves; the property table (PLATEAU style) is indexed
        // by them, so it has max ID + 1 rows, `gml_id` "bldg_<id>" (empty for unused rows).
        let count = distinct.last().map_or(0, |&m| m as usize + 1);
        let mut set = json!({"featureCount": count, "attribute": 0});
        if style == Style::Plateau {
            set["propertyTable"] = json!(0);
            let mut strings = Vec::new();
            let mut offsets: Vec<u32> = vec![0];
            for i in 0..count as u32 {
                if distinct.binary_search(&i).is_ok() {
                    strings.extend_from_slice(format!("bldg_{i}").as_bytes());
                }
                offsets.push(strings.len() as u32);
            }
            let values = b.push_view(&strings, None);
            let offs: Vec<u8> = offsets.iter().flat_map(|o| o.to_le_bytes()).collect();
            let offsets_view = b.push_view(&offs, None);
            root_ext.insert(
                "EXT_structural_metadata".into(),
                json!({
                    "schema": {"id": "insgen", "classes": {"building": {"properties": {"gml_id": {"type": "STRING"}}}}},
                    "propertyTables": [{"class": "building", "count": count, "properties": {"gml_id": {"values": values, "stringOffsets": offsets_view}}}]
                }),
            );
            used.push("EXT_structural_metadata");
        }
        prim_ext.insert("EXT_mesh_features".into(), json!({"featureIds": [set]}));
        used.push("EXT_mesh_features");
    }
    let mut texture_info = json!({"index": 0});
    if let Some(t) = transform {
        texture_info["extensions"] =
            json!({"KHR_texture_transform": {"offset": t.offset, "rotation": t.rotation, "scale": t.scale}});
        used.push("KHR_texture_transform");
        required.push("KHR_texture_transform");
    }
    let mut material = json!({
        "name": "Material_0",
        "pbrMetallicRoughness": {"baseColorTexture": texture_info, "metallicFactor": 0.0, "roughnessFactor": 1.0},
    });
    if matches!(style, Style::CesiumIon | Style::Google) {
        material["extensions"] = json!({"KHR_materials_unlit": {}});
        used.push("KHR_materials_unlit");
    }
    let texture = if mime == "image/webp" {
        used.push("EXT_texture_webp");
        required.push("EXT_texture_webp");
        json!({"sampler": 0, "extensions": {"EXT_texture_webp": {"source": 0}}})
    } else {
        json!({"sampler": 0, "source": 0})
    };
    let mut prim = json!({"attributes": attributes, "mode": 4, "material": 0, "indices": indices});
    if !prim_ext.is_empty() {
        prim["extensions"] = Value::Object(prim_ext);
    }
    used.sort_unstable();
    used.dedup();
    required.sort_unstable();
    required.dedup();
    let mut root = json!({
        "asset": {"version": "2.0", "generator": format!("insgen ({style:?} style)")},
        "extensionsUsed": used,
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": [node],
        "meshes": [{"primitives": [prim]}],
        "materials": [material],
        "textures": [texture],
        "images": [{"name": "texture_0", "bufferView": image_view, "mimeType": mime}],
        "samplers": [{"magFilter": 9728, "minFilter": 9728, "wrapS": 33071, "wrapT": 33071}],
    });
    if !required.is_empty() {
        root["extensionsRequired"] = json!(required);
    }
    if !root_ext.is_empty() {
        root["extensions"] = Value::Object(root_ext);
    }
    Ok(b.finish(root)?)
}

/// Writes a generated city tileset of `style` into `dir` (see the module doc).
///
/// # Errors
/// No buildings with triangles; a file that cannot be written; an encoder failure.
pub fn generate_city_tileset(
    buildings: &[CityBuilding],
    enu: &EnuFrame,
    dir: &Path,
    style: Style,
) -> Result<GeneratedTileset, WriteError> {
    let (mut root, _origin, side) = quadtree(buildings)?;
    let f = frames(style, enu);
    let mut tiles = Vec::new();
    let mut colour = 0usize;
    if style == Style::CesiumIon {
        // One ADD tile: the first level-1 cell with two or more children keeps its first child's
        // buildings as its own content and refines by adding the other children.
        if let Some(c) = root.children.iter_mut().find(|c| c.children.len() >= 2) {
            let first = c.children.remove(0);
            c.buildings = first.buildings;
            c.level = u32::MAX; // marker, restored below
        }
    }
    if style == Style::Bag3d {
        return write_implicit(buildings, dir, &root, &f, side);
    }
    let t = explicit_tile(buildings, enu, style, &f, &root, "root", None, 0, side, &mut colour, &mut tiles)?;
    let mut t = t;
    t.transform = f.root_transform;
    let path = write_tileset(dir, &t, &[])?;
    Ok(GeneratedTileset { tileset: path, tiles })
}

#[allow(clippy::too_many_arguments)]
fn explicit_tile(
    buildings: &[CityBuilding],
    enu: &EnuFrame,
    style: Style,
    f: &Frames,
    cell: &Cell,
    at: &str,
    parent: Option<&str>,
    level: u32,
    side: f64,
    colour: &mut usize,
    out: &mut Vec<GeneratedTile>,
) -> Result<TileOut, WriteError> {
    let add = cell.level == u32::MAX;
    let refine = if add { Refine::Add } else { Refine::Replace };
    let mesh = tile_mesh(buildings, &cell.buildings);
    let (roof, wall) = (palette_colour(*colour), palette_colour(*colour + 1));
    *colour += 2;
    let uri = format!("tiles/{}.glb", at.replace(['[', ']', '.'], "_"));
    let content = tile_glb(style, f, &mesh, roof, wall)?;
    let mut ids: Vec<u32> = cell.buildings.iter().map(|&i| buildings[i].id.get()).collect();
    ids.sort_unstable();
    out.push(GeneratedTile {
        at: at.to_string(),
        level,
        refine,
        content_uri: uri.clone(),
        roof_rgb: roof,
        wall_rgb: wall,
        buildings: ids,
        parent: parent.map(str::to_string),
    });
    // Children's volumes must cover the parent's too for ADD (CesiumJS culls by them): an ADD tile
    // gets the union of its own and its children's buildings.
    let mut volume_members = cell.buildings.clone();
    fn all(c: &Cell, v: &mut Vec<usize>) {
        v.extend(&c.buildings);
        for k in &c.children {
            all(k, v);
        }
    }
    for c in &cell.children {
        all(c, &mut volume_members);
    }
    let volume = tile_volume(style, f, enu, &tile_mesh(buildings, &volume_members));
    let mut children = Vec::new();
    for (i, c) in cell.children.iter().enumerate() {
        let cat = format!("{at}.children[{i}]");
        children.push(explicit_tile(
            buildings,
            enu,
            style,
            f,
            c,
            &cat,
            Some(at),
            level + 1,
            side,
            colour,
            out,
        )?);
    }
    let geometric_error_m = if children.is_empty() { 0.0 } else { side / 4f64.powi(level as i32) };
    Ok(TileOut {
        bounding_volume: volume,
        geometric_error_m,
        refine: Some(refine),
        transform: None,
        content: Some((uri, content)),
        children,
        extra: Value::Null,
    })
}

/// The `Bag3d` style: an implicit quadtree whose root box is the quadtree square.
fn write_implicit(
    buildings: &[CityBuilding],
    dir: &Path,
    root: &Cell,
    f: &Frames,
    side: f64,
) -> Result<GeneratedTileset, WriteError> {
    let (lo, hi) = min_max(buildings.iter().flat_map(|b| b.positions_enu_m.iter().copied()));
    let origin = DVec3::new(lo[0], lo[1], lo[2] - 0.5);
    let height = hi[2] - lo[2] + 1.0;
    let half = DVec3::new(0.5 * side, 0.5 * side, 0.5 * height);
    let volume = BoundingVolume::Box {
        centre: f.tile_from_enu.transform_point3(origin + half),
        half_axes: DMat3::from_mat4(f.tile_from_enu) * DMat3::from_diagonal(half),
    };
    let mut tiles = Vec::new();
    let mut colour = 0usize;
    // Cells by level, with their content.
    let mut all: Vec<&Cell> = Vec::new();
    fn walk<'c>(c: &'c Cell, v: &mut Vec<&'c Cell>) {
        v.push(c);
        for k in &c.children {
            walk(k, v);
        }
    }
    walk(root, &mut all);
    for c in &all {
        let mesh = tile_mesh(buildings, &c.buildings);
        let (roof, wall) = (palette_colour(colour), palette_colour(colour + 1));
        colour += 2;
        let uri = format!("content/{}/{}/{}.glb", c.level, c.x, c.y);
        let bytes = tile_glb(Style::Bag3d, f, &mesh, roof, wall)?;
        let path = dir.join(&uri);
        crate::util::create_dir_all(path.parent().expect("content paths have folders"))?;
        crate::util::write_bytes_atomic(&path, &bytes)?;
        let mut ids: Vec<u32> = c.buildings.iter().map(|&i| buildings[i].id.get()).collect();
        ids.sort_unstable();
        let at = |l: u32, x: u64, y: u64| format!("root{{level {l}, x {x}, y {y}}}");
        let parent = (c.level > 0).then(|| at(c.level - 1, c.x / 2, c.y / 2));
        tiles.push(GeneratedTile {
            at: at(c.level, c.x, c.y),
            level: c.level,
            refine: Refine::Replace,
            content_uri: uri,
            roof_rgb: roof,
            wall_rgb: wall,
            buildings: ids,
            parent,
        });
    }
    // Subtrees: levels 0–1 in the root subtree, each level-2 cell in a subtree of its own.
    const SUBTREE_LEVELS: u32 = 2;
    let bits = |set: &[u64], n: usize| -> Vec<u8> {
        let mut b = vec![0u8; n.div_ceil(8)];
        for &i in set {
            b[(i / 8) as usize] |= 1 << (i % 8);
        }
        b
    };
    let mut root_tiles = vec![0u64];
    let mut child_subtrees = Vec::new();
    for c in &all {
        match c.level {
            1 => root_tiles.push(1 + implicit::morton_index(c.x, c.y, 0, false)),
            2 => child_subtrees.push(implicit::morton_index(c.x, c.y, 0, false)),
            _ => {}
        }
    }
    let write_subtree = |level: u32,
                         x: u64,
                         y: u64,
                         tiles_bits: Vec<u8>,
                         child_bits: Option<Vec<u8>>|
     -> Result<(), WriteError> {
        let mut bin = tiles_bits.clone();
        let mut views = vec![json!({"buffer": 0, "byteOffset": 0, "byteLength": tiles_bits.len()})];
        while !bin.len().is_multiple_of(8) {
            bin.push(0);
        }
        let child = match child_bits {
            Some(cb) => {
                views.push(json!({"buffer": 0, "byteOffset": bin.len(), "byteLength": cb.len()}));
                bin.extend_from_slice(&cb);
                json!({"bitstream": 1})
            }
            None => json!({"constant": 0}),
        };
        let j = json!({
            "buffers": [{"byteLength": bin.len()}],
            "bufferViews": views,
            "tileAvailability": {"bitstream": 0},
            "contentAvailability": [{"bitstream": 0}],
            "childSubtreeAvailability": child,
        });
        let path = implicit::template_path(dir, "subtrees/{level}/{x}/{y}.subtree", level, x, y, 0);
        crate::util::create_dir_all(path.parent().expect("subtree paths have folders"))?;
        crate::util::write_bytes_atomic(&path, &implicit::subtree_bytes(&j, &bin))?;
        Ok(())
    };
    write_subtree(0, 0, 0, bits(&root_tiles, 5), Some(bits(&child_subtrees, 16)))?;
    for c in all.iter().filter(|c| c.level == 2) {
        write_subtree(2, c.x, c.y, bits(&[0], 5), None)?;
    }
    let root_tile = TileOut {
        bounding_volume: volume,
        geometric_error_m: side,
        refine: Some(Refine::Replace),
        transform: f.root_transform,
        content: None,
        children: vec![],
        extra: json!({
            "content": {"uri": "content/{level}/{x}/{y}.glb"},
            "implicitTiling": {"subdivisionScheme": "QUADTREE", "subtreeLevels": SUBTREE_LEVELS, "availableLevels": LEVELS,
                               "subtrees": {"uri": "subtrees/{level}/{x}/{y}.subtree"}}
        }),
    };
    let path = write_tileset(dir, &root_tile, &[])?;
    Ok(GeneratedTileset { tileset: path, tiles })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn texture_transform_inverse() {
        let t = CESIUM_TEXTURE_TRANSFORM;
        for uv in [ROOF_UV, WALL_UV, [0.1, 0.9]] {
            let back = t.apply(untransform(&t, uv));
            assert!((back[0] - uv[0]).abs() < 1e-12 && (back[1] - uv[1]).abs() < 1e-12, "{uv:?} → {back:?}");
        }
    }

    #[test]
    fn palette_is_distinct() {
        let c: Vec<[u8; 3]> = (0..24).map(palette_colour).collect();
        for i in 0..24 {
            for j in 0..i {
                assert_ne!(c[i], c[j], "{i} {j}");
            }
        }
    }
}
