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
#include <nlohmann/json.hpp>

#include "bench_support.h"
#include "optics/acquisition.h"
#include "optics/light_sheet.h"
#include "scene/scene_loader.h"

namespace {

using namespace fluorosim;
namespace fs = std::filesystem;

using bench::db;

const fs::path kScene = fs::path(FLUOROSIM_SOURCE_DIR) / "samples" / "lightsheet" / "neurons.json";

struct Setup {
    Scene scene;
    optics::ObjectiveOptions objective;
    optics::FocalPlane focus;
    optics::Filter filter = optics::Filter::open();
    optics::DetectorOptions detector;
    Setup()
        : scene(bench::loadBenchScene(kScene)) {
        scene.lights.erase(scene.lights.begin());  // keep the 561 nm sheet
        const nlohmann::json m = nlohmann::json::parse(scene.microscopeJson);
        objective.na = m["objective"]["na"];
        objective.magnification = m["objective"]["magnification"];
        objective.workingDistanceMm = 0.2;
        focus.centreMm = Vec3(0.017, -0.284, 0);
        filter = optics::Filter::fromDatabase(db(), "semrock_FF01-609-54");
        detector.exposureS = 0.02;
    }
    optics::PlaneResult plane(int spp, uint64_t seed, double zMm = 0, int threads = 1) {
        for (Light& l : scene.lights) std::get<BeamLight>(l).profile->moveTo(zMm);
        optics::FocalPlane f = focus;
        f.centreMm = focus.centreMm + Vec3(0, 0, zMm);
        optics::PlaneRenderOptions o;
        o.width = o.height = 128;
        o.spp = spp;
        o.seed = seed;
        o.threads = threads;
        return optics::renderPlane(scene, objective, f, filter, detector, o);
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
    static const std::vector<double> reference = setup().plane(64, 999, 0, 0).electrons;
    const int spp = static_cast<int>(state.range(0));
    for (auto _ : state) {
        const optics::PlaneResult r = setup().plane(spp, 7);
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
        for (int k = 0; k < 64; ++k) seconds += setup().plane(1, 7, (k - 31.5) * 0.002, 0).seconds;
        state.counters["seconds_per_plane"] = seconds / 64;
        state.counters["seconds_total"] = seconds;
    }
}
BENCHMARK(BM_NeuronStack64)->Iterations(1)->Unit(benchmark::kSecond)->UseRealTime();

}  // namespace
