#include "optics/unscattered_image.h"

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <mutex>
#include <unordered_map>
#include <unordered_set>
#include <utility>

#include "core/errors.h"
#include "core/math.h"
#include "core/parallel.h"
#include "core/quadrature.h"
#include "optics/fft_convolution.h"
#include "render/beam_core.h"
#include "render/straight_line.h"

namespace fluorosim::optics {
namespace {

constexpr double kMm2PerM2 = 1e6;  // irradiance W/mm² -> W/m², as the light sampler converts it
constexpr double kUmPerMm = 1e3;
constexpr int kCameraWavelengths = kNumWavelengths;  // the cone-mean transmittance is kept at 4 wavelengths
constexpr size_t kMaxBeamLines = 32;

int64_t floorDiv(int64_t a, int64_t b) { return a >= 0 ? a / b : -((-a + b - 1) / b); }

// Three integer coordinates within ±2^20 as one key.
uint64_t packKey(int64_t i, int64_t j, int64_t k) {
    return (static_cast<uint64_t>(i + (1 << 20)) << 42) | (static_cast<uint64_t>(j + (1 << 20)) << 21) | static_cast<uint64_t>(k + (1 << 20));
}

// One line of one beam side: where the unscattered light comes from.
struct LineSide {
    const BeamProfile* profile;
    double lambdaNm, weight;
    int side;
    size_t line;
};

// An emitting dye of an emitting medium, as this channel excites and detects it.
struct DyeTerm {
    int medium = 0, channel = 0;
    double quantumYield = 0;
    std::vector<double> absorptionPerMolar;  // per line: σa(λ_l; 1 mol/L), 1/mm
    double detected = 0;                     // D = ∫ f(λ) detection(λ)/λ dλ
    std::vector<double> nodeLambda, nodeWeight;            // spectral nodes of the polychromatic PSF
    std::array<double, kCameraWavelengths> cameraWeights{};  // over the channel's transmittance wavelengths
};

// Splits the distribution `density` on [lo, lo + n·step) into `count` bins of equal mass; each bin's
// centroid and mass (masses sum to 1). Empty bins are dropped.
void quantileNodes(const std::vector<double>& density, double lo, double step, int count, std::vector<double>& lambda,
                   std::vector<double>& weight) {
    double total = 0;
    for (double d : density) total += d;
    lambda.clear();
    weight.clear();
    if (!(total > 0)) return;
    double mass = 0, moment = 0, acc = 0;
    int bin = 0;
    for (size_t c = 0; c < density.size(); ++c) {
        const double m = density[c] / total, centre = lo + (static_cast<double>(c) + 0.5) * step;
        acc += m;
        mass += m;
        moment += m * centre;
        const bool last = c + 1 == density.size();
        if (acc >= double(bin + 1) / count - 1e-12 || last) {
            if (mass > 0) {
                lambda.push_back(moment / mass);
                weight.push_back(mass);
            }
            mass = moment = 0;
            while (bin < count && acc >= double(bin + 1) / count - 1e-12) ++bin;
        }
    }
}

double smoothStep01(double t) {
    t = std::clamp(t, 0.0, 1.0);
    return t * t * (3 - 2 * t);
}

}  // namespace

void UnscatteredOptions::validate() const {
    auto require = [](bool ok, const std::string& what) {
        if (!ok) throw ConfigError(what);
    };
    require(lateralSamples >= 1 && lateralSamples <= 16, "unscattered image: lateralSamples must lie in [1, 16], got " + std::to_string(lateralSamples));
    require(axialStepUm > 0 && std::isfinite(axialStepUm) && axialStepUm <= 10,
            "unscattered image: axialStepUm must lie in (0, 10], got " + std::to_string(axialStepUm));
    require(segmentNodes >= 1 && segmentNodes <= 16, "unscattered image: segmentNodes must lie in [1, 16], got " + std::to_string(segmentNodes));
    require(transmittanceStepUm > 0 && std::isfinite(transmittanceStepUm),
            "unscattered image: transmittanceStepUm must be positive, got " + std::to_string(transmittanceStepUm));
    require(transmittanceQuadratureVoxels > 0 && std::isfinite(transmittanceQuadratureVoxels),
            "unscattered image: transmittanceQuadratureVoxels must be positive, got " + std::to_string(transmittanceQuadratureVoxels));
    require(coneRings >= 1 && coneRings <= 32 && coneAzimuths >= 1 && coneAzimuths <= 64,
            "unscattered image: coneRings must lie in [1, 32] and coneAzimuths in [1, 64], got " + std::to_string(coneRings) + " and " +
                std::to_string(coneAzimuths));
    require(spectralNodes >= 1 && spectralNodes <= 256, "unscattered image: spectralNodes must lie in [1, 256], got " + std::to_string(spectralNodes));
    require(pixelQuadrature >= 1 && pixelQuadrature <= 16, "unscattered image: pixelQuadrature must lie in [1, 16], got " + std::to_string(pixelQuadrature));
    require(kernelPhases >= 2 && kernelPhases <= 64 && kernelPhases % (2 * lateralSamples) == 0,
            "unscattered image: kernelPhases must be a multiple of 2 x lateralSamples in [2, 64], got " + std::to_string(kernelPhases));
    require(farBinUm > 0 && std::isfinite(farBinUm), "unscattered image: farBinUm must be positive, got " + std::to_string(farBinUm));
    require(nearPixels >= 1 && nearPixels <= 64 && nearTaperPixels >= 1 && nearTaperPixels <= 64,
            "unscattered image: nearPixels and nearTaperPixels must lie in [1, 64], got " + std::to_string(nearPixels) + " and " +
                std::to_string(nearTaperPixels));
}

// ------------------------------------------------------------------------------------------------
// The model of a channel: dye terms, region, PSF kernels.

struct UnscatteredModel::Impl {
    UnscatteredOptions o;
    std::function<double(double)> detection;
    std::vector<double> lineLambda;            // the beams' lines (deduplicated per line index)
    std::vector<DyeTerm> terms;
    std::array<double, kCameraWavelengths> cameraLambda{};
    double exposureS = 0;
    // Region in the plane's frame and the lattice.
    double pixelMm = 0, latticeMm = 0, axialMm = 0, tanThetaMax = 0;
    int marginPixels = 0, regionWidth = 0, regionHeight = 0;  // region image in pixels (FOV + margins)
    int width = 0, height = 0;
    double halfDepthMm = 0;  // the lattice spans dz in [-halfDepth, halfDepth]
    int layers = 0;          // 2 × halfDepth / axial step
    // Far-field bins along dz and their near/far split radii.
    int bins = 0;
    std::vector<double> splitInnerMm;  // per bin
    std::vector<int> layerBin;
    double cutMm = 0;  // largest PSF cut radius over the detected band
    int pixelNodes = 3;  // Gauss–Legendre nodes per pixel axis: at least pixelQuadrature, more for a sharp PSF
    // Kernels, built on first use: per term, layer and sub-pixel phase, values[(dy + R) side + dx + R];
    // under them the radial profile of each term and layer.
    struct PhaseKernel {
        int radius = 0;
        std::vector<float> values;
    };
    struct Radial;
    mutable std::vector<std::unique_ptr<Radial>> radials;  // [term × layers + layer]
    mutable std::unique_ptr<std::once_flag[]> radialBuilt;
    mutable std::vector<PhaseKernel> kernels;  // [(term × layers + layer) F² + phaseY F + phaseX]
    mutable std::unique_ptr<std::once_flag[]> kernelBuilt;
    std::unique_ptr<FftConvolution> far;  // one kernel per bin
    int farRadius = 0;
    const WidefieldPsf* psf = nullptr;

    double layerDz(int l) const { return (l - 0.5 * layers + 0.5) * axialMm; }
    const Radial& radial(size_t term, int layer) const;
    const PhaseKernel& kernel(size_t term, int layer, int phaseX, int phaseY) const;
    int kernelRadius(int layer) const {
        return static_cast<int>(std::ceil((splitInnerMm[static_cast<size_t>(layerBin[static_cast<size_t>(layer)])] + taperMm()) / pixelMm)) + 1;
    }
    double profile(const DyeTerm& t, double rMm, double dzMm) const {
        double h = 0;
        for (size_t q = 0; q < t.nodeLambda.size(); ++q) h += t.nodeWeight[q] * psf->density(rMm, dzMm, t.nodeLambda[q]);
        return h;
    }
    double taperMm() const { return o.nearTaperPixels * pixelMm; }
    double splitWeight(int bin, double rMm) const {  // 1 in the near part, 0 in the far part
        const double r1 = splitInnerMm[static_cast<size_t>(bin)], r2 = r1 + taperMm();
        return 1 - smoothStep01((rMm - r1) / (r2 - r1));
    }
};

namespace {

// Pixel-integrated values of a radial profile h(r) (tabulated at step dr) for a point at (fx, fy) in
// pixel 0 (pixel units), at pixel offsets within ±radius, by Gauss–Legendre points per pixel axis.
template <class Radial>
void integratePixels(const Radial& radial, double fx, double fy, int radius, const QuadratureRule& q, double pixelMm, float* out) {
    const int side = 2 * radius + 1;
    for (int dy = -radius; dy <= radius; ++dy)
        for (int dx = -radius; dx <= radius; ++dx) {
            double sum = 0;
            for (size_t a = 0; a < q.nodes.size(); ++a)
                for (size_t b = 0; b < q.nodes.size(); ++b) {
                    const double ux = dx + q.nodes[a] - fx, uy = dy + q.nodes[b] - fy;
                    sum += q.weights[a] * q.weights[b] * radial(std::hypot(ux, uy) * pixelMm);
                }
            out[static_cast<size_t>(dy + radius) * side + (dx + radius)] = static_cast<float>(sum * pixelMm * pixelMm);
        }
}

// A radial function tabulated on [0, rMax] at step dr, linearly interpolated, zero beyond.
struct RadialTable {
    double dr = 0;
    std::vector<double> v;
    template <class F>
    RadialTable(double rMax, double step, F&& f) : dr(step) {
        const size_t n = static_cast<size_t>(std::ceil(rMax / step)) + 2;
        v.resize(n);
        for (size_t i = 0; i < n; ++i) v[i] = f(static_cast<double>(i) * step);
    }
    double operator()(double r) const {
        const double u = r / dr;
        const size_t i = static_cast<size_t>(u);
        if (i + 1 >= v.size()) return 0.0;
        const double f = u - static_cast<double>(i);
        return v[i] + f * (v[i + 1] - v[i]);
    }
};

}  // namespace

struct UnscatteredModel::Impl::Radial {
    RadialTable table;
};

const UnscatteredModel::Impl::Radial& UnscatteredModel::Impl::radial(size_t term, int layer) const {
    const size_t index = term * static_cast<size_t>(layers) + static_cast<size_t>(layer);
    std::call_once(radialBuilt[index], [&] {
        const DyeTerm& t = terms[term];
        const int bin = layerBin[static_cast<size_t>(layer)];
        const double dz = layerDz(layer);
        radials[index] = std::make_unique<Radial>(Radial{RadialTable((kernelRadius(layer) + 2) * pixelMm * std::sqrt(2.0), pixelMm / 64,
                                                                     [&](double r) { return profile(t, r, dz) * splitWeight(bin, r); })});
    });
    return *radials[index];
}

const UnscatteredModel::Impl::PhaseKernel& UnscatteredModel::Impl::kernel(size_t term, int layer, int phaseX, int phaseY) const {
    const int F = o.kernelPhases;
    const size_t index = (term * static_cast<size_t>(layers) + static_cast<size_t>(layer)) * static_cast<size_t>(F * F) +
                         static_cast<size_t>(phaseY) * F + static_cast<size_t>(phaseX);
    std::call_once(kernelBuilt[index], [&] {
        PhaseKernel k;
        k.radius = kernelRadius(layer);
        const int side = 2 * k.radius + 1;
        k.values.resize(static_cast<size_t>(side) * side);
        // Mirrors and the transpose of a canonical phase (x ≤ F/2, y ≤ F/2, x ≤ y) are copies: a point at
        // phase f sees pixel offset d as a point at phase 1 − f sees −d.
        auto copyFrom = [&](const PhaseKernel& c, bool mirrorX, bool mirrorY, bool transpose) {
            for (int dy = -k.radius; dy <= k.radius; ++dy)
                for (int dx = -k.radius; dx <= k.radius; ++dx) {
                    int sx = mirrorX ? -dx : dx, sy = mirrorY ? -dy : dy;
                    if (transpose) std::swap(sx, sy);
                    k.values[static_cast<size_t>(dy + k.radius) * side + (dx + k.radius)] =
                        c.values[static_cast<size_t>(sy + k.radius) * side + (sx + k.radius)];
                }
        };
        if (phaseX > F / 2) copyFrom(kernel(term, layer, F - phaseX, phaseY), true, false, false);
        else if (phaseY > F / 2) copyFrom(kernel(term, layer, phaseX, F - phaseY), false, true, false);
        else if (phaseX > phaseY) copyFrom(kernel(term, layer, phaseY, phaseX), false, false, true);
        else integratePixels(radial(term, layer).table, double(phaseX) / F, double(phaseY) / F, k.radius, gaussLegendre01(pixelNodes), pixelMm,
                             k.values.data());
        kernels[index] = std::move(k);
    });
    return kernels[index];
}

UnscatteredModel::UnscatteredModel(const Scene& scene, const std::vector<Light>& lights, const FluorescencePlan& plan, const Imaging& plane,
                                   std::function<double(double)> detection, UnscatteredOptions options)
    : impl_(std::make_unique<Impl>()) {
    options.validate();
    Impl& m = *impl_;
    m.o = options;
    m.detection = std::move(detection);
    m.psf = &plane.psf();
    m.width = plane.width();
    m.height = plane.height();
    m.pixelMm = plane.pixelMm();
    m.latticeMm = m.pixelMm / m.o.lateralSamples;
    m.axialMm = m.o.axialStepUm / kUmPerMm;
    m.tanThetaMax = std::tan(std::acos(plane.cosMax()));
    m.exposureS = plane.sampleEtendue() / (m.pixelMm * m.pixelMm * 1e-6 * plane.coneSolidAngle());

    const std::vector<BeamLine> lines = beamLines(lights);
    if (lines.size() > kMaxBeamLines)
        throw ConfigError("unscattered image: at most " + std::to_string(kMaxBeamLines) + " beam lines per channel, got " + std::to_string(lines.size()));
    for (const BeamLine& l : lines) m.lineLambda.push_back(l.lambdaNm);
    if (lines.empty() || !plan.active()) return;

    // The detected band: the camera wavelengths the paths would use (the scene's range), on 0.5 nm cells.
    const double lo = scene.spectral.lambdaMin, hi = scene.spectral.lambdaMax, cell = 0.5;
    const int cells = std::max(1, static_cast<int>(std::ceil((hi - lo) / cell)));
    std::vector<double> channelDensity(static_cast<size_t>(cells), 0.0);
    std::vector<std::vector<double>> termDensity;
    for (size_t med = 0; med < scene.media.size(); ++med) {
        if (!plan.active(static_cast<int>(med))) continue;
        const Medium& medium = scene.media[med];
        for (size_t i = 0; i < medium.dyes().size(); ++i) {
            const Fluorophore& dye = medium.dyes()[i].dye;
            const int channel = kFirstDyeChannel + static_cast<int>(i);
            if (!(dye.quantumYield() > 0) || !(medium.channelMax()[static_cast<size_t>(channel)] > 0)) continue;
            DyeTerm t;
            t.medium = static_cast<int>(med);
            t.channel = channel;
            t.quantumYield = dye.quantumYield();
            bool excited = false;
            for (const BeamLine& l : lines) {
                t.absorptionPerMolar.push_back(dyeAbsorption(dye, l.lambdaNm, 1.0));
                excited = excited || t.absorptionPerMolar.back() > 0;
            }
            std::vector<double> density(static_cast<size_t>(cells));
            for (int c = 0; c < cells; ++c) {
                const double lambda = lo + (c + 0.5) * (hi - lo) / cells;
                density[static_cast<size_t>(c)] = dye.emissionPdf(lambda) * m.detection(lambda) / lambda * (hi - lo) / cells;
                t.detected += density[static_cast<size_t>(c)];
            }
            if (!excited || !(t.detected > 0)) continue;
            quantileNodes(density, lo, (hi - lo) / cells, m.o.spectralNodes, t.nodeLambda, t.nodeWeight);
            for (int c = 0; c < cells; ++c) channelDensity[static_cast<size_t>(c)] += density[static_cast<size_t>(c)] / t.detected;
            termDensity.push_back(std::move(density));
            m.terms.push_back(std::move(t));
        }
    }
    if (m.terms.empty()) return;
    // The cone-mean transmittance is kept at the centroids of four equal-mass parts of the channel's
    // detected emission; each dye weighs them by its own mass in each part.
    std::vector<double> camLambda, camWeight;
    quantileNodes(channelDensity, lo, (hi - lo) / cells, kCameraWavelengths, camLambda, camWeight);
    for (int j = 0; j < kCameraWavelengths; ++j)
        m.cameraLambda[static_cast<size_t>(j)] = camLambda[std::min(camLambda.size() - 1, static_cast<size_t>(j))];
    for (size_t ti = 0; ti < m.terms.size(); ++ti) {
        DyeTerm& t = m.terms[ti];
        for (int c = 0; c < cells; ++c) {
            const double lambda = lo + (c + 0.5) * (hi - lo) / cells;
            size_t nearest = 0;
            for (size_t j = 1; j < kCameraWavelengths; ++j)
                if (std::abs(lambda - m.cameraLambda[j]) < std::abs(lambda - m.cameraLambda[nearest])) nearest = j;
            t.cameraWeights[nearest] += termDensity[ti][static_cast<size_t>(c)] / t.detected;
        }
    }

    // The axial extent: the cores' largest |dz| over the field with margins, within the PSF's table.
    double lambdaMax = 0, lambdaMin = 1e9;
    for (const DyeTerm& t : m.terms)
        for (double l : t.nodeLambda) {
            lambdaMax = std::max(lambdaMax, l);
            lambdaMin = std::min(lambdaMin, l);
        }
    m.cutMm = m.psf->cutRadiusMm(lambdaMax);
    // Pixel integration: the PSF holds spatial frequencies up to 2 NA/λ, k = pixel × 2 NA/λ cycles per
    // pixel, and n Gauss–Legendre nodes integrate e^{2πikx} over a pixel to 1e-4 for k <= (n − 3)/2
    // (tests/optics/unscattered_image_test.cpp). λ: the shortest wavelength with 1e-3 of the detected
    // band below it.
    {
        double below = 0, lambdaShort = hi;
        for (int c = 0; c < cells; ++c) {
            below += channelDensity[static_cast<size_t>(c)] / static_cast<double>(m.terms.size());
            if (below >= 1e-3) {
                lambdaShort = lo + c * (hi - lo) / cells;
                break;
            }
        }
        const double cyclesPerPixel = m.pixelMm * 2 * plane.psf().pupil().na / (lambdaShort * 1e-6);
        m.pixelNodes = std::clamp(static_cast<int>(std::ceil(2 * cyclesPerPixel + 3)), m.o.pixelQuadrature, 32);
    }
    // Axial layers: the PSF is interpolated linearly between them, so they are at most 1/8 of the
    // depth of field n λ/NA² apart (a bead's axial FWHM at NA 0.8 read 1.0 % wide at 0.25 um).
    {
        const double na = plane.psf().pupil().na, n = plane.psf().pupil().sampleIndex;
        m.axialMm = std::min(m.axialMm, n * lambdaMin * 1e-6 / (na * na) / 8);
    }
    const double dzLimit = m.psf->maxDzMm(lambdaMin);
    double depth = 0;
    {
        const double xHalf = 0.5 * m.width * m.pixelMm + m.cutMm + dzLimit * m.tanThetaMax;
        const double yHalf = 0.5 * m.height * m.pixelMm + m.cutMm + dzLimit * m.tanThetaMax;
        const int n = 16;
        for (int iy = 0; iy <= n; ++iy)
            for (int ix = 0; ix <= n; ++ix) {
                const double x = -xHalf + 2 * xHalf * ix / n, y = -yHalf + 2 * yHalf * iy / n;
                const Ray column{plane.world(x, y, dzLimit), -plane.axis()};
                for (const BeamLine& l : lines)
                    for (int side = 0; side < l.profile->sides(); ++side) {
                        const BeamCore core = l.profile->coreAlong(column, side, l.lambdaNm);
                        for (int k = 0; k < core.count; ++k) {
                            const BeamCoreInterval& iv = core.intervals[static_cast<size_t>(k)];
                            for (double t : {iv.tMin, iv.tMax})
                                depth = std::max(depth, std::min(dzLimit, std::abs(dzLimit - std::clamp(t, 0.0, 2 * dzLimit))));
                        }
                    }
            }
    }
    m.layers = 2 * std::max(1, static_cast<int>(std::ceil(depth / m.axialMm)));
    m.halfDepthMm = 0.5 * m.layers * m.axialMm;
    m.marginPixels = static_cast<int>(std::ceil((m.cutMm + m.halfDepthMm * m.tanThetaMax) / m.pixelMm)) + 2;
    m.regionWidth = m.width + 2 * m.marginPixels;
    m.regionHeight = m.height + 2 * m.marginPixels;

    // Far-field bins along dz; within a bin every layer splits near and far at the same radius, beyond
    // the widest defocus disc of the bin.
    m.bins = std::max(1, static_cast<int>(std::ceil(2 * m.halfDepthMm / (m.o.farBinUm / kUmPerMm))));
    const double binMm = 2 * m.halfDepthMm / m.bins;
    m.splitInnerMm.assign(static_cast<size_t>(m.bins), 0.0);
    for (int b = 0; b < m.bins; ++b) {
        const double binLo = -m.halfDepthMm + b * binMm, binHi = binLo + binMm;
        const double widest = std::max(std::abs(binLo), std::abs(binHi));
        m.splitInnerMm[static_cast<size_t>(b)] = (m.o.nearPixels + std::ceil(widest * m.tanThetaMax / m.pixelMm)) * m.pixelMm;
    }
    m.layerBin.resize(static_cast<size_t>(m.layers));
    for (int l = 0; l < m.layers; ++l)
        m.layerBin[static_cast<size_t>(l)] = std::clamp(static_cast<int>((m.layerDz(l) + m.halfDepthMm) / binMm), 0, m.bins - 1);
    m.radials.resize(m.terms.size() * static_cast<size_t>(m.layers));
    m.radialBuilt = std::make_unique<std::once_flag[]>(m.radials.size());
    m.kernels.resize(m.radials.size() * static_cast<size_t>(m.o.kernelPhases * m.o.kernelPhases));
    m.kernelBuilt = std::make_unique<std::once_flag[]>(m.kernels.size());

    // Far kernels: the detected-mass mean of the dyes' PSFs beyond the split, for a point at a pixel
    // centre, one per bin.
    m.farRadius = static_cast<int>(std::ceil(m.cutMm / m.pixelMm)) + 2;
    m.far = std::make_unique<FftConvolution>(m.regionWidth, m.regionHeight, m.farRadius);
    DyeTerm mean;
    double meanTotal = 0;
    for (const DyeTerm& t : m.terms) meanTotal += t.detected;
    for (const DyeTerm& t : m.terms)
        for (size_t q = 0; q < t.nodeLambda.size(); ++q) {
            mean.nodeLambda.push_back(t.nodeLambda[q]);
            mean.nodeWeight.push_back(t.nodeWeight[q] * t.detected / meanTotal);
        }
    const QuadratureRule q = gaussLegendre01(m.pixelNodes);
    const int side = 2 * m.farRadius + 1;
    for (int b = 0; b < m.bins; ++b) {
        const double dz = -m.halfDepthMm + (b + 0.5) * binMm;
        const RadialTable radial((m.farRadius + 2) * m.pixelMm * std::sqrt(2.0), m.pixelMm / 16,
                                 [&](double r) { return m.profile(mean, r, dz) * (1 - m.splitWeight(b, r)); });
        std::vector<float> k(static_cast<size_t>(side) * side);
        integratePixels(radial, 0.5, 0.5, m.farRadius, q, m.pixelMm, k.data());
        m.far->addKernel(std::vector<double>(k.begin(), k.end()));
    }
}

UnscatteredModel::~UnscatteredModel() = default;

bool UnscatteredModel::active() const { return !impl_->terms.empty(); }
const UnscatteredOptions& UnscatteredModel::options() const { return impl_->o; }

bool UnscatteredModel::covers(const Imaging& plane, const Vec3& y) const {
    const Impl& m = *impl_;
    if (m.terms.empty()) return false;
    const Imaging::Local p = plane.local(y);
    const double xHalf = 0.5 * m.regionWidth * m.pixelMm, yHalf = 0.5 * m.regionHeight * m.pixelMm;
    return std::abs(p.x) <= xHalf && std::abs(p.y) <= yHalf && std::abs(p.dz) <= m.halfDepthMm;
}

// ------------------------------------------------------------------------------------------------
// The emission as a proposal.

EmissionPoints::EmissionPoints(const Imaging& plane, double x0, double yTop, double z0, double lateralMm, double axialMm)
    : right_(plane.world(1, 0, 0) - plane.world(0, 0, 0)), up_(plane.world(0, 1, 0) - plane.world(0, 0, 0)),
      axis_(plane.axis()), centre_(plane.centre()), x0_(x0), yTop_(yTop), z0_(z0), lateral_(lateralMm), axial_(axialMm) {}

uint64_t EmissionPoints::key(int64_t i, int64_t j, int64_t l) const { return packKey(i, j, l); }

void EmissionPoints::add(int64_t i, int64_t j, int64_t layer, double power) {
    if (power > 0) power_[key(i, j, layer)] += power;
}

void EmissionPoints::finish() {
    cells_.clear();
    for (const auto& [k, v] : power_) cells_.push_back(k);
    std::sort(cells_.begin(), cells_.end());
    cdf_.resize(cells_.size());
    total_ = 0;
    for (size_t n = 0; n < cells_.size(); ++n) cdf_[n] = total_ += power_.at(cells_[n]);
}

EmissionPoints::Sample EmissionPoints::sample(double uCell, double ux, double uy, double uz) const {
    const size_t n = std::min(cells_.size() - 1, static_cast<size_t>(std::upper_bound(cdf_.begin(), cdf_.end(), uCell * total_) - cdf_.begin()));
    const uint64_t k = cells_[n];
    const int64_t i = static_cast<int64_t>(k >> 42) - (1 << 20), j = static_cast<int64_t>((k >> 21) & 0x1FFFFF) - (1 << 20),
                  l = static_cast<int64_t>(k & 0x1FFFFF) - (1 << 20);
    const double x = x0_ + (static_cast<double>(i) + ux) * lateral_, y = yTop_ - (static_cast<double>(j) + uy) * lateral_,
                 z = z0_ + (static_cast<double>(l) + uz) * axial_;
    return {centre_ + right_ * x + up_ * y + axis_ * z, power_.at(k) / total_ / (lateral_ * lateral_ * axial_)};
}

double EmissionPoints::pdf(const Vec3& p) const {
    if (cells_.empty()) return 0.0;
    const Vec3 d = p - centre_;
    const int64_t i = static_cast<int64_t>(std::floor((dot(d, right_) - x0_) / lateral_));
    const int64_t j = static_cast<int64_t>(std::floor((yTop_ - dot(d, up_)) / lateral_));
    const int64_t l = static_cast<int64_t>(std::floor((dot(d, axis_) - z0_) / axial_));
    const auto it = power_.find(key(i, j, l));
    return it == power_.end() ? 0.0 : it->second / total_ / (lateral_ * lateral_ * axial_);
}

// ------------------------------------------------------------------------------------------------
// One plane.

namespace {

// An emission point of the quadrature: its place in the plane's frame, its volume, its medium and the
// concentrations of the medium's dyes (mol/L, by dye channel − kFirstDyeChannel).
struct Sample {
    double x, y, dz;
    double volumeMm3;
    int medium;
    std::array<float, kMaxMediumChannels - kFirstDyeChannel> dyes;
};

// Transmittances on a coarse lattice of the plane's frame (over the region), computed at the nodes that
// samples need and trilinearly interpolated.
class CoarseLattice {
public:
    CoarseLattice(double x0, double y0, double z0, double x1, double y1, double z1, double step)
        : x0_(x0), y0_(y0), z0_(z0), step_(step) {
        for (int a = 0; a < 3; ++a) size_[a] = static_cast<int64_t>(std::ceil((std::array{x1 - x0, y1 - y0, z1 - z0}[a]) / step)) + 2;
        needed_.assign(static_cast<size_t>(size_[0] * size_[1] * size_[2]), 0);
    }
    void require(double x, double y, double dz) {
        const auto c = cell(x, y, dz);
        for (int a = 0; a < 8; ++a) needed_[node(c[0] + (a & 1), c[1] + ((a >> 1) & 1), c[2] + ((a >> 2) & 1))] = 1;
    }
    // Computes f(node position) at every required node.
    template <class Value, class F>
    void compute(int threads, F&& f, std::vector<Value>& values) const {
        std::vector<size_t> nodes;
        for (size_t n = 0; n < needed_.size(); ++n)
            if (needed_[n]) nodes.push_back(n);
        values.assign(needed_.size(), Value{});
        parallelFor(nodes.size(), threads, [&](size_t k) {
            const size_t n = nodes[k];
            const int64_t i = static_cast<int64_t>(n % static_cast<size_t>(size_[0])), j = static_cast<int64_t>((n / static_cast<size_t>(size_[0])) % static_cast<size_t>(size_[1])),
                          l = static_cast<int64_t>(n / static_cast<size_t>(size_[0] * size_[1]));
            values[n] = f(x0_ + static_cast<double>(i) * step_, y0_ + static_cast<double>(j) * step_, z0_ + static_cast<double>(l) * step_);
        });
    }
    template <class Value>
    Value interpolate(double x, double y, double dz, const std::vector<Value>& values) const {
        const auto c = cell(x, y, dz);
        const double fx = (x - x0_) / step_ - static_cast<double>(c[0]), fy = (y - y0_) / step_ - static_cast<double>(c[1]),
                     fz = (dz - z0_) / step_ - static_cast<double>(c[2]);
        Value sum{};
        for (int a = 0; a < 8; ++a) {
            const double w = ((a & 1) ? fx : 1 - fx) * (((a >> 1) & 1) ? fy : 1 - fy) * (((a >> 2) & 1) ? fz : 1 - fz);
            sum += values[node(c[0] + (a & 1), c[1] + ((a >> 1) & 1), c[2] + ((a >> 2) & 1))] * w;
        }
        return sum;
    }
    size_t requiredNodes() const {
        size_t n = 0;
        for (uint8_t v : needed_) n += v;
        return n;
    }

private:
    std::array<int64_t, 3> cell(double x, double y, double dz) const {
        return {std::clamp<int64_t>(static_cast<int64_t>(std::floor((x - x0_) / step_)), 0, size_[0] - 2),
                std::clamp<int64_t>(static_cast<int64_t>(std::floor((y - y0_) / step_)), 0, size_[1] - 2),
                std::clamp<int64_t>(static_cast<int64_t>(std::floor((dz - z0_) / step_)), 0, size_[2] - 2)};
    }
    size_t node(int64_t i, int64_t j, int64_t l) const { return static_cast<size_t>((l * size_[1] + j) * size_[0] + i); }

    double x0_, y0_, z0_, step_;
    std::array<int64_t, 3> size_{};
    std::vector<uint8_t> needed_;
};

}  // namespace

UnscatteredPlane computeUnscatteredImage(const Scene& scene, const std::vector<Light>& lights, const Imaging& plane,
                                         const UnscatteredModel& model, int threads, const std::atomic<bool>* cancel) {
    const auto start = std::chrono::steady_clock::now();
    const UnscatteredModel::Impl& m = model.impl();
    UnscatteredPlane out;
    out.electrons.assign(static_cast<size_t>(plane.width()) * plane.height(), 0.0);
    if (m.terms.empty()) return out;
    if (plane.width() != m.width || plane.height() != m.height || std::abs(plane.pixelMm() - m.pixelMm) > 1e-15)
        throw ConfigError("unscattered image: the plane's detector differs from the model's");

    // Lines and sides of this plane's beams.
    std::vector<LineSide> lineSides;
    {
        const std::vector<BeamLine> lines = beamLines(lights);
        if (lines.size() != m.lineLambda.size()) throw ConfigError("unscattered image: the plane's beams differ from the model's");
        for (size_t l = 0; l < lines.size(); ++l)
            for (int s = 0; s < lines[l].profile->sides(); ++s) lineSides.push_back({lines[l].profile, lines[l].lambdaNm, lines[l].weight, s, l});
    }

    const double latt = m.latticeMm, xLeft = -0.5 * m.regionWidth * m.pixelMm, yTop = 0.5 * m.regionHeight * m.pixelMm;
    const int columnsX = m.regionWidth * m.o.lateralSamples, columnsY = m.regionHeight * m.o.lateralSamples;
    const double zLow = -m.halfDepthMm;
    auto columnX = [&](int i) { return xLeft + (i + 0.5) * latt; };
    auto columnY = [&](int j) { return yTop - (j + 0.5) * latt; };
    auto inRegion = [&](double x, double y, double dz) {
        return x >= xLeft && x <= -xLeft && y <= yTop && y >= -yTop && dz >= zLow && dz <= m.halfDepthMm;
    };
    auto inAnyCore = [&](const Vec3& p) {
        for (const LineSide& ls : lineSides)
            if (ls.profile->inCore(p, ls.side, ls.lambdaNm)) return true;
        return false;
    };
    // --- 1. Emission samples.
    // Grid-dyed media: lattice nodes near the dye grids' blocks, kept where a dye is nonzero; their
    // medium is checked against the geometry below. Homogeneous dyed media: columns over the shapes that
    // hold them (all columns when the medium is not enclosed), integrated along each column segment.
    std::vector<std::vector<Sample>> perChunk;
    std::mutex samplesMutex;
    auto emitting = [&](int medium) {
        for (const DyeTerm& t : m.terms)
            if (t.medium == medium) return true;
        return false;
    };
    struct Box {
        double x0, x1, y0, y1, z0, z1;
    };
    auto localBox = [&](const Vec3* corners, int count) {
        Box b{1e300, -1e300, 1e300, -1e300, 1e300, -1e300};
        for (int c = 0; c < count; ++c) {
            const Imaging::Local p = plane.local(corners[c]);
            b.x0 = std::min(b.x0, p.x);
            b.x1 = std::max(b.x1, p.x);
            b.y0 = std::min(b.y0, p.y);
            b.y1 = std::max(b.y1, p.y);
            b.z0 = std::min(b.z0, p.dz);
            b.z1 = std::max(b.z1, p.dz);
        }
        return b;
    };
    // Grid media: a dye's lookup is nonzero only within reach of an active 8³ block (a voxel beyond it for
    // trilinear lookups); each lattice node is visited from one block, the smallest active one that reaches it.
    struct BlockTask {
        int medium;
        int64_t bx, by, bz;
    };
    std::vector<BlockTask> blockTasks;
    std::vector<std::unordered_set<uint64_t>> activeBlocks(scene.media.size());
    std::vector<int> homogeneousMedia;
    for (size_t med = 0; med < scene.media.size(); ++med) {
        if (!emitting(static_cast<int>(med))) continue;
        const Medium& medium = scene.media[med];
        const VolumeFields* volume = medium.volume();
        bool constantDye = !volume;
        for (const DyeTerm& t : m.terms)
            if (t.medium == static_cast<int>(med) && (medium.channelFloor()[static_cast<size_t>(t.channel)] > 0 || !volume || !volume->channel(t.channel).grid))
                constantDye = true;
        if (constantDye) {
            homogeneousMedia.push_back(static_cast<int>(med));
            continue;
        }
        std::unordered_set<uint64_t>& blocks = activeBlocks[med];
        for (const DyeTerm& t : m.terms) {
            if (t.medium != static_cast<int>(med)) continue;
            volume->channel(t.channel).grid->forEachBlock([&](const IndexBox& box, double maxValue) {
                if (!(maxValue > 0)) return;
                for (int64_t cz = box.lo[2] >> 3; cz <= box.hi[2] >> 3; ++cz)
                    for (int64_t cy = box.lo[1] >> 3; cy <= box.hi[1] >> 3; ++cy)
                        for (int64_t cx = box.lo[0] >> 3; cx <= box.hi[0] >> 3; ++cx) blocks.insert(packKey(cx, cy, cz));
            });
        }
        std::vector<uint64_t> sorted(blocks.begin(), blocks.end());
        std::sort(sorted.begin(), sorted.end());
        for (uint64_t k : sorted)
            blockTasks.push_back({static_cast<int>(med), static_cast<int64_t>(k >> 42) - (1 << 20), static_cast<int64_t>((k >> 21) & 0x1FFFFF) - (1 << 20),
                                  static_cast<int64_t>(k & 0x1FFFFF) - (1 << 20)});
    }
    parallelFor(blockTasks.size(), threads, [&](size_t task) {
        if (cancel && cancel->load()) return;
        const BlockTask& bt = blockTasks[task];
        const Medium& medium = scene.media[static_cast<size_t>(bt.medium)];
        const VolumeFields& volume = *medium.volume();
        const bool nearest = volume.interpolation() == Interpolation::Nearest;
        // Index positions a node may have and still read this block: [8b − 1, 8b + 8) for trilinear
        // lookups, [8b − 0.5, 8b + 7.5) for nearest ones.
        const double reachLo = nearest ? -0.5 : -1.0, reachHi = nearest ? 7.5 : 8.0;
        const std::array<int64_t, 3> b{bt.bx, bt.by, bt.bz};
        Vec3 corners[8];
        for (int a = 0; a < 8; ++a)
            corners[a] = volume.worldFromIndex().apply(Vec3(8.0 * b[0] + ((a & 1) ? reachHi : reachLo), 8.0 * b[1] + (((a >> 1) & 1) ? reachHi : reachLo),
                                                            8.0 * b[2] + (((a >> 2) & 1) ? reachHi : reachLo)));
        const Box box = localBox(corners, 8);
        if (box.x1 < xLeft || box.x0 > -xLeft || box.y0 > yTop || box.y1 < -yTop || box.z1 < zLow || box.z0 > m.halfDepthMm) return;
        // Skip blocks outside every core: the cores' extent along the columns at the box's corners bounds
        // it over the box (a sheet's half-thickness is convex across it, and a tilt is linear).
        double coreLo = 1e300, coreHi = -1e300;
        for (int c = 0; c < 4; ++c) {
            const Ray down{plane.world((c & 1) ? box.x1 : box.x0, (c & 2) ? box.y1 : box.y0, m.halfDepthMm), -plane.axis()};
            for (const LineSide& ls : lineSides) {
                const BeamCore core = ls.profile->coreAlong(down, ls.side, ls.lambdaNm);
                for (int k = 0; k < core.count; ++k) {
                    coreLo = std::min(coreLo, m.halfDepthMm - core.intervals[static_cast<size_t>(k)].tMax);
                    coreHi = std::max(coreHi, m.halfDepthMm - core.intervals[static_cast<size_t>(k)].tMin);
                }
            }
        }
        if (box.z1 < coreLo - m.axialMm || box.z0 > coreHi + m.axialMm) return;
        // The dye channels' voxels this block can read, [8b − 1, 8b + 9) on each axis, in a dense cache.
        struct DenseChannel {
            int channel;
            double offset, scale;
            std::vector<float> v;
        };
        std::vector<DenseChannel> dense;
        for (const DyeTerm& t : m.terms) {
            if (t.medium != bt.medium) continue;
            const VolumeChannel& ch = volume.channel(t.channel);
            DenseChannel d{t.channel, ch.offset, ch.scale, std::vector<float>(1000)};
            IndexBox cache;
            for (int a = 0; a < 3; ++a) {
                cache.lo[static_cast<size_t>(a)] = static_cast<int32_t>(8 * b[static_cast<size_t>(a)] - 1);
                cache.hi[static_cast<size_t>(a)] = static_cast<int32_t>(8 * b[static_cast<size_t>(a)] + 8);
            }
            ch.grid->copyVoxels(cache, d.v.data());
            dense.push_back(std::move(d));
        }
        auto lookup = [&](const DenseChannel& d, const Vec3& q) {
            const double x = q.x - (8.0 * b[0] - 1), y = q.y - (8.0 * b[1] - 1), z = q.z - (8.0 * b[2] - 1);
            auto at = [&](int i, int j, int k) { return double(d.v[static_cast<size_t>((std::clamp(k, 0, 9) * 10 + std::clamp(j, 0, 9)) * 10 + std::clamp(i, 0, 9))]); };
            if (nearest) return at(static_cast<int>(std::floor(x + 0.5)), static_cast<int>(std::floor(y + 0.5)), static_cast<int>(std::floor(z + 0.5)));
            const int i = static_cast<int>(std::floor(x)), j = static_cast<int>(std::floor(y)), k = static_cast<int>(std::floor(z));
            const double fx = x - i, fy = y - j, fz = z - k;
            double v = 0;
            for (int c = 0; c < 8; ++c)
                v += ((c & 1) ? fx : 1 - fx) * (((c >> 1) & 1) ? fy : 1 - fy) * (((c >> 2) & 1) ? fz : 1 - fz) * at(i + (c & 1), j + ((c >> 1) & 1), k + ((c >> 2) & 1));
            return v;
        };
        // Lattice nodes by the index cell (between voxel centres) that holds them: a cell whose corner
        // voxels are all zero reads zero everywhere. A cell belongs to the smallest active block among
        // its corners' blocks, so that each node is visited once.
        const std::unordered_set<uint64_t>& active = activeBlocks[static_cast<size_t>(bt.medium)];
        const uint64_t self = packKey(b[0], b[1], b[2]);
        const Affine& fromWorld = volume.indexFromWorld();
        const Affine& toWorld = volume.worldFromIndex();
        std::vector<Sample> local;
        const double volumeMm3 = latt * latt * m.axialMm;
        const int cellLo = nearest ? 0 : -1;  // nearest lookups: the cell of voxel v is [v − 0.5, v + 0.5)
        for (int ck = cellLo; ck < 8; ++ck)
            for (int cj = cellLo; cj < 8; ++cj)
                for (int ci = cellLo; ci < 8; ++ci) {
                    const int64_t gi = 8 * b[0] + ci, gj = 8 * b[1] + cj, gk = 8 * b[2] + ck;
                    bool any = false;
                    const int cornerCount = nearest ? 1 : 8;
                    for (int c = 0; c < cornerCount && !any; ++c)
                        for (const DenseChannel& d : dense)
                            any = any || d.v[static_cast<size_t>(((ck + 1 + ((c >> 2) & 1)) * 10 + cj + 1 + ((c >> 1) & 1)) * 10 + ci + 1 + (c & 1))] > 0;
                    if (!any) continue;
                    if (!nearest) {
                        bool mine = true;
                        for (int c = 0; c < 8 && mine; ++c) {
                            const uint64_t k = packKey(floorDiv(gi + (c & 1), 8), floorDiv(gj + ((c >> 1) & 1), 8), floorDiv(gk + ((c >> 2) & 1), 8));
                            mine = !(k < self && active.count(k));
                        }
                        if (!mine) continue;
                    }
                    const double off = nearest ? -0.5 : 0.0;
                    Vec3 cellCorners[8];
                    for (int c = 0; c < 8; ++c)
                        cellCorners[c] = toWorld.apply(Vec3(gi + off + (c & 1), gj + off + ((c >> 1) & 1), gk + off + ((c >> 2) & 1)));
                    const Box cell = localBox(cellCorners, 8);
                    const int i0 = std::max(0, static_cast<int>(std::ceil((cell.x0 - xLeft) / latt - 0.5))),
                              i1 = std::min(columnsX - 1, static_cast<int>(std::floor((cell.x1 - xLeft) / latt - 0.5)));
                    const int j0 = std::max(0, static_cast<int>(std::ceil((yTop - cell.y1) / latt - 0.5))),
                              j1 = std::min(columnsY - 1, static_cast<int>(std::floor((yTop - cell.y0) / latt - 0.5)));
                    const int l0 = std::max(0, static_cast<int>(std::ceil((cell.z0 - zLow) / m.axialMm - 0.5))),
                              l1 = std::min(m.layers - 1, static_cast<int>(std::floor((cell.z1 - zLow) / m.axialMm - 0.5)));
                    for (int j = j0; j <= j1; ++j)
                        for (int i = i0; i <= i1; ++i)
                            for (int l = l0; l <= l1; ++l) {
                                const double x = columnX(i), y = columnY(j), dz = m.layerDz(l);
                                const Vec3 p = plane.world(x, y, dz);
                                const Vec3 q = fromWorld.apply(p);
                                if (std::floor(q.x - off) != double(gi) || std::floor(q.y - off) != double(gj) || std::floor(q.z - off) != double(gk)) continue;
                                if (!inAnyCore(p)) continue;
                                Sample s{x, y, dz, volumeMm3, bt.medium, {}};
                                bool dyed = false;
                                for (const DenseChannel& d : dense) {
                                    const double value = d.offset + d.scale * lookup(d, q);
                                    s.dyes[static_cast<size_t>(d.channel - kFirstDyeChannel)] = static_cast<float>(value);
                                    dyed = dyed || value > 0;
                                }
                                if (dyed) local.push_back(s);
                            }
                }
        if (!local.empty()) {
            const std::lock_guard<std::mutex> lock(samplesMutex);
            perChunk.push_back(std::move(local));
        }
    });
    // Homogeneous media: the columns over their shapes, refined over small ones.
    if (!homogeneousMedia.empty()) {
        struct Column {
            double x, y, area;
        };
        std::vector<Column> columns;
        std::vector<uint8_t> taken(static_cast<size_t>(columnsX) * columnsY, 0);
        std::unordered_set<uint64_t> fineTaken;
        for (int med : homogeneousMedia) {
            bool enclosed = med != scene.camera.medium;
            std::vector<uint32_t> shapes;
            for (uint32_t s = 0; s < scene.shapes.size(); ++s) {
                if (scene.shapes[s].outsideMedium == med) enclosed = false;
                if (scene.shapes[s].insideMedium == med) shapes.push_back(s);
            }
            if (!enclosed || shapes.empty()) {
                for (int j = 0; j < columnsY; ++j)
                    for (int i = 0; i < columnsX; ++i)
                        if (!std::exchange(taken[static_cast<size_t>(j) * columnsX + i], uint8_t(1))) columns.push_back({columnX(i), columnY(j), latt * latt});
                continue;
            }
            for (uint32_t s : shapes) {
                Vec3 corners[8];
                if (scene.geometry.isSphere(s)) {
                    const Vec3 c = scene.geometry.sphereCenter(s);
                    const double r = scene.geometry.sphereRadius(s);
                    for (int a = 0; a < 8; ++a) corners[a] = c + Vec3((a & 1) ? r : -r, ((a >> 1) & 1) ? r : -r, ((a >> 2) & 1) ? r : -r);
                } else {
                    Vec3 lo(1e300, 1e300, 1e300), hi(-1e300, -1e300, -1e300);
                    for (const Vec3& p : scene.geometry.mesh(s).positions)
                        for (int a = 0; a < 3; ++a) {
                            lo[a] = std::min(lo[a], p[a]);
                            hi[a] = std::max(hi[a], p[a]);
                        }
                    for (int a = 0; a < 8; ++a) corners[a] = Vec3((a & 1) ? hi.x : lo.x, ((a >> 1) & 1) ? hi.y : lo.y, ((a >> 2) & 1) ? hi.z : lo.z);
                }
                const Box b = localBox(corners, 8);
                if (b.x1 < xLeft || b.x0 > -xLeft || b.y0 > yTop || b.y1 < -yTop || b.z1 < zLow || b.z0 > m.halfDepthMm) continue;
                const double extent = std::min(b.x1 - b.x0, b.y1 - b.y0);
                if (extent < 4 * latt) {
                    // A small shape (a bead): columns on a finer lattice, at least 8 across it.
                    const int refine = std::clamp(static_cast<int>(std::ceil(8 * latt / std::max(extent, 1e-12))), 1, 64);
                    const double fine = latt / refine;
                    const int64_t i0 = static_cast<int64_t>(std::floor((b.x0 - xLeft) / fine)), i1 = static_cast<int64_t>(std::ceil((b.x1 - xLeft) / fine));
                    const int64_t j0 = static_cast<int64_t>(std::floor((yTop - b.y1) / fine)), j1 = static_cast<int64_t>(std::ceil((yTop - b.y0) / fine));
                    for (int64_t j = j0; j <= j1; ++j)
                        for (int64_t i = i0; i <= i1; ++i) {
                            const double x = xLeft + (i + 0.5) * fine, y = yTop - (j + 0.5) * fine;
                            if (!inRegion(x, y, 0.0)) continue;
                            if (!fineTaken.insert((static_cast<uint64_t>(refine) << 56) ^ packKey(i, j, 0)).second) continue;
                            columns.push_back({x, y, fine * fine});
                        }
                    continue;
                }
                const int i0 = std::max(0, static_cast<int>(std::floor((b.x0 - xLeft) / latt))), i1 = std::min(columnsX - 1, static_cast<int>(std::ceil((b.x1 - xLeft) / latt)));
                const int j0 = std::max(0, static_cast<int>(std::floor((yTop - b.y1) / latt))), j1 = std::min(columnsY - 1, static_cast<int>(std::ceil((yTop - b.y0) / latt)));
                for (int j = j0; j <= j1; ++j)
                    for (int i = i0; i <= i1; ++i)
                        if (!std::exchange(taken[static_cast<size_t>(j) * columnsX + i], uint8_t(1))) columns.push_back({columnX(i), columnY(j), latt * latt});
            }
        }
        const QuadratureRule gl = gaussLegendre01(m.o.segmentNodes);
        parallelFor(columns.size(), threads, [&](size_t c) {
            if (cancel && cancel->load()) return;
            const Column& col = columns[c];
            const Vec3 top = plane.world(col.x, col.y, m.halfDepthMm);
            const Ray down{top, -plane.axis()};
            const int medium0 = mediumAt(scene, top, plane.axis());
            const StraightLine line = traceStraightLine(scene, down, medium0, 0.0, 2 * m.halfDepthMm, LineSurfaces::ThroughAll);
            // The union of the cores along the column.
            std::vector<std::pair<double, double>> cores;
            for (const LineSide& ls : lineSides) {
                const BeamCore core = ls.profile->coreAlong(down, ls.side, ls.lambdaNm);
                for (int k = 0; k < core.count; ++k)
                    cores.push_back({std::max(0.0, core.intervals[static_cast<size_t>(k)].tMin),
                                     std::min(2 * m.halfDepthMm, core.intervals[static_cast<size_t>(k)].tMax)});
            }
            std::sort(cores.begin(), cores.end());
            std::vector<std::pair<double, double>> merged;
            for (const auto& iv : cores) {
                if (!(iv.second > iv.first)) continue;
                if (!merged.empty() && iv.first <= merged.back().second) merged.back().second = std::max(merged.back().second, iv.second);
                else merged.push_back(iv);
            }
            std::vector<Sample> local;
            for (const RaySegment& seg : line.segments) {
                if (std::find(homogeneousMedia.begin(), homogeneousMedia.end(), seg.medium) == homogeneousMedia.end()) continue;
                const Medium& medium = scene.media[static_cast<size_t>(seg.medium)];
                for (const auto& core : merged) {
                    const double a = std::max(seg.t0, core.first), b = std::min(seg.t1, core.second);
                    if (!(b > a)) continue;
                    const int pieces = std::max(1, static_cast<int>(std::ceil((b - a) / m.axialMm)));
                    const double h = (b - a) / pieces;
                    for (int piece = 0; piece < pieces; ++piece)
                        for (size_t n = 0; n < gl.nodes.size(); ++n) {
                            const double t = a + (piece + gl.nodes[n]) * h;
                            Sample s{col.x, col.y, m.halfDepthMm - t, col.area * h * gl.weights[n], seg.medium, {}};
                            ChannelValues values;
                            medium.channelValues(down.at(t), values.data());
                            for (int dc = kFirstDyeChannel; dc < medium.channelCount(); ++dc)
                                s.dyes[static_cast<size_t>(dc - kFirstDyeChannel)] = static_cast<float>(values[static_cast<size_t>(dc)]);
                            local.push_back(s);
                        }
                }
            }
            if (!local.empty()) {
                const std::lock_guard<std::mutex> lock(samplesMutex);
                perChunk.push_back(std::move(local));
            }
        });
    }
    if (cancel && cancel->load()) {
        out.complete = false;
        return out;
    }
    // Chunks arrive in scheduling order: sort them so that sums do not depend on it.
    std::sort(perChunk.begin(), perChunk.end(), [](const std::vector<Sample>& a, const std::vector<Sample>& b) {
        return std::tie(a.front().y, a.front().x, a.front().dz) > std::tie(b.front().y, b.front().x, b.front().dz);
    });
    std::vector<Sample> samples;
    for (auto& chunk : perChunk) samples.insert(samples.end(), chunk.begin(), chunk.end());
    perChunk.clear();

    // --- 2. Grid samples: the medium at each from the geometry of its lattice column.
    {
        std::unordered_map<uint64_t, std::vector<RaySegment>> columnMedia;
        for (const Sample& s : samples)
            if (!scene.media[static_cast<size_t>(s.medium)].isHomogeneous())
                columnMedia.emplace(packKey(std::llround((s.x - xLeft) / latt - 0.5), std::llround((yTop - s.y) / latt - 0.5), 0), std::vector<RaySegment>{});
        std::vector<uint64_t> keys;
        for (const auto& kv : columnMedia) keys.push_back(kv.first);
        std::vector<std::vector<RaySegment>> media(keys.size());
        parallelFor(keys.size(), threads, [&](size_t n) {
            const int64_t i = static_cast<int64_t>(keys[n] >> 42) - (1 << 20), j = static_cast<int64_t>((keys[n] >> 21) & 0x1FFFFF) - (1 << 20);
            const Vec3 top = plane.world(columnX(static_cast<int>(i)), columnY(static_cast<int>(j)), m.halfDepthMm);
            const int medium0 = mediumAt(scene, top, plane.axis());
            media[n] = traceStraightLine(scene, Ray{top, -plane.axis()}, medium0, 0.0, 2 * m.halfDepthMm, LineSurfaces::ThroughAll).segments;
        });
        for (size_t n = 0; n < keys.size(); ++n) columnMedia[keys[n]] = std::move(media[n]);
        std::vector<Sample> kept;
        kept.reserve(samples.size());
        for (const Sample& s : samples) {
            if (scene.media[static_cast<size_t>(s.medium)].isHomogeneous()) {
                kept.push_back(s);
                continue;
            }
            const auto& segs = columnMedia.at(packKey(std::llround((s.x - xLeft) / latt - 0.5), std::llround((yTop - s.y) / latt - 0.5), 0));
            const double t = m.halfDepthMm - s.dz;
            for (const RaySegment& seg : segs)
                if (t >= seg.t0 && t < seg.t1) {
                    if (seg.medium == s.medium) kept.push_back(s);
                    break;
                }
        }
        samples.swap(kept);
    }
    out.points = samples.size();

    // --- 3. Transmittances back along each beam side to where it entered the sample, and toward the
    // objective (mean over the cone). On a coarse lattice, trilinearly interpolated, for samples of grid
    // media; exactly at each sample of a homogeneous medium, whose object (a bead, a layer) is often
    // thinner than the lattice and absorbs on its own.
    auto beamTransmittance = [&](const Vec3& p, int medium, const LineSide& side) {
        const Vec3 back = -side.profile->direction(side.side);
        const StraightLine line = traceStraightLine(scene, Ray{p, back}, medium, 0.0, 2 * (scene.geometry.extent() + length(p)) + 1,
                                                    LineSurfaces::UntilRefraction);
        if (line.end == LineEnd::Blocked) return 0.0;
        return quadratureTransmittance(scene, Ray{p, back}, line.segments, SampledWavelengths::atLine(side.lambdaNm, 1.0),
                                       m.o.transmittanceQuadratureVoxels)[0];
    };
    SampledWavelengths cameraWl;
    for (int j = 0; j < kCameraWavelengths; ++j) {
        cameraWl.lambda[static_cast<size_t>(j)] = m.cameraLambda[static_cast<size_t>(j)];
        cameraWl.pdf[static_cast<size_t>(j)] = 1;
    }
    const QuadratureRule rings = gaussLegendre01(m.o.coneRings);
    auto cameraTransmittance = [&](const Vec3& p, double dz) {
        SampledSpectrum sum(0.0);
        for (size_t r = 0; r < rings.nodes.size(); ++r) {
            const double cosT = 1 - rings.nodes[r] * (1 - plane.cosMax());
            for (int a = 0; a < m.o.coneAzimuths; ++a) {
                const Vec3 w = plane.coneDirection(cosT, 2 * kPi * (a + 0.5) / m.o.coneAzimuths);
                // The camera path that reaches p along -w starts at the working distance above the
                // focal plane, in the camera's medium.
                const double distance = (plane.workingDistanceMm() - dz) / cosT;
                if (!(distance > 0)) continue;
                const Ray ray{p + w * distance, -w};
                const StraightLine line = traceStraightLine(scene, ray, scene.camera.medium, 0.0, distance, LineSurfaces::StopAtAny);
                if (line.end != LineEnd::Open) continue;
                sum += quadratureTransmittance(scene, ray, line.segments, cameraWl, m.o.transmittanceQuadratureVoxels) *
                       (rings.weights[r] / m.o.coneAzimuths);
            }
        }
        return sum;
    };
    const double coarse = m.o.transmittanceStepUm / kUmPerMm;
    CoarseLattice lattice(xLeft, -yTop, zLow, -xLeft, yTop, m.halfDepthMm, coarse);
    std::vector<size_t> exactSamples;  // indices of samples in homogeneous media
    for (size_t n = 0; n < samples.size(); ++n) {
        if (scene.media[static_cast<size_t>(samples[n].medium)].isHomogeneous()) exactSamples.push_back(n);
        else lattice.require(samples[n].x, samples[n].y, samples[n].dz);
    }
    std::vector<std::vector<double>> beamT(lineSides.size());
    for (size_t ls = 0; ls < lineSides.size(); ++ls)
        lattice.compute<double>(threads, [&](double x, double y, double dz) {
            const Vec3 p = plane.world(x, y, dz);
            return beamTransmittance(p, mediumAt(scene, p, plane.axis()), lineSides[ls]);
        }, beamT[ls]);
    std::vector<SampledSpectrum> cameraT;
    lattice.compute<SampledSpectrum>(threads, [&](double x, double y, double dz) { return cameraTransmittance(plane.world(x, y, dz), dz); },
                                     cameraT);
    // Exact values of the homogeneous media's samples: [exact index × line sides + side] and per sample.
    std::vector<double> exactBeamT(exactSamples.size() * lineSides.size());
    std::vector<SampledSpectrum> exactCameraT(exactSamples.size());
    std::vector<int64_t> exactIndex(samples.size(), -1);
    for (size_t k = 0; k < exactSamples.size(); ++k) exactIndex[exactSamples[k]] = static_cast<int64_t>(k);
    parallelFor(exactSamples.size(), threads, [&](size_t k) {
        const Sample& s = samples[exactSamples[k]];
        const Vec3 p = plane.world(s.x, s.y, s.dz);
        for (size_t ls = 0; ls < lineSides.size(); ++ls) exactBeamT[k * lineSides.size() + ls] = beamTransmittance(p, s.medium, lineSides[ls]);
        exactCameraT[k] = cameraTransmittance(p, s.dz);
    });

    // --- 4. Weights: per sample and dye, the photoelectrons and where they land (pixel coordinates
    // in the region image, axial layer position).
    struct Splat {
        double u, v, layerPos, e;
        size_t term;
        double power;  // what the point emits into the channel's band, before the camera's side (for EmissionPoints)
    };
    // At most one splat per dye of the sample's medium; unused slots keep e = 0 and are dropped.
    size_t termsPerMedium = 0;
    for (size_t med = 0; med < scene.media.size(); ++med) {
        size_t n = 0;
        for (const DyeTerm& t : m.terms) n += t.medium == static_cast<int>(med);
        termsPerMedium = std::max(termsPerMedium, n);
    }
    std::vector<Splat> slots(samples.size() * termsPerMedium, Splat{0, 0, 0, 0, 0, 0});
    const double cone = plane.coneSolidAngle();
    parallelFor(samples.size(), threads, [&](size_t n) {
        if (cancel && cancel->load()) return;
        const Sample& s = samples[n];
        const Vec3 p = plane.world(s.x, s.y, s.dz);
        // Excitation per line: Σ_sides E T_beam (W/m²) where p is inside that side's core.
        std::array<double, kMaxBeamLines> excitation{};
        bool lit = false;
        for (size_t ls = 0; ls < lineSides.size(); ++ls) {
            const LineSide& side = lineSides[ls];
            if (!side.profile->inCore(p, side.side, side.lambdaNm)) continue;
            const double E = side.profile->irradiance(p, side.side, side.lambdaNm) * kMm2PerM2 * side.weight;
            if (!(E > 0)) continue;
            const int64_t exact = exactIndex[n];
            excitation[side.line] += E * (exact >= 0 ? exactBeamT[static_cast<size_t>(exact) * lineSides.size() + ls] : lattice.interpolate(s.x, s.y, s.dz, beamT[ls]));
            lit = true;
        }
        if (!lit) return;
        const SampledSpectrum Tcam = exactIndex[n] >= 0 ? exactCameraT[static_cast<size_t>(exactIndex[n])] : lattice.interpolate(s.x, s.y, s.dz, cameraT);
        size_t slot = n * termsPerMedium;
        for (size_t ti = 0; ti < m.terms.size(); ++ti) {
            const DyeTerm& t = m.terms[ti];
            if (t.medium != s.medium) continue;
            Splat& slotOut = slots[slot++];
            const double c = s.dyes[static_cast<size_t>(t.channel - kFirstDyeChannel)];
            if (!(c > 0)) continue;
            double absorbed = 0;  // Σ_l E T σa(λ_l; c) λ_l
            for (size_t l = 0; l < m.lineLambda.size(); ++l) absorbed += excitation[l] * t.absorptionPerMolar[l] * c * m.lineLambda[l];
            double camera = 0;
            for (int j = 0; j < kCameraWavelengths; ++j) camera += t.cameraWeights[static_cast<size_t>(j)] * Tcam[j];
            const double e = m.exposureS * cone * s.volumeMm3 * 1e-6 * kInv4Pi * camera * t.quantumYield * t.detected * absorbed;
            if (e > 0)
                slotOut = {(s.x - xLeft) / m.pixelMm, (yTop - s.y) / m.pixelMm, (s.dz - zLow) / m.axialMm - 0.5, e, ti,
                       s.volumeMm3 * t.quantumYield * t.detected * absorbed};
        }
    });
    if (cancel && cancel->load()) {
        out.complete = false;
        return out;
    }
    std::vector<Splat> splats;
    for (const Splat& sp : slots)
        if (sp.e > 0) splats.push_back(sp);
    slots = {};
    auto emission = std::make_shared<EmissionPoints>(plane, xLeft, yTop, zLow, latt, m.axialMm);
    for (const Splat& sp : splats)
        emission->add(static_cast<int64_t>(std::floor(sp.u * m.o.lateralSamples)), static_cast<int64_t>(std::floor(sp.v * m.o.lateralSamples)),
                      static_cast<int64_t>(std::floor(sp.layerPos + 0.5)), sp.power);
    emission->finish();
    out.emission = std::move(emission);
    std::stable_sort(splats.begin(), splats.end(), [](const Splat& a, const Splat& b) { return std::floor(a.v) < std::floor(b.v); });

    // --- 5. Splats, by bands of output rows (each pixel sums its splats in one fixed order, whatever the
    // thread count). A splat is up to 2 layers × 4 sub-pixel phases, each a tabulated kernel near the
    // point and a bilinear deposit at the pixel centres for the far part.
    const int F = m.o.kernelPhases, W = m.regionWidth, H = m.regionHeight;
    int reach = 0;  // the widest kernel, in pixels
    for (double r : m.splitInnerMm) reach = std::max(reach, static_cast<int>(std::ceil((r + m.taperMm()) / m.pixelMm)) + 2);
    constexpr int kBandRows = 48;
    const int bands = (H + kBandRows - 1) / kBandRows;
    const int fovX0 = m.marginPixels, fovX1 = m.marginPixels + plane.width(), fovY0 = m.marginPixels, fovY1 = m.marginPixels + plane.height();
    // Float sums: each pixel adds at most a few thousand splats, far within float's 24 bits.
    std::vector<float> nearImage(static_cast<size_t>(W) * H, 0.0f);
    std::vector<std::vector<double>> farBins(static_cast<size_t>(m.bins));
    for (const Splat& sp : splats) {
        const int l0 = std::clamp(static_cast<int>(std::floor(sp.layerPos)), 0, m.layers - 1);
        for (int layer : {l0, std::min(l0 + 1, m.layers - 1)}) {
            std::vector<double>& bin = farBins[static_cast<size_t>(m.layerBin[static_cast<size_t>(layer)])];
            if (bin.empty()) bin.assign(static_cast<size_t>(W) * H, 0.0);
        }
    }
    parallelFor(static_cast<size_t>(bands), threads, [&](size_t band) {
        if (cancel && cancel->load()) return;
        const int y0 = static_cast<int>(band) * kBandRows, y1 = std::min(H, y0 + kBandRows);
        const auto first = std::lower_bound(splats.begin(), splats.end(), y0 - reach - 1, [](const Splat& a, int row) { return std::floor(a.v) < row; });
        for (auto it = first; it != splats.end() && std::floor(it->v) <= y1 + reach; ++it) {
            const Splat& sp = *it;
            const int l0 = std::clamp(static_cast<int>(std::floor(sp.layerPos)), 0, m.layers - 1), l1 = std::min(l0 + 1, m.layers - 1);
            const double fl = std::clamp(sp.layerPos - l0, 0.0, 1.0);
            const double pu = sp.u * F, pv = sp.v * F;
            const int64_t iu = static_cast<int64_t>(std::floor(pu)), iv = static_cast<int64_t>(std::floor(pv));
            const double fu = pu - static_cast<double>(iu), fv = pv - static_cast<double>(iv);
            for (int dl = 0; dl < 2; ++dl) {
                const double wl = dl ? fl : 1 - fl;
                if (!(wl > 0)) continue;
                const int layer = dl ? l1 : l0;
                const int bin = m.layerBin[static_cast<size_t>(layer)];
                for (int corner = 0; corner < 4; ++corner) {
                    const double wc = ((corner & 1) ? fu : 1 - fu) * ((corner & 2) ? fv : 1 - fv) * wl;
                    if (!(wc > 0)) continue;
                    const int64_t qu = iu + (corner & 1), qv = iv + ((corner >> 1) & 1);
                    const int64_t px = floorDiv(qu, F), py = floorDiv(qv, F);
                    const int phx = static_cast<int>(qu - px * F), phy = static_cast<int>(qv - py * F);
                    const double weight = sp.e * wc;
                    const auto& k = m.kernel(sp.term, layer, phx, phy);
                    const int side = 2 * k.radius + 1;
                    const float* kv = k.values.data();
                    // The near part only where the camera is (the far part reaches the whole region).
                    const int64_t xa = std::max<int64_t>(fovX0, px - k.radius), xb = std::min<int64_t>(fovX1, px + k.radius + 1);
                    const float w = static_cast<float>(weight);
                    for (int64_t y = std::max<int64_t>(std::max(y0, fovY0), py - k.radius); y < std::min<int64_t>(std::min(y1, fovY1), py + k.radius + 1); ++y) {
                        float* __restrict row = nearImage.data() + static_cast<size_t>(y) * W + xa;
                        const float* __restrict krow = kv + static_cast<size_t>(y - py + k.radius) * side + (xa - px + k.radius);
                        for (int64_t x = 0; x < xb - xa; ++x) row[x] += w * krow[x];
                    }
                    // The far part: bilinear deposits at the four pixel centres around the node.
                    const double cu = double(qu) / F - 0.5, cv = double(qv) / F - 0.5;
                    const int64_t cx = static_cast<int64_t>(std::floor(cu)), cy = static_cast<int64_t>(std::floor(cv));
                    const double gx = cu - static_cast<double>(cx), gy = cv - static_cast<double>(cy);
                    for (int q = 0; q < 4; ++q) {
                        const int64_t x = cx + (q & 1), y = cy + ((q >> 1) & 1);
                        if (x < 0 || x >= W || y < y0 || y >= y1) continue;
                        farBins[static_cast<size_t>(bin)][static_cast<size_t>(y) * W + static_cast<size_t>(x)] += weight * ((q & 1) ? gx : 1 - gx) * ((q & 2) ? gy : 1 - gy);
                    }
                }
            }
        }
    });
    if (cancel && cancel->load()) {
        out.complete = false;
        return out;
    }
    const std::vector<double> farImage = m.far->convolveSum(farBins);
    for (int y = 0; y < plane.height(); ++y)
        for (int x = 0; x < plane.width(); ++x) {
            const size_t r = static_cast<size_t>(y + m.marginPixels) * W + static_cast<size_t>(x + m.marginPixels);
            // The FFT leaves round-off of both signs (about 1e-16 of the largest value) where the far part is 0.
            out.electrons[static_cast<size_t>(y) * plane.width() + x] = std::max(0.0, nearImage[r] + farImage[r]);
        }
    out.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    return out;
}

}  // namespace fluorosim::optics
