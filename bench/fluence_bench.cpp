// The excitation field's tallies (FluenceGrid::deposit): tracks through a box shaped like a light sheet's
// field (16 um nodes along the focal plane, 0.5 um across the sheet, 40 um deep), as the field's photons lay
// them. A track that crosses the sheet cuts ~80 node planes: the tallies are about a sixth of an adaptive
// plane's time at sigma_s 2 /mm (docs/performance.md, "The field's tallies").
#include <benchmark/benchmark.h>

#include <cmath>
#include <vector>

#include "core/math.h"
#include "core/rng.h"
#include "render/fluence_field.h"

namespace {

using namespace fluorosim;

void BM_FluenceDeposit(benchmark::State& state) {
    FieldBox box;
    box.halfX = box.halfY = 0.2;
    box.halfZ = 0.02;
    box.hx = box.hy = 0.016;
    box.hz = 0.0005;
    FluenceGrid grid(box);
    // Isotropic tracks of 0.1 mm (a mean free path at sigma_s 10 /mm) starting anywhere in the box.
    constexpr int kTracks = 4096;
    std::vector<std::pair<Vec3, Vec3>> tracks;
    Rng rng(3, 0);
    for (int i = 0; i < kTracks; ++i) {
        const Vec3 a((2 * rng.uniform() - 1) * box.halfX, (2 * rng.uniform() - 1) * box.halfY, (2 * rng.uniform() - 1) * box.halfZ);
        const double z = 2 * rng.uniform() - 1, phi = 2 * kPi * rng.uniform(), s = std::sqrt(1 - z * z);
        tracks.push_back({a, a + Vec3(s * std::cos(phi), s * std::sin(phi), z) * 0.1});
    }
    for (auto _ : state)
        for (const auto& [a, b] : tracks) grid.deposit(a, b, 1.0);
    benchmark::DoNotOptimize(grid.at(Vec3(0, 0, 0)));
    state.SetItemsProcessed(state.iterations() * kTracks);
}
BENCHMARK(BM_FluenceDeposit)->Unit(benchmark::kMicrosecond);

}  // namespace
