#pragma once
// Which labelled object's dye re-emits at a point: the path tracer's EmissionLabels over a scene's label
// grids, so that an acquisition tallies its Monte Carlo part (the scattered light) per label in the same
// render, for fits whose parameters are labels. At p, each dye channel's trilinear (or nearest) stencil
// is split by the labels of its voxels; a grid's offset, a medium without labels and a homogeneous
// medium belong to their medium's label 0.
#include <vector>

#include "optics/emission_lattice.h"
#include "render/path_tracer.h"

namespace fluorosim::optics {

class VoxelLabels final : public EmissionLabels {
public:
    // `keys`: the labels to tally, their index the key a tally reports; others stay unattributed.
    VoxelLabels(const Scene& scene, std::vector<LabelKey> keys);
    int split(int medium, const Vec3& p, const double* channels, std::array<LabelledChannels, kMaxLabelsAtPoint>& out) const override;
    const std::vector<LabelKey>& keys() const { return keys_; }

private:
    int indexOf(int medium, int32_t value) const;
    const Scene& scene_;
    std::vector<LabelKey> keys_;
};

}  // namespace fluorosim::optics
