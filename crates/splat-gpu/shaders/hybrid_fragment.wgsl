// One rasterized fragment of a hybrid sample in the volumetric look (48 bytes), mirrored by
// splat_gpu::GpuFragment: the splat's colour and its weight Tᵢ αᵢ in Eq. 3, its normal along
// sample 0's ray, its distance along the sample's ray and its id. The tile pass lists them
// (depth_pick.wgsl, FIRST_HIT_FRAGMENTS); the trace kernel lights each with its shadow rays
// (trace.wgsl `finish`), as raster/mod.rs `sorted` lights each fragment through `lit_color`.
struct Fragment {
    color: vec3<f32>,
    weight: f32,
    normal: vec3<f32>,
    t: f32,
    id: u32,
    pad0: u32,
    pad1: u32,
    pad2: u32,
}
