#include "geometry/geometry.h"

#include <embree3/rtcore.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <string>

#include "core/errors.h"
#include "core/math.h"

namespace fluorosim {
namespace {

struct Sphere {
    Vec3 center;
    double radius;
};

// Extends Embree's context with the double-precision ray, so spheres intersect exactly.
struct DoubleRayContext {
    RTCIntersectContext base;
    const Ray* ray;
};

void sphereBounds(const RTCBoundsFunctionArguments* args) {
    const auto* s = static_cast<const Sphere*>(args->geometryUserPtr);
    // Generous against float rounding of the centre and radius.
    const double extent = std::max({std::abs(s->center.x), std::abs(s->center.y), std::abs(s->center.z)}) + s->radius;
    const float pad = static_cast<float>(extent * 1e-6 + 1e-9);
    args->bounds_o->lower_x = static_cast<float>(s->center.x - s->radius) - pad;
    args->bounds_o->lower_y = static_cast<float>(s->center.y - s->radius) - pad;
    args->bounds_o->lower_z = static_cast<float>(s->center.z - s->radius) - pad;
    args->bounds_o->upper_x = static_cast<float>(s->center.x + s->radius) + pad;
    args->bounds_o->upper_y = static_cast<float>(s->center.y + s->radius) + pad;
    args->bounds_o->upper_z = static_cast<float>(s->center.z + s->radius) + pad;
}

// Both roots of |o + t d - c|^2 = r^2, computed without catastrophic cancellation.
bool sphereRoots(const Sphere& s, const Ray& ray, double* t0, double* t1) {
    const Vec3 oc = ray.o - s.center;
    const double a = dot(ray.d, ray.d);
    const double b = dot(oc, ray.d);
    // Hearn-Baker form of the discriminant keeps precision for distant spheres.
    const Vec3 f = oc - ray.d * (b / a);
    const double disc = s.radius * s.radius - dot(f, f);
    if (disc < 0) return false;
    const double c = dot(oc, oc) - s.radius * s.radius;
    const double q = -(b + std::copysign(std::sqrt(a * disc), b));
    double r0 = c / q, r1 = q / a;
    if (q == 0) r0 = r1 = 0;
    if (r0 > r1) std::swap(r0, r1);
    *t0 = r0;
    *t1 = r1;
    return true;
}

void sphereIntersect(const RTCIntersectFunctionNArguments* args) {
    if (!args->valid[0]) return;
    const auto* s = static_cast<const Sphere*>(args->geometryUserPtr);
    const auto* ctx = reinterpret_cast<const DoubleRayContext*>(args->context);
    auto* rh = reinterpret_cast<RTCRayHit*>(args->rayhit);
    double t0, t1;
    if (!sphereRoots(*s, *ctx->ray, &t0, &t1)) return;
    double t = t0;
    if (!(t > rh->ray.tnear)) t = t1;
    if (!(t > rh->ray.tnear) || !(t < rh->ray.tfar)) return;
    const Vec3 p = ctx->ray->at(t);
    const Vec3 n = (p - s->center) / s->radius;
    rh->ray.tfar = static_cast<float>(t);
    rh->hit.Ng_x = static_cast<float>(n.x);
    rh->hit.Ng_y = static_cast<float>(n.y);
    rh->hit.Ng_z = static_cast<float>(n.z);
    rh->hit.u = 0;
    rh->hit.v = 0;
    rh->hit.primID = args->primID;
    rh->hit.geomID = args->geomID;
    rh->hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
}

void sphereOccluded(const RTCOccludedFunctionNArguments* args) {
    if (!args->valid[0]) return;
    const auto* s = static_cast<const Sphere*>(args->geometryUserPtr);
    const auto* ctx = reinterpret_cast<const DoubleRayContext*>(args->context);
    auto* ray = reinterpret_cast<RTCRay*>(args->ray);
    double t0, t1;
    if (!sphereRoots(*s, *ctx->ray, &t0, &t1)) return;
    if ((t0 > ray->tnear && t0 < ray->tfar) || (t1 > ray->tnear && t1 < ray->tfar)) ray->tfar = -std::numeric_limits<float>::infinity();
}

}  // namespace

struct Geometry::Impl {
    RTCDevice device = nullptr;
    RTCScene scene = nullptr;
    std::vector<TriangleMesh> meshes;         // indexed by shape id (empty for spheres)
    std::vector<std::unique_ptr<Sphere>> spheres;  // indexed by shape id (null for meshes)
    std::vector<double> areas;
    Vec3 lo{1e300, 1e300, 1e300}, hi{-1e300, -1e300, -1e300};
    bool committed = false;

    Impl() {
        device = rtcNewDevice("verbose=0");
        if (!device) throw Error("Embree: cannot create a device");
        scene = rtcNewScene(device);
        rtcSetSceneFlags(scene, RTC_SCENE_FLAG_ROBUST);
        rtcSetSceneBuildQuality(scene, RTC_BUILD_QUALITY_HIGH);
    }
    ~Impl() {
        if (scene) rtcReleaseScene(scene);
        if (device) rtcReleaseDevice(device);
    }
    void grow(const Vec3& p) {
        for (int i = 0; i < 3; ++i) {
            lo[i] = std::min(lo[i], p[i]);
            hi[i] = std::max(hi[i], p[i]);
        }
    }
};

Geometry::Geometry() : impl_(std::make_unique<Impl>()) {}
Geometry::~Geometry() = default;
Geometry::Geometry(Geometry&&) noexcept = default;
Geometry& Geometry::operator=(Geometry&&) noexcept = default;

uint32_t Geometry::addMesh(TriangleMesh mesh) {
    if (mesh.indices.empty() || mesh.indices.size() % 3 != 0) throw ConfigError("mesh has no triangles");
    for (uint32_t i : mesh.indices)
        if (i >= mesh.positions.size()) throw ConfigError("mesh index " + std::to_string(i) + " out of range");
    double area = 0;
    for (size_t t = 0; t < mesh.indices.size(); t += 3) {
        const Vec3 &a = mesh.positions[mesh.indices[t]], &b = mesh.positions[mesh.indices[t + 1]],
                   &c = mesh.positions[mesh.indices[t + 2]];
        area += 0.5 * length(cross(b - a, c - a));
    }
    if (!(area > 0) || !std::isfinite(area)) throw ConfigError("mesh has zero or non-finite area");
    RTCGeometry g = rtcNewGeometry(impl_->device, RTC_GEOMETRY_TYPE_TRIANGLE);
    auto* v = static_cast<float*>(rtcSetNewGeometryBuffer(g, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3,
                                                          3 * sizeof(float), mesh.positions.size()));
    for (size_t i = 0; i < mesh.positions.size(); ++i) {
        if (!isFinite(mesh.positions[i])) throw ConfigError("mesh has a non-finite vertex");
        for (int k = 0; k < 3; ++k) v[3 * i + k] = static_cast<float>(mesh.positions[i][k]);
        impl_->grow(mesh.positions[i]);
    }
    auto* idx = static_cast<uint32_t*>(rtcSetNewGeometryBuffer(g, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3,
                                                               3 * sizeof(uint32_t), mesh.indices.size() / 3));
    std::copy(mesh.indices.begin(), mesh.indices.end(), idx);
    rtcCommitGeometry(g);
    const uint32_t id = rtcAttachGeometry(impl_->scene, g);
    rtcReleaseGeometry(g);
    if (id != impl_->meshes.size()) throw Error("Embree: unexpected geometry id");
    impl_->meshes.push_back(std::move(mesh));
    impl_->spheres.emplace_back();
    impl_->areas.push_back(area);
    return id;
}

uint32_t Geometry::addSphere(const Vec3& center, double radius) {
    if (!(radius > 0) || !std::isfinite(radius) || !isFinite(center))
        throw ConfigError("sphere needs a finite centre and a positive radius, got radius " + std::to_string(radius));
    auto sphere = std::make_unique<Sphere>(Sphere{center, radius});
    RTCGeometry g = rtcNewGeometry(impl_->device, RTC_GEOMETRY_TYPE_USER);
    rtcSetGeometryUserPrimitiveCount(g, 1);
    rtcSetGeometryUserData(g, sphere.get());
    rtcSetGeometryBoundsFunction(g, sphereBounds, nullptr);
    rtcSetGeometryIntersectFunction(g, sphereIntersect);
    rtcSetGeometryOccludedFunction(g, sphereOccluded);
    rtcCommitGeometry(g);
    const uint32_t id = rtcAttachGeometry(impl_->scene, g);
    rtcReleaseGeometry(g);
    if (id != impl_->meshes.size()) throw Error("Embree: unexpected geometry id");
    impl_->grow(center - Vec3(radius, radius, radius));
    impl_->grow(center + Vec3(radius, radius, radius));
    impl_->meshes.emplace_back();
    impl_->spheres.push_back(std::move(sphere));
    impl_->areas.push_back(4.0 * kPi * radius * radius);
    return id;
}

void Geometry::commit() {
    rtcCommitScene(impl_->scene);
    impl_->committed = true;
}

std::optional<SurfaceHit> Geometry::intersect(const Ray& ray, double tMin, double tMax) const {
    return intersectImpl(ray, tMin, tMax, true);
}

std::optional<SurfaceHit> Geometry::intersectImpl(const Ray& ray, double tMin, double tMax, bool retry) const {
    DoubleRayContext ctx;
    rtcInitIntersectContext(&ctx.base);
    ctx.ray = &ray;
    RTCRayHit rh;
    rh.ray.org_x = static_cast<float>(ray.o.x);
    rh.ray.org_y = static_cast<float>(ray.o.y);
    rh.ray.org_z = static_cast<float>(ray.o.z);
    rh.ray.dir_x = static_cast<float>(ray.d.x);
    rh.ray.dir_y = static_cast<float>(ray.d.y);
    rh.ray.dir_z = static_cast<float>(ray.d.z);
    rh.ray.tnear = static_cast<float>(tMin);
    rh.ray.tfar = std::isfinite(tMax) ? static_cast<float>(tMax) : std::numeric_limits<float>::infinity();
    rh.ray.time = 0;
    rh.ray.mask = 0xFFFFFFFF;
    rh.ray.id = 0;
    rh.ray.flags = 0;
    rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
    rh.hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
    rtcIntersect1(impl_->scene, &ctx.base, &rh);
    if (rh.hit.geomID == RTC_INVALID_GEOMETRY_ID) return std::nullopt;

    SurfaceHit hit;
    hit.shape = rh.hit.geomID;
    hit.prim = rh.hit.primID;
    if (const Sphere* s = impl_->spheres[hit.shape].get()) {
        // Embree stores t as float; recompute the root in double.
        double t0 = 0, t1 = 0;
        sphereRoots(*s, ray, &t0, &t1);
        hit.t = t0 > tMin ? t0 : t1;
        hit.p = ray.at(hit.t);
        hit.n = normalize(hit.p - s->center);
        // Project onto the sphere so spawned rays start from the exact surface.
        hit.p = s->center + hit.n * s->radius;
        hit.epsilon = sphereRayEpsilon(hit.p);
    } else {
        const TriangleMesh& m = impl_->meshes[hit.shape];
        const Vec3 &a = m.positions[m.indices[3 * hit.prim]], &b = m.positions[m.indices[3 * hit.prim + 1]],
                   &c = m.positions[m.indices[3 * hit.prim + 2]];
        const Vec3 e1 = b - a, e2 = c - a;
        hit.n = normalize(cross(e1, e2));
        // Re-intersect the plane in double precision.
        const double denom = dot(hit.n, ray.d);
        hit.t = denom != 0 ? dot(hit.n, a - ray.o) / denom : static_cast<double>(rh.ray.tfar);
        if (!(hit.t > 0) || !std::isfinite(hit.t)) hit.t = rh.ray.tfar;
        const double u = rh.hit.u, v = rh.hit.v;
        hit.p = a * (1 - u - v) + b * u + c * v;
        hit.epsilon = rayEpsilon(hit.p);
    }
    if (!(hit.t > tMin)) {
        // Float traversal accepted a hit that double precision puts at or before tMin: a self-hit.
        // Look once more, just past it.
        const double skip = std::max(static_cast<double>(rh.ray.tfar), tMin) * (1.0 + 1e-6) + 1e-12;
        if (!retry || skip >= tMax) return std::nullopt;
        return intersectImpl(ray, skip, tMax, false);
    }
    if (!(hit.t < tMax)) return std::nullopt;
    return hit;
}

size_t Geometry::shapeCount() const { return impl_->meshes.size(); }
bool Geometry::isSphere(uint32_t shape) const { return impl_->spheres.at(shape) != nullptr; }
const TriangleMesh& Geometry::mesh(uint32_t shape) const { return impl_->meshes.at(shape); }
Vec3 Geometry::sphereCenter(uint32_t shape) const { return impl_->spheres.at(shape)->center; }
double Geometry::sphereRadius(uint32_t shape) const { return impl_->spheres.at(shape)->radius; }
double Geometry::area(uint32_t shape) const { return impl_->areas.at(shape); }
double Geometry::extent() const {
    if (impl_->lo.x > impl_->hi.x) return 1.0;
    return length(impl_->hi - impl_->lo);
}

double rayEpsilon(const Vec3& p) {
    const double m = std::max({std::abs(p.x), std::abs(p.y), std::abs(p.z), 1.0});
    return 2e-5 * m;
}

double sphereRayEpsilon(const Vec3& p) {
    const double m = std::max({std::abs(p.x), std::abs(p.y), std::abs(p.z), 1.0});
    return 1e-9 * m;
}

}  // namespace fluorosim
