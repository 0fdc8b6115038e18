//! The compiled kernels and render pipelines of the splatting path.

use super::*;

/// The compiled kernels and pipelines of the splatting path.
pub struct RasterPipelines {
    pub(super) sort: RadixSort,
    pub(super) project: wgpu::ComputePipeline,
    pub(super) tile_count: wgpu::ComputePipeline,
    pub(super) tile_emit: wgpu::ComputePipeline,
    pub(super) tile_ranges: wgpu::ComputePipeline,
    pub(super) tile_blend: wgpu::ComputePipeline,
    pub(super) mesh_prepass: wgpu::ComputePipeline,
    pub(super) splat_layout: wgpu::BindGroupLayout,
    pub(super) over: wgpu::RenderPipeline,
    pub(super) under: wgpu::RenderPipeline,
    pub(super) stochastic: wgpu::RenderPipeline,
    pub(super) stochastic_lit: wgpu::RenderPipeline,
    pub(super) fold_layout: wgpu::BindGroupLayout,
    pub(super) fold: wgpu::ComputePipeline,
    /// Colour target of sorted blending: RGBA32F where the adapter blends it, else RGBA16F.
    pub blend_format: wgpu::TextureFormat,
}

/// Colour target of a stochastic frame (written, never blended).
pub(super) const STOCHASTIC_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba32Float;
pub(super) const DEPTH_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Depth32Float;

impl RasterPipelines {
    /// Compile every raster kernel; a typed error when the device rejects one.
    pub fn new(ctx: &GpuContext) -> Result<Self, GpuError> {
        let device = &ctx.device;
        let sort = RadixSort::new(ctx)?;
        let scope = device.push_error_scope(wgpu::ErrorFilter::Validation);
        let module = |label, source: &str| {
            device.create_shader_module(wgpu::ShaderModuleDescriptor {
                label: Some(label),
                source: wgpu::ShaderSource::Wgsl(source.into()),
            })
        };
        let raster = module("raster.wgsl", RASTER_WGSL);
        let splat = module("splat.wgsl", SPLAT_WGSL);
        let fold = module("fold.wgsl", FOLD_WGSL);
        let mesh_prepass = module("mesh_prepass.wgsl", MESH_PREPASS_WGSL);
        let draw_stages = wgpu::ShaderStages::VERTEX_FRAGMENT;
        let splat_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("splat"),
            entries: &[
                uniform_entry(0, draw_stages, false, size_of::<RasterParams>()),
                uniform_entry(1, draw_stages, true, size_of::<FrameParams>()),
                storage_entry(2, draw_stages, true),
                storage_entry(3, wgpu::ShaderStages::VERTEX, true),
                storage_entry(4, wgpu::ShaderStages::VERTEX, true),
                storage_entry(5, wgpu::ShaderStages::FRAGMENT, true),
                storage_entry(13, wgpu::ShaderStages::FRAGMENT, true),
                storage_entry(14, wgpu::ShaderStages::FRAGMENT, true),
                storage_entry(15, wgpu::ShaderStages::FRAGMENT, true),
            ],
        });
        let fold_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("fold"),
            entries: &[
                uniform_entry(0, wgpu::ShaderStages::COMPUTE, false, size_of::<RasterParams>()),
                uniform_entry(1, wgpu::ShaderStages::COMPUTE, true, size_of::<FrameParams>()),
                wgpu::BindGroupLayoutEntry {
                    binding: 2,
                    visibility: wgpu::ShaderStages::COMPUTE,
                    ty: wgpu::BindingType::Texture {
                        sample_type: wgpu::TextureSampleType::Float { filterable: false },
                        view_dimension: wgpu::TextureViewDimension::D2,
                        multisampled: false,
                    },
                    count: None,
                },
                storage_entry(3, wgpu::ShaderStages::COMPUTE, false),
                storage_entry(4, wgpu::ShaderStages::COMPUTE, false),
                storage_entry(5, wgpu::ShaderStages::COMPUTE, true),
            ],
        });
        let pipeline_layout = |label, layout: &wgpu::BindGroupLayout| {
            device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
                label: Some(label),
                bind_group_layouts: &[Some(layout)],
                immediate_size: 0,
            })
        };
        let splat_pipeline_layout = pipeline_layout("splat", &splat_layout);
        let blend_format = if device.features().contains(wgpu::Features::FLOAT32_BLENDABLE) {
            wgpu::TextureFormat::Rgba32Float
        } else {
            wgpu::TextureFormat::Rgba16Float
        };
        let render = |entry, format, blend: Option<wgpu::BlendState>, depth: bool| {
            device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
                label: Some(entry),
                layout: Some(&splat_pipeline_layout),
                vertex: wgpu::VertexState {
                    module: &splat,
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
                multisample: wgpu::MultisampleState::default(),
                fragment: Some(wgpu::FragmentState {
                    module: &splat,
                    entry_point: Some(entry),
                    compilation_options: Default::default(),
                    targets: &[Some(wgpu::ColorTargetState { format, blend, write_mask: wgpu::ColorWrites::ALL })],
                }),
                multiview_mask: None,
                cache: None,
            })
        };
        let component =
            |src, dst| wgpu::BlendComponent { src_factor: src, dst_factor: dst, operation: wgpu::BlendOperation::Add };
        use wgpu::BlendFactor::{One, OneMinusDstAlpha, OneMinusSrcAlpha, SrcAlpha};
        // Seed 003 §1.5.1 for the colour. The alpha channel uses the over operator too (ONE,
        // ONE_MINUS_SRC_ALPHA) so that it holds the coverage 1 − T; vk's additive ONE / ONE
        // alpha (a sum of opacities) is read only by its mesh pass, which we do not have.
        let over =
            wgpu::BlendState { color: component(SrcAlpha, OneMinusSrcAlpha), alpha: component(One, OneMinusSrcAlpha) };
        // Seed 003 §1.5.2: premultiplied colour and alpha, ONE_MINUS_DST_ALPHA / ONE.
        let under =
            wgpu::BlendState { color: component(OneMinusDstAlpha, One), alpha: component(OneMinusDstAlpha, One) };
        let pipes = Self {
            project: compute_pipeline(device, &raster, None, "project"),
            tile_count: compute_pipeline(device, &raster, None, "tile_count"),
            tile_emit: compute_pipeline(device, &raster, None, "tile_emit"),
            tile_ranges: compute_pipeline(device, &raster, None, "tile_ranges"),
            tile_blend: compute_pipeline(device, &raster, None, "tile_blend"),
            mesh_prepass: compute_pipeline(device, &mesh_prepass, None, "mesh_prepass"),
            over: render("fs_sorted", blend_format, Some(over), false),
            under: render("fs_sorted", blend_format, Some(under), false),
            stochastic: render("fs_stochastic", STOCHASTIC_FORMAT, None, true),
            stochastic_lit: render("fs_stochastic_lit", STOCHASTIC_FORMAT, None, true),
            fold: compute_pipeline(device, &fold, Some(&pipeline_layout("fold", &fold_layout)), "fold"),
            splat_layout,
            fold_layout,
            blend_format,
            sort,
        };
        if let Some(e) = pollster::block_on(scope.pop()) {
            return Err(GpuError::Shader(e.to_string()));
        }
        Ok(pipes)
    }

    /// The radix sort.
    pub fn sort(&self) -> &RadixSort {
        &self.sort
    }

    pub(super) fn render_pipeline(&self, draw: Draw, lit: bool) -> &wgpu::RenderPipeline {
        match draw {
            Draw::Over => &self.over,
            Draw::Under => &self.under,
            Draw::Stochastic if lit => &self.stochastic_lit,
            Draw::Stochastic => &self.stochastic,
        }
    }
}
