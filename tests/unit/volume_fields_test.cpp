// The volume module: reading and validating OpenVDB grids, and the majorant grid's DDA. The DDA is
// checked as a property: along random rays (including rays that start exactly on cell and grid
// boundaries, axis-aligned and grazing rays, a grid far from the origin and one with 50 nm voxels),
// its segments tile [tMin, tMax) without gaps and bound every channel at every point.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>

#include "core/errors.h"
#include "core/rng.h"
#include "support/temp_dir.h"
#include "volume/volume_fields.h"

namespace fluorosim {
namespace {

namespace fs = std::filesystem;

Affine voxels(double size, const Vec3& origin = Vec3()) { return Affine::scaling(size).then(Affine::translation(origin)); }

// A sparse, high-contrast field: a one-voxel-thick sheet at k = 7, a dense blob, and empty space.
double sparseField(int i, int j, int k) {
    if (k == 7 && i >= 0 && i < 40 && j >= 0 && j < 40) return 1e6;
    const double r2 = (i - 20.0) * (i - 20) + (j - 25.0) * (j - 25) + (k - 30.0) * (k - 30);
    return r2 < 64 ? 1.0 + 0.01 * r2 : 0.0;
}

void expectDdaBounds(const VolumeFields& f, const Ray& ray, double tMin, double tMax, Rng& rng) {
    auto tr = f.traverse(ray, tMin, tMax);
    double t = tMin;
    int segments = 0;
    std::vector<double> v(static_cast<size_t>(f.channelCount()));
    while (const auto s = tr.next()) {
        ASSERT_NEAR(s->tMin, t, 1e-9 * std::max(1.0, std::abs(t))) << "gap or overlap before segment " << segments;
        ASSERT_GE(s->tMax, s->tMin);
        for (int n = 0; n < 8; ++n) {
            const double u = n == 0 ? 0.0 : (n == 1 ? 0.999999 : rng.uniform());
            const double tt = s->tMin + u * (s->tMax - s->tMin);
            if (!std::isfinite(tt)) continue;
            f.values(ray.at(tt), v.data());
            for (int c = 0; c < f.channelCount(); ++c)
                ASSERT_LE(v[c], s->maxValues[c] * (1 + 1e-6)) << "channel " << c << " at t = " << tt << " in segment " << segments;
        }
        t = s->tMax;
        ++segments;
        ASSERT_LT(segments, 1000000);
    }
    EXPECT_NEAR(t, tMax, 1e-9 * std::max(1.0, std::abs(tMax)));
}

VolumeFields sparseFields(double voxel, const Vec3& origin, int cellVoxels) {
    const DensityGrid g = DensityGrid::fromVoxels("sparse", {{-2, -2, -2}, {45, 45, 45}}, voxels(voxel, origin), sparseField);
    std::vector<VolumeChannel> ch(2);
    ch[0].grid = g;
    ch[0].scale = 2.0;
    ch[1].offset = 0.5;  // a constant channel
    return VolumeFields(std::move(ch), Affine(), Interpolation::Trilinear, {cellVoxels});
}

TEST(MajorantGrid, DdaSegmentsTileTheRayAndBoundEveryChannel) {
    for (int cell : {-1, 0, 1, 3, 8}) {
        for (const auto& [voxel, origin] : {std::pair{0.01, Vec3()}, std::pair{5e-4, Vec3(100, -100, 100)}, std::pair{5e-5, Vec3(0.1, 0, 0)}}) {
            const VolumeFields f = sparseFields(voxel, origin, cell);
            Rng rng(11, static_cast<uint64_t>(cell + 2));
            const Vec3 centre = f.worldFromIndex().apply(Vec3(20, 20, 20));
            const double size = 60 * voxel;
            for (int r = 0; r < 300; ++r) {
                Vec3 o = centre + Vec3(rng.uniform() - 0.5, rng.uniform() - 0.5, rng.uniform() - 0.5) * (2 * size);
                Vec3 d = normalize(Vec3(rng.uniform() - 0.5, rng.uniform() - 0.5, rng.uniform() - 0.5));
                if (r % 5 == 0) d = Vec3(r % 3 == 0, r % 3 == 1, r % 3 == 2);  // axis-aligned
                if (r % 7 == 0) d = normalize(Vec3(1, 0.3, 1e-3));              // grazing the one-voxel sheet
                // Start exactly on a voxel (and so a cell) boundary in index space.
                if (r % 4 == 0) o = f.worldFromIndex().apply(Vec3(std::round(rng.uniform() * 40) - 0.0, 7, std::round(rng.uniform() * 40)));
                expectDdaBounds(f, Ray{o, d}, 0.0, 3 * size, rng);
                if (HasFatalFailure()) {
                    ADD_FAILURE() << "cell " << cell << ", voxel " << voxel << ", ray " << r;
                    return;
                }
            }
        }
    }
}

// The same property on a large sparse grid (38³ blocks of 1-voxel cells, dye in four small spots):
// long runs of empty blocks and mixed blocks' empty cells, rays that start on block faces and rays
// aimed at the spots, checked every quarter voxel as well as at random points of each segment.
TEST(MajorantGrid, LongEmptyRunsOfALargeSparseGridStillTileAndBound) {
    static constexpr int centres[4][3] = {{40, 40, 40}, {250, 60, 200}, {150, 150, 150}, {20, 280, 270}};
    const auto spots = [](int i, int j, int k) {
        for (const auto& c : centres)
            if (std::abs(i - c[0]) <= 2 && std::abs(j - c[1]) <= 1 && std::abs(k - c[2]) <= 3) return 1.0 + 0.1 * (i - c[0]);
        return 0.0;
    };
    const DensityGrid g = DensityGrid::fromVoxels("spots", {{0, 0, 0}, {299, 299, 299}}, voxels(0.01), spots);
    std::vector<VolumeChannel> ch(2);
    ch[0].grid = g;
    ch[1].offset = 0.25;
    const VolumeFields f(std::move(ch), Affine(), Interpolation::Trilinear, {1});
    Rng rng(29, 3);
    const Vec3 centre = f.worldFromIndex().apply(Vec3(150, 150, 150));
    for (int r = 0; r < 400; ++r) {
        Vec3 o = centre + Vec3(rng.uniform() - 0.5, rng.uniform() - 0.5, rng.uniform() - 0.5) * 4.0;
        Vec3 d = r % 5 == 0 ? Vec3(r % 3 == 0, r % 3 == 1, r % 3 == 2) : normalize(Vec3(rng.uniform() - 0.5, rng.uniform() - 0.5, rng.uniform() - 0.5));
        if (r % 4 == 0) o = f.worldFromIndex().apply(Vec3(8.0 * std::round(rng.uniform() * 37) - 2, 8.0 * std::round(rng.uniform() * 37) - 2, 150));  // on block faces
        if (r % 2 == 1) {  // aimed at a spot, so that the ray meets dye after a long empty run
            const auto& c = centres[(r / 2) % 4];
            d = normalize(f.worldFromIndex().apply(Vec3(c[0], c[1], c[2])) - o);
        }
        expectDdaBounds(f, Ray{o, d}, 0.0, 8.0, rng);
        if (HasFatalFailure()) {
            ADD_FAILURE() << "ray " << r;
            return;
        }
        // Every quarter voxel along the ray, not only a few points per segment: a long empty segment
        // that reached one block too far would hold a spot.
        std::vector<MajorantCellSegment> segments;
        auto tr = f.traverse(Ray{o, d}, 0.0, 8.0);
        while (const auto seg = tr.next()) segments.push_back(*seg);
        std::vector<double> v(2);
        size_t at = 0;
        for (double t = 0; t < 8.0; t += 0.0025) {
            while (at + 1 < segments.size() && segments[at].tMax <= t) ++at;
            f.values(Ray{o, d}.at(t), v.data());
            ASSERT_LE(v[0], segments[at].maxValues[0] * (1 + 1e-6)) << "ray " << r << " at t = " << t;
        }
    }
    // And the dye is still found: a ray along the first spot's row meets its maxima.
    auto tr = f.traverse(Ray{f.worldFromIndex().apply(Vec3(-5, 40, 40)), Vec3(1, 0, 0)}, 0.0, 10.0);
    double largest = 0;
    while (const auto s = tr.next()) largest = std::max(largest, s->maxValues[0]);
    EXPECT_NEAR(largest, 1.2, 1e-6);  // the grid holds floats
}

TEST(MajorantGrid, FinerCellsAreTighterAndTheGlobalCellIsTheMaximum) {
    const VolumeFields global = sparseFields(0.01, Vec3(), -1), fine = sparseFields(0.01, Vec3(), 4);
    EXPECT_EQ(global.cellCounts(), (std::array<int, 3>{1, 1, 1}));
    const auto gmax = global.channelMaxima();
    EXPECT_DOUBLE_EQ(gmax[0], 2e6);
    EXPECT_DOUBLE_EQ(gmax[1], 0.5);
    // A ray through the blob only, far from the sheet: the fine grid's majorant there is about 2 (the
    // blob), the global one 2e6.
    auto tr = fine.traverse(Ray{fine.worldFromIndex().apply(Vec3(-5, 25, 30)), Vec3(1, 0, 0)}, 0.0, 1.0);
    double largest = 0;
    while (const auto s = tr.next()) largest = std::max(largest, s->maxValues[0]);
    EXPECT_GT(largest, 1.9);
    EXPECT_LT(largest, 2.0 * (1 + 0.01 * 64) + 1e-9);
}

// Cells with the same maxima make one segment, and blocks of such cells are crossed in one step: a ray
// through a large grid's empty part costs one segment, however many cells it crosses.
TEST(MajorantGrid, EmptyAndUniformRunsAreOneSegment) {
    const DensityGrid g = DensityGrid::fromVoxels("corner", {{0, 0, 0}, {199, 199, 199}}, voxels(0.01), [](int i, int j, int k) {
        return (i < 8 && j < 8 && k < 8) || (i >= 192 && j >= 192 && k >= 192) ? 1.0 : 0.0;  // dye in two opposite corners
    });
    std::vector<VolumeChannel> ch(2);
    ch[0].grid = g;
    ch[1].offset = 0.5;
    const VolumeFields f(std::move(ch), Affine(), Interpolation::Trilinear, {1});
    EXPECT_EQ(f.cellCounts()[0], 203);  // voxels -2 .. 200
    const auto count = [&](const Ray& ray) {
        auto tr = f.traverse(ray, 0.0, 10.0);
        int n = 0;
        while (tr.next()) ++n;
        return n;
    };
    // Far from the dye: before the domain, the domain's cells (all alike), after it.
    EXPECT_EQ(count(Ray{f.worldFromIndex().apply(Vec3(-50, 100, 150)), normalize(Vec3(1, 0.1, 0.05))}), 3);
    // Through the dyed corner: a few more, not one per cell.
    const int throughDye = count(Ray{f.worldFromIndex().apply(Vec3(-50, 4, 4)), Vec3(1, 0, 0)});
    EXPECT_GE(throughDye, 4);
    EXPECT_LE(throughDye, 12);
}

TEST(MajorantGrid, BadOptionsAreRefusedByName) {
    const auto message = [](MajorantGridOptions o) {
        try {
            o.validate();
        } catch (const ConfigError& e) {
            return std::string(e.what());
        }
        return std::string("(no error)");
    };
    EXPECT_NE(message({-2}).find("majorant cell size must be >= 1 voxel"), std::string::npos);
    EXPECT_NE(message({0, 0}).find("majorant target cell count must lie in [1, 1024], got 0"), std::string::npos);
    EXPECT_NE(message({0, 64, 0}).find("majorant cell cap must be >= 1, got 0"), std::string::npos);
    EXPECT_EQ(message({}), "(no error)");
}

TEST(MajorantGrid, AllZeroGridHasNoDomain) {
    const DensityGrid g = DensityGrid::fromVoxels("zero", {{0, 0, 0}, {9, 9, 9}}, voxels(0.1), [](int, int, int) { return 0.0; });
    std::vector<VolumeChannel> ch(1);
    ch[0].grid = g;
    const VolumeFields f(std::move(ch), Affine(), Interpolation::Trilinear);
    auto tr = f.traverse(Ray{Vec3(-1, 0.5, 0.5), Vec3(1, 0, 0)}, 0.0, 3.0);
    const auto s = tr.next();
    ASSERT_TRUE(s);
    EXPECT_EQ(s->maxValues[0], 0.0);
    EXPECT_EQ(s->tMax, 3.0);
    EXPECT_FALSE(tr.next());
}

TEST(DensityGrid, InterpolationIsTrilinearOrNearest) {
    const DensityGrid g = DensityGrid::fromVoxels("ramp", {{0, 0, 0}, {3, 3, 3}}, voxels(1.0), [](int i, int, int) { return 1.0 + i; });
    EXPECT_NEAR(g.value(Vec3(1.25, 1, 1), Interpolation::Trilinear), 2.25, 1e-6);
    EXPECT_NEAR(g.value(Vec3(1.25, 1, 1), Interpolation::Nearest), 2.0, 1e-6);
    EXPECT_NEAR(g.value(Vec3(1.75, 1, 1), Interpolation::Nearest), 3.0, 1e-6);
}

std::string readError(const fs::path& file, const std::string& grid, bool labels = false) {
    try {
        (void)DensityGrid::read(file.string(), grid, labels);
    } catch (const Error& e) {
        return e.what();
    }
    return "(no error)";
}

TEST(DensityGrid, BadVoxelsAreRejectedWithGridNameAndCoordinate) {
    const testing::TempDir dir;
    const fs::path file = dir.file("bad_voxels.vdb");
    auto bad = [](double v) {
        return [v](int i, int j, int k) { return (i == 3 && j == 4 && k == 5) ? v : 1.0; };
    };
    writeVoxelGrids(file.string(), voxels(0.1),
                    {{"nan", {{0, 0, 0}, {7, 7, 7}}, bad(std::nan(""))},
                     {"inf", {{0, 0, 0}, {7, 7, 7}}, bad(INFINITY)},
                     {"negative", {{0, 0, 0}, {7, 7, 7}}, bad(-2.0)},
                     {"labels", {{0, 0, 0}, {7, 7, 7}}, [](int, int, int) { return 3.0; }, {}, true}});
    for (const char* name : {"nan", "inf", "negative"}) {
        const std::string e = readError(file, name);
        EXPECT_NE(e.find(std::string("grid \"") + name + "\""), std::string::npos) << e;
        EXPECT_NE(e.find("(3, 4, 5)"), std::string::npos) << e;
        EXPECT_NE(e.find(file.string()), std::string::npos) << e;
    }
    EXPECT_NE(readError(file, "negative").find("-2"), std::string::npos);
    // Wrong type, then accepted as labels.
    const std::string wrongType = readError(file, "labels");
    EXPECT_NE(wrongType.find("int32"), std::string::npos) << wrongType;
    EXPECT_NE(wrongType.find("expected float"), std::string::npos) << wrongType;
    EXPECT_NEAR(DensityGrid::read(file.string(), "labels", true).value(Vec3(2, 2, 2), Interpolation::Nearest), 3.0, 0);
    // A missing grid lists the ones present.
    const std::string missing = readError(file, "AF488");
    EXPECT_NE(missing.find("no grid named \"AF488\""), std::string::npos) << missing;
    EXPECT_NE(missing.find("\"negative\""), std::string::npos) << missing;
}

TEST(DensityGrid, MissingEmptyAndForeignFilesGiveClearErrors) {
    const testing::TempDir dir;
    const auto tempFile = [&](const std::string& name) { return dir.file(name); };
    EXPECT_THROW((void)DensityGrid::read(tempFile("does_not_exist.vdb").string(), "x"), IoError);
    EXPECT_NE(readError(tempFile("does_not_exist.vdb"), "x").find("no such file"), std::string::npos);
    const fs::path empty = tempFile("empty.vdb");
    std::ofstream(empty).close();
    EXPECT_THROW((void)DensityGrid::read(empty.string(), "x"), IoError);
    const fs::path text = tempFile("text.vdb");
    std::ofstream(text) << "not a volume\n";
    EXPECT_NE(readError(text, "x").find("cannot read as an OpenVDB file"), std::string::npos) << readError(text, "x");
    const fs::path noGrids = tempFile("no_grids.vdb");
    writeVoxelGrids(noGrids.string(), voxels(1), {});
    EXPECT_NE(readError(noGrids, "x").find("holds no grids"), std::string::npos) << readError(noGrids, "x");
}

TEST(VolumeFields, GridsOfOneMediumMustShareTheirVoxels) {
    const auto one = [](int, int, int) { return 1.0; };
    std::vector<VolumeChannel> ch(2);
    ch[0].grid = DensityGrid::fromVoxels("a", {{0, 0, 0}, {3, 3, 3}}, voxels(0.1), one);
    ch[1].grid = DensityGrid::fromVoxels("b", {{0, 0, 0}, {3, 3, 3}}, voxels(0.2), one);
    try {
        VolumeFields f(std::move(ch), Affine(), Interpolation::Trilinear);
        FAIL() << "no error";
    } catch (const ConfigError& e) {
        EXPECT_NE(std::string(e.what()).find("different transform"), std::string::npos) << e.what();
    }
}

TEST(DensityGrid, CorruptLengthsAreRefusedBeforeOpenVdbAllocatesThem) {
    // A grid type name claiming 2 GB used to make OpenVDB allocate and fill it (gigabytes, a minute)
    // before failing; the file's structure is now checked against its size first.
    const testing::TempDir dir;
    const fs::path file = dir.file("grid.vdb");
    writeVoxelGrids(file.string(), voxels(1), {{"density", {{0, 0, 0}, {7, 7, 7}}, [](int, int, int) { return 1.0; }}});
    std::string bytes;
    {
        std::ifstream in(file, std::ios::binary);
        bytes.assign(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
    }
    const auto at = bytes.find("Tree_float_5_4_3");
    ASSERT_NE(at, std::string::npos);
    bytes.replace(at - 4, 4, std::string("\xff\xff\xff\x7f", 4));
    std::ofstream(file, std::ios::binary | std::ios::trunc) << bytes;
    EXPECT_THROW(checkVdbStructure(file.string()), IoError);
    const std::string e = readError(file, "density");
    EXPECT_NE(e.find("corrupt OpenVDB file"), std::string::npos) << e;
    EXPECT_NE(e.find("grid type name of 2147483647 bytes"), std::string::npos) << e;
    EXPECT_NE(e.find(file.string()), std::string::npos) << e;
}

TEST(DensityGrid, ValidFilesPassTheStructureCheck) {
    const testing::TempDir dir;
    const fs::path file = dir.file("two.vdb");
    writeVoxelGrids(file.string(), voxels(0.5),
                    {{"a", {{0, 0, 0}, {9, 9, 9}}, [](int, int, int) { return 2.0; }, {"uM", "mm"}},
                     {"b", {{-4, 0, 0}, {3, 3, 3}}, [](int, int, int) { return 1.0; }, {}, true}});
    EXPECT_NO_THROW(checkVdbStructure(file.string()));
    EXPECT_NO_THROW((void)DensityGrid::read(file.string(), "a"));
    EXPECT_NO_THROW((void)DensityGrid::read(file.string(), "b", true));
}

}  // namespace
}  // namespace fluorosim
