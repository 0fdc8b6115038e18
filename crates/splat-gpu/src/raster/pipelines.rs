//! The compiled kernels and render pipelines of the splatting path.

use super::*;
use crate::context::{pipeline_layout, shader_module};

/// The compiled kernels and pipelines of the splatting path: those that read the projected
/// splats and canonical transforms for each [`RasterSplit`] a scene needs (one,
/// [`RasterSplit::WHOLE`], compiled at once, for every scene whose arrays fit one binding each;
/// another on the first rasterizer of its split), the others once.
pub struct RasterPipelines {
    pub(super) sort: RadixSort,
    pub(super) mesh_prepass: wgpu::ComputePipeline,
    pub(super) fold_layout: wgpu::BindGroupLayout,
    pub(super) fold: wgpu::ComputePipeline,
    pub(super) fold_msaa_layout: wgpu::BindGroupLayout,
    pub(super) fold_msaa: wgpu::ComputePipeline,
    /// Colour target of sorted blending: RGBA32F where the adapter blends it, else RGBA16F.
    pub blend_format: wgpu::TextureFormat,
    kernels: crate::split::PerSplit<RasterSplit, SplatKernels>,
}

/// The kernels and the splat draw compiled for one [`RasterSplit`].
pub(crate) struct SplatKernels {
    pub(super) split: RasterSplit,
    pub(super) project: wgpu::ComputePipeline,
    pub(super) tile_count: wgpu::ComputePipeline,
    pub(super) tile_emit: wgpu::ComputePipeline,
    pub(super) tile_ranges: wgpu::ComputePipeline,
    pub(super) tile_blend: wgpu::ComputePipeline,
    pub(super) shuffle_keys: wgpu::ComputePipeline,
    /// The per-pixel raster operations of Enderton and Laine–Karras (centre, plane depth).
    pub(super) tile_rop: [wgpu::ComputePipeline; 2],
    /// Their written sample as the hybrid's first hit.
    pub(super) rop_first_hit: wgpu::ComputePipeline,
    pub(super) splat_module: wgpu::ShaderModule,
    /// The same with the max-density-plane entry point, where the device shades per sample.
    pub(super) plane_module: Option<wgpu::ShaderModule>,
    pub(super) splat_layout: wgpu::BindGroupLayout,
    /// The layout of the splat draw's binding arrays' group, where the split has any.
    pub(super) splat_arrays_layout: Option<wgpu::BindGroupLayout>,
    pub(super) splat_pipeline_layout: wgpu::PipelineLayout,
    /// The one-sample pipelines.
    pub(super) single: SamplePipelines,
    blend_format: wgpu::TextureFormat,
}

/// The render pipelines of one sample count: sorted over and under, StochasticSplats (unlit,
/// lit) and StochasticSplats at the max-density plane.
pub(crate) struct SamplePipelines {
    pub(super) over: wgpu::RenderPipeline,
    pub(super) under: wgpu::RenderPipeline,
    pub(super) stochastic: wgpu::RenderPipeline,
    pub(super) stochastic_lit: Option<wgpu::RenderPipeline>,
    pub(super) stochastic_plane: Option<wgpu::RenderPipeline>,
    /// Lit StochasticSplats shaded per sample, at centre and plane depth, where the device
    /// shades per sample (at one sample only the plane's: `stochastic_lit` takes the centre).
    pub(super) stochastic_lit_sample: [Option<wgpu::RenderPipeline>; 2],
}

/// Colour target of a stochastic frame (written, never blended).
pub(super) const STOCHASTIC_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba32Float;
pub(super) const DEPTH_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Depth32Float;

/// The bindings of the splat draw's vertex and fragment stages for `split` (checked against
/// `splat.wgsl`'s by a test).
pub(super) fn splat_layout_entries(split: &RasterSplit) -> Vec<wgpu::BindGroupLayoutEntry> {
    let draw_stages = wgpu::ShaderStages::VERTEX_FRAGMENT;
    let mut entries = vec![
        params_entry(0, draw_stages, false, size_of::<RasterParams>()),
        params_entry(1, draw_stages, true, size_of::<FrameParams>()),
        storage_entry(2, draw_stages, true),
        storage_entry(3, wgpu::ShaderStages::VERTEX, true),
        storage_entry(4, wgpu::ShaderStages::VERTEX, true),
        storage_entry(5, wgpu::ShaderStages::FRAGMENT, true),
        storage_entry(6, wgpu::ShaderStages::FRAGMENT, true),
        storage_entry(13, wgpu::ShaderStages::FRAGMENT, true),
        storage_entry(14, wgpu::ShaderStages::FRAGMENT, true),
        storage_entry(15, wgpu::ShaderStages::FRAGMENT, true),
    ];
    entries.extend(split.draw_extra_entries(0));
    entries
}

/// The splat draw's bindings in its binding arrays' group for `split` (none, no such group).
pub(super) fn splat_array_entries(split: &RasterSplit) -> Vec<wgpu::BindGroupLayoutEntry> {
    split.draw_extra_entries(crate::split::ARRAY_GROUP)
}

/// The bindings of the fold of the raster targets into the accumulation, from a `multisampled`
/// colour target or not (checked against `fold.wgsl`'s by a test).
pub(super) fn fold_layout_entries(multisampled: bool) -> [wgpu::BindGroupLayoutEntry; 6] {
    [
        params_entry(0, wgpu::ShaderStages::COMPUTE, false, size_of::<RasterParams>()),
        params_entry(1, wgpu::ShaderStages::COMPUTE, true, size_of::<FrameParams>()),
        wgpu::BindGroupLayoutEntry {
            binding: 2,
            visibility: wgpu::ShaderStages::COMPUTE,
            ty: wgpu::BindingType::Texture {
                sample_type: wgpu::TextureSampleType::Float { filterable: false },
                view_dimension: wgpu::TextureViewDimension::D2,
                multisampled,
            },
            count: None,
        },
        storage_entry(3, wgpu::ShaderStages::COMPUTE, false),
        storage_entry(4, wgpu::ShaderStages::COMPUTE, false),
        storage_entry(5, wgpu::ShaderStages::COMPUTE, true),
    ]
}

impl RasterPipelines {
    /// Compile every raster kernel (those of [`RasterSplit::WHOLE`] among them); a typed error
    /// when the device rejects one.
    pub fn new(ctx: &GpuContext) -> Result<Self, GpuError> {
        let device = &ctx.device;
        let sort = RadixSort::new(ctx)?;
        let pipes = crate::context::validated(device, || {
            let fold = shader_module(device, "fold.wgsl", FOLD_WGSL);
            let fold_msaa = shader_module(device, "fold.wgsl (msaa)", FOLD_MSAA_WGSL);
            let mesh_prepass = shader_module(device, "mesh_prepass.wgsl", MESH_PREPASS_WGSL);
            let fold_layout_of = |multisampled| {
                device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
                    label: Some("fold"),
                    entries: &fold_layout_entries(multisampled),
                })
            };
            let (fold_layout, fold_msaa_layout) = (fold_layout_of(false), fold_layout_of(true));
            Self {
                mesh_prepass: compute_pipeline(device, &mesh_prepass, None, "mesh_prepass"),
                fold: compute_pipeline(device, &fold, Some(&pipeline_layout(device, "fold", &[&fold_layout])), "fold"),
                fold_msaa: compute_pipeline(
                    device,
                    &fold_msaa,
                    Some(&pipeline_layout(device, "fold (msaa)", &[&fold_msaa_layout])),
                    "fold",
                ),
                fold_layout,
                fold_msaa_layout,
                blend_format: ctx.blend_format(),
                sort,
                kernels: crate::split::PerSplit::new(),
            }
        })?;
        pipes.kernels(ctx, RasterSplit::WHOLE)?;
        Ok(pipes)
    }

    /// The radix sort.
    pub fn sort(&self) -> &RadixSort {
        &self.sort
    }

    /// The kernels of `split`, compiled on first use.
    pub(super) fn kernels(
        &self,
        ctx: &GpuContext,
        split: RasterSplit,
    ) -> Result<std::sync::Arc<SplatKernels>, GpuError> {
        self.kernels.get(split, || SplatKernels::new(ctx, split, self.blend_format))
    }
}

impl SplatKernels {
    /// Compile the kernels and the splat draw that read the arrays as `split` cuts them.
    fn new(ctx: &GpuContext, split: RasterSplit, blend_format: wgpu::TextureFormat) -> Result<Self, GpuError> {
        let device = &ctx.device;
        // The kernels' layouts as wgpu would derive them, with the counts of binding arrays.
        let source = split.raster_wgsl();
        let layouts = crate::reflect::compute_layouts(&source).map_err(GpuError::Shader)?;
        crate::context::validated(device, || {
            let layout = |entry: &str| {
                let (_, groups) =
                    layouts.iter().find(|(name, _)| name == entry).expect("an entry point of raster.wgsl");
                crate::reflect::pipeline_layout(device, entry, groups)
            };
            let raster = shader_module(device, "raster.wgsl", &source);
            let kernel = |entry| compute_pipeline(device, &raster, Some(&layout(entry)), entry);
            let splat_module = shader_module(device, "splat.wgsl", &split.splat_wgsl(false));
            let plane_module =
                ctx.sample_rate_shading.then(|| shader_module(device, "splat.wgsl (plane)", &split.splat_wgsl(true)));
            let (entries, arrays) = (splat_layout_entries(&split), splat_array_entries(&split));
            let (splat_layout, splat_arrays_layout, splat_pipeline_layout) =
                crate::split::layouts(device, "splat", &entries, &arrays);
            let rop = |plane: f64| {
                device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                    label: Some("tile_rop"),
                    layout: Some(&layout("tile_rop")),
                    module: &raster,
                    entry_point: Some("tile_rop"),
                    compilation_options: wgpu::PipelineCompilationOptions {
                        constants: &[("PLANE_DEPTH", plane)],
                        ..Default::default()
                    },
                    cache: None,
                })
            };
            let modules = (&splat_module, plane_module.as_ref());
            let single = SamplePipelines::new(device, modules, &splat_pipeline_layout, blend_format, 1);
            Self {
                split,
                project: kernel("project"),
                tile_count: kernel("tile_count"),
                tile_emit: kernel("tile_emit"),
                tile_ranges: kernel("tile_ranges"),
                tile_blend: kernel("tile_blend"),
                shuffle_keys: kernel("shuffle_keys"),
                tile_rop: [rop(0.0), rop(1.0)],
                rop_first_hit: kernel("rop_first_hit"),
                single,
                splat_module,
                plane_module,
                splat_layout,
                splat_arrays_layout,
                splat_pipeline_layout,
                blend_format,
            }
        })
    }

    /// The render pipelines at `samples` per pixel (the one-sample set is [`SplatKernels::single`]).
    pub(super) fn at_samples(&self, ctx: &GpuContext, samples: u32) -> Result<SamplePipelines, GpuError> {
        let modules = (&self.splat_module, self.plane_module.as_ref());
        crate::context::validated(&ctx.device, || {
            SamplePipelines::new(&ctx.device, modules, &self.splat_pipeline_layout, self.blend_format, samples)
        })
    }
}

impl SamplePipelines {
    fn new(
        device: &wgpu::Device,
        (splat, plane): (&wgpu::ShaderModule, Option<&wgpu::ShaderModule>),
        layout: &wgpu::PipelineLayout,
        blend_format: wgpu::TextureFormat,
        samples: u32,
    ) -> Self {
        let render_with = |module, entry, format, blend: Option<wgpu::BlendState>, depth: bool, constants: &[_]| {
            device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
                label: Some(entry),
                layout: Some(layout),
                vertex: wgpu::VertexState {
                    module,
                    entry_point: Some("vs"),
                    compilation_options: Default::default(),
                    buffers: &[],
                },
                primitive: wgpu::PrimitiveState::default(),
                depth_stencil: depth.then(|| wgpu::DepthStencilState {
                    format: DEPTH_FORMAT,
                    depth_write_enabled: Some(true),
                    depth_compare: Some(wgpu::CompareFunction::Less),
                    stencil: Default::default(),
                    bias: Default::default(),
                }),
                multisample: wgpu::MultisampleState { count: samples, ..Default::default() },
                fragment: Some(wgpu::FragmentState {
                    module,
                    entry_point: Some(entry),
                    compilation_options: wgpu::PipelineCompilationOptions { constants, ..Default::default() },
                    targets: &[Some(wgpu::ColorTargetState { format, blend, write_mask: wgpu::ColorWrites::ALL })],
                }),
                multiview_mask: None,
                cache: None,
            })
        };
        let render = |entry, format, blend, depth| render_with(splat, entry, format, blend, depth, &[]);
        let lit_sample = |plane_depth: bool| {
            let constants = [("LIT_PLANE_DEPTH", f64::from(u8::from(plane_depth)))];
            let entry = "fs_stochastic_lit_sample";
            let wanted = samples > 1 || plane_depth;
            plane.filter(|_| wanted).map(|m| render_with(m, entry, STOCHASTIC_FORMAT, None, true, &constants))
        };
        let component =
            |src, dst| wgpu::BlendComponent { src_factor: src, dst_factor: dst, operation: wgpu::BlendOperation::Add };
        use wgpu::BlendFactor::{One, OneMinusDstAlpha, OneMinusSrcAlpha, SrcAlpha};
        // vk_gaussian_splatting Lighting §1.5.1 for the colour. The alpha channel uses the over
        // operator too (ONE, ONE_MINUS_SRC_ALPHA) so that it holds the coverage 1 − T; vk's
        // additive ONE / ONE alpha (a sum of opacities) is read only by its mesh pass.
        let over =
            wgpu::BlendState { color: component(SrcAlpha, OneMinusSrcAlpha), alpha: component(One, OneMinusSrcAlpha) };
        // §1.5.2: premultiplied colour and alpha, ONE_MINUS_DST_ALPHA / ONE.
        let under =
            wgpu::BlendState { color: component(OneMinusDstAlpha, One), alpha: component(OneMinusDstAlpha, One) };
        // One sample: the centre-only entry points; S samples: those writing a sample mask.
        let (sorted, stochastic) =
            if samples == 1 { ("fs_sorted", "fs_stochastic") } else { ("fs_sorted_msaa", "fs_stochastic_msaa") };
        Self {
            over: render(sorted, blend_format, Some(over), false),
            under: render(sorted, blend_format, Some(under), false),
            stochastic: render(stochastic, STOCHASTIC_FORMAT, None, true),
            stochastic_lit: (samples == 1).then(|| render("fs_stochastic_lit", STOCHASTIC_FORMAT, None, true)),
            stochastic_plane: plane.map(|m| render_with(m, "fs_stochastic_plane", STOCHASTIC_FORMAT, None, true, &[])),
            stochastic_lit_sample: [lit_sample(false), lit_sample(true)],
        }
    }

    /// The pipeline that draws `draw` (lit: StochasticSplats' shaded variant, per sample where
    /// the samples' colours differ; plane: the max-density-plane depth).
    pub(super) fn get(&self, draw: Draw, lit: bool, plane: bool) -> Result<&wgpu::RenderPipeline, GpuError> {
        fn per_sample<'p>(
            pipeline: Option<&'p wgpu::RenderPipeline>,
            what: &str,
        ) -> Result<&'p wgpu::RenderPipeline, GpuError> {
            pipeline.ok_or_else(|| {
                GpuError::refused(
                    format!("{what} shades per sample, which this adapter cannot (wgpu's MULTISAMPLED_SHADING)"),
                    &[Remedy::Cpu],
                )
            })
        }
        Ok(match draw {
            Draw::Over => &self.over,
            Draw::Under => &self.under,
            Draw::Stochastic if lit => match &self.stochastic_lit {
                Some(centre) if !plane => centre,
                _ => per_sample(self.stochastic_lit_sample[usize::from(plane)].as_ref(), "lit StochasticSplats")?,
            },
            Draw::Stochastic if plane => per_sample(self.stochastic_plane.as_ref(), "the max-density-plane depth")?,
            Draw::Stochastic => &self.stochastic,
            Draw::Enderton | Draw::Stratified | Draw::StratifiedPlain => {
                return Err(GpuError::Unsupported(format!("{draw:?} runs in the compute ROP, not a render pipeline")));
            }
        })
    }
}
