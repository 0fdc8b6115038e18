// The frame's colour target of fold.wgsl: one sample per pixel.
@group(0) @binding(2) var target_color: texture_2d<f32>;

fn frame_color(pixel: vec2<i32>) -> vec4<f32> {
    return textureLoad(target_color, pixel, 0);
}
