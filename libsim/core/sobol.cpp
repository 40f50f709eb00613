#include "core/sobol.h"

#include <boost/random/sobol.hpp>

#include "core/errors.h"
#include "core/rng.h"

namespace fluorosim {
namespace {

uint32_t reverseBits(uint32_t v) {
    v = ((v >> 1) & 0x55555555u) | ((v & 0x55555555u) << 1);
    v = ((v >> 2) & 0x33333333u) | ((v & 0x33333333u) << 2);
    v = ((v >> 4) & 0x0F0F0F0Fu) | ((v & 0x0F0F0F0Fu) << 4);
    v = ((v >> 8) & 0x00FF00FFu) | ((v & 0x00FF00FFu) << 8);
    return (v >> 16) | (v << 16);
}

// Burley's improved Laine-Karras permutation: each bit flips depending only on the bits below it
// (in reversed order, the bits above it in the original), which is Owen's nested scrambling.
uint32_t laineKarrasPermutation(uint32_t x, uint32_t seed) {
    x += seed;
    x ^= x * 0x6c50b47cu;
    x ^= x * 0xb82f1e52u;
    x ^= x * 0xc7afe638u;
    x ^= x * 0x8d22f6e6u;
    return x;
}

}  // namespace

SobolTable::SobolTable(int dimensions, int points) : dimensions_(dimensions), points_(points) {
    if (dimensions < 1 || dimensions > 1000 || points < 1 || points > (1 << 24))
        throw ConfigError("Sobol' table: dimensions in [1, 1000] and points in [1, 2^24], got " + std::to_string(dimensions) + " and " +
                          std::to_string(points));
    table_.assign(static_cast<size_t>(dimensions) * static_cast<size_t>(points), 0u);
    boost::random::sobol_engine<uint32_t, 32> engine(static_cast<std::size_t>(dimensions));
    // Boost starts at the second point of the sequence; the first is the origin.
    for (size_t i = static_cast<size_t>(dimensions); i < table_.size(); ++i) table_[i] = engine();
}

double SobolTable::sample(int index, int dim, uint64_t seed) const {
    const uint32_t v = table_[static_cast<size_t>(index) * static_cast<size_t>(dimensions_) + static_cast<size_t>(dim)];
    const uint32_t s = static_cast<uint32_t>(mixBits(seed + 0x9E3779B97F4A7C15ULL * static_cast<uint64_t>(dim + 1)));
    const uint32_t scrambled = reverseBits(laineKarrasPermutation(reverseBits(v), s));
    // 32 bits of the point, plus half an ulp of them so that 0 maps inside the first cell's interior.
    return (static_cast<double>(scrambled) + 0.5) * (1.0 / 4294967296.0);
}

}  // namespace fluorosim
