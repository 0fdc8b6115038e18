// The raster pipeline's mesh pre-pass (vk_gaussian_splatting Lighting §1.5.3 and §3), the twin of
// the CPU reference's `Rasterizer::pixel` ray casts and `Rasterizer::behind`: per sample of each
// pixel, the nearest opaque mesh along the sample's ray (a transparent triangle is a fragment
// of the raster operations, rop.wgsl), its distance (the splats' depth test) and its
// forward-shaded colour (lit with every light visible and sampled at its centre, no bounces: the
// mirror and glass shares see the background), or the background at distance FAR. The splat
// fragments read the distance (splat.wgsl), the fold blends the colour under them with the
// sample's remaining transmittance (fold.wgsl). Sample i of pixel p is entry p S + i.

@group(0) @binding(0) var<storage, read> params: RasterParams;
@group(0) @binding(1) var<storage, read> nodes: array<Node>;
// bvh.wgsl's read of node i (the ray tracer's may span several bindings, splat_gpu::split).
fn node_at(i: u32) -> Node { return nodes[i]; }
// raster_lighting.wgsl's read of the canonical transforms (the splatting kernels' may span
// several bindings, splat_gpu::RasterSplit); the pre-pass lights meshes only, so it binds none.
@group(0) @binding(15) var<storage, read> canonical: array<vec4<f32>>;
fn canonical_at(i: u32) -> vec4<f32> { return canonical[i]; }
@group(0) @binding(2) var<storage, read> triangles: array<Triangle>;
@group(0) @binding(3) var<storage, read> mesh_materials: array<MeshMaterial>;
@group(0) @binding(4) var<storage, read_write> behind: array<vec4<f32>>;
// The mesh's shading normal turned toward the ray (zero without a mesh), for the depth
// consolidation of the tile rasterizer.
@group(0) @binding(5) var<storage, read_write> behind_normal: array<vec4<f32>>;
// Sub-pixel position of sample i in [0, 1)² (params.samples of them).
@group(0) @binding(6) var<storage, read> sample_offsets: array<vec2<f32>>;

// bvh.wgsl's loop counter (no budget is checked here).
var<private> iterations: u32;

// mesh.wgsl's filter of transparent crossings: the pre-pass draws opaque triangles alone.
fn transparent_stops(tri: Triangle, h: vec3<f32>) -> bool {
    return false;
}

@compute @workgroup_size(8, 8, 1)
fn mesh_prepass(@builtin(global_invocation_id) gid: vec3<u32>) {
    if (gid.x >= params.size.x || gid.y >= params.size.y) {
        return;
    }
    let pixel = gid.y * params.size.x + gid.x;
    for (var i = 0u; i < params.samples; i++) {
        let index = pixel * params.samples + i;
        let p = vec2<f32>(gid.xy) + sample_offsets[i];
        let ray = Ray(camera_origin(), pixel_dir(p), params.cam_row2.xyz, params.t_min, params.t_max);
        let hit = mesh_traverse(ROOT, ray, true);
        if (hit.triangle == NONE) {
            behind[index] = vec4<f32>(params.background.xyz, FAR);
            behind_normal[index] = vec4<f32>(0.0);
            continue;
        }
        let m = mesh_materials[triangles[hit.triangle].mesh];
        let n = surface_normal(hit, ray);
        behind_normal[index] = vec4<f32>(n, 0.0);
        let lit = shade_material_unshadowed(m.shading, m.color, ray.origin, ray.dir, hit.t, n);
        let background = background_share(m, clamp(-dot(ray.dir, n), 0.0, 1.0)) * params.background.xyz;
        behind[index] = vec4<f32>(local_share(m) * lit + background, hit.t);
    }
}
