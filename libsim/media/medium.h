#pragma once
// Participating media. A homogeneous medium has spectral absorption and scattering coefficients
// (1/mm), a Henyey-Greenstein phase function and a refractive index. Coefficients are evaluated by
// pure const functions with no hidden state, so later fitting code can differentiate them.
#include <string>

#include "media/free_flight.h"
#include "media/henyey_greenstein.h"
#include "spectral/spectrum.h"

namespace fluorosim {

struct MediumSample {
    SampledSpectrum sigmaA, sigmaS;
};

class HomogeneousMedium {
public:
    // Throws ConfigError (naming `name`) for negative or non-finite coefficients, |g| >= 1, ior < 1.
    HomogeneousMedium(std::string name, Spectrum sigmaA, Spectrum sigmaS, double g, double ior);

    const std::string& name() const { return name_; }
    double ior() const { return ior_; }
    const HenyeyGreenstein& phase() const { return phase_; }
    bool isVacuumLike() const { return vacuum_; }  // no absorption or scattering anywhere

    MediumSample coefficients(const SampledWavelengths& wl) const {
        return {sigmaA_.sample(wl), sigmaS_.sample(wl)};
    }
    HomogeneousMajorantIterator<SampledSpectrum> majorants(double tMin, double tMax,
                                                           const SampledWavelengths& wl) const {
        const MediumSample m = coefficients(wl);
        return {tMin, tMax, m.sigmaA + m.sigmaS};
    }

private:
    std::string name_;
    Spectrum sigmaA_, sigmaS_;
    HenyeyGreenstein phase_;
    double ior_;
    bool vacuum_;
};

}  // namespace fluorosim
