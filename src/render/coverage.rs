//! Amodal coverage: how many pixels each building would cover if it were alone in the scene (the
//! denominator of `visible_fraction`).
//!
//! For each requested building, one render pass draws only that building's triangles (its index range
//! in the building-grouped index buffer, see [`GpuScene`]) onto the ID target *without* a depth test
//! and *without* clearing, then one compute pass counts the pixels holding that building's ID inside a
//! rectangle that bounds its projection. Pixels left by earlier buildings never hold this building's
//! ID, so one clear per call suffices; within a draw, every covered pixel ends up with the ID however
//! many triangles overlap there, so each pixel counts once. The same vertex transform and rasteriser as
//! the ID pass are used, so a building's visible pixels are always a subset of its amodal pixels.

use bytemuck::{Pod, Zeroable};
use wgpu::util::DeviceExt;

use super::device::{gpu_scope, Renderer};
use super::scene::GpuScene;
use super::view::{DepthRange, View, ViewUniform};
use super::RenderError;
use crate::scene::BuildingId;

/// Bytes per slot of the coverage buffer: the dynamic-offset alignment wgpu guarantees to accept
/// (`min_storage_buffer_offset_alignment` ≤ 256 on every adapter).
pub const SLOT_BYTES: u64 = 256;

/// Buildings per submission (slot buffer of 64 KiB).
const SLOTS_PER_SUBMISSION: usize = 256;

/// Workgroup side of `count_id` in `coverage.wgsl`.
const WORKGROUP: u32 = 16;

/// One slot as `coverage.wgsl` reads it (`struct Slot`), padded to [`SLOT_BYTES`].
#[repr(C)]
#[derive(Debug, Clone, Copy, Pod, Zeroable)]
struct Slot {
    building_id: u32,
    x0: u32,
    y0: u32,
    w: u32,
    h: u32,
    count: u32,
    _pad: [u32; 58],
}

/// A pixel rectangle `[x0, x1) × [y0, y1)`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PixelRect {
    /// First column, pixels.
    pub x0: u32,
    /// First row, pixels.
    pub y0: u32,
    /// One past the last column, pixels.
    pub x1: u32,
    /// One past the last row, pixels.
    pub y1: u32,
}

impl PixelRect {
    /// Whether the rectangle holds no pixel.
    pub fn is_empty(&self) -> bool {
        self.x0 >= self.x1 || self.y0 >= self.y1
    }
}

/// A rectangle of pixels that contains every pixel centre covered by the box `[min_m, max_m]` (ENU
/// metres) in `view`: the projections of its 8 corners, widened by 1 px and clipped to the frame. When a
/// corner is not in front of the near plane, the whole frame (the projection is then unbounded).
pub fn projected_bounds(view: &View, range: &DepthRange, min_m: [f64; 3], max_m: [f64; 3]) -> PixelRect {
    let k = &view.intrinsics;
    let full = PixelRect { x0: 0, y0: 0, x1: k.width_px, y1: k.height_px };
    let (mut u0, mut v0, mut u1, mut v1) =
        (f64::INFINITY, f64::INFINITY, f64::NEG_INFINITY, f64::NEG_INFINITY);
    for corner in 0..8 {
        let p = [0, 1, 2].map(|a| if corner >> a & 1 == 0 { min_m[a] } else { max_m[a] });
        let c = view.pose.world_to_cam(p.into());
        if c[2] <= range.near_m {
            return full;
        }
        let (u, v) = (k.fx_px * c[0] / c[2] + k.cx_px, k.fy_px * c[1] / c[2] + k.cy_px);
        u0 = u0.min(u);
        v0 = v0.min(v);
        u1 = u1.max(u);
        v1 = v1.max(v);
    }
    let clamp = |x: f64, hi: u32| x.clamp(0.0, hi as f64) as u32;
    PixelRect {
        x0: clamp((u0 - 1.0).floor(), k.width_px),
        y0: clamp((v0 - 1.0).floor(), k.height_px),
        x1: clamp((u1 + 1.0).ceil(), k.width_px),
        y1: clamp((v1 + 1.0).ceil(), k.height_px),
    }
}

impl Renderer {
    /// Pixels each of `building_ids` covers in `view` when drawn alone (amodal, inside the frame), in
    /// the order given. A building not in the scene covers 0 pixels.
    ///
    /// # Errors
    /// [`RenderError::InvalidView`] for an invalid view; [`RenderError::Gpu`] / [`RenderError::ReadBack`]
    /// when the device fails.
    pub fn isolated_coverage_px(
        &self,
        scene: &GpuScene,
        view: &View,
        building_ids: &[BuildingId],
        range: &DepthRange,
    ) -> Result<Vec<u64>, RenderError> {
        let uniform = ViewUniform::new(view, range)?;
        let key = (view.intrinsics.width_px, view.intrinsics.height_px, false);
        let ring = self.take_targets(key, 1)?;
        let result = self.coverage_with_target(&ring[0], &uniform, scene, view, building_ids, range);
        self.return_targets(ring);
        result
    }

    fn coverage_with_target(
        &self,
        target: &super::target::IdTarget,
        uniform: &ViewUniform,
        scene: &GpuScene,
        view: &View,
        building_ids: &[BuildingId],
        range: &DepthRange,
    ) -> Result<Vec<u64>, RenderError> {
        let mut counts = vec![0u64; building_ids.len()];
        let mut first_chunk = true;
        for (chunk_no, chunk) in building_ids.chunks(SLOTS_PER_SUBMISSION).enumerate() {
            // (building range, rect) for the buildings that can cover anything.
            let jobs: Vec<Option<(super::scene::BuildingRange, PixelRect)>> = chunk
                .iter()
                .map(|&id| {
                    let b = *scene.building(id)?;
                    let rect = projected_bounds(view, range, b.min_m.map(f64::from), b.max_m.map(f64::from));
                    (!rect.is_empty()).then_some((b, rect))
                })
                .collect();
            if !jobs.iter().any(Option::is_some) {
                continue;
            }
            let slots: Vec<Slot> = jobs
                .iter()
                .map(|j| {
                    let (id, r) = j
                        .map(|(b, r)| (b.building_id, r))
                        .unwrap_or((BuildingId::BACKGROUND, PixelRect { x0: 0, y0: 0, x1: 0, y1: 0 }));
                    Slot {
                        building_id: id.get(),
                        x0: r.x0,
                        y0: r.y0,
                        w: r.x1 - r.x0,
                        h: r.y1 - r.y0,
                        count: 0,
                        _pad: [0; 58],
                    }
                })
                .collect();
            let (submission, staging, rx) = gpu_scope(&self.device, "counting amodal coverage", || {
                let slot_buffer = self.device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                    label: Some("coverage slots"),
                    contents: bytemuck::cast_slice(&slots),
                    usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
                });
                let staging = self.device.create_buffer(&wgpu::BufferDescriptor {
                    label: Some("coverage slots staging"),
                    size: slot_buffer.size(),
                    usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
                    mapped_at_creation: false,
                });
                let bind_group = self.device.create_bind_group(&wgpu::BindGroupDescriptor {
                    label: Some("coverage bind group"),
                    layout: &self.pipelines.coverage_layout,
                    entries: &[
                        wgpu::BindGroupEntry {
                            binding: 0,
                            resource: wgpu::BindingResource::TextureView(&target.id_view),
                        },
                        wgpu::BindGroupEntry {
                            binding: 1,
                            resource: wgpu::BindingResource::Buffer(wgpu::BufferBinding {
                                buffer: &slot_buffer,
                                offset: 0,
                                size: wgpu::BufferSize::new(SLOT_BYTES),
                            }),
                        },
                    ],
                });
                self.queue.write_buffer(&target.uniform, 0, bytemuck::bytes_of(uniform));
                let mut encoder = self.device.create_command_encoder(&wgpu::CommandEncoderDescriptor {
                    label: Some("amodal coverage"),
                });
                if first_chunk {
                    clear_ids(&mut encoder, target);
                }
                for (k, job) in jobs.iter().enumerate() {
                    let Some((b, rect)) = job else { continue };
                    draw_alone(&mut encoder, &self.pipelines, target, scene, b, rect);
                    count_pixels(&mut encoder, &self.pipelines, &bind_group, k, rect);
                }
                encoder.copy_buffer_to_buffer(&slot_buffer, 0, &staging, 0, slot_buffer.size());
                let submission = self.queue.submit([encoder.finish()]);
                let (tx, rx) = std::sync::mpsc::channel();
                staging.map_async(wgpu::MapMode::Read, .., move |r| {
                    let _ = tx.send(r); // see IdTarget::start_map
                });
                (submission, staging, rx)
            })?;
            first_chunk = false;
            super::target::wait_mapped(&self.device, submission, &rx, 1, "coverage counts")?;
            {
                let data = staging
                    .get_mapped_range(..)
                    .map_err(|e| RenderError::ReadBack { what: "coverage counts", detail: e.to_string() })?;
                let read: &[Slot] = bytemuck::cast_slice(&data);
                for (k, s) in read.iter().enumerate() {
                    counts[chunk_no * SLOTS_PER_SUBMISSION + k] = s.count as u64;
                }
            }
            staging.unmap();
        }
        Ok(counts)
    }
}

/// Clears the ID texture to 0 (one pass, no draw).
fn clear_ids(encoder: &mut wgpu::CommandEncoder, target: &super::target::IdTarget) {
    let _pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
        label: Some("coverage clear"),
        color_attachments: &[Some(wgpu::RenderPassColorAttachment {
            view: &target.id_view,
            depth_slice: None,
            resolve_target: None,
            ops: wgpu::Operations {
                load: wgpu::LoadOp::Clear(wgpu::Color::TRANSPARENT),
                store: wgpu::StoreOp::Store,
            },
        })],
        ..Default::default()
    });
}

/// Draws one building alone (no depth test, keeping what earlier passes left), limited to `rect`.
fn draw_alone(
    encoder: &mut wgpu::CommandEncoder,
    pipelines: &super::device::Pipelines,
    target: &super::target::IdTarget,
    scene: &GpuScene,
    building: &super::scene::BuildingRange,
    rect: &PixelRect,
) {
    let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
        label: Some("coverage draw"),
        color_attachments: &[Some(wgpu::RenderPassColorAttachment {
            view: &target.id_view,
            depth_slice: None,
            resolve_target: None,
            ops: wgpu::Operations { load: wgpu::LoadOp::Load, store: wgpu::StoreOp::Store },
        })],
        ..Default::default()
    });
    pass.set_pipeline(&pipelines.coverage_draw);
    pass.set_bind_group(0, &target.bind_group, &[]);
    pass.set_scissor_rect(rect.x0, rect.y0, rect.x1 - rect.x0, rect.y1 - rect.y0);
    pass.set_vertex_buffer(0, scene.vertices.slice(..));
    pass.set_index_buffer(scene.indices.slice(..), wgpu::IndexFormat::Uint32);
    pass.draw_indexed(building.first_index..building.first_index + building.index_count, 0, 0..1);
}

/// Counts the pixels of slot `k`'s building inside its rectangle.
fn count_pixels(
    encoder: &mut wgpu::CommandEncoder,
    pipelines: &super::device::Pipelines,
    bind_group: &wgpu::BindGroup,
    k: usize,
    rect: &PixelRect,
) {
    let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
        label: Some("coverage count"),
        timestamp_writes: None,
    });
    pass.set_pipeline(&pipelines.coverage_count);
    pass.set_bind_group(0, bind_group, &[(k as u64 * SLOT_BYTES) as u32]);
    pass.dispatch_workgroups(
        (rect.x1 - rect.x0).div_ceil(WORKGROUP),
        (rect.y1 - rect.y0).div_ceil(WORKGROUP),
        1,
    );
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::camera::{Intrinsics, Pose};

    #[test]
    fn slot_is_one_alignment_unit() {
        assert_eq!(std::mem::size_of::<Slot>() as u64, SLOT_BYTES);
    }

    #[test]
    fn projected_bounds_of_a_box_below_a_nadir_camera() {
        // 100 m above the origin, f = 100 px, centred 200×200 frame: a 20 m square at ground level
        // spans u ∈ [100 − 10, 100 + 10] (hand computation: 100·10/100 = 10 px).
        let view = View {
            intrinsics: Intrinsics {
                width_px: 200,
                height_px: 200,
                fx_px: 100.0,
                fy_px: 100.0,
                cx_px: 100.0,
                cy_px: 100.0,
            },
            pose: Pose::from_ypr_deg(0.0, 0.0, 0.0, [0.0, 0.0, 100.0]),
        };
        let r = projected_bounds(&view, &DepthRange::default(), [-10.0, -10.0, 0.0], [10.0, 10.0, 0.0]);
        assert_eq!(r, PixelRect { x0: 89, y0: 89, x1: 111, y1: 111 });
        // A box straddling the camera plane has an unbounded projection: the whole frame.
        let r = projected_bounds(&view, &DepthRange::default(), [-10.0, -10.0, 0.0], [10.0, 10.0, 150.0]);
        assert_eq!(r, PixelRect { x0: 0, y0: 0, x1: 200, y1: 200 });
        // Far outside the frame: empty after clipping.
        let r = projected_bounds(&view, &DepthRange::default(), [500.0, 500.0, 0.0], [510.0, 510.0, 0.0]);
        assert!(r.is_empty());
    }
}
