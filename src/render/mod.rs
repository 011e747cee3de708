//! The wgpu offscreen instance-ID renderer: takes the scene mesh (f32 ENU metres relative to the area
//! origin, a building ID per vertex) and camera views (intrinsics + pose, f64), hands on per-pixel
//! building IDs ([`crate::scene::IdMap`]) and, optionally, linear depth in metres.
//!
//! - [`Renderer::new`] finds an adapter (lavapipe, the software Vulkan rasteriser, works) and builds
//!   the pipelines; [`Renderer::with_device`] reuses a caller's device.
//! - [`GpuScene::new`] / [`Renderer::upload`] validates and uploads the mesh once.
//! - [`Renderer::render_each`] / [`Renderer::render_batch`] render many views with frames in flight;
//!   [`Renderer::isolated_coverage_px`] counts the pixels of buildings drawn alone (amodal coverage).
//!
//! Target: R32Uint IDs (flat-interpolated vertex attribute, no MSAA, no blending, no sRGB, cleared to
//! 0), reversed-Z Depth32Float (clear 0, compare `Greater`), optional R32Float linear depth. Back-face
//! culling is off. The projection is the exact pinhole of [`crate::camera::Intrinsics`] and the vertex
//! transform is camera-relative; both are derived in [`view`].
//!
//! [`cpu`] is a second backend for many small frames (the localizer's hypotheses): a fixed-point CPU
//! rasteriser following the same conventions, tested to agree with the GPU on ≥ 99.9 % of pixels;
//! [`warp`] reads views rotated about the camera centre out of one wide render.
//!
//! [`seam`] puts both behind one interface ([`IdRenderer`], [`IdScene`]) that the masks stage and the
//! localizer use, and resolves `--renderer auto|cpu|gpu` ([`RendererChoice`]) into one of them.
//!
//! This is where f32 starts (STYLE rule 4): [`view::ViewUniform::new`] is the one place that casts the
//! camera to f32.

pub mod batch;
pub mod coverage;
pub mod cpu;
pub mod device;
pub mod error;
pub mod scene;
pub mod seam;
pub mod target;
pub mod timing;
pub mod view;
pub mod warp;

pub use batch::{RenderOptions, FRAMES_IN_FLIGHT};
pub use device::Renderer;
pub use error::{MeshProblem, RenderError, ViewProblem};
pub use scene::{BuildingRange, GpuScene};
pub use seam::{
    resolve, CpuRenderer, IdRenderer, IdScene, RendererChoice, RendererKind, RendererRecord, Resolved,
    Workload,
};
pub use target::RenderedFrame;
pub use timing::{time_render, RenderTimings};
pub use view::{DepthRange, View};
