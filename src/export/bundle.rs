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
use crate::util::FileError;

use super::coco::Split;
use super::format::Dataset;
use super::CocoError;

/// The image root of a self-contained export: its names are relative to the folder itself.
pub const SELF_ROOT: &str = ".";

/// Rewrites the names of `datasets` (relative to `workdir`) to names inside `out_dir` and places
/// the files there; a photo that does not exist is skipped only in a label-only export
/// (`info.images_missing`), whose photos are still to come. Returns how many files were (re)written.
///
/// # Errors
/// [`CocoError::File`] naming a file that could not be read (an ID map that vanished since the export
/// read it) or written; [`CocoError::Interrupted`].
pub fn place_files(
    workdir: &Path,
    out_dir: &Path,
    datasets: &mut [(Split, Dataset)],
) -> Result<u64, CocoError> {
    // (source, destination, may be missing)
    let mut jobs: Vec<(PathBuf, PathBuf, bool)> = Vec::new();
    for (split, ds) in datasets.iter_mut() {
        let split = split.as_str();
        let label_only = ds.info.images_missing;
        ds.info.image_root = SELF_ROOT.to_string();
        for im in &mut ds.images {
            let file = |name: &str| name.rsplit('/').next().unwrap_or(name).to_string();
            let mut place = |name: &mut String, inside: String, optional: bool| {
                jobs.push((workdir.join(&*name), out_dir.join(&inside), optional));
                *name = inside;
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
                let inside = ExportDir::mask_name(split, &im.area_name, &im.camera, &file(ignore));
                place(ignore, inside, false);
            }
        }
    }
    let written = jobs
        .par_iter()
        .map(|(src, dst, optional)| {
            crate::util::interrupt::check()?;
            if *optional && !src.exists() {
                return Ok(false);
            }
            Ok(crate::util::link_or_copy(src, dst)?)
        })
        .collect::<Result<Vec<bool>, CocoError>>()?;
    let keep: BTreeSet<&Path> = jobs.iter().map(|(_, dst, _)| dst.as_path()).collect();
    let export = ExportDir::new(out_dir);
    for dir in [export.images(), export.masks()] {
        remove_unlisted(&dir, &keep)?;
    }
    Ok(written.into_iter().filter(|&w| w).count() as u64)
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
