#pragma once
// Points where a ray crosses the cores of beams (scene/beam.h), shared by the estimators that
// integrate a beam's unscattered light along rays instead of waiting for a path vertex to land in a
// thin sheet: the microscope's direct estimator (render/direct_beam.h) and the path tracer's
// excitation sub-paths. A ray runs straight through null interfaces until the first surface; along
// each of its media, every core interval gets stratified points from the beam's proposal.
#include <array>
#include <vector>

#include "media/medium.h"
#include "render/straight_line.h"
#include "scene/scene.h"

namespace fluorosim {

// One line of one beam light: the light's profile, the line and its share of the beam's power.
struct BeamLine {
    const BeamProfile* profile;
    double lambdaNm, weight;
};
// Every spectral line of every beam in `lights`.
std::vector<BeamLine> beamLines(const std::vector<Light>& lights);


struct CorePoint {
    Vec3 y;
    double t;
    int medium, line, side;
    double weight;  // source per unit length / pdf / points, before transmittances
};
inline constexpr int kPointsPerCore = 8;
inline constexpr double kUniformCoreShare = 0.25;  // of the points, uniform over the piece (addCorePoints)
// Appends the core points of line `line` (all sides) along the segments (traceStraightLine's), with weight
// sourcePerChannel(medium, side) · channels(y) · E(y) / pdf / kPointsPerCore, E the line's irradiance
// in W/m². `uPoints` shifts the stratified points. Returns the sum of the weights added.
template <class SourcePerChannel>
double addCorePoints(const Scene& scene, const BeamLine& beam, int line, const Ray& ray, const std::vector<RaySegment>& segments,
                     double uPoints, SourcePerChannel&& sourcePerChannel, std::vector<CorePoint>& out);

}  // namespace fluorosim

#include "render/beam_core_impl.h"
