#include "volume/density_grid.h"

#include <openvdb/io/File.h>
#include <openvdb/openvdb.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <new>
#include <stdexcept>
#include <mutex>
#include <sstream>
#include <unordered_set>
#include <vector>

#include "core/errors.h"
#include "core/memory_cap.h"
#include "core/message.h"
#include "volume/sparse_voxels.h"

namespace fluorosim {

Affine Affine::scaling(double s) {
    Affine a;
    for (int i = 0; i < 3; ++i) a.m[i][i] = s;
    return a;
}

Affine Affine::translation(const Vec3& t) {
    Affine a;
    a.t = t;
    return a;
}

double Affine::determinant() const {
    return m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1]) - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0]) +
           m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0]);
}

Affine Affine::inverse() const {
    const double det = determinant();
    if (!(std::abs(det) > 0) || !std::isfinite(det)) throw NumericError("singular volume transform");
    Affine r;
    r.m[0][0] = (m[1][1] * m[2][2] - m[1][2] * m[2][1]) / det;
    r.m[0][1] = (m[0][2] * m[2][1] - m[0][1] * m[2][2]) / det;
    r.m[0][2] = (m[0][1] * m[1][2] - m[0][2] * m[1][1]) / det;
    r.m[1][0] = (m[1][2] * m[2][0] - m[1][0] * m[2][2]) / det;
    r.m[1][1] = (m[0][0] * m[2][2] - m[0][2] * m[2][0]) / det;
    r.m[1][2] = (m[0][2] * m[1][0] - m[0][0] * m[1][2]) / det;
    r.m[2][0] = (m[1][0] * m[2][1] - m[1][1] * m[2][0]) / det;
    r.m[2][1] = (m[0][1] * m[2][0] - m[0][0] * m[2][1]) / det;
    r.m[2][2] = (m[0][0] * m[1][1] - m[0][1] * m[1][0]) / det;
    r.t = -r.applyLinear(t);
    return r;
}

Affine Affine::then(const Affine& outer) const {
    Affine r;
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) {
            double s = 0;
            for (int k = 0; k < 3; ++k) s += outer.m[i][k] * m[k][j];
            r.m[i][j] = s;
        }
    r.t = outer.apply(t);
    return r;
}

struct DensityGrid::Impl {
    std::string name, file;
    Affine worldFromIndex;
    GridMetadata metadata;
    SparseVoxels voxels;
    std::vector<std::pair<IndexBox, double>> blocks;
    IndexBox bounds;
    double background = 0, maxValue = 0;
    uint64_t activeVoxels = 0;
};

namespace {

void initializeOpenVdb() {
    static std::once_flag once;
    std::call_once(once, [] { openvdb::initialize(); });
}

IndexBox toIndexBox(const openvdb::CoordBBox& b) {
    return {{b.min().x(), b.min().y(), b.min().z()}, {b.max().x(), b.max().y(), b.max().z()}};
}

std::string coordText(const openvdb::Coord& c) {
    std::ostringstream s;
    s << "(" << c.x() << ", " << c.y() << ", " << c.z() << ")";
    return s.str();
}

std::string stringMeta(const openvdb::GridBase& grid, const char* key) {
    const auto meta = grid[key];
    return meta && meta->typeName() == openvdb::StringMetadata::staticTypeName() ? meta->str() : std::string();
}

openvdb::FloatGrid::Ptr labelsAsFloats(const openvdb::Int32Grid& labels) {
    auto out = openvdb::FloatGrid::create(static_cast<float>(labels.background()));
    out->setTransform(labels.transform().copy());
    auto acc = out->getAccessor();
    for (auto it = labels.cbeginValueOn(); it; ++it) {
        if (it.isVoxelValue()) acc.setValue(it.getCoord(), static_cast<float>(*it));
        else {
            openvdb::CoordBBox b;
            it.getBoundingBox(b);
            out->fill(b, static_cast<float>(*it), true);
        }
    }
    return out;
}

DensityGrid fromOpenVdb(std::shared_ptr<DensityGrid::Impl> impl, const openvdb::FloatGrid::Ptr& grid, const std::string& where);

// Reads the little-endian fields of a VDB file, refusing any length or offset beyond its end.
class VdbWalker {
public:
    VdbWalker(const std::string& file) : file_(file), in_(file, std::ios::binary) {
        std::error_code ec;
        size_ = std::filesystem::file_size(file, ec);
        if (ec || !in_) throw IoError(file + ": cannot open the VDB file");
    }
    uint64_t size() const { return size_; }
    uint64_t pos() { return static_cast<uint64_t>(in_.tellg()); }
    uint64_t remaining() { return size_ - std::min(size_, pos()); }
    template <class T>
    T read(const char* what) {
        T v{};
        if (remaining() < sizeof(T)) corrupt(std::string(what) + " lies beyond the end of the file");
        in_.read(reinterpret_cast<char*>(&v), sizeof(T));
        if (!in_) corrupt(std::string("cannot read ") + what);
        return v;
    }
    void skip(uint64_t bytes, const char* what) {
        if (bytes > remaining())
            corrupt(std::string(what) + " of " + std::to_string(bytes) + " bytes, with " + std::to_string(remaining()) + " bytes left");
        in_.seekg(static_cast<std::streamoff>(bytes), std::ios::cur);
    }
    void seek(uint64_t offset, const char* what) {
        if (offset > size_) corrupt(std::string(what) + " at byte " + std::to_string(offset) + ", beyond the end");
        in_.seekg(static_cast<std::streamoff>(offset));
    }
    void string(const char* what) { skip(read<uint32_t>(what), what); }
    // OpenVDB's MetaMap: count, then (name, type name, byte count, bytes) per entry.
    void metaMap(const char* what) {
        const int32_t count = read<int32_t>(what);
        if (count < 0 || static_cast<uint64_t>(count) > remaining() / 12)
            corrupt(std::string(what) + ": " + std::to_string(count) + " entries cannot fit in the file");
        for (int32_t i = 0; i < count; ++i) {
            string("metadata name");
            string("metadata type name");
            skip(read<uint32_t>("metadata size"), "metadata value");
        }
    }
    [[noreturn]] void corrupt(const std::string& what) const {
        throw IoError(file_ + ": corrupt OpenVDB file (" + what + ", in a file of " + std::to_string(size_) + " bytes)");
    }

private:
    std::string file_;
    std::ifstream in_;
    uint64_t size_ = 0;
};

}  // namespace

void checkVdbStructure(const std::string& file) {
    VdbWalker w(file);
    if (w.size() < 8 || w.read<int64_t>("magic number") != openvdb::OPENVDB_MAGIC) return;  // OpenVDB says "not a VDB file"
    const uint32_t version = w.read<uint32_t>("file version");
    if (version < openvdb::OPENVDB_FILE_VERSION_NO_GRIDMAP) return;  // older layouts: left to OpenVDB
    w.read<uint32_t>("library major version");
    w.read<uint32_t>("library minor version");
    const bool offsets = w.read<char>("grid offsets flag") != 0;
    if (version < openvdb::OPENVDB_FILE_VERSION_NODE_MASK_COMPRESSION && version >= openvdb::OPENVDB_FILE_VERSION_SELECTIVE_COMPRESSION)
        w.read<char>("compression flag");
    w.skip(36, "UUID");
    w.metaMap("file metadata");
    if (!offsets) return;  // a stream without descriptors
    const int32_t grids = w.read<int32_t>("grid count");
    if (grids < 0 || static_cast<uint64_t>(grids) > w.remaining() / 28)
        w.corrupt(std::to_string(grids) + " grid descriptors cannot fit in the file");
    for (int32_t g = 0; g < grids; ++g) {
        w.string("grid name");
        w.string("grid type name");
        if (version >= openvdb::OPENVDB_FILE_VERSION_GRID_INSTANCING) w.string("instance parent name");
        const auto gridPos = w.read<int64_t>("grid position"), blockPos = w.read<int64_t>("block position"),
                   endPos = w.read<int64_t>("end position");
        const auto descriptorEnd = static_cast<int64_t>(w.pos());
        if (!(gridPos >= descriptorEnd && gridPos <= blockPos && blockPos <= endPos && static_cast<uint64_t>(endPos) <= w.size()))
            w.corrupt("grid " + std::to_string(g) + " spans bytes " + std::to_string(gridPos) + " to " + std::to_string(endPos));
        w.seek(static_cast<uint64_t>(gridPos), "grid data");
        if (version >= openvdb::OPENVDB_FILE_VERSION_NODE_MASK_COMPRESSION) w.read<uint32_t>("grid compression");
        w.metaMap("grid metadata");
        if (version >= openvdb::OPENVDB_FILE_VERSION_GRID_INSTANCING) w.string("transform type name");
        w.seek(static_cast<uint64_t>(endPos), "next grid descriptor");
    }
}

DensityGrid DensityGrid::read(const std::string& file, const std::string& gridName, bool allowIntegers) {
    initializeOpenVdb();
    std::error_code ec;
    if (!std::filesystem::exists(file, ec)) throw IoError(file + ": no such file");
    if (std::filesystem::is_directory(file, ec)) throw IoError(file + ": is a folder, expected an OpenVDB file");
    if (!std::filesystem::is_regular_file(file, ec)) throw IoError(file + ": not a regular file, expected an OpenVDB file");
    checkVdbStructure(file);
    auto impl = std::make_shared<Impl>();
    impl->name = gridName;
    impl->file = file;
    openvdb::GridBase::Ptr base;
    std::vector<std::string> names;
    try {
        openvdb::io::File f(file);
        f.open(false);
        for (auto it = f.beginName(); it != f.endName(); ++it) names.push_back(it.gridName());
        if (names.empty()) throw ConfigError(file + ": the file holds no grids");
        if (std::find(names.begin(), names.end(), gridName) == names.end()) {
            std::string list;
            for (const auto& n : names) list += (list.empty() ? "\"" : ", \"") + n + "\"";
            throw ConfigError(file + ": no grid named \"" + gridName + "\" (the file has " + list + ")");
        }
        base = f.readGrid(gridName);
        f.close();
    } catch (const openvdb::Exception& e) {
        throw IoError(file + ": cannot read as an OpenVDB file: " + excerpt(e.what(), 200));
    } catch (const std::bad_alloc&) {
        // Corrupt node counts or sizes deeper in the file than checkVdbStructure looks.
        throw IoError(file + ": cannot read as an OpenVDB file: out of memory (is the file corrupt?)");
    } catch (const std::length_error&) {
        throw IoError(file + ": cannot read as an OpenVDB file: out of memory (is the file corrupt?)");
    } catch (const std::ios_base::failure& e) {
        throw IoError(file + ": cannot read as an OpenVDB file: " + excerpt(e.what(), 200));
    }
    const std::string where = file + ": grid \"" + gridName + "\"";
    openvdb::FloatGrid::Ptr grid = openvdb::gridPtrCast<openvdb::FloatGrid>(base);
    if (!grid && allowIntegers)
        if (const auto labels = openvdb::gridPtrCast<openvdb::Int32Grid>(base)) grid = labelsAsFloats(*labels);
    if (!grid)
        throw ConfigError(where + " has type " + base->valueType() + "; expected float" + (allowIntegers ? " or int32" : ""));
    return fromOpenVdb(std::move(impl), grid, where);
}

namespace {

DensityGrid fromOpenVdb(std::shared_ptr<DensityGrid::Impl> impl, const openvdb::FloatGrid::Ptr& grid, const std::string& where) {
    if (!grid->transform().isLinear()) throw ConfigError(where + " has a non-linear (frustum) transform, which is not supported");
    const openvdb::Mat4d M = grid->transform().baseMap()->getAffineMap()->getMat4();
    for (int i = 0; i < 3; ++i) {
        for (int j = 0; j < 3; ++j) impl->worldFromIndex.m[i][j] = M(j, i);  // OpenVDB multiplies row vectors
        impl->worldFromIndex.t[i] = M(3, i);
    }
    impl->metadata = {stringMeta(*grid, "units"), stringMeta(*grid, "length_unit")};

    const auto& tree = grid->tree();
    impl->background = tree.background();
    if (!std::isfinite(impl->background) || impl->background < 0)
        throw ConfigError(where + " has background value " + std::to_string(impl->background) + "; it must be finite and >= 0");
    impl->voxels = SparseVoxels(tree.background());
    impl->maxValue = impl->background;
    for (auto it = tree.cbeginValueAll(); it; ++it) {
        const float v = *it;
        if (!std::isfinite(v) || v < 0)
            throw ConfigError(where + " has value " + std::to_string(v) + " at voxel " + coordText(it.getCoord()) +
                              "; values must be finite and >= 0");
        impl->maxValue = std::max(impl->maxValue, double(v));
        if (!it.isVoxelValue() && v != impl->background) {
            openvdb::CoordBBox b;
            it.getBoundingBox(b);
            impl->voxels.addUniform(toIndexBox(b), v, where);
            if (v > impl->background) impl->blocks.push_back({toIndexBox(b), v});
        }
    }
    static_assert(openvdb::FloatTree::LeafNodeType::SIZE == SparseVoxels::kBlockVoxels);
    // The sparse copy is at most the size of the OpenVDB tree, which is freed after the conversion.
    requireMemory(2.0 * static_cast<double>(tree.memUsage()), where + ": holding the grid");
    for (auto leaf = tree.cbeginLeaf(); leaf; ++leaf) {
        float mx = 0;
        std::array<float, SparseVoxels::kBlockVoxels> values;
        for (openvdb::Index i = 0; i < values.size(); ++i) {
            values[i] = leaf->getValue(i);
            mx = std::max(mx, values[i]);
        }
        const openvdb::Coord o = leaf->origin();
        impl->voxels.addBlock({o.x(), o.y(), o.z()}, values.data(), where);
        if (mx > impl->background) impl->blocks.push_back({toIndexBox(leaf->getNodeBoundingBox()), mx});
    }
    impl->voxels.finish();
    for (const auto& [b, v] : impl->blocks) {
        if (impl->bounds.empty()) impl->bounds = b;
        for (int a = 0; a < 3; ++a) {
            impl->bounds.lo[a] = std::min(impl->bounds.lo[a], b.lo[a]);
            impl->bounds.hi[a] = std::max(impl->bounds.hi[a], b.hi[a]);
        }
    }
    impl->activeVoxels = tree.activeVoxelCount();
    return DensityGrid(std::move(impl));
}

openvdb::FloatGrid::Ptr makeGrid(const std::string& name, const IndexBox& box, const Affine& worldFromIndex,
                                 const std::function<double(int, int, int)>& value, const GridMetadata& metadata) {
    auto grid = openvdb::FloatGrid::create(0.0f);
    grid->setName(name);
    openvdb::Mat4d M = openvdb::Mat4d::identity();
    for (int i = 0; i < 3; ++i) {
        for (int j = 0; j < 3; ++j) M(j, i) = worldFromIndex.m[i][j];
        M(3, i) = worldFromIndex.t[i];
    }
    grid->setTransform(openvdb::math::Transform::createLinearTransform(M));
    if (!metadata.units.empty()) grid->insertMeta("units", openvdb::StringMetadata(metadata.units));
    if (!metadata.lengthUnit.empty()) grid->insertMeta("length_unit", openvdb::StringMetadata(metadata.lengthUnit));
    auto acc = grid->getAccessor();
    for (int i = box.lo[0]; i <= box.hi[0]; ++i)
        for (int j = box.lo[1]; j <= box.hi[1]; ++j)
            for (int k = box.lo[2]; k <= box.hi[2]; ++k) {
                const double v = value(i, j, k);
                if (v != 0) acc.setValue(openvdb::Coord(i, j, k), static_cast<float>(v));
            }
    return grid;
}

}  // namespace

DensityGrid DensityGrid::fromVoxels(const std::string& name, const IndexBox& box, const Affine& worldFromIndex,
                                    const std::function<double(int, int, int)>& value, GridMetadata metadata) {
    initializeOpenVdb();
    auto impl = std::make_shared<Impl>();
    impl->name = name;
    impl->file = "(in memory)";
    return fromOpenVdb(std::move(impl), makeGrid(name, box, worldFromIndex, value, metadata), "grid \"" + name + "\"");
}

void writeVoxelGrids(const std::string& file, const Affine& worldFromIndex, const std::vector<VoxelGridSpec>& grids) {
    initializeOpenVdb();
    openvdb::GridPtrVec out;
    for (const auto& g : grids) {
        auto grid = makeGrid(g.name, g.box, worldFromIndex, g.value, g.metadata);
        if (!g.integers) {
            out.push_back(grid);
            continue;
        }
        auto labels = openvdb::Int32Grid::create(0);
        labels->setName(g.name);
        labels->setTransform(grid->transform().copy());
        auto acc = labels->getAccessor();
        for (auto it = grid->cbeginValueOn(); it; ++it) acc.setValue(it.getCoord(), static_cast<int32_t>(*it));
        out.push_back(labels);
    }
    try {
        openvdb::io::File(file).write(out);
    } catch (const openvdb::Exception& e) {
        throw IoError(file + ": cannot write: " + e.what());
    }
}

DensityGrid DensityGrid::scaled(const std::function<double(int, int, int)>& factor) const {
    const Impl& src = *impl_;
    auto impl = std::make_shared<Impl>();
    impl->name = src.name;
    impl->file = src.file;
    impl->worldFromIndex = src.worldFromIndex;
    impl->metadata = src.metadata;
    impl->background = src.background;
    impl->maxValue = src.background;
    impl->voxels = SparseVoxels(static_cast<float>(src.background));
    const std::string where = "grid \"" + src.name + "\" (scaled)";
    // Every block and tile of the source, cut into 8³ blocks; a block is visited once even where a
    // tile's box covers it too.
    std::unordered_set<uint64_t> done;
    auto key = [](int64_t x, int64_t y, int64_t z) {
        return (static_cast<uint64_t>(x + (1 << 20)) << 42) | (static_cast<uint64_t>(y + (1 << 20)) << 21) | static_cast<uint64_t>(z + (1 << 20));
    };
    std::array<float, SparseVoxels::kBlockVoxels> values{}, copied{};
    for (const auto& [box, unused] : src.blocks) {
        (void)unused;
        for (int32_t bz = box.lo[2] & ~7; bz <= box.hi[2]; bz += 8)
            for (int32_t by = box.lo[1] & ~7; by <= box.hi[1]; by += 8)
                for (int32_t bx = box.lo[0] & ~7; bx <= box.hi[0]; bx += 8) {
                    if (!done.insert(key(bx >> 3, by >> 3, bz >> 3)).second) continue;
                    const IndexBox b{{bx, by, bz}, {bx + 7, by + 7, bz + 7}};
                    src.voxels.copyBox(b, copied.data());
                    float mx = 0;
                    bool any = false;
                    for (int z = 0; z < 8; ++z)
                        for (int y = 0; y < 8; ++y)
                            for (int x = 0; x < 8; ++x) {
                                const float v = copied[static_cast<size_t>((z * 8 + y) * 8 + x)];
                                float out = v;
                                if (v != static_cast<float>(src.background)) {
                                    const double f = factor(bx + x, by + y, bz + z);
                                    if (!(f >= 0) || !std::isfinite(f))
                                        throw ConfigError(where + ": factor " + std::to_string(f) + " at voxel (" + std::to_string(bx + x) + ", " +
                                                          std::to_string(by + y) + ", " + std::to_string(bz + z) + ") must be finite and >= 0");
                                    out = static_cast<float>(v * f);
                                    any = true;
                                }
                                values[static_cast<size_t>(64 * x + 8 * y + z)] = out;
                                mx = std::max(mx, out);
                            }
                    if (!any) continue;
                    impl->voxels.addBlock({bx, by, bz}, values.data(), where);
                    impl->maxValue = std::max(impl->maxValue, double(mx));
                    if (mx > impl->background) {
                        impl->blocks.push_back({b, mx});
                        if (impl->bounds.empty()) impl->bounds = b;
                        for (int a = 0; a < 3; ++a) {
                            impl->bounds.lo[a] = std::min(impl->bounds.lo[a], b.lo[a]);
                            impl->bounds.hi[a] = std::max(impl->bounds.hi[a], b.hi[a]);
                        }
                    }
                }
    }
    impl->voxels.finish();
    impl->activeVoxels = impl->voxels.storedVoxelCount();
    return DensityGrid(std::move(impl));
}

void writeDensityGrids(const std::string& file, const std::vector<GridToWrite>& grids) {
    initializeOpenVdb();
    openvdb::GridPtrVec out;
    for (const GridToWrite& g : grids) {
        const DensityGrid::Impl& src = *g.grid->impl();
        openvdb::Mat4d M = openvdb::Mat4d::identity();
        for (int i = 0; i < 3; ++i) {
            for (int j = 0; j < 3; ++j) M(j, i) = src.worldFromIndex.m[i][j];
            M(3, i) = src.worldFromIndex.t[i];
        }
        auto write = [&](auto grid) {
            grid->setName(g.name);
            grid->setTransform(openvdb::math::Transform::createLinearTransform(M));
            if (!src.metadata.units.empty()) grid->insertMeta("units", openvdb::StringMetadata(src.metadata.units));
            if (!src.metadata.lengthUnit.empty()) grid->insertMeta("length_unit", openvdb::StringMetadata(src.metadata.lengthUnit));
            auto acc = grid->getAccessor();
            std::array<float, SparseVoxels::kBlockVoxels> v{};
            for (const auto& [box, unused] : src.blocks) {
                (void)unused;
                for (int32_t bz = box.lo[2] & ~7; bz <= box.hi[2]; bz += 8)
                    for (int32_t by = box.lo[1] & ~7; by <= box.hi[1]; by += 8)
                        for (int32_t bx = box.lo[0] & ~7; bx <= box.hi[0]; bx += 8) {
                            src.voxels.copyBox({{bx, by, bz}, {bx + 7, by + 7, bz + 7}}, v.data());
                            for (int z = 0; z < 8; ++z)
                                for (int y = 0; y < 8; ++y)
                                    for (int x = 0; x < 8; ++x) {
                                        const float value = v[static_cast<size_t>((z * 8 + y) * 8 + x)];
                                        if (value != static_cast<float>(src.background))
                                            acc.setValue(openvdb::Coord(bx + x, by + y, bz + z), static_cast<typename decltype(grid)::element_type::ValueType>(value));
                                    }
                        }
            }
            out.push_back(grid);
        };
        if (g.integers) write(openvdb::Int32Grid::create(static_cast<int32_t>(src.background)));
        else write(openvdb::FloatGrid::create(static_cast<float>(src.background)));
    }
    try {
        openvdb::io::File(file).write(out);
    } catch (const openvdb::Exception& e) {
        throw IoError(file + ": cannot write: " + e.what());
    }
}

double DensityGrid::value(const Vec3& p, Interpolation interpolation) const {
    return interpolation == Interpolation::Nearest ? impl_->voxels.nearest(p) : impl_->voxels.trilinear(p);
}

void DensityGrid::copyVoxels(const IndexBox& box, float* out) const { impl_->voxels.copyBox(box, out); }

void DensityGrid::forEachBlock(const std::function<void(const IndexBox&, double)>& callback) const {
    for (const auto& [b, v] : impl_->blocks) callback(b, v);
}

const std::string& DensityGrid::name() const { return impl_->name; }
const std::string& DensityGrid::file() const { return impl_->file; }
const Affine& DensityGrid::worldFromIndex() const { return impl_->worldFromIndex; }
const GridMetadata& DensityGrid::metadata() const { return impl_->metadata; }
IndexBox DensityGrid::bounds() const { return impl_->bounds; }
double DensityGrid::background() const { return impl_->background; }
double DensityGrid::maxValue() const { return impl_->maxValue; }
uint64_t DensityGrid::activeVoxelCount() const { return impl_->activeVoxels; }
size_t DensityGrid::memoryBytes() const { return impl_->voxels.memoryBytes() + impl_->blocks.capacity() * sizeof(impl_->blocks[0]); }

}  // namespace fluorosim
