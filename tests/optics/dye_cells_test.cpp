// The traced photons' sources in the field-lit dye (optics/dye_cells.h): a sampler, so its density must be
// the one its weights divide by. For any g, the mean of g(p) / pdf(p) over its draws estimates ∫ g over the
// cells; with g the dye's trilinear concentration, whose cells hold all of it, that is Σ voxels × h³ exactly
// (each voxel's tent integrates to h³). Dye beyond the field's box is no cell's.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>

#include "core/rng.h"
#include "optics/dye_cells.h"
#include "optics/acquisition.h"
#include "optics/unscattered_image.h"
#include "support/sheet_scenes.h"

namespace fluorosim {
namespace {

using namespace testing;

constexpr double kVoxelMm = 0.002;

// AF594 (µM) on 2 µm voxels: a filament along x in the sheet and a fainter blob above it, in σs 2 /mm tissue.
double micromolar(int i, int j, int k) { return 200.0 * std::exp(-(j * j + k * k) / 2.0) + 50.0 * std::exp(-(i * i + j * j + (k - 6) * (k - 6)) / 4.0); }
const IndexBox kVoxels{{-15, -6, -5}, {15, 6, 12}};

Scene tissue() {
    Scene scene = af594Tissue(DensityGrid::fromVoxels("AF594", kVoxels, Affine::scaling(kVoxelMm), micromolar), 2.0);
    addSheetAndFinalize(scene, 0.003, 0.1);
    return scene;
}

struct Plane {
    Scene scene = tissue();
    PathTracer tracer{scene};
    optics::ObjectiveOptions objective;
    optics::DetectorOptions detector;
    optics::Filter filter = optics::Filter::bandPass({630, 60});
    std::optional<optics::ChannelImaging> channel;
    std::optional<optics::Imaging> imaging;
    Plane() {
        objective.na = 0.5;
        objective.magnification = 6.5 / 1.5;
        objective.workingDistanceMm = 0.2;
        channel.emplace(optics::setUpChannelImaging(scene, scene.lights, objective, optics::FocalPlane{}, filter, detector, 24, 24, optics::AcquireOptions{}));
        imaging.emplace(objective, optics::FocalPlane{}, detector, 24, 24, channel->psf);
    }
    // The sheet's scattered light over a box of half-height `halfZ` about the focal plane.
    BeamExcitationField field(double halfZ) const {
        FieldBox box;
        box.halfX = box.halfY = 0.05;
        box.halfZ = halfZ;
        box.hx = box.hy = 0.004;
        FluenceOptions o;
        o.photons = 20000;
        return BeamExcitationField({traceBeamFluence(scene, beamLineSides(scene.lights).at(0), box, o)});
    }
    double detection(double lambda) const { return filter.transmission(lambda); }
};

// The mean of c(p) / pdf(p) over n draws, and its standard error; c in µM.
std::pair<double, double> concentrationIntegral(const Plane& s, const optics::DyeCells& cells, int n) {
    const Medium& tissue = s.scene.media[0];
    Rng rng(7, 0);
    double sum = 0, sum2 = 0;
    for (int i = 0; i < n; ++i) {
        const optics::DyeCells::Sample y = cells.sample(rng.uniform(), rng.uniform(), rng.uniform(), rng.uniform());
        EXPECT_EQ(y.medium, 0);
        EXPECT_GT(y.pdf, 0.0);
        ChannelValues ch;
        tissue.channelValues(y.p, ch.data());
        const double v = ch[kFirstDyeChannel] * 1e6 / y.pdf;
        sum += v;
        sum2 += v * v;
    }
    const double mean = sum / n;
    return {mean, std::sqrt((sum2 / n - mean * mean) / (n - 1))};
}

TEST(DyeCells, DrawsTheDyeWithTheDensityItsWeightsDivideBy) {
    const Plane s;
    const BeamExcitationField field = s.field(0.04);  // holds all the dye (z from -10 to 24 µm)
    const optics::DyeCells cells(s.scene, s.tracer, field, {561.0}, [&](double l) { return s.detection(l); }, *s.imaging, 2);
    ASSERT_FALSE(cells.empty());
    ASSERT_EQ(cells.media().size(), s.scene.media.size());
    EXPECT_TRUE(cells.media()[0]);
    double exact = 0;
    for (int k = kVoxels.lo[2]; k <= kVoxels.hi[2]; ++k)
        for (int j = kVoxels.lo[1]; j <= kVoxels.hi[1]; ++j)
            for (int i = kVoxels.lo[0]; i <= kVoxels.hi[0]; ++i) exact += micromolar(i, j, k) * std::pow(kVoxelMm, 3);
    const auto [mean, stderr] = concentrationIntegral(s, cells, 200000);
    std::printf("  integral of c: drawn %.6g +- %.2g, exact %.6g uM mm^3\n", mean, stderr, exact);
    EXPECT_LT(std::abs(mean - exact), 4 * stderr);
    EXPECT_LT(stderr, 0.01 * exact) << "the comparison must be sharp";
}

TEST(DyeCells, LeaveOutTheDyeBeyondTheFieldsBox) {
    const Plane s;
    // The box ends 6 µm above the focal plane. Blocks are 8 voxels (16 µm) wide: the one from 0 to 16 µm has
    // corners in the box and is drawn; the one from 16 to 32 µm, which holds the dye's top 8 µm, is not.
    const BeamExcitationField field = s.field(0.006);
    const optics::DyeCells cells(s.scene, s.tracer, field, {561.0}, [&](double l) { return s.detection(l); }, *s.imaging, 2);
    ASSERT_FALSE(cells.empty());
    Rng rng(9, 0);
    double highest = -1;
    for (int i = 0; i < 20000; ++i) highest = std::max(highest, cells.sample(rng.uniform(), rng.uniform(), rng.uniform(), rng.uniform()).p.z);
    EXPECT_LT(highest, 8 * kVoxelMm) << "a cell of a block the box does not reach";
    EXPECT_GT(highest, 6 * kVoxelMm) << "the blocks the box reaches are drawn to their top";
}

}  // namespace
}  // namespace fluorosim
