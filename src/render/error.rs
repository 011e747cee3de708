//! Errors of the renderer. What is wrong with a view or a mesh is a value of its own
//! ([`ViewProblem`], [`MeshProblem`]) carrying the numbers involved; its `Display` is the text after
//! "invalid view: " or "invalid scene mesh: ".

use glam::{DMat3, DVec3};

use super::cpu::NEAR_M;
use super::view::MAX_FRAME_SIDE_PX;
use crate::scene::BuildingId;

/// What can go wrong while setting up the GPU or rendering instance-ID maps.
#[derive(Debug, thiserror::Error)]
pub enum RenderError {
    /// No wgpu adapter (GPU or software rasteriser) was found.
    #[error(
        "no GPU adapter found ({reason}); insgen renders on any Vulkan/GL device, including the software \
         rasteriser lavapipe: install mesa-vulkan-drivers and libvulkan1 (run scripts/setup.sh)"
    )]
    NoAdapter {
        /// What each backend tried answered (wgpu's own texts, joined by "; ").
        reason: String,
    },
    /// The adapter refused to create a device.
    #[error("the GPU adapter {adapter:?} could not create a device")]
    Device {
        /// The adapter: name, backend, driver.
        adapter: String,
        /// wgpu's error.
        #[source]
        source: wgpu::RequestDeviceError,
    },
    /// The device lacks something the renderer needs.
    #[error("the GPU adapter {adapter:?} cannot render instance IDs: no {missing}")]
    Capability {
        /// The adapter: name, backend, driver.
        adapter: String,
        /// The missing capability ("compute shaders").
        missing: &'static str,
    },
    /// A frame cannot be rendered with these parameters (size, intrinsics, pose, depth range).
    #[error("invalid view: {}{problem}", view.map(|i| format!("view {i}: ")).unwrap_or_default())]
    InvalidView {
        /// The view's index in a batch, when it is one of several.
        view: Option<usize>,
        /// What is wrong with it.
        problem: ViewProblem,
    },
    /// The mesh cannot be uploaded (inconsistent buffers, too large).
    #[error("invalid scene mesh: {0}")]
    InvalidMesh(MeshProblem),
    /// Reading a rendered frame back from the GPU failed.
    #[error("reading back {what} from the GPU failed: {detail}")]
    ReadBack {
        /// What was being read ("a frame", "depth", "coverage counts").
        what: &'static str,
        /// wgpu's error text.
        detail: String,
    },
    /// A read-back frame holds values that are not building IDs (a corrupt render).
    #[error("the GPU returned an invalid ID map")]
    Ids(#[from] crate::scene::IdError),
    /// The device reported an error while rendering (validation, out of memory, device lost).
    #[error("GPU error while {what}: {detail}")]
    Gpu {
        /// What the renderer was doing ("uploading the scene", "rendering a batch").
        what: &'static str,
        /// wgpu's error text.
        detail: String,
    },
}

/// Why a view cannot be rendered (see [`crate::render::view::validate_view`]).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ViewProblem {
    /// A side of the frame is 0 or larger than [`MAX_FRAME_SIDE_PX`].
    #[error("frame size {width_px}×{height_px} px is outside 1..={MAX_FRAME_SIDE_PX} px per side")]
    FrameSize {
        /// Width, pixels.
        width_px: u32,
        /// Height, pixels.
        height_px: u32,
    },
    /// A focal length is not a finite positive number.
    #[error("focal lengths must be finite and positive, got fx={fx_px} fy={fy_px} px")]
    Focal {
        /// Horizontal focal length, pixels.
        fx_px: f64,
        /// Vertical focal length, pixels.
        fy_px: f64,
    },
    /// The principal point is not finite.
    #[error("principal point must be finite, got ({cx_px}, {cy_px}) px")]
    PrincipalPoint {
        /// x, pixels.
        cx_px: f64,
        /// y, pixels.
        cy_px: f64,
    },
    /// The camera centre is not finite.
    #[error("camera centre must be finite, got {centre_m:?} m")]
    Centre {
        /// The centre, ENU metres.
        centre_m: DVec3,
    },
    /// The pose's rotation is not orthonormal and right-handed (to 1e-6).
    #[error("the pose rotation is not a rotation (|RᵀR − I| = {orthonormality:.3e}, det = {det:.6}): {rotation:?}")]
    Rotation {
        /// The largest |RᵀR − I| entry.
        orthonormality: f64,
        /// The determinant.
        det: f64,
        /// The matrix (world from camera).
        rotation: DMat3,
    },
    /// The depth range is not 0 < near < far.
    #[error("depth range must satisfy 0 < near < far, got near={near_m} m far={far_m} m")]
    DepthRange {
        /// Near plane, metres.
        near_m: f64,
        /// Far plane, metres.
        far_m: f64,
    },
    /// The CPU rasteriser clips at [`NEAR_M`] only; another near plane is refused rather than ignored.
    #[error(
        "the CPU rasteriser clips at a near plane of {NEAR_M} m, not {near_m} m (far {far_m} m); render \
         with wgpu for other clip planes"
    )]
    CpuNearPlane {
        /// The near plane asked for, metres.
        near_m: f64,
        /// The far plane asked for, metres.
        far_m: f64,
    },
}

/// Why a scene mesh cannot be uploaded (see [`crate::render::GpuScene::new`]).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum MeshProblem {
    /// Positions and building IDs differ in number.
    #[error("{positions} positions but {building_ids} building IDs")]
    Lengths {
        /// Positions.
        positions: usize,
        /// Building IDs.
        building_ids: usize,
    },
    /// The index count is not a multiple of 3.
    #[error("{indices} indices is not a multiple of 3")]
    IndexCount {
        /// Indices.
        indices: usize,
    },
    /// More indices or vertices than 32-bit indices reach.
    #[error("too large: {indices} indices, {vertices} vertices")]
    TooLarge {
        /// Indices.
        indices: usize,
        /// Vertices.
        vertices: usize,
    },
    /// A vertex position is NaN or infinite.
    #[error("vertex {vertex} has a non-finite position {position_m:?}")]
    NonFinite {
        /// The vertex.
        vertex: usize,
        /// Its position, ENU metres.
        position_m: [f32; 3],
    },
    /// A triangle refers to a vertex that does not exist.
    #[error("triangle {triangle} refers to vertex {vertex}, but there are {vertices} vertices")]
    VertexIndex {
        /// The triangle.
        triangle: usize,
        /// The vertex index it holds.
        vertex: u32,
        /// Vertices in the mesh.
        vertices: usize,
    },
    /// A triangle joins an occluder's vertex (ID 0) with a building's.
    #[error("triangle {triangle} mixes building ID 0 (an occluder) with a building: {ids:?}")]
    MixedOccluder {
        /// The triangle.
        triangle: usize,
        /// Its vertices' IDs.
        ids: [BuildingId; 3],
    },
    /// A triangle joins vertices of different buildings (the flat-interpolated ID would then depend
    /// on the provoking vertex).
    #[error("triangle {triangle} joins vertices of buildings {ids:?}")]
    MixedBuildings {
        /// The triangle.
        triangle: usize,
        /// Its vertices' IDs.
        ids: [BuildingId; 3],
    },
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn problem_texts() {
        let b = |i| BuildingId::new(i).unwrap();
        let cases: Vec<(String, &str)> = vec![
            (
                RenderError::InvalidView {
                    view: Some(3),
                    problem: ViewProblem::FrameSize { width_px: 0, height_px: 10 },
                }
                .to_string(),
                "invalid view: view 3: frame size 0×10 px is outside 1..=8192 px per side",
            ),
            (
                RenderError::InvalidView { view: None, problem: ViewProblem::DepthRange { near_m: 2.0, far_m: 1.0 } }
                    .to_string(),
                "invalid view: depth range must satisfy 0 < near < far, got near=2 m far=1 m",
            ),
            (
                ViewProblem::CpuNearPlane { near_m: 1.0, far_m: 100.0 }.to_string(),
                "the CPU rasteriser clips at a near plane of 0.1 m, not 1 m (far 100 m); render with wgpu for \
                 other clip planes",
            ),
            (
                RenderError::InvalidMesh(MeshProblem::Lengths { positions: 3, building_ids: 2 }).to_string(),
                "invalid scene mesh: 3 positions but 2 building IDs",
            ),
            (
                MeshProblem::VertexIndex { triangle: 1, vertex: 9, vertices: 4 }.to_string(),
                "triangle 1 refers to vertex 9, but there are 4 vertices",
            ),
            (
                MeshProblem::MixedBuildings { triangle: 0, ids: [b(1), b(1), b(2)] }.to_string(),
                "triangle 0 joins vertices of buildings [BuildingId(1), BuildingId(1), BuildingId(2)]",
            ),
            (
                RenderError::Capability { adapter: "llvmpipe".into(), missing: "compute shaders" }.to_string(),
                "the GPU adapter \"llvmpipe\" cannot render instance IDs: no compute shaders",
            ),
        ];
        for (got, want) in cases {
            assert_eq!(got, want);
        }
    }
}
