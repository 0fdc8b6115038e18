//! Why the GPU path cannot run.

use crate::trace::LOOP_BUDGET;
use thiserror::Error;

/// Why the GPU path cannot run.
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum GpuError {
    /// No adapter matched.
    #[error(
        "no GPU adapter found{detail}. Install a Vulkan driver (on Debian/Ubuntu: `apt-get install mesa-vulkan-drivers`, which provides the lavapipe CPU driver) or choose a backend with WGPU_BACKEND=vulkan|metal|dx12|gl (gl: build with --features gl) and an adapter with WGPU_ADAPTER_NAME"
    )]
    NoAdapter {
        /// What was asked for.
        detail: String,
    },
    /// The adapter refused the device.
    #[error("the GPU adapter '{adapter}' refused a device: {message}")]
    Device {
        /// Adapter name.
        adapter: String,
        /// Its reason.
        message: String,
    },
    /// The kernel failed validation or pipeline creation on this device.
    #[error("the GPU kernel was rejected by the device: {0}")]
    Shader(String),
    /// A buffer exceeds the adapter's storage binding limit.
    #[error(
        "the scene's {buffer} buffer needs {bytes} bytes but the adapter binds at most {limit} bytes per storage buffer ({count} particles); render it with --backend cpu or on an adapter with larger limits"
    )]
    SceneTooLarge {
        /// Which buffer.
        buffer: &'static str,
        /// Its size.
        bytes: u64,
        /// The adapter's limit.
        limit: u64,
        /// Particles in the scene.
        count: usize,
    },
    /// The method or its parameters cannot run on the GPU.
    #[error("{0}")]
    Unsupported(String),
    /// The scene or settings are invalid.
    #[error(transparent)]
    Render(#[from] splat_core::RenderError),
    /// Reading results back failed.
    #[error("GPU readback failed: {0}")]
    Readback(String),
    /// A ray may need more loop iterations than lavapipe allows one invocation.
    #[error(
        "pixel ({x}, {y}) ran {iterations} loop iterations in one frame; with {lanes} lanes in lockstep a loop of it may have reached lavapipe's limit of {LOOP_BUDGET} iterations, which silently cuts rays short. Use --backend cpu, a larger k (fewer passes), a smaller n, or a hardware GPU"
    )]
    LoopBudget {
        /// Pixel column.
        x: u32,
        /// Pixel row.
        y: u32,
        /// Loop iterations of the busiest lane.
        iterations: u32,
        /// Lanes in lockstep.
        lanes: u32,
    },
}
