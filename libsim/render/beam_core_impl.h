#pragma once
// The template of beam_core.h.
#include <cmath>

#include "core/sampling.h"

namespace fluorosim {

template <class SourcePerChannel>
double addCorePoints(const Scene& scene, const BeamLine& beam, int line, const Ray& ray, const std::vector<RaySegment>& segments,
                     double uPoints, SourcePerChannel&& sourcePerChannel, std::vector<CorePoint>& out) {
    constexpr double kMm2PerM2 = 1e6;  // irradiance W/mm² -> W/m², as the light sampler converts it
    double total = 0;
    ChannelValues ch;
    for (int side = 0; side < beam.profile->sides(); ++side) {
        const BeamCore core = beam.profile->coreAlong(ray, side, beam.lambdaNm);
        for (size_t si = 0; si < segments.size() && core.count > 0; ++si) {
            const RaySegment& seg = segments[si];
            if (seg.medium == kNone || scene.media[static_cast<size_t>(seg.medium)].isVacuumLike()) continue;
            const Medium& med = scene.media[static_cast<size_t>(seg.medium)];
            const std::array<double, kMaxMediumChannels> perChannel = sourcePerChannel(seg.medium, side);
            bool any = false;
            for (int c = 0; c < med.channelCount(); ++c) any = any || perChannel[static_cast<size_t>(c)] > 0;
            if (!any) continue;
            for (int k = 0; k < core.count; ++k) {
                const BeamCoreInterval& iv = core.intervals[static_cast<size_t>(k)];
                const double lo = std::max(iv.tMin, seg.t0), hi = std::min(iv.tMax, seg.t1);
                // An unbounded piece needs the normal proposal; uniform over it is impossible.
                if (!(hi > lo) || (!std::isfinite(hi - lo) && !std::isfinite(iv.sigma))) continue;
                // A defensive mixture: the profile's normal across the beam, and uniform over the piece,
                // which bounds the weights where the normal misjudges the profile (a line nearly
                // parallel to a sheet, along which the beam widens).
                const double uniformShare = std::isfinite(hi - lo) ? kUniformCoreShare : 0.0;
                for (int n = 0; n < kPointsPerCore; ++n) {
                    const double u = (n + uPoints) / kPointsPerCore;
                    double pdf = 0, t = 0;
                    if (u < uniformShare) t = lo + (u / uniformShare) * (hi - lo);
                    else t = sampleTruncatedNormal((u - uniformShare) / (1 - uniformShare), iv.centre, iv.sigma, lo, hi, &pdf);
                    pdf = (1 - uniformShare) * truncatedNormalPdf(t, iv.centre, iv.sigma, lo, hi) + (uniformShare > 0 ? uniformShare / (hi - lo) : 0.0);
                    if (!(pdf > 0)) continue;
                    const Vec3 y = ray.at(t);
                    const double E = beam.profile->irradiance(y, side, beam.lambdaNm) * kMm2PerM2 * beam.weight;
                    if (!(E > 0)) continue;
                    med.channelValues(y, ch.data());
                    double source = 0;
                    for (int c = 0; c < med.channelCount(); ++c) source += perChannel[static_cast<size_t>(c)] * ch[static_cast<size_t>(c)];
                    const double w = source * E / (pdf * kPointsPerCore);
                    if (!(w > 0)) continue;
                    out.push_back({y, t, seg.medium, line, side, w});
                    total += w;
                }
            }
        }
    }
    return total;
}

}  // namespace fluorosim
