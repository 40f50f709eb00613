// walkPhoton's survival: Russian roulette below 1 and splitting above it leave every tally's expectation
// unchanged. A ball of scattering, absorbing tissue (index-matched, so photons cross its surface) with a
// photon source at its centre; each photon's tallies are the power it scatters inside a small target ball
// off-centre and the power that escapes. Three walks of the same photons: analog; roulette at half survival
// wherever the target is not (the scattered-emission photons' rule before their weight window), whose
// survivors double their power at every such vertex; and a weight window by importance (1 in the target,
// falling with the distance from it), which splits photons that come back heavy. Their means agree within
// 4 standard errors (fixed seeds); the window's heaviest tallied vertex is lighter than the roulette's.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <vector>

#include "core/rng.h"
#include "core/sampling.h"
#include "render/photon_tracer.h"
#include "support/test_scenes.h"

namespace fluorosim {
namespace {

using testing::addInterfaceSphere;
using testing::addMedium;
using testing::Estimate;
using testing::meanOf;

const Vec3 kTarget(0.5, 0, 0);
constexpr double kTargetRadius = 0.15;

enum class Walk { Analog, Roulette, Window };

// A photon of unit power at 500 nm leaving the centre in a uniform direction.
Photon photonFromCentre(Rng& rng, int medium) {
    Photon ph;
    ph.ray = Ray{Vec3(0, 0, 0), sampleUniformSphere(rng.uniform(), rng.uniform())};
    ph.medium = medium;
    ph.lambda = 500;
    ph.weight = 1;
    return ph;
}

struct Tallies final : PhotonEvents {
    Walk walk = Walk::Analog;
    double unitPower = 1;
    double target = 0, escapedPower = 0, heaviest = 0;
    int splits = 0;
    double beyondTarget(const Vec3& p) const { return std::max(0.0, length(p - kTarget) - kTargetRadius); }
    void scattered(const Photon& ph, const Vec3& p) override {
        if (beyondTarget(p) > 0) return;
        target += ph.weight;
        heaviest = std::max(heaviest, ph.weight);
    }
    void escaped(const Photon& ph) override { escapedPower += ph.weight; }
    double survival(const Photon& ph, const Vec3& p) override {
        const double d = beyondTarget(p);
        if (walk == Walk::Roulette) return d > 0 ? 0.5 : 1.0;
        if (walk == Walk::Analog) return 1.0;
        const double q = ph.weight * (d > 0 ? 0.5 / (1 + d / 0.1) : 1.0) / unitPower;
        if (q > 2) ++splits;
        return q < 0.5 || q > 2 ? q : 1.0;
    }
};

struct Result {
    Estimate target, escaped;
    double heaviest = 0;
    int splits = 0;
};

Result walkAll(Walk walk, int photons) {
    Scene scene;
    const int tissue = addMedium(scene, "tissue", 0.3, 8, 0.8, 1.0);
    addInterfaceSphere(scene, Vec3(0, 0, 0), 1.0, tissue, kNone);
    scene.finalize();
    Result r;
    std::vector<double> escaped(static_cast<size_t>(photons));
    r.target = meanOf(photons, [&](int i) {
        Rng rng = Rng::forKey(7, static_cast<uint64_t>(i), 11);
        Tallies t;
        t.walk = walk;
        const Photon ph = photonFromCentre(rng, tissue);
        // The source lies beyond the target: its unit power is its power over the importance there.
        t.unitPower = walk == Walk::Window ? 0.5 / (1 + t.beyondTarget(ph.ray.o) / 0.1) : 1.0;
        walkPhoton(scene, ph, rng, t, false);
        escaped[static_cast<size_t>(i)] = t.escapedPower;
        r.heaviest = std::max(r.heaviest, t.heaviest);
        r.splits += t.splits;
        return t.target;
    });
    r.escaped = meanOf(photons, [&](int i) { return escaped[static_cast<size_t>(i)]; });
    return r;
}

double z(const Estimate& a, const Estimate& b) { return (a.mean - b.mean) / std::hypot(a.stderr_, b.stderr_); }

TEST(PhotonWalk, RouletteAndSplittingLeaveTheTalliesUnbiased) {
    constexpr int kPhotons = 200000;
    const Result analog = walkAll(Walk::Analog, kPhotons), roulette = walkAll(Walk::Roulette, kPhotons), window = walkAll(Walk::Window, kPhotons);
    std::printf("target: analog %.5g ± %.2g, roulette %.5g ± %.2g (z %.2f), window %.5g ± %.2g (z %.2f)\n", analog.target.mean,
                analog.target.stderr_, roulette.target.mean, roulette.target.stderr_, z(roulette.target, analog.target), window.target.mean,
                window.target.stderr_, z(window.target, analog.target));
    std::printf("escaped: analog %.5g ± %.2g, roulette %.5g ± %.2g (z %.2f), window %.5g ± %.2g (z %.2f)\n", analog.escaped.mean,
                analog.escaped.stderr_, roulette.escaped.mean, roulette.escaped.stderr_, z(roulette.escaped, analog.escaped),
                window.escaped.mean, window.escaped.stderr_, z(window.escaped, analog.escaped));
    std::printf("heaviest tallied vertex: analog %.3g, roulette %.3g, window %.3g (%d splits)\n", analog.heaviest, roulette.heaviest, window.heaviest,
                window.splits);
    ASSERT_GT(analog.target.mean, 0);
    ASSERT_GT(window.splits, 0);  // the window splits photons, so the test covers copies
    EXPECT_LT(std::abs(z(roulette.target, analog.target)), 4);
    EXPECT_LT(std::abs(z(window.target, analog.target)), 4);
    EXPECT_LT(std::abs(z(roulette.escaped, analog.escaped)), 4);
    EXPECT_LT(std::abs(z(window.escaped, analog.escaped)), 4);
    EXPECT_LT(window.heaviest, roulette.heaviest);
}

// The power scattered in a slab |x - 0.5| < 0.05 through the ball, counted at the scatterings and along the
// flights (walkPhoton's `flew`: σs times each flight's length inside the slab, a track-length estimate of the
// same mean), by an analog walk and by the weight window's (copies walk flights of their own). They agree
// within 4 standard errors, and the flights' estimate has the smaller error: every photon that crosses the
// slab adds to it, not only the few that scatter there.
TEST(PhotonWalk, FlightsGiveTheScatteringsTrackLengthEstimate) {
    Scene scene;
    const int tissue = addMedium(scene, "tissue", 0.3, 8, 0.8, 1.0);
    addInterfaceSphere(scene, Vec3(0, 0, 0), 1.0, tissue, kNone);
    scene.finalize();
    constexpr double kSlabX = 0.5, kHalf = 0.05;
    struct Slab final : PhotonEvents {
        bool window = false;
        double atScatterings = 0, alongFlights = 0;
        int flights = 0;
        void scattered(const Photon& ph, const Vec3& p) override {
            if (std::abs(p.x - kSlabX) < kHalf) atScatterings += ph.weight;
        }
        void flew(const Photon& ph, double tEnd, double, const Medium& m, double sigmaS) override {
            ++flights;
            double a = 0, b = tEnd;
            if (ph.ray.d.x == 0) {
                if (!(std::abs(ph.ray.o.x - kSlabX) < kHalf)) return;
            } else {
                const double t1 = (kSlabX - kHalf - ph.ray.o.x) / ph.ray.d.x, t2 = (kSlabX + kHalf - ph.ray.o.x) / ph.ray.d.x;
                a = std::max(a, std::min(t1, t2));
                b = std::min(b, std::max(t1, t2));
            }
            if (!(b > a)) return;
            ChannelValues ch{};
            m.channelValues(ph.ray.at(0.5 * (a + b)), ch.data());
            alongFlights += ph.weight * sigmaS * ch[kScatteringChannel] * (b - a);
        }
        double survival(const Photon& ph, const Vec3& p) override {
            if (!window) return 1.0;
            const double q = ph.weight * (std::abs(p.x - kSlabX) < 0.2 ? 1.0 : 0.25);
            return q < 0.5 || q > 2 ? q : 1.0;
        }
    };
    constexpr int kPhotons = 100000;
    for (const bool window : {false, true}) {
        std::vector<double> atScatterings(kPhotons), alongFlights(kPhotons);
        int walked = 0;
        for (int i = 0; i < kPhotons; ++i) {
            Rng rng = Rng::forKey(9, static_cast<uint64_t>(i), 13);
            Slab t;
            t.window = window;
            walkPhoton(scene, photonFromCentre(rng, tissue), rng, t, false);
            atScatterings[static_cast<size_t>(i)] = t.atScatterings;
            alongFlights[static_cast<size_t>(i)] = t.alongFlights;
            walked += t.flights;
        }
        auto mean = [&](auto&& f) { return meanOf(kPhotons, [&](int i) { return f(static_cast<size_t>(i)); }); };
        const Estimate scatterings = mean([&](size_t i) { return atScatterings[i]; }), along = mean([&](size_t i) { return alongFlights[i]; });
        // The same photons give both: their difference photon by photon has its own error.
        const Estimate difference = mean([&](size_t i) { return alongFlights[i] - atScatterings[i]; });
        const double zd = difference.mean / difference.stderr_;
        std::printf("%s walk: at the scatterings %.5g ± %.2g, along the flights %.5g ± %.2g (difference z %.2f), %.1f flights a photon\n",
                    window ? "window" : "analog", scatterings.mean, scatterings.stderr_, along.mean, along.stderr_, zd, double(walked) / kPhotons);
        ASSERT_GT(scatterings.mean, 0);
        EXPECT_LT(std::abs(zd), 4);
        EXPECT_LT(along.stderr_, scatterings.stderr_);
    }
}

// A survival far above the copies' bound at every vertex: the photon goes on as at most 4096 copies in all
// (64 at a vertex), so the walk ends, and the escaped power stays finite.
TEST(PhotonWalk, SplittingIsBounded) {
    Scene scene;
    const int tissue = addMedium(scene, "tissue", 2, 2, 0, 1.0);
    addInterfaceSphere(scene, Vec3(0, 0, 0), 1.0, tissue, kNone);
    scene.finalize();
    struct Greedy final : PhotonEvents {
        double escapedPower = 0;
        long vertices = 0;
        void escaped(const Photon& ph) override { escapedPower += ph.weight; }
        void scattered(const Photon&, const Vec3&) override { ++vertices; }
        double survival(const Photon&, const Vec3&) override { return 1e9; }
    } greedy;
    Rng rng = Rng::forKey(3, 0, 0);
    Photon ph;
    ph.ray = Ray{Vec3(0, 0, 0), Vec3(1, 0, 0)};
    ph.medium = tissue;
    ph.lambda = 500;
    ph.weight = 1;
    walkPhoton(scene, ph, rng, greedy, false);
    EXPECT_TRUE(std::isfinite(greedy.escapedPower));
    EXPECT_GT(greedy.escapedPower, 0);
    // 4097 walks of at most a few dozen vertices each (optical radius 4).
    EXPECT_LT(greedy.vertices, 4097L * 200);
}

}  // namespace
}  // namespace fluorosim
