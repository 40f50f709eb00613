#pragma once
#include <algorithm>
#include <cmath>

namespace fluorosim {

inline constexpr double kPi = 3.14159265358979323846;
inline constexpr double kInvPi = 1.0 / kPi;
inline constexpr double kInv4Pi = 1.0 / (4.0 * kPi);
inline constexpr double kLn10 = 2.30258509299404568402;

template <class T>
inline T sqr(T x) { return x * x; }
inline double safeSqrt(double x) { return std::sqrt(std::max(0.0, x)); }
inline double lerp(double t, double a, double b) { return (1.0 - t) * a + t * b; }
inline double clamp01(double x) { return std::clamp(x, 0.0, 1.0); }

// Power heuristic (beta = 2) for two-strategy MIS.
inline double powerHeuristic(double pdfA, double pdfB) {
    const double a = pdfA * pdfA, b = pdfB * pdfB;
    if (std::isinf(a)) return 1.0;
    return (a + b) > 0.0 ? a / (a + b) : 0.0;
}

}  // namespace fluorosim
