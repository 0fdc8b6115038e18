// The depth, unit normal and picked particle of a sample (frame.rs `Sample`), written for frame
// 0 only (picks are never averaged); mirrored by splat_gpu::GpuPick. depth < 0: none; picked
// NONE: none; normal zero where nothing was hit. Written by trace.wgsl, read by display.wgsl.
struct Pick {
    normal: vec3<f32>,
    depth: f32,
    picked: u32,
    pad0: u32,
    pad1: u32,
    pad2: u32,
}
