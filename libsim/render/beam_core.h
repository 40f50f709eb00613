#pragma once
// Beams' lines, and points along a ray inside a beam's core, for estimators that integrate a beam's
// unscattered light along a line instead of waiting for a path vertex to land in a thin sheet (the path
// tracer's sheet-side sampling of scattered light).
#include <vector>

#include "scene/scene.h"

namespace fluorosim {

// One line of one beam light: the light's profile, the line and its share of the beam's power.
struct BeamLine {
    const BeamProfile* profile;
    double lambdaNm, weight;
};
// Every spectral line of every beam in `lights`.
std::vector<BeamLine> beamLines(const std::vector<Light>& lights);

// Points inside a piece of a beam's core along a ray come from a defensive mixture: the profile's normal
// across the beam, and a uniform share over the piece, which bounds the weights where the normal
// misjudges the profile (a line nearly parallel to a sheet, along which the beam widens). The pieces are
// the beam's own (coreAhead: coreAlong at t >= 0), not clipped to media, so that a point's density
// depends on the beam and the ray alone, and another strategy can evaluate it.
inline constexpr int kPointsPerCore = 8;
inline constexpr double kUniformCoreShare = 0.25;
BeamCore coreAhead(const BeamProfile& profile, const Ray& ray, int side, double lambdaNm);
// A point of `piece` from u in [0, 1), and its density; 0 for a piece no density covers (unbounded and
// uniform across).
double sampleCorePoint(double u, const BeamCoreInterval& piece, double* pdf);
double corePointPdf(double t, const BeamCoreInterval& piece);

}  // namespace fluorosim
