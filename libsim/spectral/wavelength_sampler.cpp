#include "spectral/wavelength_sampler.h"

#include <algorithm>
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
    return SampledWavelengths::sampleUniform(u, lambdaMin_, lambdaMax_, 1.0 - lineProbability_);
}

}  // namespace fluorosim
