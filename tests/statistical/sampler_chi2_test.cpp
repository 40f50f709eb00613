// Chi-square goodness-of-fit tests: every sampler draws from exactly the pdf it reports.
// Each TEST is one family at significance chi2::kFamilyAlpha, split over its cases (Sidak).
// Seeds are fixed, so the outcome is deterministic; 1e6 samples per case resolve pdf errors of a
// few percent (see Chi2Harness.* for the harness rejecting such errors).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <optional>
#include <string>
#include <vector>

#include "core/math.h"
#include "core/rng.h"
#include "core/exponential.h"
#include "core/sampling.h"
#include "materials/fresnel.h"
#include "materials/material.h"
#include "media/free_flight.h"
#include "media/henyey_greenstein.h"
#include "scene/light_sampler.h"
#include "scene/scene.h"
#include "spectral/wavelength_sampler.h"
#include "statistical/chi2.h"

namespace fluorosim {
namespace {

using chi2::DirSample;
using chi2::DirectionalResult;
using chi2::DirectionalTest;
using chi2::SphericalGrid;

// Inverse-CDF exponential distance with rate sigma, for the harness's deliberately wrong sampler.
double sampleExponential(double u, double sigma) { return -std::log(1.0 - u) / sigma; }

double relDiff(double a, double b) {
    const double s = std::max(std::abs(a), std::abs(b));
    return s > 0 ? std::abs(a - b) / s : 0.0;
}

Vec3 sphericalDirection(double thetaDeg, double phi) {
    const double t = thetaDeg * kPi / 180.0;
    return {std::sin(t) * std::cos(phi), std::sin(t) * std::sin(phi), std::cos(t)};
}

void logResult(const std::string& name, const std::string& summary) { std::printf("[chi2] %s: %s\n", name.c_str(), summary.c_str()); }

// The checks every directional case shares. `canFail`: the sampler may return nullopt.
void expectMatches(const std::string& name, const DirectionalResult& r, double alpha, bool canFail) {
    logResult(name, r.summary());
    EXPECT_TRUE(r.chi2.accept(alpha)) << name << " rejected at alpha = " << alpha << ": " << r.summary() << "\n"
                                      << r.table();
    EXPECT_EQ(r.pdfMismatches, 0u) << name << ": " << r.summary();
    EXPECT_EQ(r.outside, 0u) << name << ": " << r.summary();
    EXPECT_EQ(r.nonFinite, 0u) << name << ": " << r.summary();
    // Cubature error (a pessimistic estimate, summed over all cells) below 30 expected samples: cells
    // hold 1e3 .. 1e5 samples, so this is a small fraction of one standard deviation per cell.
    EXPECT_LE(r.integration.errorEstimate * static_cast<double>(r.total), 30.0) << name << ": " << r.summary();
    if (canFail) {
        // The pdf integrates to the probability of success (the failure cell tests this too).
        EXPECT_NEAR(r.pdfIntegral, r.successFraction(), 5 * r.successStderr() + 1e-6) << name << ": " << r.summary();
    } else {
        EXPECT_EQ(r.successes, r.total) << name;
        EXPECT_NEAR(r.pdfIntegral, 1.0, 1e-5) << name << ": " << r.summary();
    }
}

// ------------------------------------------------------------------------------------------------
// The harness itself: it accepts a correct sampler and rejects wrong pdfs.

TEST(Chi2Harness, SidakAndPooling) {
    EXPECT_NEAR(chi2::sidak(1e-4, 1), 1e-4, 1e-16);
    EXPECT_NEAR(chi2::sidak(1e-4, 10), 1e-5, 1e-9);
    EXPECT_GT(chi2::sidak(1e-4, 10), 1e-5);  // slightly above Bonferroni's alpha / k

    // Exact agreement: statistic 0, p = 1. The three small cells are pooled into one.
    const std::vector<double> exp1 = {100, 200, 1, 2, 3, 300};
    const auto r1 = chi2::chiSquare(exp1, exp1);
    EXPECT_TRUE(r1.error.empty());
    EXPECT_EQ(r1.pooledCells, 3);
    EXPECT_EQ(r1.cells, 4);
    EXPECT_EQ(r1.dof, 3);
    EXPECT_NEAR(r1.pValue, 1.0, 1e-12);

    // Against a tabulated quantile: chi2(dof = 3) exceeds 16.266 with probability 1e-3.
    const std::vector<double> obs2 = {100, 100, 100, 100 + std::sqrt(16.266 * 100)};
    const std::vector<double> exp2 = {100, 100, 100, 100};
    EXPECT_NEAR(chi2::chiSquare(obs2, exp2).pValue, 1e-3, 2e-6);

    // Samples where none are expected reject outright.
    const std::vector<double> obs3 = {100, 100, 1}, exp3 = {100.5, 100.5, 0};
    const auto r3 = chi2::chiSquare(obs3, exp3);
    EXPECT_FALSE(r3.error.empty());
    EXPECT_FALSE(r3.accept(1e-300));
}

// HG sampled with g = 0.5 but evaluated with g = 0.45.
TEST(Chi2Harness, RejectsWrongHgPdf) {
    const HenyeyGreenstein sampled(0.5), claimed(0.45);
    const Vec3 dirIn = normalize(Vec3(0.3, -0.5, 0.8));
    DirectionalTest t;
    t.name = "HG g=0.5 vs pdf g=0.45";
    t.sample = [&](Rng& rng) -> std::optional<DirSample> {
        const double u1 = rng.uniform(), u2 = rng.uniform();
        return DirSample{sampled.sample(dirIn, u1, u2)};
    };
    t.pdf = [&](const Vec3& w) { return claimed.pdf(dirIn, w); };
    t.seed = 7;
    const auto r = chi2::runDirectional(t);
    logResult(t.name, r.summary());
    EXPECT_FALSE(r.chi2.accept(chi2::kFamilyAlpha)) << r.summary();
    EXPECT_LT(r.chi2.pValue, 1e-12);
    EXPECT_NEAR(r.pdfIntegral, 1.0, 1e-6);  // a normalized but wrong pdf
}

// A subtle mismatch: cosine-weighted sampling against the normalized density of cos^1.05, which
// differs by -3% .. +2.5% over most of the hemisphere.
TEST(Chi2Harness, RejectsFewPercentDirectionalMismatch) {
    DirectionalTest t;
    t.name = "cosine sampling vs cos^1.05 pdf";
    t.grid.cosMin = 0;
    t.sample = [](Rng& rng) -> std::optional<DirSample> {
        const double u1 = rng.uniform(), u2 = rng.uniform();
        return DirSample{sampleCosineHemisphere(u1, u2)};
    };
    t.pdf = [](const Vec3& w) { return w.z > 0 ? 2.05 / (2 * kPi) * std::pow(w.z, 1.05) : 0.0; };
    t.seed = 8;
    const auto r = chi2::runDirectional(t);
    logResult(t.name, r.summary());
    EXPECT_FALSE(r.chi2.accept(chi2::kFamilyAlpha)) << r.summary();
    EXPECT_NEAR(r.pdfIntegral, 1.0, 1e-6);
}

// 1-D: exponential distances with rate 2 against the density of rate 2.04 (2% off).
TEST(Chi2Harness, RejectsTwoPercentRateMismatch) {
    const double sigma = 2.0, claimed = 2.04;
    const auto edges = chi2::uniformEdges(0, 3, 60);
    std::vector<double> obs(edges.size(), 0.0);  // bins + tail
    Rng rng(9, 1);
    const int n = 1'000'000;
    for (int i = 0; i < n; ++i) {
        const double t = sampleExponential(rng.uniform(), sigma);
        const int b = chi2::binIndex(edges, t);
        obs[b < 0 ? obs.size() - 1 : static_cast<size_t>(b)] += 1;
    }
    const auto cdf = [&](double x) { return -std::expm1(-claimed * x); };
    auto expected = chi2::expectedFromCdf(edges, cdf, n);
    expected.push_back(n * std::exp(-claimed * edges.back()));
    const auto r = chi2::chiSquare(obs, expected);
    logResult("exponential rate 2 vs 2.04", r.summary());
    EXPECT_FALSE(r.accept(chi2::kFamilyAlpha)) << r.summary();
}

// ------------------------------------------------------------------------------------------------
// Phase function.

TEST(Chi2HenyeyGreenstein, SamplesItsPdf) {
    const std::vector<double> gs = {-0.9, -0.5, 0.0, 1e-7, 0.3, 0.9, 0.99};
    const double alpha = chi2::sidak(chi2::kFamilyAlpha, static_cast<int>(gs.size()));
    for (size_t k = 0; k < gs.size(); ++k) {
        const HenyeyGreenstein hg(gs[k]);
        // Off-axis incoming directions, alternating in the upper and lower half (both branches of
        // the frame construction).
        const Vec3 dirIn = k % 2 == 0 ? normalize(Vec3(0.3, -0.5, 0.8)) : normalize(Vec3(-0.48, 0.6, -0.64));
        DirectionalTest t;
        t.name = "HG g=" + std::to_string(gs[k]);
        t.sample = [&](Rng& rng) -> std::optional<DirSample> {
            const double u1 = rng.uniform(), u2 = rng.uniform();
            double pdf = -1;
            const Vec3 w = hg.sample(dirIn, u1, u2, &pdf);
            return DirSample{w, pdf};
        };
        t.pdf = [&](const Vec3& w) { return hg.pdf(dirIn, w); };
        t.seed = 1000 + k;
        expectMatches(t.name, chi2::runDirectional(t), alpha, false);
    }
}

// ------------------------------------------------------------------------------------------------
// Warps in core/sampling.h.

TEST(Chi2Sampling, CosineHemisphere) {
    DirectionalTest t;
    t.name = "cosine hemisphere";
    t.grid.cosMin = 0;
    t.sample = [](Rng& rng) -> std::optional<DirSample> {
        const double u1 = rng.uniform(), u2 = rng.uniform();
        const Vec3 w = sampleCosineHemisphere(u1, u2);
        return DirSample{w, cosineHemispherePdf(w.z)};
    };
    t.pdf = [](const Vec3& w) { return cosineHemispherePdf(w.z); };
    t.seed = 11;
    expectMatches(t.name, chi2::runDirectional(t), chi2::kFamilyAlpha, false);
}

TEST(Chi2Sampling, UniformSphere) {
    DirectionalTest t;
    t.name = "uniform sphere";
    t.sample = [](Rng& rng) -> std::optional<DirSample> {
        const double u1 = rng.uniform(), u2 = rng.uniform();
        return DirSample{sampleUniformSphere(u1, u2), uniformSpherePdf()};
    };
    t.pdf = [](const Vec3&) { return uniformSpherePdf(); };
    t.seed = 12;
    expectMatches(t.name, chi2::runDirectional(t), chi2::kFamilyAlpha, false);
}

// cos(phi) for phi uniform (the slab kernel's azimuth): the arcsine density 1 / (pi sqrt(1 - x^2)),
// CDF 1 - acos(x) / pi.
TEST(Chi2Sampling, CosUniformAzimuth) {
    const auto edges = chi2::uniformEdges(-1, 1, 50);
    std::vector<double> obs(edges.size() - 1, 0.0);
    Rng rng(13, 4);
    const int n = 1'000'000;
    int outside = 0;
    for (int i = 0; i < n; ++i) {
        const double x = sampleCosUniformAzimuth(rng);
        const int b = x == 1.0 ? static_cast<int>(obs.size()) - 1 : chi2::binIndex(edges, x);
        if (b < 0) {
            ++outside;
            continue;
        }
        obs[static_cast<size_t>(b)] += 1;
    }
    const auto expected = chi2::expectedFromCdf(edges, [](double x) { return 1 - std::acos(std::clamp(x, -1.0, 1.0)) / kPi; }, n);
    const auto r = chi2::chiSquare(obs, expected);
    logResult("cos of uniform azimuth", r.summary());
    EXPECT_EQ(outside, 0);
    EXPECT_TRUE(r.accept(chi2::kFamilyAlpha)) << r.summary();
}

// Standard exponential by the ziggurat: bins over [0, 12) (past the tail start r = 7.7, so strip,
// wedge and tail paths are all exercised) plus the tail beyond 12, against the CDF 1 - exp(-x).
TEST(Chi2Sampling, ZigguratExponential) {
    std::vector<double> edges = chi2::uniformEdges(0, 12, 96);
    edges.push_back(1e300);
    std::vector<double> obs(edges.size() - 1, 0.0);
    Rng rng(15, 4);
    const int n = 4'000'000;
    double sum = 0;
    for (int i = 0; i < n; ++i) {
        const double x = sampleStandardExponential(rng);
        ASSERT_GE(x, 0.0);
        sum += x;
        obs[static_cast<size_t>(chi2::binIndex(edges, x))] += 1;
    }
    const auto expected = chi2::expectedFromCdf(edges, [](double x) { return x > 1e299 ? 1.0 : -std::expm1(-x); }, n);
    const auto r = chi2::chiSquare(obs, expected);
    logResult("ziggurat exponential", r.summary());
    EXPECT_TRUE(r.accept(chi2::kFamilyAlpha)) << r.summary();
    EXPECT_NEAR(sum / n, 1.0, 4.0 / std::sqrt(n));  // mean 1, standard deviation 1
}

// Discrete sampling: index i with probability w_i / sum (zero weights never), the reported pmf, and
// the remapped u uniform on [0, 1) (it is reused for the next decision).
TEST(Chi2Sampling, Discrete) {
    const std::vector<double> w = {0.5, 0.0, 2.0, 1e-3, 3.0, 0.0, 0.25};
    const double total = 5.751;
    std::vector<double> obs(w.size(), 0.0);
    const auto edges = chi2::uniformEdges(0, 1, 40);
    std::vector<double> remapObs(edges.size() - 1, 0.0);
    Rng rng(14, 4);
    const int n = 1'000'000;
    int badPmf = 0, badRemap = 0;
    for (int k = 0; k < n; ++k) {
        double pmf = -1, ur = -1;
        const int i = sampleDiscrete(w, rng.uniform(), &pmf, &ur);
        ASSERT_GE(i, 0);
        obs[static_cast<size_t>(i)] += 1;
        if (relDiff(pmf, w[static_cast<size_t>(i)] / total) > 1e-12) ++badPmf;
        const int b = chi2::binIndex(edges, ur);
        if (b < 0) {
            ++badRemap;
            continue;
        }
        remapObs[static_cast<size_t>(b)] += 1;
    }
    std::vector<double> expected;
    for (double x : w) expected.push_back(n * x / total);
    const auto r = chi2::chiSquare(obs, expected);
    const auto rr = chi2::chiSquare(remapObs, std::vector<double>(remapObs.size(), n / 40.0));
    logResult("sampleDiscrete index", r.summary());
    logResult("sampleDiscrete remapped u", rr.summary());
    const double alpha = chi2::sidak(chi2::kFamilyAlpha, 2);
    EXPECT_TRUE(r.accept(alpha)) << r.summary();
    EXPECT_TRUE(rr.accept(alpha)) << rr.summary();
    EXPECT_EQ(badPmf, 0);
    EXPECT_EQ(badRemap, 0);
}

// ------------------------------------------------------------------------------------------------
// Free-flight distances through sampleTmaj.

// A majorant iterator over given (contiguous) segments.
struct SegmentsIterator {
    std::vector<MajorantSegment<double>> segments;
    size_t next_ = 0;
    std::optional<MajorantSegment<double>> next() {
        if (next_ >= segments.size()) return std::nullopt;
        return segments[next_++];
    }
};

// Optical depth from segments.front().tMin to t.
double opticalDepth(const std::vector<MajorantSegment<double>>& segs, double t) {
    double tau = 0;
    for (const auto& s : segs) {
        if (t <= s.tMin) break;
        if (s.sigmaMaj > 0) tau += s.sigmaMaj * (std::min(t, s.tMax) - s.tMin);
    }
    return tau;
}

// The first tentative collision of sampleTmaj has density sigma(t) exp(-tau(t)) on the segments,
// and "no collision" has probability exp(-tau(end)). Also checks the T_maj and sigma_maj handed to
// the callback and the returned T_maj.
template <class Iter>
void testFirstCollision(const std::string& name, const Iter& prototype, const std::vector<MajorantSegment<double>>& segs,
                        uint64_t seed) {
    const double t0 = segs.front().tMin, tEnd = segs.back().tMax;
    const auto edges = chi2::uniformEdges(t0, tEnd, 60);
    const size_t bins = edges.size() - 1, noCollision = bins;
    std::vector<double> obs(bins + 1, 0.0);
    const auto survival = [&](double t) { return std::exp(-opticalDepth(segs, t)); };
    const auto sigmaAt = [&](double t) {
        for (const auto& s : segs)
            if (t >= s.tMin && t < s.tMax) return s.sigmaMaj;
        return -1.0;
    };
    Rng rng(seed, 3);
    const int n = 1'000'000;
    int badT = 0, badSigma = 0, badReturn = 0, outside = 0;
    double worstT = 0;
    for (int i = 0; i < n; ++i) {
        double tHit = -1, sigmaHit = 0, tmajHit = 0;
        const double ret = sampleTmaj<double>(prototype, rng, [&](double t, double sigma, double tmaj) {
            tHit = t;
            sigmaHit = sigma;
            tmajHit = tmaj;
            return false;
        });
        if (tHit < 0) {
            obs[noCollision] += 1;
            if (relDiff(ret, survival(tEnd)) > 1e-9) ++badReturn;
            continue;
        }
        if (ret != 1.0) ++badReturn;
        const int b = chi2::binIndex(edges, tHit);
        if (b < 0) {
            ++outside;
            continue;
        }
        obs[static_cast<size_t>(b)] += 1;
        if (sigmaHit != sigmaAt(tHit)) ++badSigma;
        const double rel = relDiff(tmajHit, survival(tHit));
        if (rel > 1e-9) ++badT;
        worstT = std::max(worstT, rel);
    }
    auto expected = chi2::expectedFromCdf(edges, [&](double t) { return -survival(t); }, n);
    expected.push_back(n * survival(tEnd));
    const auto r = chi2::chiSquare(obs, expected);
    logResult(name, r.summary() + ", no-collision " + std::to_string(obs[noCollision]) + " vs " +
                  std::to_string(expected[noCollision]));
    EXPECT_TRUE(r.accept(chi2::kFamilyAlpha)) << name << ": " << r.summary();
    EXPECT_EQ(outside, 0) << name;
    EXPECT_EQ(badSigma, 0) << name << ": sigma_maj handed to the callback is not the segment's";
    EXPECT_EQ(badT, 0) << name << ": T_maj at the collision differs from exp(-tau) (worst rel " << worstT << ")";
    EXPECT_EQ(badReturn, 0) << name << ": returned T_maj";
}

TEST(Chi2FreeFlight, HomogeneousFromZero) {
    const double sigma = 2.0, tMax = 1.5;  // P(no collision) = e^-3
    testFirstCollision("homogeneous [0, 1.5) sigma 2", HomogeneousMajorantIterator<double>(0.0, tMax, sigma),
                       {{0.0, tMax, sigma}}, 21);
}

TEST(Chi2FreeFlight, HomogeneousOffset) {
    const double sigma = 0.7, tMin = 0.4, tMax = 3.0;
    testFirstCollision("homogeneous [0.4, 3) sigma 0.7", HomogeneousMajorantIterator<double>(tMin, tMax, sigma),
                       {{tMin, tMax, sigma}}, 22);
}

TEST(Chi2FreeFlight, PiecewiseMajorants) {
    const std::vector<MajorantSegment<double>> segs = {{0.0, 0.5, 1.0}, {0.5, 1.2, 3.0}, {1.2, 2.0, 0.5}};
    testFirstCollision("segments sigma 1, 3, 0.5", SegmentsIterator{segs}, segs, 23);
}

// A zero-majorant segment is skipped: no collisions there, and the density resumes after it.
TEST(Chi2FreeFlight, PiecewiseWithEmptySegment) {
    const std::vector<MajorantSegment<double>> segs = {{0.2, 0.8, 2.0}, {0.8, 1.4, 0.0}, {1.4, 2.0, 4.0}};
    testFirstCollision("segments sigma 2, 0, 4", SegmentsIterator{segs}, segs, 24);
}

// ------------------------------------------------------------------------------------------------
// Wavelengths.

// Histograms of each of the 4 slots over [lo, hi) plus one cell per line.
struct WavelengthCounts {
    std::vector<double> edges;
    std::vector<std::vector<double>> slot;  // [slot][bin]
    std::vector<double> lineCounts;
    int badContinuousPdf = 0, badLine = 0, badStratification = 0, discreteFlagWrong = 0;
};

WavelengthCounts sampleWavelengths(const WavelengthSampler& ws, const std::vector<double>& lines, int n, uint64_t seed) {
    const double lo = ws.lambdaMin(), hi = ws.lambdaMax(), range = hi - lo;
    WavelengthCounts c;
    c.edges = chi2::uniformEdges(lo, hi, 50);
    c.slot.assign(kNumWavelengths, std::vector<double>(50, 0.0));
    c.lineCounts.assign(lines.size(), 0.0);
    const double contPdf = (1 - ws.lineProbability()) / range;
    Rng rng(seed, 5);
    for (int k = 0; k < n; ++k) {
        const double uBranch = rng.uniform(), u = rng.uniform();
        const SampledWavelengths wl = ws.sample(uBranch, u);
        const auto line = std::find(lines.begin(), lines.end(), wl.lambda[0]);
        if (wl.discrete) {
            bool ok = line != lines.end();
            for (int i = 0; i < kNumWavelengths; ++i)
                ok = ok && wl.lambda[i] == wl.lambda[0] && relDiff(wl.pdf[i], ws.lineMass()) < 1e-12;
            if (!ok) {
                ++c.badLine;
                continue;
            }
            c.lineCounts[static_cast<size_t>(line - lines.begin())] += 1;
            continue;
        }
        for (int i = 0; i < kNumWavelengths; ++i) {
            if (relDiff(wl.pdf[i], contPdf) > 1e-12) ++c.badContinuousPdf;
            const int b = chi2::binIndex(c.edges, wl.lambda[i]);
            if (b >= 0) c.slot[static_cast<size_t>(i)][static_cast<size_t>(b)] += 1;
            // Stratified: slot i + 1 sits a quarter of the range after slot i (cyclically).
            double d = wl.lambda[(i + 1) % kNumWavelengths] - wl.lambda[i];
            if (d < 0) d += range;
            if (std::abs(d - range / kNumWavelengths) > 1e-9 * range) ++c.badStratification;
        }
    }
    return c;
}

TEST(Chi2Wavelength, ContinuousSlotsUniformAndStratified) {
    const WavelengthSampler ws(360, 830, {}, true);
    EXPECT_EQ(ws.lineProbability(), 0.0);
    const int n = 1'000'000;
    const auto c = sampleWavelengths(ws, {}, n, 31);
    EXPECT_EQ(c.badContinuousPdf, 0);
    EXPECT_EQ(c.badStratification, 0);
    EXPECT_EQ(c.badLine, 0);
    const double alpha = chi2::sidak(chi2::kFamilyAlpha, kNumWavelengths);
    for (int i = 0; i < kNumWavelengths; ++i) {
        // Expected counts from the reported density 1 / range, integrated over each bin.
        const auto expected = chi2::expectedFromCdf(c.edges, [&](double l) { return (l - 360.0) / 470.0; }, n);
        const auto r = chi2::chiSquare(c.slot[static_cast<size_t>(i)], expected);
        logResult("wavelength slot " + std::to_string(i), r.summary());
        EXPECT_TRUE(r.accept(alpha)) << "slot " << i << ": " << r.summary();
    }
}

// Lines plus a continuum: half the samples go to lines, split evenly; the rest are uniform.
TEST(Chi2Wavelength, LinesAndContinuum) {
    const std::vector<double> requested = {546.1, 404.7, 700.0, 546.1};  // unsorted, one duplicate
    const std::vector<double> lines = {404.7, 546.1, 700.0};
    const WavelengthSampler ws(380, 780, requested, true);
    EXPECT_EQ(ws.lineProbability(), 0.5);
    EXPECT_NEAR(ws.lineMass(), 0.5 / 3, 1e-15);
    // Probabilities add up: line masses plus the continuous density integrated over the range.
    const double contPdf = (1 - ws.lineProbability()) / (ws.lambdaMax() - ws.lambdaMin());
    EXPECT_NEAR(ws.lineMass() * 3 + contPdf * (ws.lambdaMax() - ws.lambdaMin()), 1.0, 1e-12);

    const int n = 1'000'000;
    const auto c = sampleWavelengths(ws, lines, n, 32);
    EXPECT_EQ(c.badContinuousPdf, 0);
    EXPECT_EQ(c.badStratification, 0);
    EXPECT_EQ(c.badLine, 0);
    const double alpha = chi2::sidak(chi2::kFamilyAlpha, kNumWavelengths);
    for (int i = 0; i < kNumWavelengths; ++i) {
        // Cells: the 50 continuous bins of slot i, then one per line.
        std::vector<double> obs = c.slot[static_cast<size_t>(i)];
        auto expected =
            chi2::expectedFromCdf(c.edges, [&](double l) { return contPdf * (l - ws.lambdaMin()); }, n);
        for (size_t k = 0; k < lines.size(); ++k) {
            obs.push_back(c.lineCounts[k]);
            expected.push_back(ws.lineMass() * n);
        }
        const auto r = chi2::chiSquare(obs, expected);
        logResult("wavelength lines + continuum, slot " + std::to_string(i), r.summary());
        EXPECT_TRUE(r.accept(alpha)) << "slot " << i << ": " << r.summary();
    }
}

TEST(Chi2Wavelength, LinesOnly) {
    const std::vector<double> lines = {450.0, 532.0, 633.0};
    const WavelengthSampler ws(400, 700, lines, false);
    EXPECT_EQ(ws.lineProbability(), 1.0);
    const int n = 300'000;
    const auto c = sampleWavelengths(ws, lines, n, 33);
    EXPECT_EQ(c.badLine, 0);
    for (const auto& s : c.slot)
        for (double v : s) EXPECT_EQ(v, 0.0);  // nothing continuous
    const std::vector<double> expected(lines.size(), ws.lineMass() * n);
    const auto r = chi2::chiSquare(c.lineCounts, expected);
    logResult("wavelength lines only", r.summary());
    EXPECT_TRUE(r.accept(chi2::kFamilyAlpha)) << r.summary();
}

// ------------------------------------------------------------------------------------------------
// Light sampling: a (non-planar, unequal-triangle) quad and a sphere, seen from one point.

TEST(Chi2LightSampler, DirectionsHaveReportedDensity) {
    Scene scene;
    TriangleMesh quad;
    quad.positions = {{-1.0, -0.8, 0.6}, {1.2, -1.0, 0.4}, {0.9, 1.1, 0.7}, {-0.7, 0.9, 0.5}};
    quad.indices = {0, 2, 1, 0, 3, 2};  // normals towards -z, i.e. towards the reference point
    const uint32_t quadShape = scene.geometry.addMesh(quad);
    scene.shapes.push_back(ShapeInfo{"quad"});
    const Vec3 center(0.3, 0.2, -1.2);
    const double radius = 0.6;
    const uint32_t sphereShape = scene.geometry.addSphere(center, radius);
    scene.shapes.push_back(ShapeInfo{"sphere"});
    scene.addAreaLight(quadShape, AreaEmission{Spectrum::constant(1), false});
    scene.addAreaLight(sphereShape, AreaEmission{Spectrum::constant(1), false});
    scene.finalize();
    const LightSampler sampler(scene);
    const Vec3 ref(0.1, -0.05, 0.0);
    const SampledWavelengths wl = SampledWavelengths::sampleUniform(0.3, 400, 700);

    SphericalGrid grid;
    grid.nCos = 20;
    grid.nPhi = 40;

    // Expected cell probabilities. A direction's density is the sum of LightSampler::pdf over every
    // light point along it (for a sphere seen from outside, the pdf is zero on the far side, since only
    // the visible cap is sampled). Integrating over the light surfaces avoids the silhouette, where
    // the area-to-direction Jacobian is singular: P(cell) = sum over lights of the integral over the points x
    // whose direction lies in the cell of pdf(ref, x) * cos(x) / |x - ref|^2 dA(x).
    std::vector<double> prob(static_cast<size_t>(grid.cells()), 0.0);
    auto accumulate = [&](uint32_t shape, const Vec3& x, const Vec3& n, double dA) {
        const Vec3 d = x - ref;
        const double dist2 = dot(d, d);
        const double cosLight = std::abs(dot(n, d)) / std::sqrt(dist2);
        const double pdfArea = sampler.pdf(ref, shape, x, n) * cosLight / dist2;
        const int cell = grid.cellIndex(normalize(d));
        if (cell >= 0) prob[static_cast<size_t>(cell)] += pdfArea * dA;
    };
    {
        const int m = 700;  // each triangle split into m^2 congruent sub-triangles, midpoint rule
        for (size_t t = 0; t < quad.indices.size(); t += 3) {
            const Vec3 a = quad.positions[quad.indices[t]], b = quad.positions[quad.indices[t + 1]],
                       c = quad.positions[quad.indices[t + 2]];
            const Vec3 n = normalize(cross(b - a, c - a));
            const double dA = 0.5 * length(cross(b - a, c - a)) / (double(m) * m);
            auto at = [&](double u, double v) { return a + (b - a) * (u / m) + (c - a) * (v / m); };
            for (int i = 0; i < m; ++i)
                for (int j = 0; i + j < m; ++j) {
                    accumulate(quadShape, at(i + 1.0 / 3, j + 1.0 / 3), n, dA);
                    if (i + j + 1 < m) accumulate(quadShape, at(i + 2.0 / 3, j + 2.0 / 3), n, dA);
                }
        }
        const int mc = 1000, mp = 2000;
        const double dA = radius * radius * (2.0 / mc) * (2 * kPi / mp);
        for (int i = 0; i < mc; ++i) {
            const double z = -1 + (i + 0.5) * 2.0 / mc, s = safeSqrt(1 - z * z);
            for (int j = 0; j < mp; ++j) {
                const double phi = (j + 0.5) * 2 * kPi / mp;
                const Vec3 n(s * std::cos(phi), s * std::sin(phi), z);
                accumulate(sphereShape, center + n * radius, n, dA);
            }
        }
    }

    int badPdf = 0, badDir = 0, wrongShape = 0;
    double worst = 0;
    DirectionalTest t;
    t.name = "light sampler (quad + sphere)";
    t.grid = grid;
    t.sample = [&](Rng& rng) -> std::optional<DirSample> {
        const double ul = rng.uniform(), u1 = rng.uniform(), u2 = rng.uniform();
        const auto ls = sampler.sample(ref, ul, u1, u2, wl);
        if (!ls) return std::nullopt;
        if (ls->shape != quadShape && ls->shape != sphereShape) ++wrongShape;
        const double p = sampler.pdf(ref, ls->shape, ls->p, ls->n);
        const double rel = relDiff(p, ls->pdf);
        worst = std::max(worst, rel);
        if (rel > 1e-9) ++badPdf;
        if (length(ls->wi - normalize(ls->p - ref)) > 1e-12 || relDiff(ls->distance, length(ls->p - ref)) > 1e-12)
            ++badDir;
        return DirSample{ls->wi};
    };
    t.seed = 41;
    const auto r = chi2::runDirectional(t, prob);
    expectMatches(t.name, r, chi2::kFamilyAlpha, false);
    EXPECT_EQ(badPdf, 0) << "ls->pdf differs from LightSampler::pdf (worst relative difference " << worst << ")";
    EXPECT_EQ(badDir, 0) << "ls->wi or ls->distance inconsistent with ls->p";
    EXPECT_EQ(wrongShape, 0);
}

// ------------------------------------------------------------------------------------------------
// Materials.

const SampledWavelengths& testWavelengths() {
    static const SampledWavelengths wl = SampledWavelengths::sampleUniform(0.37, 400, 700);
    return wl;
}

// Runs the chi-square test of a material's sample() against its pdf() for one wo; checks that the
// reported pdf and f equal pdf(wo, wi) and f(wo, wi).
void testMaterial(const std::string& name, const Material& m, const Vec3& wo, double eta, bool fullSphere,
                  uint64_t seed, double alpha) {
    const SampledWavelengths& wl = testWavelengths();
    int badF = 0, specular = 0, badEtap = 0;
    double worstF = 0;
    DirectionalTest t;
    t.name = name;
    if (!fullSphere) t.grid.cosMin = 0;
    t.sample = [&](Rng& rng) -> std::optional<DirSample> {
        const double uc = rng.uniform(), u1 = rng.uniform(), u2 = rng.uniform();
        const auto s = m.sample(wo, uc, u1, u2, wl, eta, TransportMode::Radiance);
        if (!s) return std::nullopt;
        if (s->specular) ++specular;
        const SampledSpectrum f = m.f(wo, s->wi, wl, eta, TransportMode::Radiance);
        for (int i = 0; i < kNumWavelengths; ++i) {
            const double rel = relDiff(f[i], s->f[i]);
            worstF = std::max(worstF, rel);
            if (rel > 1e-6) ++badF;
        }
        const bool transmitted = wo.z * s->wi.z < 0;
        if (transmitted != s->transmission) ++badEtap;
        const double etap = transmitted ? (wo.z > 0 ? eta : 1 / eta) : 1.0;
        if (relDiff(s->etap, etap) > 1e-12) ++badEtap;
        return DirSample{s->wi, s->pdf};
    };
    t.pdf = [&](const Vec3& w) { return m.pdf(wo, w, eta); };
    t.seed = seed;
    expectMatches(name, chi2::runDirectional(t), alpha, true);
    EXPECT_EQ(badF, 0) << name << ": sample().f differs from f(wo, wi) (worst relative " << worstF << ")";
    EXPECT_EQ(specular, 0) << name << ": a rough material returned a specular sample";
    EXPECT_EQ(badEtap, 0) << name << ": transmission flag or etap wrong";
}

std::string woName(double thetaDeg, bool below) {
    return " wo " + std::to_string(static_cast<int>(thetaDeg)) + "deg" + (below ? " below" : "");
}

const std::vector<double> kWoAngles = {3.0, 45.0, 80.0};
constexpr double kWoPhi = 0.6;

TEST(Chi2Material, Diffuse) {
    const auto m = makeDiffuse(Spectrum::constant(0.8));
    const double alpha = chi2::sidak(chi2::kFamilyAlpha, static_cast<int>(kWoAngles.size()));
    uint64_t seed = 500;
    for (double th : kWoAngles) testMaterial("diffuse" + woName(th, false), *m, sphericalDirection(th, kWoPhi), 1.5, false, seed++, alpha);
    // No reflection from below.
    EXPECT_FALSE(m->sample(sphericalDirection(120, kWoPhi), 0.5, 0.5, 0.5, testWavelengths(), 1.5, TransportMode::Radiance));
}

TEST(Chi2Material, Plastic) {
    const std::vector<double> roughness = {0.05, 0.3, 0.8};
    const double alpha = chi2::sidak(chi2::kFamilyAlpha, static_cast<int>(roughness.size() * kWoAngles.size()));
    uint64_t seed = 600;
    for (double a : roughness) {
        const auto m = makePlastic(Spectrum::constant(0.5), 1.5, a);
        for (double th : kWoAngles)
            testMaterial("plastic alpha " + std::to_string(a) + woName(th, false), *m, sphericalDirection(th, kWoPhi),
                         1.5, false, seed++, alpha);
        EXPECT_FALSE(m->sample(sphericalDirection(120, kWoPhi), 0.5, 0.5, 0.5, testWavelengths(), 1.5, TransportMode::Radiance));
    }
}

TEST(Chi2Material, Conductor) {
    const std::vector<double> roughness = {0.1, 0.5};
    const double alpha = chi2::sidak(chi2::kFamilyAlpha, static_cast<int>(roughness.size() * kWoAngles.size()));
    uint64_t seed = 700;
    for (double a : roughness) {
        const auto m = makeConductor(Spectrum::constant(0.2), Spectrum::constant(3.0), a);
        for (double th : kWoAngles)
            testMaterial("conductor alpha " + std::to_string(a) + woName(th, false), *m,
                         sphericalDirection(th, kWoPhi), 1.5, false, seed++, alpha);
        EXPECT_FALSE(m->sample(sphericalDirection(120, kWoPhi), 0.5, 0.5, 0.5, testWavelengths(), 1.5, TransportMode::Radiance));
    }
}

// Rough dielectric: reflection and transmission, wo outside (+z) and inside (-z), eta = n_in / n_out
// above and below 1 (so total internal reflection occurs on one side).
TEST(Chi2Material, RoughDielectric) {
    const std::vector<double> roughness = {0.1, 0.5}, etas = {1.5, 1 / 1.5};
    const int cases = static_cast<int>(roughness.size() * etas.size() * 2 * kWoAngles.size());
    const double alpha = chi2::sidak(chi2::kFamilyAlpha, cases);
    uint64_t seed = 800;
    for (double a : roughness) {
        const auto m = makeDielectric(a);
        for (double eta : etas)
            for (bool below : {false, true})
                for (double th : kWoAngles) {
                    const Vec3 wo = sphericalDirection(below ? 180 - th : th, kWoPhi);
                    testMaterial("dielectric alpha " + std::to_string(a) + " eta " + std::to_string(eta) +
                                     woName(th, below),
                                 *m, wo, eta, true, seed++, alpha);
                }
    }
}

// Smooth dielectric: excluded from chi-square (delta lobes). The discrete lobe probabilities are
// Fresnel's R and T; the transmitted direction obeys Snell's law; f is T / |cos| (/ etap^2 for
// radiance).
TEST(Chi2Material, SmoothDielectricFresnelAndSnell) {
    // Fresnel at normal incidence: ((eta - 1) / (eta + 1))^2, same from both sides.
    EXPECT_NEAR(fresnelDielectric(1.0, 1.5), 0.04, 1e-12);
    EXPECT_NEAR(fresnelDielectric(-1.0, 1.5), 0.04, 1e-12);

    const auto m = makeDielectric(0.0);
    ASSERT_TRUE(m->isSpecular());
    const SampledWavelengths& wl = testWavelengths();
    const std::vector<double> angles = {0.0, 3.0, 30.0, 45.0, 60.0, 80.0, 89.0};
    const int cases = 2 * 2 * static_cast<int>(angles.size());
    const double alpha = chi2::sidak(chi2::kFamilyAlpha, cases);
    uint64_t seed = 900;
    for (double eta : {1.5, 1 / 1.5})
        for (bool below : {false, true})
            for (double th : angles) {
                const std::string name = "smooth dielectric eta " + std::to_string(eta) + woName(th, below);
                SCOPED_TRACE(name);
                const Vec3 wo = sphericalDirection(below ? 180 - th : th, kWoPhi);
                const double nO = wo.z > 0 ? 1.0 : eta, nI = wo.z > 0 ? eta : 1.0;  // wo side, transmitted side
                const double R = fresnelDielectric(wo.z, eta), T = 1 - R;
                const double sinO = std::sqrt(std::max(0.0, 1 - wo.z * wo.z));
                const bool tir = nO * sinO >= nI;
                EXPECT_EQ(tir, R == 1.0);
                EXPECT_EQ(m->pdf(wo, Vec3(-wo.x, -wo.y, wo.z), eta), 0.0);
                EXPECT_TRUE(m->f(wo, Vec3(-wo.x, -wo.y, wo.z), wl, eta, TransportMode::Radiance).isZero());
                Rng rng(seed++, 9);
                const int n = 200'000;
                double reflected = 0, transmitted = 0;
                int badReflect = 0, badSnell = 0, badF = 0, badPdf = 0, failed = 0;
                for (int k = 0; k < n; ++k) {
                    const double uc = rng.uniform(), u1 = rng.uniform(), u2 = rng.uniform();
                    const TransportMode mode = k % 2 ? TransportMode::Importance : TransportMode::Radiance;
                    const auto s = m->sample(wo, uc, u1, u2, wl, eta, mode);
                    if (!s) {
                        ++failed;
                        continue;
                    }
                    EXPECT_TRUE(s->specular);
                    if (!s->transmission) {
                        reflected += 1;
                        if (length(s->wi - Vec3(-wo.x, -wo.y, wo.z)) > 1e-12) ++badReflect;
                        if (relDiff(s->pdf, R) > 1e-12) ++badPdf;
                        if (relDiff(s->f[0], R / std::abs(wo.z)) > 1e-12 || s->etap != 1.0) ++badF;
                    } else {
                        transmitted += 1;
                        const Vec3 wi = s->wi;
                        const double sinI = std::sqrt(std::max(0.0, 1 - wi.z * wi.z));
                        // Snell: n_o sin(theta_o) = n_i sin(theta_i); opposite side; plane of incidence,
                        // azimuth turned by pi.
                        if (std::abs(length(wi) - 1) > 1e-12 || wi.z * wo.z >= 0 ||
                            std::abs(nO * sinO - nI * sinI) > 1e-12 || std::abs(wi.x * wo.y - wi.y * wo.x) > 1e-12 ||
                            wi.x * wo.x + wi.y * wo.y > 1e-15)
                            ++badSnell;
                        if (relDiff(s->etap, nI / nO) > 1e-12) ++badF;
                        if (relDiff(s->pdf, T) > 1e-12) ++badPdf;
                        const double fExpected =
                            T / std::abs(wi.z) / (mode == TransportMode::Radiance ? sqr(nI / nO) : 1.0);
                        for (int i = 0; i < kNumWavelengths; ++i)
                            if (relDiff(s->f[i], fExpected) > 1e-12) ++badF;
                    }
                }
                EXPECT_EQ(failed, 0);
                EXPECT_EQ(badReflect, 0);
                EXPECT_EQ(badSnell, 0);
                EXPECT_EQ(badF, 0);
                EXPECT_EQ(badPdf, 0);
                if (tir) {
                    EXPECT_EQ(transmitted, 0);
                } else {
                    const std::vector<double> obs = {reflected, transmitted}, expected = {R * n, T * n};
                    const auto r = chi2::chiSquare(obs, expected);
                    logResult(name, r.summary() + ", reflected " + std::to_string(reflected / n) + " vs R " + std::to_string(R));
                    EXPECT_TRUE(r.accept(alpha)) << r.summary();
                }
            }
}

TEST(Chi2Material, SmoothConductorMirror) {
    const auto m = makeConductor(Spectrum::constant(0.2), Spectrum::constant(3.0), 0.0);
    ASSERT_TRUE(m->isSpecular());
    const SampledWavelengths& wl = testWavelengths();
    for (double th : {0.0, 45.0, 80.0}) {
        const Vec3 wo = sphericalDirection(th, kWoPhi);
        const auto s = m->sample(wo, 0.3, 0.4, 0.5, wl, 1.0, TransportMode::Radiance);
        ASSERT_TRUE(s);
        EXPECT_TRUE(s->specular);
        EXPECT_EQ(s->pdf, 1.0);
        EXPECT_LT(length(s->wi - Vec3(-wo.x, -wo.y, wo.z)), 1e-12);
        EXPECT_NEAR(s->f[0] * std::abs(wo.z), fresnelConductor(wo.z, {0.2, 3.0}), 1e-12);
        EXPECT_EQ(m->pdf(wo, s->wi, 1.0), 0.0);
    }
}

}  // namespace
}  // namespace fluorosim
