#pragma once
// The scattered excitation of beams at spectral lines as a field, not as paths (docs/model.md, "The
// excitation field"). Photons leave each beam where its unscattered light first scatters (drawn in
// proportion to σs E T along the beam and across its profile), are traced forward through the scene
// (analog delta tracking, Fresnel at smooth dielectrics) and lay their track length into a fluence grid
// with tent (hat) weights; the grid is read by trilinear interpolation, so its resolution error is O(h²).
// The grid is a box in a frame with anisotropic nodes: fine along `axis` (across a light sheet, where the
// fluence varies on the waist's scale) and coarse along the two others. Two halves of the photons are
// kept apart, so that the field's own noise, which is correlated across the pixels it lights, can be
// estimated from their difference.
//
// The fluence rate φ is in the units of a beam's E in next-event estimation: W/m² per unit of the scene's
// radiance scale, so that (1/4π)(E T + φ) is the mean radiance at the line that excites a dye.
#include <array>
#include <atomic>
#include <cstdint>
#include <optional>
#include <vector>

#include "render/path_tracer.h"
#include "scene/scene.h"

namespace fluorosim {

// A box in a frame: |x| <= halfX along `right`, |y| <= halfY along `up`, |z| <= halfZ along `axis`, from
// `centre` (mm), with node spacings hx, hy, hz (mm). With a far half extent beyond the box's, the field
// also reaches out to |x| <= farHalfX, |y| <= farHalfY, |z| <= farHalfZ on coarser nodes (farHz along the
// axis, farHxy along the others but not finer than hx and hy), where its light only reaches the image after
// scattering or far out of focus.
struct FieldBox {
    Vec3 centre, right{1, 0, 0}, up{0, 1, 0}, axis{0, 0, 1};
    double halfX = 0, halfY = 0, halfZ = 0;
    double hx = 0.004, hy = 0.004, hz = 0.0005;
    double farHalfX = 0, farHalfY = 0, farHalfZ = 0, farHz = 0.004, farHxy = 0.016;
    // With a positive spacing, the light of photons that have scattered kDiffuseAfterScatterings times is
    // tallied apart, over the whole reach on nodes this far apart (mm): it has forgotten where it left the
    // beam, and varies on the scale of the transport length, not the sheet's waist.
    double diffuseH = 0;
    bool contains(const Vec3& p) const;  // the fine box
    bool hasFar() const { return farHalfX > halfX || farHalfY > halfY || farHalfZ > halfZ; }
    FieldBox far() const;     // the far box on the far spacing (itself without one)
    FieldBox diffuse() const;  // the far box (or itself) on the diffuse spacing
    void validate() const;  // ConfigError naming the field and value
};

// Tent tallies on the nodes of a box, one node beyond each face, so that every node a lookup inside the
// box needs has its whole support inside the tallied range.
class FluenceGrid {
public:
    explicit FluenceGrid(const FieldBox& box);
    const FieldBox& box() const { return box_; }
    size_t nodes() const { return values_.size(); }
    // Adds weight × ∫ hat_node along the segment [a, b] (world, mm) to every node, exactly (the hats'
    // product is cubic along a cell's piece: two Gauss–Legendre points).
    void deposit(const Vec3& a, const Vec3& b, double weight);
    // Trilinear interpolation of the node values (0 outside the box).
    double at(const Vec3& p) const;
    // The eight nodes and weights around p (none outside the box), to read several grids of the same box.
    struct Stencil {
        std::array<size_t, 8> node{};
        std::array<double, 8> weight{};
    };
    std::optional<Stencil> stencil(const Vec3& p) const;
    double at(const Stencil& s) const {
        double v = 0;
        for (size_t c = 0; c < 8; ++c) v += s.weight[c] * values_[s.node[c]];
        return v;
    }
    // Turns tallies (weight × mm) into fluence: divided by `photons` and each node's hat volume inside
    // the tallied range.
    void normalise(double photons);
    void add(const FluenceGrid& o);
    void scale(double s);
    std::vector<double>& values() { return values_; }
    const std::vector<double>& values() const { return values_; }
    int nx() const { return n_[0]; }
    int ny() const { return n_[1]; }
    int nz() const { return n_[2]; }

private:
    FieldBox box_;
    std::array<int, 3> n_{};
    std::array<double, 3> origin_{}, h_{};  // node 0's local coordinates and spacings
    std::vector<double> values_;
    size_t index(int i, int j, int k) const { return (static_cast<size_t>(k) * n_[1] + j) * n_[0] + i; }
};

// One side of one spectral line of a beam: what a field is traced for.
struct BeamLineSide {
    const BeamProfile* profile = nullptr;
    double lambdaNm = 0, weight = 0;  // the line's share of the beam's normalised spectrum
    int side = 0;
};
// Every side of every line of the beams among `lights` (none when a light is not a beam).
std::vector<BeamLineSide> beamLineSides(const std::vector<Light>& lights);

// The largest extinction (σa + σs, /mm) of any of the scene's media at λ, at its channels' largest values.
double largestExtinctionAt(const Scene& scene, double lambdaNm);
// Photons that have scattered this many times are diffuse (FieldBox::diffuseH): in uncleared cortex (σs 20 /mm,
// g 0.9) all the light that reaches the field of view 1 mm from where the sheet enters has, at σs 2 /mm 0.1 %.
constexpr int kDiffuseAfterScatterings = 10;

struct FluenceOptions {
    uint64_t photons = 200000;  // per beam line side
    uint64_t seed = 1;
    int threads = 0;
    int maxEvents = 100000;     // per photon: a guard, counted when reached
    void validate() const;
};

struct FluenceStats {
    uint64_t photons = 0, sourced = 0;  // traced, and with a first scattering point of nonzero weight
    uint64_t truncated = 0;             // stopped by maxEvents
    double sourcePowerW = 0;            // ∫ σs E T dV over the beam, per unit of the line's weight × W/m² scale
    double seconds = 0;
    bool complete = true;
};

// The scattered light of one beam line side: φ in each half of the photons (even and odd slots), and
// beyond the fine box, with FieldBox::hasFar, φ on the far box's nodes, also in halves.
struct BeamFluence {
    BeamLineSide line;
    FluenceGrid half[2];
    FluenceGrid mean;  // (half[0] + half[1]) / 2
    FluenceStats stats;
    std::optional<FluenceGrid> far, farHalf[2];
    // With FieldBox::diffuseH, the diffuse photons' φ over the reach, added to the others' everywhere.
    std::optional<FluenceGrid> diffuse, diffuseHalf[2];
    const FieldBox& reach() const { return far ? far->box() : mean.box(); }  // where it is known
    double at(const Vec3& y) const;  // φ at y: the fine grid's inside its box, else the far one's (0 beyond)
    // φ at y and half the difference of the halves' φ there (its noise), from one trilinear stencil per grid.
    struct MeanAndHalfDifference {
        double mean = 0, halfDifference = 0;
    };
    MeanAndHalfDifference withNoiseAt(const Vec3& y) const;
};

// Traces the field of one beam line side over `box`. The photons are split over a fixed number of slots,
// so the field does not depend on the thread count. Throws ConfigError for a beam without a cross-section
// sampler and when the grid exceeds the memory cap.
BeamFluence traceBeamFluence(const Scene& scene, const BeamLineSide& line, const FieldBox& box, const FluenceOptions& options,
                             const std::atomic<bool>* cancel = nullptr);

// Two traces of one line side over the same box pooled as one with all their photons: the mean and each half
// weighted by the photons each trace had.
BeamFluence pooledFluence(const BeamFluence& a, const BeamFluence& b);

// The scattered light of a plane's beams at their lines, as the path tracer looks it up.
class BeamExcitationField final : public ExcitationField {
public:
    explicit BeamExcitationField(std::vector<BeamFluence> fields) : fields_(std::move(fields)) {}
    std::optional<double> scatteredMeanRadiance(const Vec3& y, double lambdaNm, double coreWeight = 1, double outsideWeight = 1) const override;
    // φ of field `i` at y (W/m²) in the fine box (none beyond): its mean, and half the difference of its halves
    // (its noise), from one trilinear stencil per grid.
    using MeanAndHalfDifference = BeamFluence::MeanAndHalfDifference;
    MeanAndHalfDifference scatteredWithNoise(size_t i, const Vec3& y) const;
    // The mean radiance of the scattered light at y at λ, and its half difference, from the fields whose beam's
    // core holds y and from the others apart (as scatteredMeanRadiance with weights 1, 0 and 0, 1), in one
    // look-up of each field; none outside the reach.
    struct CoreAndOutside {
        MeanAndHalfDifference core, outside;
    };
    std::optional<CoreAndOutside> scatteredByCore(const Vec3& y, double lambdaNm) const;
    const std::vector<BeamFluence>& fields() const { return fields_; }
    bool contains(const Vec3& y) const;  // where every field is known (their far boxes, if any)

private:
    std::vector<BeamFluence> fields_;
};

}  // namespace fluorosim
