// Surface look-ups of a light-sheet scene: samples/lightsheet's tissue block inside its water bath (two boxes
// of 12 triangles), rays from inside the block in isotropic directions to infinity, as the
// photons' free flights ask for them.
#include <benchmark/benchmark.h>

#include <cmath>
#include <string>
#include <vector>

#include "core/math.h"
#include "core/rng.h"
#include "geometry/geometry.h"

namespace {

using namespace fluorosim;

// One of the sample's meshes (µm in its file) in mm, as the scene loader scales it.
TriangleMesh sampleMesh(const std::string& file) {
    TriangleMesh mesh = loadMesh(std::string(FLUOROSIM_SOURCE_DIR) + "/samples/" + file);
    for (Vec3& p : mesh.positions) p = p * 1e-3;
    return mesh;
}

void BM_BoxSceneIntersect(benchmark::State& state) {
    Geometry geometry;
    geometry.addMesh(sampleMesh("lightsheet/neurons_bath.obj"));
    geometry.addMesh(sampleMesh("neurons/tissue_block.obj"));
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
