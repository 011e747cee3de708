//! One tile content → a plain GLB that any glTF importer (Blender's included) reads without
//! extensions: insgen decodes everything itself and hands on triangles, UVs, PNG/JPEG textures and
//! simple materials.
//!
//! # What is read
//! - containers: b3dm (feature table `RTC_CENTER`), GLB, glTF JSON (external and `data:` buffers and
//!   images), cmpt of those, any of them gzip-compressed;
//! - geometry: node hierarchies (baked in f64), triangle lists/strips/fans,
//!   `KHR_draco_mesh_compression` (positions, UVs, `_FEATURE_ID_0`), `EXT_meshopt_compression`
//!   (vertex/index codecs and filters), `KHR_mesh_quantization` (integer positions and UVs,
//!   normalised or not), sparse accessors, `CESIUM_RTC`;
//! - surface: the base colour texture and factor, its UV set, `KHR_texture_transform` (baked into
//!   the UVs), `KHR_materials_unlit` (kept, as Blender's importer shows it as emission), images as
//!   PNG or JPEG (copied) or WebP (`EXT_texture_webp`, or a WebP `source`: decoded and re-encoded as
//!   PNG); the sampler is copied;
//! - `_FEATURE_ID_0` per vertex (kept, as a float attribute: Blender's ID renders read it).
//!
//! # What is refused (an error naming the extension; the caller adds the tile)
//! KTX2 / Basis Universal textures (`KHR_texture_basisu` without a PNG/JPEG fallback `source`), DDS
//! (`MSFT_texture_dds` without fallback), i3dm and pnts contents (instances, point clouds), and any
//! required glTF extension not listed above (see [`super::gltf::HANDLED_EXTENSIONS`]).
//!
//! # Frame
//! The content's triangles are taken to the tile frame in f64 — `translate(RTC_CENTER) ·
//! translate(CESIUM_RTC) · U · N · p`, `U` the glTF up-axis correction (y-up → z-up), `N` the node's
//! global matrix — and written as f32 relative to their bounding-box centre `c`. So the plain GLB's
//! coordinates `q` satisfy `tile frame = translate(c) · q`, and the tile's ENU-from-glTF is
//! `ENU_from_ECEF · tile transform · translate(c)` ([`Importable::tile_from_plain`]): the placement
//! chain `ENU_from_ECEF · tile transform · translate(RTC) · Y2Z · glTF` with its f64 part done here,
//! and only a small translation left for Blender's float32 matrices.

use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;

use glam::{DMat4, DVec3};
use serde_json::{json, Value};

use super::content::relative_loader;
use super::error::{ContentError, WebpError};
use super::gltf::{self, Gltf, LoadUri, Surface, UpAxis};
use super::{b3dm, maybe_gunzip};
use crate::util::glb::GlbBuilder;

/// A plain GLB and where its coordinates sit in the tile frame.
#[derive(Debug, Clone)]
pub struct Importable {
    /// The GLB bytes (glTF 2.0, no extensions required).
    pub glb: Vec<u8>,
    /// Tile frame from the GLB's coordinates: `translate(c)` (see the module doc).
    pub tile_from_plain: DMat4,
    /// Triangles written.
    pub triangles: u64,
    /// Extensions the content used that were decoded (or baked) on the way, sorted.
    pub decoded_extensions: BTreeSet<String>,
}

/// Image formats recognised by their first bytes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum ImageKind {
    Png,
    Jpeg,
    Webp,
    Ktx2,
    Dds,
    Unknown,
}

fn sniff(bytes: &[u8]) -> ImageKind {
    if bytes.starts_with(b"\x89PNG\r\n\x1a\n") {
        ImageKind::Png
    } else if bytes.starts_with(&[0xFF, 0xD8, 0xFF]) {
        ImageKind::Jpeg
    } else if bytes.len() >= 12 && &bytes[0..4] == b"RIFF" && &bytes[8..12] == b"WEBP" {
        ImageKind::Webp
    } else if bytes.starts_with(b"\xABKTX 20\xBB") {
        ImageKind::Ktx2
    } else if bytes.starts_with(b"DDS ") {
        ImageKind::Dds
    } else {
        ImageKind::Unknown
    }
}

/// Converts a tile content's bytes (`file` locates external buffers and images) into a plain GLB.
///
/// # Errors
/// [`ContentError`] saying what is wrong where, naming the extension when one is refused
/// ([`ContentError::Basisu`], [`ContentError::Dds`], [`ContentError::UnsupportedExtensions`], …);
/// the caller names the file and the tile.
pub fn importable_glb(bytes: &[u8], file: &Path, up: UpAxis) -> Result<Importable, ContentError> {
    let bytes = maybe_gunzip(bytes)?;
    let load_uri = relative_loader(file);
    let mut parts = Vec::new();
    collect(&bytes, DMat4::IDENTITY, up, &load_uri, &mut parts, "")?;
    build(&parts, &load_uri)
}

/// One decoded glTF with its primitives in the tile frame.
struct Part<'a> {
    gltf: Gltf<'a>,
    prims: Vec<gltf::WorldPrimitive>,
    /// Prefix of names in the output (`cmpt[1]/`), so inner tiles' names stay apart.
    label: String,
}

fn collect<'a>(
    bytes: &'a [u8],
    outer: DMat4,
    up: UpAxis,
    load_uri: &LoadUri<'_>,
    parts: &mut Vec<Part<'a>>,
    label: &str,
) -> Result<(), ContentError> {
    let magic = bytes.get(0..4).unwrap_or(bytes);
    let (g, outer) = match magic {
        b"b3dm" => {
            let tile = b3dm::parse(bytes)?;
            let g =
                gltf::parse_glb(tile.glb, load_uri).map_err(|e| ContentError::EmbeddedGlb(Box::new(e)))?;
            let outer = match tile.rtc_center {
                Some(c) => outer * DMat4::from_translation(DVec3::from_array(c)),
                None => outer,
            };
            (g, outer)
        }
        b"glTF" => (gltf::parse_glb(bytes, load_uri)?, outer),
        b"cmpt" => {
            for (k, inner) in b3dm::split_cmpt(bytes)?.into_iter().enumerate() {
                collect(inner, outer, up, load_uri, parts, &format!("{label}cmpt[{k}]/"))
                    .map_err(|e| ContentError::CmptTile { index: k, source: Box::new(e) })?;
            }
            return Ok(());
        }
        b"i3dm" | b"pnts" => {
            return Err(ContentError::NotRenderable { kind: String::from_utf8_lossy(magic).into_owned() })
        }
        _ if bytes.iter().find(|b| !b.is_ascii_whitespace()) == Some(&b'{')
            || bytes.starts_with(b"\xEF\xBB\xBF") =>
        {
            let json = bytes.strip_prefix(b"\xEF\xBB\xBF").unwrap_or(bytes);
            (gltf::parse_gltf_json(json, load_uri)?, outer)
        }
        _ => return Err(ContentError::UnknownContent { magic: String::from_utf8_lossy(magic).into_owned() }),
    };
    let outer = match g.cesium_rtc()? {
        Some(c) => outer * DMat4::from_translation(DVec3::from_array(c)),
        None => outer,
    };
    let (prims, _skipped) = g.world_primitives(outer, up, Surface::Yes)?;
    parts.push(Part { gltf: g, prims, label: label.to_string() });
    Ok(())
}

/// Extensions that this conversion decodes or bakes (reported in [`Importable::decoded_extensions`]).
const DECODED: &[&str] = &[
    "CESIUM_RTC",
    "KHR_draco_mesh_compression",
    "EXT_meshopt_compression",
    "KHR_mesh_quantization",
    "KHR_texture_transform",
    "KHR_materials_unlit",
    "EXT_texture_webp",
    "EXT_mesh_features",
    "EXT_structural_metadata",
];

fn build(parts: &[Part<'_>], load_uri: &LoadUri<'_>) -> Result<Importable, ContentError> {
    let mut w = PlainWriter::new(bounds_centre(parts), load_uri);
    for (pi, part) in parts.iter().enumerate() {
        let r = &part.gltf.root;
        for e in r.extensions_used.iter().chain(&r.extensions_required) {
            if DECODED.contains(&e.as_str()) {
                w.decoded.insert(e.clone());
            }
        }
        // Input material index → output material index, built on first use.
        let mut mat_map: BTreeMap<usize, usize> = BTreeMap::new();
        for prim in part.prims.iter().filter(|p| !p.triangles.is_empty()) {
            let material = match prim.material {
                None => None,
                Some(mi) => Some(match mat_map.get(&mi) {
                    Some(&o) => o,
                    None => {
                        let o = w.material(part, pi, mi)?;
                        mat_map.insert(mi, o);
                        o
                    }
                }),
            };
            w.primitive(prim, material);
        }
    }
    w.finish()
}

/// The centre of the bounding box of all positions (tile frame, f64); the origin without any.
fn bounds_centre(parts: &[Part<'_>]) -> DVec3 {
    let mut lo = DVec3::INFINITY;
    let mut hi = DVec3::NEG_INFINITY;
    for p in parts.iter().flat_map(|p| &p.prims).flat_map(|w| &w.positions) {
        lo = lo.min(DVec3::from_array(*p));
        hi = hi.max(DVec3::from_array(*p));
    }
    if lo.x.is_finite() {
        0.5 * (lo + hi)
    } else {
        DVec3::ZERO
    }
}

/// The plain GLB being written: its binary chunk and the JSON arrays that grow with it.
struct PlainWriter<'l> {
    b: GlbBuilder,
    /// Subtracted from every position (tile frame, metres).
    centre: DVec3,
    load_uri: &'l LoadUri<'l>,
    materials: Vec<Value>,
    textures: Vec<Value>,
    images: Vec<Value>,
    samplers: Vec<Value>,
    primitives: Vec<Value>,
    decoded: BTreeSet<String>,
    triangles: u64,
    unlit_used: bool,
}

impl<'l> PlainWriter<'l> {
    fn new(centre: DVec3, load_uri: &'l LoadUri<'l>) -> Self {
        PlainWriter {
            b: GlbBuilder::default(),
            centre,
            load_uri,
            materials: Vec::new(),
            textures: Vec::new(),
            images: Vec::new(),
            samplers: Vec::new(),
            primitives: Vec::new(),
            decoded: BTreeSet::new(),
            triangles: 0,
            unlit_used: false,
        }
    }

    /// Writes `materials[mi]` of part `pi` as a simple material (base colour factor and texture,
    /// unlit kept); returns its output index.
    fn material(&mut self, part: &Part<'_>, pi: usize, mi: usize) -> Result<usize, ContentError> {
        let r = &part.gltf.root;
        let at = format!("materials[{mi}]");
        let m = r.materials.get(mi).ok_or(ContentError::Missing { what: "material", index: mi })?;
        let mut out = json!({
            "name": format!("{}{}", part.label, m.name.clone().unwrap_or_else(|| format!("material_{mi}"))),
            "pbrMetallicRoughness": {"baseColorFactor": m.base_color_factor(), "metallicFactor": 0.0, "roughnessFactor": 1.0},
            "doubleSided": m.double_sided,
        });
        if let Some(t) = m.base_color_texture() {
            let texture = self
                .texture(part, pi, t.index)
                .map_err(|e| e.at(format!("{at}.pbrMetallicRoughness.baseColorTexture")))?;
            out["pbrMetallicRoughness"]["baseColorTexture"] = json!({"index": texture});
        }
        if m.unlit() {
            out["extensions"] = json!({"KHR_materials_unlit": {}});
            self.unlit_used = true;
        }
        self.materials.push(out);
        Ok(self.materials.len() - 1)
    }

    /// Writes `textures[index]` of part `pi` (its image as PNG or JPEG, its sampler); returns its
    /// output index.
    fn texture(&mut self, part: &Part<'_>, pi: usize, index: usize) -> Result<usize, ContentError> {
        let r = &part.gltf.root;
        let (img, mime, sampler) = texture_image(&part.gltf, index, self.load_uri, &mut self.decoded)?;
        let view = self.b.push_view(&img, None);
        self.images.push(json!({
            "bufferView": view,
            "mimeType": mime,
            "name": format!("{}{}#{pi}.{}", part.label, r.images.get(r.textures[index].source.unwrap_or(0)).and_then(|i| i.name.clone()).unwrap_or_else(|| "image".into()), self.images.len()),
        }));
        let mut tex = json!({"source": self.images.len() - 1});
        if let Some(s) = sampler {
            self.samplers.push(s);
            tex["sampler"] = json!(self.samplers.len() - 1);
        }
        self.textures.push(tex);
        Ok(self.textures.len() - 1)
    }

    /// Writes one primitive: positions relative to the centre (f32), UVs, `_FEATURE_ID_0`, indices.
    fn primitive(&mut self, w: &gltf::WorldPrimitive, material: Option<usize>) {
        let b = &mut self.b;
        let pos: Vec<[f32; 3]> =
            w.positions.iter().map(|p| (DVec3::from_array(*p) - self.centre).as_vec3().to_array()).collect();
        let mut attributes = serde_json::Map::new();
        attributes.insert("POSITION".into(), json!(b.push_vec3(&pos)));
        if let Some(uv) = &w.uv {
            let uv: Vec<[f32; 2]> = uv.iter().map(|t| [t[0] as f32, t[1] as f32]).collect();
            attributes.insert("TEXCOORD_0".into(), json!(b.push_vec2(&uv)));
        }
        if let Some(f) = &w.feature_id0 {
            let f: Vec<f32> = f.iter().map(|&v| v as f32).collect();
            attributes.insert("_FEATURE_ID_0".into(), json!(b.push_scalar_f32(&f)));
        }
        let idx: Vec<u32> = w.triangles.iter().flatten().copied().collect();
        self.triangles += w.triangles.len() as u64;
        let mut prim = json!({"attributes": attributes, "indices": b.push_indices(&idx), "mode": 4});
        if let Some(m) = material {
            prim["material"] = json!(m);
        }
        self.primitives.push(prim);
    }

    /// The GLB with one node holding one mesh of all primitives.
    fn finish(self) -> Result<Importable, ContentError> {
        let primitives = self.primitives;
        let mut root = json!({
            "asset": {"version": "2.0", "generator": "insgen (plain GLB for import)"},
            "scene": 0,
            "scenes": [{"nodes": if primitives.is_empty() { json!([]) } else { json!([0]) }}],
            "nodes": if primitives.is_empty() { json!([]) } else { json!([{"mesh": 0}]) },
            "meshes": if primitives.is_empty() { json!([]) } else { json!([{"primitives": primitives}]) },
            "materials": self.materials,
            "textures": self.textures,
            "images": self.images,
            "samplers": self.samplers,
        });
        if self.unlit_used {
            root["extensionsUsed"] = json!(["KHR_materials_unlit"]);
        }
        let glb = self.b.finish(root)?;
        Ok(Importable {
            glb,
            tile_from_plain: DMat4::from_translation(self.centre),
            triangles: self.triangles,
            decoded_extensions: self.decoded,
        })
    }
}

/// The image of `textures[index]` as PNG or JPEG bytes with its MIME type, and its sampler.
fn texture_image(
    g: &Gltf<'_>,
    index: usize,
    load_uri: &LoadUri<'_>,
    decoded: &mut BTreeSet<String>,
) -> Result<(Vec<u8>, &'static str, Option<Value>), ContentError> {
    let r = &g.root;
    let tex = r.textures.get(index).ok_or(ContentError::Missing { what: "texture", index })?;
    let sampler = match tex.sampler {
        None => None,
        Some(s) => Some(r.samplers.get(s).cloned().ok_or_else(|| {
            ContentError::Missing { what: "sampler", index: s }.at(format!("textures[{index}].sampler"))
        })?),
    };
    let ext_source =
        |name: &str| tex.extensions.get(name).and_then(|e| e.get("source")).and_then(Value::as_u64);
    // Candidates in order of preference: PNG/JPEG `source`, then WebP (decoded), refusing KTX2/DDS.
    let mut candidates: Vec<(usize, &'static str)> = Vec::new();
    if let Some(s) = tex.source {
        candidates.push((s, "source"));
    }
    if let Some(s) = ext_source("EXT_texture_webp") {
        candidates.push((s as usize, "EXT_texture_webp"));
    }
    let mut refused = None;
    for (src, via) in &candidates {
        let bytes = image_bytes(g, *src, load_uri).map_err(|e| e.at(format!("images[{src}]")))?;
        let via = *via;
        match sniff(&bytes) {
            ImageKind::Png => return Ok((bytes, "image/png", sampler)),
            ImageKind::Jpeg => return Ok((bytes, "image/jpeg", sampler)),
            ImageKind::Webp => {
                let png = webp_to_png(&bytes).map_err(|source| ContentError::Webp { image: *src, source })?;
                decoded.insert("EXT_texture_webp".into());
                return Ok((png, "image/png", sampler));
            }
            ImageKind::Ktx2 => {
                refused = Some(ContentError::UnreadableImage {
                    image: *src,
                    via,
                    kind: "KTX2 (KHR_texture_basisu)",
                })
            }
            ImageKind::Dds => {
                refused =
                    Some(ContentError::UnreadableImage { image: *src, via, kind: "DDS (MSFT_texture_dds)" })
            }
            ImageKind::Unknown => {
                refused =
                    Some(ContentError::UnreadableImage { image: *src, via, kind: "not PNG, JPEG or WebP" })
            }
        }
    }
    if let Some(image) = ext_source("KHR_texture_basisu") {
        return Err(ContentError::Basisu { texture: index, image });
    }
    if let Some(image) = ext_source("MSFT_texture_dds") {
        return Err(ContentError::Dds { texture: index, image });
    }
    Err(refused.unwrap_or(ContentError::NoTextureImage { texture: index }))
}

/// The bytes of `images[i]`: its buffer view, `data:` URI or file (errors relative to the image).
fn image_bytes(g: &Gltf<'_>, i: usize, load_uri: &LoadUri<'_>) -> Result<Vec<u8>, ContentError> {
    let img = g.root.images.get(i).ok_or(ContentError::Missing { what: "image", index: i })?;
    match (&img.uri, img.buffer_view) {
        (_, Some(v)) => Ok(g.view_bytes(v).map_err(|e| e.at("bufferView"))?.to_vec()),
        (Some(uri), None) if uri.starts_with("data:") => gltf::data_uri_bytes(uri),
        (Some(uri), None) => load_uri(uri),
        (None, None) => Err(ContentError::ImageWithoutData),
    }
}

/// Decodes a WebP image and encodes it as an 8-bit RGB(A) PNG.
fn webp_to_png(bytes: &[u8]) -> Result<Vec<u8>, WebpError> {
    let mut dec = image_webp::WebPDecoder::new(std::io::Cursor::new(bytes)).map_err(WebpError::Decode)?;
    let (w, h) = dec.dimensions();
    let alpha = dec.has_alpha();
    let n = dec.output_buffer_size().ok_or(WebpError::TooLarge)?;
    let mut buf = vec![0u8; n];
    dec.read_image(&mut buf).map_err(WebpError::Decode)?;
    let mut out = Vec::new();
    {
        let mut enc = png::Encoder::new(&mut out, w, h);
        enc.set_color(if alpha { png::ColorType::Rgba } else { png::ColorType::Rgb });
        enc.set_depth(png::BitDepth::Eight);
        let mut wr = enc.write_header().map_err(WebpError::Png)?;
        wr.write_image_data(&buf).map_err(WebpError::Png)?;
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn image_kinds() {
        assert_eq!(sniff(b"\x89PNG\r\n\x1a\n...."), ImageKind::Png);
        assert_eq!(sniff(&[0xFF, 0xD8, 0xFF, 0xE0]), ImageKind::Jpeg);
        assert_eq!(sniff(b"RIFF\0\0\0\0WEBPVP8L"), ImageKind::Webp);
        assert_eq!(sniff(b"\xABKTX 20\xBB\r\n\x1a\n"), ImageKind::Ktx2);
        assert_eq!(sniff(b"GIF89a"), ImageKind::Unknown);
    }
}
