//! `insgen align`: the rigid residual between a prepared area's LoD model and a photogrammetry tileset,
//! recorded in the area's manifest as its alignment correction (see [`crate::scene::align`] and
//! [`crate::scene::correction`]).

use std::path::{Path, PathBuf};

use anyhow::Context;
use serde::Serialize;

use crate::geo::{EnuFrame, Geodetic};
use crate::scene::align::{self, AlignOptions, Estimate, HeightMap, GROUND_WINDOW_M};
use crate::scene::artifact::{PreparedScene, MANIFEST_FILE};
use crate::scene::correction::{Agreement, AlignmentRecord, Correction, CorrectionSource};

/// Measure how far the LoD model sits from a tileset of the same area, and correct it.
///
/// Reads <workdir>/<NAME>/scene (the LoD model as prepared, ignoring any earlier correction) and the
/// tileset (every content of its finest level). Estimates the shift (east, north, up) and yaw that move
/// the LoD model onto the tileset (height-map search, then point-to-plane least squares), with a
/// one-sigma uncertainty and the agreement before and after (median |Δh| on roofs, footprint IoU).
/// Writes <workdir>/<NAME>/align/align.json (the report) and the correction into the scene's
/// manifest.json (`alignment`), which sample, render-masks, render-rgb, export-coco and eval-loc then
/// apply. A correction pinned in scenes/<NAME>.toml ([alignment]) is never overwritten.
#[derive(Debug, Clone, clap::Args)]
#[command(
    after_long_help = "Examples:\n  insgen align --area tokyo --tileset /data/shibuya_mesh/tileset.json\n  \
insgen align --area demo --tileset runs/demo/synthetic/tileset.json --dry-run\n\n\
To pin a correction by hand instead, add to scenes/<NAME>.toml and run `insgen prepare` again:\n  \
[alignment]\n  east_m = 0.4\n  north_m = -1.2\n  up_m = 0.3\n  yaw_deg = 0.15\n  pivot_enu_m = [120.0, -35.0]"
)]
pub struct Args {
    /// The prepared area (<workdir>/<NAME>/scene).
    #[arg(long, value_name = "NAME")]
    pub area: String,
    /// The reference tileset (tileset.json, or one .b3dm/.glb).
    #[arg(long, value_name = "FILE")]
    pub tileset: PathBuf,
    /// Largest horizontal shift searched, each axis.
    #[arg(long, value_name = "METRES", default_value_t = 6.0)]
    pub search_m: f64,
    /// Largest yaw searched.
    #[arg(long, value_name = "DEGREES", default_value_t = 1.5)]
    pub search_deg: f64,
    /// Cell of the height maps the agreement is measured on.
    #[arg(long, value_name = "METRES", default_value_t = 0.5, hide_short_help = true)]
    pub cell_m: f64,
    /// Measure and report only; leave the manifest as it is.
    #[arg(long)]
    pub dry_run: bool,
}

/// `<workdir>/<area>/align/align.json`.
#[derive(Debug, Serialize)]
pub struct Report {
    /// The area.
    pub area: String,
    /// The tileset JSON, as given.
    pub tileset: String,
    /// SHA-256 of the tileset JSON, hex.
    pub tileset_sha256: String,
    /// The estimated correction.
    pub estimate: Estimate,
    /// LoD/tileset agreement before the correction.
    pub before: Agreement,
    /// LoD/tileset agreement after it.
    pub after: Agreement,
    /// Tileset triangles over the area.
    pub tileset_triangles: u64,
    /// LoD triangles.
    pub lod_triangles: u64,
    /// Wall-clock seconds reading the tileset.
    pub read_s: f64,
    /// Wall-clock seconds estimating.
    pub estimate_s: f64,
    /// Wall-clock seconds measuring the agreement.
    pub agreement_s: f64,
    /// Whether the manifest now holds this estimate (false with --dry-run or a pinned correction).
    pub written: bool,
}

/// Runs `align`.
pub fn run(args: &Args, global: &super::Global) -> anyhow::Result<()> {
    let printer = global.printer();
    let area_dir = global.workdir.join(&args.area);
    let scene_dir = area_dir.join(crate::layout::SCENE_DIR);
    anyhow::ensure!(
        args.tileset.is_file(),
        "{}: no such tileset file (give the tileset.json of the photogrammetry model)",
        args.tileset.display()
    );
    anyhow::ensure!(
        args.cell_m.is_finite() && (0.05..=5.0).contains(&args.cell_m),
        "--cell-m {}: expected 0.05 to 5 metres",
        args.cell_m
    );
    let scene = PreparedScene::load_as_prepared(&scene_dir).with_context(|| {
        format!("loading {} (run `insgen prepare --area {}`)", scene_dir.display(), args.area)
    })?;
    let o = scene.manifest.origin;
    let enu = EnuFrame::new(Geodetic::new(o.lat_deg, o.lon_deg, o.h_m));
    let lod = align::scene_surface(&scene.mesh);
    let (lo, hi) = align::bounds_2d(&lod)
        .with_context(|| format!("area {}: the prepared scene has no triangles", args.area))?;

    let t0 = std::time::Instant::now();
    printer.status(format!("reading {}", args.tileset.display()));
    let margin = args.search_m + 60.0;
    let tiles = align::tileset_surface(
        &args.tileset,
        &enu,
        [lo[0] - margin, lo[1] - margin],
        [hi[0] + margin, hi[1] + margin],
    )
    .with_context(|| format!("reading the tileset {}", args.tileset.display()))?;
    let read_s = t0.elapsed().as_secs_f64();

    let t1 = std::time::Instant::now();
    printer.status(format!(
        "estimating ({} LoD / {} tileset triangles)",
        lod.triangles.len(),
        tiles.triangles.len()
    ));
    let opts =
        AlignOptions { search_m: args.search_m, search_deg: args.search_deg, ..AlignOptions::default() };
    let est = align::estimate(&lod, &tiles, &opts)
        .with_context(|| format!("aligning area {} with {}", args.area, args.tileset.display()))?;
    let estimate_s = t1.elapsed().as_secs_f64();

    let t2 = std::time::Instant::now();
    let (before, after) = agreements(&lod, &tiles, (lo, hi), args.cell_m, &est.correction);
    let agreement_s = t2.elapsed().as_secs_f64();

    let tileset_sha256 = crate::lod::tiles3d::fingerprint(&args.tileset)?;
    let tileset = absolute(&args.tileset).display().to_string();
    let pinned = scene.manifest.alignment.as_ref().is_some_and(|r| r.source == CorrectionSource::SceneConfig);
    let written = !args.dry_run && !pinned;
    if written {
        let mut manifest = scene.manifest.clone();
        let mut rec =
            AlignmentRecord::new(CorrectionSource::Estimated, est.correction, manifest.ecef_from_enu);
        rec.sigma = Some(est.sigma);
        rec.tileset = Some(tileset.clone());
        rec.tileset_sha256 = Some(tileset_sha256.clone());
        rec.before = Some(before);
        rec.after = Some(after);
        manifest.alignment = Some(rec);
        crate::util::write_json_atomic(&scene_dir.join(MANIFEST_FILE), &manifest)?;
    }
    let report = Report {
        area: args.area.clone(),
        tileset,
        tileset_sha256,
        estimate: est.clone(),
        before,
        after,
        tileset_triangles: tiles.triangles.len() as u64,
        lod_triangles: lod.triangles.len() as u64,
        read_s,
        estimate_s,
        agreement_s,
        written,
    };
    let out = area_dir.join("align").join("align.json");
    crate::util::create_dir_all(out.parent().expect("a file under the area directory"))?;
    crate::util::write_json_atomic(&out, &report)?;

    printer.summary(describe(&est.correction, &est.sigma));
    printer.summary(format!(
        "agreement: median |dh| on roofs {:.3} m -> {:.3} m, footprint IoU {:.4} -> {:.4}",
        before.median_abs_dh_roofs_m, after.median_abs_dh_roofs_m, before.footprint_iou, after.footprint_iou
    ));
    if pinned {
        printer.summary(format!(
            "not written: scenes/{}.toml pins the correction ([alignment]); remove it and run `insgen prepare` to use this estimate",
            args.area
        ));
    } else if written {
        printer.summary(format!("wrote the correction into {}", scene_dir.join(MANIFEST_FILE).display()));
    }
    printer.summary(format!("report: {}", out.display()));
    Ok(())
}

/// One line describing an estimate.
fn describe(c: &Correction, s: &crate::scene::correction::CorrectionSigma) -> String {
    format!(
        "estimate: east {:+.3} ± {:.3} m, north {:+.3} ± {:.3} m, up {:+.3} ± {:.3} m, yaw {:+.4} ± {:.4}° about ({:.2}, {:.2})",
        c.east_m,
        s.east_m,
        c.north_m,
        s.north_m,
        c.up_m,
        s.up_m,
        c.yaw_deg,
        s.yaw_deg,
        c.pivot_enu_m[0],
        c.pivot_enu_m[1]
    )
}

/// Agreement before (as prepared) and after the correction, on height maps of `cell_m` over the LoD
/// bounds plus 10 m.
fn agreements(
    lod: &crate::lod::TriMesh,
    tiles: &crate::lod::TriMesh,
    (lo, hi): ([f64; 2], [f64; 2]),
    cell_m: f64,
    c: &Correction,
) -> (Agreement, Agreement) {
    let mut t = HeightMap::new([lo[0] - 10.0, lo[1] - 10.0], [hi[0] + 10.0, hi[1] + 10.0], cell_m);
    t.rasterise(tiles, &Correction::IDENTITY);
    let ground = t.ground(GROUND_WINDOW_M);
    let before = align::agreement(lod, &t, &ground, &Correction::IDENTITY);
    let after = align::agreement(lod, &t, &ground, c);
    (before, after)
}

fn absolute(p: &Path) -> PathBuf {
    p.canonicalize().unwrap_or_else(|_| p.to_path_buf())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(argv: &[&str]) -> Result<crate::cli::testing::Parsed<Args>, clap::Error> {
        crate::cli::testing::parse(argv)
    }

    #[test]
    fn area_and_tileset_are_required() {
        assert!(parse(&["--area", "demo"]).is_err());
        assert!(parse(&["--tileset", "t.json"]).is_err());
        let t = parse(&["--area", "demo", "--tileset", "t.json"]).unwrap();
        assert_eq!(
            (t.args.search_m, t.args.search_deg, t.args.cell_m, t.args.dry_run),
            (6.0, 1.5, 0.5, false)
        );
        let t = parse(&["--area", "demo", "--tileset", "t.json", "--search-m", "10", "--dry-run"]).unwrap();
        assert_eq!((t.args.search_m, t.args.dry_run), (10.0, true));
    }
}
