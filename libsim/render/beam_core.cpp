#include "render/beam_core.h"

#include <algorithm>
#include <cmath>

#include "core/sampling.h"

namespace fluorosim {

std::vector<BeamLine> beamLines(const std::vector<Light>& lights) {
    std::vector<BeamLine> lines;
    for (const Light& light : lights)
        if (const BeamLight* b = std::get_if<BeamLight>(&light))
            for (const SpectralLine& line : b->profile->spectrum().spectralLines())
                if (line.power > 0) lines.push_back({b->profile.get(), line.lambdaNm, line.power});
    return lines;
}

BeamCore coreAhead(const BeamProfile& profile, const Ray& ray, int side, double lambdaNm) {
    BeamCore core = profile.coreAlong(ray, side, lambdaNm);
    BeamCore ahead;
    for (int k = 0; k < core.count; ++k) {
        BeamCoreInterval piece = core.intervals[static_cast<size_t>(k)];
        piece.tMin = std::max(piece.tMin, 0.0);
        if (piece.tMax > piece.tMin) ahead.intervals[static_cast<size_t>(ahead.count++)] = piece;
    }
    return ahead;
}

namespace {
double uniformShare(const BeamCoreInterval& piece) { return std::isfinite(piece.tMax - piece.tMin) ? kUniformCoreShare : 0.0; }
}  // namespace

double sampleCorePoint(double u, const BeamCoreInterval& piece, double* pdf) {
    const double share = uniformShare(piece);
    double t = 0;
    if (u < share) {
        t = piece.tMin + (u / share) * (piece.tMax - piece.tMin);
    } else {
        if (!std::isfinite(piece.sigma) && !std::isfinite(piece.tMax - piece.tMin)) {
            *pdf = 0;
            return piece.tMin;
        }
        double normalPdf = 0;
        t = sampleTruncatedNormal((u - share) / (1 - share), piece.centre, piece.sigma, piece.tMin, piece.tMax, &normalPdf);
    }
    *pdf = corePointPdf(t, piece);
    return t;
}

double corePointPdf(double t, const BeamCoreInterval& piece) {
    if (!(t >= piece.tMin && t <= piece.tMax)) return 0.0;
    const double share = uniformShare(piece);
    if (share == 0 && !std::isfinite(piece.sigma)) return 0.0;
    const double normal = truncatedNormalPdf(t, piece.centre, piece.sigma, piece.tMin, piece.tMax);
    return (1 - share) * normal + (share > 0 ? share / (piece.tMax - piece.tMin) : 0.0);
}

}  // namespace fluorosim
