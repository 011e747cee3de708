//! Getting a GPU: instance → adapter → device, and the pipelines built once per device.
//!
//! Device creation ([`Renderer::new`]) is split from rendering ([`Renderer::with_device`] takes any
//! `Device`/`Queue`), so tests, benches and the CLI share the same rendering code.

use std::sync::Mutex;

use super::scene::GpuVertex;
use super::target::IdTarget;
use super::view::ViewUniform;
use super::RenderError;

/// The colour format of the ID target: one u32 per pixel, no sRGB, no blending.
pub const ID_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::R32Uint;
/// The optional linear-depth target (metres along the optical axis; 0 = no building).
pub const LINEAR_DEPTH_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::R32Float;
/// The depth buffer: reversed Z (clear 0, compare `Greater`).
pub const DEPTH_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Depth32Float;

/// The render and compute pipelines, built once per device.
#[derive(Debug)]
pub(crate) struct Pipelines {
    /// Bind group 0 of `ids.wgsl`: the view uniform.
    pub view_layout: wgpu::BindGroupLayout,
    /// IDs with the depth test (the instance map).
    pub ids: wgpu::RenderPipeline,
    /// IDs and linear depth with the depth test.
    pub ids_depth: wgpu::RenderPipeline,
    /// IDs without any depth test (coverage of one building drawn alone).
    pub coverage_draw: wgpu::RenderPipeline,
    /// Bind group 0 of `coverage.wgsl`: the ID texture and a slot with a dynamic offset.
    pub coverage_layout: wgpu::BindGroupLayout,
    /// The per-building pixel count of `coverage.wgsl`.
    pub coverage_count: wgpu::ComputePipeline,
}

/// An instance-ID renderer bound to one wgpu device.
///
/// It is `Sync`: render calls from several threads serialise on an internal cache of render targets.
#[derive(Debug)]
pub struct Renderer {
    pub(crate) device: wgpu::Device,
    pub(crate) queue: wgpu::Queue,
    adapter: String,
    /// The adapter is a software rasteriser (lavapipe, llvmpipe, WARP): wgpu's `DeviceType::Cpu`.
    software: bool,
    pub(crate) pipelines: Pipelines,
    /// Render targets kept between calls (a ring per frame size), so batches do not reallocate.
    pub(crate) targets: Mutex<Vec<IdTarget>>,
}

impl Renderer {
    /// Finds an adapter (honouring `WGPU_BACKEND`, `WGPU_ADAPTER_NAME` and the other wgpu environment
    /// variables), creates a device and builds the pipelines. Logs the adapter chosen.
    ///
    /// # Errors
    /// [`RenderError::NoAdapter`] (with the hint to install software Vulkan) when there is no adapter,
    /// [`RenderError::Device`] when the adapter refuses to create a device.
    pub fn new() -> Result<Renderer, RenderError> {
        pollster::block_on(async {
            // Vulkan/Metal/DX12 first (lavapipe is Vulkan); GL only as a fallback, because probing EGL
            // on a headless machine prints warnings to stderr. WGPU_BACKEND overrides both.
            let explicit = wgpu::Backends::from_env().is_some();
            let mut tried = Vec::new();
            let mut found = None;
            for backends in [wgpu::Backends::PRIMARY, wgpu::Backends::all()] {
                let mut desc = wgpu::InstanceDescriptor::new_without_display_handle_from_env();
                if !explicit {
                    desc.backends = backends;
                }
                let instance = wgpu::Instance::new(desc);
                match wgpu::util::initialize_adapter_from_env_or_default(&instance, None).await {
                    Ok(adapter) => {
                        found = Some(adapter);
                        break;
                    }
                    Err(e) => tried.push(e.to_string()),
                }
                if explicit {
                    break;
                }
            }
            let adapter = found.ok_or_else(|| RenderError::NoAdapter { reason: tried.join("; ") })?;
            let info = adapter.get_info();
            let name = format!("{} ({:?}, {} {})", info.name, info.backend, info.driver, info.driver_info);
            log::info!("GPU adapter: {name}");
            if info.device_type == wgpu::DeviceType::Cpu {
                log::info!("the adapter is a software rasteriser: expect a few frames per second at 1080p");
            }
            let downlevel = adapter.get_downlevel_capabilities();
            if !downlevel.flags.contains(wgpu::DownlevelFlags::COMPUTE_SHADERS) {
                return Err(RenderError::Capability { adapter: name, missing: "compute shaders" });
            }
            let (device, queue) = adapter
                .request_device(&wgpu::DeviceDescriptor {
                    label: Some("insgen id renderer"),
                    required_limits: wgpu::Limits::default().using_resolution(adapter.limits()),
                    ..Default::default()
                })
                .await
                .map_err(|source| RenderError::Device { adapter: name.clone(), source })?;
            device.on_uncaptured_error(std::sync::Arc::new(|e: wgpu::Error| {
                log::error!("uncaptured GPU error: {e}");
            }));
            let mut renderer = Renderer::build(device, queue, name)?;
            renderer.software = info.device_type == wgpu::DeviceType::Cpu;
            Ok(renderer)
        })
    }

    /// Builds a renderer on a device the caller created (tests, or an application sharing its GPU).
    ///
    /// # Errors
    /// [`RenderError::Gpu`] when the pipelines cannot be built on this device.
    pub fn with_device(device: wgpu::Device, queue: wgpu::Queue) -> Result<Renderer, RenderError> {
        Renderer::build(device, queue, "caller-provided device".to_string())
    }

    fn build(device: wgpu::Device, queue: wgpu::Queue, adapter: String) -> Result<Renderer, RenderError> {
        let pipelines = gpu_scope(&device, "building the render pipelines", || Pipelines::new(&device))?;
        Ok(Renderer { device, queue, adapter, software: false, pipelines, targets: Mutex::new(Vec::new()) })
    }

    /// The adapter description logged at creation.
    pub fn adapter(&self) -> &str {
        &self.adapter
    }

    /// Whether the adapter is a software rasteriser (lavapipe, llvmpipe): then the CPU rasteriser of
    /// [`super::cpu`] is the faster choice for many small frames (see [`super::RendererChoice`]).
    /// False for a caller-provided device.
    pub fn is_software(&self) -> bool {
        self.software
    }

    /// The wgpu device (for callers that add their own passes).
    pub fn device(&self) -> &wgpu::Device {
        &self.device
    }

    /// The device's queue.
    pub fn queue(&self) -> &wgpu::Queue {
        &self.queue
    }

    /// Uploads a scene mesh (see [`super::GpuScene::new`]).
    ///
    /// # Errors
    /// [`RenderError::InvalidMesh`] for an inconsistent mesh, [`RenderError::Gpu`] when the device cannot
    /// hold it.
    pub fn upload(&self, mesh: &crate::scene::SceneMesh) -> Result<super::GpuScene, RenderError> {
        gpu_scope(&self.device, "uploading the scene mesh", || {
            super::GpuScene::new(&self.device, &self.queue, mesh)
        })?
    }
}

/// Runs `f` inside validation and out-of-memory error scopes and turns a captured error into
/// [`RenderError::Gpu`] (instead of wgpu's default of panicking).
pub(crate) fn gpu_scope<T>(
    device: &wgpu::Device,
    what: &'static str,
    f: impl FnOnce() -> T,
) -> Result<T, RenderError> {
    let oom = device.push_error_scope(wgpu::ErrorFilter::OutOfMemory);
    let validation = device.push_error_scope(wgpu::ErrorFilter::Validation);
    let out = f();
    let v = pollster::block_on(validation.pop());
    let o = pollster::block_on(oom.pop());
    match v.or(o) {
        Some(e) => Err(RenderError::Gpu { what, detail: e.to_string() }),
        None => Ok(out),
    }
}

impl Pipelines {
    fn new(device: &wgpu::Device) -> Pipelines {
        // The WGSL lives beside this file (STYLE rule 13).
        let ids_module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("ids.wgsl"),
            source: wgpu::ShaderSource::Wgsl(include_str!("ids.wgsl").into()),
        });
        let coverage_module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("coverage.wgsl"),
            source: wgpu::ShaderSource::Wgsl(include_str!("coverage.wgsl").into()),
        });
        let view_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("view uniform layout"),
            entries: &[wgpu::BindGroupLayoutEntry {
                binding: 0,
                visibility: wgpu::ShaderStages::VERTEX,
                ty: wgpu::BindingType::Buffer {
                    ty: wgpu::BufferBindingType::Uniform,
                    has_dynamic_offset: false,
                    min_binding_size: wgpu::BufferSize::new(std::mem::size_of::<ViewUniform>() as u64),
                },
                count: None,
            }],
        });
        let layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("id pass layout"),
            bind_group_layouts: &[Some(&view_layout)],
            immediate_size: 0,
        });
        let id_target = Some(wgpu::ColorTargetState {
            format: ID_FORMAT,
            blend: None, // integer targets cannot blend, and IDs must never mix
            write_mask: wgpu::ColorWrites::ALL,
        });
        let depth_target = Some(wgpu::ColorTargetState {
            format: LINEAR_DEPTH_FORMAT,
            blend: None,
            write_mask: wgpu::ColorWrites::ALL,
        });
        let reversed_z = Some(wgpu::DepthStencilState {
            format: DEPTH_FORMAT,
            depth_write_enabled: Some(true),
            depth_compare: Some(wgpu::CompareFunction::Greater),
            stencil: wgpu::StencilState::default(),
            bias: wgpu::DepthBiasState::default(),
        });
        let primitive = wgpu::PrimitiveState {
            topology: wgpu::PrimitiveTopology::TriangleList,
            // LoD models mix windings (and we see roofs from above and walls from any side): no culling.
            cull_mode: None,
            ..Default::default()
        };
        let render = |label: &str, fs: &str, targets: &[Option<wgpu::ColorTargetState>], depth: bool| {
            device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
                label: Some(label),
                layout: Some(&layout),
                vertex: wgpu::VertexState {
                    module: &ids_module,
                    entry_point: Some("vs_main"),
                    compilation_options: Default::default(),
                    buffers: &[Some(GpuVertex::LAYOUT)],
                },
                primitive,
                depth_stencil: if depth { reversed_z.clone() } else { None },
                multisample: wgpu::MultisampleState::default(), // one sample: IDs are never blended
                fragment: Some(wgpu::FragmentState {
                    module: &ids_module,
                    entry_point: Some(fs),
                    compilation_options: Default::default(),
                    targets,
                }),
                multiview_mask: None,
                cache: None,
            })
        };
        let ids = render("ids pipeline", "fs_ids", std::slice::from_ref(&id_target), true);
        let ids_depth =
            render("ids+depth pipeline", "fs_ids_depth", &[id_target.clone(), depth_target], true);
        let coverage_draw = render("coverage draw pipeline", "fs_ids", &[id_target], false);
        let coverage_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("coverage count layout"),
            entries: &[
                wgpu::BindGroupLayoutEntry {
                    binding: 0,
                    visibility: wgpu::ShaderStages::COMPUTE,
                    ty: wgpu::BindingType::Texture {
                        sample_type: wgpu::TextureSampleType::Uint,
                        view_dimension: wgpu::TextureViewDimension::D2,
                        multisampled: false,
                    },
                    count: None,
                },
                wgpu::BindGroupLayoutEntry {
                    binding: 1,
                    visibility: wgpu::ShaderStages::COMPUTE,
                    ty: wgpu::BindingType::Buffer {
                        ty: wgpu::BufferBindingType::Storage { read_only: false },
                        has_dynamic_offset: true,
                        min_binding_size: wgpu::BufferSize::new(super::coverage::SLOT_BYTES),
                    },
                    count: None,
                },
            ],
        });
        let coverage_pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("coverage count pipeline layout"),
            bind_group_layouts: &[Some(&coverage_layout)],
            immediate_size: 0,
        });
        let coverage_count = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
            label: Some("coverage count pipeline"),
            layout: Some(&coverage_pipeline_layout),
            module: &coverage_module,
            entry_point: Some("count_id"),
            compilation_options: Default::default(),
            cache: None,
        });
        Pipelines { view_layout, ids, ids_depth, coverage_draw, coverage_layout, coverage_count }
    }
}
