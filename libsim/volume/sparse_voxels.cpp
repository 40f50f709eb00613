#include "volume/sparse_voxels.h"

#include <algorithm>
#include <bit>

#include "core/errors.h"

namespace fluorosim {
namespace {

// Blocks a uniform region may expand into (a 128³ OpenVDB tile); larger regions stay boxes.
constexpr int64_t kMaxExpandedBlocks = 4096;
// Positions farther out cannot hold a voxel and must not overflow the int32 conversion.
constexpr double kPositionLimit = double(SparseVoxels::kCoordinateLimit) * 2;

std::string coordinateError(const std::string& where, int64_t c) {
    return where + ": voxel coordinate " + std::to_string(c) + " lies beyond +-" + std::to_string(SparseVoxels::kCoordinateLimit) +
           ", which the volume store does not support";
}

bool insideBox(const IndexBox& b, int32_t i, int32_t j, int32_t k) {
    return i >= b.lo[0] && i <= b.hi[0] && j >= b.lo[1] && j <= b.hi[1] && k >= b.lo[2] && k <= b.hi[2];
}

}  // namespace

void SparseVoxels::addBlock(const std::array<int32_t, 3>& origin, const float* values, const std::string& where) {
    for (int32_t c : origin) {
        if (!inRange(c) || !inRange(c + 7)) throw ConfigError(coordinateError(where, c));
        if (c % 8 != 0) throw Error(where + ": block origin " + std::to_string(c) + " is not a multiple of 8");
    }
    Block b;
    b.firstValue = values_.size();
    int count = 0;
    for (int word = 0; word < 8; ++word) {
        b.storedBefore[word] = static_cast<uint16_t>(count);
        for (int bit = 0; bit < 64; ++bit) {
            const float v = values[word * 64 + bit];
            if (v == background_) continue;
            b.stored[word] |= uint64_t(1) << bit;
            values_.push_back(v);
            ++count;
        }
    }
    if (count == 0) return;
    blocks_.push_back(b);
    keys_.push_back(blockKey(origin[0], origin[1], origin[2]));
}

void SparseVoxels::addUniform(const IndexBox& box, float value, const std::string& where) {
    if (box.empty() || value == background_) return;
    for (int a = 0; a < 3; ++a)
        for (int32_t c : {box.lo[a], box.hi[a]})
            if (!inRange(c)) throw ConfigError(coordinateError(where, c));
    bool aligned = true;
    int64_t count = 1;
    for (int a = 0; a < 3; ++a) {
        aligned = aligned && box.lo[a] % 8 == 0 && (box.hi[a] + 1) % 8 == 0;
        count *= (int64_t(box.hi[a]) - box.lo[a] + 1) / 8;
    }
    if (!aligned || count > kMaxExpandedBlocks) {
        largeUniform_.push_back({box, value});
        return;
    }
    for (int32_t i = box.lo[0]; i <= box.hi[0]; i += 8)
        for (int32_t j = box.lo[1]; j <= box.hi[1]; j += 8)
            for (int32_t k = box.lo[2]; k <= box.hi[2]; k += 8) {
                Block b;
                b.firstValue = kUniform;
                b.uniform = value;
                blocks_.push_back(b);
                keys_.push_back(blockKey(i, j, k));
            }
}

void SparseVoxels::finish() {
    // At most half full, so probe sequences stay short and an empty slot always ends them.
    const size_t size = std::max<size_t>(2, std::bit_ceil(2 * blocks_.size()));
    slots_.assign(size, Slot{});
    hashShift_ = 64 - std::countr_zero(size);
    for (size_t n = 0; n < keys_.size(); ++n) {
        size_t s = static_cast<size_t>((keys_[n] * 0x9E3779B97F4A7C15ULL) >> hashShift_);
        while (slots_[s].key != kEmptyKey) {
            if (slots_[s].key == keys_[n]) throw Error("volume store: a block was added twice");
            s = (s + 1) & (size - 1);
        }
        slots_[s] = {keys_[n], n};
    }
    keys_.clear();
    keys_.shrink_to_fit();
    blocks_.shrink_to_fit();
    values_.shrink_to_fit();
}

size_t SparseVoxels::memoryBytes() const {
    return sizeof(*this) + blocks_.capacity() * sizeof(Block) + values_.capacity() * sizeof(float) + slots_.capacity() * sizeof(Slot) +
           largeUniform_.capacity() * sizeof(UniformBox);
}

float SparseVoxels::outsideBlocks(int32_t i, int32_t j, int32_t k) const {
    for (const UniformBox& u : largeUniform_)
        if (insideBox(u.box, i, j, k)) return u.value;
    return background_;
}

void SparseVoxels::copyBox(const IndexBox& box, float* out) const {
    if (box.empty()) return;
    const int32_t nx = box.hi[0] - box.lo[0] + 1, ny = box.hi[1] - box.lo[1] + 1;
    for (int32_t k = box.lo[2]; k <= box.hi[2]; ++k)
        for (int32_t j = box.lo[1]; j <= box.hi[1]; ++j) {
            float* row = out + (static_cast<size_t>(k - box.lo[2]) * ny + static_cast<size_t>(j - box.lo[1])) * nx;
            for (int32_t i = box.lo[0]; i <= box.hi[0];) {
                // One block (or the stretch outside blocks up to the next block boundary) at a time.
                const int32_t end = std::min(box.hi[0], static_cast<int32_t>((i & ~7) + 7));
                const uint64_t key = blockKey(i, j, k);
                const Block* b = key == kOutsideKey ? nullptr : find(key);
                for (; i <= end; ++i)
                    row[i - box.lo[0]] = b ? b->value(voxelOffset(i, j, k), values_.data(), background_) : outsideBlocks(i, j, k);
            }
        }
}

float SparseVoxels::nearest(const Vec3& p) const {
    if (!(std::abs(p.x) < kPositionLimit && std::abs(p.y) < kPositionLimit && std::abs(p.z) < kPositionLimit)) return background_;
    return voxel(static_cast<int32_t>(std::floor(p.x + 0.5)), static_cast<int32_t>(std::floor(p.y + 0.5)),
                 static_cast<int32_t>(std::floor(p.z + 0.5)));
}

float SparseVoxels::trilinear(const Vec3& p) const {
    if (!(std::abs(p.x) < kPositionLimit && std::abs(p.y) < kPositionLimit && std::abs(p.z) < kPositionLimit)) return background_;
    const double fx = std::floor(p.x), fy = std::floor(p.y), fz = std::floor(p.z);
    const double wx = p.x - fx, wy = p.y - fy, wz = p.z - fz;
    const auto i = static_cast<int32_t>(fx), j = static_cast<int32_t>(fy), k = static_cast<int32_t>(fz);
    float v[2][2][2];  // v[di][dj][dk]
    const Block* b = nullptr;
    const bool oneBlock = (i & 7) != 7 && (j & 7) != 7 && (k & 7) != 7;
    if (oneBlock && (b = find(blockKey(i, j, k)))) {
        // The common case: all eight voxels in one stored block, found once.
        const int o = voxelOffset(i, j, k);
        for (int di = 0; di < 2; ++di)
            for (int dj = 0; dj < 2; ++dj)
                for (int dk = 0; dk < 2; ++dk) v[di][dj][dk] = b->value(o + 64 * di + 8 * dj + dk, values_.data(), background_);
    } else if (oneBlock && largeUniform_.empty()) {
        return background_;  // no block there: every voxel is the background, and so is the lerp
    } else {
        uint64_t lastKey = kEmptyKey;
        for (int di = 0; di < 2; ++di)
            for (int dj = 0; dj < 2; ++dj)
                for (int dk = 0; dk < 2; ++dk) {
                    const int32_t x = i + di, y = j + dj, z = k + dk;
                    const uint64_t key = blockKey(x, y, z);
                    if (key != lastKey) {
                        lastKey = key;
                        b = find(key);
                    }
                    v[di][dj][dk] = b ? b->value(voxelOffset(x, y, z), values_.data(), background_) : outsideBlocks(x, y, z);
                }
    }
    // NanoVDB's SampleFromVoxels<acc, 1, false>: lerp(a, b, w) = a + float(w) * (b - a), z first, then y, then x.
    const auto lerp = [](float a, float c, double w) { return a + static_cast<float>(w) * (c - a); };
    const float vx = lerp(lerp(v[0][0][0], v[0][0][1], wz), lerp(v[0][1][0], v[0][1][1], wz), wy);
    const float vx1 = lerp(lerp(v[1][0][0], v[1][0][1], wz), lerp(v[1][1][0], v[1][1][1], wz), wy);
    return lerp(vx, vx1, wx);
}

}  // namespace fluorosim
