// optics::Microscope and the acquisition API: the scene's microscope block parsed into the model, a
// plane's lights moved without touching the shared scene, and planes rendered concurrently giving the
// same images as one after the other.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <thread>

#include "core/errors.h"
#include "optics/acquire_request.h"
#include "optics/acquisition.h"
#include "optics/light_sheet.h"
#include "scene/scene_loader.h"
#include "support/fluorescent_scenes.h"

namespace fluorosim {
namespace {

using namespace testing;
namespace fs = std::filesystem;

Scene beadsScene() {
    const fs::path file = fs::path(FLUOROSIM_SOURCE_DIR) / "samples" / "lightsheet" / "beads.json";
    return loadScene(
        file, [](const std::string& ref, const fs::path& base) { return database().resolve(ref, base); },
        [](const std::string& name, std::optional<double> ec, std::optional<double> qy) { return database().fluorophore(name, ec, qy); },
        [](const LightSheetSpec& spec) { return optics::makeLightSheet(spec); });
}

TEST(Microscope, ParsesTheSceneBlock) {
    const Scene scene = beadsScene();
    const optics::Microscope m = optics::Microscope::fromScene(scene, database());
    EXPECT_EQ(m.objective.na, 0.8);
    EXPECT_EQ(m.objective.magnification, 16);
    EXPECT_NEAR(m.objective.workingDistanceMm, 0.2, 1e-15);
    EXPECT_NEAR(m.pixelSizeMm(), 6.5e-3 / 16, 1e-18);
    EXPECT_EQ(m.width, 64);
    EXPECT_EQ(m.stack.planes, 8);
    EXPECT_NEAR(m.stack.stepMm, 0.001, 1e-15);
    ASSERT_EQ(m.channels.size(), 1u);
    EXPECT_EQ(m.channels[0].name, "AF488");
    EXPECT_EQ(m.channels[0].excitationNm, 488);
    EXPECT_NEAR(m.channels[0].emissionNm, 525, 2);
    EXPECT_EQ(m.channelIndex("AF488"), 0u);
    EXPECT_THROW(m.channelIndex("GFP"), ConfigError);
    EXPECT_NEAR(m.planeOffsetMm(0), -0.0035, 1e-15);
    EXPECT_NEAR(m.planeOffsetMm(7), 0.0035, 1e-15);
}

TEST(Microscope, PlaneLightsMoveWithoutChangingTheScene) {
    const Scene scene = beadsScene();
    const optics::Microscope m = optics::Microscope::fromScene(scene, database());
    const auto& original = std::get<BeamLight>(scene.lights[0]).profile;
    const double peak = original->irradiance(Vec3(0, 0, 0), 0, 488);
    const std::vector<Light> moved = m.lightsAt(scene, m.channels[0], 0.002);
    const auto& profile = std::get<BeamLight>(moved[0]).profile;
    EXPECT_NEAR(profile->irradiance(Vec3(0, 0, 0.002), 0, 488), peak, 1e-12 * peak);  // the sheet follows the focal plane
    EXPECT_NEAR(profile->irradiance(Vec3(0, 0, 0), 0, 488) / peak, std::exp(-2 * sqr(0.002 / 0.0015)), 1e-12);
    EXPECT_EQ(original->irradiance(Vec3(0, 0, 0), 0, 488), peak);  // the scene's own sheet is untouched
    EXPECT_NEAR(m.focalPlaneAt(0.002).centreMm.z, 0.002, 1e-18);
}

TEST(Microscope, PlanesRenderConcurrentlyAsTheyDoAlone) {
    const Scene scene = beadsScene();
    optics::Microscope m = optics::Microscope::fromScene(scene, database());
    m.width = m.height = 48;
    optics::AcquireOptions o;
    o.spp = 32;
    o.threads = 1;
    const optics::PlaneImage a = optics::acquirePlane(scene, m, 0, 3, o), b = optics::acquirePlane(scene, m, 0, 4, o);
    optics::PlaneImage ca, cb;
    std::thread ta([&] { ca = optics::acquirePlane(scene, m, 0, 3, o); });
    std::thread tb([&] { cb = optics::acquirePlane(scene, m, 0, 4, o); });
    ta.join();
    tb.join();
    EXPECT_EQ(a.electrons, ca.electrons);
    EXPECT_EQ(b.electrons, cb.electrons);
    EXPECT_NE(a.electrons, b.electrons);
    EXPECT_GT(*std::max_element(a.electrons.begin(), a.electrons.end()), 0.0);
}

// --exposure auto scales a finished stack; it must be the stack acquired at the exposure it chose: the
// photoelectrons scale with the exposure, and each plane keeps its noise stream.
TEST(Microscope, AutoExposureIsTheStackAcquiredAtTheChosenExposure) {
    const Scene scene = beadsScene();
    optics::Microscope m = optics::Microscope::fromScene(scene, database());
    m.width = m.height = 32;
    m.stack.planes = 2;
    optics::AcquireOptions o;
    o.spp = 4;
    optics::Stack scaled = optics::emptyStack(m, {0});
    ASSERT_TRUE(optics::acquireStack(scene, m, scaled, o));
    optics::Microscope chosen = m;
    const optics::AutoExposure a = optics::autoExpose(scaled, chosen, 0.6, o.seed);
    std::printf("  exposure %.4g ms x %.4g = %.4g ms; brightest pixel %.4g e- before\n", m.detector.exposureS * 1e3, a.factor, a.exposureS * 1e3,
                a.brightestElectrons);
    EXPECT_NEAR(chosen.detector.exposureS, m.detector.exposureS * a.factor, 1e-15);
    optics::Stack direct = optics::emptyStack(chosen, {0});
    ASSERT_TRUE(optics::acquireStack(scene, chosen, direct, o));
    double brightest = 0, worst = 0;
    size_t sameCounts = 0;
    const double dark = chosen.detector.darkCurrentElectronsPerS * chosen.detector.exposureS;
    for (size_t i = 0; i < direct.expected.size(); ++i) {
        worst = std::max(worst, std::abs(double(scaled.expected[i]) - direct.expected[i]) / std::max(1.0, double(direct.expected[i])));
        sameCounts += scaled.counts[i] == direct.counts[i];
        if (direct.stderrElectrons[i] <= 0.25 * (direct.expected[i] - dark)) brightest = std::max(brightest, direct.expected[i] - dark);
    }
    std::printf("  against a stack acquired at that exposure: largest relative difference %.2e, counts equal in %zu of %zu pixels\n", worst,
                sameCounts, direct.counts.size());
    EXPECT_LT(worst, 1e-5);
    EXPECT_GE(sameCounts, direct.counts.size() - direct.counts.size() / 1000);
    EXPECT_NEAR(brightest, 0.6 * chosen.detector.fullWellElectrons, 1e-4 * chosen.detector.fullWellElectrons);
    EXPECT_THROW(optics::autoExpose(scaled, chosen, 1.5, o.seed), ConfigError);
}

TEST(Microscope, ExposureOptionTakesATimeOrAuto) {
    EXPECT_EQ(optics::parseExposure(std::string("auto")).autoFraction, 0.5);
    EXPECT_EQ(optics::parseExposure(std::string("auto:0.8")).autoFraction, 0.8);
    EXPECT_NEAR(*optics::parseExposure(std::string("20 ms")).seconds, 0.02, 1e-15);
    EXPECT_FALSE(optics::parseExposure(std::nullopt).seconds || optics::parseExposure(std::nullopt).autoFraction);
    for (const char* bad : {"auto:2", "auto0.5", "auto:", "auto:0.5x", "fast", "-5 ms", "20"}) {
        try {
            optics::parseExposure(std::string(bad));
            ADD_FAILURE() << bad << " was accepted";
        } catch (const ConfigError& e) {
            const std::string what = e.what();
            EXPECT_NE(what.find("--exposure"), std::string::npos) << what;
            EXPECT_EQ(what.find('\n'), std::string::npos) << what;
        }
    }
}

}  // namespace
}  // namespace fluorosim
