//! The geometry encoders of the 3D Tiles writers: Draco (`KHR_draco_mesh_compression`, with the
//! pure-Rust `draco-core` encoder) and meshoptimizer (`EXT_meshopt_compression`, with the `meshopt`
//! crate). Their decoders are the reader's ([`crate::lod::tiles3d`]); `lod/` only reads.

use super::city_tileset::WriteError;
use crate::util::glb::floats;

/// Draco-encodes a triangle soup: POSITION (unique id 0, 16-bit quantised), TEXCOORD_0 (id 1,
/// 14-bit) and, if given, `_FEATURE_ID_0` (id 2, not quantised, so IDs stay exact). Returns the
/// bitstream, the decoded point count, and the feature-ID attribute's unique id.
pub(crate) fn draco_mesh(
    pos: &[[f32; 3]],
    uv: &[[f32; 2]],
    ids: Option<&[f32]>,
    indices: &[u32],
) -> Result<(Vec<u8>, usize, Option<u32>), WriteError> {
    use draco_core::draco_types::DataType;
    use draco_core::geometry_attribute::{GeometryAttributeType, PointAttribute};
    use draco_core::geometry_indices::{FaceIndex, PointIndex};
    let err = |what, e: draco_core::DracoError| WriteError::Encode { what, source: Box::new(e) };
    let n = pos.len();
    let mut mesh = draco_core::mesh::Mesh::new();
    mesh.set_num_points(n);
    let mut add = |kind, comps: u8, data: Vec<u8>| {
        let mut a = PointAttribute::new();
        a.init(kind, comps, DataType::Float32, false, n);
        a.buffer_mut().write(0, &data);
        mesh.add_attribute(a)
    };
    add(GeometryAttributeType::Position, 3, floats(pos.iter().flatten()));
    add(GeometryAttributeType::TexCoord, 2, floats(uv.iter().flatten()));
    let fid = ids.map(|v| add(GeometryAttributeType::Generic, 1, floats(v.iter())) as u32);
    mesh.set_num_faces(indices.len() / 3);
    for (f, t) in indices.chunks_exact(3).enumerate() {
        mesh.set_face(FaceIndex(f as u32), [PointIndex(t[0]), PointIndex(t[1]), PointIndex(t[2])]);
    }
    let mut options = draco_core::EncoderOptions::new();
    options.set_attribute_quantization(0, 16);
    options.set_attribute_quantization(1, 14);
    let mut enc = draco_core::mesh_encoder::MeshEncoder::new();
    enc.set_mesh(mesh);
    let mut buf = draco_core::encoder_buffer::EncoderBuffer::new();
    enc.encode(&options, &mut buf).map_err(|e| err("a Draco mesh", e))?;
    let bytes = buf.data().to_vec();
    // The point count the decoder will produce (the encoder may merge or split points).
    let mut d = draco_core::mesh::Mesh::new();
    draco_core::MeshDecoder::new()
        .decode(&mut draco_core::DecoderBuffer::new(&bytes), &mut d)
        .map_err(|e| err("a Draco mesh (decoding the encoded mesh back)", e))?;
    Ok((bytes, d.num_points(), fid))
}

/// Encodes vertex data for an `ATTRIBUTES` view (codec version 0, which `EXT_meshopt_compression`
/// requires), `stride` bytes per element.
pub(crate) fn meshopt_attributes(data: &[u8], stride: usize) -> Vec<u8> {
    let count = data.len() / stride;
    // SAFETY: the bound is the encoder's worst case for count × stride; `data` holds that many bytes.
    unsafe {
        let bound = ::meshopt::ffi::meshopt_encodeVertexBufferBound(count, stride);
        let mut out = vec![0u8; bound];
        let n = ::meshopt::ffi::meshopt_encodeVertexBufferLevel(
            out.as_mut_ptr(),
            out.len(),
            data.as_ptr().cast(),
            count,
            stride,
            2,
            0,
        );
        out.truncate(n);
        out
    }
}

/// Encodes a triangle index list for a `TRIANGLES` view (4-byte indices).
pub(crate) fn meshopt_triangles(indices: &[u32], vertex_count: usize) -> Vec<u8> {
    // The index codec's version 1 is what every decoder since meshoptimizer 0.14 reads, and what
    // EXT_meshopt_compression allows.
    ::meshopt::encoding::encode_index_buffer(indices, vertex_count).expect("encoding a valid index list")
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::lod::tiles3d::meshopt::{decode, MeshoptView};

    #[test]
    fn attributes_and_triangles_round_trip() {
        let verts: Vec<u8> =
            (0..40u32).flat_map(|i| [(i * 7) as u16, (i * 3) as u16]).flat_map(u16::to_le_bytes).collect();
        let enc = meshopt_attributes(&verts, 4);
        let ext = |mode: &str, count, stride, len| MeshoptView {
            buffer: 0,
            byte_offset: 0,
            byte_length: len,
            byte_stride: stride,
            count,
            mode: mode.into(),
            filter: None,
        };
        assert_eq!(decode(&ext("ATTRIBUTES", 40, 4, enc.len()), &enc).unwrap(), verts);
        let idx: Vec<u32> = vec![0, 1, 2, 2, 1, 3, 3, 1, 4];
        let enc = meshopt_triangles(&idx, 5);
        let out = decode(&ext("TRIANGLES", 9, 4, enc.len()), &enc).unwrap();
        let back: Vec<u32> = out.chunks_exact(4).map(|c| u32::from_le_bytes(c.try_into().unwrap())).collect();
        assert_eq!(back, idx);
    }
}
