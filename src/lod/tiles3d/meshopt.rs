//! `EXT_meshopt_compression`: buffer views compressed with meshoptimizer's vertex and index codecs
//! (3DBAG, gltfpack and ContextCapture exports), decoded with the `meshopt` crate (meshoptimizer's C++
//! decoder, which is safe for untrusted input).
//!
//! A compressed bufferView carries `extensions.EXT_meshopt_compression = {buffer, byteOffset,
//! byteLength, byteStride, count, mode, filter}`: the compressed bytes sit in `buffer`, and decoding
//! yields `count × byteStride` bytes, the view's uncompressed content. Modes: `ATTRIBUTES` (vertex
//! codec; stride a multiple of 4, at most 256), `TRIANGLES` (index codec; count a multiple of 3) and
//! `INDICES` (index sequence codec), with 2- or 4-byte indices. Filters (applied after decoding):
//! `NONE`, `OCTAHEDRAL` (stride 4 or 8), `QUATERNION` (stride 8), `EXPONENTIAL` (stride a multiple
//! of 4). Every precondition of the C++ decoder is checked here first: its assertions would abort
//! the process. The view's own `buffer` is usually a "fallback" buffer without data
//! (`extensions.EXT_meshopt_compression.fallback = true`), which is never read.

use serde::Deserialize;

use super::error::MeshoptError;

/// `bufferViews[i].extensions.EXT_meshopt_compression`.
#[derive(Debug, Clone, Deserialize)]
#[serde(rename_all = "camelCase")]
pub(crate) struct MeshoptView {
    pub buffer: usize,
    #[serde(default)]
    pub byte_offset: usize,
    pub byte_length: usize,
    pub byte_stride: usize,
    pub count: usize,
    /// `"ATTRIBUTES"`, `"TRIANGLES"` or `"INDICES"`.
    pub mode: String,
    /// `"NONE"` (default), `"OCTAHEDRAL"`, `"QUATERNION"`, `"EXPONENTIAL"`.
    #[serde(default)]
    pub filter: Option<String>,
}

/// Largest decoded view insgen accepts, bytes (a corrupt count would otherwise allocate wildly).
const MAX_DECODED_BYTES: usize = 1 << 30;

/// Decodes one compressed view from its `source` bytes (the `byteLength` bytes at `byteOffset` of
/// the extension's buffer).
///
/// # Errors
/// [`MeshoptError`] naming the broken precondition or the decoder's error code.
pub(crate) fn decode(ext: &MeshoptView, source: &[u8]) -> Result<Vec<u8>, MeshoptError> {
    let (count, stride) = (ext.count, ext.byte_stride);
    let total = count
        .checked_mul(stride)
        .filter(|&t| t <= MAX_DECODED_BYTES)
        .ok_or(MeshoptError::TooLarge { count, stride, max: MAX_DECODED_BYTES })?;
    let mut out = vec![0u8; total];
    let (mode, code) = match ext.mode.as_str() {
        "ATTRIBUTES" => {
            if stride == 0 || stride > 256 || stride % 4 != 0 {
                return Err(MeshoptError::Stride {
                    what: "ATTRIBUTES mode",
                    expected: "that is a multiple of 4 in 4..=256",
                    stride,
                });
            }
            // SAFETY: `out` holds count × stride bytes, the decoder's destination size; the source
            // slice is valid for its length.
            let code = unsafe {
                ::meshopt::ffi::meshopt_decodeVertexBuffer(
                    out.as_mut_ptr().cast(),
                    count,
                    stride,
                    source.as_ptr(),
                    source.len(),
                )
            };
            ("ATTRIBUTES", code)
        }
        "TRIANGLES" | "INDICES" => {
            let mode = if ext.mode == "TRIANGLES" { "TRIANGLES" } else { "INDICES" };
            if stride != 2 && stride != 4 {
                let what = if mode == "TRIANGLES" { "TRIANGLES mode" } else { "INDICES mode" };
                return Err(MeshoptError::Stride { what, expected: "of 2 or 4", stride });
            }
            if mode == "TRIANGLES" && count % 3 != 0 {
                return Err(MeshoptError::TriangleCount { count });
            }
            // SAFETY: as above; index_size is 2 or 4 as the decoder asserts.
            let code = unsafe {
                if mode == "TRIANGLES" {
                    ::meshopt::ffi::meshopt_decodeIndexBuffer(
                        out.as_mut_ptr().cast(),
                        count,
                        stride,
                        source.as_ptr(),
                        source.len(),
                    )
                } else {
                    ::meshopt::ffi::meshopt_decodeIndexSequence(
                        out.as_mut_ptr().cast(),
                        count,
                        stride,
                        source.as_ptr(),
                        source.len(),
                    )
                }
            };
            (mode, code)
        }
        other => return Err(MeshoptError::UnknownMode { mode: other.to_string() }),
    };
    if code != 0 {
        return Err(MeshoptError::Corrupt { mode, code });
    }
    let filter = ext.filter.as_deref().unwrap_or("NONE");
    if filter != "NONE" && mode != "ATTRIBUTES" {
        return Err(MeshoptError::FilterMode { filter: filter.to_string(), mode });
    }
    // SAFETY (all three): `out` holds count × stride bytes and the stride is one the filter accepts.
    match filter {
        "NONE" => {}
        "OCTAHEDRAL" => {
            if stride != 4 && stride != 8 {
                return Err(MeshoptError::Stride {
                    what: "OCTAHEDRAL filter",
                    expected: "of 4 or 8",
                    stride,
                });
            }
            unsafe { ::meshopt::ffi::meshopt_decodeFilterOct(out.as_mut_ptr().cast(), count, stride) }
        }
        "QUATERNION" => {
            if stride != 8 {
                return Err(MeshoptError::Stride { what: "QUATERNION filter", expected: "of 8", stride });
            }
            unsafe { ::meshopt::ffi::meshopt_decodeFilterQuat(out.as_mut_ptr().cast(), count, stride) }
        }
        "EXPONENTIAL" => {
            if stride % 4 != 0 {
                return Err(MeshoptError::Stride {
                    what: "EXPONENTIAL filter",
                    expected: "that is a multiple of 4",
                    stride,
                });
            }
            unsafe { ::meshopt::ffi::meshopt_decodeFilterExp(out.as_mut_ptr().cast(), count, stride) }
        }
        other => return Err(MeshoptError::UnknownFilter { filter: other.to_string() }),
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn broken_preconditions_and_garbage_are_errors() {
        let e = |mode: &str, count, stride| MeshoptView {
            buffer: 0,
            byte_offset: 0,
            byte_length: 0,
            byte_stride: stride,
            count,
            mode: mode.into(),
            filter: None,
        };
        let msg =
            |mode: &str, count, stride, source: &[u8]| decode(&e(mode, count, stride), source).unwrap_err();
        let err = msg("ATTRIBUTES", 4, 6, &[0; 10]);
        assert!(matches!(err, MeshoptError::Stride { what: "ATTRIBUTES mode", stride: 6, .. }), "{err:?}");
        assert!(err.to_string().contains("multiple of 4"), "{err}");
        let err = msg("TRIANGLES", 4, 4, &[0; 10]);
        assert_eq!(err, MeshoptError::TriangleCount { count: 4 });
        assert!(err.to_string().contains("multiple of 3"), "{err}");
        let err = msg("TRIANGLES", 3, 3, &[0; 10]);
        assert!(err.to_string().contains("2 or 4"), "{err}");
        let err = msg("ATTRIBUTES", 4, 8, b"garbage!");
        assert!(matches!(err, MeshoptError::Corrupt { mode: "ATTRIBUTES", .. }), "{err:?}");
        assert!(err.to_string().contains("corrupt"), "{err}");
        let err = msg("POINTS", 4, 8, b"");
        assert!(err.to_string().contains("POINTS"), "{err}");
        let err = msg("ATTRIBUTES", usize::MAX / 2, 8, b"");
        assert!(matches!(err, MeshoptError::TooLarge { stride: 8, .. }), "{err:?}");
        assert!(err.to_string().contains("exceeds"), "{err}");
    }
}
