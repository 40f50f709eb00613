#pragma once
// The unscattered image of a plane, computed, not sampled: the fluorescence that the beams' unscattered
// light excites inside their cores and that reaches the objective without scattering, imaged through the
// 3-D PSF (optics/imaging.h). No random numbers: a pixel's value does not depend on the seed. Camera
// paths leave out exactly this part (UnscatteredModel::covers, through CameraPathImaging), so the two
// add up to the full model (docs/model.md, "The computed image").
//
// It is a linear operator on the concentrations, y = P · diag(g) · S · c, in three pieces that a fit
// reuses (optics/imaging_operator.h):
//  - S (optics/emission_lattice.h): the stack's emission points on a support fixed by where the dye is,
//    their concentrations and their parts by label;
//  - g (optics/emission_gains.h): per point and dye, photoelectrons per mol/L: sheet irradiance,
//    transmittances along the beam and toward the objective, σa per molar, Φ and the detected emission;
//  - P (optics/psf_projector.h): each dye's polychromatic PSF integrated over the pixels, and its adjoint.
// The dyes' own attenuation makes y non-linear in c; g freezes it at the scene's concentrations.
//
// For a point y, dye i and beam line l (side s), the expected photoelectrons are
//   e = t Ω V · T̄_cam,i(y) · (1/4π) Σ_{l,s} E_ls(y) T_beam,ls(y) σa,i(λ_l; c_i(y)) λ_l Φ_i · D_i,
//   D_i = ∫ f_i(λ) detection(λ)/λ dλ.
// A model serves a whole stack: S and the transmittances are built once, and a plane evaluates only its
// sheet's irradiance and the projection (kernels cached across planes).
#include <atomic>
#include <functional>
#include <memory>
#include <vector>

#include "optics/emission_gains.h"
#include "optics/emission_lattice.h"
#include "optics/imaging.h"
#include "optics/psf_projector.h"
#include "render/fluorescence.h"

namespace fluorosim::optics {

struct UnscatteredOptions {
    int lateralSamples = 2;
    double axialStepUm = 0.25;
    int segmentNodes = 2;               // Gauss–Legendre nodes per axial step in homogeneous media
    double transmittanceStepUm = 2;
    double transmittanceQuadratureVoxels = 4;  // midpoint step along rays through grid media, in voxels
    int coneRings = 3, coneAzimuths = 4;
    int spectralNodes = 8;
    int pixelQuadrature = 3;
    int kernelPhases = 8;               // a multiple of 2 × lateralSamples, so lattice points fall on phases
    double farBinUm = 2;
    int nearPixels = 2;                 // the exact part of each kernel reaches this far beyond the defocus disc
    int nearTaperPixels = 3;            // over which it hands over to the far part
    int tailBlockPixels = 8;            // the PSF's tail beyond its cut on blocks of this many pixels (0: left out)
    // Dyes whose photoelectrons per mol/L in the channel fall below this fraction of its most efficient
    // dye's are left out of the computed image (and, covered by it, of the paths' core emission too).
    double dropDyesBelow = 1e-5;
    // The faintest points of a plane, together at most this fraction of the photoelectrons its points send,
    // are left out of its projection (they still feed the scattered emission's proposal). Points far out in
    // the sheet's Gaussian flanks are faint and defocused, so their kernels are the widest.
    double dropPointsBelow = 1e-4;
    // False: every transmittance is 1 (no attenuation by the media or the dyes), the image of a perfect
    // microscope with this objective and sheet (the ground truth, optics/ground_truth.h).
    bool attenuation = true;
    void validate() const;              // ConfigError naming the option and value
};

// The computed part's emission as a proposal for camera paths that connect to it after scattering
// (scattered emission): the lattice cells of the plane drawn in proportion to the power they send to the
// camera, then a point uniform in the cell. Thread-safe once built.
class EmissionPoints {
public:
    struct Sample {
        Vec3 p;
        double pdf = 0;  // per mm³
    };
    bool empty() const { return cdf_.empty(); }
    Sample sample(double uCell, double ux, double uy, double uz) const;
    double pdf(const Vec3& p) const;  // 0 outside the cells

    // Cells of the plane's lattice (i, j, layer) with their power; (x0, yTop, z0) the lattice's corner in
    // the plane's frame.
    EmissionPoints(const Imaging& plane, double x0, double yTop, double z0, double lateralMm, double axialMm);
    void add(int64_t i, int64_t j, int64_t layer, double power);
    void finish();

private:
    uint64_t key(int64_t i, int64_t j, int64_t l) const;
    Vec3 right_, up_, axis_, centre_;
    double x0_, yTop_, z0_, lateral_, axial_;
    std::vector<std::pair<uint64_t, double>> pending_;  // cells and powers as added, before finish()
    std::vector<uint64_t> cells_;                        // sorted
    std::vector<double> power_;                          // of each cell
    std::vector<double> cdf_;
    double total_ = 0;
};

// Where the computed part's time goes (seconds): the stack's pieces once, then each plane.
struct UnscatteredTimings {
    double lattice = 0;        // S: emission points (once per stack)
    double transmittances = 0; // g's transmittances (once per stack)
    double gains = 0;          // this plane's sheet irradiance and gains
    double projection = 0;     // splats and far FFTs, with the kernels built on the way
    double kernelThreadSeconds = 0;  // of the projection: building P's near kernels (cached after), summed over threads
};

struct UnscatteredPlane {
    std::vector<double> electrons;  // expected photoelectrons per pixel, row-major from the top
    uint64_t points = 0;            // emission points lit in this plane
    uint64_t droppedPoints = 0;     // of them, left out of the projection (UnscatteredOptions::dropPointsBelow)
    double droppedFraction = 0;     // their share of the photoelectrons the points send
    double seconds = 0;
    UnscatteredTimings timings;
    bool complete = true;           // false when cancelled
    std::shared_ptr<const EmissionPoints> emission;
    // With an excitation field: the electrons its scattered light excites (part of `electrons`), and per
    // pixel half the difference of the field's two halves summed over the points under it, whose square
    // bounds the variance of that part (the field's noise, correlated across pixels; empty without a field).
    double fieldElectrons = 0;
    std::vector<double> fieldHalfDifference;
};

// What the computed image of one channel needs, for every plane of a stack: the emitting dyes as the
// channel excites and detects them, the lattice's geometry, the PSF projector, and (built on first use)
// S and g. Thread-safe after construction.
class UnscatteredModel {
public:
    // `lights`: the channel's lights at the reference plane (only their lines, directions and cores matter
    // here); `detection(λ)`: photoelectrons per joule at λ (emission path × QE × λ/hc); `reference`: the
    // reference plane's imaging (its geometry and PSF); `planeOffsetsMm`: the stack's planes along the
    // axis from the reference plane (the lattice's axial step divides their spacing when it is uniform);
    // `labels`: split S by label (for fits); `planePsfs`: each plane's PSF, parallel to the offsets (empty:
    // the reference's for every plane; planes sharing a PSF share its projector and kernels).
    UnscatteredModel(const Scene& scene, const std::vector<Light>& lights, const FluorescencePlan& plan, const Imaging& reference,
                     std::function<double(double)> detection, UnscatteredOptions options = {}, std::vector<double> planeOffsetsMm = {0.0},
                     bool labels = false, std::vector<std::shared_ptr<const WidefieldPsf>> planePsfs = {});
    ~UnscatteredModel();

    // False when no beam line excites an emitting dye (the image is then zero and covers nothing).
    bool active() const;
    // Whether the computed image of `plane` holds the unscattered fluorescence excited at y (a point
    // inside a beam's core): y lies in the region of the plane's lattice.
    bool covers(const Imaging& plane, const Vec3& y) const;
    const UnscatteredOptions& options() const;
    const ChannelDyes& dyes() const;
    const LatticeGeometry& geometry() const;
    const PsfProjector& projector(double planeOffsetMm) const;  // the projector of the stack's plane at that offset
    // The plane's offset along the axis from the reference plane; ConfigError unless `plane` is the
    // reference plane moved along the axis to one of the stack's planes.
    double planeOffset(const Imaging& plane) const;

    // S and g for `scene` (the one the model was built for, or the same scene with other concentrations
    // for g), built on first use; nullptr when cancelled. The model keeps them.
    const EmissionLattice* lattice(const Scene& scene, int threads, const std::atomic<bool>* cancel = nullptr) const;
    const EmissionGains* gains(const Scene& scene, int threads, const std::atomic<bool>* cancel = nullptr) const;
    // Gains for other concentrations of the same scene (a fit's frozen attenuation), not kept.
    std::unique_ptr<EmissionGains> gainsFor(const Scene& scene, int threads, const std::atomic<bool>* cancel = nullptr) const;
    const std::vector<Light>& referenceLights() const;

    struct Impl;

private:
    std::unique_ptr<Impl> impl_;
};

// The computed unscattered image of `plane` lit by `lights` (the channel's lights at this plane).
// With `field` (the plane's excitation field for the same lights), the dye its scattered light excites
// in the region too.
UnscatteredPlane computeUnscatteredImage(const Scene& scene, const std::vector<Light>& lights, const Imaging& plane,
                                         const UnscatteredModel& model, int threads = 0, const std::atomic<bool>* cancel = nullptr,
                                         const BeamExcitationField* field = nullptr);

// Where a lattice point lands for the projector in the plane at `planeOffsetMm` (e, dye, target unset).
PointEmission pointEmission(const LatticeGeometry& geometry, const LatticePoint& point, double planeOffsetMm);
// The emissions of a plane for the projector: each lattice point lit in the plane, per dye, with e = its
// gain × its concentration, sent to target 0.
// With `field`, the scattered excitation too; `fieldEmissions`, if given, receives the field's part of them
// (its sum, in `e` of target 0) and half the difference of its halves (target 1).
std::vector<PointEmission> planeEmissions(const UnscatteredModel& model, const EmissionLattice& lattice, const EmissionGains& gains,
                                          const std::vector<Light>& lights, double planeOffsetMm, int threads,
                                          const BeamExcitationField* field = nullptr, std::vector<PointEmission>* fieldEmissions = nullptr);

}  // namespace fluorosim::optics
