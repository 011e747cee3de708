//! Merging work directories written by separate processes or machines (`insgen merge`).
//!
//! Shards of a stage write disjoint per-frame files (`masks/<frame>.png`, `rgb/<frame>.png`, …) and
//! identical shared inputs (the prepared scene, `poses.jsonl`), so a work directory merges as a union
//! of files: a file missing from the destination is copied, a byte-identical one is left alone, and two
//! different files at one path are a conflict. Conflicts are found before anything is written, so a
//! refused merge leaves the destination as it was. The one file every process appends to,
//! `commands.jsonl` (the command log of the dataset manifest), is merged line by line instead: the
//! destination's lines first, then each source's new lines in source order.
//!
//! The merged directory is then exactly the directory one process would have written (a test checks
//! it byte for byte through `export-coco`), so exports and evaluations run on it as usual.

use std::collections::BTreeMap;
use std::fs;
use std::path::{Path, PathBuf};

use super::{read_file, write_bytes_atomic, FileError};

/// The command log every command appends to; merged line by line.
pub const COMMAND_LOG: &str = "commands.jsonl";

/// Why a merge was refused.
#[derive(Debug, thiserror::Error)]
pub enum MergeError {
    #[error(transparent)]
    File(#[from] FileError),
    #[error(transparent)]
    Interrupted(#[from] super::interrupt::Interrupted),
    #[error("{} is not a directory", .0.display())]
    NotADirectory(PathBuf),
    #[error("{} is both a source and the destination", .0.display())]
    SourceIsDestination(PathBuf),
    #[error(
        "{count} file(s) differ between the work directories, e.g. {}: {}; merge takes shards of the \
         same run (same scene, poses and settings); run exports after the merge, not in each shard",
        first.0.display(),
        first.1
    )]
    Conflicts { count: usize, first: (PathBuf, String) },
    #[error("{} is a symbolic link or special file; merge copies regular files only", .0.display())]
    NotAFile(PathBuf),
}

/// What a merge did.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct MergeReport {
    /// Files copied into the destination.
    pub copied: usize,
    /// Files already present with the same bytes.
    pub identical: usize,
    /// Lines added to `commands.jsonl`.
    pub command_lines_added: usize,
    /// Leftover temporary files of killed runs (`.insgen-tmp-*`), not copied.
    pub temporaries_skipped: usize,
}

/// Merges the work directories `sources` into `dest` (created if missing). Sources are read in the
/// order given; the result does not depend on it, since a path may only hold one content.
///
/// # Errors
/// [`MergeError::Conflicts`] (nothing written) when one path holds different bytes in two places;
/// I/O errors naming the file.
pub fn merge_workdirs(sources: &[PathBuf], dest: &Path) -> Result<MergeReport, MergeError> {
    let dest_canonical = fs::canonicalize(dest).ok();
    // Relative path → the first source holding it, or None when the destination already holds it.
    let mut files: BTreeMap<PathBuf, Option<PathBuf>> = BTreeMap::new();
    let mut conflicts: Vec<(PathBuf, String)> = Vec::new();
    let mut report = MergeReport::default();
    let mut logs: Vec<PathBuf> = Vec::new();
    for src in sources {
        if !src.is_dir() {
            return Err(MergeError::NotADirectory(src.clone()));
        }
        if dest_canonical.is_some() && fs::canonicalize(src).ok() == dest_canonical {
            return Err(MergeError::SourceIsDestination(src.clone()));
        }
        for rel in list_files(src, &mut report)? {
            if rel == Path::new(COMMAND_LOG) {
                logs.push(src.join(&rel));
                continue;
            }
            let path = src.join(&rel);
            let in_dest = dest.join(&rel);
            let holder = match files.get(&rel) {
                Some(Some(first)) => Some(first.clone()),
                Some(None) => Some(in_dest),
                None => in_dest.is_file().then_some(in_dest),
            };
            match holder {
                None => {
                    files.insert(rel, Some(path));
                }
                Some(other) if read_file(&other)? != read_file(&path)? => {
                    conflicts.push((rel, format!("{} ≠ {}", other.display(), path.display())));
                }
                Some(_) => {
                    report.identical += 1;
                    files.entry(rel).or_insert(None);
                }
            }
        }
    }
    if let Some(first) = conflicts.first().cloned() {
        return Err(MergeError::Conflicts { count: conflicts.len(), first });
    }
    for (rel, from) in files.iter().filter_map(|(rel, from)| Some((rel, from.as_ref()?))) {
        super::interrupt::check()?;
        write_bytes_atomic(&dest.join(rel), &read_file(from)?)?;
        report.copied += 1;
    }
    report.command_lines_added = merge_command_logs(&logs, &dest.join(COMMAND_LOG))?;
    Ok(report)
}

/// Regular files below `root`, relative and sorted; temporaries of killed runs are counted and left.
fn list_files(root: &Path, report: &mut MergeReport) -> Result<Vec<PathBuf>, MergeError> {
    let mut out = Vec::new();
    let mut stack = vec![PathBuf::new()];
    while let Some(rel) = stack.pop() {
        let dir = root.join(&rel);
        let entries = fs::read_dir(&dir).map_err(|e| FileError::new("listing", &dir, e))?;
        for entry in entries {
            let entry = entry.map_err(|e| FileError::new("listing", &dir, e))?;
            let kind = entry.file_type().map_err(|e| FileError::new("inspecting", &entry.path(), e))?;
            let child = rel.join(entry.file_name());
            if entry.file_name().to_string_lossy().starts_with(".insgen-tmp-") {
                report.temporaries_skipped += 1;
            } else if kind.is_dir() {
                stack.push(child);
            } else if kind.is_file() {
                out.push(child);
            } else {
                return Err(MergeError::NotAFile(root.join(child)));
            }
        }
    }
    out.sort();
    Ok(out)
}

/// Appends to `dest` the lines of `sources` it does not hold yet, in order; returns how many.
fn merge_command_logs(sources: &[PathBuf], dest: &Path) -> Result<usize, MergeError> {
    if sources.is_empty() {
        return Ok(0);
    }
    let mut text =
        if dest.is_file() { String::from_utf8_lossy(&read_file(dest)?).into_owned() } else { String::new() };
    let mut seen: std::collections::HashSet<String> = text.lines().map(str::to_string).collect();
    let mut added = 0;
    for src in sources {
        for line in String::from_utf8_lossy(&read_file(src)?).lines() {
            if !line.trim().is_empty() && seen.insert(line.to_string()) {
                if !text.is_empty() && !text.ends_with('\n') {
                    text.push('\n');
                }
                text.push_str(line);
                text.push('\n');
                added += 1;
            }
        }
    }
    if added > 0 {
        write_bytes_atomic(dest, text.as_bytes())?;
    }
    Ok(added)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn put(root: &Path, rel: &str, bytes: &[u8]) {
        let p = root.join(rel);
        fs::create_dir_all(p.parent().unwrap()).unwrap();
        fs::write(p, bytes).unwrap();
    }

    #[test]
    fn union_of_disjoint_shards_with_shared_inputs() {
        let t = tempfile::tempdir().unwrap();
        let (a, b, out) = (t.path().join("a"), t.path().join("b"), t.path().join("out"));
        put(&a, "demo/cam2/poses.jsonl", b"p\n");
        put(&b, "demo/cam2/poses.jsonl", b"p\n");
        put(&a, "demo/cam2/masks/f0.png", b"0");
        put(&b, "demo/cam2/masks/f1.png", b"1");
        put(&b, "demo/cam2/masks/.insgen-tmp-f3.png", b"half");
        put(&a, COMMAND_LOG, b"{\"argv\":[\"sample\"]}\n{\"argv\":[\"masks 0/2\"]}\n");
        put(&b, COMMAND_LOG, b"{\"argv\":[\"sample\"]}\n{\"argv\":[\"masks 1/2\"]}\n");
        let r = merge_workdirs(&[a.clone(), b.clone()], &out).unwrap();
        assert_eq!(
            r,
            MergeReport { copied: 3, identical: 1, command_lines_added: 3, temporaries_skipped: 1 }
        );
        assert_eq!(fs::read(out.join("demo/cam2/masks/f1.png")).unwrap(), b"1");
        assert!(!out.join("demo/cam2/masks/.insgen-tmp-f3.png").exists());
        assert_eq!(
            fs::read_to_string(out.join(COMMAND_LOG)).unwrap(),
            "{\"argv\":[\"sample\"]}\n{\"argv\":[\"masks 0/2\"]}\n{\"argv\":[\"masks 1/2\"]}\n"
        );
        // Merging again changes nothing.
        let again = merge_workdirs(&[a, b], &out).unwrap();
        assert_eq!((again.copied, again.identical, again.command_lines_added), (0, 4, 0));
    }

    #[test]
    fn conflicting_files_are_refused_before_anything_is_written() {
        let t = tempfile::tempdir().unwrap();
        let (a, b, out) = (t.path().join("a"), t.path().join("b"), t.path().join("out"));
        put(&a, "x/only_a.png", b"a");
        put(&a, "x/poses.jsonl", b"one\n");
        put(&b, "x/poses.jsonl", b"two\n");
        let e = merge_workdirs(&[a.clone(), b], &out).unwrap_err();
        let msg = e.to_string();
        assert!(msg.contains("1 file(s) differ") && msg.contains("poses.jsonl"), "{msg}");
        assert!(!out.exists(), "a refused merge writes nothing");
        // A source that is the destination is refused too.
        assert!(matches!(
            merge_workdirs(std::slice::from_ref(&a), &a),
            Err(MergeError::SourceIsDestination(_))
        ));
        assert!(matches!(
            merge_workdirs(&[t.path().join("missing")], &out),
            Err(MergeError::NotADirectory(_))
        ));
    }
}
