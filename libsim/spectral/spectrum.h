#pragma once
// A spectrum: a constant or a tabulated function, plus optional spectral lines (Dirac deltas with a
// given integrated power). Lines only make sense for emission; coefficients and reflectances reject them.
#include <optional>
#include <utility>
#include <vector>

#include "spectral/sampled_wavelengths.h"
#include "spectral/tabulated_spectrum.h"

namespace fluorosim {

struct SpectralLine {
    double lambdaNm;
    double power;  // integrated over wavelength (the delta's weight)
};

class Spectrum {
public:
    Spectrum() = default;
    static Spectrum constant(double c);
    static Spectrum tabulated(TabulatedSpectrum t, double scale = 1.0);
    static Spectrum lines(std::vector<SpectralLine> lines);

    // Continuous part at one wavelength.
    double operator()(double lambdaNm) const;
    // Continuous part at the sampled wavelengths (for coefficients, reflectances, filters).
    SampledSpectrum sample(const SampledWavelengths& wl) const;
    // Emission as a measure: line power when the wavelengths sit on a line, else the continuous density.
    SampledSpectrum sampleEmission(const SampledWavelengths& wl) const;

    const std::vector<SpectralLine>& spectralLines() const { return lines_; }
    bool hasContinuousPart() const { return constant_ != 0.0 || table_.has_value(); }
    bool isConstant() const { return !table_ && lines_.empty(); }
    // Wavelength range of the tabulated part, if any (outside it the spectrum is 0).
    std::optional<std::pair<double, double>> tableRange() const {
        if (!table_) return std::nullopt;
        return std::pair{table_->minLambda(), table_->maxLambda()};
    }
    double maxValue() const;
    // Total power over [a, b]: continuous integral plus lines inside the range.
    double integral(double a, double b) const;
    Spectrum scaled(double s) const;

private:
    double constant_ = 0.0;
    std::optional<TabulatedSpectrum> table_;
    double tableScale_ = 1.0;
    std::vector<SpectralLine> lines_;
};

}  // namespace fluorosim
