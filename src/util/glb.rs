//! The GLB container (binary glTF 2.0): the crate's one GLB writer ([`GlbBuilder`]) and one GLB
//! reader ([`read`]).
//!
//! Every GLB insgen writes — the prepared `scene.glb` and its clutter layers (`scene::glb`), the 3D
//! Tiles contents of the export stage (`export::city_tileset`) and the plain GLBs handed to Blender
//! (`lod::tiles3d::plain`) — is assembled by [`GlbBuilder`]; every GLB it reads — `scene.glb` and the
//! contents of 3D Tiles (`lod::tiles3d`) — is opened by [`read`]. What the JSON document says (meshes,
//! feature IDs, materials) stays with those modules; this one only knows the container: the 12-byte
//! header, the JSON chunk (padded with spaces) and the BIN chunk (padded with zeros), buffer views
//! packed into buffer 0 at a fixed alignment, and accessors.
//!
//! # References
//! glTF 2.0 specification (Khronos), "GLB File Format Specification" and "Data Alignment";
//! `EXT_meshopt_compression` (Khronos extension registry) for the fallback buffer.

use serde_json::{json, Value};

/// The GLB magic, the first four bytes of the file.
pub const MAGIC: &[u8; 4] = b"glTF";
/// Chunk type of the JSON chunk (`JSON` in ASCII, little-endian).
const CHUNK_JSON: &[u8; 4] = b"JSON";
/// Chunk type of the binary chunk (`BIN\0`).
const CHUNK_BIN: &[u8; 4] = b"BIN\0";
/// Bytes of the header plus the JSON chunk's header.
const HEADER_BYTES: usize = 12 + 8;

/// Errors of the GLB container: what is wrong with the header or the chunks, or a file too large for
/// the format's 32-bit lengths.
#[derive(Debug, thiserror::Error)]
pub enum GlbError {
    /// The bytes do not start with a GLB header.
    #[error("not a GLB: {length} bytes starting with {magic:?}")]
    NotGlb {
        /// How many bytes there are.
        length: usize,
        /// Their first (up to) four bytes, as text.
        magic: String,
    },
    /// A GLB of another glTF version than 2.
    #[error(
        "glTF version {version} content is not supported; only glTF 2.0 is (upgrade the tileset, e.g. with `npx 3d-tiles-tools upgrade`)"
    )]
    Version {
        /// The version the header gives.
        version: usize,
    },
    /// The header's length is shorter than a header or longer than the bytes there are.
    #[error("GLB header length is {length} but {available} bytes are available")]
    Length {
        /// The length the header gives, bytes.
        length: usize,
        /// The bytes there are.
        available: usize,
    },
    /// The chunks are inconsistent (the `gltf` crate's error).
    #[error("not a valid GLB")]
    Chunks(#[source] Box<gltf::Error>),
    /// The file would pass the 4 GiB that the GLB header's 32-bit length can describe.
    #[error("the GLB would be {bytes} bytes, past the format's 4 GiB limit")]
    TooLarge {
        /// The size the file would have, bytes.
        bytes: u64,
    },
}

/// Opens a GLB: checks the header (magic, version 2, a length within the bytes there are) and splits
/// the chunks. Bytes after the header's length (the padding a b3dm may add) are ignored.
///
/// # Errors
/// [`GlbError::NotGlb`], [`GlbError::Version`], [`GlbError::Length`] for a bad header;
/// [`GlbError::Chunks`] for inconsistent chunks.
pub fn read(bytes: &[u8]) -> Result<gltf::Glb<'_>, GlbError> {
    // The header is checked here so that the `gltf` crate only ever sees a consistent one (it
    // subtracts 12 from the length field unchecked).
    if bytes.len() < HEADER_BYTES || &bytes[0..4] != MAGIC {
        return Err(GlbError::NotGlb {
            length: bytes.len(),
            magic: String::from_utf8_lossy(&bytes[..bytes.len().min(4)]).into_owned(),
        });
    }
    let word = |i: usize| u32::from_le_bytes([bytes[i], bytes[i + 1], bytes[i + 2], bytes[i + 3]]) as usize;
    let version = word(4);
    if version != 2 {
        return Err(GlbError::Version { version });
    }
    let length = word(8);
    if !(HEADER_BYTES..=bytes.len()).contains(&length) {
        return Err(GlbError::Length { length, available: bytes.len() });
    }
    gltf::Glb::from_slice(&bytes[..length]).map_err(|e| GlbError::Chunks(Box::new(e)))
}

/// Accumulates a GLB's binary chunk, buffer views and accessors, then writes the container.
///
/// Views are packed into buffer 0 in push order, each starting at a multiple of the builder's
/// alignment (4 bytes by default, as glTF requires for every component type); the BIN chunk is
/// padded to 4 bytes. The JSON is serialised as `serde_json` does (sorted keys), so the same pushes
/// give the same bytes.
#[derive(Debug)]
pub struct GlbBuilder {
    bin: Vec<u8>,
    views: Vec<Value>,
    accessors: Vec<Value>,
    /// Alignment of every view's start in the BIN chunk, bytes.
    view_align: usize,
    /// Bytes of the `EXT_meshopt_compression` fallback buffer (buffer 1), when any view is compressed.
    fallback_len: usize,
}

impl Default for GlbBuilder {
    fn default() -> Self {
        GlbBuilder::with_view_alignment(4)
    }
}

/// `bytes` rounded up to a multiple of `align`.
fn align_up(bytes: usize, align: usize) -> usize {
    bytes.div_ceil(align) * align
}

impl GlbBuilder {
    /// An empty builder whose views start at multiples of `align` bytes (a multiple of 4).
    pub fn with_view_alignment(align: usize) -> GlbBuilder {
        debug_assert!(align > 0 && align.is_multiple_of(4), "view alignment {align}");
        GlbBuilder {
            bin: Vec::new(),
            views: Vec::new(),
            accessors: Vec::new(),
            view_align: align,
            fallback_len: 0,
        }
    }

    /// A builder that goes on where an existing GLB stopped: its BIN chunk, `bufferViews` and
    /// `accessors` (taken out of `root`), so that what is pushed next is appended to them.
    pub fn continuing(root: &mut Value, bin: &[u8], align: usize) -> GlbBuilder {
        let mut take = |key: &str| match root.get_mut(key).map(Value::take) {
            Some(Value::Array(items)) => items,
            _ => Vec::new(),
        };
        let (views, accessors) = (take("bufferViews"), take("accessors"));
        GlbBuilder { bin: bin.to_vec(), views, accessors, view_align: align, fallback_len: 0 }
    }

    fn pad_bin(&mut self, align: usize) {
        self.bin.resize(align_up(self.bin.len(), align), 0);
    }

    /// Appends a buffer view of `bytes` with an optional `byteStride`; returns its index.
    pub fn push_view(&mut self, bytes: &[u8], stride: Option<usize>) -> usize {
        self.push_view_with(bytes, stride, None)
    }

    /// Appends a buffer view of `bytes` with an optional `byteStride` and `target`
    /// (34962 ARRAY_BUFFER, 34963 ELEMENT_ARRAY_BUFFER); returns its index.
    pub fn push_view_with(&mut self, bytes: &[u8], stride: Option<usize>, target: Option<u32>) -> usize {
        self.pad_bin(self.view_align);
        let mut v = json!({"buffer": 0, "byteOffset": self.bin.len(), "byteLength": bytes.len()});
        if let Some(s) = stride {
            v["byteStride"] = json!(s);
        }
        if let Some(t) = target {
            v["target"] = json!(t);
        }
        self.bin.extend_from_slice(bytes);
        self.views.push(v);
        self.views.len() - 1
    }

    /// Appends an `EXT_meshopt_compression` view: `compressed` in buffer 0, decoding to `count ×
    /// stride` bytes of the fallback buffer (buffer 1); `vertex` views carry a `byteStride`.
    pub fn push_meshopt_view(
        &mut self,
        compressed: &[u8],
        count: usize,
        stride: usize,
        mode: &str,
        vertex: bool,
    ) -> usize {
        self.pad_bin(self.view_align);
        let len = count * stride;
        let mut v = json!({
            "buffer": 1, "byteOffset": self.fallback_len, "byteLength": len,
            "extensions": {"EXT_meshopt_compression": {
                "buffer": 0, "byteOffset": self.bin.len(), "byteLength": compressed.len(),
                "byteStride": stride, "count": count, "mode": mode}}
        });
        if vertex {
            v["byteStride"] = json!(stride);
        }
        self.bin.extend_from_slice(compressed);
        self.fallback_len = align_up(self.fallback_len + len, 4);
        self.views.push(v);
        self.views.len() - 1
    }

    /// Appends an accessor object; returns its index.
    pub fn push_accessor(&mut self, a: Value) -> usize {
        self.accessors.push(a);
        self.accessors.len() - 1
    }

    /// FLOAT VEC3 with min/max (as POSITION requires).
    pub fn push_vec3(&mut self, v: &[[f32; 3]]) -> usize {
        let (lo, hi) = min_max(v.iter().map(|p| p.map(f64::from)));
        let view = self.push_view(&floats(v.iter().flatten()), None);
        self.push_accessor(json!({"bufferView": view, "componentType": 5126, "count": v.len(), "type": "VEC3", "min": lo, "max": hi}))
    }

    /// FLOAT VEC2.
    pub fn push_vec2(&mut self, v: &[[f32; 2]]) -> usize {
        let view = self.push_view(&floats(v.iter().flatten()), None);
        self.push_accessor(
            json!({"bufferView": view, "componentType": 5126, "count": v.len(), "type": "VEC2"}),
        )
    }

    /// FLOAT SCALAR.
    pub fn push_scalar_f32(&mut self, v: &[f32]) -> usize {
        let view = self.push_view(&floats(v.iter()), None);
        self.push_accessor(
            json!({"bufferView": view, "componentType": 5126, "count": v.len(), "type": "SCALAR"}),
        )
    }

    /// UNSIGNED_INT indices.
    pub fn push_indices(&mut self, v: &[u32]) -> usize {
        let bytes: Vec<u8> = v.iter().flat_map(|i| i.to_le_bytes()).collect();
        let view = self.push_view(&bytes, None);
        self.push_accessor(
            json!({"bufferView": view, "componentType": 5125, "count": v.len(), "type": "SCALAR"}),
        )
    }

    /// The GLB: `root` with `buffers`, `bufferViews` and `accessors` filled in.
    ///
    /// # Errors
    /// [`GlbError::TooLarge`] past the format's 4 GiB.
    pub fn finish(mut self, mut root: Value) -> Result<Vec<u8>, GlbError> {
        self.pad_bin(4);
        let mut buffers = vec![json!({"byteLength": self.bin.len()})];
        if self.fallback_len > 0 {
            buffers.push(json!({"byteLength": self.fallback_len, "extensions": {"EXT_meshopt_compression": {"fallback": true}}}));
        }
        root["buffers"] = json!(buffers);
        root["bufferViews"] = json!(self.views);
        root["accessors"] = json!(self.accessors);
        container(&root, &self.bin)
    }
}

/// Little-endian bytes of f32 values, as a FLOAT accessor stores them.
pub fn floats<'a>(v: impl Iterator<Item = &'a f32>) -> Vec<u8> {
    v.flat_map(|f| f.to_le_bytes()).collect()
}

/// Per-axis minimum and maximum of points (±infinity when there are none).
pub fn min_max(points: impl Iterator<Item = [f64; 3]>) -> ([f64; 3], [f64; 3]) {
    let mut lo = [f64::INFINITY; 3];
    let mut hi = [f64::NEG_INFINITY; 3];
    for p in points {
        for k in 0..3 {
            lo[k] = lo[k].min(p[k]);
            hi[k] = hi[k].max(p[k]);
        }
    }
    (lo, hi)
}

/// A GLB container around a glTF JSON document and its binary chunk (both padded to 4 bytes; no BIN
/// chunk when `bin` is empty).
///
/// # Errors
/// [`GlbError::TooLarge`] past the format's 4 GiB.
pub fn container(json: &Value, bin: &[u8]) -> Result<Vec<u8>, GlbError> {
    let mut j = serde_json::to_vec(json).expect("a JSON value serialises");
    j.resize(align_up(j.len(), 4), b' ');
    let bin_len = align_up(bin.len(), 4);
    let total = HEADER_BYTES + j.len() + if bin.is_empty() { 0 } else { 8 + bin_len };
    let total_u32 = u32::try_from(total).map_err(|_| GlbError::TooLarge { bytes: total as u64 })?;
    let mut out = Vec::with_capacity(total);
    out.extend_from_slice(MAGIC);
    out.extend_from_slice(&2u32.to_le_bytes());
    out.extend_from_slice(&total_u32.to_le_bytes());
    out.extend_from_slice(&(j.len() as u32).to_le_bytes());
    out.extend_from_slice(CHUNK_JSON);
    out.extend_from_slice(&j);
    if !bin.is_empty() {
        out.extend_from_slice(&(bin_len as u32).to_le_bytes());
        out.extend_from_slice(CHUNK_BIN);
        out.extend_from_slice(bin);
        out.resize(total, 0);
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn builder_round_trips_through_the_reader() {
        let mut b = GlbBuilder::with_view_alignment(8);
        let pos = b.push_vec3(&[[0.0, 1.0, 2.0], [3.0, 4.0, 5.0], [6.0, 7.0, 8.5]]);
        let v = b.push_view_with(&[1, 2, 3], None, Some(34963));
        let bytes = b.finish(json!({"asset": {"version": "2.0"}})).unwrap();
        assert_eq!(bytes.len() % 4, 0);
        let glb = read(&bytes).unwrap();
        let doc: Value = serde_json::from_slice(&glb.json).unwrap();
        assert_eq!(pos, 0);
        assert_eq!(doc["bufferViews"][v]["byteOffset"], 40, "36 bytes of positions, then 8-byte aligned");
        assert_eq!(doc["bufferViews"][v]["target"], 34963);
        assert_eq!(doc["accessors"][0]["max"], json!([6.0, 7.0, 8.5]));
        let bin = glb.bin.unwrap();
        assert_eq!(bin.len(), 44, "BIN chunk padded to 4 bytes");
        assert_eq!(&bin[40..43], &[1, 2, 3]);
        assert_eq!(doc["buffers"][0]["byteLength"], 44);
    }

    #[test]
    fn continuing_appends_after_the_existing_chunk() {
        let mut b = GlbBuilder::default();
        b.push_scalar_f32(&[1.0]);
        let bytes = b.finish(json!({})).unwrap();
        let glb = read(&bytes).unwrap();
        let mut doc: Value = serde_json::from_slice(&glb.json).unwrap();
        let mut more = GlbBuilder::continuing(&mut doc, glb.bin.as_deref().unwrap(), 8);
        let view = more.push_view(&[9; 4], None);
        let again = more.finish(doc).unwrap();
        let doc: Value = serde_json::from_slice(&read(&again).unwrap().json).unwrap();
        assert_eq!(view, 1);
        assert_eq!(doc["bufferViews"][1]["byteOffset"], 8);
        assert_eq!(doc["accessors"].as_array().unwrap().len(), 1);
    }

    #[test]
    fn bad_headers_say_what_is_wrong() {
        let zip = b"PK\x03\x04 not a glb at all";
        assert!(matches!(read(zip), Err(GlbError::NotGlb { length, .. }) if length == zip.len()));
        let mut one = container(&json!({}), &[]).unwrap();
        one[4] = 1;
        assert!(matches!(read(&one), Err(GlbError::Version { version: 1 })));
        let mut long = container(&json!({}), &[]).unwrap();
        long[8] = 200;
        assert!(matches!(read(&long), Err(GlbError::Length { length: 200, .. })));
        // Trailing bytes past the header's length (b3dm padding) are ignored.
        let mut padded = container(&json!({"a": 1}), &[7; 5]).unwrap();
        padded.extend_from_slice(&[0; 8]);
        assert_eq!(read(&padded).unwrap().bin.unwrap().len(), 8);
    }
}
