#include "spectral/sampled_wavelengths.h"

#include <cmath>

namespace fluorosim {

SampledWavelengths SampledWavelengths::sampleUniform(double u, double lambdaMin, double lambdaMax, double weight) {
    SampledWavelengths wl;
    const double range = lambdaMax - lambdaMin;
    for (int i = 0; i < kNumWavelengths; ++i) {
        double ui = u + static_cast<double>(i) / kNumWavelengths;
        ui -= std::floor(ui);
        wl.lambda[i] = lambdaMin + ui * range;
        wl.pdf[i] = weight / range;
    }
    return wl;
}

SampledWavelengths SampledWavelengths::atLine(double lambdaNm, double mass) {
    SampledWavelengths wl;
    wl.lambda.fill(lambdaNm);
    wl.pdf.fill(mass);
    wl.discrete = true;
    return wl;
}

}  // namespace fluorosim
