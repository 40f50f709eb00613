#pragma once
// The microscope's one imaging operator: how the objective images the sample onto the camera in one
// plane. Every estimator of a plane images through it, so the computed unscattered image and the
// camera paths estimate one model (docs/optics.md, "Imaging").
//  - Geometry: the focal plane (centre; right, up and the axis toward the objective), object pixels
//    (pitch / magnification; pixel (x, y) row-major from the top, columns along +right), the collection
//    cone (half-angle asin(NA/n) in the sample) and the working distance where camera paths start.
//  - The 3-D diffraction PSF (optics/widefield_psf.h): light leaving a point at lateral offset ρ and
//    axial offset dz from the focal point of a pixel point x lands at x with density h(ρ, dz; λ).
//  - Camera paths: a point uniform in the pixel, displaced by the in-focus PSF at the hero wavelength,
//    a direction uniform over the cone; at the path's first vertex y the weight h/h_geo
//    (WidefieldPsf::reweight) turns the geometric image of y into the PSF's (firstVertexWeight).
#include <cmath>
#include <memory>

#include "optics/microscope.h"
#include "optics/widefield_psf.h"
#include "render/straight_line.h"
#include "spectral/sampled_wavelengths.h"

namespace fluorosim::optics {

class Imaging {
public:
    // `psf` must describe this objective (its NA; the sample's index).
    Imaging(const ObjectiveOptions& objective, const FocalPlane& focus, const DetectorOptions& detector, int width, int height,
            std::shared_ptr<const WidefieldPsf> psf);

    // Coordinates in the plane's frame: x along right and y along up from the field centre (mm), dz along
    // the axis toward the objective from the focal plane.
    struct Local {
        double x = 0, y = 0, dz = 0;
    };
    Local local(const Vec3& p) const;
    Vec3 world(double x, double y, double dz) const { return centre_ + right_ * x + up_ * y + axis_ * dz; }

    int width() const { return width_; }
    int height() const { return height_; }
    double pixelMm() const { return pixelMm_; }
    // x of the left edge of pixel column 0, y of the top edge of row 0 (rows run along -up).
    double leftMm() const { return -0.5 * width_ * pixelMm_; }
    double topMm() const { return 0.5 * height_ * pixelMm_; }

    // A camera sample: a point of pixel (x, y) on the focal plane, its displacement by the in-focus PSF
    // at λ, and the ray that starts at the working distance and crosses the focal plane there from a
    // direction uniform over the cone (*cosTheta: its angle to the axis).
    Vec3 pixelPoint(int x, int y, double ux, double uy) const;
    Vec3 displacement(double uRadius, double uAngle, double lambdaNm, double* radiusMm) const;
    Ray cameraRay(const Vec3& focal, double uCos, double uPhi, double* cosTheta) const;
    // The same ray where the way to the objective bends (`bends`: the scene has refracting surfaces). The
    // direction is uniform over the cone in the medium at the focal point, and the path starts just below
    // the refraction nearest the focal point, in that medium, weighted by the transmittance of the rest of
    // the way (Fresnel at each crossing, attenuation; scattering above the first crossing is left out).
    // Without a refraction on the way it is cameraRay's ray, in the camera's medium, with weight 1.
    struct CameraStart {
        Ray ray;
        int medium = kNone;
        double tMin = 0;  // > 0: the ray starts on the surface it leaves
        SampledSpectrum weight{1.0};
        double cosTheta = 1;
    };
    CameraStart cameraStart(const Scene& scene, bool bends, const Vec3& focal, double uCos, double uPhi, const SampledWavelengths& wl) const;
    // The way from p (in `medium`) along the cone direction w (toward the objective) to the objective's
    // front plane, the working distance above this focal plane: straight in each medium, bent at each
    // refracting surface. A point beyond that plane has no way (open = false).
    BentLine collectionLine(const Scene& scene, const Vec3& p, int medium, const Vec3& w) const;
    // A direction of the cone from its polar cosine and azimuth (toward the objective).
    Vec3 coneDirection(double cosTheta, double phi) const;
    double cosMax() const { return cosMax_; }
    double tanThetaMax() const { return std::sqrt(1 - cosMax_ * cosMax_) / cosMax_; }
    double coneSolidAngle() const;
    double workingDistanceMm() const { return workingDistanceMm_; }
    // Object pixel area (m²) × cone solid angle × exposure: what the mean radiance of a pixel's samples,
    // weighted by cos θ, is multiplied by to give energy on the pixel.
    double sampleEtendue() const { return sampleEtendue_; }

    // The weight of a camera path started at `pixelPoint` (before the displacement) at its first vertex
    // y, per wavelength: reweight(|x − y⊥|, dz(y), λ).
    SampledSpectrum firstVertexWeight(const Vec3& pixelPoint, const Vec3& y, const SampledWavelengths& wl) const;

    const WidefieldPsf& psf() const { return *psf_; }
    const std::shared_ptr<const WidefieldPsf>& sharedPsf() const { return psf_; }
    Vec3 axis() const { return axis_; }
    Vec3 centre() const { return centre_; }

private:
    Vec3 right_, up_, axis_, centre_;
    Frame frame_;
    int width_, height_;
    double pixelMm_, cosMax_, workingDistanceMm_, sampleEtendue_;
    std::shared_ptr<const WidefieldPsf> psf_;
};

// The PSF of an objective focused at `focus` in a scene: the pupil in the medium at the focus (its index;
// with a mismatch to the immersion index, the focus's depth below the nearest change of index toward the
// objective), apodised by the transmittance over the collection cone from the focus, measured at
// `emissionNm` along the camera rays (relative to the axial ray; 16 angles, 8 azimuths).
std::shared_ptr<const WidefieldPsf> makePsf(const Scene& scene, const ObjectiveOptions& objective, const FocalPlane& focus, double emissionNm,
                                            const PsfTableOptions& table);
// The pupil makePsf builds its PSF from.
PupilOptions pupilAt(const Scene& scene, const ObjectiveOptions& objective, const FocalPlane& focus, double emissionNm);

// The PSFs of a stack's planes (`focus` moved by each offset along its axis toward the objective): planes
// share one PSF while their pupils lie within `table.depthTolerance` (pupilDistance, at `emissionNm`) of
// the first plane of their group, in the order of their offsets. Under an index mismatch the focus's depth changes
// the Gibson–Lanni aberration; in any sample the depth changes the apodisation.
std::vector<std::shared_ptr<const WidefieldPsf>> makePlanePsfs(const Scene& scene, const ObjectiveOptions& objective, const FocalPlane& focus,
                                                               const std::vector<double>& planeOffsetsMm, double emissionNm,
                                                               const PsfTableOptions& table);

}  // namespace fluorosim::optics
