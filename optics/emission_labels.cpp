#include "optics/emission_labels.h"

#include <algorithm>
#include <cmath>

namespace fluorosim::optics {

VoxelLabels::VoxelLabels(const Scene& scene, std::vector<LabelKey> keys) : scene_(scene), keys_(std::move(keys)) {}

int VoxelLabels::indexOf(int medium, int32_t value) const {
    for (size_t i = 0; i < keys_.size(); ++i)
        if (keys_[i].medium == medium && keys_[i].value == value) return static_cast<int>(i);
    return -1;
}

int VoxelLabels::split(int medium, const Vec3& p, const double* channels, std::array<LabelledChannels, kMaxLabelsAtPoint>& out) const {
    if (medium < 0 || static_cast<size_t>(medium) >= scene_.media.size()) return 0;
    const Medium& m = scene_.media[static_cast<size_t>(medium)];
    const VolumeFields* v = m.volume();
    int n = 0;
    auto part = [&](int32_t value) -> LabelledChannels* {
        const int key = indexOf(medium, value);
        if (key < 0) return nullptr;
        for (int i = 0; i < n; ++i)
            if (out[static_cast<size_t>(i)].key == static_cast<uint32_t>(key)) return &out[static_cast<size_t>(i)];
        if (n == kMaxLabelsAtPoint) return nullptr;
        LabelledChannels& c = out[static_cast<size_t>(n++)];
        c.key = static_cast<uint32_t>(key);
        c.channels.fill(0.0);
        return &c;
    };
    if (!v || !v->labels()) {
        if (LabelledChannels* c = part(0))
            for (int ch = kFirstDyeChannel; ch < m.channelCount(); ++ch) c->channels[static_cast<size_t>(ch)] = channels[ch];
        return n;
    }
    const Vec3 q = v->indexFromWorld().apply(p);
    std::array<std::array<int, 3>, 8> voxel{};
    std::array<double, 8> w{};
    int stencil = 8;
    if (v->interpolation() == Interpolation::Nearest) {
        stencil = 1;
        voxel[0] = {static_cast<int>(std::floor(q.x + 0.5)), static_cast<int>(std::floor(q.y + 0.5)), static_cast<int>(std::floor(q.z + 0.5))};
        w[0] = 1;
    } else {
        const int i = static_cast<int>(std::floor(q.x)), j = static_cast<int>(std::floor(q.y)), k = static_cast<int>(std::floor(q.z));
        const double fx = q.x - i, fy = q.y - j, fz = q.z - k;
        for (int c = 0; c < 8; ++c) {
            voxel[static_cast<size_t>(c)] = {i + (c & 1), j + ((c >> 1) & 1), k + ((c >> 2) & 1)};
            w[static_cast<size_t>(c)] = ((c & 1) ? fx : 1 - fx) * (((c >> 1) & 1) ? fy : 1 - fy) * (((c >> 2) & 1) ? fz : 1 - fz);
        }
    }
    for (int c = 0; c < stencil; ++c) {
        if (!(w[static_cast<size_t>(c)] > 0)) continue;
        const Vec3 at(voxel[static_cast<size_t>(c)][0], voxel[static_cast<size_t>(c)][1], voxel[static_cast<size_t>(c)][2]);
        const int32_t label = static_cast<int32_t>(v->labels()->value(at, Interpolation::Nearest));
        LabelledChannels* target = nullptr;
        for (int ch = kFirstDyeChannel; ch < m.channelCount(); ++ch) {
            const VolumeChannel& vc = v->channel(ch);
            if (!vc.grid) continue;
            const double value = vc.scale * w[static_cast<size_t>(c)] * vc.grid->value(at, Interpolation::Nearest);
            if (!(value > 0)) continue;
            if (!target) target = part(label);
            if (!target) break;
            target->channels[static_cast<size_t>(ch)] += value;
        }
    }
    // Offsets (floors), and dye channels without a grid, are the medium's label 0.
    for (int ch = kFirstDyeChannel; ch < m.channelCount(); ++ch) {
        const VolumeChannel& vc = v->channel(ch);
        const double floor = vc.grid ? vc.offset : channels[ch];
        if (floor > 0)
            if (LabelledChannels* c = part(0)) c->channels[static_cast<size_t>(ch)] += floor;
    }
    return n;
}

}  // namespace fluorosim::optics
