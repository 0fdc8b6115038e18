//! Opaque triangle meshes beside the splats (the vk_gaussian_splatting documentation, "Lighting,
//! Shading and Shadows" §3–§5; Sun et al. 2025, Figs. 1 and 5): geometry, materials with mirror
//! and glass bounces, and the triangle BVH the ray tracer clips its rays with.
//!
//! A ray meets the meshes before the splats: the closest triangle hit at t_s ends the splat
//! segment, so every method composites (or samples) the splats in (t_min, t_s) exactly as it
//! would over a background, and the background's place is taken by the surface's shaded colour
//! S. The expectation is Eq. 3 over the splats in front of the surface plus their
//! transmittance times S:
//!
//! ```text
//! C = Σ_{tᵢ < t_s} Tᵢ αᵢ cᵢ + T(t_s) S,     T(t_s) = Π_{tᵢ < t_s} (1 − αᵢ).
//! ```
//!
//! S is the mesh material's Blinn–Phong colour ([`crate::lighting`]) weighted by
//! 1 − mirror − transmission, plus `mirror` times the radiance of the reflected ray and
//! `transmission` times Fresnel's mix of the reflected and refracted rays ([`fresnel`]), each
//! secondary ray traced through the splats by the same method, up to
//! [`crate::RenderSettings::max_bounces`].
//!
//! The meshes have their own BVH beside the splats' (over triangle boxes, the same builder):
//! splat leaves carry prepared particles, alpha bounds and ids in leaf order that a triangle has
//! no use for, and the mesh traversal, done first, hands the splat traversal its tightest t_max
//! from the start.

use crate::bvh::Bvh4;
use crate::hit::Ray;
use crate::lighting::Material;
use crate::particle::Aabb;
use glam::{Affine3A, Mat3, Vec3};

/// A triangle mesh: positions, optional per-vertex normals (empty for flat shading), optional
/// per-vertex opacities (an opacity texture sampled at the vertices, interpolated across each
/// triangle) and counter-clockwise triangles (seen from outside).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct TriangleMesh {
    /// Vertex positions.
    pub positions: Vec<Vec3>,
    /// Per-vertex unit normals, one per position, or empty for face normals.
    pub normals: Vec<Vec3>,
    /// Per-vertex opacities in [0, 1], one per position, or empty for 1; multiplied by the
    /// material's [`MeshMaterial::opacity`].
    pub opacities: Vec<f32>,
    /// Vertex indices of each triangle.
    pub triangles: Vec<[u32; 3]>,
}

impl TriangleMesh {
    /// Check that indices are in range, values finite and normals one per vertex.
    pub fn validate(&self) -> Result<(), String> {
        if let Some(i) = self.positions.iter().position(|p| !p.is_finite()) {
            return Err(format!("vertex {i} has a non-finite position {}", self.positions[i]));
        }
        if !self.normals.is_empty() {
            if self.normals.len() != self.positions.len() {
                return Err(format!("{} normals for {} vertices", self.normals.len(), self.positions.len()));
            }
            if let Some(i) = self.normals.iter().position(|n| !n.is_finite()) {
                return Err(format!("vertex {i} has a non-finite normal {}", self.normals[i]));
            }
        }
        if !self.opacities.is_empty() {
            if self.opacities.len() != self.positions.len() {
                return Err(format!("{} opacities for {} vertices", self.opacities.len(), self.positions.len()));
            }
            if let Some(i) = self.opacities.iter().position(|a| !(0.0..=1.0).contains(a)) {
                return Err(format!("vertex {i} has opacity {}, outside [0, 1]", self.opacities[i]));
            }
        }
        let n = self.positions.len() as u32;
        if let Some((i, t)) = self.triangles.iter().enumerate().find(|(_, t)| t.iter().any(|&v| v >= n)) {
            return Err(format!("triangle {i} indexes vertex {} of {n}", t.iter().max().unwrap()));
        }
        Ok(())
    }

    /// The square [−1, 1]² in the xz plane (y = 0), facing +y.
    pub fn plane() -> Self {
        let positions = vec![
            Vec3::new(-1.0, 0.0, -1.0),
            Vec3::new(-1.0, 0.0, 1.0),
            Vec3::new(1.0, 0.0, 1.0),
            Vec3::new(1.0, 0.0, -1.0),
        ];
        Self { normals: vec![Vec3::Y; 4], positions, triangles: vec![[0, 1, 2], [0, 2, 3]], ..Self::default() }
    }

    /// The cube [−1, 1]³, four vertices per face so that faces stay flat.
    pub fn cube() -> Self {
        let mut mesh = Self::default();
        for axis in 0..3 {
            for sign in [-1.0f32, 1.0] {
                let n = Vec3::AXES[axis] * sign;
                let (u, v) = (Vec3::AXES[(axis + 1) % 3], Vec3::AXES[(axis + 2) % 3] * sign);
                let base = mesh.positions.len() as u32;
                for (a, b) in [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)] {
                    mesh.positions.push(n + a * u + b * v);
                    mesh.normals.push(n);
                }
                mesh.triangles.extend([[base, base + 1, base + 2], [base, base + 2, base + 3]]);
            }
        }
        mesh
    }

    /// The unit sphere as a UV sphere of `segments` around and `rings` from pole to pole, with
    /// smooth normals.
    pub fn sphere(segments: u32, rings: u32) -> Self {
        let (segments, rings) = (segments.max(3), rings.max(2));
        let mut mesh = Self::default();
        for r in 0..=rings {
            let theta = std::f32::consts::PI * r as f32 / rings as f32;
            for s in 0..=segments {
                let phi = std::f32::consts::TAU * s as f32 / segments as f32;
                let p = Vec3::new(theta.sin() * phi.cos(), theta.cos(), -theta.sin() * phi.sin());
                mesh.positions.push(p);
                mesh.normals.push(p);
            }
        }
        let row = segments + 1;
        for r in 0..rings {
            for s in 0..segments {
                let (a, b) = (r * row + s, (r + 1) * row + s);
                if r > 0 {
                    mesh.triangles.push([a, b, a + 1]);
                }
                if r + 1 < rings {
                    mesh.triangles.push([a + 1, b, b + 1]);
                }
            }
        }
        mesh
    }

    /// The mesh under the affine map `m` (normals by the inverse transpose; a mirroring map
    /// also flips the winding so that triangles keep facing out).
    pub fn transformed(&self, m: Affine3A) -> Self {
        let linear = Mat3::from(m.matrix3);
        let normal_map = linear.inverse().transpose();
        let mut triangles = self.triangles.clone();
        if linear.determinant() < 0.0 {
            triangles.iter_mut().for_each(|t| t.swap(1, 2));
        }
        Self {
            positions: self.positions.iter().map(|&p| m.transform_point3(p)).collect(),
            normals: self.normals.iter().map(|&n| (normal_map * n).normalize_or_zero()).collect(),
            opacities: self.opacities.clone(),
            triangles,
        }
    }

    /// The bounding box of the vertices.
    pub fn bounds(&self) -> Aabb {
        self.positions.iter().fold(Aabb::EMPTY, |b, &p| b.union(Aabb { min: p, max: p }))
    }
}

/// How a mesh surface answers light: its base colour lit by the splats' material model, and the
/// share of light it passes to a mirror reflection or through a dielectric.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MeshMaterial {
    /// Base colour c of [`Material::shade`].
    pub color: Vec3,
    /// Emissive, ambient, diffuse and specular shares (the splat material model).
    pub shading: Material,
    /// Share of the radiance taken from the perfect mirror reflection.
    pub mirror: f32,
    /// Reflectance F₀ of the mirror share at normal incidence, rising to 1 at grazing angles by
    /// Schlick's approximation ([`schlick`]): a metal's colour (glTF's base colour of a metallic
    /// material, whose conductor Fresnel this is). 1, the default, is an untinted mirror.
    pub mirror_tint: Vec3,
    /// Share of the radiance taken from a smooth dielectric: Fresnel's mix of the reflected and
    /// refracted rays.
    pub transmission: f32,
    /// Index of refraction of the dielectric (outside is 1).
    pub ior: f32,
    /// GGX roughness of the mirror and glass shares in the path tracer ([`crate::path`]; 0 is
    /// perfectly smooth). The ray-tracing and raster pipelines treat both shares as smooth.
    pub roughness: f32,
    /// Whether the path tracer puts a dielectric specular layer over the local share, as glTF's
    /// non-metals have (glTF 2.0 Appendix B, `fresnel_mix`): Schlick's F of F₀ =
    /// ((ior − 1)/(ior + 1))² ([`MeshMaterial::layer_f0`]) reflected by a GGX lobe of the
    /// material's roughness, 1 − F passed to the Lambertian base. The ray-tracing and raster
    /// pipelines' Blinn–Phong specular term is their stand-in for it.
    pub specular_layer: bool,
    /// Opacity α ∈ (0, 1] of the surface (times the mesh's per-vertex opacities): a transparent
    /// surface is one more layer of Eq. 3, α S over what lies behind it with weight 1 − α
    /// (Laine & Karras 2011's primitives of constant opacity). 1: opaque.
    pub opacity: f32,
}

impl Default for MeshMaterial {
    /// A grey diffuse surface with a little ambient light.
    fn default() -> Self {
        Self {
            color: Vec3::splat(0.8),
            shading: Material::DIFFUSE,
            mirror: 0.0,
            mirror_tint: Vec3::ONE,
            transmission: 0.0,
            ior: 1.5,
            roughness: 0.0,
            specular_layer: false,
            opacity: 1.0,
        }
    }
}

impl MeshMaterial {
    /// Check colours, shares (each in [0, 1], summing to at most 1) and index (finite, > 0).
    pub fn validate(&self) -> Result<(), String> {
        self.shading.validate()?;
        if !self.color.is_finite() || self.color.min_element() < 0.0 {
            return Err(format!("mesh colour {} must be finite and non-negative", self.color));
        }
        let tint = self.mirror_tint;
        if !(tint.is_finite() && tint.min_element() >= 0.0 && tint.max_element() <= 1.0) {
            return Err(format!("mirror tint {} must lie in [0, 1]", self.mirror_tint));
        }
        let shares = [self.mirror, self.transmission];
        if shares.iter().any(|s| !(0.0..=1.0).contains(s)) || self.mirror + self.transmission > 1.0 {
            return Err(format!(
                "mirror {} and transmission {} must lie in [0, 1] and sum to at most 1",
                self.mirror, self.transmission
            ));
        }
        if !(self.ior.is_finite() && self.ior > 0.0) {
            return Err(format!("index of refraction {} must be finite and positive", self.ior));
        }
        if !(0.0..=1.0).contains(&self.roughness) {
            return Err(format!("roughness {} must lie in [0, 1]", self.roughness));
        }
        if !(self.opacity > 0.0 && self.opacity <= 1.0) {
            return Err(format!("opacity {} must lie in (0, 1]", self.opacity));
        }
        Ok(())
    }

    /// The weight of the locally lit colour: 1 − mirror − transmission.
    pub fn local_share(&self) -> f32 {
        (1.0 - self.mirror - self.transmission).max(0.0)
    }

    /// What a forward-shaded surface (the raster pipelines') takes from the background for a
    /// ray meeting it at `cos_i` to its normal: its mirror share, times F(cos θᵢ), and its glass
    /// share, which see nothing else there.
    pub fn background_share(&self, cos_i: f32) -> Vec3 {
        self.mirror_reflectance(cos_i) + Vec3::splat(self.transmission)
    }

    /// F₀ of the specular layer: ((ior − 1)/(ior + 1))² with one, 0 without.
    pub fn layer_f0(&self) -> f32 {
        let r = (self.ior - 1.0) / (self.ior + 1.0);
        if self.specular_layer { r * r } else { 0.0 }
    }

    /// What the mirror share reflects of a ray meeting the surface at `cos_i` to its normal:
    /// mirror × F(cos θᵢ), [`schlick`] of [`MeshMaterial::mirror_tint`].
    pub fn mirror_reflectance(&self, cos_i: f32) -> Vec3 {
        self.mirror * schlick(self.mirror_tint, cos_i)
    }
}

/// Barycentric slack of the edge tests: a ray through the edge two triangles share hits at
/// least one of them despite rounding (Möller–Trumbore alone is not watertight; a hit just
/// outside the edge lands on the neighbour's plane, so two hits there agree).
pub const EDGE_SLACK: f32 = 1e-6;

/// One triangle ready for intersection: a vertex, two edges, the vertex normals and its mesh.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PreparedTriangle {
    /// Vertex p₀.
    pub p0: Vec3,
    /// p₁ − p₀.
    pub e1: Vec3,
    /// p₂ − p₀.
    pub e2: Vec3,
    /// Vertex normals (all three the face normal for flat meshes).
    pub normals: [Vec3; 3],
    /// Vertex opacities: the mesh's per-vertex opacities times its material's.
    pub alphas: [f32; 3],
    /// Index of its mesh (its material).
    pub mesh: u32,
    /// Its place in the order the meshes list their triangles (the draw order of the
    /// stochastic raster methods, and the id that keys a transparent triangle's decisions).
    pub order: u32,
}

impl PreparedTriangle {
    /// The unit face normal, (e₁ × e₂)/|e₁ × e₂|: outward for counter-clockwise triangles.
    pub fn face_normal(&self) -> Vec3 {
        self.e1.cross(self.e2).normalize_or_zero()
    }

    /// Whether any part of it lets light through (an opacity below 1).
    pub fn is_transparent(&self) -> bool {
        self.alphas.iter().any(|&a| a < 1.0)
    }

    /// The opacity at barycentrics (b₁, b₂), clamped to [0, 1] (a point outside the triangle
    /// extrapolates the interpolation, as a rasterizer's attribute at a pixel centre does); a
    /// constant opacity exactly, so that an opaque triangle stays opaque.
    pub fn alpha_at(&self, b1: f32, b2: f32) -> f32 {
        let [a0, a1, a2] = self.alphas;
        if a0 == a1 && a1 == a2 {
            return a0; // exactly, where the interpolation's rounding would leave 1 − 6·10⁻⁸
        }
        ((1.0 - b1 - b2) * a0 + b1 * a1 + b2 * a2).clamp(0.0, 1.0)
    }

    /// The barycentrics (b₁, b₂) where the ray's line meets the triangle's plane, inside the
    /// triangle or not; `None` when the ray runs parallel to it.
    pub fn plane_barycentrics(&self, ray: &Ray) -> Option<(f32, f32)> {
        let p = ray.dir.cross(self.e2);
        let det = self.e1.dot(p);
        if det.abs() < 1e-12 {
            return None;
        }
        let s = ray.origin - self.p0;
        Some((s.dot(p) / det, ray.dir.dot(s.cross(self.e1)) / det))
    }

    /// [`PreparedTriangle::intersect`] with each edge shared by two triangles counted once: a
    /// crossing within [`EDGE_SLACK`] of an edge belongs to the triangle that runs along that
    /// edge in its canonical direction. What a transparent surface needs (the slack alone would
    /// count a ray through the edge twice, two layers where there is one); an opaque surface
    /// takes the closest hit and needs no rule.
    #[inline]
    pub fn crosses(&self, ray: &Ray) -> Option<(f32, f32, f32)> {
        self.intersect(ray).filter(|&(_, b1, b2)| self.owns(b1, b2))
    }

    /// Whether a crossing at barycentrics (b₁, b₂) belongs to this triangle
    /// ([`PreparedTriangle::crosses`]): inside it beyond the edge slack, or within the slack of
    /// an edge that it runs along in the canonical direction.
    #[inline]
    pub fn owns(&self, b1: f32, b2: f32) -> bool {
        // The edge opposite each vertex: p₁ → p₂, p₂ → p₀, p₀ → p₁.
        let edges = [(1.0 - b1 - b2, self.e2 - self.e1), (b1, -self.e2), (b2, self.e1)];
        edges.iter().all(|&(b, edge)| b > EDGE_SLACK || canonical(edge))
    }

    /// Möller–Trumbore: (t, b₁, b₂) where the ray crosses the triangle within (t_min, t_max).
    #[inline]
    pub fn intersect(&self, ray: &Ray) -> Option<(f32, f32, f32)> {
        let p = ray.dir.cross(self.e2);
        let det = self.e1.dot(p);
        if det.abs() < 1e-12 {
            return None;
        }
        let inv = 1.0 / det;
        let s = ray.origin - self.p0;
        let b1 = s.dot(p) * inv;
        if !(-EDGE_SLACK..=1.0 + EDGE_SLACK).contains(&b1) {
            return None;
        }
        let q = s.cross(self.e1);
        let b2 = ray.dir.dot(q) * inv;
        if b2 < -EDGE_SLACK || b1 + b2 > 1.0 + EDGE_SLACK {
            return None;
        }
        let t = self.e2.dot(q) * inv;
        (t > ray.t_min && t < ray.t_max).then_some((t, b1, b2))
    }
}

/// Whether edge direction `d` is the canonical one of its two (its first non-zero coordinate
/// positive): the two triangles sharing an edge run along it in opposite directions, so exactly
/// one of them sees it canonical.
fn canonical(d: Vec3) -> bool {
    if d.x != 0.0 {
        d.x > 0.0
    } else if d.y != 0.0 {
        d.y > 0.0
    } else {
        d.z > 0.0
    }
}

/// Where a ray meets a mesh.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SurfaceHit {
    /// Distance along the ray.
    pub t: f32,
    /// Leaf-order index of the triangle.
    pub triangle: u32,
    /// Index of the mesh (its material).
    pub mesh: u32,
    /// Unit outward face normal.
    pub face_normal: Vec3,
    /// Unit interpolated shading normal, outward.
    pub normal: Vec3,
    /// Opacity at the hit ([`PreparedTriangle::alpha_at`]).
    pub alpha: f32,
}

impl SurfaceHit {
    /// The face and shading normals turned toward a ray of unit direction `d` (the shading
    /// normal falls back to the face normal where interpolation turns it away), and whether the
    /// ray arrives from outside (against the outward face normal).
    pub fn facing(&self, d: Vec3) -> (Vec3, Vec3, bool) {
        let outside = d.dot(self.face_normal) < 0.0;
        let side = if outside { 1.0 } else { -1.0 };
        let (face, n) = (side * self.face_normal, side * self.normal);
        (face, if n.dot(d) < 0.0 { n } else { face }, outside)
    }
}

/// Every mesh of a world, with its material, in one triangle BVH.
#[derive(Clone, Debug, Default)]
pub struct Meshes {
    triangles: Vec<PreparedTriangle>,
    materials: Vec<MeshMaterial>,
    /// Whether any triangle is transparent.
    transparent: bool,
    bvh: Bvh4,
}

/// Most triangles of a world's meshes (the BVH's index range).
pub const MAX_TRIANGLES: usize = crate::bvh::MAX_PRIMITIVES;

impl Meshes {
    /// No meshes: rays see the background behind the splats.
    pub fn none() -> Self {
        Self::default()
    }

    /// Validate each mesh and material, prepare the triangles and build their BVH.
    pub fn new(meshes: &[(TriangleMesh, MeshMaterial)]) -> Result<Self, String> {
        let mut prepared = Vec::new();
        for (i, (mesh, material)) in meshes.iter().enumerate() {
            mesh.validate().map_err(|e| format!("mesh {i}: {e}"))?;
            material.validate().map_err(|e| format!("mesh {i}: {e}"))?;
            for &[a, b, c] in &mesh.triangles {
                let p = [a, b, c].map(|v| mesh.positions[v as usize]);
                let (e1, e2) = (p[1] - p[0], p[2] - p[0]);
                let face = e1.cross(e2).normalize_or_zero();
                if face == Vec3::ZERO {
                    continue; // degenerate: no ray can hit it
                }
                let normals = if mesh.normals.is_empty() {
                    [face; 3]
                } else {
                    [a, b, c].map(|v| mesh.normals[v as usize].try_normalize().unwrap_or(face))
                };
                let alphas =
                    [a, b, c].map(|v| material.opacity * mesh.opacities.get(v as usize).copied().unwrap_or(1.0));
                let order = prepared.len() as u32;
                prepared.push(PreparedTriangle { p0: p[0], e1, e2, normals, alphas, mesh: i as u32, order });
            }
        }
        if prepared.len() > MAX_TRIANGLES {
            return Err(format!("{} triangles exceed the {MAX_TRIANGLES} a BVH can index", prepared.len()));
        }
        let boxes: Vec<Aabb> = prepared
            .iter()
            .map(|t| {
                let b = [t.p0, t.p0 + t.e1, t.p0 + t.e2];
                Aabb { min: b[0].min(b[1]).min(b[2]), max: b[0].max(b[1]).max(b[2]) }.padded()
            })
            .collect();
        let (bvh, order) = Bvh4::build(boxes, "triangles")?;
        let triangles: Vec<PreparedTriangle> = order.iter().map(|&i| prepared[i as usize]).collect();
        let transparent = triangles.iter().any(PreparedTriangle::is_transparent);
        Ok(Self { triangles, materials: meshes.iter().map(|m| m.1).collect(), transparent, bvh })
    }

    /// Whether there are no triangles.
    pub fn is_empty(&self) -> bool {
        self.triangles.is_empty()
    }

    /// Whether any triangle lets light through ([`MeshMaterial::opacity`] or a per-vertex
    /// opacity below 1).
    pub fn has_transparent(&self) -> bool {
        self.transparent
    }

    /// Triangles in BVH leaf order (what a GPU uploads beside [`Meshes::bvh`]).
    pub fn triangles(&self) -> &[PreparedTriangle] {
        &self.triangles
    }

    /// The 4-wide BVH over the triangles, which both backends traverse.
    pub fn bvh(&self) -> &Bvh4 {
        &self.bvh
    }

    /// The material of each mesh.
    pub fn materials(&self) -> &[MeshMaterial] {
        &self.materials
    }

    /// The material of mesh `mesh`.
    pub fn material(&self, mesh: u32) -> &MeshMaterial {
        &self.materials[mesh as usize]
    }

    /// The closest triangle the ray crosses within (t_min, t_max), transparent or not; ties go
    /// to the lower leaf-order index, so the answer does not depend on traversal order.
    pub fn closest(&self, ray: &Ray) -> Option<SurfaceHit> {
        self.closest_where(ray, |_, _, _| true)
    }

    /// The closest opaque triangle (what the raster pipeline's depth pre-pass draws; the
    /// transparent ones are fragments, [`Meshes::transparent_hits`]).
    pub fn closest_opaque(&self, ray: &Ray) -> Option<SurfaceHit> {
        if !self.transparent {
            return self.closest(ray);
        }
        self.closest_where(ray, |tri, _, _| !tri.is_transparent())
    }

    /// The closest triangle the ray meets that stops it: an opaque one wherever it crosses it, a
    /// transparent one where it [crosses](PreparedTriangle::crosses) it (each crossing of an
    /// edge counted once) and `accept(order, α)` takes the crossing, given the triangle's place
    /// in the meshes' order ([`PreparedTriangle::order`], which keys its decisions) and its
    /// opacity there. With `accept` true with probability α, independently for each triangle,
    /// this is Algorithm 1 of Sun et al. 2025 over the triangles: the closest accepted surface,
    /// whose expectation over the decisions composites the surfaces by Eq. 3 (the path tracer's
    /// transparent meshes). Ties go to the lower leaf-order index, as in [`Meshes::closest`].
    pub fn closest_accepted(&self, ray: &Ray, accept: impl Fn(u32, f32) -> bool) -> Option<SurfaceHit> {
        if !self.transparent {
            return self.closest(ray);
        }
        self.closest_where(ray, |tri, b1, b2| {
            !tri.is_transparent() || (tri.owns(b1, b2) && accept(tri.order, tri.alpha_at(b1, b2)))
        })
    }

    /// The closest crossing within (t_min, t_max] that `keep(triangle, b₁, b₂)` keeps.
    fn closest_where(&self, ray: &Ray, keep: impl Fn(&PreparedTriangle, f32, f32) -> bool) -> Option<SurfaceHit> {
        let mut best: Option<(f32, u32, f32, f32)> = None;
        let mut t_max = ray.t_max;
        self.bvh.traverse(ray, &mut t_max, |k, t_max| {
            let tri = &self.triangles[k as usize];
            let clipped = Ray { t_max: t_max.next_up(), ..*ray };
            let Some((t, b1, b2)) = tri.intersect(&clipped).filter(|&(_, b1, b2)| keep(tri, b1, b2)) else {
                return;
            };
            if best.is_none_or(|(bt, bk, _, _)| t < bt || (t == bt && k < bk)) {
                best = Some((t, k, b1, b2));
                *t_max = t;
            }
        });
        best.map(|(t, k, b1, b2)| self.hit(k, t, b1, b2))
    }

    /// The hit of leaf-order triangle `k` at distance `t` and barycentrics (b₁, b₂).
    fn hit(&self, k: u32, t: f32, b1: f32, b2: f32) -> SurfaceHit {
        let tri = &self.triangles[k as usize];
        let [n0, n1, n2] = tri.normals;
        let face_normal = tri.face_normal();
        let normal = ((1.0 - b1 - b2) * n0 + b1 * n1 + b2 * n2).try_normalize().unwrap_or(face_normal);
        SurfaceHit { t, triangle: k, mesh: tri.mesh, face_normal, normal, alpha: tri.alpha_at(b1, b2) }
    }

    /// Where the ray crosses leaf-order triangle `k` within (t_min, t_max), if it does (within
    /// the edge slack: wherever [`Meshes::transparent_hits`] finds it, and a little more).
    pub fn hit_triangle(&self, k: u32, ray: &Ray) -> Option<SurfaceHit> {
        let (t, b1, b2) = self.triangles[k as usize].intersect(ray)?;
        Some(self.hit(k, t, b1, b2))
    }

    /// The leaf-order index of every transparent triangle the ray crosses within
    /// (t_min, t_max), in no particular order, into `out` (cleared first).
    pub fn transparent_hits(&self, ray: &Ray, out: &mut Vec<u32>) {
        out.clear();
        if !self.transparent {
            return;
        }
        let mut t_max = ray.t_max;
        self.bvh.traverse(ray, &mut t_max, |k, _| {
            let tri = &self.triangles[k as usize];
            if tri.is_transparent() && tri.crosses(ray).is_some() {
                out.push(k);
            }
        });
    }

    /// The light a shadow ray carries past the meshes within (t_min, t_max): Π (1 − αᵢ) over
    /// the triangles it crosses, 0 at the first opaque one (glass blocks shadow rays, as opaque
    /// surfaces do; only an opacity below 1 lets light through).
    pub fn transmittance(&self, ray: &Ray) -> f32 {
        let mut transmittance = 1.0f32;
        let mut t_max = ray.t_max;
        self.bvh.traverse(ray, &mut t_max, |k, t_max| {
            if transmittance == 0.0 {
                return;
            }
            let tri = &self.triangles[k as usize];
            let crossing = if tri.is_transparent() { tri.crosses(ray) } else { tri.intersect(ray) };
            let Some((_, b1, b2)) = crossing else { return };
            transmittance *= 1.0 - tri.alpha_at(b1, b2);
            if transmittance == 0.0 {
                *t_max = f32::NEG_INFINITY;
            }
        });
        transmittance
    }
}

/// The mirror direction of unit `d` about unit normal `n`: d − 2 (d·n) n.
pub fn reflect(d: Vec3, n: Vec3) -> Vec3 {
    d - 2.0 * d.dot(n) * n
}

/// Snell's law: the refracted unit direction of unit `d` through a surface of unit normal `n`
/// facing the incoming ray (d·n < 0), with `eta` = n_incident / n_transmitted; `None` under
/// total internal reflection.
pub fn refract(d: Vec3, n: Vec3, eta: f32) -> Option<Vec3> {
    if eta == 1.0 {
        return Some(d); // index-matched: straight on (cos θₜ through a square root would round)
    }
    let cos_i = -d.dot(n);
    let sin2_t = eta * eta * (1.0 - cos_i * cos_i).max(0.0);
    if sin2_t >= 1.0 {
        return None;
    }
    let cos_t = (1.0 - sin2_t).sqrt();
    Some((eta * d + (eta * cos_i - cos_t) * n).normalize())
}

/// Schlick's approximation of a conductor's Fresnel reflectance, F₀ + (1 − F₀)(1 − cos θᵢ)⁵ for
/// reflectance F₀ at normal incidence and incidence cosine `cos_i` ∈ [0, 1]: glTF 2.0's
/// `conductor_fresnel` (Appendix B). Exactly 1 at every angle for F₀ = 1.
pub fn schlick(f0: Vec3, cos_i: f32) -> Vec3 {
    let m = (1.0 - cos_i).clamp(0.0, 1.0);
    let m2 = m * m;
    f0 + (Vec3::ONE - f0) * (m2 * m2 * m)
}

/// The unpolarised Fresnel reflectance of a smooth dielectric interface (the mean of the s and p
/// reflectances), for incidence cosine `cos_i` ∈ [0, 1] and `eta` = n_incident / n_transmitted;
/// 1 under total internal reflection, exactly 0 at `eta` = 1.
pub fn fresnel(cos_i: f32, eta: f32) -> f32 {
    if eta == 1.0 {
        return 0.0; // index-matched (cos θₜ through a square root would round)
    }
    let sin2_t = eta * eta * (1.0 - cos_i * cos_i).max(0.0);
    if sin2_t >= 1.0 {
        return 1.0;
    }
    let cos_t = (1.0 - sin2_t).sqrt();
    let r_s = (eta * cos_i - cos_t) / (eta * cos_i + cos_t);
    let r_p = (cos_i - eta * cos_t) / (cos_i + eta * cos_t);
    0.5 * (r_s * r_s + r_p * r_p)
}

/// A renderer keeps the meshes it is given, or borrows them with their BVH
/// (`TraceScene::with_meshes`, `Rasterizer::with_meshes`).
impl<'a> From<&'a Meshes> for std::borrow::Cow<'a, Meshes> {
    fn from(meshes: &'a Meshes) -> Self {
        std::borrow::Cow::Borrowed(meshes)
    }
}

impl From<Meshes> for std::borrow::Cow<'_, Meshes> {
    fn from(meshes: Meshes) -> Self {
        std::borrow::Cow::Owned(meshes)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    #[test]
    fn primitives_are_closed_and_face_out() {
        for mesh in [TriangleMesh::cube(), TriangleMesh::sphere(24, 12)] {
            mesh.validate().unwrap();
            // A closed surface facing out: Σ (p₀ · (e₁ × e₂)) / 6 is its positive volume.
            let volume: f32 = mesh
                .triangles
                .iter()
                .map(|&[a, b, c]| {
                    let p = [a, b, c].map(|v| mesh.positions[v as usize]);
                    p[0].dot((p[1] - p[0]).cross(p[2] - p[0])) / 6.0
                })
                .sum();
            let expected = if mesh.triangles.len() == 12 { 8.0 } else { 4.0 / 3.0 * std::f32::consts::PI };
            assert_relative_eq!(volume, expected, max_relative = 0.03);
        }
    }

    #[test]
    fn closest_hit_of_a_ray_through_a_cube() {
        let m = Affine3A::from_translation(Vec3::new(0.0, 0.0, 5.0)) * Affine3A::from_scale(Vec3::splat(0.5));
        let meshes = Meshes::new(&[(TriangleMesh::cube().transformed(m), MeshMaterial::default())]).unwrap();
        let hit = meshes.closest(&Ray::new(Vec3::new(0.1, 0.2, 0.0), Vec3::Z)).unwrap();
        assert_relative_eq!(hit.t, 4.5, epsilon = 1e-5);
        assert!(hit.normal.abs_diff_eq(-Vec3::Z, 1e-6));
        assert_eq!(meshes.transmittance(&Ray::new(Vec3::ZERO, Vec3::Z)), 0.0);
        assert_eq!(meshes.transmittance(&Ray { t_max: 4.4, ..Ray::new(Vec3::ZERO, Vec3::Z) }), 1.0);
        assert!(meshes.closest(&Ray::new(Vec3::new(0.6, 0.0, 0.0), Vec3::Z)).is_none());
    }

    /// A ray through the edge two triangles share crosses exactly one of them (`crosses`), where
    /// the slack of `intersect` finds both: a transparent quad would be two layers along its
    /// diagonal.
    #[test]
    fn a_shared_edge_is_crossed_once() {
        let meshes =
            Meshes::new(&[(TriangleMesh::plane(), MeshMaterial { opacity: 0.5, ..MeshMaterial::default() })]).unwrap();
        for p in [Vec3::new(0.3, 1.0, 0.3), Vec3::new(-0.7, 1.0, -0.7), Vec3::new(0.0, 1.0, 0.0)] {
            let ray = Ray::new(p, -Vec3::Y);
            let tris = meshes.triangles();
            assert_eq!(tris.iter().filter(|t| t.crosses(&ray).is_some()).count(), 1, "through {p}");
            assert_eq!(tris.iter().filter(|t| t.intersect(&ray).is_some()).count(), 2, "the slack's double hit at {p}");
            assert_relative_eq!(meshes.transmittance(&ray), 0.5);
        }
    }

    #[test]
    fn bad_meshes_are_refused_with_the_reason() {
        let mut mesh = TriangleMesh::plane();
        mesh.triangles.push([0, 1, 9]);
        assert!(Meshes::new(&[(mesh, MeshMaterial::default())]).unwrap_err().contains("indexes vertex 9"));
        let glassy = MeshMaterial { mirror: 0.6, transmission: 0.6, ..MeshMaterial::default() };
        assert!(Meshes::new(&[(TriangleMesh::plane(), glassy)]).unwrap_err().contains("sum to at most 1"));
        let mut nan = TriangleMesh::plane();
        nan.positions[0].x = f32::NAN;
        assert!(Meshes::new(&[(nan, MeshMaterial::default())]).unwrap_err().contains("non-finite"));
        for tint in [Vec3::new(f32::NAN, 0.5, 0.5), Vec3::new(1.2, 0.5, 0.5), Vec3::new(0.5, -0.1, 0.5)] {
            let tinted = MeshMaterial { mirror: 1.0, mirror_tint: tint, ..MeshMaterial::default() };
            assert!(Meshes::new(&[(TriangleMesh::plane(), tinted)]).unwrap_err().contains("mirror tint"), "{tint}");
        }
    }

    /// Schlick's Fresnel by hand: F₀ at normal incidence, 1 at grazing incidence, exactly 1 at
    /// every angle for F₀ = 1 (the untinted mirror stays what it was), and at 60° F₀ + (1 − F₀)/32.
    #[test]
    fn schlick_by_hand() {
        let gold = Vec3::new(1.0, 0.78, 0.34);
        assert_eq!(schlick(gold, 1.0), gold);
        assert_eq!(schlick(gold, 0.0), Vec3::ONE);
        assert!((0..=100).all(|i| schlick(Vec3::ONE, i as f32 / 100.0) == Vec3::ONE));
        assert!(schlick(gold, 0.5).abs_diff_eq(gold + (Vec3::ONE - gold) / 32.0, 1e-7));
    }

    #[test]
    fn fresnel_by_hand() {
        // Normal incidence: ((1 − n)/(1 + n))², 0.04 for n = 1.5; index 1 reflects nothing.
        assert_relative_eq!(fresnel(1.0, 1.0 / 1.5), 0.04, epsilon = 1e-6);
        assert_eq!(fresnel(0.3, 1.0), 0.0);
        // Grazing incidence reflects everything; inside glass beyond the critical angle, too.
        assert_relative_eq!(fresnel(0.0, 1.0 / 1.5), 1.0, epsilon = 1e-6);
        assert_eq!(fresnel(0.2, 1.5), 1.0);
        // Brewster's angle: p vanishes, R = R_s / 2.
        let theta_b = 1.5f32.atan();
        let (cos_i, cos_t) = (theta_b.cos(), (1.0 - (theta_b.sin() / 1.5).powi(2)).sqrt());
        let r_s = ((cos_i - 1.5 * cos_t) / (cos_i + 1.5 * cos_t)).powi(2);
        assert_relative_eq!(fresnel(cos_i, 1.0 / 1.5), 0.5 * r_s, epsilon = 1e-6);
    }

    #[test]
    fn snell_and_mirror_directions() {
        let d = Vec3::new(1.0, -1.0, 0.0).normalize();
        assert!(reflect(d, Vec3::Y).abs_diff_eq(Vec3::new(1.0, 1.0, 0.0).normalize(), 1e-6));
        assert!(refract(d, Vec3::Y, 1.0).unwrap().abs_diff_eq(d, 1e-6));
        let t = refract(d, Vec3::Y, 1.0 / 1.5).unwrap();
        // n₁ sin θ₁ = n₂ sin θ₂.
        assert_relative_eq!(d.x, 1.5 * t.x, epsilon = 1e-6);
        assert!(refract(Vec3::new(0.9, -0.1, 0.0).normalize(), Vec3::Y, 1.5).is_none());
    }
}
