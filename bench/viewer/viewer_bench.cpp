// Frame times of the viewer (issue 13's goals: a 256³ volume renders a still frame in under 1 s and
// an interactive one in under 250 ms, and a z step takes under 50 ms, on Mesa's llvmpipe with 2 cores).
// Runs under X: `xvfb-run -a build/bench/fluorosim_viewer_bench`. The scene: two dye grids of
// 256 x 256 x 256 voxels of 1 µm (AF488 dense everywhere, AF594 two rods), a light sheet and a
// microscope with 64 planes of 2 µm; the window is 1280 x 800, the viewer's default.
// - BM_Still/{cpu,gpu}: the 3D view alone, a full-quality frame after turning the camera by 1°.
// - BM_Interactive/{cpu,gpu}: the same at the interactive rate, as while the view is dragged.
// - BM_OverviewStill/{cpu,gpu}: the four-view layout, every view redrawn.
// - BM_ZStep/{cpu,gpu}: one plane up or down in the four-view layout, as the arrow keys do it.
#include <benchmark/benchmark.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>

#include "viewer/viewer.h"
#include "volume/density_grid.h"

namespace {

using namespace fluorosim;
namespace fs = std::filesystem;
using json = nlohmann::json;

constexpr int kN = 256;

// Writes the grids (once; about 10 s) and the scene; returns the scene's path.
fs::path benchScene() {
    const fs::path dir = fs::temp_directory_path() / "fluorosim_viewer_bench";
    const fs::path vdb = dir / "grid256.vdb", scene = dir / "scene.json";
    if (!fs::exists(vdb)) {
        fs::create_directories(dir);
        const IndexBox box{{0, 0, 0}, {kN - 1, kN - 1, kN - 1}};
        writeVoxelGrids(vdb.string(), Affine::scaling(1e-3),
                        {{"green", box, [](int i, int j, int k) { return 5 * (1.2 + std::sin(i / 7.0) * std::sin(j / 9.0) * std::sin(k / 11.0)); },
                          {"uM", "mm"}},
                         {"magenta", box,
                          [](int i, int j, int k) {
                              const double a = (i - 128.0) * (i - 128.0) + (j - 128.0) * (j - 128.0);
                              const double b = (j - 64.0) * (j - 64.0) + (k - 128.0) * (k - 128.0);
                              return 10 * (std::exp(-a / 50) + std::exp(-b / 50));
                          },
                          {"uM", "mm"}}});
    }
    const json centre = {"0.128 mm", "0.128 mm", "0.128 mm"};
    const json s{
        {"fluorosim_scene", 1},
        {"spectral", {{"range", {"450 nm", "700 nm"}}}},
        {"camera", {{"position", {"0.128 mm", "0.128 mm", "2 mm"}}, {"look_at", centre}, {"fov_y_deg", 10}, {"resolution", {8, 8}}, {"medium", "tissue"}}},
        {"media",
         {{"tissue",
           {{"ior", 1.33},
            {"dyes", json::array({json{{"dye", "AF488"}, {"grid", "green"}}, json{{"dye", "AF594"}, {"grid", "magenta"}}})},
            {"volume", {{"file", "grid256.vdb"}}}}}}},
        {"shapes", json::array({json{{"type", "sphere"}, {"name", "bath"}, {"center", centre}, {"radius", "1 mm"}, {"interior", "tissue"}}})},
        {"lights", json::array({json{{"type", "light_sheet"}, {"wavelength", "488 nm"}, {"power_mW", 1}, {"propagation", {1, 0, 0}},
                                     {"normal", {0, 0, 1}}, {"center", centre}, {"waist", "2 um"}, {"height", "0.3 mm"}}})},
        {"microscope",
         {{"objective", {{"na", 0.8}, {"magnification", 16}, {"immersion_index", 1.33}, {"working_distance", "3 mm"}}},
          {"focus", {{"center", centre}, {"toward_objective", {0, 0, 1}}, {"up", {0, 1, 0}}}},
          {"detector", {{"width", 256}, {"height", 256}, {"pixel_pitch", "6.5 um"}}},
          {"channels", json::array({json{{"name", "AF488"}, {"emission_filter", "semrock_FF01-525-45"}, {"lights", {0}}}})},
          {"stack", {{"planes", 64}, {"step", "2 um"}}}}}};
    std::ofstream(scene) << s.dump(1);
    return scene;
}

viewer::ViewerOptions options(int64_t gpu, viewer::ViewPreset view) {
    viewer::ViewerOptions o;
    o.scene = benchScene();
    o.findSwc = false;
    o.offscreen = true;
    o.width = 1280;
    o.height = 800;
    o.view = view;
    o.mapper = gpu ? viewer::MapperChoice::Gpu : viewer::MapperChoice::Cpu;
    return o;
}

void BM_Still(benchmark::State& state) {
    viewer::Viewer v(options(state.range(0), viewer::ViewPreset::ThreeD));
    v.render();
    for (auto _ : state) {
        v.orbit(1);
        v.render();
    }
    state.SetLabel(v.mapperName());
}
BENCHMARK(BM_Still)->Arg(0)->Arg(1)->Unit(benchmark::kMillisecond)->UseRealTime()->MinTime(3);

void BM_Interactive(benchmark::State& state) {
    viewer::Viewer v(options(state.range(0), viewer::ViewPreset::ThreeD));
    v.render();
    for (auto _ : state) {
        v.orbit(1);
        v.renderInteractive();
    }
    state.SetLabel(v.mapperName());
}
BENCHMARK(BM_Interactive)->Arg(0)->Arg(1)->Unit(benchmark::kMillisecond)->UseRealTime()->MinTime(3);

void BM_OverviewStill(benchmark::State& state) {
    viewer::Viewer v(options(state.range(0), viewer::ViewPreset::Overview));
    v.render();
    for (auto _ : state) {
        v.orbit(1);
        v.render();
    }
    state.SetLabel(v.mapperName());
}
BENCHMARK(BM_OverviewStill)->Arg(0)->Arg(1)->Unit(benchmark::kMillisecond)->UseRealTime()->MinTime(3);

void BM_ZStep(benchmark::State& state) {
    viewer::Viewer v(options(state.range(0), viewer::ViewPreset::Overview));
    v.render();
    int direction = 1;
    for (auto _ : state) {
        if (v.plane() + direction < 0 || v.plane() + direction >= v.planeCount()) direction = -direction;
        v.stepPlane(direction);
    }
    state.SetLabel(v.mapperName());
}
BENCHMARK(BM_ZStep)->Arg(0)->Arg(1)->Unit(benchmark::kMillisecond)->UseRealTime()->MinTime(2);

}  // namespace
