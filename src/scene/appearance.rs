//! Appearances of LoD models in the prepared scene: textures and flat colours per face.
//!
//! The readers hand on, per face, a texture with per-vertex coordinates or a colour
//! ([`crate::lod::FaceAppearance`]). `prepare` numbers the distinct images and colours of an area
//! 1, 2, … in the order faces first use them ([`AppearanceTable`]; 0 = no appearance, the renderer's
//! procedural look), carries one `(u, v)` and one appearance number per vertex through triangulation
//! ([`VertexAppearance`]), copies the images next to `scene.glb` (`textures/NNNN_<name>`) and writes
//! them into the GLB (see [`super::glb`]).
//!
//! An image that is missing or not a PNG/JPEG/TIFF/WebP/GIF/BMP file is not fatal: it is counted in
//! the manifest (`sources[].appearance.missing_images`), named in a warning, and its faces get
//! appearance 0. Appearances never touch the building IDs, the triangles or their order, so masks
//! are the same with and without them.

use std::collections::HashMap;
use std::io::Read;
use std::path::{Path, PathBuf};

use crate::util::{self, FileError};

/// Folder (next to `scene.glb`) the texture images are copied into.
pub use crate::layout::TEXTURES_DIR;

/// Per-vertex appearance, parallel to a mesh's vertices.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct VertexAppearance {
    /// Texture coordinates (0, 0) = the image's lower-left corner (CityGML/CityJSON convention);
    /// (0, 0) on faces without a texture.
    pub uvs: Vec<[f32; 2]>,
    /// Appearance number of the vertex's face: 0 = none, k = [`AppearanceTable::materials`]`[k − 1]`.
    pub ids: Vec<u32>,
}

impl VertexAppearance {
    /// Appends `n` vertices without appearance.
    pub fn pad(&mut self, n: usize) {
        self.uvs.resize(self.uvs.len() + n, [0.0, 0.0]);
        self.ids.resize(self.ids.len() + n, 0);
    }
}

/// One distinct appearance of the scene.
#[derive(Debug, Clone, PartialEq)]
pub enum AppearanceMaterial {
    /// An image: where it was read from and its file name under [`TEXTURES_DIR`].
    Texture {
        /// Where the image was read from.
        source: PathBuf,
        /// Its file name under [`TEXTURES_DIR`].
        file_name: String,
    },
    /// A flat colour, linear RGB in 0..=1.
    Colour {
        /// Linear RGB, 0..=1.
        rgb: [f64; 3],
    },
}

/// The distinct images and colours of an area, numbered from 1 in order of first use.
#[derive(Debug, Clone, Default)]
pub struct AppearanceTable {
    /// Appearance k is `materials[k − 1]`.
    pub materials: Vec<AppearanceMaterial>,
    /// Every image path asked for: its number, or 0 when it is missing or unreadable.
    images: HashMap<PathBuf, u32>,
    colours: HashMap<[u64; 3], u32>,
    /// Missing or unreadable images: (path, why), in order of first use.
    pub missing: Vec<(PathBuf, String)>,
}

impl AppearanceTable {
    /// The number of an image, checking it the first time it is asked for: 0 when it is missing or
    /// not an image (then recorded in [`AppearanceTable::missing`]).
    pub fn texture(&mut self, path: &Path) -> u32 {
        if let Some(&id) = self.images.get(path) {
            return id;
        }
        let id = match image_problem(path) {
            Some(why) => {
                self.missing.push((path.to_path_buf(), why));
                0
            }
            None => {
                let k = self.materials.len() + 1;
                let base = path.file_name().map(|n| n.to_string_lossy().to_string()).unwrap_or_default();
                let safe: String = base
                    .chars()
                    .map(|c| if c.is_ascii_alphanumeric() || matches!(c, '.' | '-' | '_') { c } else { '_' })
                    .collect();
                let file_name = format!("{k:04}_{safe}");
                self.materials.push(AppearanceMaterial::Texture { source: path.to_path_buf(), file_name });
                k as u32
            }
        };
        self.images.insert(path.to_path_buf(), id);
        id
    }

    /// How many distinct image paths faces have asked for so far (usable or not).
    pub fn images_asked(&self) -> usize {
        self.images.len()
    }

    /// The number of a colour (linear RGB 0..=1, clamped).
    pub fn colour(&mut self, rgb: [f64; 3]) -> u32 {
        let rgb = rgb.map(|c| c.clamp(0.0, 1.0));
        let key = rgb.map(f64::to_bits);
        if let Some(&id) = self.colours.get(&key) {
            return id;
        }
        self.materials.push(AppearanceMaterial::Colour { rgb });
        let id = self.materials.len() as u32;
        self.colours.insert(key, id);
        id
    }
}

/// Copies the images of `materials` into `dir/`[`TEXTURES_DIR`] (atomically, each file) and removes
/// the files a previous `prepare` left there that are not among them (the folder itself when there
/// are no images), so a re-prepared scene holds exactly what its GLB names.
///
/// # Errors
/// [`FileError`] naming the image or the copy that failed.
pub fn copy_images(materials: &[AppearanceMaterial], dir: &Path) -> Result<(), FileError> {
    let out = dir.join(TEXTURES_DIR);
    let wanted: std::collections::HashSet<&str> = materials
        .iter()
        .filter_map(|m| match m {
            AppearanceMaterial::Texture { file_name, .. } => Some(file_name.as_str()),
            AppearanceMaterial::Colour { .. } => None,
        })
        .collect();
    if let Ok(entries) = std::fs::read_dir(&out) {
        for e in entries.flatten() {
            let name = e.file_name();
            if !wanted.contains(name.to_string_lossy().as_ref()) && e.path().is_file() {
                std::fs::remove_file(e.path()).map_err(|err| FileError::new("removing", &e.path(), err))?;
            }
        }
        if wanted.is_empty() {
            // Only fails when something else is in the folder: then it stays.
            let _ = std::fs::remove_dir(&out);
        }
    }
    let mut made = false;
    for m in materials {
        if let AppearanceMaterial::Texture { source, file_name } = m {
            if !made {
                util::create_dir_all(&out)?;
                made = true;
            }
            let bytes = util::read_file(source)?;
            util::write_bytes_atomic(&out.join(file_name), &bytes)?;
        }
    }
    Ok(())
}

/// Why an image file cannot be used (`None` = it can): missing, unreadable, or not an image format
/// Blender reads (PNG, JPEG, TIFF, WebP, GIF, BMP, told by the first bytes).
pub fn image_problem(path: &Path) -> Option<String> {
    let mut head = [0u8; 12];
    let n = match std::fs::File::open(path).and_then(|mut f| f.read(&mut head)) {
        Ok(n) => n,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Some("missing".into()),
        Err(e) => return Some(format!("unreadable: {e}")),
    };
    let h = &head[..n];
    let known = h.starts_with(b"\x89PNG\r\n\x1a\n")
        || h.starts_with(&[0xFF, 0xD8, 0xFF])
        || h.starts_with(b"II*\0")
        || h.starts_with(b"MM\0*")
        || h.starts_with(b"GIF8")
        || h.starts_with(b"BM")
        || h.len() >= 12 && &h[..4] == b"RIFF" && &h[8..12] == b"WEBP";
    (!known).then(|| "not a PNG, JPEG, TIFF, WebP, GIF or BMP image".to_string())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn images_are_numbered_once_and_missing_ones_are_zero() {
        let dir = tempfile::tempdir().unwrap();
        let png = dir.path().join("a b.png");
        std::fs::write(&png, b"\x89PNG\r\n\x1a\n0000").unwrap();
        let text = dir.path().join("notes.png");
        std::fs::write(&text, b"hello").unwrap();
        let mut t = AppearanceTable::default();
        assert_eq!(t.colour([0.5, 0.0, 0.0]), 1);
        assert_eq!(t.texture(&png), 2);
        assert_eq!(t.texture(&png), 2);
        assert_eq!(t.texture(&dir.path().join("gone.jpg")), 0);
        assert_eq!(t.texture(&text), 0);
        assert_eq!(t.colour([0.5, 0.0, 0.0]), 1);
        assert_eq!(t.missing.len(), 2);
        assert_eq!(t.missing[0].1, "missing");
        assert!(t.missing[1].1.starts_with("not a PNG"));
        assert_eq!(
            t.materials[1],
            AppearanceMaterial::Texture { source: png.clone(), file_name: "0002_a_b.png".into() }
        );
        std::fs::create_dir_all(dir.path().join("textures")).unwrap();
        std::fs::write(dir.path().join("textures/0001_stale.png"), b"old").unwrap();
        copy_images(&t.materials, dir.path()).unwrap();
        assert_eq!(
            std::fs::read(dir.path().join("textures/0002_a_b.png")).unwrap(),
            std::fs::read(&png).unwrap()
        );
        assert!(!dir.path().join("textures/0001_stale.png").exists(), "a stale image was left");
        copy_images(&[], dir.path()).unwrap();
        assert!(!dir.path().join("textures").exists());
    }
}
