#pragma once
// The path tracer's estimate of the power leaving a ball (for example a dyed sphere): radiance is
// traced backwards from uniform points on the ball's surface along cosine-distributed inward
// directions, so power = area x π x E[L]. It is the quantity the forward photon tracer tallies,
// which makes the two estimators directly comparable.
#include <cstdint>
#include <vector>

#include "render/path_tracer.h"
#include "render/tally.h"

namespace fluorosim {

struct FluxSensorOptions {
    Vec3 center;
    double radius = 1;                 // mm; must enclose the emitting media, in vacuum
    uint64_t paths = 100000;
    uint64_t seed = 1;
    int threads = 0;
    std::vector<double> binEdgesNm;    // spectral bins of the fluorescent power
};

struct FluxSensorResult {
    TallyValue fluorescentPower;             // W
    TallyValue fluorescentPowerTimesLambda;  // W nm, proportional to photons per second
    TallyValue elasticPower;                 // W
    std::vector<TallyValue> binPower;        // fluorescent power per bin
    PathStats stats;
    double seconds = 0;
};

FluxSensorResult measureExitantFlux(const Scene& scene, const FluxSensorOptions& options);

}  // namespace fluorosim
