#pragma once
// Gauss–Legendre quadrature: n nodes and weights on [0, 1], exact for polynomials of degree 2n − 1.
#include <vector>

namespace fluorosim {

struct QuadratureRule {
    std::vector<double> nodes, weights;  // weights sum to 1
};
QuadratureRule gaussLegendre01(int n);  // throws ConfigError for n < 1 or n > 4096

}  // namespace fluorosim
