//! The binary as a batch system and a person at a terminal see it: Ctrl-C stops between frames with
//! exit status 130 and leaves only complete files, a rerun finishes the job, batch logs get periodic
//! progress lines, and a headless run prints no driver noise.

use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use crate::util::{repo_scene, scratch_with_scenes};

/// A scratch directory with the demo area prepared and `count` grid poses of a small camera sampled
/// (480×270, so the masks take a few seconds in all).
fn demo_with_poses(count: u32) -> tempfile::TempDir {
    let dir = scratch_with_scenes(&[("demo", repo_scene("demo"))]);
    let run = |args: &[&str]| {
        let o = crate::util::insgen(dir.path(), args);
        assert!(o.status.success(), "{args:?}: {}", crate::util::stderr(&o));
    };
    run(&["prepare", "--area", "demo"]);
    // cam2's field of view at a quarter of its pixels.
    std::fs::write(
        dir.path().join("small.toml"),
        "name = \"small\"\nwidth_px = 480\nheight_px = 270\nsensor_width_mm = 6.4\nsensor_height_mm = 3.6\n\
         hfov_deg = 25.0\nstrategy = \"grid\"\n",
    )
    .unwrap();
    run(&["sample", "--area", "demo", "--camera", "small.toml", "--count", &count.to_string()]);
    dir
}

fn masks(dir: &Path) -> Vec<String> {
    let m = dir.join("runs/demo/small/masks");
    let mut v: Vec<String> = std::fs::read_dir(&m)
        .map(|r| r.filter_map(|e| e.ok()).map(|e| e.file_name().to_string_lossy().into_owned()).collect())
        .unwrap_or_default();
    v.sort();
    v
}

#[test]
fn ctrl_c_stops_between_frames_with_130_and_a_rerun_completes() {
    let dir = demo_with_poses(120);
    let mut child = Command::new(env!("CARGO_BIN_EXE_insgen"))
        .args(["render-masks", "--area", "demo", "--camera", "small", "--no-progress"])
        .current_dir(dir.path())
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .expect("insgen starts");
    // Wait for the first finished frames, then interrupt as a terminal's Ctrl-C would.
    let started = Instant::now();
    while masks(dir.path()).iter().filter(|n| n.ends_with(".instances.json")).count() < 3 {
        assert!(started.elapsed() < Duration::from_secs(120), "no frame written within 2 minutes");
        if let Some(status) = child.try_wait().unwrap() {
            panic!("render-masks ended before it was interrupted: {status}");
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    let pid = child.id().to_string();
    assert!(Command::new("kill").args(["-INT", &pid]).status().unwrap().success());
    let out = child.wait_with_output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(130), "stderr: {err}");
    assert!(err.contains("interrupted (Ctrl-C)"), "{err}");
    let after_stop = masks(dir.path());
    assert!(
        after_stop.iter().all(|n| !n.starts_with(".insgen-tmp-")),
        "temporary files left: {after_stop:?}"
    );
    let done = after_stop.iter().filter(|n| n.ends_with(".instances.json")).count();
    assert!(done < 120, "the stop came too late to test anything ({done} frames done)");
    // Every frame listed has its PNG, and every PNG decodes.
    for n in after_stop.iter().filter(|n| n.ends_with(".png")) {
        insgen::scene::IdMap::read_png(&dir.path().join("runs/demo/small/masks").join(n))
            .expect("complete PNG");
    }
    // The rerun does the rest only.
    let o = crate::util::insgen(dir.path(), &["render-masks", "--area", "demo", "--camera", "small", "-v"]);
    assert!(o.status.success(), "{}", crate::util::stderr(&o));
    assert_eq!(masks(dir.path()).iter().filter(|n| n.ends_with(".instances.json")).count(), 120);
}

#[test]
fn a_batch_log_gets_progress_lines_and_no_driver_noise() {
    let dir = demo_with_poses(12);
    // stderr is a pipe here, as in a Slurm log: lines, not a bar; --log-every 0 prints one per frame.
    let o = Command::new(env!("CARGO_BIN_EXE_insgen"))
        .args(["render-masks", "--area", "demo", "--camera", "small", "--log-every", "0"])
        .current_dir(dir.path())
        .env_remove("NODEVICE_SELECT")
        .env_remove("XDG_RUNTIME_DIR")
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{err}");
    let lines: Vec<&str> = err.lines().filter(|l| l.starts_with("frames: ")).collect();
    assert!(lines.len() >= 12, "{err}");
    assert!(lines.last().unwrap().starts_with("frames: 12/12 (100.0 %)"), "{err}");
    assert!(!err.contains("XDG_RUNTIME_DIR"), "driver noise on a headless run: {err}");
    assert!(!err.contains('\r'), "a bar was drawn into a log: {err:?}");
}

#[test]
fn slurm_array_shards_merge_into_what_one_process_writes() {
    let dir = demo_with_poses(10);
    let cwd = dir.path();
    for shard in ["task0", "task1"] {
        let ok = Command::new("cp").args(["-r", "runs", shard]).current_dir(cwd).status().unwrap();
        assert!(ok.success());
    }
    // One process.
    let run = |args: &[&str]| {
        let o = crate::util::insgen(cwd, args);
        assert!(o.status.success(), "{args:?}: {}", crate::util::stderr(&o));
        o
    };
    run(&["render-masks", "--area", "demo", "--camera", "small", "--preview", "0"]);
    run(&["export-coco", "--label-only"]);
    // Two tasks of a Slurm job array submitted as --array=1-2, each in its own (node-local) workdir.
    for (task, workdir) in [("1", "task0"), ("2", "task1")] {
        let o = Command::new(env!("CARGO_BIN_EXE_insgen"))
            .args(["--workdir", workdir, "-v", "render-masks", "--area", "demo", "--camera", "small"])
            .args(["--preview", "0", "--shard", "auto"])
            .env("SLURM_ARRAY_TASK_ID", task)
            .env("SLURM_ARRAY_TASK_MIN", "1")
            .env("SLURM_ARRAY_TASK_MAX", "2")
            .env("RUST_LOG", "info")
            .current_dir(cwd)
            .output()
            .unwrap();
        let err = crate::util::stderr(&o);
        assert!(o.status.success(), "{err}");
        let index = task.parse::<u32>().unwrap() - 1;
        assert!(err.contains(&format!("shard {index}/2 (from the Slurm job array)")), "{err}");
    }
    let frames = |w: &str| crate::util::tree(&cwd.join(w).join("demo/small/masks")).len();
    assert_eq!(frames("task0") + frames("task1"), frames("runs"), "the shards split the frames");
    assert!(frames("task0") > 0 && frames("task1") > 0);
    // A shard of another run (here: other poses) conflicts, and a refused merge writes nothing.
    let poses = cwd.join("task1/demo/small/poses.jsonl");
    let original = std::fs::read(&poses).unwrap();
    std::fs::write(&poses, b"{}\n").unwrap();
    let o = crate::util::insgen(cwd, &["merge", "--workdir", "merged", "task0", "task1"]);
    let err = crate::util::stderr(&o);
    assert!(!o.status.success() && err.contains("differ between the work directories"), "{err}");
    assert!(err.contains("poses.jsonl"), "{err}");
    assert!(!cwd.join("merged").exists(), "a refused merge writes nothing");
    std::fs::write(&poses, original).unwrap();
    // The merge, then the export, equal the single process's byte for byte.
    run(&["merge", "--workdir", "merged", "task0", "task1"]);
    run(&["--workdir", "merged", "export-coco", "--label-only"]);
    let single = crate::util::tree(&cwd.join("runs/demo"));
    let merged = crate::util::tree(&cwd.join("merged/demo"));
    assert_eq!(single.keys().collect::<Vec<_>>(), merged.keys().collect::<Vec<_>>());
    for (k, v) in &single {
        assert!(merged[k] == *v, "{} differs after the merge", k.display());
    }
    for split in ["train", "val", "test"] {
        let name = format!("instances_{split}.json");
        let a = std::fs::read(cwd.join("runs/coco").join(&name)).unwrap();
        let b = std::fs::read(cwd.join("merged/coco").join(&name)).unwrap();
        assert!(a == b, "{name} differs between one process and the merged shards");
    }
}

/// Processes (other than this test) whose command line mentions `needle`.
fn processes_mentioning(needle: &str) -> Vec<String> {
    let me = std::process::id().to_string();
    let mut found = Vec::new();
    for e in std::fs::read_dir("/proc").into_iter().flatten().flatten() {
        let name = e.file_name().to_string_lossy().into_owned();
        if !name.bytes().all(|b| b.is_ascii_digit()) || name == me {
            continue;
        }
        if let Ok(cmd) = std::fs::read(e.path().join("cmdline")) {
            let cmd = String::from_utf8_lossy(&cmd).replace('\0', " ");
            if cmd.contains(needle) {
                found.push(format!("{name}: {cmd}"));
            }
        }
    }
    found
}

/// A real SIGINT to `render-rgb` (to insgen alone, as `kill -INT` from a batch system would; a terminal's
/// Ctrl-C also reaches Blender, which process.rs handles the same way): the frame in progress finishes or
/// is dropped, Blender is stopped, the exit status is 130, no temporary or half-written file is left, and a
/// rerun renders only the rest.
#[test]
fn ctrl_c_stops_render_rgb_with_130_and_a_rerun_completes() {
    let Some(py) = crate::blender_support::blender_python() else { return };
    let n = 8;
    let dir = demo_with_poses(n);
    let rgb_dir = dir.path().join("runs/demo/small/rgb");
    let pngs = || -> Vec<String> {
        let mut v: Vec<String> = std::fs::read_dir(&rgb_dir)
            .map(|r| r.filter_map(|e| e.ok()).map(|e| e.file_name().to_string_lossy().into_owned()).collect())
            .unwrap_or_default();
        v.sort();
        v
    };
    let args = |extra: &[&str]| -> Vec<String> {
        let mut a: Vec<String> =
            ["render-rgb", "--area", "demo", "--camera", "small", "--samples", "1", "--no-denoise"]
                .iter()
                .map(|s| s.to_string())
                .collect();
        a.extend(["--blender-python".to_string(), py.display().to_string()]);
        a.extend(extra.iter().map(|s| s.to_string()));
        a
    };
    let mut child = Command::new(env!("CARGO_BIN_EXE_insgen"))
        .args(args(&["--no-progress"]))
        .current_dir(dir.path())
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .expect("insgen starts");
    let started = Instant::now();
    while !pngs().iter().any(|n| n.ends_with(".png") && !n.starts_with(".insgen-tmp-")) {
        assert!(started.elapsed() < Duration::from_secs(300), "no RGB frame within 5 minutes");
        if let Some(status) = child.try_wait().unwrap() {
            panic!("render-rgb ended before it was interrupted: {status}");
        }
        std::thread::sleep(Duration::from_millis(50));
    }
    let pid = child.id().to_string();
    assert!(Command::new("kill").args(["-INT", &pid]).status().unwrap().success());
    let out = child.wait_with_output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(130), "stderr: {err}");
    assert!(err.contains("interrupted (Ctrl-C)"), "{err}");
    let scratch = dir.path().display().to_string();
    let left = processes_mentioning(&scratch);
    assert!(left.is_empty(), "Blender outlived render-rgb: {left:?}");
    let after = pngs();
    assert!(after.iter().all(|n| !n.starts_with(".insgen-tmp-")), "temporary files left: {after:?}");
    let done: Vec<&String> = after.iter().filter(|n| n.ends_with(".png")).collect();
    assert!(
        !done.is_empty() && done.len() < n as usize,
        "the stop came too late to test anything: {after:?}"
    );
    for png in &done {
        // Every finished frame decodes and has its render metadata.
        insgen::coco::raster::read_png_rgb(&rgb_dir.join(png)).expect("complete PNG");
        let meta = rgb_dir.join(png.replace(".png", ".render.json"));
        assert!(meta.is_file(), "{} without its metadata", png);
    }
    // The rerun renders the rest only.
    let o = crate::util::insgen(dir.path(), &args(&[]).iter().map(String::as_str).collect::<Vec<_>>());
    let err = crate::util::stderr(&o);
    assert!(o.status.success(), "{err}");
    assert!(err.contains(&format!("{} already done", done.len())), "{err}");
    assert_eq!(pngs().iter().filter(|n| n.ends_with(".png")).count(), n as usize);
}
