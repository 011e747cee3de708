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
        /// JSON path of the nested error (`materials[0].pbrMetallicRoughness…`).
        at: String,
        /// The nested error.
        #[source]
        source: Box<ContentError>,
    },
    /// The GLB embedded in a b3dm is wrong.
    #[error("embedded GLB")]
    EmbeddedGlb(#[source] Box<ContentError>),
    /// One inner tile of a cmpt is wrong.
    #[error("cmpt inner tile {index}")]
    CmptTile {
        /// 0-based index of the inner tile.
        index: usize,
        /// What is wrong with it.
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
        /// The URI as written.
        uri: String,
        /// The file it names.
        path: PathBuf,
        /// The I/O error.
        #[source]
        source: std::io::Error,
    },
    /// The content file itself cannot be opened or read.
    #[error("the content file cannot be read")]
    Unreadable(#[source] std::io::Error),
    /// A `data:` URI without `;base64,` (the URI's start is kept).
    #[error("data URI {head:?}… is not base64")]
    DataUriNotBase64 {
        /// The URI's first characters.
        head: String,
    },
    /// A `data:` URI whose payload is not valid base64.
    #[error("data URI {head:?}… holds invalid base64")]
    DataUriBase64 {
        /// The URI's first characters.
        head: String,
    },
    /// The gzip stream is corrupt.
    #[error("gzip-compressed content cannot be inflated")]
    Gunzip(#[source] std::io::Error),
    /// The gzip stream inflates past the limit (a decompression bomb, or a corrupt file).
    #[error("gzip-compressed content inflates past {limit} bytes")]
    GunzipTooLarge {
        /// The limit, bytes.
        limit: u64,
    },
    /// A tileset JSON that does not parse as one.
    #[error("not a valid 3D Tiles tileset JSON")]
    TilesetJson(#[source] serde_json::Error),
    /// A JSON object (an extension, a subtree's JSON, an external schema) that does not parse.
    #[error("{at} is malformed")]
    Json {
        /// JSON path (or name) of the object.
        at: String,
        /// The parser's error.
        #[source]
        source: serde_json::Error,
    },

    // ------------------------------------------------------------------ containers: b3dm, cmpt, subtree
    /// Fewer bytes than the container's header needs.
    #[error("{length} bytes is too short for a {what} ({needed} bytes)")]
    TooShort {
        /// The header (`"b3dm header"`, `"cmpt header"`, `"subtree header"`).
        what: &'static str,
        /// Bytes there are.
        length: usize,
        /// Bytes the header needs.
        needed: usize,
    },
    /// A container version other than 1.
    #[error("unsupported {container} version {version} (expected 1)")]
    Version {
        /// The container ("b3dm", "cmpt", "subtree").
        container: &'static str,
        /// The version in the header.
        version: u32,
    },
    /// The header's byteLength disagrees with the bytes there are.
    #[error(
        "{container} header byteLength is {byte_length} but the tile has {length} bytes{}",
        if byte_length > length { " (truncated file?)" } else { "" }
    )]
    ByteLength {
        /// The container ("b3dm", "cmpt").
        container: &'static str,
        /// The header's byteLength, bytes.
        byte_length: usize,
        /// Bytes there are.
        length: usize,
    },
    /// [`crate::lod::tiles3d`] was handed something that is not a b3dm as one.
    #[error("not a b3dm: magic is {magic:?}")]
    NotB3dm {
        /// The first four bytes, as text.
        magic: String,
    },
    /// A b3dm section length (one of [`B3DM_SECTIONS`]) runs past the end of the tile.
    #[error(
        "b3dm header {name} = {len} runs past the end of the tile ({byte_length} bytes; sections {})",
        B3DM_SECTIONS.iter().zip(lengths).map(|(n, l)| format!("{n}={l}")).collect::<Vec<_>>().join(", ")
    )]
    B3dmSection {
        /// The header field (one of [`B3DM_SECTIONS`]).
        name: &'static str,
        /// Its value, bytes.
        len: usize,
        /// The tile's byteLength, bytes.
        byte_length: usize,
        /// All four section lengths, bytes, in [`B3DM_SECTIONS`] order.
        lengths: [usize; 4],
    },
    /// A b3dm whose header and tables use up every byte.
    #[error("the b3dm has no GLB after its tables ({byte_length} bytes all used by header and tables)")]
    NoGlb {
        /// The tile's byteLength, bytes.
        byte_length: usize,
    },
    /// The feature or batch table JSON does not parse.
    #[error("{table} JSON is invalid")]
    TableJson {
        /// "feature table" or "batch table".
        table: &'static str,
        /// The parser's error.
        #[source]
        source: serde_json::Error,
    },
    /// The feature or batch table JSON is not an object.
    #[error("{table} JSON is not an object")]
    TableNotObject {
        /// "feature table" or "batch table".
        table: &'static str,
    },
    /// The feature table's `BATCH_LENGTH` is not a non-negative integer.
    #[error("feature table BATCH_LENGTH is not a non-negative integer: {value}")]
    BatchLength {
        /// The value found.
        value: serde_json::Value,
    },
    /// The feature table has no `BATCH_LENGTH`.
    #[error("feature table has no BATCH_LENGTH")]
    NoBatchLength,
    /// A feature count past [`super::MAX_FEATURES`] (taken as corrupt rather than allocated).
    #[error("{at} {count} exceeds {max} features")]
    TooManyFeatures {
        /// What gives the count (`"feature table BATCH_LENGTH"`, …).
        at: String,
        /// The count given.
        count: usize,
        /// The most features read.
        max: usize,
    },
    /// The feature table's `RTC_CENTER` is neither three numbers nor a binary reference.
    #[error("feature table RTC_CENTER is neither [x, y, z] (3 numbers) nor {{byteOffset}}: {value}")]
    RtcCenter {
        /// The value found.
        value: serde_json::Value,
    },
    /// The feature table's binary `RTC_CENTER` lies past the binary body.
    #[error("feature table RTC_CENTER byteOffset {offset} + 12 exceeds the {body}-byte binary body")]
    RtcCenterOffset {
        /// Its byteOffset, bytes.
        offset: usize,
        /// Length of the feature table's binary body, bytes.
        body: usize,
    },
    /// Numbers that must be finite (`RTC_CENTER`, `CESIUM_RTC.center`, a texture transform) are not.
    #[error("{at} {values:?} is not finite")]
    NotFinite {
        /// What the numbers are (`"feature table RTC_CENTER"`, …).
        at: &'static str,
        /// The numbers.
        values: Vec<f64>,
    },
    /// A batch table property array shorter than the batch.
    #[error("batch table property {name:?} has {values} values for BATCH_LENGTH {batch_length}")]
    BatchPropertyShort {
        /// The property's name.
        name: String,
        /// Values the array has.
        values: usize,
        /// The feature table's `BATCH_LENGTH`.
        batch_length: usize,
    },
    /// A batch table binary property reference that lacks a field or names an unknown type.
    #[error("batch table property {name:?}: {problem} ({value})")]
    BatchProperty {
        /// The property's name.
        name: String,
        /// What is wrong ("no byteOffset", "unknown componentType", …).
        problem: &'static str,
        /// The property's JSON.
        value: serde_json::Value,
    },
    #[error(
        "batch table property {name:?}: {len} bytes at byteOffset {offset} exceed the {body}-byte binary body"
    )]
    /// A batch table binary property whose bytes lie past the binary body.
    BatchPropertyRange {
        /// The property's name.
        name: String,
        /// The property's length, bytes.
        len: usize,
        /// Its byteOffset, bytes.
        offset: usize,
        /// Length of the batch table's binary body, bytes.
        body: usize,
    },
    /// A cmpt inner tile starts past the end of the cmpt.
    #[error("cmpt inner tile {index} starts at byte {at}, past the end ({byte_length} bytes)")]
    CmptTileStart {
        /// 0-based index of the inner tile.
        index: usize,
        /// Byte offset where it starts.
        at: usize,
        /// The cmpt's length, bytes.
        byte_length: usize,
    },
    /// A cmpt inner tile runs past the end of the cmpt.
    #[error("cmpt inner tile {index} byteLength {len} at byte {at} runs past the end ({byte_length} bytes)")]
    CmptTileLength {
        /// 0-based index of the inner tile.
        index: usize,
        /// The inner tile's byteLength, bytes.
        len: usize,
        /// Byte offset where it starts.
        at: usize,
        /// The cmpt's length, bytes.
        byte_length: usize,
    },
    /// A subtree chunk length (`jsonByteLength`, `binaryByteLength`) past the end of the file.
    #[error("subtree {name} {len} runs past the end of the file ({length} bytes)")]
    SubtreeChunk {
        /// The header field (`jsonByteLength`, `binaryByteLength`).
        name: &'static str,
        /// Its value, bytes.
        len: u64,
        /// The file's length, bytes.
        length: usize,
    },
    /// A subtree availability with an invalid `constant`.
    #[error("{at}.constant: {value} is not 0 or 1")]
    AvailabilityConstant {
        /// JSON path of the availability.
        at: String,
        /// The constant given.
        value: u8,
    },
    /// A subtree availability with neither a bitstream nor a constant.
    #[error("{at}: needs a bitstream or a constant")]
    NoAvailability {
        /// JSON path of the availability.
        at: String,
    },
    /// Bytes that are neither b3dm, GLB, cmpt, i3dm, pnts nor glTF JSON.
    #[error("unknown tile content (magic {magic:?}); expected b3dm, glb, cmpt or glTF JSON")]
    UnknownContent {
        /// The first four bytes, as text.
        magic: String,
    },
    /// An i3dm or pnts content where a renderable one is needed.
    #[error(
        "{kind} content (instanced models / point clouds) cannot be rendered; only b3dm, glb, glTF and cmpt contents can"
    )]
    NotRenderable {
        /// "i3dm" or "pnts".
        kind: String,
    },

    // ------------------------------------------------------------------ GLB and glTF
    /// The GLB container is not one (magic, version, length, chunks): the one GLB reader's error.
    #[error(transparent)]
    Glb(#[from] crate::util::glb::GlbError),
    /// A glTF JSON (`.gltf` or a GLB's JSON chunk) that does not parse.
    #[error("invalid glTF JSON")]
    GltfJson(#[source] serde_json::Error),
    /// A glTF whose `asset.version` is not 2.x.
    #[error("glTF asset.version {version:?} is not supported; only glTF 2.0 is")]
    AssetVersion {
        /// The version as written.
        version: String,
    },
    /// `buffers[0]` has no URI and the GLB has no BIN chunk.
    #[error("buffers[0] has no uri but the GLB has no BIN chunk")]
    NoBinChunk,
    /// A buffer other than the first has no URI in a GLB.
    #[error("buffers[{index}] has no uri (only buffers[0] may use the BIN chunk)")]
    GlbBufferWithoutUri {
        /// Index in `buffers`.
        index: usize,
    },
    /// A buffer without URI in a `.gltf` JSON asset (which has no BIN chunk).
    #[error("buffers[{index}] has no uri in a .gltf JSON asset")]
    GltfBufferWithoutUri {
        /// Index in `buffers`.
        index: usize,
    },
    /// Required glTF extensions insgen cannot decode (named), with the list of those it can.
    #[error(
        "the glTF requires extension(s) {} that insgen cannot decode (supported: {})",
        extensions.join(", "),
        super::gltf::HANDLED_EXTENSIONS.join(", ")
    )]
    UnsupportedExtensions {
        /// The required extensions insgen cannot decode.
        extensions: Vec<String>,
    },
    /// Every cross-reference and byte range problem of a glTF, each with its JSON path.
    #[error(
        "invalid glTF ({} problem(s)): {}",
        issues.len(),
        issues.iter().map(ToString::to_string).collect::<Vec<_>>().join("; ")
    )]
    Invalid {
        /// Every problem found, in document order.
        issues: Vec<GltfIssue>,
    },
    /// An index that points at nothing (`what` names the kind of object: "bufferView", "material", …).
    /// Usually inside a [`ContentError::At`] naming where the index was read.
    #[error("{what} {index} does not exist")]
    Missing {
        /// The kind of object ("bufferView", "material", …).
        what: &'static str,
        /// The index given.
        index: usize,
    },
    /// A bufferView that runs past the end of its buffer.
    #[error("bufferView {view} exceeds buffer {buffer}")]
    ViewRange {
        /// Index in `bufferViews`.
        view: usize,
        /// Index of its buffer.
        buffer: usize,
    },
    /// A `CESIUM_RTC` extension that is not `{"center": [x, y, z]}`.
    #[error("extensions.CESIUM_RTC: expected {{\"center\": [x, y, z]}}")]
    CesiumRtc(#[source] serde_json::Error),
    /// An `EXT_meshopt_compression` view whose compressed bytes lie outside their buffer.
    #[error(
        "bufferViews[{view}].extensions.EXT_meshopt_compression: bytes {offset}..+{len} exceed buffer {buffer} ({buffer_len} bytes)"
    )]
    MeshoptRange {
        /// Index in `bufferViews`.
        view: usize,
        /// The compressed bytes' byteOffset.
        offset: usize,
        /// The compressed bytes' byteLength.
        len: usize,
        /// Index of the buffer.
        buffer: usize,
        /// The buffer's length, bytes.
        buffer_len: usize,
    },
    /// An `EXT_meshopt_compression` view that cannot be decoded.
    #[error("bufferViews[{view}].extensions.EXT_meshopt_compression")]
    Meshopt {
        /// Index in `bufferViews`.
        view: usize,
        /// The decoder's complaint.
        #[source]
        source: MeshoptError,
    },
    #[error(
        "bufferViews[{view}].extensions.EXT_meshopt_compression: decodes to {decoded} bytes but the bufferView's byteLength is {byte_length}"
    )]
    /// An `EXT_meshopt_compression` view that decodes to fewer bytes than the bufferView's byteLength.
    MeshoptShort {
        /// Index in `bufferViews`.
        view: usize,
        /// Bytes decoded.
        decoded: usize,
        /// The bufferView's byteLength, bytes.
        byte_length: usize,
    },
    /// An accessor (or the Draco attribute standing in for it) that a primitive cannot use; `at` is
    /// the JSON path of the reference (`meshes[0].primitives[1].attributes["POSITION"]`).
    #[error("{at}{}: {problem}", accessor.map_or(String::new(), |a| format!(" (accessor {a})")))]
    Accessor {
        /// JSON path of the reference (`meshes[0].primitives[1].attributes["POSITION"]`).
        at: String,
        /// Index of the accessor, when there is one (not for Draco attributes).
        accessor: Option<usize>,
        /// What is wrong with it.
        problem: AccessorProblem,
    },
    /// A primitive without positions; `at` is its `attributes` (or the Draco extension's).
    #[error("{at} has no POSITION")]
    NoPosition {
        /// JSON path of the primitive's `attributes` (or the Draco extension's).
        at: String,
    },
    /// A `KHR_draco_mesh_compression` primitive whose Draco mesh cannot be used.
    #[error("{at}")]
    Draco {
        /// JSON path of the primitive's `KHR_draco_mesh_compression`.
        at: String,
        /// Why the Draco mesh cannot be used.
        #[source]
        source: DracoMeshError,
    },
    /// A vertex whose position is not finite.
    #[error("{at}: vertex {vertex} has a non-finite position {position:?}")]
    NonFiniteVertex {
        /// JSON path of the primitive.
        at: String,
        /// 0-based index of the vertex.
        vertex: usize,
        /// The position read (primitive units, usually metres).
        position: [f64; 3],
    },
    /// A triangle that refers to a vertex the primitive does not have.
    #[error("{at}: triangle {triangle:?} refers past the {vertices} vertices")]
    TriangleIndex {
        /// JSON path of the primitive.
        at: String,
        /// The triangle's vertex indices.
        triangle: [u32; 3],
        /// Vertices the primitive has.
        vertices: usize,
    },
    /// An `EXT_mesh_features` feature-ID set names a vertex attribute the primitive lacks.
    #[error("{at}.extensions.EXT_mesh_features.featureIds[{set}] names attribute {name}, which is missing")]
    FeatureIdAttribute {
        /// JSON path of the primitive.
        at: String,
        /// Index in `featureIds`.
        set: usize,
        /// The attribute's name (`_FEATURE_ID_n`).
        name: String,
    },
    /// The glTF node hierarchy has a cycle.
    #[error("nodes[{node}]: the node hierarchy has a cycle")]
    NodeCycle {
        /// Index of a node on the cycle.
        node: usize,
    },

    // ------------------------------------------------------------------ feature IDs and metadata
    /// A `_BATCHID` at or above the feature table's `BATCH_LENGTH`.
    #[error("_BATCHID {id} is not below the feature table's BATCH_LENGTH {batch_length}")]
    BatchIdRange {
        /// The batch ID.
        id: u32,
        /// The feature table's `BATCH_LENGTH`.
        batch_length: usize,
    },
    /// `EXT_mesh_features` names a property table that does not exist.
    #[error("EXT_mesh_features refers to property table {table}, which does not exist")]
    NoPropertyTable {
        /// Index in `propertyTables`.
        table: usize,
    },
    /// A feature ID at or above its property table's count.
    #[error("feature ID {id} is not below property table {table}'s count {count}")]
    FeatureIdRange {
        /// The feature ID.
        id: u32,
        /// Index of the property table.
        table: usize,
        /// The property table's `count`.
        count: usize,
    },
    /// A feature ID at or above its feature-ID set's `featureCount`.
    #[error("feature ID {id} is not below featureIds[{set}].featureCount {count}")]
    FeatureCountRange {
        /// The feature ID.
        id: u32,
        /// Index in `featureIds`.
        set: usize,
        /// The set's `featureCount`.
        count: u64,
    },
    /// `EXT_structural_metadata` without a schema.
    #[error("EXT_structural_metadata has neither schema nor schemaUri")]
    NoSchema,
    /// A property table whose class the schema does not define.
    #[error("EXT_structural_metadata.propertyTables[{table}].class {class:?} is not in the schema")]
    UnknownClass {
        /// Index in `propertyTables`.
        table: usize,
        /// The class as written.
        class: String,
    },
    /// A STRING property table column without `stringOffsets`.
    #[error("STRING property without stringOffsets")]
    NoStringOffsets,
    /// A SCALAR property without `componentType`.
    #[error("SCALAR property without componentType")]
    NoComponentType,
    /// A property `componentType` this reader does not know.
    #[error("unknown componentType {component_type:?}")]
    UnknownComponentType {
        /// The componentType as written.
        component_type: String,
    },
    /// A property offset type this reader does not know.
    #[error("unknown offset type {kind:?}")]
    UnknownOffsetType {
        /// The offset type as written.
        kind: String,
    },
    /// A property's offsets run past their bufferView.
    #[error("{count} offsets of {size} bytes exceed their buffer view")]
    OffsetsRange {
        /// Offsets needed.
        count: usize,
        /// Bytes per offset.
        size: usize,
    },
    /// A property's values run past their bufferView.
    #[error("{count} values of {size} bytes exceed the {available}-byte buffer view")]
    ValuesRange {
        /// Values needed.
        count: usize,
        /// Bytes per value.
        size: usize,
        /// The bufferView's length, bytes.
        available: usize,
    },
    /// A string property's offsets point past its values.
    #[error("string bytes {start}..{end} exceed the values")]
    StringRange {
        /// First byte of the string.
        start: usize,
        /// Byte after its last.
        end: usize,
    },
    /// A string property value that is not UTF-8.
    #[error("string at bytes {start}..{end} is not UTF-8")]
    StringUtf8 {
        /// First byte of the string.
        start: usize,
        /// Byte after its last.
        end: usize,
        /// The UTF-8 error.
        #[source]
        source: std::str::Utf8Error,
    },
    /// A buffer shorter than its `byteLength`.
    #[error("buffers[{index}]: byteLength {byte_length} but {available} bytes available")]
    BufferLength {
        /// Index in `buffers`.
        index: usize,
        /// Its `byteLength`, bytes.
        byte_length: usize,
        /// Bytes there are.
        available: usize,
    },

    // ------------------------------------------------------------------ textures (plain GLB conversion)
    /// An image insgen cannot decode; `kind` says what it is ("KTX2 (KHR_texture_basisu)", …).
    #[error("images[{image}] (via {via}) is {kind}")]
    UnreadableImage {
        /// Index in `images`.
        image: usize,
        /// How the texture reaches it (`source`, an extension's name).
        via: &'static str,
        /// What the image is ("KTX2 (KHR_texture_basisu)", …).
        kind: &'static str,
    },
    #[error(
        "textures[{texture}] needs KHR_texture_basisu (KTX2 / Basis Universal, images[{image}]), which insgen cannot decode; re-encode the tileset's textures as JPEG or PNG (e.g. `npx gltf-transform png`)"
    )]
    /// A texture that needs `KHR_texture_basisu` (KTX2), which insgen cannot decode.
    Basisu {
        /// Index in `textures`.
        texture: usize,
        /// Index of the KTX2 image.
        image: u64,
    },
    /// A texture that needs `MSFT_texture_dds`, which insgen cannot decode.
    #[error("textures[{texture}] needs MSFT_texture_dds (images[{image}]), which insgen cannot decode")]
    Dds {
        /// Index in `textures`.
        texture: usize,
        /// Index of the DDS image.
        image: u64,
    },
    /// A texture without any image insgen can read.
    #[error("textures[{texture}] has no image insgen can read")]
    NoTextureImage {
        /// Index in `textures`.
        texture: usize,
    },
    /// An image without data (always inside a [`ContentError::At`] naming the image).
    #[error("has neither a uri nor a bufferView")]
    ImageWithoutData,
    /// A WebP image that cannot be turned into a PNG.
    #[error("images[{image}] (EXT_texture_webp)")]
    Webp {
        /// Index in `images`.
        image: usize,
        /// Why it cannot be converted.
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
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{at}: {problem}")]
pub struct GltfIssue {
    /// `accessors[0].bufferView`, `nodes[2].children`, …
    pub at: String,
    /// What is wrong there.
    pub problem: GltfProblem,
}

/// A broken cross-reference or byte range of a glTF (see [`GltfIssue`]).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum GltfProblem {
    /// A buffer with fewer bytes than its `byteLength`.
    #[error("byteLength {byte_length} but only {available} bytes available")]
    BufferShort {
        /// `byteLength`.
        byte_length: usize,
        /// Bytes loaded.
        available: usize,
    },
    /// An index to an object that does not exist.
    #[error("{kind} {index} does not exist")]
    Missing {
        /// The kind of object: "buffer", "bufferView", "accessor", "node", "mesh", "scene".
        kind: &'static str,
        /// The index.
        index: usize,
    },
    /// A buffer view past the end of its buffer.
    #[error("bytes {offset}..+{length} exceed buffer {buffer} ({buffer_bytes} bytes)")]
    ViewRange {
        /// `byteOffset`.
        offset: usize,
        /// `byteLength`.
        length: usize,
        /// The buffer.
        buffer: usize,
        /// The buffer's size, bytes.
        buffer_bytes: usize,
    },
    /// A `byteStride` outside 4..=252 or not a multiple of 4.
    #[error("{stride} is not a multiple of 4 in 4..=252")]
    Stride {
        /// The stride, bytes.
        stride: usize,
    },
    /// An accessor `type` or `componentType` glTF does not define.
    #[error("unknown type {kind:?} / componentType {component_type}")]
    AccessorType {
        /// `type` as written.
        kind: String,
        /// `componentType`.
        component_type: u32,
    },
    /// An accessor's elements past the end of its buffer view.
    #[error(
        "{count} elements of {element} bytes (stride {stride}) from offset {offset} exceed bufferView {view} \
         ({view_bytes} bytes)"
    )]
    AccessorRange {
        /// Elements.
        count: usize,
        /// Element size, bytes.
        element: usize,
        /// Stride, bytes.
        stride: usize,
        /// `byteOffset`.
        offset: usize,
        /// The buffer view.
        view: usize,
        /// The view's `byteLength`.
        view_bytes: usize,
    },
    /// Sparse indices of a type that is not an unsigned integer.
    #[error("{component_type} is not an unsigned integer")]
    SparseIndexType {
        /// `componentType`.
        component_type: u32,
    },
    /// Sparse indices or values past the end of their buffer view.
    #[error("{count} entries exceed bufferView {view}")]
    SparseRange {
        /// Entries.
        count: usize,
        /// The buffer view.
        view: usize,
    },
    /// A node listed as the child of two nodes.
    #[error("node {node} is already a child of node {first} (glTF nodes form trees)")]
    SecondParent {
        /// The child.
        node: usize,
        /// Its first parent.
        first: usize,
    },
    /// A node transform with NaN or infinite values.
    #[error("transform has non-finite values")]
    NonFiniteTransform,
}

/// What is wrong with an accessor a primitive reads (see [`ContentError::Accessor`]).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum AccessorProblem {
    /// The accessor's type has the wrong number of components.
    #[error("is not {expected}")]
    Type {
        /// The accessor type needed ("VEC3", "SCALAR", …).
        expected: &'static str,
    },
    /// The attribute has a different number of elements than the primitive has vertices.
    #[error("has {values} values for {vertices} vertices")]
    Count {
        /// Elements of the accessor.
        values: usize,
        /// Vertices of the primitive.
        vertices: usize,
    },
    /// A feature-ID value that is not a non-negative integer.
    #[error("value {value} is not a feature ID (a non-negative integer)")]
    NotFeatureId {
        /// The value read.
        value: f64,
    },
    /// An all-zero accessor (no bufferView) so large it is taken as corrupt.
    #[error("{count} elements without a bufferView is implausible")]
    ZeroFilled {
        /// The accessor's `count`.
        count: usize,
    },
    /// A sparse accessor index at or above the accessor's count.
    #[error("sparse index {index} ≥ count {count}")]
    SparseIndex {
        /// The sparse index.
        index: usize,
        /// The accessor's `count`.
        count: usize,
    },
    /// An accessor `type` that glTF does not define.
    #[error("unknown type {kind:?}")]
    UnknownType {
        /// The type as written.
        kind: String,
    },
    /// An accessor `componentType` that glTF does not define.
    #[error("unknown componentType {component_type}")]
    UnknownComponentType {
        /// The componentType as written.
        component_type: u32,
    },
}

/// A content, buffer, image, schema or subtree URI that insgen cannot turn into a local file.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum UriError {
    /// A remote (`scheme://`) or `data:` URI where a file is needed.
    #[error("URI {uri:?} is not a relative file path; only local tilesets are read (download it first)")]
    NotLocal {
        /// The URI as written.
        uri: String,
    },
    /// A URI without a path (empty once query and fragment are dropped).
    #[error("URI {uri:?} names no file")]
    NoFile {
        /// The URI as written.
        uri: String,
    },
    /// A URI with a `%` not followed by two hex digits.
    #[error("URI {uri:?} has an invalid %-escape at byte {at}")]
    PercentEscape {
        /// The URI as written.
        uri: String,
        /// Byte offset of the `%`.
        at: usize,
    },
    /// A URI whose %-escapes decode to bytes that are not UTF-8.
    #[error("URI {uri:?} does not decode to UTF-8")]
    NotUtf8 {
        /// The URI as written.
        uri: String,
        /// The UTF-8 error.
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
    /// The Draco decoder rejects the bitstream.
    #[error("cannot decode the Draco bitstream")]
    Decode(#[source] draco_core::DracoError),
    /// The bitstream is a point cloud, not a triangle mesh.
    #[error("the Draco bitstream holds no triangles (a point cloud?)")]
    PointCloud,
    /// The extension names a Draco attribute (by unique id) the mesh does not have.
    #[error("the Draco mesh has no attribute with unique id {id}{}", if *position { " (POSITION)" } else { "" })]
    NoAttribute {
        /// The attribute's unique id.
        id: u32,
        /// Whether it is the POSITION attribute.
        position: bool,
    },
    #[error(
        "the Draco attribute {id}{} has {found} components, not {needed}",
        if *position { " (POSITION)" } else { "" }
    )]
    /// A Draco attribute with the wrong number of components.
    Components {
        /// The attribute's unique id.
        id: u32,
        /// Whether it is the POSITION attribute.
        position: bool,
        /// Components it has.
        found: usize,
        /// Components needed.
        needed: usize,
    },
}

/// Why an `EXT_meshopt_compression` view cannot be decoded: a broken precondition of the decoder
/// (checked first: its assertions would abort the process) or the decoder's error code.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum MeshoptError {
    /// The decoded view would exceed the size limit.
    #[error("count {count} × byteStride {stride} exceeds {max} bytes")]
    TooLarge {
        /// Elements of the view.
        count: usize,
        /// The view's byteStride, bytes.
        stride: usize,
        /// The limit, bytes.
        max: usize,
    },
    /// `what` is the mode or filter ("ATTRIBUTES mode", "OCTAHEDRAL filter"), `expected` the strides
    /// it accepts.
    #[error("{what} needs a byteStride {expected}, not {stride}")]
    Stride {
        /// The mode or filter ("ATTRIBUTES mode", "OCTAHEDRAL filter").
        what: &'static str,
        /// The strides it accepts ("that is a multiple of 4", …).
        expected: &'static str,
        /// The view's byteStride, bytes.
        stride: usize,
    },
    /// TRIANGLES mode with a count that is not a multiple of 3.
    #[error("TRIANGLES mode needs a count that is a multiple of 3, not {count}")]
    TriangleCount {
        /// The view's count.
        count: usize,
    },
    /// A mode other than ATTRIBUTES, TRIANGLES and INDICES.
    #[error("mode {mode:?} is not ATTRIBUTES, TRIANGLES or INDICES")]
    UnknownMode {
        /// The mode as written.
        mode: String,
    },
    /// The decoder returned an error code: the data is corrupt.
    #[error("the meshopt {mode} decoder failed (code {code}): the data is corrupt")]
    Corrupt {
        /// The mode decoded.
        mode: &'static str,
        /// The decoder's return code.
        code: i32,
    },
    /// A filter on a mode other than ATTRIBUTES.
    #[error("filter {filter} applies to ATTRIBUTES mode only, not {mode}")]
    FilterMode {
        /// The filter as written.
        filter: String,
        /// The mode.
        mode: &'static str,
    },
    /// A filter other than NONE, OCTAHEDRAL, QUATERNION and EXPONENTIAL.
    #[error("filter {filter:?} is not NONE, OCTAHEDRAL, QUATERNION or EXPONENTIAL")]
    UnknownFilter {
        /// The filter as written.
        filter: String,
    },
}

/// Why a WebP texture cannot be re-encoded as PNG.
#[derive(Debug, thiserror::Error)]
pub enum WebpError {
    /// The WebP decoder rejects the image.
    #[error("cannot decode the WebP image")]
    Decode(#[source] image_webp::DecodingError),
    /// The image is too large to decode.
    #[error("the WebP image is too large to decode")]
    TooLarge,
    /// The decoded image cannot be encoded as PNG.
    #[error("cannot encode the decoded WebP image as PNG")]
    Png(#[source] png::EncodingError),
}

#[cfg(test)]
pub(crate) use crate::util::error_chain as chain;
