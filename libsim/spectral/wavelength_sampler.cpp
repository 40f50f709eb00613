#include "spectral/wavelength_sampler.h"

#include <algorithm>
#include <cmath>
#include <string>

#include "core/errors.h"

namespace fluorosim {

WavelengthSampler::WavelengthSampler(double lambdaMin, double lambdaMax, std::vector<double> lines, bool hasContinuousEmission)
    : lambdaMin_(lambdaMin), lambdaMax_(lambdaMax), lines_(std::move(lines)) {
    if (!(lambdaMin > 0) || !(lambdaMax > lambdaMin) || lambdaMax > 1e5)
        throw ConfigError("wavelength range must satisfy 0 < min < max, got [" + std::to_string(lambdaMin) + ", " +
                          std::to_string(lambdaMax) + "] nm");
    std::sort(lines_.begin(), lines_.end());
    lines_.erase(std::unique(lines_.begin(), lines_.end()), lines_.end());
    // Half the samples go to lines when both kinds of emission exist.
    lineProbability_ = lines_.empty() ? 0.0 : (hasContinuousEmission ? 0.5 : 1.0);
}

SampledWavelengths WavelengthSampler::sample(double uBranch, double u) const {
    if (lineProbability_ > 0 && uBranch < lineProbability_) {
        const size_t n = lines_.size();
        const size_t i = std::min(n - 1, static_cast<size_t>(uBranch / lineProbability_ * static_cast<double>(n)));
        return SampledWavelengths::atLine(lines_[i], lineMass());
    }
    if (cellPdf_.empty()) return SampledWavelengths::sampleUniform(u, lambdaMin_, lambdaMax_, 1.0 - lineProbability_);
    // Hero and companions rotated in CDF space: each slot's marginal density is the tabulated one.
    SampledWavelengths wl;
    const double n = static_cast<double>(cellPdf_.size()), width = (lambdaMax_ - lambdaMin_) / n;
    for (int i = 0; i < kNumWavelengths; ++i) {
        double ui = u + static_cast<double>(i) / kNumWavelengths;
        ui -= std::floor(ui);
        const size_t c = std::min(cellPdf_.size() - 1,
                                  static_cast<size_t>(std::upper_bound(cellCdf_.begin(), cellCdf_.end(), ui) - cellCdf_.begin()));
        const double before = c == 0 ? 0.0 : cellCdf_[c - 1];
        const double mass = cellCdf_[c] - before;
        const double t = mass > 0 ? std::clamp((ui - before) / mass, 0.0, 1.0) : 0.5;
        wl.lambda[i] = lambdaMin_ + (static_cast<double>(c) + t) * width;
        wl.pdf[i] = (1.0 - lineProbability_) * cellPdf_[c];
    }
    return wl;
}

void WavelengthSampler::setContinuousDensity(std::vector<double> density) {
    double sum = 0;
    for (double d : density) {
        if (!(d >= 0) || !std::isfinite(d)) throw ConfigError("wavelength density must be finite and non-negative");
        sum += d;
    }
    if (!(sum > 0)) throw ConfigError("wavelength density has no positive value");
    const double width = (lambdaMax_ - lambdaMin_) / static_cast<double>(density.size());
    cellPdf_.clear();
    cellCdf_.clear();
    double acc = 0;
    for (double d : density) {
        cellPdf_.push_back(d / (sum * width));
        acc += d / sum;
        cellCdf_.push_back(acc);
    }
    cellCdf_.back() = 1.0;
}

double WavelengthSampler::continuousPdf(double lambda) const {
    if (lambda < lambdaMin_ || lambda > lambdaMax_) return 0.0;
    if (cellPdf_.empty()) return 1.0 / (lambdaMax_ - lambdaMin_);
    const double n = static_cast<double>(cellPdf_.size());
    const size_t c = std::min(cellPdf_.size() - 1, static_cast<size_t>((lambda - lambdaMin_) / (lambdaMax_ - lambdaMin_) * n));
    return cellPdf_[c];
}

}  // namespace fluorosim
