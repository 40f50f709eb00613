#include "optics/emission_gains.h"

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>

#include "core/errors.h"
#include "core/math.h"
#include "core/parallel.h"
#include "core/quadrature.h"
#include "render/beam_core.h"
#include "render/straight_line.h"

namespace fluorosim::optics {
namespace {

constexpr double kMm2PerM2 = 1e6;  // irradiance W/mm² -> W/m², as the light sampler converts it
constexpr double kUmPerMm = 1e3;

// Values on a coarse lattice of the stack frame, computed at the nodes that points need and trilinearly
// interpolated.
class CoarseLattice {
public:
    CoarseLattice(double x0, double y0, double z0, double x1, double y1, double z1, double step) : x0_(x0), y0_(y0), z0_(z0), step_(step) {
        const std::array<double, 3> extent{x1 - x0, y1 - y0, z1 - z0};
        for (int a = 0; a < 3; ++a) size_[a] = static_cast<int64_t>(std::ceil(extent[static_cast<size_t>(a)] / step)) + 2;
        needed_.assign(static_cast<size_t>(size_[0] * size_[1] * size_[2]), 0);
    }
    void require(double x, double y, double z) {
        const auto c = cell(x, y, z);
        for (int a = 0; a < 8; ++a) needed_[node(c[0] + (a & 1), c[1] + ((a >> 1) & 1), c[2] + ((a >> 2) & 1))] = 1;
    }
    template <class Value, class F>
    void compute(int threads, F&& f, std::vector<Value>& values, const std::atomic<bool>* cancel) const {
        std::vector<size_t> nodes;
        for (size_t n = 0; n < needed_.size(); ++n)
            if (needed_[n]) nodes.push_back(n);
        values.assign(needed_.size(), Value{});
        parallelFor(nodes.size(), threads, [&](size_t k) {
            if (cancel && cancel->load()) return;
            const size_t n = nodes[k];
            const int64_t i = static_cast<int64_t>(n % static_cast<size_t>(size_[0]));
            const int64_t j = static_cast<int64_t>((n / static_cast<size_t>(size_[0])) % static_cast<size_t>(size_[1]));
            const int64_t l = static_cast<int64_t>(n / static_cast<size_t>(size_[0] * size_[1]));
            values[n] = f(x0_ + static_cast<double>(i) * step_, y0_ + static_cast<double>(j) * step_, z0_ + static_cast<double>(l) * step_);
        });
    }
    template <class Value>
    Value interpolate(double x, double y, double z, const std::vector<Value>& values) const {
        const auto c = cell(x, y, z);
        const double fx = (x - x0_) / step_ - static_cast<double>(c[0]), fy = (y - y0_) / step_ - static_cast<double>(c[1]),
                     fz = (z - z0_) / step_ - static_cast<double>(c[2]);
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
    std::array<int64_t, 3> cell(double x, double y, double z) const {
        return {std::clamp<int64_t>(static_cast<int64_t>(std::floor((x - x0_) / step_)), 0, size_[0] - 2),
                std::clamp<int64_t>(static_cast<int64_t>(std::floor((y - y0_) / step_)), 0, size_[1] - 2),
                std::clamp<int64_t>(static_cast<int64_t>(std::floor((z - z0_) / step_)), 0, size_[2] - 2)};
    }
    size_t node(int64_t i, int64_t j, int64_t l) const { return static_cast<size_t>((l * size_[1] + j) * size_[0] + i); }

    double x0_, y0_, z0_, step_;
    std::array<int64_t, 3> size_{};
    std::vector<uint8_t> needed_;
};

}  // namespace

std::vector<LineSide> lineSides(const std::vector<Light>& lights) {
    std::vector<LineSide> out;
    const std::vector<BeamLine> lines = beamLines(lights);
    for (size_t l = 0; l < lines.size(); ++l)
        for (int s = 0; s < lines[l].profile->sides(); ++s) out.push_back({lines[l].profile, lines[l].lambdaNm, lines[l].weight, s, l});
    return out;
}

EmissionGains::EmissionGains(const Scene& scene, const EmissionLattice& lattice, const ChannelDyes& dyes, const std::vector<Light>& lights,
                             const Imaging& reference, const TransmittanceOptions& o, int threads, const std::atomic<bool>* cancel)
    : lattice_(lattice), dyes_(dyes) {
    const auto start = std::chrono::steady_clock::now();
    const std::vector<LineSide> sides = lineSides(lights);
    if (beamLines(lights).size() != dyes.lineLambda.size()) throw ConfigError("emission gains: the lights' beam lines differ from the channel's");
    sides_ = sides.size();
    const LatticeGeometry& g = lattice.geometry();
    const size_t n = lattice.size();
    const int slots = lattice.slots();

    auto beamTransmittance = [&](const Vec3& p, int medium, const LineSide& side) {
        if (!o.attenuation) return 1.0;
        const Vec3 back = -side.profile->direction(side.side);
        const StraightLine line =
            traceStraightLine(scene, Ray{p, back}, medium, 0.0, 2 * (scene.geometry.extent() + length(p)) + 1, LineSurfaces::UntilRefraction);
        if (line.end == LineEnd::Blocked) return 0.0;
        return quadratureTransmittance(scene, Ray{p, back}, line.segments, SampledWavelengths::atLine(side.lambdaNm, 1.0), o.quadratureVoxels)[0];
    };
    SampledWavelengths cameraWl;
    for (int j = 0; j < kNumWavelengths; ++j) {
        cameraWl.lambda[static_cast<size_t>(j)] = dyes.cameraLambda[static_cast<size_t>(j)];
        cameraWl.pdf[static_cast<size_t>(j)] = 1;
    }
    const QuadratureRule rings = gaussLegendre01(o.coneRings);
    // The mean over the cone of the transmittance from p (in `medium`) to the objective's front plane of the
    // reference plane: straight in each medium, bent and Fresnel-weighted at each refracting surface.
    auto cameraTransmittance = [&](const Vec3& p, int medium) {
        if (!o.attenuation) return SampledSpectrum(1.0);
        SampledSpectrum sum(0.0);
        for (size_t r = 0; r < rings.nodes.size(); ++r) {
            const double cosT = 1 - rings.nodes[r] * (1 - reference.cosMax());
            for (int a = 0; a < o.coneAzimuths; ++a) {
                const Vec3 w = reference.coneDirection(cosT, 2 * kPi * (a + 0.5) / o.coneAzimuths);
                const BentLine line = reference.collectionLine(scene, p, medium, w);
                if (line.open) sum += quadratureTransmittance(scene, line, cameraWl, o.quadratureVoxels) * (rings.weights[r] / o.coneAzimuths);
            }
        }
        return sum;
    };
    // The cone's rings in the immersion medium, bent from the sample's by Snell's law.
    const double bend = reference.psf().pupil().sampleIndex / scene.ior(scene.camera.medium);
    for (size_t r = 0; r < rings.nodes.size(); ++r) {
        const double cosT = 1 - rings.nodes[r] * (1 - reference.cosMax());
        coneCos_.push_back(bend == 1 ? cosT : std::sqrt(std::max(0.0, 1 - bend * bend * (1 - cosT * cosT))));
        coneWeight_.push_back(rings.weights[r]);
    }
    if (o.attenuation && scene.camera.medium != kNone && scene.media[static_cast<size_t>(scene.camera.medium)].isHomogeneous()) {
        const Medium& cam = scene.media[static_cast<size_t>(scene.camera.medium)];
        for (int j = 0; j < kNumWavelengths; ++j)
            cameraExtinction_[static_cast<size_t>(j)] = cam.absorptionAt(dyes.cameraLambda[static_cast<size_t>(j)]) +
                                                        cam.scatteringAt(dyes.cameraLambda[static_cast<size_t>(j)]);
    }

    // Grid media's points on the coarse lattice, homogeneous media's points exactly (their object, a bead
    // or a layer, is often thinner than the lattice and absorbs on its own).
    const double coarse = o.stepUm / kUmPerMm;
    const double zLow = g.zLow(), zHigh = zLow + g.stackLayers() * g.axialMm;
    CoarseLattice grid(g.xLeft(), -g.yTop(), zLow, -g.xLeft(), g.yTop(), zHigh, coarse);
    std::vector<size_t> exactPoints;
    for (size_t p = 0; p < n; ++p) {
        const LatticePoint& q = lattice.point(p);
        if (lattice.exact(p)) exactPoints.push_back(p);
        else grid.require(q.x, q.y, q.z);
    }
    nodes_ = grid.requiredNodes() + exactPoints.size();
    std::vector<std::vector<double>> beamGrid(sides.size());
    for (size_t s = 0; s < sides.size(); ++s)
        grid.compute<double>(
            threads,
            [&](double x, double y, double z) {
                const Vec3 p = g.world(x, y, z);
                return beamTransmittance(p, mediumAt(scene, p, g.axis), sides[s]);
            },
            beamGrid[s], cancel);
    std::vector<SampledSpectrum> cameraGrid;
    grid.compute<SampledSpectrum>(
        threads,
        [&](double x, double y, double z) {
            const Vec3 p = g.world(x, y, z);
            return cameraTransmittance(p, mediumAt(scene, p, g.axis));
        },
        cameraGrid, cancel);
    if (cancel && cancel->load()) {
        complete_ = false;
        return;
    }

    beamT_.assign(n * sides_, 0.0f);
    base_.assign(n * static_cast<size_t>(slots), 0.0f);
    const double exposureS = reference.sampleEtendue() / (reference.pixelMm() * reference.pixelMm() * 1e-6 * reference.coneSolidAngle());
    const double constant = exposureS * reference.coneSolidAngle() * 1e-6 * kInv4Pi;  // mm³ -> m³ with irradiance in W/m²
    std::vector<int64_t> exactIndex(n, -1);
    for (size_t k = 0; k < exactPoints.size(); ++k) exactIndex[exactPoints[k]] = static_cast<int64_t>(k);
    parallelFor(n, threads, [&](size_t p) {
        if (cancel && cancel->load()) return;
        const LatticePoint& q = lattice.point(p);
        SampledSpectrum cam;
        if (exactIndex[p] >= 0) {
            const Vec3 w = g.world(q.x, q.y, q.z);
            for (size_t s = 0; s < sides.size(); ++s) beamT_[p * sides_ + s] = static_cast<float>(beamTransmittance(w, q.medium, sides[s]));
            cam = cameraTransmittance(w, q.medium);
        } else {
            for (size_t s = 0; s < sides.size(); ++s) beamT_[p * sides_ + s] = static_cast<float>(grid.interpolate(q.x, q.y, q.z, beamGrid[s]));
            cam = grid.interpolate(q.x, q.y, q.z, cameraGrid);
        }
        for (int slot = 0; slot < slots; ++slot) {
            const EmittingDye* d = dyes.dyeOf(q.medium, slot);
            if (!d) continue;
            double camera = 0;
            for (int j = 0; j < kNumWavelengths; ++j) camera += d->cameraWeights[static_cast<size_t>(j)] * cam[j];
            base_[p * static_cast<size_t>(slots) + static_cast<size_t>(slot)] =
                static_cast<float>(constant * q.volumeMm3 * d->quantumYield * d->detected * camera);
        }
    });
    if (cancel && cancel->load()) complete_ = false;
    seconds_ = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

void EmissionGains::planeGains(const std::vector<Light>& lights, double planeOffsetMm, size_t first, size_t last, std::vector<double>& out,
                               int threads, const BeamExcitationField* field, FieldGains* fieldGains) const {
    const std::vector<LineSide> sides = lineSides(lights);
    if (sides.size() != sides_) throw ConfigError("emission gains: the plane's beams differ from the stack's");
    // Each side's field, if any.
    std::vector<int> fieldOf(sides.size(), -1);
    if (field)
        for (size_t s = 0; s < sides.size(); ++s)
            for (size_t f = 0; f < field->fields().size(); ++f) {
                const BeamLineSide& l = field->fields()[f].line;
                if (l.profile == sides[s].profile && l.side == sides[s].side && l.lambdaNm == sides[s].lambdaNm) fieldOf[s] = static_cast<int>(f);
            }
    if (fieldGains) {
        fieldGains->scattered.assign((last - first) * static_cast<size_t>(lattice_.slots()), 0.0);
        fieldGains->halfDifference.assign(fieldGains->scattered.size(), 0.0);
    }
    const LatticeGeometry& g = lattice_.geometry();
    const int slots = lattice_.slots();
    out.assign((last - first) * static_cast<size_t>(slots), 0.0);
    // The camera's longer (or shorter) path through a homogeneous immersion medium, per dye.
    std::vector<double> immersion(dyes_.dyes.size(), 1.0);
    for (size_t t = 0; t < dyes_.dyes.size(); ++t) {
        double f = 0;
        for (int j = 0; j < kNumWavelengths; ++j) {
            double mean = 0;
            for (size_t r = 0; r < coneCos_.size(); ++r)
                mean += coneWeight_[r] * std::exp(-cameraExtinction_[static_cast<size_t>(j)] * planeOffsetMm / coneCos_[r]);
            f += dyes_.dyes[t].cameraWeights[static_cast<size_t>(j)] * mean;
        }
        immersion[t] = f;
    }
    const size_t lines = dyes_.lineLambda.size();
    constexpr size_t kChunk = 4096;
    parallelFor((last - first + kChunk - 1) / kChunk, threads, [&](size_t chunk) {
        std::vector<double> excitation(lines), scattered(lines), difference(lines);
        for (size_t p = first + chunk * kChunk; p < std::min(last, first + (chunk + 1) * kChunk); ++p) {
            const LatticePoint& q = lattice_.point(p);
            const Vec3 w = g.world(q.x, q.y, q.z);
            std::fill(excitation.begin(), excitation.end(), 0.0);
            std::fill(scattered.begin(), scattered.end(), 0.0);
            std::fill(difference.begin(), difference.end(), 0.0);
            bool lit = false;
            for (size_t s = 0; s < sides.size(); ++s) {
                const LineSide& side = sides[s];
                if (!side.profile->inCore(w, side.side, side.lambdaNm)) continue;
                if (fieldOf[s] >= 0) {
                    const auto f = static_cast<size_t>(fieldOf[s]);
                    const auto phi = field->scatteredWithNoise(f, w);
                    if (phi.mean != 0) {
                        excitation[side.line] += phi.mean;
                        scattered[side.line] += phi.mean;
                        lit = true;
                        if (fieldGains) difference[side.line] += phi.halfDifference;
                    }
                }
                const double E = side.profile->irradiance(w, side.side, side.lambdaNm) * kMm2PerM2 * side.weight;
                if (!(E > 0)) continue;
                excitation[side.line] += E * static_cast<double>(beamT_[p * sides_ + s]);
                lit = true;
            }
            if (!lit) continue;
            for (int slot = 0; slot < slots; ++slot) {
                const double base = base_[p * static_cast<size_t>(slots) + static_cast<size_t>(slot)];
                if (!(base > 0)) continue;
                const int dyeIndex = dyes_.firstOfMedium[static_cast<size_t>(q.medium)] + slot;
                const EmittingDye& d = dyes_.dyes[static_cast<size_t>(dyeIndex)];
                auto absorbed = [&](const std::vector<double>& irradiance) {  // Σ_l E T σa(λ_l; 1 M) λ_l
                    double a = 0;
                    for (size_t l = 0; l < lines; ++l) a += irradiance[l] * d.absorptionPerMolar[l] * dyes_.lineLambda[l];
                    return a;
                };
                const double factor = base * immersion[static_cast<size_t>(dyeIndex)];
                const size_t at = (p - first) * static_cast<size_t>(slots) + static_cast<size_t>(slot);
                out[at] = factor * absorbed(excitation);
                if (fieldGains) {
                    fieldGains->scattered[at] = factor * absorbed(scattered);
                    fieldGains->halfDifference[at] = factor * absorbed(difference);
                }
            }
        }
    });
}

}  // namespace fluorosim::optics
