#include "optics/psf.h"

#include <algorithm>
#include <cmath>

#include "core/math.h"

namespace fluorosim::optics {

double AiryPattern::intensity(double v) {
    if (std::abs(v) < 1e-6) return 1.0;
    const double a = 2 * std::cyl_bessel_j(1.0, v) / v;
    return a * a;
}

double AiryPattern::fwhmMm(double lambdaNm, double na) { return 1.61634 / kPi * lambdaNm * 1e-6 / na; }

AiryPattern::AiryPattern(double vMax, int cells) : vMax_(vMax) {
    v_.resize(static_cast<size_t>(cells) + 1);
    cdf_.resize(v_.size());
    double acc = 0, prev = 0;
    for (int i = 0; i <= cells; ++i) {
        const double v = vMax * i / cells;
        const double f = intensity(v) * 2 * kPi * v;
        if (i > 0) acc += 0.5 * (f + prev) * (vMax / cells);
        v_[static_cast<size_t>(i)] = v;
        cdf_[static_cast<size_t>(i)] = acc;
        prev = f;
    }
    norm_ = acc;
    for (double& c : cdf_) c /= norm_;
}

double AiryPattern::sampleRadiusMm(double u, double lambdaNm, double na) const {
    const size_t i = std::min(cdf_.size() - 1, static_cast<size_t>(std::upper_bound(cdf_.begin(), cdf_.end(), u) - cdf_.begin()));
    const double c0 = i == 0 ? 0.0 : cdf_[i - 1], c1 = cdf_[i];
    const double v0 = i == 0 ? 0.0 : v_[i - 1], v1 = v_[i];
    const double v = c1 > c0 ? v0 + (u - c0) / (c1 - c0) * (v1 - v0) : v1;
    return v * lambdaNm * 1e-6 / (2 * kPi * na);
}

double AiryPattern::densityPerMm2(double rMm, double lambdaNm, double na) const {
    const double k = 2 * kPi * na / (lambdaNm * 1e-6);  // v per mm
    const double v = k * rMm;
    if (v > vMax_) return 0.0;
    return intensity(v) * k * k / norm_;
}

}  // namespace fluorosim::optics
