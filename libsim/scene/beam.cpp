#include "scene/beam.h"

#include <cmath>

namespace fluorosim {

BeamCore quadraticCore(double a, double b, double c) {
    constexpr double kInf = std::numeric_limits<double>::infinity();
    BeamCore core;
    auto add = [&](double lo, double hi) {
        if (lo < hi) core.intervals[static_cast<size_t>(core.count++)] = {lo, hi};
    };
    // A vanishing quadratic term: a linear (or constant) condition.
    if (std::abs(a) <= 1e-14 * (std::abs(b) + std::sqrt(std::abs(c)) + 1e-300)) {
        if (b > 0) add(-kInf, -c / b);
        else if (b < 0) add(-c / b, kInf);
        else if (c <= 0) add(-kInf, kInf);
        return core;
    }
    const double disc = b * b - 4 * a * c;
    if (disc < 0) {
        if (a < 0) add(-kInf, kInf);  // always negative
        return core;
    }
    // Roots without cancellation (Numerical Recipes' q).
    const double q = -0.5 * (b + std::copysign(std::sqrt(disc), b));
    double r1 = q / a, r2 = q != 0 ? c / q : r1;
    if (r1 > r2) std::swap(r1, r2);
    if (a > 0) add(r1, r2);
    else {
        add(-kInf, r1);
        add(r2, kInf);
    }
    return core;
}

}  // namespace fluorosim
