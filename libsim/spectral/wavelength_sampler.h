#pragma once
// Chooses the wavelengths of a path: stratified hero wavelengths over [lambdaMin, lambdaMax], or,
// when emitters have spectral lines, one of those lines with a probability mass. The estimator is
// then unbiased for spectra that mix continuous densities and lines.
#include <vector>

#include "spectral/sampled_wavelengths.h"

namespace fluorosim {

class WavelengthSampler {
public:
    // Lines outside the range are ignored by the caller's validation, not here.
    WavelengthSampler(double lambdaMin, double lambdaMax, std::vector<double> lines, bool hasContinuousEmission);
    // The continuous part follows `density` (any non-negative values on equal cells spanning
    // [lambdaMin, lambdaMax], normalized here) instead of being uniform. Throws ConfigError if it has
    // no positive cell.
    void setContinuousDensity(std::vector<double> density);
    SampledWavelengths sample(double uBranch, double u) const;
    // Density of the continuous part at one wavelength (without the branch weight), for tests.
    double continuousPdf(double lambda) const;
    double lambdaMin() const { return lambdaMin_; }
    double lambdaMax() const { return lambdaMax_; }
    double lineProbability() const { return lineProbability_; }
    // Probability mass of one line, or density of a continuous wavelength (for tests).
    double lineMass() const { return lines_.empty() ? 0.0 : lineProbability_ / static_cast<double>(lines_.size()); }

private:
    double lambdaMin_, lambdaMax_;
    std::vector<double> lines_;
    double lineProbability_;
    std::vector<double> cellPdf_, cellCdf_;  // empty: uniform
};

}  // namespace fluorosim
