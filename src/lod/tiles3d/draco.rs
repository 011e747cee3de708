//! `KHR_draco_mesh_compression`: decoding a Draco mesh with the pure-Rust `draco-core` decoder.
//!
//! The extension names Draco attributes by their *unique id* (`attributes: {"POSITION": 0,
//! "_BATCHID": 2}`), not by their position in the decoded attribute list; values are read per point
//! through the attribute's point → value mapping. Quantised positions come out dequantised.

use draco_core::{DecoderBuffer, Mesh, MeshDecoder};

use super::error::DracoMeshError;

/// A decoded Draco mesh: positions, triangles, and the other requested attributes per point.
#[derive(Debug)]
pub(crate) struct DecodedDraco {
    pub positions: Vec<[f64; 3]>,
    pub triangles: Vec<[u32; 3]>,
    /// The requested attributes (e.g. `_BATCHID`, `TEXCOORD_0`), `components` values per point.
    pub attributes: Vec<Vec<f64>>,
}

/// Decodes `bytes` and extracts the position attribute (`position_id`) and the attributes asked
/// for as (unique id, components), all by Draco unique id.
///
/// # Errors
/// [`DracoMeshError`] when the bitstream is invalid (the decoder's error as the source), is a point
/// cloud, or lacks one of the attributes or components.
pub(crate) fn decode(
    bytes: &[u8],
    position_id: u32,
    wanted: &[(u32, usize)],
) -> Result<DecodedDraco, DracoMeshError> {
    // The decoder is memory-safe Rust but third-party; a panic on a hostile bitstream must become an
    // error naming the file rather than abort a whole run.
    let mesh = std::panic::catch_unwind(|| {
        let mut buffer = DecoderBuffer::new(bytes);
        let mut mesh = Mesh::new();
        MeshDecoder::new().decode(&mut buffer, &mut mesh).map(|()| mesh)
    })
    .map_err(|_| DracoMeshError::Panicked)?
    .map_err(DracoMeshError::Decode)?;

    let n_points = mesh.num_points();
    if mesh.num_faces() == 0 {
        return Err(DracoMeshError::PointCloud);
    }
    let pos = mesh
        .attribute_by_unique_id(position_id)
        .ok_or(DracoMeshError::NoAttribute { id: position_id, position: true })?;
    if pos.num_components() < 3 {
        return Err(DracoMeshError::Components {
            id: position_id,
            position: true,
            found: pos.num_components() as usize,
            needed: 3,
        });
    }
    let positions =
        pos.read_f32s(n_points, 3).chunks_exact(3).map(|c| [c[0] as f64, c[1] as f64, c[2] as f64]).collect();
    let mut attributes = Vec::with_capacity(wanted.len());
    for &(id, n) in wanted {
        let att =
            mesh.attribute_by_unique_id(id).ok_or(DracoMeshError::NoAttribute { id, position: false })?;
        if (att.num_components() as usize) < n {
            return Err(DracoMeshError::Components {
                id,
                position: false,
                found: att.num_components() as usize,
                needed: n,
            });
        }
        attributes.push(att.read_f32s(n_points, n).into_iter().map(f64::from).collect());
    }
    let triangles = mesh.faces().iter().map(|f| [f[0].0, f[1].0, f[2].0]).collect();
    Ok(DecodedDraco { positions, triangles, attributes })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn garbage_is_an_error_not_a_panic() {
        for bytes in [&b"DRACO\x02\x02\x01\x01\x00\x00"[..], b"not draco at all", &[]] {
            let e = decode(bytes, 0, &[]).unwrap_err();
            // The decoder's own error is kept as the cause.
            assert!(matches!(e, DracoMeshError::Decode(_)), "{e:?}");
            assert!(std::error::Error::source(&e).is_some());
        }
    }
}
