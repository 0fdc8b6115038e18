// The frame's colour target of fold.wgsl: one sample per pixel (the raster operations' target
// holds the pixel's resolved samples).
@group(0) @binding(2) var target_color: texture_2d<f32>;

fn frame_color(pixel: vec2<i32>, index: u32) -> vec4<f32> {
    return composed(textureLoad(target_color, pixel, 0), index, 0u);
}
