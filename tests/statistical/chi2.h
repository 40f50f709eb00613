#pragma once
// Chi-square goodness-of-fit harness (after Mitsuba's ChiSquareTest): histogram what a sampler
// draws, integrate the pdf it reports over the same cells, pool cells with small expected counts,
// and compute Pearson's statistic and its p-value.
//
// Samplers that can fail (return nullopt) are handled with an explicit failure cell: the histogram
// counts successes only, expected counts are N_total * (probability of the cell under the pdf), and
// the failure cell compares the failure count with N_total * (1 - integral of the pdf).
#include <cstddef>
#include <cstdint>
#include <functional>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "core/rng.h"
#include "core/vec3.h"

namespace fluorosim::chi2 {

// Family-wise significance of every TEST that uses this harness; split over the chi-square tests
// inside one TEST with sidak().
inline constexpr double kFamilyAlpha = 1e-4;

// Per-test significance so that `numTests` independent tests together reject a correct sampler with
// probability `familyAlpha` (Sidak correction).
double sidak(double familyAlpha, int numTests);

struct Chi2Result {
    double statistic = 0;
    int dof = 0;
    double pValue = 1;
    int cells = 0;        // cells in the statistic, the pooled cell included
    int pooledCells = 0;  // cells merged into the pooled cell
    std::string error;    // non-empty: reject outright (e.g. samples in a cell of expected count 0)
    bool accept(double alpha) const { return error.empty() && pValue >= alpha; }
    std::string summary() const;
};

// Pearson's statistic. Cells are visited by increasing expected count; cells with expected count
// below `minExpected` are pooled into one cell (Mitsuba). A cell with expected count 0 (exactly, or
// below `zeroExpected`) and observed samples is an outright rejection.
Chi2Result chiSquare(std::span<const double> observed, std::span<const double> expected, double minExpected = 5.0,
                     double zeroExpected = 1e-12);

// ---------------------------------------------------------------------------------------------
// Directional samplers.

// A grid over (cosTheta, phi) in the local coordinates of `frame`: cells of equal solid angle.
struct SphericalGrid {
    int nCos = 10, nPhi = 20;
    double cosMin = -1, cosMax = 1;  // [0, 1] for a hemisphere
    Frame frame{Vec3(1, 0, 0), Vec3(0, 1, 0), Vec3(0, 0, 1)};

    int cells() const { return nCos * nPhi; }
    // Cell of a unit direction, -1 if outside [cosMin, cosMax].
    int cellIndex(const Vec3& w) const;
    Vec3 direction(double cosTheta, double phi) const;
};

struct IntegrationStats {
    double errorEstimate = 0;  // summed |S2 - S1| of the final regions (absolute, in probability)
    size_t evaluations = 0;
};

// Probability of each cell under the solid-angle pdf: globally adaptive Simpson cubature over each
// cell (in (theta, phi) with the solid-angle Jacobian sin(theta), which is smooth at the poles where
// d cosTheta d phi is not), starting from initialSplits^2
// regions per cell and refining until the summed error estimate is below totalTol or `budget` pdf
// evaluations are spent.
std::vector<double> integrateOverGrid(const SphericalGrid& grid, const std::function<double(const Vec3&)>& pdf,
                                      double totalTol = 3e-7, int initialSplits = 2, size_t budget = 2'000'000,
                                      IntegrationStats* stats = nullptr);

struct DirSample {
    Vec3 w;
    double pdf = -1;  // the pdf the sampler reports for w; < 0 when it reports none
};

struct DirectionalTest {
    std::string name;
    SphericalGrid grid;
    std::function<std::optional<DirSample>(Rng&)> sample;  // nullopt: the sampler failed
    std::function<double(const Vec3&)> pdf;                // not needed if cell probabilities are given
    std::size_t samples = 1'000'000;
    uint64_t seed = 1;
    double pdfRelTol = 1e-6;  // reported pdf vs pdf(w)
    // Cubature tolerance (absolute, in probability; 3e-7 is 0.3 expected samples in total at 1e6
    // samples) and evaluation budget. Densities with a discontinuity that cuts through cells (e.g.
    // GGX transmission where the half vector crosses the horizon) stop at the budget with an error
    // estimate of a few 1e-6, still far below the statistical noise.
    double integrationTol = 3e-7;
    size_t integrationBudget = 2'000'000;
};

struct DirectionalResult {
    Chi2Result chi2;
    double pdfIntegral = 0;  // sum of the cell probabilities
    std::size_t total = 0, successes = 0, outside = 0, nonFinite = 0;
    std::size_t pdfMismatches = 0;  // reported pdf differs from pdf(w) by more than pdfRelTol
    double worstPdfRelError = 0, worstReported = 0, worstEvaluated = 0;
    Vec3 worstDir;
    std::vector<double> observed, expected;  // per grid cell, then outside, then failure
    IntegrationStats integration;             // when runDirectional integrated the pdf
    double successFraction() const { return total ? double(successes) / double(total) : 0.0; }
    // Binomial standard error of the success fraction (for comparing with pdfIntegral).
    double successStderr() const;
    std::string summary() const;
    std::string table() const;  // observed / expected per cell, for failure messages
};

DirectionalResult runDirectional(const DirectionalTest& test);
// Same, with cell probabilities computed by the caller (e.g. integrated on a light's surface).
DirectionalResult runDirectional(const DirectionalTest& test, std::vector<double> cellProbabilities);

// ---------------------------------------------------------------------------------------------
// 1-D samplers.

// Index of the bin [edges[i], edges[i+1]) holding x, or -1 outside [edges.front(), edges.back()).
int binIndex(std::span<const double> edges, double x);
std::vector<double> uniformEdges(double a, double b, int bins);
// Expected counts per bin from an exact CDF: n * (cdf(e[i+1]) - cdf(e[i])).
std::vector<double> expectedFromCdf(std::span<const double> edges, const std::function<double(double)>& cdf, double n);

}  // namespace fluorosim::chi2
