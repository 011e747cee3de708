//! `scene.glb`: the instanced scene mesh as binary glTF 2.0, written and read back.
//!
//! # Frame and axes
//! Positions are f32 metres in the area's ENU frame, relative to the area origin. glTF is y-up and
//! right-handed, so the file stores glTF (x, y, z) = ENU (east, up, −north); [`read_glb`] undoes this
//! (ENU = (x, −z, y)). Negation is exact in f32, so a write/read round trip is bit-exact.
//!
//! # Layout written by [`write_glb`]
//! - one node (no transform) → one mesh → one triangle primitive with `u32` indices;
//! - `POSITION` (VEC3 FLOAT, with the `min`/`max` glTF requires);
//! - `_FEATURE_ID_0` (SCALAR FLOAT): the 24-bit building ID of each vertex. `EXT_mesh_features`
//!   allows any component type for a feature ID attribute but core glTF has no 32-bit integer vertex
//!   attributes; FLOAT holds every integer up to 2^24 exactly, i.e. every building ID
//!   ([`MAX_BUILDING_ID`] = 2^24 − 1). The primitive declares it with
//!   `EXT_mesh_features: {featureIds: [{featureCount, attribute: 0, nullFeatureId: 0, label: "building",
//!   propertyTable: 0}]}`;
//! - `EXT_structural_metadata`: a schema with class `building` (one STRING property `source_id`) and a
//!   property table with one row per ID `0..=max ID` (row = building ID; rows of IDs without a
//!   building, including the background row 0, hold the empty string), so a viewer that understands
//!   the extension (CesiumJS, for one) shows the source identity of a picked building. Written only
//!   when the IDs are dense (max ID ≤ 2 × buildings + 1024, always the case for IDs 1..=N as
//!   `prepare` assigns them); otherwise the feature IDs stand alone (no `propertyTable`);
//! - `COLOR_0` (VEC4 UNSIGNED_BYTE normalized): a flat colour per building from a hash of its ID
//!   ([`building_colour`]), with an unlit (`KHR_materials_unlit`), double-sided material, so any glTF
//!   viewer shows the instances.
//!
//! With appearances ([`write_glb_with_appearance`], LoD sources with textures or materials), the
//! same primitive (same vertices, triangles and order, so the IDs and masks do not change) also has
//! - `TEXCOORD_0` (VEC2 FLOAT): the face's texture coordinates, flipped to glTF's convention
//!   (`v_gltf = 1 − v`; CityGML/CityJSON put (0, 0) at the image's lower left, glTF at its upper left);
//! - `_APPEARANCE` (SCALAR FLOAT, integers): the face's appearance number, 0 = none (procedural look),
//!   k = `materials[k]`;
//! - `materials[1..]`: one per distinct image (`baseColorTexture` → `textures` → `images` whose `uri`
//!   is `textures/NNNN_<name>` next to the GLB) or colour (`baseColorFactor`), in appearance order;
//!   `asset.extras.appearance_materials` repeats that list for renderers (`{"texture": uri}` or
//!   `{"colour": [r, g, b]}`, linear). The primitive itself keeps material 0: core glTF has one
//!   material per primitive, and splitting the primitive would reorder the triangles the mask
//!   renderer draws.
//!
//! [`add_layers`] then appends the clutter layers as further nodes/meshes named `insgen_clutter_<layer>`
//! (POSITION, COLOR_0, indices; no feature IDs); [`read_glb`] skips them and [`read_layers`] reads them.
//!
//! The JSON is serialised with sorted keys and the binary chunk is written in a fixed order, so
//! identical input gives a byte-identical file.
//!
//! # References
//! glTF 2.0 specification (Khronos), GLB container and accessor rules; `EXT_mesh_features` and
//! `EXT_structural_metadata` (Cesium vendor extensions, glTF extension registry).

use glam::{DMat4, DVec3, Mat4};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use serde_json::{json, Value};

use super::appearance::{AppearanceMaterial, VertexAppearance};
use super::artifact::BuildingRecord;
use super::ids::{BuildingId, MAX_BUILDING_ID};
use super::mesh::SceneMesh;
use crate::util::glb::GlbBuilder;
use crate::util::FileError;

/// Errors of the GLB writer and reader; every variant names the file.
#[derive(Debug, thiserror::Error)]
pub enum GlbError {
    /// Reading or writing the file failed.
    #[error(transparent)]
    File(#[from] FileError),
    /// The mesh or building table handed to [`write_glb`] cannot be written (inconsistent lengths,
    /// out-of-range indices or IDs, non-finite coordinates, an ID missing from the table).
    #[error("{}: cannot write the scene: {problem}", path.display())]
    BadInput {
        /// The GLB being written.
        path: PathBuf,
        /// What is wrong with the input.
        problem: InputProblem,
    },
    /// The data does not fit the GLB container (32-bit lengths).
    #[error("{}: the scene needs {bytes} bytes, more than a GLB file can hold (4 GiB); split the area", path.display())]
    TooLarge {
        /// The GLB being written.
        path: PathBuf,
        /// Bytes it would need.
        bytes: u64,
    },
    /// The file is not a valid GLB/glTF document.
    #[error("{}: not a valid binary glTF file", path.display())]
    Parse {
        /// The file.
        path: PathBuf,
        /// The glTF reader's error.
        #[source]
        source: gltf::Error,
    },
    /// The file is not a GLB container (header or chunks).
    #[error("{}: not a valid binary glTF file", path.display())]
    Container {
        /// The file.
        path: PathBuf,
        /// The container reader's error.
        #[source]
        source: crate::util::glb::GlbError,
    },
    /// The `EXT_mesh_features` extensions do not parse.
    #[error("{}: meshes[*].primitives[*].extensions: unexpected EXT_mesh_features content", path.display())]
    MeshFeatures {
        /// The file.
        path: PathBuf,
        /// The JSON parser's error.
        #[source]
        source: serde_json::Error,
    },
    /// The document is valid glTF but not an instanced scene insgen can read; `at` is a JSON path.
    #[error("{}: {at}: {problem}", path.display())]
    Invalid {
        /// The file.
        path: PathBuf,
        /// JSON path of the object at fault (`meshes[0].primitives[1].indices`).
        at: String,
        /// What is wrong there.
        problem: SceneGlbProblem,
    },
}

/// Why a mesh (or clutter layer) cannot be written as `scene.glb` (see [`GlbError::BadInput`]).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum InputProblem {
    /// Positions and building IDs differ in number.
    #[error("{positions} positions but {building_ids} building IDs")]
    Lengths {
        /// Positions.
        positions: usize,
        /// Building IDs.
        building_ids: usize,
    },
    /// The mesh has no triangle.
    #[error("the mesh has no triangles")]
    NoTriangles,
    /// The index count is not a multiple of 3.
    #[error("{indices} indices is not a multiple of 3")]
    IndexCount {
        /// Indices.
        indices: usize,
    },
    /// More vertices than a u32-indexed primitive holds.
    #[error("{vertices} vertices: a u32-indexed primitive holds at most {}", u32::MAX - 1)]
    TooManyVertices {
        /// Vertices.
        vertices: usize,
    },
    /// An index past the vertices.
    #[error("index {index} is {value}, but there are only {vertices} vertices")]
    IndexRange {
        /// Position in the index list.
        index: usize,
        /// The index.
        value: u32,
        /// Vertices.
        vertices: usize,
    },
    /// A vertex position is NaN or infinite.
    #[error("vertex {vertex} has a non-finite coordinate {position_m:?}")]
    NonFinite {
        /// The vertex.
        vertex: usize,
        /// Its position, ENU metres.
        position_m: [f32; 3],
    },
    /// A building table row with the background's ID.
    #[error("building {source_id:?} has ID 0, the background's")]
    BackgroundId {
        /// The building's source id.
        source_id: String,
    },
    /// Two building table rows with one ID.
    #[error("ID {id} is used by both {first:?} and {second:?}")]
    DuplicateId {
        /// The ID.
        id: BuildingId,
        /// The first row's source id.
        first: String,
        /// The second row's source id.
        second: String,
    },
    /// A vertex ID the building table lacks.
    #[error("vertex {vertex} has building ID {id}, which is not in the building table")]
    UnknownId {
        /// The vertex.
        vertex: usize,
        /// Its building ID.
        id: BuildingId,
    },
    /// Appearance data not parallel to the vertices.
    #[error("{vertices} vertices but {uvs} texture coordinates and {appearances} appearance numbers")]
    AppearanceLengths {
        /// Vertices.
        vertices: usize,
        /// Texture coordinates.
        uvs: usize,
        /// Appearance numbers.
        appearances: usize,
    },
    /// An appearance number past the materials.
    #[error("appearance {appearance}, but there are {materials} materials")]
    AppearanceIndex {
        /// The appearance number.
        appearance: u32,
        /// Materials.
        materials: usize,
    },
    /// A texture coordinate that is NaN or infinite.
    #[error("non-finite texture coordinate {uv:?}")]
    NonFiniteUv {
        /// The coordinate.
        uv: [f32; 2],
    },
    /// A clutter layer whose colours or indices do not fit its positions.
    #[error("clutter layer {layer}: inconsistent buffers")]
    LayerBuffers {
        /// The layer.
        layer: crate::scene::clutter::ClutterLayer,
    },
    /// A clutter layer with a non-finite coordinate.
    #[error("clutter layer {layer}: a non-finite coordinate")]
    LayerNonFinite {
        /// The layer.
        layer: crate::scene::clutter::ClutterLayer,
    },
    /// The scene GLB's JSON lacks a top-level list (`materials`, `meshes`, `nodes`).
    #[error("the scene GLB has no {key} list")]
    NoList {
        /// The list's key.
        key: &'static str,
    },
    /// The scene GLB's scene has no node list.
    #[error("the scene GLB has no scene node list")]
    NoSceneNodes,
}

/// Why a valid glTF is not a scene insgen can read (see [`GlbError::Invalid`]).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SceneGlbProblem {
    /// A sparse accessor.
    #[error("sparse accessors are not supported")]
    Sparse,
    /// An accessor without a buffer view.
    #[error("accessor has no bufferView")]
    NoBufferView,
    /// Data outside the GLB's binary chunk.
    #[error("data in an external buffer; scene.glb must be self-contained")]
    ExternalBuffer,
    /// A stride shorter than an element.
    #[error("byteStride {stride} is smaller than the element size {element}")]
    Stride {
        /// The stride, bytes.
        stride: usize,
        /// The element size, bytes.
        element: usize,
    },
    /// An accessor that runs past its view or the binary chunk.
    #[error(
        "{count} elements of {element} bytes (stride {stride}) at byte {start} overrun the buffer view (ends \
         at {view_end}) or the binary chunk ({bin} bytes)"
    )]
    Overrun {
        /// Elements.
        count: usize,
        /// Element size, bytes.
        element: usize,
        /// Stride, bytes.
        stride: usize,
        /// First byte.
        start: u64,
        /// End of the view, bytes.
        view_end: u64,
        /// Size of the binary chunk, bytes.
        bin: usize,
    },
    /// POSITION not VEC3 FLOAT.
    #[error("POSITION must be VEC3 FLOAT (quantized positions are not supported), found {dimensions:?} {data_type:?}")]
    PositionType {
        /// The accessor's type.
        dimensions: gltf::accessor::Dimensions,
        /// The accessor's component type.
        data_type: gltf::accessor::DataType,
    },
    /// A feature ID attribute that is not a plain scalar.
    #[error("a feature ID attribute must be SCALAR and not normalized")]
    FeatureIdShape,
    /// A feature ID component type that is not read.
    #[error("feature IDs of component type {data_type:?} are not supported")]
    FeatureIdType {
        /// The component type.
        data_type: gltf::accessor::DataType,
    },
    /// A float feature ID that is not a building ID.
    #[error(
        "vertex {vertex}: feature ID {value} is not a building ID (an integer in 1..={MAX_BUILDING_ID})"
    )]
    FeatureIdFloat {
        /// The vertex.
        vertex: usize,
        /// Its feature ID.
        value: f32,
    },
    /// An integer feature ID that is not a building ID (0, too large, or the null ID).
    #[error(
        "vertex {vertex}: feature ID {value} is not a building ID (1..={MAX_BUILDING_ID}, not the null ID)"
    )]
    FeatureIdValue {
        /// The vertex.
        vertex: usize,
        /// Its feature ID.
        value: u32,
    },
    /// Indices that are not scalar unsigned integers.
    #[error("indices must be SCALAR unsigned integers, found {dimensions:?} {data_type:?}")]
    IndexType {
        /// The accessor's type.
        dimensions: gltf::accessor::Dimensions,
        /// The accessor's component type.
        data_type: gltf::accessor::DataType,
    },
    /// An index count that is not whole triangles.
    #[error("{count} indices is not a multiple of 3 (TRIANGLES)")]
    IndexCount {
        /// Indices.
        count: usize,
    },
    /// An index past the primitive's vertices.
    #[error("index {index} is {value}, but the primitive has {vertices} vertices")]
    IndexRange {
        /// Position in the index list.
        index: usize,
        /// The index.
        value: u32,
        /// The primitive's vertices.
        vertices: usize,
    },
    /// The document has no scene.
    #[error("the file has no scene")]
    NoScene,
    /// The scene has no triangle.
    #[error("the scene has no triangles")]
    NoTriangles,
    /// A primitive that is not TRIANGLES.
    #[error("mode {mode:?}: only TRIANGLES are supported")]
    Mode {
        /// Its mode.
        mode: gltf::mesh::Mode,
    },
    /// A primitive without building IDs.
    #[error(
        "no EXT_mesh_features feature ID attribute: building IDs are missing (was this file written by \
         `insgen prepare`?)"
    )]
    NoFeatureIds,
    /// A primitive without POSITION.
    #[error("no POSITION attribute")]
    NoPosition,
    /// `EXT_mesh_features` names an attribute the primitive lacks.
    #[error("EXT_mesh_features names {attribute}, which is absent")]
    MissingFeatureAttribute {
        /// The attribute (`_FEATURE_ID_0`).
        attribute: String,
    },
    /// POSITION and feature IDs differ in count.
    #[error("{positions} positions but {feature_ids} feature IDs")]
    CountMismatch {
        /// Positions.
        positions: usize,
        /// Feature IDs.
        feature_ids: usize,
    },
    /// More vertices than u32 indices reach.
    #[error("more than 2^32 − 1 vertices in total")]
    TooManyVertices,
    /// A non-indexed primitive that is not whole triangles.
    #[error("{vertices} vertices without indices is not whole triangles")]
    Unindexed {
        /// Vertices.
        vertices: usize,
    },
    /// A clutter node of a layer insgen does not know.
    #[error("unknown clutter layer {name:?}")]
    UnknownLayer {
        /// The layer's name.
        name: String,
    },
    /// A clutter primitive without POSITION.
    #[error("no POSITION")]
    LayerNoPosition,
    /// A clutter primitive whose colours and positions differ in count.
    #[error("COLOR_0 and POSITION counts differ")]
    LayerColors,
    /// A clutter primitive without indices.
    #[error("no indices")]
    LayerNoIndices,
}

/// glTF `componentType` codes (glTF 2.0, accessor.componentType).
const COMPONENT_UNSIGNED_BYTE: u32 = 5121;
const COMPONENT_UNSIGNED_INT: u32 = 5125;
const COMPONENT_FLOAT: u32 = 5126;
/// glTF bufferView `target` codes.
const TARGET_ARRAY_BUFFER: u32 = 34962;
const TARGET_ELEMENT_ARRAY_BUFFER: u32 = 34963;
/// glTF primitive mode TRIANGLES.
const MODE_TRIANGLES: u32 = 4;
/// Alignment of buffer views: 4 bytes for vertex data (glTF), 8 bytes for property tables
/// (`EXT_structural_metadata`, "Binary Data Storage"); 8 serves both.
const VIEW_ALIGN: usize = 8;

/// Semantic of the feature ID attribute (`EXT_mesh_features`: `_FEATURE_ID_n`, set index 0).
pub const FEATURE_ID_ATTRIBUTE: &str = "_FEATURE_ID_0";
/// Label of the feature ID set and name of the metadata class.
pub const FEATURE_LABEL: &str = "building";

/// The flat display colour of a building (sRGB bytes), a deterministic hash of its ID.
///
/// Channels are kept in 56..=255 so that no building is near-black against a dark background.
pub fn building_colour(id: BuildingId) -> [u8; 3] {
    // splitmix64 finaliser: neighbouring IDs get unrelated colours.
    let mut z = u64::from(id.get()).wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^= z >> 31;
    let ch = |shift: u32| (56 + ((z >> shift) & 0xFF) * 199 / 255) as u8;
    [ch(0), ch(8), ch(16)]
}

/// ENU metres → glTF y-up axes.
#[inline]
fn enu_to_gltf(p: [f32; 3]) -> [f32; 3] {
    [p[0], p[2], -p[1]]
}

/// glTF y-up axes → ENU metres.
#[inline]
fn gltf_to_enu(p: [f32; 3]) -> [f32; 3] {
    [p[0], -p[2], p[1]]
}

/// Checks the mesh and the building table before anything is written.
fn check_input(path: &Path, mesh: &SceneMesh, buildings: &[BuildingRecord]) -> Result<(), GlbError> {
    let bad = |problem: InputProblem| GlbError::BadInput { path: path.to_path_buf(), problem };
    let n = mesh.positions_m.len();
    if mesh.building_ids.len() != n {
        return Err(bad(InputProblem::Lengths { positions: n, building_ids: mesh.building_ids.len() }));
    }
    if mesh.indices.is_empty() {
        return Err(bad(InputProblem::NoTriangles));
    }
    if !mesh.indices.len().is_multiple_of(3) {
        return Err(bad(InputProblem::IndexCount { indices: mesh.indices.len() }));
    }
    // glTF forbids the largest index value (primitive restart), so at most u32::MAX vertices.
    if n >= u32::MAX as usize {
        return Err(bad(InputProblem::TooManyVertices { vertices: n }));
    }
    if let Some((k, &i)) = mesh.indices.iter().enumerate().find(|(_, &i)| i as usize >= n) {
        return Err(bad(InputProblem::IndexRange { index: k, value: i, vertices: n }));
    }
    if let Some((k, p)) = mesh.positions_m.iter().enumerate().find(|(_, p)| !p.iter().all(|c| c.is_finite()))
    {
        return Err(bad(InputProblem::NonFinite { vertex: k, position_m: *p }));
    }
    let mut known = BTreeMap::new();
    for b in buildings {
        if b.id.is_background() {
            return Err(bad(InputProblem::BackgroundId { source_id: b.source_id.clone() }));
        }
        if let Some(prev) = known.insert(b.id, &b.source_id) {
            return Err(bad(InputProblem::DuplicateId {
                id: b.id,
                first: prev.clone(),
                second: b.source_id.clone(),
            }));
        }
    }
    let mut last = None;
    for (k, &id) in mesh.building_ids.iter().enumerate() {
        if last != Some(id) && !known.contains_key(&id) {
            return Err(bad(InputProblem::UnknownId { vertex: k, id }));
        }
        last = Some(id);
    }
    Ok(())
}

/// Appearances to write with the mesh: per-vertex data parallel to the mesh's vertices, and the
/// materials it numbers (appearance k = `materials[k − 1]`).
#[derive(Debug, Clone, Copy)]
pub struct GlbAppearance<'a> {
    /// Per-vertex texture coordinates and appearance numbers, parallel to the mesh's vertices.
    pub vertices: &'a VertexAppearance,
    /// The materials the appearance numbers count (appearance k = `materials[k − 1]`).
    pub materials: &'a [AppearanceMaterial],
}

/// Name of the per-vertex appearance attribute (a glTF application-specific attribute).
pub const APPEARANCE_ATTRIBUTE: &str = "_APPEARANCE";

/// Writes the instanced scene mesh as `scene.glb` (atomically).
///
/// `buildings` is the building table: every ID in `mesh.building_ids` must be in it; it fills the
/// `EXT_structural_metadata` property table (ID → `source_id`). See the module doc for the layout.
///
/// # Units
/// `mesh.positions_m` are ENU metres relative to the area origin; they are stored as glTF (x, y, z) =
/// (east, up, −north).
///
/// # Errors
/// [`GlbError::BadInput`] when the mesh is empty or inconsistent or an ID is not in `buildings`;
/// [`GlbError::TooLarge`] past the 4 GiB GLB limit; [`GlbError::File`] on I/O failure (then `path` is
/// left as it was).
pub fn write_glb(path: &Path, mesh: &SceneMesh, buildings: &[BuildingRecord]) -> Result<(), GlbError> {
    write_glb_with_appearance(path, mesh, buildings, None)
}

/// [`write_glb`] with textures and colours (see the module doc): without `appearance` the file is
/// byte for byte what [`write_glb`] writes.
///
/// # Errors
/// As [`write_glb`], and [`GlbError::BadInput`] when the appearance data is not parallel to the
/// vertices or numbers a material that does not exist.
pub fn write_glb_with_appearance(
    path: &Path,
    mesh: &SceneMesh,
    buildings: &[BuildingRecord],
    appearance: Option<&GlbAppearance>,
) -> Result<(), GlbError> {
    check_input(path, mesh, buildings)?;
    if let Some(a) = appearance {
        check_appearance(path, mesh, a)?;
    }
    let n_vertices = mesh.positions_m.len() as u64;
    let table = SourceIdTable::new(mesh, buildings);
    if table.string_bytes > u64::from(u32::MAX) {
        return Err(GlbError::TooLarge { path: path.to_path_buf(), bytes: table.string_bytes });
    }

    // Views in a fixed order (0 POSITION, 1 _FEATURE_ID_0, 2 COLOR_0, 3 indices, then the property
    // table's strings and offsets, then the appearance views), so the file is the same every time.
    let mut b = GlbBuilder::with_view_alignment(VIEW_ALIGN);
    let vertex_view =
        |b: &mut GlbBuilder, bytes: Vec<u8>| b.push_view_with(&bytes, None, Some(TARGET_ARRAY_BUFFER));
    vertex_view(
        &mut b,
        mesh.positions_m.iter().flat_map(|&p| enu_to_gltf(p)).flat_map(f32::to_le_bytes).collect(),
    );
    // Exact: a BuildingId is at most 2^24 − 1, and f32 holds every integer up to 2^24.
    vertex_view(&mut b, mesh.building_ids.iter().flat_map(|id| (id.get() as f32).to_le_bytes()).collect());
    vertex_view(&mut b, colour_bytes(&mesh.building_ids));
    let indices: Vec<u8> = mesh.indices.iter().flat_map(|i| i.to_le_bytes()).collect();
    b.push_view_with(&indices, None, Some(TARGET_ELEMENT_ARRAY_BUFFER));
    if table.rows.is_some() {
        let (strings, offsets) = table.views();
        b.push_view(&strings, None);
        b.push_view(&offsets, None);
    }

    // Bounds in the glTF frame, as the validator recomputes them from the stored f32 values; min/max
    // as the f64 value of each f32, so they equal the stored data exactly whichever precision the
    // reader compares in.
    let (mut lo, mut hi) = ([f32::INFINITY; 3], [f32::NEG_INFINITY; 3]);
    for &p in &mesh.positions_m {
        let g = enu_to_gltf(p);
        for k in 0..3 {
            lo[k] = lo[k].min(g[k]);
            hi[k] = hi[k].max(g[k]);
        }
    }
    let f64s = |a: [f32; 3]| a.map(f64::from).to_vec();
    let n_indices = mesh.indices.len();
    for accessor in [
        json!({"bufferView": 0, "componentType": COMPONENT_FLOAT, "count": n_vertices, "type": "VEC3",
               "min": f64s(lo), "max": f64s(hi)}),
        json!({"bufferView": 1, "componentType": COMPONENT_FLOAT, "count": n_vertices, "type": "SCALAR"}),
        json!({"bufferView": 2, "componentType": COMPONENT_UNSIGNED_BYTE, "normalized": true,
               "count": n_vertices, "type": "VEC4"}),
        json!({"bufferView": 3, "componentType": COMPONENT_UNSIGNED_INT, "count": n_indices, "type": "SCALAR"}),
    ] {
        b.push_accessor(accessor);
    }
    let mut json = document_json(table.rows, table.feature_count);
    if let Some(a) = appearance {
        add_appearance(&mut json, &mut b, a);
    }
    let bytes = b.finish(json).map_err(|e| glb_error(path, e))?;
    Ok(crate::util::write_bytes_atomic(path, &bytes)?)
}

/// The container's error, for the scene file at `path`.
fn glb_error(path: &Path, e: crate::util::glb::GlbError) -> GlbError {
    match e {
        crate::util::glb::GlbError::TooLarge { bytes } => {
            GlbError::TooLarge { path: path.to_path_buf(), bytes }
        }
        source => GlbError::Container { path: path.to_path_buf(), source },
    }
}

/// Checks that the appearance data is parallel to the mesh's vertices and numbers existing materials.
fn check_appearance(path: &Path, mesh: &SceneMesh, a: &GlbAppearance) -> Result<(), GlbError> {
    let n = mesh.positions_m.len();
    let bad = |problem: InputProblem| GlbError::BadInput { path: path.to_path_buf(), problem };
    if a.vertices.uvs.len() != n || a.vertices.ids.len() != n {
        return Err(bad(InputProblem::AppearanceLengths {
            vertices: n,
            uvs: a.vertices.uvs.len(),
            appearances: a.vertices.ids.len(),
        }));
    }
    if let Some(&k) = a.vertices.ids.iter().find(|&&k| k as usize > a.materials.len()) {
        return Err(bad(InputProblem::AppearanceIndex { appearance: k, materials: a.materials.len() }));
    }
    if let Some(uv) = a.vertices.uvs.iter().find(|uv| !uv.iter().all(|c| c.is_finite())) {
        return Err(bad(InputProblem::NonFiniteUv { uv: *uv }));
    }
    Ok(())
}

/// `COLOR_0` bytes: each vertex's building colour ([`building_colour`]), opaque.
fn colour_bytes(ids: &[BuildingId]) -> Vec<u8> {
    let mut out = Vec::with_capacity(ids.len() * 4);
    let mut colour_of = (None, [0u8; 4]);
    for &id in ids {
        if colour_of.0 != Some(id) {
            let [r, g, b] = building_colour(id);
            colour_of = (Some(id), [r, g, b, 255]);
        }
        out.extend_from_slice(&colour_of.1);
    }
    out
}

/// The `EXT_structural_metadata` property table: row = building ID, rows 0..=max ID, one STRING
/// property `source_id`.
struct SourceIdTable<'a> {
    source_ids: BTreeMap<u32, &'a str>,
    max_id: u32,
    /// Number of distinct building IDs in the mesh.
    feature_count: u64,
    /// Rows of the table; `None` when the IDs are too sparse for one (see the module doc).
    rows: Option<u64>,
    /// Bytes of all strings of the table.
    string_bytes: u64,
}

impl<'a> SourceIdTable<'a> {
    fn new(mesh: &SceneMesh, buildings: &'a [BuildingRecord]) -> SourceIdTable<'a> {
        let mut distinct: Vec<u32> = mesh.building_ids.iter().map(|id| id.get()).collect();
        distinct.sort_unstable();
        distinct.dedup();
        let feature_count = distinct.len() as u64;
        // Only when the IDs are dense (as `prepare` assigns them, 1..=N), so that a few scattered
        // large IDs do not bloat the file with empty rows.
        let source_ids: BTreeMap<u32, &str> =
            buildings.iter().map(|b| (b.id.get(), b.source_id.as_str())).collect();
        let max_id = distinct.last().copied().unwrap_or(0);
        let rows = (u64::from(max_id) <= 2 * feature_count + 1024).then_some(u64::from(max_id) + 1);
        let string_bytes: u64 = match rows {
            Some(_) => (0..=max_id).map(|id| source_ids.get(&id).map_or(0, |s| s.len() as u64)).sum(),
            None => 0,
        };
        SourceIdTable { source_ids, max_id, feature_count, rows, string_bytes }
    }

    /// The string values and the UINT32 string offsets (one more than rows).
    fn views(&self) -> (Vec<u8>, Vec<u8>) {
        let mut strings = Vec::with_capacity(self.string_bytes as usize);
        let mut offsets = Vec::with_capacity((self.max_id as usize + 2) * 4);
        let mut offset = 0u32;
        offsets.extend_from_slice(&offset.to_le_bytes());
        for id in 0..=self.max_id {
            if let Some(s) = self.source_ids.get(&id) {
                strings.extend_from_slice(s.as_bytes());
                // Cannot overflow: the sum of all lengths was checked against u32::MAX.
                offset += s.len() as u32;
            }
            offsets.extend_from_slice(&offset.to_le_bytes());
        }
        (strings, offsets)
    }
}

/// The glTF JSON document of the scene, without the buffers, views and accessors the
/// [`GlbBuilder`] fills in; `table_rows` as [`SourceIdTable::rows`].
fn document_json(table_rows: Option<u64>, feature_count: u64) -> Value {
    let mut doc = json!({
        "asset": {
            "version": "2.0",
            "generator": concat!("insgen ", env!("CARGO_PKG_VERSION")),
            "extras": {
                "frame": "area ENU metres relative to the origin in manifest.json; \
                          glTF (x, y, z) = (east, up, -north)"
            }
        },
        "extensionsUsed": ["EXT_mesh_features", "EXT_structural_metadata", "KHR_materials_unlit"],
        "extensions": {
            "EXT_structural_metadata": {
                "schema": {
                    "id": "insgen",
                    "classes": {
                        FEATURE_LABEL: {
                            "description": "One building instance; the row index is its 24-bit ID",
                            "properties": {
                                "source_id": {
                                    "type": "STRING",
                                    "description": "gml:id, CityJSON key or other identity in the source"
                                }
                            }
                        }
                    }
                },
                "propertyTables": [{
                    "name": "buildings",
                    "class": FEATURE_LABEL,
                    "count": table_rows.unwrap_or(0),
                    "properties": {
                        "source_id": {"values": 4, "stringOffsets": 5, "stringOffsetType": "UINT32"}
                    }
                }]
            }
        },
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": [{"name": "buildings", "mesh": 0}],
        "meshes": [{
            "name": "buildings",
            "primitives": [{
                "attributes": {"POSITION": 0, FEATURE_ID_ATTRIBUTE: 1, "COLOR_0": 2},
                "indices": 3,
                "material": 0,
                "mode": MODE_TRIANGLES,
                "extensions": {
                    "EXT_mesh_features": {
                        "featureIds": [{
                            "featureCount": feature_count,
                            "attribute": 0,
                            "nullFeatureId": 0,
                            "label": FEATURE_LABEL,
                            "propertyTable": 0
                        }]
                    }
                }
            }]
        }],
        "materials": [{
            "name": "building_ids_unlit",
            "pbrMetallicRoughness": {"baseColorFactor": [1.0, 1.0, 1.0, 1.0], "metallicFactor": 0.0,
                                     "roughnessFactor": 1.0},
            "doubleSided": true,
            "extensions": {"KHR_materials_unlit": {}}
        }],
    });
    if table_rows.is_none() {
        doc["extensionsUsed"] = json!(["EXT_mesh_features", "KHR_materials_unlit"]);
        if let Some(root) = doc.as_object_mut() {
            root.remove("extensions");
        }
        if let Some(set) = doc["meshes"][0]["primitives"][0]["extensions"]["EXT_mesh_features"]["featureIds"]
            [0]
        .as_object_mut()
        {
            set.remove("propertyTable");
        }
    }
    doc
}

/// Adds the appearance views and accessors (`TEXCOORD_0`, `_APPEARANCE`, after every other view) and
/// the images, textures and materials to the document (see the module doc).
fn add_appearance(doc: &mut Value, b: &mut GlbBuilder, a: &GlbAppearance) {
    let n_vertices = a.vertices.uvs.len();
    // glTF puts (0, 0) at the image's upper-left corner, the LoD sources at its lower left.
    let uvs: Vec<u8> =
        a.vertices.uvs.iter().flat_map(|uv| [uv[0], 1.0 - uv[1]]).flat_map(f32::to_le_bytes).collect();
    let uv_view = b.push_view_with(&uvs, None, Some(TARGET_ARRAY_BUFFER));
    // Exact: appearance numbers stay far below 2^24.
    let numbers: Vec<u8> = a.vertices.ids.iter().flat_map(|&k| (k as f32).to_le_bytes()).collect();
    let number_view = b.push_view_with(&numbers, None, Some(TARGET_ARRAY_BUFFER));
    let uv_accessor = b.push_accessor(
        json!({"bufferView": uv_view, "componentType": COMPONENT_FLOAT, "count": n_vertices, "type": "VEC2"}),
    );
    let number_accessor = b.push_accessor(
        json!({"bufferView": number_view, "componentType": COMPONENT_FLOAT, "count": n_vertices, "type": "SCALAR"}),
    );
    let attributes = &mut doc["meshes"][0]["primitives"][0]["attributes"];
    attributes["TEXCOORD_0"] = json!(uv_accessor);
    attributes[APPEARANCE_ATTRIBUTE] = json!(number_accessor);
    let materials = a.materials;
    let (mut images, mut textures, mut mats, mut extras) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    for (k, m) in materials.iter().enumerate() {
        let name = format!("appearance_{}", k + 1);
        match m {
            AppearanceMaterial::Texture { file_name, .. } => {
                let uri = format!("{}/{file_name}", super::appearance::TEXTURES_DIR);
                textures.push(json!({"source": images.len(), "sampler": 0}));
                images.push(json!({"uri": uri}));
                mats.push(json!({"name": name, "doubleSided": true,
                    "pbrMetallicRoughness": {"baseColorTexture": {"index": textures.len() - 1},
                                             "metallicFactor": 0.0, "roughnessFactor": 1.0}}));
                extras.push(json!({"texture": uri}));
            }
            AppearanceMaterial::Colour { rgb } => {
                mats.push(json!({"name": name, "doubleSided": true,
                    "pbrMetallicRoughness": {"baseColorFactor": [rgb[0], rgb[1], rgb[2], 1.0],
                                             "metallicFactor": 0.0, "roughnessFactor": 1.0}}));
                extras.push(json!({"colour": rgb}));
            }
        }
    }
    if let Some(list) = doc["materials"].as_array_mut() {
        list.extend(mats);
    }
    if !images.is_empty() {
        doc["images"] = json!(images);
        doc["textures"] = json!(textures);
        // REPEAT wrapping and linear filtering (glTF sampler codes 10497, 9729).
        doc["samplers"] = json!([{"wrapS": 10497, "wrapT": 10497, "magFilter": 9729, "minFilter": 9729}]);
    }
    doc["asset"]["extras"]["appearance_materials"] = json!(extras);
}

/// The part of a primitive's JSON that the `gltf` crate does not keep (extensions it does not know).
#[derive(serde::Deserialize, Default)]
struct RawRoot {
    #[serde(default)]
    meshes: Vec<RawMesh>,
}
#[derive(serde::Deserialize, Default)]
struct RawMesh {
    #[serde(default)]
    primitives: Vec<RawPrimitive>,
}
#[derive(serde::Deserialize, Default)]
struct RawPrimitive {
    #[serde(default)]
    extensions: Option<RawPrimitiveExtensions>,
}
#[derive(serde::Deserialize, Default)]
struct RawPrimitiveExtensions {
    #[serde(rename = "EXT_mesh_features")]
    mesh_features: Option<RawMeshFeatures>,
}
/// `EXT_mesh_features` on a primitive (only the fields the reader uses).
#[derive(serde::Deserialize, Default)]
struct RawMeshFeatures {
    #[serde(rename = "featureIds", default)]
    feature_ids: Vec<RawFeatureId>,
}
#[derive(serde::Deserialize, Default)]
struct RawFeatureId {
    /// Set index `n` of the `_FEATURE_ID_n` attribute.
    attribute: Option<u32>,
    label: Option<String>,
    #[serde(rename = "nullFeatureId")]
    null_feature_id: Option<u64>,
}

/// A located accessor: its bytes in the binary chunk.
struct AccessorBytes<'a> {
    data: &'a [u8],
    stride: usize,
    count: usize,
}

/// Resolves an accessor to a byte range of the BIN chunk, checking every bound.
fn accessor_bytes<'a>(
    path: &Path,
    at: &str,
    acc: &gltf::Accessor<'_>,
    bin: &'a [u8],
    elem_size: usize,
) -> Result<AccessorBytes<'a>, GlbError> {
    let invalid = |problem| GlbError::Invalid { path: path.to_path_buf(), at: at.to_string(), problem };
    if acc.sparse().is_some() {
        return Err(invalid(SceneGlbProblem::Sparse));
    }
    let view = acc.view().ok_or_else(|| invalid(SceneGlbProblem::NoBufferView))?;
    if !matches!(view.buffer().source(), gltf::buffer::Source::Bin) {
        return Err(invalid(SceneGlbProblem::ExternalBuffer));
    }
    let stride = view.stride().unwrap_or(elem_size);
    if stride < elem_size {
        return Err(invalid(SceneGlbProblem::Stride { stride, element: elem_size }));
    }
    let count = acc.count();
    let start = view.offset() as u64 + acc.offset() as u64;
    let need = if count == 0 { 0 } else { (count as u64 - 1) * stride as u64 + elem_size as u64 };
    let view_end = view.offset() as u64 + view.length() as u64;
    if start + need > view_end || view_end > bin.len() as u64 {
        return Err(invalid(SceneGlbProblem::Overrun {
            count,
            element: elem_size,
            stride,
            start,
            view_end,
            bin: bin.len(),
        }));
    }
    let data = &bin[start as usize..(start + need) as usize];
    Ok(AccessorBytes { data, stride, count })
}

fn le_f32(b: &[u8]) -> f32 {
    f32::from_le_bytes([b[0], b[1], b[2], b[3]])
}

/// Decodes a VEC3 FLOAT position accessor, converting to ENU.
fn read_positions(
    path: &Path,
    at: &str,
    acc: &gltf::Accessor<'_>,
    bin: &[u8],
    transform: Option<&DMat4>,
    out: &mut Vec<[f32; 3]>,
) -> Result<(), GlbError> {
    use gltf::accessor::{DataType, Dimensions};
    if acc.data_type() != DataType::F32 || acc.dimensions() != Dimensions::Vec3 || acc.normalized() {
        return Err(GlbError::Invalid {
            path: path.to_path_buf(),
            at: at.to_string(),
            problem: SceneGlbProblem::PositionType {
                dimensions: acc.dimensions(),
                data_type: acc.data_type(),
            },
        });
    }
    let a = accessor_bytes(path, at, acc, bin, 12)?;
    out.reserve(a.count);
    let elems = (0..a.count).map(|k| &a.data[k * a.stride..k * a.stride + 12]);
    match transform {
        None => {
            out.extend(elems.map(|e| gltf_to_enu([le_f32(&e[0..4]), le_f32(&e[4..8]), le_f32(&e[8..12])])))
        }
        Some(m) => out.extend(elems.map(|e| {
            let p = DVec3::new(le_f32(&e[0..4]).into(), le_f32(&e[4..8]).into(), le_f32(&e[8..12]).into());
            gltf_to_enu(m.transform_point3(p).as_vec3().to_array())
        })),
    }
    Ok(())
}

/// Decodes a SCALAR feature ID accessor into building IDs (1..=MAX_BUILDING_ID).
fn read_feature_ids(
    path: &Path,
    at: &str,
    acc: &gltf::Accessor<'_>,
    bin: &[u8],
    null_id: Option<u64>,
    out: &mut Vec<BuildingId>,
) -> Result<(), GlbError> {
    use gltf::accessor::{DataType, Dimensions};
    let invalid = |problem| GlbError::Invalid { path: path.to_path_buf(), at: at.to_string(), problem };
    if acc.dimensions() != Dimensions::Scalar || acc.normalized() {
        return Err(invalid(SceneGlbProblem::FeatureIdShape));
    }
    let size = match acc.data_type() {
        DataType::U8 => 1,
        DataType::U16 => 2,
        DataType::U32 | DataType::F32 => 4,
        other => return Err(invalid(SceneGlbProblem::FeatureIdType { data_type: other })),
    };
    let a = accessor_bytes(path, at, acc, bin, size)?;
    let elems = (0..a.count).map(|k| &a.data[k * a.stride..k * a.stride + size]);
    let raw: Vec<u32> = match acc.data_type() {
        DataType::U8 => elems.map(|e| u32::from(e[0])).collect(),
        DataType::U16 => elems.map(|e| u32::from(u16::from_le_bytes([e[0], e[1]]))).collect(),
        DataType::U32 => elems.map(|e| u32::from_le_bytes([e[0], e[1], e[2], e[3]])).collect(),
        _ => {
            let mut raw = Vec::with_capacity(a.count);
            for (k, e) in elems.enumerate() {
                let v = le_f32(e);
                if !(v >= 1.0 && v <= MAX_BUILDING_ID as f32 && v.fract() == 0.0) {
                    return Err(invalid(SceneGlbProblem::FeatureIdFloat { vertex: k, value: v }));
                }
                raw.push(v as u32);
            }
            raw
        }
    };
    out.reserve(raw.len());
    for (k, id) in raw.into_iter().enumerate() {
        match BuildingId::new(id) {
            Ok(b) if !b.is_background() && Some(u64::from(id)) != null_id => out.push(b),
            _ => return Err(invalid(SceneGlbProblem::FeatureIdValue { vertex: k, value: id })),
        }
    }
    Ok(())
}

/// Decodes an index accessor (u8/u16/u32), offset by `base`, checking each index against `n_vertices`.
fn read_indices(
    path: &Path,
    at: &str,
    acc: &gltf::Accessor<'_>,
    bin: &[u8],
    base: u32,
    n_vertices: usize,
    out: &mut Vec<u32>,
) -> Result<(), GlbError> {
    use gltf::accessor::{DataType, Dimensions};
    let invalid = |problem| GlbError::Invalid { path: path.to_path_buf(), at: at.to_string(), problem };
    let size = match (acc.dimensions(), acc.data_type()) {
        (Dimensions::Scalar, DataType::U8) => 1,
        (Dimensions::Scalar, DataType::U16) => 2,
        (Dimensions::Scalar, DataType::U32) => 4,
        (d, t) => return Err(invalid(SceneGlbProblem::IndexType { dimensions: d, data_type: t })),
    };
    let a = accessor_bytes(path, at, acc, bin, size)?;
    if a.count % 3 != 0 {
        return Err(invalid(SceneGlbProblem::IndexCount { count: a.count }));
    }
    let first = out.len();
    out.reserve(a.count);
    let elems = (0..a.count).map(|k| &a.data[k * a.stride..k * a.stride + size]);
    match size {
        1 => out.extend(elems.map(|e| u32::from(e[0]))),
        2 => out.extend(elems.map(|e| u32::from(u16::from_le_bytes([e[0], e[1]])))),
        _ => out.extend(elems.map(|e| u32::from_le_bytes([e[0], e[1], e[2], e[3]]))),
    }
    if let Some((k, &i)) = out[first..].iter().enumerate().find(|(_, &i)| i as usize >= n_vertices) {
        return Err(invalid(SceneGlbProblem::IndexRange { index: k, value: i, vertices: n_vertices }));
    }
    if base != 0 {
        for i in &mut out[first..] {
            *i += base;
        }
    }
    Ok(())
}

/// Reads `scene.glb` back into a [`SceneMesh`] (ENU metres, per-vertex building IDs).
///
/// Reads what [`write_glb`] writes, and more generally any self-contained GLB whose triangle
/// primitives carry an `EXT_mesh_features` feature ID attribute (the set labelled `building`, else the
/// first attribute-based set) with IDs in 1..=2^24−1: all meshes of the default scene are
/// concatenated, node transforms applied. Decoding is a straight pass over the binary chunk.
///
/// # Units
/// Positions come back as ENU metres relative to the area origin (glTF (x, y, z) → (x, −z, y)).
///
/// # Errors
/// [`GlbError::File`] if the file cannot be read, [`GlbError::Parse`] if it is not valid GLB/glTF,
/// [`GlbError::Invalid`] (with the JSON path) if a primitive is not triangles, has no feature IDs,
/// uses unsupported encodings (sparse, quantized, Draco, external buffers) or has out-of-range data.
pub fn read_glb(path: &Path) -> Result<SceneMesh, GlbError> {
    let bytes = crate::util::read_file(path)?;
    let parse = |source: gltf::Error| GlbError::Parse { path: path.to_path_buf(), source };
    let glb = crate::util::glb::read(&bytes).map_err(|e| glb_error(path, e))?;
    let root: gltf::json::Root =
        gltf::json::deserialize::from_slice(&glb.json).map_err(|e| parse(gltf::Error::Deserialize(e)))?;
    let doc = gltf::Document::from_json(root).map_err(parse)?;
    let raw: RawRoot = serde_json::from_slice(&glb.json)
        .map_err(|source| GlbError::MeshFeatures { path: path.to_path_buf(), source })?;
    let bin: &[u8] = glb.bin.as_deref().unwrap_or(&[]);
    let invalid = |at: String, problem| GlbError::Invalid { path: path.to_path_buf(), at, problem };

    let scene = doc
        .default_scene()
        .or_else(|| doc.scenes().next())
        .ok_or_else(|| invalid("scenes".into(), SceneGlbProblem::NoScene))?;
    // Depth-first over the scene graph, with world transforms (None = identity, kept exact).
    let mut stack: Vec<(gltf::Node<'_>, DMat4)> = scene.nodes().map(|n| (n, DMat4::IDENTITY)).collect();
    stack.reverse();
    let mut mesh = SceneMesh::default();
    while let Some((node, parent)) = stack.pop() {
        // glTF stores node matrices column-major, as glam does.
        // Clutter layers (see `add_layers`) are not buildings: `read_layers` reads them.
        if node.name().is_some_and(|n| n.starts_with(CLUTTER_NODE_PREFIX)) {
            continue;
        }
        let local = Mat4::from_cols_array_2d(&node.transform().matrix()).as_dmat4();
        let world = if local == DMat4::IDENTITY { parent } else { parent * local };
        for child in node.children().collect::<Vec<_>>().into_iter().rev() {
            stack.push((child, world));
        }
        let Some(m) = node.mesh() else { continue };
        let transform = if world == DMat4::IDENTITY { None } else { Some(&world) };
        for prim in m.primitives() {
            read_primitive(path, &raw, bin, &m, &prim, transform, &mut mesh)?;
        }
    }
    if mesh.indices.is_empty() {
        return Err(invalid("meshes".into(), SceneGlbProblem::NoTriangles));
    }
    Ok(mesh)
}

/// Appends one building primitive of `scene.glb` (positions, feature IDs, indices) to `mesh`.
fn read_primitive(
    path: &Path,
    raw: &RawRoot,
    bin: &[u8],
    m: &gltf::Mesh<'_>,
    prim: &gltf::Primitive<'_>,
    transform: Option<&DMat4>,
    mesh: &mut SceneMesh,
) -> Result<(), GlbError> {
    let invalid = |at: String, problem| GlbError::Invalid { path: path.to_path_buf(), at, problem };
    let at = format!("meshes[{}].primitives[{}]", m.index(), prim.index());
    if prim.mode() != gltf::mesh::Mode::Triangles {
        return Err(invalid(at, SceneGlbProblem::Mode { mode: prim.mode() }));
    }
    let features = raw
        .meshes
        .get(m.index())
        .and_then(|rm| rm.primitives.get(prim.index()))
        .and_then(|rp| rp.extensions.as_ref())
        .and_then(|e| e.mesh_features.as_ref());
    let set = features.and_then(|f| {
        let with_attr = || f.feature_ids.iter().filter(|s| s.attribute.is_some());
        with_attr().find(|s| s.label.as_deref() == Some(FEATURE_LABEL)).or_else(|| with_attr().next())
    });
    let Some(set) = set else {
        return Err(invalid(at, SceneGlbProblem::NoFeatureIds));
    };
    // Checked above: the set has an attribute.
    let attr_name = format!("_FEATURE_ID_{}", set.attribute.unwrap_or(0));
    let mut pos_acc = None;
    let mut id_acc = None;
    for (sem, acc) in prim.attributes() {
        match sem {
            gltf::Semantic::Positions => pos_acc = Some(acc),
            gltf::Semantic::Extras(name) if format!("_{name}") == attr_name => id_acc = Some(acc),
            _ => {}
        }
    }
    let pos_acc = pos_acc.ok_or_else(|| invalid(format!("{at}.attributes"), SceneGlbProblem::NoPosition))?;
    let id_acc = id_acc.ok_or_else(|| {
        invalid(
            format!("{at}.attributes"),
            SceneGlbProblem::MissingFeatureAttribute { attribute: attr_name.clone() },
        )
    })?;
    if pos_acc.count() != id_acc.count() {
        return Err(invalid(
            format!("{at}.attributes"),
            SceneGlbProblem::CountMismatch { positions: pos_acc.count(), feature_ids: id_acc.count() },
        ));
    }
    let base = mesh.positions_m.len();
    if base + pos_acc.count() >= u32::MAX as usize {
        return Err(invalid(at, SceneGlbProblem::TooManyVertices));
    }
    read_positions(
        path,
        &format!("{at}.attributes[\"POSITION\"]"),
        &pos_acc,
        bin,
        transform,
        &mut mesh.positions_m,
    )?;
    read_feature_ids(
        path,
        &format!("{at}.attributes[\"{attr_name}\"]"),
        &id_acc,
        bin,
        set.null_feature_id,
        &mut mesh.building_ids,
    )?;
    let n = pos_acc.count();
    match prim.indices() {
        Some(acc) => {
            read_indices(path, &format!("{at}.indices"), &acc, bin, base as u32, n, &mut mesh.indices)?
        }
        None => {
            if n % 3 != 0 {
                return Err(invalid(at, SceneGlbProblem::Unindexed { vertices: n }));
            }
            mesh.indices.extend(base as u32..(base + n) as u32);
        }
    }
    Ok(())
}

/// Name prefix of the clutter layer nodes and meshes (`insgen_clutter_trees`, …).
pub const CLUTTER_NODE_PREFIX: &str = "insgen_clutter_";

/// Appends clutter layers to a scene GLB written by [`write_glb`] (atomically): per layer one node and
/// mesh named `insgen_clutter_<layer>` (node `extras.insgen_layer` = the layer name), one triangle
/// primitive with `POSITION` (VEC3 FLOAT, ENU → glTF axes as for the buildings), `COLOR_0` (VEC4
/// UNSIGNED_BYTE normalized, the clutter's sRGB colour) and `u32` indices, and a double-sided material
/// of the same name. Layer primitives carry no feature IDs: they are not buildings, and
/// [`read_glb`] skips them ([`read_layers`] reads them back). The building part of the file is left
/// as it was; the new data follows the existing binary chunk.
///
/// # Errors
/// [`GlbError::File`] on I/O failure, [`GlbError::Parse`] if `path` is not a GLB,
/// [`GlbError::BadInput`] for a layer with inconsistent buffers or non-finite coordinates,
/// [`GlbError::TooLarge`] past 4 GiB.
pub fn add_layers(path: &Path, layers: &crate::scene::clutter::Clutter) -> Result<(), GlbError> {
    if layers.layers.is_empty() {
        return Ok(());
    }
    let bytes = crate::util::read_file(path)?;
    let glb = crate::util::glb::read(&bytes).map_err(|e| glb_error(path, e))?;
    let mut doc: Value = serde_json::from_slice(&glb.json)
        .map_err(|e| GlbError::Parse { path: path.to_path_buf(), source: gltf::Error::Deserialize(e) })?;
    let mut b = GlbBuilder::continuing(&mut doc, glb.bin.as_deref().unwrap_or(&[]), VIEW_ALIGN);
    for (layer, m) in &layers.layers {
        add_layer(path, &mut doc, &mut b, *layer, m)?;
    }
    let out = b.finish(doc).map_err(|e| glb_error(path, e))?;
    Ok(crate::util::write_bytes_atomic(path, &out)?)
}

/// Appends one clutter layer's views, accessors, material, mesh and node (see [`add_layers`]).
fn add_layer(
    path: &Path,
    doc: &mut Value,
    b: &mut GlbBuilder,
    layer: crate::scene::clutter::ClutterLayer,
    m: &crate::scene::clutter::LayerMesh,
) -> Result<(), GlbError> {
    let bad = |problem| GlbError::BadInput { path: path.to_path_buf(), problem };
    let count = |key: &str, doc: &Value| doc[key].as_array().map_or(0, |a| a.len());
    let n = m.positions_m.len();
    if m.colors_srgb.len() != n
        || !m.indices.len().is_multiple_of(3)
        || m.indices.iter().any(|&i| i as usize >= n)
    {
        return Err(bad(InputProblem::LayerBuffers { layer }));
    }
    if m.positions_m.iter().any(|p| !p.iter().all(|c| c.is_finite())) {
        return Err(bad(InputProblem::LayerNonFinite { layer }));
    }
    let name = format!("{CLUTTER_NODE_PREFIX}{}", layer.name());
    let (mut lo, mut hi) = ([f32::INFINITY; 3], [f32::NEG_INFINITY; 3]);
    let mut pos = Vec::with_capacity(n * 12);
    for &p in &m.positions_m {
        let g = enu_to_gltf(p);
        for k in 0..3 {
            lo[k] = lo[k].min(g[k]);
            hi[k] = hi[k].max(g[k]);
            pos.extend_from_slice(&g[k].to_le_bytes());
        }
    }
    let col: Vec<u8> = m.colors_srgb.iter().flat_map(|c| [c[0], c[1], c[2], 255]).collect();
    let idx: Vec<u8> = m.indices.iter().flat_map(|i| i.to_le_bytes()).collect();
    let v_pos = b.push_view_with(&pos, None, Some(TARGET_ARRAY_BUFFER));
    let v_col = b.push_view_with(&col, None, Some(TARGET_ARRAY_BUFFER));
    let v_idx = b.push_view_with(&idx, None, Some(TARGET_ELEMENT_ARRAY_BUFFER));
    let f64s = |a: [f32; 3]| a.map(f64::from).to_vec();
    let a0 = b.push_accessor(json!({"bufferView": v_pos, "componentType": COMPONENT_FLOAT, "count": n,
                                    "type": "VEC3", "min": f64s(lo), "max": f64s(hi)}));
    b.push_accessor(json!({"bufferView": v_col, "componentType": COMPONENT_UNSIGNED_BYTE,
                           "normalized": true, "count": n, "type": "VEC4"}));
    b.push_accessor(json!({"bufferView": v_idx, "componentType": COMPONENT_UNSIGNED_INT,
                           "count": m.indices.len(), "type": "SCALAR"}));
    let list = |doc: &mut Value, key: &'static str| -> Result<usize, GlbError> {
        let n = count(key, doc);
        match doc[key].as_array() {
            Some(_) => Ok(n),
            None => Err(bad(InputProblem::NoList { key })),
        }
    };
    let material = list(doc, "materials")?;
    doc["materials"].as_array_mut().into_iter().for_each(|l| {
        l.push(json!({
            "name": name,
            "pbrMetallicRoughness": {"baseColorFactor": [1.0, 1.0, 1.0, 1.0], "metallicFactor": 0.0,
                                     "roughnessFactor": 1.0},
            "doubleSided": true
        }))
    });
    let mesh = list(doc, "meshes")?;
    doc["meshes"].as_array_mut().into_iter().for_each(|l| {
        l.push(json!({
            "name": name,
            "primitives": [{"attributes": {"POSITION": a0, "COLOR_0": a0 + 1}, "indices": a0 + 2,
                            "material": material, "mode": MODE_TRIANGLES}]
        }))
    });
    let node = list(doc, "nodes")?;
    doc["nodes"]
        .as_array_mut()
        .into_iter()
        .for_each(|l| l.push(json!({"name": name, "mesh": mesh, "extras": {"insgen_layer": layer.name()}})));
    let scene = doc["scene"].as_u64().unwrap_or(0) as usize;
    doc["scenes"][scene]["nodes"]
        .as_array_mut()
        .ok_or_else(|| bad(InputProblem::NoSceneNodes))?
        .push(json!(node));
    Ok(())
}

/// Reads the clutter layers of a scene GLB (the nodes [`add_layers`] wrote); none for a scene
/// without clutter.
///
/// # Errors
/// As [`read_glb`]; [`GlbError::Invalid`] for a clutter node of an unknown layer or malformed data.
pub fn read_layers(path: &Path) -> Result<crate::scene::clutter::Clutter, GlbError> {
    use crate::scene::clutter::{Clutter, ClutterLayer, LayerMesh};
    use gltf::accessor::{DataType, Dimensions};
    let bytes = crate::util::read_file(path)?;
    let parse = |source: gltf::Error| GlbError::Parse { path: path.to_path_buf(), source };
    let glb = crate::util::glb::read(&bytes).map_err(|e| glb_error(path, e))?;
    let root: gltf::json::Root =
        gltf::json::deserialize::from_slice(&glb.json).map_err(|e| parse(gltf::Error::Deserialize(e)))?;
    let doc = gltf::Document::from_json(root).map_err(parse)?;
    let bin: &[u8] = glb.bin.as_deref().unwrap_or(&[]);
    let invalid = |at: String, problem| GlbError::Invalid { path: path.to_path_buf(), at, problem };
    let mut out = Clutter::default();
    for node in doc.nodes() {
        let Some(name) = node.name().and_then(|n| n.strip_prefix(CLUTTER_NODE_PREFIX)) else { continue };
        let at = format!("nodes[{}]", node.index());
        let layer = ClutterLayer::from_name(name)
            .ok_or_else(|| invalid(at.clone(), SceneGlbProblem::UnknownLayer { name: name.to_string() }))?;
        let Some(mesh) = node.mesh() else { continue };
        let mut m = LayerMesh::default();
        for prim in mesh.primitives() {
            let at = format!("meshes[{}].primitives[{}]", mesh.index(), prim.index());
            let pos = prim
                .get(&gltf::Semantic::Positions)
                .ok_or_else(|| invalid(at.clone(), SceneGlbProblem::LayerNoPosition))?;
            let base = m.positions_m.len();
            read_positions(path, &at, &pos, bin, None, &mut m.positions_m)?;
            match prim.get(&gltf::Semantic::Colors(0)) {
                Some(c) if c.data_type() == DataType::U8 && c.dimensions() == Dimensions::Vec4 => {
                    let a = accessor_bytes(path, &at, &c, bin, 4)?;
                    m.colors_srgb.extend((0..a.count).map(|k| {
                        let e = &a.data[k * a.stride..k * a.stride + 3];
                        [e[0], e[1], e[2]]
                    }));
                }
                _ => m.colors_srgb.extend(std::iter::repeat_n([128, 128, 128], pos.count())),
            }
            if m.colors_srgb.len() != m.positions_m.len() {
                return Err(invalid(at, SceneGlbProblem::LayerColors));
            }
            let acc = prim.indices().ok_or_else(|| invalid(at.clone(), SceneGlbProblem::LayerNoIndices))?;
            read_indices(
                path,
                &format!("{at}.indices"),
                &acc,
                bin,
                base as u32,
                pos.count(),
                &mut m.indices,
            )?;
        }
        out.layers.push((layer, m));
    }
    out.layers.sort_by_key(|(l, _)| *l);
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    mod axes {
        use super::*;

        #[test]
        fn enu_to_gltf_is_y_up_and_right_handed() {
            // East stays x, up becomes y, north becomes −z (glTF's "forward" is +z toward the viewer).
            assert_eq!(enu_to_gltf([1.0, 0.0, 0.0]), [1.0, 0.0, 0.0]);
            assert_eq!(enu_to_gltf([0.0, 1.0, 0.0]), [0.0, 0.0, -1.0]);
            assert_eq!(enu_to_gltf([0.0, 0.0, 1.0]), [0.0, 1.0, 0.0]);
            // A rotation (determinant +1): handedness is preserved, so no triangle flips its winding.
            let m =
                [enu_to_gltf([1.0, 0.0, 0.0]), enu_to_gltf([0.0, 1.0, 0.0]), enu_to_gltf([0.0, 0.0, 1.0])];
            let det = m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1])
                - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
                + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0]);
            assert_eq!(det, 1.0);
        }

        #[test]
        fn gltf_to_enu_inverts_exactly() {
            for p in [[1.5f32, -2.25, 1e6], [-0.0, 0.0, 3.3], [f32::MIN_POSITIVE, -7.1, 123.456]] {
                let back = gltf_to_enu(enu_to_gltf(p));
                assert_eq!(back.map(f32::to_bits), p.map(f32::to_bits));
            }
        }
    }

    mod colour {
        use super::*;

        #[test]
        fn deterministic_and_not_dark() {
            let id = |n| BuildingId::new(n).unwrap();
            assert_eq!(building_colour(id(17)), building_colour(id(17)));
            for n in 1..2000 {
                let c = building_colour(id(n));
                assert!(c.iter().all(|&v| v >= 56), "id {n}: {c:?}");
            }
        }

        #[test]
        fn neighbours_differ() {
            let distinct: std::collections::BTreeSet<[u8; 3]> =
                (1..=1000).map(|n| building_colour(BuildingId::new(n).unwrap())).collect();
            assert!(distinct.len() > 990, "{} distinct colours for 1000 IDs", distinct.len());
        }
    }

    mod layout {
        use crate::util::glb::GlbBuilder;

        #[test]
        fn views_are_8_byte_aligned_and_disjoint() {
            let mut b = GlbBuilder::with_view_alignment(super::super::VIEW_ALIGN);
            let offsets: Vec<usize> =
                [36, 12, 5, 4].iter().map(|&n| b.push_view(&vec![1; n], None)).collect();
            let bytes = b.finish(serde_json::json!({})).unwrap();
            let glb = crate::util::glb::read(&bytes).unwrap();
            let doc: serde_json::Value = serde_json::from_slice(&glb.json).unwrap();
            let starts: Vec<u64> =
                offsets.iter().map(|&v| doc["bufferViews"][v]["byteOffset"].as_u64().unwrap()).collect();
            assert_eq!(starts, vec![0, 40, 56, 64]);
            assert_eq!(doc["buffers"][0]["byteLength"], 68);
        }
    }
}
