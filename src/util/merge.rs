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
//!
//! Reports that shards write in parts (`export-coco --shard`, `eval-loc --shard`: a directory
//! `<report>/parts/<i>-of-<N>/` holding a [`PART_MARKER`]) are not copied: [`plan_merge`] hands them,
//! grouped by report directory, to the caller, which combines them into the report one process writes
//! (the COCO files renumbered, results interleaved back into query order, summaries recomputed). The
//! parts already in the destination count too, so shards that wrote into one shared work directory
//! are combined by a merge without sources.

use std::collections::BTreeMap;
use std::fs;
use std::path::{Path, PathBuf};

use super::shard::{Shard, PARTS_DIR, PART_MARKER};
use super::{read_file, write_bytes_atomic, FileError};

/// The command log every command appends to; merged line by line.
pub const COMMAND_LOG: &str = "commands.jsonl";

/// Why a merge was refused.
#[derive(Debug, thiserror::Error)]
pub enum MergeError {
    /// Reading, writing or listing a file failed.
    #[error(transparent)]
    File(#[from] FileError),
    /// Stopped by Ctrl-C.
    #[error(transparent)]
    Interrupted(#[from] super::interrupt::Interrupted),
    /// A source or the destination is not a directory.
    #[error("{} is not a directory", .0.display())]
    NotADirectory(PathBuf),
    /// A directory given both as a source and as the destination.
    #[error("{} is both a source and the destination", .0.display())]
    SourceIsDestination(PathBuf),
    #[error(
        "{count} file(s) differ between the work directories, e.g. {}: {}; merge takes shards of the \
         same run (same scene, poses and settings); run exports after the merge, not in each shard",
        first.0.display(),
        first.1
    )]
    /// Files of the same path differ between the sources.
    Conflicts {
        /// Files that differ.
        count: usize,
        /// The first of them and how it differs.
        first: (PathBuf, String),
    },
    /// A symbolic link or special file in a source.
    #[error("{} is a symbolic link or special file; merge copies regular files only", .0.display())]
    NotAFile(PathBuf),
    #[error(
        "the parts of {} are of different runs: shard {shard} appears as {} and as {}; merge takes the \
         parts of one run",
        report.display(),
        first.display(),
        second.display()
    )]
    /// Two parts of one export claim the same shard.
    PartConflict {
        /// The export directory the parts belong to.
        report: PathBuf,
        /// The shard claimed twice.
        shard: Shard,
        /// One part directory.
        first: PathBuf,
        /// The other.
        second: PathBuf,
    },
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

/// The parts of one report written by shards: `<report>/parts/<i>-of-<N>/`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ReportParts {
    /// The report's directory, relative to the work directory (e.g. `coco`).
    pub report: PathBuf,
    /// Each part found, by shard (one directory per shard: a source's or the destination's).
    pub parts: BTreeMap<Shard, PathBuf>,
}

/// A merge checked and ready to write: the files to copy, the command logs, and the reports in parts.
#[derive(Debug, Clone)]
pub struct MergePlan {
    dest: PathBuf,
    /// Relative path → the source file to copy, or None when the destination already holds it.
    files: BTreeMap<PathBuf, Option<PathBuf>>,
    logs: Vec<PathBuf>,
    report: MergeReport,
    /// Reports written in parts, by report directory; the caller combines them.
    pub parts: Vec<ReportParts>,
}

impl MergePlan {
    /// The file that will hold `rel` (relative to the work directory) after [`MergePlan::apply`], if
    /// the union has one: a source's file or the destination's.
    pub fn holder(&self, rel: &Path) -> Option<PathBuf> {
        match self.files.get(rel) {
            Some(Some(src)) => Some(src.clone()),
            Some(None) => Some(self.dest.join(rel)),
            None => Some(self.dest.join(rel)).filter(|p| p.is_file()),
        }
    }

    /// Copies the files and merges the command logs.
    ///
    /// # Errors
    /// I/O errors naming the file; [`MergeError::Interrupted`] between files.
    pub fn apply(self) -> Result<MergeReport, MergeError> {
        let mut report = self.report;
        for (rel, from) in self.files.iter().filter_map(|(rel, from)| Some((rel, from.as_ref()?))) {
            super::interrupt::check()?;
            write_bytes_atomic(&self.dest.join(rel), &read_file(from)?)?;
            report.copied += 1;
        }
        report.command_lines_added = merge_command_logs(&self.logs, &self.dest.join(COMMAND_LOG))?;
        Ok(report)
    }
}

/// Merges the work directories `sources` into `dest` (created if missing): [`plan_merge`], then
/// [`MergePlan::apply`]. Reports in parts are left to the caller (see [`MergePlan::parts`]).
///
/// # Errors
/// As [`plan_merge`] and [`MergePlan::apply`].
pub fn merge_workdirs(sources: &[PathBuf], dest: &Path) -> Result<MergeReport, MergeError> {
    plan_merge(sources, dest)?.apply()
}

/// Checks a merge of the work directories `sources` into `dest` without writing anything. Sources are
/// read in the order given; the result does not depend on it, since a path may only hold one content.
///
/// # Errors
/// [`MergeError::Conflicts`] when one path holds different bytes in two places;
/// [`MergeError::PartConflict`] when one shard's part of a report differs between two places; I/O
/// errors naming the file.
pub fn plan_merge(sources: &[PathBuf], dest: &Path) -> Result<MergePlan, MergeError> {
    let dest_canonical = fs::canonicalize(dest).ok();
    let mut files: BTreeMap<PathBuf, Option<PathBuf>> = BTreeMap::new();
    let mut conflicts: Vec<(PathBuf, String)> = Vec::new();
    let mut report = MergeReport::default();
    let mut logs: Vec<PathBuf> = Vec::new();
    let mut parts: BTreeMap<PathBuf, BTreeMap<Shard, PathBuf>> = BTreeMap::new();
    let mut add_parts = |root: &Path, found: Vec<(PathBuf, Shard)>| -> Result<(), MergeError> {
        for (rel, shard) in found {
            let report_dir = rel.parent().and_then(Path::parent).unwrap_or(Path::new("")).to_path_buf();
            let dir = root.join(&rel);
            let by_shard = parts.entry(report_dir.clone()).or_default();
            match by_shard.get(&shard) {
                None => {
                    by_shard.insert(shard, dir);
                }
                Some(first) if !same_tree(first, &dir)? => {
                    return Err(MergeError::PartConflict {
                        report: report_dir,
                        shard,
                        first: first.clone(),
                        second: dir,
                    })
                }
                Some(_) => {}
            }
        }
        Ok(())
    };
    if dest.is_dir() {
        // Sources may live inside the destination (a job array's shards under <workdir>/.shards/):
        // their parts are a source's, found below, not the destination's.
        let inside: Vec<PathBuf> = sources.iter().filter_map(|s| fs::canonicalize(s).ok()).collect();
        let (_, found) = list_files_except(dest, &inside, &mut MergeReport::default())?;
        add_parts(dest, found)?;
    }
    for src in sources {
        if !src.is_dir() {
            return Err(MergeError::NotADirectory(src.clone()));
        }
        if dest_canonical.is_some() && fs::canonicalize(src).ok() == dest_canonical {
            return Err(MergeError::SourceIsDestination(src.clone()));
        }
        let (listed, found) = list_files(src, &mut report)?;
        add_parts(src, found)?;
        for rel in listed {
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
    let parts = parts.into_iter().map(|(report, parts)| ReportParts { report, parts }).collect();
    Ok(MergePlan { dest: dest.to_path_buf(), files, logs, report, parts })
}

/// Whether two directories hold the same files with the same bytes.
fn same_tree(a: &Path, b: &Path) -> Result<bool, MergeError> {
    let mut scratch = MergeReport::default();
    let (fa, _) = list_files(a, &mut scratch)?;
    let (fb, _) = list_files(b, &mut scratch)?;
    if fa != fb {
        return Ok(false);
    }
    for rel in &fa {
        if read_file(&a.join(rel))? != read_file(&b.join(rel))? {
            return Ok(false);
        }
    }
    Ok(true)
}

/// Regular files below `root`, relative and sorted, and the shards' part directories (not listed
/// file by file); temporaries of killed runs are counted and left.
type Listing = (Vec<PathBuf>, Vec<(PathBuf, Shard)>);
fn list_files(root: &Path, report: &mut MergeReport) -> Result<Listing, MergeError> {
    list_files_except(root, &[], report)
}

/// As [`list_files`], leaving out the directories `except` (canonical paths) and what they hold.
fn list_files_except(
    root: &Path,
    except: &[PathBuf],
    report: &mut MergeReport,
) -> Result<Listing, MergeError> {
    let mut out = Vec::new();
    let mut parts = Vec::new();
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
                if !except.is_empty() && fs::canonicalize(entry.path()).is_ok_and(|c| except.contains(&c)) {
                    continue;
                }
                match part_shard(root, &child) {
                    Some(shard) => parts.push((child, shard)),
                    None => stack.push(child),
                }
            } else if kind.is_file() {
                out.push(child);
            } else {
                return Err(MergeError::NotAFile(root.join(child)));
            }
        }
    }
    out.sort();
    parts.sort();
    Ok((out, parts))
}

/// The shard whose part of a report `rel` (below `root`) is: a directory `parts/<i>-of-<N>` holding a
/// [`PART_MARKER`].
fn part_shard(root: &Path, rel: &Path) -> Option<Shard> {
    let parent = rel.parent()?.file_name()?;
    if parent != PARTS_DIR || !root.join(rel).join(PART_MARKER).is_file() {
        return None;
    }
    Shard::from_part_dir_name(rel.file_name()?.to_str()?)
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

    #[test]
    fn report_parts_are_handed_over_not_copied() {
        let t = tempfile::tempdir().unwrap();
        let (a, b, out) = (t.path().join("a"), t.path().join("b"), t.path().join("out"));
        put(&a, "coco/parts/0-of-2/part.json", b"{}");
        put(&a, "coco/parts/0-of-2/instances_train.json", b"a");
        put(&b, "coco/parts/1-of-2/part.json", b"{}");
        // Without the marker a directory of that name is ordinary output.
        put(&b, "x/parts/0-of-2/file", b"f");
        // A part already in the destination counts, and an identical copy of it is no conflict.
        put(&out, "loc/parts/1-of-2/part.json", b"l1");
        put(&a, "loc/parts/1-of-2/part.json", b"l1");
        let plan = plan_merge(&[a.clone(), b.clone()], &out).unwrap();
        let shard = |index| Shard { index, count: 2 };
        assert_eq!(
            plan.parts,
            [
                ReportParts {
                    report: "coco".into(),
                    parts: [(shard(0), a.join("coco/parts/0-of-2")), (shard(1), b.join("coco/parts/1-of-2"))]
                        .into()
                },
                ReportParts {
                    report: "loc".into(),
                    parts: [(shard(1), out.join("loc/parts/1-of-2"))].into()
                },
            ]
        );
        assert_eq!(plan.holder(Path::new("x/parts/0-of-2/file")), Some(b.join("x/parts/0-of-2/file")));
        assert_eq!(plan.holder(Path::new("coco/parts/0-of-2/part.json")), None);
        let r = plan.apply().unwrap();
        assert_eq!(r.copied, 1);
        assert!(!out.join("coco").exists(), "parts are not copied");
        // Sources inside the destination (a job array's <workdir>/.shards/…) count once, as sources.
        let inner = out.join(".shards/s1");
        put(&inner, "coco/parts/1-of-2/part.json", b"{}");
        let plan = plan_merge(&[a.clone(), inner.clone()], &out).unwrap();
        assert_eq!(plan.parts[0].report, Path::new("coco"));
        assert_eq!(plan.parts[0].parts.len(), 2, "{:?}", plan.parts);
        assert!(plan.parts.iter().all(|p| !p.report.starts_with(".shards")), "{:?}", plan.parts);
        // The same shard's part with other bytes is a conflict.
        put(&b, "coco/parts/0-of-2/part.json", b"{\"other\": 1}");
        let e = plan_merge(&[a, b], &out).unwrap_err();
        assert!(matches!(e, MergeError::PartConflict { .. }), "{e}");
        assert!(e.to_string().contains("shard 0/2"), "{e}");
    }
}
