//! `KHR_draco_mesh_compression`: decoding a Draco mesh with the pure-Rust `draco-core` decoder.
//!
//! The extension names Draco attributes by their *unique id* (`attributes: {"POSITION": 0,
//! "_BATCHID": 2}`), not by their position in the decoded attribute list; values are read per point
//! through the attribute's point → value mapping. Quantised positions come out dequantised.

use draco_core::{DecoderBuffer, Mesh, MeshDecoder};

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
/// A message when the bitstream is invalid, is a point cloud, or lacks one of the attributes.
pub(crate) fn decode(
    bytes: &[u8],
    position_id: u32,
    wanted: &[(u32, usize)],
) -> Result<DecodedDraco, String> {
    // The decoder is memory-safe Rust but third-party; a panic on a hostile bitstream must become an
    // error naming the file rather than abort a whole run.
    let mesh = std::panic::catch_unwind(|| {
        let mut buffer = DecoderBuffer::new(bytes);
        let mut mesh = Mesh::new();
        MeshDecoder::new().decode(&mut buffer, &mut mesh).map(|()| mesh)
    })
    .map_err(|_| "the Draco decoder failed on this bitstream (panicked)".to_string())?
    .map_err(|e| format!("cannot decode the Draco bitstream: {e}"))?;

    let n_points = mesh.num_points();
    if mesh.num_faces() == 0 {
        return Err("the Draco bitstream holds no triangles (a point cloud?)".into());
    }
    let pos = mesh
        .attribute_by_unique_id(position_id)
        .ok_or_else(|| format!("the Draco mesh has no attribute with unique id {position_id} (POSITION)"))?;
    if pos.num_components() < 3 {
        return Err(format!("the Draco POSITION attribute has {} components, not 3", pos.num_components()));
    }
    let positions =
        pos.read_f32s(n_points, 3).chunks_exact(3).map(|c| [c[0] as f64, c[1] as f64, c[2] as f64]).collect();
    let mut attributes = Vec::with_capacity(wanted.len());
    for &(id, n) in wanted {
        let att = mesh
            .attribute_by_unique_id(id)
            .ok_or_else(|| format!("the Draco mesh has no attribute with unique id {id}"))?;
        if (att.num_components() as usize) < n {
            return Err(format!("the Draco attribute {id} has {} components, not {n}", att.num_components()));
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
        assert!(decode(b"DRACO\x02\x02\x01\x01\x00\x00", 0, &[]).is_err());
        assert!(decode(b"not draco at all", 0, &[]).is_err());
        assert!(decode(&[], 0, &[]).is_err());
    }
}
