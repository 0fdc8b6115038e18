// The compute tile rasterizer, the twin of splat_gpu raster/depth_pick.rs and of splat-core's
// Rasterizer::sorted with Blend::Under: every pixel's fragments composited front to back to
// pick the iso-opacity depth and splat. Part of the raster kernels (splat_gpu::RASTER_WGSL).

// Per pixel: colour + coverage of front-to-back compositing, and (depth bits, picked id).
@group(0) @binding(11) var<storage, read_write> out_color: array<vec4<f32>>;
@group(0) @binding(12) var<storage, read_write> out_pick: array<vec2<u32>>;
// Per pixel: the integrated unit normal (zero where no fragment, w unused).
@group(0) @binding(16) var<storage, read_write> out_normal: array<vec4<f32>>;
// The mesh pre-pass (mesh_prepass.wgsl): colour and distance, and the mesh's normal, per pixel;
// read where params.meshes is 1.
@group(0) @binding(17) var<storage, read> behind: array<vec4<f32>>;
@group(0) @binding(18) var<storage, read> behind_normal: array<vec4<f32>>;

// StochasticSplats' decision for splat s at pixel px of frame params.frame_key: u < α, with u
// drawn as splat.wgsl `accepted_splat` draws it (raster/mod.rs `stochastic_splat`, slot 0).
fn accepted(s: Splat, px: vec2<u32>, alpha: f32) -> bool {
    let pixel_key = xxhash32(vec3<u32>(px.x, px.y, params.frame_key));
    return unit_f32(pcg(xxhash32(vec3<u32>(pixel_key, s.id, 0u)))) - params.u_shift < alpha;
}

// One workgroup per 16 × 16 tile, one invocation per pixel, walking the tile's splats in depth
// order in batches loaded cooperatively into workgroup memory (the 3DGS rasterizer's loop).
//
// Why a compute pass and not the raster pipeline: front-to-back blending gives the colour, but
// the iso-opacity depth needs the transmittance *before and after* each fragment, in order,
// which a fixed-function blend cannot return and a fragment shader can only read back through
// a storage image under fragment-shader interlock (what vk_gaussian_splatting does). wgpu has
// no interlock, and without it the read-modify-write of overlapping fragments races. Here one
// invocation owns its pixel and walks the fragments sequentially in the global depth order, so
// the depth and picked splat are exact, the same (depth, id) order as the CPU reference.
@compute @workgroup_size(16, 16, 1)
fn tile_blend(
    @builtin(workgroup_id) wg: vec3<u32>,
    @builtin(local_invocation_id) lid: vec3<u32>,
    @builtin(local_invocation_index) l: u32,
) {
    let tile = wg.y * params.tiles.x + wg.x;
    let px = wg.xy * TILE + lid.xy;
    let inside = px.x < params.size.x && px.y < params.size.y;
    let centre = vec2<f32>(px) + vec2<f32>(0.5);
    let range = tile_pairs(tile, l);
    var transmittance = 1.0;
    var color = vec3<f32>(0.0);
    var depth = 0.0;
    var picked = NONE;
    // The pixel-centre ray, and the integrated normal Σ nᵢ αᵢ Tᵢ.
    let origin = camera_origin();
    let dir = pixel_dir(centre);
    let to_t = stretch(centre);
    var normal = vec3<f32>(0.0);
    var drawn = false;
    // What lies behind (raster/mod.rs `Rasterizer::behind`): the background, or the pixel's
    // mesh, which hides the fragments at or behind it (the depth test of the splat pass).
    var back = vec4<f32>(params.background.xyz, FAR_DEPTH);
    if (inside && params.meshes == 1u) {
        back = behind[px.y * params.size.x + px.x];
    }
    let mesh = back.w < FAR_DEPTH;
    for (var start = range.x; start < range.y; start += BATCH) {
        load_batch(start, range.y, l);
        let n = min(BATCH, range.y - start);
        for (var j = 0u; j < n; j++) {
            let s = batch[j];
            let in_rect = all(px >= s.rect.xy) && all(px < s.rect.zw);
            if (inside && in_rect && s.depth * to_t < back.w) {
                var alpha = splat_alpha(s, centre, params);
                if (params.first_hit == FIRST_HIT_ACCEPTED) {
                    // StochasticSplats (splat.wgsl `accepted_splat`): the fragment is written
                    // opaque where u < α; in depth order the first accepted is the closest.
                    alpha = select(0.0, 1.0, picked == NONE && accepted(s, px, alpha));
                }
                if (alpha > 0.0) {
                    var c = s.color;
                    let n = splat_normal(s.id, origin, dir);
                    if (params.lit == 1u && params.look == LOOK_VOLUMETRIC) {
                        c = shade_unshadowed(s.color, s.id, origin, dir, s.depth * to_t, n);
                    }
                    normal += transmittance * alpha * n;
                    drawn = true;
                    color += transmittance * alpha * c;
                    transmittance *= 1.0 - alpha;
                    let written = params.first_hit == FIRST_HIT_ACCEPTED;
                    if (picked == NONE && (written || transmittance < params.iso_threshold)) {
                        picked = s.id;
                        depth = s.depth;
                    }
                }
            }
        }
        workgroupBarrier();
    }
    if (inside) {
        let index = px.y * params.size.x + px.x;
        let covered = select(0.0, 1.0, mesh);
        var out = vec4<f32>(color + transmittance * back.xyz, 1.0 - transmittance + transmittance * covered);
        // raster/mod.rs `sorted`: the integrated normal normalised, −dir when degenerate; the
        // depth as a distance along the pixel-centre ray, t = z |d_cam|, where T fell below the
        // threshold, else the mesh's (depth consolidation, vk_gaussian_splatting Lighting §1.5.3).
        // composite.rs `integrated_normal`: zero where no fragment was drawn.
        var n = vec3<f32>(0.0);
        if (drawn) {
            let len = length(normal);
            n = select(-dir, normal / len, len > DEGENERATE_NORMAL);
        }
        var t = -1.0;
        if (params.first_hit != 0u) {
            // The hybrid pipeline lights and continues from this in the ray tracer.
            out_color[index] = vec4<f32>(color, transmittance);
            out_normal[index] = vec4<f32>(n, 0.0);
            out_pick[index] = vec2<u32>(bitcast<u32>(select(-1.0, depth * to_t, picked != NONE)), picked);
            return;
        }
        if (picked != NONE) {
            t = depth * to_t;
        } else if (mesh) {
            t = back.w;
            n = behind_normal[index].xyz;
        }
        if (params.lit == 1u && params.look == LOOK_SURFACE) {
            // raster/mod.rs `light_surface`: L lit once at the picked depth with the integrated
            // normal and the picked splat's material; what lies behind (the mesh's normal and
            // depth, or the background and no normal) where T stayed above the threshold.
            if (picked == NONE) {
                out = vec4<f32>(back.xyz, covered);
                n = select(vec3<f32>(0.0), n, mesh);
            } else {
                let lit = shade_unshadowed(color, picked, origin, dir, depth * to_t, n);
                out = vec4<f32>(lit + transmittance * back.xyz, out.w);
            }
        }
        out_color[index] = out;
        out_normal[index] = vec4<f32>(n, 0.0);
        out_pick[index] = vec2<u32>(bitcast<u32>(t), picked);
    }
}
