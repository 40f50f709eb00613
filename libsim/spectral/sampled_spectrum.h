#pragma once
// Spectral quantities at the path's sampled wavelengths (hero wavelength + 3 rotated companions).
#include <algorithm>
#include <array>
#include <cmath>

namespace fluorosim {

inline constexpr int kNumWavelengths = 4;

class SampledSpectrum {
public:
    SampledSpectrum() { v_.fill(0.0); }
    explicit SampledSpectrum(double c) { v_.fill(c); }
    double operator[](int i) const { return v_[i]; }
    double& operator[](int i) { return v_[i]; }

    SampledSpectrum& operator+=(const SampledSpectrum& o) {
        for (int i = 0; i < kNumWavelengths; ++i) v_[i] += o.v_[i];
        return *this;
    }
    SampledSpectrum& operator+=(double s) {
        for (double& x : v_) x += s;
        return *this;
    }
    SampledSpectrum operator+(const SampledSpectrum& o) const { return SampledSpectrum(*this) += o; }
    SampledSpectrum operator+(double s) const { return SampledSpectrum(*this) += s; }
    SampledSpectrum& operator-=(const SampledSpectrum& o) {
        for (int i = 0; i < kNumWavelengths; ++i) v_[i] -= o.v_[i];
        return *this;
    }
    SampledSpectrum& operator-=(double s) {
        for (double& x : v_) x -= s;
        return *this;
    }
    SampledSpectrum operator-(const SampledSpectrum& o) const { return SampledSpectrum(*this) -= o; }
    SampledSpectrum operator-(double s) const { return SampledSpectrum(*this) -= s; }
    SampledSpectrum& operator*=(const SampledSpectrum& o) {
        for (int i = 0; i < kNumWavelengths; ++i) v_[i] *= o.v_[i];
        return *this;
    }
    SampledSpectrum& operator*=(double s) {
        for (double& x : v_) x *= s;
        return *this;
    }
    SampledSpectrum operator*(const SampledSpectrum& o) const { return SampledSpectrum(*this) *= o; }
    SampledSpectrum operator*(double s) const { return SampledSpectrum(*this) *= s; }

    // Division defined as 0 where the divisor is 0: used for ratios of pdfs along paths.
    SampledSpectrum operator/(const SampledSpectrum& o) const {
        SampledSpectrum r;
        for (int i = 0; i < kNumWavelengths; ++i) r.v_[i] = o.v_[i] != 0 ? v_[i] / o.v_[i] : 0.0;
        return r;
    }
    SampledSpectrum& operator/=(const SampledSpectrum& o) { return *this = *this / o; }
    SampledSpectrum operator/(double s) const { return *this * (1.0 / s); }
    SampledSpectrum& operator/=(double s) { return *this *= (1.0 / s); }

    bool isZero() const {
        return std::all_of(v_.begin(), v_.end(), [](double x) { return x == 0.0; });
    }
    explicit operator bool() const { return !isZero(); }
    double maxComponent() const { return *std::max_element(v_.begin(), v_.end()); }
    double minComponent() const { return *std::min_element(v_.begin(), v_.end()); }
    double average() const {
        double s = 0;
        for (double x : v_) s += x;
        return s / kNumWavelengths;
    }
    bool isFinite() const {
        return std::all_of(v_.begin(), v_.end(), [](double x) { return std::isfinite(x); });
    }

private:
    std::array<double, kNumWavelengths> v_;
};

inline SampledSpectrum operator*(double s, const SampledSpectrum& v) { return v * s; }
inline SampledSpectrum exp(const SampledSpectrum& v) {
    SampledSpectrum r;
    for (int i = 0; i < kNumWavelengths; ++i) r[i] = std::exp(v[i]);
    return r;
}

}  // namespace fluorosim
