#include "optics/acquisition_summary.h"

#include <gtest/gtest.h>

#include <cmath>
#include <map>
#include <string>

namespace fluorosim::optics {
namespace {

// A pixel over the full well is light the exposure puts there unless it lies within 4 standard errors of
// the full well and its error is over the camera's noise (sqrt(signal + read²)): then a rare large Monte Carlo
// sample may be all that lifts it. Within 4 errors that are under the camera's noise, it is borderline.
TEST(AcquisitionSummary, SaturatedPixelsAreToldApartFromMonteCarloOutliers) {
    Stack stack;
    stack.width = 7;
    stack.height = 1;
    stack.planes = 1;
    stack.channels = {0};
    DetectorOptions detector;
    detector.fullWellElectrons = 1000;
    detector.readNoiseElectrons = 2;
    //                 below   real    real    outlier  outlier  border  border: 32.4² < 1050 + 4 < 32.5²
    stack.expected = {900.f, 1500.f, 1200.f, 3000.f, 1100.f, 1100.f, 1050.f};
    stack.stderrElectrons = {500.f, 10.f, 40.f, 2900.f, 40.f, 26.f, 32.4f};
    AcquisitionSummary::Saturation s = AcquisitionSummary::saturation(stack, detector);
    EXPECT_EQ(s.pixels, 6u);
    EXPECT_EQ(s.monteCarlo, 2u);  // 3000 − 4 × 2900 and 1100 − 4 × 40 lie below 1000, with 2900² > 3004 and 40² > 1104
    EXPECT_EQ(s.borderline, 2u);  // 1100 − 4 × 26 and 1050 − 4 × 32.4 too, with 26² < 1104 and 32.4² < 1054
    EXPECT_EQ(s.brightest, 3000.0);

    stack.stderrElectrons[6] = 32.5f;  // 32.5² = 1056.25 > 1054: now the Monte Carlo's
    s = AcquisitionSummary::saturation(stack, detector);
    EXPECT_EQ(s.monteCarlo, 3u);
    EXPECT_EQ(s.borderline, 1u);

    // A read-noise map, per pixel of the plane: 10 e- rms on the last pixel lifts its camera variance over 32.5².
    detector.readNoiseMapElectrons = {2, 2, 2, 2, 2, 2, 10};
    s = AcquisitionSummary::saturation(stack, detector);
    EXPECT_EQ(s.monteCarlo, 2u);
    EXPECT_EQ(s.borderline, 2u);

    stack.expected = {900.f, 999.f, 0.f, 1000.f, 10.f, 0.f, 0.f};
    const AcquisitionSummary::Saturation none = AcquisitionSummary::saturation(stack, detector);
    EXPECT_EQ(none.pixels, 0u);  // at the full well is not over it
    EXPECT_EQ(none.monteCarlo, 0u);
    EXPECT_EQ(none.borderline, 0u);
}

// A 10 × 10 microscope of one channel without dark current, and its one-plane stack: every pixel expects
// `electrons` with standard error `stderrElectrons`.
struct FlatPlane {
    Microscope m;
    Stack stack;
    FlatPlane(double readNoise, float electrons, float stderrElectrons) {
        m.width = m.height = 10;
        m.detector.darkCurrentElectronsPerS = 0;
        m.detector.readNoiseElectrons = readNoise;
        m.channels.push_back({});
        m.channels.back().name = "c";
        stack.width = stack.height = 10;
        stack.planes = 1;
        stack.channels = {0};
        stack.expected.assign(100, electrons);
        stack.stderrElectrons.assign(100, stderrElectrons);
    }
};

// The noise budget: each part's noise variance over the camera's, per pixel, its median over the brightest
// 10 % and 1 %. Known parts on a flat plane of 100 e-, no dark current or read noise: the field's half
// difference 5 e- (0.25), the traced emission's slot halves 110 and 90 e- (half their difference, 10 e-: 1.0),
// the paths' variance what stderr² holds beyond the traced part's (13 - 4: 0.09).
TEST(AcquisitionSummary, TheNoiseBudgetSplitsTheVarianceByPart) {
    const FlatPlane flat(0, 100.f, std::sqrt(13.f));
    const Microscope& m = flat.m;
    const Stack& stack = flat.stack;
    AcquireOptions o;
    o.spp = 4;
    AcquisitionSummary summary(m, stack, o);
    PlaneImage image;
    image.width = image.height = 10;
    image.electrons.assign(100, 100.0);
    image.stderrElectrons.assign(100, std::sqrt(13.0));
    image.fieldHalfDifference.assign(100, 5.0);
    image.emissionVariance.assign(100, 4.0);
    for (int s = 0; s < 16; ++s) image.emissionEstimates.push_back(std::vector<double>(100, s < 8 ? 110.0 : 90.0));
    EXPECT_EQ(summary.addPlane(0, 0, image), "");
    std::map<std::string, double> budget;
    for (const AcquisitionSummary::Entry& e : summary.entries(stack, m, std::nullopt, 1))
        if (e.group == "noise_budget") {
            EXPECT_FALSE(e.null) << e.name;
            budget[e.name] = e.value;
        }
    ASSERT_EQ(budget.size(), 8u);
    EXPECT_EQ(budget["scattered_emission_pixels_above_1"], 0.0);  // every part's variance is below the camera's 100
    EXPECT_EQ(budget["paths_pixels_above_1"], 0.0);
    for (const char* top : {"_top10", "_top1"}) {
        EXPECT_NEAR(budget[std::string("excitation_field") + top], 0.25, 1e-12);
        EXPECT_NEAR(budget[std::string("scattered_emission") + top], 1.0, 1e-12);
        EXPECT_NEAR(budget[std::string("paths") + top], 0.09, 1e-6);
    }
    // One path per pixel says nothing of the paths' spread: their entries are null then.
    o.spp = 1;
    AcquisitionSummary single(m, stack, o);
    single.addPlane(0, 0, image);
    for (const AcquisitionSummary::Entry& e : single.entries(stack, m, std::nullopt, 1))
        if (e.group == "noise_budget") {
            EXPECT_EQ(e.null, e.name.rfind("paths", 0) == 0) << e.name;
        }
}

// Specks: over every pixel, the largest Monte Carlo variance over the camera's and how many pixels hold more
// Monte Carlo noise than camera noise, in all and by part. A dark plane of 100 pixels at 4 e- with read noise 2 e- (camera variance
// 8): one pixel at stderr 4 (16 / 8 = 2), one at 3 (9 / 8), the rest at 2 (4 / 8, below 1).
TEST(AcquisitionSummary, SpecksAreCountedOverEveryPixel) {
    const FlatPlane flat(2, 4.f, 2.f);
    const Microscope& m = flat.m;
    const Stack& stack = flat.stack;
    AcquireOptions o;
    AcquisitionSummary summary(m, stack, o);
    PlaneImage image;
    image.width = image.height = 10;
    image.electrons.assign(100, 4.0);
    image.stderrElectrons.assign(100, 2.0);
    image.stderrElectrons[17] = 4.0;
    image.stderrElectrons[93] = 3.0;
    image.emissionVariance.assign(100, 0.0);
    image.emissionVariance[17] = 12.0;
    image.emissionVariance[93] = 6.0;
    summary.addPlane(0, 0, image);
    std::map<std::string, double> top;
    for (const AcquisitionSummary::Entry& e : summary.entries(stack, m, std::nullopt, 1))
        if (e.group.empty()) top[e.name] = e.value;
    EXPECT_NEAR(top.at("largest_mc_over_camera_variance"), 2.0, 1e-12);
    EXPECT_EQ(top.at("pixels_mc_over_camera_variance_above_1"), 2.0);
    // By part: the traced photons' variance 12 of the stderr² 16 at pixel 17 (and 6 of 9 at 93): only it is above 8.
    std::map<std::string, double> budget;
    for (const AcquisitionSummary::Entry& e : summary.entries(stack, m, std::nullopt, 1))
        if (e.group == "noise_budget") budget[e.name] = e.value;
    EXPECT_EQ(budget.at("scattered_emission_pixels_above_1"), 1.0);
    EXPECT_EQ(budget.at("paths_pixels_above_1"), 0.0);
}

}  // namespace
}  // namespace fluorosim::optics
