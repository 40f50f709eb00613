// Gauss–Legendre rules: exact for polynomials up to degree 2n − 1 and convergent for oscillatory
// integrands at the node counts the PSF tables use.
#include <gtest/gtest.h>

#include <cmath>

#include "core/errors.h"
#include "core/quadrature.h"

namespace fluorosim {
namespace {

double integrate(const QuadratureRule& rule, double (*f)(double, int), int p) {
    double sum = 0;
    for (size_t i = 0; i < rule.nodes.size(); ++i) sum += rule.weights[i] * f(rule.nodes[i], p);
    return sum;
}

TEST(GaussLegendre, IsExactForPolynomialsUpToDegreeTwoNMinusOne) {
    for (int n : {1, 2, 3, 5, 8, 17, 64}) {
        const QuadratureRule rule = gaussLegendre01(n);
        double weightSum = 0;
        for (size_t i = 0; i < rule.nodes.size(); ++i) {
            EXPECT_GT(rule.nodes[i], 0.0);
            EXPECT_LT(rule.nodes[i], 1.0);
            EXPECT_GT(rule.weights[i], 0.0);
            weightSum += rule.weights[i];
        }
        EXPECT_NEAR(weightSum, 1.0, 1e-13) << n;
        for (int p = 0; p <= 2 * n - 1; ++p)
            EXPECT_NEAR(integrate(rule, [](double x, int q) { return std::pow(x, q); }, p), 1.0 / (p + 1), 1e-12) << "n " << n << " degree " << p;
        // Degree 2n misses by exactly the remainder term (n!)^4 / ((2n+1) ((2n)!)^2) (on [0, 1], f^(2n) = (2n)!):
        // the nodes are Gauss' and not merely some exact rule. Beyond n = 8 the remainder is below round-off.
        if (n <= 8) {
            const double factN = std::tgamma(n + 1.0), fact2N = std::tgamma(2 * n + 1.0);
            const double remainder = std::pow(factN, 4) / ((2 * n + 1) * fact2N * fact2N);
            const double missed = 1.0 / (2 * n + 1) - integrate(rule, [](double x, int q) { return std::pow(x, q); }, 2 * n);
            EXPECT_NEAR(missed / remainder, 1.0, 1e-4) << n;
        }
    }
}

TEST(GaussLegendre, ManyNodesIntegrateFastOscillations) {
    // ∫0^1 cos(k x) dx = sin(k)/k for k up to the PSF tables' largest v·ρ phase (~1000).
    for (int n : {400, 1000}) {
        const QuadratureRule rule = gaussLegendre01(n);
        for (int k : {50, 300, 900}) {
            const double got = integrate(rule, [](double x, int q) { return std::cos(q * x); }, k);
            EXPECT_NEAR(got, std::sin(k) / k, 1e-11) << "n " << n << " k " << k;
        }
    }
}

TEST(GaussLegendre, RefusesNodeCountsOutsideItsRange) {
    EXPECT_THROW(gaussLegendre01(0), ConfigError);
    EXPECT_THROW(gaussLegendre01(4097), ConfigError);
}

}  // namespace
}  // namespace fluorosim
