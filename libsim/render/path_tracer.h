#pragma once
// Unbiased spectral volumetric path tracer (pbrt-v4's VolPathIntegrator design): hero wavelengths
// with path-space spectral MIS through rescaled path pdfs (r_u, r_l), next-event estimation with
// MIS at surfaces and in media, free flights through sampleTmaj, and Russian roulette on the
// MIS-weighted throughput (bounded by 1, so surviving weights cannot explode).
#include <cstdint>

#include "core/rng.h"
#include "scene/light_sampler.h"
#include "scene/scene.h"

namespace fluorosim {

struct PathStats {
    uint64_t paths = 0;
    uint64_t scatteringEvents = 0;   // real collisions in media
    uint64_t surfaceBounces = 0;
    uint64_t truncated = 0;          // paths stopped by the safety depth cap (a bias, so it is reported)
    void add(const PathStats& o) {
        paths += o.paths;
        scatteringEvents += o.scatteringEvents;
        surfaceBounces += o.surfaceBounces;
        truncated += o.truncated;
    }
};

class PathTracer {
public:
    explicit PathTracer(const Scene& scene) : scene_(scene), lights_(scene) {}
    // Radiance arriving along -ray.d at ray.o, for a ray that starts in `medium`.
    SampledSpectrum radiance(Ray ray, int medium, const SampledWavelengths& wl, Rng& rng, PathStats& stats) const;

    // Transmittance from p0 to p1 through null interfaces and media; zero if a surface blocks.
    // When p0 lies on a surface, pass its normal so the ray leaves it without self-intersection.
    SampledSpectrum transmittance(const Vec3& p0, const Vec3& p1, int medium, const SampledWavelengths& wl,
                                  const Vec3* surfaceNormal = nullptr, double surfaceEpsilon = 0.0) const;

private:
    int mediumAfterCrossing(const ShapeInfo& shape, const Vec3& n, const Vec3& dir, int current) const;

    const Scene& scene_;
    LightSampler lights_;
};

}  // namespace fluorosim
