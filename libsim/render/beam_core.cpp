#include "render/beam_core.h"

#include <limits>

namespace fluorosim {

std::vector<BeamLine> beamLines(const std::vector<Light>& lights) {
    std::vector<BeamLine> lines;
    for (const Light& light : lights)
        if (const BeamLight* b = std::get_if<BeamLight>(&light))
            for (const SpectralLine& line : b->profile->spectrum().spectralLines())
                if (line.power > 0) lines.push_back({b->profile.get(), line.lambdaNm, line.power});
    return lines;
}

int straightSegments(const Scene& scene, const Ray& ray, int medium, double tMin, std::array<RaySegment, kMaxRaySegments>& out) {
    int count = 0;
    Ray r = ray;
    double tBase = 0;
    int current = medium;
    for (int crossings = 0; crossings < 1000 && count < kMaxRaySegments; ++crossings) {
        const auto hit = scene.geometry.intersect(r, tMin, std::numeric_limits<double>::infinity());
        const double t1 = hit ? tBase + hit->t : std::numeric_limits<double>::infinity();
        if (current != kNone && !scene.media[static_cast<size_t>(current)].isVacuumLike()) out[static_cast<size_t>(count++)] = {tBase, t1, current};
        if (!hit) break;
        const ShapeInfo& s = scene.shapes[hit->shape];
        if (!(s.isInterface && s.material == kNone)) break;
        current = dot(r.d, hit->n) < 0 ? s.insideMedium : s.outsideMedium;
        r.o = hit->p;
        tBase = t1;
        // Rays leave a surface from on it and skip it with tMin (as the path tracer does).
        tMin = hit->epsilon / std::max(std::abs(dot(hit->n, r.d)), 1e-2);
    }
    return count;
}

}  // namespace fluorosim
