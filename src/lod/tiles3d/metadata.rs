//! `EXT_structural_metadata` property tables (3D Tiles 1.1 glTF content): the per-feature identity,
//! LoD and height that `EXT_mesh_features` feature IDs point to.
//!
//! Only what insgen needs is decoded: non-array `STRING` properties (UTF-8 values with a
//! `stringOffsets` buffer view of UINT8/16/32/64 offsets, default UINT32) and non-array `SCALAR`
//! properties (any component type, with `normalized`, `offset`, `scale` and `noData`). Other property
//! types read as absent. The schema is inline (`schema`) or a file (`schemaUri`, loaded by the caller).

use std::collections::BTreeMap;

use serde::Deserialize;
use serde_json::Value;

use super::error::ContentError;
use super::features::{feature_props, FeatureProps, PropValue};
use super::gltf::{Gltf, LoadUri};

/// `EXT_structural_metadata` on the glTF root.
#[derive(Debug, Deserialize)]
#[serde(rename_all = "camelCase")]
struct StructuralMetadata {
    schema: Option<Schema>,
    schema_uri: Option<String>,
    #[serde(default)]
    property_tables: Vec<PropertyTable>,
}

#[derive(Debug, Deserialize)]
struct Schema {
    #[serde(default)]
    classes: BTreeMap<String, Class>,
}

#[derive(Debug, Deserialize)]
struct Class {
    #[serde(default)]
    properties: BTreeMap<String, ClassProperty>,
}

/// `schema.classes[c].properties[p]`.
#[derive(Debug, Deserialize)]
#[serde(rename_all = "camelCase")]
struct ClassProperty {
    /// `SCALAR`, `STRING`, `VEC3`, `ENUM`, `BOOLEAN`…
    #[serde(rename = "type")]
    kind: String,
    /// `INT8` … `FLOAT64` for numeric types.
    component_type: Option<String>,
    #[serde(default)]
    array: bool,
    #[serde(default)]
    normalized: bool,
    offset: Option<f64>,
    scale: Option<f64>,
    no_data: Option<Value>,
}

/// `propertyTables[i]`.
#[derive(Debug, Deserialize)]
struct PropertyTable {
    class: String,
    count: usize,
    #[serde(default)]
    properties: BTreeMap<String, TableProperty>,
}

/// `propertyTables[i].properties[p]`.
#[derive(Debug, Deserialize)]
#[serde(rename_all = "camelCase")]
struct TableProperty {
    values: usize,
    string_offsets: Option<usize>,
    string_offset_type: Option<String>,
    offset: Option<f64>,
    scale: Option<f64>,
}

/// The properties of every feature of every property table, indexed `[table][feature]`.
///
/// `load_uri` loads an external `schemaUri` relative to the glTF.
///
/// # Errors
/// [`ContentError`] naming the table and property that cannot be read.
pub(crate) fn property_tables(
    gltf: &Gltf<'_>,
    load_uri: &LoadUri<'_>,
) -> Result<Vec<Vec<FeatureProps>>, ContentError> {
    let Some(v) = gltf.root.extensions.get("EXT_structural_metadata") else { return Ok(Vec::new()) };
    let meta: StructuralMetadata = serde_json::from_value(v.clone())
        .map_err(|source| ContentError::Json { at: "extensions.EXT_structural_metadata".into(), source })?;
    let schema = match (meta.schema, &meta.schema_uri) {
        (Some(s), _) => s,
        (None, Some(uri)) => {
            let bytes = load_uri(uri).map_err(|e| e.at("extensions.EXT_structural_metadata.schemaUri"))?;
            serde_json::from_slice(&bytes).map_err(|source| ContentError::Json {
                at: format!("EXT_structural_metadata schemaUri {uri:?}"),
                source,
            })?
        }
        (None, None) => return Err(ContentError::NoSchema),
    };
    let mut out = Vec::with_capacity(meta.property_tables.len());
    for (t, table) in meta.property_tables.iter().enumerate() {
        if table.count > super::MAX_FEATURES {
            return Err(ContentError::TooManyFeatures {
                at: format!("EXT_structural_metadata.propertyTables[{t}].count"),
                count: table.count,
                max: super::MAX_FEATURES,
            });
        }
        let class = schema
            .classes
            .get(&table.class)
            .ok_or_else(|| ContentError::UnknownClass { table: t, class: table.class.clone() })?;
        let props = feature_props(table.count, |name| {
            let (Some(tp), Some(cp)) = (table.properties.get(name), class.properties.get(name)) else {
                return Ok(None);
            };
            read_property(gltf, table.count, tp, cp).map_err(|e| {
                e.at(format!("EXT_structural_metadata.propertyTables[{t}].properties[{name:?}]"))
            })
        })?;
        out.push(props);
    }
    Ok(out)
}

/// Reads one property column; `None` for types insgen does not use.
fn read_property(
    gltf: &Gltf<'_>,
    count: usize,
    tp: &TableProperty,
    cp: &ClassProperty,
) -> Result<Option<Vec<PropValue>>, ContentError> {
    if cp.array {
        return Ok(None);
    }
    let values = gltf.view_bytes(tp.values).map_err(|e| e.at("values"))?;
    match cp.kind.as_str() {
        "STRING" => {
            let offsets_view = tp.string_offsets.ok_or(ContentError::NoStringOffsets)?;
            let offset_type = tp.string_offset_type.as_deref().unwrap_or("UINT32");
            let offset_bytes = gltf.view_bytes(offsets_view).map_err(|e| e.at("stringOffsets"))?;
            let offsets = read_uints(offset_bytes, offset_type, count.saturating_add(1))?;
            let mut out = Vec::with_capacity(count);
            for w in offsets.windows(2) {
                let (start, end) = (w[0] as usize, w[1] as usize);
                let s = values.get(start..end).ok_or(ContentError::StringRange { start, end })?;
                let s = std::str::from_utf8(s).map_err(|source| ContentError::StringUtf8 {
                    start,
                    end,
                    source,
                })?;
                out.push(PropValue::Str(s.to_string()));
            }
            Ok(Some(out))
        }
        "SCALAR" => {
            let ctype = cp.component_type.as_deref().ok_or(ContentError::NoComponentType)?;
            let size = match ctype {
                "INT8" | "UINT8" => 1,
                "INT16" | "UINT16" => 2,
                "INT32" | "UINT32" | "FLOAT32" => 4,
                "INT64" | "UINT64" | "FLOAT64" => 8,
                _ => return Err(ContentError::UnknownComponentType { component_type: ctype.to_string() }),
            };
            let body = count
                .checked_mul(size)
                .and_then(|len| values.get(..len))
                .ok_or(ContentError::ValuesRange { count, size, available: values.len() })?;
            let no_data = cp.no_data.as_ref().and_then(Value::as_f64);
            let offset = tp.offset.or(cp.offset).unwrap_or(0.0);
            let scale = tp.scale.or(cp.scale).unwrap_or(1.0);
            Ok(Some(
                body.chunks_exact(size)
                    .map(|c| {
                        let raw = scalar(c, ctype);
                        if Some(raw) == no_data {
                            return PropValue::Null;
                        }
                        let x = if cp.normalized { normalize(raw, ctype) } else { raw };
                        PropValue::Num(offset + scale * x)
                    })
                    .collect(),
            ))
        }
        _ => Ok(None),
    }
}

fn read_uints(bytes: &[u8], kind: &str, n: usize) -> Result<Vec<u64>, ContentError> {
    let size = match kind {
        "UINT8" => 1,
        "UINT16" => 2,
        "UINT32" => 4,
        "UINT64" => 8,
        _ => return Err(ContentError::UnknownOffsetType { kind: kind.to_string() }),
    };
    let body = n
        .checked_mul(size)
        .and_then(|len| bytes.get(..len))
        .ok_or(ContentError::OffsetsRange { count: n, size })?;
    Ok(body
        .chunks_exact(size)
        .map(|c| {
            let mut b = [0u8; 8];
            b[..size].copy_from_slice(c);
            u64::from_le_bytes(b)
        })
        .collect())
}

fn scalar(c: &[u8], ctype: &str) -> f64 {
    let mut b = [0u8; 8];
    b[..c.len()].copy_from_slice(c);
    match ctype {
        "INT8" => c[0] as i8 as f64,
        "UINT8" => c[0] as f64,
        "INT16" => i16::from_le_bytes([c[0], c[1]]) as f64,
        "UINT16" => u16::from_le_bytes([c[0], c[1]]) as f64,
        "INT32" => i32::from_le_bytes([c[0], c[1], c[2], c[3]]) as f64,
        "UINT32" => u32::from_le_bytes([c[0], c[1], c[2], c[3]]) as f64,
        "FLOAT32" => f32::from_le_bytes([c[0], c[1], c[2], c[3]]) as f64,
        "INT64" => i64::from_le_bytes(b) as f64,
        "UINT64" => u64::from_le_bytes(b) as f64,
        _ => f64::from_le_bytes(b),
    }
}

fn normalize(x: f64, ctype: &str) -> f64 {
    let max = match ctype {
        "INT8" => i8::MAX as f64,
        "UINT8" => u8::MAX as f64,
        "INT16" => i16::MAX as f64,
        "UINT16" => u16::MAX as f64,
        "INT32" => i32::MAX as f64,
        "UINT32" => u32::MAX as f64,
        "INT64" => i64::MAX as f64,
        "UINT64" => u64::MAX as f64,
        _ => return x,
    };
    (x / max).max(-1.0)
}
