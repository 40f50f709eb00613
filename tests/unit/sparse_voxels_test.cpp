// The sparse voxel store behind DensityGrid (volume/sparse_voxels.h): every lookup agrees with a plain
// map of the voxels that were added (blocks in negative and positive coordinates, uniform regions small
// enough to expand and too large to, a non-zero background), trilinear and nearest interpolation agree
// with a direct evaluation, and the memory follows the stored voxels rather than the 8³ blocks.
#include <gtest/gtest.h>

#include <cmath>
#include <map>
#include <tuple>

#include "core/errors.h"
#include "core/rng.h"
#include "volume/density_grid.h"
#include "volume/sparse_voxels.h"

namespace fluorosim {
namespace {

using Voxel = std::tuple<int32_t, int32_t, int32_t>;

struct Reference {
    float background = 0;
    std::map<Voxel, float> voxels;
    std::vector<std::pair<IndexBox, float>> uniform;
    float at(int32_t i, int32_t j, int32_t k) const {
        if (const auto it = voxels.find({i, j, k}); it != voxels.end()) return it->second;
        for (const auto& [b, v] : uniform)
            if (i >= b.lo[0] && i <= b.hi[0] && j >= b.lo[1] && j <= b.hi[1] && k >= b.lo[2] && k <= b.hi[2]) return v;
        return background;
    }
};

// Random sparse blocks (about 5 % of their voxels stored) at block origins in [-5, 4]³ × 8, and four
// uniform regions: an 8³ tile and a 16 x 8 x 8 region (expanded into blocks), a region not aligned to
// blocks and one of 4224 blocks (both kept as boxes).
std::pair<SparseVoxels, Reference> randomStore(float background, uint64_t seed) {
    Rng rng = Rng::forKey(seed, 0, 0);
    SparseVoxels store(background);
    Reference ref;
    ref.background = background;
    for (int bi = -5; bi < 5; ++bi)
        for (int bj = -5; bj < 5; ++bj)
            for (int bk = -5; bk < 5; ++bk) {
                if (bk == 4 || rng.uniform() < 0.5) continue;  // bk == 4 stays free for the uniform regions
                std::array<float, SparseVoxels::kBlockVoxels> values;
                values.fill(background);
                for (int n = 0; n < SparseVoxels::kBlockVoxels; ++n) {
                    if (rng.uniform() >= 0.05) continue;
                    values[n] = static_cast<float>(100 * rng.uniform());
                    ref.voxels[{bi * 8 + (n >> 6), bj * 8 + ((n >> 3) & 7), bk * 8 + (n & 7)}] = values[n];
                }
                store.addBlock({bi * 8, bj * 8, bk * 8}, values.data(), "test");
            }
    const std::vector<std::pair<IndexBox, float>> regions = {
        {{{0, 0, 32}, {7, 7, 39}}, 7.5f},
        {{{-16, 8, 32}, {-1, 15, 39}}, 3.25f},
        {{{-130, -40, 33}, {127, -33, 39}}, 1.5f},
        {{{-512, -1024, 32}, {511, -761, 39}}, 2.5f}};
    for (const auto& [box, v] : regions) {
        store.addUniform(box, v, "test");
        ref.uniform.push_back({box, v});
    }
    store.finish();
    return {std::move(store), std::move(ref)};
}

TEST(SparseVoxels, EveryVoxelMatchesWhatWasAdded) {
    for (const float background : {0.0f, 0.5f}) {
        const auto [store, ref] = randomStore(background, 3);
        ASSERT_GT(ref.voxels.size(), 1000u);
        for (int32_t i = -42; i < 42; ++i)
            for (int32_t j = -42; j < 42; ++j)
                for (int32_t k = -42; k < 42; ++k) ASSERT_EQ(store.voxel(i, j, k), ref.at(i, j, k)) << i << " " << j << " " << k;
        EXPECT_EQ(store.voxel(-131, -36, 35), background);  // just outside the unaligned region
        EXPECT_EQ(store.voxel(127, -33, 39), 1.5f);
        EXPECT_EQ(store.voxel(-512, -1024, 32), 2.5f);
        EXPECT_EQ(store.voxel(511, -761, 39), 2.5f);
        EXPECT_EQ(store.voxel(512, -761, 39), background);
        EXPECT_EQ(store.voxel(SparseVoxels::kCoordinateLimit, 0, 0), background);
        EXPECT_EQ(store.voxel(-SparseVoxels::kCoordinateLimit - 1, 0, 0), background);
        EXPECT_EQ(store.voxel(INT32_MIN, INT32_MAX, 0), background);
    }
}

TEST(SparseVoxels, TrilinearAndNearestAgreeWithDirectEvaluation) {
    const auto [store, ref] = randomStore(0.25f, 5);
    Rng rng = Rng::forKey(11, 0, 0);
    for (int n = 0; n < 200000; ++n) {
        // Half of the points on block boundaries, where the eight voxels span several blocks.
        const auto coordinate = [&] {
            const double c = -41 + 82 * rng.uniform();
            return n % 2 ? c : 8 * std::round(c / 8) - 0.5 + rng.uniform() * 1e-3;
        };
        const Vec3 p(coordinate(), coordinate(), coordinate());
        const int32_t i = static_cast<int32_t>(std::floor(p.x)), j = static_cast<int32_t>(std::floor(p.y)),
                      k = static_cast<int32_t>(std::floor(p.z));
        const double u = p.x - i, v = p.y - j, w = p.z - k;
        double expected = 0;
        for (int di = 0; di < 2; ++di)
            for (int dj = 0; dj < 2; ++dj)
                for (int dk = 0; dk < 2; ++dk)
                    expected += (di ? u : 1 - u) * (dj ? v : 1 - v) * (dk ? w : 1 - w) * ref.at(i + di, j + dj, k + dk);
        // Float arithmetic on values up to 100.
        ASSERT_NEAR(store.trilinear(p), expected, 1e-4) << p.x << " " << p.y << " " << p.z;
        const int32_t ri = static_cast<int32_t>(std::floor(p.x + 0.5)), rj = static_cast<int32_t>(std::floor(p.y + 0.5)),
                      rk = static_cast<int32_t>(std::floor(p.z + 0.5));
        ASSERT_EQ(store.nearest(p), ref.at(ri, rj, rk));
    }
    EXPECT_EQ(store.trilinear(Vec3(1e300, 0, 0)), 0.25f);
    EXPECT_EQ(store.nearest(Vec3(-1e12, 3, 3)), 0.25f);
}

TEST(SparseVoxels, CoordinatesBeyondTheLimitAreRefusedNamingTheGrid) {
    SparseVoxels store;
    std::array<float, SparseVoxels::kBlockVoxels> values;
    values.fill(1);
    try {
        store.addBlock({SparseVoxels::kCoordinateLimit, 0, 0}, values.data(), "f.vdb: grid \"far\"");
        FAIL() << "no error";
    } catch (const ConfigError& e) {
        EXPECT_NE(std::string(e.what()).find("f.vdb: grid \"far\""), std::string::npos) << e.what();
        EXPECT_NE(std::string(e.what()).find(std::to_string(SparseVoxels::kCoordinateLimit)), std::string::npos) << e.what();
    }
    EXPECT_THROW(store.addUniform({{0, 0, 0}, {7, 7, SparseVoxels::kCoordinateLimit + 8}}, 1.0f, "g"), ConfigError);
}

// One voxel in each of 4096 blocks: dense 8³ float blocks would hold 8 MiB; the store keeps the voxel
// values and per-block bookkeeping only.
TEST(SparseVoxels, MemoryFollowsStoredVoxels) {
    const DensityGrid g = DensityGrid::fromVoxels("dots", {{0, 0, 0}, {127, 127, 127}}, Affine::scaling(0.001),
                                                  [](int i, int j, int k) { return i % 8 == 3 && j % 8 == 5 && k % 8 == 1 ? 2.0 : 0.0; });
    const size_t denseBytes = 4096 * SparseVoxels::kBlockVoxels * sizeof(float);
    EXPECT_LT(g.memoryBytes(), denseBytes / 8);
    EXPECT_EQ(g.value(Vec3(3, 5, 1), Interpolation::Nearest), 2.0);
    EXPECT_EQ(g.value(Vec3(3.5, 5, 1), Interpolation::Trilinear), 1.0);
}

}  // namespace
}  // namespace fluorosim
