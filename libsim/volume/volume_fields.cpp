#include "volume/volume_fields.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <map>
#include <string>
#include <unordered_map>

#include "core/errors.h"

namespace fluorosim {
namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();

int floorDiv(int64_t a, int64_t b) { return static_cast<int>(a >= 0 ? a / b : -((-a + b - 1) / b)); }

bool sameTransform(const Affine& a, const Affine& b) {
    double scale = 0, diff = 0;
    for (int i = 0; i < 3; ++i) {
        for (int j = 0; j < 3; ++j) {
            scale = std::max(scale, std::abs(a.m[i][j]));
            diff = std::max(diff, std::abs(a.m[i][j] - b.m[i][j]));
        }
        diff = std::max(diff, std::abs(a.t[i] - b.t[i]) * 1e-3);
    }
    return diff <= 1e-9 * scale;
}

}  // namespace

void MajorantGridOptions::validate() const {
    if (cellVoxels < -1) throw ConfigError("majorant cell size must be >= 1 voxel (0: automatic, -1: one global cell), got " + std::to_string(cellVoxels));
    if (targetCells < 1 || targetCells > 1024) throw ConfigError("majorant target cell count must lie in [1, 1024], got " + std::to_string(targetCells));
    if (maxCells < 1) throw ConfigError("majorant cell cap must be >= 1, got " + std::to_string(maxCells));
}

VolumeFields::VolumeFields(std::vector<VolumeChannel> channels, const Affine& worldFromFile, Interpolation interpolation,
                           MajorantGridOptions majorants, std::optional<DensityGrid> labels)
    : channels_(std::move(channels)), labels_(std::move(labels)), worldFromFile_(worldFromFile), majorantOptions_(majorants),
      interpolation_(interpolation) {
    majorants.validate();
    const DensityGrid* first = nullptr;
    IndexBox bounds;
    for (const VolumeChannel& c : channels_) {
        if (!std::isfinite(c.scale) || c.scale < 0 || !std::isfinite(c.offset) || c.offset < 0)
            throw ConfigError("volume channel scale and offset must be finite and >= 0");
        outside_.push_back(c.offset + (c.grid ? c.scale * c.grid->background() : 0.0));
        if (!c.grid) continue;
        if (!first) first = &*c.grid;
        else if (!sameTransform(first->worldFromIndex(), c.grid->worldFromIndex()))
            throw ConfigError(c.grid->file() + ": grid \"" + c.grid->name() + "\" has a different transform from grid \"" +
                              first->name() + "\"; the grids of one medium must share their voxels");
        const IndexBox b = c.grid->bounds();
        if (b.empty()) continue;
        if (bounds.empty()) bounds = b;
        for (int a = 0; a < 3; ++a) {
            bounds.lo[a] = std::min(bounds.lo[a], b.lo[a]);
            bounds.hi[a] = std::max(bounds.hi[a], b.hi[a]);
        }
    }
    if (labels_ && first && !sameTransform(first->worldFromIndex(), labels_->worldFromIndex()))
        throw ConfigError(labels_->file() + ": label grid \"" + labels_->name() + "\" has a different transform from grid \"" + first->name() +
                          "\"; labels must share the dye grids' voxels");
    worldFromIndex_ = (first ? first->worldFromIndex() : Affine()).then(worldFromFile);
    indexFromWorld_ = worldFromIndex_.inverse();
    if (bounds.empty()) return;  // no voxel differs from the background: the outside values hold everywhere

    // Trilinear lookups at p read voxels floor(p) and floor(p) + 1, so values other than the background
    // live in [lo - 1, hi + 1), and a cell [x0, x0 + B) reads voxels x0 .. x0 + B. Both are widened by
    // one voxel so that a point rounded across a cell or domain boundary (positions are computed from
    // t) is still bounded by the segment that holds its t.
    int64_t extent[3];
    int64_t longest = 0;
    for (int a = 0; a < 3; ++a) {
        domainLo_[a] = bounds.lo[a] - 2.0;
        domainHi_[a] = bounds.hi[a] + 2.0;
        extent[a] = int64_t(bounds.hi[a]) - bounds.lo[a] + 4;
        longest = std::max(longest, extent[a]);
    }
    int64_t cell = majorants.cellVoxels;
    if (cell == 0) {
        cell = std::clamp<int64_t>((longest + majorants.targetCells - 1) / majorants.targetCells, 4, 8);
        const auto count = [&](int64_t c) {
            double n = 1;
            for (int a = 0; a < 3; ++a) n *= double((extent[a] + c - 1) / c);
            return n;
        };
        while (count(cell) > double(majorants.maxCells)) ++cell;
    }
    double cellCount = 1;
    for (int a = 0; a < 3; ++a) {
        const int64_t size = cell < 0 ? extent[a] : cell;
        cellSize_[a] = static_cast<double>(size);
        cells_[a] = static_cast<int>((extent[a] + size - 1) / size);
        cellCount *= cells_[a];
    }
    if (cellCount > double(std::numeric_limits<uint32_t>::max()) || cellCount * static_cast<double>(channels_.size()) > double(1 << 28))
        throw ConfigError("the majorant grid would have " + std::to_string(static_cast<int64_t>(cellCount)) +
                          " cells; use a larger majorant cell size");
    // Cells no block touches hold the outside values (entry 0); only touched cells are gathered.
    const size_t nc = channels_.size();
    std::unordered_map<size_t, std::vector<double>> touched;
    for (size_t c = 0; c < nc; ++c) {
        const VolumeChannel& ch = channels_[c];
        if (!ch.grid) continue;
        ch.grid->forEachBlock([&](const IndexBox& b, double maxValue) {
            int lo[3], hi[3];
            for (int a = 0; a < 3; ++a) {
                const int64_t size = static_cast<int64_t>(cellSize_[a]);
                const int64_t origin = bounds.lo[a] - 2;
                lo[a] = std::max(0, floorDiv(b.lo[a] - origin - 2, size));
                hi[a] = std::min(cells_[a] - 1, floorDiv(b.hi[a] - origin + 1, size));
            }
            const double v = ch.offset + ch.scale * maxValue;
            for (int k = lo[2]; k <= hi[2]; ++k)
                for (int j = lo[1]; j <= hi[1]; ++j)
                    for (int i = lo[0]; i <= hi[0]; ++i) {
                        auto [it, added] = touched.try_emplace((static_cast<size_t>(k) * cells_[1] + j) * cells_[0] + static_cast<size_t>(i));
                        if (added) it->second = outside_;
                        it->second[c] = std::max(it->second[c], v);
                    }
        });
    }
    std::map<std::vector<double>, uint32_t> entries{{outside_, 0}};
    cellMaxima_ = outside_;
    std::vector<uint32_t> dense(static_cast<size_t>(cellCount), 0);
    for (const auto& [at, maxima] : touched) {
        const auto [it, added] = entries.try_emplace(maxima, static_cast<uint32_t>(entries.size()));
        if (added) cellMaxima_.insert(cellMaxima_.end(), maxima.begin(), maxima.end());
        dense[at] = it->second;
    }
    cellMaxima_.shrink_to_fit();
    // Blocks whose cells share one entry keep it; the others (mixed) keep their cells' entries together,
    // so that a ray crossing a block reads one small piece of memory.
    for (int a = 0; a < 3; ++a) blocks_[a] = (cells_[a] + kBlockCells - 1) / kBlockCells;
    constexpr int32_t kNoCell = -2, kMixed = -1;
    blockEntry_.assign(static_cast<size_t>(blocks_[0]) * blocks_[1] * blocks_[2], kNoCell);
    const auto blockOf = [&](int i, int j, int k) {
        return (static_cast<size_t>(k / kBlockCells) * blocks_[1] + static_cast<size_t>(j / kBlockCells)) * blocks_[0] + static_cast<size_t>(i / kBlockCells);
    };
    const auto denseAt = [&](int i, int j, int k) { return dense[(static_cast<size_t>(k) * cells_[1] + j) * cells_[0] + static_cast<size_t>(i)]; };
    for (int k = 0; k < cells_[2]; ++k)
        for (int j = 0; j < cells_[1]; ++j)
            for (int i = 0; i < cells_[0]; ++i) {
                const auto e = static_cast<int32_t>(denseAt(i, j, k));
                int32_t& b = blockEntry_[blockOf(i, j, k)];
                b = b == kNoCell || b == e ? e : kMixed;
            }
    size_t mixed = 0;
    for (int32_t& b : blockEntry_)
        if (b == kMixed) b = -static_cast<int32_t>(++mixed);  // mixed block m is -(m + 1)
    cellEntry_.assign(mixed * kCellsPerBlock, 0);
    for (int k = 0; k < cells_[2]; ++k)
        for (int j = 0; j < cells_[1]; ++j)
            for (int i = 0; i < cells_[0]; ++i) {
                const int32_t b = blockEntry_[blockOf(i, j, k)];
                if (b < 0) cellEntry_[static_cast<size_t>(-b - 1) * kCellsPerBlock + localCell({i, j, k})] = denseAt(i, j, k);
            }
}

void VolumeFields::values(const Vec3& pWorld, double* out, const double* upper) const {
    const Vec3 p = indexFromWorld_.apply(pWorld);
    for (size_t c = 0; c < channels_.size(); ++c) {
        const VolumeChannel& ch = channels_[c];
        out[c] = ch.grid && (!upper || upper[c] > ch.offset) ? ch.offset + ch.scale * ch.grid->value(p, interpolation_) : ch.offset;
    }
}

double VolumeFields::voxelSizeMm() const {
    bool anyGrid = false;
    for (const VolumeChannel& c : channels_) anyGrid = anyGrid || c.grid.has_value();
    if (!anyGrid) return 1.0;
    double shortest = std::numeric_limits<double>::infinity();
    for (int a = 0; a < 3; ++a) shortest = std::min(shortest, length(worldFromIndex_.applyLinear(Vec3(a == 0, a == 1, a == 2))));
    return shortest;
}

std::shared_ptr<const VolumeFields> VolumeFields::scaled(const std::function<double(int, int, int, int)>& factor) const {
    std::vector<VolumeChannel> channels = channels_;
    for (size_t c = 0; c < channels.size(); ++c)
        if (channels[c].grid)
            channels[c].grid = channels[c].grid->scaled([&](int i, int j, int k) { return factor(static_cast<int>(c), i, j, k); });
    return std::make_shared<const VolumeFields>(std::move(channels), worldFromFile_, interpolation_, majorantOptions_, labels_);
}

std::vector<double> VolumeFields::channelMaxima() const {
    std::vector<double> m = outside_;
    for (size_t i = 0; i < cellMaxima_.size(); ++i) m[i % m.size()] = std::max(m[i % m.size()], cellMaxima_[i]);
    return m;
}

std::vector<double> VolumeFields::channelFloors() const {
    std::vector<double> f;
    for (const VolumeChannel& c : channels_) f.push_back(c.offset);
    return f;
}

size_t VolumeFields::memoryBytes() const {
    size_t bytes = cellMaxima_.size() * sizeof(double) + cellEntry_.size() * sizeof(uint32_t) + blockEntry_.size() * sizeof(int32_t);
    for (const VolumeChannel& c : channels_)
        if (c.grid) bytes += c.grid->memoryBytes();
    return bytes;
}

VolumeFields::Traversal VolumeFields::traverse(const Ray& worldRay, double tMin, double tMax) const {
    Traversal tr;
    tr.f_ = this;
    tr.t_ = tMin;
    tr.tEnd_ = tMax;
    tr.tEnter_ = tr.tExit_ = kInf;
    if (blockEntry_.empty()) return tr;  // phase 0 with no domain: one outside segment
    const Vec3 o = indexFromWorld_.apply(worldRay.o), d = indexFromWorld_.applyLinear(worldRay.d);
    double t0 = tMin, t1 = tMax;
    for (int a = 0; a < 3; ++a) {
        if (d[a] == 0) {
            if (o[a] < domainLo_[a] || o[a] >= domainHi_[a]) t1 = -kInf;
            continue;
        }
        double ta = (domainLo_[a] - o[a]) / d[a], tb = (domainHi_[a] - o[a]) / d[a];
        if (ta > tb) std::swap(ta, tb);
        t0 = std::max(t0, ta);
        t1 = std::min(t1, tb);
    }
    if (!(t0 < t1)) return tr;
    tr.tEnter_ = t0;
    tr.tExit_ = t1;
    tr.o_ = o;
    tr.d_ = d;
    tr.blockExit_ = t0;  // where the first block is entered
    std::array<double, 3> blockSize;
    for (int a = 0; a < 3; ++a) blockSize[a] = cellSize_[a] * kBlockCells;
    tr.start(tr.block_, t0, blockSize, {0, 0, 0}, {blocks_[0] - 1, blocks_[1] - 1, blocks_[2] - 1});
    return tr;
}

// A DDA over cells of `size` (index space, from the domain's corner) at the ray's point t, clamped to
// cells lo..hi.
void VolumeFields::Traversal::start(Dda& dda, double t, const std::array<double, 3>& size, const std::array<int, 3>& lo,
                                    const std::array<int, 3>& hi) const {
    const Vec3 p = o_ + d_ * t;
    const Vec3& origin = f_->domainLo_;
    for (int a = 0; a < 3; ++a) {
        dda.cell[a] = std::clamp(static_cast<int>(std::floor((p[a] - origin[a]) / size[a])), lo[a], hi[a]);
        if (d_[a] > 0) {
            dda.step[a] = 1;
            dda.tNext[a] = (origin[a] + (dda.cell[a] + 1) * size[a] - o_[a]) / d_[a];
            dda.tDelta[a] = size[a] / d_[a];
        } else if (d_[a] < 0) {
            dda.step[a] = -1;
            dda.tNext[a] = (origin[a] + dda.cell[a] * size[a] - o_[a]) / d_[a];
            dda.tDelta[a] = -size[a] / d_[a];
        } else {
            dda.step[a] = 0;
            dda.tNext[a] = kInf;
            dda.tDelta[a] = kInf;
        }
    }
}

// One uniform block, or one cell of a mixed block, from t_ on.
VolumeFields::Traversal::Piece VolumeFields::Traversal::piece() {
    if (!inBlock_) {
        const std::array<int, 3> b = block_.cell;
        const int axis = block_.axis();
        const double enter = blockExit_;
        blockExit_ = block_.tNext[axis];
        block_.cell[axis] += block_.step[axis];
        block_.tNext[axis] += block_.tDelta[axis];
        // The last block reaches the domain's exit even when rounding steps out of range first.
        blockLast_ = blockExit_ >= tExit_ || block_.cell[axis] < 0 || block_.cell[axis] >= f_->blocks_[axis];
        if (blockLast_) blockExit_ = tExit_;
        if (const double* values = f_->blockMax(b)) return {blockExit_, values, blockLast_};
        blockCells_ = f_->mixedCells(b);
        for (int a = 0; a < 3; ++a) {
            blockCellLo_[a] = b[a] * kBlockCells;
            blockCellHi_[a] = std::min(f_->cells_[a], blockCellLo_[a] + kBlockCells) - 1;
        }
        start(cell_, enter, f_->cellSize_, blockCellLo_, blockCellHi_);
        inBlock_ = true;
    }
    const double* values = f_->cellValues(blockCells_[localCell(cell_.cell)]);
    const int axis = cell_.axis();
    double end = cell_.tNext[axis];
    cell_.cell[axis] += cell_.step[axis];
    cell_.tNext[axis] += cell_.tDelta[axis];
    if (end >= blockExit_ || cell_.cell[axis] < blockCellLo_[axis] || cell_.cell[axis] > blockCellHi_[axis]) {
        end = blockExit_;
        inBlock_ = false;
        return {end, values, blockLast_};
    }
    return {end, values, false};
}

std::optional<MajorantCellSegment> VolumeFields::Traversal::next() {
    while (phase_ < 3) {
        if (t_ >= tEnd_) return std::nullopt;
        if (phase_ == 0) {
            phase_ = std::isfinite(tEnter_) ? 1 : 3;
            const double end = std::min(tEnter_, tEnd_);
            if (end > t_) {
                const MajorantCellSegment s{t_, end, f_->outside_.data()};
                t_ = end;
                return s;
            }
            if (phase_ == 3) return std::nullopt;
            continue;
        }
        if (phase_ == 1) {
            Piece p = pending_ ? *pending_ : piece();
            pending_.reset();
            // Consecutive pieces with the same maxima (empty space, one dye's neurite at full
            // concentration) make one segment, so the tracker's per-segment work is paid once.
            while (!p.last && p.end < tEnd_) {
                const Piece q = piece();
                if (q.values != p.values) {
                    pending_ = q;
                    break;
                }
                p.end = q.end;
                p.last = q.last;
            }
            if (p.last) phase_ = 2;
            const MajorantCellSegment s{t_, std::max(t_, std::min(p.end, tEnd_)), p.values};
            t_ = s.tMax;
            if (s.tMax > s.tMin) return s;
            continue;
        }
        phase_ = 3;
        if (tEnd_ > t_) return MajorantCellSegment{t_, tEnd_, f_->outside_.data()};
    }
    return std::nullopt;
}

}  // namespace fluorosim
