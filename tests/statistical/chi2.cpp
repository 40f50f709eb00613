#include "statistical/chi2.h"

#include <algorithm>
#include <array>
#include <boost/math/special_functions/gamma.hpp>
#include <cmath>
#include <cstdio>
#include <numeric>
#include <queue>
#include <utility>

#include "core/math.h"

namespace fluorosim::chi2 {
namespace {

std::string format(const char* fmt, auto... args) {
    char buf[512];
    std::snprintf(buf, sizeof buf, fmt, args...);
    return buf;
}

// Globally adaptive Simpson cubature over the cells of a grid: every region carries a 5x5 node
// grid, its Simpson estimate on 3x3 nodes (S1) and the sum of its four children's (S2); |S2 - S1|
// is its error estimate. The region with the largest estimate is split until the summed estimate
// is below the tolerance or the evaluation budget is spent. Children reuse their parent's nodes.
class GridCubature {
public:
    // f(cell, x, y) for (x, y) inside the cell's rectangle.
    using Fn = std::function<double(int, double, double)>;
    GridCubature(Fn f, size_t budget) : f_(std::move(f)), budget_(budget) {}

    void addRegion(int cell, double x0, double x1, double y0, double y1) {
        std::array<double, 9> v;
        for (int i = 0; i < 3; ++i)
            for (int j = 0; j < 3; ++j) v[3 * i + j] = eval(cell, x0 + 0.5 * i * (x1 - x0), y0 + 0.5 * j * (y1 - y0));
        push(make(cell, x0, x1, y0, y1, v));
    }

    // Refines until the summed error estimate is below tol; returns the estimate.
    double run(double tol) {
        while (!heap_.empty() && totalError_ > tol && evaluations_ < budget_) {
            const size_t k = heap_.top().second;
            heap_.pop();
            const Region r = regions_[k];
            totalError_ -= r.err;
            free_.push_back(k);
            const double xm = 0.5 * (r.x0 + r.x1), ym = 0.5 * (r.y0 + r.y1);
            const double xs[3] = {r.x0, xm, r.x1}, ys[3] = {r.y0, ym, r.y1};
            for (int cx = 0; cx < 2; ++cx)
                for (int cy = 0; cy < 2; ++cy) {
                    std::array<double, 9> v;
                    for (int i = 0; i < 3; ++i)
                        for (int j = 0; j < 3; ++j) v[3 * i + j] = r.g[5 * (2 * cx + i) + 2 * cy + j];
                    push(make(r.cell, xs[cx], xs[cx + 1], ys[cy], ys[cy + 1], v));
                }
        }
        // Recompute the total (the running sum drifts).
        double e = 0;
        for (const auto& [err, k] : heapItems()) e += err, (void)k;
        return e;
    }

    // Adds every live region's estimate to its cell.
    void accumulate(std::vector<double>& cells) const {
        for (const auto& [err, k] : heapItems()) {
            (void)err;
            cells[static_cast<size_t>(regions_[k].cell)] += regions_[k].value;
        }
    }
    size_t evaluations() const { return evaluations_; }

private:
    struct Region {
        double x0, x1, y0, y1;
        int cell;
        std::array<double, 25> g;
        double value, err;
    };

    double eval(int cell, double x, double y) {
        ++evaluations_;
        return f_(cell, x, y);
    }
    static double simpson(double x0, double x1, double y0, double y1, const double* v, int stride) {
        static constexpr double w[3] = {1, 4, 1};
        double s = 0;
        for (int i = 0; i < 3; ++i)
            for (int j = 0; j < 3; ++j) s += w[i] * w[j] * v[stride * i + j];
        return s * (x1 - x0) * (y1 - y0) / 36.0;
    }
    Region make(int cell, double x0, double x1, double y0, double y1, const std::array<double, 9>& v) {
        Region r{x0, x1, y0, y1, cell, {}, 0, 0};
        for (int a = 0; a < 5; ++a)
            for (int b = 0; b < 5; ++b)
                r.g[5 * a + b] = (a % 2 == 0 && b % 2 == 0) ? v[3 * (a / 2) + b / 2]
                                                            : eval(cell, x0 + 0.25 * a * (x1 - x0), y0 + 0.25 * b * (y1 - y0));
        const double whole = simpson(x0, x1, y0, y1, v.data(), 3);
        const double xm = 0.5 * (x0 + x1), ym = 0.5 * (y0 + y1);
        const double xs[3] = {x0, xm, x1}, ys[3] = {y0, ym, y1};
        double sum = 0;
        for (int cx = 0; cx < 2; ++cx)
            for (int cy = 0; cy < 2; ++cy)
                sum += simpson(xs[cx], xs[cx + 1], ys[cy], ys[cy + 1], &r.g[5 * (2 * cx) + 2 * cy], 5);
        // No Richardson extrapolation: it can turn a non-negative density negative at a kink.
        r.value = sum;
        r.err = std::isfinite(sum) ? std::abs(sum - whole) : 0.0;
        return r;
    }
    void push(const Region& r) {
        size_t k;
        if (!free_.empty()) {
            k = free_.back();
            free_.pop_back();
            regions_[k] = r;
        } else {
            k = regions_.size();
            regions_.push_back(r);
        }
        totalError_ += r.err;
        heap_.push({r.err, k});
    }
    std::vector<std::pair<double, size_t>> heapItems() const {
        auto copy = heap_;
        std::vector<std::pair<double, size_t>> items;
        while (!copy.empty()) {
            items.push_back(copy.top());
            copy.pop();
        }
        return items;
    }

    Fn f_;
    size_t budget_;
    size_t evaluations_ = 0;
    double totalError_ = 0;
    std::vector<Region> regions_;
    std::vector<size_t> free_;
    std::priority_queue<std::pair<double, size_t>> heap_;
};

}  // namespace

double sidak(double familyAlpha, int numTests) {
    return -std::expm1(std::log1p(-familyAlpha) / static_cast<double>(std::max(1, numTests)));
}

std::string Chi2Result::summary() const {
    std::string s = format("chi2 = %.2f, dof = %d, p = %.4g, cells = %d (%d pooled)", statistic, dof, pValue, cells,
                           pooledCells);
    if (!error.empty()) s += "; " + error;
    return s;
}

Chi2Result chiSquare(std::span<const double> observed, std::span<const double> expected, double minExpected,
                     double zeroExpected) {
    Chi2Result r;
    if (observed.size() != expected.size()) {
        r.error = "observed and expected differ in size";
        r.pValue = 0;
        return r;
    }
    std::vector<size_t> order(expected.size());
    std::iota(order.begin(), order.end(), size_t{0});
    std::stable_sort(order.begin(), order.end(), [&](size_t a, size_t b) { return expected[a] < expected[b]; });
    double pooledObs = 0, pooledExp = 0;
    for (const size_t i : order) {
        const double e = expected[i], o = observed[i];
        if (!std::isfinite(e) || e < 0) {
            r.error = format("cell %zu has an invalid expected count %g", i, e);
            r.pValue = 0;
            return r;
        }
        if (e <= zeroExpected) {
            if (o > 0 && r.error.empty())
                r.error = format("%g samples in cell %zu whose expected count is %g", o, i, e);
            continue;
        }
        if (e < minExpected || (pooledExp > 0 && pooledExp < minExpected)) {
            pooledObs += o;
            pooledExp += e;
            ++r.pooledCells;
        } else {
            r.statistic += sqr(o - e) / e;
            ++r.cells;
        }
    }
    if (r.pooledCells > 0) {
        r.statistic += sqr(pooledObs - pooledExp) / pooledExp;
        ++r.cells;
    }
    r.dof = r.cells - 1;
    if (!r.error.empty()) {
        r.pValue = 0;
        return r;
    }
    if (r.dof < 1) {
        r.error = "fewer than two cells after pooling";
        r.pValue = 0;
        return r;
    }
    r.pValue = boost::math::gamma_q(0.5 * r.dof, 0.5 * r.statistic);
    return r;
}

int SphericalGrid::cellIndex(const Vec3& w) const {
    const Vec3 l = frame.toLocal(w);
    const double c = std::clamp(l.z, -1.0, 1.0);
    if (!(c >= cosMin && c <= cosMax)) return -1;
    const int i = std::min(nCos - 1, static_cast<int>((c - cosMin) / (cosMax - cosMin) * nCos));
    double phi = std::atan2(l.y, l.x);
    if (phi < 0) phi += 2 * kPi;
    const int j = std::clamp(static_cast<int>(phi / (2 * kPi) * nPhi), 0, nPhi - 1);
    return i * nPhi + j;
}

Vec3 SphericalGrid::direction(double cosTheta, double phi) const {
    const double s = safeSqrt(1 - cosTheta * cosTheta);
    return frame.toWorld({s * std::cos(phi), s * std::sin(phi), cosTheta});
}

std::vector<double> integrateOverGrid(const SphericalGrid& grid, const std::function<double(const Vec3&)>& pdf,
                                      double totalTol, int initialSplits, size_t budget, IntegrationStats* stats) {
    const double dc = (grid.cosMax - grid.cosMin) / grid.nCos, dphi = 2 * kPi / grid.nPhi;
    // Cells are bounded in cosTheta, but the cubature runs in theta with the Jacobian sin(theta):
    // as a function of (cosTheta, phi) a density has a square-root singularity at the poles, as a
    // function of (theta, phi) it is smooth there (Mitsuba does the same).
    auto thetaEdge = [&](int i) {  // theta decreases with cosTheta; edge i is the cell's lower cosTheta
        return std::acos(std::clamp(i == grid.nCos ? grid.cosMax : grid.cosMin + dc * i, -1.0, 1.0));
    };
    // Nodes on a cell's border are nudged inside: densities are often discontinuous exactly there
    // (the horizon), and the one-sided limit is what the cell integrates.
    GridCubature cub(
        [&](int cell, double theta, double phi) {
            const int i = cell / grid.nPhi, j = cell % grid.nPhi;
            const double t0 = thetaEdge(i + 1), t1 = thetaEdge(i), p0 = dphi * j, p1 = dphi * (j + 1);
            const double et = 1e-9 * (t1 - t0), ep = 1e-9 * (p1 - p0);
            theta = std::clamp(theta, t0 + et, t1 - et);
            phi = std::clamp(phi, p0 + ep, p1 - ep);
            return pdf(grid.direction(std::cos(theta), phi)) * std::sin(theta);
        },
        budget);
    const int k = initialSplits;
    for (int i = 0; i < grid.nCos; ++i)
        for (int j = 0; j < grid.nPhi; ++j) {
            const double t0 = thetaEdge(i + 1), t1 = thetaEdge(i), p0 = dphi * j, p1 = dphi * (j + 1);
            for (int a = 0; a < k; ++a)
                for (int b = 0; b < k; ++b)
                    cub.addRegion(i * grid.nPhi + j, t0 + (t1 - t0) * a / k, t0 + (t1 - t0) * (a + 1) / k,
                                  p0 + (p1 - p0) * b / k, p0 + (p1 - p0) * (b + 1) / k);
        }
    const double err = cub.run(totalTol);
    std::vector<double> prob(static_cast<size_t>(grid.cells()), 0.0);
    cub.accumulate(prob);
    if (stats) *stats = {err, cub.evaluations()};
    return prob;
}

double DirectionalResult::successStderr() const {
    if (total == 0) return 0;
    const double p = successFraction();
    return std::sqrt(std::max(p * (1 - p), 1.0 / double(total)) / double(total));
}

std::string DirectionalResult::summary() const {
    std::string s = chi2.summary();
    s += format("; integral of pdf = %.8f, success fraction = %.8f (+- %.2g) of %zu", pdfIntegral, successFraction(),
                successStderr(), total);
    if (integration.evaluations)
        s += format("; cubature error <= %.2g (%zu evaluations)", integration.errorEstimate, integration.evaluations);
    if (outside) s += format("; %zu samples outside the grid", outside);
    if (nonFinite) s += format("; %zu invalid directions", nonFinite);
    if (pdfMismatches)
        s += format("; %zu reported pdfs disagree with pdf(w) (worst: reported %.10g, evaluated %.10g at (%.6f, %.6f, "
                    "%.6f))",
                    pdfMismatches, worstReported, worstEvaluated, worstDir.x, worstDir.y, worstDir.z);
    return s;
}

std::string DirectionalResult::table() const {
    // The ten cells that contribute most to the statistic.
    std::vector<size_t> idx(observed.size());
    std::iota(idx.begin(), idx.end(), size_t{0});
    auto contrib = [&](size_t i) { return expected[i] > 0 ? sqr(observed[i] - expected[i]) / expected[i] : observed[i]; };
    std::sort(idx.begin(), idx.end(), [&](size_t a, size_t b) { return contrib(a) > contrib(b); });
    std::string s = "largest contributions (cell: observed / expected):";
    const size_t grid = observed.size() - 2;
    for (size_t k = 0; k < std::min<size_t>(10, idx.size()); ++k) {
        const size_t i = idx[k];
        const std::string name = i < grid ? std::to_string(i) : (i == grid ? "outside" : "failure");
        s += format(" [%s: %.0f / %.2f]", name.c_str(), observed[i], expected[i]);
    }
    return s;
}

DirectionalResult runDirectional(const DirectionalTest& test) {
    IntegrationStats stats;
    const auto prob = integrateOverGrid(test.grid, test.pdf, test.integrationTol, 2, test.integrationBudget, &stats);
    DirectionalResult r = runDirectional(test, prob);
    r.integration = stats;
    return r;
}

DirectionalResult runDirectional(const DirectionalTest& test, std::vector<double> cellProbabilities) {
    DirectionalResult r;
    const size_t cells = static_cast<size_t>(test.grid.cells());
    const size_t outsideCell = cells, failureCell = cells + 1;
    r.observed.assign(cells + 2, 0.0);
    Rng rng(test.seed, 0x2545f4914f6cdd1dULL);
    r.total = test.samples;
    for (size_t n = 0; n < test.samples; ++n) {
        const std::optional<DirSample> s = test.sample(rng);
        if (!s) {
            r.observed[failureCell] += 1;
            continue;
        }
        ++r.successes;
        if (!isFinite(s->w) || std::abs(length(s->w) - 1) > 1e-6) {
            ++r.nonFinite;
            r.observed[outsideCell] += 1;
            continue;
        }
        const int cell = test.grid.cellIndex(s->w);
        if (cell < 0) {
            ++r.outside;
            r.observed[outsideCell] += 1;
        } else {
            r.observed[static_cast<size_t>(cell)] += 1;
        }
        if (s->pdf >= 0 && test.pdf) {
            const double p = test.pdf(s->w);
            const double scale = std::max(std::abs(p), std::abs(s->pdf));
            const double rel = scale > 0 ? std::abs(p - s->pdf) / scale : 0.0;
            if (!(rel <= test.pdfRelTol)) {
                ++r.pdfMismatches;
                if (!(rel <= r.worstPdfRelError)) {
                    r.worstPdfRelError = std::isfinite(rel) ? rel : 1e300;
                    r.worstReported = s->pdf;
                    r.worstEvaluated = p;
                    r.worstDir = s->w;
                }
            }
        }
    }
    const double n = static_cast<double>(test.samples);
    r.expected.assign(cells + 2, 0.0);
    for (size_t i = 0; i < cells; ++i) {
        r.pdfIntegral += cellProbabilities[i];
        r.expected[i] = cellProbabilities[i] * n;
    }
    r.expected[failureCell] = std::max(0.0, (1 - r.pdfIntegral) * n);
    r.chi2 = chiSquare(r.observed, r.expected);
    return r;
}

int binIndex(std::span<const double> edges, double x) {
    if (edges.size() < 2 || !(x >= edges.front() && x < edges.back())) return -1;
    const auto it = std::upper_bound(edges.begin(), edges.end(), x);
    return static_cast<int>(it - edges.begin()) - 1;
}

std::vector<double> uniformEdges(double a, double b, int bins) {
    std::vector<double> e(static_cast<size_t>(bins) + 1);
    for (int i = 0; i <= bins; ++i) e[static_cast<size_t>(i)] = a + (b - a) * i / bins;
    e.back() = b;
    return e;
}

std::vector<double> expectedFromCdf(std::span<const double> edges, const std::function<double(double)>& cdf, double n) {
    std::vector<double> e;
    for (size_t i = 0; i + 1 < edges.size(); ++i) e.push_back(n * (cdf(edges[i + 1]) - cdf(edges[i])));
    return e;
}

}  // namespace fluorosim::chi2
