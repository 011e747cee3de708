//! One render target of the ID pass and its three steps, one function each (STYLE rule 13):
//! [`IdTarget::new`] allocates, [`draw_ids`] records the pass, [`read_back`] maps the staging buffers
//! and strips the row padding.

use std::sync::mpsc;

use super::device::{Pipelines, DEPTH_FORMAT, ID_FORMAT, LINEAR_DEPTH_FORMAT};
use super::scene::GpuScene;
use super::view::ViewUniform;
use super::RenderError;
use crate::scene::IdMap;

/// A rendered frame: its building IDs and, when asked for, linear depth.
#[derive(Debug, Clone, PartialEq)]
pub struct RenderedFrame {
    /// One building ID per pixel.
    pub ids: IdMap,
    /// Row-major depth along the optical axis in metres (0 where no building was hit), when rendered.
    pub depth_m: Option<Vec<f32>>,
}

/// Bytes per row of a staging buffer: 4 bytes per pixel rounded up to wgpu's copy alignment (256).
pub fn padded_bytes_per_row(width_px: u32) -> u32 {
    let unpadded = 4 * width_px;
    let align = wgpu::COPY_BYTES_PER_ROW_ALIGNMENT;
    unpadded.div_ceil(align) * align
}

/// An offscreen target: the R32Uint ID texture, the reversed-Z depth buffer, the optional R32Float
/// linear-depth texture, their staging buffers and the view uniform with its bind group.
#[derive(Debug)]
pub struct IdTarget {
    /// Target width, pixels.
    pub width: u32,
    /// Target height, pixels.
    pub height: u32,
    /// Whether the linear-depth texture exists.
    pub with_depth: bool,
    pub(crate) id_texture: wgpu::Texture,
    pub(crate) id_view: wgpu::TextureView,
    depth_view: wgpu::TextureView,
    linear_depth: Option<(wgpu::Texture, wgpu::TextureView)>,
    staging_ids: wgpu::Buffer,
    staging_depth: Option<wgpu::Buffer>,
    pub(crate) uniform: wgpu::Buffer,
    pub(crate) bind_group: wgpu::BindGroup,
    padded_row_bytes: u32,
}

impl IdTarget {
    /// Allocates a `width × height` target (no MSAA). `with_depth` adds the linear-depth texture.
    /// The staging buffers' rows are padded to 256 bytes as texture-to-buffer copies require.
    pub(crate) fn new(
        device: &wgpu::Device,
        pipelines: &Pipelines,
        width: u32,
        height: u32,
        with_depth: bool,
    ) -> IdTarget {
        let size = wgpu::Extent3d { width, height, depth_or_array_layers: 1 };
        let texture = |label: &str, format: wgpu::TextureFormat, usage: wgpu::TextureUsages| {
            device.create_texture(&wgpu::TextureDescriptor {
                label: Some(label),
                size,
                mip_level_count: 1,
                sample_count: 1,
                dimension: wgpu::TextureDimension::D2,
                format,
                usage,
                view_formats: &[],
            })
        };
        // Render attachment + copy source for read-back; texture binding for the coverage count.
        let id_texture = texture(
            "id target (R32Uint)",
            ID_FORMAT,
            wgpu::TextureUsages::RENDER_ATTACHMENT
                | wgpu::TextureUsages::COPY_SRC
                | wgpu::TextureUsages::TEXTURE_BINDING,
        );
        let id_view = id_texture.create_view(&wgpu::TextureViewDescriptor::default());
        let depth_texture =
            texture("reversed-z depth (Depth32Float)", DEPTH_FORMAT, wgpu::TextureUsages::RENDER_ATTACHMENT);
        let depth_view = depth_texture.create_view(&wgpu::TextureViewDescriptor::default());
        let linear_depth = with_depth.then(|| {
            let t = texture(
                "linear depth target (R32Float, m)",
                LINEAR_DEPTH_FORMAT,
                wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::COPY_SRC,
            );
            let v = t.create_view(&wgpu::TextureViewDescriptor::default());
            (t, v)
        });
        let padded_row_bytes = padded_bytes_per_row(width);
        // A separate buffer for reading: MAP_READ is only allowed together with COPY_DST.
        let staging = |label: &str| {
            device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size: padded_row_bytes as u64 * height as u64,
                usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            })
        };
        let staging_ids = staging("id staging buffer");
        let staging_depth = with_depth.then(|| staging("depth staging buffer"));
        let uniform = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("view uniform"),
            size: std::mem::size_of::<ViewUniform>() as u64,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let bind_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("view bind group"),
            layout: &pipelines.view_layout,
            entries: &[wgpu::BindGroupEntry { binding: 0, resource: uniform.as_entire_binding() }],
        });
        IdTarget {
            width,
            height,
            with_depth,
            id_texture,
            id_view,
            depth_view,
            linear_depth,
            staging_ids,
            staging_depth,
            uniform,
            bind_group,
            padded_row_bytes,
        }
    }

    /// Records the copies of the rendered textures into the staging buffers.
    pub(crate) fn record_copies(&self, encoder: &mut wgpu::CommandEncoder) {
        let size = wgpu::Extent3d { width: self.width, height: self.height, depth_or_array_layers: 1 };
        let copy = |encoder: &mut wgpu::CommandEncoder, texture: &wgpu::Texture, buffer: &wgpu::Buffer| {
            encoder.copy_texture_to_buffer(
                wgpu::TexelCopyTextureInfo {
                    texture,
                    mip_level: 0,
                    origin: wgpu::Origin3d::ZERO,
                    aspect: wgpu::TextureAspect::All,
                },
                wgpu::TexelCopyBufferInfo {
                    buffer,
                    layout: wgpu::TexelCopyBufferLayout {
                        offset: 0,
                        bytes_per_row: Some(self.padded_row_bytes),
                        rows_per_image: Some(self.height),
                    },
                },
                size,
            );
        };
        copy(encoder, &self.id_texture, &self.staging_ids);
        if let (Some((t, _)), Some(b)) = (&self.linear_depth, &self.staging_depth) {
            copy(encoder, t, b);
        }
    }

    /// Unmaps the staging buffers (cancelling a pending mapping), after an interrupted batch.
    pub(crate) fn unmap_all(&self) {
        self.staging_ids.unmap();
        if let Some(b) = &self.staging_depth {
            b.unmap();
        }
    }

    /// Starts mapping the staging buffers (after the submission that fills them). The returned receiver
    /// yields one result per buffer once the device has been polled past that submission.
    pub(crate) fn start_map(&self) -> mpsc::Receiver<Result<(), wgpu::BufferAsyncError>> {
        let (tx, rx) = mpsc::channel();
        for buffer in std::iter::once(&self.staging_ids).chain(self.staging_depth.as_ref()) {
            let tx = tx.clone();
            buffer.map_async(wgpu::MapMode::Read, .., move |r| {
                // The receiver lives until read_back has collected every result; a send can only fail
                // if read_back gave up early, and then nobody needs the result.
                let _ = tx.send(r);
            });
        }
        rx
    }
}

/// Records the ID pass for `target` in its own scope: clear IDs (and linear depth) to 0 and the
/// reversed-Z depth to 0, bind the view, draw the whole scene with the depth test `Greater`.
pub(crate) fn draw_ids(
    encoder: &mut wgpu::CommandEncoder,
    pipelines: &Pipelines,
    target: &IdTarget,
    scene: &GpuScene,
) {
    let clear_zero =
        wgpu::Operations { load: wgpu::LoadOp::Clear(wgpu::Color::TRANSPARENT), store: wgpu::StoreOp::Store };
    let mut colour = vec![Some(wgpu::RenderPassColorAttachment {
        view: &target.id_view,
        depth_slice: None,
        resolve_target: None,
        ops: clear_zero,
    })];
    if let Some((_, view)) = &target.linear_depth {
        colour.push(Some(wgpu::RenderPassColorAttachment {
            view,
            depth_slice: None,
            resolve_target: None,
            ops: clear_zero,
        }));
    }
    let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
        label: Some("id pass"),
        color_attachments: &colour,
        depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
            view: &target.depth_view,
            // Reversed Z: 0 is the far plane.
            depth_ops: Some(wgpu::Operations {
                load: wgpu::LoadOp::Clear(0.0),
                store: wgpu::StoreOp::Discard,
            }),
            stencil_ops: None,
        }),
        timestamp_writes: None,
        occlusion_query_set: None,
        multiview_mask: None,
    });
    if scene.index_count == 0 {
        return; // nothing to draw: the clear is the frame
    }
    pass.push_debug_group("draw scene");
    pass.set_pipeline(if target.with_depth { &pipelines.ids_depth } else { &pipelines.ids });
    pass.set_bind_group(0, &target.bind_group, &[]);
    pass.set_vertex_buffer(0, scene.vertices.slice(..));
    pass.set_index_buffer(scene.indices.slice(..), wgpu::IndexFormat::Uint32);
    pass.draw_indexed(0..scene.index_count, 0, 0..1);
    pass.pop_debug_group();
}

/// How long [`wait_mapped`] waits for map callbacks after the GPU finished before it gives up.
const MAP_CALLBACK_TIMEOUT: std::time::Duration = std::time::Duration::from_secs(120);

/// Waits for `submission`, then for `expected` map callbacks on `mapped`.
///
/// A finished submission does not mean the callbacks already ran: when several threads share a
/// device, another thread's `poll` may be the one running them, concurrently with ours. So after the
/// wait we block on the channel (polling again now and then) instead of expecting the messages to
/// be there already.
///
/// # Errors
/// [`RenderError::ReadBack`] when polling fails (device lost), a mapping fails, or the callbacks do
/// not arrive within [`MAP_CALLBACK_TIMEOUT`].
pub(crate) fn wait_mapped(
    device: &wgpu::Device,
    submission: wgpu::SubmissionIndex,
    mapped: &mpsc::Receiver<Result<(), wgpu::BufferAsyncError>>,
    expected: usize,
    what: &'static str,
) -> Result<(), RenderError> {
    device
        .poll(wgpu::PollType::Wait { submission_index: Some(submission), timeout: None })
        .map_err(|e| RenderError::ReadBack { what, detail: e.to_string() })?;
    let deadline = std::time::Instant::now() + MAP_CALLBACK_TIMEOUT;
    let mut received = 0;
    while received < expected {
        match mapped.recv_timeout(std::time::Duration::from_millis(5)) {
            Ok(Ok(())) => received += 1,
            Ok(Err(e)) => return Err(RenderError::ReadBack { what, detail: e.to_string() }),
            Err(mpsc::RecvTimeoutError::Timeout) if std::time::Instant::now() < deadline => {
                device
                    .poll(wgpu::PollType::Poll)
                    .map_err(|e| RenderError::ReadBack { what, detail: e.to_string() })?;
            }
            Err(e) => {
                return Err(RenderError::ReadBack {
                    what,
                    detail: format!("the staging buffer was not mapped after the wait ({e})"),
                })
            }
        }
    }
    Ok(())
}

/// Waits for `submission`, reads the mapped staging buffers, strips the row padding and unmaps.
///
/// # Errors
/// [`RenderError::ReadBack`] when polling or mapping fails (device lost).
pub(crate) fn read_back(
    device: &wgpu::Device,
    target: &IdTarget,
    submission: wgpu::SubmissionIndex,
    mapped: mpsc::Receiver<Result<(), wgpu::BufferAsyncError>>,
) -> Result<RenderedFrame, RenderError> {
    let expected = 1 + target.staging_depth.is_some() as usize;
    wait_mapped(device, submission, &mapped, expected, "a frame")?;
    let strip = |buffer: &wgpu::Buffer| -> Result<Vec<u32>, RenderError> {
        let mut out = Vec::with_capacity(target.width as usize * target.height as usize);
        {
            let view = buffer
                .get_mapped_range(..)
                .map_err(|e| RenderError::ReadBack { what: "a frame", detail: e.to_string() })?;
            let row_bytes = 4 * target.width as usize;
            for row in view.chunks_exact(target.padded_row_bytes as usize) {
                out.extend(
                    row[..row_bytes].chunks_exact(4).map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]])),
                );
            }
        }
        buffer.unmap();
        Ok(out)
    };
    let ids = strip(&target.staging_ids)?;
    let depth_m = match &target.staging_depth {
        Some(b) => Some(strip(b)?.into_iter().map(f32::from_bits).collect()),
        None => None,
    };
    Ok(RenderedFrame { ids: IdMap::from_raw(target.width, target.height, ids)?, depth_m })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rows_are_padded_to_256_bytes() {
        assert_eq!(padded_bytes_per_row(64), 256);
        assert_eq!(padded_bytes_per_row(65), 512);
        assert_eq!(padded_bytes_per_row(1920), 7680); // 1920·4 = 7680 = 30·256
        assert_eq!(padded_bytes_per_row(1), 256);
    }
}
