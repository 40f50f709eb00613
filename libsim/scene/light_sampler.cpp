#include "scene/light_sampler.h"

#include <algorithm>
#include <tuple>

#include "core/math.h"
#include "core/sampling.h"

namespace fluorosim {
namespace {

// Cone of directions subtended by a sphere seen from outside (pbrt-v4's Sphere::Sample).
struct SphereCone {
    double sin2ThetaMax, cosThetaMax, oneMinusCosThetaMax;
    bool inside;  // the reference point is inside the sphere: sample by area instead
    SphereCone(const Vec3& ref, const Vec3& center, double radius) {
        const double dc2 = dot(ref - center, ref - center);
        inside = dc2 <= radius * radius;
        sin2ThetaMax = inside ? 1.0 : radius * radius / dc2;
        cosThetaMax = safeSqrt(1.0 - sin2ThetaMax);
        oneMinusCosThetaMax = 1.0 - cosThetaMax;
        // For tiny cones 1 - cos loses digits; use its Taylor expansion.
        if (sin2ThetaMax < 0.00068523) oneMinusCosThetaMax = sin2ThetaMax / 2;
    }
    double solidAnglePdf() const { return 1.0 / (2.0 * kPi * oneMinusCosThetaMax); }
};

double smoothStep(double x, double a, double b) {
    if (a == b) return x < a ? 0.0 : 1.0;
    const double t = std::clamp((x - a) / (b - a), 0.0, 1.0);
    return t * t * (3 - 2 * t);
}

}  // namespace

SampledSpectrum LightSampler::emitted(const AreaLight& light, const Vec3& n, const Vec3& w, const SampledWavelengths& wl) const {
    if (!light.emission.twoSided && dot(n, w) <= 0) return SampledSpectrum(0.0);
    return light.emission.radiance.sampleEmission(wl);
}

std::pair<Vec3, Vec3> LightSampler::pointByArea(const AreaLight& al, double u1, double u2) const {
    if (scene_.geometry.isSphere(al.shape)) {
        const Vec3 n = sampleUniformSphere(u1, u2);
        return {scene_.geometry.sphereCenter(al.shape) + n * scene_.geometry.sphereRadius(al.shape), n};
    }
    const TriangleMesh& m = scene_.geometry.mesh(al.shape);
    const auto it = std::lower_bound(al.triangleCdf.begin(), al.triangleCdf.end(), u1);
    const size_t tri = std::min(static_cast<size_t>(it - al.triangleCdf.begin()), al.triangleCdf.size() - 1);
    const double lo = tri == 0 ? 0.0 : al.triangleCdf[tri - 1];
    const double uRemap = std::clamp((u1 - lo) / std::max(al.triangleCdf[tri] - lo, 1e-300), 0.0, 1.0);
    const auto b = sampleUniformTriangle(uRemap, u2);
    const Vec3 &a = m.positions[m.indices[3 * tri]], &bb = m.positions[m.indices[3 * tri + 1]], &cc = m.positions[m.indices[3 * tri + 2]];
    return {a * b[0] + bb * b[1] + cc * (1 - b[0] - b[1]), normalize(cross(bb - a, cc - a))};
}

double LightSampler::spotFalloff(const SpotLight& light, const Vec3& w) {
    return smoothStep(dot(w, light.direction), light.cosTotalWidth, light.cosFalloffStart);
}

SampledSpectrum LightSampler::deltaIntensity(const Light& light, const Vec3& w, const SampledWavelengths& wl, double squaredDistanceMm) {
    const PointLight* pl = std::get_if<PointLight>(&light);
    const SpotLight* sl = std::get_if<SpotLight>(&light);
    if (!pl && !sl) return SampledSpectrum(0.0);
    const double falloff = sl ? spotFalloff(*sl, w) : 1.0;
    return (pl ? pl->intensity : sl->intensity).sampleEmission(wl) * (falloff * kMm2PerM2 / squaredDistanceMm);
}

std::optional<LightSample> LightSampler::sample(const Vec3& ref, double uLight, double u1, double u2,
                                                const SampledWavelengths& wl) const {
    const size_t count = lights_.size();
    if (count == 0) return std::nullopt;
    const size_t index = std::min(count - 1, static_cast<size_t>(uLight * static_cast<double>(count)));
    const double selectPdf = 1.0 / static_cast<double>(count);
    const Light& light = lights_[index];
    LightSample ls;
    ls.light = &light;
    const PointLight* pl = std::get_if<PointLight>(&light);
    const SpotLight* sl = std::get_if<SpotLight>(&light);
    if (pl || sl) {
        // Delta lights: irradiance I / d^2.
        ls.p = pl ? pl->position : sl->position;
        const Vec3 d = ls.p - ref;
        ls.distance = length(d);
        if (!(ls.distance > 0)) return std::nullopt;
        ls.wi = d / ls.distance;
        ls.L = deltaIntensity(light, -ls.wi, wl, sqr(ls.distance));
        ls.pdf = selectPdf;
        ls.delta = true;
        return ls;
    }
    if (const BeamLight* beam = std::get_if<BeamLight>(&light)) {
        // Exact connection: the light arrives along the beam, so the shadow ray runs from ref back
        // against it to beyond the scene, where the beam comes from.
        const int sides = beam->profile->sides();
        const int side = std::min(sides - 1, static_cast<int>(u1 * sides));
        ls.wi = -beam->profile->direction(side);
        ls.distance = 2 * (scene_.geometry.extent() + length(ref)) + 1;
        ls.p = ref + ls.wi * ls.distance;
        ls.L = beam->profile->spectrum().sampleEmission(wl);
        for (int j = 0; j < kNumWavelengths; ++j)
            if (ls.L[j] != 0) ls.L[j] *= beam->profile->irradiance(ref, side, wl.lambda[j]) * kMm2PerM2;
        ls.pdf = selectPdf / sides;
        ls.delta = true;
        ls.beam = true;
        ls.beamProfile = beam->profile.get();
        ls.side = side;
        return ls;
    }
    const auto& al = std::get<AreaLight>(light);
    ls.shape = al.shape;
    if (scene_.geometry.isSphere(al.shape)) {
        const Vec3 c = scene_.geometry.sphereCenter(al.shape);
        const double r = scene_.geometry.sphereRadius(al.shape);
        const SphereCone cone(ref, c, r);
        if (cone.inside) {
            std::tie(ls.p, ls.n) = pointByArea(al, u1, u2);
        } else {
            // Uniform direction in the cone, then the visible point of the sphere along it.
            double cosTheta = 1.0 - u1 * cone.oneMinusCosThetaMax;
            double sin2Theta = 1.0 - cosTheta * cosTheta;
            if (cone.sin2ThetaMax < 0.00068523) {
                sin2Theta = cone.sin2ThetaMax * u1;
                cosTheta = std::sqrt(1.0 - sin2Theta);
            }
            const double sinThetaMax = std::sqrt(cone.sin2ThetaMax);
            const double cosAlpha = sin2Theta / sinThetaMax + cosTheta * safeSqrt(1.0 - sin2Theta / cone.sin2ThetaMax);
            const double sinAlpha = safeSqrt(1.0 - cosAlpha * cosAlpha);
            const double phi = 2.0 * kPi * u2;
            const Frame frame = Frame::fromNormal(normalize(c - ref));
            ls.n = frame.toWorld(Vec3(-sinAlpha * std::cos(phi), -sinAlpha * std::sin(phi), -cosAlpha));
            ls.p = c + ls.n * r;
            const Vec3 d = ls.p - ref;
            ls.distance = length(d);
            if (!(ls.distance > 0)) return std::nullopt;
            ls.wi = d / ls.distance;
            ls.L = emitted(al, ls.n, -ls.wi, wl);
            ls.pdf = selectPdf * cone.solidAnglePdf();
            return ls;
        }
    } else {
        std::tie(ls.p, ls.n) = pointByArea(al, u1, u2);
    }
    const Vec3 d = ls.p - ref;
    ls.distance = length(d);
    if (!(ls.distance > 0)) return std::nullopt;
    ls.wi = d / ls.distance;
    const double cosLight = std::abs(dot(ls.n, ls.wi));
    if (cosLight <= 0) return std::nullopt;
    ls.L = emitted(al, ls.n, -ls.wi, wl);
    ls.pdf = selectPdf * sqr(ls.distance) / (scene_.geometry.area(al.shape) * cosLight);
    return ls;
}

double LightSampler::pdf(const Vec3& ref, uint32_t shape, const Vec3& pLight, const Vec3& nLight) const {
    if (scene_.geometry.isSphere(shape)) {
        const SphereCone cone(ref, scene_.geometry.sphereCenter(shape), scene_.geometry.sphereRadius(shape));
        if (!cone.inside) {
            // Only the cap facing the reference point is ever sampled.
            if (dot(nLight, ref - pLight) <= 0) return 0.0;
            return cone.solidAnglePdf() / static_cast<double>(lights_.size());
        }
    }
    const Vec3 d = pLight - ref;
    const double dist2 = dot(d, d);
    const double cosLight = std::abs(dot(nLight, d)) / std::sqrt(dist2);
    if (cosLight <= 0) return 0.0;
    return dist2 / (scene_.geometry.area(shape) * cosLight) / static_cast<double>(lights_.size());
}

}  // namespace fluorosim
