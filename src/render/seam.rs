//! The renderer seam: what the stages that need building-ID images (render-masks, eval-loc) ask of a
//! renderer, so that they never name one.
//!
//! - [`IdRenderer`] is a renderer: it describes itself ([`RendererRecord`], for logs and summaries)
//!   and prepares a mesh once ([`IdRenderer::prepare`]).
//! - [`IdScene`] is a mesh prepared by one: it renders one view into a reusable [`Frame`] (the
//!   localizer's hypotheses, one per thread), a batch of views in order as [`RenderedFrame`]s (IDs and
//!   optional linear depth: the masks), and the pixels of buildings drawn alone (amodal coverage).
//! - [`CpuRenderer`] (the fixed-point rasteriser of [`super::cpu`]) and [`Renderer`] (wgpu) implement
//!   both; a third renderer implements them too and is added to [`resolve`].
//! - [`RendererChoice`] (`auto`, `cpu`, `gpu`) is resolved by [`resolve`] into a renderer with the
//!   reason for it, which the caller logs. `auto` depends on the [`Workload`]: masks (few large
//!   frames) take wgpu on any adapter, lavapipe included; the localizer's hypotheses (many small
//!   frames) take wgpu only on a hardware adapter, since on a software one the CPU rasteriser is faster
//!   (`bench/renderer.md`).
//!
//! Both renderers follow the same conventions (pinhole of [`crate::camera::Intrinsics`], pixel centres,
//! nearest surface wins, top-left rule); they agree on ≥ 99.9 % of pixels, the rest being centres
//! within float rounding of an edge (`tests/it/render_cpu_agreement.rs`, `tests/it/render_seam.rs`).

use std::fmt;
use std::ops::ControlFlow;

use glam::DVec3;
use serde::{Deserialize, Serialize};

use super::cpu::{self, CpuScene, Frame, NEAR_M};
use super::error::{MeshProblem, ViewProblem};
use super::{DepthRange, GpuScene, RenderError, RenderOptions, RenderedFrame, Renderer, View};
use crate::scene::{BuildingId, IdMap, SceneMesh};

/// Which kind of rasteriser renders.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum RendererKind {
    /// The fixed-point CPU rasteriser ([`super::cpu`]), on the rayon pool.
    Cpu,
    /// wgpu on an adapter (a GPU, or a software Vulkan rasteriser such as lavapipe).
    Gpu,
}

/// What rendered, as logged and recorded (eval-loc's `summary.json`).
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct RendererRecord {
    /// `cpu` or `gpu`.
    pub kind: RendererKind,
    /// The wgpu adapter as logged at start-up (name, backend, driver); absent for the CPU rasteriser.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub adapter: Option<String>,
}

impl fmt::Display for RendererRecord {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match (&self.kind, &self.adapter) {
            (RendererKind::Cpu, _) => {
                write!(f, "the CPU rasteriser on {} threads", rayon::current_num_threads())
            }
            (RendererKind::Gpu, Some(a)) => write!(f, "wgpu on {a}"),
            (RendererKind::Gpu, None) => write!(f, "wgpu"),
        }
    }
}

/// A renderer of building-ID images (see the module doc).
pub trait IdRenderer: Send + Sync {
    /// What this renderer is, for logs and summaries.
    fn record(&self) -> RendererRecord;

    /// Prepares `mesh` (f32 ENU metres relative to the area origin, one building ID per vertex, ID 0
    /// for occluders) for rendering many views. `anchor_m` is a point near the cameras, ENU metres: the
    /// CPU rasteriser keeps positions relative to it (the wgpu renderer is camera-relative anyway).
    ///
    /// # Errors
    /// [`RenderError::InvalidMesh`] for an inconsistent mesh; [`RenderError::Gpu`] when a device
    /// cannot hold it.
    fn prepare<'r>(&'r self, mesh: &SceneMesh, anchor_m: DVec3)
        -> Result<Box<dyn IdScene + 'r>, RenderError>;
}

/// A mesh prepared by an [`IdRenderer`]. Shared between threads (`Sync`).
pub trait IdScene: Sync {
    /// Renders one view's building IDs into `frame.ids` (row-major, 0 = background), with the default
    /// clip planes ([`DepthRange::default`]'s near plane; no far plane closer than 10 km).
    ///
    /// # Errors
    /// [`RenderError`] when the device fails or the view cannot be rendered.
    fn render_into(&self, view: &View, frame: &mut Frame) -> Result<(), RenderError>;

    /// Renders `views` in order and hands each frame to `emit(index, frame)` as soon as it is done;
    /// `emit` returns [`ControlFlow::Break`] to stop the batch (keeping its own reason).
    ///
    /// # Errors
    /// [`RenderError::InvalidView`] for a view or clip range this renderer cannot render, or any
    /// device error; frames emitted before it stand.
    fn render_each(
        &self,
        views: &[View],
        options: &RenderOptions,
        emit: &mut dyn FnMut(usize, RenderedFrame) -> ControlFlow<()>,
    ) -> Result<(), RenderError>;

    /// Renders one view (see [`IdScene::render_each`]).
    ///
    /// # Errors
    /// As [`IdScene::render_each`].
    fn render(&self, view: &View, options: &RenderOptions) -> Result<RenderedFrame, RenderError> {
        let mut out = None;
        self.render_each(std::slice::from_ref(view), options, &mut |_, image| {
            out = Some(image);
            ControlFlow::Continue(())
        })?;
        out.ok_or(RenderError::ReadBack { what: "a frame", detail: "no frame was produced".into() })
    }

    /// For each of `building_ids`, the pixels it covers in `view` when drawn alone (no depth test
    /// against the others), in the order given.
    ///
    /// # Errors
    /// As [`IdScene::render_each`].
    fn isolated_coverage_px(
        &self,
        view: &View,
        building_ids: &[BuildingId],
        range: &DepthRange,
    ) -> Result<Vec<u64>, RenderError>;

    /// Whether [`IdScene::render_into`] is best called from many threads at once (the CPU
    /// rasteriser), rather than views being handed over in batches to [`IdScene::render_each`],
    /// which keeps several frames in flight (wgpu).
    fn renders_in_parallel(&self) -> bool;
}

/// The CPU rasteriser of [`super::cpu`] behind the seam: it needs no device.
#[derive(Debug, Clone, Copy, Default)]
pub struct CpuRenderer;

impl IdRenderer for CpuRenderer {
    fn record(&self) -> RendererRecord {
        RendererRecord { kind: RendererKind::Cpu, adapter: None }
    }

    fn prepare<'r>(
        &'r self,
        mesh: &SceneMesh,
        anchor_m: DVec3,
    ) -> Result<Box<dyn IdScene + 'r>, RenderError> {
        let vertices = mesh.positions_m.len();
        if mesh.building_ids.len() != vertices {
            return Err(RenderError::InvalidMesh(MeshProblem::Lengths {
                positions: vertices,
                building_ids: mesh.building_ids.len(),
            }));
        }
        if let Some((k, &vertex)) = mesh.indices.iter().enumerate().find(|(_, &i)| i as usize >= vertices) {
            return Err(RenderError::InvalidMesh(MeshProblem::VertexIndex {
                triangle: k / 3,
                vertex,
                vertices,
            }));
        }
        Ok(Box::new(CpuScene::new(mesh, anchor_m)))
    }
}

/// The CPU rasteriser clips at [`NEAR_M`] only: another near plane is refused rather than ignored.
fn check_cpu_range(range: &DepthRange) -> Result<(), RenderError> {
    if range.near_m == NEAR_M && range.far_m > range.near_m {
        Ok(())
    } else {
        Err(RenderError::InvalidView {
            view: None,
            problem: ViewProblem::CpuNearPlane { near_m: range.near_m, far_m: range.far_m },
        })
    }
}

/// One CPU frame as the wgpu renderer hands it on: what lies beyond the far plane is background (a
/// pixel whose nearest surface lies beyond it has no surface within the range), depth on request.
fn cpu_rendered(
    scene: &CpuScene,
    view: &View,
    options: &RenderOptions,
    frame: &mut Frame,
) -> Result<RenderedFrame, RenderError> {
    let k = &view.intrinsics;
    cpu::render_ids(scene, &view.pose, k, frame);
    let far_m = options.range.far_m as f32;
    let mut depth_m: Vec<f32> = frame.depth_m().map(|d| if d > far_m { 0.0 } else { d }).collect();
    let mut ids = frame.ids.clone();
    for ((id, d), raw) in ids.iter_mut().zip(&mut depth_m).zip(frame.depth_m()) {
        if raw > far_m {
            *id = 0;
            *d = 0.0;
        }
    }
    Ok(RenderedFrame {
        ids: IdMap::from_raw(k.width_px, k.height_px, ids)?,
        depth_m: options.linear_depth.then_some(depth_m),
    })
}

impl IdScene for CpuScene {
    fn render_into(&self, view: &View, frame: &mut Frame) -> Result<(), RenderError> {
        cpu::render_ids(self, &view.pose, &view.intrinsics, frame);
        Ok(())
    }

    /// Renders the views one after the other on the calling thread. Not on the rayon pool: a caller
    /// may keep the pool's threads waiting for these very frames (the masks stage's writers take them
    /// from a channel with `par_bridge`), and a render queued behind them would never run.
    fn render_each(
        &self,
        views: &[View],
        options: &RenderOptions,
        emit: &mut dyn FnMut(usize, RenderedFrame) -> ControlFlow<()>,
    ) -> Result<(), RenderError> {
        check_cpu_range(&options.range)?;
        let mut frame = Frame::default();
        for (i, view) in views.iter().enumerate() {
            if emit(i, cpu_rendered(self, view, options, &mut frame)?).is_break() {
                break;
            }
        }
        Ok(())
    }

    fn isolated_coverage_px(
        &self,
        view: &View,
        building_ids: &[BuildingId],
        range: &DepthRange,
    ) -> Result<Vec<u64>, RenderError> {
        check_cpu_range(range)?;
        let far_m = range.far_m as f32;
        let mut frame = Frame::default();
        Ok(building_ids
            .iter()
            .map(|b| {
                cpu::render_building_alone(self, &view.pose, &view.intrinsics, b.get(), &mut frame);
                frame.ids.iter().zip(frame.depth_m()).filter(|&(&id, d)| id != 0 && d <= far_m).count() as u64
            })
            .collect())
    }

    fn renders_in_parallel(&self) -> bool {
        true
    }
}

impl IdRenderer for Renderer {
    fn record(&self) -> RendererRecord {
        RendererRecord { kind: RendererKind::Gpu, adapter: Some(self.adapter().to_string()) }
    }

    fn prepare<'r>(
        &'r self,
        mesh: &SceneMesh,
        _anchor_m: DVec3,
    ) -> Result<Box<dyn IdScene + 'r>, RenderError> {
        Ok(Box::new(GpuIdScene { renderer: self, scene: self.upload(mesh)? }))
    }
}

/// A mesh uploaded to a wgpu [`Renderer`].
#[derive(Debug)]
pub struct GpuIdScene<'r> {
    renderer: &'r Renderer,
    scene: GpuScene,
}

impl GpuIdScene<'_> {
    /// The uploaded mesh (for the wgpu renderer's own calls).
    pub fn gpu_scene(&self) -> &GpuScene {
        &self.scene
    }
}

/// Why a wgpu batch stopped early: the device, or the consumer.
enum Stop {
    Render(RenderError),
    Consumer,
}

impl From<RenderError> for Stop {
    fn from(e: RenderError) -> Self {
        Stop::Render(e)
    }
}

impl IdScene for GpuIdScene<'_> {
    fn render_into(&self, view: &View, frame: &mut Frame) -> Result<(), RenderError> {
        let image = self.renderer.render(&self.scene, view, &RenderOptions::default())?;
        frame.ids.clear();
        frame.ids.extend_from_slice(image.ids.raw());
        Ok(())
    }

    /// Up to [`super::FRAMES_IN_FLIGHT`] frames submitted ahead ([`Renderer::render_each`]).
    fn render_each(
        &self,
        views: &[View],
        options: &RenderOptions,
        emit: &mut dyn FnMut(usize, RenderedFrame) -> ControlFlow<()>,
    ) -> Result<(), RenderError> {
        let result =
            self.renderer.render_each(&self.scene, views, options, |i, image| match emit(i, image) {
                ControlFlow::Continue(()) => Ok(()),
                ControlFlow::Break(()) => Err(Stop::Consumer),
            });
        match result {
            Ok(()) | Err(Stop::Consumer) => Ok(()),
            Err(Stop::Render(e)) => Err(e),
        }
    }

    fn isolated_coverage_px(
        &self,
        view: &View,
        building_ids: &[BuildingId],
        range: &DepthRange,
    ) -> Result<Vec<u64>, RenderError> {
        self.renderer.isolated_coverage_px(&self.scene, view, building_ids, range)
    }

    fn renders_in_parallel(&self) -> bool {
        false
    }
}

/// `--renderer`: which renderer a stage uses.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum RendererChoice {
    /// Decided by the [`Workload`] and the adapter found (see [`resolve`]).
    #[default]
    Auto,
    /// The CPU rasteriser, whatever the machine has.
    Cpu,
    /// wgpu on whatever adapter there is, a software one included; an error without one.
    Gpu,
}

impl RendererChoice {
    /// The accepted spellings, in order.
    pub const NAMES: [&'static str; 3] = ["auto", "cpu", "gpu"];
}

impl fmt::Display for RendererChoice {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let i = match self {
            RendererChoice::Auto => 0,
            RendererChoice::Cpu => 1,
            RendererChoice::Gpu => 2,
        };
        f.write_str(Self::NAMES[i])
    }
}

/// A renderer name that is none of [`RendererChoice::NAMES`].
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("unknown renderer {given:?}: expected one of auto, cpu, gpu")]
pub struct UnknownRenderer {
    /// The text given.
    pub given: String,
}

impl std::str::FromStr for RendererChoice {
    type Err = UnknownRenderer;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s.trim().to_ascii_lowercase().as_str() {
            "auto" => Ok(RendererChoice::Auto),
            "cpu" => Ok(RendererChoice::Cpu),
            "gpu" | "wgpu" => Ok(RendererChoice::Gpu),
            _ => Err(UnknownRenderer { given: s.to_string() }),
        }
    }
}

/// What a stage renders, which decides [`RendererChoice::Auto`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Workload {
    /// Few large frames with depth and coverage (render-masks): wgpu on any adapter, lavapipe
    /// included; without an adapter, an error with the hint to install one.
    Masks,
    /// Many small frames (eval-loc's hypotheses): wgpu on a hardware adapter only; on a software
    /// adapter, or none, the CPU rasteriser.
    Hypotheses,
}

/// A renderer resolved from a [`RendererChoice`], with why it was chosen.
pub struct Resolved {
    /// The renderer.
    pub renderer: Box<dyn IdRenderer>,
    /// Why this one, in words for the log (e.g. "auto: llvmpipe is a software rasteriser").
    pub reason: String,
}

impl fmt::Debug for Resolved {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("Resolved")
            .field("renderer", &self.renderer.record())
            .field("reason", &self.reason)
            .finish()
    }
}

/// Resolves `choice` for `workload` (see [`Workload`]); looks for a wgpu adapter unless `choice` is
/// [`RendererChoice::Cpu`].
///
/// # Errors
/// [`RenderError::NoAdapter`] (with the hint to install software Vulkan) when wgpu is required — `gpu`,
/// or `auto` for masks — and no adapter is found; [`RenderError::Device`] / [`RenderError::Capability`]
/// when the adapter cannot serve.
pub fn resolve(choice: RendererChoice, workload: Workload) -> Result<Resolved, RenderError> {
    let resolved = |renderer: Box<dyn IdRenderer>, reason: String| Ok(Resolved { renderer, reason });
    match (choice, workload) {
        (RendererChoice::Cpu, _) => resolved(Box::new(CpuRenderer), "asked for the CPU rasteriser".into()),
        (RendererChoice::Gpu, _) => {
            let r = Renderer::new()?;
            let reason = if r.is_software() {
                "asked for wgpu (on a software rasteriser: slower than the CPU one for small frames)"
            } else {
                "asked for wgpu"
            };
            resolved(Box::new(r), reason.into())
        }
        (RendererChoice::Auto, Workload::Masks) => {
            resolved(Box::new(Renderer::new()?), "auto: masks render with wgpu on any adapter".into())
        }
        (RendererChoice::Auto, Workload::Hypotheses) => match Renderer::new() {
            Ok(r) if !r.is_software() => {
                resolved(Box::new(r), "auto: a hardware GPU adapter is present".into())
            }
            Ok(r) => resolved(
                Box::new(CpuRenderer),
                format!("auto: the only adapter, {}, is a software rasteriser", r.adapter()),
            ),
            Err(e) => resolved(Box::new(CpuRenderer), format!("auto: no GPU adapter ({e})")),
        },
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    mod choice {
        use super::*;

        #[test]
        fn names_parse_and_print_back() {
            for name in RendererChoice::NAMES {
                let c: RendererChoice = name.parse().unwrap();
                assert_eq!(c.to_string(), name);
            }
            assert_eq!(" GPU ".parse::<RendererChoice>(), Ok(RendererChoice::Gpu));
            assert_eq!("wgpu".parse::<RendererChoice>(), Ok(RendererChoice::Gpu));
            let e = "vulkan".parse::<RendererChoice>().unwrap_err();
            assert_eq!(e.to_string(), "unknown renderer \"vulkan\": expected one of auto, cpu, gpu");
        }

        #[test]
        fn cpu_needs_no_adapter() {
            let r = resolve(RendererChoice::Cpu, Workload::Hypotheses).unwrap();
            assert_eq!(r.renderer.record(), RendererRecord { kind: RendererKind::Cpu, adapter: None });
        }
    }

    mod cpu_scene {
        use super::*;
        use crate::camera::{Intrinsics, Pose};

        fn two_roofs() -> SceneMesh {
            let mut m = SceneMesh::default();
            cpu::tests::closed_box(&mut m, [-10.0, -10.0, 0.0], [10.0, 10.0, 10.0], 1, false, true);
            cpu::tests::closed_box(&mut m, [-4.0, -4.0, 0.0], [4.0, 4.0, 40.0], 2, false, true);
            m
        }

        fn nadir() -> View {
            View {
                intrinsics: Intrinsics {
                    width_px: 64,
                    height_px: 48,
                    fx_px: 100.0,
                    fy_px: 100.0,
                    cx_px: 32.0,
                    cy_px: 24.0,
                },
                pose: Pose::from_ypr_deg(0.0, 0.0, 0.0, [0.0, 0.0, 100.0]),
            }
        }

        #[test]
        fn batches_match_single_renders_and_carry_depth() {
            let scene = CpuRenderer.prepare(&two_roofs(), DVec3::ZERO).unwrap();
            let views = vec![nadir(); 5];
            let mut single = Frame::default();
            scene.render_into(&views[0], &mut single).unwrap();
            let options = RenderOptions { linear_depth: true, ..Default::default() };
            let mut seen = Vec::new();
            scene
                .render_each(&views, &options, &mut |i, image| {
                    assert_eq!(image.ids.raw(), &single.ids[..]);
                    // The tower's roof at the centre: 100 m − 40 m = 60 m away.
                    let depth = image.depth_m.expect("asked for depth");
                    assert!((depth[24 * 64 + 32] - 60.0).abs() < 1e-3, "{}", depth[24 * 64 + 32]);
                    seen.push(i);
                    ControlFlow::Continue(())
                })
                .unwrap();
            assert_eq!(seen, vec![0, 1, 2, 3, 4]);
            // Break stops the batch.
            let mut n = 0;
            scene
                .render_each(&views, &options, &mut |_, _| {
                    n += 1;
                    ControlFlow::Break(())
                })
                .unwrap();
            assert_eq!(n, 1);
        }

        #[test]
        fn the_far_plane_and_coverage_follow_the_gpu_conventions() {
            let scene = CpuRenderer.prepare(&two_roofs(), DVec3::ZERO).unwrap();
            let view = nadir();
            // Far plane at 80 m: the lower roof (90 m) is cut away, the tower (60 m) stays.
            let options =
                RenderOptions { range: DepthRange { near_m: NEAR_M, far_m: 80.0 }, linear_depth: false };
            let mut ids = Vec::new();
            scene
                .render_each(std::slice::from_ref(&view), &options, &mut |_, image| {
                    ids = image.ids.raw().to_vec();
                    ControlFlow::Continue(())
                })
                .unwrap();
            assert_eq!(ids.iter().filter(|&&i| i == 1).count(), 0);
            assert!(ids.contains(&2));
            // Drawn alone the lower roof covers its whole 20 m square at 90 m: (20/90·100)² ≈ 22.2² px;
            // with the tower in front it shows fewer.
            let b = [BuildingId::new(1).unwrap(), BuildingId::new(2).unwrap()];
            let alone = scene.isolated_coverage_px(&view, &b, &DepthRange::default()).unwrap();
            let mut f = Frame::default();
            scene.render_into(&view, &mut f).unwrap();
            let visible = f.ids.iter().filter(|&&i| i == 1).count() as u64;
            assert!(alone[0] > visible && (440..=520).contains(&alone[0]), "{alone:?} vs {visible}");
            // A near plane the CPU rasteriser does not have is refused, not ignored.
            let near = DepthRange { near_m: 1.0, far_m: 100.0 };
            assert!(matches!(
                scene.isolated_coverage_px(&view, &b, &near),
                Err(RenderError::InvalidView { .. })
            ));
        }
    }
}
