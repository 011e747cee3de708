//! One tile content (b3dm, glb, glTF JSON, cmpt) → its features' triangles in the tileset frame.
//!
//! Triangles are grouped per feature: a triangle belongs to the feature of its *first* vertex (the
//! three normally agree; those that do not are counted). Triangles with repeated indices or zero
//! area are dropped and counted. Geometry without feature IDs is kept apart for the caller to split
//! into connected components.

use std::collections::{BTreeMap, BTreeSet, HashMap};
use std::path::Path;

use glam::{DMat4, DVec3};

use super::b3dm;
use super::error::ContentError;
use super::features::FeatureProps;
use super::gltf::{self, Gltf, LoadUri, Surface, TableKey, UpAxis, WorldPrimitive};
use super::metadata;
use crate::lod::TriMesh;

/// One feature of a content: its properties and triangles.
#[derive(Debug)]
pub(crate) struct DecodedFeature {
    /// The feature's identity: the table's `gml_id` (or equivalent), else a synthesized
    /// `"<label>#batch<N>"`-style id.
    pub source_id: String,
    pub lod: Option<String>,
    pub measured_height_m: Option<f64>,
    pub mesh: TriMesh,
}

/// Counters gathered while decoding contents.
#[derive(Debug, Clone, Default, PartialEq)]
pub(crate) struct Counters {
    pub contents_read: u64,
    pub unsupported_contents: u64,
    pub triangles: u64,
    pub degenerate_triangles: u64,
    pub mixed_feature_triangles: u64,
    pub null_feature_triangles: u64,
    pub features_without_geometry: u64,
    pub skipped_primitives: u64,
}

impl Counters {
    pub(crate) fn add(&mut self, o: &Counters) {
        self.contents_read += o.contents_read;
        self.unsupported_contents += o.unsupported_contents;
        self.triangles += o.triangles;
        self.degenerate_triangles += o.degenerate_triangles;
        self.mixed_feature_triangles += o.mixed_feature_triangles;
        self.null_feature_triangles += o.null_feature_triangles;
        self.features_without_geometry += o.features_without_geometry;
        self.skipped_primitives += o.skipped_primitives;
    }
}

/// What one content yields.
#[derive(Debug, Default)]
pub(crate) struct DecodedContent {
    /// Features in table order, then feature ID order.
    pub features: Vec<DecodedFeature>,
    /// Geometry without feature IDs (to be split into connected components).
    pub idless: TriMesh,
    pub counters: Counters,
}

/// The loader of URIs relative to the folder of content `file` (external buffers, images, schemas).
pub(crate) fn relative_loader(file: &Path) -> impl Fn(&str) -> Result<Vec<u8>, ContentError> {
    let dir = file.parent().unwrap_or(Path::new(".")).to_path_buf();
    move |uri: &str| {
        let path = super::tileset::resolve_uri(&dir, uri)?;
        std::fs::read(&path).map_err(|source| ContentError::ReadUri { uri: uri.to_string(), path, source })
    }
}

/// Decodes one content file's bytes. `file` locates relative buffer and schema URIs; `label` names
/// the content in synthesized ids; `world_from_tile` is the accumulated tile transform.
///
/// # Errors
/// [`ContentError`] saying what is wrong where (the caller names the file and the tile).
pub(crate) fn decode(
    bytes: &[u8],
    file: &Path,
    label: &str,
    world_from_tile: DMat4,
    up: UpAxis,
) -> Result<DecodedContent, ContentError> {
    let load_uri = relative_loader(file);
    let magic = bytes.get(0..4).unwrap_or(bytes);
    match magic {
        b"b3dm" => {
            let tile = b3dm::parse(bytes)?;
            let embedded = |e| ContentError::EmbeddedGlb(Box::new(e));
            let g = gltf::parse_glb(tile.glb, &load_uri).map_err(embedded)?;
            let batch = tile.batch_table.feature_props(tile.batch_length)?;
            let mut outer = world_from_tile;
            if let Some(c) = tile.rtc_center {
                outer *= DMat4::from_translation(DVec3::from_array(c));
            }
            features_of(&g, outer, up, Some(&batch), label, &load_uri).map_err(embedded)
        }
        b"glTF" => {
            let g = gltf::parse_glb(bytes, &load_uri)?;
            features_of(&g, world_from_tile, up, None, label, &load_uri)
        }
        b"cmpt" => {
            let mut out = DecodedContent::default();
            for (k, inner) in b3dm::split_cmpt(bytes)?.into_iter().enumerate() {
                let part = decode(inner, file, &format!("{label}[{k}]"), world_from_tile, up)
                    .map_err(|e| ContentError::CmptTile { index: k, source: Box::new(e) })?;
                out.features.extend(part.features);
                append(&mut out.idless, &part.idless);
                out.counters.add(&part.counters);
            }
            Ok(out)
        }
        b"i3dm" | b"pnts" => Ok(DecodedContent {
            counters: Counters { unsupported_contents: 1, ..Default::default() },
            ..Default::default()
        }),
        _ if bytes.iter().find(|b| !b.is_ascii_whitespace()) == Some(&b'{')
            || bytes.starts_with(b"\xEF\xBB\xBF") =>
        {
            let json = bytes.strip_prefix(b"\xEF\xBB\xBF").unwrap_or(bytes);
            let g = gltf::parse_gltf_json(json, &load_uri)?;
            features_of(&g, world_from_tile, up, None, label, &load_uri)
        }
        _ => Err(ContentError::UnknownContent { magic: String::from_utf8_lossy(magic).into_owned() }),
    }
}

/// Appends `b` to `a`, offsetting indices.
pub(crate) fn append(a: &mut TriMesh, b: &TriMesh) {
    let base = a.positions.len() as u32;
    a.positions.extend_from_slice(&b.positions);
    a.triangles.extend(b.triangles.iter().map(|t| t.map(|i| i + base)));
}

/// True for triangles with a repeated index or exactly zero area.
fn degenerate(p: &[[f64; 3]], t: [u32; 3]) -> bool {
    if t[0] == t[1] || t[1] == t[2] || t[0] == t[2] {
        return true;
    }
    let [a, b, c] = t.map(|i| DVec3::from_array(p[i as usize]));
    (b - a).cross(c - a).length_squared() == 0.0
}

/// Groups a glTF's triangles by feature and resolves each feature's properties.
fn features_of(
    g: &Gltf<'_>,
    outer: DMat4,
    up: UpAxis,
    batch: Option<&[FeatureProps]>,
    label: &str,
    load_uri: &LoadUri<'_>,
) -> Result<DecodedContent, ContentError> {
    let mut outer = outer;
    if let Some(c) = g.cesium_rtc()? {
        outer *= DMat4::from_translation(DVec3::from_array(c));
    }
    let (prims, skipped) = g.world_primitives(outer, up, Surface::No)?;
    let tables = metadata::property_tables(g, load_uri)?;
    let mut counters = Counters { contents_read: 1, skipped_primitives: skipped, ..Default::default() };
    let mut meshes: BTreeMap<(TableKey, u32), TriMesh> = BTreeMap::new();
    let mut idless = TriMesh::default();

    for WorldPrimitive { positions, triangles, features, .. } in &prims {
        let Some(fids) = features else {
            let base = idless.positions.len() as u32;
            idless.positions.extend_from_slice(positions);
            for &t in triangles {
                if degenerate(positions, t) {
                    counters.degenerate_triangles += 1;
                } else {
                    idless.triangles.push(t.map(|i| i + base));
                }
            }
            continue;
        };
        let mut remap: HashMap<(u32, u32), u32> = HashMap::new();
        for &t in triangles {
            if degenerate(positions, t) {
                counters.degenerate_triangles += 1;
                continue;
            }
            let ids = t.map(|i| fids.ids[i as usize]);
            if ids[1] != ids[0] || ids[2] != ids[0] {
                counters.mixed_feature_triangles += 1;
            }
            let Some(fid) = ids[0] else {
                counters.null_feature_triangles += 1;
                continue;
            };
            check_feature_id(fids.table, fid, batch, &tables)?;
            let mesh = meshes.entry((fids.table, fid)).or_default();
            let tri = t.map(|i| {
                *remap.entry((fid, i)).or_insert_with(|| {
                    mesh.positions.push(positions[i as usize]);
                    (mesh.positions.len() - 1) as u32
                })
            });
            mesh.triangles.push(tri);
        }
    }

    // Features a table lists but no triangle uses.
    let used: BTreeSet<(TableKey, u32)> = meshes.keys().copied().collect();
    if let Some(b) = batch {
        counters.features_without_geometry +=
            (0..b.len() as u32).filter(|&i| !used.contains(&(TableKey::Batch, i))).count() as u64;
    }
    let features = meshes
        .into_iter()
        .map(|((table, fid), mesh)| {
            counters.triangles += mesh.triangles.len() as u64;
            let props = match table {
                TableKey::Batch => batch.and_then(|b| b.get(fid as usize)),
                TableKey::Property(t) => tables.get(t).and_then(|p| p.get(fid as usize)),
                TableKey::Anonymous(..) => None,
            };
            let source_id = props.and_then(|p| p.id.clone()).unwrap_or_else(|| match table {
                TableKey::Batch => format!("{label}#batch{fid}"),
                TableKey::Property(t) => format!("{label}#table{t}.feature{fid}"),
                TableKey::Anonymous(s, _) => format!("{label}#ids{s}.feature{fid}"),
            });
            DecodedFeature {
                source_id,
                lod: props.and_then(|p| p.lod.clone()),
                measured_height_m: props.and_then(|p| p.measured_height_m),
                mesh,
            }
        })
        .collect();
    counters.triangles += idless.triangles.len() as u64;
    Ok(DecodedContent { features, idless, counters })
}

/// A feature ID must address a row of its table.
fn check_feature_id(
    table: TableKey,
    fid: u32,
    batch: Option<&[FeatureProps]>,
    tables: &[Vec<FeatureProps>],
) -> Result<(), ContentError> {
    match table {
        TableKey::Batch => match batch {
            Some(b) if fid as usize >= b.len() => {
                Err(ContentError::BatchIdRange { id: fid, batch_length: b.len() })
            }
            _ => Ok(()),
        },
        TableKey::Property(t) => match tables.get(t) {
            None => Err(ContentError::NoPropertyTable { table: t }),
            Some(p) if fid as usize >= p.len() => {
                Err(ContentError::FeatureIdRange { id: fid, table: t, count: p.len() })
            }
            Some(_) => Ok(()),
        },
        TableKey::Anonymous(s, count) if fid as u64 >= count => {
            Err(ContentError::FeatureCountRange { id: fid, set: s, count })
        }
        TableKey::Anonymous(..) => Ok(()),
    }
}
