#pragma once
// SWC neuron morphologies -> OpenVDB dye-concentration grids, from the options as text: shared by
// `fluorosim voxelize` and the Python module, so both check and name their inputs alike.
#include <charconv>
#include <cmath>
#include <filesystem>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include "core/parallel.h"
#include "core/errors.h"
#include "core/units.h"
#include "database.h"
#include "morphology/swc.h"
#include "core/output_checks.h"
#include "volume/voxelize.h"

namespace fluorosim::optics {

struct VoxelizeArgs {
    std::vector<std::string> swc, dyes, concentrations, grids;
    std::string voxel, mode = "filled", output;
    std::optional<std::string> membraneThickness;
    // Placement per file (one value for all, or one per file): "10um,0um,-5um", and "z:90,x:15" (degrees
    // about x, y or z in that order, about the neuron's soma).
    std::vector<std::string> offsets, rotations;
    int supersampling = 4;
    int threads = 0;
};

// One value for every file, or one per file.
inline const std::string& perFile(const std::vector<std::string>& values, size_t i) { return values.size() == 1 ? values[0] : values[i]; }

inline void checkCount(const std::vector<std::string>& values, size_t files, const char* option) {
    if (values.size() == 1 || values.size() == files) return;
    throw ConfigError(std::string(option) + ": give one value or one per SWC file (" + std::to_string(files) + " file" +
                      (files == 1 ? "" : "s") + "), got " + std::to_string(values.size()) + " values");
}

inline void checkOutput(const std::filesystem::path& out) {
    if (out.extension() != ".vdb") throw ConfigError(out.string() + ": output must be a .vdb file");
    requireWritableFolder(out);
}

inline double positiveLength(const std::string& text, const char* option) {
    const double v = parseQuantity(text, Dimension::Length, option);
    if (!(v > 0)) throw ConfigError(std::string(option) + ": must be positive, got \"" + text + "\"");
    return v;
}

struct Concentration {
    double value;       // in `units`
    std::string units;  // canonical spelling
};

// The number as typed and a canonical unit, so "10 µM" is stored as 10 with units "uM".
inline Concentration parseConcentration(const std::string& text) {
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

// "10um,0um,-5um": three lengths with units, in µm.
inline Vec3 parseOffsetUm(const std::string& text) {
    std::vector<std::string> parts{""};
    for (char c : text) {
        if (c == ',') parts.emplace_back();
        else parts.back() += c;
    }
    if (parts.size() != 3) throw ConfigError("--offset: expected three lengths \"x,y,z\" with units, e.g. 10um,0um,-5um, got \"" + text + "\"");
    Vec3 v;
    for (int k = 0; k < 3; ++k) v[k] = parseQuantity(parts[static_cast<size_t>(k)], Dimension::Length, "--offset") * 1e3;
    return v;
}

// "z:90,x:15": rotations in degrees about x, y or z, applied in order.
inline std::vector<std::pair<char, double>> parseRotations(const std::string& text) {
    std::vector<std::pair<char, double>> out;
    size_t start = 0;
    while (start <= text.size()) {
        const size_t end = std::min(text.find(',', start), text.size());
        const std::string part = text.substr(start, end - start);
        double degrees = 0;
        const bool axis = part.size() >= 3 && (part[0] == 'x' || part[0] == 'y' || part[0] == 'z') && part[1] == ':';
        const auto [ptr, ec] = axis ? std::from_chars(part.data() + 2, part.data() + part.size(), degrees) : std::from_chars_result{nullptr, std::errc::invalid_argument};
        if (!axis || ec != std::errc() || ptr != part.data() + part.size() || !std::isfinite(degrees))
            throw ConfigError("--rotate: expected rotations \"axis:degrees\" about x, y or z, comma-separated, e.g. z:90,x:15, got \"" + text + "\"");
        out.emplace_back(part[0], degrees);
        start = end + 1;
    }
    return out;
}

// Checks the request, reads the SWC files and writes the grids; `progress` gets the finished fraction.
inline VoxelizeSummary voxelizeFiles(const VoxelizeArgs& a, const spectra::Database& db, std::function<void(double)> progress,
                                     VoxelizeOptions* used = nullptr) {
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
    if (!a.offsets.empty()) checkCount(a.offsets, files, "--offset");
    if (!a.rotations.empty()) checkCount(a.rotations, files, "--rotate");
    std::vector<Placement> placements(files);
    for (size_t i = 0; i < files; ++i) {
        if (!a.offsets.empty()) placements[i].offsetUm = parseOffsetUm(perFile(a.offsets, i));
        if (!a.rotations.empty()) placements[i].rotationsDeg = parseRotations(perFile(a.rotations, i));
    }
    std::vector<Concentration> conc;
    for (const auto& c : a.concentrations) conc.push_back(parseConcentration(c));
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
        place(n.morphology, placements[i]);
        n.swcPath = std::filesystem::absolute(a.swc[i]).lexically_normal().string();
        n.placement = placements[i];
        n.dye = dyeIds.size() == 1 ? dyeIds[0] : dyeIds[i];
        n.gridName = a.grids.empty() ? n.dye : perFile(a.grids, i);
        const Concentration& c = conc.size() == 1 ? conc[0] : conc[i];
        n.concentration = c.value;
        n.units = c.units;
        n.label = static_cast<int>(i + 1);
        neurons.push_back(std::move(n));
    }

    opt.progress = std::move(progress);
    if (used) *used = opt;
    return writeVoxelizedVdb(a.output, neurons, opt);
}

}  // namespace fluorosim::optics
