#pragma once
// P of the computed image y = P · diag(g) · S · c (optics/unscattered_image.h), and its adjoint: the
// projection of point emissions through each dye's polychromatic 3-D PSF onto the camera's pixels.
//  - Near part: kernels of the PSF integrated over each pixel by n² Gauss–Legendre points (n at least
//    `pixelQuadrature`, and at least 2k + 3 for a PSF band of k = pixel × 2 NA/λ cycles per pixel),
//    tabulated per dye at the lattice's axial layers and at `kernelPhases` sub-pixel positions per axis;
//    a point between layers or phases is split linearly. They reach a few pixels beyond the defocus disc
//    and hand over to the far part over a taper.
//  - Far part: the rest of the PSF on the pixel grid by FFT convolution in axial bins of `farBinUm`, with
//    bilinear deposits at pixel centres; each dye's own polychromatic PSF per bin.
//  - Tail: the light beyond the PSF table's cut (v > vCut; 0.42 % in focus), with its exact mass per
//    plane 1 − enclosed(dz) (Parseval) and the diffraction tail's 1/v³ profile, by FFT convolution on
//    blocks of `tailBlockPixels`, bilinear both ways, out to the whole region: light from the region's
//    points reaches every camera pixel, and only the tail of dye beyond the region's margin is left out.
// The adjoint gathers what the forward scatters (kernels) and correlates where it convolves (far part),
// so ⟨P e, y⟩ = ⟨e, Pᵀ y⟩ to round-off (tests/optics/imaging_operator_test.cpp).
#include <atomic>
#include <memory>
#include <vector>

#include "optics/channel_dyes.h"
#include "optics/widefield_psf.h"

namespace fluorosim::optics {

struct ProjectorOptions {
    int pixelQuadrature = 3;
    int kernelPhases = 8;   // a multiple of 2 × lateral samples, so lattice points fall on phases
    double farBinUm = 2;
    int nearPixels = 2;     // the exact part of each kernel reaches this far beyond the defocus disc
    int nearTaperPixels = 3;  // over which it hands over to the far part
    int tailBlockPixels = 8;  // the tail's grid (0: the tail is left out)
};

// Where a point's emission lands for one plane: its place in the region image (pixel units, x right from
// the region's left edge, y down from its top), its continuous layer position, the photoelectrons it
// sends and through which dye's PSF, and which output image receives it.
struct PointEmission {
    double u = 0, v = 0, layer = 0;
    double e = 0;
    uint32_t dye = 0;
    uint32_t target = 0;
};

struct ProjectorGeometry {
    double pixelMm = 0;
    int width = 0, height = 0, marginPixels = 0;  // the camera field and the region's margins, pixels
    int layers = 2;                               // a plane's layers
    double axialMm = 0;
    double tanThetaMax = 0;                       // the collection cone in the sample
};

// What project() adds up: everything, all but the PSF's tail beyond its cut (sparse images: a fit's
// columns), or the tail alone.
enum class ProjectorParts { All, WithoutTail, TailOnly };

class PsfProjector {
public:
    PsfProjector(const ChannelDyes& dyes, std::shared_ptr<const WidefieldPsf> psf, const ProjectorGeometry& geometry, int pixelNodes,
                 const ProjectorOptions& options);
    ~PsfProjector();

    // Σ over emissions of their images, per target (0 .. targets − 1): camera images, row-major from the
    // top. Each pixel sums its emissions in one fixed order, whatever the thread count. `emissions` need
    // not be sorted. Empty result when cancelled.
    std::vector<std::vector<double>> project(const std::vector<PointEmission>& emissions, int targets, int threads,
                                             const std::atomic<bool>* cancel = nullptr, ProjectorParts parts = ProjectorParts::All) const;
    // The adjoint: for each emission, Σ_pixels image(pixel) × the photoelectrons a unit emission (e = 1)
    // sends there. `image` is a camera image.
    std::vector<double> backProject(const std::vector<double>& image, const std::vector<PointEmission>& emissions, int threads) const;

    const ProjectorGeometry& geometry() const;
    int reachPixels() const;  // the widest near kernel
    double kernelSeconds() const;  // spent building kernels so far

    struct Impl;

private:
    std::unique_ptr<Impl> impl_;
};

}  // namespace fluorosim::optics
