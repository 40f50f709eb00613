// The excitation field (render/fluence_field.h) against an independent estimator: the full model's
// excitation sub-paths (PathTracer::meanRadiance: next-event estimation to the sheet, sheet-side sampling
// and phase sampling, the estimator the field replaces), at points in, beside and far from a light sheet
// in scattering tissue; the field's own error from independent seeds. And the tent tallies' resolution
// error, which must fall as h² when the node spacing halves.
#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <cstdio>
#include <vector>

#include "core/sampling.h"
#include "render/fluence_field.h"
#include "render/path_tracer.h"
#include "support/fluorescent_scenes.h"
#include "support/sheet_scenes.h"

namespace fluorosim {
namespace {

using namespace testing;

Scene sheetInTissue(double sigmaS, double g) {
    Scene scene;
    scene.spectral.lambdaMin = 450;
    scene.spectral.lambdaMax = 750;
    addDyedMedium(scene, "tissue", 0.0, sigmaS, g, 1.33, {});
    addBath(scene, 0.4, 0);
    addSheetAndFinalize(scene, 0.003, 0.1);
    return scene;
}

FieldBox sheetBox(double hz, double lateral = 0.004) {
    FieldBox box;
    box.halfX = 0.03;
    box.halfY = 0.03;
    box.halfZ = 0.02;
    box.hx = box.hy = lateral;
    box.hz = hz;
    return box;
}

struct Estimate {
    double mean = 0, stderr = 0;
};

// The field at `points` from `seeds` independent fields over `box`: their mean and its standard error.
std::vector<Estimate> fieldAt(const Scene& scene, const std::vector<Vec3>& points, const FieldBox& box, uint64_t photons, int seeds) {
    const std::vector<BeamLineSide> lines = beamLineSides(scene.lights);
    std::vector<double> sum(points.size()), sum2(points.size());
    for (int s = 0; s < seeds; ++s) {
        FluenceOptions o;
        o.photons = photons;
        o.seed = 100 + static_cast<uint64_t>(s);
        const BeamExcitationField field({traceBeamFluence(scene, lines.at(0), box, o)});
        for (size_t i = 0; i < points.size(); ++i) {
            const double v = *field.scatteredMeanRadiance(points[i], 561);
            sum[i] += v;
            sum2[i] += v * v;
        }
    }
    std::vector<Estimate> out;
    for (size_t i = 0; i < points.size(); ++i) {
        const double mean = sum[i] / seeds;
        out.push_back({mean, std::sqrt(std::max(0.0, sum2[i] / seeds - mean * mean) / (seeds - 1))});
    }
    return out;
}

// At each point, the field's scattered light against the sub-paths' mean radiance less the unscattered part:
// within 4 standard errors, which must be at most 3 % of it (`paths` sub-paths at each).
template <class Unscattered>
void expectFieldMatchesSubPaths(const PathTracer& tracer, const std::vector<Vec3>& points, const std::vector<Estimate>& fields, Unscattered unscattered,
                                int paths = 200000) {
    const SampledWavelengths wl = SampledWavelengths::atLine(561, 1.0);
    for (size_t k = 0; k < points.size(); ++k) {
        const Vec3& p = points[k];
        double sum = 0, sum2 = 0;
        PathStats stats;
        for (int i = 0; i < paths; ++i) {
            Rng rng = Rng::forKey(7, static_cast<uint64_t>(i), 0x6d65616e);
            const double v = tracer.meanRadiance(p, 0, wl, rng, stats).total()[0];
            sum += v;
            sum2 += v * v;
        }
        const double mean = sum / paths, se = std::sqrt(std::max(0.0, sum2 / paths - mean * mean) / (paths - 1));
        const double pathScattered = mean - unscattered(p);
        const Estimate& field = fields[k];
        const double sigma = std::hypot(se, field.stderr), z = (field.mean - pathScattered) / sigma;
        std::printf("  (%+.3f, %+.3f, %+.4f) mm: sub-paths %.5g +- %.2g (unscattered %.4g), field %.5g +- %.2g, z = %+.2f\n", p.x, p.y, p.z,
                    pathScattered, se, unscattered(p), field.mean, field.stderr, z);
        EXPECT_LT(std::abs(z), 4.0);
        EXPECT_LT(sigma, 0.03 * field.mean) << "the comparison must be sharp";
    }
}

TEST(ExcitationField, AgreesWithTheExcitationSubPaths) {
    const Scene scene = sheetInTissue(5.0, 0.9);
    const PathTracer tracer(scene);
    const BeamProfile& sheet = *std::get<BeamLight>(scene.lights[0]).profile;
    // The unscattered part, exactly: the sheet enters the bath's face at x = -0.4 mm.
    auto unscattered = [&](const Vec3& p) { return kInv4Pi * sheet.irradiance(p, 0, 561) * 1e6 * std::exp(-5.0 * (p.x + 0.4)); };
    const std::vector<Vec3> points{Vec3(0, 0, 0), Vec3(0, 0, 0.003), Vec3(0.02, 0.01, 0.001), Vec3(0, 0, 0.008), Vec3(-0.02, 0, 0.015)};
    expectFieldMatchesSubPaths(tracer, points, fieldAt(scene, points, sheetBox(0.0005), 400000, 8), unscattered);
}

// Beyond the fine box the far nodes (4 um along the axis) hold the light out to 60 um from the sheet, where
// the dye the objective sees out of focus is lit only by scattered light: the same sub-paths agree there.
TEST(ExcitationField, FarNodesAgreeWithTheExcitationSubPaths) {
    const Scene scene = sheetInTissue(5.0, 0.9);
    const PathTracer tracer(scene);
    FieldBox box = sheetBox(0.0005);
    box.halfZ = 0.01;
    box.farHalfZ = 0.06;
    box.farHz = 0.004;
    const std::vector<Vec3> points{Vec3(0, 0, 0.014), Vec3(0.01, 0, -0.03), Vec3(-0.02, 0.01, 0.055)};
    for (const Vec3& p : points) EXPECT_FALSE(box.contains(p)) << "the points lie beyond the fine box";
    expectFieldMatchesSubPaths(tracer, points, fieldAt(scene, points, box, 400000, 8), [](const Vec3&) { return 0.0; }, 600000);
}

}  // namespace
}  // namespace fluorosim

namespace fluorosim {
namespace {

// Tent tallies read by trilinear interpolation smooth the field twice with a hat of width h: an error
// O(h²). Tracks with a known fluence (parallel lines whose offsets across the sheet follow a normal density
// of deviation 1 um, placed at its quantiles, so without sampling noise) show it: the error at the peak
// falls by 4 when h halves (once h is below the profile's deviation).
TEST(ExcitationField, TentTalliesConvergeAsHSquared) {
    constexpr int kTracks = 20000;
    constexpr double kSigma = 0.001, kHeight = 0.06;
    auto exact = [&](double z) { return std::exp(-0.5 * z * z / (kSigma * kSigma)) / (std::sqrt(2 * kPi) * kSigma) / kHeight; };
    std::vector<double> errors;
    for (double hz : {0.001, 0.0005, 0.00025}) {
        FieldBox box;
        box.halfX = box.halfY = 0.02;
        box.halfZ = 0.01;
        box.hx = box.hy = 0.004;
        box.hz = hz;
        FluenceGrid grid(box);
        for (int k = 0; k < kTracks; ++k) {
            double pdf = 0;
            const double z = sampleTruncatedNormal((k + 0.5) / kTracks, 0.0, kSigma, -8 * kSigma, 8 * kSigma, &pdf);
            const double y = kHeight * ((k * 0.6180339887498949 - std::floor(k * 0.6180339887498949)) - 0.5);
            grid.deposit(Vec3(-0.05, y, z), Vec3(0.05, y, z), 1.0 / kTracks);
        }
        grid.normalise(1.0);
        errors.push_back(grid.at(Vec3(0.001, 0.002, 0)) / exact(0) - 1);
    }
    std::printf("  relative error at the peak for h = 1, 0.5, 0.25 um: %.4g %.4g %.4g (ratios %.2f, %.2f)\n", errors[0], errors[1], errors[2],
                errors[0] / errors[1], errors[1] / errors[2]);
    for (int i = 0; i < 2; ++i) {
        EXPECT_GT(errors[i] / errors[i + 1], 3.5);
        EXPECT_LT(errors[i] / errors[i + 1], 4.5);
    }
}

// On the traced field (the same photons tallied at three axial spacings) the resolution error at the
// sheet's plane is far below its noise: the spacing the microscope uses, 0.5 um across a 3 um waist, is
// not what limits it.
TEST(ExcitationField, ResolutionErrorOfTheTracedFieldIsSmall) {
    const Scene scene = sheetInTissue(5.0, 0.9);
    const std::vector<BeamLineSide> lines = beamLineSides(scene.lights);
    FluenceOptions o;
    o.photons = 1000000;
    std::vector<double> phi;
    for (double hz : {0.002, 0.001, 0.0005}) {
        const BeamExcitationField field({traceBeamFluence(scene, lines.at(0), sheetBox(hz), o)});
        double v = 0;  // averaged along the sheet over a line of points, to average the tallies' noise
        for (int i = -10; i <= 10; ++i) v += *field.scatteredMeanRadiance(Vec3(0.002 * i, 0, 0), 561) / 21;
        phi.push_back(v);
    }
    std::printf("  phi at h = 2, 1, 0.5 um: %.6g %.6g %.6g\n", phi[0], phi[1], phi[2]);
    EXPECT_LT(std::abs(phi[0] / phi[2] - 1), 0.005);
    EXPECT_LT(std::abs(phi[1] / phi[2] - 1), 0.003);
}

// Along the focal plane the scattered light varies on the scattering length and near the sheet's height
// edges, not on its waist: nodes 16 um apart read the same field as 4 um ones far from an edge, with less
// noise, and read it low within a node or two of an edge (why the microscope takes coarse nodes only where the
// sheet's light per unit height is flat over the box grown by two nodes: optics/acquisition.cpp). Four seeds
// of 10^6 photons per spacing, read at the sheet's plane on lines along the beam at y = 0, 20 and 40 um of a
// 100 um top-hat (edge at 50 um).
TEST(ExcitationField, CoarseLateralNodesReadTheSameFieldAwayFromTheSheetsEdges) {
    const Scene scene = sheetInTissue(5.0, 0.9);
    const std::vector<BeamLineSide> lines = beamLineSides(scene.lights);
    constexpr int kSeeds = 4, kPoints = 21;
    std::array<std::array<Estimate, 3>, 2> at{};  // [spacing 16, 4 um][y]: the line's mean and its standard error
    std::array<double, 2> pointNoise{};             // one field's relative standard deviation at a point (y = 0, 20 um)
    for (int s = 0; s < 2; ++s) {
        std::array<std::array<std::array<double, kPoints>, 3>, kSeeds> v{};
        for (int seed = 0; seed < kSeeds; ++seed) {
            FluenceOptions o;
            o.photons = 1000000;
            o.seed = 7 + static_cast<uint64_t>(seed);
            FieldBox box = sheetBox(0.0005, s == 0 ? 0.016 : 0.004);
            box.halfY = 0.045;
            const BeamExcitationField field({traceBeamFluence(scene, lines.at(0), box, o)});
            for (size_t line = 0; line < 3; ++line)
                for (int i = 0; i < kPoints; ++i)
                    v[static_cast<size_t>(seed)][line][static_cast<size_t>(i)] =
                        *field.scatteredMeanRadiance(Vec3(0.0025 * (i - kPoints / 2), 0.02 * static_cast<double>(line), 0), 561);
        }
        double pooled = 0, mean01 = 0;
        for (size_t line = 0; line < 3; ++line) {
            std::array<double, kSeeds> lineMean{};
            for (size_t seed = 0; seed < kSeeds; ++seed)
                for (double x : v[seed][line]) lineMean[seed] += x / kPoints;
            double m = 0, m2 = 0;
            for (double x : lineMean) m += x / kSeeds;
            for (double x : lineMean) m2 += (x - m) * (x - m);
            at[static_cast<size_t>(s)][line] = {m, std::sqrt(m2 / (kSeeds - 1) / kSeeds)};
            if (line == 2) continue;
            for (int i = 0; i < kPoints; ++i) {  // the spread over seeds at each point, pooled over the points
                double pm = 0;
                for (size_t seed = 0; seed < kSeeds; ++seed) pm += v[seed][line][static_cast<size_t>(i)] / kSeeds;
                for (size_t seed = 0; seed < kSeeds; ++seed) pooled += sqr(v[seed][line][static_cast<size_t>(i)] - pm) / (kSeeds - 1) / (2 * kPoints);
                mean01 += pm / (2 * kPoints);
            }
        }
        pointNoise[static_cast<size_t>(s)] = std::sqrt(pooled) / mean01;
    }
    for (size_t line = 0; line < 3; ++line)
        std::printf("  y = %2d um: phi %.1f +- %.1f at 16 um, %.1f +- %.1f at 4 um\n", int(20 * line), at[0][line].mean, at[0][line].stderr,
                    at[1][line].mean, at[1][line].stderr);
    std::printf("  one field's noise at a point (y = 0, 20 um): %.2f %% at 16 um, %.2f %% at 4 um\n", 100 * pointNoise[0], 100 * pointNoise[1]);
    for (size_t line = 0; line < 2; ++line) {
        const double sigma = std::hypot(at[0][line].stderr, at[1][line].stderr);
        EXPECT_LT(std::abs(at[0][line].mean - at[1][line].mean), 4 * sigma);
        EXPECT_LT(sigma, 0.02 * at[1][line].mean) << "the comparison must be sharp";
    }
    // Where the field is flat, coarse nodes read it with less noise: about 4 times more tracks cross a node's
    // support along the sheet's height.
    EXPECT_LT(pointNoise[0], 0.6 * pointNoise[1]);
    // 10 um inside the edge the coarse nodes smooth the edge into the field (measured: 11 % low).
    EXPECT_LT(at[0][2].mean, 0.95 * at[1][2].mean);
}

// In strongly scattering tissue (σs 20 /mm, g 0.9, the sheet 400 um in) much of the light near the sheet has
// scattered ten times and more. The same photons (six seeds) tallied with that light on 50 um diffuse nodes
// (FieldBox::diffuseH) and on the fine and far nodes alone read the same field, averaged along lines of 21
// points 50 um long in and beyond the fine box: their paired difference is within 4 of its standard errors of 0
// plus 1 % of the field (the diffuse nodes' stated resolution error; measured up to 0.6 %, 40 um from the sheet
// where the field curves most within a node), and those are within 5 % of the field. Whether they lower the
// noise depends on what is read: at a point on the sheet's plane the light that scattered a few times (still on
// fine nodes) is most of the noise, and a field far from the sheet's entry is limited by how many photons arrive
// at all; over a small bright structure 1 mm from it they do (docs/performance.md). The noise is printed.
TEST(ExcitationField, DiffuseNodesReadTheSameField) {
    const Scene scene = sheetInTissue(20.0, 0.9);
    const std::vector<BeamLineSide> lines = beamLineSides(scene.lights);
    FieldBox box = sheetBox(0.0005);
    box.halfZ = 0.01;
    box.farHalfZ = 0.06;
    box.farHz = 0.004;
    const std::vector<Vec3> points{Vec3(0, 0, 0), Vec3(0, 0.01, 0.005), Vec3(0, 0, 0.014), Vec3(0, -0.01, -0.04)};  // the lines' centres
    constexpr int kSeeds = 6;
    // [without, with the diffuse nodes][point][seed]
    std::array<std::vector<std::array<double, kSeeds>>, 2> v{std::vector<std::array<double, kSeeds>>(points.size()),
                                                           std::vector<std::array<double, kSeeds>>(points.size())};
    auto centre = v;  // at the lines' centres alone
    for (int seed = 0; seed < kSeeds; ++seed)
        for (int d = 0; d < 2; ++d) {
            FieldBox b = box;
            b.diffuseH = d == 0 ? 0.0 : 0.05;
            FluenceOptions o;
            o.photons = 400000;
            o.seed = 100 + static_cast<uint64_t>(seed);
            const BeamExcitationField field({traceBeamFluence(scene, lines.at(0), b, o)});
            for (size_t i = 0; i < points.size(); ++i)
                for (int k = -10; k <= 10; ++k) {
                    const double phi = *field.scatteredMeanRadiance(points[i] + Vec3(0.0025 * k, 0, 0), 561);
                    v[static_cast<size_t>(d)][i][static_cast<size_t>(seed)] += phi / 21;
                    if (k == 0) centre[static_cast<size_t>(d)][i][static_cast<size_t>(seed)] = phi;
                }
        }
    auto meanAndError = [](const std::array<double, kSeeds>& x) {
        double m = 0, m2 = 0;
        for (double a : x) m += a / kSeeds;
        for (double a : x) m2 += sqr(a - m);
        return Estimate{m, std::sqrt(m2 / (kSeeds - 1) / kSeeds)};
    };
    for (size_t i = 0; i < points.size(); ++i) {
        std::array<double, kSeeds> difference{};
        for (size_t s = 0; s < kSeeds; ++s) difference[s] = v[1][i][s] - v[0][i][s];
        const Estimate plain = meanAndError(v[0][i]), diffuse = meanAndError(v[1][i]), d = meanAndError(difference);
        std::printf("  (%+.3f, %+.3f, %+.4f) mm%s: phi %.5g +- %.2g without diffuse nodes, %.5g +- %.2g with; difference %+.3g +- %.2g (%+.2f %%)\n",
                    points[i].x, points[i].y, points[i].z, box.contains(points[i]) ? "" : " (far nodes)", plain.mean, plain.stderr, diffuse.mean,
                    diffuse.stderr, d.mean, d.stderr, 100 * d.mean / plain.mean);
        EXPECT_LT(std::abs(d.mean), 4 * d.stderr + 0.01 * plain.mean);
        EXPECT_LT(4 * d.stderr, 0.05 * plain.mean) << "the comparison must be sharp";
        const Estimate a = meanAndError(centre[0][i]), b = meanAndError(centre[1][i]);
        std::printf("    at its centre: relative standard error %.2f %% without, %.2f %% with\n", 100 * a.stderr / a.mean, 100 * b.stderr / b.mean);
    }
}

// The field's own noise, from half the difference of its halves (BeamExcitationField::scatteredByCore,
// on the fine nodes and on the far ones): over 32 independent fields, at points in and beyond the fine box,
// the mean of its square against the variance of the fields there. With 32 fields each ratio's 4σ range is
// about [0.4, 2.5] (F distribution, 32 and 31 degrees of freedom).
TEST(ExcitationField, HalfDifferenceEstimatesTheFieldsSpread) {
    const Scene scene = sheetInTissue(5.0, 0.9);
    FieldBox box = sheetBox(0.0005);
    box.halfZ = 0.01;
    box.farHalfZ = 0.06;
    box.farHz = 0.004;
    const std::vector<Vec3> points{Vec3(0, 0, 0), Vec3(0.01, 0.005, 0.003), Vec3(0, 0, 0.014), Vec3(0.01, 0, -0.03), Vec3(-0.02, 0.01, 0.055)};
    const std::vector<BeamLineSide> lines = beamLineSides(scene.lights);
    constexpr int kFields = 32;
    std::vector<double> sum(points.size()), sum2(points.size()), halfDifference2(points.size());
    for (int s = 0; s < kFields; ++s) {
        FluenceOptions o;
        o.photons = 20000;
        o.seed = 300 + static_cast<uint64_t>(s);
        const BeamExcitationField field({traceBeamFluence(scene, lines.at(0), box, o)});
        for (size_t i = 0; i < points.size(); ++i) {
            const auto parts = *field.scatteredByCore(points[i], 561);
            const double v = *field.scatteredMeanRadiance(points[i], 561), d = parts.core.halfDifference + parts.outside.halfDifference;
            sum[i] += v;
            sum2[i] += v * v;
            halfDifference2[i] += d * d / kFields;
        }
    }
    for (size_t i = 0; i < points.size(); ++i) {
        const double mean = sum[i] / kFields, variance = (sum2[i] - kFields * mean * mean) / (kFields - 1);
        const double ratio = halfDifference2[i] / variance;
        std::printf("  (%+.3f, %+.3f, %+.4f) mm%s: field %.4g, spread %.3g, half difference %.3g: ratio %.2f\n", points[i].x, points[i].y, points[i].z,
                    box.contains(points[i]) ? "" : " (far nodes)", mean, std::sqrt(variance), std::sqrt(halfDifference2[i]), ratio);
        ASSERT_GT(variance, 0);
        EXPECT_GT(ratio, 0.4);
        EXPECT_LT(ratio, 2.5);
    }
}

}  // namespace
}  // namespace fluorosim
