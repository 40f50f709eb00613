// The computed image as a linear operator: adjoints by the dot-product test, columns that add up to the
// image the acquisition computes, label parts that add up to the concentrations.
#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "optics/acquisition.h"
#include "optics/fft_convolution.h"
#include "optics/imaging_operator.h"
#include "optics/scene_files.h"
#include "support/fit_scenes.h"
#include "support/fluorescent_scenes.h"
#include "support/temp_dir.h"

#include <fstream>
#include <nlohmann/json.hpp>

namespace fluorosim {
namespace {

using testing::TempDir;

double dot(const std::vector<double>& a, const std::vector<double>& b) {
    double s = 0;
    for (size_t i = 0; i < a.size(); ++i) s += a[i] * b[i];
    return s;
}

std::vector<double> randomVector(size_t n, std::mt19937_64& rng, double lo = -1, double hi = 1) {
    std::uniform_real_distribution<double> u(lo, hi);
    std::vector<double> v(n);
    for (double& x : v) x = u(rng);
    return v;
}

TEST(FftConvolution, CorrelationIsTheConvolutionsAdjoint) {
    std::mt19937_64 rng(7);
    const int w = 37, h = 23, r = 6;
    optics::FftConvolution conv(w, h, r);
    for (int b = 0; b < 3; ++b) conv.addKernel(randomVector(static_cast<size_t>((2 * r + 1) * (2 * r + 1)), rng));
    for (int b = 0; b < 3; ++b) {
        const std::vector<double> x = randomVector(static_cast<size_t>(w * h), rng), y = randomVector(static_cast<size_t>(w * h), rng);
        std::vector<std::vector<double>> images(3);
        images[static_cast<size_t>(b)] = x;
        const double lhs = dot(conv.convolveSum(images), y), rhs = dot(x, conv.correlate(y, b));
        EXPECT_NEAR(lhs, rhs, 1e-12 * std::abs(lhs)) << "kernel " << b;
    }
}

struct FitSpecimen {
    TempDir dir;
    Scene scene;
    optics::Microscope microscope;
    explicit FitSpecimen(const testing::FitSceneOptions& o = {})
        : scene(optics::loadSceneFile(testing::writeFitScene(dir.path(), o), testing::database())),
          microscope(optics::Microscope::fromScene(scene, testing::database())) {}
};

TEST(PsfProjector, BackProjectionIsTheProjectionsAdjoint) {
    FitSpecimen s;
    optics::AcquireOptions o;
    const optics::ChannelImaging imaging = optics::setUpChannelImaging(s.scene, s.microscope, 0, o);
    const optics::PsfProjector& p = imaging.unscattered->projector(imaging.planeOffsetsMm.front());
    const optics::ProjectorGeometry& g = p.geometry();
    std::mt19937_64 rng(11);
    std::uniform_real_distribution<double> u(0, 1);
    // Points anywhere in the region and between layers, on and off the lattice's phases.
    std::vector<optics::PointEmission> ems;
    for (int i = 0; i < 400; ++i) {
        optics::PointEmission e;
        e.u = u(rng) * (g.width + 2 * g.marginPixels);
        e.v = u(rng) * (g.height + 2 * g.marginPixels);
        if (i % 4 == 0) e.u = std::floor(e.u * 4) / 4, e.v = std::floor(e.v * 4) / 4;
        e.layer = u(rng) * (g.layers - 1);
        if (i % 3 == 0) e.layer = std::floor(e.layer);
        e.e = u(rng);
        e.dye = 0;
        ems.push_back(e);
    }
    const std::vector<double> y = randomVector(static_cast<size_t>(g.width * g.height), rng);
    const std::vector<double> forward = p.project(ems, 1, 2)[0];
    const std::vector<double> back = p.backProject(y, ems, 2);
    double rhs = 0;
    for (size_t i = 0; i < ems.size(); ++i) rhs += ems[i].e * back[i];
    const double lhs = dot(forward, y);
    EXPECT_NEAR(lhs, rhs, 1e-12 * std::abs(lhs));
    std::printf("  <P e, y> = %.15g, <e, P^T y> = %.15g\n", lhs, rhs);
}

TEST(PsfProjector, EachDyeImagesThroughItsOwnPsfNearAndFar) {
    // A channel with a green and a red dye: a red point images as it does in a channel of the red dye
    // alone, in the near kernels and in the far part (which once used one mean PSF of the channel's dyes).
    FitSpecimen s;
    optics::AcquireOptions o;
    const optics::ChannelImaging imaging = optics::setUpChannelImaging(s.scene, s.microscope, 0, o);
    const optics::ProjectorGeometry& g = imaging.unscattered->projector(imaging.planeOffsetsMm.front()).geometry();
    optics::EmittingDye green, red;
    green.nodeLambda = {500, 520};
    green.nodeWeight = {0.5, 0.5};
    green.detected = 3;
    red.nodeLambda = {640, 680};
    red.nodeWeight = {0.5, 0.5};
    red.detected = 1;
    optics::ChannelDyes both, redOnly;
    both.dyes = {green, red};
    redOnly.dyes = {red};
    const optics::PsfProjector pBoth(both, imaging.psf, g, 5, {}), pRed(redOnly, imaging.psf, g, 5, {});
    for (double layer : {0.0, 0.5 * (g.layers - 1)}) {  // the farthest layer from focus, and the middle
        optics::PointEmission e;
        e.u = 0.5 * (g.width + 2 * g.marginPixels) + 0.3;
        e.v = 0.5 * (g.height + 2 * g.marginPixels) - 0.2;
        e.layer = layer;
        e.e = 1;
        e.dye = 1;
        const std::vector<double> inBoth = pBoth.project({e}, 1, 2)[0];
        e.dye = 0;
        const std::vector<double> alone = pRed.project({e}, 1, 2)[0], asGreen = pBoth.project({e}, 1, 2)[0];
        double worst = 0, peak = 0, greenDiff = 0;
        for (size_t i = 0; i < alone.size(); ++i) {
            worst = std::max(worst, std::abs(inBoth[i] - alone[i]));
            greenDiff = std::max(greenDiff, std::abs(asGreen[i] - alone[i]));
            peak = std::max(peak, alone[i]);
        }
        std::printf("  layer %.1f: red point in a two-dye channel against the red channel, largest difference %.2e of the peak (green PSF: %.2e)\n",
                    layer, worst / peak, greenDiff / peak);
        EXPECT_LT(worst, 1e-12 * peak);
        EXPECT_GT(greenDiff, 1e-2 * peak);
    }
}

TEST(StackOperator, AdjointPassesTheDotProductTestForLabelsAndGrid) {
    FitSpecimen s;
    optics::AcquireOptions o;
    optics::StackOperator op(s.scene, s.microscope, {0, 1}, o);
    ASSERT_TRUE(op.refreshGains(s.scene));
    std::mt19937_64 rng(3);
    for (bool grid : {false, true}) {
        const optics::ParameterMap map = grid ? optics::ParameterMap::grid(0.004, op.lattices()) : optics::ParameterMap::labels(op.labels(), false);
        ASSERT_GT(map.size(), 0u);
        const std::vector<double> theta = randomVector(map.size(), rng, 0, 2), y = randomVector(op.stackPixels(), rng);
        const double lhs = dot(op.apply(map, theta, false), y), rhs = dot(theta, op.applyAdjoint(map, y));
        EXPECT_NEAR(lhs, rhs, 1e-11 * std::abs(lhs)) << (grid ? "grid" : "labels");
        std::printf("  %s (%zu parameters): <A t, y> = %.15g, <t, A^T y> = %.15g\n", grid ? "grid" : "labels", map.size(), lhs, rhs);
    }
}

// The columns add up to the acquisition's computed image: in clear tissue the unscattered light, in
// scattering tissue also the emission of the excitation field, traced with the acquisition's streams.
void expectColumnsAddUpToTheComputedImage(double sigmaSPerMm) {
    testing::FitSceneOptions so;
    so.sigmaSPerMm = sigmaSPerMm;
    FitSpecimen s(so);
    optics::AcquireOptions o;
    optics::StackOperator op(s.scene, s.microscope, {0, 1}, o);
    ASSERT_TRUE(op.refreshGains(s.scene));
    const optics::ParameterMap map = optics::ParameterMap::labels(op.labels(), false);
    ASSERT_EQ(map.size(), 3u) << "three labels hold dye";
    // The columns leave out the PSF's tail (it reaches every pixel); tail() gives it, and whole columns hold it.
    const optics::SparseColumns cols = op.columns(map), whole = op.columns(map, nullptr, true);
    const std::vector<double> tail = op.tail(map, std::vector<double>(map.size(), 1.0));
    std::vector<double> sum = tail, sumWhole(op.stackPixels(), 0.0);
    size_t stored = 0, storedWhole = 0;
    for (size_t j = 0; j < map.size(); ++j) {
        for (size_t k = 0; k < cols.pixels[j].size(); ++k) sum[cols.pixels[j][k]] += cols.values[j][k];
        for (size_t k = 0; k < whole.pixels[j].size(); ++k) sumWhole[whole.pixels[j][k]] += whole.values[j][k];
        stored += cols.pixels[j].size();
        storedWhole += whole.pixels[j].size();
    }
    std::printf("  values stored: %zu without the tail, %zu with it (%zu pixels x %zu labels dense)\n", stored, storedWhole, op.stackPixels(), map.size());
    EXPECT_LE(stored, storedWhole);  // equal on this 40-pixel field: the far part alone reaches all of it
    const std::vector<double> applied = op.apply(map, std::vector<double>(map.size(), 1.0));
    // The acquisition's computed part, plane by plane (its own lattice, not split by label).
    const size_t planePixels = static_cast<size_t>(op.width()) * op.height();
    double worstColumns = 0, worstAcquisition = 0, peak = 0, fieldElectrons = 0, computedElectrons = 0;
    // The operator leaves no faint point out; the acquisition by default leaves out 1e-4 of what they send.
    optics::AcquireOptions exact = o;
    exact.unscattered.dropPointsBelow = 0;
    for (size_t slot = 0; slot < 2; ++slot) {
        const optics::ChannelImaging imaging = optics::setUpChannelImaging(s.scene, s.microscope, slot, exact);
        for (int k = 0; k < op.planes(); ++k) {
            const optics::PlaneImage image = optics::acquirePlane(s.scene, s.microscope, slot, k, [&] {
                optics::AcquireOptions a = exact;
                a.spp = 1;
                return a;
            }(), &imaging);
            fieldElectrons += image.fieldElectrons;
            for (size_t i = 0; i < planePixels; ++i) {
                const size_t at = op.planeImage(slot, k) * planePixels + i;
                computedElectrons += image.computedImage[i];
                peak = std::max(peak, applied[at]);
                worstColumns = std::max({worstColumns, std::abs(sum[at] - applied[at]), std::abs(sumWhole[at] - applied[at])});
                worstAcquisition = std::max(worstAcquisition, std::abs(image.computedImage[i] - applied[at]));
            }
        }
    }
    std::printf("  sigma_s %g /mm: peak %.6g e-, the field's share %.4f; largest |sum of columns - image| %.3g, |acquisition's computed part - image| %.3g\n",
                sigmaSPerMm, peak, fieldElectrons / computedElectrons, worstColumns, worstAcquisition);
    if (sigmaSPerMm > 0) {
        EXPECT_GT(fieldElectrons, 1e-3 * computedElectrons);  // the field is there (and the check above says the columns hold it)
        // Without the field the operator's image is the computed image less the field's light.
        optics::AcquireOptions noField = o;
        noField.field.photons = 0;
        optics::StackOperator without(s.scene, s.microscope, {0, 1}, noField);
        ASSERT_TRUE(without.refreshGains(s.scene));
        const std::vector<double> appliedWithout = without.apply(map, std::vector<double>(map.size(), 1.0));
        double total = 0, totalWithout = 0;
        for (size_t i = 0; i < applied.size(); ++i) total += applied[i], totalWithout += appliedWithout[i];
        std::printf("  the columns' total %.6g e- with the field, %.6g without; the acquisitions' estimate of the field's light %.6g\n", total,
                    totalWithout, fieldElectrons);
        EXPECT_GT(total - totalWithout, 1e-3 * total);
    } else {
        EXPECT_EQ(fieldElectrons, 0.0);
    }
    EXPECT_GT(peak, 0);
    EXPECT_LE(worstColumns, 1e-11 * peak);
    // The label split keeps each part in float: parts and whole differ by float rounding (1e-7).
    EXPECT_LE(worstAcquisition, 1e-6 * peak);
}

TEST(StackOperator, LabelColumnsAddUpToTheAcquisitionsComputedImage) { expectColumnsAddUpToTheComputedImage(0.0); }

TEST(StackOperator, LabelColumnsHoldTheExcitationFieldsEmissionInScatteringTissue) { expectColumnsAddUpToTheComputedImage(5.0); }

TEST(EmissionLattice, LabelPartsAddUpToTheConcentrations) {
    FitSpecimen s;
    optics::AcquireOptions o;
    optics::StackOperator op(s.scene, s.microscope, {0, 1}, o);
    size_t points = 0, checked = 0;
    for (const optics::EmissionLattice* l : op.lattices()) {
        ASSERT_TRUE(l->hasParts());
        for (size_t p = 0; p < l->size(); ++p, ++points)
            for (int slot = 0; slot < l->slots(); ++slot) {
                double sum = 0;
                for (const auto* part = l->partsBegin(p); part != l->partsEnd(p); ++part)
                    if (part->slot == slot) sum += part->value;
                const double c = l->concentration(p, slot);
                EXPECT_NEAR(sum, c, 1e-6 * std::max(c, 1e-12)) << "point " << p << " slot " << slot;
                checked += c > 0;
            }
        for (const optics::LabelKey& k : l->labels()) EXPECT_NE(k.value, 0) << "every voxel with dye carries a label";
    }
    std::printf("  %zu points, %zu concentrations checked\n", points, checked);
    EXPECT_GT(checked, 1000u);
}

TEST(StackOperator, IsLinearInTheParameters) {
    FitSpecimen s;
    optics::AcquireOptions o;
    optics::StackOperator op(s.scene, s.microscope, {0, 1}, o);
    ASSERT_TRUE(op.refreshGains(s.scene));
    const optics::ParameterMap map = optics::ParameterMap::labels(op.labels(), false);
    std::mt19937_64 rng(5);
    const std::vector<double> a = randomVector(map.size(), rng, 0, 3), b = randomVector(map.size(), rng, 0, 3);
    std::vector<double> c(map.size());
    for (size_t j = 0; j < c.size(); ++j) c[j] = 2 * a[j] - 0.5 * b[j];
    const std::vector<double> ya = op.apply(map, a, false), yb = op.apply(map, b, false), yc = op.apply(map, c, false);
    double worst = 0, peak = 0;
    for (size_t i = 0; i < yc.size(); ++i) {
        worst = std::max(worst, std::abs(yc[i] - (2 * ya[i] - 0.5 * yb[i])));
        peak = std::max(peak, std::abs(yc[i]));
    }
    EXPECT_LE(worst, 1e-12 * peak);
}

}  // namespace
}  // namespace fluorosim

namespace fluorosim {
namespace {

// The computed image of a bead in a dyed bath is the bead's plus the bath's: every lattice column
// integrates every homogeneous dyed medium along it, so columns refined over the bead must not overlap
// the standard ones (they did: the bath under the bead was counted twice).
TEST(UnscatteredImage, ABeadInADyedBathIsTheSumOfTheTwo) {
    TempDir dir;
    const std::filesystem::path beads = std::filesystem::path(FLUOROSIM_SOURCE_DIR) / "samples" / "lightsheet" / "beads.json";
    auto scene = [&](bool bead, bool bath) {
        std::ifstream f(beads);
        nlohmann::json j = nlohmann::json::parse(f);
        j["shapes"][0]["file"] = (beads.parent_path() / "bath.obj").string();
        j["shapes"] = nlohmann::json::array({j["shapes"][0], j["shapes"][1]});  // the bath and bead 0
        if (!bead) j["media"]["bead"]["dyes"][0]["concentration"] = "0 uM";
        if (bath) j["media"]["water"]["dyes"] = nlohmann::json::array({{{"dye", "AF488"}, {"concentration", "2 uM"}}});
        j["microscope"]["detector"]["width"] = 12;
        j["microscope"]["detector"]["height"] = 12;
        j["microscope"]["focus"]["center"] = j["shapes"][1]["center"];
        const auto path = dir.path() / (std::string("s") + (bead ? "1" : "0") + (bath ? "1" : "0") + ".json");
        std::ofstream(path) << j.dump();
        return optics::loadSceneFile(path, testing::database());
    };
    auto computed = [&](const Scene& s) {
        const optics::Microscope m = optics::Microscope::fromScene(s, testing::database());
        optics::AcquireOptions o;
        o.spp = 1;
        o.psf.vCut = 30;  // a narrow PSF keeps the region (and the bath's columns) small
        return optics::acquirePlane(s, m, 0, 0, o).computedImage;
    };
    const std::vector<double> both = computed(scene(true, true)), bead = computed(scene(true, false)), bath = computed(scene(false, true));
    double worst = 0, peak = 0;
    for (size_t i = 0; i < both.size(); ++i) {
        peak = std::max(peak, both[i]);
        worst = std::max(worst, std::abs(both[i] - bead[i] - bath[i]) / std::max(bath[i], 1e-300));
    }
    std::printf("  largest |both - bead - bath| / bath %.2e (peak %.4g e-)\n", worst, peak);
    EXPECT_GT(peak, 0);
    // The dyes' attenuation couples them: the bead (1 mM AF488, 0.2 um across) absorbs 0.34 % of the
    // light that crosses it. Counting the bath twice over the bead's refined cells (the old columns) gave 0.155.
    EXPECT_LT(worst, 1e-2);
}

}  // namespace
}  // namespace fluorosim
