//! Rendering many frames: a ring of targets keeps several frames in flight, so the GPU (or lavapipe's
//! worker threads) renders frame i + 1 while frame i is being mapped and copied out.

use std::collections::VecDeque;
use std::sync::mpsc;

use super::device::{gpu_scope, Renderer};
use super::scene::GpuScene;
use super::target::{draw_ids, read_back, IdTarget, RenderedFrame};
use super::view::{DepthRange, View, ViewUniform};
use super::RenderError;

/// Frames in flight: frame i + 2 is submitted before frame i is read back.
pub const FRAMES_IN_FLIGHT: usize = 3;

/// Targets kept between calls, at most this many (e.g. two frame sizes × the ring).
const MAX_CACHED_TARGETS: usize = 2 * FRAMES_IN_FLIGHT;

/// Options of a render call.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct RenderOptions {
    /// Clip planes (default 0.1 m – 10 km).
    pub range: DepthRange,
    /// Also render linear depth (metres along the optical axis) into [`RenderedFrame::depth_m`].
    pub linear_depth: bool,
}

type TargetKey = (u32, u32, bool);

struct InFlight {
    frame: usize,
    slot: usize,
    submission: wgpu::SubmissionIndex,
    mapped: mpsc::Receiver<Result<(), wgpu::BufferAsyncError>>,
}

impl Renderer {
    /// Takes up to `n` targets of this size from the cache, creating the missing ones.
    pub(crate) fn take_targets(&self, key: TargetKey, n: usize) -> Result<Vec<IdTarget>, RenderError> {
        let mut ring = Vec::with_capacity(n);
        {
            // A poisoned lock only means another thread panicked while holding the cache; the targets
            // in it are still valid GPU objects.
            let mut cache = self.targets.lock().unwrap_or_else(|p| p.into_inner());
            while ring.len() < n {
                match cache.iter().position(|t| (t.width, t.height, t.with_depth) == key) {
                    Some(i) => ring.push(cache.remove(i)),
                    None => break,
                }
            }
        }
        while ring.len() < n {
            let t = gpu_scope(&self.device, "allocating a render target", || {
                IdTarget::new(&self.device, &self.pipelines, key.0, key.1, key.2)
            })?;
            ring.push(t);
        }
        Ok(ring)
    }

    /// Returns targets to the cache (dropping the oldest beyond its capacity).
    pub(crate) fn return_targets(&self, ring: Vec<IdTarget>) {
        let mut cache = self.targets.lock().unwrap_or_else(|p| p.into_inner());
        cache.extend(ring);
        let excess = cache.len().saturating_sub(MAX_CACHED_TARGETS);
        cache.drain(..excess);
    }

    /// Renders one frame.
    ///
    /// # Errors
    /// As [`Renderer::render_each`].
    pub fn render(
        &self,
        scene: &GpuScene,
        view: &View,
        options: &RenderOptions,
    ) -> Result<RenderedFrame, RenderError> {
        let mut out = self.render_batch(scene, std::slice::from_ref(view), options)?;
        out.pop().ok_or(RenderError::ReadBack { what: "a frame", detail: "no frame was produced".into() })
    }

    /// Renders a batch of frames and returns them in order (see [`Renderer::render_each`] for
    /// streaming them instead of holding all in memory).
    ///
    /// # Errors
    /// As [`Renderer::render_each`].
    pub fn render_batch(
        &self,
        scene: &GpuScene,
        views: &[View],
        options: &RenderOptions,
    ) -> Result<Vec<RenderedFrame>, RenderError> {
        let mut out = Vec::with_capacity(views.len());
        self.render_each(scene, views, options, |_, image| {
            out.push(image);
            Ok::<(), RenderError>(())
        })?;
        Ok(out)
    }

    /// Renders `views` in order and hands each frame to `emit(index, image)` as soon as it is read back,
    /// with up to [`FRAMES_IN_FLIGHT`] frames submitted ahead. Views may differ in size; the ring is
    /// rebuilt when the size changes.
    ///
    /// # Errors
    /// [`RenderError::InvalidView`] (naming the view index) before anything is rendered if any view is
    /// invalid; [`RenderError::Gpu`] / [`RenderError::ReadBack`] when the device fails; any error of
    /// `emit`, which stops the batch.
    pub fn render_each<E, F>(
        &self,
        scene: &GpuScene,
        views: &[View],
        options: &RenderOptions,
        mut emit: F,
    ) -> Result<(), E>
    where
        E: From<RenderError>,
        F: FnMut(usize, RenderedFrame) -> Result<(), E>,
    {
        let uniforms = views
            .iter()
            .enumerate()
            .map(|(i, v)| {
                ViewUniform::new(v, &options.range).map_err(|e| match e {
                    RenderError::InvalidView { problem, .. } => {
                        RenderError::InvalidView { view: Some(i), problem }
                    }
                    other => other,
                })
            })
            .collect::<Result<Vec<_>, _>>()?;
        let mut ring: Vec<IdTarget> = Vec::new();
        let mut ring_key: Option<TargetKey> = None;
        let mut in_flight: VecDeque<InFlight> = VecDeque::new();
        let mut next_slot = 0usize;
        let result = (|| -> Result<(), E> {
            for (i, (view, uniform)) in views.iter().zip(&uniforms).enumerate() {
                let key = (view.intrinsics.width_px, view.intrinsics.height_px, options.linear_depth);
                if ring_key != Some(key) {
                    while let Some(f) = in_flight.pop_front() {
                        let image = read_back(&self.device, &ring[f.slot], f.submission, f.mapped)?;
                        emit(f.frame, image)?;
                    }
                    self.return_targets(std::mem::take(&mut ring));
                    ring = self.take_targets(key, FRAMES_IN_FLIGHT)?;
                    ring_key = Some(key);
                    next_slot = 0;
                }
                if in_flight.len() == FRAMES_IN_FLIGHT {
                    // The ring is full: the oldest frame must leave before its slot is reused.
                    let f = in_flight.pop_front().expect("the ring is full, so not empty");
                    let image = read_back(&self.device, &ring[f.slot], f.submission, f.mapped)?;
                    emit(f.frame, image)?;
                }
                let slot = next_slot;
                next_slot = (next_slot + 1) % FRAMES_IN_FLIGHT;
                let target = &ring[slot];
                let submission = gpu_scope(&self.device, "rendering a frame", || {
                    self.queue.write_buffer(&target.uniform, 0, bytemuck::bytes_of(uniform));
                    let mut encoder = self
                        .device
                        .create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("id frame") });
                    draw_ids(&mut encoder, &self.pipelines, target, scene);
                    target.record_copies(&mut encoder);
                    self.queue.submit([encoder.finish()])
                })?;
                let mapped = target.start_map();
                in_flight.push_back(InFlight { frame: i, slot, submission, mapped });
            }
            while let Some(f) = in_flight.pop_front() {
                let image = read_back(&self.device, &ring[f.slot], f.submission, f.mapped)?;
                emit(f.frame, image)?;
            }
            Ok(())
        })();
        if !in_flight.is_empty() {
            // Stopped early: cancel pending mappings so the targets can be reused.
            let _ = self.device.poll(wgpu::PollType::wait_indefinitely());
            for f in &in_flight {
                ring[f.slot].unmap_all();
            }
        }
        self.return_targets(ring);
        result
    }
}
