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

double CameraNoise::scaledObservation(double signalElectrons) const { return std::max(0.0, (signalElectrons + shift()) / excessNoiseFactorSquared); }

bool CameraNoise::saturated(double adu, double sigmas) const {
    if (adu >= adcMaxAdu - 0.5) return true;
    const double sigma = std::sqrt(excessNoiseFactorSquared * fullWellElectrons + readSigmaElectrons() * readSigmaElectrons());
    return electrons(adu) >= fullWellElectrons - sigmas * sigma;
}

DevianceResidual devianceResidual(double x, double lambda) {
    const double d = x - lambda;
    // Near x = λ: with u = d/λ, λ − x + x ln(x/λ) = λ [u²/2 − u³/6 + u⁴/12 − u⁵/20 + ...], so
    // r = (d/√λ) √(1 − u/3 + u²/6 − u³/10 + ...), and dr/dλ follows by differentiating in λ.
    const double u = d / lambda;
    if (std::abs(u) < 1e-3) {
        const double series = 1 - u / 3 + u * u / 6 - u * u * u / 10;
        const double s = std::sqrt(series);
        const double r = d / std::sqrt(lambda) * s;
        // dr/dλ = 0.5 (∂r²/∂λ) / r with ∂r²/∂λ = 2 (1 − x/λ) = −2u: dr/dλ = −u/r when r ≠ 0.
        // At r = 0 the limit is −1/√λ (r ≈ −(λ − x)/√λ).
        const double dr = d == 0 ? -1 / std::sqrt(lambda) : -u / r;
        return {r, dr};
    }
    const double dev = x > 0 ? 2 * (lambda - x + x * std::log(x / lambda)) : 2 * lambda;
    const double r = (d > 0 ? 1.0 : -1.0) * std::sqrt(std::max(0.0, dev));
    return {r, -u / r};
}

}  // namespace fluorosim::optics
