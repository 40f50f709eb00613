#pragma once
// A fluorescent dye: absorption through its molar extinction spectrum, re-emission through its
// quantum yield and emission spectrum. This build uses the absorption; re-emission (the inelastic
// source term) is not simulated yet, and scenes with dyes say so in Scene::warnings.
#include <string>

#include "core/math.h"
#include "spectral/tabulated_spectrum.h"

namespace fluorosim {

class Fluorophore {
public:
    // excitationRelative: absorption spectrum, any scale (normalized here to peak 1).
    // extinctionPeak: molar extinction at the excitation peak, M^-1 cm^-1.
    // emissionRelative: emission spectrum in photon units, any scale (normalized here to unit integral).
    // Throws ConfigError naming `id` for a non-positive or non-finite extinction, a quantum yield
    // outside [0, 1], or spectra with no signal.
    Fluorophore(std::string id, const TabulatedSpectrum& excitationRelative, double extinctionPeak,
                const TabulatedSpectrum& emissionRelative, double quantumYield);

    const std::string& id() const { return id_; }
    double extinctionPeak() const { return extinctionPeak_; }
    double quantumYield() const { return quantumYield_; }
    // Molar extinction coefficient epsilon(lambda), M^-1 cm^-1.
    double molarExtinction(double lambdaNm) const { return extinctionPeak_ * excitation_(lambdaNm); }
    // Emission spectrum as a probability density over wavelength (1/nm, photon units).
    double emissionPdf(double lambdaNm) const { return emission_(lambdaNm); }
    const TabulatedSpectrum& emission() const { return emission_; }

private:
    std::string id_;
    TabulatedSpectrum excitation_;  // peak 1
    double extinctionPeak_;
    TabulatedSpectrum emission_;    // unit integral
    double quantumYield_;
};

// Absorption coefficient of a dye, mu_a = ln(10) epsilon(lambda) c, in 1/mm for c in mol/L.
// Templated on the scalar so that fitting code can differentiate it (e.g. with ceres::Jet).
template <class Scalar>
Scalar dyeAbsorption(const Fluorophore& dye, double lambdaNm, const Scalar& molar) {
    constexpr double kPerCmToPerMm = 0.1;
    return molar * (kLn10 * dye.molarExtinction(lambdaNm) * kPerCmToPerMm);
}

}  // namespace fluorosim
