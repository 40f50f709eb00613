// Fluorescence branch points are extra null collisions in the camera paths' free flights; next-event
// estimation does not see them. Spectral MIS between light sampling and hitting an area light must
// still sum to one, so the elastic light leaving a dyed, scattering ball under an area light must not
// depend on whether dyes re-emit: the full model and "none" (dyes only absorb, no branch points) must
// give the same elastic power, in a homogeneous and in a grid medium.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>

#include "render/flux_sensor.h"
#include "support/fluorescent_scenes.h"
#include "volume/volume_fields.h"

namespace fluorosim {
namespace {

using namespace testing;

Scene areaLitBall(FluorescenceModel model, bool grid) {
    Scene scene;
    scene.spectral.lambdaMin = 380;
    scene.spectral.lambdaMax = 780;
    scene.render.fluorescence = model;
    std::shared_ptr<const VolumeFields> volume;
    if (grid) {
        const DensityGrid g = DensityGrid::fromVoxels("AF488", {{-21, -21, -21}, {21, 21, 21}}, Affine::scaling(0.05), [](int i, int j, int k) {
            return 40.0 * std::exp(-(i * i + j * j + k * k) * 0.0025 / (2 * 0.09));
        });
        std::vector<VolumeChannel> ch(3);
        ch[kSolventChannel].offset = 1;
        ch[kScatteringChannel].offset = 1;
        ch[kFirstDyeChannel].grid = g;
        ch[kFirstDyeChannel].scale = 1e-6;
        volume = std::make_shared<const VolumeFields>(std::move(ch), Affine(), Interpolation::Trilinear);
    }
    // Wavelength-dependent absorption (the dye) and scattering, so spectral MIS has work to do.
    scene.media.emplace_back("dyed", Spectrum::constant(0.05), Spectrum::tabulated(TabulatedSpectrum({380, 780}, {3.0, 1.0})), 0.5, 1.0,
                             std::vector<DyeComponent>{{databaseDye("AF488"), grid ? 0.0 : 2e-5}}, volume);
    addDyedBall(scene, 1.0, 0, false);
    const uint32_t bulb = scene.geometry.addSphere(Vec3(0, 0, 3.6), 2.4);  // large: both MIS strategies matter
    scene.shapes.push_back(ShapeInfo{"bulb"});
    scene.addAreaLight(bulb, AreaEmission{Spectrum::constant(1.0), false});
    scene.finalize();
    return scene;
}

// Before branch points were made a separate process (they used to raise r_l like null collisions),
// the homogeneous case read 1.25 % low, z = -6.4 at 1.6e6 paths; 1.2e6 paths resolve that at about 5.5 sigma.
void expectSameElastic(bool grid, uint64_t paths) {
    FluxSensorOptions s;
    s.radius = 1.0001;
    s.paths = paths;
    s.seed = grid ? 5 : 3;
    const FluxSensorResult full = measureExitantFlux(areaLitBall(FluorescenceModel::Full, grid), s);
    s.seed += 100;
    const FluxSensorResult none = measureExitantFlux(areaLitBall(FluorescenceModel::None, grid), s);
    const double sigma = std::hypot(full.elasticPower.stderr_, none.elasticPower.stderr_);
    const double z = (full.elasticPower.mean - none.elasticPower.mean) / sigma;
    std::printf("  %s: elastic power full %.6g +- %.2g (%llu branches), none %.6g +- %.2g, z = %+.2f; fluorescent %.4g\n",
                grid ? "grid" : "homogeneous", full.elasticPower.mean, full.elasticPower.stderr_,
                static_cast<unsigned long long>(full.stats.fluorescenceBranches), none.elasticPower.mean, none.elasticPower.stderr_, z,
                full.fluorescentPower.mean);
    EXPECT_GT(full.stats.fluorescenceBranches, 5000u);  // the branch points are really exercised
    EXPECT_LT(std::abs(z), 4.0);
    EXPECT_LT(sigma, 0.01 * none.elasticPower.mean) << "the check must be sharp";
}

TEST(SpectralMis, ElasticLightIgnoresBranchPointsHomogeneous) { expectSameElastic(false, 1200000); }
TEST(SpectralMis, ElasticLightIgnoresBranchPointsGrid) { expectSameElastic(true, 400000); }

}  // namespace
}  // namespace fluorosim
