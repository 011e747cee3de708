//! Building instance IDs and the frames that hold them.
//!
//! Every building of an area gets one 24-bit ID, 1 … 2²⁴ − 1 ([`BuildingId`]); 0 is the background. The
//! cap is the instance map's: an ID map stores one ID per pixel losslessly as 8-bit RGB, R = bits 16–23,
//! G = bits 8–15, B = bits 0–7 (SPEC.md, "Instancing"), and Blender's ID render stores it in a float32
//! channel, which holds every integer up to 2²⁴ exactly. This module owns that rule: a [`BuildingId`] can
//! only be built through a check against it, and [`IdMap`] is the one image-of-IDs type the renderers
//! produce and the later stages (labels, COCO, Blender's alignment check, the localizer) read.
//!
//! The ID model lives here, with instancing, rather than in `label/`: the renderers (an earlier stage)
//! produce ID maps, and data only flows forward.
//!
//! # File formats
//! - PNG ([`IdMap::encode_png`], [`IdMap::decode_png`]): 8-bit RGB, nothing else — grey, palette,
//!   16-bit and RGBA files are refused with the colour type found, so an ID map is never silently
//!   reinterpreted. Written with the `Fast` deflate level and the `Sub` filter: ID maps are long runs of
//!   equal pixels, which `Sub` turns into zeros (a dense 1920×1080 map is typically 50–150 kB).
//! - EXR ([`IdMap::read_exr`]): the float32 `R` channel of Blender's ID render; every value must be an
//!   integer in 0 ..= 2²⁴ − 1.

use std::io::Cursor;
use std::path::{Path, PathBuf};

use bytemuck::{TransparentWrapper, TransparentWrapperAlloc};
use serde::{Deserialize, Serialize};

use crate::util::FileError;

/// A building's instance ID: 0 (background) or 1 ..= [`BuildingId::MAX`].
#[derive(
    Debug,
    Clone,
    Copy,
    PartialEq,
    Eq,
    PartialOrd,
    Ord,
    Hash,
    Default,
    Serialize,
    Deserialize,
    TransparentWrapper,
)]
#[repr(transparent)]
#[serde(try_from = "u32", into = "u32")]
pub struct BuildingId(u32);

/// Largest building ID that fits the 24-bit instance maps, as a plain integer.
pub const MAX_BUILDING_ID: u32 = (1 << 24) - 1;

impl BuildingId {
    /// The background (no building).
    pub const BACKGROUND: BuildingId = BuildingId(0);
    /// The largest ID: 2²⁴ − 1.
    pub const MAX: BuildingId = BuildingId(MAX_BUILDING_ID);

    /// The ID `id`, or an error when it does not fit in 24 bits.
    ///
    /// # Errors
    /// [`IdError::TooLarge`] (with pixel index 0) for `id` > 2²⁴ − 1.
    pub fn new(id: u32) -> Result<BuildingId, IdError> {
        if id > MAX_BUILDING_ID {
            return Err(IdError::TooLarge { index: 0, id });
        }
        Ok(BuildingId(id))
    }

    /// The ID of the building at position `index` (0-based) of an area's sorted building list, which
    /// numbers buildings from 1.
    ///
    /// # Errors
    /// [`IdError::TooManyBuildings`] when the area has more buildings than the ID space.
    pub fn from_index(index: usize) -> Result<BuildingId, IdError> {
        match u32::try_from(index + 1) {
            Ok(id) if id <= MAX_BUILDING_ID => Ok(BuildingId(id)),
            _ => Err(IdError::TooManyBuildings { count: index as u64 + 1 }),
        }
    }

    /// The ID as an integer.
    pub fn get(self) -> u32 {
        self.0
    }

    /// Whether this is the background (0).
    pub fn is_background(self) -> bool {
        self.0 == 0
    }

    /// The RGB bytes of the ID in an ID map: R = bits 16–23, G = bits 8–15, B = bits 0–7.
    pub fn to_rgb(self) -> [u8; 3] {
        [(self.0 >> 16) as u8, (self.0 >> 8) as u8, self.0 as u8]
    }

    /// The ID of one ID-map pixel (any three bytes are a valid ID).
    pub fn from_rgb(rgb: [u8; 3]) -> BuildingId {
        BuildingId((rgb[0] as u32) << 16 | (rgb[1] as u32) << 8 | rgb[2] as u32)
    }
}

impl TryFrom<u32> for BuildingId {
    type Error = IdError;

    fn try_from(id: u32) -> Result<Self, IdError> {
        BuildingId::new(id)
    }
}

impl From<BuildingId> for u32 {
    fn from(id: BuildingId) -> u32 {
        id.0
    }
}

/// An ID equals the plain integer it holds (`id == 3`).
impl PartialEq<u32> for BuildingId {
    fn eq(&self, other: &u32) -> bool {
        self.0 == *other
    }
}

impl std::fmt::Display for BuildingId {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        self.0.fmt(f)
    }
}

/// Errors of building IDs and ID maps.
#[derive(Debug, thiserror::Error)]
pub enum IdError {
    /// A file could not be read or written.
    #[error(transparent)]
    File(#[from] FileError),
    /// An ID does not fit in 24 bits (a caller bug or a corrupt render).
    #[error("pixel {index} holds ID {id}, which does not fit the 24-bit ID map (max {MAX_BUILDING_ID})")]
    TooLarge {
        /// Pixel index (row-major).
        index: usize,
        /// The ID found.
        id: u32,
    },
    /// More buildings than 24-bit IDs.
    #[error(
        "{count} buildings exceed the 24-bit instance ID space (at most {MAX_BUILDING_ID}); split the area into \
         smaller ones"
    )]
    TooManyBuildings {
        /// Number of buildings.
        count: u64,
    },
    /// The pixel buffer does not match the stated size.
    #[error("ID buffer of {len} pixels does not match {width}×{height}")]
    SizeMismatch {
        /// Pixels in the buffer.
        len: usize,
        /// Width stated, pixels.
        width: u32,
        /// Height stated, pixels.
        height: u32,
    },
    /// The PNG encoder failed.
    #[error("encoding the ID PNG failed")]
    PngEncode(#[source] png::EncodingError),
    /// The file is not a PNG or is truncated.
    #[error("{}: not a readable PNG", path.display())]
    PngDecode {
        /// The file.
        path: PathBuf,
        /// The PNG decoder's error.
        #[source]
        source: png::DecodingError,
    },
    /// The PNG is valid but is not a 24-bit RGB ID map.
    #[error(
        "{}: expected an 8-bit RGB ID map (R<<16 | G<<8 | B), found {}",
        path.display(),
        match (color, bit_depth) {
            (Some(c), Some(b)) => format!("{c:?} with {} bits per sample", *b as u8),
            _ => "a truncated file (no IEND chunk)".to_string(),
        }
    )]
    NotAnIdMap {
        /// The file.
        path: PathBuf,
        /// Its colour type (`None`: the file is truncated).
        color: Option<png::ColorType>,
        /// Its bit depth (`None`: the file is truncated).
        bit_depth: Option<png::BitDepth>,
    },
    /// The EXR cannot be read.
    #[error("{}: not a readable EXR", path.display())]
    ExrDecode {
        /// The file.
        path: PathBuf,
        /// The EXR decoder's error.
        #[source]
        source: exr::error::Error,
    },
    /// The EXR is readable but does not hold IDs in a float32 `R` channel.
    #[error("{}: {problem}", path.display())]
    NotAnIdExr {
        /// The file.
        path: PathBuf,
        /// What is wrong with it.
        problem: ExrIdProblem,
    },
}

/// Why an EXR is not an ID render (see [`IdError::NotAnIdExr`]).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ExrIdProblem {
    /// No `R` channel.
    #[error("no R channel")]
    NoR,
    /// The `R` channel is not float32.
    #[error("the R channel is not float32 (IDs above 2048 need float32)")]
    NotF32,
    /// A pixel that is not a building ID.
    #[error("pixel ({x}, {y}) holds {value}, not a building ID")]
    Value {
        /// Column.
        x: usize,
        /// Row.
        y: usize,
        /// The value.
        value: f32,
    },
}

/// A frame of building IDs: row-major from the top-left pixel, [`BuildingId::BACKGROUND`] where no
/// building is seen.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct IdMap {
    width: u32,
    height: u32,
    ids: Vec<BuildingId>,
}

/// The last 12 bytes of every complete PNG: the empty IEND chunk with its CRC.
const IEND: [u8; 12] = [0, 0, 0, 0, b'I', b'E', b'N', b'D', 0xAE, 0x42, 0x60, 0x82];

impl IdMap {
    /// A map of `ids`, `width × height`, row-major.
    ///
    /// # Errors
    /// [`IdError::SizeMismatch`] when `ids` does not hold `width × height` pixels.
    pub fn new(width: u32, height: u32, ids: Vec<BuildingId>) -> Result<IdMap, IdError> {
        if ids.len() != width as usize * height as usize {
            return Err(IdError::SizeMismatch { len: ids.len(), width, height });
        }
        Ok(IdMap { width, height, ids })
    }

    /// A map of plain integers (a renderer's read-back, a test's hand-made frame), checking the 24-bit
    /// cap of every pixel. The buffer is reused, not copied.
    ///
    /// # Errors
    /// [`IdError::SizeMismatch`], or [`IdError::TooLarge`] naming the first pixel above 2²⁴ − 1.
    pub fn from_raw(width: u32, height: u32, ids: Vec<u32>) -> Result<IdMap, IdError> {
        if let Some((index, &id)) = ids.iter().enumerate().find(|(_, &id)| id > MAX_BUILDING_ID) {
            return Err(IdError::TooLarge { index, id });
        }
        IdMap::new(width, height, BuildingId::wrap_vec(ids))
    }

    /// An all-background map.
    pub fn background(width: u32, height: u32) -> IdMap {
        IdMap { width, height, ids: vec![BuildingId::BACKGROUND; width as usize * height as usize] }
    }

    /// Width, pixels.
    pub fn width(&self) -> u32 {
        self.width
    }

    /// Height, pixels.
    pub fn height(&self) -> u32 {
        self.height
    }

    /// The IDs, row-major.
    pub fn ids(&self) -> &[BuildingId] {
        &self.ids
    }

    /// The IDs as plain integers, for loops that compare or count them (no copy).
    pub fn raw(&self) -> &[u32] {
        BuildingId::peel_slice(&self.ids)
    }

    /// The ID at column `x`, row `y`.
    ///
    /// # Panics
    /// When (x, y) is outside the map.
    pub fn get(&self, x: u32, y: u32) -> BuildingId {
        assert!(x < self.width && y < self.height, "pixel ({x}, {y}) outside {}×{}", self.width, self.height);
        self.ids[y as usize * self.width as usize + x as usize]
    }

    /// The distinct buildings seen (background excluded), ascending.
    pub fn visible_buildings(&self) -> Vec<BuildingId> {
        let mut set = std::collections::BTreeSet::new();
        let mut last = BuildingId::BACKGROUND;
        for &id in &self.ids {
            // Runs of equal IDs are the common case: skip the set lookup for them.
            if id != last {
                if !id.is_background() {
                    set.insert(id);
                }
                last = id;
            }
        }
        set.into_iter().collect()
    }

    /// Encodes the map as an 8-bit RGB PNG in memory (see the module doc).
    ///
    /// # Errors
    /// [`IdError::PngEncode`] if the encoder fails.
    pub fn encode_png(&self) -> Result<Vec<u8>, IdError> {
        let rgb: Vec<u8> = self.ids.iter().flat_map(|id| id.to_rgb()).collect();
        let mut out = Vec::with_capacity(self.ids.len() / 16 + 1024);
        {
            let mut encoder = png::Encoder::new(Cursor::new(&mut out), self.width, self.height);
            encoder.set_color(png::ColorType::Rgb);
            encoder.set_depth(png::BitDepth::Eight);
            encoder.set_compression(png::Compression::Fast);
            encoder.set_filter(png::FilterType::Sub);
            let mut writer = encoder.write_header().map_err(IdError::PngEncode)?;
            writer.write_image_data(&rgb).map_err(IdError::PngEncode)?;
            writer.finish().map_err(IdError::PngEncode)?;
        }
        Ok(out)
    }

    /// Encodes the map and writes it to `path` atomically.
    ///
    /// # Errors
    /// As [`IdMap::encode_png`], plus [`IdError::File`] naming `path`.
    pub fn write_png(&self, path: &Path) -> Result<(), IdError> {
        crate::util::write_bytes_atomic(path, &self.encode_png()?)?;
        Ok(())
    }

    /// Decodes an ID PNG from bytes (`path` only names it in errors).
    ///
    /// # Errors
    /// [`IdError::PngDecode`] for a broken or truncated PNG, [`IdError::NotAnIdMap`] for a PNG that is
    /// not 8-bit RGB.
    pub fn decode_png(path: &Path, bytes: &[u8]) -> Result<IdMap, IdError> {
        let mut r = png_reader(path, Cursor::new(bytes))?;
        let mut buf = vec![0u8; r.output_buffer_size()];
        let frame = r
            .next_frame(&mut buf)
            .map_err(|source| IdError::PngDecode { path: path.to_path_buf(), source })?;
        let ids =
            buf[..frame.buffer_size()].chunks_exact(3).map(|p| BuildingId::from_rgb([p[0], p[1], p[2]]));
        IdMap::new(frame.width, frame.height, ids.collect())
    }

    /// Reads and decodes the ID PNG at `path`.
    ///
    /// # Errors
    /// As [`IdMap::decode_png`], plus [`IdError::File`].
    pub fn read_png(path: &Path) -> Result<IdMap, IdError> {
        IdMap::decode_png(path, &crate::util::read_file(path)?)
    }

    /// Checks an existing ID PNG cheaply, for resuming: the header (up to the first image data) must
    /// decode as 8-bit RGB and the file must end with the IEND chunk. Returns (width, height).
    ///
    /// # Errors
    /// [`IdError::File`], [`IdError::PngDecode`] or [`IdError::NotAnIdMap`], naming `path`.
    pub fn read_png_size(path: &Path) -> Result<(u32, u32), IdError> {
        use std::io::{Read, Seek, SeekFrom};
        let mut file = std::fs::File::open(path).map_err(|e| FileError::new("opening", path, e))?;
        let mut tail = [0u8; 12];
        file.seek(SeekFrom::End(-12))
            .and_then(|_| file.read_exact(&mut tail))
            .and_then(|_| file.seek(SeekFrom::Start(0)))
            .map_err(|e| FileError::new("reading", path, e))?;
        if tail != IEND {
            return Err(IdError::NotAnIdMap { path: path.to_path_buf(), color: None, bit_depth: None });
        }
        let r = png_reader(path, std::io::BufReader::new(file))?;
        Ok((r.info().width, r.info().height))
    }

    /// Reads Blender's ID render: a float32 EXR whose `R` channel holds the building ID.
    ///
    /// # Errors
    /// [`IdError::ExrDecode`] when the file is unreadable, [`IdError::NotAnIdExr`] when it has no
    /// float32 `R` channel or a value that is not an integer in 0 ..= 2²⁴ − 1 (naming the pixel).
    pub fn read_exr(path: &Path) -> Result<IdMap, IdError> {
        let bad = |problem| IdError::NotAnIdExr { path: path.to_path_buf(), problem };
        let image = exr::prelude::read_first_flat_layer_from_file(path)
            .map_err(|source| IdError::ExrDecode { path: path.to_path_buf(), source })?;
        let layer = &image.layer_data;
        let (w, h) = (layer.size.0, layer.size.1);
        let r =
            layer.channel_data.list.iter().find(|c| c.name.eq("R")).ok_or_else(|| bad(ExrIdProblem::NoR))?;
        let values = match &r.sample_data {
            exr::prelude::FlatSamples::F32(v) => v,
            _ => return Err(bad(ExrIdProblem::NotF32)),
        };
        let mut ids = Vec::with_capacity(values.len());
        for (i, &v) in values.iter().enumerate() {
            if !(v >= 0.0 && v <= MAX_BUILDING_ID as f32 && v.fract() == 0.0) {
                return Err(bad(ExrIdProblem::Value { x: i % w.max(1), y: i / w.max(1), value: v }));
            }
            ids.push(BuildingId(v as u32));
        }
        IdMap::new(w as u32, h as u32, ids)
    }
}

fn png_reader<R: std::io::BufRead + std::io::Seek>(
    path: &Path,
    source: R,
) -> Result<png::Reader<R>, IdError> {
    let decoder = png::Decoder::new(source);
    let reader =
        decoder.read_info().map_err(|source| IdError::PngDecode { path: path.to_path_buf(), source })?;
    let info = reader.info();
    if info.color_type != png::ColorType::Rgb || info.bit_depth != png::BitDepth::Eight {
        return Err(IdError::NotAnIdMap {
            path: path.to_path_buf(),
            color: Some(info.color_type),
            bit_depth: Some(info.bit_depth),
        });
    }
    Ok(reader)
}

#[cfg(test)]
mod tests {
    use super::*;

    mod building_id {
        use super::*;

        #[test]
        fn the_cap_is_24_bits() {
            assert_eq!(BuildingId::new(MAX_BUILDING_ID).unwrap(), BuildingId::MAX);
            assert!(matches!(BuildingId::new(1 << 24), Err(IdError::TooLarge { id: 16_777_216, .. })));
            assert!(BuildingId::from_index(MAX_BUILDING_ID as usize - 1).is_ok());
            let e = BuildingId::from_index(MAX_BUILDING_ID as usize).unwrap_err();
            assert!(e.to_string().contains("16777216 buildings exceed"), "{e}");
        }

        #[test]
        fn red_is_the_high_byte() {
            // 0x12_34_56: R = 0x12 (bits 16–23), G = 0x34, B = 0x56 (SPEC.md).
            let id = BuildingId::new(0x12_34_56).unwrap();
            assert_eq!(id.to_rgb(), [0x12, 0x34, 0x56]);
            assert_eq!(BuildingId::from_rgb([0x12, 0x34, 0x56]), id);
            assert_eq!(BuildingId::from_rgb(BuildingId::MAX.to_rgb()), BuildingId::MAX);
        }

        #[test]
        fn serde_is_the_plain_integer_and_checks_the_cap() {
            let id: BuildingId = serde_json::from_str("42").unwrap();
            assert_eq!(serde_json::to_string(&id).unwrap(), "42");
            let e = serde_json::from_str::<BuildingId>("16777216").unwrap_err();
            assert!(e.to_string().contains("does not fit the 24-bit ID map"), "{e}");
        }
    }

    mod png_round_trip {
        use super::*;

        #[test]
        fn ids_survive_encode_decode_exactly() {
            let (w, h) = (37u32, 23u32);
            // IDs exercising all three bytes, including values whose red byte alone differs.
            let ids: Vec<u32> = (0..w * h)
                .map(|i| if i % 7 == 0 { 0 } else { i.wrapping_mul(2_654_435_761u32) & MAX_BUILDING_ID })
                .collect();
            let map = IdMap::from_raw(w, h, ids.clone()).unwrap();
            let back = IdMap::decode_png(Path::new("mem.png"), &map.encode_png().unwrap()).unwrap();
            assert_eq!((back.width(), back.height()), (w, h));
            assert_eq!(back.raw(), &ids[..]);
        }

        #[test]
        fn encoding_is_deterministic() {
            let map = IdMap::from_raw(64, 48, (0..64 * 48).map(|i| i / 100).collect()).unwrap();
            assert_eq!(map.encode_png().unwrap(), map.encode_png().unwrap());
        }

        #[test]
        fn header_size_is_read_from_the_file() {
            let dir = tempfile::tempdir().unwrap();
            let p = dir.path().join("a.png");
            IdMap::from_raw(300, 200, vec![5; 300 * 200]).unwrap().write_png(&p).unwrap();
            assert_eq!(IdMap::read_png_size(&p).unwrap(), (300, 200));
        }

        #[test]
        fn visible_buildings_are_distinct_and_sorted() {
            let map = IdMap::from_raw(9, 1, vec![0, 5, 5, 3, 0, 5, 9, 9, 3]).unwrap();
            assert_eq!(map.visible_buildings().iter().map(|b| b.get()).collect::<Vec<_>>(), vec![3, 5, 9]);
            assert!(IdMap::background(2, 1).visible_buildings().is_empty());
        }
    }

    mod errors {
        use super::*;

        #[test]
        fn raw_ids_above_24_bits_are_refused_with_their_pixel() {
            let e = IdMap::from_raw(2, 1, vec![1, 1 << 24]).unwrap_err();
            assert!(matches!(e, IdError::TooLarge { index: 1, id: 16_777_216 }), "{e}");
        }

        #[test]
        fn size_mismatch_is_refused() {
            assert!(matches!(IdMap::from_raw(2, 2, vec![1, 2, 3]), Err(IdError::SizeMismatch { .. })));
        }

        #[test]
        fn truncated_png_names_the_path() {
            let bytes = IdMap::from_raw(10, 10, vec![3; 100]).unwrap().encode_png().unwrap();
            let e = IdMap::decode_png(Path::new("x/frame.png"), &bytes[..bytes.len() / 2]).unwrap_err();
            assert!(e.to_string().contains("x/frame.png"), "{e}");
        }

        fn png_of(color: png::ColorType, w: u32, h: u32, data: &[u8]) -> Vec<u8> {
            let mut out = Vec::new();
            {
                let mut enc = png::Encoder::new(&mut out, w, h);
                enc.set_color(color);
                enc.set_depth(png::BitDepth::Eight);
                let mut wr = enc.write_header().unwrap();
                wr.write_image_data(data).unwrap();
            }
            out
        }

        #[test]
        fn rgba_png_is_not_an_id_map() {
            let e =
                IdMap::decode_png(Path::new("rgba.png"), &png_of(png::ColorType::Rgba, 1, 1, &[1, 2, 3, 4]))
                    .unwrap_err();
            assert!(
                e.to_string().contains("expected an 8-bit RGB ID map") && e.to_string().contains("Rgba"),
                "{e}"
            );
        }

        #[test]
        fn grey_png_is_rejected_with_its_colour_type() {
            let e = IdMap::decode_png(
                Path::new("masks/f.png"),
                &png_of(png::ColorType::Grayscale, 2, 2, &[0, 1, 2, 3]),
            )
            .unwrap_err()
            .to_string();
            assert!(e.contains("masks/f.png") && e.contains("Grayscale"), "{e}");
        }
    }
    mod exr_ids {
        use super::*;

        #[test]
        fn exr_round_trip_and_rejects_fractions() {
            let dir = tempfile::tempdir().unwrap();
            let p = dir.path().join("ids.exr");
            let ids = [0u32, 7, 16_000_000, 70_000, 3, 0];
            exr::prelude::write_rgb_file(&p, 3, 2, |x, y| {
                let v = ids[y * 3 + x] as f32;
                (v, v, v)
            })
            .unwrap();
            let im = IdMap::read_exr(&p).unwrap();
            assert_eq!((im.width(), im.height()), (3, 2));
            assert_eq!(im.raw(), &ids[..]);
            exr::prelude::write_rgb_file(&p, 1, 1, |_, _| (2.5f32, 0.0f32, 0.0f32)).unwrap();
            let e = IdMap::read_exr(&p).unwrap_err().to_string();
            assert!(e.contains("2.5") && e.contains("ids.exr"), "{e}");
        }
    }
}
