#pragma once
// An independent forward estimator for validating the path tracer's fluorescence: analog photons
// leave the point lights, scatter, are absorbed and re-emitted by dyes (new wavelength from the
// emission spectrum, energy scaled by λ_absorbed/λ_emitted, isotropic direction), cross smooth
// dielectric interfaces by Fresnel sampling, and the fluorescent ones that escape to infinity are
// tallied. It shares only geometry queries, the HG sampler and the Fresnel formula with the path
// tracer; the adjoint weights, MIS and NEE it checks are not involved.
#include <cstdint>
#include <vector>

#include "render/tally.h"
#include "scene/scene.h"

namespace fluorosim {

struct ForwardPhotonOptions {
    uint64_t photons = 1000000;
    uint64_t seed = 1;
    int threads = 0;
    // Photons are emitted only into the cone that subtends this ball (it must enclose every medium
    // and interface), and weighted by the cone's solid angle.
    Vec3 aimCenter;
    double aimRadius = 1;
    std::vector<double> binEdgesNm;  // spectral bins for the tally (at least 2 edges)
    void validate() const;           // throws ConfigError
};

// Escaping fluorescence in watts (with the scene's units: point-light intensity in W sr^-1 nm^-1 or
// W sr^-1 per line), and the photon-count-proportional sum of power x wavelength (W nm).
struct ForwardPhotonResult {
    TallyValue fluorescentPower, fluorescentPowerTimesLambda;
    std::vector<TallyValue> binPower;  // per bin of binEdgesNm
    TallyValue absorbedPower;          // power absorbed by dyes (first absorption of light photons)
    uint64_t photons = 0;
    double seconds = 0;
};

// Only point lights are supported (others throw ConfigError); opaque surfaces absorb.
ForwardPhotonResult traceForwardPhotons(const Scene& scene, const ForwardPhotonOptions& options);

}  // namespace fluorosim
