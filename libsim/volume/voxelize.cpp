#include "volume/voxelize.h"

#include <openvdb/io/File.h>
#include <openvdb/openvdb.h>
#include <openvdb/tools/Prune.h>

#include <algorithm>
#include <array>
#include <cassert>
#include <chrono>
#include <cmath>
#include <deque>
#include <filesystem>
#include <limits>
#include <memory>
#include <mutex>
#include <numbers>
#include <sstream>
#include <unordered_map>

#include "core/errors.h"
#include "core/memory_cap.h"
#include "core/parallel.h"
#include "volume/density_grid.h"

namespace fluorosim {
namespace {

// Blocks match OpenVDB's leaf nodes (8³ voxels), so a finished block becomes one leaf or one tile.
constexpr int kBlockLog2 = 3;
constexpr int kBlockDim = 1 << kBlockLog2;
constexpr int kBlockVoxels = kBlockDim * kBlockDim * kBlockDim;
// Half diagonal of a voxel, and the distance from a block's centre to its farthest voxel corner.
const double kVoxelHalfDiagonal = std::sqrt(3.0) / 2;
const double kBlockReach = std::sqrt(3.0) * kBlockDim / 2;
constexpr double kMaxIndex = 2e9;      // OpenVDB coordinates are int32
constexpr double kMaxVoxels = 4e9;     // about 16 GB of float voxels

// Local offset of a voxel in a block, OpenVDB's LeafNode::coordToOffset order.
constexpr int offsetOf(int dx, int dy, int dz) { return (dx << (2 * kBlockLog2)) | (dy << kBlockLog2) | dz; }

struct BlockKey {
    int32_t x, y, z;
    bool operator==(const BlockKey&) const = default;
};
struct BlockKeyHash {
    size_t operator()(const BlockKey& k) const {
        uint64_t h = static_cast<uint32_t>(k.x) * 0x9E3779B97F4A7C15ull;
        h ^= static_cast<uint32_t>(k.y) * 0xC2B2AE3D27D4EB4Full + (h << 6) + (h >> 2);
        h ^= static_cast<uint32_t>(k.z) * 0x165667B19E3779F9ull + (h << 6) + (h >> 2);
        return static_cast<size_t>(h);
    }
};
template <class T>
using BlockMap = std::unordered_map<BlockKey, T, BlockKeyHash>;

// A sphere or round cone in index units with an exact signed distance (exact inside too, because
// it is convex). In the plane through the axis with coordinates (along, radial), the shape is the
// hull of two circles; their common tangent has normal (sin α, cos α) with sin α = (r1 - r2) / L
// (the same function as Quilez's exact sdRoundCone).
struct Piece {
    Vec3 a, b, u;
    double r1 = 0, r2 = 0, len = 0, sinA = 0, cosA = 1, sideLen = 0;
    bool sphere = true;
    Vec3 lo, hi;

    double sdf(const Vec3& p) const {
        const Vec3 w = p - a;
        if (sphere) return length(w) - r1;
        const double along = dot(w, u);
        const double radial = length(w - u * along);
        const double t = along * cosA - radial * sinA;
        if (t < 0) return length(w) - r1;
        if (t > sideLen) return std::sqrt((along - len) * (along - len) + radial * radial) - r2;
        return along * sinA + radial * cosA - r1;
    }
};

Piece makePiece(const MorphologyPiece& m, double perUm) {
    Piece p;
    p.a = m.aUm * perUm;
    p.b = m.bUm * perUm;
    p.r1 = m.raUm * perUm;
    p.r2 = m.rbUm * perUm;
    const Vec3 d = p.b - p.a;
    p.len = length(d);
    // One sphere inside the other: the hull is the larger sphere.
    if (m.sphere || p.len <= std::abs(p.r1 - p.r2)) {
        if (!m.sphere && p.r2 > p.r1) p.a = p.b, p.r1 = p.r2;
        p.sphere = true;
        p.b = p.a;
        p.r2 = p.r1;
        p.len = 0;
    } else {
        p.sphere = false;
        p.u = d / p.len;
        p.sinA = (p.r1 - p.r2) / p.len;
        p.cosA = std::sqrt(std::max(0.0, 1 - p.sinA * p.sinA));
        p.sideLen = p.len * p.cosA;
    }
    const double r = std::max(p.r1, p.r2);
    p.lo = Vec3(std::min(p.a.x, p.b.x) - r, std::min(p.a.y, p.b.y) - r, std::min(p.a.z, p.b.z) - r);
    p.hi = Vec3(std::max(p.a.x, p.b.x) + r, std::max(p.a.y, p.b.y) + r, std::max(p.a.z, p.b.z) + r);
    return p;
}

struct BlockEntry {
    std::vector<uint32_t> pieces;
    bool deep = false;  // some piece contains the whole block with room to spare
};

struct Kernel {
    LabelMode mode;
    double thickness;  // membrane, in voxels
    int k;             // supersampling per axis
    double deepMargin() const { return mode == LabelMode::Filled ? 0.0 : thickness; }
};

// Memory per block, from the containers below: a block cut by the surface holds float coverage in its
// BlockResult, a dense GridBlock, label and best-coverage arrays, and later an OpenVDB leaf (2 KiB
// each) plus its registry entry; a block deep inside holds map entries only.
constexpr double kBytesPerCutBlock = 9 * 1024.0;
constexpr double kBytesPerDeepBlock = 512.0;

// Counts registered blocks across neurons and refuses the voxelization once their memory passes the
// cap, before the blocks (and minutes of work on them) are allocated.
struct BlockBudget {
    double cut = 0, deep = 0;
    std::string what;
    double bytes() const { return cut * kBytesPerCutBlock + deep * kBytesPerDeepBlock; }
    void check() const { requireMemory(bytes(), what); }
};

// Blocks that can hold a voxel with some point inside a piece, and the pieces to test there.
BlockMap<BlockEntry> registerBlocks(const std::vector<Piece>& pieces, const Kernel& kernel, BlockBudget& budget) {
    BlockMap<BlockEntry> blocks;
    uint64_t sinceCheck = 0;
    for (uint32_t idx = 0; idx < pieces.size(); ++idx) {
        const Piece& p = pieces[idx];
        // Walk long cones in sub-ranges of about one block so the boxes scanned stay close to the piece.
        const int parts = p.sphere ? 1 : std::max(1, static_cast<int>(std::ceil(p.len / kBlockDim)));
        const double r = std::max(p.r1, p.r2) + 1.0;
        for (int s = 0; s < parts; ++s) {
            const Vec3 a = p.sphere ? p.a : p.a + p.u * (p.len * s / parts);
            const Vec3 b = p.sphere ? p.a : p.a + p.u * (p.len * (s + 1) / parts);
            std::array<int32_t, 3> lo{}, hi{};
            for (int c = 0; c < 3; ++c) {
                lo[c] = static_cast<int32_t>(std::floor(std::min(a[c], b[c]) - r + 0.5)) >> kBlockLog2;
                hi[c] = static_cast<int32_t>(std::floor(std::max(a[c], b[c]) + r + 0.5)) >> kBlockLog2;
            }
            for (int32_t x = lo[0]; x <= hi[0]; ++x)
                for (int32_t y = lo[1]; y <= hi[1]; ++y)
                    for (int32_t z = lo[2]; z <= hi[2]; ++z) {
                        const Vec3 centre(x * kBlockDim + (kBlockDim - 1) * 0.5, y * kBlockDim + (kBlockDim - 1) * 0.5,
                                          z * kBlockDim + (kBlockDim - 1) * 0.5);
                        const double d = p.sdf(centre);
                        if (d >= kBlockReach) continue;
                        const auto [it, inserted] = blocks.try_emplace(BlockKey{x, y, z});
                        BlockEntry& e = it->second;
                        if (e.deep || (!e.pieces.empty() && e.pieces.back() == idx)) continue;
                        if (d + kBlockReach < -kernel.deepMargin()) {
                            if (!inserted) budget.cut -= 1;
                            budget.deep += 1;
                            e.deep = true;
                            e.pieces.clear();
                            e.pieces.shrink_to_fit();
                        } else {
                            if (inserted) budget.cut += 1;
                            e.pieces.push_back(idx);
                        }
                        if (inserted && ++sinceCheck == 4096) {
                            sinceCheck = 0;
                            budget.check();
                        }
                    }
        }
    }
    budget.check();
    return blocks;
}

struct BlockResult {
    BlockKey key{};
    bool full = false;  // every voxel has coverage 1
    std::unique_ptr<std::array<float, kBlockVoxels>> values;
    double sum = 0;  // of coverage
};

struct Candidate {
    uint32_t piece;
    double d;
};

// Coverage of the 8³ voxels of one block. A voxel whose centre lies deeper than its half diagonal
// on one side of the surface(s) is 0 or 1 (the signed distance is 1-Lipschitz); the others are
// supersampled on k³ points, each tested against the union of the pieces near it.
BlockResult coverBlock(const BlockKey& key, const BlockEntry& entry, const std::vector<Piece>& pieces, const Kernel& kernel) {
    BlockResult out;
    out.key = key;
    if (entry.deep) {
        if (kernel.mode == LabelMode::Filled) out.full = true, out.sum = kBlockVoxels;
        return out;
    }
    const double hd = kVoxelHalfDiagonal;
    const double t = kernel.thickness;
    const bool membrane = kernel.mode == LabelMode::Membrane;
    const int k = kernel.k;
    const double invCount = 1.0 / (k * k * k);
    auto values = std::make_unique<std::array<float, kBlockVoxels>>();
    std::vector<Candidate> cand;
    cand.reserve(entry.pieces.size());
    bool any = false, allOne = true;
    for (int dx = 0; dx < kBlockDim; ++dx)
        for (int dy = 0; dy < kBlockDim; ++dy)
            for (int dz = 0; dz < kBlockDim; ++dz) {
                const Vec3 c(key.x * kBlockDim + dx, key.y * kBlockDim + dy, key.z * kBlockDim + dz);
                double fmin = std::numeric_limits<double>::infinity();
                cand.clear();
                for (uint32_t idx : entry.pieces) {
                    const double d = pieces[idx].sdf(c);
                    fmin = std::min(fmin, d);
                    if (d < hd) cand.push_back({idx, d});
                }
                double cov = 0;
                if (fmin >= hd) {
                    cov = 0;
                } else if (!membrane && fmin <= -hd) {
                    cov = 1;
                } else if (membrane && fmin <= -t - hd) {
                    cov = 0;
                } else if (membrane && fmin <= -hd && fmin >= -t + hd) {
                    cov = 1;
                } else {
                    // Nearest candidates first: inside points then usually stop at the first test.
                    std::sort(cand.begin(), cand.end(), [](const Candidate& x, const Candidate& y) { return x.d < y.d; });
                    int inside = 0;
                    for (int i = 0; i < k; ++i)
                        for (int j = 0; j < k; ++j)
                            for (int l = 0; l < k; ++l) {
                                const Vec3 q = c + Vec3((i + 0.5) / k - 0.5, (j + 0.5) / k - 0.5, (l + 0.5) / k - 0.5);
                                if (!membrane) {
                                    for (const Candidate& cd : cand)
                                        if (pieces[cd.piece].sdf(q) < 0) {
                                            ++inside;
                                            break;
                                        }
                                } else {
                                    double f = std::numeric_limits<double>::infinity();
                                    for (const Candidate& cd : cand) {
                                        f = std::min(f, pieces[cd.piece].sdf(q));
                                        if (f < -t) break;
                                    }
                                    if (f < 0 && f >= -t) ++inside;
                                }
                            }
                    cov = inside * invCount;
                }
                (*values)[offsetOf(dx, dy, dz)] = static_cast<float>(cov);
                out.sum += cov;
                any = any || cov > 0;
                allOne = allOne && cov == 1;
            }
    if (!any) return out;
    if (allOne) {
        out.full = true;
        return out;
    }
    out.values = std::move(values);
    return out;
}

// A block of a concentration grid: `uniform` over all voxels when `dense` is null.
struct GridBlock {
    float uniform = 0;
    std::unique_ptr<std::array<float, kBlockVoxels>> dense;
};

// A block of the label grid: `uniformLabel` (with coverage 1) over all voxels when `label` is null.
struct LabelBlock {
    int32_t uniformLabel = 0;
    std::unique_ptr<std::array<int32_t, kBlockVoxels>> label;
    std::unique_ptr<std::array<float, kBlockVoxels>> best;  // coverage of the labelled neuron
};

struct GridAccumulator {
    std::string name, units, dye;
    BlockMap<GridBlock> blocks;
    double coveredVoxels = 0;
    double analyticUm3 = 0;
};

void addToGrid(GridAccumulator& g, const BlockResult& r, float concentration) {
    auto [it, inserted] = g.blocks.try_emplace(r.key);
    GridBlock& b = it->second;
    if (inserted && r.full) {
        b.uniform = concentration;
        return;
    }
    if (!b.dense && r.full) {
        b.uniform += concentration;
        return;
    }
    if (!b.dense) {
        b.dense = std::make_unique<std::array<float, kBlockVoxels>>();
        b.dense->fill(b.uniform);
    }
    for (int n = 0; n < kBlockVoxels; ++n) (*b.dense)[n] += concentration * (r.full ? 1.0f : (*r.values)[n]);
}

void addToLabels(BlockMap<LabelBlock>& labels, const BlockResult& r, int32_t label) {
    auto [it, inserted] = labels.try_emplace(r.key);
    LabelBlock& b = it->second;
    if (inserted && r.full) {
        b.uniformLabel = label;
        return;
    }
    if (!inserted && !b.label) return;  // already fully covered by an earlier neuron; ties keep it
    if (inserted) {
        b.label = std::make_unique<std::array<int32_t, kBlockVoxels>>();
        b.best = std::make_unique<std::array<float, kBlockVoxels>>();
        b.label->fill(0);
        b.best->fill(0);
    }
    for (int n = 0; n < kBlockVoxels; ++n) {
        const float c = r.full ? 1.0f : (*r.values)[n];
        if (c > 0 && c > (*b.best)[n]) (*b.label)[n] = label, (*b.best)[n] = c;
    }
}

struct Voxelized {
    std::deque<GridAccumulator> grids;  // not a vector: relocating would copy the block maps
    BlockMap<LabelBlock> labels;
    VoxelizeSummary summary;
};

std::string mmText(double mm) {
    std::ostringstream os;
    os << mm << " mm (" << mm * 1e3 << " um)";
    return os.str();
}

void checkInputs(const std::vector<NeuronVolumeInput>& neurons) {
    if (neurons.empty()) throw ConfigError("voxelize: no neurons given");
    std::map<std::string, const NeuronVolumeInput*> byGrid;
    for (const NeuronVolumeInput& n : neurons) {
        const std::string& src = n.morphology.source;
        if (n.gridName.empty()) throw ConfigError(src + ": empty grid name");
        if (n.gridName == "label") throw ConfigError(src + ": grid name \"label\" is reserved for the label grid");
        if (!(n.concentration > 0) || !std::isfinite(n.concentration)) {
            std::ostringstream os;
            os << src << ": concentration must be positive and finite, got " << n.concentration << " " << n.units;
            throw ConfigError(os.str());
        }
        if (n.units.empty()) throw ConfigError(src + ": empty concentration units");
        if (n.label <= 0) throw ConfigError(src + ": label must be positive, got " + std::to_string(n.label));
        if (n.morphology.samples.empty()) throw ConfigError(src + ": no samples");
        const auto [it, inserted] = byGrid.emplace(n.gridName, &n);
        if (inserted) continue;
        if (it->second->units != n.units)
            throw ConfigError(src + ": grid \"" + n.gridName + "\" holds \"" + it->second->units + "\" from " +
                              it->second->morphology.source + ", got \"" + n.units + "\"");
        if (it->second->dye != n.dye)
            throw ConfigError(src + ": grid \"" + n.gridName + "\" holds dye \"" + it->second->dye + "\" from " +
                              it->second->morphology.source + ", got \"" + n.dye + "\"");
    }
}

// Refuses grids beyond OpenVDB's int32 coordinates or with more voxels than memory can hold.
void checkSize(const std::vector<std::vector<Piece>>& pieces, const std::vector<NeuronVolumeInput>& neurons, double voxelMm) {
    double voxels = 0;
    for (size_t i = 0; i < pieces.size(); ++i)
        for (const Piece& p : pieces[i]) {
            for (int c = 0; c < 3; ++c)
                if (!(std::abs(p.lo[c]) < kMaxIndex - 64 && std::abs(p.hi[c]) < kMaxIndex - 64))
                    throw ConfigError(neurons[i].morphology.source + ": at voxel size " + mmText(voxelMm) +
                                      " the neuron reaches index coordinates beyond ±2e9 (OpenVDB's limit); choose a larger voxel size");
            const double r = std::max(p.r1, p.r2) + 1;
            voxels += 4.0 / 3.0 * std::numbers::pi * r * r * r + std::numbers::pi * r * r * p.len;
        }
    if (voxels > kMaxVoxels) {
        std::ostringstream os;
        os << "voxel size " << mmText(voxelMm) << ": the neurons would cover about " << voxels
           << " voxels (limit 4e9, about 16 GB); choose a larger voxel size";
        throw ConfigError(os.str());
    }
}

Voxelized voxelize(const std::vector<NeuronVolumeInput>& neurons, const VoxelizeOptions& options) {
    const auto start = std::chrono::steady_clock::now();
    options.validate();
    checkInputs(neurons);
    const double h = options.voxelSizeMm;
    const double perUm = 1e-3 / h;  // µm -> voxels
    const Kernel kernel{options.mode, options.membraneThickness() / h, options.supersampling};

    std::vector<std::vector<Piece>> pieces(neurons.size());
    for (size_t i = 0; i < neurons.size(); ++i)
        for (const MorphologyPiece& m : morphologyPieces(neurons[i].morphology)) pieces[i].push_back(makePiece(m, perUm));
    checkSize(pieces, neurons, h);

    std::vector<BlockMap<BlockEntry>> registries(neurons.size());
    size_t totalBlocks = 0;
    BlockBudget budget;
    budget.what = "voxel size " + mmText(h) + ": voxelizing " + neurons[0].morphology.source +
                  (neurons.size() > 1 ? " and " + std::to_string(neurons.size() - 1) + " more neurons" : std::string()) +
                  " (counting its blocks of 8^3 voxels, stopped at the cap)";
    for (size_t i = 0; i < neurons.size(); ++i) {
        registries[i] = registerBlocks(pieces[i], kernel, budget);
        totalBlocks += registries[i].size();
    }

    Voxelized v;
    v.summary.voxelSizeMm = h;
    const double voxelUm3 = std::pow(h * 1e3, 3);
    size_t doneBlocks = 0;
    for (size_t i = 0; i < neurons.size(); ++i) {
        const NeuronVolumeInput& n = neurons[i];
        std::vector<std::pair<BlockKey, const BlockEntry*>> work;
        work.reserve(registries[i].size());
        for (const auto& [key, entry] : registries[i]) work.emplace_back(key, &entry);
        std::vector<BlockResult> results(work.size());
        // Chunks let the calling thread report progress between them.
        const size_t chunk = std::max<size_t>(1024, totalBlocks / 200);
        for (size_t begin = 0; begin < work.size(); begin += chunk) {
            const size_t count = std::min(chunk, work.size() - begin);
            parallelFor(count, options.threads, [&](size_t j) {
                results[begin + j] = coverBlock(work[begin + j].first, *work[begin + j].second, pieces[i], kernel);
            });
            doneBlocks += count;
            if (options.progress) options.progress(static_cast<double>(doneBlocks) / static_cast<double>(std::max<size_t>(1, totalBlocks)));
        }
        BlockMap<BlockEntry>().swap(registries[i]);

        auto git = std::find_if(v.grids.begin(), v.grids.end(), [&](const GridAccumulator& g) { return g.name == n.gridName; });
        if (git == v.grids.end()) {
            v.grids.push_back(GridAccumulator{n.gridName, n.units, n.dye, {}, 0, 0});
            git = v.grids.end() - 1;
        }
        double covered = 0;
        for (const BlockResult& r : results) {
            covered += r.sum;
            if (!r.full && !r.values) continue;
            addToGrid(*git, r, static_cast<float>(n.concentration));
            addToLabels(v.labels, r, n.label);
        }
        const double analytic = analyticVolumeUm3(n.morphology);
        git->coveredVoxels += covered;
        git->analyticUm3 += analytic;
        v.summary.neurons.push_back({n.morphology.source, n.gridName, n.label, analytic, covered * voxelUm3});
    }

    for (const GridAccumulator& g : v.grids) {
        VoxelizedGridSummary s;
        s.name = g.name;
        s.units = g.units;
        for (const auto& [key, b] : g.blocks) {
            if (!b.dense) {
                s.activeVoxels += kBlockVoxels;
                s.maxValue = std::max<double>(s.maxValue, b.uniform);
                continue;
            }
            for (float x : *b.dense)
                if (x > 0) ++s.activeVoxels, s.maxValue = std::max<double>(s.maxValue, x);
        }
        s.coveredVolumeUm3 = g.coveredVoxels * voxelUm3;
        s.coveredVolumeMm3 = s.coveredVolumeUm3 * 1e-9;
        s.analyticVolumeUm3 = g.analyticUm3;
        v.summary.grids.push_back(s);
    }
    for (const auto& [key, b] : v.labels) {
        if (!b.label) {
            v.summary.labelVoxels += kBlockVoxels;
            continue;
        }
        for (int32_t x : *b.label) v.summary.labelVoxels += x != 0;
    }
    v.summary.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    return v;
}

void initOpenVdb() {
    static std::once_flag once;
    std::call_once(once, [] { openvdb::initialize(); });
}

template <class GridT, class BlockT, class UniformF, class DenseF>
void fillTree(GridT& grid, const BlockMap<BlockT>& blocks, UniformF uniformOf, DenseF denseOf) {
    using LeafT = typename GridT::TreeType::LeafNodeType;
    using ValueT = typename GridT::ValueType;
    assert(LeafT::coordToOffset(openvdb::Coord(1, 2, 3)) == static_cast<openvdb::Index>(offsetOf(1, 2, 3)));
    auto& tree = grid.tree();
    for (const auto& [key, b] : blocks) {
        const openvdb::Coord origin(key.x * kBlockDim, key.y * kBlockDim, key.z * kBlockDim);
        const auto* dense = denseOf(b);
        if (!dense) {
            tree.addTile(1, origin, uniformOf(b), true);
            continue;
        }
        auto leaf = std::make_unique<LeafT>(origin, ValueT(0), false);
        bool any = false;
        for (int n = 0; n < kBlockVoxels; ++n)
            if ((*dense)[n] != ValueT(0)) leaf->setValueOn(static_cast<openvdb::Index>(n), (*dense)[n]), any = true;
        if (any) tree.addLeaf(leaf.release());
    }
    openvdb::tools::prune(tree);
}

}  // namespace

const char* labelModeName(LabelMode mode) { return mode == LabelMode::Filled ? "filled" : "membrane"; }

std::optional<LabelMode> labelModeFromName(std::string_view name) {
    if (name == "filled") return LabelMode::Filled;
    if (name == "membrane") return LabelMode::Membrane;
    return std::nullopt;
}

void VoxelizeOptions::validate() const {
    if (!(voxelSizeMm > 0) || !std::isfinite(voxelSizeMm))
        throw ConfigError("voxel size: must be positive and finite, got " + mmText(voxelSizeMm));
    if (membraneThicknessMm && (!(*membraneThicknessMm > 0) || !std::isfinite(*membraneThicknessMm)))
        throw ConfigError("membrane thickness: must be positive and finite, got " + mmText(*membraneThicknessMm));
    if (supersampling < 1 || supersampling > 16)
        throw ConfigError("supersampling: must lie in [1, 16] points per axis, got " + std::to_string(supersampling));
    checkThreadCount(threads, "threads");
}

VoxelizeSummary voxelizeNeurons(const std::vector<NeuronVolumeInput>& neurons, const VoxelizeOptions& options) {
    return voxelize(neurons, options).summary;
}

VoxelizeSummary writeVoxelizedVdb(const std::string& path, const std::vector<NeuronVolumeInput>& neurons,
                                  const VoxelizeOptions& options) {
    namespace fs = std::filesystem;
    const auto start = std::chrono::steady_clock::now();
    Voxelized v = voxelize(neurons, options);
    initOpenVdb();
    const double h = options.voxelSizeMm;
    const auto transform = openvdb::math::Transform::createLinearTransform(h);
    openvdb::GridPtrVec grids;
    for (GridAccumulator& g : v.grids) {
        auto grid = openvdb::FloatGrid::create(0.0f);
        grid->setName(g.name);
        grid->setTransform(transform->copy());
        grid->setGridClass(openvdb::GRID_FOG_VOLUME);
        grid->insertMeta("units", openvdb::StringMetadata(g.units));
        grid->insertMeta("length_unit", openvdb::StringMetadata("mm"));
        grid->insertMeta("mode", openvdb::StringMetadata(labelModeName(options.mode)));
        if (!g.dye.empty()) grid->insertMeta("dye", openvdb::StringMetadata(g.dye));
        fillTree(*grid, g.blocks, [](const GridBlock& b) { return b.uniform; },
                 [](const GridBlock& b) { return b.dense.get(); });
        BlockMap<GridBlock>().swap(g.blocks);  // free the memory now
        grids.push_back(grid);
    }
    auto label = openvdb::Int32Grid::create(0);
    label->setName("label");
    label->setTransform(transform->copy());
    label->insertMeta("length_unit", openvdb::StringMetadata("mm"));
    label->insertMeta("mode", openvdb::StringMetadata(labelModeName(options.mode)));
    for (const NeuronVolumeInput& n : neurons) {
        const std::string key = "label_" + std::to_string(n.label);
        label->insertMeta(key, openvdb::StringMetadata(n.morphology.source + " (grid " + n.gridName + ")"));
        if (!n.swcPath.empty()) label->insertMeta(key + "_swc", openvdb::StringMetadata(n.swcPath));
        if (!n.placement.identity()) {
            std::ostringstream offset, rotate;
            offset.precision(17);
            offset << n.placement.offsetUm.x << "um," << n.placement.offsetUm.y << "um," << n.placement.offsetUm.z << "um";
            label->insertMeta(key + "_offset", openvdb::StringMetadata(offset.str()));
            rotate.precision(17);
            for (size_t r = 0; r < n.placement.rotationsDeg.size(); ++r)
                rotate << (r ? "," : "") << n.placement.rotationsDeg[r].first << ':' << n.placement.rotationsDeg[r].second;
            if (!n.placement.rotationsDeg.empty()) label->insertMeta(key + "_rotate", openvdb::StringMetadata(rotate.str()));
        }
    }
    fillTree(*label, v.labels, [](const LabelBlock& b) { return b.uniformLabel; }, [](const LabelBlock& b) { return b.label.get(); });
    BlockMap<LabelBlock>().swap(v.labels);
    grids.push_back(label);

    // A temporary name first, so a failed write never leaves a truncated file under the real name.
    const fs::path tmp = path + ".partial";
    try {
        openvdb::io::File file(tmp.string());
        file.setCompression(openvdb::io::COMPRESS_ACTIVE_MASK |
                            (openvdb::io::Archive::hasBloscCompression() ? openvdb::io::COMPRESS_BLOSC : openvdb::io::COMPRESS_ZIP));
        openvdb::MetaMap meta;
        meta.insertMeta("creator", openvdb::StringMetadata("fluorosim voxelize"));
        file.write(grids, meta);
        file.close();
    } catch (const openvdb::Exception& e) {
        std::error_code ec;
        fs::remove(tmp, ec);
        throw IoError(path + ": cannot write the VDB file: " + e.what());
    }
    std::error_code ec;
    fs::rename(tmp, path, ec);
    if (ec) {
        fs::remove(tmp, ec);
        throw IoError(path + ": cannot write the VDB file: " + ec.message());
    }
    v.summary.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    return v.summary;
}

std::vector<VdbGridStats> readVdbGridStats(const std::string& path) {
    initOpenVdb();
    checkVdbStructure(path);
    openvdb::GridPtrVecPtr grids;
    try {
        openvdb::io::File file(path);
        file.open();
        grids = file.getGrids();
        file.close();
    } catch (const openvdb::Exception& e) {
        throw IoError(path + ": cannot read the VDB file: " + e.what());
    } catch (const std::bad_alloc&) {
        throw IoError(path + ": cannot read the VDB file: out of memory (is the file corrupt?)");
    }
    std::vector<VdbGridStats> out;
    for (const openvdb::GridBase::Ptr& base : *grids) {
        VdbGridStats s;
        s.name = base->getName();
        s.valueType = base->valueType();
        for (auto it = base->beginMeta(); it != base->endMeta(); ++it)
            if (it->second && std::string(it->second->typeName()) == openvdb::StringMetadata::staticTypeName())
                s.stringMetadata[it->first] = it->second->str();
        if (base->transform().isLinear()) {
            const openvdb::Vec3d vs = base->transform().voxelSize();
            s.voxelSizeMm = vs.x();
            s.uniformScale = vs.x() == vs.y() && vs.y() == vs.z();
        }
        s.activeVoxels = base->activeVoxelCount();
        auto scan = [&s](auto& grid, bool histogram) {
            bool first = true;
            for (auto it = grid.cbeginValueOn(); it; ++it) {
                const double v = static_cast<double>(*it);
                const auto count = it.getVoxelCount();
                s.sum += v * static_cast<double>(count);
                s.min = first ? v : std::min(s.min, v);
                s.max = first ? v : std::max(s.max, v);
                first = false;
                if (histogram) s.int32Histogram[static_cast<int64_t>(*it)] += count;
            }
        };
        if (auto f = openvdb::gridPtrCast<openvdb::FloatGrid>(base)) scan(*f, false);
        else if (auto i = openvdb::gridPtrCast<openvdb::Int32Grid>(base)) scan(*i, true);
        out.push_back(std::move(s));
    }
    return out;
}

}  // namespace fluorosim
