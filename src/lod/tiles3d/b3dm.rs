//! Batched 3D Model (b3dm) and Composite (cmpt) tile containers of 3D Tiles 1.0.
//!
//! A b3dm is a 28-byte header — magic `"b3dm"`, version 1, byteLength, featureTableJSONByteLength,
//! featureTableBinaryByteLength, batchTableJSONByteLength, batchTableBinaryByteLength (all u32 LE) —
//! followed by the feature table (JSON + binary), the batch table (JSON + binary) and a GLB. Every
//! length is checked against the file before anything is sliced. The two pre-1.0 header layouts
//! (20 bytes: batchLength, batchTableByteLength; 24 bytes: batchTableJSONByteLength,
//! batchTableBinaryByteLength, batchLength) are recognised the way CesiumJS does: in those layouts
//! the word read as a batch-table length is really the first bytes of JSON or of the GLB, which is
//! implausibly large (≥ 0x22000000).
//!
//! Feature table: `BATCH_LENGTH` (required) and `RTC_CENTER` (JSON array, or a FLOAT VEC3 in the
//! binary body). Batch table: one JSON array per property, or a reference
//! `{byteOffset, componentType, type}` into the binary body.

use serde_json::{Map, Value};

use super::error::{ContentError, B3DM_SECTIONS};
use super::features::{feature_props, FeatureProps, PropValue};

/// Length of the current b3dm header, bytes.
const HEADER_LEN: usize = 28;
/// A legacy header is recognised when a length word is at least this (CesiumJS's rule: the word is
/// then really `"` (0x22) or `g` (0x67) of the following JSON or GLB).
const LEGACY_THRESHOLD: u32 = 0x2200_0000;

/// A parsed b3dm: its tables and the embedded GLB.
#[derive(Debug)]
pub(crate) struct B3dm<'a> {
    pub batch_length: usize,
    /// `RTC_CENTER`: positions are relative to this point of the tile frame.
    pub rtc_center: Option<[f64; 3]>,
    pub batch_table: BatchTable<'a>,
    pub glb: &'a [u8],
}

/// The batch table: JSON properties and the binary body they may reference.
#[derive(Debug, Default)]
pub(crate) struct BatchTable<'a> {
    json: Map<String, Value>,
    binary: &'a [u8],
}

fn u32_at(bytes: &[u8], at: usize) -> u32 {
    u32::from_le_bytes([bytes[at], bytes[at + 1], bytes[at + 2], bytes[at + 3]])
}

/// Parses a JSON chunk (`table` names it) padded with spaces or NULs; an empty chunk is an empty
/// object.
fn parse_json_chunk(bytes: &[u8], table: &'static str) -> Result<Map<String, Value>, ContentError> {
    let end = bytes.iter().rposition(|&b| b != 0 && b != b' ').map_or(0, |i| i + 1);
    if end == 0 {
        return Ok(Map::new());
    }
    match serde_json::from_slice::<Value>(&bytes[..end]) {
        Ok(Value::Object(m)) => Ok(m),
        Ok(_) => Err(ContentError::TableNotObject { table }),
        Err(source) => Err(ContentError::TableJson { table, source }),
    }
}

/// Parses a b3dm from `bytes` (exactly the tile: a standalone file or a slice of a cmpt).
///
/// # Errors
/// [`ContentError`] naming the header field or table that is wrong and the numbers involved.
pub(crate) fn parse(bytes: &[u8]) -> Result<B3dm<'_>, ContentError> {
    let too_short =
        || ContentError::TooShort { what: "b3dm header", length: bytes.len(), needed: HEADER_LEN };
    if bytes.len() < 20 {
        return Err(too_short());
    }
    if &bytes[0..4] != b"b3dm" {
        return Err(ContentError::NotB3dm { magic: String::from_utf8_lossy(&bytes[0..4]).into_owned() });
    }
    let version = u32_at(bytes, 4);
    if version != 1 {
        return Err(ContentError::Version { container: "b3dm", version });
    }
    let byte_length = u32_at(bytes, 8) as usize;
    if byte_length != bytes.len() {
        return Err(ContentError::ByteLength { container: "b3dm", byte_length, length: bytes.len() });
    }
    let word = |i: usize| if bytes.len() >= 12 + 4 * (i + 1) { u32_at(bytes, 12 + 4 * i) } else { 0 };
    let (header_len, ft_json, ft_bin, bt_json, bt_bin, legacy_batch_length) =
        if bytes.len() >= HEADER_LEN && word(2) >= LEGACY_THRESHOLD {
            // Legacy 20-byte header: batchLength, batchTableByteLength.
            (20, 0, 0, word(1) as usize, 0, Some(word(0) as usize))
        } else if bytes.len() >= HEADER_LEN && word(3) >= LEGACY_THRESHOLD {
            // Legacy 24-byte header: batchTableJSONByteLength, batchTableBinaryByteLength, batchLength.
            (24, 0, 0, word(0) as usize, word(1) as usize, Some(word(2) as usize))
        } else if bytes.len() >= HEADER_LEN {
            (HEADER_LEN, word(0) as usize, word(1) as usize, word(2) as usize, word(3) as usize, None)
        } else {
            return Err(too_short());
        };
    let lengths = [ft_json, ft_bin, bt_json, bt_bin];
    let mut end = header_len;
    for (name, len) in B3DM_SECTIONS.into_iter().zip(lengths) {
        end = end.checked_add(len).filter(|&e| e <= byte_length).ok_or(ContentError::B3dmSection {
            name,
            len,
            byte_length,
            lengths,
        })?;
    }
    if end == byte_length {
        return Err(ContentError::NoGlb { byte_length });
    }
    let mut at = header_len;
    let mut take = |len: usize| {
        let s = &bytes[at..at + len];
        at += len;
        s
    };
    let ft_json = take(ft_json);
    let ft_bin = take(ft_bin);
    let bt_json = take(bt_json);
    let bt_bin = take(bt_bin);
    let glb = &bytes[end..];

    let ft = parse_json_chunk(ft_json, "feature table")?;
    let batch_length = match (ft.get("BATCH_LENGTH"), legacy_batch_length) {
        (Some(v), _) => v.as_u64().ok_or_else(|| ContentError::BatchLength { value: v.clone() })? as usize,
        (None, Some(n)) => n,
        (None, None) => return Err(ContentError::NoBatchLength),
    };
    if batch_length > super::MAX_FEATURES {
        return Err(ContentError::TooManyFeatures {
            at: "feature table BATCH_LENGTH".into(),
            count: batch_length,
            max: super::MAX_FEATURES,
        });
    }
    let rtc_center = match ft.get("RTC_CENTER") {
        None => None,
        Some(v) => Some(rtc_center(v, ft_bin)?),
    };
    let batch_table = BatchTable { json: parse_json_chunk(bt_json, "batch table")?, binary: bt_bin };
    Ok(B3dm { batch_length, rtc_center, batch_table, glb })
}

/// `RTC_CENTER`: `[x, y, z]`, or `{"byteOffset": n}` pointing at three f32 in the binary body.
fn rtc_center(v: &Value, binary: &[u8]) -> Result<[f64; 3], ContentError> {
    let c = if let Some(arr) = v.as_array() {
        let nums: Vec<f64> = arr.iter().filter_map(Value::as_f64).collect();
        <[f64; 3]>::try_from(nums).map_err(|_| ContentError::RtcCenter { value: v.clone() })?
    } else if let Some(off) = v.get("byteOffset").and_then(Value::as_u64) {
        let off = off as usize;
        let b = binary
            .get(off..off.saturating_add(12))
            .ok_or(ContentError::RtcCenterOffset { offset: off, body: binary.len() })?;
        let f = |i: usize| f32::from_le_bytes([b[i], b[i + 1], b[i + 2], b[i + 3]]) as f64;
        [f(0), f(4), f(8)]
    } else {
        return Err(ContentError::RtcCenter { value: v.clone() });
    };
    if c.iter().any(|x| !x.is_finite()) {
        return Err(ContentError::NotFinite { at: "feature table RTC_CENTER", values: c.to_vec() });
    }
    Ok(c)
}

impl<'a> BatchTable<'a> {
    /// The values of property `name` for batch ids `0..batch_length`, or `None` if absent.
    ///
    /// # Errors
    /// When the property is an array shorter than `batch_length`, or a binary reference that is
    /// malformed or runs past the binary body.
    pub(crate) fn column(
        &self,
        name: &str,
        batch_length: usize,
    ) -> Result<Option<Vec<PropValue>>, ContentError> {
        let Some(v) = self.json.get(name) else { return Ok(None) };
        if let Some(arr) = v.as_array() {
            if arr.len() < batch_length {
                return Err(ContentError::BatchPropertyShort {
                    name: name.to_string(),
                    values: arr.len(),
                    batch_length,
                });
            }
            return Ok(Some(arr[..batch_length].iter().map(PropValue::from_json).collect()));
        }
        let bad = |problem: &'static str| ContentError::BatchProperty {
            name: name.to_string(),
            problem,
            value: v.clone(),
        };
        let offset =
            v.get("byteOffset").and_then(Value::as_u64).ok_or_else(|| bad("no byteOffset"))? as usize;
        let ctype = v.get("componentType").and_then(Value::as_str).ok_or_else(|| bad("no componentType"))?;
        let kind = v.get("type").and_then(Value::as_str).ok_or_else(|| bad("no type"))?;
        let n = match kind {
            "SCALAR" => 1,
            "VEC2" => 2,
            "VEC3" => 3,
            "VEC4" => 4,
            _ => return Err(bad("unknown type")),
        };
        let size = match ctype {
            "BYTE" | "UNSIGNED_BYTE" => 1,
            "SHORT" | "UNSIGNED_SHORT" => 2,
            "INT" | "UNSIGNED_INT" | "FLOAT" => 4,
            "DOUBLE" => 8,
            _ => return Err(bad("unknown componentType")),
        };
        let len = batch_length * n * size;
        let body = offset.checked_add(len).and_then(|end| self.binary.get(offset..end)).ok_or_else(|| {
            ContentError::BatchPropertyRange { name: name.to_string(), len, offset, body: self.binary.len() }
        })?;
        // Only the first component of vector properties is kept (insgen reads scalars only).
        Ok(Some(
            body.chunks_exact(n * size)
                .map(|c| {
                    let x = match ctype {
                        "BYTE" => c[0] as i8 as f64,
                        "UNSIGNED_BYTE" => c[0] as f64,
                        "SHORT" => i16::from_le_bytes([c[0], c[1]]) as f64,
                        "UNSIGNED_SHORT" => u16::from_le_bytes([c[0], c[1]]) as f64,
                        "INT" => i32::from_le_bytes([c[0], c[1], c[2], c[3]]) as f64,
                        "UNSIGNED_INT" => u32::from_le_bytes([c[0], c[1], c[2], c[3]]) as f64,
                        "FLOAT" => f32::from_le_bytes([c[0], c[1], c[2], c[3]]) as f64,
                        _ => f64::from_le_bytes([c[0], c[1], c[2], c[3], c[4], c[5], c[6], c[7]]),
                    };
                    PropValue::Num(x)
                })
                .collect(),
        ))
    }

    /// Identity, LoD and height of every batch id (see [`super::features`]).
    pub(crate) fn feature_props(&self, batch_length: usize) -> Result<Vec<FeatureProps>, ContentError> {
        feature_props(batch_length, |name| self.column(name, batch_length))
    }
}

/// Splits a cmpt (composite) tile into its inner tiles: a 16-byte header (magic `"cmpt"`, version 1,
/// byteLength, tilesLength), then `tilesLength` tiles, each starting with its own magic, version and
/// byteLength.
///
/// # Errors
/// [`ContentError`] when a length disagrees with the data (with both numbers).
pub(crate) fn split_cmpt(bytes: &[u8]) -> Result<Vec<&[u8]>, ContentError> {
    if bytes.len() < 16 {
        return Err(ContentError::TooShort { what: "cmpt header", length: bytes.len(), needed: 16 });
    }
    let version = u32_at(bytes, 4);
    if version != 1 {
        return Err(ContentError::Version { container: "cmpt", version });
    }
    let byte_length = u32_at(bytes, 8) as usize;
    if byte_length != bytes.len() {
        return Err(ContentError::ByteLength { container: "cmpt", byte_length, length: bytes.len() });
    }
    let tiles_length = u32_at(bytes, 12) as usize;
    let mut tiles = Vec::with_capacity(tiles_length.min(1024));
    let mut at = 16;
    for k in 0..tiles_length {
        if at + 12 > byte_length {
            return Err(ContentError::CmptTileStart { index: k, at, byte_length });
        }
        let len = u32_at(bytes, at + 8) as usize;
        let end = at
            .checked_add(len)
            .filter(|&e| e <= byte_length && len >= 12)
            .ok_or(ContentError::CmptTileLength { index: k, len, at, byte_length })?;
        tiles.push(&bytes[at..end]);
        at = end;
    }
    Ok(tiles)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A b3dm around `glb` with the given table chunks (padded to 8 bytes as the spec asks).
    pub(crate) fn build(ft_json: &str, ft_bin: &[u8], bt_json: &str, bt_bin: &[u8], glb: &[u8]) -> Vec<u8> {
        let pad = |mut v: Vec<u8>, fill: u8| {
            while !v.len().is_multiple_of(8) {
                v.push(fill);
            }
            v
        };
        let ftj = pad(ft_json.as_bytes().to_vec(), b' ');
        let ftb = pad(ft_bin.to_vec(), 0);
        let btj = pad(bt_json.as_bytes().to_vec(), b' ');
        let btb = pad(bt_bin.to_vec(), 0);
        let total = 28 + ftj.len() + ftb.len() + btj.len() + btb.len() + glb.len();
        let mut out = b"b3dm".to_vec();
        for w in [1, total, ftj.len(), ftb.len(), btj.len(), btb.len()] {
            out.extend_from_slice(&(w as u32).to_le_bytes());
        }
        for part in [&ftj[..], &ftb, &btj, &btb, glb] {
            out.extend_from_slice(part);
        }
        out
    }

    #[test]
    fn tables_and_binary_properties() {
        let mut bin = Vec::new();
        for v in [2i8, 1, 2] {
            bin.push(v as u8);
        }
        let rtc: Vec<u8> = [1.5f32, -2.0, 3.25].iter().flat_map(|f| f.to_le_bytes()).collect();
        let b = build(
            r#"{"BATCH_LENGTH":3,"RTC_CENTER":{"byteOffset":0}}"#,
            &rtc,
            r#"{"gml_id":["a","b",null],"_lod":{"byteOffset":0,"componentType":"BYTE","type":"SCALAR"},"height":[1,-9999,"7.5"]}"#,
            &bin,
            b"glTF-not-really",
        );
        let t = parse(&b).unwrap();
        assert_eq!(t.batch_length, 3);
        assert_eq!(t.rtc_center, Some([1.5, -2.0, 3.25]));
        assert_eq!(t.glb, b"glTF-not-really");
        let props = t.batch_table.feature_props(3).unwrap();
        assert_eq!(props[0].id.as_deref(), Some("a"));
        assert_eq!(props[2].id, None);
        assert_eq!(props[1].lod.as_deref(), Some("1"));
        assert_eq!(props[0].measured_height_m, Some(1.0));
        assert_eq!(props[1].measured_height_m, None);
        assert_eq!(props[2].measured_height_m, Some(7.5));
    }

    #[test]
    fn header_lengths_are_checked() {
        let good = build(r#"{"BATCH_LENGTH":0}"#, &[], "", &[], b"glTF....");
        assert!(parse(&good).is_ok());
        let mut wrong = good.clone();
        wrong[8..12].copy_from_slice(&((good.len() + 4) as u32).to_le_bytes());
        let e = parse(&wrong).unwrap_err();
        let len = good.len();
        assert!(
            matches!(e, ContentError::ByteLength { byte_length, length, .. } if byte_length == len + 4 && length == len),
            "{e:?}"
        );
        let e = e.to_string();
        assert!(e.contains("byteLength") && e.contains("truncated"), "{e}");
        let mut past = good.clone();
        past[12..16].copy_from_slice(&10_000u32.to_le_bytes());
        let e = parse(&past).unwrap_err();
        assert!(matches!(
            e,
            ContentError::B3dmSection { name: "featureTableJSONByteLength", len: 10_000, .. }
        ));
        assert!(e.to_string().contains("featureTableJSONByteLength = 10000"), "{e}");
        assert!(parse(&good[..good.len() - 3]).is_err());
        assert!(matches!(parse(b"b3dm"), Err(ContentError::TooShort { length: 4, needed: 28, .. })));
    }

    #[test]
    fn implausible_batch_length_is_refused() {
        let b = build(r#"{"BATCH_LENGTH":4000000000}"#, &[], "", &[], b"glTF....");
        assert!(parse(&b).unwrap_err().to_string().contains("BATCH_LENGTH 4000000000 exceeds"));
    }

    #[test]
    fn legacy_24_byte_header() {
        // magic, version, byteLength, batchTableJSONByteLength, batchTableBinaryByteLength, batchLength.
        let bt = br#"{"gml_id":["x"]}"#;
        let glb = b"glTF0000";
        let total = 24 + bt.len() + glb.len();
        let mut b = b"b3dm".to_vec();
        for w in [1, total, bt.len(), 0, 1] {
            b.extend_from_slice(&(w as u32).to_le_bytes());
        }
        b.extend_from_slice(bt);
        b.extend_from_slice(glb);
        let t = parse(&b).unwrap();
        assert_eq!(t.batch_length, 1);
        assert_eq!(t.glb, glb);
        assert_eq!(t.batch_table.feature_props(1).unwrap()[0].id.as_deref(), Some("x"));
    }

    #[test]
    fn short_property_array_is_an_error() {
        let b = build(r#"{"BATCH_LENGTH":2}"#, &[], r#"{"gml_id":["a"]}"#, &[], b"glTF....");
        let t = parse(&b).unwrap();
        let e = t.batch_table.feature_props(2).unwrap_err();
        assert!(
            matches!(&e, ContentError::BatchPropertyShort { name, values: 1, batch_length: 2 } if name == "gml_id")
        );
        assert!(e.to_string().contains("gml_id"), "{e}");
    }

    #[test]
    fn binary_property_out_of_bounds() {
        let b = build(
            r#"{"BATCH_LENGTH":2}"#,
            &[],
            r#"{"height":{"byteOffset":4,"componentType":"DOUBLE","type":"SCALAR"}}"#,
            &[0; 8],
            b"glTF....",
        );
        let t = parse(&b).unwrap();
        let e = t.batch_table.feature_props(2).unwrap_err();
        assert!(matches!(e, ContentError::BatchPropertyRange { len: 16, offset: 4, body: 8, .. }), "{e:?}");
        assert!(e.to_string().contains("exceed"), "{e}");
    }

    #[test]
    fn cmpt_split() {
        let inner = build(r#"{"BATCH_LENGTH":0}"#, &[], "", &[], b"glTF....");
        let mut c = b"cmpt".to_vec();
        let total = 16 + 2 * inner.len();
        for w in [1, total, 2] {
            c.extend_from_slice(&(w as u32).to_le_bytes());
        }
        c.extend_from_slice(&inner);
        c.extend_from_slice(&inner);
        let tiles = split_cmpt(&c).unwrap();
        assert_eq!(tiles.len(), 2);
        assert_eq!(tiles[1], &inner[..]);
        assert!(matches!(
            split_cmpt(&c[..c.len() - 1]),
            Err(ContentError::ByteLength { container: "cmpt", .. })
        ));
    }
}
