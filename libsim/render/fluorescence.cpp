#include "render/fluorescence.h"

#include <algorithm>
#include <cmath>
#include <limits>

namespace fluorosim {
namespace {

// Branch points per unit of the dye's own emission strength. Any value is unbiased; larger values
// trade more (rouletted) sub-paths for less variance. On the forward-comparison balls, 16 instead of
// 1 cut the standard error about 3x at about the same run time; 8 keeps dense media cheaper.
constexpr double kBranchBoost = 8.0;
constexpr double kGridBranchesPerVoxel = 4.0;
// Objects larger than this keep the branch cap of max(σt, 1/mm) (kGridBranchesPerVoxel per 4 mm).
constexpr double kLargestFeatureMm = 4.0;

struct LightSpectra {
    std::vector<double> lines;
    bool continuous = false;
};

LightSpectra lightSpectra(const std::vector<Light>& lights) {
    LightSpectra out;
    for (const Light& light : lights) {
        const Spectrum& s = emissionSpectrum(light);
        for (const SpectralLine& line : s.spectralLines()) out.lines.push_back(line.lambdaNm);
        out.continuous = out.continuous || s.hasContinuousPart();
    }
    return out;
}

// The dye's largest concentration anywhere in its medium, mol/L.
double maxMolar(const Medium& m, size_t dye) { return m.channelMax()[kFirstDyeChannel + dye]; }
bool canEmit(const Medium& m, size_t dye) { return maxMolar(m, dye) > 0 && m.dyes()[dye].dye.quantumYield() > 0; }

// The length over which a medium's dye varies: the voxel of a grid medium; for a homogeneous medium
// the smallest diameter of the spheres, or the thinnest bounding-box side of the meshes, that enclose
// it (at most 4 mm, which keeps the old cap of 1/mm for large objects).
double featureSizeMm(const Scene& scene, int medium) {
    const Medium& m = scene.media[static_cast<size_t>(medium)];
    if (const VolumeFields* v = m.volume()) return v->voxelSizeMm();
    double size = kLargestFeatureMm;
    for (uint32_t s = 0; s < scene.shapes.size(); ++s) {
        if (!scene.shapes[s].isInterface || scene.shapes[s].insideMedium != medium) continue;
        if (scene.geometry.isSphere(s)) {
            size = std::min(size, 2 * scene.geometry.sphereRadius(s));
            continue;
        }
        const auto& positions = scene.geometry.mesh(s).positions;
        if (positions.empty()) continue;
        Vec3 lo = positions[0], hi = positions[0];
        for (const Vec3& p : positions)
            for (int a = 0; a < 3; ++a) {
                lo[a] = std::min(lo[a], p[a]);
                hi[a] = std::max(hi[a], p[a]);
            }
        for (int a = 0; a < 3; ++a)
            if (hi[a] - lo[a] > 0) size = std::min(size, hi[a] - lo[a]);
    }
    return size;
}

struct Interval {
    double lo = std::numeric_limits<double>::infinity(), hi = -std::numeric_limits<double>::infinity();
    void add(std::pair<double, double> s) {
        lo = std::min(lo, s.first);
        hi = std::max(hi, s.second);
    }
    Interval clipped(double a, double b) const { return {std::max(lo, a), std::min(hi, b)}; }
    bool empty() const { return !(hi > lo); }
    bool overlaps(std::pair<double, double> s) const { return std::min(hi, s.second) > std::max(lo, s.first); }
};

// Hulls of the absorption and emission bands of every dye that can emit.
struct DyeBands {
    Interval absorption, emission;
    std::vector<std::pair<double, double>> absorptionBands, emissionBands;
    std::vector<const Fluorophore*> dyes;
};

DyeBands dyeBands(const Scene& scene) {
    DyeBands b;
    for (const Medium& m : scene.media)
        for (size_t i = 0; i < m.dyes().size(); ++i) {
            if (!canEmit(m, i)) continue;
            const DyeComponent& d = m.dyes()[i];
            b.absorption.add(d.dye.excitationSupport());
            b.emission.add(d.dye.emissionSupport());
            b.absorptionBands.push_back(d.dye.excitationSupport());
            b.emissionBands.push_back(d.dye.emissionSupport());
            b.dyes.push_back(&d.dye);
        }
    return b;
}

WavelengthSampler makeExcitationSampler(const Scene& scene, const std::vector<Light>& sceneLights, bool& possible) {
    const LightSpectra lights = lightSpectra(sceneLights);
    const DyeBands bands = dyeBands(scene);
    std::vector<double> lines;
    for (double l : lights.lines)
        if (std::any_of(bands.dyes.begin(), bands.dyes.end(), [&](const Fluorophore* f) { return f->molarExtinction(l) > 0; }))
            lines.push_back(l);
    bool reabsorption = false;
    for (const auto& em : bands.emissionBands)
        for (const auto& ab : bands.absorptionBands) reabsorption = reabsorption || Interval{ab.first, ab.second}.overlaps(em);
    const Interval range = bands.absorption.clipped(scene.spectral.lambdaMin, scene.spectral.lambdaMax);
    const bool continuous = (lights.continuous || reabsorption) && !range.empty();
    possible = continuous || !lines.empty();
    if (!possible) return WavelengthSampler(scene.spectral.lambdaMin, scene.spectral.lambdaMax, {}, false);
    if (!continuous) return WavelengthSampler(scene.spectral.lambdaMin, scene.spectral.lambdaMax, lines, false);
    return WavelengthSampler(range.lo, range.hi, lines, true);
}

}  // namespace

WavelengthSampler cameraWavelengthSampler(const Scene& scene, const std::vector<Light>& sceneLights, bool fluorescenceActive) {
    const LightSpectra lights = lightSpectra(sceneLights);
    const double lo = scene.spectral.lambdaMin, hi = scene.spectral.lambdaMax;
    if (lights.continuous || !fluorescenceActive) return WavelengthSampler(lo, hi, lights.lines, lights.continuous);
    const Interval emission = dyeBands(scene).emission.clipped(lo, hi);
    if (emission.empty()) return WavelengthSampler(lo, hi, lights.lines, false);
    WavelengthSampler sampler(emission.lo, emission.hi, lights.lines, true);
    // Camera wavelengths follow the dyes' emission (each dye weighted by its branch strength), mixed
    // with 20 % uniform so that every wavelength where something could arrive keeps a density.
    const int cells = std::max(1, static_cast<int>(std::ceil(emission.hi - emission.lo)));
    std::vector<double> density(static_cast<size_t>(cells), 0.0);
    const double width = (emission.hi - emission.lo) / cells;
    double total = 0;
    for (const Medium& m : scene.media)
        for (size_t i = 0; i < m.dyes().size(); ++i) {
            if (!canEmit(m, i)) continue;
            const DyeComponent& d = m.dyes()[i];
            const double w = d.dye.quantumYield() * dyePeakAbsorption(d.dye, maxMolar(m, i));
            for (int c = 0; c < cells; ++c) {
                const double a = emission.lo + c * width;
                const double v = w * d.dye.emission().integral(a, a + width);
                density[static_cast<size_t>(c)] += v;
                total += v;
            }
        }
    if (total > 0) {
        for (double& v : density) v = 0.8 * v / total + 0.2 / cells;
        sampler.setContinuousDensity(std::move(density));
    }
    return sampler;
}

FluorescencePlan::FluorescencePlan(const Scene& scene, const std::vector<Light>& lights)
    : model_(scene.render.fluorescence), excitation_(makeExcitationSampler(scene, lights, active_)) {
    if (model_ == FluorescenceModel::None) active_ = false;
    media_.resize(scene.media.size());
    std::vector<double> featureSize(scene.media.size());  // scans the enclosing meshes once per medium
    for (size_t m = 0; m < scene.media.size(); ++m) featureSize[m] = featureSizeMm(scene, static_cast<int>(m));
    bool anyDye = false;
    for (size_t m = 0; m < scene.media.size(); ++m)
        for (size_t i = 0; i < scene.media[m].dyes().size(); ++i) {
            if (!canEmit(scene.media[m], i)) continue;
            const DyeComponent& d = scene.media[m].dyes()[i];
            // Not weighted by Φ: the branch's weight carries Φ, so a dim dye would otherwise get fewer
            // branches for the same relative noise (measured: AF555, Φ = 0.1, had 5x the spectral noise).
            // In a grid medium a labelled structure may be a voxel thick and weakly absorbing (a 1 µm
            // dendrite at 10 µM has optical depth ~1e-4), so the density at the dye's largest
            // concentration is at least kGridBranchesPerVoxel per voxel length: each crossing then
            // branches, and the roulette in the tracer keeps the cost to what the branches carry.
            // Likewise a dyed homogeneous object much smaller than a millimetre (a 0.2 µm bead) gets at
            // least kGridBranchesPerVoxel branch points per diameter.
            double weight = kBranchBoost * dyePeakAbsorption(d.dye, 1.0);
            weight = std::max(weight, kGridBranchesPerVoxel / (featureSize[m] * maxMolar(scene.media[m], i)));
            weight /= d.dye.emissionPdfMax();
            media_[m].dyes.push_back({&d.dye, kFirstDyeChannel + static_cast<int>(i), weight});
            anyDye = true;
        }
    for (size_t m = 0; m < scene.media.size(); ++m)
        media_[m].branchCap = std::max(1.0, kGridBranchesPerVoxel / featureSize[m]);
    active_ = active_ && anyDye;
}

double FluorescencePlan::branchDensityCap(int medium) const { return media_[static_cast<size_t>(medium)].branchCap; }

std::array<SampledSpectrum, kMaxMediumChannels> FluorescencePlan::branchDensityPerMolar(int medium, const SampledWavelengths& wl) const {
    thread_local WavelengthCache<std::array<SampledSpectrum, kMaxMediumChannels>> recent;
    return recent.get(cacheId_, medium, wl, [&] { return evaluateBranchDensityPerMolar(medium, wl); });
}

std::array<SampledSpectrum, kMaxMediumChannels> FluorescencePlan::evaluateBranchDensityPerMolar(int medium, const SampledWavelengths& wl) const {
    std::array<SampledSpectrum, kMaxMediumChannels> perChannel{};
    for (const DyeTerm& t : media_[static_cast<size_t>(medium)].dyes)
        for (int j = 0; j < kNumWavelengths; ++j) perChannel[static_cast<size_t>(t.channel)][j] += t.branchWeight * t.dye->emissionPdf(wl.lambda[j]);
    return perChannel;
}

double FluorescencePlan::kernel(int medium, const double* channels, double lambdaExcitation, double lambda) const {
    double sum = 0;
    for (const DyeTerm& t : media_[static_cast<size_t>(medium)].dyes)
        sum += t.dye->quantumYield() * t.dye->emissionPdf(lambda) * dyeAbsorption(*t.dye, lambdaExcitation, channels[t.channel]);
    return sum * lambdaExcitation / lambda;
}

void FluorescencePlan::kernels(int medium, const double* channels, const double* lambdaExcitation, const double* lambda,
                               double out[kNumWavelengths][kNumWavelengths]) const {
    double sum[kNumWavelengths][kNumWavelengths] = {};
    for (const DyeTerm& t : media_[static_cast<size_t>(medium)].dyes) {
        double emitted[kNumWavelengths], absorbed[kNumWavelengths];
        for (int j = 0; j < kNumWavelengths; ++j) emitted[j] = t.dye->quantumYield() * t.dye->emissionPdf(lambda[j]);
        for (int k = 0; k < kNumWavelengths; ++k) absorbed[k] = dyeAbsorption(*t.dye, lambdaExcitation[k], channels[t.channel]);
        for (int j = 0; j < kNumWavelengths; ++j)
            for (int k = 0; k < kNumWavelengths; ++k) sum[j][k] += emitted[j] * absorbed[k];
    }
    for (int j = 0; j < kNumWavelengths; ++j)
        for (int k = 0; k < kNumWavelengths; ++k) out[j][k] = sum[j][k] * lambdaExcitation[k] / lambda[j];
}

std::array<double, kMaxMediumChannels> FluorescencePlan::kernelPerMolar(int medium, double lambdaExcitation, double lambda) const {
    std::array<double, kMaxMediumChannels> perChannel{};
    for (const DyeTerm& t : media_[static_cast<size_t>(medium)].dyes)
        perChannel[static_cast<size_t>(t.channel)] +=
            t.dye->quantumYield() * t.dye->emissionPdf(lambda) * dyeAbsorption(*t.dye, lambdaExcitation, 1.0) * lambdaExcitation / lambda;
    return perChannel;
}

}  // namespace fluorosim
