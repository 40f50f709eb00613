#include "optics/camera_likelihood.h"

#include <algorithm>
#include <cmath>

namespace fluorosim::optics {

CameraNoise CameraNoise::fromMetadata(const CameraMetadata& c, double exposureS) {
    CameraNoise n;
    n.gainElectronsPerAdu = c.gainElectronsPerAdu;
    n.offsetAdu = c.offsetAdu;
    n.readNoiseElectrons = c.readNoiseElectrons;
    n.emGain = c.emGain;
    // The detector's EM register has F² = 2 for every gain above 1 (optics/detector.h).
    n.excessNoiseFactorSquared = c.sensor == "EMCCD" && c.emGain > 1 ? 2.0 : 1.0;
    n.fullWellElectrons = c.fullWellElectrons;
    n.adcMaxAdu = std::ldexp(1.0, c.bitDepth) - 1;
    n.darkElectrons = c.darkCurrentElectronsPerS * exposureS;
    return n;
}

double CameraNoise::scaledObservation(double signalElectrons) const { return (signalElectrons + shift()) / excessNoiseFactorSquared; }

bool CameraNoise::saturated(double adu, double sigmas) const {
    if (adu >= adcMaxAdu - 0.5) return true;
    const double sigma = std::sqrt(excessNoiseFactorSquared * fullWellElectrons + readSigmaElectrons() * readSigmaElectrons());
    return electrons(adu) >= fullWellElectrons - sigmas * sigma;
}

DevianceResidual devianceResidual(double x, double lambda, double lambdaMin) {
    if (x <= 0) {
        const double l = std::max(lambda, lambdaMin);
        const double r = -std::sqrt(2 * l - 2 * x * std::log(l / lambdaMin));
        return {r, (1 - x / l) / r};
    }
    const double d = x - lambda;
    // Near x = λ: with u = d/λ, λ − x + x ln(x/λ) = λ Σ_{k>=2} (−u)^k/(k(k − 1)), so
    // r = (d/√λ) √(1 − u/3 + u²/6 − u³/10 + u⁴/15 − u⁵/21 + ...). Below |u| = 0.01 the series' truncation
    // (u⁶/28) and above it the closed form's cancellation (ε/u²) both stay under 1e-12.
    const double u = d / lambda;
    if (std::abs(u) < 1e-2) {
        const double series = 1 + u * (-1.0 / 3 + u * (1.0 / 6 + u * (-1.0 / 10 + u * (1.0 / 15 - u / 21))));
        const double s = std::sqrt(series);
        const double r = d / std::sqrt(lambda) * s;
        // dr/dλ = 0.5 (∂r²/∂λ) / r with ∂r²/∂λ = 2 (1 − x/λ) = −2u: dr/dλ = −u/r when r ≠ 0.
        // At r = 0 the limit is −1/√λ (r ≈ −(λ − x)/√λ).
        const double dr = d == 0 ? -1 / std::sqrt(lambda) : -u / r;
        return {r, dr};
    }
    const double dev = 2 * (lambda - x + x * std::log(x / lambda));
    const double r = (d > 0 ? 1.0 : -1.0) * std::sqrt(std::max(0.0, dev));
    return {r, -u / r};
}

}  // namespace fluorosim::optics
