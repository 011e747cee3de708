//! The self-contained export: every photo and ID map a COCO file names, placed inside the export
//! folder, so that the folder alone is the dataset (`mv`, `rsync` or `tar` it anywhere).
//!
//! Takes in the built datasets, whose names are relative to the work directory
//! (`<area>/<camera>/rgb/<frame>.png`, `<area>/<camera>/masks/<frame>.png`), and hands on the same
//! datasets with `info.image_root` = `"."` and every name inside the export
//! ([`crate::layout::ExportDir::image_name`], [`crate::layout::ExportDir::mask_name`]):
//! `images/<split>/<area>/<camera>/<frame>.png`, `masks/<split>/<area>/<camera>/<frame>.png` with the
//! frame's instance list `<frame>.instances.json` (and `<frame>.ignore.png`) beside it. Each file is a hard link to the work directory's file where the file
//! system allows it (no space taken), else a copy ([`crate::util::link_or_copy`]); an existing
//! identical file is kept, so a rerun rewrites nothing, and files a previous export placed that no
//! image names any more are removed (a stale photo never lingers in the folder).

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

use rayon::prelude::*;

use crate::layout::ExportDir;
use crate::util::{FileError, Placed};

use super::coco::Split;
use super::format::Dataset;
use super::CocoError;

/// The image root of a self-contained export: its names are relative to the folder itself.
pub const SELF_ROOT: &str = ".";

/// A file [`place_files`] puts in the export: `from` relative to the work directory, `to` relative to
/// the export folder.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Placement {
    /// The file in the work directory.
    pub from: String,
    /// Its place in the export folder.
    pub to: String,
    /// A photo of a label-only export (`info.images_missing`), which may not exist yet.
    pub optional: bool,
}

/// Rewrites the names of `datasets` (relative to the work directory) to names inside the export
/// folder, with `info.image_root` = [`SELF_ROOT`]; returns the files to place. Writes nothing (the
/// merge predicts the combined COCO files with it).
pub fn names_inside(datasets: &mut [(Split, Dataset)]) -> Vec<Placement> {
    let mut out = Vec::new();
    for (split, ds) in datasets.iter_mut() {
        let split = split.as_str();
        let label_only = ds.info.images_missing;
        ds.info.image_root = SELF_ROOT.to_string();
        for im in &mut ds.images {
            let file = |name: &str| name.rsplit('/').next().unwrap_or(name).to_string();
            let mut place = |name: &mut String, to: String, optional: bool| {
                out.push(Placement { from: std::mem::replace(name, to.clone()), to, optional });
            };
            let image = ExportDir::image_name(split, &im.area_name, &im.camera, &file(&im.file_name));
            place(&mut im.file_name, image, label_only);
            // The frame's instance list beside its ID map (connectivity, minimum component area):
            // what an independent check of the masks needs.
            let list = |png: &str| format!("{}.instances.json", png.trim_end_matches(".png"));
            let mut instances = list(&im.mask_file);
            let mask = ExportDir::mask_name(split, &im.area_name, &im.camera, &file(&im.mask_file));
            place(&mut instances, list(&mask), false);
            place(&mut im.mask_file, mask, false);
            if let Some(ignore) = &mut im.ignore_file {
                let to = ExportDir::mask_name(split, &im.area_name, &im.camera, &file(ignore));
                place(ignore, to, false);
            }
        }
    }
    out
}

/// Rewrites the names of `datasets` as [`names_inside`] does and places the files in `out_dir`,
/// removing what an earlier export placed there that no image names now; a photo that does not
/// exist is skipped only in a label-only export, whose photos are still to come. Returns how many
/// files were (re)written and the names (relative to `out_dir`) of every file now placed.
///
/// # Errors
/// [`CocoError::File`] naming a file that could not be read (an ID map that vanished since the export
/// read it) or written; [`CocoError::Interrupted`].
pub fn place_files(
    workdir: &Path,
    out_dir: &Path,
    datasets: &mut [(Split, Dataset)],
) -> Result<(u64, Vec<String>), CocoError> {
    let placements = names_inside(datasets);
    let jobs: Vec<(PathBuf, PathBuf, bool)> =
        placements.iter().map(|p| (workdir.join(&p.from), out_dir.join(&p.to), p.optional)).collect();
    let written = jobs
        .par_iter()
        .map(|(src, dst, optional)| {
            crate::util::interrupt::check()?;
            if *optional && !src.exists() {
                return Ok(None);
            }
            Ok(Some(crate::util::link_or_copy(src, dst)?))
        })
        .collect::<Result<Vec<Option<Placed>>, CocoError>>()?;
    let keep: BTreeSet<&Path> = jobs.iter().map(|(_, dst, _)| dst.as_path()).collect();
    let export = ExportDir::new(out_dir);
    for dir in [export.images(), export.masks()] {
        remove_unlisted(&dir, &keep)?;
    }
    let count = written.iter().filter(|w| w.is_some_and(Placed::written)).count() as u64;
    let copied = written.iter().filter(|w| **w == Some(Placed::Copied)).count();
    if copied > 0 {
        log::info!(
            "copied {copied} photo and ID map file(s) into {}: no hard link possible (another file system?), \
             so they take space of their own",
            out_dir.display()
        );
    }
    let placed =
        placements.into_iter().zip(&written).filter(|(_, w)| w.is_some()).map(|(p, _)| p.to).collect();
    Ok((count, placed))
}

/// Writes `SHA256SUMS` in `out_dir`: one line `<hex>  <name>` per file of `names` (relative to
/// `out_dir`, sorted, each once), the format `sha256sum -c` checks. Returns the file's own SHA-256 and
/// how many files it lists.
///
/// # Errors
/// [`CocoError::File`] naming a file that cannot be read, or the checksums file that cannot be written.
pub fn write_checksums(out_dir: &Path, names: &[String]) -> Result<(String, u64), CocoError> {
    let names: BTreeSet<&String> = names.iter().collect();
    let lines = names
        .par_iter()
        .map(|name| {
            crate::util::interrupt::check()?;
            Ok(format!("{}  {name}\n", crate::util::sha256_file(&out_dir.join(name.as_str()))?))
        })
        .collect::<Result<Vec<String>, CocoError>>()?;
    let path = ExportDir::new(out_dir).checksums();
    crate::util::write_bytes_atomic(&path, lines.concat().as_bytes())?;
    Ok((crate::util::sha256_file(&path)?, names.len() as u64))
}

/// The lines of a `SHA256SUMS` text: (hex digest, name); a line that is not `<64 hex>  <name>` is an
/// `Err` with its 1-based number.
pub fn parse_checksums(text: &str) -> Vec<Result<(String, String), usize>> {
    text.lines()
        .enumerate()
        .filter(|(_, l)| !l.is_empty())
        .map(|(i, line)| {
            let (hex, name) = line.split_once("  ").ok_or(i + 1)?;
            let name = name.strip_prefix('*').unwrap_or(name);
            let ok = hex.len() == 64 && hex.bytes().all(|b| b.is_ascii_hexdigit()) && !name.is_empty();
            if ok {
                Ok((hex.to_ascii_lowercase(), name.to_string()))
            } else {
                Err(i + 1)
            }
        })
        .collect()
}

/// Removes the files under `dir` not in `keep` (what an earlier export placed), and folders left empty.
fn remove_unlisted(dir: &Path, keep: &BTreeSet<&Path>) -> Result<(), CocoError> {
    let entries = match std::fs::read_dir(dir) {
        Ok(e) => e,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(()),
        Err(e) => return Err(FileError::new("listing", dir, e).into()),
    };
    for entry in entries {
        let entry = entry.map_err(|e| FileError::new("listing", dir, e))?;
        let path = entry.path();
        let kind = entry.file_type().map_err(|e| FileError::new("listing", &path, e))?;
        if kind.is_dir() {
            remove_unlisted(&path, keep)?;
            if std::fs::read_dir(&path).map(|mut d| d.next().is_none()).unwrap_or(false) {
                std::fs::remove_dir(&path)
                    .map_err(|e| FileError::new("removing the empty folder", &path, e))?;
            }
        } else if !keep.contains(path.as_path()) {
            std::fs::remove_file(&path).map_err(|e| FileError::new("removing the stale file", &path, e))?;
        }
    }
    Ok(())
}
