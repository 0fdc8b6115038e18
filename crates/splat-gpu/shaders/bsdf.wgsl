// The path tracer's BSDFs, the twin of splat-core's path/bsdf.rs: Lambert (under a dielectric
// specular layer, glTF's fresnel_mix, where layer_f0 > 0), GGX conductor and dielectric with
// visible-normal sampling. Part of the trace kernel (splat_gpu::TRACE_WGSL).

const PI: f32 = 3.14159265;
const MIN_ROUGHNESS: f32 = 1e-3;

struct Bsdf {
    diffuse: f32,
    albedo: vec3<f32>,
    conductor: f32,
    // The conductor's F₀ (Schlick's Fresnel).
    tint: vec3<f32>,
    dielectric: f32,
    // F₀ of the specular layer over the Lambertian lobe (0: none).
    layer_f0: f32,
    alpha: f32,
    eta: f32,
}

// bsdf.rs `BsdfSample`; `ok` is false for an absorbed draw.
struct BsdfSample {
    wi: vec3<f32>,
    weight: vec3<f32>,
    pdf: f32,
    delta: bool,
    ok: bool,
}

fn ggx_d(h: vec3<f32>, alpha: f32) -> f32 {
    if (h.z <= 0.0) {
        return 0.0;
    }
    let a2 = alpha * alpha;
    let k = h.z * h.z * (a2 - 1.0) + 1.0;
    return a2 / (PI * k * k);
}

fn ggx_lambda(w: vec3<f32>, alpha: f32) -> f32 {
    let cos2 = w.z * w.z;
    if (cos2 <= 0.0) {
        return FAR;
    }
    let tan2 = max(1.0 - cos2, 0.0) / cos2;
    return 0.5 * (sqrt(1.0 + alpha * alpha * tan2) - 1.0);
}

fn ggx_g1(w: vec3<f32>, alpha: f32) -> f32 {
    return 1.0 / (1.0 + ggx_lambda(w, alpha));
}

fn ggx_g2(wo: vec3<f32>, wi: vec3<f32>, alpha: f32) -> f32 {
    return 1.0 / (1.0 + ggx_lambda(wo, alpha) + ggx_lambda(wi, alpha));
}

fn visible_normal_pdf(wo: vec3<f32>, h: vec3<f32>, alpha: f32) -> f32 {
    return ggx_g1(wo, alpha) * max(dot(wo, h), 0.0) * ggx_d(h, alpha) / wo.z;
}

fn visible_normal(wo: vec3<f32>, alpha: f32, u: vec2<f32>) -> vec3<f32> {
    let wh = normalize(vec3<f32>(alpha * wo.x, alpha * wo.y, wo.z));
    let phi = 2.0 * PI * u.x;
    let z = (1.0 - u.y) * (1.0 + wh.z) - wh.z;
    let sin_theta = sqrt(clamp(1.0 - z * z, 0.0, 1.0));
    let h = vec3<f32>(sin_theta * cos(phi), sin_theta * sin(phi), z) + wh;
    return normalize(vec3<f32>(alpha * h.x, alpha * h.y, max(h.z, 0.0)));
}

fn reflect_about(wo: vec3<f32>, h: vec3<f32>) -> vec3<f32> {
    return 2.0 * dot(wo, h) * h - wo;
}

fn cosine_hemisphere(u: vec2<f32>) -> vec3<f32> {
    let d = concentric_disk(u);
    return vec3<f32>(d.x, d.y, sqrt(max(1.0 - dot(d, d), 0.0)));
}

// bsdf.rs `conductor_eval`: f|cos θᵢ| (rgb, Schlick's Fresnel of F₀ = f0) and p (w).
fn conductor_eval(wo: vec3<f32>, wi: vec3<f32>, alpha: f32, f0: vec3<f32>) -> vec4<f32> {
    if (wi.z <= 0.0 || wo.z <= 0.0) {
        return vec4<f32>(0.0);
    }
    let h = normalize(wo + wi);
    let d = ggx_d(h, alpha);
    let f = schlick(f0, dot(wo, h)) * (d * ggx_g2(wo, wi, alpha) / (4.0 * wo.z));
    return vec4<f32>(f, visible_normal_pdf(wo, h, alpha) / (4.0 * dot(wo, h)));
}

// bsdf.rs `dielectric_eval`: (f|cos θᵢ|, p).
fn dielectric_eval(wo: vec3<f32>, wi: vec3<f32>, alpha: f32, eta: f32) -> vec2<f32> {
    if (wo.z <= 0.0 || wi.z == 0.0) {
        return vec2<f32>(0.0);
    }
    let is_reflection = wi.z > 0.0;
    let raw = select(wo + eta * wi, wo + wi, is_reflection);
    let len = length(raw);
    if (!(len > 0.0 && len < FAR)) {
        return vec2<f32>(0.0);
    }
    var h = raw / len;
    if (h.z < 0.0) {
        h = -h;
    }
    let cos_o = dot(wo, h);
    let cos_i = dot(wi, h);
    if (cos_o <= 0.0 || (is_reflection && cos_i <= 0.0) || (!is_reflection && cos_i >= 0.0)) {
        return vec2<f32>(0.0);
    }
    let f = fresnel(cos_o, 1.0 / eta);
    let d = ggx_d(h, alpha);
    let g2 = ggx_g2(wo, wi, alpha);
    let vn = visible_normal_pdf(wo, h, alpha);
    if (is_reflection) {
        return vec2<f32>(f * d * g2 / (4.0 * wo.z), f * vn / (4.0 * cos_o));
    }
    let denom = (cos_o + eta * cos_i) * (cos_o + eta * cos_i);
    let jacobian = eta * eta * abs(cos_i) / denom;
    return vec2<f32>((1.0 - f) * d * g2 * cos_o * jacobian / (wo.z * eta * eta), (1.0 - f) * vn * jacobian);
}

// bsdf.rs `Bsdf::layer_fresnel`: the specular layer's F(cos θ).
fn layer_fresnel(b: Bsdf, cos_t: f32) -> f32 {
    return schlick(vec3<f32>(b.layer_f0), cos_t).x;
}

// bsdf.rs `Bsdf::layer_pick`: the layer's Fresnel reflectance at ωₒ's incidence.
fn layer_pick(b: Bsdf, wo: vec3<f32>) -> f32 {
    return layer_fresnel(b, wo.z);
}

// bsdf.rs `Bsdf::eval`: f|cos θᵢ| (rgb) and the mixture density (w).
fn bsdf_eval(b: Bsdf, wo: vec3<f32>, wi: vec3<f32>) -> vec4<f32> {
    var f = vec3<f32>(0.0);
    var pdf = 0.0;
    if (b.diffuse > 0.0 && wi.z > 0.0) {
        if (b.layer_f0 > 0.0) {
            let h = normalize(wo + wi);
            let fresnel = layer_fresnel(b, dot(wo, h));
            let q = layer_pick(b, wo);
            f += b.diffuse * (1.0 - fresnel) * b.albedo * (wi.z / PI);
            pdf += b.diffuse * (1.0 - q) * wi.z / PI;
            if (b.alpha != 0.0) {
                let l = conductor_eval(wo, wi, b.alpha, vec3<f32>(b.layer_f0));
                f += b.diffuse * l.xyz;
                pdf += b.diffuse * q * l.w;
            }
        } else {
            f += b.diffuse * b.albedo * (wi.z / PI);
            pdf += b.diffuse * wi.z / PI;
        }
    }
    if (b.alpha != 0.0) {
        if (b.conductor > 0.0) {
            let c = conductor_eval(wo, wi, b.alpha, b.tint);
            f += b.conductor * c.xyz;
            pdf += b.conductor * c.w;
        }
        if (b.dielectric > 0.0) {
            let d = dielectric_eval(wo, wi, b.alpha, b.eta);
            f += vec3<f32>(b.dielectric * d.x);
            pdf += b.dielectric * d.y;
        }
    }
    return vec4<f32>(f, pdf);
}

fn absorbed() -> BsdfSample {
    return BsdfSample(vec3<f32>(0.0), vec3<f32>(0.0), 0.0, false, false);
}

fn delta_sample(wi: vec3<f32>, weight: vec3<f32>) -> BsdfSample {
    return BsdfSample(wi, weight, 0.0, true, true);
}

// bsdf.rs `Bsdf::sample`.
fn bsdf_sample(b: Bsdf, wo: vec3<f32>, u_lobe: f32, u: vec2<f32>) -> BsdfSample {
    var pick = u_lobe;
    var wi = vec3<f32>(0.0);
    if (pick < b.diffuse) {
        var q = 0.0;
        if (b.layer_f0 > 0.0) {
            q = layer_pick(b, wo);
        }
        if (pick < b.diffuse * q) {
            if (b.alpha == 0.0) {
                // F(ωₒ.z) / q = 1.
                return delta_sample(vec3<f32>(-wo.x, -wo.y, wo.z), vec3<f32>(1.0));
            }
            wi = reflect_about(wo, visible_normal(wo, b.alpha, u));
            if (!(wi.z > 0.0)) {
                return absorbed();
            }
        } else {
            wi = cosine_hemisphere(u);
        }
    } else {
        pick -= b.diffuse;
        if (pick < b.conductor) {
            if (b.alpha == 0.0) {
                return delta_sample(vec3<f32>(-wo.x, -wo.y, wo.z), schlick(b.tint, wo.z));
            }
            wi = reflect_about(wo, visible_normal(wo, b.alpha, u));
            if (!(wi.z > 0.0)) {
                return absorbed();
            }
        } else if (pick - b.conductor < b.dielectric) {
            if (b.alpha == 0.0) {
                let f = fresnel(wo.z, 1.0 / b.eta);
                if (u.x < f) {
                    return delta_sample(vec3<f32>(-wo.x, -wo.y, wo.z), vec3<f32>(1.0));
                }
                let r = refract_dir(-wo, vec3<f32>(0.0, 0.0, 1.0), 1.0 / b.eta);
                if (r.w == 0.0) {
                    return absorbed();
                }
                return delta_sample(r.xyz, vec3<f32>(1.0 / (b.eta * b.eta)));
            }
            let h = visible_normal(wo, b.alpha, u);
            let cos_o = dot(wo, h);
            if (cos_o <= 0.0) {
                return absorbed();
            }
            if ((pick - b.conductor) / b.dielectric < fresnel(cos_o, 1.0 / b.eta)) {
                wi = reflect_about(wo, h);
                if (!(wi.z > 0.0)) {
                    return absorbed();
                }
            } else {
                let r = refract_dir(-wo, h, 1.0 / b.eta);
                if (r.w == 0.0 || !(r.z < 0.0)) {
                    return absorbed();
                }
                wi = r.xyz;
            }
        } else {
            return absorbed();
        }
    }
    let e = bsdf_eval(b, wo, wi);
    if (!(e.w > 0.0) || all(e.xyz == vec3<f32>(0.0))) {
        return absorbed();
    }
    return BsdfSample(wi, e.xyz / e.w, e.w, false, true);
}
