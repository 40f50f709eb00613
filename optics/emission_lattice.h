#pragma once
// S of the computed image y = P · diag(g) · S · c (optics/unscattered_image.h): the emission points of a
// z-stack, fixed in the sample, with each point's dye concentrations and, where its medium has a label
// grid, their parts by label. The support is where the scene's dye grids (or homogeneous dyed media)
// can be nonzero near the stack's planes: it depends on where the dye is, never on how much, so a
// label fitted to zero keeps its points and its column.
//
// Points live in the stack frame: x along the focal plane's right, y along its up, z along the axis
// toward the objective, from the reference plane's focal centre (mm). Every plane of the stack shares
// the lateral lattice, and the axial lattice is a divisor of the plane step, so a point sits at the
// same layer position relative to every plane it is near.
//  - Grid media: lattice nodes (a midpoint rule over the trilinear or nearest concentrations), kept where
//    some dye's lookup is nonzero; their medium from the geometry of their column.
//  - Homogeneous dyed media: columns over the shapes that hold them (all columns when a medium is not
//    enclosed), refined over shapes smaller than a few lattice steps (beads); the columns partition the
//    region, each integrating every homogeneous dyed medium along it by Gauss–Legendre nodes.
#include <atomic>
#include <cstdint>
#include <utility>
#include <vector>

#include "optics/channel_dyes.h"
#include "scene/scene.h"

namespace fluorosim::optics {

// Where the lattice lies: the reference plane's frame, the region (the field of view with margins for
// the PSF and defocus), the layers a plane reaches and the planes of the stack.
struct LatticeGeometry {
    Vec3 centre, right, up, axis;  // the reference focal plane
    double pixelMm = 0;
    int lateralSamples = 2;        // lattice columns per pixel along x and y
    double axialMm = 0;            // layer spacing
    int width = 0, height = 0;     // the camera's field, in pixels
    int marginPixels = 0;          // around it
    int planeLayers = 2;           // layers one plane reaches (even): dz in ±planeLayers/2 × axialMm
    std::vector<double> planeOffsetsMm;  // each plane's focal plane along the axis from the reference

    int regionWidth() const { return width + 2 * marginPixels; }
    int regionHeight() const { return height + 2 * marginPixels; }
    double lateralMm() const { return pixelMm / lateralSamples; }
    double xLeft() const { return -0.5 * regionWidth() * pixelMm; }
    double yTop() const { return 0.5 * regionHeight() * pixelMm; }
    int columnsX() const { return regionWidth() * lateralSamples; }
    int columnsY() const { return regionHeight() * lateralSamples; }
    double columnX(int i) const { return xLeft() + (i + 0.5) * lateralMm(); }
    double columnY(int j) const { return yTop() - (j + 0.5) * lateralMm(); }
    double halfDepthMm() const { return 0.5 * planeLayers * axialMm; }
    // The stack's layers: k = 0 .. stackLayers() - 1 at z = zLow() + (k + 0.5) axialMm.
    double zLow() const;
    int stackLayers() const;
    double layerZ(int k) const { return zLow() + (k + 0.5) * axialMm; }
    // Whether some plane reaches z (|z − offset| <= halfDepth).
    bool reached(double z) const;
    // A point's continuous layer position relative to a plane: layer l of the plane sits at
    // dz = (l − planeLayers/2 + 0.5) axialMm.
    double layerPosition(double z, double planeOffsetMm) const { return (z - planeOffsetMm + halfDepthMm()) / axialMm - 0.5; }

    Vec3 world(double x, double y, double z) const { return centre + right * x + up * y + axis * z; }
    struct Local {
        double x, y, z;
    };
    Local local(const Vec3& p) const {
        const Vec3 d = p - centre;
        return {dot(d, right), dot(d, up), dot(d, axis)};
    }
};

// A point of the quadrature: where it is, the volume it stands for, its medium.
struct LatticePoint {
    double x = 0, y = 0, z = 0;  // stack frame, mm
    double volumeMm3 = 0;
    int32_t medium = 0;
};

// What a label stands for: a label value of a medium's label grid (value 0: the medium's dye outside
// every label, or a medium without labels, homogeneous ones included).
struct LabelKey {
    int32_t medium = 0;
    int32_t value = 0;
    friend bool operator==(const LabelKey&, const LabelKey&) = default;
    friend auto operator<=>(const LabelKey&, const LabelKey&) = default;
};

class EmissionLattice {
public:
    // With `labels`, each point's concentrations are split by label (the voxels' labels under the
    // trilinear or nearest stencil). Throws ConfigError when the support would exceed the memory cap.
    EmissionLattice(const Scene& scene, const ChannelDyes& dyes, const LatticeGeometry& geometry, int segmentNodes, bool labels, int threads,
                    const std::atomic<bool>* cancel = nullptr);

    size_t size() const { return points_.size(); }
    const LatticePoint& point(size_t p) const { return points_[p]; }
    int slots() const { return slots_; }
    // Concentration (mol/L) of the dye in `slot` of the point's medium.
    float concentration(size_t p, int slot) const { return concentrations_[p * static_cast<size_t>(slots_) + static_cast<size_t>(slot)]; }
    // Whether the point's medium is homogeneous: its transmittances are computed at the point itself.
    bool exact(size_t p) const { return exact_[p] != 0; }

    // Parts by label (with `labels`): the point's concentration of `slot` that label `key` holds.
    struct Part {
        uint32_t key;  // index into labels()
        uint16_t slot;
        float value;   // mol/L
    };
    const Part* partsBegin(size_t p) const { return parts_.data() + partStart_[p]; }
    const Part* partsEnd(size_t p) const { return parts_.data() + partStart_[p + 1]; }
    bool hasParts() const { return !partStart_.empty(); }
    const std::vector<LabelKey>& labels() const { return labels_; }

    // The points are sorted by z: those with z in [z0, z1].
    std::pair<size_t, size_t> zRange(double z0, double z1) const;
    const LatticeGeometry& geometry() const { return geometry_; }
    bool complete() const { return complete_; }
    double seconds() const { return seconds_; }
    size_t memoryBytes() const;

private:
    LatticeGeometry geometry_;
    int slots_ = 0;
    std::vector<LatticePoint> points_;
    std::vector<float> concentrations_;
    std::vector<uint8_t> exact_;
    std::vector<uint32_t> partStart_;
    std::vector<Part> parts_;
    std::vector<LabelKey> labels_;
    bool complete_ = true;
    double seconds_ = 0;
};

}  // namespace fluorosim::optics
