#include "media/fluorophore.h"

#include <cmath>

#include "core/errors.h"

namespace fluorosim {

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
}

}  // namespace fluorosim
