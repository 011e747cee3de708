//! `insgen export-tiles`: a prepared area as a 3D Tiles 1.1 tileset placed on the globe.

use std::path::PathBuf;

use anyhow::Context;

use crate::export::tiles::{write_scene_tileset, TILESET_DIR};

/// Write a prepared area as a 3D Tiles 1.1 tileset that CesiumJS shows where it belongs on the globe.
///
/// Reads <workdir>/<area>/scene/{scene.glb, manifest.json, buildings.json} (from `insgen prepare`).
/// Writes tileset.json (root transform = the manifest's ENU→ECEF; the glTF y-up content is turned z-up
/// by the viewer, as 3D Tiles specifies) and scene.glb (a copy, with its EXT_mesh_features building
/// IDs and EXT_structural_metadata source IDs) into <workdir>/<area>/scene/tileset/.
#[derive(Debug, Clone, clap::Args)]
#[command(after_long_help = "Examples:\n  insgen export-tiles --area demo\n  \
insgen export-tiles --area tokyo --out /srv/tiles/tokyo\n\n\
In CesiumJS (serve the folder over HTTP):\n  \
viewer.scene.primitives.add(await Cesium.Cesium3DTileset.fromUrl(\"tiles/tokyo/tileset.json\"));")]
pub struct Args {
    /// The prepared area (<workdir>/<NAME>/scene).
    #[arg(long, value_name = "NAME")]
    pub area: String,
    /// Output directory [default: <workdir>/<NAME>/scene/tileset].
    #[arg(long, value_name = "DIR")]
    pub out: Option<PathBuf>,
    /// Write a synthetic textured tileset in the style of a real service instead of the scene copy:
    /// a quadtree of tiles, each with its own known colour texture (cesium-ion: Draco, unlit, rotated
    /// and scaled root, REPLACE and ADD refinement). For testing and benchmarking photogrammetry
    /// rendering (scripts/bench_rgb.sh); the tiles carry no building IDs a dataset could use.
    #[arg(long, value_enum, value_name = "STYLE", hide_short_help = true)]
    pub style: Option<StyleArg>,
    /// With --style: move the buildings by a known rigid offset "EAST_M,NORTH_M,UP_M,YAW_DEG" (yaw
    /// about the centre of the area's footprint, as `insgen align` reports it), so that `align` has
    /// something to recover.
    #[arg(long, value_name = "E,N,U,YAW", requires = "style", value_parser = parse_offset, allow_hyphen_values = true, hide_short_help = true)]
    pub offset: Option<[f64; 4]>,
    /// With --style: make it photogrammetry-like: ±5 cm vertex jitter, a ground surface, 40 box trees
    /// and a 45 m crane the LoD model does not have (seeded by --seed).
    #[arg(long, requires = "style", hide_short_help = true)]
    pub photogrammetry_noise: bool,
    /// Seed of --photogrammetry-noise.
    #[arg(long, value_name = "N", default_value_t = 1, hide_short_help = true)]
    pub seed: u64,
}

fn parse_offset(s: &str) -> Result<[f64; 4], String> {
    let v: Vec<f64> = s
        .split(',')
        .map(|x| x.trim().parse::<f64>().map_err(|e| format!("{x:?}: {e}")))
        .collect::<Result<_, _>>()?;
    match v[..] {
        [e, n, u, y] if v.iter().all(|x| x.is_finite()) => Ok([e, n, u, y]),
        _ => Err(format!("expected four finite numbers EAST_M,NORTH_M,UP_M,YAW_DEG, got {s:?}")),
    }
}

/// Style of a synthetic tileset.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum StyleArg {
    /// Cesium ion photogrammetry: Draco, unlit, rotated and scaled root, REPLACE and ADD refinement.
    CesiumIon,
    /// Google Photorealistic 3D Tiles: Draco without building IDs, boxes in ECEF.
    Google,
    /// Project PLATEAU: feature IDs with gml_id metadata, WebP textures, region bounds.
    Plateau,
    /// 3D BAG: implicit quadtree with subtree files, meshopt-compressed geometry.
    #[value(name = "3dbag")]
    Bag3d,
}

impl Args {
    /// The scene directory and the output directory.
    pub fn dirs(&self, global: &super::Global) -> (PathBuf, PathBuf) {
        let scene = global.workdir.join(&self.area).join(crate::layout::SCENE_DIR);
        let out = self.out.clone().unwrap_or_else(|| scene.join(TILESET_DIR));
        (scene, out)
    }
}

/// Runs `export-tiles`.
pub fn run(args: &Args, global: &super::Global) -> anyhow::Result<()> {
    let (scene, out) = args.dirs(global);
    if let Some(style) = args.style {
        use crate::export::city_tileset::{generate_city_tileset, Style};
        use crate::scene::mesh::buildings_from_scene;
        let prepared = crate::scene::artifact::PreparedScene::load(&scene)?;
        let o = prepared.manifest.origin;
        let enu = crate::geo::EnuFrame::new(crate::geo::Geodetic::new(o.lat_deg, o.lon_deg, o.h_m));
        let style = match style {
            StyleArg::CesiumIon => Style::CesiumIon,
            StyleArg::Google => Style::Google,
            StyleArg::Plateau => Style::Plateau,
            StyleArg::Bag3d => Style::Bag3d,
        };
        let mut buildings = buildings_from_scene(&prepared.mesh);
        if args.offset.is_some() || args.photogrammetry_noise {
            use crate::scene::correction::Correction;
            use crate::scene::photogrammetry::{perturb, Perturbation};
            let [east_m, north_m, up_m, yaw_deg] = args.offset.unwrap_or([0.0; 4]);
            let pivot_enu_m =
                crate::scene::align::pivot_of(&crate::scene::align::scene_surface(&prepared.mesh));
            let offset = Correction { east_m, north_m, up_m, yaw_deg, pivot_enu_m };
            let p = if args.photogrammetry_noise {
                Perturbation::photogrammetry_like(offset, prepared.manifest.ground_enu_m, args.seed)
            } else {
                Perturbation {
                    offset,
                    jitter_m: 0.0,
                    trees: 0,
                    crane: false,
                    ground_enu_m: None,
                    seed: args.seed,
                }
            };
            buildings = perturb(&buildings, &p).map_err(|e| anyhow::anyhow!("area {}: {e}", args.area))?;
        }
        let g = generate_city_tileset(&buildings, &enu, &out, style)
            .with_context(|| format!("writing a synthetic tileset of area {}", args.area))?;
        global.printer().summary(format!("wrote {} ({} tiles)", g.tileset.display(), g.tiles.len()));
        return Ok(());
    }
    let s = write_scene_tileset(&scene, &out)
        .with_context(|| format!("exporting area {} as 3D Tiles", args.area))?;
    global.printer().summary(format!("wrote {} and {}", s.tileset.display(), s.content.display()));
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(argv: &[&str]) -> Result<crate::cli::testing::Parsed<Args>, clap::Error> {
        crate::cli::testing::parse(argv)
    }

    #[test]
    fn area_is_required_and_out_defaults_into_the_scene() {
        assert!(parse(&[]).is_err());
        let t = parse(&["--area", "demo"]).unwrap();
        assert_eq!(
            t.args.dirs(&t.global),
            (PathBuf::from("runs/demo/scene"), PathBuf::from("runs/demo/scene/tileset"))
        );
        let t = parse(&["--area", "demo", "--out", "o"]).unwrap();
        assert_eq!(t.args.dirs(&t.global).1, PathBuf::from("o"));
    }

    #[test]
    fn offset_needs_a_style_and_four_numbers() {
        assert!(parse(&["--area", "demo", "--offset", "1,2,3,0.5"]).is_err());
        let t = parse(&["--area", "demo", "--style", "plateau", "--offset", "-1,2,-3,0.5"]).unwrap();
        assert_eq!(t.args.offset, Some([-1.0, 2.0, -3.0, 0.5]));
        assert!(parse(&["--area", "demo", "--style", "plateau", "--offset", "1,2,3"]).is_err());
        assert!(parse(&["--area", "demo", "--style", "plateau", "--offset", "1,2,3,nan"]).is_err());
    }
}
