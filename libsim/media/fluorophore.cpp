#include "media/fluorophore.h"

#include <algorithm>
#include <cmath>

#include "core/errors.h"

namespace fluorosim {
namespace {

// The spectrum is piecewise linear, so it is nonzero strictly between the zero samples that bracket
// its nonzero ones.
std::pair<double, double> support(const TabulatedSpectrum& s) {
    const auto& l = s.wavelengths();
    const auto& v = s.values();
    size_t first = 0, last = v.size() - 1;
    while (first < v.size() && v[first] == 0) ++first;
    while (last > first && v[last] == 0) --last;
    return {l[first > 0 ? first - 1 : 0], l[std::min(v.size() - 1, last + 1)]};
}

}  // namespace

Fluorophore::Fluorophore(std::string id, const TabulatedSpectrum& excitationRelative, double extinctionPeak,
                         const TabulatedSpectrum& emissionRelative, double quantumYield)
    : id_(std::move(id)), extinctionPeak_(extinctionPeak), quantumYield_(quantumYield) {
    if (!(extinctionPeak > 0) || !std::isfinite(extinctionPeak))
        throw ConfigError("dye \"" + id_ + "\": peak molar extinction must be positive and finite, got " + std::to_string(extinctionPeak));
    if (!(quantumYield >= 0 && quantumYield <= 1))
        throw ConfigError("dye \"" + id_ + "\": quantum yield must lie in [0, 1], got " + std::to_string(quantumYield));
    const double peak = excitationRelative.maxValue();
    if (!(peak > 0)) throw ConfigError("dye \"" + id_ + "\": the excitation spectrum is zero everywhere");
    excitation_ = excitationRelative.scaled(1.0 / peak);
    const double area = emissionRelative.integral();
    if (!(area > 0)) throw ConfigError("dye \"" + id_ + "\": the emission spectrum is zero everywhere");
    emission_ = emissionRelative.scaled(1.0 / area);
    emissionMax_ = emission_.maxValue();
    excitationSupport_ = support(excitation_);
    emissionSupport_ = support(emission_);
}

}  // namespace fluorosim
