#pragma once
// What the fluorescence estimator needs from a scene, computed once: which wavelengths camera paths
// and excitation sub-paths must carry, how often a camera path branches into an excitation sub-path,
// and the inelastic kernel. The derivation is in docs/model.md ("Fluorescence estimator").
#include <array>
#include <vector>

#include "scene/scene.h"
#include "spectral/wavelength_cache.h"
#include "spectral/wavelength_sampler.h"

namespace fluorosim {

// Camera wavelengths: the lights' lines (elastic light seen directly) plus a continuous part. The
// continuous part spans the spectral range when some light is continuous; when every light is a
// line it spans only where the scene's dyes emit (nothing else can arrive at other wavelengths).
WavelengthSampler cameraWavelengthSampler(const Scene& scene, const std::vector<Light>& lights, bool fluorescenceActive);
inline WavelengthSampler cameraWavelengthSampler(const Scene& scene, bool fluorescenceActive) {
    return cameraWavelengthSampler(scene, scene.lights, fluorescenceActive);
}

class FluorescencePlan {
public:
    explicit FluorescencePlan(const Scene& scene) : FluorescencePlan(scene, scene.lights) {}
    // With the lights a render uses instead of the scene's (a microscope channel's).
    FluorescencePlan(const Scene& scene, const std::vector<Light>& lights);

    // False when the model is None or no medium holds a dye that can emit (zero concentration, Φ = 0,
    // or no light and no other dye's emission inside the dye's absorption band).
    bool active() const { return active_; }
    bool active(int medium) const { return active_ && medium >= 0 && !media_[static_cast<size_t>(medium)].dyes.empty(); }
    FluorescenceModel model() const { return model_; }

    // Density (1/mm) of fluorescence branch points along a camera path, per mol/L of each channel, at
    // the sampled wavelengths (zero for channels without a dye that emits). At a point with channel
    // values c the density is Σ_c c · this[c]: about 8 Σ_i σa,i(peak; c_i) f_i(λ)/max f_i over dyes
    // with Φ > 0, raised for thin structures (see fluorescence.cpp). Linear in the concentrations, so
    // the medium's majorant grid bounds it. The tracer samples branch points as a Poisson process of
    // their own, so the source term is sampled even where the dye does not absorb at the camera's
    // wavelength. Any positive choice is unbiased; this one follows the emission shape and the dye's
    // strength.
    std::array<SampledSpectrum, kMaxMediumChannels> branchDensityPerMolar(int medium, const SampledWavelengths& wl) const;
    // The tracer uses min(branch density, max(σt, cap)): where the medium is dense its own collisions
    // suffice. 1/mm in homogeneous media; 4 per voxel length in grid media.
    double branchDensityCap(int medium) const;

    // Inelastic kernel in radiance units (1/(mm nm)) at a point with channel values `channels`:
    // Σ_i Φ_i f_i(λ) σa,i(λx; c_i) λx/λ. The factor λx/λ
    // turns photons counted by Φ into energy.
    double kernel(int medium, const double* channels, double lambdaExcitation, double lambda) const;
    // The kernel at every pair of n camera and n excitation wavelengths, out[j][k] for λ_j and λx_k, each
    // the same number kernel() gives; each dye's spectra are looked up once per wavelength, not per pair.
    void kernels(int medium, const double* channels, const double* lambdaExcitation, const double* lambda,
                 double out[kNumWavelengths][kNumWavelengths]) const;
    // The same per mol/L of each channel (linear in the concentrations): kernel = Σ_c channels[c] this[c].
    std::array<double, kMaxMediumChannels> kernelPerMolar(int medium, double lambdaExcitation, double lambda) const;

    // Excitation wavelengths of a sub-path: the lights' lines that some dye absorbs, plus a continuous
    // part over the dyes' absorption bands when a light is continuous or when one dye's emission can
    // be re-absorbed (secondary fluorescence).
    SampledWavelengths sampleExcitation(double uBranch, double u) const { return excitation_.sample(uBranch, u); }
    const WavelengthSampler& excitationSampler() const { return excitation_; }

private:
    struct DyeTerm {
        const Fluorophore* dye;
        int channel;                // the medium channel holding its concentration
        double branchWeight;        // kBranchBoost σa(peak; 1 M) / max f
    };
    struct MediumTerms {
        std::vector<DyeTerm> dyes;  // only dyes that can emit
        double branchCap = 1.0;     // 1/mm
    };
    std::array<SampledSpectrum, kMaxMediumChannels> evaluateBranchDensityPerMolar(int medium, const SampledWavelengths& wl) const;

    uint64_t cacheId_ = newWavelengthCacheId();  // copies share it, as they share the terms
    FluorescenceModel model_;
    bool active_ = false;
    std::vector<MediumTerms> media_;
    WavelengthSampler excitation_;
};

}  // namespace fluorosim
