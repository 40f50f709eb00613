#pragma once
// The wavelengths a path carries, each with the pdf it was sampled with (pbrt-v4 style).
#include <array>

#include "spectral/sampled_spectrum.h"

namespace fluorosim {

struct SampledWavelengths {
    std::array<double, kNumWavelengths> lambda{};
    // Density per nm for continuous samples; a probability mass when `discrete` (a spectral line).
    std::array<double, kNumWavelengths> pdf{};
    bool discrete = false;

    // Hero wavelength at u, companions rotated by 1/4 of the range (stratified; each marginal is uniform).
    static SampledWavelengths sampleUniform(double u, double lambdaMin, double lambdaMax, double weight = 1.0);
    // All four slots at one spectral line, sampled with probability mass `mass`.
    static SampledWavelengths atLine(double lambdaNm, double mass);
};

}  // namespace fluorosim
