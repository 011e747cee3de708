//! Issue 19, item 5: crash safety. `render-masks`, `render-rgb` and `export-coco` killed with SIGKILL
//! at seeded pseudo-random points and run again leave exactly the files of an uninterrupted run, byte
//! for byte, and no temporary file (`.insgen-tmp-*`); a full disk or an unusable output directory
//! gives an error naming the file and leaves no partial output.
//!
//! How a kill lands mid-work: the test polls the output directory and sends SIGKILL once k more
//! frames (k drawn from a seeded generator) are complete, after a further drawn delay of 0–40 ms, so
//! kills fall inside a frame as well as between frames. A kill that comes after the process ended
//! fails the test: it would test nothing. Each kill is followed by a rerun that is killed again, and
//! the last rerun completes.
//!
//! What the comparison leaves out, and why (nothing else is excluded):
//! - `runs/commands.jsonl`, the command log: it records every command with its duration and outcome,
//!   the killed ones too (as started and never finished), so it differs between any two workdirs;
//! - `coco/dataset.json`'s `commands` and the card (`coco/README.md`), which quote that log;
//! - render-rgb's `<camera>/blender/` working directory (the job files handed to Blender): each job
//!   lists the frames left to render, which depends on where the kills landed.
//!
//! Full disk: as root (which `chmod` does not stop) the output directory is a 64 KiB tmpfs filled up
//! to the last block, so writes fail with ENOSPC; as another user the directory is made read-only
//! instead. In both cases an output path whose parent is a regular file is tried too (ENOTDIR).
//! render-rgb is killed but not run on a full disk (its writes go through the same `write_atomic`).

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use crate::util::{insgen, repo_scene, scratch_with_scenes, stderr};

/// A scratch directory with the demo area prepared and `count` grid poses of a `width`×`height`
/// camera named `crash` (cam2's field of view).
fn demo_with_poses(count: u32, width_px: u32, height_px: u32) -> tempfile::TempDir {
    let dir = scratch_with_scenes(&[("demo", repo_scene("demo"))]);
    let run = |args: &[&str]| {
        let o = insgen(dir.path(), args);
        assert!(o.status.success(), "{args:?}: {}", stderr(&o));
    };
    run(&["prepare", "--area", "demo"]);
    std::fs::write(
        dir.path().join("crash.toml"),
        format!(
            "name = \"crash\"\nwidth_px = {width_px}\nheight_px = {height_px}\nsensor_width_mm = 6.4\n\
             sensor_height_mm = 3.6\nhfov_deg = 25.0\nstrategy = \"grid\"\n"
        ),
    )
    .unwrap();
    run(&["sample", "--area", "demo", "--camera", "crash.toml", "--count", &count.to_string()]);
    dir
}

/// xorshift64*: the kill points, reproducible from the seed printed on failure.
struct Draws(u64);

impl Draws {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_f491_4f6c_dd1d)
    }
    /// In `lo..=hi`.
    fn between(&mut self, lo: u64, hi: u64) -> u64 {
        lo + self.next() % (hi - lo + 1)
    }
}

fn count_files(dir: &Path, suffix: &str) -> usize {
    std::fs::read_dir(dir)
        .map(|r| {
            r.filter_map(|e| e.ok())
                .filter(|e| {
                    let n = e.file_name().to_string_lossy().into_owned();
                    n.ends_with(suffix) && !n.starts_with(".insgen-tmp-")
                })
                .count()
        })
        .unwrap_or(0)
}

/// Every `.insgen-tmp-*` file below `root`.
fn temp_files(root: &Path) -> Vec<PathBuf> {
    if !root.exists() {
        return Vec::new();
    }
    crate::util::tree(root)
        .into_keys()
        .filter(|p| p.file_name().is_some_and(|n| n.to_string_lossy().starts_with(".insgen-tmp-")))
        .collect()
}

/// Runs `args` in `cwd` and SIGKILLs it once `done()` has grown by `k` and `extra_ms` more have
/// passed. Returns `done()` at the kill.
fn kill_after(cwd: &Path, args: &[String], done: &dyn Fn() -> usize, k: usize, extra_ms: u64) -> usize {
    let before = done();
    let mut child = Command::new(env!("CARGO_BIN_EXE_insgen"))
        .args(args)
        .current_dir(cwd)
        .env("RUST_LOG", "warn")
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .expect("insgen starts");
    let started = Instant::now();
    while done() < before + k {
        assert!(started.elapsed() < Duration::from_secs(300), "{args:?}: no progress within 5 minutes");
        if let Some(status) = child.try_wait().unwrap() {
            panic!("{args:?} ended ({status}) before the kill after {k} more item(s): nothing tested");
        }
        std::thread::sleep(Duration::from_millis(5));
    }
    std::thread::sleep(Duration::from_millis(extra_ms));
    assert!(
        child.try_wait().unwrap().is_none(),
        "{args:?} ended before the kill {extra_ms} ms after {k} more item(s): nothing tested"
    );
    child.kill().expect("SIGKILL"); // Child::kill sends SIGKILL on Unix
    let status = child.wait().unwrap();
    assert_eq!(std::os::unix::process::ExitStatusExt::signal(&status), Some(9), "{args:?}: {status}");
    done()
}

/// The files of `root` that a rerun must reproduce (see the module doc for what is left out).
fn outputs(root: &Path) -> std::collections::BTreeMap<PathBuf, Vec<u8>> {
    let mut t = crate::util::tree(root);
    t.retain(|p, _| {
        let s = p.to_string_lossy();
        s != "commands.jsonl" && s != "coco/README.md" && !s.contains("/blender/")
    });
    if let Some(m) = t.get_mut(Path::new("coco/dataset.json")) {
        let mut v: serde_json::Value = serde_json::from_slice(m).unwrap();
        v.as_object_mut().unwrap().remove("commands");
        *m = serde_json::to_vec(&v).unwrap();
    }
    t
}

fn assert_same_outputs(reference: &Path, rerun: &Path, what: &str) {
    let (a, b) = (outputs(reference), outputs(rerun));
    let (ka, kb): (Vec<_>, Vec<_>) = (a.keys().collect(), b.keys().collect());
    assert_eq!(ka, kb, "{what}: the files differ from an uninterrupted run's");
    for (p, bytes) in &a {
        assert!(b[p] == *bytes, "{what}: {} differs from an uninterrupted run's", p.display());
    }
}

/// Kills `args` in `dir` at `kills` points drawn from `seed` (more of `done()` each time), plants a stale
/// temporary file as a killed writer would leave it, reruns to completion, and checks the tree
/// against `reference` (the same stage run uninterrupted on a copy of the inputs).
fn kill_rerun_compare(
    dir: &Path,
    reference: &Path,
    args: &[String],
    done: &dyn Fn() -> usize,
    total: usize,
    (kills, seed): (usize, u64),
    stale_dir: &Path,
) {
    let mut draws = Draws(seed);
    let mut points = Vec::new();
    for _ in 0..kills {
        let left = total - done();
        assert!(left > 1, "seed {seed}: no work left to kill at ({points:?})");
        // Leave at least one item for the next run.
        let k = draws.between(1, ((left - 1) as u64 / (kills as u64)).max(1)) as usize;
        let extra_ms = draws.between(0, 40);
        let at = kill_after(dir, args, done, k, extra_ms);
        points.push((k, extra_ms, at));
    }
    let left_by_kills = temp_files(&dir.join("runs"));
    eprintln!("seed {seed}: kills (k, ms, done) {points:?}; temporary files left: {left_by_kills:?}");
    // What a writer killed inside `write_atomic` leaves: an unlocked `.insgen-tmp-XXXXXX`.
    std::fs::create_dir_all(stale_dir).unwrap();
    std::fs::write(stale_dir.join(".insgen-tmp-Kil1ed"), b"half a file").unwrap();
    let a: Vec<&str> = args.iter().map(String::as_str).collect();
    let o = insgen(dir, &a);
    assert!(o.status.success(), "seed {seed}: the rerun failed: {}", stderr(&o));
    let left = temp_files(&dir.join("runs"));
    assert!(left.is_empty(), "seed {seed}: temporary files after the rerun: {left:?}");
    assert_same_outputs(&reference.join("runs"), &dir.join("runs"), &format!("seed {seed} {args:?}"));
}

fn strings(args: &[&str]) -> Vec<String> {
    args.iter().map(|s| s.to_string()).collect()
}

/// A copy of `dir`'s `runs/` in a new scratch directory (the inputs of the reference run).
fn copy_runs(dir: &Path) -> tempfile::TempDir {
    let copy = tempfile::tempdir().unwrap();
    let ok = Command::new("cp").arg("-a").arg(dir.join("runs")).arg(copy.path()).status().unwrap();
    assert!(ok.success());
    copy
}

#[test]
fn render_masks_killed_at_random_points_reruns_to_identical_files() {
    let n = 40;
    let dir = demo_with_poses(n, 480, 270);
    let reference = copy_runs(dir.path());
    // The default preview contact sheets too: written last, after every frame.
    let args = strings(&["render-masks", "--area", "demo", "--camera", "crash", "--no-progress"]);
    let a: Vec<&str> = args.iter().map(String::as_str).collect();
    let o = insgen(reference.path(), &a);
    assert!(o.status.success(), "{}", stderr(&o));
    let masks = dir.path().join("runs/demo/crash/masks");
    let done = || count_files(&masks, ".instances.json");
    kill_rerun_compare(dir.path(), reference.path(), &args, &done, n as usize, (3, 0x19_0005), &masks);
}

#[test]
fn export_coco_killed_at_random_points_reruns_to_identical_files() {
    let n = 24;
    let dir = demo_with_poses(n, 480, 270);
    let o = insgen(dir.path(), &["render-masks", "--area", "demo", "--camera", "crash", "--preview", "0"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let reference = copy_runs(dir.path());
    let args = strings(&["export-coco", "--label-only", "--no-progress"]);
    let a: Vec<&str> = args.iter().map(String::as_str).collect();
    let o = insgen(reference.path(), &a);
    assert!(o.status.success(), "{}", stderr(&o));
    // The export writes a handful of files (COCO, statistics, charts, manifest, card) in well under
    // a second: the kills land after 0, 1, 2, … of them, at drawn delays after the start.
    let coco = dir.path().join("runs/coco");
    let files = || crate::util::live_paths(&coco).len();
    let mut draws = Draws(0x19_c0c0);
    let mut landed = Vec::new();
    for _ in 0..6 {
        let delay_ms = draws.between(0, 1200);
        let mut child = Command::new(env!("CARGO_BIN_EXE_insgen"))
            .args(&args)
            .current_dir(dir.path())
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .unwrap();
        std::thread::sleep(Duration::from_millis(delay_ms));
        let finished = child.try_wait().unwrap().is_some();
        child.kill().ok();
        child.wait().unwrap();
        landed.push((delay_ms, finished, files(), temp_files(&coco).len()));
        if !finished {
            // Start the next attempt from scratch, so that later kills land early in the export too.
            let _ = std::fs::remove_dir_all(&coco);
        }
    }
    eprintln!("export-coco kills (delay ms, had finished, files, temporary files): {landed:?}");
    assert!(landed.iter().any(|l| !l.1), "every kill came after the export had finished: {landed:?}");
    // The last killed attempt's leftovers stay for the rerun to clean up.
    let mut child = Command::new(env!("CARGO_BIN_EXE_insgen"))
        .args(&args)
        .current_dir(dir.path())
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let start = Instant::now();
    while files() < 2 && start.elapsed() < Duration::from_secs(60) {
        std::thread::sleep(Duration::from_millis(2));
    }
    child.kill().ok();
    child.wait().unwrap();
    std::fs::create_dir_all(&coco).unwrap();
    std::fs::write(coco.join(".insgen-tmp-Kil1ed"), b"half a file").unwrap();
    let o = insgen(dir.path(), &a);
    assert!(o.status.success(), "{}", stderr(&o));
    let left = temp_files(&dir.path().join("runs"));
    assert!(left.is_empty(), "temporary files after the rerun: {left:?}");
    assert_same_outputs(&reference.path().join("runs"), &dir.path().join("runs"), "export-coco");
    // A shard's part too: killed, rerun, equal to an uninterrupted part.
    let part = strings(&["export-coco", "--label-only", "--no-progress", "--shard", "1/2"]);
    let p: Vec<&str> = part.iter().map(String::as_str).collect();
    let o = insgen(reference.path(), &p);
    assert!(o.status.success(), "{}", stderr(&o));
    let mut child =
        Command::new(env!("CARGO_BIN_EXE_insgen")).args(&part).current_dir(dir.path()).spawn().unwrap();
    std::thread::sleep(Duration::from_millis(draws.between(0, 150)));
    child.kill().ok();
    child.wait().unwrap();
    let o = insgen(dir.path(), &p);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(temp_files(&dir.path().join("runs")).is_empty());
    assert_same_outputs(&reference.path().join("runs"), &dir.path().join("runs"), "export-coco --shard 1/2");
}

#[test]
fn render_rgb_killed_at_random_points_reruns_to_identical_files() {
    let Some(py) = crate::blender_support::blender_python() else { return };
    let n = 8;
    let dir = demo_with_poses(n, 64, 36);
    let reference = copy_runs(dir.path());
    let mut args = strings(&["render-rgb", "--area", "demo", "--camera", "crash", "--samples", "1"]);
    args.extend(strings(&["--no-denoise", "--threads", "1", "--exr", "--no-progress", "--blender-python"]));
    args.push(py.display().to_string());
    let a: Vec<&str> = args.iter().map(String::as_str).collect();
    let o = insgen(reference.path(), &a);
    assert!(o.status.success(), "{}", stderr(&o));
    let rgb = dir.path().join("runs/demo/crash/rgb");
    let done = || count_files(&rgb, ".exr");
    kill_rerun_compare(dir.path(), reference.path(), &args, &done, n as usize, (2, 0x19_b1e0), &rgb);
    // Blender died with insgen: nothing of it is left running in the scratch directory.
    let scratch = dir.path().display().to_string();
    let ps = Command::new("ps").args(["-eo", "args"]).output().unwrap();
    let left: Vec<String> = String::from_utf8_lossy(&ps.stdout)
        .lines()
        .filter(|l| l.contains(&scratch))
        .map(String::from)
        .collect();
    assert!(left.is_empty(), "Blender outlived a killed render-rgb: {left:?}");
}

/// Unmounts a tmpfs when the test ends, passing or not.
struct Mount(PathBuf);

impl Drop for Mount {
    fn drop(&mut self) {
        let _ = Command::new("umount").arg("-l").arg(&self.0).status();
    }
}

/// Makes `dir` unwritable for this process: as root a full 64 KiB tmpfs (ENOSPC on the first data
/// block), otherwise a read-only directory (EACCES). Returns the guard and the expected error text.
fn unwritable(dir: &Path) -> Option<(Option<Mount>, &'static str)> {
    std::fs::create_dir_all(dir).unwrap();
    let root = Command::new("id").arg("-u").output().map(|o| o.stdout == b"0\n").unwrap_or(false);
    if !root {
        use std::os::unix::fs::PermissionsExt;
        std::fs::set_permissions(dir, std::fs::Permissions::from_mode(0o555)).unwrap();
        return Some((None, "Permission denied"));
    }
    let ok = Command::new("mount").args(["-t", "tmpfs", "-o", "size=64k", "tmpfs"]).arg(dir).status();
    if !ok.is_ok_and(|s| s.success()) {
        crate::util::skip("root, but cannot mount a tmpfs to fill up (no CAP_SYS_ADMIN?)");
        return None;
    }
    let guard = Mount(dir.to_path_buf());
    // Fill it: dd stops at ENOSPC (and says so), leaving no block free.
    let _ = Command::new("dd")
        .args(["if=/dev/zero", "bs=4096"])
        .arg(format!("of={}", dir.join("filler").display()))
        .stderr(Stdio::null())
        .status();
    Some((Some(guard), "No space left on device"))
}

/// The files below `dir` other than the filler: what a failed write left.
fn written(dir: &Path) -> Vec<PathBuf> {
    crate::util::tree(dir).into_keys().filter(|p| p != Path::new("filler")).collect()
}

#[test]
fn a_full_disk_or_unusable_directory_fails_clearly_and_writes_nothing() {
    let dir = demo_with_poses(3, 160, 90);
    let cwd = dir.path();
    // render-masks on a full masks directory.
    let masks = cwd.join("runs/demo/crash/masks");
    if let Some((_guard, why)) = unwritable(&masks) {
        let o = insgen(cwd, &["render-masks", "--area", "demo", "--camera", "crash"]);
        let err = stderr(&o);
        assert_eq!(o.status.code(), Some(1), "{err}");
        assert!(err.contains(why) && err.contains("runs/demo/crash/masks/"), "{err}");
        assert_eq!(written(&masks), Vec::<PathBuf>::new(), "{err}");
    }
    std::fs::remove_dir_all(&masks).ok();
    let o = insgen(cwd, &["render-masks", "--area", "demo", "--camera", "crash", "--preview", "0"]);
    assert!(o.status.success(), "{}", stderr(&o));
    // export-coco on a full output directory.
    let coco = cwd.join("runs/coco");
    if let Some((_guard, why)) = unwritable(&coco) {
        let o = insgen(cwd, &["export-coco", "--label-only"]);
        let err = stderr(&o);
        assert_eq!(o.status.code(), Some(1), "{err}");
        assert!(err.contains(why) && err.contains("runs/coco/"), "{err}");
        assert_eq!(written(&coco), Vec::<PathBuf>::new(), "{err}");
    }
    // An output path under a regular file (ENOTDIR, which stops root too).
    std::fs::write(cwd.join("a-file"), b"not a directory").unwrap();
    let o = insgen(cwd, &["export-coco", "--label-only", "--out", "a-file/coco"]);
    let err = stderr(&o);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(err.contains("a-file/coco") && err.contains("Not a directory"), "{err}");
    assert_eq!(std::fs::read(cwd.join("a-file")).unwrap(), b"not a directory");
}
