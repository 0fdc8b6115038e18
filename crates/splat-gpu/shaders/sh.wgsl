// Prepended to the kernels that shade particles: the SH colour of crates/splat-core/src/sh.rs,
// read through `sh_at(i)` (coefficient i of the RGB + pad array) that the including module declares.

// The 3DGS constants of sh.rs (SH_C0, SH_C1, SH_C2, SH_C3), one named constant each; a test
// compares every one with its Rust twin.
const SH_C0: f32 = 0.2820948;
const SH_C1: f32 = 0.48860252;
const SH_C2 = array<f32, 5>(1.0925484, -1.0925484, 0.31539157, -1.0925484, 0.5462742);
const SH_C3 = array<f32, 7>(-0.5900436, 2.8906114, -0.4570458, 0.37317634, -0.4570458, 1.4453057, -0.5900436);

// sh.rs: colour of particle `id` (degree `deg`) seen along unit direction `dir`, +0.5, clamped at 0.
fn sh_eval(id: u32, deg: u32, dir: vec3<f32>) -> vec3<f32> {
    let base = id * (deg + 1u) * (deg + 1u);
    var c = SH_C0 * sh_at(base).xyz;
    if (deg >= 1u) {
        let x = dir.x;
        let y = dir.y;
        let z = dir.z;
        c += -SH_C1 * y * sh_at(base + 1u).xyz + SH_C1 * z * sh_at(base + 2u).xyz - SH_C1 * x * sh_at(base + 3u).xyz;
        if (deg >= 2u) {
            let xx = x * x;
            let yy = y * y;
            let zz = z * z;
            c += SH_C2[0] * x * y * sh_at(base + 4u).xyz
                + SH_C2[1] * y * z * sh_at(base + 5u).xyz
                + SH_C2[2] * (2.0 * zz - xx - yy) * sh_at(base + 6u).xyz
                + SH_C2[3] * x * z * sh_at(base + 7u).xyz
                + SH_C2[4] * (xx - yy) * sh_at(base + 8u).xyz;
            if (deg >= 3u) {
                c += SH_C3[0] * y * (3.0 * xx - yy) * sh_at(base + 9u).xyz
                    + SH_C3[1] * x * y * z * sh_at(base + 10u).xyz
                    + SH_C3[2] * y * (4.0 * zz - xx - yy) * sh_at(base + 11u).xyz
                    + SH_C3[3] * z * (2.0 * zz - 3.0 * xx - 3.0 * yy) * sh_at(base + 12u).xyz
                    + SH_C3[4] * x * (4.0 * zz - xx - yy) * sh_at(base + 13u).xyz
                    + SH_C3[5] * z * (xx - yy) * sh_at(base + 14u).xyz
                    + SH_C3[6] * x * (xx - 3.0 * yy) * sh_at(base + 15u).xyz;
            }
        }
    }
    return max(c + vec3<f32>(0.5), vec3<f32>(0.0));
}
