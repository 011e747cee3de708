//! Small shared helpers: atomic file output, progress reporting, hashing, the error chain, (in
//! [`math`]) the median and point-in-polygon test, and (in [`figure`]) the text, charts and legends of
//! every figure a stage draws.
//!
//! Every stage writes its files through [`write_atomic`], so an interrupted or failed run never leaves a
//! half-written file behind, and reports long work through the [`Progress`] trait, which the CLI
//! implements with indicatif and tests implement with [`NoProgress`].

pub mod math;

pub use math::{convex_hull, median, point_in_polygon};

use std::fs;
use std::io::{self, Write};
use std::path::{Path, PathBuf};

pub mod figure;
pub mod glb;
pub mod interrupt;
pub mod merge;
pub mod provenance;
pub mod row_major;
pub mod shard;
pub use shard::{Scheduler, Shard, ShardError, ShardSpec};

/// An I/O error that names the file it happened on.
#[derive(Debug, thiserror::Error)]
#[error("{action} {}", path.display())]
pub struct FileError {
    /// What was being done ("writing", "reading", "creating directory").
    pub action: &'static str,
    /// The file or directory concerned.
    pub path: PathBuf,
    /// The I/O error.
    #[source]
    pub source: io::Error,
}

impl FileError {
    /// A [`FileError`]: `action` ("reading", …) failed on `path` with `source`.
    pub fn new(action: &'static str, path: &Path, source: io::Error) -> Self {
        Self { action, path: path.to_path_buf(), source }
    }
}

/// Reads a whole file, naming it in the error.
pub fn read_file(path: &Path) -> Result<Vec<u8>, FileError> {
    fs::read(path).map_err(|e| FileError::new("reading", path, e))
}

/// Creates a directory and its parents, naming it in the error.
pub fn create_dir_all(path: &Path) -> Result<(), FileError> {
    fs::create_dir_all(path).map_err(|e| FileError::new("creating directory", path, e))
}

/// Writes a file atomically: the content goes to a temporary file in the same directory, which is
/// flushed, synced and then renamed over `path`. If `fill` fails, the temporary file is removed and
/// `path` is left as it was.
///
/// # Errors
/// Any I/O error (naming `path`), or the error returned by `fill`.
pub fn write_atomic<E, F>(path: &Path, fill: F) -> Result<(), E>
where
    E: From<FileError>,
    F: FnOnce(&mut io::BufWriter<&mut fs::File>) -> Result<(), E>,
{
    let dir = match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => PathBuf::from("."),
    };
    create_dir_all(&dir)?;
    let mut tmp =
        locked_tempfile_in(&dir).map_err(|e| FileError::new("creating a temporary file for", path, e))?;
    {
        let mut w = io::BufWriter::new(tmp.as_file_mut());
        fill(&mut w)?;
        w.flush().map_err(|e| FileError::new("writing", path, e))?;
    }
    tmp.as_file().sync_all().map_err(|e| FileError::new("syncing", path, e))?;
    // tempfile creates 0600 files; outputs are data for others to read, so give them the usual 0644.
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        tmp.as_file()
            .set_permissions(fs::Permissions::from_mode(0o644))
            .map_err(|e| FileError::new("setting permissions of", path, e))?;
    }
    tmp.persist(path).map_err(|e| FileError::new("renaming into place", path, e.error))?;
    Ok(())
}

/// Prefix of every temporary file insgen writes next to its outputs (`.insgen-tmp-*`).
pub const TMP_PREFIX: &str = ".insgen-tmp-";

/// A new temporary file `<dir>/.insgen-tmp-XXXXXX`, exclusively locked (`flock`) for as long as it is
/// open (on Unix; elsewhere unlocked, and a concurrent cleanup could remove it), so that [`remove_stale_temps`] in another process can tell it from the leftover of a killed
/// run: the kernel drops the lock when its process dies, SIGKILL included.
///
/// # Errors
/// I/O errors creating or locking the file.
pub fn locked_tempfile_in(dir: &Path) -> io::Result<tempfile::NamedTempFile> {
    // A cleaner may take the file for stale between its creation and our lock, and unlink it; the
    // locked inode then has no link left, and we start again with a new name.
    for _ in 0..8 {
        let tmp = tempfile::Builder::new().prefix(TMP_PREFIX).tempfile_in(dir)?;
        flock_exclusive(tmp.as_file(), true)?;
        if linked(tmp.as_file())? {
            return Ok(tmp);
        }
    }
    Err(io::Error::other(format!(
        "temporary files in {} keep disappearing (another process removing them?)",
        dir.display()
    )))
}

/// Takes an exclusive `flock` on `f` (waiting for it if `wait`); `Ok(false)`: another process holds
/// it. (`File::lock` would do, but needs Rust 1.89; our MSRV is 1.88.)
#[cfg(unix)]
fn flock_exclusive(f: &fs::File, wait: bool) -> io::Result<bool> {
    use std::os::unix::io::AsRawFd;
    let op = libc::LOCK_EX | if wait { 0 } else { libc::LOCK_NB };
    loop {
        // SAFETY: flock on a descriptor `f` owns and keeps open for the call.
        if unsafe { libc::flock(f.as_raw_fd(), op) } == 0 {
            return Ok(true);
        }
        let e = io::Error::last_os_error();
        match e.raw_os_error() {
            Some(libc::EWOULDBLOCK) => return Ok(false),
            Some(libc::EINTR) => continue,
            _ => return Err(e),
        }
    }
}

#[cfg(not(unix))]
fn flock_exclusive(_f: &fs::File, _wait: bool) -> io::Result<bool> {
    Ok(true)
}

#[cfg(unix)]
fn linked(f: &fs::File) -> io::Result<bool> {
    use std::os::unix::fs::MetadataExt;
    Ok(f.metadata()?.nlink() > 0)
}

#[cfg(not(unix))]
fn linked(_f: &fs::File) -> io::Result<bool> {
    Ok(true)
}

/// Removes the temporary files (`.insgen-tmp-*`) that killed runs left in `dir` and, if `recursive`,
/// below it; returns how many. A file still locked by a live writer ([`locked_tempfile_in`]) is left
/// alone, and so is any whose name `keep` accepts (another shard's Blender output, which Blender writes
/// without a lock). Stages call this on their output directories before they start, so that a rerun
/// after SIGKILL leaves exactly the files of an uninterrupted run.
///
/// # Errors
/// Listing `dir` (a missing `dir` is no error) or removing a stale file, naming the path.
pub fn remove_stale_temps(
    dir: &Path,
    recursive: bool,
    keep: &dyn Fn(&str) -> bool,
) -> Result<usize, FileError> {
    let entries = match fs::read_dir(dir) {
        Ok(e) => e,
        Err(e) if e.kind() == io::ErrorKind::NotFound => return Ok(0),
        Err(e) => return Err(FileError::new("listing", dir, e)),
    };
    let mut removed = 0;
    for entry in entries {
        let entry = entry.map_err(|e| FileError::new("listing", dir, e))?;
        let path = entry.path();
        let Ok(kind) = entry.file_type() else { continue };
        let name = entry.file_name().to_string_lossy().into_owned();
        if kind.is_dir() {
            if recursive {
                removed += remove_stale_temps(&path, true, keep)?;
            }
            continue;
        }
        if !kind.is_file() || !name.starts_with(TMP_PREFIX) || keep(&name) {
            continue;
        }
        let Ok(f) = fs::File::open(&path) else { continue }; // gone meanwhile
        match flock_exclusive(&f, false) {
            Ok(true) => {}
            Ok(false) => continue, // a live writer
            Err(e) => return Err(FileError::new("locking", &path, e)),
        }
        // The name may have been renamed into place, or reused, since we opened it.
        if !same_file(&f, &path) {
            continue;
        }
        match fs::remove_file(&path) {
            Ok(()) => {
                log::info!("removed {} (left by an interrupted run)", path.display());
                removed += 1;
            }
            Err(e) if e.kind() == io::ErrorKind::NotFound => {}
            Err(e) => return Err(FileError::new("removing the stale temporary file", &path, e)),
        }
    }
    Ok(removed)
}

#[cfg(unix)]
fn same_file(f: &fs::File, path: &Path) -> bool {
    use std::os::unix::fs::MetadataExt;
    match (f.metadata(), fs::symlink_metadata(path)) {
        (Ok(a), Ok(b)) => a.dev() == b.dev() && a.ino() == b.ino(),
        _ => false,
    }
}

#[cfg(not(unix))]
fn same_file(_f: &fs::File, path: &Path) -> bool {
    path.exists()
}

/// Writes `bytes` to `path` atomically (see [`write_atomic`]).
pub fn write_bytes_atomic(path: &Path, bytes: &[u8]) -> Result<(), FileError> {
    write_atomic(path, |w| w.write_all(bytes).map_err(|e| FileError::new("writing", path, e)))
}

/// How [`link_or_copy`] placed a file.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Placed {
    /// `dst` was already `src` (the same inode) or held the same bytes: nothing was written.
    Kept,
    /// `dst` is now a hard link to `src` (no space taken).
    Linked,
    /// `dst` is now a copy of `src`: the file system refused the link (another file system, EXDEV, or
    /// one without hard links).
    Copied,
}

impl Placed {
    /// Whether `dst` was (re)written.
    pub fn written(self) -> bool {
        self != Placed::Kept
    }
}

/// Places the file `src` at `dst`: a hard link where the file system allows one, else a copy, made
/// under a temporary name and renamed into place (atomic like every other output). A `dst` that is
/// already `src` (the same inode) or holds the same bytes is kept, so reruns touch nothing. Returns
/// how the file was placed.
///
/// # Errors
/// Reading `src` (a missing `src` included), or writing `dst`, naming the file.
pub fn link_or_copy(src: &Path, dst: &Path) -> Result<Placed, FileError> {
    link_or_copy_with(src, dst, &|from, to| fs::hard_link(from, to))
}

/// [`link_or_copy`] with the link operation given (`link(src, tmp)`), so that tests can make it fail as
/// a link across file systems does. Any error of `link` leads to a copy: the link is an optimisation,
/// and whatever refuses it (EXDEV, EPERM on file systems without links, EMLINK) leaves the copy to do.
fn link_or_copy_with(
    src: &Path,
    dst: &Path,
    link: &dyn Fn(&Path, &Path) -> io::Result<()>,
) -> Result<Placed, FileError> {
    let src_meta = fs::metadata(src).map_err(|e| FileError::new("reading", src, e))?;
    if let Ok(dst_meta) = fs::metadata(dst) {
        if same_inode(&src_meta, &dst_meta)
            || (dst_meta.len() == src_meta.len() && read_file(dst)? == read_file(src)?)
        {
            return Ok(Placed::Kept);
        }
    }
    let dir = match dst.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => PathBuf::from("."),
    };
    create_dir_all(&dir)?;
    let name = dst.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
    // One temporary name per destination: files of one folder are placed in parallel.
    let tmp = dir.join(format!("{TMP_PREFIX}link-{name}"));
    let _ = fs::remove_file(&tmp);
    match link(src, &tmp) {
        Ok(()) => {
            fs::rename(&tmp, dst).map_err(|e| FileError::new("renaming into place", dst, e))?;
            return Ok(Placed::Linked);
        }
        Err(e) => log::debug!("linking {} to {}: {e}; copying instead", src.display(), dst.display()),
    }
    // Another file system (or one without links): a copy.
    let _ = fs::remove_file(&tmp);
    write_atomic(dst, |w| {
        let mut f = fs::File::open(src).map_err(|e| FileError::new("reading", src, e))?;
        // A failed copy is named by its destination: that is where the disk is full or read-only.
        io::copy(&mut f, w).map_err(|e| FileError::new("copying into", dst, e))?;
        Ok::<(), FileError>(())
    })?;
    Ok(Placed::Copied)
}

#[cfg(unix)]
fn same_inode(a: &fs::Metadata, b: &fs::Metadata) -> bool {
    use std::os::unix::fs::MetadataExt;
    a.dev() == b.dev() && a.ino() == b.ino()
}

#[cfg(not(unix))]
fn same_inode(_a: &fs::Metadata, _b: &fs::Metadata) -> bool {
    false
}

/// Serialises `value` as pretty JSON (with a trailing newline) and writes it atomically.
pub fn write_json_atomic<T: serde::Serialize>(path: &Path, value: &T) -> Result<(), FileError> {
    let mut bytes = serde_json::to_vec_pretty(value)
        .map_err(|e| FileError::new("serialising JSON for", path, io::Error::other(e)))?;
    bytes.push(b'\n');
    write_bytes_atomic(path, &bytes)
}

/// Stable 64-bit FNV-1a of a string, starting from the FNV offset basis XORed with `seed`: the same
/// value on every run and platform (unlike `std`'s hashers), for seeds derived from names (a frame's
/// prior and degradations, an area's look). `seed` 0 gives plain FNV-1a.
pub fn fnv1a_seeded(seed: u64, s: &str) -> u64 {
    s.bytes().fold(0xcbf2_9ce4_8422_2325 ^ seed, |h, b| (h ^ b as u64).wrapping_mul(0x0100_0000_01b3))
}

/// Hex SHA-256 of a file's content, for provenance in manifests.
pub fn sha256_file(path: &Path) -> Result<String, FileError> {
    use sha2::{Digest, Sha256};
    let mut f = fs::File::open(path).map_err(|e| FileError::new("opening", path, e))?;
    let mut h = Sha256::new();
    io::copy(&mut f, &mut h).map_err(|e| FileError::new("reading", path, e))?;
    Ok(hex::encode(h.finalize()))
}

/// An error and its causes on one line (`a: b: c`), as `main` prints them: for logs and for lists of
/// failures that cannot all be sources.
pub fn error_chain(e: &dyn std::error::Error) -> String {
    let mut s = e.to_string();
    let mut cur = e.source();
    while let Some(c) = cur {
        s.push_str(": ");
        s.push_str(&c.to_string());
        cur = c.source();
    }
    s
}

/// Progress reporting for long work. The CLI implements it with an indicatif bar on stderr; library
/// callers and tests use [`NoProgress`].
pub trait Progress: Sync {
    /// Work of `len` items starts; `what` names it ("frames", "tiles").
    fn start(&self, len: u64, what: &str);
    /// `n` more items are done.
    fn inc(&self, n: u64);
    /// Free-form status shown beside the bar (e.g. running recall).
    fn message(&self, _msg: &str) {}
    /// The work is over.
    fn finish(&self);
}

/// A [`Progress`] that shows nothing.
pub struct NoProgress;

impl Progress for NoProgress {
    fn start(&self, _len: u64, _what: &str) {}
    fn inc(&self, _n: u64) {}
    fn finish(&self) {}
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fnv1a_is_stable_and_the_seed_changes_it() {
        // FNV-1a 64 of "a" = 0xaf63dc4c8601ec8c (published test vector).
        assert_eq!(fnv1a_seeded(0, "a"), 0xaf63_dc4c_8601_ec8c);
        assert_eq!(fnv1a_seeded(0, ""), 0xcbf2_9ce4_8422_2325);
        assert_ne!(fnv1a_seeded(1, "a"), fnv1a_seeded(0, "a"));
        assert_ne!(fnv1a_seeded(0, "demo_cam2_00001_0000"), fnv1a_seeded(0, "tokyo_cam2_00001_0000"));
    }

    #[test]
    fn atomic_write_leaves_nothing_on_failure() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("out.json");
        let r: Result<(), anyhow::Error> = write_atomic(&path, |w| {
            w.write_all(b"half").unwrap();
            anyhow::bail!("boom")
        });
        assert!(r.is_err());
        assert!(!path.exists());
        assert_eq!(fs::read_dir(dir.path()).unwrap().count(), 0, "temporary file left behind");
    }

    #[test]
    fn stale_temps_go_and_live_ones_stay() {
        let dir = tempfile::tempdir().unwrap();
        let d = dir.path();
        fs::create_dir(d.join("sub")).unwrap();
        // Left by killed runs: no lock held.
        fs::write(d.join(".insgen-tmp-abc123"), b"half").unwrap();
        fs::write(d.join("sub/.insgen-tmp-def456"), b"half").unwrap();
        fs::write(d.join(".insgen-tmp-f1.png"), b"blender").unwrap();
        fs::write(d.join(".insgen-tmp-f2.png"), b"another shard's").unwrap();
        fs::write(d.join("f0.png"), b"done").unwrap();
        // Being written by a live process (this one).
        let live = locked_tempfile_in(d).unwrap();
        let keep = |n: &str| n == ".insgen-tmp-f2.png";
        assert_eq!(remove_stale_temps(d, false, &keep).unwrap(), 2);
        assert!(d.join("sub/.insgen-tmp-def456").exists(), "not recursive");
        assert_eq!(remove_stale_temps(d, true, &keep).unwrap(), 1);
        let mut left: Vec<String> =
            fs::read_dir(d).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into_owned()).collect();
        left.sort();
        let live_name = live.path().file_name().unwrap().to_string_lossy().into_owned();
        let mut want = vec![".insgen-tmp-f2.png".to_string(), "f0.png".into(), "sub".into(), live_name];
        want.sort();
        assert_eq!(left, want);
        // Once its writer is gone, the live one is stale too.
        drop(live);
        assert_eq!(remove_stale_temps(d, true, &|_| false).unwrap(), 1);
        assert_eq!(remove_stale_temps(&d.join("missing"), true, &|_| false).unwrap(), 0);
    }

    #[test]
    fn atomic_write_replaces_content() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("a/b/out.txt");
        write_bytes_atomic(&path, b"one").unwrap();
        write_bytes_atomic(&path, b"two").unwrap();
        assert_eq!(fs::read(&path).unwrap(), b"two");
    }

    #[test]
    fn link_or_copy_links_keeps_identical_files_and_replaces_others() {
        let dir = tempfile::tempdir().unwrap();
        let src = dir.path().join("src.png");
        fs::write(&src, b"pixels").unwrap();
        let dst = dir.path().join("out/a/dst.png");
        assert_eq!(link_or_copy(&src, &dst).unwrap(), Placed::Linked, "first placement links");
        assert_eq!(fs::read(&dst).unwrap(), b"pixels");
        #[cfg(unix)]
        {
            use std::os::unix::fs::MetadataExt;
            assert_eq!(fs::metadata(&src).unwrap().ino(), fs::metadata(&dst).unwrap().ino(), "a hard link");
        }
        assert_eq!(link_or_copy(&src, &dst).unwrap(), Placed::Kept, "the same file is kept");
        fs::write(src.with_extension("new"), b"other").unwrap();
        fs::rename(src.with_extension("new"), &src).unwrap();
        assert_eq!(link_or_copy(&src, &dst).unwrap(), Placed::Linked, "other bytes are replaced");
        assert_eq!(fs::read(&dst).unwrap(), b"other");
        let names: Vec<_> =
            fs::read_dir(dst.parent().unwrap()).unwrap().map(|e| e.unwrap().file_name()).collect();
        assert_eq!(names, ["dst.png"], "no temporary file left");
        assert!(link_or_copy(&dir.path().join("missing"), &dst).is_err());
    }

    /// A link that fails as `link(2)` does across file systems (EXDEV, "Invalid cross-device link").
    #[cfg(unix)]
    fn cross_device(_from: &Path, _to: &Path) -> io::Result<()> {
        Err(io::Error::from_raw_os_error(libc::EXDEV))
    }

    #[cfg(not(unix))]
    fn cross_device(_from: &Path, _to: &Path) -> io::Result<()> {
        Err(io::Error::new(io::ErrorKind::CrossesDevices, "cross-device link"))
    }

    #[test]
    fn a_refused_link_falls_back_to_a_copy_of_its_own() {
        let dir = tempfile::tempdir().unwrap();
        let src = dir.path().join("src.png");
        let bytes: Vec<u8> = (0..70_000u32).map(|i| (i * 7 % 251) as u8).collect();
        fs::write(&src, &bytes).unwrap();
        let dst = dir.path().join("export/images/dst.png");
        assert_eq!(link_or_copy_with(&src, &dst, &cross_device).unwrap(), Placed::Copied);
        assert_eq!(fs::read(&dst).unwrap(), bytes, "the copy holds the same bytes");
        #[cfg(unix)]
        {
            use std::os::unix::fs::{MetadataExt, PermissionsExt};
            let (a, b) = (fs::metadata(&src).unwrap(), fs::metadata(&dst).unwrap());
            assert_ne!((a.dev(), a.ino()), (b.dev(), b.ino()), "a copy, not a link");
            assert_eq!(a.nlink(), 1, "the source gained no link");
            assert_eq!(b.permissions().mode() & 0o777, 0o644, "readable like every other output");
        }
        let names: Vec<_> =
            fs::read_dir(dst.parent().unwrap()).unwrap().map(|e| e.unwrap().file_name()).collect();
        assert_eq!(names, ["dst.png"], "no temporary file left");
        // A rerun keeps the identical copy (same bytes, another inode), with or without links.
        assert_eq!(link_or_copy_with(&src, &dst, &cross_device).unwrap(), Placed::Kept);
        assert_eq!(link_or_copy(&src, &dst).unwrap(), Placed::Kept);
        // Changed bytes replace the copy, again by copying.
        fs::write(&src, b"other").unwrap();
        assert_eq!(link_or_copy_with(&src, &dst, &cross_device).unwrap(), Placed::Copied);
        assert_eq!(fs::read(&dst).unwrap(), b"other");
        assert!(Placed::Copied.written() && Placed::Linked.written() && !Placed::Kept.written());
    }
}
