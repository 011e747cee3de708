//! `insgen inspect`: what source files hold (extent, centre, CRS, LoDs, counts), or what a prepared
//! area contains.

use std::fmt::Write as _;
use std::io::Write;
use std::path::{Path, PathBuf};

use anyhow::Context;
use serde::Serialize;

use super::Global;
use crate::lod::ReadStats;
use crate::scene::sources;
use crate::scene::survey::{self, FileSurvey, SourceExtent, Survey, SurveyOptions};

/// Prints what building-model files hold (format, CRS, extent, centre, LoDs, counts) or what a
/// prepared area contains.
///
/// Reads the SOURCE files (CityGML, CityJSON, OBJ, tileset.json/b3dm/glb; folders and quoted globs as
/// in a scene file's [[sources]] path) or <workdir>/<NAME>/scene/manifest.json; writes nothing. Prints
/// a labelled summary on stdout: the extent in the source CRS and in WGS84 longitude/latitude, the
/// centre (the origin `insgen init` writes), the CRS as `prepare` resolves it, buildings per LoD,
/// surfaces, triangles, textures and what the reader skipped. With --json: one JSON object
/// (schemas/inspect.schema.json; for --area, the manifest).
#[derive(Debug, Clone, clap::Args)]
#[command(
    after_long_help = "Examples:\n  insgen inspect ../shared/data/nl_denhaag_lod2/DenHaag_01.city.json\n  \
insgen inspect data/munich/                      # a folder: every file a reader takes\n  \
insgen inspect 'plateau/udx/bldg/*.gml' --json   # a quoted glob\n  \
insgen inspect ../shared/data/jp_tokyo_shibuya_plateau_3dtiles/tileset.json --json\n  \
insgen inspect --area demo\n  \
insgen inspect --area demo --json | jq .ecef_from_enu"
)]
pub struct Args {
    /// Source files, folders or quoted globs (CityGML, CityJSON, OBJ, tileset.json/b3dm/glb).
    #[arg(value_name = "SOURCE", required_unless_present = "area")]
    pub sources: Vec<PathBuf>,
    /// A prepared area (<workdir>/<NAME>/scene).
    #[arg(long, value_name = "NAME", conflicts_with = "sources")]
    pub area: Option<String>,
    /// LoD to read (e.g. 2, 1.2).
    #[arg(long, value_name = "LOD")]
    pub lod: Option<String>,
    /// CRS of files that declare none (or to override theirs), e.g. EPSG:25832.
    #[arg(long, value_name = "CRS")]
    pub crs: Option<String>,
    /// Print one JSON object on stdout instead of the text summary.
    #[arg(long)]
    pub json: bool,
}

/// What `inspect --json` prints for source files (schema: `schemas/inspect.schema.json`).
#[derive(Debug, Serialize)]
pub struct SourcesJson<'a> {
    /// The inputs as given.
    pub inputs: &'a [PathBuf],
    /// The survey of their files.
    #[serde(flatten)]
    pub survey: &'a Survey,
}

/// Runs `insgen inspect`.
pub fn run(args: &Args, global: &Global) -> anyhow::Result<()> {
    // Written with `writeln!` so that a closed pipe (`insgen inspect F | head`) is an error that
    // `main` treats as success, not a panic of `println!`.
    let stdout = std::io::stdout();
    let mut out = stdout.lock();
    if let Some(area) = &args.area {
        return print_area(&mut out, global, area, args.json);
    }
    let mut files = Vec::new();
    for input in &args.sources {
        files.extend(sources::expand(Path::new(""), input, None).context("insgen inspect")?);
    }
    let opts = SurveyOptions { lod: args.lod.clone(), crs: args.crs.clone(), format: None };
    let printer = global.printer();
    let survey = survey::survey(&files, &opts, &printer.progress()).context("inspecting")?;
    if args.json {
        let j = SourcesJson { inputs: &args.sources, survey: &survey };
        writeln!(out, "{}", serde_json::to_string_pretty(&j)?)?;
        return Ok(());
    }
    write!(out, "{}", summary_text(&survey))?;
    Ok(())
}

fn print_area(out: &mut impl Write, global: &Global, area: &str, json: bool) -> anyhow::Result<()> {
    let dir = global.workdir.join(area).join(crate::layout::SCENE_DIR);
    let s = crate::scene::PreparedScene::load(&dir)?;
    let m = &s.manifest;
    if json {
        writeln!(out, "{}", serde_json::to_string_pretty(m)?)?;
        return Ok(());
    }
    writeln!(out, "area:       {} ({} split)", m.area, m.split)?;
    writeln!(
        out,
        "origin:     lat {} °, lon {} °, h {} m (WGS84)",
        m.origin.lat_deg, m.origin.lon_deg, m.origin.h_m
    )?;
    writeln!(out, "geoid:      {} (N = {} m at the origin)", m.geoid.model, m.geoid.undulation_at_origin_m)?;
    writeln!(out, "buildings:  {}", m.buildings)?;
    writeln!(out, "triangles:  {}", m.triangles)?;
    for src in &m.sources {
        writeln!(
            out,
            "source:     {} ({}, {} buildings; {})",
            src.path, src.format, src.buildings, src.crs_chain
        )?;
    }
    for a in &m.attributions {
        writeln!(out, "credit:     {a}")?;
    }
    Ok(())
}

/// Files listed one per line in the text summary; the rest are counted.
const LISTED_FILES: usize = 8;

/// The labelled text summary of a survey.
pub fn summary_text(s: &Survey) -> String {
    let mut t = String::new();
    let mut line = |label: &str, value: String| {
        let label = if label.is_empty() { String::new() } else { format!("{label}:") };
        let _ = writeln!(t, "{label:<12}{value}");
    };
    let fmt_name = |f: &FileSurvey| format!("{:?}", f.format).to_lowercase().replace("tiles3d", "3dtiles");
    if let [f] = &s.files[..] {
        line("file", format!("{} ({})", f.file.display(), fmt_name(f)));
    } else {
        let mut formats: Vec<String> = s.files.iter().map(fmt_name).collect();
        formats.sort();
        formats.dedup();
        line("files", format!("{} ({})", s.files.len(), formats.join(", ")));
        for f in s.files.iter().take(LISTED_FILES) {
            line("", format!("{}  {} buildings", f.file.display(), f.buildings));
        }
        if s.files.len() > LISTED_FILES {
            line("", format!("… and {} more (all of them: --json)", s.files.len() - LISTED_FILES));
        }
    }
    let mut frames: Vec<&str> = s.files.iter().map(|f| f.frame.as_str()).collect();
    frames.dedup();
    frames.sort();
    frames.dedup();
    for fr in &frames {
        line("CRS", fr.to_string());
    }
    extent_lines(s, &mut line);
    let lods = s.lod.iter().map(|(k, v)| format!("LoD{k}: {v}")).collect::<Vec<_>>().join(", ");
    line(
        "buildings",
        if lods.is_empty() { s.buildings.to_string() } else { format!("{} ({lods})", s.buildings) },
    );
    line("polygons", s.polygons.to_string());
    line("triangles", s.triangles.to_string());
    let sum = |f: fn(&FileSurvey) -> u64| s.files.iter().map(f).sum::<u64>();
    let (textured, coloured) = (sum(|f| f.appearance.textured_faces), sum(|f| f.appearance.coloured_faces));
    line(
        "appearance",
        if s.images + textured + coloured == 0 {
            "no textures or colours".into()
        } else {
            format!("{} texture image(s), {textured} textured faces, {coloured} coloured faces", s.images)
        },
    );
    let st = |f: fn(&ReadStats) -> u64| s.files.iter().map(|x| f(&x.stats)).sum::<u64>();
    line(
        "skipped",
        format!(
            "{} non-building objects, {} buildings without geometry, {} degenerate faces",
            st(|r| r.skipped_non_building),
            st(|r| r.buildings_without_geometry),
            st(|r| r.degenerate_faces)
        ),
    );
    let unused = st(|r| r.bad_coordinates_unused);
    if unused > 0 {
        line("unused", format!("{unused} bad coordinate(s) outside any building (ignored)"));
    }
    for f in &s.files {
        if let Some(r) = &f.relative_heights {
            line(
                "heights",
                format!(
                    "{} of {} buildings start at z ≈ 0 m although their {} is not 0: heights above the ground? \
                     (prepare them with heights = \"above_ground\", ground_attribute = \"{}\"){}",
                    r.buildings,
                    f.buildings,
                    r.attribute,
                    r.attribute,
                    if s.files.len() > 1 { format!(" [{}]", f.file.display()) } else { String::new() }
                ),
            );
        }
    }
    let ids: Vec<&str> =
        s.files.iter().flat_map(|f| &f.first_source_ids).take(5).map(String::as_str).collect();
    line("first IDs", ids.join(", "));
    t
}

/// The extent lines: in the source CRS (when there is one), in WGS84, its size and its centre.
fn extent_lines(s: &Survey, line: &mut impl FnMut(&str, String)) {
    let src: Vec<&SourceExtent> = s.files.iter().filter_map(|f| f.extent_source.as_ref()).collect();
    // One frame for all files (one CRS, or none declared by any): their source extents add up.
    let one_frame = s.files.windows(2).all(|w| w[0].crs == w[1].crs);
    if one_frame && !src.is_empty() {
        let mut lo = [f64::INFINITY; 3];
        let mut hi = [f64::NEG_INFINITY; 3];
        for e in &src {
            for k in 0..3 {
                lo[k] = lo[k].min(e.min[k]);
                hi[k] = hi[k].max(e.max[k]);
            }
        }
        let axes = &src[0].axes;
        // Millimetres, or about a centimetre in degrees.
        let digits = |k: usize| if src[0].units[k].contains("degree") { 7 } else { 3 };
        let parts: Vec<String> = (0..3)
            .map(|k| format!("{} {:.*} … {:.*}", axes[k], digits(k), lo[k], digits(k), hi[k]))
            .collect();
        line("extent", format!("{} (source CRS)", parts.join(", ")));
    }
    if let (Some(e), Some(c), Some(size)) = (s.extent_deg, s.centre_deg, s.size_m) {
        let ll = format!(
            "lon {:.7} … {:.7}, lat {:.7} … {:.7} (WGS84, degrees)",
            e.lon_min_deg, e.lon_max_deg, e.lat_min_deg, e.lat_max_deg
        );
        line(if one_frame { "" } else { "extent" }, ll);
        line("size", format!("{:.0} m west–east × {:.0} m south–north", size[0], size[1]));
        line(
            "centre",
            format!("lat {:.8}°, lon {:.8}° (the [origin] `insgen init` writes)", c.lat_deg, c.lon_deg),
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;

    #[derive(Debug, Parser)]
    struct T {
        #[command(flatten)]
        args: Args,
    }

    fn parse(argv: &[&str]) -> Result<T, clap::Error> {
        T::try_parse_from(std::iter::once("t").chain(argv.iter().copied()))
    }

    #[test]
    fn json_works_with_a_file_and_with_an_area() {
        let t = parse(&["f.gml", "--json"]).unwrap();
        assert!(t.args.json && t.args.sources.len() == 1);
        let t = parse(&["a/", "b/*.gml", "c.city.json"]).unwrap();
        assert_eq!(t.args.sources.len(), 3);
        let t = parse(&["--area", "demo", "--json"]).unwrap();
        assert!(t.args.json && t.args.area.as_deref() == Some("demo"));
        assert!(!parse(&["f.gml"]).unwrap().args.json);
    }

    #[test]
    fn file_or_area_is_required_and_not_both() {
        assert!(parse(&["--json"]).is_err());
        assert!(parse(&["f.gml", "--area", "demo"]).is_err());
    }
}
