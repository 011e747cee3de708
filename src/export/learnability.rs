//! Per-area statistics that predict how learnable the building instances are (issue 37): how much of
//! the instances' outlines borders another building, how much the photo separates touching buildings,
//! how large the instances are, and how often occluders split a building's mask.
//!
//! Takes in one split's COCO [`Dataset`] and the directory its `images[].file_name` and `mask_file`
//! are relative to; reads each image's instance-ID map ([`IdMap::read_png`]) and, when the export lists
//! photos, its RGB frame. Hands on one [`Learnability`] per area, for `stats.{md,json}` and the card.
//!
//! # Definitions
//! - **Touching-neighbour pair**: two 4-neighbours (left/right or up/down) of an ID map that are both
//!   buildings, with different building IDs. The **touching boundary** of an image is the number of such
//!   pairs, px: two 10 × 10 squares side by side touch along 10 px.
//! - **Background pair**: two 4-neighbours of which one is a building and the other background.
//! - **Perimeter** of an instance (a building in one frame, all its visible pixels): its touching and
//!   background pairs (the frame border does not count). Its **touching share** is touching / perimeter:
//!   the fraction of its outline that borders another building rather than background.
//! - **Colour contrast** of a pair: |ΔR| + |ΔG| + |ΔB| over 3, in 0–255 levels, averaged over the
//!   touching pairs and over the background pairs of the area's photos; their ratio (touching /
//!   background) is low when nothing in the photo separates neighbours that the masks separate.
//! - **Texture contrast** of a pair: the absolute difference of the two pixels' local texture, each the
//!   standard deviation of the grey level ((R + G + B) / 3, 0–255 levels) over the pixel's 3 × 3
//!   neighbours with its own ID (so the window never straddles the boundary being measured).
//! - **Sizes**: annotation `area` (px, and as a share of the image's pixels), quantiles by nearest rank
//!   (the smallest value with at least q of the values at or below it), and the share below 32² px
//!   (COCO's "small").
//! - **Split by occluders**: a building in a frame whose visible mask has more than one connected
//!   component (`num_components > 1` in building-unit exports; more than one annotation with that
//!   `building_id` in the image in component-unit exports).
//!
//! Every number is computed per image in parallel, then summed in image order (colour sums are integers),
//! so the same files give byte-identical reports, however the frames were exported or merged.

use std::collections::{BTreeMap, BTreeSet, HashMap};
use std::fmt::Write as _;
use std::path::Path;

use rayon::prelude::*;
use serde::Serialize;

use super::error::ImageProblem;
use super::format::{Dataset, Image};
use super::raster::{read_png_rgb, RgbImage};
use super::stats::{AreaStats, SMALL_MAX_PX};
use super::CocoError;
use crate::scene::{BuildingId, IdMap};

/// The learnability statistics of one area.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Learnability {
    /// Images of the area.
    pub images: u64,
    /// Images whose ID map was on disk and read (the boundary statistics cover these).
    pub images_with_id_map: u64,
    /// Images whose RGB photo was on disk and read (the contrast statistics cover these; a
    /// `--label-only` export has none).
    pub images_with_rgb: u64,
    /// Annotation sizes.
    pub sizes: SizeDistribution,
    /// Masks split in several components by an occluder.
    pub occluder_splits: OccluderSplits,
    /// Absent when no ID map could be read.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub boundary: Option<BoundaryStats>,
    /// Absent when no photo could be read.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub contrast: Option<ContrastStats>,
}

/// The distribution of annotation sizes.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SizeDistribution {
    /// Annotations.
    pub instances: u64,
    /// 10th percentile of the annotation area, pixels.
    pub area_p10_px: u64,
    /// Median annotation area, pixels.
    pub area_p50_px: u64,
    /// 90th percentile of the annotation area, pixels.
    pub area_p90_px: u64,
    /// Quantiles of area / (width × height) of the annotation's image.
    pub area_p10_share: f64,
    /// Median of area / image area.
    pub area_p50_share: f64,
    /// 90th percentile of area / image area.
    pub area_p90_share: f64,
    /// Annotations with area < 32² px.
    pub small_share: f64,
}

/// Buildings whose mask occluders split.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct OccluderSplits {
    /// Buildings annotated per frame, summed over the frames ((image, building) pairs).
    pub buildings: u64,
    /// Of those, buildings whose visible mask has more than one connected component.
    pub split: u64,
    /// `split / buildings` (0 without buildings).
    pub split_share: f64,
}

/// Touching-neighbour boundaries in the ID maps.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct BoundaryStats {
    /// Touching-neighbour pairs per image, mean over the images with an ID map, px.
    pub touching_px_per_image: f64,
    /// Annotated buildings per frame measured ((image, building) pairs).
    pub instances: u64,
    /// Mean over the instances with a perimeter of touching / perimeter.
    pub touching_perimeter_share: f64,
    /// Instances that touch at least one other building.
    pub touching_instances_share: f64,
}

/// Colour and texture contrast across boundaries in the photos.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ContrastStats {
    /// Touching-neighbour pairs measured, px.
    pub touching_pairs_px: u64,
    /// Building/background pairs measured, px.
    pub background_pairs_px: u64,
    /// Mean colour difference across touching pairs, 0–255 levels.
    pub touching_rgb_levels: f64,
    /// Mean colour difference across building/background pairs, 0–255 levels.
    pub background_rgb_levels: f64,
    /// `touching_rgb_levels / background_rgb_levels`; absent when either has no pairs or the
    /// background contrast is 0.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub touching_to_background_rgb_ratio: Option<f64>,
    /// Mean texture difference across touching pairs, 0–255 levels.
    pub touching_texture_levels: f64,
    /// Mean texture difference across building/background pairs, 0–255 levels.
    pub background_texture_levels: f64,
}

/// Sums of one photo's contrast over its pairs.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
struct ContrastSums {
    touching_pairs: u64,
    background_pairs: u64,
    /// Σ (|ΔR| + |ΔG| + |ΔB|), an integer so that any summation order gives the same total.
    touching_rgb: u64,
    background_rgb: u64,
    touching_texture: f64,
    background_texture: f64,
}

impl ContrastSums {
    fn add(&mut self, o: &ContrastSums) {
        self.touching_pairs += o.touching_pairs;
        self.background_pairs += o.background_pairs;
        self.touching_rgb += o.touching_rgb;
        self.background_rgb += o.background_rgb;
        self.touching_texture += o.touching_texture;
        self.background_texture += o.background_texture;
    }
}

/// What one frame's ID map (and photo) show.
#[derive(Debug, Clone, Default, PartialEq)]
struct FrameMeasure {
    id_map_read: bool,
    /// Touching-neighbour pairs, px.
    touching_px: u64,
    /// Per annotated building in the frame (ascending ID): (touching, perimeter) pairs.
    instances: Vec<(u64, u64)>,
    contrast: Option<ContrastSums>,
}

/// Calls `f(i, j)` for every 4-neighbour pair of pixels (row-major indices) whose IDs differ.
fn for_each_differing_pair(ids: &[u32], width: usize, mut f: impl FnMut(usize, usize)) {
    if width == 0 {
        return;
    }
    for (y, row) in ids.chunks_exact(width).enumerate() {
        let base = y * width;
        for x in 0..width {
            let i = base + x;
            if x + 1 < width && row[x] != row[x + 1] {
                f(i, i + 1);
            }
            if i + width < ids.len() && row[x] != ids[i + width] {
                f(i, i + width);
            }
        }
    }
}

/// Standard deviation of the grey level ((R + G + B) / 3, 0–255 levels) over the 3 × 3 neighbours of
/// pixel `i` that carry its ID (itself included).
fn local_texture(ids: &[u32], rgb: &[u8], width: usize, i: usize) -> f64 {
    let height = ids.len() / width;
    let (x, y) = (i % width, i / width);
    let (mut n, mut sum, mut sum_sq) = (0.0f64, 0.0f64, 0.0f64);
    for ny in y.saturating_sub(1)..(y + 2).min(height) {
        for nx in x.saturating_sub(1)..(x + 2).min(width) {
            let j = ny * width + nx;
            if ids[j] == ids[i] {
                let g = (rgb[3 * j] as f64 + rgb[3 * j + 1] as f64 + rgb[3 * j + 2] as f64) / 3.0;
                n += 1.0;
                sum += g;
                sum_sq += g * g;
            }
        }
    }
    let mean = sum / n;
    (sum_sq / n - mean * mean).max(0.0).sqrt()
}

/// Measures one ID map (and, when given, its photo of the same size): touching pairs, each annotated
/// building's (touching, perimeter) pairs, and the contrast sums.
fn measure_ids(map: &IdMap, rgb: Option<&RgbImage>, annotated: &BTreeSet<BuildingId>) -> FrameMeasure {
    let ids = map.raw();
    let width = map.width() as usize;
    // Per building: (touching pairs, perimeter pairs).
    let mut per_building: HashMap<u32, (u64, u64)> = HashMap::new();
    let mut touching_px = 0u64;
    let mut sums = ContrastSums::default();
    for_each_differing_pair(ids, width, |i, j| {
        let (a, b) = (ids[i], ids[j]);
        let touching = a != 0 && b != 0;
        touching_px += touching as u64;
        for id in [a, b].into_iter().filter(|&id| id != 0) {
            let e = per_building.entry(id).or_default();
            e.0 += touching as u64;
            e.1 += 1;
        }
        if let Some(rgb) = rgb {
            let (p, q) = (&rgb.data[3 * i..3 * i + 3], &rgb.data[3 * j..3 * j + 3]);
            let diff: u64 = (0..3).map(|c| p[c].abs_diff(q[c]) as u64).sum();
            let texture =
                (local_texture(ids, &rgb.data, width, i) - local_texture(ids, &rgb.data, width, j)).abs();
            if touching {
                sums.touching_pairs += 1;
                sums.touching_rgb += diff;
                sums.touching_texture += texture;
            } else {
                sums.background_pairs += 1;
                sums.background_rgb += diff;
                sums.background_texture += texture;
            }
        }
    });
    let instances = annotated.iter().map(|b| per_building.get(&b.get()).copied().unwrap_or((0, 0))).collect();
    FrameMeasure { id_map_read: true, touching_px, instances, contrast: rgb.map(|_| sums) }
}

/// Reads and measures one image's ID map and (when `read_rgb`) photo. A file not on disk is skipped
/// (the measure says what was read); a file that is there but unreadable, or a photo whose size
/// differs from its ID map's, is an error naming it.
fn measure_image(
    image: &Image,
    annotated: &BTreeSet<BuildingId>,
    image_root: &Path,
    read_rgb: bool,
) -> Result<FrameMeasure, CocoError> {
    let mask_path = image_root.join(&image.mask_file);
    if !mask_path.is_file() {
        return Ok(FrameMeasure::default());
    }
    let map = IdMap::read_png(&mask_path)?;
    let rgb_path = image_root.join(&image.file_name);
    let rgb = if read_rgb && image.file_name != image.mask_file && rgb_path.is_file() {
        let rgb = read_png_rgb(&rgb_path)?;
        if (rgb.width, rgb.height) != (map.width(), map.height()) {
            return Err(CocoError::Image {
                path: rgb_path,
                problem: ImageProblem::SizeMismatch {
                    size: [rgb.width, rgb.height],
                    id_map: mask_path,
                    id_map_size: [map.width(), map.height()],
                },
            });
        }
        Some(rgb)
    } else {
        None
    };
    Ok(measure_ids(&map, rgb.as_ref(), annotated))
}

/// The value at quantile `percent` of ascending `sorted` by nearest rank (`None` when empty).
fn nearest_rank<T: Copy>(sorted: &[T], percent: usize) -> Option<T> {
    let rank = (percent * sorted.len()).div_ceil(100).max(1);
    sorted.get(rank - 1).copied()
}

fn share(part: u64, whole: u64) -> f64 {
    if whole == 0 {
        0.0
    } else {
        part as f64 / whole as f64
    }
}

fn mean(sum: f64, n: u64) -> f64 {
    if n == 0 {
        0.0
    } else {
        sum / n as f64
    }
}

/// The size distribution and occluder splits of `images` (an area's) from the annotations alone.
fn from_annotations(ds: &Dataset, images: &BTreeSet<u64>) -> (SizeDistribution, OccluderSplits) {
    let pixels: HashMap<u64, u64> =
        ds.images.iter().map(|im| (im.id, im.width as u64 * im.height as u64)).collect();
    let mut areas_px = Vec::new();
    let mut area_shares = Vec::new();
    // (image, building) → components.
    let mut components: BTreeMap<(u64, BuildingId), u64> = BTreeMap::new();
    for a in ds.annotations.iter().filter(|a| images.contains(&a.image_id)) {
        areas_px.push(a.area);
        area_shares.push(share(a.area, pixels.get(&a.image_id).copied().unwrap_or(0)));
        let n = components.entry((a.image_id, a.building_id)).or_default();
        *n = match a.num_components {
            Some(c) => (*n).max(c as u64),
            None => *n + 1,
        };
    }
    areas_px.sort_unstable();
    area_shares.sort_by(f64::total_cmp);
    let small = areas_px.iter().filter(|&&a| a < SMALL_MAX_PX).count() as u64;
    let split = components.values().filter(|&&n| n > 1).count() as u64;
    let sizes = SizeDistribution {
        instances: areas_px.len() as u64,
        area_p10_px: nearest_rank(&areas_px, 10).unwrap_or(0),
        area_p50_px: nearest_rank(&areas_px, 50).unwrap_or(0),
        area_p90_px: nearest_rank(&areas_px, 90).unwrap_or(0),
        area_p10_share: nearest_rank(&area_shares, 10).unwrap_or(0.0),
        area_p50_share: nearest_rank(&area_shares, 50).unwrap_or(0.0),
        area_p90_share: nearest_rank(&area_shares, 90).unwrap_or(0.0),
        small_share: share(small, areas_px.len() as u64),
    };
    let buildings = components.len() as u64;
    (sizes, OccluderSplits { buildings, split, split_share: share(split, buildings) })
}

/// Sums the frames' measures into the boundary and contrast statistics.
fn from_measures(frames: &[FrameMeasure]) -> (Option<BoundaryStats>, Option<ContrastStats>) {
    let read: Vec<&FrameMeasure> = frames.iter().filter(|f| f.id_map_read).collect();
    let boundary = (!read.is_empty()).then(|| {
        let touching_px: u64 = read.iter().map(|f| f.touching_px).sum();
        let instances: Vec<(u64, u64)> = read.iter().flat_map(|f| f.instances.iter().copied()).collect();
        let with_perimeter: Vec<f64> =
            instances.iter().filter(|i| i.1 > 0).map(|&(t, p)| t as f64 / p as f64).collect();
        BoundaryStats {
            touching_px_per_image: mean(touching_px as f64, read.len() as u64),
            instances: instances.len() as u64,
            touching_perimeter_share: mean(with_perimeter.iter().sum(), with_perimeter.len() as u64),
            touching_instances_share: share(
                instances.iter().filter(|i| i.0 > 0).count() as u64,
                instances.len() as u64,
            ),
        }
    });
    let mut any_rgb = false;
    let mut s = ContrastSums::default();
    for c in frames.iter().filter_map(|f| f.contrast.as_ref()) {
        any_rgb = true;
        s.add(c);
    }
    let contrast = any_rgb.then(|| {
        let touching_rgb_levels = mean(s.touching_rgb as f64 / 3.0, s.touching_pairs);
        let background_rgb_levels = mean(s.background_rgb as f64 / 3.0, s.background_pairs);
        ContrastStats {
            touching_pairs_px: s.touching_pairs,
            background_pairs_px: s.background_pairs,
            touching_rgb_levels,
            background_rgb_levels,
            touching_to_background_rgb_ratio: (s.touching_pairs > 0 && background_rgb_levels > 0.0)
                .then(|| touching_rgb_levels / background_rgb_levels),
            touching_texture_levels: mean(s.touching_texture, s.touching_pairs),
            background_texture_levels: mean(s.background_texture, s.background_pairs),
        }
    });
    (boundary, contrast)
}

/// The learnability statistics of every area of `ds`, keyed by area name (areas without images
/// included). `image_root` is the directory `images[].file_name` and `mask_file` are relative to.
/// ID maps and photos not on disk are skipped and counted ([`Learnability::images_with_id_map`],
/// [`Learnability::images_with_rgb`]); a label-only export (`info.images_missing`) gets no photo read.
///
/// # Errors
/// [`CocoError::Ids`] / [`CocoError::PngDecode`] / [`CocoError::File`] for an ID map or photo that is
/// there but cannot be read, [`CocoError::Image`] for a photo whose size differs from its ID map's —
/// each naming the file; the first such image in the dataset's order.
pub fn compute(ds: &Dataset, image_root: &Path) -> Result<BTreeMap<String, Learnability>, CocoError> {
    let mut annotated: HashMap<u64, BTreeSet<BuildingId>> = HashMap::new();
    for a in &ds.annotations {
        annotated.entry(a.image_id).or_default().insert(a.building_id);
    }
    let none = BTreeSet::new();
    // A label-only export lists the photos to come: those on disk may be half-written renders.
    let read_rgb = !ds.info.images_missing;
    let results: Vec<Result<FrameMeasure, CocoError>> = ds
        .images
        .par_iter()
        .map(|im| measure_image(im, annotated.get(&im.id).unwrap_or(&none), image_root, read_rgb))
        .collect();
    // Sequentially, so that the error reported is always the first image's.
    let measures = results.into_iter().collect::<Result<Vec<_>, _>>()?;
    let mut out = BTreeMap::new();
    for info in &ds.info.areas {
        let idx: Vec<usize> = (0..ds.images.len()).filter(|&i| ds.images[i].area_name == info.name).collect();
        let ids: BTreeSet<u64> = idx.iter().map(|&i| ds.images[i].id).collect();
        let frames: Vec<FrameMeasure> = idx.iter().map(|&i| measures[i].clone()).collect();
        let (sizes, occluder_splits) = from_annotations(ds, &ids);
        let (boundary, contrast) = from_measures(&frames);
        out.insert(
            info.name.clone(),
            Learnability {
                images: idx.len() as u64,
                images_with_id_map: frames.iter().filter(|f| f.id_map_read).count() as u64,
                images_with_rgb: frames.iter().filter(|f| f.contrast.is_some()).count() as u64,
                sizes,
                occluder_splits,
                boundary,
                contrast,
            },
        );
    }
    Ok(out)
}

/// What the learnability numbers predict, in one sentence (stats.md and the card).
pub const WHAT_IT_PREDICTS: &str = "Instances are harder to learn the more of their outline touches another \
building, the less the photo changes across those touching boundaries compared with the building/background \
boundaries (a contrast ratio well below 1: neighbours that nothing in the photo separates), the smaller they \
are, and the more often occluders split them into pieces.";

/// `touching / background (ratio)` of the colour contrast, or a dash without photos.
fn colour_cell(c: Option<&ContrastStats>) -> String {
    match c {
        None => "— (no photos)".into(),
        Some(c) => format!(
            "{:.1} / {:.1} ({})",
            c.touching_rgb_levels,
            c.background_rgb_levels,
            c.touching_to_background_rgb_ratio.map(|r| format!("{r:.2}")).unwrap_or_else(|| "—".into())
        ),
    }
}

fn boundary_cells(b: Option<&BoundaryStats>) -> [String; 3] {
    match b {
        None => ["— (no ID maps)".into(), "—".into(), "—".into()],
        Some(b) => [
            format!("{:.0}", b.touching_px_per_image),
            format!("{:.1}%", 100.0 * b.touching_perimeter_share),
            format!("{:.1}%", 100.0 * b.touching_instances_share),
        ],
    }
}

/// The `## Learnability` section of `stats.md`: one row per area, the definitions in plain words, and
/// which images had no ID map or photo on disk.
pub fn markdown_section(areas: &[AreaStats]) -> String {
    let mut s = String::new();
    let _ = writeln!(s, "\n## Learnability\n\n{WHAT_IT_PREDICTS}\n");
    let _ = writeln!(
        s,
        "| area | split | touching boundary px / image | touching share of outline | instances touching | \
         colour contrast touching / background, levels (ratio) | texture contrast touching / background, \
         levels | area p10 / p50 / p90 px | area p10 / p50 / p90 % of image | small | split by occluders |"
    );
    let _ = writeln!(s, "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|");
    for a in areas {
        let l = &a.learnability;
        let [touching, perimeter, instances] = boundary_cells(l.boundary.as_ref());
        let texture = l
            .contrast
            .as_ref()
            .map(|c| format!("{:.1} / {:.1}", c.touching_texture_levels, c.background_texture_levels))
            .unwrap_or_else(|| "—".into());
        let z = &l.sizes;
        let _ = writeln!(
            s,
            "| {} | {} | {touching} | {perimeter} | {instances} | {} | {texture} | {} / {} / {} | {:.2} / {:.2} / \
             {:.2} | {:.1}% | {:.1}% ({} of {}) |",
            a.area,
            a.split,
            colour_cell(l.contrast.as_ref()),
            z.area_p10_px,
            z.area_p50_px,
            z.area_p90_px,
            100.0 * z.area_p10_share,
            100.0 * z.area_p50_share,
            100.0 * z.area_p90_share,
            100.0 * z.small_share,
            100.0 * l.occluder_splits.split_share,
            l.occluder_splits.split,
            l.occluder_splits.buildings
        );
    }
    s.push_str(DEFINITIONS);
    for a in areas {
        let l = &a.learnability;
        if l.images_with_id_map < l.images || l.images_with_rgb < l.images {
            let _ = writeln!(
                s,
                "- {}: {} of {} images have their ID map on disk, {} their photo; the boundary and contrast \
                 columns cover only those.",
                a.area, l.images_with_id_map, l.images, l.images_with_rgb
            );
        }
    }
    s
}

/// The definitions of the learnability columns, in plain words.
const DEFINITIONS: &str = "
Definitions. A *touching pair* is two pixels side by side or one above the other in an ID map that \
belong to two different buildings; a *background pair* is a building pixel next to a background pixel. \
*Touching boundary* counts an image's touching pairs (two 10 × 10 px squares side by side touch along \
10 px). An instance here is a building in one frame (all its visible pixels); its outline is its touching \
plus background pairs (the frame border does not count), and its *touching share* is the part of the \
outline that borders another building, averaged over instances. *Instances touching* is the share of \
instances with at least one touching pair. *Colour contrast* is the mean of |ΔR| + |ΔG| + |ΔB| over 3 \
(0–255 levels) across the pairs in the photos, touching and background, with their ratio; *texture \
contrast* is the mean difference across the pairs of the grey-level standard deviation over each \
pixel's 3 × 3 neighbours of its own building (or background). Sizes are the annotations' areas, \
quantiles by nearest rank; *small* is below 32² px. *Split by occluders* is the share of buildings per \
frame whose visible mask has more than one connected component.

";

/// The card's learnability table: one row per area, with [`WHAT_IT_PREDICTS`] above it.
pub fn card_section(areas: &[AreaStats]) -> String {
    let mut s = String::new();
    let _ = writeln!(s, "\n### Learnability\n\n{WHAT_IT_PREDICTS} Definitions in `stats.md`.\n");
    let _ = writeln!(
        s,
        "| area | touching boundary px / image | touching share of outline | colour contrast touching / \
         background (ratio) | median area px | small | split by occluders |"
    );
    let _ = writeln!(s, "|---|---:|---:|---:|---:|---:|---:|");
    for a in areas {
        let l = &a.learnability;
        let [touching, perimeter, _] = boundary_cells(l.boundary.as_ref());
        let _ = writeln!(
            s,
            "| {} | {touching} | {perimeter} | {} | {} | {:.1}% | {:.1}% |",
            a.area,
            colour_cell(l.contrast.as_ref()),
            l.sizes.area_p50_px,
            100.0 * l.sizes.small_share,
            100.0 * l.occluder_splits.split_share
        );
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::export::format::*;

    /// Two 10 × 10 px squares side by side (building 1 at x 1–10, building 2 at x 11–20, rows 1–10)
    /// on background, in a 22 × 12 px map.
    fn two_squares() -> IdMap {
        let (w, h) = (22u32, 12u32);
        let ids = (0..w * h)
            .map(|i| {
                let (x, y) = (i % w, i / w);
                match (x, y) {
                    (1..=10, 1..=10) => 1,
                    (11..=20, 1..=10) => 2,
                    _ => 0,
                }
            })
            .collect();
        IdMap::from_raw(w, h, ids).unwrap()
    }

    /// A photo of `map` painted with `colour(id, x)`.
    fn paint(map: &IdMap, colour: impl Fn(u32, u32) -> [u8; 3]) -> RgbImage {
        let mut img = RgbImage::new(map.width(), map.height(), [0, 0, 0]);
        for y in 0..map.height() {
            for x in 0..map.width() {
                img.put(x as i64, y as i64, colour(map.get(x, y).get(), x));
            }
        }
        img
    }

    fn flat(id: u32, _x: u32) -> [u8; 3] {
        match id {
            1 => [100, 100, 100],
            2 => [130, 100, 70],
            _ => [0, 0, 0],
        }
    }

    fn buildings(ids: &[u32]) -> BTreeSet<BuildingId> {
        ids.iter().map(|&b| BuildingId::new(b).unwrap()).collect()
    }

    mod boundary {
        use super::*;

        #[test]
        fn two_touching_squares_share_ten_px() {
            let m = measure_ids(&two_squares(), None, &buildings(&[1, 2]));
            // By hand: the squares meet along one 10 px column edge.
            assert_eq!(m.touching_px, 10);
            // Each square: 10 touching + 30 background pairs (top, bottom, outer side).
            assert_eq!(m.instances, [(10, 40), (10, 40)]);
            assert_eq!(m.contrast, None);
            let (b, c) = from_measures(&[m]);
            let b = b.unwrap();
            assert_eq!((b.touching_px_per_image, b.instances), (10.0, 2));
            assert_eq!((b.touching_perimeter_share, b.touching_instances_share), (0.25, 1.0));
            assert_eq!(c, None);
        }

        #[test]
        fn only_annotated_buildings_are_instances() {
            let m = measure_ids(&two_squares(), None, &buildings(&[2, 7]));
            // Building 7 is annotated but not in the map: no perimeter, touches nothing.
            assert_eq!(m.instances, [(10, 40), (0, 0)]);
            let b = from_measures(&[m, FrameMeasure::default()]).0.unwrap();
            // The unread frame counts in no mean; the instance without perimeter not in the share mean.
            assert_eq!((b.touching_px_per_image, b.touching_perimeter_share), (10.0, 0.25));
            assert_eq!(b.touching_instances_share, 0.5);
        }
    }

    mod contrast {
        use super::*;

        #[test]
        fn flat_colours_give_exact_differences() {
            let map = two_squares();
            let m = measure_ids(&map, Some(&paint(&map, flat)), &buildings(&[1, 2]));
            let (_, c) = from_measures(&[m]);
            let c = c.unwrap();
            assert_eq!((c.touching_pairs_px, c.background_pairs_px), (10, 60));
            // By hand: (|100−130| + 0 + |100−70|) / 3 = 20; to black (100·3)/3 = 100 and (130+100+70)/3 = 100.
            assert_eq!((c.touching_rgb_levels, c.background_rgb_levels), (20.0, 100.0));
            assert_eq!(c.touching_to_background_rgb_ratio, Some(0.2));
            assert_eq!((c.touching_texture_levels, c.background_texture_levels), (0.0, 0.0));
        }

        #[test]
        fn texture_is_measured_inside_each_side() {
            // Building 2 striped by column: grey 0 on x = 11, 13, …, grey 90 on x = 12, 14, …; its 3 × 3
            // neighbours of its own ID hold as many of each, so its texture is 45 levels (std of {0, 90});
            // building 1 is flat (0). Every touching pair: |0 − 45| = 45.
            let map = two_squares();
            let rgb = paint(&map, |id, x| match id {
                2 if x % 2 == 0 => [90, 90, 90],
                2 => [0, 0, 0],
                other => flat(other, x),
            });
            let c = from_measures(&[measure_ids(&map, Some(&rgb), &buildings(&[1, 2]))]).1.unwrap();
            assert!((c.touching_texture_levels - 45.0).abs() < 1e-9, "{}", c.touching_texture_levels);
        }
    }

    mod sizes_and_splits {
        use super::*;

        #[test]
        fn quantiles_by_nearest_rank_and_small_share() {
            let areas = [100, 200, 300, 400, 500, 600, 700, 800, 900, 2000];
            let anns: Vec<(u64, u32, u64, Option<u32>)> =
                areas.iter().enumerate().map(|(i, &a)| (1, i as u32 + 1, a, None)).collect();
            let ds = dataset(&anns, 100, 100);
            let (z, _) = from_annotations(&ds, &BTreeSet::from([1]));
            assert_eq!((z.instances, z.area_p10_px, z.area_p50_px, z.area_p90_px), (10, 100, 500, 900));
            // 100 × 100 px images: 500 px is 5 %.
            assert_eq!((z.area_p10_share, z.area_p50_share, z.area_p90_share), (0.01, 0.05, 0.09));
            assert_eq!(z.small_share, 0.9);
        }

        #[test]
        fn component_annotations_of_one_building_count_as_split() {
            // Building 5 has two components in image 1, building 6 one: one of two is split.
            let ds = dataset(&[(1, 5, 50, None), (1, 5, 20, None), (1, 6, 30, None)], 10, 10);
            let (_, s) = from_annotations(&ds, &BTreeSet::from([1]));
            assert_eq!((s.buildings, s.split, s.split_share), (2, 1, 0.5));
        }

        #[test]
        fn building_annotations_use_num_components() {
            let ds = dataset(&[(1, 5, 70, Some(2)), (1, 6, 30, Some(1)), (2, 5, 10, Some(1))], 10, 10);
            let (_, s) = from_annotations(&ds, &BTreeSet::from([1, 2]));
            assert_eq!((s.buildings, s.split, s.split_share), (3, 1, 1.0 / 3.0));
            // Image 2 alone: building 5 is whole there.
            let (_, s) = from_annotations(&ds, &BTreeSet::from([2]));
            assert_eq!((s.buildings, s.split), (1, 0));
        }
    }

    mod files {
        use super::*;

        fn write_frame(root: &Path, rgb: bool) -> Dataset {
            let map = two_squares();
            std::fs::create_dir_all(root.join("a/cam2/masks")).unwrap();
            std::fs::create_dir_all(root.join("a/cam2/rgb")).unwrap();
            map.write_png(&root.join("a/cam2/masks/1.png")).unwrap();
            if rgb {
                paint(&map, flat).save(&root.join("a/cam2/rgb/1.png")).unwrap();
            }
            let mut ds = dataset(&[(1, 1, 100, None), (1, 2, 100, None)], 22, 12);
            ds.images[0].file_name = "a/cam2/rgb/1.png".into();
            ds
        }

        #[test]
        fn reads_id_maps_and_photos_through_the_image_root() {
            let dir = tempfile::tempdir().unwrap();
            let ds = write_frame(dir.path(), true);
            let l = &compute(&ds, dir.path()).unwrap()["a"];
            // Image 2 has no files: the means are over image 1 alone.
            assert_eq!((l.images, l.images_with_id_map, l.images_with_rgb), (2, 1, 1));
            assert_eq!(l.boundary.as_ref().unwrap().touching_px_per_image, 10.0);
            assert_eq!(l.contrast.as_ref().unwrap().touching_rgb_levels, 20.0);
            assert_eq!(compute(&ds, dir.path()).unwrap(), compute(&ds, dir.path()).unwrap());
        }

        #[test]
        fn files_not_on_disk_are_skipped_and_counted() {
            let dir = tempfile::tempdir().unwrap();
            let ds = write_frame(dir.path(), false);
            let l = &compute(&ds, dir.path()).unwrap()["a"];
            assert_eq!((l.images_with_id_map, l.images_with_rgb), (1, 0));
            assert!(l.boundary.is_some() && l.contrast.is_none());
            // A label-only export reads no photo, even where one is on disk.
            let mut labels = write_frame(dir.path(), true);
            labels.info.images_missing = true;
            assert_eq!(compute(&labels, dir.path()).unwrap()["a"].images_with_rgb, 0);
            let empty = tempfile::tempdir().unwrap();
            let l = &compute(&ds, empty.path()).unwrap()["a"];
            assert_eq!((l.images_with_id_map, l.boundary.as_ref()), (0, None));
            // The sizes come from the annotations alone.
            assert_eq!(l.sizes.instances, 2);
        }

        #[test]
        fn broken_files_are_errors_naming_them() {
            let dir = tempfile::tempdir().unwrap();
            let ds = write_frame(dir.path(), false);
            RgbImage::new(8, 8, [0, 0, 0]).save(&dir.path().join("a/cam2/rgb/1.png")).unwrap();
            let e = crate::util::error_chain(&compute(&ds, dir.path()).unwrap_err());
            assert!(e.contains("rgb/1.png: 8×8 px, but its ID map") && e.contains("22×12 px"), "{e}");
            std::fs::write(dir.path().join("a/cam2/masks/1.png"), b"not a png").unwrap();
            let e = crate::util::error_chain(&compute(&ds, dir.path()).unwrap_err());
            assert!(e.contains("masks/1.png"), "{e}");
        }
    }

    /// One area `a`, images 1 and 2 of `width × height` px (masks at `a/cam2/masks/<id>.png`), and
    /// annotations (image_id, building_id, area px, num_components).
    fn dataset(anns: &[(u64, u32, u64, Option<u32>)], width: u32, height: u32) -> Dataset {
        let images = (1..=2).map(|id| super::super::format::testing::image(id, width, height)).collect();
        let annotations = anns
            .iter()
            .enumerate()
            .map(|(i, &(image_id, building_id, area, num_components))| Annotation {
                id: i as u64 + 1,
                image_id,
                category_id: 1,
                segmentation: Segmentation::Polygons(vec![]),
                area,
                bbox: [0.0; 4],
                iscrowd: 0,
                building_id: BuildingId::new(building_id).unwrap(),
                source_id: String::new(),
                component: num_components.is_none().then_some(0),
                num_components,
                visible_fraction: None,
                truncated: false,
                area_name: "a".into(),
                mask_rle: None,
            })
            .collect();
        let info = super::super::format::testing::info();
        Dataset { info, licenses: vec![], images, annotations, categories: vec![Category::building()] }
    }
}
