#pragma once
// Standard exponential variates by the ziggurat method (Marsaglia & Tsang 2000, 256 strips), with
// the strip index and the uniform taken from disjoint high bits of one 64-bit draw (Doornik 2005). Exact:
// 98.9% of draws cost one table lookup and a comparison; the rest fall back to an exact wedge test or
// to the memoryless tail beyond r. Tested by chi-square in tests/statistical.
#include <array>
#include <cmath>
#include <cstdint>

namespace fluorosim {

struct ExponentialZiggurat {
    static constexpr double kR = 7.69711747013104972;     // start of the tail
    static constexpr double kV = 3.949659822581572e-3;    // area of every strip
    std::array<double, 257> x;  // strip widths, decreasing; x[0] is the base strip's virtual width
    std::array<double, 257> f;  // exp(-x)
    ExponentialZiggurat();
};

// Built before main() (no static initializer anywhere samples exponentials); an inline variable,
// so the sampler's fast path reads it without a guard.
inline const ExponentialZiggurat kExponentialZiggurat{};

// Wedge test, tail and retry: the rare cases, kept out of line so the fast path inlines.
template <class Generator>
[[gnu::noinline]] double sampleStandardExponentialSlow(Generator& rng, unsigned i, double x) {
    const ExponentialZiggurat& z = kExponentialZiggurat;
    while (true) {
        if (i == 0) return ExponentialZiggurat::kR - std::log(1.0 - rng.uniform());
        if (z.f[i] + rng.uniform() * (z.f[i + 1] - z.f[i]) < std::exp(-x)) return x;
        const uint64_t bits = rng.next64();
        i = static_cast<unsigned>((bits >> 3) & 0xffu);
        x = static_cast<double>(bits >> 11) * (1.0 / 9007199254740992.0) * z.x[i];
        if (x < z.x[i + 1]) return x;
    }
}

template <class Generator>
inline double sampleStandardExponential(Generator& rng) {
    // Strip index from bits 3-10 (the lowest bits of xoshiro256+ are weak), uniform from bits 11-63.
    const ExponentialZiggurat& z = kExponentialZiggurat;
    const uint64_t bits = rng.next64();
    const unsigned i = static_cast<unsigned>((bits >> 3) & 0xffu);
    const double x = static_cast<double>(bits >> 11) * (1.0 / 9007199254740992.0) * z.x[i];
    if (x < z.x[i + 1]) [[likely]] return x;
    return sampleStandardExponentialSlow(rng, i, x);
}

}  // namespace fluorosim
