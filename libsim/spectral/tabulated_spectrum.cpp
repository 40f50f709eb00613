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
    // A uniform grid of as many cells as samples, each holding the sample interval its start lies in:
    // a look-up starts there instead of a binary search (the path tracer evaluates spectra per vertex).
    const size_t cells = lambda_.size();
    cellsPerNm_ = static_cast<double>(cells) / (lambda_.back() - lambda_.front());
    cellStart_.resize(cells);
    size_t i = 0;
    for (size_t k = 0; k < cells; ++k) {
        const double start = lambda_.front() + static_cast<double>(k) / cellsPerNm_;
        while (i + 2 < lambda_.size() && lambda_[i + 1] <= start) ++i;
        cellStart_[k] = static_cast<uint32_t>(i);
    }
}

double TabulatedSpectrum::operator()(double l) const {
    if (lambda_.empty() || l < lambda_.front() || l > lambda_.back()) return 0.0;
    if (l == lambda_.back()) return values_.back();
    // The interval with lambda_[i] <= l < lambda_[i + 1], as a binary search would find it; the walks
    // absorb the cell index's rounding.
    const size_t k = std::min(cellStart_.size() - 1, static_cast<size_t>((l - lambda_.front()) * cellsPerNm_));
    size_t i = cellStart_[k];
    while (i > 0 && lambda_[i] > l) --i;
    while (lambda_[i + 1] <= l) ++i;
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
