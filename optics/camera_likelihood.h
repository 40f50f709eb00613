#pragma once
// The camera's likelihood of a pixel, for fitting expected photoelectrons to a noisy stack.
//
// A pixel's signal in photoelectrons, s = (ADU − offset) · gain / M (gain in e-/ADU after the EM gain M),
// has mean μ (signal plus dark electrons) and variance F² μ + σ², with σ the read noise referred to
// the photoelectrons (read noise / M) and F² the excess noise factor (1 for sCMOS, 2 for an EMCCD:
// optics/detector.h). The shifted, scaled Poisson approximation (Huang et al. 2013, Nature Methods,
// for sCMOS; F² = 2 its EMCCD form) matches both moments:
//   x = (s + σ²/F²) / F²,   λ = (μ + σ²/F²) / F²,   x ~ Poisson(λ),
// negative log-likelihood Σ λ − x ln λ. A fit minimises it as least squares over the signed-root
// deviance r = sign(x − λ) √(2 [λ − x + x ln(x/λ)]) (Σ r² is twice the negative log-likelihood up to a
// constant), which is unbiased at any count; Pearson residuals (x − λ)/√λ with live weights are biased
// (Humphrey, Liu & Buote 2009) and are kept only for that comparison. The Fisher information of λ in
// this model is 1/λ per pixel.
// x is not clamped at zero (Huang et al. clamp it): read noise makes x < 0 in dark pixels, and a clamp
// raises their mean above λ, a bias that reached 7 standard errors at one photoelectron per pixel
// (tests/optics/concentration_fit_test.cpp). For x <= 0 the residual keeps the Poisson score
// ∂(r²/2)/∂λ = 1 − x/λ: r² = 2λ − 2x ln(λ/λ_min), with λ_min = σ²/F⁴ the smallest mean a pixel can
// have, which is continuous with the deviance at x = 0 and non-negative for λ >= λ_min.
#include <algorithm>
#include <vector>

#include "optics/ome_tiff.h"

namespace fluorosim::optics {

struct CameraNoise {
    double gainElectronsPerAdu = 0.46;  // after the EM gain
    double offsetAdu = 100;
    double readNoiseElectrons = 1.4;    // at the output, before the EM gain is divided out
    double emGain = 1;
    double excessNoiseFactorSquared = 1;  // F²: 1 for sCMOS, 2 for an EMCCD
    double fullWellElectrons = 30000;
    double adcMaxAdu = 65535;
    double darkElectrons = 0;           // dark current × exposure, per pixel

    static CameraNoise fromMetadata(const CameraMetadata& camera, double exposureS);
    double readSigmaElectrons() const { return readNoiseElectrons / emGain; }
    double shift() const { return readSigmaElectrons() * readSigmaElectrons() / excessNoiseFactorSquared; }
    // Photoelectrons from ADU.
    double electrons(double adu) const { return (adu - offsetAdu) * gainElectronsPerAdu / emGain; }
    // The Poisson-scaled observation x and mean λ, and the smallest mean (no signal).
    double scaledObservation(double signalElectrons) const;
    double scaledMinimum() const { return std::max(shift() / excessNoiseFactorSquared, 1e-12); }
    double scaledMean(double expectedElectrons) const { return (expectedElectrons + shift()) / excessNoiseFactorSquared; }
    // Whether an ADU value lies where the camera clips (at the ADC's maximum, or within `sigmas` noise
    // standard deviations of the full well): such pixels are left out of a fit.
    bool saturated(double adu, double sigmas) const;
};

// The signed-root deviance of an observation x under a Poisson mean λ >= λ_min > 0, and its derivative
// with respect to λ; a series near x = λ keeps both accurate where the closed form cancels. x <= 0
// (read noise below a dark pixel's mean) takes the continuation above.
struct DevianceResidual {
    double r, dr;
};
DevianceResidual devianceResidual(double x, double lambda, double lambdaMin = 1e-12);

}  // namespace fluorosim::optics
