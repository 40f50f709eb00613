#pragma once
// The dyes a channel computes: every emitting dye of every emitting medium, as the channel's beam lines
// excite it and its emission path detects it. Shared by the three pieces of the computed image
// y = P · diag(g) · S · c (optics/unscattered_image.h): S holds their concentrations, g their
// absorption, quantum yield and detected emission, P their polychromatic PSFs.
#include <array>
#include <functional>
#include <string>
#include <vector>

#include "render/beam_core.h"
#include "render/fluorescence.h"
#include "spectral/sampled_wavelengths.h"

namespace fluorosim::optics {

struct EmittingDye {
    int medium = 0;        // index into Scene::media
    int channel = 0;       // the medium's dye channel (kFirstDyeChannel + i)
    int slot = 0;          // its place among the medium's emitting dyes (0, 1, ...)
    std::string name;      // the dye's id
    double quantumYield = 0;
    std::vector<double> absorptionPerMolar;  // per beam line: σa(λ_l; 1 mol/L), 1/mm
    double detected = 0;                     // D = ∫ f(λ) detection(λ)/λ dλ, photoelectrons per J × nm⁻¹ scale
    std::vector<double> nodeLambda, nodeWeight;             // spectral nodes of the polychromatic PSF (weights sum to 1)
    std::array<double, kNumWavelengths> cameraWeights{};    // its detected emission over the channel's camera wavelengths
};

struct ChannelDyes {
    std::vector<double> lineLambda;       // the channel's beam lines (one per beam line, in beamLines order)
    std::vector<EmittingDye> dyes;        // ordered by medium, then by the medium's dye order
    std::array<double, kNumWavelengths> cameraLambda{};  // where the cone-mean transmittance is evaluated
    std::vector<int> firstOfMedium;       // per medium: index of its first emitting dye, or -1
    int slots = 0;                        // the most emitting dyes of one medium
    double shortestDetectedNm = 0;        // with 1e-3 of the detected band below it (the pixel quadrature's band)
    bool empty() const { return dyes.empty(); }
    // The emitting dye of `medium` in `slot`, or nullptr.
    const EmittingDye* dyeOf(int medium, int slot) const;
};

// `detection(λ)`: photoelectrons per joule at λ (emission path × QE × λ/hc). Dyes that no line excites or
// whose emission the channel does not detect are left out, and with `lineIrradiance` (per line, at the
// field's centre) so are those whose photoelectrons per mol/L fall below `dropBelow` of the channel's
// most efficient dye: the AF594 neuron in an AF488 channel (1e-7 of it) would otherwise be computed
// point by point. `spectralNodes`: equal-mass parts of each dye's detected emission for its PSF.
ChannelDyes channelDyes(const Scene& scene, const std::vector<BeamLine>& lines, const FluorescencePlan& plan,
                        const std::function<double(double)>& detection, int spectralNodes, const std::vector<double>& lineIrradiance = {},
                        double dropBelow = 0);

// Splits the distribution `density` on [lo, lo + n·step) into `count` bins of equal mass; each bin's
// centroid and mass (masses sum to 1). Empty bins are dropped.
void quantileNodes(const std::vector<double>& density, double lo, double step, int count, std::vector<double>& lambda,
                   std::vector<double>& weight);

}  // namespace fluorosim::optics
