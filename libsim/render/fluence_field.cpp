#include "render/fluence_field.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <vector>

#include "core/errors.h"
#include "core/math.h"
#include "core/memory_cap.h"
#include "core/parallel.h"
#include "core/rng.h"
#include "materials/fresnel.h"
#include "media/free_flight.h"
#include "render/beam_core.h"
#include "render/weight_window.h"
#include "render/straight_line.h"
#include "scene/light_sampler.h"

namespace fluorosim {
namespace {

// The photons are split over this many slots, each traced in order into its own grid, so the sum does not
// depend on the thread count; even and odd slots make the two halves.
constexpr int kSlots = 8;
// How photons that wander from the field are handled depends on how far they fly between scatterings, by the
// largest extinction σt of the scene's media at the line:
// - σt <= kRouletteOpticalMargin / kRouletteMarginMm (4 /mm): a photon farther than kRouletteMarginMm from the
//   field's reach and heading away goes on with probability kRouletteSurvival. It seldom scatters before it
//   is far from the field, and seldom comes back.
// - σt >= kWindowOpticalMargin / kRouletteMarginMm (10 /mm, free flights under 100 µm): a weight window
//   (render/weight_window.h), by importance 1 out to kRouletteMarginMm beyond the reach and
//   1 / (1 + d / kRouletteMarginMm) at d beyond that. Photons that wander off (hundreds of scatterings before
//   they leave uncleared cortex) mostly die, and those that come back split into copies of their first power.
//   The roulette's fivefold weights there made the field spiky (the paths that looked it up doubled their
//   variance, 0.148 -> 0.252 of the camera's).
// - Between them, analog. Where flights are long the window's survivors of a far-upstream source cross the
//   field with their raised power before they can split: at σs 2 /mm it did worse than the roulette (two seed
//   pairs, 0.53 / 0.45 and 1.34 / 0.46 against 0.33 / 0.39 and 0.46 / 0.30), at σs 5 /mm eight fields' spread
//   grew from 1.5-2.5 % to 1.6-3.2 % of the field at the sheet against analog transport.
constexpr double kRouletteMarginMm = 0.05;
constexpr double kRouletteSurvival = 0.2;
constexpr double kRouletteOpticalMargin = 0.2;
constexpr double kWindowOpticalMargin = 0.5;

std::string number(double v) {
    char b[32];
    std::snprintf(b, sizeof b, "%g", v);
    return b;
}

// How far a line may run before it has surely left the scene.
double farDistance(const Scene& scene, const Vec3& p) { return 2 * (scene.geometry.extent() + length(p)) + 1; }

// Transmittance from y back along the beam (toward -d) to where the beam entered the sample: each
// medium's floor exactly and what rises above it (the dye) by ratio tracking, an unbiased estimate that
// is all a photon's weight needs (quadrature along the whole beam cost most of the field's time).
double beamTransmittanceAt(const Scene& scene, const Vec3& y, int medium, const Vec3& d, double lambdaNm, Rng& rng) {
    const Ray back{y, -d};
    const StraightLine line = traceStraightLine(scene, back, medium, 0.0, farDistance(scene, y), LineSurfaces::UntilRefraction);
    if (line.end == LineEnd::Blocked) return 0.0;
    const SampledWavelengths wl = SampledWavelengths::atLine(lambdaNm, 1.0);
    double T = 1;
    for (const RaySegment& seg : line.segments) {
        if (seg.medium == kNone) continue;
        const Medium& m = scene.media[static_cast<size_t>(seg.medium)];
        if (m.isVacuumLike()) continue;
        const MediumSpectra spec = m.spectra(wl);
        const ChannelValues& floor = m.channelFloor();
        const MediumSample f = spec.at(floor.data());
        T *= std::exp(-(f.sigmaA[0] + f.sigmaS[0]) * (seg.t1 - seg.t0));
        if (m.isHomogeneous() || !(T > 0)) continue;
        auto above = [&](const double* values) {
            ChannelValues v;
            for (int c = 0; c < spec.channels; ++c) v[c] = std::max(0.0, values[c] - floor[c]);
            const MediumSample s = spec.at(v.data());
            return s.sigmaA + s.sigmaS;
        };
        auto majorants = m.majorants(back, seg.t0, seg.t1, [&](const double* mx) { return above(mx); });
        ChannelValues ch{};
        sampleTmaj<SampledSpectrum>(majorants, rng, [&](double t, const SampledSpectrum& sigmaMaj, const SampledSpectrum&) {
            m.channelValues(back.at(t), ch.data());
            T *= std::max(0.0, 1 - above(ch.data())[0] / sigmaMaj[0]);
            return T > 0;
        });
    }
    return T;
}

// Where the beam's unscattered light first scatters, along its axis from where it enters the sample to
// where it leaves: pieces of the axis with the bound σs̄ of the medium's scattering and its floor extinction,
// drawn in proportion to σs̄ e^{-τ_floor}.
class AxisSource {
public:
    AxisSource(const Scene& scene, const BeamProfile& profile, int side, double lambdaNm) {
        const Vec3 d = profile.direction(side);
        origin_ = *profile.axisPoint();
        d_ = d;
        const int m0 = mediumAt(scene, origin_, -d);
        const double far = farDistance(scene, origin_);
        const StraightLine back = traceStraightLine(scene, Ray{origin_, -d}, m0, 0.0, far, LineSurfaces::UntilRefraction);
        const StraightLine ahead = traceStraightLine(scene, Ray{origin_, d}, m0, 0.0, far, LineSurfaces::UntilRefraction);
        const SampledWavelengths wl = SampledWavelengths::atLine(lambdaNm, 1.0);
        auto add = [&](double a0, double a1, int medium) {
            Piece p{a0, a1, 0, 0};
            if (medium != kNone && !scene.media[static_cast<size_t>(medium)].isVacuumLike()) {
                const Medium& m = scene.media[static_cast<size_t>(medium)];
                const MediumSpectra spec = m.spectra(wl);
                p.sigmaS = spec.at(m.channelMax().data()).sigmaS[0];
                const MediumSample floor = spec.at(m.channelFloor().data());
                p.sigmaT = floor.sigmaA[0] + floor.sigmaS[0];
            }
            if (a1 > a0) pieces_.push_back(p);
        };
        for (auto it = back.segments.rbegin(); it != back.segments.rend(); ++it) add(-it->t1, -it->t0, it->medium);
        for (const RaySegment& s : ahead.segments) add(s.t0, s.t1, s.medium);
        double tau = 0;
        for (Piece& p : pieces_) {
            p.tau0 = tau;
            const double len = p.a1 - p.a0;
            const double mass = p.sigmaT > 1e-12 ? p.sigmaS * std::exp(-tau) * -std::expm1(-p.sigmaT * len) / p.sigmaT : p.sigmaS * std::exp(-tau) * len;
            total_ += mass;
            cdf_.push_back(total_);
            tau += p.sigmaT * len;
        }
    }
    double total() const { return total_; }
    // A point of the axis and its density per mm.
    bool sample(double u, Vec3* p, double* pdf) const {
        if (!(total_ > 0)) return false;
        const double target = u * total_;
        const size_t i = std::min(cdf_.size() - 1, static_cast<size_t>(std::upper_bound(cdf_.begin(), cdf_.end(), target) - cdf_.begin()));
        const Piece& piece = pieces_[i];
        if (!(piece.sigmaS > 0)) return false;
        const double r = target - (i > 0 ? cdf_[i - 1] : 0.0);  // mass into the piece
        const double len = piece.a1 - piece.a0;
        double s = 0;
        if (piece.sigmaT > 1e-12) {
            const double x = r * piece.sigmaT * std::exp(piece.tau0) / piece.sigmaS;
            s = x < 1 ? -std::log1p(-x) / piece.sigmaT : len;
        } else {
            s = r * std::exp(piece.tau0) / piece.sigmaS;
        }
        s = std::clamp(s, 0.0, len);
        *p = origin_ + d_ * (piece.a0 + s);
        *pdf = piece.sigmaS * std::exp(-piece.tau0 - piece.sigmaT * s) / total_;
        return *pdf > 0;
    }

private:
    struct Piece {
        double a0, a1, sigmaS, sigmaT, tau0 = 0;
    };
    Vec3 origin_, d_;
    std::vector<Piece> pieces_;
    std::vector<double> cdf_;
    double total_ = 0;
};

// Narrows [t0, t1] to where the segment's coordinate, ua + t (ub − ua), lies in [lo, hi]; false when nothing is left.
bool clipToSlab(double ua, double ub, double lo, double hi, double& t0, double& t1) {
    if (std::abs(ub - ua) < 1e-300) return ua >= lo && ua <= hi && t1 > t0;
    double ta = (lo - ua) / (ub - ua), tb = (hi - ua) / (ub - ua);
    if (ta > tb) std::swap(ta, tb);
    t0 = std::max(t0, ta);
    t1 = std::min(t1, tb);
    return t1 > t0;
}

}  // namespace

bool FieldBox::contains(const Vec3& p) const {
    const Vec3 d = p - centre;
    return std::abs(dot(d, right)) <= halfX && std::abs(dot(d, up)) <= halfY && std::abs(dot(d, axis)) <= halfZ;
}

FieldBox FieldBox::far() const {
    if (!hasFar()) return *this;
    FieldBox b = *this;
    b.halfX = std::max(halfX, farHalfX);
    b.halfY = std::max(halfY, farHalfY);
    b.halfZ = std::max(halfZ, farHalfZ);
    b.hx = std::max(hx, farHxy);
    b.hy = std::max(hy, farHxy);
    b.hz = farHz;
    b.farHalfX = b.farHalfY = b.farHalfZ = 0;
    return b;
}

FieldBox FieldBox::diffuse() const {
    FieldBox b = far();
    b.hx = b.hy = b.hz = diffuseH;
    b.diffuseH = 0;
    return b;
}

void FieldBox::validate() const {
    auto positive = [](double v, const char* what) {
        if (!(v > 0) || !std::isfinite(v)) throw ConfigError(std::string("excitation field: ") + what + " must be positive and finite, got " + number(v));
    };
    positive(halfX, "half width");
    positive(halfY, "half height");
    positive(halfZ, "half depth");
    positive(hx, "node spacing along x");
    positive(hy, "node spacing along y");
    positive(hz, "node spacing along the axis");
    for (double v : {farHalfX, farHalfY, farHalfZ})
        if (!(v >= 0) || !std::isfinite(v)) throw ConfigError("excitation field: a far half extent must be >= 0 and finite, got " + number(v));
    if (!(diffuseH >= 0) || !std::isfinite(diffuseH)) throw ConfigError("excitation field: the diffuse node spacing must be >= 0 and finite, got " + number(diffuseH));
    if (hasFar()) {
        positive(farHz, "far node spacing along the axis");
        positive(farHxy, "far node spacing along the focal plane");
    }
}

FluenceGrid::FluenceGrid(const FieldBox& box) : box_(box) {
    box.validate();
    const std::array<double, 3> half{box.halfX, box.halfY, box.halfZ};
    h_ = {box.hx, box.hy, box.hz};
    double count = 1;
    for (int a = 0; a < 3; ++a) {
        const double n = std::ceil(2 * half[static_cast<size_t>(a)] / h_[static_cast<size_t>(a)] - 1e-9) + 3;
        if (!(n < 1e7)) throw ConfigError("excitation field: " + number(n) + " nodes along one axis (spacing " + number(h_[static_cast<size_t>(a)]) + " mm)");
        n_[static_cast<size_t>(a)] = static_cast<int>(n);
        origin_[static_cast<size_t>(a)] = -0.5 * (n - 1) * h_[static_cast<size_t>(a)];
        count *= n;
    }
    requireMemory(8.0 * count, "the excitation field's grid");
    values_.assign(static_cast<size_t>(count), 0.0);
}

void FluenceGrid::deposit(const Vec3& a, const Vec3& b, double weight) {
    if (!(weight != 0)) return;
    const double lengthMm = length(b - a);
    if (!(lengthMm > 0)) return;
    // Both ends in node coordinates.
    std::array<double, 3> u0{}, du{};
    const Vec3 da = a - box_.centre, db = b - box_.centre;
    const std::array<Vec3, 3> axes{box_.right, box_.up, box_.axis};
    for (size_t k = 0; k < 3; ++k) {
        u0[k] = (dot(da, axes[k]) - origin_[k]) / h_[k];
        du[k] = (dot(db, axes[k]) - origin_[k]) / h_[k] - u0[k];
    }
    // Clip to the tallied range [0, n - 1] on every axis.
    double t0 = 0, t1 = 1;
    for (size_t k = 0; k < 3; ++k)
        if (!clipToSlab(u0[k], u0[k] + du[k], 0, n_[k] - 1, t0, t1)) return;
    // Walk the node planes crossed in order (the next crossing on each axis), so that each piece lies in one cell.
    std::array<double, 3> plane{}, next{};
    for (size_t k = 0; k < 3; ++k) {
        next[k] = std::numeric_limits<double>::infinity();
        if (std::abs(du[k]) < 1e-300) continue;
        const double ua = u0[k] + t0 * du[k];
        plane[k] = du[k] > 0 ? std::floor(ua) + 1 : std::ceil(ua) - 1;
        next[k] = (plane[k] - u0[k]) / du[k];
    }
    static const double kGauss = 1 / std::sqrt(3.0);
    // A cell's eight nodes from its first, in index order (x fastest).
    const size_t sy = static_cast<size_t>(n_[0]), sz = sy * static_cast<size_t>(n_[1]);
    const std::array<size_t, 8> offset{0, 1, sy, sy + 1, sz, sz + 1, sz + sy, sz + sy + 1};
    for (double ta = t0;;) {
        const size_t k = next[0] <= next[1] ? (next[0] <= next[2] ? 0 : 2) : (next[1] <= next[2] ? 1 : 2);
        const double tb = std::min(next[k], t1);
        if (tb > ta) {
            const double mid = 0.5 * (ta + tb), half = 0.5 * (tb - ta);
            std::array<int, 3> cell{};
            for (size_t q = 0; q < 3; ++q) cell[q] = std::clamp(static_cast<int>(std::floor(u0[q] + mid * du[q])), 0, n_[q] - 2);
            // The corners' hat weights summed over both Gauss points, each point's share half × length.
            std::array<double, 8> corner{};
            for (double g : {-kGauss, kGauss}) {
                const double t = mid + g * half;
                std::array<double, 3> f{};
                for (size_t q = 0; q < 3; ++q) f[q] = std::clamp(u0[q] + t * du[q] - cell[q], 0.0, 1.0);
                const std::array<double, 4> xy{(1 - f[0]) * (1 - f[1]), f[0] * (1 - f[1]), (1 - f[0]) * f[1], f[0] * f[1]};
                for (size_t c = 0; c < 4; ++c) {
                    corner[c] += xy[c] * (1 - f[2]);
                    corner[c + 4] += xy[c] * f[2];
                }
            }
            const double w = weight * half * lengthMm;
            double* first = &values_[index(cell[0], cell[1], cell[2])];
            for (size_t c = 0; c < 8; ++c) first[offset[c]] += w * corner[c];
            ta = tb;
        }
        if (!(next[k] < t1)) break;
        plane[k] += du[k] > 0 ? 1 : -1;
        next[k] = (plane[k] - u0[k]) / du[k];
    }
}

std::optional<FluenceGrid::Stencil> FluenceGrid::stencil(const Vec3& p) const {
    if (!box_.contains(p)) return std::nullopt;
    const Vec3 d = p - box_.centre;
    const std::array<double, 3> l{dot(d, box_.right), dot(d, box_.up), dot(d, box_.axis)};
    std::array<int, 3> cell{};
    std::array<double, 3> f{};
    for (size_t k = 0; k < 3; ++k) {
        const double u = (l[k] - origin_[k]) / h_[k];
        cell[k] = std::clamp(static_cast<int>(std::floor(u)), 0, n_[k] - 2);
        f[k] = std::clamp(u - cell[k], 0.0, 1.0);
    }
    Stencil s;
    for (int c = 0; c < 8; ++c) {
        const double wx = c & 1 ? f[0] : 1 - f[0], wy = c & 2 ? f[1] : 1 - f[1], wz = c & 4 ? f[2] : 1 - f[2];
        s.weight[static_cast<size_t>(c)] = wx * wy * wz;
        s.node[static_cast<size_t>(c)] = index(cell[0] + (c & 1), cell[1] + ((c >> 1) & 1), cell[2] + ((c >> 2) & 1));
    }
    return s;
}

double FluenceGrid::at(const Vec3& p) const {
    const auto s = stencil(p);
    return s ? at(*s) : 0.0;
}

void FluenceGrid::normalise(double photons) {
    for (int k = 0; k < n_[2]; ++k)
        for (int j = 0; j < n_[1]; ++j)
            for (int i = 0; i < n_[0]; ++i) {
                // The hat's volume inside the tallied range: half along an axis at its first or last node.
                const double vx = h_[0] * (i == 0 || i == n_[0] - 1 ? 0.5 : 1.0), vy = h_[1] * (j == 0 || j == n_[1] - 1 ? 0.5 : 1.0),
                             vz = h_[2] * (k == 0 || k == n_[2] - 1 ? 0.5 : 1.0);
                values_[index(i, j, k)] /= photons * vx * vy * vz;
            }
}

void FluenceGrid::add(const FluenceGrid& o) {
    for (size_t i = 0; i < values_.size(); ++i) values_[i] += o.values_[i];
}

void FluenceGrid::scale(double s) {
    for (double& v : values_) v *= s;
}

BeamFluence pooledFluence(const BeamFluence& a, const BeamFluence& b) {
    if (b.stats.photons == 0) return a;
    if (a.stats.photons == 0) return b;
    if (a.mean.values().size() != b.mean.values().size()) throw std::logic_error("pooledFluence: fields over different boxes");
    const double wa = double(a.stats.photons) / double(a.stats.photons + b.stats.photons), wb = 1 - wa;
    BeamFluence out = a;
    auto pool = [&](FluenceGrid& into, const FluenceGrid& other) {
        FluenceGrid scaled = other;
        scaled.scale(wb);
        into.scale(wa);
        into.add(scaled);
    };
    pool(out.mean, b.mean);
    for (int k = 0; k < 2; ++k) pool(out.half[k], b.half[k]);
    if (out.far && b.far) pool(*out.far, *b.far);
    for (int k = 0; k < 2; ++k)
        if (out.farHalf[k] && b.farHalf[k]) pool(*out.farHalf[k], *b.farHalf[k]);
    if (out.diffuse && b.diffuse) pool(*out.diffuse, *b.diffuse);
    for (int k = 0; k < 2; ++k)
        if (out.diffuseHalf[k] && b.diffuseHalf[k]) pool(*out.diffuseHalf[k], *b.diffuseHalf[k]);
    out.stats.photons += b.stats.photons;
    out.stats.sourced += b.stats.sourced;
    out.stats.truncated += b.stats.truncated;
    out.stats.sourcePowerW = wa * a.stats.sourcePowerW + wb * b.stats.sourcePowerW;
    out.stats.seconds += b.stats.seconds;
    out.stats.complete = a.stats.complete && b.stats.complete;
    return out;
}

std::vector<BeamLineSide> beamLineSides(const std::vector<Light>& lights) {
    if (!std::all_of(lights.begin(), lights.end(), [](const Light& l) { return std::holds_alternative<BeamLight>(l); })) return {};
    std::vector<BeamLineSide> out;
    for (const BeamLine& l : beamLines(lights))
        if (l.weight > 0)
            for (int s = 0; s < l.profile->sides(); ++s) out.push_back({l.profile, l.lambdaNm, l.weight, s});
    return out;
}

double largestExtinctionAt(const Scene& scene, double lambdaNm) {
    const SampledWavelengths wl = SampledWavelengths::atLine(lambdaNm, 1.0);
    double most = 0;
    for (const Medium& m : scene.media)
        if (!m.isVacuumLike()) {
            const MediumSample c = m.spectra(wl).at(m.channelMax().data());
            most = std::max(most, c.sigmaA[0] + c.sigmaS[0]);
        }
    return most;
}

void FluenceOptions::validate() const {
    if (photons < 2 || photons > (uint64_t(1) << 40)) throw ConfigError("excitation field: photons must lie in [2, 2^40], got " + std::to_string(photons));
    if (threads < 0) throw ConfigError("excitation field: threads must be >= 0, got " + std::to_string(threads));
    if (maxEvents < 1) throw ConfigError("excitation field: maxEvents must be at least 1, got " + std::to_string(maxEvents));
}

BeamFluence traceBeamFluence(const Scene& scene, const BeamLineSide& line, const FieldBox& box, const FluenceOptions& options,
                             const std::atomic<bool>* cancel) {
    options.validate();
    const auto start = std::chrono::steady_clock::now();
    const BeamProfile& profile = *line.profile;
    if (!profile.axisPoint()) throw ConfigError("excitation field: the beam has no cross-section sampler");
    const Vec3 d = profile.direction(line.side);
    const double lambda = line.lambdaNm;
    const SampledWavelengths wl = SampledWavelengths::atLine(lambda, 1.0);
    const AxisSource axis(scene, profile, line.side, lambda);
    const FluenceGrid empty(box);
    const FieldBox reach = box.far();
    const std::optional<FluenceGrid> emptyFar = box.hasFar() ? std::optional<FluenceGrid>(FluenceGrid(reach)) : std::nullopt;
    const std::optional<FluenceGrid> emptyDiffuse = box.diffuseH > 0 ? std::optional<FluenceGrid>(FluenceGrid(box.diffuse())) : std::nullopt;
    requireMemory(8.0 * static_cast<double>(empty.nodes() + (emptyFar ? emptyFar->nodes() : 0) + (emptyDiffuse ? emptyDiffuse->nodes() : 0)) * (kSlots + 3),
                  "the excitation field's grids");
    std::vector<FluenceGrid> slots(kSlots, empty);
    std::vector<std::optional<FluenceGrid>> farSlots(kSlots, emptyFar), diffuseSlots(kSlots, emptyDiffuse);
    struct SlotStats {
        uint64_t sourced = 0, truncated = 0;
        double source = 0;
    };
    std::vector<SlotStats> slotStats(kSlots);
    const double boxReach = length(Vec3(reach.halfX, reach.halfY, reach.halfZ));
    const uint64_t seedKey = 0x666c75656e6365ULL ^ static_cast<uint64_t>(std::llround(lambda * 1000)) ^ (static_cast<uint64_t>(line.side) << 40);

    // The far grid is read only beyond the fine box, where its nodes' hats reach at most two far nodes into
    // it: a segment's piece deeper inside is left out of it (most of the tracks near the sheet lie there).
    const std::array<Vec3, 3> frame{box.axis, box.right, box.up};
    const std::array<double, 3> skip{box.halfZ - 2 * reach.hz, box.halfX - 2 * reach.hx, box.halfY - 2 * reach.hy};
    auto depositFar = [&](FluenceGrid& far, const Vec3& a, const Vec3& b, double w) {
        double t0 = 0, t1 = 1;  // the piece inside the skipped box
        bool inside = true;
        for (size_t k = 0; k < 3 && inside; ++k)
            inside = skip[k] > 0 && clipToSlab(dot(a - box.centre, frame[k]), dot(b - box.centre, frame[k]), -skip[k], skip[k], t0, t1);
        if (!inside) {
            far.deposit(a, b, w);
            return;
        }
        if (t0 > 0) far.deposit(a, a + (b - a) * t0, w);
        if (t1 < 1) far.deposit(a + (b - a) * t1, b, w);
    };
    const double opticalMargin = largestExtinctionAt(scene, lambda) * kRouletteMarginMm;
    const bool roulette = opticalMargin <= kRouletteOpticalMargin, window = opticalMargin >= kWindowOpticalMargin;
    // How far p lies outside the reach.
    auto outsideReach = [&](const Vec3& p) {
        const Vec3 r = p - reach.centre;
        const double ox = std::max(0.0, std::abs(dot(r, reach.right)) - reach.halfX), oy = std::max(0.0, std::abs(dot(r, reach.up)) - reach.halfY),
                     oz = std::max(0.0, std::abs(dot(r, reach.axis)) - reach.halfZ);
        return std::sqrt(ox * ox + oy * oy + oz * oz);
    };
    auto importance = [&](const Vec3& p) {
        const double beyond = outsideReach(p) - kRouletteMarginMm;
        return beyond > 0 ? 1 / (1 + beyond / kRouletteMarginMm) : 1.0;
    };
    // The roulette: a photon beyond kRouletteMarginMm of the reach, heading away from it, goes on with
    // probability kRouletteSurvival (false: it ends).
    auto rouletteAway = [&](const Vec3& p, const Vec3& dir, double& weight, Rng& rng) {
        if (outsideReach(p) <= kRouletteMarginMm || dot(dir, p - reach.centre) < 0) return true;
        if (rng.uniform() >= kRouletteSurvival) return false;
        weight /= kRouletteSurvival;
        return true;
    };
    auto tracePhoton = [&](uint64_t index, FluenceGrid& grid, std::optional<FluenceGrid>& farGrid, std::optional<FluenceGrid>& diffuseGrid,
                           SlotStats& st) {
        Rng rng = Rng::forKey(options.seed, index, seedKey);
        Vec3 onAxis;
        double pdfAxis = 0;
        if (!axis.sample(rng.uniform(), &onAxis, &pdfAxis)) return;
        const double u1 = rng.uniform(), u2 = rng.uniform();
        const auto cross = profile.sampleCrossSection(onAxis, line.side, lambda, u1, u2);
        if (!cross || !(cross->pdf > 0)) return;
        const Vec3 y = cross->p;
        const int sourceMedium = mediumAt(scene, y, -d);
        if (sourceMedium == kNone) return;
        const Medium& source = scene.media[static_cast<size_t>(sourceMedium)];
        if (source.isVacuumLike()) return;
        ChannelValues ch{};
        source.channelValues(y, ch.data());
        const double sigmaS = source.scatteringAt(lambda) * ch[kScatteringChannel];
        if (!(sigmaS > 0)) return;
        const double E = profile.irradiance(y, line.side, lambda);
        if (!(E > 0)) return;
        const double T = beamTransmittanceAt(scene, y, sourceMedium, d, lambda, rng);
        if (!(T > 0)) return;
        const double sourcePower = sigmaS * E * T * kMm2PerM2 * line.weight / (pdfAxis * cross->pdf);
        if (!(sourcePower > 0) || !std::isfinite(sourcePower)) return;
        ++st.sourced;
        st.source += sourcePower;
        // The photon, and the copies the window splits it into, each walked in turn.
        struct Walker {
            Ray ray;
            int medium;
            double weight, tMin;
            int scatterings = 0;
        };
        double pdf = 0;
        std::vector<Walker> pending{{Ray{y, source.phase().sample(d, rng.uniform(), rng.uniform(), &pdf)}, sourceMedium, sourcePower, 0.0}};
        if (roulette && !rouletteAway(y, pending.front().ray.d, pending.front().weight, rng)) return;
        // The window's unit is the photon's power at its source, wherever that is: photons that leave the beam
        // far from the field mostly die at their first scattering, and those that reach the field split into
        // copies within 2× of it.
        const double unitPower = sourcePower;
        int copiesLeft = kMostCopiesOfAPhoton;
        auto walk = [&](Walker w) {
            Ray& ray = w.ray;
            double& weight = w.weight;
            double& tMin = w.tMin;
            int medium = w.medium;
            int& scatterings = w.scatterings;
            const Medium* med = &scene.media[static_cast<size_t>(medium)];
            for (int events = 0;; ++events) {
                if (events >= options.maxEvents) {
                    ++st.truncated;
                    return;
                }
                const auto hit = scene.geometry.intersect(ray, tMin, std::numeric_limits<double>::infinity());
                tMin = 0;
                double end = hit ? hit->t : length(ray.o - box.centre) + 2 * boxReach;
                bool collided = false;
                if (!med->isVacuumLike()) {
                    // Analog delta tracking at the line.
                    const MediumSpectra spec = med->spectra(wl);
                    auto majorants = med->majorants(ray, 0.0, hit ? hit->t : std::numeric_limits<double>::infinity(), [&](const double* mx) {
                        const MediumSample c = spec.at(mx);
                        return c.sigmaA + c.sigmaS;
                    });
                    double s = std::numeric_limits<double>::infinity();
                    sampleTmaj<SampledSpectrum>(majorants, rng, [&](double t, const SampledSpectrum& sigmaMaj, const SampledSpectrum&) {
                        med->channelValues(ray.at(t), ch.data());
                        const MediumSample c = spec.at(ch.data());
                        if (rng.uniform() * sigmaMaj[0] >= c.sigmaA[0] + c.sigmaS[0]) return true;
                        s = t;
                        return false;
                    });
                    if (std::isfinite(s)) {
                        end = s;
                        collided = true;
                    }
                }
                if (diffuseGrid && scatterings >= kDiffuseAfterScatterings) {
                    diffuseGrid->deposit(ray.o, ray.at(end), weight);
                } else {
                    grid.deposit(ray.o, ray.at(end), weight);
                    if (farGrid) depositFar(*farGrid, ray.o, ray.at(end), weight);
                }
                if (collided) {
                    const Vec3 p = ray.at(end);
                    const MediumSample c = med->spectra(wl).at(ch.data());
                    if (!(rng.uniform() * (c.sigmaA[0] + c.sigmaS[0]) < c.sigmaS[0])) return;  // absorbed
                    ++scatterings;
                    const Vec3 arrived = ray.d;
                    auto direction = [&] { return med->phase().sample(arrived, rng.uniform(), rng.uniform(), &pdf); };
                    if (!window) {
                        ray = Ray{p, direction()};
                        if (roulette && !rouletteAway(p, ray.d, weight, rng)) return;
                        continue;
                    }
                    double q = weightWindowSurvival(weight, importance(p), unitPower);
                    const int copies = copiesGoingOn(q, copiesLeft, rng);
                    if (copies == 0) return;
                    weight /= q;
                    for (int k = 1; k < copies; ++k) pending.push_back({Ray{p, direction()}, medium, weight, 0.0, scatterings});
                    ray = Ray{p, direction()};
                    continue;
                }
                if (!hit) return;  // left the scene
                const ShapeInfo& shape = scene.shapes[hit->shape];
                if (!shape.isInterface) return;  // opaque surfaces absorb
                const bool entering = dot(ray.d, hit->n) < 0;
                const int next = entering ? shape.insideMedium : shape.outsideMedium;
                Vec3 dir = ray.d;
                if (shape.material != kNone) {
                    const Material& mat = *scene.materials[static_cast<size_t>(shape.material)];
                    if (!(mat.isSpecular() && mat.isTransmissive())) return;  // only smooth dielectrics are modelled
                    const double n1 = scene.ior(medium), n2 = scene.ior(next);
                    const Vec3 nFacing = entering ? hit->n : -hit->n;
                    const double cosI = -dot(ray.d, nFacing);
                    Vec3 wt;
                    if (rng.uniform() < fresnelDielectric(cosI, n2 / n1) || !refract(-ray.d, nFacing, n2 / n1, &wt)) {
                        dir = normalize(ray.d + nFacing * (2 * cosI));
                        ray = Ray{hit->p, dir};
                        tMin = hit->epsilon / std::max(std::abs(dot(hit->n, dir)), 1e-2);
                        continue;
                    }
                    dir = wt;
                }
                medium = next;
                if (medium == kNone) return;
                med = &scene.media[static_cast<size_t>(medium)];
                ray = Ray{hit->p, dir};
                tMin = hit->epsilon / std::max(std::abs(dot(hit->n, dir)), 1e-2);
            }
        };
        while (!pending.empty()) {
            const Walker next = pending.back();
            pending.pop_back();
            walk(next);
        }
    };

    std::atomic<bool> stopped{false};
    parallelFor(kSlots, options.threads, [&](size_t slot) {
        for (uint64_t i = slot, n = 0; i < options.photons; i += kSlots, ++n) {
            if (cancel && (n & 1023) == 0 && cancel->load()) {
                stopped = true;
                return;
            }
            tracePhoton(i, slots[slot], farSlots[slot], diffuseSlots[slot], slotStats[slot]);
        }
    });

    BeamFluence out{line, {empty, empty}, empty, {}};
    out.stats.photons = options.photons;
    for (int s = 0; s < kSlots; ++s) {
        out.half[s % 2].add(slots[static_cast<size_t>(s)]);
        out.stats.sourced += slotStats[static_cast<size_t>(s)].sourced;
        out.stats.truncated += slotStats[static_cast<size_t>(s)].truncated;
        out.stats.sourcePowerW += slotStats[static_cast<size_t>(s)].source;
    }
    out.stats.sourcePowerW /= static_cast<double>(options.photons);
    for (int h = 0; h < 2; ++h) out.half[h].normalise(static_cast<double>((options.photons + 1 - static_cast<uint64_t>(h)) / 2));
    out.mean.add(out.half[0]);
    out.mean.add(out.half[1]);
    out.mean.scale(0.5);
    // A grid's halves (even and odd slots) normalised, and their mean.
    auto halvesAndMean = [&](const std::optional<FluenceGrid>& zero, const std::vector<std::optional<FluenceGrid>>& perSlot,
                             std::optional<FluenceGrid> (&halves)[2], std::optional<FluenceGrid>& mean) {
        if (!zero) return;
        for (int h = 0; h < 2; ++h) {
            halves[h] = zero;
            for (size_t s = static_cast<size_t>(h); s < perSlot.size(); s += 2) halves[h]->add(*perSlot[s]);
            halves[h]->normalise(static_cast<double>((options.photons + 1 - static_cast<uint64_t>(h)) / 2));
        }
        mean = zero;
        mean->add(*halves[0]);
        mean->add(*halves[1]);
        mean->scale(0.5);
    };
    halvesAndMean(emptyFar, farSlots, out.farHalf, out.far);
    halvesAndMean(emptyDiffuse, diffuseSlots, out.diffuseHalf, out.diffuse);
    out.stats.complete = !stopped;
    out.stats.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    return out;
}

double BeamFluence::at(const Vec3& y) const {
    const double spread = diffuse ? diffuse->at(y) : 0.0;
    if (mean.box().contains(y) || !far) return mean.at(y) + spread;
    return far->at(y) + spread;
}

BeamFluence::MeanAndHalfDifference BeamFluence::withNoiseAt(const Vec3& y) const {
    MeanAndHalfDifference out;
    auto read = [&](const FluenceGrid& m, const FluenceGrid& h0, const FluenceGrid& h1) {
        if (const auto s = m.stencil(y)) {
            out.mean += m.at(*s);
            out.halfDifference += 0.5 * (h0.at(*s) - h1.at(*s));
        }
    };
    if (mean.box().contains(y) || !far)
        read(mean, half[0], half[1]);
    else
        read(*far, *farHalf[0], *farHalf[1]);
    if (diffuse) read(*diffuse, *diffuseHalf[0], *diffuseHalf[1]);
    return out;
}

bool BeamExcitationField::contains(const Vec3& y) const {
    if (fields_.empty()) return false;
    for (const BeamFluence& f : fields_)
        if (!f.reach().contains(y)) return false;
    return true;
}

BeamExcitationField::MeanAndHalfDifference BeamExcitationField::scatteredWithNoise(size_t i, const Vec3& y) const {
    const BeamFluence& f = fields_.at(i);
    return f.mean.box().contains(y) ? f.withNoiseAt(y) : MeanAndHalfDifference{};
}

std::optional<double> BeamExcitationField::scatteredMeanRadiance(const Vec3& y, double lambdaNm, double coreWeight, double outsideWeight) const {
    if (!contains(y)) return std::nullopt;
    double total = 0;
    for (const BeamFluence& f : fields_) {
        if (f.line.lambdaNm != lambdaNm) continue;
        const double w = f.line.profile->inCore(y, f.line.side, lambdaNm) ? coreWeight : outsideWeight;
        if (w > 0) total += w * f.at(y);
    }
    return total * kInv4Pi;
}

std::optional<BeamExcitationField::CoreAndOutside> BeamExcitationField::scatteredByCore(const Vec3& y, double lambdaNm) const {
    if (!contains(y)) return std::nullopt;
    CoreAndOutside out;
    for (const BeamFluence& f : fields_) {
        if (f.line.lambdaNm != lambdaNm) continue;
        MeanAndHalfDifference& into = f.line.profile->inCore(y, f.line.side, lambdaNm) ? out.core : out.outside;
        const MeanAndHalfDifference v = f.withNoiseAt(y);
        into.mean += v.mean * kInv4Pi;
        into.halfDifference += v.halfDifference * kInv4Pi;
    }
    return out;
}


}  // namespace fluorosim
