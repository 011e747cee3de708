//! Small shared helpers: atomic file output, progress reporting, hashing, the error chain, and (in
//! [`math`]) the median and point-in-polygon test.
//!
//! Every stage writes its files through [`write_atomic`], so an interrupted or failed run never leaves a
//! half-written file behind, and reports long work through the [`Progress`] trait, which the CLI
//! implements with indicatif and tests implement with [`NoProgress`].

pub mod math;

pub use math::{median, point_in_polygon};

use std::fs;
use std::io::{self, Write};
use std::path::{Path, PathBuf};

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
    #[source]
    pub source: io::Error,
}

impl FileError {
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
    let mut tmp = tempfile::Builder::new()
        .prefix(".insgen-tmp-")
        .tempfile_in(&dir)
        .map_err(|e| FileError::new("creating a temporary file for", path, e))?;
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

/// Writes `bytes` to `path` atomically (see [`write_atomic`]).
pub fn write_bytes_atomic(path: &Path, bytes: &[u8]) -> Result<(), FileError> {
    write_atomic(path, |w| w.write_all(bytes).map_err(|e| FileError::new("writing", path, e)))
}

/// Serialises `value` as pretty JSON (with a trailing newline) and writes it atomically.
pub fn write_json_atomic<T: serde::Serialize>(path: &Path, value: &T) -> Result<(), FileError> {
    let mut bytes = serde_json::to_vec_pretty(value)
        .map_err(|e| FileError::new("serialising JSON for", path, io::Error::other(e)))?;
    bytes.push(b'\n');
    write_bytes_atomic(path, &bytes)
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
    fn atomic_write_replaces_content() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("a/b/out.txt");
        write_bytes_atomic(&path, b"one").unwrap();
        write_bytes_atomic(&path, b"two").unwrap();
        assert_eq!(fs::read(&path).unwrap(), b"two");
    }
}
