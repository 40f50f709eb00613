// The path tracer's fluorescence (camera paths with excitation sub-paths, i.e. adjoint weights)
// against an independent forward photon tracer, on dyed balls from optically thin to optical depth
// 100, with refraction, two overlapping dyes, a continuous light and re-absorption. Both estimate
// the fluorescent power leaving the ball; they must agree within 4 combined standard errors, in
// total and per spectral band.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>

#include "render/flux_sensor.h"
#include "render/photon_tracer.h"
#include "support/fluorescent_scenes.h"

namespace fluorosim {
namespace {

using namespace testing;

struct Comparison {
    FluxSensorResult backward;
    ForwardPhotonResult forward;
};

Comparison compare(const Scene& scene, double radius, uint64_t paths, uint64_t photons, const std::vector<double>& bins) {
    FluxSensorOptions s;
    s.radius = radius * 1.0001;
    s.paths = paths;
    s.seed = 11;
    s.binEdgesNm = bins;
    ForwardPhotonOptions f;
    f.aimRadius = radius * 1.0001;
    f.photons = photons;
    f.seed = 12;
    f.binEdgesNm = bins;
    Comparison c{measureExitantFlux(scene, s), traceForwardPhotons(scene, f)};
    return c;
}

// `sharpness`: the largest combined standard error, relative to the value, that still makes the
// comparison meaningful.
void expectAgree(const TallyValue& a, const TallyValue& b, const char* what, double sharpness) {
    const double sigma = std::hypot(a.stderr_, b.stderr_);
    const double z = (a.mean - b.mean) / sigma;
    std::printf("  %-28s path tracer %.6g +- %.2g, forward %.6g +- %.2g, z = %+.2f\n", what, a.mean, a.stderr_, b.mean, b.stderr_, z);
    EXPECT_GT(a.mean, 0) << what;
    EXPECT_LT(std::abs(z), 4.0) << what;
    // The comparison must be sharp enough to mean something.
    EXPECT_LT(sigma, sharpness * std::abs(b.mean)) << what;
}

void expectAgreement(const Comparison& c, const std::vector<double>& bins) {
    std::printf("  path tracer %.1f s (%llu branches), forward %.1f s\n", c.backward.seconds,
                static_cast<unsigned long long>(c.backward.stats.fluorescenceBranches), c.forward.seconds);
    expectAgree(c.backward.fluorescentPower, c.forward.fluorescentPower, "fluorescent power (W)", 0.06);
    expectAgree(c.backward.fluorescentPowerTimesLambda, c.forward.fluorescentPowerTimesLambda, "power x lambda (W nm)", 0.06);
    for (size_t b = 0; b + 1 < bins.size(); ++b) {
        char name[64];
        std::snprintf(name, sizeof name, "band %.0f-%.0f nm", bins[b], bins[b + 1]);
        expectAgree(c.backward.binPower[b], c.forward.binPower[b], name, 0.15);
    }
}

Scene baseScene(double lambdaMin = 400, double lambdaMax = 750) {
    Scene scene;
    scene.spectral.lambdaMin = lambdaMin;
    scene.spectral.lambdaMax = lambdaMax;
    return scene;
}

// Optical depth 0.03 (radius): nearly every photon is absorbed at most once.
TEST(FluorescenceForward, OpticallyThinBall) {
    Scene scene = baseScene();
    const int m = addDyedMedium(scene, "thin", 0.0, 0.05, 0.0, 1.0, {{databaseDye("AF488"), 5e-6}});
    addDyedBall(scene, 1.0, m, false);
    addPointLight(scene, Vec3(0, 0, 6), Spectrum::lines({{488, 1.0}}));
    scene.finalize();
    const std::vector<double> bins{450, 510, 540, 750};
    expectAgreement(compare(scene, 1.0, 100000, 1000000, bins), bins);
}

// Optical depth 10, anisotropic scattering, two dyes whose bands overlap (AF488's emission excites
// AF568), a line light and a continuous light. (A refracting boundary is left out: a point light seen
// through a smooth interface is a caustic that no unidirectional path tracer samples.)
TEST(FluorescenceForward, ScatteringBallTwoDyes) {
    Scene scene = baseScene();
    const int m = addDyedMedium(scene, "two dyes", 0.01, 10.0, 0.5, 1.0,
                                {{databaseDye("AF488"), 2e-5}, {databaseDye("AF568"), 2e-5}});
    addDyedBall(scene, 1.0, m, false);
    addPointLight(scene, Vec3(0, 0, 5), Spectrum::lines({{488, 1.0}}));
    addPointLight(scene, Vec3(4, 0, -3), Spectrum::constant(0.004));
    scene.finalize();
    const std::vector<double> bins{400, 540, 590, 750};
    expectAgreement(compare(scene, 1.0, 100000, 1000000, bins), bins);
}

// Optical depth 100 (radius) by scattering, with a concentrated dye that re-absorbs much of its own
// emission (inner filter; many fluorescence generations).
TEST(FluorescenceForward, OpticallyThickBallWithReabsorption) {
    Scene scene = baseScene();
    const int m = addDyedMedium(scene, "thick", 0.0, 100.0, 0.0, 1.0, {{databaseDye("AF488"), 1e-4}});
    addDyedBall(scene, 1.0, m, false);
    addPointLight(scene, Vec3(0, 0, 5), Spectrum::lines({{488, 1.0}}));
    scene.finalize();
    const std::vector<double> bins{450, 520, 560, 750};
    expectAgreement(compare(scene, 1.0, 60000, 200000, bins), bins);
}

// Lights inside the dyes' emission bands (561 nm excites AF546 and lies where both dyes emit): paths
// at a spectral line must not branch (re-emission is a density, not part of the line's delta weight).
// Before that rule this scene hung in line-to-line cascades and over-counted.
TEST(FluorescenceForward, LightInsideEmissionBands) {
    Scene scene = baseScene();
    const int m = addDyedMedium(scene, "overlap", 0.0, 2.0, 0.0, 1.0, {{databaseDye("AF488"), 2e-5}, {databaseDye("AF546"), 2e-5}});
    addDyedBall(scene, 1.0, m, false);
    addPointLight(scene, Vec3(0, 0, 5), Spectrum::lines({{499, 1.0}, {561, 1.0}}));
    scene.finalize();
    const std::vector<double> bins{450, 540, 580, 750};
    expectAgreement(compare(scene, 1.0, 60000, 600000, bins), bins);
}

}  // namespace
}  // namespace fluorosim
