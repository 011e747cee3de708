//! Errors of the renderer.

/// What can go wrong while setting up the GPU or rendering instance-ID maps.
#[derive(Debug, thiserror::Error)]
pub enum RenderError {
    /// No wgpu adapter (GPU or software rasteriser) was found.
    #[error(
        "no GPU adapter found ({reason}); insgen renders on any Vulkan/GL device, including the software \
         rasteriser lavapipe: install mesa-vulkan-drivers and libvulkan1 (run scripts/setup.sh)"
    )]
    NoAdapter { reason: String },
    /// The adapter refused to create a device.
    #[error("the GPU adapter {adapter:?} could not create a device")]
    Device {
        adapter: String,
        #[source]
        source: wgpu::RequestDeviceError,
    },
    /// The device lacks something the renderer needs.
    #[error("the GPU adapter {adapter:?} cannot render instance IDs: {what}")]
    Capability { adapter: String, what: String },
    /// A frame cannot be rendered with these parameters (size, intrinsics, pose).
    #[error("invalid view: {what}")]
    InvalidView { what: String },
    /// The mesh cannot be uploaded (inconsistent buffers, too large).
    #[error("invalid scene mesh: {what}")]
    InvalidMesh { what: String },
    /// Reading a rendered frame back from the GPU failed.
    #[error("reading back {what} from the GPU failed: {detail}")]
    ReadBack { what: &'static str, detail: String },
    /// A read-back frame holds values that are not building IDs (a corrupt render).
    #[error("the GPU returned an invalid ID map")]
    Ids(#[from] crate::scene::IdError),
    /// The device reported an error while rendering (validation, out of memory, device lost).
    #[error("GPU error while {what}: {detail}")]
    Gpu { what: &'static str, detail: String },
}
