#pragma once
// The computed image of a whole z-stack as a linear operator on fit parameters: y = A θ, with
// A = P · diag(g) · S per channel and plane (optics/unscattered_image.h) and c(x) = Σ_j θ_j φ_j(x):
//  - per label: φ_j is label j's template, the scene's concentrations in its voxels (θ = 1 reproduces
//    the scene); the columns are dense images, one projection each;
//  - coarse grid: φ_j = the template × a trilinear hat function of a grid of cells in the stack frame,
//    over the cells that hold dye; the columns are sparse.
// g is frozen at the concentrations of the scene it was last refreshed with (the dyes' own attenuation
// is the operator's only non-linearity); a fit refreshes it between outer iterations.
// Adjoint: Aᵀ = Sᵀ · diag(g) · Pᵀ, tested by ⟨A θ, y⟩ = ⟨θ, Aᵀ y⟩ (tests/optics/imaging_operator_test.cpp).
#include <atomic>
#include <memory>
#include <string>
#include <vector>

#include "optics/acquisition.h"
#include "optics/unscattered_image.h"

namespace fluorosim::optics {

// One fit parameter.
struct FitParameter {
    std::string name;           // "label 2 (tissue)", "cell (3, 1, 0)"
    LabelKey label;             // per label: which
    bool node = false;          // a grid node (else a label)
    std::array<int, 3> cell{};  // grid: the node's index
    Vec3 centreMm;              // where it is (the label's or node's position in the world)
    double referenceMolar = 0;  // what θ = 1 means: labels, the value most of their voxels share; nodes, the template's peak (reports θ in µM)
};

class ParameterMap {
public:
    // Every label that holds emitting dye in some channel's lattice; `includeUnlabelled` keeps value-0
    // keys (dye outside every label, homogeneous dyed media) as parameters, otherwise they stay fixed.
    static ParameterMap labels(const std::vector<LabelKey>& keys, bool includeUnlabelled);
    // Trilinear nodes of a grid of `cellMm` in the stack frame whose support holds dye of `lattices`.
    static ParameterMap grid(double cellMm, const std::vector<const EmissionLattice*>& lattices);

    bool isGrid() const { return grid_; }
    double cellMm() const { return cellMm_; }
    size_t size() const { return parameters_.size(); }
    const std::vector<FitParameter>& parameters() const { return parameters_; }
    std::vector<FitParameter>& parameters() { return parameters_; }
    // The parameter of label `key` (−1: fixed at the scene's value).
    int parameterOf(const LabelKey& key) const;

    // How point p's concentration of `slot` depends on the parameters: c = fixed + Σ coefficient θ_param.
    struct Entry {
        int parameter;  // −1: the fixed part
        uint16_t slot;
        double coefficient;  // mol/L per unit θ
    };
    void entries(const EmissionLattice& lattice, size_t p, std::vector<Entry>& out) const;
    // The grid's basis at a stack-frame position: nodes and weights (8 at most).
    void basis(double x, double y, double z, std::vector<std::pair<int, double>>& out) const;
    // Σ_j θ_j B_j at a stack-frame position (1 where no node around is a parameter).
    double gridFactor(double x, double y, double z, const std::vector<double>& theta) const;
    // Grid: where parameter j's node lies, in the stack frame the lattices use (mm).
    std::array<double, 3> nodePosition(size_t parameter) const;

private:
    bool grid_ = false;
    double cellMm_ = 0;
    std::array<double, 3> origin_{};
    std::array<int, 3> counts_{};
    std::vector<int> nodeParameter_;  // per grid node, −1 when not a parameter
    std::vector<LabelKey> keys_;      // per label parameter
    std::vector<FitParameter> parameters_;
};

// Sparse columns of A: per parameter, its nonzero pixels of the stack (index into the stack's
// (channel, plane, y, x) pixels) and values, expected photoelectrons per unit θ.
struct SparseColumns {
    std::vector<std::vector<uint32_t>> pixels;
    std::vector<std::vector<double>> values;
};

class StackOperator {
public:
    // The computed image of `channels` (microscope channel indices) over the microscope's stack, with S
    // split by label. Throws ConfigError when no channel computes anything.
    StackOperator(const Scene& scene, const Microscope& microscope, std::vector<size_t> channels, const AcquireOptions& options);
    ~StackOperator();

    int width() const { return width_; }
    int height() const { return height_; }
    int planes() const { return planes_; }
    size_t channelCount() const { return channels_.size(); }
    size_t stackPixels() const { return static_cast<size_t>(width_) * height_ * planes_ * channels_.size(); }
    size_t planeImage(size_t channelSlot, int plane) const { return channelSlot * static_cast<size_t>(planes_) + static_cast<size_t>(plane); }
    // The union of the channels' labels that hold emitting dye.
    std::vector<LabelKey> labels() const;
    std::vector<const EmissionLattice*> lattices() const;
    const UnscatteredModel& model(size_t channelSlot) const;

    // g at `scene`'s concentrations (the same scene, rescaled), and each plane's excitation field traced in
    // it (as the acquisition traces it, with the same streams): the attenuation and scattered excitation the
    // next columns and products freeze. Returns false when cancelled.
    bool refreshGains(const Scene& scene, const std::atomic<bool>* cancel = nullptr);

    // A's columns. Without `withTail` they leave out the PSF's tail beyond its cut: the tail reaches every
    // pixel, so with it every column is dense over its channel (a fit freezes the tail instead: tail()).
    SparseColumns columns(const ParameterMap& map, const std::atomic<bool>* cancel = nullptr, bool withTail = false) const;
    // y = A θ + (the fixed parts' image), over the stack's pixels.
    std::vector<double> apply(const ParameterMap& map, const std::vector<double>& theta, bool withFixed = true) const;
    // The part of apply() that the tail-less columns leave out: the PSF's tail of A θ (and of the fixed parts).
    std::vector<double> tail(const ParameterMap& map, const std::vector<double>& theta, bool withFixed = true) const;
    // Aᵀ y (the fixed parts do not enter).
    std::vector<double> applyAdjoint(const ParameterMap& map, const std::vector<double>& y) const;

    // Where the operator's time went (seconds).
    double gainSeconds() const { return gainSeconds_; }
    double projectionSeconds() const { return projectionSeconds_; }
    int projections() const { return projections_; }  // plane images projected so far (a forward image is planes × channels)

private:
    std::vector<double> applyParts(const ParameterMap& map, const std::vector<double>& theta, bool withFixed, ProjectorParts parts) const;
    struct Channel;
    std::vector<std::unique_ptr<Channel>> channels_;
    const Scene& scene_;
    int width_ = 0, height_ = 0, planes_ = 0;
    std::vector<double> offsets_;
    std::vector<FocalPlane> focalPlanes_;
    AcquireOptions options_;  // the acquisition the operator models (its field options, seed and threads)
    ObjectiveOptions objective_;
    DetectorOptions detector_;
    mutable double gainSeconds_ = 0, projectionSeconds_ = 0;
    mutable int projections_ = 0;
};

// The scene's media rescaled by θ: each label's voxels (or each grid node's share) multiply their dye
// concentrations, homogeneous dyed media scale by their parameter. `original` holds the media the
// template came from; the result replaces scene.media.
std::vector<Medium> scaledMedia(const std::vector<Medium>& original, const ParameterMap& map, const std::vector<double>& theta,
                                const LatticeGeometry& frame);

}  // namespace fluorosim::optics
