// The Embree peer of `splat bench`: Sun et al. 2025 Algorithm 1, exact compositing (Eq. 3) and
// the opaque closest-ellipsoid baseline on Embree 3 user geometry, one intersection callback per
// particle, as Sun et al. ran their CPU numbers. It makes the decisions of splat-core's CPU
// tracer (the same xxhash32/PCG keys, cutoff, clamp, cull and tie-break by particle id), so
// the same seed gives the same image, and `embree-peer` checks that it does.
//
// This is a benchmark baseline, not part of the library: built only by the embree-peer crate
// when Embree 3's headers are installed (Debian: libembree-dev).

#include <embree3/rtcore.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <thread>
#include <vector>

namespace {

// ---- decisions: the twins of splat_core::rng ----

inline uint32_t rotl(uint32_t x, int r) { return (x << r) | (x >> (32 - r)); }

inline uint32_t xxhash32(uint32_t p0, uint32_t p1, uint32_t p2) {
    const uint32_t P2 = 2246822519u, P3 = 3266489917u, P4 = 668265263u, P5 = 374761393u;
    uint32_t h = p2 + P5 + p0 * P3;
    h = P4 * rotl(h, 17);
    h = h + p1 * P3;
    h = P4 * rotl(h, 17);
    h = P2 * (h ^ (h >> 15));
    h = P3 * (h ^ (h >> 13));
    return h ^ (h >> 16);
}

inline uint32_t pcg(uint32_t v) {
    uint32_t s = v * 747796405u + 2891336453u;
    uint32_t w = ((s >> ((s >> 28) + 4)) ^ s) * 277803737u;
    return (w >> 22) ^ w;
}

inline float unit_f32(uint32_t bits) { return float(bits >> 8) * (1.0f / 16777216.0f); }

// ---- the scene, as splat-core prepares it ----

struct Particle {
    float mean[3];
    float m[9];  // canonical transform M = S^-1 R^T, column-major (glam's Mat3)
    float opacity;
    float lo[3], hi[3];  // the padded box the BVH is built over
    float radius_sq;     // squared radius of the bounding ellipsoid (the opaque ray's surface)
};

struct Settings {
    float cutoff, alpha_clamp, alpha_cull, t_min, t_max;
    float background[3];
    uint32_t sh_degree;
};

struct Peer {
    RTCDevice device = nullptr;
    RTCScene scene = nullptr;
    std::vector<Particle> particles;
    std::vector<float> sh;  // 48 floats per particle: 16 RGB coefficients
    Settings settings;
};

struct Vec3 {
    float x, y, z;
};
inline Vec3 operator-(Vec3 a, Vec3 b) { return {a.x - b.x, a.y - b.y, a.z - b.z}; }
inline float dot(Vec3 a, Vec3 b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
inline Vec3 cross(Vec3 a, Vec3 b) { return {a.y * b.z - b.y * a.z, a.z * b.x - b.z * a.x, a.x * b.y - b.x * a.y}; }

// glam's Mat3 * Vec3: x_axis * v.x + y_axis * v.y + z_axis * v.z.
inline Vec3 mul(const float* m, Vec3 v) {
    return {m[0] * v.x + m[3] * v.y + m[6] * v.z, m[1] * v.x + m[4] * v.y + m[7] * v.z,
            m[2] * v.x + m[5] * v.y + m[8] * v.z};
}

// splat_core::sh::eval.
void sh_eval(const float* sh, uint32_t degree, Vec3 d, float out[3]) {
    const float C0 = 0.2820948f, C1 = 0.48860252f;
    const float C2[5] = {1.0925484f, -1.0925484f, 0.31539157f, -1.0925484f, 0.5462742f};
    const float C3[7] = {-0.5900436f, 2.8906114f, -0.4570458f, 0.37317634f, -0.4570458f, 1.4453057f, -0.5900436f};
    for (int c = 0; c < 3; ++c) {
        auto k = [&](int i) { return sh[3 * i + c]; };
        float v = C0 * k(0);
        if (degree >= 1) {
            float x = d.x, y = d.y, z = d.z;
            v += -C1 * y * k(1) + C1 * z * k(2) - C1 * x * k(3);
            if (degree >= 2) {
                float xx = x * x, yy = y * y, zz = z * z, xy = x * y, yz = y * z, xz = x * z;
                v += C2[0] * xy * k(4) + C2[1] * yz * k(5) + C2[2] * (2.0f * zz - xx - yy) * k(6) +
                     C2[3] * xz * k(7) + C2[4] * (xx - yy) * k(8);
                if (degree >= 3) {
                    v += C3[0] * y * (3.0f * xx - yy) * k(9) + C3[1] * xy * z * k(10) +
                         C3[2] * y * (4.0f * zz - xx - yy) * k(11) + C3[3] * z * (2.0f * zz - 3.0f * xx - 3.0f * yy) * k(12) +
                         C3[4] * x * (4.0f * zz - xx - yy) * k(13) + C3[5] * z * (xx - yy) * k(14) +
                         C3[6] * x * (xx - 3.0f * yy) * k(15);
                }
            }
        }
        out[c] = std::max(v + 0.5f, 0.0f);
    }
}

inline bool depth_before(float t, uint32_t id, float ot, uint32_t oid) { return t < ot || (t == ot && id < oid); }

enum Method : uint32_t { OPAQUE = 0, STOCHASTIC = 1, EXACT = 2 };

struct HitRecord {
    float t, alpha;
    uint32_t id;
};

// Embree 3's per-ray context, extended with what the callbacks need.
struct Context {
    RTCIntersectContext ctx;
    const Peer* peer;
    Method method;
    uint32_t pixel_key;
    Vec3 origin, dir;
    float best_t;
    uint32_t best_id;
    std::vector<HitRecord>* hits;
};

// splat_core::hit::intersect with HitDistance::Mean and kernel degree 2.
inline bool gaussian_hit(const Particle& p, const Settings& s, Vec3 o, Vec3 d, float* t_out, float* alpha_out) {
    Vec3 oc = mul(p.m, o - Vec3{p.mean[0], p.mean[1], p.mean[2]});
    Vec3 dc = mul(p.m, d);
    float dd = dot(dc, dc);
    Vec3 x = cross(oc, dc);
    float d2 = dot(x, x) / dd;
    if (d2 > s.cutoff * s.cutoff) return false;  // outside the cutoff ellipsoid, before the exponential
    float response = std::exp(-4.5f * (d2 * (1.0f / 9.0f)));
    float alpha = p.opacity * response;
    if (!(alpha >= s.alpha_cull && alpha > 0.0f)) return false;
    alpha = std::min(alpha, s.alpha_clamp);
    float t = -dot(oc, dc) / dd;
    if (!(t > s.t_min && t < s.t_max)) return false;
    *t_out = t;
    *alpha_out = alpha;
    return true;
}

void bounds(const RTCBoundsFunctionArguments* args) {
    const Peer* peer = static_cast<const Peer*>(args->geometryUserPtr);
    const Particle& p = peer->particles[args->primID];
    RTCBounds* b = args->bounds_o;
    b->lower_x = p.lo[0];
    b->lower_y = p.lo[1];
    b->lower_z = p.lo[2];
    b->upper_x = p.hi[0];
    b->upper_y = p.hi[1];
    b->upper_z = p.hi[2];
}

void intersect(const RTCIntersectFunctionNArguments* args) {
    if (!args->valid[0]) return;
    Context* c = reinterpret_cast<Context*>(args->context);
    RTCRayHit* rh = reinterpret_cast<RTCRayHit*>(args->rayhit);
    const uint32_t id = args->primID;
    const Particle& p = c->peer->particles[id];
    const Settings& s = c->peer->settings;
    float t = 0.0f, alpha = 0.0f;
    switch (c->method) {
        case OPAQUE: {
            Vec3 oc = mul(p.m, c->origin - Vec3{p.mean[0], p.mean[1], p.mean[2]});
            Vec3 dc = mul(p.m, c->dir);
            float a = dot(dc, dc);
            Vec3 x = cross(oc, dc);
            float disc = a * p.radius_sq - dot(x, x);
            if (disc < 0.0f) return;
            t = (-dot(oc, dc) - std::sqrt(disc)) / a;
            if (!(t > s.t_min && t < s.t_max) || !depth_before(t, id, c->best_t, c->best_id)) return;
            break;
        }
        case STOCHASTIC: {
            // Algorithm 1 with the draw before the kernel, as splat does: alpha <= min(opacity, clamp).
            float u = unit_f32(pcg(xxhash32(c->pixel_key, id, 0)));
            if (u >= std::min(p.opacity, s.alpha_clamp)) return;
            if (!gaussian_hit(p, s, c->origin, c->dir, &t, &alpha)) return;
            if (!depth_before(t, id, c->best_t, c->best_id) || !(u < alpha)) return;
            break;
        }
        case EXACT:
            if (gaussian_hit(p, s, c->origin, c->dir, &t, &alpha)) c->hits->push_back({t, alpha, id});
            return;
    }
    // Accepted: record it and clip the ray, so that Embree skips what lies behind.
    c->best_t = t;
    c->best_id = id;
    rh->ray.tfar = t;
    rh->hit.geomID = args->geomID;
    rh->hit.primID = id;
}

void trace_pixel(const Peer& peer, Method method, uint32_t frame_key, uint32_t px, uint32_t py, const float* ray,
                 std::vector<HitRecord>& hits, float* out) {
    const Settings& s = peer.settings;
    Context c;
    rtcInitIntersectContext(&c.ctx);
    c.peer = &peer;
    c.method = method;
    c.pixel_key = xxhash32(px, py, frame_key);
    c.origin = {ray[0], ray[1], ray[2]};
    c.dir = {ray[3], ray[4], ray[5]};
    c.best_t = INFINITY;
    c.best_id = UINT32_MAX;
    hits.clear();
    c.hits = &hits;
    RTCRayHit rh;
    rh.ray.org_x = ray[0];
    rh.ray.org_y = ray[1];
    rh.ray.org_z = ray[2];
    rh.ray.dir_x = ray[3];
    rh.ray.dir_y = ray[4];
    rh.ray.dir_z = ray[5];
    rh.ray.tnear = s.t_min;
    rh.ray.tfar = s.t_max;
    rh.ray.time = 0.0f;
    rh.ray.mask = UINT32_MAX;
    rh.ray.id = 0;
    rh.ray.flags = 0;
    rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
    rh.hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
    rtcIntersect1(peer.scene, &c.ctx, &rh);
    if (method == EXACT) {
        std::sort(hits.begin(), hits.end(), [](const HitRecord& a, const HitRecord& b) {
            return a.t < b.t || (a.t == b.t && a.id < b.id);
        });
        double radiance[3] = {0.0, 0.0, 0.0}, transmittance = 1.0;
        for (const HitRecord& h : hits) {
            float color[3];
            sh_eval(&peer.sh[48 * size_t(h.id)], s.sh_degree, c.dir, color);
            double w = transmittance * double(h.alpha);
            for (int k = 0; k < 3; ++k) radiance[k] += w * double(color[k]);
            transmittance *= 1.0 - double(h.alpha);
        }
        for (int k = 0; k < 3; ++k) out[k] = float(radiance[k] + transmittance * double(s.background[k]));
    } else if (c.best_id == UINT32_MAX) {
        for (int k = 0; k < 3; ++k) out[k] = s.background[k];
    } else {
        sh_eval(&peer.sh[48 * size_t(c.best_id)], s.sh_degree, c.dir, out);
    }
}

}  // namespace

extern "C" {

// Build the Embree scene over `n` particles (the arrays are copied). Returns null on failure.
void* splat_peer_build(const float* particles, const float* sh, uint32_t n, const float* settings,
                       uint32_t sh_degree, uint32_t threads) {
    Peer* peer = new Peer();
    peer->particles.resize(n);
    std::memcpy(peer->particles.data(), particles, sizeof(Particle) * n);
    peer->sh.assign(sh, sh + 48 * size_t(n));
    std::memcpy(&peer->settings, settings, 8 * sizeof(float));
    peer->settings.sh_degree = sh_degree;
    char config[64];
    std::snprintf(config, sizeof config, "threads=%u", threads);
    peer->device = rtcNewDevice(config);
    if (!peer->device) {
        delete peer;
        return nullptr;
    }
    peer->scene = rtcNewScene(peer->device);
    RTCGeometry geometry = rtcNewGeometry(peer->device, RTC_GEOMETRY_TYPE_USER);
    rtcSetGeometryUserPrimitiveCount(geometry, n);
    rtcSetGeometryUserData(geometry, peer);
    rtcSetGeometryBoundsFunction(geometry, bounds, nullptr);
    rtcSetGeometryIntersectFunction(geometry, intersect);
    rtcCommitGeometry(geometry);
    rtcAttachGeometry(peer->scene, geometry);
    rtcReleaseGeometry(geometry);
    rtcCommitScene(peer->scene);
    if (rtcGetDeviceError(peer->device) != RTC_ERROR_NONE) {
        rtcReleaseScene(peer->scene);
        rtcReleaseDevice(peer->device);
        delete peer;
        return nullptr;
    }
    return peer;
}

// Trace `width` x `height` rays (6 floats each, row-major pixels) with `method` on `threads`
// threads over 16 x 16 tiles; writes RGB to `out`.
void splat_peer_render(const void* handle, uint32_t method, uint32_t frame_key, const float* rays, uint32_t width,
                       uint32_t height, uint32_t threads, float* out) {
    const Peer& peer = *static_cast<const Peer*>(handle);
    const uint32_t tiles_x = (width + 15) / 16, tiles = tiles_x * ((height + 15) / 16);
    std::atomic<uint32_t> next{0};
    auto work = [&]() {
        std::vector<HitRecord> hits;
        for (uint32_t tile; (tile = next.fetch_add(1)) < tiles;) {
            uint32_t x0 = 16 * (tile % tiles_x), y0 = 16 * (tile / tiles_x);
            for (uint32_t y = y0; y < std::min(y0 + 16, height); ++y)
                for (uint32_t x = x0; x < std::min(x0 + 16, width); ++x) {
                    size_t i = size_t(y) * width + x;
                    trace_pixel(peer, Method(method), frame_key, x, y, rays + 6 * i, hits, out + 3 * i);
                }
        }
    };
    std::vector<std::thread> pool;
    for (uint32_t i = 1; i < threads; ++i) pool.emplace_back(work);
    work();
    for (auto& t : pool) t.join();
}

void splat_peer_free(void* handle) {
    Peer* peer = static_cast<Peer*>(handle);
    rtcReleaseScene(peer->scene);
    rtcReleaseDevice(peer->device);
    delete peer;
}

}  // extern "C"
