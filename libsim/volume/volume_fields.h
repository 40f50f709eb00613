#pragma once
// The spatially varying scalar fields of one medium (dye concentrations, tissue scattering and
// absorption scales), each value_c(p) = offset_c + scale_c * grid_c(p), and their majorant grid: coarse
// cells, each holding every channel's maximum over the cell, traversed along a ray by a 3-D DDA
// (Amanatides and Woo) so that empty and dim space costs one segment per cell.
#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <vector>

#include "core/vec3.h"
#include "volume/density_grid.h"

namespace fluorosim {

struct VolumeChannel {
    std::optional<DensityGrid> grid;  // none: the channel is the constant `offset`
    double scale = 1, offset = 0;
};

struct MajorantGridOptions {
    // Cell edge in voxels; -1 makes one global cell over the whole grid (the loosest majorant, for tests
    // and benchmarks). 0 is automatic: 64 cells along the longest axis, but cells of at least 4 and at
    // most 8 voxels (one OpenVDB leaf), enlarged only to keep the grid within `maxCells` (4 bytes each).
    // On the README job 8-voxel cells trace paths 1.6x faster than 44-voxel ones: coarse cells flood the
    // tracker with null collisions near neurites, and the two-level DDA keeps fine cells cheap.
    int cellVoxels = 0;
    int targetCells = 64;
    int64_t maxCells = int64_t(1) << 24;
    void validate() const;  // throws ConfigError
};

// One piece of a ray over which `maxValues` bounds every channel (maxValues[c] for channel c).
struct MajorantCellSegment {
    double tMin, tMax;
    const double* maxValues;
};

class VolumeFields {
public:
    // Grids must share one index space (same transform in their file). `worldFromFile` maps the files'
    // coordinates (already in mm) into the scene. Throws ConfigError.
    // `labels`, if given, is an integer grid in the same index space: which labelled object (a neuron)
    // each voxel belongs to, 0 for none. Transport never reads it; fits parametrise by it.
    VolumeFields(std::vector<VolumeChannel> channels, const Affine& worldFromFile, Interpolation interpolation,
                 MajorantGridOptions majorants = {}, std::optional<DensityGrid> labels = std::nullopt);

    // The same fields with every grid channel's stored voxels multiplied by factor(channel, i, j, k)
    // (DensityGrid::scaled), the labels and transform kept: concentrations rescaled by a fit.
    std::shared_ptr<const VolumeFields> scaled(const std::function<double(int channel, int i, int j, int k)>& factor) const;
    const DensityGrid* labels() const { return labels_ ? &*labels_ : nullptr; }

    int channelCount() const { return static_cast<int>(channels_.size()); }
    const VolumeChannel& channel(int c) const { return channels_.at(static_cast<size_t>(c)); }
    Interpolation interpolation() const { return interpolation_; }
    // Channel values at a world position, into out[channelCount()].
    // `upper`, if given, bounds each channel at pWorld (a majorant segment's maxima): a channel bounded
    // by its floor is its floor there, so its grid is not read.
    void values(const Vec3& pWorld, double* out, const double* upper = nullptr) const;
    const Affine& worldFromIndex() const { return worldFromIndex_; }
    // The shortest voxel edge in world units (mm); 1 when there is no grid.
    double voxelSizeMm() const;
    const Affine& indexFromWorld() const { return indexFromWorld_; }
    std::array<int, 3> cellCounts() const { return cells_; }
    // Each channel's largest value anywhere (over the cells and outside the grid).
    std::vector<double> channelMaxima() const;
    // A lower bound of each channel's value everywhere (its offset: grid values are never negative).
    std::vector<double> channelFloors() const;
    size_t memoryBytes() const;  // grids and majorant cells

    // The DDA. Segments cover [tMin, tMax) in order, with cells of the grid and, outside its domain,
    // the channels' values far from every voxel. It runs on two levels: blocks of kBlockCells³ cells
    // whose cells all share their maxima are crossed in one step, the others cell by cell; consecutive
    // pieces with the same maxima are merged into one segment.
    static constexpr int kBlockCells = 8;
    static constexpr size_t kCellsPerBlock = size_t(kBlockCells) * kBlockCells * kBlockCells;
    class Traversal {
    public:
        std::optional<MajorantCellSegment> next();

    private:
        friend class VolumeFields;
        struct Dda {
            std::array<int, 3> cell{}, step{};
            std::array<double, 3> tNext{}, tDelta{};
            int axis() const { return tNext[0] < tNext[1] ? (tNext[0] < tNext[2] ? 0 : 2) : (tNext[1] < tNext[2] ? 1 : 2); }
        };
        struct Piece {
            double end;
            const double* values;
            bool last;  // reaches the domain's exit
        };
        void start(Dda& dda, double t, const std::array<double, 3>& size, const std::array<int, 3>& lo, const std::array<int, 3>& hi) const;
        Piece piece();

        const VolumeFields* f_ = nullptr;
        double t_ = 0, tEnd_ = 0, tEnter_ = 0, tExit_ = 0;
        int phase_ = 0;  // 0 before the domain, 1 in it, 2 after it, 3 done
        Vec3 o_, d_;     // the ray in index space
        Dda block_, cell_;
        bool inBlock_ = false;       // stepping through the cells of a mixed block
        const uint32_t* blockCells_ = nullptr;  // its cells' entries
        bool blockLast_ = false;     // the current block reaches the domain's exit
        double blockExit_ = 0;       // where the current block ends (before it starts: where it begins)
        std::array<int, 3> blockCellLo_{}, blockCellHi_{};
        std::optional<Piece> pending_;  // read ahead while merging
    };
    Traversal traverse(const Ray& worldRay, double tMin, double tMax) const;

private:
    // A cell's place within its block (blocks of kBlockCells³ cells, x fastest).
    static_assert((kBlockCells & (kBlockCells - 1)) == 0, "blocks are a power of two cells wide");
    static size_t localCell(const std::array<int, 3>& c) {  // cells are >= 0, so & is the remainder
        constexpr int mask = kBlockCells - 1;
        return (static_cast<size_t>(c[2] & mask) * kBlockCells + static_cast<size_t>(c[1] & mask)) * kBlockCells + static_cast<size_t>(c[0] & mask);
    }
    const double* cellValues(uint32_t entry) const { return &cellMaxima_[entry * channels_.size()]; }
    int32_t blockEntry(const std::array<int, 3>& b) const {
        return blockEntry_[(static_cast<size_t>(b[2]) * blocks_[1] + b[1]) * blocks_[0] + static_cast<size_t>(b[0])];
    }
    // The maxima shared by every cell of block b, or null where the block's cells differ (mixed).
    const double* blockMax(const std::array<int, 3>& b) const {
        const int32_t e = blockEntry(b);
        return e < 0 ? nullptr : cellValues(static_cast<uint32_t>(e));
    }
    // The entries of a mixed block's cells, by localCell.
    const uint32_t* mixedCells(const std::array<int, 3>& b) const { return &cellEntry_[static_cast<size_t>(-blockEntry(b) - 1) * kCellsPerBlock]; }

    std::vector<VolumeChannel> channels_;
    std::optional<DensityGrid> labels_;
    Affine worldFromFile_;
    MajorantGridOptions majorantOptions_;
    Interpolation interpolation_;
    Affine worldFromIndex_, indexFromWorld_;
    Vec3 domainLo_, domainHi_;      // index space
    std::array<double, 3> cellSize_{};  // in voxels
    std::array<int, 3> cells_{0, 0, 0};
    // Most cells share their maxima (empty space, one dye's neurite at full concentration), so each
    // distinct set of channel maxima is stored once (channel-minor) and a cell holds its index.
    std::vector<double> cellMaxima_;
    std::array<int, 3> blocks_{0, 0, 0};
    std::vector<int32_t> blockEntry_;  // a block's shared entry, or -(m + 1) for the m-th mixed block
    std::vector<uint32_t> cellEntry_;  // the mixed blocks' cells, kBlockCells³ each
    std::vector<double> outside_;   // values where every voxel is background
};

}  // namespace fluorosim
