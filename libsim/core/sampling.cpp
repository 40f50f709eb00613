#include "core/sampling.h"

#include <boost/math/special_functions/erf.hpp>

#include <algorithm>
#include <cmath>
#include <numeric>

namespace fluorosim {

Vec3 sampleCosineHemisphere(double u1, double u2) {
    const double ox = 2.0 * u1 - 1.0, oy = 2.0 * u2 - 1.0;
    double r = 0, theta = 0;
    if (ox != 0 || oy != 0) {
        if (std::abs(ox) > std::abs(oy)) {
            r = ox;
            theta = (kPi / 4.0) * (oy / ox);
        } else {
            r = oy;
            theta = kPi / 2.0 - (kPi / 4.0) * (ox / oy);
        }
    }
    const double dx = r * std::cos(theta), dy = r * std::sin(theta);
    return {dx, dy, safeSqrt(1.0 - dx * dx - dy * dy)};
}

std::array<double, 2> sampleUniformTriangle(double u1, double u2) {
    double b0, b1;
    if (u1 < u2) {
        b0 = u1 / 2;
        b1 = u2 - b0;
    } else {
        b1 = u2 / 2;
        b0 = u1 - b1;
    }
    return {b0, b1};
}

int sampleDiscrete(std::span<const double> weights, double u, double* pmf, double* uRemapped) {
    const double total = std::accumulate(weights.begin(), weights.end(), 0.0);
    if (!(total > 0)) {
        if (pmf) *pmf = 0;
        return -1;
    }
    double up = u * total;
    if (up >= total) up = std::nextafter(total, 0.0);
    double sum = 0;
    for (size_t i = 0; i < weights.size(); ++i) {
        if (weights[i] <= 0) continue;
        if (up < sum + weights[i] || i + 1 == weights.size()) {
            if (pmf) *pmf = weights[i] / total;
            if (uRemapped) *uRemapped = std::min((up - sum) / weights[i], 0.99999999999999989);
            return static_cast<int>(i);
        }
        sum += weights[i];
    }
    // Trailing zero weights: fall back to the last positive one.
    for (size_t i = weights.size(); i-- > 0;)
        if (weights[i] > 0) {
            if (pmf) *pmf = weights[i] / total;
            if (uRemapped) *uRemapped = 0.5;
            return static_cast<int>(i);
        }
    return -1;
}

double sampleTruncatedNormal(double u, double mean, double sigma, double lo, double hi, double* pdf) {
    auto uniform = [&] {
        *pdf = 1.0 / (hi - lo);
        return std::clamp(lo + u * (hi - lo), lo, hi);
    };
    if (!std::isfinite(sigma) || !(sigma > 0) || hi - lo < 0.2 * sigma) return uniform();
    const double a = (lo - mean) / sigma, b = (hi - mean) / sigma;
    // Work in the tail the interval lies in (upper tail Q(x) = erfc(x/√2)/2), so that far-out
    // intervals keep their digits.
    const bool upper = a > 0;
    const double qa = 0.5 * std::erfc((upper ? a : -a) / std::sqrt(2.0)), qb = 0.5 * std::erfc((upper ? b : -b) / std::sqrt(2.0));
    const double mass = upper ? qa - qb : qb - qa;
    if (!(mass > 1e-280) || !std::isfinite(mass)) return uniform();
    double x;
    if (upper) x = std::sqrt(2.0) * boost::math::erfc_inv(2 * (qa - u * mass));
    else x = -std::sqrt(2.0) * boost::math::erfc_inv(2 * (qa + u * mass));
    const double t = std::clamp(mean + sigma * x, lo, hi);
    const double z = (t - mean) / sigma;
    *pdf = std::exp(-0.5 * z * z) / (std::sqrt(2 * kPi) * sigma * mass);
    return t;
}

double truncatedNormalPdf(double t, double mean, double sigma, double lo, double hi) {
    if (!(t >= lo && t <= hi)) return 0.0;
    if (!std::isfinite(sigma) || !(sigma > 0) || hi - lo < 0.2 * sigma) return 1.0 / (hi - lo);
    const double a = (lo - mean) / sigma, b = (hi - mean) / sigma;
    const bool upper = a > 0;
    const double qa = 0.5 * std::erfc((upper ? a : -a) / std::sqrt(2.0)), qb = 0.5 * std::erfc((upper ? b : -b) / std::sqrt(2.0));
    const double mass = upper ? qa - qb : qb - qa;
    if (!(mass > 1e-280) || !std::isfinite(mass)) return 1.0 / (hi - lo);
    const double z = (t - mean) / sigma;
    return std::exp(-0.5 * z * z) / (std::sqrt(2 * kPi) * sigma * mass);
}

}  // namespace fluorosim
