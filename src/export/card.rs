//! The dataset card, `README.md` next to the COCO files: what the dataset contains, its splits and
//! areas, counts and statistics (with each area's learnability table), camera presets, the licences
//! and attributions of every source, how it was made and how to load it. Written from the
//! [`DatasetManifest`] and the [`Stats`], so it never says anything the files do not.

use std::fmt::Write as _;

use super::coco::Split;
use super::format::SourceInfo;
use super::manifest::DatasetManifest;
use super::stats::Stats;

/// File name of the card in a dataset directory.
pub use crate::layout::CARD_FILE;

/// The card's Markdown; `hf_splits`: the splits with Hugging Face `datasets` metadata
/// (`images/<split>/metadata.jsonl`), named in the YAML front matter ([`super::hf::front_matter`]) so
/// that `datasets.load_dataset("<this folder>")` loads them.
pub fn card_markdown(m: &DatasetManifest, stats: &Stats, hf_splits: &[Split]) -> String {
    let mut s = super::hf::front_matter(hf_splits);
    let total_images: u64 = m.files.iter().map(|f| f.images).sum();
    let total_anns: u64 = m.files.iter().map(|f| f.annotations).sum();
    let _ = writeln!(s, "# Building-instance dataset (insgen)\n");
    let _ = writeln!(
        s,
        "Aerial (UAV) RGB frames of {} area(s) with one instance mask per visible building, made by \
         insgen {} (commit `{}`) from geo-referenced LoD city models: \
         {total_images} images, {total_anns} annotations, one category (`building`). Every image is a \
         rendered photo; every mask is exactly what the instanced city model shows at that photo's pose \
         (pixel-aligned renders of the same scene).\n",
        m.areas.len(),
        m.tool.version,
        m.tool.git_commit
    );
    let _ = writeln!(s, "## Splits\n\nSplits are geographic: an area's images are all in one split.\n");
    let _ = writeln!(s, "| split | file | images | annotations | areas |\n|---|---|---:|---:|---|");
    for f in &m.files {
        let areas: Vec<&str> =
            m.areas.iter().filter(|a| a.split == f.split).map(|a| a.name.as_str()).collect();
        let _ = writeln!(
            s,
            "| {} | `{}` | {} | {} | {} |",
            f.split,
            f.path,
            f.images,
            f.annotations,
            areas.join(", ")
        );
    }
    let _ = writeln!(s, "\n## Areas and cameras\n");
    let _ = writeln!(s, "| area | split | buildings | camera | frame size | images | annotations |");
    let _ = writeln!(s, "|---|---|---:|---|---|---:|---:|");
    for a in &m.areas {
        for c in &a.cameras {
            let _ = writeln!(
                s,
                "| {}{} | {} | {} | {} | {}×{} | {} | {} |",
                a.name,
                if a.held_out { " (held out)" } else { "" },
                a.split,
                a.buildings,
                camera_and_preset(&c.name, &c.preset),
                c.width_px,
                c.height_px,
                c.images,
                c.annotations
            );
        }
    }
    s.push_str(&statistics_section(stats));
    s.push_str(&super::learnability::card_section(&stats.areas));
    let _ = writeln!(s, "\n## Sources, licences and attributions\n");
    for a in &m.areas {
        let attribution = if a.attributions.is_empty() {
            "no attribution given".to_string()
        } else {
            a.attributions.join("; ")
        };
        let _ = writeln!(s, "- **{}**: {attribution}", a.name);
        for src in &a.sources {
            let _ = writeln!(s, "  - {}", source_line(src));
        }
    }
    let _ = writeln!(
        s,
        "\nThe masks and images derive from these models: use them under the sources' licences, with their \
         attributions."
    );
    let _ = writeln!(s, "\n## How it was made\n");
    let _ = writeln!(
        s,
        "Annotation unit: `{}`; filters: minimum area {} px{}, truncated instances: {:?}. The commands, in \
         order (also in `dataset.json`, with their durations):\n\n```sh",
        match m.export.annotation_unit {
            super::AnnotationUnit::Component => "component",
            super::AnnotationUnit::Building => "building",
        },
        m.export.filters.min_area_px,
        m.export
            .filters
            .min_visible_fraction
            .map(|v| format!(", minimum visible fraction {v}"))
            .unwrap_or_default(),
        m.export.filters.truncated,
    );
    for c in m.commands.iter().filter(|c| c.ok) {
        let _ = writeln!(s, "{}", c.argv.iter().map(|a| shell_word(a)).collect::<Vec<_>>().join(" "));
    }
    let _ = writeln!(s, "```\n");
    let _ = writeln!(
        s,
        "## Loading\n\n```python\nfrom pycocotools.coco import COCO\nimport json, os\ncoco = COCO(\"instances_train.json\")\n\
         root = os.path.join(os.path.dirname(\"instances_train.json\"), json.load(open(\"instances_train.json\"))[\"info\"][\"image_root\"])\n\
         img = coco.loadImgs(coco.getImgIds()[0])[0]\nphoto = os.path.join(root, img[\"file_name\"])\n\
         masks = [coco.annToMask(a) for a in coco.loadAnns(coco.getAnnIds(imgIds=img[\"id\"]))]\n```\n\n\
         `file_name` is relative to `info.image_root` (relative to this directory). Each image record also \
         carries the camera (`intrinsics`, `cam_to_world_enu`, COLMAP `colmap_qvec`/`colmap_tvec`, WGS84 \
         position and yaw/pitch/roll) and `mask_file`, the lossless 24-bit ID map (building ID = R·2¹⁶ + \
         G·2⁸ + B). `insgen verify <this directory>` checks the files against `dataset.json`."
    );
    s.push_str(&hf_loading(hf_splits));
    s
}

/// The card's lines on loading the dataset with Hugging Face `datasets` (none without metadata).
fn hf_loading(hf_splits: &[Split]) -> String {
    if hf_splits.is_empty() {
        return String::new();
    }
    let names: Vec<&str> = hf_splits.iter().map(|s| super::hf::split_name(*s)).collect();
    format!(
        "\nWith Hugging Face `datasets` (the front matter above names the splits: {}):\n\n```python\n\
         from datasets import load_dataset\nds = load_dataset(\"path/to/this/directory\")\nrow = ds[\"{}\"][0]\n\
         row[\"image\"], row[\"objects\"][\"bbox\"], row[\"objects\"][\"segmentation\"]  # PIL image, [x, y, w, h], COCO RLE\n```\n",
        names.join(", "),
        names[0]
    )
}

/// The card's statistics: the table `stats.md` and `index.html` show too.
fn statistics_section(stats: &Stats) -> String {
    format!(
        "\n## Statistics\n\n{}\n{} `stats.md` has the histograms; `index.html` shows them with contact sheets and \
         flight plans.\n",
        super::stats::splits_table(stats).markdown(),
        super::stats::SIZE_CLASSES_NOTE
    )
}

/// A camera as the card names it: `name`, or `name (preset P)` when it was sampled with a preset of
/// another name.
pub fn camera_and_preset(name: &str, preset: &str) -> String {
    if name == preset || preset.is_empty() {
        name.to_string()
    } else {
        format!("{name} (preset {preset})")
    }
}

/// A source as the card lists it: the file with its SHA-256, or, for the generated demo city (no
/// file: `prepare` records [`crate::scene::procedural::DEMO_SOURCE_PATH`] for both), the seed and
/// parameters that define it (from the scene manifest's record; an export of a scene prepared before
/// the record existed says where they are instead).
pub fn source_line(src: &SourceInfo) -> String {
    use crate::scene::procedural::DEMO_SOURCE_PATH;
    let path = &src.path;
    match (&src.procedural, src.sha256 == DEMO_SOURCE_PATH) {
        (Some(city), _) => format!(
            "`{path}`: procedural (insgen's embedded demo city generator; no source file to hash — these \
             parameters define the city: {})",
            city.describe()
        ),
        (None, true) => format!(
            "`{path}`: procedural (insgen's embedded demo city generator; no source file to hash — the scene \
             file's `[sources.procedural]` table and its seed define the city)"
        ),
        (None, false) => format!("`{path}` (SHA-256 `{}`)", src.sha256),
    }
}

/// `a` quoted for a POSIX shell when it holds anything but safe characters.
fn shell_word(a: &str) -> String {
    if !a.is_empty() && a.chars().all(|c| c.is_ascii_alphanumeric() || "-_./=:,+@%".contains(c)) {
        a.to_string()
    } else {
        format!("'{}'", a.replace('\'', r"'\''"))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shell_words_are_quoted_only_when_needed() {
        assert_eq!(shell_word("--area"), "--area");
        assert_eq!(shell_word("runs/demo"), "runs/demo");
        assert_eq!(shell_word("a b"), "'a b'");
        assert_eq!(shell_word("it's"), r"'it'\''s'");
        assert_eq!(shell_word(""), "''");
    }

    #[test]
    fn cameras_and_sources_say_each_thing_once() {
        assert_eq!(camera_and_preset("cam2-quarter", "cam2-quarter"), "cam2-quarter");
        assert_eq!(camera_and_preset("low", "cam2"), "low (preset cam2)");
        let source = |path: &str, sha256: &str| SourceInfo {
            path: path.into(),
            sha256: sha256.into(),
            procedural: None,
        };
        let demo = source_line(&source("procedural", "procedural"));
        assert!(
            demo.starts_with("`procedural`: procedural (insgen's embedded demo city")
                && !demo.contains("SHA"),
            "{demo}"
        );
        assert_eq!(source_line(&source("a.gml", "ab12")), "`a.gml` (SHA-256 `ab12`)");
    }

    #[test]
    fn a_generated_city_is_named_by_its_seed_and_parameters() {
        use crate::scene::procedural::{PlaneOrigin, ProceduralCity, ProceduralSpec};
        let spec =
            ProceduralSpec { seed: 4242, blocks_x: 6, tower_m: [90.0, 150.5], ..ProceduralSpec::default() };
        let city = ProceduralCity { spec, origin: PlaneOrigin { easting_m: -900.0, northing_m: -40800.0 } };
        let src =
            SourceInfo { path: "procedural".into(), sha256: "procedural".into(), procedural: Some(city) };
        let line = source_line(&src);
        assert_eq!(
            line,
            "`procedural`: procedural (insgen's embedded demo city generator; no source file to hash — these \
             parameters define the city: seed 4242; 6 × 10 blocks of 80 m, streets 14 m wide, avenues 30 m wide \
             every 4 streets, grid rotated 17°; ground at 3 m; 5 tower blocks, 2 plazas; heights: low-rise \
             6–25 m, mid-rise 25–60 m, towers 90–150.5 m; centre EPSG:6677 E -900 m N -40800 m)"
        );
    }
}
