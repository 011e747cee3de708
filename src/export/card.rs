//! The dataset card, `README.md` next to the COCO files: what the dataset contains, its splits and
//! areas, counts and statistics (with each area's learnability table), camera presets, the licences
//! and attributions of every source, how it was made and how to load it. Written from the
//! [`DatasetManifest`] and the [`Stats`], so it never says anything the files do not.

use std::fmt::Write as _;

use super::manifest::DatasetManifest;
use super::stats::Stats;

/// File name of the card in a dataset directory.
pub use crate::layout::CARD_FILE;

/// The card's Markdown.
pub fn card_markdown(m: &DatasetManifest, stats: &Stats) -> String {
    let mut s = String::new();
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
            let _ = writeln!(s, "  - {}", source_line(&src.path, &src.sha256));
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
    s
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
/// file: `prepare` records [`crate::scene::procedural::DEMO_SOURCE_PATH`] for both), what it is.
pub fn source_line(path: &str, sha256: &str) -> String {
    use crate::scene::procedural::DEMO_SOURCE_PATH;
    if sha256 == DEMO_SOURCE_PATH {
        format!(
            "`{path}`: procedural (insgen's embedded demo city generator; no source file to hash — the scene \
             file's `[sources.procedural]` table and its seed define the city)"
        )
    } else {
        format!("`{path}` (SHA-256 `{sha256}`)")
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
        let demo = source_line("procedural", "procedural");
        assert!(
            demo.starts_with("`procedural`: procedural (insgen's embedded demo city")
                && !demo.contains("SHA"),
            "{demo}"
        );
        assert_eq!(source_line("a.gml", "ab12"), "`a.gml` (SHA-256 `ab12`)");
    }
}
