// TabulatedSpectrum: piecewise-linear interpolation, exact integrals and input validation.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <string>
#include <vector>

#include "core/errors.h"
#include "spectral/tabulated_spectrum.h"

namespace fluorosim {
namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
constexpr double kInf = std::numeric_limits<double>::infinity();

// f: 0 at 400 nm, 1 at 500 nm, 0.5 at 600 nm.
TabulatedSpectrum triangle() { return TabulatedSpectrum({400, 500, 600}, {0, 1, 0.5}, "triangle"); }

TEST(TabulatedSpectrum, InterpolatesLinearly) {
    const auto f = triangle();
    EXPECT_DOUBLE_EQ(f(400), 0.0);
    EXPECT_DOUBLE_EQ(f(425), 0.25);
    EXPECT_DOUBLE_EQ(f(450), 0.5);
    EXPECT_DOUBLE_EQ(f(500), 1.0);
    EXPECT_DOUBLE_EQ(f(550), 0.75);
    EXPECT_DOUBLE_EQ(f(580), 0.6);
    EXPECT_DOUBLE_EQ(f(600), 0.5);  // the last sample itself is inside the range
    EXPECT_DOUBLE_EQ(f.minLambda(), 400.0);
    EXPECT_DOUBLE_EQ(f.maxLambda(), 600.0);
    EXPECT_DOUBLE_EQ(f.maxValue(), 1.0);
    EXPECT_FALSE(f.empty());
    EXPECT_TRUE(TabulatedSpectrum().empty());
}

TEST(TabulatedSpectrum, IsZeroOutsideItsRange) {
    const auto f = triangle();
    EXPECT_EQ(f(399.999), 0.0);
    EXPECT_EQ(f(600.001), 0.0);
    EXPECT_EQ(f(0), 0.0);
    EXPECT_EQ(f(-5), 0.0);
    EXPECT_EQ(f(1e9), 0.0);
    EXPECT_EQ(TabulatedSpectrum()(500), 0.0);
    // A spectrum with a non-zero value at its ends drops to zero just outside.
    const TabulatedSpectrum flat({300, 800}, {2, 2});
    EXPECT_DOUBLE_EQ(flat(300), 2.0);
    EXPECT_DOUBLE_EQ(flat(800), 2.0);
    EXPECT_EQ(flat(299.9), 0.0);
    EXPECT_EQ(flat(800.1), 0.0);
}

TEST(TabulatedSpectrum, IntegralIsTheExactTrapezoidSum) {
    const auto f = triangle();
    // Whole range: 0.5*(0+1)*100 + 0.5*(1+0.5)*100 = 50 + 75.
    EXPECT_DOUBLE_EQ(f.integral(), 125.0);
    EXPECT_DOUBLE_EQ(f.integral(400, 600), 125.0);
    // Limits beyond the range are clipped (zero outside).
    EXPECT_DOUBLE_EQ(f.integral(0, 1000), 125.0);
    EXPECT_DOUBLE_EQ(f.integral(300, 450), 12.5);  // 0.5*(0+0.5)*50
    // Straddling a knot: 0.5*(0.5+1)*50 + 0.5*(1+0.75)*50 = 37.5 + 43.75.
    EXPECT_DOUBLE_EQ(f.integral(450, 550), 81.25);
    // Inside one segment: 0.5*(0.1+0.2)*10.
    EXPECT_DOUBLE_EQ(f.integral(410, 420), 1.5);
    // Knot to knot.
    EXPECT_DOUBLE_EQ(f.integral(500, 600), 75.0);
    EXPECT_DOUBLE_EQ(f.integral(400, 500), 50.0);
    // Additivity.
    EXPECT_NEAR(f.integral(400, 537) + f.integral(537, 600), 125.0, 1e-12);
    // Empty, inverted and disjoint intervals.
    EXPECT_EQ(f.integral(500, 500), 0.0);
    EXPECT_EQ(f.integral(550, 450), 0.0);
    EXPECT_EQ(f.integral(100, 200), 0.0);
    EXPECT_EQ(f.integral(700, 800), 0.0);
    EXPECT_EQ(TabulatedSpectrum().integral(), 0.0);
}

TEST(TabulatedSpectrum, IntegralOfManyUnevenKnots) {
    const std::vector<double> l = {380, 381.5, 390, 402.25, 455, 455.5, 700};
    const std::vector<double> v = {0.3, 2.0, 0.0, 1.25, 4.0, 0.5, 0.1};
    const TabulatedSpectrum f(l, v, "uneven");
    long double expected = 0;
    for (size_t i = 0; i + 1 < l.size(); ++i) expected += 0.5L * (v[i] + v[i + 1]) * (l[i + 1] - l[i]);
    EXPECT_NEAR(f.integral(), static_cast<double>(expected), 1e-12 * static_cast<double>(expected));
}

// The look-up starts from a cell grid instead of a binary search; it must pick the same interval
// (so the same bits) at every knot, just beside it and between knots, on clustered and wide tables.
TEST(TabulatedSpectrum, CellLookUpEqualsABinarySearchBitForBit) {
    const std::vector<double> l = {380, 380.001, 380.002, 381.5, 390, 402.25, 455, 455.5, 455.50001, 700, 1000};
    const std::vector<double> v = {0.3, 2.0, 0.7, 0.0, 1.25, 4.0, 0.5, 0.9, 0.2, 0.1, 3.0};
    const TabulatedSpectrum f(l, v, "clustered");
    auto searched = [&](double x) {
        if (x < l.front() || x > l.back()) return 0.0;
        const auto it = std::upper_bound(l.begin(), l.end(), x);
        if (it == l.end()) return v.back();
        const size_t i = static_cast<size_t>(it - l.begin()) - 1;
        const double t = (x - l[i]) / (l[i + 1] - l[i]);
        return (1 - t) * v[i] + t * v[i + 1];
    };
    std::vector<double> xs;
    for (double k : l) xs.insert(xs.end(), {k, std::nextafter(k, 0.0), std::nextafter(k, 2000.0)});
    for (int i = 0; i <= 20000; ++i) xs.push_back(370 + 640.0 * i / 20000);
    for (double x : xs) ASSERT_EQ(f(x), searched(x)) << "at " << x << " nm";
}

// Exact reference: linear interpolation in long double and, on each interval of the merged knot
// set where both factors are linear, the closed form  h/6 (2 f0 g0 + f0 g1 + f1 g0 + 2 f1 g1).
long double lerp(const std::vector<double>& l, const std::vector<double>& v, long double x) {
    if (x < l.front() || x > l.back()) return 0;
    for (size_t i = 0; i + 1 < l.size(); ++i)
        if (x <= l[i + 1]) {
            const long double t = (x - l[i]) / (static_cast<long double>(l[i + 1]) - l[i]);
            return (1 - t) * v[i] + t * v[i + 1];
        }
    return v.back();
}

long double exactProduct(const std::vector<double>& la, const std::vector<double>& va, const std::vector<double>& lb,
                         const std::vector<double>& vb) {
    const double a = std::max(la.front(), lb.front()), b = std::min(la.back(), lb.back());
    if (!(b > a)) return 0;
    std::vector<double> knots = {a, b};
    for (double x : la)
        if (x > a && x < b) knots.push_back(x);
    for (double x : lb)
        if (x > a && x < b) knots.push_back(x);
    std::sort(knots.begin(), knots.end());
    knots.erase(std::unique(knots.begin(), knots.end()), knots.end());
    long double sum = 0;
    for (size_t i = 0; i + 1 < knots.size(); ++i) {
        const long double x0 = knots[i], x1 = knots[i + 1], h = x1 - x0;
        // Inside [a, b] both spectra are continuous and linear between merged knots.
        const long double f0 = lerp(la, va, x0), f1 = lerp(la, va, x1);
        const long double g0 = lerp(lb, vb, x0), g1 = lerp(lb, vb, x1);
        sum += h / 6 * (2 * f0 * g0 + f0 * g1 + f1 * g0 + 2 * f1 * g1);
    }
    return sum;
}

TEST(TabulatedSpectrum, IntegrateProductHandComputed) {
    // f = t, g = 1 - t with t = (l - 400)/100: integral 100 * 1/6.
    const TabulatedSpectrum f({400, 500}, {0, 1}), g({400, 500}, {1, 0});
    EXPECT_NEAR(f.integrateProduct(g), 100.0 / 6.0, 1e-12);
    // f^2: 100 * 1/3.
    EXPECT_NEAR(f.integrateProduct(f), 100.0 / 3.0, 1e-12);
    // With a constant, the product integral is the integral over the overlap.
    const TabulatedSpectrum one({300, 900}, {1, 1});
    EXPECT_NEAR(triangle().integrateProduct(one), 125.0, 1e-12);
    const TabulatedSpectrum partial({450, 550}, {1, 1});
    EXPECT_NEAR(triangle().integrateProduct(partial), 81.25, 1e-12);
}

TEST(TabulatedSpectrum, IntegrateProductExactForDifferentKnots) {
    const std::vector<double> la = {400, 450, 520, 600}, va = {0, 2, 1, 3};
    const std::vector<double> lb = {420, 480, 500, 650}, vb = {1, 0, 4, 2};
    const TabulatedSpectrum fa(la, va, "a"), fb(lb, vb, "b");
    // Merged knots on the overlap: 420, 450, 480, 500, 520, 600.
    const long double exact = exactProduct(la, va, lb, vb);
    EXPECT_NEAR(fa.integrateProduct(fb), static_cast<double>(exact), 1e-11 * static_cast<double>(exact));
    EXPECT_NEAR(fb.integrateProduct(fa), static_cast<double>(exact), 1e-11 * static_cast<double>(exact));

    // Cross-check the reference itself against a dense Simpson sum of the library's own evaluation.
    long double dense = 0;
    const int n = 200000;
    const double a = 420, b = 600, h = (b - a) / n;
    for (int i = 0; i <= n; ++i) {
        const double x = a + i * h;
        const long double w = (i == 0 || i == n) ? 1 : (i % 2 ? 4 : 2);
        dense += w * static_cast<long double>(fa(x)) * fb(x);
    }
    dense *= h / 3;
    EXPECT_NEAR(static_cast<double>(dense), static_cast<double>(exact), 1e-6);
}

TEST(TabulatedSpectrum, IntegrateProductExactForIrregularSpectra) {
    const std::vector<double> la = {350, 351.3, 377, 402.5, 403, 480.75, 512, 640};
    const std::vector<double> va = {0.1, 3.0, 0.0, 0.7, 5.5, 2.25, 0.0, 1.0};
    const std::vector<double> lb = {340, 360, 361, 403, 470.125, 520, 600.5};
    const std::vector<double> vb = {2.0, 0.0, 1.5, 0.25, 3.0, 0.125, 6.0};
    const TabulatedSpectrum fa(la, va), fb(lb, vb);
    const long double exact = exactProduct(la, va, lb, vb);
    EXPECT_GT(exact, 0);
    EXPECT_NEAR(fa.integrateProduct(fb), static_cast<double>(exact), 1e-11 * static_cast<double>(exact));
    EXPECT_NEAR(fb.integrateProduct(fa), static_cast<double>(exact), 1e-11 * static_cast<double>(exact));
}

TEST(TabulatedSpectrum, IntegrateProductOfDisjointSpectraIsZero) {
    const TabulatedSpectrum a({400, 500}, {1, 1}), b({500.5, 600}, {1, 1});
    EXPECT_EQ(a.integrateProduct(b), 0.0);
    EXPECT_EQ(b.integrateProduct(a), 0.0);
    EXPECT_EQ(a.integrateProduct(TabulatedSpectrum()), 0.0);
}

TEST(TabulatedSpectrum, Scaled) {
    const auto f = triangle().scaled(4);
    EXPECT_DOUBLE_EQ(f(550), 3.0);
    EXPECT_DOUBLE_EQ(f.integral(), 500.0);
}

// Expects ConfigError naming the source and each of `parts`.
void expectRejected(std::vector<double> l, std::vector<double> v, const std::vector<std::string>& parts = {}) {
    try {
        TabulatedSpectrum s(std::move(l), std::move(v), "my_source.csv");
        ADD_FAILURE() << "accepted";
    } catch (const ConfigError& e) {
        const std::string msg = e.what();
        EXPECT_NE(msg.find("my_source.csv"), std::string::npos) << msg;
        for (const std::string& p : parts) EXPECT_NE(msg.find(p), std::string::npos) << "no \"" << p << "\" in: " << msg;
    }
}

TEST(TabulatedSpectrum, RejectsNonIncreasingWavelengths) {
    {
        SCOPED_TRACE("repeated");
        expectRejected({400, 400, 500}, {1, 1, 1}, {"row 2"});
    }
    {
        SCOPED_TRACE("decreasing");
        expectRejected({400, 500, 450, 600}, {1, 1, 1, 1}, {"row 3"});
    }
}

TEST(TabulatedSpectrum, RejectsInvalidWavelengths) {
    {
        SCOPED_TRACE("NaN wavelength");
        expectRejected({400, kNaN, 500}, {1, 1, 1}, {"row 2"});
    }
    {
        SCOPED_TRACE("zero wavelength");
        expectRejected({0, 400}, {1, 1}, {"row 1"});
    }
    {
        SCOPED_TRACE("infinite wavelength");
        expectRejected({400, kInf}, {1, 1}, {"row 2"});
    }
}

TEST(TabulatedSpectrum, RejectsNegativeValues) {
    expectRejected({400, 500, 600}, {1, -0.5, 1}, {"-0.5", "row 2"});
}

TEST(TabulatedSpectrum, RejectsNonFiniteValues) {
    {
        SCOPED_TRACE("NaN value");
        expectRejected({400, 500, 600}, {1, 1, kNaN}, {"nan", "row 3"});
    }
    {
        SCOPED_TRACE("infinite value");
        expectRejected({400, 500, 600}, {kInf, 1, 1}, {"inf", "row 1"});
    }
}

TEST(TabulatedSpectrum, RejectsMismatchedLengths) {
    expectRejected({400, 500, 600}, {1, 1});
    expectRejected({400, 500}, {1, 1, 1});
}

TEST(TabulatedSpectrum, RejectsFewerThanTwoSamples) {
    expectRejected({500}, {1}, {"2 samples"});
    expectRejected({}, {}, {"2 samples"});
}

}  // namespace
}  // namespace fluorosim
