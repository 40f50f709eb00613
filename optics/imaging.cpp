#include "optics/imaging.h"

#include <cmath>

#include "core/errors.h"
#include "core/math.h"
#include "render/straight_line.h"

namespace fluorosim::optics {

Imaging::Imaging(const ObjectiveOptions& objective, const FocalPlane& focus, const DetectorOptions& detector, int width, int height,
                 std::shared_ptr<const WidefieldPsf> psf)
    : axis_(normalize(focus.towardObjective)), centre_(focus.centreMm), width_(width), height_(height), psf_(std::move(psf)) {
    if (!psf_) throw ConfigError("imaging needs a PSF");
    if (std::abs(psf_->pupil().na - objective.na) > 1e-12)
        throw ConfigError("the PSF's NA " + std::to_string(psf_->pupil().na) + " is not the objective's " + std::to_string(objective.na));
    right_ = focus.right();
    up_ = focus.imageUp();
    frame_ = Frame{right_, up_, axis_};
    pixelMm_ = detector.pixelPitchUm * 1e-3 / objective.magnification;
    cosMax_ = std::cos(psf_->pupil().collectionHalfAngle());
    workingDistanceMm_ = objective.workingDistanceMm;
    sampleEtendue_ = pixelMm_ * pixelMm_ * 1e-6 * coneSolidAngle() * detector.exposureS;
}

Imaging::Local Imaging::local(const Vec3& p) const {
    const Vec3 d = p - centre_;
    return {dot(d, right_), dot(d, up_), dot(d, axis_)};
}

Vec3 Imaging::pixelPoint(int x, int y, double ux, double uy) const {
    return centre_ + right_ * ((x + ux - 0.5 * width_) * pixelMm_) + up_ * ((0.5 * height_ - (y + uy)) * pixelMm_);
}

Vec3 Imaging::displacement(double uRadius, double uAngle, double lambdaNm, double* radiusMm) const {
    const double r = psf_->sampleDisplacementMm(uRadius, lambdaNm), a = 2 * kPi * uAngle;
    *radiusMm = r;
    return (right_ * std::cos(a) + up_ * std::sin(a)) * r;
}

Vec3 Imaging::coneDirection(double cosTheta, double phi) const {
    const double sinT = std::sqrt(std::max(0.0, 1 - cosTheta * cosTheta));
    return frame_.toWorld(Vec3(sinT * std::cos(phi), sinT * std::sin(phi), cosTheta));
}

Ray Imaging::cameraRay(const Vec3& focal, double uCos, double uPhi, double* cosTheta) const {
    const double cosT = 1 - uCos * (1 - cosMax_);
    const Vec3 toObjective = coneDirection(cosT, 2 * kPi * uPhi);
    *cosTheta = cosT;
    return Ray{focal + toObjective * workingDistanceMm_, -toObjective};
}

Imaging::CameraStart Imaging::cameraStart(const Scene& scene, bool bends, const Vec3& focal, double uCos, double uPhi,
                                          const SampledWavelengths& wl) const {
    CameraStart out;
    out.ray = cameraRay(focal, uCos, uPhi, &out.cosTheta);
    out.medium = scene.camera.medium;
    if (!bends) return out;
    // Straight down to the focal point first: most rays meet no refraction on the way.
    if (traceStraightLine(scene, out.ray, out.medium, 0.0, workingDistanceMm_, LineSurfaces::UntilRefraction).end != LineEnd::Refraction) return out;
    const Vec3 w = -out.ray.d;
    const int focalMedium = mediumAt(scene, focal, axis_);
    const BentLine line = collectionLine(scene, focal, focalMedium, w);
    if (!line.bent()) return out;
    const BentLine::Piece& sample = line.pieces.front();
    out.ray = Ray{line.pieces[1].ray.o, -w};
    out.medium = sample.segments.empty() ? focalMedium : sample.segments.back().medium;
    const SurfaceHit& crossing = line.pieces[1].crossing;
    out.tMin = crossing.epsilon / std::max(std::abs(dot(crossing.n, w)), 1e-2);
    out.weight = quadratureTransmittance(scene, line, wl, 0.5, 1);
    return out;
}

BentLine Imaging::collectionLine(const Scene& scene, const Vec3& p, int medium, const Vec3& w) const {
    return traceBentLine(scene, Ray{p, w}, medium, centre_ + axis_ * workingDistanceMm_, axis_);
}

double Imaging::coneSolidAngle() const { return 2 * kPi * (1 - cosMax_); }

SampledSpectrum Imaging::firstVertexWeight(const Vec3& pixelPoint, const Vec3& y, const SampledWavelengths& wl) const {
    const Local a = local(pixelPoint), b = local(y);
    const double rho = std::hypot(a.x - b.x, a.y - b.y);
    SampledSpectrum w;
    for (int j = 0; j < kNumWavelengths; ++j) w[j] = psf_->reweight(rho, b.dz, wl.lambda[j]);
    return w;
}

PupilOptions pupilAt(const Scene& scene, const ObjectiveOptions& objective, const FocalPlane& focus, double emissionNm) {
    objective.validate();
    focus.validate();
    const Vec3 axis = normalize(focus.towardObjective);
    PupilOptions pupil;
    pupil.na = objective.na;
    pupil.immersionIndex = objective.immersionIndex;
    const int sampleMedium = mediumAt(scene, focus.centreMm, axis);
    pupil.sampleIndex = scene.ior(sampleMedium);
    if (!(objective.na < pupil.sampleIndex))
        throw ConfigError("objective na " + std::to_string(objective.na) + " is not below the refractive index " + std::to_string(pupil.sampleIndex) +
                          " of the medium at the focus: the collection cone does not fit in the sample");
    if (pupil.sampleIndex != pupil.immersionIndex) {
        const StraightLine up = traceStraightLine(scene, Ray{focus.centreMm, axis}, sampleMedium, 0.0, objective.workingDistanceMm, LineSurfaces::ThroughAll);
        for (const RaySegment& seg : up.segments)
            if (scene.ior(seg.medium) != pupil.sampleIndex) {
                pupil.depthMm = seg.t0;
                break;
            }
    }
    // Apodisation: the transmittance from the focus to the objective by the angle in the sample (Fresnel
    // at each crossing, attenuation), relative to the axis.
    const Frame frame = Frame::fromNormal(axis);
    const Vec3 objectivePlane = focus.centreMm + axis * objective.workingDistanceMm;
    const double sinMax = objective.na / pupil.sampleIndex;
    const SampledWavelengths wl = SampledWavelengths::atLine(emissionNm, 1.0);
    constexpr int kAngles = 16, kAzimuths = 8;
    std::vector<double> apodization(kAngles, 0.0);
    for (int i = 0; i < kAngles; ++i) {
        const double sinT = sinMax * i / (kAngles - 1), cosT = std::sqrt(1 - sinT * sinT);
        for (int a = 0; a < kAzimuths; ++a) {
            const double phi = 2 * kPi * (a + 0.5) / kAzimuths;
            const Vec3 w = frame.toWorld(Vec3(sinT * std::cos(phi), sinT * std::sin(phi), cosT));
            const BentLine line = traceBentLine(scene, Ray{focus.centreMm, w}, sampleMedium, objectivePlane, axis);
            apodization[static_cast<size_t>(i)] += quadratureTransmittance(scene, line, wl)[0] / kAzimuths;
        }
    }
    if (apodization[0] > 0) {
        const double axial = apodization[0];
        for (double& a : apodization) a = std::clamp(a / axial, 0.0, 1.0);
        pupil.intensityApodization = std::move(apodization);
    }
    return pupil;
}

namespace {

std::shared_ptr<const WidefieldPsf> psfOf(const PupilOptions& pupil, double emissionNm, const PsfTableOptions& table) {
    // Under a mismatch the pupil's phase does not scale with λ: tables at nodes across the emission.
    std::vector<double> nodes;
    if (pupil.sampleIndex != pupil.immersionIndex)
        for (int k = -2; k <= 2; ++k) nodes.push_back(emissionNm + 30.0 * k);
    return std::make_shared<const WidefieldPsf>(pupil, table, nodes);
}

}  // namespace

std::shared_ptr<const WidefieldPsf> makePsf(const Scene& scene, const ObjectiveOptions& objective, const FocalPlane& focus, double emissionNm,
                                            const PsfTableOptions& table) {
    return psfOf(pupilAt(scene, objective, focus, emissionNm), emissionNm, table);
}

std::vector<std::shared_ptr<const WidefieldPsf>> makePlanePsfs(const Scene& scene, const ObjectiveOptions& objective, const FocalPlane& focus,
                                                               const std::vector<double>& planeOffsetsMm, double emissionNm,
                                                               const PsfTableOptions& table) {
    table.validate();
    std::vector<size_t> order(planeOffsetsMm.size());
    for (size_t i = 0; i < order.size(); ++i) order[i] = i;
    std::stable_sort(order.begin(), order.end(), [&](size_t a, size_t b) { return planeOffsetsMm[a] < planeOffsetsMm[b]; });
    std::vector<std::shared_ptr<const WidefieldPsf>> out(planeOffsetsMm.size());
    const Vec3 axis = normalize(focus.towardObjective);
    std::shared_ptr<const WidefieldPsf> current;
    for (size_t i : order) {
        FocalPlane plane = focus;
        plane.centreMm = focus.centreMm + axis * planeOffsetsMm[i];
        const PupilOptions pupil = pupilAt(scene, objective, plane, emissionNm);
        const bool sameSample = current && current->pupil().sampleIndex == pupil.sampleIndex;  // a plane in another medium starts a group
        if (!sameSample || pupilDistance(current->pupil(), pupil, emissionNm) > table.depthTolerance) current = psfOf(pupil, emissionNm, table);
        out[i] = current;
    }
    return out;
}

}  // namespace fluorosim::optics
