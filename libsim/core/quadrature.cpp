#include "core/quadrature.h"

#include <cmath>
#include <string>

#include "core/errors.h"
#include "core/math.h"

namespace fluorosim {

QuadratureRule gaussLegendre01(int n) {
    if (n < 1 || n > 4096) throw ConfigError("Gauss-Legendre nodes must lie in [1, 4096], got " + std::to_string(n));
    QuadratureRule r;
    r.nodes.resize(static_cast<size_t>(n));
    r.weights.resize(static_cast<size_t>(n));
    // Newton's method on P_n from Chebyshev-like starting points; P_n by its three-term recurrence.
    for (int i = 0; i < n; ++i) {
        double x = std::cos(kPi * (i + 0.75) / (n + 0.5)), dp = 1;
        for (int it = 0; it < 100; ++it) {
            double p0 = 1, p1 = x;
            for (int k = 2; k <= n; ++k) {
                const double p2 = ((2 * k - 1) * x * p1 - (k - 1) * p0) / k;
                p0 = p1;
                p1 = p2;
            }
            const double p = n == 1 ? x : p1;
            const double pPrev = n == 1 ? 1 : p0;
            dp = n * (x * p - pPrev) / (x * x - 1);
            const double step = p / dp;
            x -= step;
            if (std::abs(step) < 1e-15) break;
        }
        r.nodes[static_cast<size_t>(i)] = 0.5 * (1 - x);
        r.weights[static_cast<size_t>(i)] = 1.0 / ((1 - x * x) * dp * dp);  // 2/((1-x²)P'²) on [-1,1], halved for [0,1]
    }
    return r;
}

}  // namespace fluorosim
