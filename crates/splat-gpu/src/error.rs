//! Why the GPU path cannot run.

use crate::trace::LOOP_BUDGET;
use thiserror::Error;

/// What lets a refused render run, in the library's words ([`Remedy::words`]); each front end
/// says it in its own (the CLI names its flags, the viewer its controls), so no message of
/// this crate names an option of one of them. Exhaustive on purpose: a new remedy makes every
/// front end's match name it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Remedy {
    /// The CPU backend (`splat-core`), which renders every method and setting.
    Cpu,
    /// Centre fragment depth (`FragmentDepth::Center`).
    CenterDepth,
    /// The adapter's standard sample positions (`SamplePattern::Standard`).
    StandardPattern,
    /// Rasterization without early stop (`RasterSettings::early_stop` off).
    NoEarlyStop,
    /// The exact ray-tracing method, whose image equals the brute-force oracle's.
    ExactMethod,
    /// Enderton's or Laine–Karras's raster operations, which draw transparent triangles.
    RasterOperations,
}

impl Remedy {
    /// The remedy in the library's words.
    pub fn words(self) -> &'static str {
        match self {
            Remedy::Cpu => "the CPU backend",
            Remedy::CenterDepth => "centre fragment depth",
            Remedy::StandardPattern => "the standard sample pattern",
            Remedy::NoEarlyStop => "rasterization without early stop",
            Remedy::ExactMethod => "the exact method (the same image)",
            Remedy::RasterOperations => {
                "Enderton or stratified splatting (their raster operations draw transparent triangles)"
            }
        }
    }
}

/// `: use A or B` for `remedies`, empty for none.
fn remedy_words(remedies: &[Remedy]) -> String {
    match remedies {
        [] => String::new(),
        _ => format!(": use {}", remedies.iter().map(|r| r.words()).collect::<Vec<_>>().join(" or ")),
    }
}

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
        "the scene's {buffer} buffer needs {bytes} bytes but the adapter binds at most {limit} bytes per storage buffer ({count} particles): render it on the CPU backend or on an adapter with larger limits"
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
    /// The scene's arrays, split over bindings of the adapter's limit, need more storage
    /// bindings than the adapter gives a kernel (`crate::split`).
    #[error(
        "the scene's {arrays} ({bytes} bytes) split over bindings of at most {limit} bytes make {kernel} bind {needed} storage buffers, but the adapter binds at most {available} in a shader stage: it fits about {fits} {fits_what}; render it on the CPU backend or on an adapter with larger limits"
    )]
    SceneOverBindings {
        /// The arrays split ("particles, BVH nodes and SH").
        arrays: &'static str,
        /// The kernel that binds them ("the ray tracer").
        kernel: &'static str,
        /// Storage buffers the kernel would bind, its own included.
        needed: u32,
        /// Storage buffers the adapter binds in a shader stage.
        available: u32,
        /// The adapter's (or the context's) binding limit.
        limit: u64,
        /// Their size.
        bytes: u64,
        /// How many would fit: particles of this scene's kind, or pairs of a sort.
        fits: u64,
        /// What `fits` counts ("particles like these", "tile pairs").
        fits_what: &'static str,
    },
    /// The scene's arrays hold more elements than the kernels' 32-bit indices reach, whatever
    /// the adapter's bindings.
    #[error(
        "the scene's {arrays} hold {elements} elements, but {kernel} index them with 32-bit integers (at most {max}): it fits about {fits} {fits_what}; render it on the CPU backend",
        max = crate::split::MAX_ELEMENTS
    )]
    SceneOverIndices {
        /// The arrays ("particles, BVH nodes and SH").
        arrays: &'static str,
        /// The kernel that indexes them ("the ray tracer").
        kernel: &'static str,
        /// Elements of the longest array.
        elements: u64,
        /// How many would fit.
        fits: u64,
        /// What `fits` counts ("particles like these").
        fits_what: &'static str,
    },
    /// The scene's arrays need more memory than the device has left, where it can tell
    /// (`GpuContext::memory_available`: a CPU adapter's memory is the host's).
    #[error(
        "the scene's {arrays} need {bytes} bytes of device memory and the device has {available} left (a CPU adapter's memory is the host's): render it on the CPU backend, which holds the scene once, or on a GPU"
    )]
    MemoryShort {
        /// The arrays ("particles, BVH nodes and SH").
        arrays: &'static str,
        /// What they need.
        bytes: u64,
        /// What the device has left.
        available: u64,
    },
    /// The device could not allocate a scene buffer (its memory is full).
    #[error(
        "the GPU could not allocate the scene's {buffer} buffers ({bytes} bytes): {message}; render it on the CPU backend or on a device with more memory"
    )]
    DeviceMemory {
        /// Which buffer.
        buffer: &'static str,
        /// Its size.
        bytes: u64,
        /// wgpu's message.
        message: String,
    },
    /// The method or its parameters cannot run on the GPU.
    #[error("{0}")]
    Unsupported(String),
    /// The method or its parameters cannot run on the GPU, and what would let them.
    #[error("{reason}{}", remedy_words(remedies))]
    Refused {
        /// What the GPU cannot do.
        reason: String,
        /// What lets the render run instead.
        remedies: Vec<Remedy>,
    },
    /// The scene or settings are invalid.
    #[error(transparent)]
    Render(#[from] splat_core::RenderError),
    /// Reading results back failed.
    #[error("GPU readback failed: {0}")]
    Readback(String),
    /// A ray may need more loop iterations than lavapipe allows one invocation.
    #[error(
        "pixel ({x}, {y}) ran {iterations} loop iterations in one frame; with {lanes} lanes in lockstep a loop of it may have reached lavapipe's limit of {LOOP_BUDGET} iterations, which silently cuts rays short. Render it on the CPU backend, with a larger k (fewer passes) or a smaller n, or on a hardware GPU"
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

impl GpuError {
    /// A refusal with what would let the render run.
    pub fn refused(reason: impl Into<String>, remedies: &[Remedy]) -> Self {
        Self::Refused { reason: reason.into(), remedies: remedies.to_vec() }
    }

    /// What would let the refused render run: the CPU backend for a scene above the binding
    /// limits or the device's memory, or a ray over lavapipe's loop budget, a refusal's own remedies, nothing otherwise.
    pub fn remedies(&self) -> &[Remedy] {
        match self {
            Self::Refused { remedies, .. } => remedies,
            Self::SceneTooLarge { .. }
            | Self::SceneOverBindings { .. }
            | Self::SceneOverIndices { .. }
            | Self::MemoryShort { .. }
            | Self::DeviceMemory { .. }
            | Self::LoopBudget { .. } => &[Remedy::Cpu],
            _ => &[],
        }
    }
}

/// Whether the GPU has a kernel for method `id`: the catalogue's `gpu` column
/// ([`splat_core::catalogue::Entry::gpu`]), the CPU the way out where it has none. The tracer
/// and the rasterizer ask here.
pub(crate) fn supports_method(id: splat_core::MethodId) -> Result<(), GpuError> {
    let entry = id.entry();
    if entry.gpu {
        Ok(())
    } else {
        Err(GpuError::refused(format!("{} runs on the CPU only", entry.name), &[Remedy::Cpu]))
    }
}
