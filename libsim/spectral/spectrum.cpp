#include "spectral/spectrum.h"

#include <algorithm>

namespace fluorosim {

Spectrum Spectrum::constant(double c) {
    Spectrum s;
    s.constant_ = c;
    return s;
}

Spectrum Spectrum::tabulated(TabulatedSpectrum t, double scale) {
    Spectrum s;
    s.table_ = std::move(t);
    s.tableScale_ = scale;
    return s;
}

Spectrum Spectrum::lines(std::vector<SpectralLine> lines) {
    Spectrum s;
    s.lines_ = std::move(lines);
    return s;
}

double Spectrum::operator()(double l) const {
    return table_ ? tableScale_ * (*table_)(l) : constant_;
}

SampledSpectrum Spectrum::sample(const SampledWavelengths& wl) const {
    SampledSpectrum r;
    for (int i = 0; i < kNumWavelengths; ++i) r[i] = (*this)(wl.lambda[i]);
    return r;
}

SampledSpectrum Spectrum::sampleEmission(const SampledWavelengths& wl) const {
    if (!wl.discrete) return sample(wl);
    SampledSpectrum r;
    for (int i = 0; i < kNumWavelengths; ++i)
        for (const SpectralLine& line : lines_)
            if (line.lambdaNm == wl.lambda[i]) r[i] += line.power;
    return r;
}

double Spectrum::maxValue() const {
    return table_ ? tableScale_ * table_->maxValue() : constant_;
}

double Spectrum::integral(double a, double b) const {
    double sum = table_ ? tableScale_ * table_->integral(a, b) : constant_ * (b - a);
    for (const SpectralLine& line : lines_)
        if (line.lambdaNm >= a && line.lambdaNm <= b) sum += line.power;
    return sum;
}

Spectrum Spectrum::scaled(double s) const {
    Spectrum r = *this;
    r.constant_ *= s;
    r.tableScale_ *= s;
    for (SpectralLine& line : r.lines_) line.power *= s;
    return r;
}

}  // namespace fluorosim
