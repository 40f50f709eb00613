#include "optics/acquisition_summary.h"

#include <gtest/gtest.h>

namespace fluorosim::optics {
namespace {

// A pixel over the full well is light the exposure puts there unless it lies within 4 standard errors of
// the full well: then a rare large Monte Carlo sample may be all that lifts it.
TEST(AcquisitionSummary, SaturatedPixelsAreToldApartFromMonteCarloOutliers) {
    Stack stack;
    stack.width = 5;
    stack.height = 1;
    stack.planes = 1;
    stack.channels = {0};
    //                 below   real    real    outlier  outlier at the edge
    stack.expected = {900.f, 1500.f, 1200.f, 3000.f, 1100.f};
    stack.stderrElectrons = {500.f, 10.f, 40.f, 2900.f, 25.f + 1e-3f};
    const AcquisitionSummary::Saturation s = AcquisitionSummary::saturation(stack, 1000.0);
    EXPECT_EQ(s.pixels, 4u);
    EXPECT_EQ(s.monteCarlo, 2u);  // 3000 − 4 × 2900 and 1100 − 4 × 25.001 lie below 1000; 1200 − 4 × 40 does not
    EXPECT_EQ(s.brightest, 3000.0);

    stack.expected = {900.f, 999.f, 0.f, 1000.f, 10.f};
    const AcquisitionSummary::Saturation none = AcquisitionSummary::saturation(stack, 1000.0);
    EXPECT_EQ(none.pixels, 0u);  // at the full well is not over it
    EXPECT_EQ(none.monteCarlo, 0u);
}

}  // namespace
}  // namespace fluorosim::optics
