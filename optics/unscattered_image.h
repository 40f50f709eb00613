#pragma once
// The unscattered image of a plane, computed, not sampled: the fluorescence that the beams' unscattered
// light excites inside their cores and that reaches the objective without scattering, imaged through the
// 3-D PSF (optics/imaging.h). No random numbers: a pixel's value does not depend on the seed. Camera
// paths leave out exactly this part (UnscatteredModel::covers, through CameraPathImaging), so the two
// add up to the full model (docs/model.md, "The computed image").
//
// For a point y of the region, dye i and beam line l (side s), the expected photoelectrons are
//   e = t Ω V · T̄_cam,i(y) · (1/4π) Σ_{l,s} E_ls(y) T_beam,ls(y) σa,i(λ_l; c_i(y)) λ_l Φ_i · D_i,
//   D_i = ∫ f_i(λ) detection(λ)/λ dλ,
// spread over the pixels by the dye's polychromatic PSF (t exposure, Ω the cone's solid angle, V the
// point's volume, T̄_cam the cone-mean transmittance toward the objective, E the unattenuated
// irradiance, T_beam the transmittance back along the beam to where it entered the sample).
//
// Quadrature, each part with a resolution that its test refines (tests/optics/unscattered_image_test.cpp):
//  - points: a lattice in the plane's frame, `lateralSamples` per object pixel along x and y and
//    `axialStepUm` along the axis (midpoint rule over the trilinear concentrations in grid media); in
//    homogeneous media each segment of a lattice column through the medium by Gauss–Legendre nodes,
//    with columns refined over shapes smaller than a few lattice steps (beads);
//  - transmittances: on a lattice of `transmittanceStepUm`, trilinearly interpolated; the cone mean
//    from `coneRings` × `coneAzimuths` directions (Gauss–Legendre in cos θ, uniform in azimuth), at
//    four wavelengths across the channel's detected band;
//  - PSF: per dye the polychromatic PSF over `spectralNodes` quantiles of its detected emission,
//    integrated over each pixel by n² Gauss–Legendre points (n at least `pixelQuadrature`, and at
//    least 2k + 3 for a PSF band of k = pixel × 2 NA/λ cycles per pixel: a PSF narrower than the
//    pixel is otherwise integrated wrongly by up to ±20 % depending on where the point lies), tabulated at
//    `kernelPhases` sub-pixel positions per axis and at the lattice's axial layers (points between them
//    are split linearly); within a few pixels of each point (beyond the defocus disc) exactly, beyond
//    that on the pixel grid by FFT convolution in axial bins of `farBinUm`, with bilinear deposits.
#include <atomic>
#include <functional>
#include <memory>
#include <unordered_map>
#include <vector>

#include "optics/imaging.h"
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
    void validate() const;              // ConfigError naming the option and value
};

// The computed part's emission as a proposal for camera paths that connect to it after scattering
// (scattered emission): the lattice cells of the plane drawn in proportion to the power they emit into
// the channel, then a point uniform in the cell. Thread-safe once built.
class EmissionPoints {
public:
    struct Sample {
        Vec3 p;
        double pdf = 0;  // per mm³
    };
    bool empty() const { return cdf_.empty(); }
    Sample sample(double uCell, double ux, double uy, double uz) const;
    double pdf(const Vec3& p) const;  // 0 outside the cells

    // Built by computeUnscatteredImage: cells of the lattice (i, j, layer) with their power.
    EmissionPoints(const Imaging& plane, double x0, double yTop, double z0, double lateralMm, double axialMm);
    void add(int64_t i, int64_t j, int64_t layer, double power);
    void finish();

private:
    uint64_t key(int64_t i, int64_t j, int64_t l) const;
    Vec3 right_, up_, axis_, centre_;
    double x0_, yTop_, z0_, lateral_, axial_;
    std::unordered_map<uint64_t, double> power_;
    std::vector<uint64_t> cells_;
    std::vector<double> cdf_;
    double total_ = 0;
};

struct UnscatteredPlane {
    std::vector<double> electrons;  // expected photoelectrons per pixel, row-major from the top
    uint64_t points = 0;            // emission points of the quadrature
    double seconds = 0;
    bool complete = true;           // false when cancelled
    std::shared_ptr<const EmissionPoints> emission;
};

// What the computed image of one channel needs, reused for every plane: the emitting dyes as the channel
// excites and detects them, the region it covers, and the PSF kernels per dye and axial layer (built on
// first use). Thread-safe after construction.
class UnscatteredModel {
public:
    // `lights`: the channel's lights (at any plane: only their lines and cores matter here);
    // `detection(λ)`: photoelectrons per joule at λ (emission path × QE × λ/hc), as the paths weigh
    // radiance; `plane`: any plane of the stack (its imaging geometry and PSF).
    UnscatteredModel(const Scene& scene, const std::vector<Light>& lights, const FluorescencePlan& plan, const Imaging& plane,
                     std::function<double(double)> detection, UnscatteredOptions options = {});
    ~UnscatteredModel();

    // False when no beam line excites an emitting dye (the image is then zero and covers nothing).
    bool active() const;
    // Whether the computed image of `plane` holds the unscattered fluorescence excited at y (a point
    // inside a beam's core): y lies in the region of the lattice.
    bool covers(const Imaging& plane, const Vec3& y) const;
    const UnscatteredOptions& options() const;

    struct Impl;
    const Impl& impl() const { return *impl_; }

private:
    std::unique_ptr<Impl> impl_;
};

// The computed unscattered image of `plane` lit by `lights` (the channel's lights at this plane).
UnscatteredPlane computeUnscatteredImage(const Scene& scene, const std::vector<Light>& lights, const Imaging& plane,
                                         const UnscatteredModel& model, int threads = 0, const std::atomic<bool>* cancel = nullptr);

}  // namespace fluorosim::optics
