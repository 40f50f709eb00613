#include "optics/photon_transfer.h"

#include <cmath>
#include <limits>
#include <string>

#include "core/errors.h"

namespace fluorosim::optics {

PhotonTransferPoint measurePhotonTransferPoint(const std::vector<std::vector<uint16_t>>& frames) {
    if (frames.size() < 2)
        throw ConfigError("photon transfer: need at least 2 frames per level, got " + std::to_string(frames.size()));
    const size_t pixels = frames.front().size();
    if (pixels == 0) throw ConfigError("photon transfer: empty frame");
    for (size_t f = 1; f < frames.size(); ++f)
        if (frames[f].size() != pixels)
            throw ConfigError("photon transfer: frame " + std::to_string(f) + " has " + std::to_string(frames[f].size()) +
                              " pixels, frame 0 has " + std::to_string(pixels));
    const double nf = static_cast<double>(frames.size());
    double sumMean = 0, sumVar = 0;
    for (size_t i = 0; i < pixels; ++i) {
        double mean = 0;
        for (const auto& frame : frames) mean += frame[i];
        mean /= nf;
        double ss = 0;
        for (const auto& frame : frames) ss += (frame[i] - mean) * (frame[i] - mean);
        sumMean += mean;
        sumVar += ss / (nf - 1.0);
    }
    const double np = static_cast<double>(pixels);
    return {sumMean / np, sumVar / np, np * (nf - 1.0), np * nf};
}

PhotonTransferFit fitPhotonTransfer(const std::vector<PhotonTransferPoint>& points, double offsetAdu, bool includeQuantization) {
    if (points.size() < 2) throw ConfigError("photon transfer: need at least 2 levels, got " + std::to_string(points.size()));
    if (!std::isfinite(offsetAdu)) throw ConfigError("photon transfer: offset is not finite");
    for (size_t i = 0; i < points.size(); ++i) {
        const PhotonTransferPoint& p = points[i];
        if (!std::isfinite(p.meanAdu) || !std::isfinite(p.varianceAdu2) || !(p.varianceAdu2 > 0) || !(p.degreesOfFreedom > 0) ||
            !(p.samples > 0))
            throw ConfigError("photon transfer: level " + std::to_string(i) +
                              " needs a finite mean, a positive variance and positive degrees of freedom");
    }
    const double q = includeQuantization ? 1.0 / 12.0 : 0.0;

    PhotonTransferFit fit;
    double S = 0, Sx = 0, Sxx = 0, det = 0;
    // Start from the measured variances and no mean noise; then weight by the model's prediction.
    // A handful of iterations converges far below the statistical error.
    for (int iter = 0; iter < 8; ++iter) {
        S = Sx = Sxx = 0;
        double Sy = 0, Sxy = 0;
        for (const PhotonTransferPoint& p : points) {
            const double x = p.meanAdu - offsetAdu;
            const double v = iter == 0 ? p.varianceAdu2 : std::max(fit.slope * x + fit.intercept, 1e-12);
            const double sigma2 = 2.0 * v * v / p.degreesOfFreedom + (iter == 0 ? 0.0 : fit.slope * fit.slope * v / p.samples);
            const double w = 1.0 / sigma2;
            S += w, Sx += w * x, Sxx += w * x * x, Sy += w * p.varianceAdu2, Sxy += w * x * p.varianceAdu2;
        }
        det = S * Sxx - Sx * Sx;
        if (!(det > 1e-12 * S * Sxx)) throw ConfigError("photon transfer: the levels' means do not spread enough to fit a slope");
        fit.slope = (S * Sxy - Sx * Sy) / det;
        fit.intercept = (Sxx * Sy - Sx * Sxy) / det;
    }
    if (!(fit.slope > 0)) throw NumericError("photon transfer: fitted slope " + std::to_string(fit.slope) + " is not positive");

    const double varSlope = S / det, varIntercept = Sxx / det, cov = -Sx / det;
    const double a = fit.slope;
    fit.gainElectronsPerAdu = 1.0 / a;
    fit.gainStdErr = std::sqrt(varSlope) / (a * a);
    const double c = fit.intercept - q;  // read-noise variance in ADU^2
    if (c > 0) {
        const double r = std::sqrt(c);
        fit.readNoiseElectrons = r / a;
        // Delta method on s = sqrt(c) / a.
        const double dC = 1.0 / (2.0 * a * r), dA = -r / (a * a);
        fit.readNoiseStdErr = std::sqrt(dC * dC * varIntercept + dA * dA * varSlope + 2.0 * dC * dA * cov);
    } else {
        fit.readNoiseElectrons = 0;
        fit.readNoiseStdErr = std::numeric_limits<double>::quiet_NaN();
    }
    for (const PhotonTransferPoint& p : points) {
        const double x = p.meanAdu - offsetAdu;
        const double v = std::max(fit.slope * x + fit.intercept, 1e-12);
        const double sigma2 = 2.0 * v * v / p.degreesOfFreedom + fit.slope * fit.slope * v / p.samples;
        const double r = p.varianceAdu2 - v;
        fit.chi2 += r * r / sigma2;
    }
    fit.dof = static_cast<int>(points.size()) - 2;
    return fit;
}

}  // namespace fluorosim::optics
