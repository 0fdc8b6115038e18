// The path tracer's sampler, the twin of splat-core's path/sampler.rs: Owen-scrambled Sobol
// points or the counter-based hash, the dimensions of a bounce and the decisions of the
// Gaussians along a segment. Part of the trace kernel (splat_gpu::TRACE_WGSL, after path.wgsl).

// The pixel's sequence seed (Sobol) or pixel-and-frame seed (hash), and the sample index.
var<private> path_seed: u32;
var<private> path_index: u32;
// The bounce whose light samples path_light_sample draws.
var<private> path_bounce: u32;

// splat_gpu::layout::SAMPLER_* (a test compares them).
const SAMPLER_SOBOL: u32 = 0u;
const SAMPLER_HASH: u32 = 1u;
const PATH_DIM_ID: u32 = 0xfffffff8u;
const LIGHT_STREAM: u32 = 0xffffffefu;
const DIMS_PER_BOUNCE: u32 = 8u;
const SOBOL_DIMENSIONS: u32 = 256u;

// sobol_burley `parts::hash` (skeeto's hash-prospector).
fn sobol_hash(x: u32) -> u32 {
    var n = x ^ 0xe6fe3bebu;
    n ^= n >> 16u;
    n *= 0x7feb352du;
    n ^= n >> 15u;
    n *= 0x846ca68bu;
    n ^= n >> 16u;
    return n;
}

// sobol_burley `parts::owen_scramble_rev`.
fn owen_scramble_rev(x: u32, scramble: u32) -> u32 {
    var n = x;
    n ^= n * 0x3d20adeau;
    n += scramble;
    n *= (scramble >> 16u) | 1u;
    n ^= n * 0x05526c56u;
    n ^= n * 0x53a22864u;
    return n;
}

// sobol_burley `parts::sobol_rev`: the top 16 bits of the reversed index select the direction
// numbers, unrolled (no loop: lavapipe's budget counts loops).
fn sobol_rev(index_rev: u32, dim: u32) -> u32 {
    let v = dim * 16u;
    var s = 0u;
    s ^= select(0u, sobol_vectors[v + 0u], (index_rev & 0x80000000u) != 0u);
    s ^= select(0u, sobol_vectors[v + 1u], (index_rev & 0x40000000u) != 0u);
    s ^= select(0u, sobol_vectors[v + 2u], (index_rev & 0x20000000u) != 0u);
    s ^= select(0u, sobol_vectors[v + 3u], (index_rev & 0x10000000u) != 0u);
    s ^= select(0u, sobol_vectors[v + 4u], (index_rev & 0x08000000u) != 0u);
    s ^= select(0u, sobol_vectors[v + 5u], (index_rev & 0x04000000u) != 0u);
    s ^= select(0u, sobol_vectors[v + 6u], (index_rev & 0x02000000u) != 0u);
    s ^= select(0u, sobol_vectors[v + 7u], (index_rev & 0x01000000u) != 0u);
    s ^= select(0u, sobol_vectors[v + 8u], (index_rev & 0x00800000u) != 0u);
    s ^= select(0u, sobol_vectors[v + 9u], (index_rev & 0x00400000u) != 0u);
    s ^= select(0u, sobol_vectors[v + 10u], (index_rev & 0x00200000u) != 0u);
    s ^= select(0u, sobol_vectors[v + 11u], (index_rev & 0x00100000u) != 0u);
    s ^= select(0u, sobol_vectors[v + 12u], (index_rev & 0x00080000u) != 0u);
    s ^= select(0u, sobol_vectors[v + 13u], (index_rev & 0x00040000u) != 0u);
    s ^= select(0u, sobol_vectors[v + 14u], (index_rev & 0x00020000u) != 0u);
    s ^= select(0u, sobol_vectors[v + 15u], (index_rev & 0x00010000u) != 0u);
    return s;
}

// sobol_burley `sample`: dimension `dim` of point `index` of the sequence seeded by `seed`.
fn sobol_sample(index: u32, dim: u32, seed: u32) -> f32 {
    let shuffled = owen_scramble_rev(reverseBits(index), sobol_hash(seed ^ 0x79c68e4au));
    let sobol = sobol_rev(shuffled, dim);
    var c = 0x912f69bau;
    switch dim & 3u {
        case 1u: { c = 0x174f18abu; }
        case 2u: { c = 0x691e72cau; }
        case 3u: { c = 0xb40cc1b8u; }
        default: {}
    }
    let scramble = (dim >> 2u) ^ (seed * 0x9c8f2d3bu) ^ c;
    let bits = reverseBits(owen_scramble_rev(sobol, sobol_hash(scramble)));
    return bitcast<f32>((bits >> 9u) | 0x3f800000u) - 1.0;
}

// sampler.rs `PathSampler::new`.
fn path_sampler_begin(x: u32, y: u32, seed: u32, index: u32) {
    path_index = index;
    if (path.sampler == SAMPLER_SOBOL) {
        path_seed = xxhash32(vec3<u32>(x, y, seed ^ 0x50B01000u));
    } else {
        path_seed = xxhash32(vec3<u32>(x, y, frame_key(seed, index)));
    }
}

// sampler.rs `PathSampler::draw`: dimension `dim` of stream `stream`.
fn path_draw(dim: u32, stream: u32) -> f32 {
    if (path.sampler == SAMPLER_HASH) {
        return unit_f32(pcg(xxhash32(vec3<u32>(path_seed, stream, dim))));
    }
    let block = dim / SOBOL_DIMENSIONS;
    let seed = xxhash32(vec3<u32>(path_seed, stream, block | ((path_index >> 16u) << 8u)));
    return sobol_sample(path_index & 0xffffu, dim % SOBOL_DIMENSIONS, seed);
}

fn path_dim(dim: u32) -> f32 {
    return path_draw(dim, PATH_DIM_ID);
}

fn path_dim2(dim: u32) -> vec2<f32> {
    return vec2<f32>(path_dim(dim), path_dim(dim + 1u));
}

// sampler.rs `PathSampler::particle`: the acceptance draw of particle `id` in `decision`.
fn path_particle(id: u32, decision: u32) -> f32 {
    if (path.sampler == SAMPLER_HASH) {
        return path_draw(decision, id);
    }
    let seed = xxhash32(vec3<u32>(path_seed, id, decision | ((path_index >> 16u) << 24u)));
    return sobol_sample(path_index & 0xffffu, 0u, seed);
}

// sampler.rs `PathDecide::light_sample`.
fn path_light_sample(light: u32) -> vec2<f32> {
    let dim = dim_light_point(path_bounce);
    let stream = LIGHT_STREAM - light;
    return vec2<f32>(path_draw(dim, stream), path_draw(dim + 1u, stream));
}

// sampler.rs `Dim::index`.
fn dim_lobe(b: u32) -> u32 {
    return 4u + DIMS_PER_BOUNCE * b;
}
fn dim_direction(b: u32) -> u32 {
    return 5u + DIMS_PER_BOUNCE * b;
}
fn dim_light_pick(b: u32) -> u32 {
    return 7u + DIMS_PER_BOUNCE * b;
}
fn dim_light_point(b: u32) -> u32 {
    return 8u + DIMS_PER_BOUNCE * b;
}
fn dim_roulette(b: u32) -> u32 {
    return 10u + DIMS_PER_BOUNCE * b;
}

// sampler.rs `decision`, `shadow_decision` and `surface_decision`.
fn decision(b: u32, slot: u32) -> u32 {
    return (b << 12u) | slot;
}
fn shadow_decision(b: u32, light: u32) -> u32 {
    return 0x00800000u | (b << 12u) | light;
}
fn surface_decision(b: u32) -> u32 {
    return 0x00400000u | (b << 12u);
}
