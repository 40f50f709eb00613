#include "optics/dye_cells.h"

#include <algorithm>
#include <cmath>
#include <unordered_map>

#include "core/parallel.h"
#include "optics/index_key.h"
#include "render/straight_line.h"
#include "volume/volume_fields.h"

namespace fluorosim::optics {

DyeCells::DyeCells(const Scene& scene, const PathTracer& tracer, const BeamExcitationField& field, const std::vector<double>& lines,
                   const std::function<double(double)>& detection, const Imaging& imaging, int threads)
    : scene_(scene) {
    std::vector<Cell> cells;
    std::vector<Vec3> centres;
    std::vector<size_t> blockOf;
    // Per block, the transmittance back along each beam line side from its centre (by quadrature: no
    // noise, so that no block's cells are drawn far below their light).
    std::vector<std::vector<double>> blockTransmittance;
    std::vector<std::pair<const BeamProfile*, std::pair<double, int>>> sides;  // (profile, (line, side)) with the line's power
    std::vector<double> sidePower;
    for (const Light& light : tracer.lights())
        if (const BeamLight* beam = std::get_if<BeamLight>(&light))
            for (const SpectralLine& l : beam->profile->spectrum().spectralLines())
                if (l.power > 0 && std::find(lines.begin(), lines.end(), l.lambdaNm) != lines.end())
                    for (int side = 0; side < beam->profile->sides(); ++side) {
                        sides.push_back({beam->profile.get(), {l.lambdaNm, side}});
                        sidePower.push_back(l.power);
                    }
    for (size_t m = 0; m < scene.media.size(); ++m) {
        const Medium& med = scene.media[m];
        const VolumeFields* volume = med.volume();
        if (!volume || med.dyes().empty()) continue;
        // Only media whose every dye lies in grids (no floor): the cells then hold all of it.
        bool gridded = true;
        for (size_t d = 0; d < med.dyes().size(); ++d) {
            const int c = kFirstDyeChannel + static_cast<int>(d);
            gridded = gridded && volume->channel(c).grid && volume->channel(c).offset == 0 && med.channelFloor()[static_cast<size_t>(c)] == 0;
        }
        if (!gridded) continue;
        if (media_.size() <= m) media_.resize(scene.media.size(), false);
        media_[m] = true;
        // Each dye's detected emission per mol/L over the lines (the cells weigh their dye by it, so that a
        // dye this channel hardly sees draws few photons).
        std::vector<double> detected(med.dyes().size(), 0.0);
        for (size_t d = 0; d < med.dyes().size(); ++d) {
            ChannelValues unit{};
            unit[static_cast<size_t>(kFirstDyeChannel) + d] = 1.0;
            for (double l : lines)
                for (double lambda = scene.spectral.lambdaMin + 0.5; lambda < scene.spectral.lambdaMax; lambda += 1)
                    detected[d] += tracer.fluorescence().kernel(static_cast<int>(m), unit.data(), l, lambda) * std::max(0.0, detection(lambda));
        }
        // Blocks of 8³ voxels that hold dye, and the ones before them on each axis: a cell [v, v + 1) is
        // visited from the block of v.
        std::unordered_map<uint64_t, bool> blocks;
        for (size_t d = 0; d < med.dyes().size(); ++d)
            volume->channel(kFirstDyeChannel + static_cast<int>(d)).grid->forEachBlock([&](const IndexBox& box, double maxValue) {
                if (!(maxValue > 0)) return;
                for (int64_t bz = (box.lo[2] >> 3) - 1; bz <= box.hi[2] >> 3; ++bz)
                    for (int64_t by = (box.lo[1] >> 3) - 1; by <= box.hi[1] >> 3; ++by)
                        for (int64_t bx = (box.lo[0] >> 3) - 1; bx <= box.hi[0] >> 3; ++bx) blocks[packIndexKey(bx, by, bz)] = true;
            });
        const double cellMm3 = std::abs(volume->worldFromIndex().determinant());
        std::vector<uint64_t> keys;
        for (const auto& [key, unused] : blocks) keys.push_back(key);
        std::sort(keys.begin(), keys.end());  // the same cells in the same order whatever the grid's block order
        std::vector<std::array<int64_t, 3>> inBox;
        for (uint64_t key : keys) {
            const std::array<int64_t, 3> b = unpackIndexKey(key);
            bool reached = false;
            for (int a = 0; a < 8 && !reached; ++a)
                reached = field.contains(volume->worldFromIndex().apply(
                    Vec3(8.0 * b[0] + ((a & 1) ? 8.0 : 0.0), 8.0 * b[1] + (((a >> 1) & 1) ? 8.0 : 0.0), 8.0 * b[2] + (((a >> 2) & 1) ? 8.0 : 0.0))));
            if (reached) inBox.push_back(b);
        }
        // Each block's transmittances and cells on its own (in parallel), then in the keys' order.
        struct BlockCells {
            std::vector<double> T;
            std::vector<Cell> cells;
            std::vector<Vec3> centres;
        };
        std::vector<BlockCells> perBlock(inBox.size());
        parallelFor(inBox.size(), threads, [&](size_t n) {
            const std::array<int64_t, 3>& b = inBox[n];
            BlockCells& out = perBlock[n];
            // The voxels [8b, 8b + 8] on each axis: the corners of the block's cells.
            IndexBox range;
            for (int a = 0; a < 3; ++a) {
                range.lo[static_cast<size_t>(a)] = static_cast<int32_t>(8 * b[static_cast<size_t>(a)]);
                range.hi[static_cast<size_t>(a)] = static_cast<int32_t>(8 * b[static_cast<size_t>(a)] + 8);
            }
            // The beams' attenuation at the block's centre: the sheet's profile is evaluated per cell, its
            // attenuation varies on the block's scale.
            const Vec3 blockCentre = volume->worldFromIndex().apply(Vec3(8.0 * b[0] + 4, 8.0 * b[1] + 4, 8.0 * b[2] + 4));
            out.T.assign(sides.size(), 0.0);
            for (size_t k = 0; k < sides.size(); ++k) {
                const Ray back{blockCentre, -sides[k].first->direction(sides[k].second.second)};
                const StraightLine line = traceStraightLine(scene, back, static_cast<int>(m), 0.0, std::numeric_limits<double>::infinity(),
                                                            LineSurfaces::UntilRefraction);
                out.T[k] = quadratureTransmittance(scene, back, line.segments, SampledWavelengths::atLine(sides[k].second.first, 1.0))[0];
            }
            std::vector<std::vector<float>> voxels(med.dyes().size(), std::vector<float>(729, 0.0f));
            for (size_t d = 0; d < med.dyes().size(); ++d) {
                const VolumeChannel& ch = volume->channel(kFirstDyeChannel + static_cast<int>(d));
                ch.grid->copyVoxels(range, voxels[d].data());
                for (float& v : voxels[d]) v = static_cast<float>(ch.scale * v);
            }
            for (int k = 0; k < 8; ++k)
                for (int j = 0; j < 8; ++j)
                    for (int i = 0; i < 8; ++i) {
                        // Σ over dyes of the largest corner's concentration times its detected emission.
                        double c = 0;
                        for (size_t d = 0; d < voxels.size(); ++d) {
                            float most = 0;
                            for (int a = 0; a < 8; ++a)
                                most = std::max(most, voxels[d][static_cast<size_t>(((k + ((a >> 2) & 1)) * 9 + j + ((a >> 1) & 1)) * 9 + i + (a & 1))]);
                            c += most * detected[d];
                        }
                        if (!(c > 0)) continue;
                        out.cells.push_back({static_cast<int>(m), {8 * b[0] + i, 8 * b[1] + j, 8 * b[2] + k}, c, cellMm3});
                        out.centres.push_back(volume->worldFromIndex().apply(Vec3(8.0 * b[0] + i + 0.5, 8.0 * b[1] + j + 0.5, 8.0 * b[2] + k + 0.5)));
                    }
        });
        for (BlockCells& block : perBlock) {
            if (block.cells.empty()) continue;
            blockTransmittance.push_back(std::move(block.T));
            cells.insert(cells.end(), block.cells.begin(), block.cells.end());
            centres.insert(centres.end(), block.centres.begin(), block.centres.end());
            blockOf.insert(blockOf.end(), block.cells.size(), blockTransmittance.size() - 1);
        }
    }
    if (cells.empty()) return;
    std::vector<double> phi(cells.size(), 0.0);
    constexpr size_t kChunk = 4096;
    parallelFor((cells.size() + kChunk - 1) / kChunk, threads, [&](size_t chunk) {
        for (size_t i = chunk * kChunk; i < std::min(cells.size(), (chunk + 1) * kChunk); ++i) {
            // The sheets' light at the cell, attenuated as at its block's centre.
            const std::vector<double>& T = blockTransmittance[blockOf[i]];
            for (size_t k = 0; k < sides.size(); ++k)
                phi[i] += kInv4Pi * sides[k].first->irradiance(centres[i], sides[k].second.second, sides[k].second.first) * 1e6 * sidePower[k] * T[k];
            for (double l : lines) phi[i] += field.scatteredMeanRadiance(centres[i], l, 1.0, 1.0).value_or(0.0);
        }
    });
    double meanPhi = 0;
    for (size_t i = 0; i < cells.size(); ++i) meanPhi += phi[i] / static_cast<double>(cells.size());
    if (!(meanPhi > 0)) return;
    // Cells beyond the field of view draw fewer photons, fewer the farther out (1 / (1 + d / kReachMm)):
    // what they send reaches the image only by scattering, the more seldom the farther.
    constexpr double kReachMm = 0.02;
    const double halfWidth = 0.5 * imaging.width() * imaging.pixelMm(), halfHeight = 0.5 * imaging.height() * imaging.pixelMm();
    for (size_t i = 0; i < cells.size(); ++i) {
        const Imaging::Local q = imaging.local(centres[i]);
        const double beyond = std::hypot(std::max(0.0, std::abs(q.x) - halfWidth), std::max(0.0, std::abs(q.y) - halfHeight));
        cells[i].weight *= (phi[i] + meanPhi) * cells[i].volumeMm3 / (1 + beyond / kReachMm);
        total_ += cells[i].weight;
        cdf_.push_back(total_);
    }
    cells_ = std::move(cells);
}

DyeCells::Sample DyeCells::sample(double uCell, double ux, double uy, double uz) const {
    const size_t n = std::min(cells_.size() - 1, static_cast<size_t>(std::upper_bound(cdf_.begin(), cdf_.end(), uCell * total_) - cdf_.begin()));
    const Cell& c = cells_[n];
    const VolumeFields& volume = *scene_.media[static_cast<size_t>(c.medium)].volume();
    const Vec3 p = volume.worldFromIndex().apply(Vec3(double(c.v[0]) + ux, double(c.v[1]) + uy, double(c.v[2]) + uz));
    return {p, c.medium, c.weight / (total_ * c.volumeMm3)};
}

}  // namespace fluorosim::optics
