//! Shared helpers for the integration tests: real-data lookup with the CI rule, running the binary,
//! JSON Schema validation.
#![allow(dead_code)]

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

/// The repository root.
pub fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// Whether we run under CI, where real-data tests must not skip.
pub fn under_ci() -> bool {
    std::env::var("CI").map(|v| v == "true").unwrap_or(false)
}

/// A path under `../shared/data`, or `None` (with a printed reason) when it is absent. Under `CI=true`
/// a missing file is a failure, not a skip.
pub fn shared_data(rel: &str) -> Option<PathBuf> {
    let p = repo().join("../shared/data").join(rel);
    if p.exists() {
        return Some(p);
    }
    if under_ci() {
        panic!("CI=true but the real data {} is missing", p.display());
    }
    eprintln!("skipping: {} is absent", p.display());
    None
}

/// Prints why a check is skipped, or fails under `CI=true`.
pub fn skip(why: &str) {
    if under_ci() {
        panic!("CI=true, but {why}");
    }
    eprintln!("skipping: {why}");
}

/// A file under `../shared/fixtures` (reference vectors), or `None` (with a printed reason) when
/// absent; a failure under `CI=true`.
pub fn shared_fixture(rel: &str) -> Option<PathBuf> {
    let p = repo().join("../shared/fixtures").join(rel);
    if p.exists() {
        return Some(p);
    }
    skip(&format!("{} is absent", p.display()));
    None
}

/// The repository's test fixture `tests/fixtures/<dir>/<name>` (which must exist).
pub fn fixture(dir: &str, name: &str) -> PathBuf {
    let p = repo().join("tests/fixtures").join(dir).join(name);
    assert!(p.exists(), "test fixture {} is missing", p.display());
    p
}

/// The Python of `INSGEN_PYTHON` (default `.venv/bin/python`) if it imports `modules`, else `None`
/// with a printed reason (a failure under `CI=true`).
pub fn python_with(modules: &[&str]) -> Option<PathBuf> {
    let p = std::env::var_os("INSGEN_PYTHON")
        .map(PathBuf::from)
        .unwrap_or_else(|| repo().join(".venv/bin/python"));
    let import = format!("import {}", modules.join(", "));
    let ok = Command::new(&p).args(["-c", &import]).output().map(|o| o.status.success()).unwrap_or(false);
    if ok {
        return Some(p);
    }
    skip(&format!("{} cannot `{import}` (set INSGEN_PYTHON or run scripts/setup.sh)", p.display()));
    None
}

/// Runs `scripts/coco_check.py ARGS` with `py` and parses the JSON it prints.
pub fn coco_check(py: &Path, args: &[&str]) -> serde_json::Value {
    let script = repo().join("scripts/coco_check.py");
    let out = Command::new(py).arg(script).args(args).output().expect("run coco_check.py");
    assert!(out.status.success(), "coco_check.py {args:?} failed:\n{}", String::from_utf8_lossy(&out.stderr));
    serde_json::from_slice(&out.stdout).expect("coco_check.py prints JSON")
}

/// A GLB file from a JSON document and a BIN chunk (the library's one GLB container writer).
pub fn glb(json: &serde_json::Value, bin: &[u8]) -> Vec<u8> {
    insgen::util::glb::container(json, bin).unwrap()
}

/// The building `id` of a source model (panics when absent).
pub fn building<'a>(m: &'a insgen::lod::SourceModel, id: &str) -> &'a insgen::lod::SourceBuilding {
    m.buildings.iter().find(|b| b.source_id == id).unwrap_or_else(|| panic!("no building {id}"))
}

/// A building's polygons (panics for a mesh: the polygon readers never give one).
pub fn polygons(b: &insgen::lod::SourceBuilding) -> &[insgen::lod::Polygon] {
    match &b.geometry {
        insgen::lod::Geometry::Polygons(p) => p,
        insgen::lod::Geometry::Mesh(_) => panic!("{}: expected polygons, read a mesh", b.source_id),
    }
}

/// The message of a read that must fail (panics when it succeeded).
pub fn read_error(r: Result<insgen::lod::SourceModel, insgen::lod::LodError>) -> String {
    match r {
        Ok(m) => panic!("expected an error, read {} buildings", m.buildings.len()),
        Err(e) => e.to_string(),
    }
}

/// Runs `insgen` with `args` in `cwd`; returns its output.
pub fn insgen(cwd: &Path, args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_insgen"))
        .args(args)
        .current_dir(cwd)
        .env("RUST_LOG", "warn")
        .output()
        .expect("the insgen binary runs")
}

pub fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

pub fn stdout(o: &Output) -> String {
    String::from_utf8_lossy(&o.stdout).into_owned()
}

/// Validates a JSON value against a schema file in `schemas/`, panicking with every error.
pub fn assert_schema(schema_file: &str, value: &serde_json::Value) {
    let schema: serde_json::Value = serde_json::from_slice(
        &std::fs::read(repo().join("schemas").join(schema_file)).expect("schema exists"),
    )
    .expect("schema is JSON");
    let validator = jsonschema::validator_for(&schema).expect("schema compiles");
    let errors: Vec<String> =
        validator.iter_errors(value).map(|e| format!("{} at {}", e, e.instance_path)).collect();
    assert!(errors.is_empty(), "{schema_file}: {} errors:\n{}", errors.len(), errors.join("\n"));
}

/// A scratch directory with `scenes/` holding the given scene files (name, TOML text).
pub fn scratch_with_scenes(scenes: &[(&str, String)]) -> tempfile::TempDir {
    let dir = tempfile::tempdir().expect("temp dir");
    std::fs::create_dir_all(dir.path().join("scenes")).unwrap();
    for (name, text) in scenes {
        std::fs::write(dir.path().join("scenes").join(format!("{name}.toml")), text).unwrap();
    }
    dir
}

/// The repository's `scenes/<name>.toml` with its relative source paths made absolute, so it can be
/// prepared from a scratch directory.
pub fn repo_scene(name: &str) -> String {
    let text =
        std::fs::read_to_string(repo().join("scenes").join(format!("{name}.toml"))).expect("scene exists");
    let base = repo().join("scenes");
    text.lines()
        .map(|l| {
            if let Some(rest) = l.strip_prefix("path = \"") {
                let rel = rest.trim_end_matches('"');
                format!("path = \"{}\"", base.join(rel).display())
            } else {
                l.to_string()
            }
        })
        .collect::<Vec<_>>()
        .join("\n")
}

/// Prepares the repository's `scenes/<name>.toml` into `dir` through the library and loads it.
pub fn prepare_repo_scene(name: &str, dir: &Path) -> insgen::scene::PreparedScene {
    let scenes = scratch_with_scenes(&[(name, repo_scene(name))]);
    let file = scenes.path().join("scenes").join(format!("{name}.toml"));
    insgen::scene::prepare::prepare(&file, dir, &insgen::util::NoProgress)
        .unwrap_or_else(|e| panic!("preparing {name}: {e}"));
    insgen::scene::PreparedScene::load(dir).unwrap_or_else(|e| panic!("loading {name}: {e}"))
}

pub use insgen::util::error_chain;

/// The relative paths of the regular files below `root`, read while another process may be
/// writing there: a file or folder renamed or removed between the listing and the look is skipped,
/// not a panic (polling a live export must not race its temporary files).
pub fn live_paths(root: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    let mut stack = vec![root.to_path_buf()];
    while let Some(d) = stack.pop() {
        let Ok(entries) = std::fs::read_dir(&d) else { continue };
        for e in entries.flatten() {
            let p = e.path();
            match e.file_type() {
                Ok(t) if t.is_dir() => stack.push(p),
                Ok(_) => out.push(p.strip_prefix(root).unwrap().to_path_buf()),
                Err(_) => {}
            }
        }
    }
    out.sort();
    out
}

/// Every regular file below `root` (relative path → bytes), for comparing whole output trees.
pub fn tree(root: &Path) -> std::collections::BTreeMap<PathBuf, Vec<u8>> {
    let mut out = std::collections::BTreeMap::new();
    let mut stack = vec![root.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap_or_else(|e| panic!("listing {}: {e}", d.display())) {
            let p = e.unwrap().path();
            if p.is_dir() {
                stack.push(p);
            } else {
                out.insert(p.strip_prefix(root).unwrap().to_path_buf(), std::fs::read(&p).unwrap());
            }
        }
    }
    out
}
