//! Timing hook for benchmarks and side-by-side comparisons (e.g. against Blender): render a list of
//! views the way the pipeline does (frames in flight) and report wall-clock times.

use std::time::Instant;

use super::{GpuScene, RenderError, RenderOptions, Renderer, View};

/// Wall-clock timings of one batch.
#[derive(Debug, Clone, PartialEq)]
pub struct RenderTimings {
    /// Frames rendered.
    pub frames: usize,
    /// Time from the call to the last frame read back, seconds.
    pub total_s: f64,
    /// Time between consecutive frames arriving on the CPU (the first one measured from the call),
    /// seconds; with frames in flight this is the steady-state cost per frame.
    pub per_frame_s: Vec<f64>,
    /// Non-zero (building) pixels over all frames, to check that something was drawn.
    pub building_px: u64,
}

impl RenderTimings {
    /// Frames per second over the whole batch.
    pub fn frames_per_s(&self) -> f64 {
        if self.total_s > 0.0 {
            self.frames as f64 / self.total_s
        } else {
            0.0
        }
    }

    /// Median of the per-frame intervals, seconds.
    pub fn median_frame_s(&self) -> f64 {
        let mut v = self.per_frame_s.clone();
        v.sort_by(f64::total_cmp);
        v.get(v.len() / 2).copied().unwrap_or(0.0)
    }
}

/// Renders `views` (read back to CPU memory, then dropped) and times it.
///
/// # Errors
/// As [`Renderer::render_each`].
pub fn time_render(
    renderer: &Renderer,
    scene: &GpuScene,
    views: &[View],
    options: &RenderOptions,
) -> Result<RenderTimings, RenderError> {
    let start = Instant::now();
    let mut last = start;
    let mut per_frame_s = Vec::with_capacity(views.len());
    let mut building_px = 0u64;
    renderer.render_each(scene, views, options, |_, image| {
        let now = Instant::now();
        per_frame_s.push((now - last).as_secs_f64());
        last = now;
        building_px += image.ids.raw().iter().filter(|&&id| id != 0).count() as u64;
        Ok::<(), RenderError>(())
    })?;
    Ok(RenderTimings {
        frames: views.len(),
        total_s: start.elapsed().as_secs_f64(),
        per_frame_s,
        building_px,
    })
}
