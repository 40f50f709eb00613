// The light-sheet microscope on samples/lightsheet/neurons.json (channel AF594: the 561 nm sheet and
// a 609/54 filter), 128 x 128 pixels of 0.406 um around the soma of C231296A-P3:
// - BM_NeuronPlane: one plane at 1, 4 and 16 spp; relative RMSE of the expected photoelectrons against
//   a 64-spp reference (another seed), and relMSE x seconds.
// - BM_NeuronStack64: a 64-plane stack (2 um steps) at 1 spp: seconds per plane.
// Needs samples/neurons/neurons.vdb (samples/neurons/make_volume.sh); skipped with an error otherwise.
#include <benchmark/benchmark.h>

#include <cmath>
#include <filesystem>
#include <fstream>

#include "bench_support.h"
#include "optics/acquisition.h"

namespace {

using namespace fluorosim;
namespace fs = std::filesystem;

using bench::db;

const fs::path kScene = fs::path(FLUOROSIM_SOURCE_DIR) / "samples" / "lightsheet" / "neurons.json";

struct Setup {
    Scene scene;
    optics::Microscope microscope;
    size_t channel;
    Setup() : scene(bench::loadBenchScene(kScene)), microscope(optics::Microscope::fromScene(scene, db())) {
        channel = microscope.channelIndex("AF594");
        microscope.width = microscope.height = 128;
        microscope.stack.planes = 64;
        microscope.stack.stepMm = 0.002;
    }
    // Plane k of a 64-plane stack (k = 32 is 1 um above the focus of the scene).
    optics::PlaneImage plane(int spp, uint64_t seed, int k = 32, int threads = 1) {
        optics::AcquireOptions o;
        o.spp = spp;
        o.seed = seed;
        o.threads = threads;
        return optics::acquirePlane(scene, microscope, channel, k, o);
    }
};

Setup& setup() {
    static Setup s;
    return s;
}

void BM_NeuronPlane(benchmark::State& state) {
    if (!fs::exists(kScene.parent_path().parent_path() / "neurons" / "neurons.vdb")) {
        state.SkipWithError("run samples/neurons/make_volume.sh first");
        return;
    }
    static const std::vector<double> reference = setup().plane(64, 999, 32, 0).electrons;
    const int spp = static_cast<int>(state.range(0));
    for (auto _ : state) {
        const optics::PlaneImage r = setup().plane(spp, 7);
        const double rmse = bench::relativeRmse(r.electrons, reference);
        state.counters["relative_rmse"] = rmse;
        state.counters["seconds"] = r.seconds;
        state.counters["relMSE_x_s"] = rmse * rmse * r.seconds;
    }
}
BENCHMARK(BM_NeuronPlane)->Arg(1)->Arg(4)->Arg(16)->Iterations(1)->Unit(benchmark::kSecond)->UseRealTime();

void BM_NeuronStack64(benchmark::State& state) {
    if (!fs::exists(kScene.parent_path().parent_path() / "neurons" / "neurons.vdb")) {
        state.SkipWithError("run samples/neurons/make_volume.sh first");
        return;
    }
    for (auto _ : state) {
        double seconds = 0;
        for (int k = 0; k < 64; ++k) seconds += setup().plane(1, 7, k, 0).seconds;
        state.counters["seconds_per_plane"] = seconds / 64;
        state.counters["seconds_total"] = seconds;
    }
}
BENCHMARK(BM_NeuronStack64)->Iterations(1)->Unit(benchmark::kSecond)->UseRealTime();

}  // namespace
