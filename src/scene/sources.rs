//! A source `path` as a list of files: one file, a folder, or a glob pattern.
//!
//! A scene file's `[[sources]] path` (and each argument of `insgen init` and `insgen inspect`) names
//! - **a file**: that file, whatever its name (`format` may say how to read it);
//! - **a folder**: the files inside it a reader takes by their name, recursively, in sorted order: a
//!   folder holding a `tileset.json` is that tileset (its `.b3dm`/`.glb` contents and other JSON are
//!   the tileset's own); otherwise `*.gml` (CityGML), `*.json` (CityJSON; not `tileset*.json` and not
//!   the sidecar of an `.obj` beside it), `*.jsonl` (CityJSONSeq) and `*.obj`, and every sub-folder
//!   holding a `tileset.json` as that tileset. Hidden entries (`.name`) are skipped. `.xml` files are
//!   not taken from folders (PLATEAU's code lists and metadata are XML): name them with a glob;
//! - **a glob** (a path with `*`, `?` or `[`): the files it matches (`*.gml`, `udx/bldg/**/*.gml`),
//!   sorted; a matched folder counts as above; without `format`, only files whose name says how to
//!   read them (`lod::Format::from_path`).
//!
//! Relative paths are taken from a base folder (the scene file's folder, or the working directory on
//! the command line). Files are sorted by path (component by component, bytes within a name: `A.gml`,
//! `a.gml`, `b/10.gml`, `b/2.gml`), so that reruns and other machines read them in the same order
//! whatever the file system lists first. A pattern that matches nothing is an error naming it.

use std::path::{Path, PathBuf};

use crate::lod::Format;
use crate::util::FileError;

/// Why a source path gives no file to read.
#[derive(Debug, thiserror::Error)]
pub enum SourcesError {
    /// The path is neither a file nor a folder, and no glob.
    #[error("{}: does not exist", path.display())]
    Missing {
        /// The path, resolved against the base folder.
        path: PathBuf,
    },
    /// The glob matches nothing.
    #[error("{pattern}: the pattern matches no file")]
    NoMatch {
        /// The pattern, resolved against the base folder.
        pattern: String,
    },
    /// The glob or folder holds files, but none a reader takes by its name.
    #[error(
        "{}: {files} file(s), none of a format insgen reads (first: {}); insgen reads CityGML (.gml, .xml by \
         glob), CityJSON (.json, .jsonl), OBJ (.obj + sidecar) and 3D Tiles (tileset.json)",
        place,
        first.display()
    )]
    NoReadable {
        /// The folder or pattern.
        place: String,
        /// Files seen.
        files: usize,
        /// The first of them.
        first: PathBuf,
    },
    /// The folder is empty.
    #[error("{}: the folder holds no file", folder.display())]
    EmptyFolder {
        /// The folder.
        folder: PathBuf,
    },
    /// The glob is not a valid pattern.
    #[error("{pattern}: not a valid glob pattern")]
    Pattern {
        /// The pattern as given.
        pattern: String,
        /// The glob parser's error.
        #[source]
        source: glob::PatternError,
    },
    /// A folder could not be listed.
    #[error(transparent)]
    File(#[from] FileError),
}

/// Whether a source path is a glob pattern (holds `*`, `?` or `[`).
pub fn is_glob(path: &Path) -> bool {
    path.to_str().is_some_and(|s| s.contains(['*', '?', '[']))
}

/// The files a source path names (see the module doc), sorted; `path` is taken relative to `base`
/// unless absolute. With `format` given, a glob keeps every file it matches, not only those whose
/// name gives their format.
///
/// # Errors
/// [`SourcesError`] naming the path or pattern: missing, matching nothing, matching no readable file,
/// an invalid pattern, an unreadable folder.
pub fn expand(base: &Path, path: &Path, format: Option<Format>) -> Result<Vec<PathBuf>, SourcesError> {
    let full = if path.is_absolute() { path.to_path_buf() } else { base.join(path) };
    if is_glob(path) {
        return expand_glob(base, path, format);
    }
    if full.is_dir() {
        return expand_folder(&full);
    }
    if full.exists() {
        return Ok(vec![full]);
    }
    Err(SourcesError::Missing { path: full })
}

fn expand_glob(base: &Path, path: &Path, format: Option<Format>) -> Result<Vec<PathBuf>, SourcesError> {
    let text = path.to_string_lossy();
    // The base folder is literal text: its own `[` or `*` must not act as pattern characters.
    let pattern = if path.is_absolute() {
        text.to_string()
    } else {
        let base = glob::Pattern::escape(&base.to_string_lossy());
        if base.is_empty() || base == "." {
            text.to_string()
        } else {
            format!("{}/{text}", base.trim_end_matches('/'))
        }
    };
    let matches =
        glob::glob(&pattern).map_err(|source| SourcesError::Pattern { pattern: text.to_string(), source })?;
    let mut files = std::collections::BTreeSet::new();
    let mut seen = Vec::new();
    for m in matches {
        // An entry the walk could not read (permissions): named like any unreadable folder.
        let p = m.map_err(|e| {
            let p = e.path().to_path_buf();
            SourcesError::File(FileError::new("listing", &p, std::io::Error::from(e)))
        })?;
        if p.is_dir() {
            match expand_folder(&p) {
                Ok(inside) => files.extend(inside),
                Err(SourcesError::EmptyFolder { .. } | SourcesError::NoReadable { .. }) => {}
                Err(e) => return Err(e),
            }
        } else if format.is_some() || Format::from_path(&p).is_some() {
            files.insert(p);
        } else {
            seen.push(p);
        }
    }
    if files.is_empty() {
        return Err(match seen.first() {
            Some(first) => {
                SourcesError::NoReadable { place: pattern, files: seen.len(), first: first.clone() }
            }
            None => SourcesError::NoMatch { pattern },
        });
    }
    Ok(files.into_iter().collect())
}

/// The readable files in `folder` (see the module doc), sorted.
fn expand_folder(folder: &Path) -> Result<Vec<PathBuf>, SourcesError> {
    let tileset = folder.join("tileset.json");
    if tileset.is_file() {
        return Ok(vec![tileset]);
    }
    let mut files = Vec::new();
    let mut others = Vec::new();
    walk(folder, &mut files, &mut others)?;
    files.sort();
    if files.is_empty() {
        others.sort();
        return Err(match others.first() {
            Some(first) => SourcesError::NoReadable {
                place: folder.display().to_string(),
                files: others.len(),
                first: first.clone(),
            },
            None => SourcesError::EmptyFolder { folder: folder.to_path_buf() },
        });
    }
    Ok(files)
}

fn walk(dir: &Path, files: &mut Vec<PathBuf>, others: &mut Vec<PathBuf>) -> Result<(), SourcesError> {
    let entries = std::fs::read_dir(dir).map_err(|e| FileError::new("listing", dir, e))?;
    let mut paths: Vec<PathBuf> = Vec::new();
    for e in entries {
        let e = e.map_err(|e| FileError::new("listing", dir, e))?;
        if !e.file_name().to_string_lossy().starts_with('.') {
            paths.push(e.path());
        }
    }
    paths.sort();
    for p in paths {
        if p.is_dir() {
            let tileset = p.join("tileset.json");
            if tileset.is_file() {
                files.push(tileset);
            } else {
                walk(&p, files, others)?;
            }
        } else if taken_from_folder(&p) {
            files.push(p);
        } else {
            others.push(p);
        }
    }
    Ok(())
}

/// Whether a file found in a folder is read as a source (see the module doc).
fn taken_from_folder(p: &Path) -> bool {
    let Some(name) = p.file_name().and_then(|n| n.to_str()) else { return false };
    let lower = name.to_ascii_lowercase();
    if lower.ends_with(".gml") || lower.ends_with(".obj") || lower.ends_with(".jsonl") {
        return true;
    }
    if !lower.ends_with(".json") || lower.starts_with("tileset") {
        return false;
    }
    // The sidecar of an OBJ beside it (`city.obj.json`, or `city.json` next to `city.obj`).
    let sidecar = lower.ends_with(".obj.json")
        || crate::lod::obj::sidecar_candidates(&p.with_extension("obj")).iter().any(|c| c == p)
            && p.with_extension("obj").is_file();
    !sidecar
}

#[cfg(test)]
mod tests {
    use super::*;

    fn touch(root: &Path, rel: &str) {
        let p = root.join(rel);
        std::fs::create_dir_all(p.parent().unwrap()).unwrap();
        std::fs::write(p, b"x").unwrap();
    }

    fn rel(root: &Path, files: &[PathBuf]) -> Vec<String> {
        files.iter().map(|f| f.strip_prefix(root).unwrap().to_string_lossy().replace('\\', "/")).collect()
    }

    mod folders {
        use super::*;

        #[test]
        fn readable_files_recursively_in_path_order() {
            let d = tempfile::tempdir().unwrap();
            for f in [
                "b/2.gml",
                "b/10.gml",
                "a.city.json",
                "A.gml",
                "codelists/Building_class.xml",
                "tex/wall.png",
                ".hidden/x.gml",
                "seq.jsonl",
                "m.obj",
                "m.json",
                "n.obj.json",
                "tiles/tileset.json",
                "tiles/0.b3dm",
                "tileset_extra.json",
            ] {
                touch(d.path(), f);
            }
            let got = expand(d.path(), Path::new("."), None).unwrap();
            assert_eq!(
                rel(d.path(), &got),
                ["A.gml", "a.city.json", "b/10.gml", "b/2.gml", "m.obj", "seq.jsonl", "tiles/tileset.json"]
            );
            // Twice the same list: no dependence on the file system's listing order.
            assert_eq!(expand(d.path(), Path::new("."), None).unwrap(), got);
        }

        #[test]
        fn a_folder_with_a_tileset_is_that_tileset() {
            let d = tempfile::tempdir().unwrap();
            for f in ["tileset.json", "tileset_other.json", "data/1.b3dm", "data/2.glb"] {
                touch(d.path(), f);
            }
            assert_eq!(expand(d.path(), Path::new(""), None).unwrap(), [d.path().join("tileset.json")]);
        }

        #[test]
        fn empty_or_unreadable_folders_are_errors_naming_them() {
            let d = tempfile::tempdir().unwrap();
            std::fs::create_dir(d.path().join("empty")).unwrap();
            let e = expand(d.path(), Path::new("empty"), None).unwrap_err();
            assert!(matches!(&e, SourcesError::EmptyFolder { folder } if folder.ends_with("empty")), "{e}");
            touch(d.path(), "pics/a.png");
            let e = expand(d.path(), Path::new("pics"), None).unwrap_err().to_string();
            assert!(
                e.contains("pics: 1 file(s), none of a format insgen reads") && e.contains("a.png"),
                "{e}"
            );
            let e = expand(d.path(), Path::new("nowhere"), None).unwrap_err().to_string();
            assert!(e.ends_with("nowhere: does not exist"), "{e}");
        }
    }

    mod globs {
        use super::*;

        #[test]
        fn star_and_double_star_in_path_order() {
            let d = tempfile::tempdir().unwrap();
            for f in ["udx/bldg/b.gml", "udx/bldg/a.gml", "udx/bldg/sub/c.gml", "udx/tran/t.gml", "x.gml"] {
                touch(d.path(), f);
            }
            let got = expand(d.path(), Path::new("udx/bldg/*.gml"), None).unwrap();
            assert_eq!(rel(d.path(), &got), ["udx/bldg/a.gml", "udx/bldg/b.gml"]);
            let got = expand(d.path(), Path::new("**/*.gml"), None).unwrap();
            assert_eq!(
                rel(d.path(), &got),
                ["udx/bldg/a.gml", "udx/bldg/b.gml", "udx/bldg/sub/c.gml", "udx/tran/t.gml", "x.gml"]
            );
            // Absolute patterns too.
            let abs = d.path().join("udx/*/t.gml");
            assert_eq!(
                expand(Path::new("/elsewhere"), &abs, None).unwrap(),
                [d.path().join("udx/tran/t.gml")]
            );
        }

        #[test]
        fn a_base_folder_with_pattern_characters_is_literal() {
            let d = tempfile::tempdir().unwrap();
            let base = d.path().join("city [2024]");
            touch(&base, "a.gml");
            assert_eq!(expand(&base, Path::new("*.gml"), None).unwrap(), [base.join("a.gml")]);
        }

        #[test]
        fn names_without_a_format_need_format() {
            let d = tempfile::tempdir().unwrap();
            touch(d.path(), "a.txt");
            let e = expand(d.path(), Path::new("*.txt"), None).unwrap_err().to_string();
            assert!(e.contains("none of a format insgen reads"), "{e}");
            assert_eq!(expand(d.path(), Path::new("*.txt"), Some(Format::CityGml)).unwrap().len(), 1);
        }

        #[test]
        fn no_match_and_bad_patterns_name_the_pattern() {
            let d = tempfile::tempdir().unwrap();
            let e = expand(d.path(), Path::new("*.gml"), None).unwrap_err();
            assert!(matches!(&e, SourcesError::NoMatch { pattern } if pattern.ends_with("/*.gml")), "{e}");
            assert!(e.to_string().ends_with("*.gml: the pattern matches no file"), "{e}");
            let e = expand(d.path(), Path::new("a/***/b[.gml"), None).unwrap_err();
            assert!(matches!(e, SourcesError::Pattern { .. }), "{e}");
        }
    }
}
