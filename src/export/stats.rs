//! Dataset statistics: per split images, instances, instances per image, COCO size classes, buildings
//! seen per area — written as `stats.md` + `stats.json`, bar charts (`hist_*.png`) and a contact sheet
//! of annotated frames (`contact_sheet.png`).
//!
//! Size classes follow the brief of COCOeval's area ranges: small = area < 32² px, medium = 32² ≤ area
//! < 96² px, large = area ≥ 96² px. (COCOeval's own ranges are closed at both ends, so an instance of
//! exactly 1024 px counts as both small and medium there; here it is medium.)
//!
//! Everything but the learnability block is computed from the COCO files alone (the extension keys
//! `area_name` and `building_id`, and `info.areas` for the building totals), so `insgen stats` can
//! summarise any export; the learnability block ([`super::learnability`]) also reads each image's ID
//! map and photo, skipping (and counting) those not on disk.

use std::collections::{BTreeMap, BTreeSet};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use serde::Serialize;

use super::coco::Split;
use super::format::{Dataset, Segmentation};
use super::learnability::Learnability;
use super::raster::{palette, read_png_rgb, RgbImage};
use super::table::Table;
use super::CocoError;
use crate::layout::{
    CONTACT_SHEET_FILE, HIST_CONSISTENCY_FILE, HIST_INSTANCES_FILE, HIST_SIZES_FILE, STATS_JSON_FILE,
    STATS_MD_FILE,
};
use crate::scene::BuildingId;
use crate::util::figure::{text, BarChart, Series, TextStyle};

/// Upper bound (exclusive) of COCO's "small" class, px.
pub const SMALL_MAX_PX: u64 = 32 * 32;
/// Upper bound (exclusive) of COCO's "medium" class, px.
pub const MEDIUM_MAX_PX: u64 = 96 * 96;

/// Counts per COCO size class.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize)]
pub struct SizeCounts {
    /// Annotations with area < 32² px.
    pub small: u64,
    /// Annotations with 32² ≤ area < 96² px.
    pub medium: u64,
    /// Annotations with area ≥ 96² px.
    pub large: u64,
}

/// One bin of the instances-per-image histogram.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub struct PerImageBin {
    /// Annotations in the image.
    pub instances: u64,
    /// Images with exactly that many.
    pub images: u64,
}

/// Statistics of one split.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SplitStats {
    /// `train`, `val` or `test`.
    pub split: String,
    /// Areas in the split.
    pub areas: Vec<String>,
    /// Images.
    pub images: u64,
    /// Images with no annotation.
    pub images_without_annotations: u64,
    /// Annotations.
    pub annotations: u64,
    /// Annotations with `iscrowd = 1`.
    pub crowd: u64,
    /// Annotations touching the image border.
    pub truncated: u64,
    /// Mean annotations per image.
    pub mean_instances_per_image: f64,
    /// Most annotations on one image.
    pub max_instances_per_image: u64,
    /// Histogram of annotations per image.
    pub instances_per_image: Vec<PerImageBin>,
    /// Annotations by COCO size class.
    pub sizes: SizeCounts,
    /// Median annotation area, px (0 without annotations).
    pub median_area_px: u64,
    /// LoD/tileset consistency scores of the images that carry one (`render-masks --tileset`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub consistency: Option<ConsistencyStats>,
}

/// Bins of [`ConsistencyStats::bins`]: `[0, 0.1), [0.1, 0.2), …, [0.9, 1.0]`.
pub const CONSISTENCY_BINS: usize = 10;

/// The distribution of the images' consistency scores in one split.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ConsistencyStats {
    /// Images with a score.
    pub images: u64,
    /// Mean score (0–1).
    pub mean: f64,
    /// Lowest score (0–1).
    pub min: f64,
    /// Median score (0–1).
    pub median: f64,
    /// Images per tenth of the score ([`CONSISTENCY_BINS`] bins, 1.0 in the last).
    pub bins: Vec<u64>,
}

impl ConsistencyStats {
    /// The statistics of `scores` (`None` when empty).
    pub fn of(scores: &[f64]) -> Option<ConsistencyStats> {
        if scores.is_empty() {
            return None;
        }
        let mut sorted = scores.to_vec();
        sorted.sort_by(f64::total_cmp);
        let mut bins = vec![0u64; CONSISTENCY_BINS];
        for &c in scores {
            let b = ((c.clamp(0.0, 1.0) * CONSISTENCY_BINS as f64) as usize).min(CONSISTENCY_BINS - 1);
            bins[b] += 1;
        }
        Some(ConsistencyStats {
            images: scores.len() as u64,
            mean: scores.iter().sum::<f64>() / scores.len() as f64,
            min: sorted[0],
            median: sorted[sorted.len() / 2],
            bins,
        })
    }
}

/// Statistics of one area.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct AreaStats {
    /// Area (scene) name.
    pub area: String,
    /// `train`, `val` or `test`.
    pub split: String,
    /// Images of the area.
    pub images: u64,
    /// Annotations of the area.
    pub annotations: u64,
    /// Distinct buildings with at least one annotation.
    pub buildings_seen: u64,
    /// Buildings in the area's building table.
    pub buildings_total: u64,
    /// `buildings_seen / buildings_total` (0 when the table is empty).
    pub coverage: f64,
    /// Statistics that predict how learnable the area's instances are.
    pub learnability: Learnability,
}

/// The whole report (`stats.json`).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Stats {
    /// insgen's version.
    pub insgen_version: String,
    /// Per split, in [`super::Split::ALL`] order.
    pub splits: Vec<SplitStats>,
    /// Per area, by name.
    pub areas: Vec<AreaStats>,
}

/// Computes the statistics of the given splits; `image_root` is the directory `images[].file_name` and
/// `mask_file` are relative to (read for the learnability block).
///
/// # Errors
/// As [`super::learnability::compute`]: an ID map or photo that is on disk but unreadable, naming it.
pub fn compute(datasets: &[(Split, &Dataset)], image_root: &Path) -> Result<Stats, CocoError> {
    let mut splits = Vec::new();
    let mut areas = Vec::new();
    for &(split, ds) in datasets {
        let mut per_image: BTreeMap<u64, u64> = ds.images.iter().map(|im| (im.id, 0)).collect();
        let mut sizes = SizeCounts::default();
        let (mut crowd, mut truncated) = (0, 0);
        let mut area_values: Vec<u64> = Vec::with_capacity(ds.annotations.len());
        for a in &ds.annotations {
            *per_image.entry(a.image_id).or_default() += 1;
            match a.area {
                x if x < SMALL_MAX_PX => sizes.small += 1,
                x if x < MEDIUM_MAX_PX => sizes.medium += 1,
                _ => sizes.large += 1,
            }
            crowd += (a.iscrowd != 0) as u64;
            truncated += a.truncated as u64;
            area_values.push(a.area);
        }
        area_values.sort_unstable();
        let mut hist: BTreeMap<u64, u64> = BTreeMap::new();
        for &n in per_image.values() {
            *hist.entry(n).or_default() += 1;
        }
        let images = ds.images.len() as u64;
        let annotations = ds.annotations.len() as u64;
        splits.push(SplitStats {
            split: split.as_str().into(),
            areas: ds.info.areas.iter().map(|a| a.name.clone()).collect(),
            images,
            images_without_annotations: hist.get(&0).copied().unwrap_or(0),
            annotations,
            crowd,
            truncated,
            mean_instances_per_image: if images > 0 { annotations as f64 / images as f64 } else { 0.0 },
            max_instances_per_image: per_image.values().copied().max().unwrap_or(0),
            instances_per_image: hist
                .into_iter()
                .map(|(instances, images)| PerImageBin { instances, images })
                .collect(),
            sizes,
            median_area_px: area_values.get(area_values.len() / 2).copied().unwrap_or(0),
            consistency: ConsistencyStats::of(
                &ds.images.iter().filter_map(|im| im.consistency).collect::<Vec<f64>>(),
            ),
        });
        let learnability = super::learnability::compute(ds, image_root)?;
        for info in &ds.info.areas {
            let images = ds.images.iter().filter(|im| im.area_name == info.name).count() as u64;
            let anns: Vec<_> = ds.annotations.iter().filter(|a| a.area_name == info.name).collect();
            let seen: BTreeSet<BuildingId> = anns.iter().map(|a| a.building_id).collect();
            areas.push(AreaStats {
                area: info.name.clone(),
                split: split.as_str().into(),
                images,
                annotations: anns.len() as u64,
                buildings_seen: seen.len() as u64,
                buildings_total: info.buildings,
                coverage: if info.buildings > 0 { seen.len() as f64 / info.buildings as f64 } else { 0.0 },
                // learnability::compute keys every area of `ds.info.areas`.
                learnability: learnability.get(&info.name).cloned().expect("every area is measured"),
            });
        }
    }
    areas.sort_by(|a, b| a.area.cmp(&b.area));
    Ok(Stats { insgen_version: env!("CARGO_PKG_VERSION").into(), splits, areas })
}

/// Options for [`write_report`].
#[derive(Debug, Clone, Copy)]
pub struct ReportOptions {
    /// Frames on the contact sheet (0 = no contact sheet).
    pub contact_sheet_images: usize,
}

impl Default for ReportOptions {
    fn default() -> Self {
        ReportOptions { contact_sheet_images: 12 }
    }
}

const SPLIT_COLOURS: [[u8; 3]; 3] = [[31, 119, 180], [255, 127, 14], [44, 160, 44]];

/// Writes the statistics report of an export next to its COCO files (`plan.out_dir`), computing
/// the statistics unless the export carries them, and the export's `index.html` with its figures
/// ([`write_report_and_index`], flight plans copied from the work directory); returns the files
/// written.
///
/// # Errors
/// As [`compute`] and [`write_report`].
pub fn write_export_report(
    plan: &super::ExportPlan,
    ex: &super::coco::Export,
    opts: ReportOptions,
) -> Result<Vec<PathBuf>, CocoError> {
    let refs: Vec<_> = ex.datasets.iter().map(|(s, d)| (*s, d)).collect();
    let st = match &ex.stats {
        Some(st) => st.clone(),
        None => compute(&refs, plan.names_root())?,
    };
    let flight_plans = super::index::FlightPlans::WorkDir(&plan.workdir);
    write_report_and_index(&st, &refs, &plan.out_dir, plan.names_root(), flight_plans, opts)
}

/// Writes the statistics report ([`write_report`]) and, in an export folder with a manifest
/// (`dataset.json`), the page that shows it, `index.html` with its figures ([`super::index`]), so that
/// the page never shows other numbers or charts than the report beside it: what `export-coco` and
/// `merge` write after the COCO files, and what `insgen stats` rewrites. Returns the files written.
///
/// # Errors
/// As [`write_report`] and [`super::index::write_index`].
pub fn write_report_and_index(
    stats: &Stats,
    datasets: &[(Split, &Dataset)],
    out_dir: &Path,
    image_root: &Path,
    flight_plans: super::index::FlightPlans,
    opts: ReportOptions,
) -> Result<Vec<PathBuf>, CocoError> {
    let mut written = write_report(stats, datasets, out_dir, image_root, opts)?;
    if crate::layout::ExportDir::new(out_dir).manifest().is_file() {
        written.extend(super::index::write_index(
            out_dir,
            image_root,
            flight_plans,
            datasets,
            stats,
            opts.contact_sheet_images,
        )?);
    } else {
        log::info!("{}: no dataset.json (not an export-coco folder), so no index.html", out_dir.display());
    }
    Ok(written)
}

/// Writes `stats.json`, `stats.md`, `hist_instances_per_image.png`, `hist_sizes.png` and (unless
/// disabled) `contact_sheet.png` into `out_dir`; `image_root` is where `images[].file_name` are found.
/// Returns the files written.
///
/// # Errors
/// I/O and PNG errors naming the file. An image missing from the contact sheet is not an error: its
/// tile is drawn on grey and the problem logged.
pub fn write_report(
    stats: &Stats,
    datasets: &[(Split, &Dataset)],
    out_dir: &Path,
    image_root: &Path,
    opts: ReportOptions,
) -> Result<Vec<PathBuf>, CocoError> {
    let mut written = Vec::new();
    let json_path = out_dir.join(STATS_JSON_FILE);
    crate::util::write_json_atomic(&json_path, stats)?;
    written.push(json_path);

    for (file, chart) in charts(stats) {
        let p = out_dir.join(file);
        chart.draw().0.save(&p)?;
        written.push(p);
    }

    let sheet = opts.contact_sheet_images > 0;
    if sheet {
        let p = out_dir.join(CONTACT_SHEET_FILE);
        contact_sheet(datasets, image_root, &pick_images(datasets, opts.contact_sheet_images, None))?
            .save(&p)?;
        written.push(p);
    }

    let md_path = out_dir.join(STATS_MD_FILE);
    crate::util::write_bytes_atomic(&md_path, markdown(stats, sheet).as_bytes())?;
    written.push(md_path);
    Ok(written)
}

/// The report's charts with their file names, in the order they appear: instances per image, sizes
/// and (when any image was scored) consistency, one series per split.
pub fn charts(stats: &Stats) -> Vec<(&'static str, BarChart)> {
    let series = |values: &dyn Fn(&SplitStats) -> Option<Vec<f64>>| -> Vec<Series> {
        stats
            .splits
            .iter()
            .enumerate()
            .filter_map(|(i, s)| {
                Some(Series { name: s.split.clone(), colour: SPLIT_COLOURS[i % 3], values: values(s)? })
            })
            .collect()
    };
    // Instances per image, grouped into at most 25 bins.
    let max = stats.splits.iter().map(|s| s.max_instances_per_image).max().unwrap_or(0);
    let width = (max + 1).div_ceil(25).max(1);
    let n_bins = (max / width + 1) as usize;
    let per_image = BarChart {
        title: if width == 1 {
            "Images by number of instances".to_string()
        } else {
            format!("Images by number of instances (bins of {width})")
        },
        x_label: if width == 1 {
            "instances (building masks) per image".to_string()
        } else {
            format!("instances per image (lower bound of a bin of {width})")
        },
        y_label: "images".into(),
        categories: (0..n_bins as u64).map(|b| format!("{}", b * width)).collect(),
        series: series(&|s| {
            let mut values = vec![0.0; n_bins];
            for bin in &s.instances_per_image {
                values[(bin.instances / width) as usize] += bin.images as f64;
            }
            Some(values)
        }),
    };
    let sizes = BarChart {
        title: "Instances by COCO size class".into(),
        x_label: "mask area (px)".into(),
        y_label: "instances".into(),
        categories: vec!["small: < 32²".into(), "medium: 32²–96²".into(), "large: ≥ 96²".into()],
        series: series(&|s| Some(vec![s.sizes.small as f64, s.sizes.medium as f64, s.sizes.large as f64])),
    };
    let mut out = vec![(HIST_INSTANCES_FILE, per_image), (HIST_SIZES_FILE, sizes)];
    // Consistency scores (render-masks --tileset), when any image has one.
    if stats.splits.iter().any(|s| s.consistency.is_some()) {
        out.push((
            HIST_CONSISTENCY_FILE,
            BarChart {
                title: "Images by LoD/tileset consistency score".into(),
                x_label: "consistency score (lower bound of a bin of 0.1)".into(),
                y_label: "images".into(),
                categories: (0..CONSISTENCY_BINS)
                    .map(|b| format!("{:.1}", b as f64 / CONSISTENCY_BINS as f64))
                    .collect(),
                series: series(&|s| Some(s.consistency.as_ref()?.bins.iter().map(|&n| n as f64).collect())),
            },
        ));
    }
    out
}

/// What the size columns of [`splits_table`] count.
pub const SIZE_CLASSES_NOTE: &str =
    "Size classes are COCO's: small < 32² px, medium < 96² px, large ≥ 96² px (area = mask pixel count).";

/// The statistics table, one row per split: the one table the dataset card, `stats.md` and
/// `index.html` show.
pub fn splits_table(stats: &Stats) -> Table {
    let mut t = Table::new(&[
        ("split", false),
        ("areas", false),
        ("images", true),
        ("without annotations", true),
        ("annotations", true),
        ("per image (mean / max)", true),
        ("small", true),
        ("medium", true),
        ("large", true),
        ("truncated", true),
        ("crowd", true),
        ("median area (px)", true),
    ]);
    for sp in &stats.splits {
        t.push(vec![
            sp.split.clone(),
            if sp.areas.is_empty() { "—".to_string() } else { sp.areas.join(", ") },
            sp.images.to_string(),
            sp.images_without_annotations.to_string(),
            sp.annotations.to_string(),
            format!("{:.2} / {}", sp.mean_instances_per_image, sp.max_instances_per_image),
            sp.sizes.small.to_string(),
            sp.sizes.medium.to_string(),
            sp.sizes.large.to_string(),
            sp.truncated.to_string(),
            sp.crowd.to_string(),
            sp.median_area_px.to_string(),
        ]);
    }
    t
}

fn markdown(stats: &Stats, sheet: bool) -> String {
    let mut s = String::new();
    let _ = writeln!(s, "# COCO export statistics\n\nWritten by insgen {}.\n", stats.insgen_version);
    let _ = writeln!(s, "## Splits\n");
    s.push_str(&splits_table(stats).markdown());
    let _ = writeln!(s, "\n{SIZE_CLASSES_NOTE}\n");
    if stats.splits.iter().any(|sp| sp.consistency.is_some()) {
        let _ = writeln!(s, "## LoD/tileset consistency\n\n| split | images scored | mean | median | min |");
        let _ = writeln!(s, "|---|---:|---:|---:|---:|");
        for sp in &stats.splits {
            if let Some(c) = &sp.consistency {
                let _ = writeln!(
                    s,
                    "| {} | {} | {:.3} | {:.3} | {:.3} |",
                    sp.split, c.images, c.mean, c.median, c.min
                );
            }
        }
        let _ = writeln!(s, "\n![consistency](hist_consistency.png)\n");
    }
    let _ = writeln!(s, "## Instances per image\n");
    let _ = writeln!(s, "| split | instances: images |\n|---|---|");
    for sp in &stats.splits {
        let bins: Vec<String> =
            sp.instances_per_image.iter().map(|b| format!("{}: {}", b.instances, b.images)).collect();
        let _ =
            writeln!(s, "| {} | {} |", sp.split, if bins.is_empty() { "—".into() } else { bins.join(", ") });
    }
    let _ =
        writeln!(s, "\n![instances per image](hist_instances_per_image.png)\n\n![sizes](hist_sizes.png)\n");
    let _ = writeln!(s, "## Areas\n");
    let _ = writeln!(
        s,
        "| area | split | images | annotations | buildings seen | buildings in model | coverage |"
    );
    let _ = writeln!(s, "|---|---|---:|---:|---:|---:|---:|");
    for a in &stats.areas {
        let _ = writeln!(
            s,
            "| {} | {} | {} | {} | {} | {} | {:.1}% |",
            a.area,
            a.split,
            a.images,
            a.annotations,
            a.buildings_seen,
            a.buildings_total,
            100.0 * a.coverage
        );
    }
    s.push_str(&super::learnability::markdown_section(&stats.areas));
    if sheet {
        let _ = writeln!(s, "\n## Contact sheet\n\n![annotated frames](contact_sheet.png)");
    }
    s
}

/// Tile size of the contact sheet, px.
const TILE_W: u32 = 320;
const TILE_H: u32 = 240;
const COLUMNS: u32 = 4;

/// Picks up to `n` images (of `area` only, when given) spread evenly over the splits and over each
/// split's images.
fn pick_images(datasets: &[(Split, &Dataset)], n: usize, area: Option<&str>) -> Vec<(Split, usize)> {
    let candidates: Vec<(Split, Vec<usize>)> = datasets
        .iter()
        .map(|(split, ds)| {
            let of_area =
                ds.images.iter().enumerate().filter(|(_, im)| area.is_none_or(|a| im.area_name == a));
            (*split, of_area.map(|(i, _)| i).collect::<Vec<usize>>())
        })
        .filter(|(_, idx)| !idx.is_empty())
        .collect();
    if candidates.is_empty() || n == 0 {
        return Vec::new();
    }
    let per = n.div_ceil(candidates.len());
    let mut out = Vec::new();
    for (split, idx) in candidates {
        let len = idx.len();
        let k = per.min(len);
        for j in 0..k {
            out.push((split, idx[j * len / k]));
        }
    }
    out.truncate(n);
    out
}

/// The contact sheet of one area: up to `n` of its frames, annotated as on `contact_sheet.png`.
///
/// # Errors
/// As the report's contact sheet (an unreadable photo is drawn grey and logged, not an error).
pub fn area_contact_sheet(
    datasets: &[(Split, &Dataset)],
    area: &str,
    image_root: &Path,
    n: usize,
) -> Result<RgbImage, CocoError> {
    contact_sheet(datasets, image_root, &pick_images(datasets, n, Some(area)))
}

/// Draws the contact sheet: each picked frame (RGB when `file_name` is an RGB render, else grey) with
/// its annotations filled and outlined in per-building colours, labelled with split and frame.
fn contact_sheet(
    datasets: &[(Split, &Dataset)],
    image_root: &Path,
    picks: &[(Split, usize)],
) -> Result<RgbImage, CocoError> {
    let cols = COLUMNS.min(picks.len().max(1) as u32);
    let rows = (picks.len() as u32).div_ceil(cols).max(1);
    let mut sheet = RgbImage::new(cols * TILE_W, rows * TILE_H, [32, 32, 32]);
    for (t, &(split, idx)) in picks.iter().enumerate() {
        let ds = datasets.iter().find(|(s, _)| *s == split).map(|(_, d)| *d).expect("picked from datasets");
        let im = &ds.images[idx];
        // Fit the frame into the tile keeping its aspect ratio.
        let scale = (TILE_W as f64 / im.width.max(1) as f64).min(TILE_H as f64 / im.height.max(1) as f64);
        let (tw, th) =
            (((im.width as f64 * scale) as u32).max(1), ((im.height as f64 * scale) as u32).max(1));
        let mut tile = if im.file_name != im.mask_file {
            match read_png_rgb(&image_root.join(&im.file_name)) {
                Ok(rgb) => rgb.resized(tw, th),
                Err(e) => {
                    log::warn!("contact sheet: {}", super::error::chain_string(&e));
                    RgbImage::new(tw, th, [90, 90, 90])
                }
            }
        } else {
            RgbImage::new(tw, th, [90, 90, 90])
        };
        for a in ds.annotations.iter().filter(|a| a.image_id == im.id) {
            let rle_json = match (&a.segmentation, &a.mask_rle) {
                (_, Some(r)) => r,
                (Segmentation::Rle(r), None) => r,
                (Segmentation::Polygons(_), None) => continue,
            };
            let Ok(rle) = rle_json.to_rle() else { continue };
            let [h, w] = rle.size;
            if (w, h) != (im.width, im.height) {
                continue;
            }
            let full = rle.decode();
            // Nearest-neighbour downsampling of the mask to the tile.
            let small: Vec<bool> = (0..th)
                .flat_map(|y| {
                    let sy = (((y as f64 + 0.5) / scale) as u32).min(h - 1);
                    let full = &full;
                    (0..tw).map(move |x| {
                        let sx = (((x as f64 + 0.5) / scale) as u32).min(w - 1);
                        full[(sy * w + sx) as usize] != 0
                    })
                })
                .collect();
            let c = palette(a.building_id.get() as u64);
            let at = |x: i64, y: i64| {
                x >= 0 && y >= 0 && x < tw as i64 && y < th as i64 && small[(y * tw as i64 + x) as usize]
            };
            for y in 0..th as i64 {
                for x in 0..tw as i64 {
                    if !at(x, y) {
                        continue;
                    }
                    if !at(x - 1, y) || !at(x + 1, y) || !at(x, y - 1) || !at(x, y + 1) {
                        tile.put(x, y, c);
                    } else {
                        tile.blend(x, y, c, 0.35);
                    }
                }
            }
        }
        let label = format!("{} · {}", split.as_str(), im.frame);
        tile.text_on(0, 0, &label, TextStyle::new(text::TICK_PX, [255, 255, 255]), [0, 0, 0], 3);
        let (col, row) = (t as u32 % cols, t as u32 / cols);
        let (ox, oy) = (col * TILE_W + (TILE_W - tw) / 2, row * TILE_H + (TILE_H - th) / 2);
        sheet.paste(&tile, ox as i64, oy as i64);
    }
    Ok(sheet)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::export::format::*;

    fn dataset(anns: &[(u64, u64, u32)]) -> Dataset {
        // anns: (image_id, area, building_id)
        let info = super::super::format::testing::info();
        let images = (1..=3).map(|id| super::super::format::testing::image(id, 4, 4)).collect();
        let annotations = anns
            .iter()
            .enumerate()
            .map(|(i, &(image_id, area, building_id))| Annotation {
                id: i as u64 + 1,
                image_id,
                category_id: 1,
                segmentation: Segmentation::Polygons(vec![]),
                area,
                bbox: [0.0; 4],
                iscrowd: (i == 0) as u8,
                building_id: BuildingId::new(building_id).unwrap(),
                source_id: String::new(),
                component: Some(0),
                num_components: None,
                visible_fraction: None,
                truncated: i == 1,
                area_name: "a".into(),
                mask_rle: None,
            })
            .collect();
        Dataset { info, licenses: vec![], images, annotations, categories: vec![Category::building()] }
    }

    #[test]
    fn counts_sizes_histogram_and_coverage() {
        // Image 1: three instances; image 2: one; image 3: none. Areas on both sides of 32² and 96².
        let ds = dataset(&[(1, 1023, 5), (1, 1024, 5), (1, 9215, 6), (2, 9216, 7)]);
        // No ID map is on disk here: the learnability block has sizes and splits only.
        let st = compute(&[(Split::Train, &ds)], Path::new("/nonexistent")).unwrap();
        let sp = &st.splits[0];
        assert_eq!((sp.images, sp.annotations, sp.images_without_annotations), (3, 4, 1));
        assert_eq!(sp.sizes, SizeCounts { small: 1, medium: 2, large: 1 });
        assert_eq!(
            sp.instances_per_image,
            [
                PerImageBin { instances: 0, images: 1 },
                PerImageBin { instances: 1, images: 1 },
                PerImageBin { instances: 3, images: 1 }
            ]
        );
        assert_eq!((sp.max_instances_per_image, sp.crowd, sp.truncated), (3, 1, 1));
        assert!((sp.mean_instances_per_image - 4.0 / 3.0).abs() < 1e-12);
        assert_eq!(sp.median_area_px, 9215);
        let a = &st.areas[0];
        assert_eq!((a.buildings_seen, a.buildings_total, a.images, a.annotations), (3, 10, 3, 4));
        assert!((a.coverage - 0.3).abs() < 1e-12);
    }

    #[test]
    fn consistency_bins_mean_median() {
        assert_eq!(ConsistencyStats::of(&[]), None);
        let c = ConsistencyStats::of(&[1.0, 0.95, 0.05, 0.5]).unwrap();
        assert_eq!(c.images, 4);
        assert_eq!(c.bins, vec![1, 0, 0, 0, 0, 1, 0, 0, 0, 2]);
        assert!((c.mean - 0.625).abs() < 1e-12);
        assert_eq!((c.min, c.median), (0.05, 0.95));
    }

    #[test]
    fn picks_spread_over_splits() {
        let ds = dataset(&[]);
        let picks = pick_images(&[(Split::Train, &ds), (Split::Val, &ds)], 4, None);
        assert_eq!(picks, [(Split::Train, 0), (Split::Train, 1), (Split::Val, 0), (Split::Val, 1)]);
    }
}
