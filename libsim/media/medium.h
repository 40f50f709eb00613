#pragma once
// Participating media. A homogeneous medium has spectral absorption and scattering coefficients
// (1/mm), a Henyey-Greenstein phase function and a refractive index. Coefficients are evaluated by
// pure const functions with no hidden state, so later fitting code can differentiate them.
#include <span>
#include <string>
#include <vector>

#include "media/fluorophore.h"
#include "media/free_flight.h"
#include "media/henyey_greenstein.h"
#include "spectral/spectrum.h"

namespace fluorosim {

struct MediumSample {
    SampledSpectrum sigmaA, sigmaS;
};

struct DyeComponent {
    Fluorophore dye;
    double molar;  // concentration, mol/L
};

// Absorption coefficient (1/mm) of a solvent holding dyes at the given concentrations (mol/L):
// sigma_a(lambda) = sigma_a,solvent(lambda) + sum_i ln(10) epsilon_i(lambda) c_i. A pure function,
// templated on the scalar so that fitting code can evaluate it on ceres::Jet concentrations; the
// tracer calls it with double.
template <class Scalar>
Scalar absorptionCoefficient(const Spectrum& solventAbsorption, const std::vector<DyeComponent>& dyes,
                             std::span<const Scalar> molar, double lambdaNm) {
    Scalar sum = Scalar(solventAbsorption(lambdaNm));
    for (size_t i = 0; i < dyes.size(); ++i) sum = sum + dyeAbsorption(dyes[i].dye, lambdaNm, molar[i]);
    return sum;
}

class HomogeneousMedium {
public:
    // sigmaA is the solvent's own absorption; dyes add theirs. Throws ConfigError (naming `name`) for
    // negative or non-finite coefficients or concentrations, |g| >= 1, ior < 1.
    HomogeneousMedium(std::string name, Spectrum sigmaA, Spectrum sigmaS, double g, double ior,
                      std::vector<DyeComponent> dyes = {});
    const std::vector<DyeComponent>& dyes() const { return dyes_; }

    const std::string& name() const { return name_; }
    const Spectrum& solventAbsorption() const { return sigmaA_; }
    const Spectrum& scattering() const { return sigmaS_; }
    double ior() const { return ior_; }
    const HenyeyGreenstein& phase() const { return phase_; }
    bool isVacuumLike() const { return vacuum_; }  // no absorption or scattering anywhere

    MediumSample coefficients(const SampledWavelengths& wl) const {
        MediumSample m{SampledSpectrum(0.0), sigmaS_.sample(wl)};
        for (int i = 0; i < kNumWavelengths; ++i)
            m.sigmaA[i] = absorptionCoefficient<double>(sigmaA_, dyes_, molar_, wl.lambda[i]);
        return m;
    }
    // Total absorption (solvent and dyes) and scattering at one wavelength, 1/mm.
    double absorptionAt(double lambdaNm) const { return absorptionCoefficient<double>(sigmaA_, dyes_, molar_, lambdaNm); }
    double scatteringAt(double lambdaNm) const { return sigmaS_(lambdaNm); }
    HomogeneousMajorantIterator<SampledSpectrum> majorants(double tMin, double tMax,
                                                           const SampledWavelengths& wl) const {
        const MediumSample m = coefficients(wl);
        return {tMin, tMax, m.sigmaA + m.sigmaS};
    }

private:
    std::string name_;
    Spectrum sigmaA_, sigmaS_;
    std::vector<DyeComponent> dyes_;
    std::vector<double> molar_;
    HenyeyGreenstein phase_;
    double ior_;
    bool vacuum_;
};

}  // namespace fluorosim
