// Surface look-ups of a light-sheet scene: a tissue block inside a water bath (two boxes of 12 triangles, in
// mm, as samples/lightsheet has them), rays from inside the block in isotropic directions to infinity, as the
// photons' free flights ask for them.
#include <benchmark/benchmark.h>

#include <cmath>
#include <vector>

#include "core/math.h"
#include "core/rng.h"
#include "geometry/geometry.h"

namespace {

using namespace fluorosim;

TriangleMesh boxMesh(const Vec3& lo, const Vec3& hi) {
    TriangleMesh m;
    for (int i = 0; i < 8; ++i) m.positions.push_back(Vec3((i & 1) ? hi.x : lo.x, (i & 2) ? hi.y : lo.y, (i & 4) ? hi.z : lo.z));
    // Two triangles per face, wound outward.
    m.indices = {0, 2, 1, 1, 2, 3, 4, 5, 6, 5, 7, 6, 0, 1, 4, 1, 5, 4, 2, 6, 3, 3, 6, 7, 0, 4, 2, 2, 4, 6, 1, 3, 5, 3, 7, 5};
    return m;
}

void BM_BoxSceneIntersect(benchmark::State& state) {
    Geometry geometry;
    geometry.addMesh(boxMesh(Vec3(-1.1, -0.87, -0.36), Vec3(0.55, 0.57, 1.2)));
    geometry.addMesh(boxMesh(Vec3(-1.0, -0.77, -0.26), Vec3(0.45, 0.47, 0.25)));
    geometry.commit();
    constexpr int kRays = 4096;
    std::vector<Ray> rays;
    Rng rng(5, 0);
    for (int i = 0; i < kRays; ++i) {
        const Vec3 o(-0.04 + 0.2 * (2 * rng.uniform() - 1), -0.02 + 0.2 * (2 * rng.uniform() - 1), 0.008 + 0.1 * (2 * rng.uniform() - 1));
        const double z = 2 * rng.uniform() - 1, phi = 2 * kPi * rng.uniform(), s = std::sqrt(1 - z * z);
        rays.push_back(Ray{o, Vec3(s * std::cos(phi), s * std::sin(phi), z)});
    }
    double sum = 0;
    for (auto _ : state)
        for (const Ray& r : rays)
            if (const auto hit = geometry.intersect(r, 0.0, std::numeric_limits<double>::infinity())) sum += hit->t;
    benchmark::DoNotOptimize(sum);
    state.SetItemsProcessed(state.iterations() * kRays);
}
BENCHMARK(BM_BoxSceneIntersect)->Unit(benchmark::kMicrosecond);

}  // namespace
