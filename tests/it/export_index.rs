//! `index.html` of an export (issue 39): written by the export's report with its figures, relative
//! links only, byte-identical between runs and after `insgen stats` rewrote the report of the moved
//! folder, and seen by a browser — headless Chromium opens it from
//! `file://` after the export folder was moved away from its work directory, and every image must load
//! (`naturalWidth > 0`), every link must name a file inside the folder, no resource may come from
//! anywhere else, and a full-page screenshot is taken (`scripts/index_check.mjs`).
//!
//! Chromium and node come from `scripts/setup.sh`; without them the browser part prints why and
//! skips, unless `CI=true`, where it fails.

use std::path::{Path, PathBuf};
use std::process::Command;

use insgen::export::coco::export;
use insgen::export::stats::{self, ReportOptions};
use insgen::util::figure::{text, RgbImage, TextStyle, INK};
use insgen::util::NoProgress;
use serde_json::Value;

use crate::coco_export::{plan, standard_workdir};
use crate::util::{insgen, repo, skip, stderr};

/// A flight plan for one camera (any picture does: the index copies it).
fn write_flight_plan(camera_dir: &Path) {
    let mut img = RgbImage::new(320, 200, [240, 244, 236]);
    img.text(10, 10, "flight plan", TextStyle::new(text::TITLE_PX, INK));
    img.save(&camera_dir.join("flight_plan.png")).unwrap();
}

fn chromium() -> Option<PathBuf> {
    let ok = |c: &str| Command::new(c).arg("--version").output().map(|o| o.status.success()).unwrap_or(false);
    if !ok("node") {
        skip("`node` is not on PATH (scripts/setup.sh installs it)");
        return None;
    }
    let found = ["/usr/bin/chromium", "chromium", "chromium-browser"].into_iter().find(|c| ok(c));
    if found.is_none() {
        skip("no `chromium` on PATH (scripts/setup.sh installs Debian's)");
    }
    found.map(PathBuf::from)
}

#[test]
fn index_html_shows_the_export_in_a_browser_after_the_folder_moved() {
    let tmp = tempfile::tempdir().unwrap();
    let wd = standard_workdir(tmp.path());
    write_flight_plan(&wd.join("alpha/cam2"));
    let p = plan(&wd, "coco");
    let (ex, _) = export(&p, &NoProgress).unwrap();
    let written = stats::write_export_report(&p, &ex, ReportOptions::default()).unwrap();
    let rel = |f: &PathBuf| f.strip_prefix(&p.out_dir).unwrap().to_string_lossy().into_owned();
    let names: Vec<String> = written.iter().map(rel).collect();
    for f in [
        "index.html",
        "figures/alpha/cam2/flight_plan.png",
        "figures/alpha/contact_sheet.png",
        "figures/bravo/contact_sheet.png",
        "figures/charlie/contact_sheet.png",
        "figures/delta/contact_sheet.png",
    ] {
        assert!(names.iter().any(|n| n == f), "{f} not written: {names:?}");
    }
    // The copy is the work directory's picture, byte for byte.
    assert_eq!(
        std::fs::read(p.out_dir.join("figures/alpha/cam2/flight_plan.png")).unwrap(),
        std::fs::read(wd.join("alpha/cam2/flight_plan.png")).unwrap()
    );
    let html = std::fs::read_to_string(p.out_dir.join("index.html")).unwrap();
    // The statistics table is the card's (one writer), every split's row is there, and the cameras
    // without a flight plan are named rather than shown broken.
    let card = std::fs::read_to_string(p.out_dir.join("README.md")).unwrap();
    let st =
        stats::compute(&ex.datasets.iter().map(|(s, d)| (*s, d)).collect::<Vec<_>>(), &p.out_dir).unwrap();
    assert!(card.contains(&stats::splits_table(&st).markdown()), "{card}");
    assert!(html.contains(&stats::splits_table(&st).html()), "{html}");
    assert!(
        html.contains(
            "No flight plan in the work directory for: bravo / cam2, charlie / cam2, delta / cam2."
        ),
        "{html}"
    );
    assert!(!html.contains("<script") && !html.contains("http://") && !html.contains("https://"), "{html}");
    // Same inputs, same page and figures.
    let p2 = plan(&wd, "coco2");
    let (ex2, _) = export(&p2, &NoProgress).unwrap();
    stats::write_export_report(&p2, &ex2, ReportOptions::default()).unwrap();
    for n in names.iter().filter(|n| n.ends_with(".html") || n.ends_with(".png")) {
        assert!(
            std::fs::read(p.out_dir.join(n)).unwrap() == std::fs::read(p2.out_dir.join(n)).unwrap(),
            "{n}"
        );
    }

    // Moved away, and the work directory gone: the folder alone must hold the page.
    let before: Vec<(String, Vec<u8>)> =
        names.iter().map(|n| (n.clone(), std::fs::read(p.out_dir.join(n)).unwrap())).collect();
    let moved = tmp.path().join("elsewhere/dataset");
    std::fs::create_dir_all(moved.parent().unwrap()).unwrap();
    std::fs::rename(&p.out_dir, &moved).unwrap();
    std::fs::rename(&wd, tmp.path().join("workdir-gone")).unwrap();
    // `insgen stats` rewrites the report and the page that shows it, as the export wrote them (the
    // flight plan kept from the folder, the work directory being gone): nothing changed, so every
    // file is byte-identical, index.html included.
    std::fs::remove_file(moved.join("index.html")).unwrap();
    let o = insgen(tmp.path(), &["stats", "--coco", moved.to_str().unwrap()]);
    assert!(o.status.success(), "insgen stats: {}", stderr(&o));
    for (n, bytes) in &before {
        assert!(&std::fs::read(moved.join(n)).unwrap_or_default() == bytes, "insgen stats changed {n}");
    }

    let Some(chromium) = chromium() else { return };
    let shot = tmp.path().join("index.png");
    let out = Command::new("node")
        .arg(repo().join("scripts/index_check.mjs"))
        .arg(moved.join("index.html"))
        .arg(&shot)
        .arg(&chromium)
        .output()
        .unwrap();
    let r: Value = serde_json::from_slice(&out.stdout)
        .unwrap_or_else(|_| panic!("index_check.mjs: {}", String::from_utf8_lossy(&out.stdout)));
    assert!(out.status.success() && r.get("error").is_none(), "index_check.mjs: {r}");
    assert_eq!(r["problems"], serde_json::json!([]), "{r}");
    // Two charts, four areas' contact sheets, the report's contact sheet, one flight plan: all loaded.
    let images = r["images"].as_array().unwrap();
    assert_eq!(images.len(), 8, "{images:?}");
    assert!(images.iter().all(|i| i["naturalWidth"].as_u64().unwrap() > 0), "{images:?}");
    let links: Vec<&str> = r["links"].as_array().unwrap().iter().map(|l| l.as_str().unwrap()).collect();
    for l in [
        "README.md",
        "dataset.json",
        "stats.md",
        "instances_train.json",
        "instances_test.json",
        "#flight-plans",
    ] {
        assert!(links.contains(&l), "{l} not linked: {links:?}");
    }
    assert_eq!(r["resources"].as_array().unwrap().len(), 0, "the page fetched something: {r}");
    // The screenshot: the whole page at 1280 px, not blank.
    let img = insgen::export::raster::read_png_rgb(&shot).unwrap();
    assert_eq!(img.width, 1280);
    assert!(img.height > 1500, "{} px tall", img.height);
    let colours: std::collections::BTreeSet<[u8; 3]> =
        img.data.chunks_exact(3).map(|p| [p[0], p[1], p[2]]).collect();
    assert!(colours.len() > 200, "{} colours: a blank page?", colours.len());
    if let Some(keep) = std::env::var_os("INSGEN_FIGURES_PREVIEW") {
        std::fs::create_dir_all(&keep).unwrap();
        std::fs::copy(&shot, Path::new(&keep).join("index_screenshot_fixture.png")).unwrap();
    }
}
