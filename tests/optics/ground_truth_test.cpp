// The ground truth of a stack: each dye's concentration on the detector grid of each plane, and the image of
// a perfect microscope (no attenuation, no scattered light). A 1 µm dye layer in a scattering, absorbing
// bath under a known sheet: the perfect image against the closed-form chain without Beer–Lambert, the
// acquired image below it, and the concentration exactly the layer's inside it and 0 outside.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>

#include "optics/ground_truth.h"
#include "optics/light_sheet.h"
#include "support/dye_layer.h"
#include "support/fluorescent_scenes.h"

namespace fluorosim {
namespace {

using namespace testing;

TEST(GroundTruth, PerfectImageAndConcentrationOfADyeLayer) {
    const DyeLayer layer{separatedBandDye(70000, 0.9), 1e-4, 0.001, 0.05};
    Scene scene;
    scene.spectral.lambdaMin = 450;
    scene.spectral.lambdaMax = 750;
    scene.media.emplace_back("tissue", Spectrum::constant(0.05), Spectrum::constant(5.0), 0.9, 1.33);
    addDyeLayer(scene, layer, 0, 0.05, 5.0, 0.9, 1.33);
    addBath(scene, 0.4, 0);
    const auto sheet = addLayerSheet(scene, 1.33);
    scene.camera.medium = 0;
    scene.finalize();

    optics::Microscope m;
    m.objective.na = 0.8;
    m.objective.workingDistanceMm = 0.2;
    m.detector.exposureS = 0.01;
    m.detector.darkCurrentElectronsPerS = 0;
    m.width = m.height = 12;
    optics::MicroscopeChannel channel;
    channel.name = "red";
    channel.lights = {0};
    optics::BandPassOptions band;
    band.centreNm = 650;
    band.fwhmNm = 60;
    channel.emissionPath = optics::Filter::bandPass(band);
    m.channels = {channel};
    m.stack.planes = 3;  // the layer's plane and 2 µm to either side
    m.stack.stepMm = 0.002;
    optics::AcquireOptions o;
    o.psf.vCut = 60;
    const optics::GroundTruth truth = optics::groundTruth(scene, m, {0}, o);
    ASSERT_EQ(truth.dyes.size(), 1u);
    ASSERT_EQ(truth.concentration.size(), 3u * 12 * 12);
    ASSERT_EQ(truth.ideal.size(), 3u * 12 * 12);
    for (int k = 0; k < 3; ++k)
        for (size_t i = 0; i < 144; ++i) EXPECT_EQ(truth.concentration[static_cast<size_t>(k) * 144 + i], k == 1 ? static_cast<float>(layer.molar) : 0.0f);

    // The closed form of the photon budget (photon_budget_test.cpp) without the sheet's loss in the
    // layer and the tissue, on the middle plane.
    const double collection = (1 - std::cos(m.objective.collectionHalfAngle())) / 2;
    const LayerCamera camera{m.pixelSizeMm(), 12, 0.01, 0.8, collection};
    double expected = layerElectrons(layer, *sheet, 488.0, channel.emissionPath, camera, false);
    double ideal = 0;
    for (int y = 0; y < 12; ++y)
        for (int x = 0; x < 12; ++x) {
            const Vec3 p = optics::pixelCentreMm(m, 1, x, y);
            EXPECT_NEAR(p.x, (x + 0.5 - 6) * m.pixelSizeMm(), 1e-15);
            EXPECT_NEAR(p.y, (6 - y - 0.5) * m.pixelSizeMm(), 1e-15);
            ideal += truth.ideal[144 + static_cast<size_t>(y * 12 + x)];
        }
    // Only the PSF tail of the dye beyond the computed region is missing (the layer is uniform).
    expected *= layerImageKept(optics::setUpChannelImaging(scene, m, 0, o), layer, 650, camera);
    // What the microscope records: the sheet and the emission lose light in 50 µm of tissue and in the layer.
    optics::Stack stack = optics::emptyStack(m, {0});
    o.spp = 4;
    ASSERT_TRUE(optics::acquireStack(scene, m, stack, o));
    double acquired = 0;
    for (size_t i = 0; i < 144; ++i) acquired += stack.expected[stack.pixelOffset(0, 1) + i];
    std::printf("  perfect microscope %.6g e-, closed form %.6g (ratio %.5f); acquired %.6g (%.3f of the perfect image)\n", ideal, expected,
                ideal / expected, acquired, acquired / ideal);
    // The computed image's quadrature bound (0.5 %, docs/model.md).
    EXPECT_NEAR(ideal / expected, 1.0, 0.005);
    EXPECT_LT(acquired, 0.9 * ideal);
}

}  // namespace
}  // namespace fluorosim
