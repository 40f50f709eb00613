#pragma once
// Sampling warps with their pdfs. Each sampler has a chi-square test in tests/statistical.
#include <array>
#include <cstdint>
#include <cmath>
#include <span>

#include "core/math.h"
#include "core/vec3.h"

namespace fluorosim {

inline Vec3 sampleUniformSphere(double u1, double u2) {
    const double z = 1.0 - 2.0 * u1;
    const double r = safeSqrt(1.0 - z * z);
    const double phi = 2.0 * kPi * u2;
    return {r * std::cos(phi), r * std::sin(phi), z};
}
inline constexpr double uniformSpherePdf() { return kInv4Pi; }

// Cosine-weighted hemisphere around +z (Malley's method on a concentric disk).
Vec3 sampleCosineHemisphere(double u1, double u2);
inline double cosineHemispherePdf(double cosTheta) { return cosTheta > 0 ? cosTheta * kInvPi : 0.0; }

// Uniform point on a triangle, as barycentrics (b0, b1) (Heitz 2019 low-distortion map).
std::array<double, 2> sampleUniformTriangle(double u1, double u2);

// cos(phi) for phi uniform in [0, 2 pi), without trigonometry (von Neumann 1951): for (x, y)
// uniform in the unit disk, (x^2 - y^2) / (x^2 + y^2) = cos(2 atan2(y, x)). Each candidate point takes
// two disjoint 26-bit fields from the high bits of one 64-bit draw (the lowest bits of xoshiro256+ are
// weak); 2^-26 resolution is far below any tally's noise.
template <class Generator>
double sampleCosUniformAzimuth(Generator& rng) {
    constexpr double kScale = 1.0 / 33554432.0;  // maps [0, 2^26) to [0, 2)
    constexpr uint64_t kMask = (uint64_t(1) << 26) - 1;
    while (true) {
        const uint64_t bits = rng.next64();
        const double x = static_cast<double>(bits >> 38) * kScale - 1.0;
        const double y = static_cast<double>((bits >> 12) & kMask) * kScale - 1.0;
        const double r2 = x * x + y * y;
        if (r2 <= 1.0 && r2 > 0.0) return (x * x - y * y) / r2;
    }
}

// Index into weights with probability proportional to weight; u is remapped to a fresh uniform.
int sampleDiscrete(std::span<const double> weights, double u, double* pmf = nullptr, double* uRemapped = nullptr);

// A point of [lo, hi] (finite, lo < hi) from the normal density of `mean` and `sigma` restricted to
// it, by inversion (so stratified u give stratified points), and its pdf. Uniform when sigma is
// infinite, when the interval is short against sigma, or when it lies so far in a tail that the
// normal's mass there underflows.
double sampleTruncatedNormal(double u, double mean, double sigma, double lo, double hi, double* pdf);
// The density sampleTruncatedNormal samples with, at t (0 outside [lo, hi]).
double truncatedNormalPdf(double t, double mean, double sigma, double lo, double hi);

}  // namespace fluorosim
