#pragma once
// Participating media. A medium has spectral solvent absorption and scattering coefficients (1/mm),
// dyes, a Henyey-Greenstein phase function and a refractive index. It is homogeneous, or its fields
// vary in space through a VolumeFields (OpenVDB grids): then every coefficient is linear in a few
// channels,
//     sigma_a(p, λ) = a(p) sigma_a,solvent(λ) + Σ_i c_i(p) ln(10) ε_i(λ),   sigma_s(p, λ) = s(p) sigma_s(λ),
// with channel 0 = a (solvent absorption scale), 1 = s (scattering scale), 2 + i = c_i (mol/L).
// The per-channel spectra are evaluated once per set of wavelengths; the channel values per point.
#include <array>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "media/fluorophore.h"
#include "media/free_flight.h"
#include "media/henyey_greenstein.h"
#include "spectral/spectrum.h"
#include "volume/volume_fields.h"

namespace fluorosim {

struct MediumSample {
    SampledSpectrum sigmaA, sigmaS;
};

struct DyeComponent {
    Fluorophore dye;
    double molar;  // concentration, mol/L (unused when a grid holds the concentration)
};

// Absorption coefficient (1/mm) of a solvent holding dyes at the given concentrations (mol/L):
// sigma_a(lambda) = sigma_a,solvent(lambda) + sum_i ln(10) epsilon_i(lambda) c_i. A pure function,
// templated on the scalar so that fitting code can evaluate it on ceres::Jet concentrations; the
// tracer calls it with double.
template <class Scalar>
Scalar absorptionCoefficient(const Spectrum& solventAbsorption, const std::vector<DyeComponent>& dyes,
                             std::span<const Scalar> molar, double lambdaNm) {
    Scalar sum = Scalar(solventAbsorption(lambdaNm));
    for (size_t i = 0; i < dyes.size(); ++i) sum = sum + dyeAbsorption(dyes[i].dye, lambdaNm, molar[i]);
    return sum;
}

inline constexpr int kMaxMediumChannels = 16;  // 2 + at most 14 dyes per medium
inline constexpr int kSolventChannel = 0, kScatteringChannel = 1, kFirstDyeChannel = 2;
using ChannelValues = std::array<double, kMaxMediumChannels>;

// Coefficients per unit channel value at a set of sampled wavelengths.
struct MediumSpectra {
    int channels = 2;
    std::array<SampledSpectrum, kMaxMediumChannels> sigmaA;  // sigmaA[kScatteringChannel] is zero
    SampledSpectrum sigmaS;
    MediumSample at(const double* ch) const {
        MediumSample m{sigmaA[0] * ch[0], sigmaS * ch[kScatteringChannel]};
        for (int c = kFirstDyeChannel; c < channels; ++c) m.sigmaA += sigmaA[c] * ch[c];
        return m;
    }
};

// Majorant segments of a medium along a ray: one segment for a homogeneous medium, the majorant
// grid's DDA cells otherwise. `toMajorant(const double* channelMax)` turns the channels' bounds over a
// segment into the majorant spectrum (it may add densities of its own, such as branch points).
template <class ToMajorant>
class MediumMajorantIterator {
public:
    MediumMajorantIterator(std::optional<VolumeFields::Traversal> traversal, double tMin, double tMax, const double* constants,
                           ToMajorant toMajorant)
        : traversal_(std::move(traversal)), tMin_(tMin), tMax_(tMax), constants_(constants), toMajorant_(std::move(toMajorant)) {}
    std::optional<MajorantSegment<SampledSpectrum>> next() {
        if (traversal_) {
            const auto s = traversal_->next();
            if (!s) return std::nullopt;
            return MajorantSegment<SampledSpectrum>{s->tMin, s->tMax, toMajorant_(s->maxValues)};
        }
        if (done_) return std::nullopt;
        done_ = true;
        return MajorantSegment<SampledSpectrum>{tMin_, tMax_, toMajorant_(constants_)};
    }

private:
    std::optional<VolumeFields::Traversal> traversal_;
    double tMin_, tMax_;
    const double* constants_;
    ToMajorant toMajorant_;
    bool done_ = false;
};

class Medium {
public:
    // sigmaA is the solvent's own absorption; dyes add theirs. `volume`, if given, has channels
    // [solvent absorption scale, scattering scale, one per dye] (see the top of this file). Throws
    // ConfigError (naming `name`) for negative or non-finite coefficients or concentrations, |g| >= 1,
    // ior < 1, too many dyes or a volume with the wrong channel count.
    Medium(std::string name, Spectrum sigmaA, Spectrum sigmaS, double g, double ior, std::vector<DyeComponent> dyes = {},
           std::shared_ptr<const VolumeFields> volume = nullptr);
    const std::vector<DyeComponent>& dyes() const { return dyes_; }
    // The same medium over other fields (same channels), e.g. dye grids rescaled by a fit.
    Medium withVolume(std::shared_ptr<const VolumeFields> volume) const;

    const std::string& name() const { return name_; }
    const Spectrum& solventAbsorption() const { return sigmaA_; }
    const Spectrum& scattering() const { return sigmaS_; }
    double ior() const { return ior_; }
    const HenyeyGreenstein& phase() const { return phase_; }
    bool isVacuumLike() const { return vacuum_; }  // no absorption or scattering anywhere
    bool isHomogeneous() const { return !volume_; }
    const VolumeFields* volume() const { return volume_.get(); }
    int channelCount() const { return kFirstDyeChannel + static_cast<int>(dyes_.size()); }
    // Largest value of each channel anywhere in the medium (the constants when homogeneous).
    const ChannelValues& channelMax() const { return channelMax_; }
    // A lower bound of each channel everywhere (the constants when homogeneous): the part of the
    // medium whose transmittance is known exactly, so that only the rest needs ratio tracking.
    const ChannelValues& channelFloor() const { return channelFloor_; }

    // Each thread keeps the last few evaluations: a path asks for the same medium at the same
    // wavelengths at every free flight and shadow ray.
    MediumSpectra spectra(const SampledWavelengths& wl) const;
    // `upper`, if given, bounds each channel at p (the maxima a majorant segment was built from).
    void channelValues(const Vec3& p, double* out, const double* upper = nullptr) const {
        if (volume_) volume_->values(p, out, upper);
        else std::copy(constants_.begin(), constants_.begin() + channelCount(), out);
    }
    MediumSample coefficients(const Vec3& p, const SampledWavelengths& wl) const {
        ChannelValues ch;
        channelValues(p, ch.data());
        return spectra(wl).at(ch.data());
    }
    // Total absorption (solvent and dyes) and scattering at one wavelength, 1/mm, of a homogeneous medium.
    double absorptionAt(double lambdaNm) const { return absorptionCoefficient<double>(sigmaA_, dyes_, molar_, lambdaNm); }
    double scatteringAt(double lambdaNm) const { return sigmaS_(lambdaNm); }

    // `fewCollisions`: one segment at the fields' largest values also where they expect at most this many
    // collisions over [tMin, tMax] at the hero wavelength (a thin residual over a short line: ratio tracking
    // then looks up so few points that the grid's DDA costs more, and a larger majorant adds no variance).
    template <class ToMajorant>
    MediumMajorantIterator<ToMajorant> majorants(const Ray& ray, double tMin, double tMax, ToMajorant toMajorant, double fewCollisions = 0) const {
        if (!volume_) return {std::nullopt, tMin, tMax, constants_.data(), std::move(toMajorant)};
        // Where the fields' largest values bound the coefficient within kLooseMajorant of its floor (dye in
        // tissue that scatters more than the dye absorbs), one segment at those values spares the grid's DDA
        // at the price of at most kLooseMajorant - 1 null collisions per real one. toMajorant is called here at
        // the maxima and the floors before the iterator's own calls, so a caller's side effects in it (the
        // segment's maxima it keeps) hold only from next() on.
        const SampledSpectrum most = toMajorant(channelMax_.data()), least = toMajorant(channelFloor_.data());
        bool loose = true;
        for (int i = 0; i < kNumWavelengths && loose; ++i) loose = most[i] <= kLooseMajorant * least[i];
        if (loose || most[0] * (tMax - tMin) <= fewCollisions) return {std::nullopt, tMin, tMax, channelMax_.data(), std::move(toMajorant)};
        return {volume_->traverse(ray, tMin, tMax), tMin, tMax, constants_.data(), std::move(toMajorant)};
    }
    static constexpr double kLooseMajorant = 1.5;

private:
    MediumSpectra evaluateSpectra(const SampledWavelengths& wl) const;

    // Names the spectra for the per-thread cache; copies share it, as they share the spectra.
    uint64_t spectraId_;
    std::string name_;
    Spectrum sigmaA_, sigmaS_;
    std::vector<DyeComponent> dyes_;
    std::vector<double> molar_;
    std::shared_ptr<const VolumeFields> volume_;
    ChannelValues constants_{}, channelMax_{}, channelFloor_{};
    HenyeyGreenstein phase_;
    double ior_;
    bool vacuum_;
};

}  // namespace fluorosim
