#include "media/medium.h"

#include <algorithm>
#include <cmath>

#include "core/errors.h"
#include "spectral/wavelength_cache.h"

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

Medium::Medium(std::string name, Spectrum sigmaA, Spectrum sigmaS, double g, double ior, std::vector<DyeComponent> dyes,
               std::shared_ptr<const VolumeFields> volume)
    : spectraId_(newWavelengthCacheId()), name_(std::move(name)), sigmaA_(std::move(sigmaA)), sigmaS_(std::move(sigmaS)), dyes_(std::move(dyes)),
      volume_(std::move(volume)), phase_(0.0), ior_(ior) {
    if (channelCount() > kMaxMediumChannels)
        throw ConfigError("medium \"" + name_ + "\": at most " + std::to_string(kMaxMediumChannels - kFirstDyeChannel) +
                          " dyes per medium, got " + std::to_string(dyes_.size()));
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
    constants_[kSolventChannel] = constants_[kScatteringChannel] = 1.0;
    for (size_t i = 0; i < dyes_.size(); ++i) constants_[kFirstDyeChannel + i] = dyes_[i].molar;
    channelMax_ = channelFloor_ = constants_;
    if (volume_) {
        if (volume_->channelCount() != channelCount())
            throw ConfigError("medium \"" + name_ + "\": its volume has " + std::to_string(volume_->channelCount()) +
                              " channels, expected " + std::to_string(channelCount()));
        const std::vector<double> mx = volume_->channelMaxima();
        std::copy(mx.begin(), mx.end(), channelMax_.begin());
        const std::vector<double> floors = volume_->channelFloors();
        std::copy(floors.begin(), floors.end(), channelFloor_.begin());
    }
    bool anything = sigmaA_.maxValue() * channelMax_[kSolventChannel] > 0 || sigmaS_.maxValue() * channelMax_[kScatteringChannel] > 0;
    for (int c = kFirstDyeChannel; c < channelCount(); ++c) anything = anything || channelMax_[c] > 0;
    vacuum_ = !anything;
}

Medium Medium::withVolume(std::shared_ptr<const VolumeFields> volume) const {
    return Medium(name_, sigmaA_, sigmaS_, phase_.g(), ior_, dyes_, std::move(volume));
}

MediumSpectra Medium::spectra(const SampledWavelengths& wl) const {
    thread_local WavelengthCache<MediumSpectra> recent;
    return recent.get(spectraId_, 0, wl, [&] { return evaluateSpectra(wl); });
}

MediumSpectra Medium::evaluateSpectra(const SampledWavelengths& wl) const {
    MediumSpectra s;
    s.channels = channelCount();
    s.sigmaA[kSolventChannel] = sigmaA_.sample(wl);
    s.sigmaA[kScatteringChannel] = SampledSpectrum(0.0);
    s.sigmaS = sigmaS_.sample(wl);
    for (size_t i = 0; i < dyes_.size(); ++i)
        for (int k = 0; k < kNumWavelengths; ++k)
            s.sigmaA[kFirstDyeChannel + i][k] = dyeAbsorption(dyes_[i].dye, wl.lambda[k], 1.0);
    return s;
}

}  // namespace fluorosim
