#pragma once
// A scalar voxel grid read from an OpenVDB file and held sparsely for rendering (volume/sparse_voxels.h; read-only and
// thread-safe). OpenVDB appears only in volume/*.cpp; this header exposes project types.
// Index space follows OpenVDB: voxel centres at integer coordinates.
#include <array>
#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "core/vec3.h"

namespace fluorosim {

enum class Interpolation { Trilinear, Nearest };

// An affine map p' = M p + t.
struct Affine {
    std::array<std::array<double, 3>, 3> m{{{1, 0, 0}, {0, 1, 0}, {0, 0, 1}}};
    Vec3 t;
    Vec3 apply(const Vec3& p) const { return applyLinear(p) + t; }
    Vec3 applyLinear(const Vec3& v) const {
        return {m[0][0] * v.x + m[0][1] * v.y + m[0][2] * v.z, m[1][0] * v.x + m[1][1] * v.y + m[1][2] * v.z,
                m[2][0] * v.x + m[2][1] * v.y + m[2][2] * v.z};
    }
    Affine inverse() const;                    // throws NumericError when singular
    Affine then(const Affine& outer) const;    // outer ∘ this
    double determinant() const;
    static Affine scaling(double s);
    static Affine translation(const Vec3& t);
};

struct IndexBox {
    std::array<int32_t, 3> lo{0, 0, 0}, hi{-1, -1, -1};  // inclusive voxel bounds; empty when hi < lo
    bool empty() const { return hi[0] < lo[0] || hi[1] < lo[1] || hi[2] < lo[2]; }
};

struct GridMetadata {
    std::string units;       // "units" metadata (e.g. "uM"), empty if absent
    std::string lengthUnit;  // "length_unit" metadata (e.g. "mm"), empty if absent
};

class DensityGrid {
public:
    // Reads float grid `gridName` from `file` (an Int32 grid is accepted when `allowIntegers`, for
    // labels). Throws IoError for a missing or unreadable file, ConfigError for an empty file, a
    // missing grid (listing the ones present), a grid of the wrong type, a non-linear transform, or a
    // NaN, Inf or negative voxel (naming the grid and the voxel's index coordinate).
    static DensityGrid read(const std::string& file, const std::string& gridName, bool allowIntegers = false);
    // A grid holding value(i, j, k) on the voxels of `box` (zero values stay inactive), validated like
    // read(). For analytic test volumes and generated tissue.
    static DensityGrid fromVoxels(const std::string& name, const IndexBox& box, const Affine& worldFromIndex,
                                  const std::function<double(int, int, int)>& value, GridMetadata metadata = {});

    // A copy whose stored voxels are multiplied by factor(i, j, k) >= 0 (the background is kept): a dye
    // grid rescaled by label or by a coarse basis, for transmittances at fitted concentrations. Tiles
    // become voxel blocks. Throws ConfigError for a negative or non-finite factor.
    DensityGrid scaled(const std::function<double(int, int, int)>& factor) const;

    // Value at a continuous index-space position.
    double value(const Vec3& indexPos, Interpolation interpolation) const;
    // The voxel values of `box` (x fastest, then y, then z) into `out`, which holds the box's voxel count.
    void copyVoxels(const IndexBox& box, float* out) const;
    // Voxel and tile blocks that can hold values other than the background: callback(box, max value).
    void forEachBlock(const std::function<void(const IndexBox&, double maxValue)>& callback) const;

    const std::string& name() const;
    const std::string& file() const;
    const Affine& worldFromIndex() const;  // in the file's length unit
    const GridMetadata& metadata() const;
    IndexBox bounds() const;  // of all blocks
    double background() const;
    double maxValue() const;  // over every stored value, including the background
    uint64_t activeVoxelCount() const;
    size_t memoryBytes() const;  // the voxel store and the block list

    struct Impl;  // opaque: holds the voxel store
    explicit DensityGrid(std::shared_ptr<const Impl> impl) : impl_(std::move(impl)) {}
    const Impl* impl() const { return impl_.get(); }

private:
    std::shared_ptr<const Impl> impl_;
};

// Walks an OpenVDB file's header, grid descriptors and each grid's metadata and throws IoError when a
// length or offset there points beyond the end of the file: a corrupt length would otherwise make
// OpenVDB allocate it (gigabytes) before failing. Files in layouts older than version 219 pass.
void checkVdbStructure(const std::string& file);

// Writes value(i, j, k) on the voxels of `box` as float grid `name` into an OpenVDB file, with the
// metadata as string fields (values are written as given, unchecked, so tests can write bad grids).
// Appends to the grids already listed in `others` (name, box, value) so one file can hold several.
struct VoxelGridSpec {
    std::string name;
    IndexBox box;
    std::function<double(int, int, int)> value;
    GridMetadata metadata;
    bool integers = false;  // an Int32 grid (labels) instead of a float grid
};
void writeVoxelGrids(const std::string& file, const Affine& worldFromIndex, const std::vector<VoxelGridSpec>& grids);

// Writes grids held in memory (their stored voxels, transform and metadata) into one OpenVDB file under
// the names given: float grids, or Int32 with `integers` (labels). Throws IoError naming the file.
struct GridToWrite {
    std::string name;
    const DensityGrid* grid = nullptr;
    bool integers = false;
};
void writeDensityGrids(const std::string& file, const std::vector<GridToWrite>& grids);

}  // namespace fluorosim
