#include "optics/emission_lattice.h"

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <map>
#include <mutex>
#include <numeric>
#include <unordered_map>
#include <unordered_set>

#include "core/errors.h"
#include "core/memory_cap.h"
#include "core/parallel.h"
#include "core/quadrature.h"
#include "optics/index_key.h"
#include "render/straight_line.h"

namespace fluorosim::optics {
namespace {

int64_t floorDiv(int64_t a, int64_t b) { return a >= 0 ? a / b : -((-a + b - 1) / b); }


struct Box {
    double x0 = 1e300, x1 = -1e300, y0 = 1e300, y1 = -1e300, z0 = 1e300, z1 = -1e300;
};
Box localBox(const LatticeGeometry& g, const Vec3* corners, int count) {
    Box b;
    for (int c = 0; c < count; ++c) {
        const LatticeGeometry::Local p = g.local(corners[c]);
        b.x0 = std::min(b.x0, p.x);
        b.x1 = std::max(b.x1, p.x);
        b.y0 = std::min(b.y0, p.y);
        b.y1 = std::max(b.y1, p.y);
        b.z0 = std::min(b.z0, p.z);
        b.z1 = std::max(b.z1, p.z);
    }
    return b;
}

// A point with its concentrations and parts, before the points are sorted.
struct Candidate {
    LatticePoint point;
    bool exact = false;       // a homogeneous medium: transmittances at the point itself
    bool fromColumn = false;  // placed along a column through the geometry: its medium is known
    std::array<float, kMaxMediumChannels - kFirstDyeChannel> c{};  // by slot
    std::vector<EmissionLattice::Part> parts;  // key: a LabelKey index into a chunk-local list, resolved below
};

// Sorted, merged [o − h, o + h] over the planes.
std::vector<std::pair<double, double>> planeSlabs(const LatticeGeometry& g) {
    std::vector<double> o = g.planeOffsetsMm;
    std::sort(o.begin(), o.end());
    std::vector<std::pair<double, double>> slabs;
    const double h = g.halfDepthMm();
    for (double x : o) {
        if (!slabs.empty() && x - h <= slabs.back().second) slabs.back().second = x + h;
        else slabs.push_back({x - h, x + h});
    }
    return slabs;
}

}  // namespace

double LatticeGeometry::zLow() const {
    double lo = 0;
    for (size_t i = 0; i < planeOffsetsMm.size(); ++i) lo = i ? std::min(lo, planeOffsetsMm[i]) : planeOffsetsMm[i];
    return lo - halfDepthMm();
}

int LatticeGeometry::stackLayers() const {
    double lo = 0, hi = 0;
    for (size_t i = 0; i < planeOffsetsMm.size(); ++i) {
        lo = i ? std::min(lo, planeOffsetsMm[i]) : planeOffsetsMm[i];
        hi = i ? std::max(hi, planeOffsetsMm[i]) : planeOffsetsMm[i];
    }
    return static_cast<int>(std::ceil((hi - lo) / axialMm - 1e-9)) + planeLayers;
}

bool LatticeGeometry::reached(double z) const {
    const double h = halfDepthMm();
    for (double o : planeOffsetsMm)
        if (std::abs(z - o) <= h) return true;
    return false;
}

EmissionLattice::EmissionLattice(const Scene& scene, const ChannelDyes& dyes, const LatticeGeometry& g, int segmentNodes, bool withLabels,
                                 int threads, const std::atomic<bool>* cancel)
    : geometry_(g), slots_(std::max(1, dyes.slots)) {
    const auto start = std::chrono::steady_clock::now();
    if (dyes.empty() || g.planeOffsetsMm.empty()) return;
    const double latt = g.lateralMm(), xLeft = g.xLeft(), yTop = g.yTop();
    const int columnsX = g.columnsX(), columnsY = g.columnsY();
    const int stackLayers = g.stackLayers();
    const double zLow = g.zLow(), zHigh = zLow + stackLayers * g.axialMm;
    const std::vector<std::pair<double, double>> slabs = planeSlabs(g);
    auto reachedRange = [&](double z0, double z1) {
        for (const auto& s : slabs)
            if (z1 >= s.first && z0 <= s.second) return true;
        return false;
    };
    auto emitting = [&](int medium) { return dyes.firstOfMedium[static_cast<size_t>(medium)] >= 0; };
    std::vector<uint8_t> layerReached(static_cast<size_t>(stackLayers));
    for (int k = 0; k < stackLayers; ++k) layerReached[static_cast<size_t>(k)] = g.reached(g.layerZ(k));

    // Label keys are collected per chunk and resolved to one sorted list at the end.
    std::vector<std::vector<Candidate>> chunks;
    std::vector<std::vector<LabelKey>> chunkKeys;
    std::mutex chunkMutex;
    auto addChunk = [&](std::vector<Candidate>&& c, std::vector<LabelKey>&& keys) {
        if (c.empty()) return;
        const std::lock_guard<std::mutex> lock(chunkMutex);
        chunks.push_back(std::move(c));
        chunkKeys.push_back(std::move(keys));
    };
    // Bytes per point held at the end (point, concentrations, flag, a part per slot).
    const double bytesPerPoint = sizeof(LatticePoint) + 4.0 * slots_ + 1 + (withLabels ? (sizeof(Part) + 4.0) * slots_ : 0.0);
    std::atomic<size_t> total{0};
    auto account = [&](size_t n) {
        const size_t now = total += n;
        // Candidates hold about four times the final bytes while the chunks are gathered.
        requireMemory(4 * bytesPerPoint * static_cast<double>(now), "the computed image's emission points (" + std::to_string(now) + " so far)");
    };

    // --- Grid media: lattice nodes near the dye grids' active 8³ blocks (a voxel beyond for trilinear
    // lookups); each node is visited from one block, the smallest active one that reaches it.
    struct BlockTask {
        int medium;
        int64_t bx, by, bz;
    };
    std::vector<BlockTask> blockTasks;
    std::vector<std::unordered_set<uint64_t>> activeBlocks(scene.media.size());
    std::vector<int> homogeneousMedia;
    for (size_t med = 0; med < scene.media.size(); ++med) {
        if (!emitting(static_cast<int>(med))) continue;
        const Medium& medium = scene.media[med];
        const VolumeFields* volume = medium.volume();
        bool constantDye = !volume;
        for (const EmittingDye& t : dyes.dyes)
            if (t.medium == static_cast<int>(med) &&
                (medium.channelFloor()[static_cast<size_t>(t.channel)] > 0 || !volume || !volume->channel(t.channel).grid))
                constantDye = true;
        if (constantDye) {
            homogeneousMedia.push_back(static_cast<int>(med));
            continue;
        }
        std::unordered_set<uint64_t>& blocks = activeBlocks[med];
        for (const EmittingDye& t : dyes.dyes) {
            if (t.medium != static_cast<int>(med)) continue;
            volume->channel(t.channel).grid->forEachBlock([&](const IndexBox& box, double maxValue) {
                if (!(maxValue > 0)) return;
                for (int64_t cz = box.lo[2] >> 3; cz <= box.hi[2] >> 3; ++cz)
                    for (int64_t cy = box.lo[1] >> 3; cy <= box.hi[1] >> 3; ++cy)
                        for (int64_t cx = box.lo[0] >> 3; cx <= box.hi[0] >> 3; ++cx) blocks.insert(packIndexKey(cx, cy, cz));
            });
        }
        std::vector<uint64_t> sorted(blocks.begin(), blocks.end());
        std::sort(sorted.begin(), sorted.end());
        for (uint64_t k : sorted) {
            const auto b = unpackIndexKey(k);
            blockTasks.push_back({static_cast<int>(med), b[0], b[1], b[2]});
        }
    }
    parallelFor(blockTasks.size(), threads, [&](size_t task) {
        if (cancel && cancel->load()) return;
        const BlockTask& bt = blockTasks[task];
        const Medium& medium = scene.media[static_cast<size_t>(bt.medium)];
        const VolumeFields& volume = *medium.volume();
        const bool nearest = volume.interpolation() == Interpolation::Nearest;
        // Index positions a node may have and still read this block: [8b − 1, 8b + 8) for trilinear
        // lookups, [8b − 0.5, 8b + 7.5) for nearest ones.
        const double reachLo = nearest ? -0.5 : -1.0, reachHi = nearest ? 7.5 : 8.0;
        const std::array<int64_t, 3> b{bt.bx, bt.by, bt.bz};
        Vec3 corners[8];
        for (int a = 0; a < 8; ++a)
            corners[a] = volume.worldFromIndex().apply(Vec3(8.0 * b[0] + ((a & 1) ? reachHi : reachLo), 8.0 * b[1] + (((a >> 1) & 1) ? reachHi : reachLo),
                                                            8.0 * b[2] + (((a >> 2) & 1) ? reachHi : reachLo)));
        const Box box = localBox(g, corners, 8);
        if (box.x1 < xLeft || box.x0 > -xLeft || box.y0 > yTop || box.y1 < -yTop || box.z1 < zLow || box.z0 > zHigh) return;
        if (!reachedRange(box.z0 - g.axialMm, box.z1 + g.axialMm)) return;
        // The dye channels' voxels this block can read, [8b − 1, 8b + 9) on each axis, in a dense cache.
        IndexBox cache;
        for (int a = 0; a < 3; ++a) {
            cache.lo[static_cast<size_t>(a)] = static_cast<int32_t>(8 * b[static_cast<size_t>(a)] - 1);
            cache.hi[static_cast<size_t>(a)] = static_cast<int32_t>(8 * b[static_cast<size_t>(a)] + 8);
        }
        struct DenseChannel {
            int slot;
            double offset, scale;
            std::vector<float> v;
        };
        std::vector<DenseChannel> dense;
        for (const EmittingDye& t : dyes.dyes) {
            if (t.medium != bt.medium) continue;
            const VolumeChannel& ch = volume.channel(t.channel);
            DenseChannel d{t.slot, ch.offset, ch.scale, std::vector<float>(1000)};
            ch.grid->copyVoxels(cache, d.v.data());
            dense.push_back(std::move(d));
        }
        std::vector<float> labelCache;
        if (withLabels && volume.labels()) {
            labelCache.resize(1000);
            volume.labels()->copyVoxels(cache, labelCache.data());
        }
        auto at = [](int i, int j, int k) { return static_cast<size_t>((std::clamp(k, 0, 9) * 10 + std::clamp(j, 0, 9)) * 10 + std::clamp(i, 0, 9)); };
        // Lattice nodes by the index cell (between voxel centres) that holds them: a cell whose corner
        // voxels are all zero reads zero everywhere. A cell belongs to the smallest active block among
        // its corners' blocks, so that each node is visited once.
        const std::unordered_set<uint64_t>& active = activeBlocks[static_cast<size_t>(bt.medium)];
        const uint64_t self = packIndexKey(b[0], b[1], b[2]);
        const Affine& fromWorld = volume.indexFromWorld();
        const Affine& toWorld = volume.worldFromIndex();
        const double volumeMm3 = latt * latt * g.axialMm;
        const int cellLo = nearest ? 0 : -1;  // nearest lookups: the cell of voxel v is [v − 0.5, v + 0.5)
        const double off = nearest ? -0.5 : 0.0;
        std::vector<Candidate> local;
        std::vector<LabelKey> keys;
        std::map<LabelKey, uint32_t> keyIndex;
        auto keyOf = [&](int32_t value) {
            const LabelKey k{bt.medium, value};
            const auto [it, inserted] = keyIndex.try_emplace(k, static_cast<uint32_t>(keys.size()));
            if (inserted) keys.push_back(k);
            return it->second;
        };
        for (int ck = cellLo; ck < 8; ++ck)
            for (int cj = cellLo; cj < 8; ++cj)
                for (int ci = cellLo; ci < 8; ++ci) {
                    const int64_t gi = 8 * b[0] + ci, gj = 8 * b[1] + cj, gk = 8 * b[2] + ck;
                    bool any = false;
                    const int cornerCount = nearest ? 1 : 8;
                    for (int c = 0; c < cornerCount && !any; ++c)
                        for (const DenseChannel& d : dense)
                            any = any || d.v[at(ci + 1 + (c & 1), cj + 1 + ((c >> 1) & 1), ck + 1 + ((c >> 2) & 1))] > 0;
                    if (!any) continue;
                    if (!nearest) {
                        bool mine = true;
                        for (int c = 0; c < 8 && mine; ++c) {
                            const uint64_t k = packIndexKey(floorDiv(gi + (c & 1), 8), floorDiv(gj + ((c >> 1) & 1), 8), floorDiv(gk + ((c >> 2) & 1), 8));
                            mine = !(k < self && active.count(k));
                        }
                        if (!mine) continue;
                    }
                    Vec3 cellCorners[8];
                    for (int c = 0; c < 8; ++c) cellCorners[c] = toWorld.apply(Vec3(gi + off + (c & 1), gj + off + ((c >> 1) & 1), gk + off + ((c >> 2) & 1)));
                    const Box cell = localBox(g, cellCorners, 8);
                    const int i0 = std::max(0, static_cast<int>(std::ceil((cell.x0 - xLeft) / latt - 0.5))),
                              i1 = std::min(columnsX - 1, static_cast<int>(std::floor((cell.x1 - xLeft) / latt - 0.5)));
                    const int j0 = std::max(0, static_cast<int>(std::ceil((yTop - cell.y1) / latt - 0.5))),
                              j1 = std::min(columnsY - 1, static_cast<int>(std::floor((yTop - cell.y0) / latt - 0.5)));
                    const int k0 = std::max(0, static_cast<int>(std::ceil((cell.z0 - zLow) / g.axialMm - 0.5))),
                              k1 = std::min(stackLayers - 1, static_cast<int>(std::floor((cell.z1 - zLow) / g.axialMm - 0.5)));
                    for (int j = j0; j <= j1; ++j)
                        for (int i = i0; i <= i1; ++i)
                            for (int k = k0; k <= k1; ++k) {
                                if (!layerReached[static_cast<size_t>(k)]) continue;
                                const double x = g.columnX(i), y = g.columnY(j), z = zLow + (k + 0.5) * g.axialMm;
                                const Vec3 q = fromWorld.apply(g.world(x, y, z));
                                if (std::floor(q.x - off) != double(gi) || std::floor(q.y - off) != double(gj) || std::floor(q.z - off) != double(gk)) continue;
                                // The stencil: voxel corners and their weights.
                                const double ux = q.x - double(8 * b[0] - 1), uy = q.y - double(8 * b[1] - 1), uz = q.z - double(8 * b[2] - 1);
                                std::array<size_t, 8> idx{};
                                std::array<double, 8> w{};
                                int stencil = 8;
                                if (nearest) {
                                    stencil = 1;
                                    idx[0] = at(static_cast<int>(std::floor(ux + 0.5)), static_cast<int>(std::floor(uy + 0.5)), static_cast<int>(std::floor(uz + 0.5)));
                                    w[0] = 1;
                                } else {
                                    const int ii = static_cast<int>(std::floor(ux)), jj = static_cast<int>(std::floor(uy)), kk = static_cast<int>(std::floor(uz));
                                    const double fx = ux - ii, fy = uy - jj, fz = uz - kk;
                                    for (int c = 0; c < 8; ++c) {
                                        idx[static_cast<size_t>(c)] = at(ii + (c & 1), jj + ((c >> 1) & 1), kk + ((c >> 2) & 1));
                                        w[static_cast<size_t>(c)] = ((c & 1) ? fx : 1 - fx) * (((c >> 1) & 1) ? fy : 1 - fy) * (((c >> 2) & 1) ? fz : 1 - fz);
                                    }
                                }
                                Candidate cand;
                                cand.point = {x, y, z, volumeMm3, bt.medium};
                                bool dyed = false;
                                for (const DenseChannel& d : dense) {
                                    double v = 0;
                                    for (int c = 0; c < stencil; ++c) v += w[static_cast<size_t>(c)] * d.v[idx[static_cast<size_t>(c)]];
                                    const double value = d.offset + d.scale * v;
                                    cand.c[static_cast<size_t>(d.slot)] = static_cast<float>(value);
                                    dyed = dyed || value > 0;
                                }
                                if (!dyed) continue;
                                if (withLabels) {
                                    // Each voxel's dye belongs to its label: the parts are the stencil's
                                    // sums by label (the offset, a floor, to label 0).
                                    for (const DenseChannel& d : dense) {
                                        std::array<std::pair<int32_t, double>, 9> sums{};
                                        int n = 0;
                                        auto add = [&](int32_t label, double v) {
                                            if (!(v > 0)) return;
                                            for (int s = 0; s < n; ++s)
                                                if (sums[static_cast<size_t>(s)].first == label) {
                                                    sums[static_cast<size_t>(s)].second += v;
                                                    return;
                                                }
                                            sums[static_cast<size_t>(n++)] = {label, v};
                                        };
                                        for (int c = 0; c < stencil; ++c) {
                                            const int32_t label = labelCache.empty() ? 0 : static_cast<int32_t>(labelCache[idx[static_cast<size_t>(c)]]);
                                            add(label, d.scale * w[static_cast<size_t>(c)] * d.v[idx[static_cast<size_t>(c)]]);
                                        }
                                        add(0, d.offset);
                                        for (int s = 0; s < n; ++s)
                                            cand.parts.push_back({keyOf(sums[static_cast<size_t>(s)].first), static_cast<uint16_t>(d.slot),
                                                                  static_cast<float>(sums[static_cast<size_t>(s)].second)});
                                    }
                                }
                                local.push_back(std::move(cand));
                            }
                }
        account(local.size());
        addChunk(std::move(local), std::move(keys));
    });

    // --- Homogeneous dyed media: columns that partition the region, refined over small shapes.
    if (!homogeneousMedia.empty() && !(cancel && cancel->load())) {
        // Per standard cell: 0 no column, r >= 1 r × r sub-columns.
        std::vector<uint8_t> refine(static_cast<size_t>(columnsX) * columnsY, 0);
        auto mark = [&](int i0, int i1, int j0, int j1, int r) {
            for (int j = std::max(0, j0); j <= std::min(columnsY - 1, j1); ++j)
                for (int i = std::max(0, i0); i <= std::min(columnsX - 1, i1); ++i) {
                    uint8_t& v = refine[static_cast<size_t>(j) * columnsX + i];
                    v = std::max<uint8_t>(v, static_cast<uint8_t>(r));
                }
        };
        for (int med : homogeneousMedia) {
            bool enclosed = med != scene.camera.medium;
            std::vector<uint32_t> shapes;
            for (uint32_t s = 0; s < scene.shapes.size(); ++s) {
                if (scene.shapes[s].outsideMedium == med) enclosed = false;
                if (scene.shapes[s].insideMedium == med) shapes.push_back(s);
            }
            if (!enclosed || shapes.empty()) {
                mark(0, columnsX - 1, 0, columnsY - 1, 1);
                continue;
            }
            for (uint32_t s : shapes) {
                Vec3 corners[8];
                if (scene.geometry.isSphere(s)) {
                    const Vec3 c = scene.geometry.sphereCenter(s);
                    const double r = scene.geometry.sphereRadius(s);
                    for (int a = 0; a < 8; ++a) corners[a] = c + Vec3((a & 1) ? r : -r, ((a >> 1) & 1) ? r : -r, ((a >> 2) & 1) ? r : -r);
                } else {
                    Vec3 lo(1e300, 1e300, 1e300), hi(-1e300, -1e300, -1e300);
                    for (const Vec3& p : scene.geometry.mesh(s).positions)
                        for (int a = 0; a < 3; ++a) {
                            lo[a] = std::min(lo[a], p[a]);
                            hi[a] = std::max(hi[a], p[a]);
                        }
                    for (int a = 0; a < 8; ++a) corners[a] = Vec3((a & 1) ? hi.x : lo.x, ((a >> 1) & 1) ? hi.y : lo.y, ((a >> 2) & 1) ? hi.z : lo.z);
                }
                const Box b = localBox(g, corners, 8);
                if (b.x1 < xLeft || b.x0 > -xLeft || b.y0 > yTop || b.y1 < -yTop || b.z1 < zLow || b.z0 > zHigh) continue;
                if (!reachedRange(b.z0, b.z1)) continue;
                const double extent = std::min(b.x1 - b.x0, b.y1 - b.y0);
                // A small shape (a bead): at least 8 sub-columns across it.
                const int r = extent < 4 * latt ? std::clamp(static_cast<int>(std::ceil(8 * latt / std::max(extent, 1e-12))), 1, 64) : 1;
                mark(static_cast<int>(std::floor((b.x0 - xLeft) / latt)), static_cast<int>(std::floor((b.x1 - xLeft) / latt)),
                     static_cast<int>(std::floor((yTop - b.y1) / latt)), static_cast<int>(std::floor((yTop - b.y0) / latt)), r);
            }
        }
        struct Column {
            double x, y, area;
        };
        std::vector<Column> columns;
        for (int j = 0; j < columnsY; ++j)
            for (int i = 0; i < columnsX; ++i) {
                const int r = refine[static_cast<size_t>(j) * columnsX + i];
                if (!r) continue;
                const double fine = latt / r;
                for (int b = 0; b < r; ++b)
                    for (int a = 0; a < r; ++a)
                        columns.push_back({xLeft + i * latt + (a + 0.5) * fine, yTop - j * latt - (b + 0.5) * fine, fine * fine});
            }
        const QuadratureRule gl = gaussLegendre01(segmentNodes);
        constexpr size_t kColumnsPerTask = 256;
        parallelFor((columns.size() + kColumnsPerTask - 1) / kColumnsPerTask, threads, [&](size_t task) {
            if (cancel && cancel->load()) return;
            std::vector<Candidate> local;
            std::vector<LabelKey> keys;
            std::map<LabelKey, uint32_t> keyIndex;
            for (size_t c = task * kColumnsPerTask; c < std::min(columns.size(), (task + 1) * kColumnsPerTask); ++c) {
                const Column& col = columns[c];
                const Vec3 top = g.world(col.x, col.y, zHigh);
                const Ray down{top, -g.axis};
                const int medium0 = mediumAt(scene, top, g.axis);
                const StraightLine line = traceStraightLine(scene, down, medium0, 0.0, zHigh - zLow, LineSurfaces::ThroughAll);
                for (const RaySegment& seg : line.segments) {
                    if (std::find(homogeneousMedia.begin(), homogeneousMedia.end(), seg.medium) == homogeneousMedia.end()) continue;
                    const Medium& medium = scene.media[static_cast<size_t>(seg.medium)];
                    const VolumeFields* volume = medium.volume();
                    for (const auto& slab : slabs) {
                        // The slab in t along the column (t = zHigh − z).
                        const double a = std::max(seg.t0, zHigh - slab.second), bEnd = std::min(seg.t1, zHigh - slab.first);
                        if (!(bEnd > a)) continue;
                        const int pieces = std::max(1, static_cast<int>(std::ceil((bEnd - a) / g.axialMm)));
                        const double h = (bEnd - a) / pieces;
                        for (int piece = 0; piece < pieces; ++piece)
                            for (size_t n = 0; n < gl.nodes.size(); ++n) {
                                const double t = a + (piece + gl.nodes[n]) * h;
                                Candidate cand;
                                cand.point = {col.x, col.y, zHigh - t, col.area * h * gl.weights[n], seg.medium};
                                cand.exact = medium.isHomogeneous();
                                cand.fromColumn = true;
                                ChannelValues values;
                                medium.channelValues(down.at(t), values.data());
                                int32_t label = 0;
                                if (withLabels && volume && volume->labels())
                                    label = static_cast<int32_t>(volume->labels()->value(volume->indexFromWorld().apply(down.at(t)), Interpolation::Nearest));
                                bool dyed = false;
                                for (const EmittingDye& d : dyes.dyes) {
                                    if (d.medium != seg.medium) continue;
                                    const float v = static_cast<float>(values[static_cast<size_t>(d.channel)]);
                                    cand.c[static_cast<size_t>(d.slot)] = v;
                                    dyed = dyed || v > 0;
                                    if (withLabels && v > 0) {
                                        const LabelKey k{seg.medium, label};
                                        const auto [it, inserted] = keyIndex.try_emplace(k, static_cast<uint32_t>(keys.size()));
                                        if (inserted) keys.push_back(k);
                                        cand.parts.push_back({it->second, static_cast<uint16_t>(d.slot), v});
                                    }
                                }
                                if (dyed) local.push_back(std::move(cand));
                            }
                    }
                }
            }
            account(local.size());
            addChunk(std::move(local), std::move(keys));
        });
    }
    if (cancel && cancel->load()) {
        complete_ = false;
        return;
    }

    // --- Grid points: the medium at each from the geometry of its lattice column.
    {
        std::unordered_map<uint64_t, std::vector<RaySegment>> columnMedia;
        for (const auto& chunk : chunks)
            for (const Candidate& s : chunk)
                if (!s.fromColumn)
                    columnMedia.emplace(packIndexKey(std::llround((s.point.x - xLeft) / latt - 0.5), std::llround((yTop - s.point.y) / latt - 0.5), 0),
                                        std::vector<RaySegment>{});
        std::vector<uint64_t> keys;
        for (const auto& kv : columnMedia) keys.push_back(kv.first);
        std::vector<std::vector<RaySegment>> media(keys.size());
        parallelFor(keys.size(), threads, [&](size_t n) {
            const auto ij = unpackIndexKey(keys[n]);
            const Vec3 top = g.world(g.columnX(static_cast<int>(ij[0])), g.columnY(static_cast<int>(ij[1])), zHigh);
            const int medium0 = mediumAt(scene, top, g.axis);
            media[n] = traceStraightLine(scene, Ray{top, -g.axis}, medium0, 0.0, zHigh - zLow, LineSurfaces::ThroughAll).segments;
        });
        for (size_t n = 0; n < keys.size(); ++n) columnMedia[keys[n]] = std::move(media[n]);
        parallelFor(chunks.size(), threads, [&](size_t c) {
            std::vector<Candidate>& chunk = chunks[c];
            std::vector<Candidate> kept;
            kept.reserve(chunk.size());
            for (Candidate& s : chunk) {
                if (s.fromColumn) {
                    kept.push_back(std::move(s));
                    continue;
                }
                const auto it = columnMedia.find(packIndexKey(std::llround((s.point.x - xLeft) / latt - 0.5), std::llround((yTop - s.point.y) / latt - 0.5), 0));
                const double t = zHigh - s.point.z;
                for (const RaySegment& seg : it->second)
                    if (t >= seg.t0 && t < seg.t1) {
                        if (seg.medium == s.point.medium) kept.push_back(std::move(s));
                        break;
                    }
            }
            chunk.swap(kept);
        });
    }

    // --- One sorted list: by z, then y, then x (deterministic whatever the thread count), labels
    // resolved to one sorted key list.
    std::vector<LabelKey> allKeys;
    for (const auto& ks : chunkKeys) allKeys.insert(allKeys.end(), ks.begin(), ks.end());
    std::sort(allKeys.begin(), allKeys.end());
    allKeys.erase(std::unique(allKeys.begin(), allKeys.end()), allKeys.end());
    labels_ = allKeys;
    size_t count = 0;
    for (const auto& c : chunks) count += c.size();
    // Sorted on contiguous keys (not through the chunks, whose scattered reads dominated the sort).
    struct Key {
        double z, y, x, volume;
        int32_t medium;
        uint32_t chunk, index;
    };
    std::vector<Key> order;
    order.reserve(count);
    for (size_t c = 0; c < chunks.size(); ++c)
        for (size_t i = 0; i < chunks[c].size(); ++i) {
            const LatticePoint& q = chunks[c][i].point;
            order.push_back({q.z, q.y, q.x, q.volumeMm3, q.medium, static_cast<uint32_t>(c), static_cast<uint32_t>(i)});
        }
    // Two halves sorted on two threads and merged: the same order as one sort (no two points share a key).
    const auto before = [](const Key& a, const Key& b) {
        return std::tie(a.z, a.y, a.x, a.medium, a.volume) < std::tie(b.z, b.y, b.x, b.medium, b.volume);
    };
    const auto middle = order.begin() + static_cast<std::ptrdiff_t>(order.size() / 2);
    parallelFor(2, threads, [&](size_t half) {
        if (half == 0) std::sort(order.begin(), middle, before);
        else std::sort(middle, order.end(), before);
    });
    std::inplace_merge(order.begin(), middle, order.end(), before);
    auto pointOf = [&](const Key& o) -> const Candidate& { return chunks[o.chunk][o.index]; };
    points_.resize(count);
    concentrations_.resize(count * static_cast<size_t>(slots_));
    exact_.resize(count);
    if (withLabels) {
        partStart_.assign(count + 1, 0);
        for (size_t n = 0; n < count; ++n) partStart_[n + 1] = partStart_[n] + static_cast<uint32_t>(pointOf(order[n]).parts.size());
        parts_.resize(partStart_.back());
    }
    constexpr size_t kPointsPerTask = 65536;
    parallelFor((count + kPointsPerTask - 1) / kPointsPerTask, threads, [&](size_t task) {
        for (size_t n = task * kPointsPerTask; n < std::min(count, (task + 1) * kPointsPerTask); ++n) {
            const Candidate& s = pointOf(order[n]);
            points_[n] = s.point;
            for (int k = 0; k < slots_; ++k) concentrations_[n * static_cast<size_t>(slots_) + static_cast<size_t>(k)] = s.c[static_cast<size_t>(k)];
            exact_[n] = s.exact;
            if (!withLabels) continue;
            uint32_t at = partStart_[n];
            for (Part p : s.parts) {
                const LabelKey k = chunkKeys[order[n].chunk][p.key];
                p.key = static_cast<uint32_t>(std::lower_bound(labels_.begin(), labels_.end(), k) - labels_.begin());
                parts_[at++] = p;
            }
        }
    });
    seconds_ = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

std::pair<size_t, size_t> EmissionLattice::zRange(double z0, double z1) const {
    const auto lo = std::lower_bound(points_.begin(), points_.end(), z0, [](const LatticePoint& p, double z) { return p.z < z; });
    const auto hi = std::upper_bound(lo, points_.end(), z1, [](double z, const LatticePoint& p) { return z < p.z; });
    return {static_cast<size_t>(lo - points_.begin()), static_cast<size_t>(hi - points_.begin())};
}

size_t EmissionLattice::memoryBytes() const {
    return points_.size() * sizeof(LatticePoint) + concentrations_.size() * sizeof(float) + exact_.size() + partStart_.size() * sizeof(uint32_t) +
           parts_.size() * sizeof(Part);
}

}  // namespace fluorosim::optics
