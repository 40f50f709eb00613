#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <unistd.h>

#include "core/errors.h"
#include "geometry/geometry.h"
#include "support/temp_dir.h"

namespace fluorosim {
namespace {

// One folder per test process, removed at exit.
std::string writeTemp(const std::string& name, const std::string& text) {
    static const testing::TempDir dir;
    return dir.write(name, text).string();
}

TEST(MeshLoader, ReadsAsciiPly) {
    const std::string ply = writeTemp("quad.ply", R"(ply
format ascii 1.0
element vertex 4
property float x
property float y
property float z
element face 1
property list uchar int vertex_indices
end_header
0 0 0
2 0 0
2 3 0
0 3 0
4 0 1 2 3
)");
    const TriangleMesh m = loadMesh(ply);
    EXPECT_EQ(m.indices.size(), 6u);
    Geometry g;
    const uint32_t id = g.addMesh(m);
    EXPECT_DOUBLE_EQ(g.area(id), 6.0);
    std::filesystem::remove(ply);
}

TEST(MeshLoader, ReadsObjAndIntersects) {
    const std::string obj = writeTemp("tri.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n");
    Geometry g;
    g.addMesh(loadMesh(obj));
    g.commit();
    const auto hit = g.intersect(Ray{Vec3(0.25, 0.25, -1), Vec3(0, 0, 1)}, 0, 10);
    ASSERT_TRUE(hit);
    EXPECT_NEAR(hit->t, 1.0, 1e-12);
    EXPECT_NEAR(std::abs(hit->n.z), 1.0, 1e-12);
    std::filesystem::remove(obj);
}

TEST(MeshLoader, MissingAndBrokenFilesGiveClearErrors) {
    EXPECT_THROW(loadMesh("/nonexistent/mesh.obj"), IoError);
    const std::string bad = writeTemp("bad.ply", "ply\nthis is not a ply file\n");
    try {
        loadMesh(bad);
        FAIL() << "expected an error";
    } catch (const Error& e) {
        EXPECT_NE(std::string(e.what()).find(bad), std::string::npos) << e.what();
    }
    std::filesystem::remove(bad);
}

TEST(Geometry, SphereHitsAreExactInDoublePrecision) {
    Geometry g;
    g.addSphere(Vec3(1e3, 0, 0), 0.5);
    g.commit();
    const auto hit = g.intersect(Ray{Vec3(0, 0, 0), Vec3(1, 0, 0)}, 0, 1e9);
    ASSERT_TRUE(hit);
    EXPECT_NEAR(hit->t, 999.5, 1e-9);
    // From inside, the far side.
    const auto inside = g.intersect(Ray{Vec3(1e3, 0, 0), Vec3(0, 1, 0)}, 0, 1e9);
    ASSERT_TRUE(inside);
    EXPECT_NEAR(inside->t, 0.5, 1e-12);
}

}  // namespace
}  // namespace fluorosim
