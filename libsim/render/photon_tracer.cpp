#include "render/photon_tracer.h"

#include <chrono>
#include <cmath>
#include <functional>
#include <limits>
#include <vector>

#include "core/errors.h"
#include "core/math.h"
#include "core/parallel.h"
#include "core/rng.h"
#include "core/sampling.h"
#include "materials/fresnel.h"
#include "render/weight_window.h"

namespace fluorosim {
namespace {

struct Tallies {
    Accumulator power, powerLambda, absorbed;
    std::vector<Accumulator> bins;
};

// The forward estimator's tallies: the first dye absorption of a light photon, and escaping fluorescence.
class EscapeTallies final : public PhotonEvents {
public:
    EscapeTallies(Tallies& t, const std::vector<double>& binEdges) : t_(t), edges_(binEdges) {}
    void absorbedByDye(const Photon& ph) override {
        if (!absorbedOnce_ && !ph.fluorescent) t_.absorbed.add(ph.weight);
        absorbedOnce_ = true;
    }
    void escaped(const Photon& ph) override {
        if (!ph.fluorescent) return;
        t_.power.add(ph.weight);
        t_.powerLambda.add(ph.weight * ph.lambda);
        for (size_t b = 0; b + 1 < edges_.size(); ++b)
            if (ph.lambda >= edges_[b] && ph.lambda < edges_[b + 1]) t_.bins[b].add(ph.weight);
    }

private:
    Tallies& t_;
    const std::vector<double>& edges_;
    bool absorbedOnce_ = false;
};

class ForwardTracer {
public:
    ForwardTracer(const Scene& scene, const ForwardPhotonOptions& o) : scene_(scene), o_(o) {
        for (const Light& l : scene.lights) {
            if (!std::holds_alternative<PointLight>(l)) throw ConfigError("the forward photon tracer supports point lights only");
            points_.push_back(&std::get<PointLight>(l));
        }
        if (points_.empty()) throw ConfigError("the forward photon tracer needs at least one point light");
    }

    void tracePhoton(Rng& rng, Tallies& t) const {
        const PointLight& light = *points_[std::min(points_.size() - 1, static_cast<size_t>(rng.uniform() * static_cast<double>(points_.size())))];
        Photon ph;
        ph.weight = static_cast<double>(points_.size()) *
                    sampleLightWavelength(light.intensity, scene_.spectral.lambdaMin, scene_.spectral.lambdaMax, rng, &ph.lambda);
        const Vec3 toAim = o_.aimCenter - light.position;
        const double dist = length(toAim);
        if (!(dist > o_.aimRadius)) throw ConfigError("a point light lies inside the aim ball of the forward photon tracer");
        const double sinMax = o_.aimRadius / dist, cosMax = std::sqrt(std::max(0.0, 1 - sinMax * sinMax));
        const double cosT = 1 - rng.uniform() * (1 - cosMax), phi = 2 * kPi * rng.uniform();
        const double sinT = std::sqrt(std::max(0.0, 1 - cosT * cosT));
        const Frame f = Frame::fromNormal(toAim / dist);
        ph.ray = Ray{light.position, f.toWorld(Vec3(sinT * std::cos(phi), sinT * std::sin(phi), cosT))};
        ph.weight *= 2 * kPi * (1 - cosMax);
        ph.medium = kNone;  // point lights must lie outside every medium
        if (ph.weight == 0) return;
        EscapeTallies tallies(t, o_.binEdgesNm);
        walkPhoton(scene_, ph, rng, tallies, false);
    }

private:
    const Scene& scene_;
    const ForwardPhotonOptions& o_;
    std::vector<const PointLight*> points_;
};

}  // namespace

double sampleLightWavelength(const Spectrum& s, double lambdaMin, double lambdaMax, Rng& rng, double* lambda) {
    const auto& lines = s.spectralLines();
    const bool continuous = s.hasContinuousPart();
    const double pLine = lines.empty() ? 0.0 : (continuous ? 0.5 : 1.0);
    if (rng.uniform() < pLine) {
        const size_t i = std::min(lines.size() - 1, static_cast<size_t>(rng.uniform() * static_cast<double>(lines.size())));
        *lambda = lines[i].lambdaNm;
        return lines[i].power * static_cast<double>(lines.size()) / pLine;
    }
    *lambda = lambdaMin + rng.uniform() * (lambdaMax - lambdaMin);
    return s(*lambda) * (lambdaMax - lambdaMin) / (1.0 - pLine);
}

namespace {

// After a scattering or a re-emission at p: the survival's copies (false ends the photon). The photon itself
// goes on as the first, with its power over q; each other one is left in `pending` to walk on from p in its
// own direction.
bool goOn(Photon& ph, const Vec3& p, Rng& rng, PhotonEvents& events, int& copiesLeft, std::vector<Photon>& pending,
          const std::function<Vec3()>& direction) {
    double q = events.survival(ph, p);
    const int copies = copiesGoingOn(q, copiesLeft, rng);
    if (copies == 0) return false;
    ph.weight /= q;
    for (int c = 1; c < copies; ++c) {
        Photon copy = ph;
        copy.ray = Ray{p, direction()};
        pending.push_back(copy);
    }
    return true;
}

void walkPhotonFrom(const Scene& scene, Photon ph, Rng& rng, PhotonEvents& events, bool scatterAtSurfaces, int& copiesLeft,
                    std::vector<Photon>& pending);

}  // namespace

void walkPhoton(const Scene& scene, Photon ph, Rng& rng, PhotonEvents& events, bool scatterAtSurfaces) {
    int copiesLeft = kMostCopiesOfAPhoton;
    std::vector<Photon> pending{ph};
    while (!pending.empty()) {
        const Photon next = pending.back();
        pending.pop_back();
        walkPhotonFrom(scene, next, rng, events, scatterAtSurfaces, copiesLeft, pending);
    }
}

namespace {

void walkPhotonFrom(const Scene& scene, Photon ph, Rng& rng, PhotonEvents& events, bool scatterAtSurfaces, int& copiesLeft,
                    std::vector<Photon>& pending) {
    // The medium's spectra at the photon's wavelength, looked up again only when either changes.
    const Medium* spectraOf = nullptr;
    double spectraAt = -1;
    MediumSpectra spec;
    for (int step = 0; step < 100000000; ++step) {
        const auto hit = scene.geometry.intersect(ph.ray, ph.tMin, std::numeric_limits<double>::infinity());
        ph.tMin = 0;
        if (ph.medium != kNone) {
            const Medium& m = scene.media[static_cast<size_t>(ph.medium)];
            // Analog delta tracking at the photon's one wavelength (exact sampling in a homogeneous medium).
            if (&m != spectraOf || ph.lambda != spectraAt) {
                spec = m.spectra(SampledWavelengths::atLine(ph.lambda, 1.0));
                spectraOf = &m;
                spectraAt = ph.lambda;
            }
            const double tHit = hit ? hit->t : std::numeric_limits<double>::infinity();
            ChannelValues ch{};
            double s = std::numeric_limits<double>::infinity();
            auto majorants = m.majorants(ph.ray, 0.0, tHit, [&](const double* mx) {
                const MediumSample c = spec.at(mx);
                return c.sigmaA + c.sigmaS;
            });
            sampleTmaj<SampledSpectrum>(majorants, rng, [&](double tCollision, const SampledSpectrum& sigmaMaj, const SampledSpectrum&) {
                m.channelValues(ph.ray.at(tCollision), ch.data());
                const MediumSample c = spec.at(ch.data());
                if (rng.uniform() * sigmaMaj[0] >= c.sigmaA[0] + c.sigmaS[0]) return true;  // null collision
                s = tCollision;
                return false;
            });
            if (std::isfinite(s) || hit) events.flew(ph, std::isfinite(s) ? s : tHit, tHit, m, spec.sigmaS[0]);
            if (std::isfinite(s)) {
                const MediumSample c = spec.at(ch.data());
                const double sa = c.sigmaA[0], ss = c.sigmaS[0], st = sa + ss;
                const Vec3 p = ph.ray.at(s);
                if (rng.uniform() * st < ss) {
                    ph.sigmaT = st;
                    events.scattered(ph, p);
                    ph.sigmaT = -1;
                    const Vec3 arrived = ph.ray.d;
                    auto scatteredDirection = [&] {
                        double pdf = 0;
                        return m.phase().sample(arrived, rng.uniform(), rng.uniform(), &pdf);
                    };
                    if (!goOn(ph, p, rng, events, copiesLeft, pending, scatteredDirection)) return;
                    ph.ray = Ray{p, scatteredDirection()};
                    continue;
                }
                // Absorbed: by which dye, if any?
                double u = rng.uniform() * sa;
                const Fluorophore* dye = nullptr;
                for (size_t i = 0; i < m.dyes().size(); ++i) {
                    const double a = dyeAbsorption(m.dyes()[i].dye, ph.lambda, ch[kFirstDyeChannel + i]);
                    if (u < a) {
                        dye = &m.dyes()[i].dye;
                        break;
                    }
                    u -= a;
                }
                if (!dye) return;  // solvent absorption
                events.absorbedByDye(ph);
                if (rng.uniform() >= dye->quantumYield()) return;
                // The new wavelength by the emission spectrum (rejection against its maximum), so that the
                // power changes only by the energy ratio and a cascade of re-emissions cannot grow it.
                const auto [lo, hi] = dye->emissionSupport();
                double lambdaNew = lo;
                do lambdaNew = lo + rng.uniform() * (hi - lo);
                while (rng.uniform() * dye->emissionPdfMax() > dye->emissionPdf(lambdaNew));
                ph.weight *= ph.lambda / lambdaNew;
                ph.lambda = lambdaNew;
                ph.fluorescent = true;
                ph.ray = Ray{p, sampleUniformSphere(rng.uniform(), rng.uniform())};
                if (ph.weight == 0) return;
                events.reemitted(ph, p);
                if (!goOn(ph, p, rng, events, copiesLeft, pending, [&] { return sampleUniformSphere(rng.uniform(), rng.uniform()); }))
                    return;
                continue;
            }
            if (!hit) return;  // lost in an unbounded medium
        }
        if (!hit) {
            events.escaped(ph);
            return;
        }
        const ShapeInfo& shape = scene.shapes[hit->shape];
        const bool entering = dot(ph.ray.d, hit->n) < 0;
        Vec3 dir = ph.ray.d;
        if (shape.material == kNone) {
            if (!shape.isInterface) return;  // emitters and absorbers
            ph.medium = entering ? shape.insideMedium : shape.outsideMedium;
        } else if (const Material& mat = *scene.materials[static_cast<size_t>(shape.material)];
                   shape.isInterface && mat.isSpecular() && mat.isTransmissive()) {
            const int next = entering ? shape.insideMedium : shape.outsideMedium;
            const double n1 = scene.ior(ph.medium), n2 = scene.ior(next);
            const Vec3 nFacing = entering ? hit->n : -hit->n;  // on the incident side
            const double cosI = -dot(ph.ray.d, nFacing);
            const double R = fresnelDielectric(cosI, n2 / n1);
            Vec3 wt;
            if (rng.uniform() < R || !refract(-ph.ray.d, nFacing, n2 / n1, &wt)) {
                dir = normalize(ph.ray.d + nFacing * (2 * cosI));
            } else {
                dir = wt;
                ph.medium = next;
            }
            if (const double q = events.specularSurvival(ph); q < 1) {
                if (!(rng.uniform() < q)) return;
                ph.weight /= q;
            }
        } else {
            if (!scatterAtSurfaces) return;
            // Opaque surfaces are two-sided; interfaces keep their outward orientation (as in the path tracer).
            const Vec3 n = shape.isInterface ? hit->n : faceForward(hit->n, -ph.ray.d);
            const double eta = scene.ior(shape.insideMedium) / scene.ior(shape.outsideMedium);
            const Frame frame = Frame::fromNormal(n);
            const Vec3 wo = frame.toLocal(-ph.ray.d);
            if (wo.z == 0) return;
            events.surfaceScattered(ph, *hit, n, mat, eta);
            const auto bs = mat.sample(wo, rng.uniform(), rng.uniform(), rng.uniform(), SampledWavelengths::atLine(ph.lambda, 1.0), eta,
                                       TransportMode::Importance);
            if (!bs || !(bs->pdf > 0)) return;
            const double factor = bs->f[0] * std::abs(bs->wi.z) / bs->pdf;
            const double survive = std::min(1.0, factor);
            if (!(survive > 0) || rng.uniform() >= survive) return;
            ph.weight *= factor / survive;
            dir = frame.toWorld(bs->wi);
            if (shape.isInterface && dot(dir, hit->n) * dot(ph.ray.d, hit->n) > 0) ph.medium = entering ? shape.insideMedium : shape.outsideMedium;
        }
        ph.ray = Ray{hit->p, dir};
        ph.tMin = hit->epsilon / std::max(std::abs(dot(hit->n, dir)), 1e-2);
    }
}

}  // namespace

void ForwardPhotonOptions::validate() const {
    if (photons == 0 || photons > (uint64_t(1) << 40)) throw ConfigError("photon count must lie in [1, 2^40], got " + std::to_string(photons));
    if (!(aimRadius > 0) || !std::isfinite(aimRadius)) throw ConfigError("aim radius must be positive, got " + std::to_string(aimRadius));
    for (size_t i = 1; i < binEdgesNm.size(); ++i)
        if (!(binEdgesNm[i] > binEdgesNm[i - 1])) throw ConfigError("spectral bin edges must increase");
}

ForwardPhotonResult traceForwardPhotons(const Scene& scene, const ForwardPhotonOptions& options) {
    options.validate();
    const auto start = std::chrono::steady_clock::now();
    const ForwardTracer tracer(scene, options);
    constexpr uint64_t kBatch = 4096;
    const uint64_t batches = (options.photons + kBatch - 1) / kBatch;
    std::vector<Tallies> perBatch(batches);
    parallelFor(batches, options.threads, [&](size_t b) {
        Tallies& t = perBatch[b];
        t.bins.resize(options.binEdgesNm.empty() ? 0 : options.binEdgesNm.size() - 1);
        const uint64_t end = std::min(options.photons, (b + 1) * kBatch);
        for (uint64_t i = b * kBatch; i < end; ++i) {
            Rng rng = Rng::forKey(options.seed, i, 0x70686f74);
            // Every photon adds exactly once to each accumulator (zeros included) so that the
            // per-photon variance is right.
            Tallies one;
            one.bins.resize(t.bins.size());
            tracer.tracePhoton(rng, one);
            t.power.add(one.power.sum);
            t.powerLambda.add(one.powerLambda.sum);
            t.absorbed.add(one.absorbed.sum);
            for (size_t k = 0; k < t.bins.size(); ++k) t.bins[k].add(one.bins[k].sum);
        }
    });
    Tallies total;
    total.bins.resize(perBatch.empty() ? 0 : perBatch[0].bins.size());
    for (const Tallies& t : perBatch) {
        total.power.merge(t.power);
        total.powerLambda.merge(t.powerLambda);
        total.absorbed.merge(t.absorbed);
        for (size_t k = 0; k < total.bins.size(); ++k) total.bins[k].merge(t.bins[k]);
    }
    const double n = static_cast<double>(options.photons);
    ForwardPhotonResult r;
    r.fluorescentPower = total.power.value(n);
    r.fluorescentPowerTimesLambda = total.powerLambda.value(n);
    r.absorbedPower = total.absorbed.value(n);
    for (const Accumulator& a : total.bins) r.binPower.push_back(a.value(n));
    r.photons = options.photons;
    r.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    return r;
}

}  // namespace fluorosim
