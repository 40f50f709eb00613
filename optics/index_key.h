#pragma once
// Three integer coordinates (lattice cells, voxel blocks) within ±2^20 packed into one 64-bit hash key.
#include <array>
#include <cstdint>

namespace fluorosim::optics {

inline uint64_t packIndexKey(int64_t i, int64_t j, int64_t k) {
    return (static_cast<uint64_t>(i + (1 << 20)) << 42) | (static_cast<uint64_t>(j + (1 << 20)) << 21) | static_cast<uint64_t>(k + (1 << 20));
}

inline std::array<int64_t, 3> unpackIndexKey(uint64_t key) {
    return {static_cast<int64_t>(key >> 42) - (1 << 20), static_cast<int64_t>((key >> 21) & 0x1FFFFF) - (1 << 20),
            static_cast<int64_t>(key & 0x1FFFFF) - (1 << 20)};
}

}  // namespace fluorosim::optics
