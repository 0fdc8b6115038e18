//! Stage timings of the splatting path, for `splat bench`.

use super::*;

/// GPU times of one frame's stages, from timestamp queries when the adapter has them, else
/// wall time around each stage's own submission.
#[derive(Clone, Copy, Debug, Default)]
pub struct RasterTimings {
    /// Projection and culling.
    pub project: Duration,
    /// Depth sort.
    pub sort: Duration,
    /// Dispatches of one depth sort (its setup, and each pass's histogram, scan levels and
    /// scatter): a count that does not depend on the machine.
    pub sort_dispatches: u64,
    /// Sorted splatting (over) of every visible splat.
    pub draw_sorted: Duration,
    /// One StochasticSplats frame (1 spp) of every visible splat.
    pub draw_stochastic: Duration,
    /// Whether the times come from timestamp queries.
    pub timestamps: bool,
}

impl RasterTimings {
    /// A sorted frame: projection, sort and draw.
    pub fn sorted_frame(&self) -> Duration {
        self.project + self.sort + self.draw_sorted
    }

    /// A stochastic frame: projection and draw, no sort.
    pub fn stochastic_frame(&self) -> Duration {
        self.project + self.draw_stochastic
    }
}

impl GpuRasterizer<'_> {
    /// Time one frame's stages: projection, sort, a sorted (over) draw and a StochasticSplats
    /// draw at 1 spp; the fastest of `repeat` runs of each.
    pub fn profile(&self, repeat: u32) -> Result<RasterTimings, GpuError> {
        let (w, h) = (self.camera.width, self.camera.height);
        let sorted_targets = RasterTargets::new(self.ctx, self.pipes, w, h, Draw::Over, 1);
        let stochastic_targets = RasterTargets::new(self.ctx, self.pipes, w, h, Draw::Stochastic, 1);
        let slots = FrameSlots::new(self.ctx);
        slots.write(self.ctx, &[splat_core::rng::frame_key(1, 0)], 0, &splat_core::Frames::default());
        let groups = [Draw::Over, Draw::Stochastic].map(|draw| self.draw_group(&slots.buffer, draw));
        let timer = self.ctx.timestamps.then(|| crate::timing::Timer::new(self.ctx));
        let mut best = [Duration::MAX; 4];
        let mut sort_dispatches = 0;
        for _ in 0..repeat.max(1) {
            for (phase, slot) in best.iter_mut().enumerate() {
                let mut encoder = self.encoder("profile");
                let writes = timer.as_ref().map(|t| (&t.queries, 0u32, 1u32));
                let compute_ts = writes.map(|(q, b, e)| wgpu::ComputePassTimestampWrites {
                    query_set: q,
                    beginning_of_pass_write_index: Some(b),
                    end_of_pass_write_index: Some(e),
                });
                let render_ts = writes.map(|(q, b, e)| wgpu::RenderPassTimestampWrites {
                    query_set: q,
                    beginning_of_pass_write_index: Some(b),
                    end_of_pass_write_index: Some(e),
                });
                match phase {
                    0 => self.encode_project(&mut encoder, compute_ts),
                    1 => {
                        let before = self.ctx.counters();
                        self.encode_sort(&mut encoder, compute_ts)?;
                        sort_dispatches = (self.ctx.counters() - before).dispatches;
                    }
                    2 => {
                        self.set_mode(Draw::Over);
                        self.encode_draw(&mut encoder, Draw::Over, &sorted_targets, &groups[0], 0, render_ts)?;
                    }
                    _ => {
                        self.set_mode(Draw::Stochastic);
                        self.encode_draw(
                            &mut encoder,
                            Draw::Stochastic,
                            &stochastic_targets,
                            &groups[1],
                            0,
                            render_ts,
                        )?;
                    }
                }
                if let Some(t) = &timer {
                    t.resolve(&mut encoder);
                }
                let start = Instant::now();
                self.submit(encoder)?;
                let elapsed = match &timer {
                    Some(t) => t.elapsed(self.ctx)?,
                    None => start.elapsed(),
                };
                *slot = (*slot).min(elapsed);
            }
        }
        Ok(RasterTimings {
            project: best[0],
            sort: best[1],
            sort_dispatches,
            draw_sorted: best[2],
            draw_stochastic: best[3],
            timestamps: timer.is_some(),
        })
    }
}
