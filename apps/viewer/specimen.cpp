#include "viewer/specimen.h"

#include <algorithm>
#include <cmath>
#include <fstream>
#include <map>
#include <sstream>

#include "core/errors.h"
#include "core/parallel.h"
#include "core/units.h"
#include "optics/voxelize_request.h"
#include "scene/scene_field.h"
#include "volume/voxelize.h"

namespace fluorosim::viewer {
namespace fs = std::filesystem;
namespace {

std::string readText(const fs::path& file) {
    std::ifstream in(file, std::ios::binary);
    if (!in) throw IoError(file.string() + ": cannot open the scene file");
    std::ostringstream text;
    text << in.rdbuf();
    return text.str();
}

int channelIndex(std::vector<DyeChannel>& channels, const Fluorophore& dye, const std::string& sceneName) {
    for (size_t i = 0; i < channels.size(); ++i)
        if (channels[i].id == dye.id()) return static_cast<int>(i);
    DyeChannel c;
    c.name = sceneName;
    c.id = dye.id();
    c.dye = &dye;
    channels.push_back(std::move(c));
    return static_cast<int>(channels.size()) - 1;
}

bool axisAligned(const Affine& a) {
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j)
            if (i != j && std::abs(a.m[i][j]) > 1e-9 * std::abs(a.m[i][i])) return false;
    return true;
}

std::vector<fs::path> swcFilesIn(const fs::path& dir) {
    std::vector<fs::path> files;
    std::error_code ec;
    for (const auto& e : fs::directory_iterator(dir.empty() ? fs::path(".") : dir, ec))
        if (e.is_regular_file() && e.path().extension() == ".swc") files.push_back(e.path());
    std::sort(files.begin(), files.end());
    return files;
}

// SWC coordinates are µm in the frame the voxelizer used, which is the volume file's frame.
NeuronModel neuronFromSwc(const Morphology& m, const Affine& worldUmFromSwcUm) {
    NeuronModel n;
    n.source = m.source;
    // A radius is a length: it scales with the transform's mean axis scale.
    const double scale = std::cbrt(std::abs(worldUmFromSwcUm.determinant()));
    for (MorphologyPiece p : morphologyPieces(m)) {
        p.aUm = worldUmFromSwcUm.apply(p.aUm);
        p.bUm = worldUmFromSwcUm.apply(p.bUm);
        p.raUm *= scale;
        p.rbUm *= scale;
        n.pieces.push_back(p);
    }
    return n;
}

// The channel whose grid is brightest along the neuron: the dye it was voxelized with.
int neuronChannel(const Specimen& s, const NeuronModel& n) {
    int best = -1;
    double bestSum = 0;
    for (size_t c = 0; c < s.channels.size(); ++c) {
        const DyeChannel& ch = s.channels[c];
        if (!ch.grid) continue;
        double sum = 0;
        for (const MorphologyPiece& p : n.pieces) sum += ch.grid->value(ch.indexFromWorldUm.apply(p.aUm), Interpolation::Nearest);
        if (sum > bestSum) bestSum = sum, best = static_cast<int>(c);
    }
    return best;
}

}  // namespace

Specimen loadSpecimen(const Scene& scene, const fs::path& sceneFile, const SpecimenOptions& options) {
    Specimen s;
    const Affine umFromMm = Affine::scaling(kUmPerMm);
    // The loaded scene keeps neither file names nor the dyes' names as written: read them again.
    const SceneField json = SceneField::parse(readText(sceneFile), "", sceneFile);
    std::optional<Affine> swcPlacement;  // world µm from SWC µm, for SWCs voxelized into the grid
    fs::path volumeDir, volumeFile;
    std::map<const Medium*, std::vector<int>> mediumChannels;
    for (const Medium& m : scene.media) {
        const VolumeFields* volume = m.volume();
        const SceneField medium = json.at("media").at(m.name());
        std::vector<int>& dyeChannels = mediumChannels[&m];
        for (size_t i = 0; i < m.dyes().size(); ++i)
            dyeChannels.push_back(channelIndex(s.channels, m.dyes()[i].dye, medium.at("dyes").at(i).at("dye").str()));
        if (!volume) continue;
        if (!s.gridMedium.empty()) {
            s.notes.push_back("medium \"" + m.name() + "\": only the grids of medium \"" + s.gridMedium + "\" are shown");
            continue;
        }
        const SceneField volumeField = medium.at("volume");
        const fs::path file = sceneFile.parent_path() / volumeField.at("file").str();
        volumeDir = file.parent_path();
        volumeFile = file;
        s.gridMedium = m.name();
        const SceneField dyes = medium.at("dyes");
        for (size_t i = 0; i < m.dyes().size(); ++i) {
            const SceneField entry = dyes.at(i);
            if (!entry.has("grid")) continue;
            DyeChannel& c = s.channels[static_cast<size_t>(dyeChannels[i])];
            auto grid = std::make_shared<const DensityGrid>(DensityGrid::read(file.string(), entry.at("grid").str()));
            c.units = entry.has("grid_units") ? entry.at("grid_units").str() : grid->metadata().units;
            // The loaded medium holds the grid's index -> world (mm) map the renderer uses.
            c.worldUmFromIndex = volume->worldFromIndex().then(umFromMm);
            c.indexFromWorldUm = c.worldUmFromIndex.inverse();
            if (!swcPlacement) {
                const std::string unit =
                    volumeField.has("length_unit") ? volumeField.at("length_unit").str() : grid->metadata().lengthUnit;
                const double fileUnitMm = unitScale(unit, Dimension::Length).value_or(1.0);
                const Affine worldMmFromFile = grid->worldFromIndex().inverse().then(volume->worldFromIndex());
                swcPlacement = Affine::scaling(1.0 / (kUmPerMm * fileUnitMm)).then(worldMmFromFile).then(umFromMm);
            }
            c.grid = std::move(grid);
        }
    }
    for (size_t shape = 0; shape < scene.shapes.size(); ++shape) {
        const ShapeInfo& info = scene.shapes[shape];
        if (info.insideMedium == kNone) continue;
        const Medium& m = scene.media[static_cast<size_t>(info.insideMedium)];
        if (m.volume() || m.dyes().empty()) continue;
        DyedShape d;
        d.channel = mediumChannels.at(&m).front();
        const auto id = static_cast<uint32_t>(shape);
        d.sphere = scene.geometry.isSphere(id);
        if (d.sphere) {
            d.centreUm = scene.geometry.sphereCenter(id) * kUmPerMm;
            d.radiusUm = scene.geometry.sphereRadius(id) * kUmPerMm;
        } else {
            d.meshUm = scene.geometry.mesh(id);
            for (Vec3& p : d.meshUm.positions) p *= kUmPerMm;
        }
        s.shapes.push_back(std::move(d));
    }
    // Which neurons: the explicit files; else the ones the volume's label grid names (fluorosim voxelize
    // records each neuron's SWC file and placement); else every SWC file beside the volume (or scene).
    std::vector<std::pair<fs::path, Placement>> swc;
    for (const fs::path& f : options.swc) swc.emplace_back(f, Placement{});
    if (swc.empty() && options.findSwc) {
        std::string named;
        if (!volumeFile.empty())
            for (const VdbGridStats& g : readVdbGridStats(volumeFile.string())) {
                if (g.name != "label") continue;
                for (int label = 1; g.stringMetadata.count("label_" + std::to_string(label) + "_swc"); ++label) {
                    const std::string key = "label_" + std::to_string(label);
                    fs::path file = g.stringMetadata.at(key + "_swc");
                    if (!fs::exists(file) && fs::exists(volumeDir / file.filename())) file = volumeDir / file.filename();
                    if (!fs::exists(file)) {
                        s.notes.push_back("neuron " + std::to_string(label) + " of the volume: " + file.string() + " not found, not drawn");
                        continue;
                    }
                    Placement p;
                    if (g.stringMetadata.count(key + "_offset")) p.offsetUm = optics::parseOffsetUm(g.stringMetadata.at(key + "_offset"));
                    if (g.stringMetadata.count(key + "_rotate")) p.rotationsDeg = optics::parseRotations(g.stringMetadata.at(key + "_rotate"));
                    swc.emplace_back(file, p);
                    named += (named.empty() ? "" : ", ") + file.filename().string() + " (label " + std::to_string(label) + ")";
                }
            }
        if (!named.empty()) s.notes.push_back("neurons drawn: the volume's " + named);
        else {
            for (const fs::path& f : swcFilesIn(volumeDir.empty() ? sceneFile.parent_path() : volumeDir)) {
                swc.emplace_back(f, Placement{});
                named += (named.empty() ? "" : ", ") + f.filename().string();
            }
            if (!named.empty())
                s.notes.push_back("neurons drawn: every SWC file beside the volume (" + named +
                                  "; the volume does not name its neurons: voxelize it again, or pass --swc)");
        }
    }
    const Affine placement = swcPlacement.value_or(Affine());  // SWC µm are world µm without a grid
    for (const auto& [f, p] : swc) {
        Morphology m = readSwc(f.string());
        place(m, p);
        NeuronModel n = neuronFromSwc(m, placement);
        n.channel = neuronChannel(s, n);
        s.neurons.push_back(std::move(n));
    }
    return s;
}

VoxelProbe probeVoxel(const Specimen& specimen, const Vec3& worldUm) {
    VoxelProbe p;
    p.values.assign(specimen.channels.size(), 0.0);
    bool indexSet = false;
    for (size_t c = 0; c < specimen.channels.size(); ++c) {
        const DyeChannel& ch = specimen.channels[c];
        if (!ch.grid) continue;
        const Vec3 idx = ch.indexFromWorldUm.apply(worldUm);
        const std::array<int, 3> nearest{static_cast<int>(std::lround(idx.x)), static_cast<int>(std::lround(idx.y)),
                                         static_cast<int>(std::lround(idx.z))};
        if (!indexSet) p.index = nearest, indexSet = true;
        const IndexBox b = ch.grid->bounds();
        bool inside = !b.empty();
        for (int a = 0; a < 3; ++a) inside = inside && nearest[a] >= b.lo[a] && nearest[a] <= b.hi[a];
        p.insideGrid = p.insideGrid || inside;
        p.values[c] = ch.grid->value(Vec3(nearest[0], nearest[1], nearest[2]), Interpolation::Nearest);
    }
    return p;
}

std::optional<DisplayVolume> makeDisplayVolume(const Specimen& specimen, const DisplayVolumeOptions& options) {
    DisplayVolume v;
    IndexBox box;
    const DyeChannel* first = nullptr;
    for (size_t c = 0; c < specimen.channels.size(); ++c) {
        const DyeChannel& ch = specimen.channels[c];
        if (!ch.grid || v.components() >= options.maxComponents) continue;
        if (!first) first = &ch;
        v.channels.push_back(static_cast<int>(c));
        const IndexBox b = ch.grid->bounds();
        if (b.empty()) continue;
        if (box.empty()) box = b;
        for (int a = 0; a < 3; ++a) box.lo[a] = std::min(box.lo[a], b.lo[a]), box.hi[a] = std::max(box.hi[a], b.hi[a]);
    }
    if (!first) return std::nullopt;
    const Affine& w = first->worldUmFromIndex;
    if (!axisAligned(w)) throw ConfigError("grid medium \"" + specimen.gridMedium + "\": the viewer shows only grids whose axes are the world axes");
    if (w.m[0][0] <= 0 || w.m[1][1] <= 0 || w.m[2][2] <= 0)
        throw ConfigError("grid medium \"" + specimen.gridMedium + "\": the viewer needs grids with positive axis scales");
    if (box.empty()) box.lo = box.hi = {0, 0, 0};
    if (options.regionUm) {
        const Vec3 a = first->indexFromWorldUm.apply((*options.regionUm)[0]), b = first->indexFromWorldUm.apply((*options.regionUm)[1]);
        for (int k = 0; k < 3; ++k) {
            box.lo[k] = std::max(box.lo[k], static_cast<int>(std::floor(std::min(a[k], b[k]))));
            box.hi[k] = std::min(box.hi[k], static_cast<int>(std::ceil(std::max(a[k], b[k]))));
        }
        if (box.empty()) throw ConfigError("the region to show holds none of the grid medium's voxels");
    }
    std::array<int64_t, 3> extent{};
    for (int a = 0; a < 3; ++a) extent[a] = int64_t(box.hi[a]) - box.lo[a] + 1;
    int stride = 1;
    auto dimsFor = [&](int s, int a) { return static_cast<int>((extent[a] + s - 1) / s); };
    while (size_t(dimsFor(stride, 0)) * dimsFor(stride, 1) * dimsFor(stride, 2) > options.maxVoxels) ++stride;
    v.stride = stride;
    v.indexLo = box.lo;
    for (int a = 0; a < 3; ++a) {
        v.dims[a] = dimsFor(stride, a);
        v.spacingUm[a] = w.m[a][a] * stride;
    }
    // A display voxel's centre is the centre of the full-resolution voxels it covers.
    const double half = 0.5 * (stride - 1);
    v.originUm = w.apply(Vec3(box.lo[0] + half, box.lo[1] + half, box.lo[2] + half));
    const size_t nc = v.channels.size();
    v.counts.assign(v.voxelCount() * nc, 0);
    v.unitPerCount.assign(nc, 1.0);
    for (size_t c = 0; c < nc; ++c) {
        const DyeChannel& ch = specimen.channels[size_t(v.channels[c])];
        const double maxValue = ch.grid->maxValue();
        if (maxValue > 0) v.unitPerCount[c] = maxValue / 65535.0;
        // Blocks bucketed by display slab, so each slab is written by one thread.
        std::vector<std::vector<IndexBox>> slabs(size_t(v.dims[2]));
        ch.grid->forEachBlock([&](const IndexBox& b, double) {
            IndexBox clipped = b;
            for (int a = 0; a < 3; ++a) clipped.lo[a] = std::max(b.lo[a], box.lo[a]), clipped.hi[a] = std::min(b.hi[a], box.hi[a]);
            if (clipped.empty()) return;
            const int k0 = (clipped.lo[2] - box.lo[2]) / stride, k1 = (clipped.hi[2] - box.lo[2]) / stride;
            for (int k = k0; k <= k1; ++k) slabs[size_t(k)].push_back(clipped);
        });
        parallelFor(slabs.size(), 0, [&](size_t k) {
            const int zLo = box.lo[2] + static_cast<int>(k) * stride, zHi = zLo + stride - 1;
            for (const IndexBox& b : slabs[k])
                for (int z = std::max(b.lo[2], zLo); z <= std::min(b.hi[2], zHi); ++z)
                    for (int y = b.lo[1]; y <= b.hi[1]; ++y)
                        for (int x = b.lo[0]; x <= b.hi[0]; ++x) {
                            const double value = ch.grid->value(Vec3(x, y, z), Interpolation::Nearest);
                            if (value <= 0) continue;
                            const auto q = static_cast<uint16_t>(std::min(65535.0, std::round(value / v.unitPerCount[c])));
                            const size_t i = (x - box.lo[0]) / stride, j = (y - box.lo[1]) / stride;
                            uint16_t& out = v.counts[((k * size_t(v.dims[1]) + j) * size_t(v.dims[0]) + i) * nc + c];
                            out = std::max(out, q);
                        }
        });
    }
    return v;
}

double nonZeroPercentile(const DisplayVolume& volume, int component, double percentile) {
    std::vector<uint64_t> histogram(65536, 0);
    uint64_t total = 0;
    const size_t nc = volume.channels.size();
    for (size_t i = size_t(component); i < volume.counts.size(); i += nc)
        if (volume.counts[i]) ++histogram[volume.counts[i]], ++total;
    if (!total) return 0;
    const auto target = static_cast<uint64_t>(std::ceil(percentile / 100.0 * double(total)));
    uint64_t seen = 0;
    for (size_t q = 1; q < histogram.size(); ++q) {
        seen += histogram[q];
        if (seen >= std::max<uint64_t>(target, 1)) return static_cast<double>(q);
    }
    return 65535;
}

std::optional<std::array<Vec3, 2>> geometryBoundsUm(const Specimen& specimen) {
    std::optional<std::array<Vec3, 2>> b;
    auto add = [&](const Vec3& p, double r) {
        const Vec3 d(r, r, r);
        if (!b) b = std::array<Vec3, 2>{p - d, p + d};
        for (int a = 0; a < 3; ++a) (*b)[0][a] = std::min((*b)[0][a], p[a] - r), (*b)[1][a] = std::max((*b)[1][a], p[a] + r);
    };
    for (const NeuronModel& n : specimen.neurons)
        for (const MorphologyPiece& p : n.pieces) add(p.aUm, p.raUm), add(p.bUm, p.sphere ? p.raUm : p.rbUm);
    for (const DyedShape& d : specimen.shapes) {
        if (d.sphere) add(d.centreUm, d.radiusUm);
        else
            for (const Vec3& p : d.meshUm.positions) add(p, 0);
    }
    return b;
}

}  // namespace fluorosim::viewer
