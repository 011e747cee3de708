//! Generated city tilesets (`lod::tiles3d::write`) in the styles of Cesium ion, Google, PLATEAU and
//! 3DBAG, read back by insgen's 3D Tiles reader and by an independent glTF reader (the `gltf` crate).
//!
//! - every style reads back as the same buildings (ENU boxes within 1 cm: Draco positions are
//!   16-bit quantised over a ≤ 110 m tile, 1.7 mm steps; meshopt/KHR_mesh_quantization 16-bit too);
//! - every content converts to a plain GLB (`plain::importable_glb`) without required extensions that
//!   the `gltf` crate imports, whose triangles sit on the boxes (1 cm) and whose texels, looked up at
//!   each triangle's UVs, are exactly the tile's roof or wall colour (Draco/meshopt/quantization,
//!   `KHR_texture_transform`, WebP decoded; integer RGB compared exactly, NEAREST texels);
//! - implicit tiling expands to the generated tiles, with the same names;
//! - gzip-compressed contents and tileset JSON read the same;
//! - KTX2 textures and unknown extensions are refused naming the extension and the tile;
//! - truncated and garbled contents give errors naming the file, never a panic.

use std::path::Path;

use glam::{DMat4, DVec3};
use insgen::export::city_tileset::{self, GeneratedTileset, Style};
use insgen::geo::{EnuFrame, Geodetic};
use insgen::lod::tiles3d::{self, plain, Tile, Tileset};
use insgen::lod::{Geometry, ReadOptions};
use insgen::scene::mesh::CityBuilding;

use crate::blender_support::{box_city, BoxBuilding};
use crate::util::error_chain;

pub fn area() -> EnuFrame {
    EnuFrame::new(Geodetic::new(35.0, 139.0, 50.0))
}

pub fn city_buildings(boxes: &[BoxBuilding]) -> Vec<CityBuilding> {
    boxes
        .iter()
        .map(|b| {
            let tris = b.triangles();
            CityBuilding {
                id: insgen::scene::BuildingId::new(b.id).unwrap(),
                positions_enu_m: tris.iter().flatten().copied().collect(),
                triangles: (0..tris.len() as u32).map(|t| [3 * t, 3 * t + 1, 3 * t + 2]).collect(),
            }
        })
        .collect()
}

pub fn generate(dir: &Path, style: Style) -> GeneratedTileset {
    city_tileset::generate_city_tileset(&city_buildings(&box_city()), &area(), dir, style).unwrap()
}

const STYLES: [Style; 4] = [Style::CesiumIon, Style::Google, Style::Plateau, Style::Bag3d];

fn all_tiles<'t>(t: &'t Tile, out: &mut Vec<&'t Tile>) {
    out.push(t);
    for c in &t.children {
        all_tiles(c, out);
    }
}

#[test]
fn every_style_reads_back_as_the_boxes() {
    let boxes = box_city();
    let enu = area();
    for style in STYLES {
        let dir = tempfile::tempdir().unwrap();
        let g = generate(dir.path(), style);
        // Google-style contents have no feature IDs: buildings are the connected components of
        // their (unwelded) triangles, welded at 1 cm.
        let opts = ReadOptions { weld_tolerance_m: Some(0.01), ..Default::default() };
        let (model, report) = tiles3d::read_with_report(&g.tileset, &opts).unwrap();
        assert_eq!(model.buildings.len(), boxes.len(), "{style:?}: {:?}", report);
        // Each building's ECEF vertices, taken to ENU, span exactly one box (1 cm).
        let mut matched = 0;
        for b in &model.buildings {
            let Geometry::Mesh(m) = &b.geometry else { panic!("{style:?}: not a mesh") };
            let p: Vec<[f64; 3]> =
                m.positions.iter().map(|p| enu.ecef_to_enu((*p).into()).to_array()).collect();
            let lo = p.iter().fold([f64::INFINITY; 3], |a, q| [0, 1, 2].map(|k| a[k].min(q[k])));
            let hi = p.iter().fold([f64::NEG_INFINITY; 3], |a, q| [0, 1, 2].map(|k| a[k].max(q[k])));
            let found = boxes.iter().find(|bx| {
                (0..3).all(|k| (bx.min_m[k] - lo[k]).abs() < 0.01 && (bx.max_m[k] - hi[k]).abs() < 0.01)
            });
            let bx =
                found.unwrap_or_else(|| panic!("{style:?}: {} spans {lo:?}..{hi:?}, no box", b.source_id));
            if style == Style::Plateau {
                assert_eq!(b.source_id, format!("bldg_{}", bx.id), "gml_id from EXT_structural_metadata");
            }
            matched += 1;
        }
        assert_eq!(matched, boxes.len());
        eprintln!(
            "{style:?}: {} buildings, {} contents read, {} refined away",
            matched, report.contents_read, report.contents_refined_away
        );
    }
}

/// The ENU-from-plain transform of a tile content, and the plain GLB.
fn plain_of(tile: &Tile, ts: &Tileset, content: &Path) -> (plain::Importable, DMat4) {
    let bytes = std::fs::read(content).unwrap();
    let imp = plain::importable_glb(&bytes, content, ts.up).unwrap();
    let enu_from_plain = area().enu_from_ecef() * tile.world_from_tile * imp.tile_from_plain;
    (imp, enu_from_plain)
}

#[test]
fn plain_glbs_carry_each_tiles_texture_at_the_right_place() {
    let boxes = box_city();
    for style in STYLES {
        let dir = tempfile::tempdir().unwrap();
        let g = generate(dir.path(), style);
        let ts = Tileset::load(&g.tileset, DMat4::IDENTITY).unwrap();
        let mut tiles = Vec::new();
        all_tiles(&ts.root, &mut tiles);
        let with_content: Vec<&&Tile> = tiles.iter().filter(|t| !t.contents.is_empty()).collect();
        assert_eq!(with_content.len(), g.tiles.len(), "{style:?}: tiles with content");
        let mut extensions = std::collections::BTreeSet::new();
        for tile in with_content {
            let gen = g.tile(&tile.at).unwrap_or_else(|| panic!("{style:?}: no generated tile {}", tile.at));
            let (imp, m) = plain_of(tile, &ts, &tile.contents[0].file);
            extensions.extend(imp.decoded_extensions.iter().cloned());
            let unlit = imp.glb.windows(19).any(|w| w == b"KHR_materials_unlit");
            assert_eq!(unlit, matches!(style, Style::CesiumIon | Style::Google), "{style:?}: unlit kept");
            // An independent reader: the gltf crate, which refuses unknown required extensions.
            let (doc, buffers, images) = gltf::import_slice(&imp.glb).unwrap();
            assert!(doc.extensions_required().next().is_none(), "{style:?}: plain GLB requires extensions");
            let mut tris = 0;
            for mesh in doc.meshes() {
                for prim in mesh.primitives() {
                    let r = prim.reader(|b| Some(&buffers[b.index()]));
                    let pos: Vec<[f32; 3]> = r.read_positions().unwrap().collect();
                    let uv: Vec<[f32; 2]> = r.read_tex_coords(0).unwrap().into_f32().collect();
                    let idx: Vec<u32> = r.read_indices().unwrap().into_u32().collect();
                    let tex = prim.material().pbr_metallic_roughness().base_color_texture().unwrap();
                    let img = &images[tex.texture().source().index()];
                    for t in idx.chunks_exact(3) {
                        let p = [t[0], t[1], t[2]]
                            .map(|i| m.transform_point3(DVec3::from_array(pos[i as usize].map(f64::from))));
                        // On a box of this tile (1 cm).
                        let c = (p[0] + p[1] + p[2]) / 3.0;
                        assert!(
                            boxes.iter().filter(|b| gen.buildings.contains(&b.id)).any(|b| (0..3).all(|k| c[k] > b.min_m[k] - 0.01 && c[k] < b.max_m[k] + 0.01)),
                            "{style:?} {}: triangle at {c} is on none of its boxes",
                            tile.at
                        );
                        let n = (p[1] - p[0]).cross(p[2] - p[0]).normalize();
                        let want = if n.z.abs() > 0.7 { gen.roof_rgb } else { gen.wall_rgb };
                        let u = t.iter().map(|&i| uv[i as usize][0] as f64).sum::<f64>() / 3.0;
                        let v = t.iter().map(|&i| uv[i as usize][1] as f64).sum::<f64>() / 3.0;
                        let (x, y) = (
                            (u * img.width as f64).floor() as usize,
                            (v * img.height as f64).floor() as usize,
                        );
                        assert!(
                            x < img.width as usize && y < img.height as usize,
                            "{style:?}: UV ({u}, {v}) outside the texture"
                        );
                        let ch = match img.format {
                            gltf::image::Format::R8G8B8 => 3,
                            gltf::image::Format::R8G8B8A8 => 4,
                            f => panic!("{f:?}"),
                        };
                        let at = (y * img.width as usize + x) * ch;
                        assert_eq!(
                            &img.pixels[at..at + 3],
                            &want,
                            "{style:?} {}: texel at UV ({u}, {v})",
                            tile.at
                        );
                        tris += 1;
                    }
                }
            }
            assert_eq!(tris as u64, imp.triangles);
            assert!(tris >= 12 * gen.buildings.len(), "{style:?} {}: {tris} triangles", tile.at);
        }
        let want: &[&str] = match style {
            Style::CesiumIon => &[
                "KHR_draco_mesh_compression",
                "KHR_materials_unlit",
                "KHR_texture_transform",
                "EXT_mesh_features",
            ],
            Style::Google => &["KHR_draco_mesh_compression", "KHR_materials_unlit"],
            Style::Plateau => &["EXT_texture_webp", "EXT_mesh_features", "EXT_structural_metadata"],
            Style::Bag3d => &["EXT_meshopt_compression", "KHR_mesh_quantization", "EXT_mesh_features"],
        };
        for e in want {
            assert!(extensions.contains(*e), "{style:?}: {e} not decoded ({extensions:?})");
        }
    }
}

#[test]
fn implicit_tiling_expands_to_the_generated_tiles() {
    let dir = tempfile::tempdir().unwrap();
    let g = generate(dir.path(), Style::Bag3d);
    let ts = Tileset::load(&g.tileset, DMat4::IDENTITY).unwrap();
    let mut tiles = Vec::new();
    all_tiles(&ts.root, &mut tiles);
    let names: Vec<&str> = tiles.iter().map(|t| t.at.as_str()).collect();
    let mut want: Vec<&str> = g.tiles.iter().map(|t| t.at.as_str()).collect();
    let mut got = names.clone();
    want.sort();
    got.sort();
    assert_eq!(got, want);
    // Geometric error halves per level… (root = side, level 1 = side / 2).
    let root_ge = ts.root.geometric_error_m;
    for t in &tiles {
        let level: u32 = t.at.split("level ").nth(1).unwrap().split(',').next().unwrap().parse().unwrap();
        assert!((t.geometric_error_m - root_ge / f64::from(1u32 << level)).abs() < 1e-9);
        // …and each tile's volume (a subdivision of the root box) holds its buildings' centres:
        // buildings are put in the quadtree cell of their centroid.
        let gen = g.tile(&t.at).unwrap();
        let insgen::lod::tiles3d::BoundingVolume::Box { centre, half_axes } = t.bounding_volume else {
            panic!("{}: not a box", t.at)
        };
        let tile_from_ecef = t.world_from_tile.inverse();
        for b in box_city().iter().filter(|b| gen.buildings.contains(&b.id)) {
            let mid = [0, 1, 2].map(|k| 0.5 * (b.min_m[k] + b.max_m[k]));
            let p = tile_from_ecef.transform_point3(area().enu_to_ecef(DVec3::from_array(mid)));
            let local = half_axes.inverse() * (p - centre);
            assert!(
                local.abs().max_element() <= 1.0 + 1e-9,
                "{}: box {} centre at {local} of the volume",
                t.at,
                b.id
            );
        }
    }
    // A missing subtree file is named.
    let sub = dir.path().join("subtrees/2");
    std::fs::remove_dir_all(&sub).unwrap();
    let e = Tileset::load(&g.tileset, DMat4::IDENTITY).unwrap_err().to_string();
    assert!(e.contains("subtrees/2/"), "{e}");
}

fn gzip(bytes: &[u8]) -> Vec<u8> {
    use std::io::Write;
    let mut e = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::fast());
    e.write_all(bytes).unwrap();
    e.finish().unwrap()
}

#[test]
fn gzip_compressed_contents_and_tileset_read_the_same() {
    let dir = tempfile::tempdir().unwrap();
    let g = generate(dir.path(), Style::CesiumIon);
    let before = tiles3d::read(&g.tileset, &ReadOptions::default()).unwrap();
    for t in &g.tiles {
        let p = dir.path().join(&t.content_uri);
        let b = std::fs::read(&p).unwrap();
        std::fs::write(&p, gzip(&b)).unwrap();
    }
    let b = std::fs::read(&g.tileset).unwrap();
    std::fs::write(&g.tileset, gzip(&b)).unwrap();
    let after = tiles3d::read(&g.tileset, &ReadOptions::default()).unwrap();
    assert_eq!(before.buildings, after.buildings);
}

/// A GLB with one triangle whose texture is a KTX2 image behind `KHR_texture_basisu`.
fn ktx2_glb() -> Vec<u8> {
    let mut b = insgen::util::glb::GlbBuilder::default();
    let pos = b.push_vec3(&[[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]]);
    let uv = b.push_vec2(&[[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]]);
    let idx = b.push_indices(&[0, 1, 2]);
    let img = b.push_view(b"\xABKTX 20\xBB\r\n\x1a\nnot really", None);
    b.finish(serde_json::json!({
        "asset": {"version": "2.0"},
        "extensionsUsed": ["KHR_texture_basisu"], "extensionsRequired": ["KHR_texture_basisu"],
        "scenes": [{"nodes": [0]}], "nodes": [{"mesh": 0}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": pos, "TEXCOORD_0": uv}, "indices": idx, "material": 0}]}],
        "materials": [{"pbrMetallicRoughness": {"baseColorTexture": {"index": 0}}}],
        "textures": [{"extensions": {"KHR_texture_basisu": {"source": 0}}}],
        "images": [{"bufferView": img, "mimeType": "image/ktx2"}]
    }))
    .unwrap()
}

#[test]
fn ktx2_and_unknown_extensions_are_refused_by_name_with_the_tile() {
    use insgen::blender::tileset::{prepare_tile, select_tiles, SelectOptions};
    let dir = tempfile::tempdir().unwrap();
    let g = generate(dir.path(), Style::Google);
    // Replace one leaf's content by a KTX2-textured GLB: geometry readers accept it (textures do not
    // matter to buildings), the Blender preparation refuses it naming the extension and the tile.
    let leaf = g.tiles.iter().find(|t| t.level == 2).unwrap();
    let path = dir.path().join(&leaf.content_uri);
    std::fs::write(&path, ktx2_glb()).unwrap();
    assert!(tiles3d::read(&g.tileset, &ReadOptions::default()).is_ok());
    let e = error_chain(&plain::importable_glb(&ktx2_glb(), &path, tiles3d::UpAxis::Y).unwrap_err());
    assert!(e.contains("KHR_texture_basisu"), "{e}");
    // Through the selection and preparation: a nadir camera over the whole area at 400 m.
    let k = insgen::camera::Intrinsics::from_hfov(64, 48, 60.0);
    let pose = insgen::camera::Pose::from_ypr_deg(0.0, 0.0, 0.0, [0.0, 0.0, 120.0]);
    let sel = select_tiles(&g.tileset, &area(), &[(k, pose)], &SelectOptions::default()).unwrap();
    let bad = sel.tiles.iter().find(|t| t.content == path).expect("the KTX2 leaf is selected");
    let e = error_chain(&prepare_tile(bad, &area(), dir.path()).unwrap_err());
    assert!(e.contains("KHR_texture_basisu") && e.contains(&leaf.content_uri) && e.contains(&leaf.at), "{e}");
    // An unknown required glTF extension.
    let mut json = ktx2_glb();
    // Same length, so the GLB header stays valid.
    let from = b"\"extensionsRequired\":[\"KHR_texture_basisu\"]";
    let to = b"\"extensionsRequired\":[\"EXT_vendor_madeupx\"]";
    let at = json.windows(from.len()).position(|w| w == from).unwrap();
    json[at..at + to.len()].copy_from_slice(to);
    let e = plain::importable_glb(&json, &path, tiles3d::UpAxis::Y).unwrap_err();
    assert!(
        matches!(&e, tiles3d::ContentError::UnsupportedExtensions { extensions } if extensions == &["EXT_vendor_madeupx"]),
        "{e:?}"
    );
    assert!(e.to_string().contains("EXT_vendor_madeupx"), "{e}");
}

#[test]
fn truncated_and_garbled_contents_are_errors_naming_the_tile() {
    let dir = tempfile::tempdir().unwrap();
    for style in [Style::CesiumIon, Style::Bag3d] {
        let sub = dir.path().join(format!("{style:?}"));
        let g = generate(&sub, style);
        let leaf = g.tiles.iter().find(|t| t.level == 2).unwrap();
        let path = sub.join(&leaf.content_uri);
        let good = std::fs::read(&path).unwrap();
        let mut cases: Vec<Vec<u8>> = Vec::new();
        for cut in [0, 3, 12, 19, 20, 40, good.len() / 3, good.len() / 2, good.len() - 5] {
            cases.push(good[..cut].to_vec());
        }
        // Garbled: deterministic byte flips spread over the file (header, JSON, binary chunk).
        let mut x: u64 = 0x9E37_79B9_7F4A_7C15;
        for _ in 0..16 {
            let mut b = good.clone();
            for _ in 0..8 {
                x ^= x << 13;
                x ^= x >> 7;
                x ^= x << 17;
                let i = (x % b.len() as u64) as usize;
                b[i] ^= (x >> 32) as u8 | 1;
            }
            cases.push(b);
        }
        let mut errors = 0;
        for (n, bytes) in cases.iter().enumerate() {
            std::fs::write(&path, bytes).unwrap();
            // Neither reader may panic. Truncations go through the whole tileset: the error names
            // the content file and the tile; garbled files are read alone.
            let result = if n < 9 {
                tiles3d::read(&g.tileset, &ReadOptions::default()).map(|_| ())
            } else {
                tiles3d::read(&path, &ReadOptions::default()).map(|_| ())
            };
            if let Err(e) = result {
                errors += 1;
                let e = e.to_string();
                assert!(e.contains(&path.display().to_string()), "{style:?} case {n}: {e}");
                if n < 9 {
                    assert!(e.contains(&leaf.at), "{style:?} case {n} does not name tile {}: {e}", leaf.at);
                }
            }
            let _ = plain::importable_glb(bytes, &path, tiles3d::UpAxis::Y);
        }
        // Every truncation is an error.
        assert!(errors >= 9, "{style:?}: only {errors} errors");
        std::fs::write(&path, &good).unwrap();
    }
}
