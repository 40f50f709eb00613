// Default scene: paths per second, and RMS error against a high-sample reference at several sample
// counts (error against time). The reference is rendered once per run with an independent seed.
#include <benchmark/benchmark.h>

#include <cmath>
#include <cstdio>
#include <memory>

#include "database.h"
#include "render/renderer.h"
#include "scene/scene_loader.h"

namespace {

using namespace fluorosim;

constexpr int kReferenceSpp = 2048;

struct CornellFixture {
    spectra::Database db;
    Scene scene;
    std::vector<float> reference;
    CornellFixture()
        : scene(loadScene(std::string(FLUOROSIM_SOURCE_DIR) + "/samples/cornell/scene.json",
                          [this](const std::string& ref, const std::filesystem::path& base) { return db.resolve(ref, base); })) {
        // A reduced resolution keeps the reference affordable; the per-path work is unchanged.
        scene.camera.width = 64;
        scene.camera.height = 64;
        reference = renderImage(kReferenceSpp, 999, nullptr);
    }
    std::vector<float> renderImage(int spp, uint64_t seed, double* seconds) {
        Film film(scene.camera.width, scene.camera.height, scene.spectral.lambdaMin, scene.spectral.lambdaMax,
                  scene.spectral.binWidth, db.cie1931());
        RenderOptions opt;
        opt.spp = spp;
        opt.seed = seed;
        opt.sppPerPass = 0;  // automatic
        const RenderSummary s = render(scene, film, opt);
        if (seconds) *seconds = s.seconds;
        return film.image(spp).rgb;
    }
};

CornellFixture& fixture() {
    static auto f = std::make_unique<CornellFixture>();
    return *f;
}

void BM_CornellErrorVsTime(benchmark::State& state) {
    CornellFixture& f = fixture();
    const int spp = static_cast<int>(state.range(0));
    double seconds = 0, rmse = 0;
    uint64_t seed = 1;
    for (auto _ : state) {
        const auto img = f.renderImage(spp, seed++, &seconds);
        double se = 0, refMean = 0;
        for (size_t i = 0; i < img.size(); ++i) {
            se += std::pow(static_cast<double>(img[i]) - f.reference[i], 2);
            refMean += f.reference[i];
        }
        rmse = std::sqrt(se / static_cast<double>(img.size())) / (refMean / static_cast<double>(img.size()));
    }
    const double paths = static_cast<double>(spp) * f.scene.camera.width * f.scene.camera.height;
    state.counters["paths_per_s"] = paths / seconds;
    state.counters["relative_rmse"] = rmse;
    state.counters["render_s"] = seconds;
    state.counters["rmse2_x_s"] = rmse * rmse * seconds;
}
BENCHMARK(BM_CornellErrorVsTime)->Arg(4)->Arg(16)->Arg(64)->Arg(256)->Iterations(1)->Unit(benchmark::kSecond)->UseRealTime();

}  // namespace
