//! `insgen prepare`: build the instanced scene artifact of one or more areas.

use std::path::PathBuf;

use anyhow::Context;

use super::Global;
use crate::scene::{self, config::find_scene};

/// Reads an area's building models (scenes/<area>.toml), geo-references them into the area's ENU frame
/// and writes <workdir>/<area>/scene/{scene.glb, manifest.json, buildings.json}.
#[derive(Debug, Clone, clap::Args)]
#[command(
    after_long_help = "Examples:\n  insgen prepare --area demo\n  insgen prepare --area tokyo --area niiza\n  \
insgen prepare --scene my/area.toml"
)]
pub struct Args {
    /// Area name (a file <scenes>/<NAME>.toml); repeat for several.
    #[arg(long = "area", value_name = "NAME", required_unless_present = "scene")]
    pub areas: Vec<String>,
    /// A scene file given by path instead of by area name.
    #[arg(long, value_name = "FILE", conflicts_with = "areas")]
    pub scene: Option<PathBuf>,
    /// Buildings only: no streets, ground cover, trees, cars or rooftop units.
    ///
    /// By default `prepare` generates these clutter layers from the footprints and the area (seeded,
    /// deterministic) and writes them beside the buildings in scene.glb; the masks treat trees, cars
    /// and rooftop units as occluders (see `render-masks --occluders`).
    #[arg(long)]
    pub no_clutter: bool,
    /// Seed of the clutter generator.
    #[arg(long, value_name = "N", default_value_t = crate::scene::clutter::ClutterSpec::default().seed)]
    pub clutter_seed: u64,
}

/// Runs `insgen prepare`.
pub fn run(args: &Args, global: &Global) -> anyhow::Result<()> {
    let mut files = Vec::new();
    if let Some(s) = &args.scene {
        files.push(s.clone());
    }
    for a in &args.areas {
        files.push(find_scene(&global.scenes, a)?);
    }
    let printer = global.printer();
    let progress = printer.progress();
    for file in files {
        let area = file.file_stem().and_then(|s| s.to_str()).unwrap_or("area").to_string();
        let out = global.workdir.join(&area).join(crate::layout::SCENE_DIR);
        let options = scene::prepare::PrepareOptions {
            clutter: (!args.no_clutter)
                .then(|| scene::clutter::ClutterSpec { seed: args.clutter_seed, ..Default::default() }),
        };
        let report = scene::prepare::prepare_with(&file, &out, &options, &progress)
            .with_context(|| format!("preparing area {area} from {}", file.display()))?;
        let m = &report.scene.manifest;
        let clutter = match &m.clutter {
            Some(c) => format!(
                ", clutter {} triangles ({})",
                c.layers.iter().map(|l| l.triangles).sum::<u64>(),
                c.layers.iter().map(|l| format!("{} {}", l.instances, l.name)).collect::<Vec<_>>().join(", ")
            ),
            None => String::new(),
        };
        printer.summary(format!(
            "{area}: {}, {}, {} dropped, geoid {}, origin {:.6}° N {:.6}° E {:.2} m{clutter} → {} ({:.1} s)",
            counted(m.buildings, "building", "buildings"),
            counted(m.triangles, "triangle", "triangles"),
            counted(m.degenerate_faces, "degenerate face", "degenerate faces"),
            m.geoid.model,
            m.origin.lat_deg,
            m.origin.lon_deg,
            m.origin.h_m,
            report.out_dir.display(),
            report.seconds
        ));
        let apps: Vec<_> = m.sources.iter().filter_map(|s| s.appearance.as_ref()).collect();
        if !apps.is_empty() {
            let sum = |f: fn(&&scene::artifact::AppearanceEntry) -> u64| apps.iter().map(f).sum::<u64>();
            let missing = sum(|a| a.missing_images);
            printer.summary(format!(
                "{area}: appearances: {}, {}, {missing} of {} missing{}",
                counted(sum(|a| a.textured_faces), "textured face", "textured faces"),
                counted(sum(|a| a.coloured_faces), "coloured face", "coloured faces"),
                counted(sum(|a| a.images), "image", "images"),
                if missing > 0 { " (their faces keep the procedural look)" } else { "" }
            ));
        }
    }
    Ok(())
}

/// `n` with the singular or plural noun: "1 degenerate face", "2 degenerate faces".
fn counted(n: impl Into<u64>, one: &str, many: &str) -> String {
    let n = n.into();
    format!("{n} {}", if n == 1 { one } else { many })
}

#[cfg(test)]
mod tests {
    #[test]
    fn counts_agree_with_their_noun() {
        assert_eq!(super::counted(1u64, "degenerate face", "degenerate faces"), "1 degenerate face");
        assert_eq!(super::counted(0u64, "degenerate face", "degenerate faces"), "0 degenerate faces");
        assert_eq!(super::counted(2u32, "building", "buildings"), "2 buildings");
    }
}
