// Regression tests for defects found in review: each pins a corrected behaviour.
#include <gtest/gtest.h>

#include <cmath>

#include "materials/fresnel.h"
#include "render/film.h"
#include "render/slab_transport.h"
#include "support/test_scenes.h"

namespace fluorosim {
namespace {

TEST(ReviewRegressions, SlabGuidedPhotonsTerminate) {
    // A transparent emission band inside n = 1.4 traps re-emitted photons by total internal
    // reflection forever; they must be tallied as guided, not loop.
    SlabOptions o;
    o.mus = 1.0;
    o.muaDye = 0.5;
    o.quantumYield = 1.0;
    o.thickness = 1.0;
    o.n = 1.4;
    o.emission = SlabBand{0.0, 0.0, 0.0, 0.0};
    o.photons = 100000;
    const SlabResult r = simulateSlab(o);
    EXPECT_GT(r.guided, 0.05);
    EXPECT_NEAR(r.Rd + r.Tt + r.Rf + r.Tf + r.guided + r.Rsp, 1.0, 1e-12);
    EXPECT_NEAR(r.Ta, 0.0, 1e-12);
}

TEST(ReviewRegressions, ConductorWithZeroIndexIsFinite) {
    EXPECT_EQ(fresnelConductor(0.5, {0.0, 0.0}), 1.0);
    EXPECT_TRUE(std::isfinite(fresnelConductor(1e-9, {0.2, 3.0})));
}

TEST(ReviewRegressions, LineAtRangeMaximumLandsInLastBin) {
    const TabulatedSpectrum one({360, 830}, {1, 1});
    Film film(1, 1, 400, 700, 50, {one, one, one});
    film.addSample(0, 0, PathRadiance{SampledSpectrum(2.0), SampledSpectrum(0.0)}, SampledWavelengths::atLine(700.0, 1.0));
    const ExrImage img = film.image(1);
    const auto& v = img.spectral[0].values;
    EXPECT_NEAR(v.back() * 50.0, 2.0, 2e-7);  // per nm times the bin width = the line's value (stored as float)
}

TEST(ReviewRegressions, TinyBeadFarFromOriginIsCrossedExactly) {
    // A 1 um bead 100 mm from the origin: shadow rays and path-traced rays must enter and leave it.
    Scene scene;
    testing::addEnclosure(scene, 500, 1.0);
    const int ink = testing::addMedium(scene, "ink", 200.0, 0.0, 0.0, 1.0);
    const double r = 1e-3;
    testing::addInterfaceSphere(scene, Vec3(100, 0, 0), r, ink, kNone);
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

TEST(ReviewRegressions, ChromaticScatteringFurnace) {
    // Strongly wavelength-dependent scattering (no absorption): hero-wavelength MIS with analytic
    // shadow-ray transmittance must still return the field at every wavelength.
    Scene scene;
    testing::addEnclosure(scene, 20, 2.0);
    const Spectrum sigmaS = Spectrum::tabulated(TabulatedSpectrum({380, 500, 620, 720}, {8.0, 0.5, 3.0, 0.05}));
    scene.media.emplace_back("chromatic", Spectrum::constant(0.0), sigmaS, 0.6, 1.0);
    testing::addInterfaceSphere(scene, Vec3(0, 0, 0), 1.0, 0, kNone);
    scene.finalize();
    const auto e = testing::meanRadiance(scene, Vec3(0, 0, -8), kNone, Vec3(0, 0, 0), 1.0, 40000, 21, 380, 720);
    EXPECT_NEAR(e.mean, 2.0, 4 * e.stderr_) << "stderr " << e.stderr_;
    EXPECT_GT(e.stderr_, 0.0);
}

}  // namespace
}  // namespace fluorosim
