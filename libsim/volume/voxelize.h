#pragma once
// Voxelization of neuron morphologies (morphology/swc.h) into dye-concentration grids written as
// OpenVDB files. Each voxel holds concentration × coverage, the fraction of the voxel inside the
// neuron (filled) or inside its membrane shell (membrane). A voxel whose centre is farther than its
// half diagonal from the surface is 0 or 1; the others are supersampled on k³ points, each tested
// against the union of the neuron's pieces, so joints are neither double counted nor under-counted
// (a max of per-piece coverages would be). The membrane is the union minus the union of the pieces
// shrunk by the thickness. OpenVDB appears only in voxelize.cpp.
//
// Index space follows OpenVDB: voxel (i, j, k) is centred at (i, j, k) · voxel size, in mm.
#include <cstdint>
#include <functional>
#include <map>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "morphology/swc.h"

namespace fluorosim {

enum class LabelMode { Filled, Membrane };

const char* labelModeName(LabelMode mode);
std::optional<LabelMode> labelModeFromName(std::string_view name);

struct VoxelizeOptions {
    double voxelSizeMm = 0.0005;
    LabelMode mode = LabelMode::Filled;
    // Membrane: the shell between the surface and this depth inside it; default one voxel.
    std::optional<double> membraneThicknessMm;
    int supersampling = 4;  // per axis, in voxels cut by the surface
    int threads = 0;        // 0 = all cores
    // Called from the calling thread with the finished fraction of the work.
    std::function<void(double)> progress;

    double membraneThickness() const { return membraneThicknessMm.value_or(voxelSizeMm); }
    void validate() const;  // throws ConfigError naming the option and value
};

struct NeuronVolumeInput {
    Morphology morphology;
    std::string gridName;        // neurons sharing a grid add up there
    double concentration = 0;    // in `units`, > 0
    std::string units = "uM";    // stored as the grid's "units" metadata
    int label = 1;               // value in the "label" grid, > 0
    std::string dye;             // optional, stored as the grid's "dye" metadata
    // Where the neuron came from, stored in the label grid's metadata so that a viewer draws exactly the
    // volume's neurons: its SWC file and the placement already applied to `morphology`.
    std::string swcPath;
    Placement placement;
};

struct VoxelizedNeuronSummary {
    std::string source;
    std::string gridName;
    int label = 0;
    double analyticVolumeUm3 = 0;
    double coveredVolumeUm3 = 0;  // sum of coverage × voxel volume
    // The exact volume of the shell in membrane mode is not known in closed form; this is the
    // analytic volume of the filled morphology in both modes.
};

struct VoxelizedGridSummary {
    std::string name;
    std::string units;
    uint64_t activeVoxels = 0;
    double coveredVolumeMm3 = 0;  // sum over its neurons of coverage × voxel volume
    double coveredVolumeUm3 = 0;
    double analyticVolumeUm3 = 0;  // sum over its neurons
    double maxValue = 0;
};

struct VoxelizeSummary {
    std::vector<VoxelizedGridSummary> grids;    // in order of first appearance
    std::vector<VoxelizedNeuronSummary> neurons;  // in input order
    uint64_t labelVoxels = 0;
    double voxelSizeMm = 0;
    double seconds = 0;  // including the write
};

// Voxelizes without writing anything (same numbers as writeVoxelizedVdb). Throws ConfigError for
// bad options or inputs, or a grid that would be too large for the voxel size.
VoxelizeSummary voxelizeNeurons(const std::vector<NeuronVolumeInput>& neurons, const VoxelizeOptions& options);

// Voxelizes and writes one float grid per grid name plus an Int32 grid "label": every voxel a neuron
// covers at all holds its label (where neurons overlap, the one covering more, the first on ties), so
// that each voxel's dye is attributed to one neuron (fits parametrise by label). A mask of the neuron
// itself is its label where the concentration is at least half its value.
// Throws as voxelizeNeurons, and IoError when the file cannot be written.
VoxelizeSummary writeVoxelizedVdb(const std::string& path, const std::vector<NeuronVolumeInput>& neurons,
                                  const VoxelizeOptions& options);

// What a VDB file holds, for checks and summaries.
struct VdbGridStats {
    std::string name;
    std::string valueType;  // "float", "int32", ...
    std::map<std::string, std::string> stringMetadata;
    double voxelSizeMm = 0;  // x spacing of a linear transform, 0 otherwise
    bool uniformScale = false;
    uint64_t activeVoxels = 0;
    double sum = 0, min = 0, max = 0;             // over active voxels (float and int32 grids)
    std::map<int64_t, uint64_t> int32Histogram;   // active voxels per value (int32 grids)
};
// Throws IoError when the file cannot be read.
std::vector<VdbGridStats> readVdbGridStats(const std::string& path);

}  // namespace fluorosim
