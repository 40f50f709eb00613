#pragma once
// The in-memory store behind DensityGrid: only the voxels whose value differs from the background,
// in 8³ blocks (OpenVDB's leaf size and voxel order) found through one open-addressing hash table.
// It replaced NanoVDB, which held the neuron volumes at 7-16x their .vdb file: full 8³ float leaves
// where neurites fill 2-20 % of the voxels, and fixed 32³ and 16³ internal nodes (2.2 MB for the
// eight upper nodes of a grid straddling the origin). Here a block costs 96 bytes (its voxel mask,
// prefix counts and the offset of its values) plus 32 bytes of hash slots, and a stored voxel 4 bytes,
// so values stay exact (float, as in the file) and no internal node exists.
//
// Regions of one value (OpenVDB tiles) become uniform blocks up to 128³ voxels; larger ones are kept
// as boxes and searched only when no block holds the voxel. Voxel coordinates must lie within
// ±kCoordinateLimit (±8.4 million voxels: ±2 m at 0.25 µm); lookups outside return the background.
// Read-only after building; lookups are thread-safe.
#include <array>
#include <cmath>
#include <cstdint>
#include <string>
#include <vector>

#include "volume/density_grid.h"

namespace fluorosim {

class SparseVoxels {
public:
    static constexpr int32_t kCoordinateLimit = 1 << 23;
    static constexpr int kBlockVoxels = 512;

    explicit SparseVoxels(float background = 0) : background_(background) {}

    // Building. A block is given by its origin (multiple of 8 on every axis) and its 512 values in
    // OpenVDB leaf order (offset = 64 x + 8 y + z within the block); only values other than the
    // background are kept, and a block of background alone is dropped. Each block origin may be added
    // once, and a uniform region must not overlap a block. Throw ConfigError (naming `where`) for
    // coordinates beyond the limit.
    void addBlock(const std::array<int32_t, 3>& origin, const float* values, const std::string& where);
    void addUniform(const IndexBox& box, float value, const std::string& where);
    // Builds the hash table; call once after the last add, before any lookup.
    void finish();

    float background() const { return background_; }
    size_t blockCount() const { return blocks_.size(); }
    size_t storedVoxelCount() const { return values_.size(); }
    size_t memoryBytes() const;

    // The value of voxel (i, j, k): the background where nothing is stored.
    float voxel(int32_t i, int32_t j, int32_t k) const {
        const Block* b = find(blockKey(i, j, k));
        return b ? b->value(voxelOffset(i, j, k), values_.data(), background_) : outsideBlocks(i, j, k);
    }
    // Nearest voxel to an index-space position (voxel centres at integers; ties round up, as NanoVDB).
    float nearest(const Vec3& p) const;
    // Trilinear interpolation of the eight voxels around p, in float with NanoVDB's order of operations,
    // so results match the NanoVDB sampler bit for bit.
    float trilinear(const Vec3& p) const;
    // The voxels of `box` into out (x fastest, then y, then z), one hash lookup per 8³ block.
    void copyBox(const IndexBox& box, float* out) const;

private:
    struct Block {
        std::array<uint64_t, 8> stored{};        // bit 8 y + z of word x: voxel (x, y, z) holds a value
        std::array<uint16_t, 8> storedBefore{};  // stored voxels in the words before each word
        uint64_t firstValue = 0;                 // index of the block's first value in values_
        float uniform = 0;                       // the value of every voxel when firstValue == kUniform
        float value(int offset, const float* values, float background) const {
            if (firstValue == kUniform) return uniform;
            const int word = offset >> 6;
            const uint64_t bit = uint64_t(1) << (offset & 63);
            if (!(stored[word] & bit)) return background;
            return values[firstValue + storedBefore[word] + popcount(stored[word] & (bit - 1))];
        }
    };
    struct Slot {
        uint64_t key = kEmptyKey;
        uint64_t block = 0;
    };
    struct UniformBox {
        IndexBox box;
        float value;
    };
    static constexpr uint64_t kUniform = ~uint64_t(0);
    static constexpr uint64_t kEmptyKey = ~uint64_t(0);
    static constexpr uint64_t kOutsideKey = ~uint64_t(0) - 1;  // never stored, so never found

    static int popcount(uint64_t x) {
        // Portable SWAR count; the build does not assume the POPCNT instruction.
        x = x - ((x >> 1) & 0x5555555555555555ULL);
        x = (x & 0x3333333333333333ULL) + ((x >> 2) & 0x3333333333333333ULL);
        x = (x + (x >> 4)) & 0x0f0f0f0f0f0f0f0fULL;
        return static_cast<int>((x * 0x0101010101010101ULL) >> 56);
    }
    static bool inRange(int32_t c) { return static_cast<uint32_t>(c + kCoordinateLimit) < 2u * kCoordinateLimit; }
    // 21 bits per axis of the block coordinate (voxel >> 3), offset to be non-negative.
    static uint64_t blockKey(int32_t i, int32_t j, int32_t k) {
        if (!inRange(i) || !inRange(j) || !inRange(k)) return kOutsideKey;
        constexpr int32_t bias = kCoordinateLimit >> 3;
        return (uint64_t((i >> 3) + bias) << 42) | (uint64_t((j >> 3) + bias) << 21) | uint64_t((k >> 3) + bias);
    }
    static int voxelOffset(int32_t i, int32_t j, int32_t k) { return ((i & 7) << 6) | ((j & 7) << 3) | (k & 7); }
    const Block* find(uint64_t key) const {
        size_t s = static_cast<size_t>((key * 0x9E3779B97F4A7C15ULL) >> hashShift_);
        while (true) {
            const Slot& slot = slots_[s];
            if (slot.key == key) return &blocks_[slot.block];
            if (slot.key == kEmptyKey) return nullptr;
            s = (s + 1) & (slots_.size() - 1);
        }
    }
    float outsideBlocks(int32_t i, int32_t j, int32_t k) const;
    void addKey(uint64_t key, const std::string& where);

    float background_;
    std::vector<Block> blocks_;
    std::vector<float> values_;
    std::vector<Slot> slots_{Slot{}, Slot{}};  // empty until finish(), so lookups are always defined
    int hashShift_ = 63;                       // 64 - log2(slots_.size())
    std::vector<UniformBox> largeUniform_;
    std::vector<uint64_t> keys_;  // of blocks_, until finish() puts them into slots_
};

}  // namespace fluorosim
