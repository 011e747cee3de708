//! Lossless 24-bit ID maps as RGB PNG: R = bits 16–23, G = bits 8–15, B = bits 0–7 of the building ID
//! (0 = background). Never JPEG, never palette-reduced: decoding gives back exactly the IDs rendered.
//!
//! Encoding uses the png crate's `Fast` deflate level with the `Sub` filter: ID maps are long runs of
//! equal pixels, which `Sub` turns into zeros, so the fast level compresses them well (a 1920×1080 map of
//! a dense city is typically 50–150 kB) at several hundred MB/s.

use std::io::Cursor;
use std::path::{Path, PathBuf};

use crate::scene::MAX_BUILDING_ID;
use crate::util::FileError;

/// Errors of ID-PNG encoding and decoding.
#[derive(Debug, thiserror::Error)]
pub enum IdPngError {
    #[error(transparent)]
    File(#[from] FileError),
    /// An ID does not fit in 24 bits (a caller bug or a corrupt render).
    #[error("pixel {index} holds ID {id}, which does not fit the 24-bit ID map (max {MAX_BUILDING_ID})")]
    IdTooLarge { index: usize, id: u32 },
    /// The buffer does not match the stated size.
    #[error("ID buffer of {len} pixels does not match {width}×{height}")]
    SizeMismatch { len: usize, width: u32, height: u32 },
    #[error("encoding the ID PNG failed")]
    Encode(#[source] png::EncodingError),
    /// The file is not a PNG or is truncated.
    #[error("{}: not a readable PNG", path.display())]
    Decode {
        path: PathBuf,
        #[source]
        source: png::DecodingError,
    },
    /// The PNG is valid but is not a 24-bit RGB ID map.
    #[error("{}: expected an 8-bit RGB ID map, found {what}", path.display())]
    NotAnIdMap { path: PathBuf, what: String },
}

/// The RGB bytes of one ID.
pub fn id_to_rgb(id: u32) -> [u8; 3] {
    [(id >> 16) as u8, (id >> 8) as u8, id as u8]
}

/// The ID of one RGB pixel.
pub fn rgb_to_id(rgb: [u8; 3]) -> u32 {
    (rgb[0] as u32) << 16 | (rgb[1] as u32) << 8 | rgb[2] as u32
}

/// Encodes a row-major ID map as an RGB PNG in memory.
///
/// # Errors
/// [`IdPngError::SizeMismatch`], [`IdPngError::IdTooLarge`] or [`IdPngError::Encode`].
pub fn encode_id_png(ids: &[u32], width: u32, height: u32) -> Result<Vec<u8>, IdPngError> {
    if ids.len() != width as usize * height as usize || width == 0 || height == 0 {
        return Err(IdPngError::SizeMismatch { len: ids.len(), width, height });
    }
    let mut rgb = Vec::with_capacity(ids.len() * 3);
    for (index, &id) in ids.iter().enumerate() {
        if id > MAX_BUILDING_ID {
            return Err(IdPngError::IdTooLarge { index, id });
        }
        rgb.extend_from_slice(&id_to_rgb(id));
    }
    let mut out = Vec::with_capacity(ids.len() / 16 + 1024);
    {
        let mut encoder = png::Encoder::new(Cursor::new(&mut out), width, height);
        encoder.set_color(png::ColorType::Rgb);
        encoder.set_depth(png::BitDepth::Eight);
        encoder.set_compression(png::Compression::Fast);
        encoder.set_filter(png::FilterType::Sub);
        let mut writer = encoder.write_header().map_err(IdPngError::Encode)?;
        writer.write_image_data(&rgb).map_err(IdPngError::Encode)?;
        writer.finish().map_err(IdPngError::Encode)?;
    }
    Ok(out)
}

/// Encodes and writes an ID map atomically.
///
/// # Errors
/// As [`encode_id_png`], plus [`IdPngError::File`] naming `path`.
pub fn write_id_png(path: &Path, ids: &[u32], width: u32, height: u32) -> Result<(), IdPngError> {
    let bytes = encode_id_png(ids, width, height)?;
    crate::util::write_bytes_atomic(path, &bytes)?;
    Ok(())
}

/// A decoded ID map.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct IdMap {
    /// Width, pixels.
    pub width: u32,
    /// Height, pixels.
    pub height: u32,
    /// Row-major building IDs (0 = background).
    pub ids: Vec<u32>,
}

fn reader<R: std::io::Read>(path: &Path, source: R) -> Result<png::Reader<R>, IdPngError> {
    let decoder = png::Decoder::new(source);
    let reader =
        decoder.read_info().map_err(|source| IdPngError::Decode { path: path.to_path_buf(), source })?;
    let info = reader.info();
    if info.color_type != png::ColorType::Rgb || info.bit_depth != png::BitDepth::Eight {
        return Err(IdPngError::NotAnIdMap {
            path: path.to_path_buf(),
            what: format!("{:?} at {:?} bits", info.color_type, info.bit_depth),
        });
    }
    Ok(reader)
}

/// The last 12 bytes of every complete PNG: the empty IEND chunk with its CRC.
const IEND: [u8; 12] = [0, 0, 0, 0, b'I', b'E', b'N', b'D', 0xAE, 0x42, 0x60, 0x82];

/// Checks an existing ID PNG cheaply, for resuming: the header (up to the first image data) must decode
/// as 8-bit RGB and the file must end with the IEND chunk. Returns (width, height).
///
/// # Errors
/// [`IdPngError::File`], [`IdPngError::Decode`] or [`IdPngError::NotAnIdMap`], naming `path`.
pub fn read_id_png_size(path: &Path) -> Result<(u32, u32), IdPngError> {
    use std::io::{Read, Seek, SeekFrom};
    let mut file = std::fs::File::open(path).map_err(|e| FileError::new("opening", path, e))?;
    let mut tail = [0u8; 12];
    file.seek(SeekFrom::End(-12))
        .and_then(|_| file.read_exact(&mut tail))
        .and_then(|_| file.seek(SeekFrom::Start(0)))
        .map_err(|e| FileError::new("reading", path, e))?;
    if tail != IEND {
        return Err(IdPngError::NotAnIdMap {
            path: path.to_path_buf(),
            what: "a truncated file (no IEND chunk)".into(),
        });
    }
    let r = reader(path, std::io::BufReader::new(file))?;
    Ok((r.info().width, r.info().height))
}

/// Decodes an ID PNG from bytes (`path` only names it in errors).
///
/// # Errors
/// [`IdPngError::Decode`] or [`IdPngError::NotAnIdMap`].
pub fn decode_id_png(path: &Path, bytes: &[u8]) -> Result<IdMap, IdPngError> {
    let mut r = reader(path, Cursor::new(bytes))?;
    let mut buf = vec![0u8; r.output_buffer_size()];
    let frame =
        r.next_frame(&mut buf).map_err(|source| IdPngError::Decode { path: path.to_path_buf(), source })?;
    let ids = buf[..frame.buffer_size()].chunks_exact(3).map(|p| rgb_to_id([p[0], p[1], p[2]])).collect();
    Ok(IdMap { width: frame.width, height: frame.height, ids })
}

/// Reads and decodes an ID PNG.
///
/// # Errors
/// As [`decode_id_png`], plus [`IdPngError::File`].
pub fn read_id_png(path: &Path) -> Result<IdMap, IdPngError> {
    let bytes = crate::util::read_file(path)?;
    decode_id_png(path, &bytes)
}

#[cfg(test)]
mod tests {
    use super::*;

    mod channels {
        use super::*;

        #[test]
        fn red_is_the_high_byte() {
            // 0x12_34_56: R = 0x12 (bits 16–23), G = 0x34, B = 0x56 (SPEC.md).
            assert_eq!(id_to_rgb(0x12_34_56), [0x12, 0x34, 0x56]);
            assert_eq!(rgb_to_id([0x12, 0x34, 0x56]), 0x12_34_56);
            assert_eq!(rgb_to_id(id_to_rgb(MAX_BUILDING_ID)), MAX_BUILDING_ID);
        }
    }

    mod round_trip {
        use super::*;

        #[test]
        fn ids_survive_encode_decode_exactly() {
            let (w, h) = (37u32, 23u32);
            // IDs exercising all three bytes, including values whose red byte alone differs.
            let ids: Vec<u32> = (0..w * h)
                .map(|i| if i % 7 == 0 { 0 } else { i.wrapping_mul(2_654_435_761u32) & MAX_BUILDING_ID })
                .collect();
            let bytes = encode_id_png(&ids, w, h).unwrap();
            let back = decode_id_png(Path::new("mem.png"), &bytes).unwrap();
            assert_eq!((back.width, back.height), (w, h));
            assert_eq!(back.ids, ids);
        }

        #[test]
        fn encoding_is_deterministic() {
            let ids: Vec<u32> = (0..64 * 48).map(|i| (i / 100) as u32).collect();
            assert_eq!(encode_id_png(&ids, 64, 48).unwrap(), encode_id_png(&ids, 64, 48).unwrap());
        }

        #[test]
        fn header_size_is_read_from_the_file() {
            let dir = tempfile::tempdir().unwrap();
            let p = dir.path().join("a.png");
            write_id_png(&p, &vec![5; 300 * 200], 300, 200).unwrap();
            assert_eq!(read_id_png_size(&p).unwrap(), (300, 200));
        }
    }

    mod errors {
        use super::*;

        #[test]
        fn rejects_ids_above_24_bits() {
            let e = encode_id_png(&[1, 1 << 24], 2, 1).unwrap_err();
            assert!(matches!(e, IdPngError::IdTooLarge { index: 1, id: 16_777_216 }), "{e}");
        }

        #[test]
        fn rejects_size_mismatch() {
            assert!(matches!(encode_id_png(&[1, 2, 3], 2, 2), Err(IdPngError::SizeMismatch { .. })));
        }

        #[test]
        fn truncated_file_names_the_path() {
            let bytes = encode_id_png(&vec![3; 100], 10, 10).unwrap();
            let e = decode_id_png(Path::new("x/frame.png"), &bytes[..bytes.len() / 2]).unwrap_err();
            assert!(e.to_string().contains("x/frame.png"), "{e}");
        }

        #[test]
        fn rgba_png_is_not_an_id_map() {
            let mut out = Vec::new();
            {
                let mut enc = png::Encoder::new(&mut out, 1, 1);
                enc.set_color(png::ColorType::Rgba);
                let mut w = enc.write_header().unwrap();
                w.write_image_data(&[1, 2, 3, 4]).unwrap();
            }
            let e = decode_id_png(Path::new("rgba.png"), &out).unwrap_err();
            assert!(e.to_string().contains("expected an 8-bit RGB ID map"), "{e}");
        }
    }
}
