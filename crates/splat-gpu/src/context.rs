//! The headless wgpu device every kernel runs on, its buffer helpers and the layout-entry and
//! pipeline helpers shared by the trace, raster and sort kernels.

use crate::GpuError;
use splat_core::Camera;
use splat_core::image::Image;
use wgpu::util::DeviceExt;

/// Turns off Mesa's Vulkan device-select layer where the layer can only complain: on a machine
/// without a desktop session (`XDG_RUNTIME_DIR` unset) the layer, loaded into every Vulkan
/// process, tries to reach a Wayland compositor and prints `error: XDG_RUNTIME_DIR is invalid
/// or not set in the environment` for each instance. wgpu chooses the adapter itself, so the
/// layer's ordering is not needed there. Sets the layer's own switch `NODEVICE_SELECT=1` unless
/// the session has a runtime folder or the user set the switch already.
///
/// # Safety
///
/// Call it at the start of `main`, before any other thread starts: it sets an environment
/// variable, which [`std::env::set_var`] allows only while no other thread reads the
/// environment. A library cannot promise that, so nothing in this crate calls it.
#[allow(unsafe_code)]
pub unsafe fn quiet_device_select() {
    let headless = std::env::var_os("XDG_RUNTIME_DIR").is_none();
    if headless && std::env::var_os("NODEVICE_SELECT").is_none() {
        // SAFETY: the caller promises no other thread runs yet.
        unsafe { std::env::set_var("NODEVICE_SELECT", "1") };
    }
}

/// What split arrays need of a device to bind their parts as one binding array
/// ([`crate::split::PartBindings::Array`]).
const BINDING_ARRAYS: wgpu::Features = wgpu::Features::BUFFER_BINDING_ARRAY
    .union(wgpu::Features::STORAGE_RESOURCE_BINDING_ARRAY)
    .union(wgpu::Features::SAMPLED_TEXTURE_AND_STORAGE_BUFFER_ARRAY_NON_UNIFORM_INDEXING);

/// Storage buffers the ray-tracing kernel binds in its one stage.
const MIN_STORAGE_BUFFERS_PER_STAGE: u32 = 15;

/// A wgpu device and what the kernels need to know of it: headless ([`GpuContext::new`]) or
/// a window's ([`GpuContext::from_device`]).
pub struct GpuContext {
    /// The device.
    pub device: wgpu::Device,
    /// Its queue.
    pub queue: wgpu::Queue,
    /// What the adapter is.
    pub info: wgpu::AdapterInfo,
    /// Largest storage buffer binding accepted for a scene (the adapter's limit, or less).
    pub max_binding: u64,
    /// Whether timestamp queries are available.
    pub timestamps: bool,
    /// Alignment of dynamic storage offsets.
    pub(crate) storage_alignment: u64,
    /// Storage buffers a shader stage binds (what the ray tracer's split arrays may use beside
    /// its own bindings, `crate::split`).
    pub(crate) storage_buffers: u32,
    /// Device memory left to check scenes against, set by [`GpuContext::with_memory_available`].
    memory_available: Option<u64>,
    /// Storage buffers a shader stage binds in binding arrays: the device's limit where it has
    /// arrays of storage buffers in one binding, indexed non-uniformly (wgpu's
    /// `BUFFER_BINDING_ARRAY`, `STORAGE_RESOURCE_BINDING_ARRAY` and
    /// `SAMPLED_TEXTURE_AND_STORAGE_BUFFER_ARRAY_NON_UNIFORM_INDEXING`), the split arrays' way past
    /// `storage_buffers` ([`crate::split::PartBindings::Array`]); 0 where it has not.
    pub(crate) binding_array_elements: u32,
    /// The binding limit the 4-byte index arrays of the splatting path are split by (the depth
    /// sort's keys and values, the tile pairs, the offsets): `max_binding` but for
    /// [`GpuContext::with_index_binding_limit`].
    pub(crate) max_index_binding: u64,
    /// The sample counts the rasterizer's targets (RGBA32F, the blend format and Depth32F)
    /// multisample at on this adapter: 1, and those of 2, 4, 8 and 16 that every format has.
    pub msaa_counts: Vec<u32>,
    /// Whether the device shades per sample (wgpu's `MULTISAMPLED_SHADING`), which the
    /// max-density-plane depth of StochasticSplats needs.
    pub sample_rate_shading: bool,
    /// Most frames one dispatch of the ray tracer renders ([`crate::FRAMES_PER_DISPATCH`] by
    /// default).
    pub frames_per_dispatch: u32,
    /// What the renderers have sent the device ([`GpuContext::counters`]).
    work: WorkCounters,
}

/// Work a context's renderers have sent its device, a machine-independent measure of their
/// overhead (issue 40's counters; `splat bench --backend gpu` prints them a frame): dispatches
/// and draws encoded, command buffers submitted, and host waits for the device (each a
/// synchronisation that idles the device while the host reads back or encodes more).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct GpuCounters {
    /// Compute dispatches and draws.
    pub dispatches: u64,
    /// Queue submissions.
    pub submissions: u64,
    /// Host waits for the device (polls to completion, readbacks).
    pub waits: u64,
}

impl std::ops::Sub for GpuCounters {
    type Output = GpuCounters;
    fn sub(self, earlier: GpuCounters) -> GpuCounters {
        GpuCounters {
            dispatches: self.dispatches - earlier.dispatches,
            submissions: self.submissions - earlier.submissions,
            waits: self.waits - earlier.waits,
        }
    }
}

#[derive(Debug, Default)]
struct WorkCounters {
    dispatches: std::sync::atomic::AtomicU64,
    submissions: std::sync::atomic::AtomicU64,
    waits: std::sync::atomic::AtomicU64,
}

impl GpuContext {
    /// The adapter chosen as wgpu's `from_env` helpers do: backends from `WGPU_BACKEND`, the
    /// first adapter whose name contains `WGPU_ADAPTER_NAME` (case-insensitive) when it is
    /// set, else the default adapter. A typed error, never a panic, when none matches.
    pub fn new() -> Result<Self, GpuError> {
        pollster::block_on(async { Self::from_adapter(Self::adapter().await?).await })
    }

    /// A context on a hardware GPU, or `None` when there is none: the choice of `--backend
    /// auto`. Quick and quiet where no GPU can be: on Linux without a GPU device node
    /// (`/dev/dri/renderD*`, `/dev/nvidia*`) no graphics API is initialised at all, unless
    /// `WGPU_BACKEND` or `WGPU_ADAPTER_NAME` asks for one; elsewhere the adapter is probed and a
    /// CPU adapter (lavapipe, llvmpipe, WARP) is turned down before any device is created.
    pub fn hardware() -> Result<Option<Self>, GpuError> {
        if !hardware_gpu_possible() {
            return Ok(None);
        }
        pollster::block_on(async {
            match Self::adapter().await {
                Ok(adapter) if adapter.get_info().device_type != wgpu::DeviceType::Cpu => {
                    Self::from_adapter(adapter).await.map(Some)
                }
                _ => Ok(None),
            }
        })
    }

    async fn adapter() -> Result<wgpu::Adapter, GpuError> {
        let instance = wgpu::Instance::new(wgpu::InstanceDescriptor::new_without_display_handle_from_env());
        let backends = wgpu::Backends::from_env().unwrap_or(wgpu::Backends::all());
        match std::env::var("WGPU_ADAPTER_NAME") {
            Ok(name) => {
                let wanted = name.to_lowercase();
                let adapters = instance.enumerate_adapters(backends).await;
                adapters.into_iter().find(|a| a.get_info().name.to_lowercase().contains(&wanted)).ok_or_else(|| {
                    GpuError::NoAdapter { detail: format!(" whose name contains '{name}' (WGPU_ADAPTER_NAME)") }
                })
            }
            Err(_) => instance
                .request_adapter(&wgpu::RequestAdapterOptions {
                    power_preference: wgpu::PowerPreference::from_env()
                        .unwrap_or(wgpu::PowerPreference::HighPerformance),
                    ..Default::default()
                })
                .await
                .map_err(|e| GpuError::NoAdapter { detail: format!(" for backends {backends:?} ({e})") }),
        }
    }

    async fn from_adapter(adapter: wgpu::Adapter) -> Result<Self, GpuError> {
        let (device, queue) = adapter
            .request_device(&Self::device_descriptor(&adapter))
            .await
            .map_err(|e| GpuError::Device { adapter: adapter.get_info().name, message: e.to_string() })?;
        Self::from_device(&adapter, device, queue)
    }

    /// What to ask `adapter` for so that every kernel runs: the adapter's own limits (the
    /// kernels bind more storage buffers per stage than wgpu's defaults allow) and, where it has
    /// them, timestamp queries (benchmarks), blendable RGBA32F (sorted splatting) and its own
    /// multisample counts (the MSAA rasterizer). A host that creates the device itself (a window
    /// whose surface shares it) passes this to `request_device`, then calls
    /// [`GpuContext::from_device`].
    pub fn device_descriptor(adapter: &wgpu::Adapter) -> wgpu::DeviceDescriptor<'static> {
        wgpu::DeviceDescriptor {
            label: Some("splat"),
            required_features: adapter.features() & Self::wanted_features(),
            required_limits: adapter.limits(),
            ..Default::default()
        }
    }

    fn wanted_features() -> wgpu::Features {
        wgpu::Features::TIMESTAMP_QUERY
            | wgpu::Features::FLOAT32_BLENDABLE
            | wgpu::Features::TEXTURE_ADAPTER_SPECIFIC_FORMAT_FEATURES
            | BINDING_ARRAYS
    }

    /// A context on a device the caller already has (a window's, shared with its UI renderer),
    /// created from `adapter`. The kernels need more storage buffers per stage than wgpu's
    /// default limits: a device made with other limits than
    /// [`GpuContext::device_descriptor`]'s is refused with [`GpuError::Device`] naming the limit.
    pub fn from_device(adapter: &wgpu::Adapter, device: wgpu::Device, queue: wgpu::Queue) -> Result<Self, GpuError> {
        let info = adapter.get_info();
        let limits = device.limits();
        if limits.max_storage_buffers_per_shader_stage < MIN_STORAGE_BUFFERS_PER_STAGE {
            return Err(GpuError::Device {
                adapter: info.name,
                message: format!(
                    "the device binds {} storage buffers per shader stage and the kernels need {MIN_STORAGE_BUFFERS_PER_STAGE}: create it with GpuContext::device_descriptor",
                    limits.max_storage_buffers_per_shader_stage
                ),
            });
        }
        let features = device.features();
        let sample_rate_shading =
            adapter.get_downlevel_capabilities().flags.contains(wgpu::DownlevelFlags::MULTISAMPLED_SHADING);
        Ok(Self {
            msaa_counts: msaa_counts(adapter, features),
            timestamps: features.contains(wgpu::Features::TIMESTAMP_QUERY),
            max_binding: limits.max_storage_buffer_binding_size.min(limits.max_buffer_size),
            storage_alignment: u64::from(limits.min_storage_buffer_offset_alignment),
            storage_buffers: limits.max_storage_buffers_per_shader_stage,
            binding_array_elements: if features.contains(BINDING_ARRAYS) {
                limits.max_binding_array_elements_per_shader_stage
            } else {
                0
            },
            max_index_binding: limits.max_storage_buffer_binding_size.min(limits.max_buffer_size),
            memory_available: None,
            sample_rate_shading,
            frames_per_dispatch: crate::FRAMES_PER_DISPATCH,
            work: WorkCounters::default(),
            device,
            queue,
            info,
        })
    }

    /// The colour format sorted splatting blends in: RGBA32F where the device blends it, else
    /// RGBA16F.
    pub fn blend_format(&self) -> wgpu::TextureFormat {
        blend_format(self.device.features())
    }

    /// Lower the storage binding limit scenes are checked against and split by (to test the
    /// split and the refusal on any adapter).
    pub fn with_binding_limit(mut self, bytes: u64) -> Self {
        self.max_binding = self.max_binding.min(bytes);
        self.max_index_binding = self.max_index_binding.min(bytes);
        self
    }

    /// Check scenes against `bytes` of device memory left, as if the device had only that
    /// (to test the refusal on any adapter).
    pub fn with_memory_available(mut self, bytes: u64) -> Self {
        self.memory_available = Some(bytes);
        self
    }

    /// The device memory the context can still fill, where it can tell: a CPU adapter's
    /// (lavapipe's, WARP's) is the host's ([`splat_core::host::available`]); wgpu reports no
    /// hardware device's, which refuses an allocation past its memory itself
    /// ([`GpuError::DeviceMemory`]). Scenes are checked against it before their arrays are built.
    pub fn memory_available(&self) -> Option<u64> {
        self.memory_available
            .or_else(|| (self.info.device_type == wgpu::DeviceType::Cpu).then(splat_core::host::available).flatten())
    }

    /// Refuse arrays (`what`) of `bytes` that the device's memory left cannot hold
    /// ([`GpuContext::memory_available`]), before they are built.
    pub(crate) fn check_memory(&self, what: &'static str, bytes: u64) -> Result<(), GpuError> {
        match self.memory_available() {
            Some(available) if bytes > available => Err(GpuError::MemoryShort { arrays: what, bytes, available }),
            _ => Ok(()),
        }
    }

    /// Lower the storage buffers a stage binds in binding arrays (to test the refusal past them
    /// on any adapter); 0 binds split arrays' parts one binding each, as on an adapter without
    /// binding arrays (to test that path on any adapter).
    pub fn with_binding_array_elements(mut self, elements: u32) -> Self {
        self.binding_array_elements = self.binding_array_elements.min(elements);
        self
    }

    /// How the kernels bind the parts of split arrays on this device.
    pub(crate) fn part_bindings(&self) -> crate::split::PartBindings {
        if self.binding_array_elements > 0 {
            crate::split::PartBindings::Array
        } else {
            crate::split::PartBindings::Each
        }
    }

    /// Storage buffers a shader stage binds in binding arrays (0 where the device has none):
    /// with [`GpuContext::max_binding`], the bound on scenes where the adapter has them.
    pub fn binding_array_elements_per_stage(&self) -> u32 {
        self.binding_array_elements
    }

    /// Lower the binding limit of the splatting path's 4-byte index arrays only (sort keys and
    /// values, tile pairs, offsets): they hold a sixteenth of a projected splat's bytes, so a
    /// scene small enough for the adapter's binding count splits them only below the others'.
    pub fn with_index_binding_limit(mut self, bytes: u64) -> Self {
        self.max_index_binding = self.max_index_binding.min(bytes);
        self
    }

    /// Invocations a CPU adapter runs in lockstep (its largest subgroup size, at most 128).
    pub fn lanes(&self) -> u32 {
        self.info.subgroup_max_size.clamp(1, 128)
    }

    /// The work its renderers have sent the device so far ([`GpuCounters`]); the difference of
    /// two readings is what ran between them.
    pub fn counters(&self) -> GpuCounters {
        use std::sync::atomic::Ordering::Relaxed;
        GpuCounters {
            dispatches: self.work.dispatches.load(Relaxed),
            submissions: self.work.submissions.load(Relaxed),
            waits: self.work.waits.load(Relaxed),
        }
    }

    /// `pass.dispatch_workgroups(x, y, z)`, counted.
    pub(crate) fn dispatch(&self, pass: &mut wgpu::ComputePass<'_>, x: u32, y: u32, z: u32) {
        self.count_draw();
        pass.dispatch_workgroups(x, y, z);
    }

    /// Dispatch the workgroups the three u32 of `args` at byte `offset` give, counted.
    pub(crate) fn dispatch_indirect(&self, pass: &mut wgpu::ComputePass<'_>, args: &wgpu::Buffer, offset: u64) {
        self.count_draw();
        pass.dispatch_workgroups_indirect(args, offset);
    }

    /// Count a draw (or a dispatch).
    pub(crate) fn count_draw(&self) {
        self.work.dispatches.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    }

    /// Submit `commands`, counted.
    pub(crate) fn submit(&self, commands: wgpu::CommandBuffer) {
        self.work.submissions.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        self.queue.submit([commands]);
    }

    /// Wait for the device to finish what was submitted, counted.
    pub(crate) fn wait(&self) -> Result<(), GpuError> {
        self.work.waits.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        self.device.poll(wgpu::PollType::wait_indefinitely()).map_err(|e| GpuError::Readback(e.to_string()))?;
        Ok(())
    }

    /// Storage buffers a shader stage binds: with [`GpuContext::max_binding`], what bounds the
    /// scenes the kernels take (`TraceSplit::capacity`, `RasterSplit::capacity`).
    pub fn storage_buffers_per_stage(&self) -> u32 {
        self.storage_buffers
    }

    /// One line naming the adapter.
    pub fn describe(&self) -> String {
        format!("{} ({:?}, {})", self.info.name, self.info.backend, self.info.driver)
    }

    pub(crate) fn read_buffer(&self, buffer: &wgpu::Buffer) -> Result<Vec<f32>, GpuError> {
        let slice = buffer.slice(..);
        let (tx, rx) = std::sync::mpsc::channel();
        slice.map_async(wgpu::MapMode::Read, move |r| {
            let _ = tx.send(r);
        });
        self.wait()?;
        rx.recv().map_err(|e| GpuError::Readback(e.to_string()))?.map_err(|e| GpuError::Readback(e.to_string()))?;
        let data = {
            let view = slice.get_mapped_range().map_err(|e| GpuError::Readback(e.to_string()))?;
            bytemuck::cast_slice::<u8, f32>(&view).to_vec()
        };
        buffer.unmap();
        Ok(data)
    }

    /// Refuse a storage buffer of `bytes` above the binding limit, naming the buffer and the
    /// `count` of items (particles, keys) that needed it.
    pub(crate) fn check_binding(&self, buffer: &'static str, bytes: u64, count: usize) -> Result<(), GpuError> {
        if bytes > self.max_binding {
            return Err(GpuError::SceneTooLarge { buffer, bytes, limit: self.max_binding, count });
        }
        Ok(())
    }

    /// An uninitialised buffer of `bytes` bytes.
    pub(crate) fn buffer(&self, label: &str, bytes: u64, usage: wgpu::BufferUsages) -> wgpu::Buffer {
        self.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some(label),
            size: bytes,
            usage,
            mapped_at_creation: false,
        })
    }

    /// Bytes between consecutive [`crate::Params`] in their buffer, read at dynamic offsets
    /// ([`params_entry`]).
    pub(crate) fn params_stride(&self) -> u64 {
        (std::mem::size_of::<crate::Params>() as u64).next_multiple_of(self.storage_alignment)
    }

    /// A read-only storage buffer holding `contents`.
    pub(crate) fn upload(&self, label: &str, contents: &[u8]) -> wgpu::Buffer {
        let usage = wgpu::BufferUsages::STORAGE;
        self.device.create_buffer_init(&wgpu::util::BufferInitDescriptor { label: Some(label), contents, usage })
    }

    /// Copy `words` u32 of `source` from word `first` into a staging buffer and read them.
    pub(crate) fn read_u32_at(&self, source: &wgpu::Buffer, first: usize, words: usize) -> Result<Vec<u32>, GpuError> {
        let bytes = (4 * words.max(1)) as u64;
        let staging = self.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("readback"),
            size: bytes,
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let mut data: Vec<u32> =
            self.read_through(source, 4 * first as u64, &staging, bytes)?.iter().map(|f| f.to_bits()).collect();
        data.truncate(words);
        Ok(data)
    }

    /// Copy `bytes` of `source` from byte `offset` into the mappable `staging` and read them.
    pub(crate) fn read_through(
        &self,
        source: &wgpu::Buffer,
        offset: u64,
        staging: &wgpu::Buffer,
        bytes: u64,
    ) -> Result<Vec<f32>, GpuError> {
        let mut encoder =
            self.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("readback") });
        encoder.copy_buffer_to_buffer(source, offset, staging, 0, bytes);
        self.submit(encoder.finish());
        self.read_buffer(staging)
    }

    /// The first `words` u32 of `source`.
    pub(crate) fn read_u32(&self, source: &wgpu::Buffer, words: usize) -> Result<Vec<u32>, GpuError> {
        self.read_u32_at(source, 0, words)
    }

    /// The first `words` f32 of `source`.
    pub(crate) fn read_f32(&self, source: &wgpu::Buffer, words: usize) -> Result<Vec<f32>, GpuError> {
        Ok(self.read_u32(source, words)?.into_iter().map(f32::from_bits).collect())
    }
}

/// An image of `channels` channels whose pixel p, channel c is `value(4p + c)`: the first
/// channels of a per-pixel RGBA buffer read back from the GPU.
pub(crate) fn rgba_image(camera: &Camera, channels: u32, value: &dyn Fn(usize) -> f32) -> Image {
    let pixels = camera.width as usize * camera.height as usize;
    let data = (0..pixels).flat_map(|p| (0..channels as usize).map(move |c| value(4 * p + c))).collect();
    Image::from_data(camera.width, camera.height, channels, data).expect("the buffer holds every pixel")
}

/// A storage-buffer entry of a bind group layout.
pub(crate) fn storage_entry(
    binding: u32,
    visibility: wgpu::ShaderStages,
    read_only: bool,
) -> wgpu::BindGroupLayoutEntry {
    wgpu::BindGroupLayoutEntry {
        binding,
        visibility,
        ty: wgpu::BindingType::Buffer {
            ty: wgpu::BufferBindingType::Storage { read_only },
            has_dynamic_offset: false,
            min_binding_size: None,
        },
        count: None,
    }
}

/// The entry of a shader's parameters (at least `size` bytes, at a dynamic offset when
/// `dynamic`): a read-only storage buffer. No shader of this crate reads a uniform buffer
/// (`layout::tests::check_layout` refuses one): lavapipe (Mesa 22.3, CI's driver) inlines the
/// values of uniforms that steer branches into the shader, compiles it again for each new set
/// of values (16–25 s for the ray-tracing megakernel, here for each scene), and re-derives the
/// inlined shader at every dispatch that binds the uniform (about 0.1 s of the megakernel's);
/// it never inlines storage buffers. Measured with an empty Mesa shader cache,
/// `one_frame_equals_the_cpu_frame` (two fixtures, six methods): 35 s with a uniform buffer
/// (two compiles, 100–180 ms a render), 19 s with this one (one compile, 3–53 ms a render).
pub(crate) fn params_entry(
    binding: u32,
    visibility: wgpu::ShaderStages,
    dynamic: bool,
    size: usize,
) -> wgpu::BindGroupLayoutEntry {
    wgpu::BindGroupLayoutEntry {
        binding,
        visibility,
        ty: wgpu::BindingType::Buffer {
            ty: wgpu::BufferBindingType::Storage { read_only: true },
            has_dynamic_offset: dynamic,
            min_binding_size: wgpu::BufferSize::new(size as u64),
        },
        count: None,
    }
}

/// What `build` makes of shaders and pipelines, or the device's first validation error while it
/// ran (a kernel the adapter rejects) as a typed error instead of wgpu's uncaptured-error panic.
pub(crate) fn validated<T>(device: &wgpu::Device, build: impl FnOnce() -> T) -> Result<T, GpuError> {
    let scope = device.push_error_scope(wgpu::ErrorFilter::Validation);
    let built = build();
    match pollster::block_on(scope.pop()) {
        Some(e) => Err(GpuError::Shader(e.to_string())),
        None => Ok(built),
    }
}

/// A shader module of WGSL `source`.
pub(crate) fn shader_module(device: &wgpu::Device, label: &str, source: &str) -> wgpu::ShaderModule {
    device.create_shader_module(wgpu::ShaderModuleDescriptor {
        label: Some(label),
        source: wgpu::ShaderSource::Wgsl(source.into()),
    })
}

/// A pipeline layout of the bind groups `layouts`, group g the g-th.
pub(crate) fn pipeline_layout(
    device: &wgpu::Device,
    label: &str,
    layouts: &[&wgpu::BindGroupLayout],
) -> wgpu::PipelineLayout {
    let layouts: Vec<_> = layouts.iter().copied().map(Some).collect();
    device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
        label: Some(label),
        bind_group_layouts: &layouts,
        immediate_size: 0,
    })
}

/// The bind group layout of `entries` and the pipeline layout of it alone.
pub(crate) fn layouts(
    device: &wgpu::Device,
    label: &str,
    entries: &[wgpu::BindGroupLayoutEntry],
) -> (wgpu::BindGroupLayout, wgpu::PipelineLayout) {
    let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor { label: Some(label), entries });
    let pipeline = pipeline_layout(device, label, &[&layout]);
    (layout, pipeline)
}

/// A compute pipeline of `entry` (also its label); `layout: None` derives it from the shader.
pub(crate) fn compute_pipeline(
    device: &wgpu::Device,
    module: &wgpu::ShaderModule,
    layout: Option<&wgpu::PipelineLayout>,
    entry: &str,
) -> wgpu::ComputePipeline {
    device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
        label: Some(entry),
        layout,
        module,
        entry_point: Some(entry),
        compilation_options: Default::default(),
        cache: None,
    })
}

/// The colour format sorted splatting blends in with `features`.
fn blend_format(features: wgpu::Features) -> wgpu::TextureFormat {
    if features.contains(wgpu::Features::FLOAT32_BLENDABLE) {
        wgpu::TextureFormat::Rgba32Float
    } else {
        wgpu::TextureFormat::Rgba16Float
    }
}

/// The sample counts every raster target format multisamples at (1 only without the adapter's
/// format features: WebGPU's own guarantee does not cover RGBA32F).
fn msaa_counts(adapter: &wgpu::Adapter, features: wgpu::Features) -> Vec<u32> {
    let formats = [wgpu::TextureFormat::Rgba32Float, blend_format(features), wgpu::TextureFormat::Depth32Float];
    let adapter_specific = features.contains(wgpu::Features::TEXTURE_ADAPTER_SPECIFIC_FORMAT_FEATURES);
    [1, 2, 4, 8, 16]
        .into_iter()
        .filter(|&count| {
            count == 1
                || adapter_specific
                    && formats
                        .iter()
                        .all(|&f| adapter.get_texture_format_features(f).flags.sample_count_supported(count))
        })
        .collect()
}

/// Whether a hardware GPU may be present: false only on Linux with no GPU device node and no
/// `WGPU_BACKEND` / `WGPU_ADAPTER_NAME` in the environment.
fn hardware_gpu_possible() -> bool {
    if !cfg!(target_os = "linux") || std::env::var_os("WGPU_BACKEND").is_some() {
        return true;
    }
    if std::env::var_os("WGPU_ADAPTER_NAME").is_some() {
        return true;
    }
    let has = |dir: &str, prefix: &str| {
        std::fs::read_dir(dir)
            .is_ok_and(|entries| entries.flatten().any(|e| e.file_name().to_string_lossy().starts_with(prefix)))
    };
    has("/dev/dri", "renderD") || has("/dev", "nvidia")
}
