// Prepended to the kernels that shade particles: the SH colour of crates/splat-core/src/sh.rs,
// read from the `sh` storage array (RGB + pad per coefficient) the including module declares.

// sh.rs: colour of particle `id` (degree `deg`) seen along unit direction `dir`, +0.5, clamped at 0.
fn sh_eval(id: u32, deg: u32, dir: vec3<f32>) -> vec3<f32> {
    let base = id * (deg + 1u) * (deg + 1u);
    var c = 0.2820948 * sh[base].xyz;
    if (deg >= 1u) {
        let x = dir.x;
        let y = dir.y;
        let z = dir.z;
        c += -0.48860252 * y * sh[base + 1u].xyz + 0.48860252 * z * sh[base + 2u].xyz - 0.48860252 * x * sh[base + 3u].xyz;
        if (deg >= 2u) {
            let xx = x * x;
            let yy = y * y;
            let zz = z * z;
            c += 1.0925484 * x * y * sh[base + 4u].xyz
                + -1.0925484 * y * z * sh[base + 5u].xyz
                + 0.31539157 * (2.0 * zz - xx - yy) * sh[base + 6u].xyz
                + -1.0925484 * x * z * sh[base + 7u].xyz
                + 0.5462742 * (xx - yy) * sh[base + 8u].xyz;
            if (deg >= 3u) {
                c += -0.5900436 * y * (3.0 * xx - yy) * sh[base + 9u].xyz
                    + 2.8906114 * x * y * z * sh[base + 10u].xyz
                    + -0.4570458 * y * (4.0 * zz - xx - yy) * sh[base + 11u].xyz
                    + 0.37317634 * z * (2.0 * zz - 3.0 * xx - 3.0 * yy) * sh[base + 12u].xyz
                    + -0.4570458 * x * (4.0 * zz - xx - yy) * sh[base + 13u].xyz
                    + 1.4453057 * z * (xx - yy) * sh[base + 14u].xyz
                    + -0.5900436 * x * (xx - 3.0 * yy) * sh[base + 15u].xyz;
            }
        }
    }
    return max(c + vec3<f32>(0.5), vec3<f32>(0.0));
}
