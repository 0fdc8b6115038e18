// The frame's colour target of fold.wgsl at S samples per pixel: the mean of its samples, each
// over what lies behind it (the resolve of raster/mod.rs `Rasterizer::resolve` and of sorted
// splatting's per-sample blends).
@group(0) @binding(2) var target_color: texture_multisampled_2d<f32>;

fn frame_color(pixel: vec2<i32>, index: u32) -> vec4<f32> {
    var sum = vec4<f32>(0.0);
    for (var i = 0u; i < params.samples; i++) {
        sum += composed(textureLoad(target_color, pixel, i), index, i);
    }
    return sum / f32(params.samples);
}
