//! Errors below the file level of the 3D Tiles reader: why the bytes of a tile content (b3dm, cmpt,
//! GLB, glTF JSON), of a subtree file, or the gzip and JSON layers of a tileset JSON cannot be
//! decoded ([`ContentError`]), with the codecs' own errors ([`DracoMeshError`], [`MeshoptError`],
//! [`WebpError`]) and bad URIs ([`UriError`]) as causes.
//!
//! Locations inside a file are JSON paths (`meshes[0].primitives[1].attributes["POSITION"]`) or byte
//! counts; the file, the tileset and the tile are added by the caller's wrapping error
//! ([`crate::lod::LodError::Tile`], [`crate::lod::LodError::Tiles3d`],
//! [`crate::lod::LodError::Subtree`], [`crate::blender::BlenderError::Tile`]), so that the printed
//! chain reads `tileset.json: root.children[2].content.uri "a.glb" (tiles/a.glb): meshes[0]…: …`.
//! Causes (JSON, I/O, gzip, Draco, meshopt, WebP, PNG) stay in `#[source]`.

use std::fmt;
use std::path::PathBuf;

/// Names of the four b3dm header section lengths, in file order.
pub(crate) const B3DM_SECTIONS: [&str; 4] = [
    "featureTableJSONByteLength",
    "featureTableBinaryByteLength",
    "batchTableJSONByteLength",
    "batchTableBinaryByteLength",
];

/// Why a 3D Tiles file's bytes cannot be decoded. The variants say what is wrong where, with the
/// numbers and values involved; [`ContentError::At`] adds a JSON path around a nested error.
#[derive(Debug, thiserror::Error)]
pub enum ContentError {
    // ------------------------------------------------------------------ context
    /// The nested error happened at this JSON path (`materials[0].pbrMetallicRoughness…`).
    #[error("{at}")]
    At {
        at: String,
        #[source]
        source: Box<ContentError>,
    },
    /// The GLB embedded in a b3dm is wrong.
    #[error("embedded GLB")]
    EmbeddedGlb(#[source] Box<ContentError>),
    /// One inner tile of a cmpt is wrong.
    #[error("cmpt inner tile {index}")]
    CmptTile {
        index: usize,
        #[source]
        source: Box<ContentError>,
    },

    // ------------------------------------------------------------------ files, URIs, gzip
    /// A URI (buffer, image, schema, subtree) is not a local file path.
    #[error(transparent)]
    Uri(#[from] UriError),
    /// A file a URI names cannot be read.
    #[error("cannot read {} (referenced as {uri:?})", path.display())]
    ReadUri {
        uri: String,
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// The content file itself cannot be opened or read.
    #[error("the content file cannot be read")]
    Unreadable(#[source] std::io::Error),
    /// A `data:` URI without `;base64,` (the URI's start is kept).
    #[error("data URI {head:?}… is not base64")]
    DataUriNotBase64 { head: String },
    /// A `data:` URI whose payload is not valid base64.
    #[error("data URI {head:?}… holds invalid base64")]
    DataUriBase64 { head: String },
    /// The gzip stream is corrupt.
    #[error("gzip-compressed content cannot be inflated")]
    Gunzip(#[source] std::io::Error),
    /// The gzip stream inflates past the limit (a decompression bomb, or a corrupt file).
    #[error("gzip-compressed content inflates past {limit} bytes")]
    GunzipTooLarge { limit: u64 },
    /// A tileset JSON that does not parse as one.
    #[error("not a valid 3D Tiles tileset JSON")]
    TilesetJson(#[source] serde_json::Error),
    /// A JSON object (an extension, a subtree's JSON, an external schema) that does not parse.
    #[error("{at} is malformed")]
    Json {
        at: String,
        #[source]
        source: serde_json::Error,
    },

    // ------------------------------------------------------------------ containers: b3dm, cmpt, subtree
    /// Fewer bytes than the container's header needs.
    #[error("{length} bytes is too short for a {what} ({needed} bytes)")]
    TooShort { what: &'static str, length: usize, needed: usize },
    /// A container version other than 1.
    #[error("unsupported {container} version {version} (expected 1)")]
    Version { container: &'static str, version: u32 },
    /// The header's byteLength disagrees with the bytes there are.
    #[error(
        "{container} header byteLength is {byte_length} but the tile has {length} bytes{}",
        if byte_length > length { " (truncated file?)" } else { "" }
    )]
    ByteLength { container: &'static str, byte_length: usize, length: usize },
    /// [`crate::lod::tiles3d`] was handed something that is not a b3dm as one.
    #[error("not a b3dm: magic is {magic:?}")]
    NotB3dm { magic: String },
    /// A b3dm section length (one of [`B3DM_SECTIONS`]) runs past the end of the tile.
    #[error(
        "b3dm header {name} = {len} runs past the end of the tile ({byte_length} bytes; sections {})",
        B3DM_SECTIONS.iter().zip(lengths).map(|(n, l)| format!("{n}={l}")).collect::<Vec<_>>().join(", ")
    )]
    B3dmSection { name: &'static str, len: usize, byte_length: usize, lengths: [usize; 4] },
    /// A b3dm whose header and tables use up every byte.
    #[error("the b3dm has no GLB after its tables ({byte_length} bytes all used by header and tables)")]
    NoGlb { byte_length: usize },
    /// The feature or batch table JSON does not parse.
    #[error("{table} JSON is invalid")]
    TableJson {
        table: &'static str,
        #[source]
        source: serde_json::Error,
    },
    /// The feature or batch table JSON is not an object.
    #[error("{table} JSON is not an object")]
    TableNotObject { table: &'static str },
    #[error("feature table BATCH_LENGTH is not a non-negative integer: {value}")]
    BatchLength { value: serde_json::Value },
    #[error("feature table has no BATCH_LENGTH")]
    NoBatchLength,
    /// A feature count past [`super::MAX_FEATURES`] (taken as corrupt rather than allocated).
    #[error("{at} {count} exceeds {max} features")]
    TooManyFeatures { at: String, count: usize, max: usize },
    #[error("feature table RTC_CENTER is neither [x, y, z] (3 numbers) nor {{byteOffset}}: {value}")]
    RtcCenter { value: serde_json::Value },
    #[error("feature table RTC_CENTER byteOffset {offset} + 12 exceeds the {body}-byte binary body")]
    RtcCenterOffset { offset: usize, body: usize },
    /// Numbers that must be finite (`RTC_CENTER`, `CESIUM_RTC.center`, a texture transform) are not.
    #[error("{at} {values:?} is not finite")]
    NotFinite { at: &'static str, values: Vec<f64> },
    /// A batch table property array shorter than the batch.
    #[error("batch table property {name:?} has {values} values for BATCH_LENGTH {batch_length}")]
    BatchPropertyShort { name: String, values: usize, batch_length: usize },
    /// A batch table binary property reference that lacks a field or names an unknown type.
    #[error("batch table property {name:?}: {problem} ({value})")]
    BatchProperty { name: String, problem: &'static str, value: serde_json::Value },
    #[error(
        "batch table property {name:?}: {len} bytes at byteOffset {offset} exceed the {body}-byte binary body"
    )]
    BatchPropertyRange { name: String, len: usize, offset: usize, body: usize },
    #[error("cmpt inner tile {index} starts at byte {at}, past the end ({byte_length} bytes)")]
    CmptTileStart { index: usize, at: usize, byte_length: usize },
    #[error("cmpt inner tile {index} byteLength {len} at byte {at} runs past the end ({byte_length} bytes)")]
    CmptTileLength { index: usize, len: usize, at: usize, byte_length: usize },
    /// A subtree chunk length (`jsonByteLength`, `binaryByteLength`) past the end of the file.
    #[error("subtree {name} {len} runs past the end of the file ({length} bytes)")]
    SubtreeChunk { name: &'static str, len: u64, length: usize },
    /// A subtree availability with an invalid `constant`.
    #[error("{at}.constant: {value} is not 0 or 1")]
    AvailabilityConstant { at: String, value: u8 },
    /// A subtree availability with neither a bitstream nor a constant.
    #[error("{at}: needs a bitstream or a constant")]
    NoAvailability { at: String },
    /// Bytes that are neither b3dm, GLB, cmpt, i3dm, pnts nor glTF JSON.
    #[error("unknown tile content (magic {magic:?}); expected b3dm, glb, cmpt or glTF JSON")]
    UnknownContent { magic: String },
    /// An i3dm or pnts content where a renderable one is needed.
    #[error(
        "{kind} content (instanced models / point clouds) cannot be rendered; only b3dm, glb, glTF and cmpt contents can"
    )]
    NotRenderable { kind: String },

    // ------------------------------------------------------------------ GLB and glTF
    #[error("not a GLB: {length} bytes starting with {magic:?}")]
    NotGlb { length: usize, magic: String },
    #[error(
        "glTF version {version} content is not supported; only glTF 2.0 is (upgrade the tileset, e.g. with `npx 3d-tiles-tools upgrade`)"
    )]
    GlbVersion { version: usize },
    /// The GLB header's length is shorter than a header or longer than the bytes there are.
    #[error("GLB header length is {length} but {available} bytes are available")]
    GlbLength { length: usize, available: usize },
    /// The GLB chunks are inconsistent (the `gltf` crate's error).
    #[error("not a valid GLB")]
    Glb(#[source] Box<gltf::Error>),
    #[error("invalid glTF JSON")]
    GltfJson(#[source] serde_json::Error),
    #[error("glTF asset.version {version:?} is not supported; only glTF 2.0 is")]
    AssetVersion { version: String },
    #[error("buffers[0] has no uri but the GLB has no BIN chunk")]
    NoBinChunk,
    #[error("buffers[{index}] has no uri (only buffers[0] may use the BIN chunk)")]
    GlbBufferWithoutUri { index: usize },
    #[error("buffers[{index}] has no uri in a .gltf JSON asset")]
    GltfBufferWithoutUri { index: usize },
    /// Required glTF extensions insgen cannot decode (named), with the list of those it can.
    #[error(
        "the glTF requires extension(s) {} that insgen cannot decode (supported: {})",
        extensions.join(", "),
        super::gltf::HANDLED_EXTENSIONS.join(", ")
    )]
    UnsupportedExtensions { extensions: Vec<String> },
    /// Every cross-reference and byte range problem of a glTF, each with its JSON path.
    #[error(
        "invalid glTF ({} problem(s)): {}",
        issues.len(),
        issues.iter().map(ToString::to_string).collect::<Vec<_>>().join("; ")
    )]
    Invalid { issues: Vec<GltfIssue> },
    /// An index that points at nothing (`what` names the kind of object: "bufferView", "material", …).
    /// Usually inside a [`ContentError::At`] naming where the index was read.
    #[error("{what} {index} does not exist")]
    Missing { what: &'static str, index: usize },
    #[error("bufferView {view} exceeds buffer {buffer}")]
    ViewRange { view: usize, buffer: usize },
    #[error("extensions.CESIUM_RTC: expected {{\"center\": [x, y, z]}}")]
    CesiumRtc(#[source] serde_json::Error),
    /// An `EXT_meshopt_compression` view whose compressed bytes lie outside their buffer.
    #[error(
        "bufferViews[{view}].extensions.EXT_meshopt_compression: bytes {offset}..+{len} exceed buffer {buffer} ({buffer_len} bytes)"
    )]
    MeshoptRange { view: usize, offset: usize, len: usize, buffer: usize, buffer_len: usize },
    /// An `EXT_meshopt_compression` view that cannot be decoded.
    #[error("bufferViews[{view}].extensions.EXT_meshopt_compression")]
    Meshopt {
        view: usize,
        #[source]
        source: MeshoptError,
    },
    #[error(
        "bufferViews[{view}].extensions.EXT_meshopt_compression: decodes to {decoded} bytes but the bufferView's byteLength is {byte_length}"
    )]
    MeshoptShort { view: usize, decoded: usize, byte_length: usize },
    /// An accessor (or the Draco attribute standing in for it) that a primitive cannot use; `at` is
    /// the JSON path of the reference (`meshes[0].primitives[1].attributes["POSITION"]`).
    #[error("{at}{}: {problem}", accessor.map_or(String::new(), |a| format!(" (accessor {a})")))]
    Accessor { at: String, accessor: Option<usize>, problem: AccessorProblem },
    /// A primitive without positions; `at` is its `attributes` (or the Draco extension's).
    #[error("{at} has no POSITION")]
    NoPosition { at: String },
    /// A `KHR_draco_mesh_compression` primitive whose Draco mesh cannot be used.
    #[error("{at}")]
    Draco {
        at: String,
        #[source]
        source: DracoMeshError,
    },
    #[error("{at}: vertex {vertex} has a non-finite position {position:?}")]
    NonFiniteVertex { at: String, vertex: usize, position: [f64; 3] },
    #[error("{at}: triangle {triangle:?} refers past the {vertices} vertices")]
    TriangleIndex { at: String, triangle: [u32; 3], vertices: usize },
    #[error("{at}.extensions.EXT_mesh_features.featureIds[{set}] names attribute {name}, which is missing")]
    FeatureIdAttribute { at: String, set: usize, name: String },
    #[error("nodes[{node}]: the node hierarchy has a cycle")]
    NodeCycle { node: usize },

    // ------------------------------------------------------------------ feature IDs and metadata
    #[error("_BATCHID {id} is not below the feature table's BATCH_LENGTH {batch_length}")]
    BatchIdRange { id: u32, batch_length: usize },
    #[error("EXT_mesh_features refers to property table {table}, which does not exist")]
    NoPropertyTable { table: usize },
    #[error("feature ID {id} is not below property table {table}'s count {count}")]
    FeatureIdRange { id: u32, table: usize, count: usize },
    #[error("feature ID {id} is not below featureIds[{set}].featureCount {count}")]
    FeatureCountRange { id: u32, set: usize, count: u64 },
    #[error("EXT_structural_metadata has neither schema nor schemaUri")]
    NoSchema,
    #[error("EXT_structural_metadata.propertyTables[{table}].class {class:?} is not in the schema")]
    UnknownClass { table: usize, class: String },
    #[error("STRING property without stringOffsets")]
    NoStringOffsets,
    #[error("SCALAR property without componentType")]
    NoComponentType,
    #[error("unknown componentType {component_type:?}")]
    UnknownComponentType { component_type: String },
    #[error("unknown offset type {kind:?}")]
    UnknownOffsetType { kind: String },
    #[error("{count} offsets of {size} bytes exceed their buffer view")]
    OffsetsRange { count: usize, size: usize },
    #[error("{count} values of {size} bytes exceed the {available}-byte buffer view")]
    ValuesRange { count: usize, size: usize, available: usize },
    #[error("string bytes {start}..{end} exceed the values")]
    StringRange { start: usize, end: usize },
    #[error("string at bytes {start}..{end} is not UTF-8")]
    StringUtf8 {
        start: usize,
        end: usize,
        #[source]
        source: std::str::Utf8Error,
    },
    #[error("buffers[{index}]: byteLength {byte_length} but {available} bytes available")]
    BufferLength { index: usize, byte_length: usize, available: usize },

    // ------------------------------------------------------------------ textures (plain GLB conversion)
    /// An image insgen cannot decode; `kind` says what it is ("KTX2 (KHR_texture_basisu)", …).
    #[error("images[{image}] (via {via}) is {kind}")]
    UnreadableImage { image: usize, via: &'static str, kind: &'static str },
    #[error(
        "textures[{texture}] needs KHR_texture_basisu (KTX2 / Basis Universal, images[{image}]), which insgen cannot decode; re-encode the tileset's textures as JPEG or PNG (e.g. `npx gltf-transform png`)"
    )]
    Basisu { texture: usize, image: u64 },
    #[error("textures[{texture}] needs MSFT_texture_dds (images[{image}]), which insgen cannot decode")]
    Dds { texture: usize, image: u64 },
    #[error("textures[{texture}] has no image insgen can read")]
    NoTextureImage { texture: usize },
    /// An image without data (always inside a [`ContentError::At`] naming the image).
    #[error("has neither a uri nor a bufferView")]
    ImageWithoutData,
    /// A WebP image that cannot be turned into a PNG.
    #[error("images[{image}] (EXT_texture_webp)")]
    Webp {
        image: usize,
        #[source]
        source: WebpError,
    },
}

impl ContentError {
    /// This error, located at JSON path `at` (see [`ContentError::At`]).
    pub(crate) fn at(self, at: impl Into<String>) -> ContentError {
        ContentError::At { at: at.into(), source: Box::new(self) }
    }
}

/// One problem found by the glTF validation pass: its JSON path and what is wrong there.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct GltfIssue {
    /// `accessors[0].bufferView`, `nodes[2].children`, …
    pub at: String,
    pub what: String,
}

impl fmt::Display for GltfIssue {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}: {}", self.at, self.what)
    }
}

/// What is wrong with an accessor a primitive reads (see [`ContentError::Accessor`]).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum AccessorProblem {
    /// The accessor's type has the wrong number of components.
    #[error("is not {expected}")]
    Type { expected: &'static str },
    /// The attribute has a different number of elements than the primitive has vertices.
    #[error("has {values} values for {vertices} vertices")]
    Count { values: usize, vertices: usize },
    #[error("value {value} is not a feature ID (a non-negative integer)")]
    NotFeatureId { value: f64 },
    /// An all-zero accessor (no bufferView) so large it is taken as corrupt.
    #[error("{count} elements without a bufferView is implausible")]
    ZeroFilled { count: usize },
    #[error("sparse index {index} ≥ count {count}")]
    SparseIndex { index: usize, count: usize },
    #[error("unknown type {kind:?}")]
    UnknownType { kind: String },
    #[error("unknown componentType {component_type}")]
    UnknownComponentType { component_type: u32 },
}

/// A content, buffer, image, schema or subtree URI that insgen cannot turn into a local file.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum UriError {
    #[error("URI {uri:?} is not a relative file path; only local tilesets are read (download it first)")]
    NotLocal { uri: String },
    #[error("URI {uri:?} names no file")]
    NoFile { uri: String },
    #[error("URI {uri:?} has an invalid %-escape at byte {at}")]
    PercentEscape { uri: String, at: usize },
    #[error("URI {uri:?} does not decode to UTF-8")]
    NotUtf8 {
        uri: String,
        #[source]
        source: std::string::FromUtf8Error,
    },
}

/// Why a `KHR_draco_mesh_compression` bitstream gives no usable mesh.
#[derive(Debug, thiserror::Error)]
pub enum DracoMeshError {
    /// The third-party decoder panicked (caught, so a hostile bitstream cannot abort a run).
    #[error("the Draco decoder failed on this bitstream (panicked)")]
    Panicked,
    #[error("cannot decode the Draco bitstream")]
    Decode(#[source] draco_core::DracoError),
    #[error("the Draco bitstream holds no triangles (a point cloud?)")]
    PointCloud,
    /// The extension names a Draco attribute (by unique id) the mesh does not have.
    #[error("the Draco mesh has no attribute with unique id {id}{}", if *position { " (POSITION)" } else { "" })]
    NoAttribute { id: u32, position: bool },
    #[error(
        "the Draco attribute {id}{} has {found} components, not {needed}",
        if *position { " (POSITION)" } else { "" }
    )]
    Components { id: u32, position: bool, found: usize, needed: usize },
}

/// Why an `EXT_meshopt_compression` view cannot be decoded: a broken precondition of the decoder
/// (checked first: its assertions would abort the process) or the decoder's error code.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum MeshoptError {
    #[error("count {count} × byteStride {stride} exceeds {max} bytes")]
    TooLarge { count: usize, stride: usize, max: usize },
    /// `what` is the mode or filter ("ATTRIBUTES mode", "OCTAHEDRAL filter"), `expected` the strides
    /// it accepts.
    #[error("{what} needs a byteStride {expected}, not {stride}")]
    Stride { what: &'static str, expected: &'static str, stride: usize },
    #[error("TRIANGLES mode needs a count that is a multiple of 3, not {count}")]
    TriangleCount { count: usize },
    #[error("mode {mode:?} is not ATTRIBUTES, TRIANGLES or INDICES")]
    UnknownMode { mode: String },
    #[error("the meshopt {mode} decoder failed (code {code}): the data is corrupt")]
    Corrupt { mode: &'static str, code: i32 },
    #[error("filter {filter} applies to ATTRIBUTES mode only, not {mode}")]
    FilterMode { filter: String, mode: &'static str },
    #[error("filter {filter:?} is not NONE, OCTAHEDRAL, QUATERNION or EXPONENTIAL")]
    UnknownFilter { filter: String },
}

/// Why a WebP texture cannot be re-encoded as PNG.
#[derive(Debug, thiserror::Error)]
pub enum WebpError {
    #[error("cannot decode the WebP image")]
    Decode(#[source] image_webp::DecodingError),
    #[error("the WebP image is too large to decode")]
    TooLarge,
    #[error("cannot encode the decoded WebP image as PNG")]
    Png(#[source] png::EncodingError),
}

#[cfg(test)]
pub(crate) use crate::util::error_chain as chain;
