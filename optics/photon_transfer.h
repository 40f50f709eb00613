#pragma once
// Photon-transfer (mean-variance) calibration of a camera from flat fields (Janesick, "Photon
// Transfer", SPIE 2007; EMVA 1288). In ADU, with offset b, conversion gain g (e-/ADU) and read
// noise s (e- rms), a flat field of mean m has the temporal variance
//     var = (m - b) / g + s^2 / g^2 + 1/12,
// the 1/12 ADU^2 being the rounding to integer ADU (exact to many digits once the noise is a few
// ADU wide). Dark current is part of (m - b) and of the shot noise, so it needs no separate term.
// For an EMCCD at gain M the slope is F^2 M / g = 2 M / g instead, so the fitted "gain" is g / (2 M).
#include <cstddef>
#include <cstdint>
#include <vector>

namespace fluorosim::optics {

struct PhotonTransferPoint {
    double meanAdu = 0;           // mean over pixels and frames
    double varianceAdu2 = 0;      // temporal variance of a pixel, averaged over pixels
    double degreesOfFreedom = 0;  // of the variance: pixels * (frames - 1)
    double samples = 0;           // behind the mean: pixels * frames
};

// One point from a temporal stack (>= 2 frames of one flat field, all the same size). Each pixel's
// variance is taken over its own frames, so fixed-pattern noise (per-pixel offset or gain
// differences) does not enter; for two frames this is the frame-difference estimator var(A-B)/2.
// Throws ConfigError for fewer than 2 frames, empty or unequal frames.
PhotonTransferPoint measurePhotonTransferPoint(const std::vector<std::vector<uint16_t>>& frames);

struct PhotonTransferFit {
    double gainElectronsPerAdu = 0, gainStdErr = 0;
    double readNoiseElectrons = 0, readNoiseStdErr = 0;  // 0 (and stderr NaN) if the intercept is below 1/12
    double slope = 0, intercept = 0;                     // var = slope * (mean - offset) + intercept, in ADU^2
    double chi2 = 0;                                     // weighted residuals; about `dof` when the model holds
    int dof = 0;                                         // points - 2
};

// Weighted least squares of variance on (mean - offsetAdu). Each point's weight is the inverse of
// its variance's sampling variance, 2 var^2 / dof (Gaussian noise), plus slope^2 var / samples for
// the noise of its mean; var is the model's prediction, iterated to convergence. Standard errors come
// from the fit's covariance and the delta method. Throws ConfigError for fewer than 2 points, points
// without degrees of freedom, non-finite values, or means that do not spread.
PhotonTransferFit fitPhotonTransfer(const std::vector<PhotonTransferPoint>& points, double offsetAdu,
                                    bool includeQuantization = true);

}  // namespace fluorosim::optics
