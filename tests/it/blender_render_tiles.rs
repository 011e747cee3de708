//! Blender renders of a generated Cesium-ion-style tileset (Draco, unlit, KHR_texture_transform,
//! repeated texture/material names, a rotated and 1.34-scaled root transform, REPLACE and ADD
//! refinement) made from the box city, compared with what the geometry predicts.
//!
//! - selection: in every frame, no content of a REPLACE tile is chosen together with a content of
//!   one of its descendants (the root's coarse copy is never drawn over its children);
//! - RGB: every pixel away from an edge (3×3 neighbourhood of one predicted colour) shows the texel
//!   colour of the finest tile holding the building the ray hits — roof texel on the top face, wall
//!   texel on the sides. Tolerance: 6 levels per channel (an unlit sRGB texel through Blender's
//!   Standard view transform comes back within ±1; Cycles' pixel filter only mixes at edges), and
//!   98 % of those pixels must match (a drawn REPLACE parent or a misplaced texture fails thousands);
//! - IDs: the tileset's `_FEATURE_ID_0` renders against the f64 ray-cast reference of the boxes the
//!   tileset was made from pass the alignment targets (median IoU ≥ 0.995, p5 ≥ 0.98), as
//!   `render-rgb --check-alignment` requires.

use std::path::Path;

use glam::DVec3;
use insgen::blender::align::{building_ious, pixel_agreement, summarise, FrameAlignment};
use insgen::blender::run::frame_outputs;
use insgen::blender::tileset::{select_tiles, SelectOptions};
use insgen::blender::{render_frames, Engine, FrameRequest, Launcher, Mode, RenderPlan, SceneSource};
use insgen::camera::{Intrinsics, Pose};
use insgen::export::city_tileset::Style;
use insgen::lod::tiles3d::Refine;
use insgen::scene::IdMap;
use insgen::util::NoProgress;

use crate::blender_support::{blender_python, box_city, edge_mask, read_rgb_png, reference_ids, BoxBuilding};
use crate::lod_tiles3d_generated::{area, generate};

fn plan(python: &Path, dir: &Path, mode: Mode, source: SceneSource) -> RenderPlan {
    RenderPlan {
        launcher: Launcher::Python { interpreter: python.to_path_buf() },
        mode,
        engine: Engine::Cycles,
        rgb: insgen::blender::job::RgbSettings {
            samples: 4,
            denoise: false,
            denoise_quality: insgen::blender::job::DenoiseQuality::Fast,
            max_bounces: 2,
            lighting: insgen::blender::job::Lighting::Direct,
        },
        seed: 1,
        device: insgen::blender::job::Device::Cpu,
        threads: 2,
        exr: false,
        source,
        look_seed: 11,
        look: insgen::blender::look::LookRanges::plain(35.0),
        ground_enu_m: 0.0,
        out_dir: dir.join("out"),
        work_dir: dir.join("work"),
        restart_every: 50,
        force: false,
        clip_start_m: 0.5,
        clip_end_m: 100_000.0,
        report_bounds: false,
        clutter_occluders: None,
        contrast: None,
    }
}

fn frames() -> Vec<FrameRequest> {
    let k = Intrinsics::from_hfov(160, 120, 60.0);
    vec![
        FrameRequest {
            name: "nadir".into(),
            intrinsics: k,
            pose: Pose::from_ypr_deg(20.0, 0.0, 0.0, [0.0, 0.0, 150.0]),
        },
        FrameRequest {
            name: "tilt".into(),
            intrinsics: k,
            pose: Pose::from_ypr_deg(200.0, 40.0, 0.0, [30.0, 60.0, 120.0]),
        },
    ]
}

/// Per pixel: the building hit (0 = none) and whether the hit face is a roof (normal z), by f64 ray
/// casting from the pixel centre.
fn reference_hits(boxes: &[BoxBuilding], k: &Intrinsics, pose: &Pose) -> Vec<(u32, bool)> {
    let tris: Vec<([DVec3; 3], u32)> = boxes
        .iter()
        .flat_map(|b| b.triangles().into_iter().map(move |t| (t.map(DVec3::from), b.id)))
        .collect();
    let r = pose.r_world_from_cam;
    let mut out = vec![(0, false); (k.width_px * k.height_px) as usize];
    for j in 0..k.height_px {
        for i in 0..k.width_px {
            let dc =
                DVec3::new((i as f64 + 0.5 - k.cx_px) / k.fx_px, (j as f64 + 0.5 - k.cy_px) / k.fy_px, 1.0);
            let d = r * dc;
            let mut best = (f64::INFINITY, 0, false);
            for (t, id) in &tris {
                let (e1, e2) = (t[1] - t[0], t[2] - t[0]);
                let p = d.cross(e2);
                let det = e1.dot(p);
                if det.abs() < 1e-12 {
                    continue;
                }
                let s = pose.centre_m - t[0];
                let u = s.dot(p) / det;
                let q = s.cross(e1);
                let v = d.dot(q) / det;
                let dist = e2.dot(q) / det;
                if (0.0..=1.0).contains(&u) && v >= 0.0 && u + v <= 1.0 && dist > 0.0 && dist < best.0 {
                    let n = e1.cross(e2);
                    let roof = n.z.abs() > 0.7 * n.length();
                    best = (dist, *id, roof);
                }
            }
            out[(j * k.width_px + i) as usize] = (best.1, best.2);
        }
    }
    out
}

#[test]
fn cesium_style_tileset_shows_each_tiles_texture_and_aligns_with_the_boxes() {
    let Some(py) = blender_python() else { return };
    let dir = tempfile::tempdir().unwrap();
    let boxes = box_city();
    let g = generate(&dir.path().join("tiles"), Style::CesiumIon);
    let add = g.tiles.iter().filter(|t| t.refine == Refine::Add).count();
    assert_eq!(add, 1, "the generator makes one ADD tile");
    let frames = frames();

    // Selection: never a REPLACE tile with one of its descendants.
    let cams: Vec<(Intrinsics, Pose)> = frames.iter().map(|f| (f.intrinsics, f.pose)).collect();
    let sel = select_tiles(&g.tileset, &area(), &cams, &SelectOptions::default()).unwrap();
    for (f, chosen) in frames.iter().zip(&sel.per_frame) {
        let tiles: Vec<_> = chosen.iter().map(|&i| &sel.tiles[i as usize]).collect();
        assert!(tiles.len() >= 3, "{}: only {} tiles", f.name, tiles.len());
        for a in &tiles {
            for b in &tiles {
                if b.tile_at.starts_with(&format!("{}.", a.tile_at)) {
                    assert_eq!(
                        a.refine,
                        Refine::Add,
                        "{}: REPLACE tile {} drawn with its descendant {}",
                        f.name,
                        a.tile_at,
                        b.tile_at
                    );
                }
            }
            assert_ne!(a.tile_at, "root", "{}: the root's coarse content is drawn", f.name);
        }
    }

    // RGB: each pixel is its finest tile's roof or wall texel.
    let source =
        || SceneSource::Tileset { tileset: g.tileset.clone(), enu: area(), select: SelectOptions::default() };
    let p = plan(&py, dir.path(), Mode::Rgb, source());
    render_frames(&p, &frames, &NoProgress).unwrap();
    for f in &frames {
        let k = &f.intrinsics;
        let (w, h, rgb) = read_rgb_png(&p.out_dir.join(format!("{}.png", f.name)));
        let hits = reference_hits(&boxes, k, &f.pose);
        let predicted: Vec<Option<[u8; 3]>> = hits
            .iter()
            .map(|&(id, roof)| {
                (id != 0).then(|| {
                    let t = g.finest_tile_of(id).unwrap();
                    if roof {
                        t.roof_rgb
                    } else {
                        t.wall_rgb
                    }
                })
            })
            .collect();
        let (mut checked, mut good) = (0, 0);
        let mut worst = Vec::new();
        for y in 1..h as usize - 1 {
            for x in 1..w as usize - 1 {
                let i = y * w as usize + x;
                let Some(want) = predicted[i] else { continue };
                let uniform = (-1i64..=1).all(|dy| {
                    (-1i64..=1).all(|dx| {
                        predicted[((y as i64 + dy) * w as i64 + x as i64 + dx) as usize] == Some(want)
                    })
                });
                if !uniform {
                    continue;
                }
                checked += 1;
                let got = &rgb[3 * i..3 * i + 3];
                if (0..3).all(|c| (got[c] as i32 - want[c] as i32).abs() <= 6) {
                    good += 1;
                } else if worst.len() < 5 {
                    worst.push(format!("({x}, {y}) {got:?} vs {want:?} (building {})", hits[i].0));
                }
            }
        }
        eprintln!("{}: {good}/{checked} interior pixels show their tile's texel", f.name);
        assert!(checked > 1500, "{}: only {checked} interior building pixels", f.name);
        assert!(good as f64 >= 0.98 * checked as f64, "{}: {good}/{checked}; e.g. {worst:?}", f.name);
    }

    // IDs: aligned with the boxes the tileset was made from.
    let p = plan(&py, dir.path(), Mode::Ids, source());
    render_frames(&p, &frames, &NoProgress).unwrap();
    let mut per_frame = Vec::new();
    for f in &frames {
        let k = &f.intrinsics;
        let path = frame_outputs(&p, &f.name)[0].path.clone();
        let got = IdMap::read_exr(&path).unwrap();
        let want = IdMap::from_raw(k.width_px, k.height_px, reference_ids(&boxes, k, &f.pose)).unwrap();
        let edges = edge_mask(want.raw(), k.width_px, k.height_px);
        let off_edge =
            got.ids().iter().zip(want.ids()).zip(&edges).filter(|((a, b), e)| a != b && !**e).count();
        assert!(off_edge <= 2, "{}: {off_edge} pixels differ away from edges", f.name);
        let agreement = pixel_agreement(&got, &want);
        per_frame.push(FrameAlignment {
            frame: f.name.clone(),
            pixel_agreement: agreement,
            buildings: building_ious(&got, &want, &path).unwrap(),
        });
    }
    let report = summarise(per_frame, 64);
    eprintln!("generated tileset: median IoU {:?}, p5 {:?}", report.median_iou, report.p5_iou);
    assert!(report.pass, "{}", report.to_markdown());
}
