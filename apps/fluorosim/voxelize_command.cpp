// `fluorosim voxelize`: SWC neuron morphologies -> OpenVDB dye-concentration grids.
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <memory>

#include "commands.h"
#include "database.h"
#include "progress.h"
#include "volume/voxelize.h"
#include "optics/voxelize_request.h"

namespace fluorosim::app {
namespace fs = std::filesystem;
namespace {

std::string percent(double covered, double analytic) {
    if (!(analytic > 0)) return "";
    char buf[32];
    std::snprintf(buf, sizeof buf, "%+.2f %%", 100 * (covered / analytic - 1));
    return buf;
}

void runVoxelize(const optics::VoxelizeArgs& a) {
    const size_t files = a.swc.size();
    const spectra::Database db;
    // The bar appears only for runs longer than a second.
    const auto start = std::chrono::steady_clock::now();
    std::unique_ptr<ProgressBar> bar;
    auto progress = [&](double f) {
        if (!bar && std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count() < 1.0) return;
        if (!bar) bar = std::make_unique<ProgressBar>("voxelize");
        bar->update(f);
    };
    VoxelizeOptions opt;
    const VoxelizeSummary s = optics::voxelizeFiles(a, db, progress, &opt);
    if (bar) bar->finish();

    const bool filled = opt.mode == LabelMode::Filled;
    char membrane[64] = "";
    if (!filled) std::snprintf(membrane, sizeof membrane, ", %g um thick", opt.membraneThickness() * 1e3);
    std::printf("voxelized %zu neuron%s at %g um (%s%s, %d^3 supersampling) in %.2f s\n", files, files == 1 ? "" : "s",
                opt.voxelSizeMm * 1e3, labelModeName(opt.mode), membrane, opt.supersampling, s.seconds);
    for (const VoxelizedGridSummary& g : s.grids) {
        std::printf("grid %s [%s]: %llu voxels, covered %.6g um^3, analytic %.6g um^3%s%s\n", g.name.c_str(), g.units.c_str(),
                    static_cast<unsigned long long>(g.activeVoxels), g.coveredVolumeUm3, g.analyticVolumeUm3,
                    filled ? " " : " (filled)", filled ? percent(g.coveredVolumeUm3, g.analyticVolumeUm3).c_str() : "");
        for (const VoxelizedNeuronSummary& n : s.neurons) {
            if (n.gridName != g.name) continue;
            std::printf("  label %d %s: covered %.6g um^3, analytic %.6g um^3%s%s\n", n.label, n.source.c_str(), n.coveredVolumeUm3,
                        n.analyticVolumeUm3, filled ? " " : " (filled)", filled ? percent(n.coveredVolumeUm3, n.analyticVolumeUm3).c_str() : "");
        }
    }
    std::printf("grid label: %llu voxels\n", static_cast<unsigned long long>(s.labelVoxels));
    std::printf("wrote %s (%.3g MB)\n", a.output.c_str(), static_cast<double>(fs::file_size(a.output)) / 1e6);
    std::fflush(stdout);
}

}  // namespace

void addVoxelizeCommand(CLI::App& app) {
    auto args = std::make_shared<optics::VoxelizeArgs>();
    CLI::App* cmd = app.add_subcommand("voxelize", "Turn SWC neuron morphologies into OpenVDB dye-concentration grids");
    cmd->add_option("swc", args->swc, "SWC files (NeuroMorpho.Org format, µm)")->required();
    cmd->add_option("--voxel", args->voxel, "Voxel size with a unit, e.g. 0.5um")->required();
    // One value per occurrence (repeat the option or separate with commas), so the SWC files that
    // follow are not taken as values.
    cmd->add_option("--dye", args->dyes, "Dye: one, or one per SWC file (default grid name: the dye)")
        ->required()->allow_extra_args(false)->delimiter(',');
    cmd->add_option("--concentration", args->concentrations, "Concentration inside the neuron, e.g. 10uM: one, or one per SWC file")
        ->required()->allow_extra_args(false)->delimiter(',');
    cmd->add_option("--grid", args->grids, "Grid names: one, or one per SWC file; neurons sharing a name add up")
        ->allow_extra_args(false)->delimiter(',');
    // Values hold commas: repeat the option, once for all files or once per file.
    cmd->add_option("--offset", args->offsets, "Move each neuron by x,y,z with units, e.g. 100um,0um,-20um: one, or one per SWC file")
        ->allow_extra_args(false);
    cmd->add_option("--rotate", args->rotations,
                    "Rotate each neuron about its soma before the offset, e.g. z:90,x:15 (degrees about x, y, z, in order): one, or one "
                    "per SWC file")
        ->allow_extra_args(false);
    cmd->add_option("--mode", args->mode, "filled (cytosolic label) or membrane");
    cmd->add_option("--membrane-thickness", args->membraneThickness, "Membrane shell thickness with a unit (default: one voxel)");
    cmd->add_option("--supersampling", args->supersampling, "Points per axis in voxels cut by the surface");
    cmd->add_option("--threads", args->threads, "Threads (0 = all cores)");
    cmd->add_option("-o,--output", args->output, "Output .vdb file")->required();
    cmd->callback([args] { runVoxelize(*args); });
}

}  // namespace fluorosim::app
