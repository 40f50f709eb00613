#pragma once
// A fluorescent dye: absorption through its molar extinction spectrum, re-emission through its
// quantum yield and emission spectrum (Kasha-Vavilov: the emission spectrum does not depend on the
// excitation wavelength, so the inelastic kernel is separable; see docs/model.md).
#include <string>
#include <utility>

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
    double emissionPdfMax() const { return emissionMax_; }
    // Smallest intervals outside which the spectra are exactly zero (nm).
    std::pair<double, double> excitationSupport() const { return excitationSupport_; }
    std::pair<double, double> emissionSupport() const { return emissionSupport_; }
    // Wavelengths the excitation table covers (it is 0 outside, by assumption rather than by data).
    std::pair<double, double> excitationTableRange() const { return {excitation_.minLambda(), excitation_.maxLambda()}; }

private:
    std::string id_;
    TabulatedSpectrum excitation_;  // peak 1
    double extinctionPeak_;
    TabulatedSpectrum emission_;    // unit integral
    double quantumYield_;
    double emissionMax_;
    std::pair<double, double> excitationSupport_, emissionSupport_;
};

// Absorption coefficient of a dye, mu_a = ln(10) epsilon(lambda) c, in 1/mm for c in mol/L.
// Templated on the scalar so that fitting code can differentiate it (e.g. with ceres::Jet).
inline constexpr double kLn10PerCmToPerMm = kLn10 * 0.1;
template <class Scalar>
Scalar dyeAbsorption(const Fluorophore& dye, double lambdaNm, const Scalar& molar) {
    return molar * (kLn10PerCmToPerMm * dye.molarExtinction(lambdaNm));
}
// The same at the excitation peak.
template <class Scalar>
Scalar dyePeakAbsorption(const Fluorophore& dye, const Scalar& molar) {
    return molar * (kLn10PerCmToPerMm * dye.extinctionPeak());
}

}  // namespace fluorosim
