// `fluorosim voxelize`: SWC neuron morphologies -> OpenVDB dye-concentration grids.
#include <charconv>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <memory>
#include <optional>
#include <unistd.h>

#include "commands.h"
#include "core/errors.h"
#include "core/parallel.h"
#include "core/units.h"
#include "database.h"
#include "morphology/swc.h"
#include "output_checks.h"
#include "progress.h"
#include "volume/voxelize.h"

namespace fluorosim::app {
namespace fs = std::filesystem;
namespace {

struct VoxelizeArgs {
    std::vector<std::string> swc, dyes, concentrations, grids;
    std::string voxel, mode = "filled", output;
    std::optional<std::string> membraneThickness;
    int supersampling = 4;
    int threads = 0;
};

// One value for every file, or one per file.
const std::string& perFile(const std::vector<std::string>& values, size_t i) { return values.size() == 1 ? values[0] : values[i]; }

void checkCount(const std::vector<std::string>& values, size_t files, const char* option) {
    if (values.size() == 1 || values.size() == files) return;
    throw ConfigError(std::string(option) + ": give one value or one per SWC file (" + std::to_string(files) + " file" +
                      (files == 1 ? "" : "s") + "), got " + std::to_string(values.size()) + " values");
}

void checkOutput(const fs::path& out) {
    if (out.extension() != ".vdb") throw ConfigError(out.string() + ": output must be a .vdb file");
    requireWritableFolder(out);
}

double positiveLength(const std::string& text, const char* option) {
    const double v = parseQuantity(text, Dimension::Length, option);
    if (!(v > 0)) throw ConfigError(std::string(option) + ": must be positive, got \"" + text + "\"");
    return v;
}

struct Concentration {
    double value;       // in `units`
    std::string units;  // canonical spelling
};

// The number as typed and a canonical unit, so "10 µM" is stored as 10 with units "uM".
Concentration parseConcentration(const std::string& text) {
    const double molar = parseQuantity(text, Dimension::MolarConcentration, "--concentration");
    if (!(molar > 0)) throw ConfigError("--concentration: must be positive, got \"" + text + "\"");
    if (molar > 10) throw ConfigError("--concentration: must be at most 10 M, got \"" + text + "\"");
    const size_t b = text.find_first_not_of(" \t+");
    double number = 0;
    const auto [ptr, ec] = std::from_chars(text.data() + b, text.data() + text.size(), number);
    const double scale = molar / number;
    const std::pair<double, const char*> units[] = {{1, "M"}, {1e-3, "mM"}, {1e-6, "uM"}, {1e-9, "nM"}, {1e-12, "pM"}};
    for (const auto& [s, name] : units)
        if (ec == std::errc() && std::abs(scale / s - 1) < 1e-9) return {number, name};
    return {molar * 1e6, "uM"};
}

std::string percent(double covered, double analytic) {
    if (!(analytic > 0)) return "";
    char buf[32];
    std::snprintf(buf, sizeof buf, "%+.2f %%", 100 * (covered / analytic - 1));
    return buf;
}

void runVoxelize(const VoxelizeArgs& a) {
    const size_t files = a.swc.size();
    VoxelizeOptions opt;
    opt.voxelSizeMm = positiveLength(a.voxel, "--voxel");
    const auto mode = labelModeFromName(a.mode);
    if (!mode) throw ConfigError("--mode: expected filled or membrane, got \"" + a.mode + "\"");
    opt.mode = *mode;
    if (a.membraneThickness) {
        if (opt.mode != LabelMode::Membrane) throw ConfigError("--membrane-thickness: only with --mode membrane");
        opt.membraneThicknessMm = positiveLength(*a.membraneThickness, "--membrane-thickness");
    }
    opt.supersampling = a.supersampling;
    checkThreadCount(a.threads, "--threads");
    opt.threads = a.threads;
    opt.validate();
    checkCount(a.dyes, files, "--dye");
    checkCount(a.concentrations, files, "--concentration");
    if (!a.grids.empty()) checkCount(a.grids, files, "--grid");
    std::vector<Concentration> conc;
    for (const auto& c : a.concentrations) conc.push_back(parseConcentration(c));
    const spectra::Database db;
    std::vector<std::string> dyeIds;
    for (const auto& d : a.dyes) {
        try {
            dyeIds.push_back(db.dye(d).id);
        } catch (const ConfigError& e) {
            throw ConfigError(std::string("--dye: ") + e.what());
        }
    }
    for (const auto& g : a.grids)
        if (g.empty() || g == "label") throw ConfigError("--grid: names must be non-empty and not \"label\", got \"" + g + "\"");
    checkOutput(a.output);

    std::vector<NeuronVolumeInput> neurons;
    for (size_t i = 0; i < files; ++i) {
        NeuronVolumeInput n;
        n.morphology = readSwc(a.swc[i]);
        n.dye = dyeIds.size() == 1 ? dyeIds[0] : dyeIds[i];
        n.gridName = a.grids.empty() ? n.dye : perFile(a.grids, i);
        const Concentration& c = conc.size() == 1 ? conc[0] : conc[i];
        n.concentration = c.value;
        n.units = c.units;
        n.label = static_cast<int>(i + 1);
        neurons.push_back(std::move(n));
    }

    // The bar appears only for runs longer than a second.
    const auto start = std::chrono::steady_clock::now();
    std::unique_ptr<ProgressBar> bar;
    opt.progress = [&](double f) {
        if (!bar && std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count() < 1.0) return;
        if (!bar) bar = std::make_unique<ProgressBar>("voxelize");
        bar->update(f);
    };
    const VoxelizeSummary s = writeVoxelizedVdb(a.output, neurons, opt);
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
    auto args = std::make_shared<VoxelizeArgs>();
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
    cmd->add_option("--mode", args->mode, "filled (cytosolic label) or membrane");
    cmd->add_option("--membrane-thickness", args->membraneThickness, "Membrane shell thickness with a unit (default: one voxel)");
    cmd->add_option("--supersampling", args->supersampling, "Points per axis in voxels cut by the surface");
    cmd->add_option("--threads", args->threads, "Threads (0 = all cores)");
    cmd->add_option("-o,--output", args->output, "Output .vdb file")->required();
    cmd->callback([args] { runVoxelize(*args); });
}

}  // namespace fluorosim::app
