#include "spectral/tabulated_spectrum.h"

#include <algorithm>
#include <cmath>

#include "core/errors.h"

namespace fluorosim {

TabulatedSpectrum::TabulatedSpectrum(std::vector<double> lambdaNm, std::vector<double> values,
                                     const std::string& source)
    : lambda_(std::move(lambdaNm)), values_(std::move(values)) {
    if (lambda_.size() != values_.size())
        throw ConfigError(source + ": wavelength and value columns differ in length");
    if (lambda_.size() < 2) throw ConfigError(source + ": a tabulated spectrum needs at least 2 samples");
    for (size_t i = 0; i < lambda_.size(); ++i) {
        if (!std::isfinite(lambda_[i]) || lambda_[i] <= 0)
            throw ConfigError(source + ": invalid wavelength " + std::to_string(lambda_[i]) + " nm at row " +
                              std::to_string(i + 1));
        if (i > 0 && !(lambda_[i] > lambda_[i - 1]))
            throw ConfigError(source + ": wavelengths must increase strictly, but row " + std::to_string(i + 1) +
                              " has " + std::to_string(lambda_[i]) + " nm after " + std::to_string(lambda_[i - 1]) +
                              " nm");
        if (!std::isfinite(values_[i]) || values_[i] < 0)
            throw ConfigError(source + ": negative or non-finite value " + std::to_string(values_[i]) + " at " +
                              std::to_string(lambda_[i]) + " nm (row " + std::to_string(i + 1) + ")");
    }
}

double TabulatedSpectrum::operator()(double l) const {
    if (lambda_.empty() || l < lambda_.front() || l > lambda_.back()) return 0.0;
    const auto it = std::upper_bound(lambda_.begin(), lambda_.end(), l);
    if (it == lambda_.end()) return values_.back();
    const size_t i = static_cast<size_t>(it - lambda_.begin()) - 1;
    const double t = (l - lambda_[i]) / (lambda_[i + 1] - lambda_[i]);
    return (1 - t) * values_[i] + t * values_[i + 1];
}

double TabulatedSpectrum::maxValue() const {
    return values_.empty() ? 0.0 : *std::max_element(values_.begin(), values_.end());
}

double TabulatedSpectrum::integral(double a, double b) const {
    if (empty() || b <= a) return 0.0;
    a = std::max(a, minLambda());
    b = std::min(b, maxLambda());
    double sum = 0;
    double prevL = a, prevV = (*this)(a);
    for (size_t i = 0; i < lambda_.size(); ++i) {
        if (lambda_[i] <= a) continue;
        if (lambda_[i] >= b) break;
        sum += 0.5 * (prevV + values_[i]) * (lambda_[i] - prevL);
        prevL = lambda_[i];
        prevV = values_[i];
    }
    if (b > prevL) sum += 0.5 * (prevV + (*this)(b)) * (b - prevL);
    return sum;
}

double TabulatedSpectrum::integrateProduct(const TabulatedSpectrum& other) const {
    if (empty() || other.empty()) return 0.0;
    const double a = std::max(minLambda(), other.minLambda());
    const double b = std::min(maxLambda(), other.maxLambda());
    if (b <= a) return 0.0;
    std::vector<double> knots;
    for (double l : lambda_)
        if (l > a && l < b) knots.push_back(l);
    for (double l : other.lambda_)
        if (l > a && l < b) knots.push_back(l);
    knots.push_back(a);
    knots.push_back(b);
    std::sort(knots.begin(), knots.end());
    knots.erase(std::unique(knots.begin(), knots.end()), knots.end());
    // Both factors are linear on each interval, so Simpson's rule is exact for the quadratic product.
    double sum = 0;
    for (size_t i = 0; i + 1 < knots.size(); ++i) {
        const double l0 = knots[i], l1 = knots[i + 1], lm = 0.5 * (l0 + l1);
        // Evaluate just inside the interval so a knot's own segment is used on both sides.
        const double f0 = (*this)(l0) * other(l0), f1 = (*this)(l1) * other(l1), fm = (*this)(lm) * other(lm);
        sum += (l1 - l0) / 6.0 * (f0 + 4 * fm + f1);
    }
    return sum;
}

TabulatedSpectrum TabulatedSpectrum::scaled(double s) const {
    TabulatedSpectrum r = *this;
    for (double& v : r.values_) v *= s;
    return r;
}

}  // namespace fluorosim
