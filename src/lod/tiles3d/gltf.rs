//! The glTF 2.0 subset that 3D Tiles content needs, parsed in f64, and its triangles in the tile frame.
//!
//! The GLB container is split with the `gltf` crate ([`gltf::Glb`]); the JSON is then read into the
//! small spec-mirroring types below rather than into `gltf::Document`, for two reasons: `gltf-json`
//! stores node matrices and translations as f32 (an ECEF translation of 6.4e6 m would lose half a
//! metre), and it drops the extension objects 3D Tiles depends on (`CESIUM_RTC`,
//! `KHR_draco_mesh_compression`, `EXT_mesh_features`, `EXT_structural_metadata`) unless its
//! `extensions` feature is on. [`Root::validate`] checks every cross-reference and byte range before
//! anything is read, reporting all problems with their JSON path.
//!
//! # Frames
//! A vertex `p` of a primitive instanced by a node with global matrix `N` ends up at
//! `outer · U · N · p`, where `U` is the glTF up-axis correction (y-up → z-up:
//! `(x, y, z) ↦ (x, −z, y)`, as 3D Tiles specifies) and `outer` is given by the caller (tile
//! transform · RTC translations). All of it is f64.

use std::borrow::Cow;
use std::collections::BTreeMap;

use glam::{DMat4, DQuat, DVec3, DVec4};
use serde::Deserialize;
use serde_json::Value;

use super::draco;
use super::error::{AccessorProblem, ContentError, GltfIssue, GltfProblem};

/// Required extensions this reader implements or that do not affect geometry.
pub const HANDLED_EXTENSIONS: &[&str] = &[
    "CESIUM_RTC",
    "KHR_draco_mesh_compression",
    "KHR_mesh_quantization",
    "EXT_meshopt_compression",
    "KHR_texture_transform",
    "KHR_materials_unlit",
    "EXT_texture_webp",
    "EXT_mesh_features",
    "EXT_structural_metadata",
    "KHR_lights_punctual",
    "CESIUM_primitive_outline",
];
/// Prefixes of geometry-neutral (material/texture) extensions that may be required without harm.
const HANDLED_PREFIXES: &[&str] = &["KHR_materials_", "KHR_texture_", "EXT_texture_", "MSFT_texture_"];

/// Most elements an accessor without a bufferView (all zeros) may have; its count is otherwise
/// unbounded by the file size.
const MAX_ZERO_ACCESSOR: usize = 1 << 26;

/// The glTF up axis of a tileset's content (`asset.gltfUpAxis`, default Y as 3D Tiles specifies).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum UpAxis {
    /// X up.
    X,
    /// Y up (the glTF and 3D Tiles default).
    Y,
    /// Z up.
    Z,
}

impl UpAxis {
    /// The rotation taking glTF coordinates with this up axis to z-up.
    ///
    /// Y: `(x, y, z) ↦ (x, −z, y)` (a +90° rotation about x). X: `(x, y, z) ↦ (−z, y, x)` (−90° about
    /// y), as CesiumJS's `Axis.X_UP_TO_Z_UP`. Z: identity.
    pub fn to_z_up(self) -> DMat4 {
        match self {
            UpAxis::Y => DMat4::from_cols(
                DVec4::new(1.0, 0.0, 0.0, 0.0),
                DVec4::new(0.0, 0.0, 1.0, 0.0),
                DVec4::new(0.0, -1.0, 0.0, 0.0),
                DVec4::W,
            ),
            UpAxis::X => DMat4::from_cols(
                DVec4::new(0.0, 0.0, 1.0, 0.0),
                DVec4::new(0.0, 1.0, 0.0, 0.0),
                DVec4::new(-1.0, 0.0, 0.0, 0.0),
                DVec4::W,
            ),
            UpAxis::Z => DMat4::IDENTITY,
        }
    }
}

/// The glTF root object (the parts geometry extraction needs).
#[derive(Debug, Deserialize)]
#[serde(rename_all = "camelCase")]
pub(crate) struct Root {
    pub asset: Option<Asset>,
    #[serde(default)]
    pub accessors: Vec<Accessor>,
    #[serde(default)]
    pub buffer_views: Vec<BufferView>,
    #[serde(default)]
    pub buffers: Vec<Buffer>,
    #[serde(default)]
    pub meshes: Vec<Mesh>,
    #[serde(default)]
    pub nodes: Vec<Node>,
    #[serde(default)]
    pub scenes: Vec<Scene>,
    #[serde(default)]
    pub materials: Vec<Material>,
    #[serde(default)]
    pub textures: Vec<Texture>,
    #[serde(default)]
    pub images: Vec<Image>,
    #[serde(default)]
    pub samplers: Vec<Value>,
    /// Index of the scene to show; `None` = the first scene, or all root nodes when there is none.
    pub scene: Option<usize>,
    #[serde(default)]
    pub extensions_required: Vec<String>,
    #[serde(default)]
    pub extensions_used: Vec<String>,
    #[serde(default)]
    pub extensions: BTreeMap<String, Value>,
}

/// `asset`: the glTF version (`"2.0"`).
#[derive(Debug, Deserialize)]
pub(crate) struct Asset {
    pub version: String,
}

/// `accessors[i]`: a typed view into a buffer view.
#[derive(Debug, Deserialize)]
#[serde(rename_all = "camelCase")]
pub(crate) struct Accessor {
    /// `None` for all-zero accessors and for Draco-compressed attributes.
    pub buffer_view: Option<usize>,
    #[serde(default)]
    pub byte_offset: usize,
    /// 5120 BYTE, 5121 UNSIGNED_BYTE, 5122 SHORT, 5123 UNSIGNED_SHORT, 5125 UNSIGNED_INT, 5126 FLOAT.
    pub component_type: u32,
    /// Integer values map to [0, 1] (unsigned) or [−1, 1] (signed).
    #[serde(default)]
    pub normalized: bool,
    pub count: usize,
    /// `"SCALAR"`, `"VEC2"`, `"VEC3"`, `"VEC4"`, `"MAT2"`, `"MAT3"`, `"MAT4"`.
    #[serde(rename = "type")]
    pub kind: String,
    pub sparse: Option<Sparse>,
}

/// `accessors[i].sparse`: values that replace some elements of the base accessor.
#[derive(Debug, Deserialize)]
pub(crate) struct Sparse {
    pub count: usize,
    pub indices: SparseIndices,
    pub values: SparseValues,
}

#[derive(Debug, Deserialize)]
#[serde(rename_all = "camelCase")]
pub(crate) struct SparseIndices {
    pub buffer_view: usize,
    #[serde(default)]
    pub byte_offset: usize,
    pub component_type: u32,
}

#[derive(Debug, Deserialize)]
#[serde(rename_all = "camelCase")]
pub(crate) struct SparseValues {
    pub buffer_view: usize,
    #[serde(default)]
    pub byte_offset: usize,
}

/// `bufferViews[i]`: a byte range of a buffer.
#[derive(Debug, Deserialize)]
#[serde(rename_all = "camelCase")]
pub(crate) struct BufferView {
    pub buffer: usize,
    #[serde(default)]
    pub byte_offset: usize,
    pub byte_length: usize,
    /// Bytes between the starts of consecutive elements; `None` = tightly packed.
    pub byte_stride: Option<usize>,
    /// `EXT_meshopt_compression` (the data is decoded from another buffer).
    #[serde(default)]
    pub extensions: BTreeMap<String, Value>,
}

/// `buffers[i]`: the GLB BIN chunk (no `uri`), a file next to the glTF, or a `data:` URI.
#[derive(Debug, Deserialize)]
#[serde(rename_all = "camelCase")]
pub(crate) struct Buffer {
    pub byte_length: usize,
    pub uri: Option<String>,
    /// `EXT_meshopt_compression: {"fallback": true}` marks a buffer with no data of its own.
    #[serde(default)]
    pub extensions: BTreeMap<String, Value>,
}

impl Buffer {
    fn is_meshopt_fallback(&self) -> bool {
        self.extensions
            .get("EXT_meshopt_compression")
            .and_then(|e| e.get("fallback"))
            .and_then(Value::as_bool)
            .unwrap_or(false)
    }
}

/// `materials[i]` (the parts a photogrammetry look needs).
#[derive(Debug, Clone, Default, Deserialize)]
#[serde(rename_all = "camelCase")]
pub struct Material {
    /// `name`.
    pub name: Option<String>,
    /// `pbrMetallicRoughness`: base colour factor and texture.
    pub pbr_metallic_roughness: Option<PbrMetallicRoughness>,
    /// `emissiveTexture`.
    pub emissive_texture: Option<TextureInfo>,
    /// `emissiveFactor`, linear RGB.
    pub emissive_factor: Option<[f64; 3]>,
    /// `doubleSided`.
    #[serde(default)]
    pub double_sided: bool,
    /// `KHR_materials_unlit` (an empty object) and others.
    #[serde(default)]
    pub extensions: BTreeMap<String, Value>,
}

impl Material {
    /// Whether the material is `KHR_materials_unlit`.
    pub fn unlit(&self) -> bool {
        self.extensions.contains_key("KHR_materials_unlit")
    }
    /// The base colour texture, if any.
    pub fn base_color_texture(&self) -> Option<&TextureInfo> {
        self.pbr_metallic_roughness.as_ref().and_then(|p| p.base_color_texture.as_ref())
    }
    /// Linear RGBA base colour factor (default white).
    pub fn base_color_factor(&self) -> [f64; 4] {
        self.pbr_metallic_roughness.as_ref().and_then(|p| p.base_color_factor).unwrap_or([1.0; 4])
    }
}

/// `materials[i].pbrMetallicRoughness`.
#[derive(Debug, Clone, Default, Deserialize)]
#[serde(rename_all = "camelCase")]
pub struct PbrMetallicRoughness {
    /// `baseColorFactor`, linear RGBA.
    pub base_color_factor: Option<[f64; 4]>,
    /// `baseColorTexture`.
    pub base_color_texture: Option<TextureInfo>,
}

/// A texture reference: texture index, UV set, and `KHR_texture_transform`.
#[derive(Debug, Clone, Deserialize)]
#[serde(rename_all = "camelCase")]
pub struct TextureInfo {
    /// Index into `textures`.
    pub index: usize,
    /// `texCoord`: the UV set (`TEXCOORD_n`).
    #[serde(default)]
    pub tex_coord: usize,
    /// `KHR_texture_transform` and others.
    #[serde(default)]
    pub extensions: BTreeMap<String, Value>,
}

/// `KHR_texture_transform`: `uv' = T(offset) · R(rotation) · S(scale) · uv`, optionally on another
/// UV set.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(rename_all = "camelCase")]
pub struct TextureTransform {
    /// Translation, UV units.
    #[serde(default)]
    pub offset: [f64; 2],
    /// Radians, counter-clockwise in UV space.
    #[serde(default)]
    pub rotation: f64,
    /// Scale factors (u, v).
    #[serde(default = "unit_scale")]
    pub scale: [f64; 2],
    /// The UV set it applies to instead of the texture info's `texCoord`.
    pub tex_coord: Option<usize>,
}

fn unit_scale() -> [f64; 2] {
    [1.0, 1.0]
}

impl TextureTransform {
    /// Applies the transform to one UV (the spec's matrix, rows
    /// `[sx·cos, sy·sin, ox]`, `[−sx·sin, sy·cos, oy]`).
    pub fn apply(&self, uv: [f64; 2]) -> [f64; 2] {
        let (s, c) = self.rotation.sin_cos();
        let (x, y) = (uv[0] * self.scale[0], uv[1] * self.scale[1]);
        [c * x + s * y + self.offset[0], -s * x + c * y + self.offset[1]]
    }
}

impl TextureInfo {
    /// The `KHR_texture_transform` of this reference, if any.
    ///
    /// # Errors
    /// [`ContentError::Json`] when the extension object is malformed, [`ContentError::NotFinite`]
    /// (offset, rotation, scale) when a number is not finite; paths are relative to the reference.
    pub fn transform(&self) -> Result<Option<TextureTransform>, ContentError> {
        let Some(v) = self.extensions.get("KHR_texture_transform") else { return Ok(None) };
        let t: TextureTransform = serde_json::from_value(v.clone())
            .map_err(|source| ContentError::Json { at: "extensions.KHR_texture_transform".into(), source })?;
        if !(t.offset.iter().chain(&t.scale).all(|v| v.is_finite()) && t.rotation.is_finite()) {
            let values = [t.offset[0], t.offset[1], t.rotation, t.scale[0], t.scale[1]].to_vec();
            return Err(ContentError::NotFinite {
                at: "extensions.KHR_texture_transform (offset, rotation, scale)",
                values,
            });
        }
        Ok(Some(t))
    }
    /// The UV set the texture reads (the transform's `texCoord` overrides the reference's).
    ///
    /// # Errors
    /// As [`TextureInfo::transform`].
    pub fn uv_set(&self) -> Result<usize, ContentError> {
        Ok(self.transform()?.and_then(|t| t.tex_coord).unwrap_or(self.tex_coord))
    }
}

/// `textures[i]`: an image (`source`, or an extension's) and a sampler.
#[derive(Debug, Clone, Default, Deserialize)]
#[serde(rename_all = "camelCase")]
pub struct Texture {
    /// Index into `images`.
    pub source: Option<usize>,
    /// Index into `samplers`.
    pub sampler: Option<usize>,
    /// `EXT_texture_webp`, `KHR_texture_basisu`, `MSFT_texture_dds`: `{"source": i}`.
    #[serde(default)]
    pub extensions: BTreeMap<String, Value>,
}

/// `images[i]`: a file, a data URI, or a buffer view with a MIME type.
#[derive(Debug, Clone, Default, Deserialize)]
#[serde(rename_all = "camelCase")]
pub struct Image {
    /// Relative path or `data:` URI.
    pub uri: Option<String>,
    /// Buffer view holding the bytes (GLB-embedded images).
    pub buffer_view: Option<usize>,
    /// `image/png`, `image/jpeg`, `image/webp`, …
    pub mime_type: Option<String>,
    /// `name`.
    pub name: Option<String>,
}

/// `meshes[i]`.
#[derive(Debug, Deserialize)]
pub(crate) struct Mesh {
    #[serde(default)]
    pub primitives: Vec<Primitive>,
}

/// `meshes[i].primitives[j]`.
#[derive(Debug, Deserialize)]
pub(crate) struct Primitive {
    /// Attribute semantic (`POSITION`, `_BATCHID`, `_FEATURE_ID_0`…) → accessor index.
    #[serde(default)]
    pub attributes: BTreeMap<String, usize>,
    pub indices: Option<usize>,
    /// 0 POINTS, 1 LINES, 2 LINE_LOOP, 3 LINE_STRIP, 4 TRIANGLES (default), 5 TRIANGLE_STRIP,
    /// 6 TRIANGLE_FAN.
    #[serde(default = "triangles_mode")]
    pub mode: u32,
    pub material: Option<usize>,
    #[serde(default)]
    pub extensions: BTreeMap<String, Value>,
}

fn triangles_mode() -> u32 {
    4
}

/// `nodes[i]`: a transform (matrix, or translation · rotation · scale) with children and a mesh.
#[derive(Debug, Deserialize)]
pub(crate) struct Node {
    #[serde(default)]
    pub children: Vec<usize>,
    pub mesh: Option<usize>,
    /// Column-major 4×4.
    pub matrix: Option<[f64; 16]>,
    pub translation: Option<[f64; 3]>,
    /// Unit quaternion `[x, y, z, w]`.
    pub rotation: Option<[f64; 4]>,
    pub scale: Option<[f64; 3]>,
}

/// `scenes[i]`.
#[derive(Debug, Deserialize)]
pub(crate) struct Scene {
    #[serde(default)]
    pub nodes: Vec<usize>,
}

/// `KHR_draco_mesh_compression` on a primitive.
#[derive(Debug, Deserialize)]
#[serde(rename_all = "camelCase")]
struct DracoExtension {
    buffer_view: usize,
    /// Attribute semantic → Draco attribute unique id.
    attributes: BTreeMap<String, u32>,
}

/// `EXT_mesh_features` on a primitive.
#[derive(Debug, Deserialize)]
#[serde(rename_all = "camelCase")]
struct MeshFeatures {
    #[serde(default)]
    feature_ids: Vec<FeatureIdSet>,
}

/// One entry of `EXT_mesh_features.featureIds`.
#[derive(Debug, Deserialize)]
#[serde(rename_all = "camelCase")]
struct FeatureIdSet {
    feature_count: u64,
    /// `n` for the vertex attribute `_FEATURE_ID_n`; `None` for texture or implicit IDs.
    attribute: Option<u32>,
    property_table: Option<usize>,
    null_feature_id: Option<u64>,
}

/// `CESIUM_RTC` on the root: positions are relative to `center` (in the z-up tile frame).
#[derive(Debug, Deserialize)]
struct CesiumRtc {
    center: [f64; 3],
}

/// Which table gives a primitive's feature IDs their meaning.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub(crate) enum TableKey {
    /// The b3dm batch table (`_BATCHID`).
    Batch,
    /// `EXT_structural_metadata.propertyTables[i]`.
    Property(usize),
    /// `EXT_mesh_features` IDs without a property table (set index, feature count).
    Anonymous(usize, u64),
}

/// Per-vertex feature IDs of one primitive; `None` marks the set's `nullFeatureId`.
#[derive(Debug, Clone)]
pub(crate) struct FeatureIds {
    pub table: TableKey,
    pub ids: Vec<Option<u32>>,
}

/// What of a primitive's surface to decode besides positions and feature IDs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Surface {
    /// Geometry only (the LoD reader).
    No,
    /// Also the base colour UVs (with `KHR_texture_transform` applied), the material and the raw
    /// `_FEATURE_ID_0` values (the importable GLB for Blender).
    Yes,
}

/// A primitive's triangles in its mesh's local frame.
#[derive(Debug, Clone)]
struct LocalPrimitive {
    positions: Vec<[f64; 3]>,
    triangles: Vec<[u32; 3]>,
    features: Option<FeatureIds>,
    uv: Option<Vec<[f64; 2]>>,
    feature_id0: Option<Vec<f64>>,
}

/// A primitive instance with positions in the caller's frame (`outer · U · node · p`).
#[derive(Debug, Clone)]
pub(crate) struct WorldPrimitive {
    pub positions: Vec<[f64; 3]>,
    pub triangles: Vec<[u32; 3]>,
    pub features: Option<FeatureIds>,
    /// Base colour UVs, `KHR_texture_transform` applied ([`Surface::Yes`] only).
    pub uv: Option<Vec<[f64; 2]>>,
    /// `materials[i]` of the primitive.
    pub material: Option<usize>,
    /// The `_FEATURE_ID_0` vertex attribute as stored ([`Surface::Yes`] only).
    pub feature_id0: Option<Vec<f64>>,
}

/// A parsed glTF asset with its buffers' bytes.
pub(crate) struct Gltf<'a> {
    pub root: Root,
    pub buffers: Vec<Cow<'a, [u8]>>,
    /// Buffer views decoded from `EXT_meshopt_compression`, by view index.
    pub decoded_views: Vec<Option<Vec<u8>>>,
}

/// Splits a GLB and parses its JSON. `load_uri` loads buffers that have a `uri`.
///
/// # Errors
/// [`ContentError`] saying what is wrong where (the caller adds the file name).
pub(crate) fn parse_glb<'a>(bytes: &'a [u8], load_uri: &LoadUri<'_>) -> Result<Gltf<'a>, ContentError> {
    let glb = crate::util::glb::read(bytes)?;
    let root = parse_json(&glb.json)?;
    let bin = glb.bin;
    let mut buffers = Vec::with_capacity(root.buffers.len());
    for (i, b) in root.buffers.iter().enumerate() {
        if b.uri.is_none() && b.is_meshopt_fallback() && !(i == 0 && bin.is_some()) {
            buffers.push(Cow::Owned(Vec::new()));
            continue;
        }
        match (&b.uri, i) {
            (None, 0) => match &bin {
                Some(bin) => buffers.push(bin.clone()),
                None => return Err(ContentError::NoBinChunk),
            },
            (None, index) => return Err(ContentError::GlbBufferWithoutUri { index }),
            (Some(uri), _) => buffers.push(Cow::Owned(load_buffer_uri(i, uri, load_uri)?)),
        }
    }
    finish(root, buffers)
}

/// Parses a `.gltf` JSON asset; every buffer needs a `uri`.
///
/// # Errors
/// As [`parse_glb`].
pub(crate) fn parse_gltf_json<'a>(bytes: &[u8], load_uri: &LoadUri<'_>) -> Result<Gltf<'a>, ContentError> {
    let root = parse_json(bytes)?;
    let mut buffers = Vec::with_capacity(root.buffers.len());
    for (i, b) in root.buffers.iter().enumerate() {
        match &b.uri {
            None if b.is_meshopt_fallback() => buffers.push(Cow::Owned(Vec::new())),
            Some(uri) => buffers.push(Cow::Owned(load_buffer_uri(i, uri, load_uri)?)),
            None => return Err(ContentError::GltfBufferWithoutUri { index: i }),
        }
    }
    finish(root, buffers)
}

fn parse_json(json: &[u8]) -> Result<Root, ContentError> {
    // GLB pads the JSON chunk with spaces; some writers pad with NULs.
    let end = json.iter().rposition(|&b| b != 0 && b != b' ').map_or(0, |i| i + 1);
    let root: Root = serde_json::from_slice(&json[..end]).map_err(ContentError::GltfJson)?;
    if let Some(asset) = &root.asset {
        if !asset.version.starts_with("2.") {
            return Err(ContentError::AssetVersion { version: asset.version.clone() });
        }
    }
    Ok(root)
}

fn finish<'a>(root: Root, buffers: Vec<Cow<'a, [u8]>>) -> Result<Gltf<'a>, ContentError> {
    let unsupported: Vec<String> = root
        .extensions_required
        .iter()
        .filter(|e| {
            !HANDLED_EXTENSIONS.contains(&e.as_str()) && !HANDLED_PREFIXES.iter().any(|p| e.starts_with(p))
        })
        .cloned()
        .collect();
    if !unsupported.is_empty() {
        return Err(ContentError::UnsupportedExtensions { extensions: unsupported });
    }
    let mut gltf = Gltf { root, buffers, decoded_views: Vec::new() };
    let issues = gltf.validate();
    if !issues.is_empty() {
        return Err(ContentError::Invalid { issues });
    }
    gltf.decode_meshopt_views()?;
    Ok(gltf)
}

/// Loads the file a relative URI names (buffers, images, schemas), relative to the glTF.
pub(crate) type LoadUri<'a> = dyn Fn(&str) -> Result<Vec<u8>, ContentError> + 'a;

/// The bytes of a `data:` URI with a base64 payload.
///
/// # Errors
/// [`ContentError::DataUriNotBase64`] or [`ContentError::DataUriBase64`], with the URI's start.
pub(crate) fn data_uri_bytes(uri: &str) -> Result<Vec<u8>, ContentError> {
    let head = || uri.chars().take(40).collect::<String>();
    let (_, data) = uri
        .strip_prefix("data:")
        .and_then(|rest| rest.split_once(";base64,"))
        .ok_or_else(|| ContentError::DataUriNotBase64 { head: head() })?;
    base64_decode(data).ok_or_else(|| ContentError::DataUriBase64 { head: head() })
}

/// The bytes of `buffers[index]`, whose `uri` is a `data:` URI or a file.
fn load_buffer_uri(index: usize, uri: &str, load_uri: &LoadUri<'_>) -> Result<Vec<u8>, ContentError> {
    if uri.starts_with("data:") {
        return data_uri_bytes(uri).map_err(|e| e.at(format!("buffers[{index}]")));
    }
    load_uri(uri)
}

/// Decodes standard base64 (with or without padding).
pub(crate) fn base64_decode(s: &str) -> Option<Vec<u8>> {
    let mut out = Vec::with_capacity(s.len() * 3 / 4);
    let (mut acc, mut bits) = (0u32, 0u32);
    for c in s.bytes().filter(|&c| c != b'=' && !c.is_ascii_whitespace()) {
        let v = match c {
            b'A'..=b'Z' => c - b'A',
            b'a'..=b'z' => c - b'a' + 26,
            b'0'..=b'9' => c - b'0' + 52,
            b'+' | b'-' => 62,
            b'/' | b'_' => 63,
            _ => return None,
        } as u32;
        acc = (acc << 6) | v;
        bits += 6;
        if bits >= 8 {
            bits -= 8;
            out.push((acc >> bits) as u8);
        }
    }
    Some(out)
}

/// Number of components of an accessor type.
fn components(kind: &str) -> Option<usize> {
    Some(match kind {
        "SCALAR" => 1,
        "VEC2" => 2,
        "VEC3" => 3,
        "VEC4" | "MAT2" => 4,
        "MAT3" => 9,
        "MAT4" => 16,
        _ => return None,
    })
}

/// Byte size of an accessor component type.
fn component_size(component_type: u32) -> Option<usize> {
    Some(match component_type {
        5120 | 5121 => 1,
        5122 | 5123 => 2,
        5125 | 5126 => 4,
        _ => return None,
    })
}

/// Reads one component of type `component_type` at `bytes[0..size]`, normalising integers if asked.
fn read_component(bytes: &[u8], component_type: u32, normalized: bool) -> f64 {
    match component_type {
        5120 => {
            let v = bytes[0] as i8 as f64;
            if normalized {
                (v / 127.0).max(-1.0)
            } else {
                v
            }
        }
        5121 => {
            let v = bytes[0] as f64;
            if normalized {
                v / 255.0
            } else {
                v
            }
        }
        5122 => {
            let v = i16::from_le_bytes([bytes[0], bytes[1]]) as f64;
            if normalized {
                (v / 32767.0).max(-1.0)
            } else {
                v
            }
        }
        5123 => {
            let v = u16::from_le_bytes([bytes[0], bytes[1]]) as f64;
            if normalized {
                v / 65535.0
            } else {
                v
            }
        }
        5125 => u32::from_le_bytes([bytes[0], bytes[1], bytes[2], bytes[3]]) as f64,
        _ => f32::from_le_bytes([bytes[0], bytes[1], bytes[2], bytes[3]]) as f64,
    }
}

impl<'a> Gltf<'a> {
    /// Checks every index and byte range; returns all problems, each with its JSON path.
    fn validate(&self) -> Vec<GltfIssue> {
        let mut v = Validator { gltf: self, issues: Vec::new() };
        v.buffers();
        v.buffer_views();
        v.accessors();
        v.meshes();
        v.nodes();
        v.scenes();
        v.issues
    }

    /// The `CESIUM_RTC.center` translation, if any.
    ///
    /// # Errors
    /// [`ContentError::CesiumRtc`] when the extension is not `{"center": [x, y, z]}`,
    /// [`ContentError::NotFinite`] when the centre is not finite.
    pub(crate) fn cesium_rtc(&self) -> Result<Option<[f64; 3]>, ContentError> {
        match self.root.extensions.get("CESIUM_RTC") {
            None => Ok(None),
            Some(v) => {
                let rtc: CesiumRtc = serde_json::from_value(v.clone()).map_err(ContentError::CesiumRtc)?;
                if rtc.center.iter().any(|c| !c.is_finite()) {
                    return Err(ContentError::NotFinite {
                        at: "extensions.CESIUM_RTC.center",
                        values: rtc.center.to_vec(),
                    });
                }
                Ok(Some(rtc.center))
            }
        }
    }

    /// Decodes every `EXT_meshopt_compression` buffer view into [`Gltf::decoded_views`].
    fn decode_meshopt_views(&mut self) -> Result<(), ContentError> {
        let mut decoded = vec![None; self.root.buffer_views.len()];
        for (i, v) in self.root.buffer_views.iter().enumerate() {
            let Some(ext) = v.extensions.get("EXT_meshopt_compression") else { continue };
            let at = format!("bufferViews[{i}].extensions.EXT_meshopt_compression");
            let ext: super::meshopt::MeshoptView = serde_json::from_value(ext.clone())
                .map_err(|source| ContentError::Json { at: at.clone(), source })?;
            let buf = self.buffers.get(ext.buffer).ok_or_else(|| {
                ContentError::Missing { what: "buffer", index: ext.buffer }.at(format!("{at}.buffer"))
            })?;
            let src = ext
                .byte_offset
                .checked_add(ext.byte_length)
                .and_then(|e| buf.get(ext.byte_offset..e))
                .ok_or(ContentError::MeshoptRange {
                    view: i,
                    offset: ext.byte_offset,
                    len: ext.byte_length,
                    buffer: ext.buffer,
                    buffer_len: buf.len(),
                })?;
            let out = super::meshopt::decode(&ext, src)
                .map_err(|source| ContentError::Meshopt { view: i, source })?;
            if out.len() < v.byte_length {
                return Err(ContentError::MeshoptShort {
                    view: i,
                    decoded: out.len(),
                    byte_length: v.byte_length,
                });
            }
            decoded[i] = Some(out);
        }
        self.decoded_views = decoded;
        Ok(())
    }

    /// The bytes of `bufferViews[i]` (validated to lie inside its buffer, or decoded from
    /// `EXT_meshopt_compression`).
    ///
    /// # Errors
    /// [`ContentError::Missing`] or [`ContentError::ViewRange`] for a view that validation did not
    /// check (one named by an extension).
    pub(crate) fn view_bytes(&self, i: usize) -> Result<&[u8], ContentError> {
        if let Some(Some(d)) = self.decoded_views.get(i) {
            let len = self.root.buffer_views[i].byte_length;
            return Ok(&d[..len]);
        }
        let v =
            self.root.buffer_views.get(i).ok_or(ContentError::Missing { what: "bufferView", index: i })?;
        let buf =
            self.buffers.get(v.buffer).ok_or(ContentError::Missing { what: "buffer", index: v.buffer })?;
        buf.get(v.byte_offset..v.byte_offset + v.byte_length)
            .ok_or(ContentError::ViewRange { view: i, buffer: v.buffer })
    }

    /// Reads accessor `i`, referenced at JSON path `at`, as `count × components` f64 values
    /// (normalised integers mapped to [0, 1] or [−1, 1]; sparse substitutions applied). Byte ranges
    /// were checked by `validate`.
    fn read_accessor(&self, i: usize, at: &str) -> Result<(usize, Vec<f64>), ContentError> {
        let r = &self.root;
        let bad = |problem| ContentError::Accessor { at: at.to_string(), accessor: Some(i), problem };
        let a =
            r.accessors.get(i).ok_or_else(|| ContentError::Missing { what: "accessor", index: i }.at(at))?;
        let n =
            components(&a.kind).ok_or_else(|| bad(AccessorProblem::UnknownType { kind: a.kind.clone() }))?;
        let size = component_size(a.component_type)
            .ok_or_else(|| bad(AccessorProblem::UnknownComponentType { component_type: a.component_type }))?;
        if a.buffer_view.is_none() && a.count > MAX_ZERO_ACCESSOR {
            return Err(bad(AccessorProblem::ZeroFilled { count: a.count }));
        }
        let mut out = vec![0.0; a.count * n];
        let view_bytes = |v: usize| self.view_bytes(v).map_err(|e| e.at(format!("accessors[{i}]")));
        if let Some(bv) = a.buffer_view {
            let stride = r.buffer_views[bv].byte_stride.unwrap_or(n * size);
            let bytes = view_bytes(bv)?;
            for (e, chunk) in out.chunks_exact_mut(n).enumerate() {
                let start = a.byte_offset + e * stride;
                for (c, slot) in chunk.iter_mut().enumerate() {
                    let at = start + c * size;
                    *slot = read_component(&bytes[at..at + size], a.component_type, a.normalized);
                }
            }
        }
        if let Some(s) = &a.sparse {
            let idx_bytes = view_bytes(s.indices.buffer_view)?;
            let val_bytes = view_bytes(s.values.buffer_view)?;
            let isize = component_size(s.indices.component_type).unwrap_or(4);
            for k in 0..s.count {
                let at = s.indices.byte_offset + k * isize;
                let e = read_component(&idx_bytes[at..at + isize], s.indices.component_type, false) as usize;
                if e >= a.count {
                    return Err(bad(AccessorProblem::SparseIndex { index: e, count: a.count }));
                }
                for c in 0..n {
                    let at = s.values.byte_offset + (k * n + c) * size;
                    out[e * n + c] =
                        read_component(&val_bytes[at..at + size], a.component_type, a.normalized);
                }
            }
        }
        Ok((n, out))
    }

    /// All primitive instances of the default scene, with positions in `outer · up · node` frame.
    /// Returns them with the number of primitives skipped because they are points or lines.
    ///
    /// # Errors
    /// [`ContentError`] naming the glTF object that is wrong by its JSON path.
    pub(crate) fn world_primitives(
        &self,
        outer: DMat4,
        up: UpAxis,
        surface: Surface,
    ) -> Result<(Vec<WorldPrimitive>, u64), ContentError> {
        let r = &self.root;
        let roots: Vec<usize> = match r.scene.or(if r.scenes.is_empty() { None } else { Some(0) }) {
            Some(s) => r.scenes[s].nodes.clone(),
            None => {
                let mut is_child = vec![false; r.nodes.len()];
                for n in &r.nodes {
                    for &c in &n.children {
                        is_child[c] = true;
                    }
                }
                (0..r.nodes.len()).filter(|&i| !is_child[i]).collect()
            }
        };
        let base = outer * up.to_z_up();
        // Decoded primitives, by (mesh, primitive), shared by every node that instances the mesh.
        let mut local: BTreeMap<(usize, usize), Option<LocalPrimitive>> = BTreeMap::new();
        let mut out = Vec::new();
        let mut skipped = 0u64;
        // Depth-first over the node tree. `validate` ensured no node has two parents, so a walk
        // deeper than the node count can only be a cycle.
        let mut stack: Vec<(usize, DMat4, usize)> = roots.iter().rev().map(|&n| (n, base, 0)).collect();
        while let Some((n, parent, depth)) = stack.pop() {
            if depth > r.nodes.len() {
                return Err(ContentError::NodeCycle { node: n });
            }
            let node = &r.nodes[n];
            let world = parent * node_matrix(node);
            if let Some(m) = node.mesh {
                for k in 0..r.meshes[m].primitives.len() {
                    if let std::collections::btree_map::Entry::Vacant(slot) = local.entry((m, k)) {
                        let decoded = self.local_primitive(m, k, surface)?;
                        if decoded.is_none() {
                            skipped += 1;
                        }
                        slot.insert(decoded);
                    }
                    if let Some(Some(lp)) = local.get(&(m, k)) {
                        let positions = lp
                            .positions
                            .iter()
                            .map(|p| world.transform_point3(DVec3::from_array(*p)).to_array())
                            .collect();
                        out.push(WorldPrimitive {
                            positions,
                            triangles: lp.triangles.clone(),
                            features: lp.features.clone(),
                            uv: lp.uv.clone(),
                            material: r.meshes[m].primitives[k].material,
                            feature_id0: lp.feature_id0.clone(),
                        });
                    }
                }
            }
            for &c in node.children.iter().rev() {
                stack.push((c, world, depth + 1));
            }
        }
        Ok((out, skipped))
    }

    /// Decodes `meshes[m].primitives[k]` in its local frame; `None` for points and lines. Errors
    /// carry JSON paths from the glTF root (`meshes[0].primitives[1].attributes["POSITION"]`).
    fn local_primitive(
        &self,
        m: usize,
        k: usize,
        surface: Surface,
    ) -> Result<Option<LocalPrimitive>, ContentError> {
        let prim = &self.root.meshes[m].primitives[k];
        if !(4..=6).contains(&prim.mode) {
            return Ok(None);
        }
        let at = format!("meshes[{m}].primitives[{k}]");
        let attribute_at = |name: &str| format!("{at}.attributes[\"{name}\"]");
        let feature_set = self.feature_set(prim, &at)?;
        let texture = match surface {
            Surface::Yes => self.base_color_texture(prim, &at)?,
            Surface::No => None,
        };
        let uv_name = texture.map(|(set, _)| format!("TEXCOORD_{set}"));
        let draco_at = format!("{at}.extensions.KHR_draco_mesh_compression");
        let mut raw = match prim.extensions.get("KHR_draco_mesh_compression") {
            Some(v) => {
                let ext = serde_json::from_value::<DracoExtension>(v.clone())
                    .map_err(|source| ContentError::Json { at: draco_at.clone(), source })?;
                let feature = feature_set.as_ref().map(|(name, _, _)| name.as_str());
                self.draco_geometry(&ext, &draco_at, feature, uv_name.as_deref(), surface)?
            }
            None => self.accessor_geometry(prim, &at)?,
        };
        // Attributes stored outside Draco (or all of them, without Draco).
        if let Some(name) = &uv_name {
            if raw.uv.is_none() {
                if let Some(&acc) = prim.attributes.get(name) {
                    raw.uv = Some(self.read_typed(acc, attribute_at(name), "VEC2")?);
                }
            }
        }
        if surface == Surface::Yes && raw.feature_id0.is_none() {
            if let Some(&acc) = prim.attributes.get(FEATURE_ID_0) {
                raw.feature_id0 = Some(self.read_typed(acc, attribute_at(FEATURE_ID_0), "SCALAR")?);
            }
        }
        check_geometry(&at, &raw.positions, &raw.triangles)?;
        let n_vertices = raw.positions.len();
        // A per-vertex attribute (from an accessor, or from Draco) with the wrong number of values.
        let count_error = |name: &str, values: usize| ContentError::Accessor {
            at: attribute_at(name),
            accessor: prim.attributes.get(name).copied(),
            problem: AccessorProblem::Count { values, vertices: n_vertices },
        };
        let uv = match raw.uv {
            None => None,
            Some(flat) => {
                if flat.len() != 2 * n_vertices {
                    let name = uv_name.as_deref().unwrap_or("TEXCOORD_0");
                    return Err(count_error(name, flat.len() / 2));
                }
                let transform = texture.and_then(|(_, t)| t);
                Some(
                    flat.chunks_exact(2)
                        .map(|c| transform.map_or([c[0], c[1]], |t| t.apply([c[0], c[1]])))
                        .collect(),
                )
            }
        };
        if let Some(f) = &raw.feature_id0 {
            if f.len() != n_vertices {
                return Err(count_error(FEATURE_ID_0, f.len()));
            }
        }
        let features = match feature_set {
            None => None,
            Some((name, table, null_id)) => {
                let values = match raw.features.take() {
                    Some(v) => v,
                    None => self.read_typed(prim.attributes[&name], attribute_at(&name), "SCALAR")?,
                };
                if values.len() != n_vertices {
                    return Err(count_error(&name, values.len()));
                }
                let ids = feature_ids(values, null_id).map_err(|value| ContentError::Accessor {
                    at: attribute_at(&name),
                    accessor: prim.attributes.get(&name).copied(),
                    problem: AccessorProblem::NotFeatureId { value },
                })?;
                Some(FeatureIds { table, ids })
            }
        };
        let RawPrimitive { positions, triangles, feature_id0, .. } = raw;
        Ok(Some(LocalPrimitive { positions, triangles, features, uv, feature_id0 }))
    }

    /// The UV set and `KHR_texture_transform` of the base colour texture of the primitive's (at
    /// JSON path `at`) material; `None` without material or texture.
    fn base_color_texture(
        &self,
        prim: &Primitive,
        at: &str,
    ) -> Result<Option<(usize, Option<TextureTransform>)>, ContentError> {
        let Some(mi) = prim.material else { return Ok(None) };
        let mat = self.root.materials.get(mi).ok_or_else(|| {
            ContentError::Missing { what: "material", index: mi }.at(format!("{at}.material"))
        })?;
        let Some(t) = mat.base_color_texture() else { return Ok(None) };
        let texture_at = || format!("materials[{mi}].pbrMetallicRoughness.baseColorTexture");
        let uv_set = t.uv_set().map_err(|e| e.at(texture_at()))?;
        let transform = t.transform().map_err(|e| e.at(texture_at()))?;
        Ok(Some((uv_set, transform)))
    }

    /// Positions, triangles and the wanted attributes (feature IDs, UVs named `uv`, and
    /// `_FEATURE_ID_0` for [`Surface::Yes`]) decoded from `KHR_draco_mesh_compression` (at
    /// JSON path `draco_at`).
    fn draco_geometry(
        &self,
        ext: &DracoExtension,
        draco_at: &str,
        feature: Option<&str>,
        uv: Option<&str>,
        surface: Surface,
    ) -> Result<RawPrimitive, ContentError> {
        let pos_id = *ext
            .attributes
            .get("POSITION")
            .ok_or_else(|| ContentError::NoPosition { at: format!("{draco_at}.attributes") })?;
        // (unique id, components) of each wanted attribute, and where it lands.
        let mut wanted: Vec<(u32, usize)> = Vec::new();
        let mut slot = |name: Option<&str>, n: usize| -> Option<usize> {
            let id = *ext.attributes.get(name?)?;
            wanted.push((id, n));
            Some(wanted.len() - 1)
        };
        let f_slot = slot(feature, 1);
        let uv_slot = slot(uv, 2);
        let fid0_slot = if surface == Surface::Yes { slot(Some(FEATURE_ID_0), 1) } else { None };
        let bytes = self.view_bytes(ext.buffer_view).map_err(|e| e.at(format!("{draco_at}.bufferView")))?;
        let mut d = draco::decode(bytes, pos_id, &wanted)
            .map_err(|source| ContentError::Draco { at: draco_at.to_string(), source })?;
        let mut take = |s: Option<usize>| s.map(|i| std::mem::take(&mut d.attributes[i]));
        let (features, uv, feature_id0) = (take(f_slot), take(uv_slot), take(fid0_slot));
        Ok(RawPrimitive { positions: d.positions, triangles: d.triangles, features, uv, feature_id0 })
    }

    /// Positions and triangles (assembled from `indices` and the mode) of an uncompressed
    /// primitive at JSON path `at`; its other attributes are read by the caller.
    fn accessor_geometry(&self, prim: &Primitive, at: &str) -> Result<RawPrimitive, ContentError> {
        let acc = *prim
            .attributes
            .get("POSITION")
            .ok_or_else(|| ContentError::NoPosition { at: format!("{at}.attributes") })?;
        let flat = self.read_typed(acc, format!("{at}.attributes[\"POSITION\"]"), "VEC3")?;
        let positions: Vec<[f64; 3]> = flat.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect();
        let indices: Vec<u32> = match prim.indices {
            Some(acc) => {
                let flat = self.read_typed(acc, format!("{at}.indices"), "SCALAR")?;
                flat.into_iter().map(|v| v as u32).collect()
            }
            None => (0..positions.len() as u32).collect(),
        };
        let triangles = assemble(&indices, prim.mode);
        Ok(RawPrimitive { positions, triangles, features: None, uv: None, feature_id0: None })
    }

    /// Reads accessor `acc`, referenced at JSON path `at`, which must be of accessor type `kind`
    /// (`"SCALAR"`, `"VEC2"`, …); returns its values flat.
    fn read_typed(&self, acc: usize, at: String, kind: &'static str) -> Result<Vec<f64>, ContentError> {
        let (n, flat) = self.read_accessor(acc, &at)?;
        if Some(n) != components(kind) {
            return Err(ContentError::Accessor {
                at,
                accessor: Some(acc),
                problem: AccessorProblem::Type { expected: kind },
            });
        }
        Ok(flat)
    }

    /// Which attribute holds the primitive's (at JSON path `at`) feature IDs: the first
    /// `EXT_mesh_features` set stored in a vertex attribute, else `_BATCHID` (or the pre-1.0
    /// `BATCHID`). Returns (attribute name, table, nullFeatureId).
    fn feature_set(
        &self,
        prim: &Primitive,
        at: &str,
    ) -> Result<Option<(String, TableKey, Option<u64>)>, ContentError> {
        if let Some(v) = prim.extensions.get("EXT_mesh_features") {
            let mf: MeshFeatures = serde_json::from_value(v.clone()).map_err(|source| {
                ContentError::Json { at: format!("{at}.extensions.EXT_mesh_features"), source }
            })?;
            for (s, set) in mf.feature_ids.iter().enumerate() {
                let Some(a) = set.attribute else { continue };
                let name = format!("_FEATURE_ID_{a}");
                let in_draco = prim
                    .extensions
                    .get("KHR_draco_mesh_compression")
                    .and_then(|d| d.get("attributes"))
                    .and_then(|a| a.get(&name))
                    .is_some();
                if !prim.attributes.contains_key(&name) && !in_draco {
                    return Err(ContentError::FeatureIdAttribute { at: at.to_string(), set: s, name });
                }
                let table = match set.property_table {
                    Some(t) => TableKey::Property(t),
                    None => TableKey::Anonymous(s, set.feature_count),
                };
                return Ok(Some((name, table, set.null_feature_id)));
            }
        }
        for name in ["_BATCHID", "BATCHID"] {
            if prim.attributes.contains_key(name) {
                return Ok(Some((name.to_string(), TableKey::Batch, None)));
            }
        }
        Ok(None)
    }
}

/// Walks a parsed glTF one spec object at a time, collecting every broken cross-reference and
/// byte range as a [`GltfIssue`] (JSON path, problem), in document order.
struct Validator<'g, 'a> {
    gltf: &'g Gltf<'a>,
    issues: Vec<GltfIssue>,
}

impl Validator<'_, '_> {
    fn issue(&mut self, at: String, problem: GltfProblem) {
        self.issues.push(GltfIssue { at, problem });
    }

    /// `buffers[i]`: the bytes loaded for each buffer cover its `byteLength` (a meshopt fallback
    /// buffer may have none).
    fn buffers(&mut self) {
        let g = self.gltf;
        for (i, b) in g.root.buffers.iter().enumerate() {
            let have = g.buffers[i].len();
            if have < b.byte_length && !(b.is_meshopt_fallback() && have == 0) {
                self.issue(
                    format!("buffers[{i}]"),
                    GltfProblem::BufferShort { byte_length: b.byte_length, available: have },
                );
            }
        }
    }

    /// `bufferViews[i]`: the buffer exists, the byte range lies inside it (unless meshopt-compressed)
    /// and the stride is valid.
    fn buffer_views(&mut self) {
        let g = self.gltf;
        for (i, v) in g.root.buffer_views.iter().enumerate() {
            let compressed = v.extensions.contains_key("EXT_meshopt_compression");
            match g.buffers.get(v.buffer) {
                None => self.issue(
                    format!("bufferViews[{i}].buffer"),
                    GltfProblem::Missing { kind: "buffer", index: v.buffer },
                ),
                Some(_) if compressed => {}
                Some(buf) => {
                    if v.byte_offset.checked_add(v.byte_length).is_none_or(|end| end > buf.len()) {
                        self.issue(
                            format!("bufferViews[{i}]"),
                            GltfProblem::ViewRange {
                                offset: v.byte_offset,
                                length: v.byte_length,
                                buffer: v.buffer,
                                buffer_bytes: buf.len(),
                            },
                        );
                    }
                }
            }
            if let Some(s) = v.byte_stride {
                if !(4..=252).contains(&s) || !s.is_multiple_of(4) {
                    self.issue(format!("bufferViews[{i}].byteStride"), GltfProblem::Stride { stride: s });
                }
            }
        }
    }

    /// `accessors[i]`: known type, elements inside the buffer view, sparse storage inside its views.
    fn accessors(&mut self) {
        for (i, a) in self.gltf.root.accessors.iter().enumerate() {
            let at = format!("accessors[{i}]");
            let (Some(n), Some(size)) = (components(&a.kind), component_size(a.component_type)) else {
                self.issue(
                    at,
                    GltfProblem::AccessorType { kind: a.kind.clone(), component_type: a.component_type },
                );
                continue;
            };
            if let Some(bv) = a.buffer_view {
                self.accessor_range(&at, a, bv, n * size);
            }
            if let Some(s) = &a.sparse {
                self.sparse(&at, s, n * size);
            }
        }
    }

    /// The `count` elements of `element` bytes of accessor `a` (at `at`) fit in `bufferViews[bv]`.
    fn accessor_range(&mut self, at: &str, a: &Accessor, bv: usize, element: usize) {
        let Some(view) = self.gltf.root.buffer_views.get(bv) else {
            self.issue(format!("{at}.bufferView"), GltfProblem::Missing { kind: "bufferView", index: bv });
            return;
        };
        let stride = view.byte_stride.unwrap_or(element);
        let need = if a.count == 0 {
            Some(0)
        } else {
            (a.count - 1)
                .checked_mul(stride)
                .and_then(|x| x.checked_add(element))
                .and_then(|x| x.checked_add(a.byte_offset))
        };
        if need.is_none_or(|need| need > view.byte_length) {
            self.issue(
                at.to_string(),
                GltfProblem::AccessorRange {
                    count: a.count,
                    element,
                    stride,
                    offset: a.byte_offset,
                    view: bv,
                    view_bytes: view.byte_length,
                },
            );
        }
    }

    /// The sparse substitution of the accessor at `at` (values of `element` bytes): unsigned
    /// indices, and indices and values inside their buffer views.
    fn sparse(&mut self, at: &str, s: &Sparse, element: usize) {
        let isize = match s.indices.component_type {
            5121 => 1,
            5123 => 2,
            5125 => 4,
            t => {
                self.issue(
                    format!("{at}.sparse.indices.componentType"),
                    GltfProblem::SparseIndexType { component_type: t },
                );
                return;
            }
        };
        for (what, bv, off, len) in [
            ("indices", s.indices.buffer_view, s.indices.byte_offset, isize),
            ("values", s.values.buffer_view, s.values.byte_offset, element),
        ] {
            match self.gltf.root.buffer_views.get(bv) {
                None => self.issue(
                    format!("{at}.sparse.{what}.bufferView"),
                    GltfProblem::Missing { kind: "bufferView", index: bv },
                ),
                Some(view) => {
                    if s.count
                        .checked_mul(len)
                        .and_then(|x| x.checked_add(off))
                        .is_none_or(|e| e > view.byte_length)
                    {
                        self.issue(
                            format!("{at}.sparse.{what}"),
                            GltfProblem::SparseRange { count: s.count, view: bv },
                        );
                    }
                }
            }
        }
    }

    /// `meshes[m].primitives[k]`: attribute and index accessors exist.
    fn meshes(&mut self) {
        let r = &self.gltf.root;
        for (m, mesh) in r.meshes.iter().enumerate() {
            for (k, prim) in mesh.primitives.iter().enumerate() {
                let at = format!("meshes[{m}].primitives[{k}]");
                for (sem, &acc) in &prim.attributes {
                    if acc >= r.accessors.len() {
                        self.issue(
                            format!("{at}.attributes[\"{sem}\"]"),
                            GltfProblem::Missing { kind: "accessor", index: acc },
                        );
                    }
                }
                if let Some(acc) = prim.indices {
                    if acc >= r.accessors.len() {
                        self.issue(
                            format!("{at}.indices"),
                            GltfProblem::Missing { kind: "accessor", index: acc },
                        );
                    }
                }
            }
        }
    }

    /// `nodes[i]`: children exist and have one parent each (trees), the mesh exists, the transform
    /// is finite.
    fn nodes(&mut self) {
        let r = &self.gltf.root;
        let mut parent_of: Vec<Option<usize>> = vec![None; r.nodes.len()];
        for (i, node) in r.nodes.iter().enumerate() {
            for &c in &node.children {
                match parent_of.get_mut(c) {
                    None => self.issue(
                        format!("nodes[{i}].children"),
                        GltfProblem::Missing { kind: "node", index: c },
                    ),
                    Some(Some(first)) => self.issue(
                        format!("nodes[{i}].children"),
                        GltfProblem::SecondParent { node: c, first: *first },
                    ),
                    Some(slot) => *slot = Some(i),
                }
            }
            if let Some(m) = node.mesh {
                if m >= r.meshes.len() {
                    self.issue(format!("nodes[{i}].mesh"), GltfProblem::Missing { kind: "mesh", index: m });
                }
            }
            let finite = node.matrix.iter().flatten().all(|v| v.is_finite())
                && node.translation.iter().flatten().all(|v| v.is_finite())
                && node.rotation.iter().flatten().all(|v| v.is_finite())
                && node.scale.iter().flatten().all(|v| v.is_finite());
            if !finite {
                self.issue(format!("nodes[{i}]"), GltfProblem::NonFiniteTransform);
            }
        }
    }

    /// `scenes[s].nodes` and `scene`: the nodes and the default scene exist.
    fn scenes(&mut self) {
        let r = &self.gltf.root;
        for (s, scene) in r.scenes.iter().enumerate() {
            for &n in &scene.nodes {
                if n >= r.nodes.len() {
                    self.issue(format!("scenes[{s}].nodes"), GltfProblem::Missing { kind: "node", index: n });
                }
            }
        }
        if let Some(s) = r.scene {
            if s >= r.scenes.len() {
                self.issue("scene".into(), GltfProblem::Missing { kind: "scene", index: s });
            }
        }
    }
}

/// The vertex attribute holding `EXT_mesh_features` set 0 as stored (kept for Blender).
const FEATURE_ID_0: &str = "_FEATURE_ID_0";

/// A primitive as decoded, before its attributes are checked against the vertex count: positions,
/// triangles and the flat values of the attributes that were read.
struct RawPrimitive {
    positions: Vec<[f64; 3]>,
    triangles: Vec<[u32; 3]>,
    features: Option<Vec<f64>>,
    uv: Option<Vec<f64>>,
    feature_id0: Option<Vec<f64>>,
}

/// Checks that the positions of the primitive at JSON path `at` are finite and that its triangles
/// index existing vertices.
fn check_geometry(at: &str, positions: &[[f64; 3]], triangles: &[[u32; 3]]) -> Result<(), ContentError> {
    if let Some(bad) = positions.iter().position(|p| p.iter().any(|c| !c.is_finite())) {
        return Err(ContentError::NonFiniteVertex {
            at: at.to_string(),
            vertex: bad,
            position: positions[bad],
        });
    }
    let n_vertices = positions.len();
    if let Some(t) = triangles.iter().find(|t| t.iter().any(|&i| i as usize >= n_vertices)) {
        return Err(ContentError::TriangleIndex { at: at.to_string(), triangle: *t, vertices: n_vertices });
    }
    Ok(())
}

/// Feature IDs from an attribute's float values (`None` for `null_id`); the first value that is
/// not a non-negative integer in u32 range is the error.
fn feature_ids(values: Vec<f64>, null_id: Option<u64>) -> Result<Vec<Option<u32>>, f64> {
    let mut ids = Vec::with_capacity(values.len());
    for v in values {
        let id = v.round();
        if !(v.is_finite() && (v - id).abs() < 1e-3 && (0.0..=u32::MAX as f64).contains(&id)) {
            return Err(v);
        }
        ids.push(if Some(id as u64) == null_id { None } else { Some(id as u32) });
    }
    Ok(ids)
}

/// A node's local matrix: `matrix`, or `T · R · S`.
fn node_matrix(node: &Node) -> DMat4 {
    if let Some(m) = node.matrix {
        return DMat4::from_cols_array(&m);
    }
    let t = node.translation.map_or(DVec3::ZERO, DVec3::from_array);
    let s = node.scale.map_or(DVec3::ONE, DVec3::from_array);
    let r = node.rotation.map_or(DQuat::IDENTITY, |q| {
        let q = DQuat::from_xyzw(q[0], q[1], q[2], q[3]);
        if q.length_squared() > 0.0 {
            q.normalize()
        } else {
            DQuat::IDENTITY
        }
    });
    DMat4::from_scale_rotation_translation(s, r, t)
}

/// Turns an index list into triangles according to the primitive mode (4, 5 or 6).
fn assemble(indices: &[u32], mode: u32) -> Vec<[u32; 3]> {
    match mode {
        5 => (0..indices.len().saturating_sub(2))
            .map(|i| {
                if i % 2 == 0 {
                    [indices[i], indices[i + 1], indices[i + 2]]
                } else {
                    [indices[i + 1], indices[i], indices[i + 2]]
                }
            })
            .collect(),
        6 => (1..indices.len().saturating_sub(1)).map(|i| [indices[0], indices[i], indices[i + 1]]).collect(),
        _ => indices.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::util::glb::GlbError;

    #[test]
    fn y_up_to_z_up() {
        let p = UpAxis::Y.to_z_up().transform_point3(DVec3::new(1.0, 2.0, 3.0));
        assert_eq!(p, DVec3::new(1.0, -3.0, 2.0));
        let p = UpAxis::X.to_z_up().transform_point3(DVec3::new(1.0, 2.0, 3.0));
        assert_eq!(p, DVec3::new(-3.0, 2.0, 1.0));
    }

    #[test]
    fn strips_and_fans() {
        assert_eq!(assemble(&[0, 1, 2, 3], 5), vec![[0, 1, 2], [2, 1, 3]]);
        assert_eq!(assemble(&[0, 1, 2, 3], 6), vec![[0, 1, 2], [0, 2, 3]]);
        assert_eq!(assemble(&[0, 1, 2, 3, 4], 4), vec![[0, 1, 2]]);
    }

    /// A loader for tests that read no external files.
    fn no_uri(uri: &str) -> Result<Vec<u8>, ContentError> {
        Err(ContentError::Missing { what: "test file", index: uri.len() })
    }

    #[test]
    fn glb_header_is_checked_before_the_gltf_crate_sees_it() {
        let mut b = b"glTF".to_vec();
        b.extend_from_slice(&2u32.to_le_bytes());
        b.extend_from_slice(&4u32.to_le_bytes()); // length < header size
        b.extend_from_slice(&[0; 12]);
        let e = parse_glb(&b, &no_uri).err().unwrap();
        assert!(matches!(e, ContentError::Glb(GlbError::Length { length: 4, available: 24 })), "{e:?}");
        assert!(e.to_string().contains("length is 4"), "{e}");
        b[4..8].copy_from_slice(&1u32.to_le_bytes());
        let e = parse_glb(&b, &no_uri).err().unwrap();
        assert!(matches!(e, ContentError::Glb(GlbError::Version { version: 1 })), "{e:?}");
        assert!(e.to_string().contains("glTF version 1"), "{e}");
        let e = parse_glb(b"b3dm", &no_uri).err().unwrap();
        assert!(e.to_string().contains("not a GLB"), "{e}");
    }

    #[test]
    fn invalid_json_keeps_the_parser_error() {
        let e = parse_gltf_json(b"{\"asset\": ", &no_uri).err().unwrap();
        assert!(matches!(e, ContentError::GltfJson(_)), "{e:?}");
        let chain = crate::lod::tiles3d::error::chain(&e);
        assert!(chain.starts_with("invalid glTF JSON: EOF while parsing"), "{chain}");
    }

    #[test]
    fn accessor_problems_name_the_attribute_path() {
        // POSITION points at a SCALAR accessor.
        let json = br#"{"asset": {"version": "2.0"},
            "buffers": [{"byteLength": 12, "uri": "data:application/octet-stream;base64,AAAAAAAAAAAAAAAA"}],
            "bufferViews": [{"buffer": 0, "byteLength": 12}],
            "accessors": [{"bufferView": 0, "componentType": 5126, "count": 3, "type": "SCALAR"}],
            "meshes": [{"primitives": [{"attributes": {"POSITION": 0}}]}],
            "nodes": [{"mesh": 0}]}"#;
        let g = parse_gltf_json(json, &no_uri).unwrap();
        let e = g.world_primitives(DMat4::IDENTITY, UpAxis::Z, Surface::No).unwrap_err();
        assert!(
            matches!(&e, ContentError::Accessor { at, accessor: Some(0), problem: AccessorProblem::Type { expected: "VEC3" } }
                if at == "meshes[0].primitives[0].attributes[\"POSITION\"]"),
            "{e:?}"
        );
        assert_eq!(
            e.to_string(),
            "meshes[0].primitives[0].attributes[\"POSITION\"] (accessor 0): is not VEC3"
        );
    }

    #[test]
    fn validation_reports_every_problem_with_its_path() {
        let json = br#"{"asset": {"version": "2.0"},
            "nodes": [{"children": [1]}, {"mesh": 3}, {"children": [1, 9]}],
            "meshes": [{"primitives": [{"attributes": {"POSITION": 4}}]}],
            "accessors": [{"bufferView": 2, "componentType": 5126, "count": 1, "type": "VEC3"}]}"#;
        let e = parse_gltf_json(json, &no_uri).err().unwrap();
        let ContentError::Invalid { issues } = &e else { panic!("{e:?}") };
        assert_eq!(issues.len(), 5);
        assert_eq!(
            issues[0],
            GltfIssue {
                at: "accessors[0].bufferView".into(),
                problem: GltfProblem::Missing { kind: "bufferView", index: 2 }
            }
        );
        let e = e.to_string();
        for part in [
            "5 problem(s)",
            "accessors[0].bufferView: bufferView 2 does not exist",
            "meshes[0].primitives[0].attributes[\"POSITION\"]: accessor 4 does not exist",
            "nodes[1].mesh: mesh 3 does not exist",
            "nodes[2].children: node 1 is already a child of node 0",
            "nodes[2].children: node 9 does not exist",
        ] {
            assert!(e.contains(part), "{part:?} missing from {e}");
        }
    }

    #[test]
    fn base64() {
        assert_eq!(base64_decode("aGVsbG8=").unwrap(), b"hello");
        assert_eq!(base64_decode("aGVsbG8").unwrap(), b"hello");
        assert!(base64_decode("a*b").is_none());
    }

    #[test]
    fn trs_order() {
        // Scale 2, rotate +90° about z, translate (10, 0, 0): (1, 0, 0) → (2, 0, 0) → (0, 2, 0) → (10, 2, 0).
        let s = std::f64::consts::FRAC_1_SQRT_2;
        let node = Node {
            children: vec![],
            mesh: None,
            matrix: None,
            translation: Some([10.0, 0.0, 0.0]),
            rotation: Some([0.0, 0.0, s, s]),
            scale: Some([2.0, 2.0, 2.0]),
        };
        let p = node_matrix(&node).transform_point3(DVec3::X);
        assert!((p - DVec3::new(10.0, 2.0, 0.0)).length() < 1e-12, "{p}");
    }

    #[test]
    fn normalized_components() {
        assert_eq!(read_component(&[255], 5121, true), 1.0);
        assert_eq!(read_component(&[0x80], 5120, true), -1.0);
        assert_eq!(read_component(&[0xff, 0x7f], 5122, true), 1.0);
        assert_eq!(read_component(&[7, 0], 5123, false), 7.0);
    }
}
