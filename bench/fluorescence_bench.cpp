// Fluorescence: error against time for the full model, the paper's model and the forward photon
// tracer, on dyed balls whose escaping fluorescent power all three estimate. The reference is the
// forward tracer with 16x the photons of its largest benchmark budget (independent seed); the paper
// model's error includes its bias, which is the point of the comparison.
#include <benchmark/benchmark.h>

#include <cmath>
#include <map>

#include "bench_support.h"
#include "render/flux_sensor.h"
#include "render/photon_tracer.h"
#include "render/renderer.h"
#include "scene/scene_loader.h"

namespace {

using namespace fluorosim;

using bench::db;

// 0: optical depth 10 (radius), two overlapping dyes; 1: optical depth 100, concentrated AF488.
Scene ballScene(int which, FluorescenceModel model) {
    Scene scene;
    scene.spectral.lambdaMin = 400;
    scene.spectral.lambdaMax = 750;
    scene.render.fluorescence = model;
    std::vector<DyeComponent> dyes{{db().fluorophore("AF488"), which == 0 ? 2e-5 : 1e-4}};
    if (which == 0) dyes.push_back({db().fluorophore("AF568"), 2e-5});
    scene.media.emplace_back("ball", Spectrum::constant(0.0), Spectrum::constant(which == 0 ? 10.0 : 100.0), which == 0 ? 0.5 : 0.0, 1.0,
                             std::move(dyes));
    scene.geometry.addSphere(Vec3(0, 0, 0), 1.0);
    ShapeInfo s;
    s.isInterface = true;
    s.insideMedium = 0;
    scene.shapes.push_back(s);
    scene.lights.push_back(PointLight{Vec3(0, 0, 5), Spectrum::lines({{488, 1.0}})});
    scene.finalize();
    return scene;
}

double reference(int which) {
    static std::map<int, double> cache;
    if (!cache.count(which)) {
        const Scene scene = ballScene(which, FluorescenceModel::Full);
        ForwardPhotonOptions f;
        f.aimRadius = 1.0001;
        f.photons = which == 0 ? 16000000 : 4000000;
        f.seed = 999;
        cache[which] = traceForwardPhotons(scene, f).fluorescentPower.mean;
    }
    return cache[which];
}

void report(benchmark::State& state, double value, double stderr_, double seconds, double ref) {
    const double err2 = (value - ref) * (value - ref);
    state.counters["value"] = value;
    state.counters["rel_stderr"] = stderr_ / ref;
    state.counters["rel_error"] = std::sqrt(err2) / ref;
    state.counters["seconds"] = seconds;
    // Work-normalized error: relative (bias² + variance) x seconds.
    state.counters["relMSE_x_s"] = (err2 + stderr_ * stderr_) / (ref * ref) * seconds;
}

void BM_FluorescentBall(benchmark::State& state) {
    const int which = static_cast<int>(state.range(0));
    const int method = static_cast<int>(state.range(1));  // 0 full, 1 paper, 2 forward
    const uint64_t budget = static_cast<uint64_t>(state.range(2));
    const double ref = reference(which);
    for (auto _ : state) {
        if (method == 2) {
            const Scene scene = ballScene(which, FluorescenceModel::Full);
            ForwardPhotonOptions f;
            f.aimRadius = 1.0001;
            f.photons = budget * 10;
            f.seed = 5;
            const ForwardPhotonResult r = traceForwardPhotons(scene, f);
            report(state, r.fluorescentPower.mean, r.fluorescentPower.stderr_, r.seconds, ref);
        } else {
            const Scene scene = ballScene(which, method == 0 ? FluorescenceModel::Full : FluorescenceModel::Paper);
            FluxSensorOptions o;
            o.radius = 1.0001;
            o.paths = budget;
            o.seed = 5;
            const FluxSensorResult r = measureExitantFlux(scene, o);
            report(state, r.fluorescentPower.mean, r.fluorescentPower.stderr_, r.seconds, ref);
        }
    }
}
// Args: ball, method (0 full, 1 paper, 2 forward with 10x the budget in photons), paths.
BENCHMARK(BM_FluorescentBall)
    ->ArgsProduct({{0, 1}, {0, 1, 2}, {10000, 40000, 160000}})
    ->Iterations(1)
    ->Unit(benchmark::kSecond)
    ->UseRealTime();

// The vials sample (seven dyes in glass, lit by line area lights) at 64x64: relative RMSE of the
// fluorescent layer's RGB against a full-model reference of 1024 spp (independent seed), for the
// full and the paper model. The paper model's error includes its bias. (The forward photon tracer
// does not make images, so it is compared on the balls above only.)
struct VialsFixture {
    Scene full, paper;
    std::vector<float> reference;
    VialsFixture()
        : full(load(FluorescenceModel::Full)), paper(load(FluorescenceModel::Paper)) {
        reference = bench::renderFluorescentLayer(full, 1024, 999).rgb;
    }
    static Scene load(FluorescenceModel model) {
        Scene s = bench::loadBenchScene(std::filesystem::path(FLUOROSIM_SOURCE_DIR) / "samples" / "fluorescence" / "vials.json");
        s.camera.width = s.camera.height = 64;
        s.render.fluorescence = model;
        return s;
    }
};

void BM_VialsFluorescentLayer(benchmark::State& state) {
    static VialsFixture f;
    const bool paper = state.range(0) == 1;
    const int spp = static_cast<int>(state.range(1));
    double seconds = 0, rmse = 0;
    for (auto _ : state) {
        const bench::FluorescentRender r = bench::renderFluorescentLayer(paper ? f.paper : f.full, spp, 7);
        seconds = r.summary.seconds;
        rmse = bench::relativeRmse(r.rgb, f.reference);
    }
    state.counters["relative_rmse"] = rmse;
    state.counters["render_s"] = seconds;
    state.counters["rmse2_x_s"] = rmse * rmse * seconds;
}
BENCHMARK(BM_VialsFluorescentLayer)->ArgsProduct({{0, 1}, {16, 64, 256}})->Iterations(1)->Unit(benchmark::kSecond)->UseRealTime();

}  // namespace
