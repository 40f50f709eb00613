#pragma once
// Straight lines through a scene, without sampling: the media a line crosses and where it ends, the
// medium at a point, and the transmittance along a line by quadrature. Estimators that compute part
// of the image instead of sampling it (the microscope's unscattered image) use these; the path tracer
// uses the same surface rules, so both see one geometry.
#include <vector>

#include "scene/scene.h"

namespace fluorosim {

// A straight piece [t0, t1] of a ray inside one medium (kNone: no medium).
struct RaySegment {
    double t0, t1;
    int medium;
};

// Which surfaces end a line. Null interfaces (index-matched, no material) never do.
enum class LineSurfaces {
    StopAtAny,         // the first other surface ends the line (a camera ray's first straight segment)
    UntilRefraction,   // a smooth dielectric ends it (where a beam entered the sample); any other surface blocks it
    ThroughAll,        // no surface ends it; interfaces switch the medium (geometry queries)
};
enum class LineEnd { Open, Surface, Refraction, Blocked };

struct StraightLine {
    std::vector<RaySegment> segments;  // in order, every medium crossed (vacuum-like ones included)
    LineEnd end = LineEnd::Open;       // Open: reached tMax (or infinity) without a stopping surface
    double tEnd = 0;                   // where the line ended (tMax when Open)
    SurfaceHit endHit;                 // the surface that ended it (not Open), in the last piece's ray
};

// Walks `ray` from tMin to tMax starting in `medium`. `tMin` > 0 when ray.o lies on a surface the ray
// leaves (the path tracer's convention: rays start on surfaces and skip them with tMin).
StraightLine traceStraightLine(const Scene& scene, const Ray& ray, int medium, double tMin, double tMax, LineSurfaces surfaces);

// A line that bends: straight pieces joined by Snell's law at each smooth dielectric it crosses, each
// crossing weighted by its unpolarised Fresnel transmittance, until it reaches the plane through
// `planePoint` with normal `planeNormal` (the objective's front, for light on its way to the camera).
// Null interfaces switch the medium as in traceStraightLine. Blocked (open = false) by any other surface,
// by total internal reflection, or when a piece does not approach the plane.
struct BentLine {
    struct Piece {
        Ray ray;
        std::vector<RaySegment> segments;
        SurfaceHit crossing;  // the surface it starts on (all pieces but the first)
    };
    std::vector<Piece> pieces;  // the first starts at the given ray's origin
    double fresnel = 1;         // product of the crossings' transmittances
    bool open = false;
    bool bent() const { return pieces.size() > 1; }
};
BentLine traceBentLine(const Scene& scene, const Ray& ray, int medium, const Vec3& planePoint, const Vec3& planeNormal);

// A smooth dielectric interface: where a line bends (a rough one scatters and blocks it).
bool refracts(const Scene& scene, const ShapeInfo& shape);
// Whether any smooth dielectric interface (where lines bend) exists in the scene.
bool hasRefractingSurfaces(const Scene& scene);

// The medium at p, from the nearest interface along `direction` (then the opposite one): its inside or
// outside by the side the ray meets it from. Opaque surfaces that are not interfaces are looked through.
// Where no interface encloses p, the scene's camera medium fills space (as for camera rays that cross
// nothing).
int mediumAt(const Scene& scene, const Vec3& p, const Vec3& direction);

// Transmittance along the segments of `ray` at the wavelengths `wl`, without sampling noise: exact in
// homogeneous media; in grid media each channel's floor exactly and the rest by the midpoint rule at
// steps of at most `stepVoxels` voxels, only over majorant cells where a channel rises above its floor.
// The quadrature error is O(step²) for trilinear fields and vanishes as the step shrinks.
SampledSpectrum quadratureTransmittance(const Scene& scene, const Ray& ray, const std::vector<RaySegment>& segments,
                                        const SampledWavelengths& wl, double stepVoxels = 0.5);
// The same along a bent line's pieces from `firstPiece` on, times the Fresnel transmittance of all its
// crossings (0 when the line is blocked): a camera path that starts below the first crossing samples the
// first piece itself and is weighted by the rest.
SampledSpectrum quadratureTransmittance(const Scene& scene, const BentLine& line, const SampledWavelengths& wl, double stepVoxels = 0.5,
                                        size_t firstPiece = 0);

}  // namespace fluorosim
