#include "volume/volume_fields.h"

#include <algorithm>
#include <cmath>
#include <limits>
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
    if (cell == 0) cell = std::max<int64_t>(4, (longest + majorants.targetCells - 1) / majorants.targetCells);
    double cellCount = 1;
    for (int a = 0; a < 3; ++a) {
        const int64_t size = cell < 0 ? extent[a] : cell;
        cellSize_[a] = static_cast<double>(size);
        cells_[a] = static_cast<int>((extent[a] + size - 1) / size);
        cellCount *= cells_[a];
    }
    if (cellCount * static_cast<double>(channels_.size()) > double(1 << 28))
        throw ConfigError("the majorant grid would have " + std::to_string(static_cast<int64_t>(cellCount)) +
                          " cells; use a larger majorant cell size");
    const size_t nc = channels_.size();
    std::vector<double> dense(static_cast<size_t>(cellCount) * nc);
    for (size_t i = 0; i < dense.size(); ++i) dense[i] = outside_[i % nc];
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
                        double& m = dense[((static_cast<size_t>(k) * cells_[1] + j) * cells_[0] + i) * nc + c];
                        m = std::max(m, v);
                    }
        });
    }
    std::unordered_map<std::string, uint32_t> entries;
    cellEntry_.resize(static_cast<size_t>(cellCount));
    for (size_t n = 0; n < cellEntry_.size(); ++n) {
        const double* m = &dense[n * nc];
        const auto [it, added] = entries.try_emplace(std::string(reinterpret_cast<const char*>(m), nc * sizeof(double)),
                                                     static_cast<uint32_t>(entries.size()));
        if (added) cellMaxima_.insert(cellMaxima_.end(), m, m + nc);
        cellEntry_[n] = it->second;
    }
    cellMaxima_.shrink_to_fit();
}

void VolumeFields::values(const Vec3& pWorld, double* out) const {
    const Vec3 p = indexFromWorld_.apply(pWorld);
    for (size_t c = 0; c < channels_.size(); ++c) {
        const VolumeChannel& ch = channels_[c];
        out[c] = ch.grid ? ch.offset + ch.scale * ch.grid->value(p, interpolation_) : ch.offset;
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
    size_t bytes = cellMaxima_.size() * sizeof(double) + cellEntry_.size() * sizeof(uint32_t);
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
    if (cellEntry_.empty()) return tr;  // phase 0 with no domain: one outside segment
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
    const Vec3 p = o + d * t0;
    for (int a = 0; a < 3; ++a) {
        const double rel = (p[a] - domainLo_[a]) / cellSize_[a];
        tr.cell_[a] = std::clamp(static_cast<int>(std::floor(rel)), 0, cells_[a] - 1);
        if (d[a] > 0) {
            tr.step_[a] = 1;
            tr.tNext_[a] = (domainLo_[a] + (tr.cell_[a] + 1) * cellSize_[a] - o[a]) / d[a];
            tr.tDelta_[a] = cellSize_[a] / d[a];
        } else if (d[a] < 0) {
            tr.step_[a] = -1;
            tr.tNext_[a] = (domainLo_[a] + tr.cell_[a] * cellSize_[a] - o[a]) / d[a];
            tr.tDelta_[a] = -cellSize_[a] / d[a];
        } else {
            tr.step_[a] = 0;
            tr.tNext_[a] = kInf;
            tr.tDelta_[a] = kInf;
        }
    }
    return tr;
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
            const int axis = tNext_[0] < tNext_[1] ? (tNext_[0] < tNext_[2] ? 0 : 2) : (tNext_[1] < tNext_[2] ? 1 : 2);
            const double* values = f_->cellMax(cell_);
            double end = std::min(tNext_[axis], tEnd_);
            cell_[axis] += step_[axis];
            tNext_[axis] += tDelta_[axis];
            // The last cell reaches the domain's exit even when rounding steps out of range first.
            if (end >= tExit_ || cell_[axis] < 0 || cell_[axis] >= f_->cells_[axis]) {
                end = std::min(tExit_, tEnd_);
                phase_ = 2;
            }
            const MajorantCellSegment s{t_, std::max(t_, end), values};
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
