#pragma once
// A piecewise-linear spectrum on strictly increasing wavelengths (nm), zero outside its range.
#include <string>
#include <cstdint>
#include <vector>

namespace fluorosim {

class TabulatedSpectrum {
public:
    TabulatedSpectrum() = default;
    // Throws ConfigError (naming `source`) for fewer than 2 samples, non-increasing or non-finite
    // wavelengths, and negative or non-finite values.
    TabulatedSpectrum(std::vector<double> lambdaNm, std::vector<double> values, const std::string& source = "spectrum");

    double operator()(double lambdaNm) const;
    double minLambda() const { return lambda_.front(); }
    double maxLambda() const { return lambda_.back(); }
    double maxValue() const;
    bool empty() const { return lambda_.empty(); }
    const std::vector<double>& wavelengths() const { return lambda_; }
    const std::vector<double>& values() const { return values_; }

    // Exact integral of the piecewise-linear function over [a, b].
    double integral(double a, double b) const;
    double integral() const { return empty() ? 0.0 : integral(minLambda(), maxLambda()); }
    // Exact integral of the product of two piecewise-linear spectra (a piecewise quadratic).
    double integrateProduct(const TabulatedSpectrum& other) const;

    TabulatedSpectrum scaled(double s) const;

private:
    std::vector<double> lambda_, values_;
    std::vector<uint32_t> cellStart_;  // look-up acceleration: see the constructor
    double cellsPerNm_ = 0;
};

}  // namespace fluorosim
