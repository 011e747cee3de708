//! Reading the instance-ID maps written by `render-masks` (`masks/<frame>.png`).
//!
//! An ID map is a lossless 8-bit RGB PNG; the building ID of a pixel is `R << 16 | G << 8 | B`
//! (0 = background). RGBA with 8 bits per channel is accepted too (alpha ignored). Anything else —
//! palette, grey, 16-bit, other bit depths — is rejected with the colour type found, because it
//! cannot hold 24-bit IDs losslessly.

use std::path::Path;

use super::CocoError;

/// A decoded instance-ID map.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct IdMap {
    pub width: u32,
    pub height: u32,
    /// Building ID per pixel, row-major, top row first.
    pub ids: Vec<u32>,
}

/// Reads and decodes the ID map at `path`.
///
/// # Errors
/// [`CocoError::File`] when it cannot be read, [`CocoError::PngDecode`] for a broken PNG,
/// [`CocoError::IdMap`] for a PNG that is not 8-bit RGB/RGBA.
pub fn read_id_png(path: &Path) -> Result<IdMap, CocoError> {
    let bytes = crate::util::read_file(path)?;
    decode_id_png(&bytes, path)
}

/// Decodes an ID map from PNG bytes; `path` only names the source in errors.
///
/// # Errors
/// As [`read_id_png`].
pub fn decode_id_png(bytes: &[u8], path: &Path) -> Result<IdMap, CocoError> {
    let dec_err = |source| CocoError::PngDecode { path: path.to_path_buf(), source };
    let mut decoder = png::Decoder::new(std::io::Cursor::new(bytes));
    decoder.set_transformations(png::Transformations::IDENTITY);
    let mut reader = decoder.read_info().map_err(dec_err)?;
    let (color, depth) = reader.output_color_type();
    let channels = match (color, depth) {
        (png::ColorType::Rgb, png::BitDepth::Eight) => 3,
        (png::ColorType::Rgba, png::BitDepth::Eight) => 4,
        _ => {
            return Err(CocoError::IdMap {
                path: path.to_path_buf(),
                reason: format!(
                    "ID maps must be 8-bit RGB (R<<16 | G<<8 | B); this PNG is {color:?} with {} bits per \
                     sample",
                    depth as u8
                ),
            })
        }
    };
    let mut buf = vec![0u8; reader.output_buffer_size()];
    let info = reader.next_frame(&mut buf).map_err(dec_err)?;
    let (w, h) = (info.width as usize, info.height as usize);
    let mut ids = Vec::with_capacity(w * h);
    for y in 0..h {
        let row = &buf[y * info.line_size..y * info.line_size + w * channels];
        ids.extend(
            row.chunks_exact(channels).map(|p| (p[0] as u32) << 16 | (p[1] as u32) << 8 | p[2] as u32),
        );
    }
    Ok(IdMap { width: info.width, height: info.height, ids })
}

/// Encodes an ID map as an 8-bit RGB PNG (used by the tests and by tools that fabricate ID maps).
///
/// # Errors
/// [`CocoError::IdMap`] for IDs above 2²⁴ − 1 or a buffer of the wrong size, [`CocoError::PngEncode`]
/// if the encoder fails; `path` only names the target in errors.
pub fn encode_id_png(map: &IdMap, path: &Path) -> Result<Vec<u8>, CocoError> {
    if map.ids.len() != map.width as usize * map.height as usize {
        return Err(CocoError::IdMap {
            path: path.to_path_buf(),
            reason: format!("{} IDs for a {}×{} map", map.ids.len(), map.width, map.height),
        });
    }
    if let Some(&bad) = map.ids.iter().find(|&&id| id > 0xff_ffff) {
        return Err(CocoError::IdMap {
            path: path.to_path_buf(),
            reason: format!("ID {bad} does not fit in 24 bits"),
        });
    }
    let rgb: Vec<u8> = map.ids.iter().flat_map(|&id| [(id >> 16) as u8, (id >> 8) as u8, id as u8]).collect();
    super::raster::encode_png_rgb(&rgb, map.width, map.height, path)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn all_three_channels_round_trip() {
        let map = IdMap { width: 3, height: 2, ids: vec![0, 1, 0xff, 0x100, 0x1_0000, 0xff_ffff] };
        let bytes = encode_id_png(&map, Path::new("t.png")).unwrap();
        assert_eq!(decode_id_png(&bytes, Path::new("t.png")).unwrap(), map);
    }

    #[test]
    fn grey_png_is_rejected_with_its_colour_type() {
        let mut bytes = Vec::new();
        {
            let mut enc = png::Encoder::new(&mut bytes, 2, 2);
            enc.set_color(png::ColorType::Grayscale);
            enc.set_depth(png::BitDepth::Eight);
            let mut w = enc.write_header().unwrap();
            w.write_image_data(&[0, 1, 2, 3]).unwrap();
        }
        let err = decode_id_png(&bytes, Path::new("masks/f.png")).unwrap_err().to_string();
        assert!(err.contains("masks/f.png") && err.contains("Grayscale"), "{err}");
    }

    #[test]
    fn id_above_24_bits_is_an_error() {
        let map = IdMap { width: 1, height: 1, ids: vec![1 << 24] };
        assert!(encode_id_png(&map, Path::new("x.png")).is_err());
    }
}
