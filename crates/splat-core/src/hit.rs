//! One ray against one particle: hit distance, maximum response along the ray, and the
//! negligible test of Eq. 2 (Sun et al. §3.1, Algorithm 1 lines 2–9; vk_gaussian_splatting Lighting §1.4.1).

use crate::kernel::KernelParams;
use crate::particle::Particle;
use glam::{Mat3, Vec3};

/// Default ray start (vk_gaussian_splatting `tMin`).
pub const DEFAULT_T_MIN: f32 = 0.001;
/// Default ray end (vk_gaussian_splatting `tMax`).
pub const DEFAULT_T_MAX: f32 = 10_000.0;

/// Where along the ray a particle is hit (Sun et al. §4.1).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum HitDistance {
    /// The point of maximum density along the ray, the mean of the 1D Gaussian:
    /// t = −o_c·d_c / d_c·d_c in canonical space (3DGRT, vk_gaussian_splatting Lighting §1.4.1).
    #[default]
    Mean,
    /// The particle centre projected on the view direction: the ray point on the plane through
    /// μ orthogonal to [`Ray::view`], t = (μ − o)·v / (d·v). For camera rays v is the camera's
    /// forward axis, so this is the rasterizer's billboard depth (vk_gaussian_splatting Lighting §1.4.2).
    /// Sun et al. §4.1 change only the distance: which particles are hit, and their α, are the
    /// mean convention's (Algorithm 1, lines 2–9). Defined for rays within 60° of the view axis
    /// ([`CENTER_VIEW_COS_MIN`]), which bounds how far from μ the point can lie.
    Center,
    /// The front face of the particle's icosahedron proxy (vk_gaussian_splatting Lighting
    /// §1.4.1, 3DGRT's `computeGaussianEnclosingIcosaHedron`): the regular icosahedron whose
    /// inscribed sphere is the particle's visible extent in canonical space, entered where the
    /// ray meets its first face after t_min (its back face when the ray starts inside). Which
    /// particles are hit, and their α, are the mean convention's (3DGRT evaluates the response
    /// at the maximum density point); only t, the sorting and picking distance, changes.
    Icosahedron,
}

/// The smallest cosine between a ray and its view axis at which [`HitDistance::Center`] takes a
/// hit (60°). A kept hit's ray passes through the visible ellipsoid, at a point q within R (its
/// largest semi-axis) of μ; the plane point q + s d, s = (μ − q)·v / (d·v), lies within R / cos
/// of q, so the BVH grows every particle's box by 2R under that convention
/// ([`crate::trace::bounding_box`]).
pub const CENTER_VIEW_COS_MIN: f32 = 0.5;

impl HitDistance {
    /// Every convention, in the order the front ends list them.
    pub const ALL: [HitDistance; 3] = [HitDistance::Mean, HitDistance::Center, HitDistance::Icosahedron];

    /// Its name on the command line and in the viewer.
    pub fn name(self) -> &'static str {
        match self {
            HitDistance::Mean => "mean",
            HitDistance::Center => "center",
            HitDistance::Icosahedron => "icosahedron",
        }
    }

    /// One line on what it is (the CLI's help).
    pub fn describe(self) -> &'static str {
        match self {
            HitDistance::Mean => "the maximum density along the ray (3DGRT, vk's AABB parametric mode)",
            HitDistance::Center => "the particle centre projected on the view direction (the 3DGS rasterizer's depth)",
            HitDistance::Icosahedron => "the front face of the icosahedron proxy (3DGRT's and vk's mesh mode)",
        }
    }
}

/// The 20 face planes of the regular icosahedron with vertices the cyclic permutations of
/// (±1, ±φ, 0) (3DGRT's vertex list): unit normals n along the vertices of the dual
/// dodecahedron, (±1, ±1, ±1) and the cyclic permutations of (0, ±φ, ±1/φ), each of length √3.
/// Scaled to inradius ρ, the solid is {x : nᵢ·x ≤ ρ for every i}.
pub const ICOSAHEDRON_NORMALS: [[f32; 3]; 20] = {
    const A: f32 = 0.577_350_26; // 1/√3
    const B: f32 = 0.934_172_36; // φ/√3
    const C: f32 = 0.356_822_1; // 1/(φ√3)
    [
        [A, A, A],
        [A, A, -A],
        [A, -A, A],
        [A, -A, -A],
        [-A, A, A],
        [-A, A, -A],
        [-A, -A, A],
        [-A, -A, -A],
        [0.0, B, C],
        [0.0, B, -C],
        [0.0, -B, C],
        [0.0, -B, -C],
        [C, 0.0, B],
        [-C, 0.0, B],
        [C, 0.0, -B],
        [-C, 0.0, -B],
        [B, C, 0.0],
        [B, -C, 0.0],
        [-B, C, 0.0],
        [-B, -C, 0.0],
    ]
};

/// Circumradius of the icosahedron of unit inradius, √3 √(10 + 2√5) / (2φ²) = 1.2584 (3DGRT's
/// vertices (±1, ±φ, 0) of length √(1 + φ²) times its `icosaVrtScale` √3/φ²). The ellipsoid of
/// this radius times the inradius holds the proxy, so the BVH bounds the particle by it.
pub const ICOSAHEDRON_CIRCUMRADIUS: f32 = 1.258_408_8;

/// The first crossing after `t_min` of the ray o + t d (canonical space) with the surface of the
/// icosahedron of inradius `rho` ([`ICOSAHEDRON_NORMALS`]): its entry, or its exit when the
/// entry lies at or before t_min; `None` when the ray misses it or crosses it only before t_min.
/// The slab method over the 20 face planes (Kay and Kajiya 1986).
pub fn icosahedron_crossing(o: Vec3, d: Vec3, rho: f32, t_min: f32) -> Option<f32> {
    let (mut enter, mut exit) = (f32::NEG_INFINITY, f32::INFINITY);
    for n in ICOSAHEDRON_NORMALS {
        let n = Vec3::from_array(n);
        let (num, den) = (rho - n.dot(o), n.dot(d));
        if den == 0.0 {
            if num < 0.0 {
                return None;
            }
        } else if den < 0.0 {
            enter = enter.max(num / den);
        } else {
            exit = exit.min(num / den);
        }
    }
    if enter > exit {
        return None;
    }
    if enter > t_min { Some(enter) } else { (exit > t_min).then_some(exit) }
}

/// A ray o + t d with its valid range (t_min, t_max).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Ray {
    /// Origin o.
    pub origin: Vec3,
    /// Unit direction d.
    pub dir: Vec3,
    /// Unit view direction v used by [`HitDistance::Center`]: the camera's forward axis for
    /// camera rays, the ray direction itself for other rays.
    pub view: Vec3,
    /// Hits at t ≤ t_min are ignored.
    pub t_min: f32,
    /// Hits at t ≥ t_max are ignored.
    pub t_max: f32,
}

impl Ray {
    /// A ray with the default range whose view direction is its own direction.
    pub fn new(origin: Vec3, dir: Vec3) -> Self {
        Self { origin, dir, view: dir, t_min: DEFAULT_T_MIN, t_max: DEFAULT_T_MAX }
    }

    /// The point o + t d.
    pub fn at(&self, t: f32) -> Vec3 {
        self.origin + t * self.dir
    }
}

/// A particle prepared for intersection: what the hot path needs, nothing else.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PreparedParticle {
    /// Mean μ.
    pub mean: Vec3,
    /// Canonical transform M = S⁻¹ Rᵀ.
    pub canonical: Mat3,
    /// Opacity.
    pub opacity: f32,
}

impl PreparedParticle {
    /// Precompute the canonical transform of a particle.
    pub fn new(p: &Particle) -> Self {
        Self { mean: p.mean, canonical: p.canonical_transform(), opacity: p.opacity }
    }
}

/// A ray–particle intersection that passed every test of Algorithm 1 except Russian roulette.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Hit {
    /// Hit distance t by the chosen [`HitDistance`].
    pub t: f32,
    /// alpha = opacity × max response along the ray, clamped and culled.
    pub alpha: f32,
    /// Index of the particle in its scene.
    pub index: u32,
}

/// The ray in the particle's canonical space: origin o_c = M (o − μ) and direction d_c = M d.
#[inline]
pub fn to_canonical(p: &PreparedParticle, ray: &Ray) -> (Vec3, Vec3) {
    (p.canonical * (ray.origin - p.mean), p.canonical * ray.dir)
}

/// Entry distance of the ray o + t d (canonical space) into the sphere |x|² = s², or `None` when
/// it misses. The discriminant b² − a c = a s² − |o × d|² is formed without cancellation (as
/// [`intersect`] forms d²_min): for a flat splat a = |d|² reaches 10⁷ and b² − a c
/// in f32 loses every digit, which gave entries outside the particle's box.
#[inline]
pub(crate) fn sphere_entry(o: Vec3, d: Vec3, s2: f32) -> Option<f32> {
    let a = d.length_squared();
    let disc = a * s2 - o.cross(d).length_squared();
    (disc >= 0.0).then(|| (-o.dot(d) - disc.sqrt()) / a)
}

/// Intersect one ray with one particle (Algorithm 1 without the roulette): the maximum response
/// along the ray gives alpha; the hit distance follows `convention`; the hit is dropped when
/// alpha is culled, t is outside (t_min, t_max), or the hit point lies outside the cutoff
/// ellipsoid (the negligible test of Eq. 2).
#[inline]
pub fn intersect(
    p: &PreparedParticle,
    index: u32,
    ray: &Ray,
    kernel: &KernelParams,
    convention: HitDistance,
) -> Option<Hit> {
    let (o_c, d_c) = to_canonical(p, ray);
    let dd = d_c.length_squared();
    // Squared distance of the line to the canonical origin: ‖o_c × d_c‖² / ‖d_c‖², the
    // minimum of ‖o_c + t d_c‖² over t, computed without cancellation.
    let d2_min = o_c.cross(d_c).length_squared() / dd;
    // Eq. 2 at the maximum density point, whatever the convention: a line outside the cutoff
    // ellipsoid is rejected before the exponential (most box hits of flat splats are).
    if d2_min > kernel.cutoff * kernel.cutoff {
        return None;
    }
    let alpha = kernel.alpha(p.opacity, kernel.response(d2_min))?;
    let t_mean = -o_c.dot(d_c) / dd;
    let t = match convention {
        HitDistance::Mean => t_mean,
        HitDistance::Icosahedron => icosahedron_crossing(o_c, d_c, kernel.visible_extent(p.opacity), ray.t_min)?,
        HitDistance::Center => {
            let dv = ray.dir.dot(ray.view);
            if dv < CENTER_VIEW_COS_MIN {
                return None;
            }
            (p.mean - ray.origin).dot(ray.view) / dv
        }
    };
    if !(t > ray.t_min && t < ray.t_max) {
        return None;
    }
    Some(Hit { t, alpha, index })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::SplitMix64;
    use approx::assert_relative_eq;
    use glam::Quat;

    fn particle(scale: Vec3, rotation: Quat, opacity: f32) -> PreparedParticle {
        PreparedParticle::new(&Particle::with_rgb(Vec3::ZERO, scale, rotation, opacity, Vec3::ONE))
    }

    #[test]
    fn ray_through_centre_hits_centre_with_unit_response() {
        let p = particle(Vec3::new(0.3, 2.0, 0.7), Quat::from_rotation_y(0.4), 0.8);
        let kernel = KernelParams { alpha_clamp: 1.0, ..Default::default() };
        let ray = Ray::new(Vec3::new(0.0, 0.0, -5.0), Vec3::Z);
        let hit = intersect(&p, 0, &ray, &kernel, HitDistance::Mean).unwrap();
        assert_relative_eq!(hit.t, 5.0, epsilon = 1e-5);
        assert_relative_eq!(hit.alpha, 0.8, epsilon = 1e-6);
        let hit = intersect(&p, 0, &ray, &kernel, HitDistance::Center).unwrap();
        assert_relative_eq!(hit.t, 5.0, epsilon = 1e-5);
    }

    #[test]
    fn offset_ray_response_matches_mahalanobis_distance() {
        // Axis-aligned, σx = 0.5: a ray along z at x = 0.5 is 1σ away → response e^−½.
        let p = particle(Vec3::new(0.5, 1.0, 1.0), Quat::IDENTITY, 1.0);
        let kernel = KernelParams { alpha_clamp: 1.0, ..Default::default() };
        let ray = Ray::new(Vec3::new(0.5, 0.0, -3.0), Vec3::Z);
        let hit = intersect(&p, 0, &ray, &kernel, HitDistance::Mean).unwrap();
        assert_relative_eq!(hit.alpha, (-0.5f32).exp(), epsilon = 1e-6);
    }

    #[test]
    fn hit_just_inside_and_outside_the_cutoff() {
        let p = particle(Vec3::ONE, Quat::IDENTITY, 1.0);
        let kernel = KernelParams { alpha_cull: 0.0, ..Default::default() };
        let inside = Ray::new(Vec3::new(2.99, 0.0, -5.0), Vec3::Z);
        let outside = Ray::new(Vec3::new(3.01, 0.0, -5.0), Vec3::Z);
        let hit = intersect(&p, 0, &inside, &kernel, HitDistance::Mean).unwrap();
        assert_relative_eq!(hit.alpha, (-0.5f32 * 2.99 * 2.99).exp(), max_relative = 1e-4);
        assert!(intersect(&p, 0, &outside, &kernel, HitDistance::Mean).is_none());
    }

    #[test]
    fn mean_is_the_max_density_point_for_an_oblique_ray() {
        // A thin tilted Gaussian: the max-density point is not the centre's projection.
        let p = particle(Vec3::new(1.0, 0.1, 1.0), Quat::from_rotation_z(0.7), 1.0);
        let kernel = KernelParams::default();
        let ray = Ray::new(Vec3::new(-3.0, 0.2, 0.0), Vec3::new(1.0, 0.0, 0.0));
        let hit = intersect(&p, 0, &ray, &kernel, HitDistance::Mean).unwrap();
        // Brute-force the density maximum along the ray.
        let cov_inv =
            Particle::with_rgb(Vec3::ZERO, Vec3::new(1.0, 0.1, 1.0), Quat::from_rotation_z(0.7), 1.0, Vec3::ONE)
                .covariance_inverse();
        let best = (0..60_000)
            .map(|i| i as f32 * 1e-4)
            .min_by(|&a, &b| {
                let q = |t: f32| {
                    let x = ray.at(t);
                    x.dot(cov_inv * x)
                };
                q(a).total_cmp(&q(b))
            })
            .unwrap();
        assert_relative_eq!(hit.t, best, epsilon = 1e-3);
        let center = intersect(&p, 0, &ray, &kernel, HitDistance::Center).map(|h| h.t);
        assert_relative_eq!(center.unwrap(), 3.0, epsilon = 1e-5);
    }

    #[test]
    fn range_limits_are_exclusive() {
        let p = particle(Vec3::ONE, Quat::IDENTITY, 1.0);
        let mut ray = Ray::new(Vec3::new(0.0, 0.0, -2.0), Vec3::Z);
        let k = KernelParams::default();
        ray.t_max = 2.0;
        assert!(intersect(&p, 0, &ray, &k, HitDistance::Mean).is_none());
        ray.t_max = 2.001;
        assert!(intersect(&p, 0, &ray, &k, HitDistance::Mean).is_some());
        ray.t_min = 2.0;
        assert!(intersect(&p, 0, &ray, &k, HitDistance::Mean).is_none());
    }

    /// Entries into the cutoff sphere agree with an f64 reference for rays through flat splats
    /// (canonical directions stretched 10⁴ times along one axis, as a splat with scales 0.1 and
    /// 10⁻⁵ makes them): a miss is never reported as a hit, which the textbook b² − a c did.
    #[test]
    fn ellipsoid_entries_of_flat_splats_match_f64() {
        let mut rng = SplitMix64::new(5);
        let (mut hits, mut misses) = (0, 0);
        for _ in 0..20_000 {
            let o = Vec3::new(rng.range(-4.0, 4.0), rng.range(-4.0, 4.0), rng.range(-4e4, 4e4));
            let d = Vec3::new(rng.range(-1.0, 1.0), rng.range(-1.0, 1.0), rng.range(-1e4, 1e4));
            let (od, dd) = (o.as_dvec3(), d.as_dvec3());
            let disc = dd.length_squared() * 9.0 - od.cross(dd).length_squared();
            let margin = disc / (dd.length_squared() * 9.0);
            match sphere_entry(o, d, 9.0) {
                Some(t) if margin > 1e-3 => {
                    let t64 = (-od.dot(dd) - disc.sqrt()) / dd.length_squared();
                    assert!((f64::from(t) - t64).abs() <= 1e-3 * (1.0 + t64.abs()), "t {t} vs {t64}");
                    hits += 1;
                }
                None if margin < -1e-3 => misses += 1,
                Some(t) if margin < -1e-3 => panic!("a miss (margin {margin}) reported as a hit at t = {t}"),
                None if margin > 1e-3 => panic!("a hit (margin {margin}) reported as a miss"),
                _ => {}
            }
        }
        assert!(hits > 1000 && misses > 1000, "{hits} hits, {misses} misses");
    }

    /// 3DGRT's icosahedron as it builds it (`particlePrimitives.cu`: 12 vertices, 20
    /// triangles, vertices scaled by `icosaVrtScale` for an inscribed unit sphere), intersected
    /// triangle by triangle (Möller–Trumbore, both faces): an independent port that the slab
    /// method over [`ICOSAHEDRON_NORMALS`] must reproduce, entry and exit, on random rays.
    #[test]
    fn the_proxy_is_3dgrt_icosahedron() {
        let phi = 1.618_033_988_749_895_f64;
        let scale = 0.5 * 1.323_169_076_499_215_f64;
        let v: Vec<glam::DVec3> = [
            (-1.0, phi, 0.0),
            (1.0, phi, 0.0),
            (0.0, 1.0, -phi),
            (-phi, 0.0, -1.0),
            (-phi, 0.0, 1.0),
            (0.0, 1.0, phi),
            (phi, 0.0, 1.0),
            (0.0, -1.0, phi),
            (-1.0, -phi, 0.0),
            (0.0, -1.0, -phi),
            (phi, 0.0, -1.0),
            (1.0, -phi, 0.0),
        ]
        .iter()
        .map(|&(x, y, z)| glam::DVec3::new(x, y, z) * scale)
        .collect();
        let tris = [
            [0, 1, 2],
            [0, 2, 3],
            [0, 3, 4],
            [0, 4, 5],
            [0, 5, 1],
            [6, 1, 5],
            [6, 5, 7],
            [6, 7, 11],
            [6, 11, 10],
            [6, 10, 1],
            [8, 4, 3],
            [8, 3, 9],
            [8, 9, 11],
            [8, 11, 7],
            [8, 7, 4],
            [9, 3, 2],
            [9, 2, 10],
            [9, 10, 11],
            [5, 4, 7],
            [1, 10, 2],
        ];
        // Every vertex at the circumradius; every face at distance 1 from the centre.
        for p in &v {
            assert!((p.length() - f64::from(ICOSAHEDRON_CIRCUMRADIUS)).abs() < 1e-6, "{p}");
        }
        let crossings = |o: glam::DVec3, d: glam::DVec3| -> Vec<f64> {
            let mut ts: Vec<f64> = tris
                .iter()
                .filter_map(|t| {
                    let (a, b, c) = (v[t[0]], v[t[1]], v[t[2]]);
                    let (e1, e2) = (b - a, c - a);
                    let p = d.cross(e2);
                    let det = e1.dot(p);
                    if det.abs() < 1e-12 {
                        return None;
                    }
                    let s = o - a;
                    let u = s.dot(p) / det;
                    let q = s.cross(e1);
                    let w = d.dot(q) / det;
                    (u >= 0.0 && w >= 0.0 && u + w <= 1.0).then(|| e2.dot(q) / det)
                })
                .collect();
            ts.sort_by(f64::total_cmp);
            ts
        };
        let mut rng = SplitMix64::new(5);
        let (mut hits, mut inside) = (0, 0);
        for _ in 0..4000 {
            let o = Vec3::new(rng.range(-2.5, 2.5), rng.range(-2.5, 2.5), rng.range(-2.5, 2.5));
            let d = Vec3::new(rng.range(-1.0, 1.0), rng.range(-1.0, 1.0), rng.range(-1.0, 1.0));
            let rho = rng.range(0.5, 2.0);
            let ts = crossings(o.as_dvec3() / f64::from(rho), d.as_dvec3() / f64::from(rho));
            // The first crossing after t_min = 0 (edges and vertices give a crossing twice).
            let expected = ts.iter().find(|&&t| t > 1e-9).copied();
            let got = icosahedron_crossing(o, d, rho, 0.0);
            match (expected, got) {
                (Some(e), Some(g)) => {
                    assert!((e - f64::from(g)).abs() < 2e-4 * e.abs().max(1.0), "o {o} d {d} ρ {rho}: {e} ≠ {g}");
                    hits += 1;
                    inside += usize::from(ts[0] <= 0.0);
                }
                (None, None) => {}
                // A ray grazing an edge or vertex within f32 rounding may count on one side only.
                (e, g) => {
                    let near = e.or(g.map(f64::from)).unwrap();
                    let x = o.as_dvec3() + near * d.as_dvec3();
                    let depth = ICOSAHEDRON_NORMALS
                        .iter()
                        .map(|n| glam::DVec3::from_array(n.map(f64::from)).dot(x) - f64::from(rho))
                        .fold(f64::NEG_INFINITY, f64::max);
                    assert!(depth.abs() < 1e-4, "o {o} d {d} ρ {rho}: {e:?} against {g:?}");
                }
            }
        }
        assert!(hits > 600 && inside > 100, "{hits} rays hit, {inside} from inside");
    }

    /// The proxy's crossing changes t only: the hit and its α are the mean convention's, and t
    /// lies before the maximum density point, on the proxy around the visible ellipsoid.
    #[test]
    fn the_icosahedron_changes_the_distance_only() {
        let p = particle(Vec3::new(0.3, 1.2, 0.5), Quat::from_rotation_y(0.7), 0.6);
        let kernel = KernelParams::default();
        let mut rng = SplitMix64::new(9);
        let mut hits = 0;
        for _ in 0..2000 {
            let origin = Vec3::new(rng.range(-1.0, 1.0), rng.range(-1.0, 1.0), -6.0);
            let dir = (Vec3::new(rng.range(-0.5, 0.5), rng.range(-0.5, 0.5), 0.0) - origin).normalize();
            let ray = Ray::new(origin, dir);
            let mean = intersect(&p, 0, &ray, &kernel, HitDistance::Mean);
            let ico = intersect(&p, 0, &ray, &kernel, HitDistance::Icosahedron);
            assert_eq!(mean.is_some(), ico.is_some());
            if let (Some(m), Some(i)) = (mean, ico) {
                assert_eq!(m.alpha, i.alpha);
                assert!(i.t < m.t, "the proxy's front face {} lies before the maximum density {}", i.t, m.t);
                let (o, d) = to_canonical(&p, &ray);
                let r = (o + i.t * d).length();
                let rho = kernel.visible_extent(p.opacity);
                assert!(r >= rho * 0.999 && r <= rho * ICOSAHEDRON_CIRCUMRADIUS * 1.001, "|x_c| {r} for ρ {rho}");
                hits += 1;
            }
        }
        assert!(hits > 200, "{hits} hits");
    }

    /// Sun et al. §4.1 change only the distance: the centre convention hits exactly the
    /// particles the mean convention hits, with their α, including oblique rays whose point on
    /// the centre's plane lies outside the cutoff ellipsoid (which the convention used to cull);
    /// t is the plane's.
    #[test]
    fn the_centre_convention_keeps_the_mean_conventions_hits() {
        let p = particle(Vec3::new(0.05, 1.0, 0.4), Quat::from_rotation_x(1.1), 0.9);
        let kernel = KernelParams::default();
        let mut rng = SplitMix64::new(4);
        let (mut hits, mut outside) = (0, 0);
        for _ in 0..4000 {
            let origin = Vec3::new(rng.range(-2.0, 2.0), rng.range(-2.0, 2.0), -4.0);
            let dir =
                (Vec3::new(rng.range(-0.3, 0.3), rng.range(-1.5, 1.5), rng.range(-0.5, 0.5)) - origin).normalize();
            let ray = Ray { view: Vec3::Z, ..Ray::new(origin, dir) };
            let mean = intersect(&p, 0, &ray, &kernel, HitDistance::Mean);
            let center = intersect(&p, 0, &ray, &kernel, HitDistance::Center);
            assert!(dir.z >= CENTER_VIEW_COS_MIN, "a ray within the convention's cone");
            assert_eq!(mean.map(|h| h.alpha), center.map(|h| h.alpha), "ray {ray:?}");
            if let Some(c) = center {
                assert!(((origin + c.t * dir).z - p.mean.z).abs() < 1e-4, "on the centre's plane");
                let (o, d) = to_canonical(&p, &ray);
                outside += usize::from((o + c.t * d).length() > kernel.cutoff);
                hits += 1;
            }
        }
        assert!(hits > 300 && outside > 20, "{hits} hits, {outside} with the plane point outside the cutoff");
    }

    #[test]
    fn a_camera_wider_than_the_centre_convention_is_refused() {
        let (_, camera) = crate::scenes::cloud();
        let wide = crate::Camera { fx: 0.2 * camera.fx, fy: 0.2 * camera.fy, ..camera };
        let settings = crate::RenderSettings { hit_distance: HitDistance::Center, ..Default::default() };
        assert!(crate::trace::check_camera(&settings, &camera).is_ok());
        let e = crate::trace::check_camera(&settings, &wide).unwrap_err().to_string();
        assert!(e.contains("within 60° of the view axis") && e.contains("mean hit distance"), "{e}");
        let mean = crate::RenderSettings::default();
        assert!(crate::trace::check_camera(&mean, &wide).is_ok());
    }
}
