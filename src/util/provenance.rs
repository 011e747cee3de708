//! Where a dataset came from: the tool's version and commit, and the log of the commands run in a
//! workdir.
//!
//! Every `insgen` command that works in a workdir appends one line to `<workdir>/commands.jsonl`
//! ([`CommandRecord`]: the command line as typed, whether it succeeded, how long it took). The line is
//! written with one `write` on a file opened for appending, so processes working in parallel (shards of
//! a job array) never interleave within a line. `export-coco` copies the log into the dataset manifest,
//! so a dataset says exactly which commands, seeds and options made it.

use std::io::Write;
use std::path::Path;

use serde::{Deserialize, Serialize};

use super::FileError;

/// The insgen version.
pub const VERSION: &str = env!("CARGO_PKG_VERSION");

/// The git commit the binary was built from (`-dirty` if tracked files had changes), or `unknown`.
pub const GIT_COMMIT: &str = env!("INSGEN_GIT_COMMIT");

/// File name of the command log in a workdir.
pub use crate::layout::COMMANDS_FILE;

/// One command run in a workdir.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CommandRecord {
    /// The command line, program name first.
    pub argv: Vec<String>,
    /// The subcommand (`prepare`, `render-masks`, …).
    pub command: String,
    /// Whether it succeeded.
    pub ok: bool,
    /// Wall-clock seconds.
    pub seconds: f64,
    /// insgen's version and commit.
    pub insgen_version: String,
    /// The commit insgen was built from (empty when unknown).
    pub git_commit: String,
}

/// Appends `record` to `<workdir>/commands.jsonl` (creating the workdir when needed).
///
/// # Errors
/// [`FileError`] naming the log when it cannot be written.
pub fn append_command(workdir: &Path, record: &CommandRecord) -> Result<(), FileError> {
    let path = workdir.join(COMMANDS_FILE);
    super::create_dir_all(workdir)?;
    let mut line = serde_json::to_vec(record)
        .map_err(|e| FileError::new("serialising", &path, std::io::Error::other(e)))?;
    line.push(b'\n');
    let mut f = std::fs::OpenOptions::new()
        .create(true)
        .append(true)
        .open(&path)
        .map_err(|e| FileError::new("opening", &path, e))?;
    f.write_all(&line).map_err(|e| FileError::new("appending to", &path, e))
}

/// The commands logged in `workdir`, oldest first; lines that do not parse are skipped (the log is
/// provenance, never an input of a stage).
pub fn read_commands(workdir: &Path) -> Vec<CommandRecord> {
    let Ok(text) = std::fs::read_to_string(workdir.join(COMMANDS_FILE)) else { return Vec::new() };
    text.lines().filter_map(|l| serde_json::from_str(l).ok()).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn records_are_appended_and_read_back_in_order() {
        let dir = tempfile::tempdir().unwrap();
        let rec = |c: &str| CommandRecord {
            argv: vec!["insgen".into(), c.into()],
            command: c.into(),
            ok: true,
            seconds: 1.5,
            insgen_version: VERSION.into(),
            git_commit: GIT_COMMIT.into(),
        };
        append_command(dir.path(), &rec("prepare")).unwrap();
        append_command(dir.path(), &rec("sample")).unwrap();
        std::fs::OpenOptions::new()
            .append(true)
            .open(dir.path().join(COMMANDS_FILE))
            .unwrap()
            .write_all(b"{broken\n")
            .unwrap();
        let back = read_commands(dir.path());
        assert_eq!(back, vec![rec("prepare"), rec("sample")]);
        assert!(!GIT_COMMIT.is_empty());
    }
}
