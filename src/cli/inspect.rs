//! `insgen inspect`: what a source file holds, or what a prepared area contains.

use std::collections::BTreeMap;
use std::path::PathBuf;

use anyhow::Context;

use super::Global;
use crate::lod::{self, Frame, Geometry, ReadOptions};

/// Prints a summary of a building-model file (format, CRS, buildings, LoD, faces) or of a prepared area.
#[derive(Debug, Clone, clap::Args)]
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
}

pub fn run(args: &Args, global: &Global) -> anyhow::Result<()> {
    if let Some(area) = &args.area {
        let dir = global.workdir.join(area).join("scene");
        let s = crate::scene::PreparedScene::load(&dir)?;
        println!("{}", serde_json::to_string_pretty(&s.manifest)?);
        return Ok(());
    }
    let file = args.file.as_ref().expect("clap requires FILE or --area");
    let opts = ReadOptions { lod: args.lod.clone(), weld_tolerance_m: None };
    let m = lod::read_source(file, None, &opts).with_context(|| format!("inspecting {}", file.display()))?;
    let frame = match &m.frame {
        Frame::Ecef => "ECEF (EPSG:4978)".to_string(),
        Frame::Crs { name: Some(n), axes } => format!("{n} ({axes:?} axis order)"),
        Frame::Crs { name: None, .. } => "none declared (set `crs` in the scene file)".to_string(),
    };
    let mut lods: BTreeMap<&str, u64> = BTreeMap::new();
    let (mut polys, mut tris) = (0u64, 0u64);
    for b in &m.buildings {
        *lods.entry(b.lod.as_str()).or_default() += 1;
        match &b.geometry {
            Geometry::Polygons(p) => polys += p.len() as u64,
            Geometry::Mesh(t) => tris += t.triangles.len() as u64,
        }
    }
    println!("file:       {}", m.path.display());
    println!("frame:      {frame}");
    println!("buildings:  {}", m.buildings.len());
    println!("LoD:        {}", lods.iter().map(|(k, v)| format!("{k}: {v}")).collect::<Vec<_>>().join(", "));
    println!("polygons:   {polys}");
    println!("triangles:  {tris}");
    println!("stats:      {}", serde_json::to_string(&m.stats)?);
    for b in m.buildings.iter().take(5) {
        println!("  {}", b.source_id);
    }
    Ok(())
}
