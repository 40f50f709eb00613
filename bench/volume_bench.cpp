// Grid media on the neuron sample (samples/neurons, three voxelized neurons in weakly scattering
// tissue), on a 64 x 64 crop around the large neuron's soma:
// - BM_NeuronMajorant: one global majorant cell against the majorant grid (automatic cells):
//   null collisions per real collision, tentative collisions per second on one core, and the relative
//   RMSE of the fluorescent layer against a 1024-spp reference (grid majorant, independent seed),
//   with the work-normalized error relMSE x seconds.
// - BM_NeuronResolution: the same crop from volumes voxelized at 1, 0.5 and 0.25 um: cost per path
//   against the grid's size, and the volume's memory (sparse voxel blocks plus majorant cells) against the
//   size of the .vdb file.
#include <benchmark/benchmark.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>
#include <sstream>

#include "bench_support.h"
#include "morphology/swc.h"
#include "render/renderer.h"
#include "scene/scene_loader.h"
#include "volume/voxelize.h"

namespace {

using namespace fluorosim;
namespace fs = std::filesystem;

using bench::relativeRmse;

const fs::path kSamples = fs::path(FLUOROSIM_SOURCE_DIR) / "samples" / "neurons";
const fs::path kWork = fs::temp_directory_path() / "fluorosim_volume_bench";

// The three neurons voxelized at `voxelUm` into a cached file; returns its path.
fs::path volumeFile(double voxelUm) {
    const fs::path file = kWork / ("neurons_" + std::to_string(voxelUm) + "um.vdb");
    if (fs::exists(file)) return file;
    fs::create_directories(kWork);
    std::vector<NeuronVolumeInput> in;
    int label = 1;
    for (const auto& [swc, grid] : {std::pair{"C010398B-P2.CNG.swc", "alexa_fluor_488"}, std::pair{"C231296A-P3.CNG.swc", "alexa_fluor_594"},
                                    std::pair{"mp_ma_40984_gc2.CNG.swc", "alexa_fluor_647"}}) {
        NeuronVolumeInput n;
        n.morphology = readSwc((kSamples / swc).string());
        n.gridName = grid;
        n.concentration = 10;
        n.units = "uM";
        n.label = label++;
        in.push_back(std::move(n));
    }
    VoxelizeOptions o;
    o.voxelSizeMm = voxelUm * 1e-3;
    writeVoxelizedVdb(file.string(), in, o);
    return file;
}

// neurons.json with the given volume file and majorant cells, cropped to 64 x 64 around the soma of
// C231296A-P3 (at the origin of its SWC frame) with a field of view of 0.2 mm.
Scene neuronScene(const fs::path& vdb, int majorantCellVoxels) {
    std::ifstream f(kSamples / "neurons.json");
    nlohmann::json j = nlohmann::json::parse(f);
    auto& v = j["media"]["tissue"]["volume"];
    v["file"] = vdb.string();
    v["majorant_cell_voxels"] = majorantCellVoxels;
    j["shapes"][0]["file"] = (kSamples / "tissue_block.obj").string();
    j["camera"]["position"] = {"0 mm", "0 mm", "6 mm"};
    j["camera"]["look_at"] = {"0 mm", "0 mm", "0 mm"};
    j["camera"]["fov_y_deg"] = 1.9;
    j["camera"]["resolution"] = {64, 64};
    return bench::loadBenchScene(j.dump(), kWork / "neurons.json");
}

const std::vector<float>& reference() {
    static const std::vector<float> ref = bench::renderFluorescentLayer(neuronScene(volumeFile(0.5), 0), 1024, 999, 0).rgb;
    return ref;
}

void countCollisions(benchmark::State& state, const RenderSummary& s) {
    const double real = double(s.stats.scatteringEvents + s.stats.absorptionEvents);
    state.counters["null_per_real"] = real > 0 ? (double(s.stats.tentativeCollisions) - real) / real : 0;
    state.counters["collisions_per_path"] = double(s.stats.tentativeCollisions) / double(s.stats.paths);
    state.counters["Mcollisions_per_s_core"] = double(s.stats.tentativeCollisions) / s.seconds * 1e-6;
    state.counters["us_per_path"] = s.seconds / double(s.stats.paths) * 1e6;
    state.counters["render_s"] = s.seconds;
}

// Args: majorant (0 grid with automatic cells, 1 one global cell), spp. One thread, so rates are per core.
void BM_NeuronMajorant(benchmark::State& state) {
    const bool global = state.range(0) == 1;
    const int spp = static_cast<int>(state.range(1));
    const Scene scene = neuronScene(volumeFile(0.5), global ? -1 : 0);
    const std::vector<float>& ref = reference();
    for (auto _ : state) {
        const bench::FluorescentRender r = bench::renderFluorescentLayer(scene, spp, 7, 1);
        countCollisions(state, r.summary);
        const double e = relativeRmse(r.rgb, ref);
        state.counters["relative_rmse"] = e;
        state.counters["relMSE_x_s"] = e * e * r.summary.seconds;
    }
}
BENCHMARK(BM_NeuronMajorant)->ArgsProduct({{0, 1}, {16, 64}})->Iterations(1)->Unit(benchmark::kSecond)->UseRealTime();

// Args: voxel size in nm (1000, 500, 250). Grid majorant, 16 spp, one thread.
void BM_NeuronResolution(benchmark::State& state) {
    const double voxelUm = double(state.range(0)) * 1e-3;
    const fs::path file = volumeFile(voxelUm);
    const Scene scene = neuronScene(file, 0);
    for (auto _ : state) countCollisions(state, bench::renderFluorescentLayer(scene, 16, 7, 1).summary);
    const VolumeFields* v = scene.media[0].volume();
    state.counters["vdb_MB"] = double(fs::file_size(file)) * 1e-6;
    state.counters["volume_MB"] = double(v->memoryBytes()) * 1e-6;
    state.counters["memory_over_file"] = double(v->memoryBytes()) / double(fs::file_size(file));
    const auto cells = v->cellCounts();
    state.counters["majorant_cells"] = double(cells[0]) * cells[1] * cells[2];
}
BENCHMARK(BM_NeuronResolution)->Arg(1000)->Arg(500)->Arg(250)->Iterations(1)->Unit(benchmark::kSecond)->UseRealTime();

}  // namespace
