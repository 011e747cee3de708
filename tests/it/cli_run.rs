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
