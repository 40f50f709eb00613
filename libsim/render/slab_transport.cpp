#include "render/slab_transport.h"

#include <chrono>
#include <algorithm>
#include <cmath>
#include <limits>
#include <mutex>
#include <string>
#include <vector>

#include "core/errors.h"
#include "core/math.h"
#include "core/parallel.h"
#include "core/rng.h"
#include "core/sampling.h"
#include "materials/fresnel.h"
#include "media/free_flight.h"
#include "media/henyey_greenstein.h"

namespace fluorosim {
namespace {

constexpr uint64_t kPhotonsPerChunk = 1 << 14;
// MCML's Russian roulette: below kWeightThreshold a photon survives with probability kSurvival.
constexpr double kWeightThreshold = 1e-4;
constexpr double kSurvival = 0.1;

struct Tally {
    double r = 0, r2 = 0, t = 0, t2 = 0, ballistic = 0;
    double rf = 0, rf2 = 0, tf = 0, tf2 = 0;
    double guided = 0;  // weight trapped by total internal reflection in a band without interactions
};

// Per-band constants of the collision step.
struct BandPhysics {
    HenyeyGreenstein phase;
    double mut;        // total extinction
    double survival;   // (mus + muaDye) / mut: weight kept by implicit capture of the other absorption
    double pDye;       // probability that a surviving collision is a dye absorption
    explicit BandPhysics(const SlabBand& b)
        : phase(b.g), mut(b.mua + b.mus + b.muaDye), survival(mut > 0 ? (b.mus + b.muaDye) / mut : 0.0),
          pDye(b.mus + b.muaDye > 0 ? b.muaDye / (b.mus + b.muaDye) : 0.0) {}
};

void requireFinite(const char* name, double v, bool allowZero) {
    if (!std::isfinite(v) || v < 0 || (!allowZero && v == 0))
        throw ConfigError(std::string("--") + name + ": must be finite and " + (allowZero ? "non-negative" : "positive") +
                          ", got " + std::to_string(v));
}

}  // namespace

void SlabOptions::validate() const {
    requireFinite("mua", mua, true);
    requireFinite("mus", mus, true);
    requireFinite("mua-dye", muaDye, true);
    requireFinite("thickness", thickness, false);
    if (!(g > -1 && g < 1)) throw ConfigError("--g: must lie in (-1, 1), got " + std::to_string(g));
    if (!(quantumYield >= 0 && quantumYield <= 1))
        throw ConfigError("--quantum-yield: must lie in [0, 1], got " + std::to_string(quantumYield));
    if (emission) {
        requireFinite("mua-emission", emission->mua, true);
        requireFinite("mus-emission", emission->mus, true);
        requireFinite("mua-dye-emission", emission->muaDye, true);
        if (!(emission->g > -1 && emission->g < 1))
            throw ConfigError("--g-emission: must lie in (-1, 1), got " + std::to_string(emission->g));
    }
    for (auto [name, v] : {std::pair{"n", n}, {"n-above", nAbove}, {"n-below", nBelow}})
        if (!std::isfinite(v) || v < 1.0 || v > 10.0)
            throw ConfigError(std::string("--") + name + ": refractive index must lie in [1, 10], got " + std::to_string(v));
    if (photons < 2) throw ConfigError("--photons: need at least 2 photons, got " + std::to_string(photons));
    if (photons > (uint64_t(1) << 40)) throw ConfigError("--photons: too many (" + std::to_string(photons) + ")");
    checkThreadCount(threads, "--threads");
}

SlabResult simulateSlab(const SlabOptions& opt, const std::function<void(uint64_t, uint64_t)>& progress) {
    opt.validate();
    const auto start = std::chrono::steady_clock::now();
    const BandPhysics bands[2] = {BandPhysics(opt.excitation()), BandPhysics(opt.emissionBand())};
    const double d = opt.thickness;
    const double rsp = sqr((opt.nAbove - opt.n) / (opt.nAbove + opt.n));

    const uint64_t chunks = (opt.photons + kPhotonsPerChunk - 1) / kPhotonsPerChunk;
    std::vector<Tally> tallies(chunks);
    std::mutex progressMutex;
    uint64_t done = 0;

    parallelFor(chunks, opt.threads, [&](size_t chunk) {
        Rng rng = Rng::forKey(opt.seed, chunk, 0x51ab);
        Tally tally;
        const uint64_t first = chunk * kPhotonsPerChunk;
        const uint64_t count = std::min<uint64_t>(kPhotonsPerChunk, opt.photons - first);
        for (uint64_t p = 0; p < count; ++p) {
            // The slab is laterally infinite and only Rd and Tt are tallied, so the state is the depth z and
            // the direction cosine uz; the azimuth enters only through cos(phi).
            double z = 0.0, uz = 1.0;
            double w = 1.0 - rsp;
            bool scattered = false;
            int band = 0;  // 0: excitation (elastic light), 1: emission (fluorescence)
            while (true) {
                const BandPhysics& b = bands[band];
                const double tBoundary = uz > 0 ? (d - z) / uz : uz < 0 ? -z / uz : std::numeric_limits<double>::infinity();
                double tCollision = -1;
                sampleTmaj<double>(HomogeneousMajorantIterator<double>(0.0, tBoundary, b.mut), rng,
                                   [&](double t, double, double) {
                                       tCollision = t;
                                       return false;
                                   });
                if (tCollision >= 0) {
                    z += uz * tCollision;
                    // Implicit capture of the non-dye absorption; then scattering or dye absorption,
                    // chosen in proportion to their coefficients.
                    w *= b.survival;
                    const bool dyeEvent = b.pDye > 0 && rng.uniform() < b.pDye;
                    if (dyeEvent) w *= opt.quantumYield;
                    if (w < kWeightThreshold) {
                        if (w == 0.0 || rng.uniform() >= kSurvival) break;
                        w /= kSurvival;
                    }
                    if (dyeEvent) {
                        // Isotropic re-emission into the emission band.
                        band = 1;
                        uz = 1.0 - 2.0 * rng.uniform();
                    } else {
                        const double cosTheta = b.phase.sampleCos(rng.uniform());
                        const double sinTheta = safeSqrt(1.0 - cosTheta * cosTheta);
                        uz = std::clamp(uz * cosTheta + safeSqrt(1.0 - uz * uz) * sinTheta * sampleCosUniformAzimuth(rng), -1.0, 1.0);
                    }
                    scattered = true;
                    continue;
                }
                z = uz > 0 ? d : 0.0;  // exactly on the boundary
                const double nOut = uz > 0 ? opt.nBelow : opt.nAbove;
                const double reflectance = fresnelDielectric(std::abs(uz), nOut / opt.n);
                if (reflectance >= 1.0 && b.mut == 0) {
                    // Nothing can change this photon's direction: it is guided to the slab's infinite edge.
                    tally.guided += w;
                    break;
                }
                if (reflectance > 0 && (reflectance >= 1.0 || rng.uniform() < reflectance)) {
                    uz = -uz;
                    continue;
                }
                double& sum = uz < 0 ? (band == 0 ? tally.r : tally.rf) : (band == 0 ? tally.t : tally.tf);
                double& sum2 = uz < 0 ? (band == 0 ? tally.r2 : tally.rf2) : (band == 0 ? tally.t2 : tally.tf2);
                sum += w;
                sum2 += w * w;
                if (uz > 0 && band == 0 && !scattered) tally.ballistic += w;
                break;
            }
        }
        tallies[chunk] = tally;
        if (progress) {
            std::lock_guard<std::mutex> lock(progressMutex);
            done += count;
            progress(done, opt.photons);
        }
    });

    Tally sum;
    for (const Tally& t : tallies) {
        sum.r += t.r;
        sum.r2 += t.r2;
        sum.t += t.t;
        sum.t2 += t.t2;
        sum.ballistic += t.ballistic;
        sum.rf += t.rf;
        sum.rf2 += t.rf2;
        sum.tf += t.tf;
        sum.tf2 += t.tf2;
        sum.guided += t.guided;
    }
    const double n = static_cast<double>(opt.photons);
    SlabResult res;
    res.photons = opt.photons;
    res.Rsp = rsp;
    res.Rd = sum.r / n;
    res.Tt = sum.t / n;
    res.Tballistic = sum.ballistic / n;
    auto stderrOf = [n](double s1, double s2) { return std::sqrt(std::max(0.0, s2 / n - (s1 / n) * (s1 / n)) / (n - 1)); };
    res.RdStderr = stderrOf(sum.r, sum.r2);
    res.TtStderr = stderrOf(sum.t, sum.t2);
    res.guided = sum.guided / n;
    res.Rf = sum.rf / n;
    res.Tf = sum.tf / n;
    res.RfStderr = stderrOf(sum.rf, sum.rf2);
    res.TfStderr = stderrOf(sum.tf, sum.tf2);
    res.Ta = 1.0 - rsp - res.Rd - res.Tt - res.Rf - res.Tf - res.guided;  // photons absorbed and not re-emitted (roulette is unbiased)
    res.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    return res;
}

}  // namespace fluorosim
