// Beer-Lambert attenuation through absorbing media against the closed form exp(-sigma_a d).
#include <gtest/gtest.h>

#include <cmath>

#include "render/slab_transport.h"
#include "support/test_scenes.h"

namespace fluorosim {
namespace {

using testing::addEnclosure;
using testing::addInterfaceSphere;
using testing::addMedium;

TEST(BeerLambert, ShadowRayTransmittanceIsExact) {
    Scene scene;
    addEnclosure(scene, 20, 1.0);
    const int m = addMedium(scene, "ink", 0.8, 0.0, 0.0, 1.0);
    addInterfaceSphere(scene, Vec3(0, 0, 0), 1.5, m, kNone);
    scene.finalize();
    const PathTracer tracer(scene);
    const SampledWavelengths wl = SampledWavelengths::sampleUniform(0.3, 400, 700);
    // Through the centre: 3 mm of ink. Off-centre chord at height h: 2 sqrt(r^2 - h^2).
    for (double h : {0.0, 0.5, 1.2}) {
        const double chord = 2 * std::sqrt(1.5 * 1.5 - h * h);
        Rng exactRng;  // unused: homogeneous transmittance is exact
        const SampledSpectrum T = tracer.transmittance(Vec3(-5, h, 0), Vec3(5, h, 0), kNone, wl, exactRng);
        for (int i = 0; i < kNumWavelengths; ++i) EXPECT_NEAR(T[i], std::exp(-0.8 * chord), 1e-9) << "h = " << h;
    }
}

TEST(BeerLambert, PathTracedRadianceThroughAbsorber) {
    // Free-flight sampling terminates paths at absorption (analog); the mean must be Le exp(-tau).
    Scene scene;
    const double Le = 3.0;
    addEnclosure(scene, 20, Le);
    const int m = addMedium(scene, "ink", 0.5, 0.0, 0.0, 1.0);
    addInterfaceSphere(scene, Vec3(0, 0, 0), 1.0, m, kNone);
    scene.finalize();
    const PathTracer tracer(scene);
    PathStats stats;
    const auto [mean, se] = testing::meanOf(200000, [&](int i) {
        Rng rng = Rng::forKey(5, static_cast<uint64_t>(i), 1);
        const SampledWavelengths wl = SampledWavelengths::sampleUniform(rng.uniform(), 400, 700);
        return tracer.radiance(Ray{Vec3(0, 0, -5), Vec3(0, 0, 1)}, kNone, wl, rng, stats).total().average();
    });
    EXPECT_NEAR(mean, Le * std::exp(-0.5 * 2.0), 4 * se) << "se " << se;
    EXPECT_LT(se, 0.01);
}

TEST(BeerLambert, SlabPureAbsorberMatchedBoundaries) {
    // Matched boundaries: Tt = exp(-mua d) exactly in expectation; Rd = 0 exactly.
    SlabOptions o;
    o.mua = 1.0;  // 1/mm
    o.thickness = 1.3;
    o.photons = 400000;
    o.seed = 3;
    const SlabResult r = simulateSlab(o);
    EXPECT_EQ(r.Rd, 0.0);
    EXPECT_NEAR(r.Tt, std::exp(-1.3), 4 * r.TtStderr);
    EXPECT_EQ(r.Tt, r.Tballistic);
}

// A 1 um bead 100 mm from the origin: shadow rays and path-traced rays must enter and leave it (found
// in review: an offset too large for the bead's size skipped it).
TEST(BeerLambert, TinyBeadFarFromOriginIsCrossedExactly) {
    Scene scene;
    addEnclosure(scene, 500, 1.0);
    const int ink = addMedium(scene, "ink", 200.0, 0.0, 0.0, 1.0);
    const double r = 1e-3;
    addInterfaceSphere(scene, Vec3(100, 0, 0), r, ink, kNone);
    scene.finalize();
    const PathTracer tracer(scene);
    const SampledWavelengths wl = SampledWavelengths::sampleUniform(0.1, 400, 700);
    Rng exactRng;  // unused: homogeneous transmittance is exact
    const SampledSpectrum T = tracer.transmittance(Vec3(100, 0, -1), Vec3(100, 0, 1), kNone, wl, exactRng);
    EXPECT_NEAR(T[0], std::exp(-200.0 * 2 * r), 1e-9);
    // Path tracing through the bead: every path must come out and reach the enclosure (no stuck medium).
    PathStats stats;
    const auto [mean, se] = testing::meanOf(20000, [&](int i) {
        Rng rng = Rng::forKey(3, static_cast<uint64_t>(i), 0);
        return tracer.radiance(Ray{Vec3(100, 0, -1), Vec3(0, 0, 1)}, kNone, wl, rng, stats).total().average();
    });
    EXPECT_NEAR(mean, std::exp(-0.4), 4 * se + 1e-12);
}

}  // namespace
}  // namespace fluorosim
