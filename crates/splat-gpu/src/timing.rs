//! GPU time of compute passes: timestamp queries at the start and end of a pass, where the
//! adapter has them.

use crate::{GpuContext, GpuError};
use std::time::Duration;

/// Timestamp queries at the start and end of each compute pass.
pub(crate) struct Timer {
    pub(crate) queries: wgpu::QuerySet,
    resolved: wgpu::Buffer,
    staging: wgpu::Buffer,
}

impl Timer {
    pub(crate) fn new(ctx: &GpuContext) -> Self {
        let queries = ctx.device.create_query_set(&wgpu::QuerySetDescriptor {
            label: Some("pass time"),
            ty: wgpu::QueryType::Timestamp,
            count: 2,
        });
        let buffer = |label, usage| {
            ctx.device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size: 16,
                usage,
                mapped_at_creation: false,
            })
        };
        Self {
            queries,
            resolved: buffer("timestamps", wgpu::BufferUsages::QUERY_RESOLVE | wgpu::BufferUsages::COPY_SRC),
            staging: buffer("read timestamps", wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST),
        }
    }

    pub(crate) fn resolve(&self, encoder: &mut wgpu::CommandEncoder) {
        encoder.resolve_query_set(&self.queries, 0..2, &self.resolved, 0);
        encoder.copy_buffer_to_buffer(&self.resolved, 0, &self.staging, 0, 16);
    }

    /// Time between the two timestamps of the last submitted pass.
    pub(crate) fn elapsed(&self, ctx: &GpuContext) -> Result<Duration, GpuError> {
        let words = ctx.read_buffer(&self.staging)?;
        let ticks = |i: usize| u64::from(words[2 * i].to_bits()) | (u64::from(words[2 * i + 1].to_bits()) << 32);
        let nanos = ticks(1).saturating_sub(ticks(0)) as f64 * f64::from(ctx.queue.get_timestamp_period());
        Ok(Duration::from_nanos(nanos as u64))
    }
}
