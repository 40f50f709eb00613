#include "media/medium.h"

#include <algorithm>
#include <cmath>

#include "core/errors.h"

namespace fluorosim {
namespace {

void checkCoefficient(const std::string& medium, const char* field, const Spectrum& s) {
    if (!s.spectralLines().empty())
        throw ConfigError("medium \"" + medium + "\": " + field + " cannot contain spectral lines");
    const double v = s.maxValue();
    if (!std::isfinite(v) || v < 0)
        throw ConfigError("medium \"" + medium + "\": " + field + " must be finite and non-negative, got " +
                          std::to_string(v));
}

}  // namespace

HomogeneousMedium::HomogeneousMedium(std::string name, Spectrum sigmaA, Spectrum sigmaS, double g, double ior,
                                     std::vector<DyeComponent> dyes)
    : name_(std::move(name)), sigmaA_(std::move(sigmaA)), sigmaS_(std::move(sigmaS)), dyes_(std::move(dyes)), phase_(0.0), ior_(ior) {
    for (const DyeComponent& d : dyes_) {
        if (!(d.molar >= 0) || !std::isfinite(d.molar))
            throw ConfigError("medium \"" + name_ + "\": concentration of \"" + d.dye.id() + "\" must be finite and non-negative, got " +
                              std::to_string(d.molar) + " M");
        molar_.push_back(d.molar);
    }
    checkCoefficient(name_, "sigma_a", sigmaA_);
    checkCoefficient(name_, "sigma_s", sigmaS_);
    if (!(g > -1 && g < 1))
        throw ConfigError("medium \"" + name_ + "\": g must lie in (-1, 1), got " + std::to_string(g));
    phase_ = HenyeyGreenstein(g);
    if (!(ior >= 1.0) || !std::isfinite(ior))
        throw ConfigError("medium \"" + name_ + "\": ior must be finite and >= 1, got " + std::to_string(ior));
    vacuum_ = sigmaA_.maxValue() == 0 && sigmaS_.maxValue() == 0 &&
              std::all_of(molar_.begin(), molar_.end(), [](double c) { return c == 0.0; });
}

}  // namespace fluorosim
