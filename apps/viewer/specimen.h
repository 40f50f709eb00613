#pragma once
// What the viewer shows of the specimen, read through libsim without VTK: the dye grids of a scene's
// grid medium at full resolution (for readouts and ground truth) and resampled into one dense
// display volume (for volume rendering and slices), the SWC morphologies voxelized into that volume,
// and shapes whose media hold dyes (beads).
//
// Units: the viewer works in world µm (the scene's mm × 1000). Display voxel (i, j, k) covers
// `stride`³ full-resolution voxels starting at `indexLo` + stride·(i, j, k) and holds their maximum,
// so neurites thinner than a display voxel stay visible; readouts always use the full grid.
#include <array>
#include <cstdint>
#include <filesystem>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "morphology/swc.h"
#include "scene/scene.h"
#include "volume/density_grid.h"

namespace fluorosim::viewer {

inline constexpr double kUmPerMm = 1000.0;

// One dye of the scene. `grid` is set when the dye's concentration comes from a grid.
struct DyeChannel {
    std::string name;   // the dye as the scene file names it, e.g. "AF488"
    std::string id;     // the database's id, e.g. "alexa_fluor_488"
    std::string units;  // of the grid values as stored in the file, e.g. "uM"; "" when homogeneous
    std::shared_ptr<const DensityGrid> grid;
    Affine worldUmFromIndex, indexFromWorldUm;
    const Fluorophore* dye = nullptr;  // in the scene's medium
};

// A neuron from an SWC file as the voxelizer models it (morphology/swc.h: a soma sphere and round
// cones with the samples' radii), in world µm.
struct NeuronModel {
    std::string source;
    std::vector<MorphologyPiece> pieces;
    int channel = -1;  // the dye channel whose grid holds it, -1 if none
};

// A shape whose inside holds a dye at a constant concentration, e.g. a bead.
struct DyedShape {
    int channel = 0;
    bool sphere = true;
    Vec3 centreUm;
    double radiusUm = 0;
    TriangleMesh meshUm;  // when not a sphere
};

struct Specimen {
    std::vector<DyeChannel> channels;  // every dye in the scene, in order of first appearance
    std::vector<NeuronModel> neurons;
    std::vector<DyedShape> shapes;
    std::string gridMedium;            // the medium whose grids are shown ("" if none)
    std::vector<std::string> notes;    // what the viewer left out, for stderr and the help overlay
};

struct SpecimenOptions {
    // SWC files: explicit ones, or (when `findSwc`) the neurons the grid medium's volume names in its
    // label grid (with their placement), else every *.swc beside the volume file, else beside the scene
    // file. The specimen's notes say which.
    std::vector<std::filesystem::path> swc;
    bool findSwc = true;
};

// Builds the specimen of a loaded scene. `sceneFile` resolves the volume file and grid names of the
// first grid medium (the loaded scene keeps no file names). Throws ConfigError/IoError.
Specimen loadSpecimen(const Scene& scene, const std::filesystem::path& sceneFile, const SpecimenOptions& options);

// The nearest full-resolution voxel of a world position and every channel's value there.
struct VoxelProbe {
    std::array<int, 3> index{};
    bool insideGrid = false;            // within the bounds of some channel's grid
    std::vector<double> values;         // per channel, in its grid units (0 for homogeneous dyes)
};
VoxelProbe probeVoxel(const Specimen& specimen, const Vec3& worldUm);

// The dense display volume: values quantised to uint16 per channel, interleaved (x fastest, then y,
// z, channel innermost), so VTK can render it without a copy.
struct DisplayVolume {
    std::array<int, 3> dims{0, 0, 0};
    std::array<int, 3> indexLo{0, 0, 0};  // full-resolution index of the first voxel's first voxel
    int stride = 1;
    Vec3 originUm;                        // centre of display voxel (0, 0, 0)
    std::array<double, 3> spacingUm{1, 1, 1};
    std::vector<int> channels;            // specimen channels held, in component order
    std::vector<double> unitPerCount;     // per component: grid units per quantisation step
    std::vector<uint16_t> counts;

    int components() const { return static_cast<int>(channels.size()); }
    size_t voxelCount() const { return size_t(dims[0]) * dims[1] * dims[2]; }
    uint16_t count(int i, int j, int k, int c) const {
        return counts[((size_t(k) * dims[1] + j) * dims[0] + i) * channels.size() + c];
    }
    double value(int i, int j, int k, int c) const { return count(i, j, k, c) * unitPerCount[size_t(c)]; }
    Vec3 centreUm(double i, double j, double k) const {
        return {originUm.x + i * spacingUm[0], originUm.y + j * spacingUm[1], originUm.z + k * spacingUm[2]};
    }
    // The box the display voxels fill (lo, hi).
    std::array<Vec3, 2> boundsUm() const {
        return {centreUm(-0.5, -0.5, -0.5), centreUm(dims[0] - 0.5, dims[1] - 0.5, dims[2] - 0.5)};
    }
};

struct DisplayVolumeOptions {
    size_t maxVoxels = size_t(1) << 24;  // 256³; the stride grows until the volume fits
    int maxComponents = 4;               // VTK's ray casters take at most 4 independent components
    // Only this world box (µm), e.g. the microscope's field of view; the whole grid when absent.
    std::optional<std::array<Vec3, 2>> regionUm;
};

// Resamples the grid channels (at most maxComponents of them, in order) into a display volume.
// Returns nullopt when the specimen has no grid. Throws ConfigError for a grid whose index axes are
// not aligned with the world axes (the display volume is axis-aligned).
std::optional<DisplayVolume> makeDisplayVolume(const Specimen& specimen, const DisplayVolumeOptions& options);

// Counts at percentiles of one component's non-zero voxels (0 when all are zero).
double nonZeroPercentile(const DisplayVolume& volume, int component, double percentile);

// World µm bounds (lo, hi) of the neurons and dyed shapes; nullopt when there are none.
std::optional<std::array<Vec3, 2>> geometryBoundsUm(const Specimen& specimen);

}  // namespace fluorosim::viewer
