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

// FIRST_HIT_FRAGMENTS: where each sample's fragments start (entry pixel × S + k), from the
// counts of the FIRST_HIT_COUNT pass, and the fragments.
@group(0) @binding(24) var<storage, read> fragment_start: array<u32>;
@group(0) @binding(25) var<storage, read_write> fragments: array<Fragment>;

// StochasticSplats' decision for splat s at sample k of pixel px in frame params.frame_key:
// u < α, with u drawn as splat.wgsl `accepted_splat` draws it (raster/mod.rs
// `stochastic_splat`, slot = sample k).
fn accepted(s: Splat, px: vec2<u32>, alpha: f32, k: u32) -> bool {
    let pixel_key = xxhash32(vec3<u32>(px.x, px.y, params.frame_key));
    return unit_f32(pcg(xxhash32(vec3<u32>(pixel_key, s.id, k)))) - params.u_shift < alpha;
}

// Entry `at` of the hybrid's first hits (splat_gpu::GpuFirstHit, sample k of pixel p at p S + k):
// radiance and transmittance, normal, depth along the sample's ray (−1: none) and splat.
fn write_first_hit(at: u32, radiance: vec3<f32>, transmittance: f32, n: vec3<f32>, t: f32, picked: u32) {
    out_color[at] = vec4<f32>(radiance, transmittance);
    out_normal[at] = vec4<f32>(n, 0.0);
    out_pick[at] = vec2<u32>(bitcast<u32>(select(-1.0, t, picked != NONE)), picked);
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
    let origin = camera_origin();
    // raster/mod.rs `sorted` composites each of the S samples (its coverage and depth at the
    // sample, its alpha at the centre: MSAA's shading rate) and takes the integrated normal
    // Σ nᵢ αᵢ Tᵢ, the pick and its depth from sample 0, along whose ray every normal is taken.
    let p0 = vec2<f32>(px) + rop_offsets[0];
    let dir = pixel_dir(p0);
    let to_t = stretch(p0);
    var depth = 0.0;
    var picked = NONE;
    var normal = vec3<f32>(0.0);
    var drawn = false;
    let index = px.y * params.size.x + px.x;
    // Every fragment lit in the volumetric look, but for StochasticSplats' first hit, which the
    // ray tracer lights as the pick in either look.
    let written = params.first_hit == FIRST_HIT_ACCEPTED;
    // The hybrid's volumetric look with a sorted first hit: the fragments are counted, then
    // listed for the ray tracer, which lights each with its shadow rays.
    let listed = params.first_hit == FIRST_HIT_COUNT || params.first_hit == FIRST_HIT_FRAGMENTS;
    let volumetric = params.lit == 1u && params.look == LOOK_VOLUMETRIC && params.first_hit == 0u;
    let lit_surface = params.lit == 1u && params.look == LOOK_SURFACE;
    let sorted = params.first_hit == FIRST_HIT_SORTED || params.first_hit == FIRST_HIT_FRAGMENTS;
    // Sample 0's composite L_0 and transmittance T_0 (sorted splatting's first hit).
    var l0 = vec3<f32>(0.0);
    var t0 = 1.0;
    // The means over the samples of the composite L_s, of the transmittance T_s, of what lies
    // behind B_s, of T_s B_s, of the mesh coverage T_s M_s seen through the splats and of the
    // samples' mesh share M_s.
    var color = vec3<f32>(0.0);
    var transmittance = 0.0;
    var back_mean = vec3<f32>(0.0);
    var seen_back = vec3<f32>(0.0);
    var covered = 0.0;
    var mesh_share = 0.0;
    // Whether sample 0 sees a mesh.
    var mesh0 = false;
    for (var k = 0u; k < params.samples; k++) {
        // What lies behind sample k (raster/mod.rs `Rasterizer::behind`): the background, or
        // its mesh, which hides the fragments at or behind it (the depth test of the splat pass).
        var back = vec4<f32>(params.background.xyz, FAR_DEPTH);
        if (inside && params.meshes == 1u) {
            back = behind[index * params.samples + k];
        }
        let mesh = back.w < FAR_DEPTH;
        mesh0 = mesh0 || (k == 0u && mesh);
        let p = vec2<f32>(px) + rop_offsets[k];
        let dir_k = pixel_dir(p);
        let to_t_k = stretch(p);
        var t_k = 1.0;
        var l_k = vec3<f32>(0.0);
        // StochasticSplats' written fragment at sample k: its splat, normal and depth.
        var hit_k = NONE;
        var n_k = vec3<f32>(0.0);
        var depth_k = 0.0;
        // FIRST_HIT_COUNT: the sample's fragments so far; FIRST_HIT_FRAGMENTS: where the next goes.
        var listed_k = 0u;
        if (inside && params.first_hit == FIRST_HIT_FRAGMENTS) {
            listed_k = fragment_start[index * params.samples + k];
        }
        for (var start = range.x; start < range.y; start += BATCH) {
            load_batch(start, range.y, l);
            let n = min(BATCH, range.y - start);
            for (var j = 0u; j < n; j++) {
                let s = batch[j];
                let in_rect = all(px >= s.rect.xy) && all(px < s.rect.zw);
                if (inside && in_rect && s.depth * to_t_k < back.w) {
                    var alpha = select(0.0, fragment_alpha(s, centre, params), covers(s, p, params));
                    if (written) {
                        // StochasticSplats (splat.wgsl `accepted_splat`): the fragment is written
                        // opaque where u_k < α; in depth order the first accepted is the closest.
                        alpha = select(0.0, 1.0, hit_k == NONE && accepted(s, px, alpha, k));
                    }
                    if (alpha > 0.0) {
                        var c = s.color;
                        if (k == 0u || volumetric || written || listed) {
                            let nrm = splat_normal(s.id, origin, dir);
                            if (params.first_hit == FIRST_HIT_FRAGMENTS) {
                                let t = s.depth * to_t_k;
                                fragments[listed_k] = Fragment(s.color, t_k * alpha, nrm, t, s.id, 0u, 0u, 0u);
                            }
                            if (listed) {
                                listed_k++;
                            }
                            if (volumetric) {
                                c = shade_unshadowed(s.color, s.id, origin, dir_k, s.depth * to_t_k, nrm);
                            }
                            if (k == 0u) {
                                normal += t_k * alpha * nrm;
                                drawn = true;
                            }
                            if (written) {
                                hit_k = s.id;
                                n_k = nrm;
                                depth_k = s.depth * to_t_k;
                            }
                        }
                        l_k += t_k * alpha * c;
                        t_k *= 1.0 - alpha;
                        if (k == 0u && picked == NONE && (written || t_k < params.iso_threshold)) {
                            picked = s.id;
                            depth = s.depth;
                        }
                    }
                }
            }
            workgroupBarrier();
        }
        if (inside && params.first_hit == FIRST_HIT_COUNT) {
            out_pick[index * params.samples + k] = vec2<u32>(listed_k, 0u);
        } else if (inside && written) {
            write_first_hit(index * params.samples + k, l_k, t_k, n_k, depth_k, hit_k);
        } else if (inside && sorted && k > 0u) {
            // Sorted splatting: sample k's composite and transmittance, its radiance in sample
            // 0's mean in the surface look; the pick and normal are sample 0's.
            let l = select(l_k, vec3<f32>(0.0), lit_surface);
            write_first_hit(index * params.samples + k, l, t_k, vec3<f32>(0.0), -1.0, NONE);
        }
        if (k == 0u) {
            l0 = l_k;
            t0 = t_k;
        }
        let share = 1.0 / f32(params.samples);
        color += share * l_k;
        transmittance += share * t_k;
        back_mean += share * back.xyz;
        seen_back += share * t_k * back.xyz;
        covered += share * t_k * select(0.0, 1.0, mesh);
        mesh_share += share * select(0.0, 1.0, mesh);
    }
    if (inside) {
        var out = vec4<f32>(color + seen_back, 1.0 - transmittance + covered);
        // raster/mod.rs `sorted`: the integrated normal normalised, −dir when degenerate; the
        // depth as a distance along sample 0's ray, t = z |d_cam|, where T fell below the
        // threshold, else the mesh's (depth consolidation, vk_gaussian_splatting Lighting §1.5.3).
        // composite.rs `integrated_normal`: zero where no fragment was drawn.
        var n = vec3<f32>(0.0);
        if (drawn) {
            let len = length(normal);
            n = select(-dir, normal / len, len > DEGENERATE_NORMAL);
        }
        var t = -1.0;
        if (sorted) {
            // The hybrid pipeline lights and continues from these in the ray tracer: sample 0
            // carries the pick and the integrated normal, and in the surface look the mean
            // radiance, which the tracer lights once (raster/mod.rs `light_surface`).
            write_first_hit(index * params.samples, select(l0, color, lit_surface), t0, n, depth * to_t, picked);
        }
        if (params.first_hit != 0u) {
            return;
        }
        if (picked != NONE) {
            t = depth * to_t;
        } else if (mesh0) {
            t = behind[index * params.samples].w;
            n = behind_normal[index * params.samples].xyz;
        }
        if (params.lit == 1u && params.look == LOOK_SURFACE) {
            // raster/mod.rs `light_surface`: L lit once at the picked depth with the integrated
            // normal and the picked splat's material, plus the mean of T_s B_s; where T stayed
            // above the threshold, what lies behind: the mean of B_s covering the samples'
            // mesh share, with sample 0's mesh normal and depth (none without a mesh).
            if (picked == NONE) {
                out = vec4<f32>(back_mean, mesh_share);
                n = select(vec3<f32>(0.0), n, mesh_share > 0.0);
            } else {
                let lit = shade_unshadowed(color, picked, origin, dir, depth * to_t, n);
                out = vec4<f32>(lit + seen_back, out.w);
            }
        }
        out_color[index] = out;
        out_normal[index] = vec4<f32>(n, 0.0);
        out_pick[index] = vec2<u32>(bitcast<u32>(t), picked);
    }
}
