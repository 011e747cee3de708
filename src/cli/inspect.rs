//! `insgen inspect`: what a source file holds, or what a prepared area contains.

use std::collections::BTreeMap;
use std::io::Write;
use std::path::PathBuf;

use anyhow::Context;
use serde::Serialize;

use super::Global;
use crate::lod::{self, Frame, Geometry, ReadOptions};

/// Prints a summary of a building-model file (format, CRS, buildings, LoD, faces) or of a prepared area.
///
/// Reads the file (CityGML, CityJSON, OBJ, 3D Tiles) or <workdir>/<NAME>/scene/manifest.json; writes
/// nothing, prints on stdout (with --json: one JSON object; for --area, the manifest).
#[derive(Debug, Clone, clap::Args)]
#[command(
    after_long_help = "Examples:\n  insgen inspect ../shared/data/nl_denhaag_lod2/DenHaag_01.city.json\n  \
insgen inspect ../shared/data/jp_tokyo_shibuya_plateau_3dtiles/tileset.json --json\n  \
insgen inspect --area demo\n  \
insgen inspect --area demo --json | jq .ecef_from_enu"
)]
pub struct Args {
    /// A source file (CityGML, CityJSON, OBJ, tileset.json/b3dm/glb).
    #[arg(value_name = "FILE", required_unless_present = "area")]
    pub file: Option<PathBuf>,
    /// A prepared area (<workdir>/<NAME>/scene).
    #[arg(long, value_name = "NAME", conflicts_with = "file")]
    pub area: Option<String>,
    /// LoD to read (e.g. 2, 1.2).
    #[arg(long, value_name = "LOD")]
    pub lod: Option<String>,
    /// Print one JSON object on stdout instead of the text summary.
    #[arg(long)]
    pub json: bool,
}

/// The summary of a source file, as `--json` prints it.
#[derive(Debug, Serialize)]
pub struct SourceSummary {
    /// The source file.
    pub file: PathBuf,
    /// The frame of the coordinates, in words.
    pub frame: String,
    /// Buildings read.
    pub buildings: usize,
    /// Buildings per LoD.
    pub lod: BTreeMap<String, u64>,
    /// Polygons of the buildings.
    pub polygons: u64,
    /// Triangles of the meshes, plus those the polygons make when triangulated (V + 2H − 2 each).
    pub triangles: u64,
    /// The reader's counters.
    pub stats: serde_json::Value,
    /// The first five source IDs.
    pub first_source_ids: Vec<String>,
    /// Buildings that start at z ≈ 0 while carrying a ground-height attribute (heights relative to
    /// the ground?), with the attribute; absent when there are none.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub relative_heights: Option<String>,
}

/// Runs `insgen inspect`.
pub fn run(args: &Args, global: &Global) -> anyhow::Result<()> {
    // Written with `writeln!` so that a closed pipe (`insgen inspect F | head`) is an error that
    // `main` treats as success, not a panic of `println!`.
    let stdout = std::io::stdout();
    let mut out = stdout.lock();
    if let Some(area) = &args.area {
        let dir = global.workdir.join(area).join(crate::layout::SCENE_DIR);
        let s = crate::scene::PreparedScene::load(&dir)?;
        let m = &s.manifest;
        if args.json {
            writeln!(out, "{}", serde_json::to_string_pretty(m)?)?;
            return Ok(());
        }
        writeln!(out, "area:       {} ({} split)", m.area, m.split)?;
        writeln!(
            out,
            "origin:     lat {} °, lon {} °, h {} m (WGS84)",
            m.origin.lat_deg, m.origin.lon_deg, m.origin.h_m
        )?;
        writeln!(
            out,
            "geoid:      {} (N = {} m at the origin)",
            m.geoid.model, m.geoid.undulation_at_origin_m
        )?;
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
        return Ok(());
    }
    let file = args.file.as_ref().expect("clap requires FILE or --area");
    if !file.exists() {
        anyhow::bail!("{}: no such file or directory", file.display());
    }
    let opts = ReadOptions { lod: args.lod.clone(), ..ReadOptions::default() };
    let m = lod::read_source(file, None, &opts).with_context(|| format!("inspecting {}", file.display()))?;
    // Resolve the CRS as `prepare` does, so that an unknown code fails here too (exit 1).
    let frame = match &m.frame {
        Frame::Ecef => "ECEF (EPSG:4978)".to_string(),
        Frame::Crs { name: Some(n), axes } => {
            let crs = crate::geo::Crs::parse(n)
                .and_then(|crs| crs.transform().map(|_| crs))
                .with_context(|| format!("inspecting {}: the CRS {n:?} the file declares", file.display()))?;
            let heights = match crs.heights() {
                crate::geo::HeightKind::Orthometric => "orthometric heights",
                crate::geo::HeightKind::Ellipsoidal => "ellipsoidal heights",
            };
            format!("{n} = {} ({axes:?} axis order, {heights})", crs.describe())
        }
        Frame::Crs { name: None, .. } => "none declared (set `crs` in the scene file)".to_string(),
    };
    let mut lods: BTreeMap<String, u64> = BTreeMap::new();
    let (mut polys, mut tris) = (0u64, 0u64);
    for b in &m.buildings {
        *lods.entry(b.lod.clone()).or_default() += 1;
        match &b.geometry {
            Geometry::Polygons(p) => {
                polys += p.len() as u64;
                tris += p.iter().map(polygon_triangles).sum::<u64>();
            }
            Geometry::Mesh(t) => tris += t.triangles.len() as u64,
        }
    }
    let summary = SourceSummary {
        file: m.path.clone(),
        frame,
        buildings: m.buildings.len(),
        lod: lods,
        polygons: polys,
        triangles: tris,
        stats: serde_json::to_value(&m.stats)?,
        first_source_ids: m.buildings.iter().take(5).map(|b| b.source_id.clone()).collect(),
        relative_heights: lod::relative_heights(&m).map(|r| {
            format!(
                "{} of {} buildings start at z ≈ 0 m although their {} is not 0: heights above the ground? \
                 (prepare them with heights = \"above_ground\", ground_attribute = \"{}\")",
                r.buildings,
                m.buildings.len(),
                r.attribute,
                r.attribute
            )
        }),
    };
    if args.json {
        writeln!(out, "{}", serde_json::to_string_pretty(&summary)?)?;
        return Ok(());
    }
    writeln!(out, "file:       {}", summary.file.display())?;
    writeln!(out, "frame:      {}", summary.frame)?;
    writeln!(out, "buildings:  {}", summary.buildings)?;
    writeln!(
        out,
        "LoD:        {}",
        summary.lod.iter().map(|(k, v)| format!("{k}: {v}")).collect::<Vec<_>>().join(", ")
    )?;
    writeln!(out, "polygons:   {}", summary.polygons)?;
    writeln!(out, "triangles:  {}", summary.triangles)?;
    writeln!(out, "stats:      {}", serde_json::to_string(&summary.stats)?)?;
    if let Some(r) = &summary.relative_heights {
        writeln!(out, "heights:    {r}")?;
    }
    for id in &summary.first_source_ids {
        writeln!(out, "  {id}")?;
    }
    Ok(())
}

/// The triangles a triangulation of a simple polygon with holes has: V + 2H − 2 for V vertices in
/// all rings and H holes (Euler's formula; what earcut gives in `prepare` for a valid polygon).
fn polygon_triangles(p: &lod::Polygon) -> u64 {
    let v = p.exterior.len() + p.interiors.iter().map(Vec::len).sum::<usize>();
    (v + 2 * p.interiors.len()).saturating_sub(2) as u64
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
        assert!(t.args.json && t.args.file.is_some());
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
