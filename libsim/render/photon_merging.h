#pragma once
// Photon merging along camera rays that reach a medium through glass (Integrator::Light): the light a
// camera path would find in a homogeneous medium it sees through a chain of smooth dielectric events
// (reflections off a glass sphere, refraction through a vial's mesh walls), which no connection reaches
// because the chain is not a plain refraction through one stack of spheres. Each pass traces the camera
// rays' chains first, with both Fresnel branches followed (Russian roulette on light ones), and keeps
// the straight segments they cross in such media. The light tracer's photons then gather onto every
// segment that passes within a radius r of one of their vertices (a scattering, or a re-emission): the
// beam radiance estimate of Jarosz et al. 2008, with the exact transmittance along the ray at the photon's
// own wavelength, and a disc kernel of radius r that lies parallel to the surface the segment entered by,
// not across the ray: the light near a boundary varies fast with depth, and a disc across an oblique ray
// would average it over depths, and reach outside the medium where there are no photons. Where the disc
// still reaches past the medium's sides (near an edge of a box or a vial), it keeps the strip along the
// nearest side that is symmetric about its centre, or (closer to the side) it is divided by the part of its
// area inside, both measured by rays along it (a surface curving away from the disc, as a sphere's, is not a
// side: the light follows it). r is the pixel's footprint at the segment times
// RenderSettings::mergeRadiusPixels, reduced with the sample index as in progressive photon mapping
// (r² ∝ s^(α-1), α = 2/3), so the blur it adds vanishes as samples grow. The camera paths leave exactly
// these segments out (PathStart::mergedSegments); docs/model.md, "Photon merging behind glass".
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <vector>

#include "core/parallel.h"
#include "render/light_tracer.h"
#include "render/photon_tracer.h"
#include "scene/scene.h"

namespace fluorosim {

inline constexpr uint32_t kNoEntryShape = 0xffffffffu;

// One straight piece of a camera ray's chain inside a homogeneous, non-vacuum medium, or (surface) the
// opaque, non-specular surface point where a chain ends, whose re-emitted light the photons that land
// there carry (photon mapping on surfaces, fluorescence only).
struct CameraSegment {
    bool surface = false;
    // Surface points: the shape, the normal on the side the chain arrives on, its material and eta.
    uint32_t shape = 0;
    Vec3 normal;
    const Material* material = nullptr;
    double eta = 1;
    Vec3 origin, direction;  // unit direction, away from the camera
    Vec3 depthAxis;          // the kernel disc's normal: the entry surface's, into the medium (or the direction)
    double cosDepth = 1;     // dot(direction, depthAxis)
    // The entry surface (entryShape) curving below the disc's plane: its depth there at an offset w along the
    // disc is wᵀ C w, C symmetric (xx, yy, zz, xy, xz, yz). Depths are measured from it, so the kernel follows
    // the surface: under a convex one a flat disc would reach out of the medium, and read light from nearer
    // the surface than the ray's depth.
    uint32_t entryShape = kNoEntryShape;  // none where the disc lies across the ray
    std::array<double, 6> curvature{};    // zero: flat
    double length = 0;
    double radius = 0;
    double weight = 0;  // the chain's branch weight (with its radiance scaling, (n_camera / n_medium)²) over π r² cosDepth
    int medium = kNone;  // segments
    int32_t x = 0, y = 0;  // the pixel
    uint32_t prefixBegin = 0, prefixCount = 0;  // the media crossed before it (CameraSegments::Crossing)
    // The kernel disc's cut by the medium's sides and the part of it inside the medium, at depths t = 0, step,
    // 2 step, ... along the segment (CameraSegments::inside_), beyond the last the last.
    uint32_t insideBegin = 0, insideCount = 0;
    double insideStep = 1;
};

class CameraSegments {
public:
    // Traces the chains of samples [sampleBegin, sampleEnd) of every pixel (row by row on `threads`) and
    // indexes their segments. `tracer` supplies the stacks of spheres of the connections' partition.
    CameraSegments(const Scene& scene, const PathTracer& tracer, uint64_t seed, int sampleBegin, int sampleEnd, ThreadArena& threads);

    // Adds to `out` the merges of a photon's vertex at p with every segment within reach; `phase(w)` is the
    // vertex's phase function toward w. The pass traces `photonsPerSample` photons for each of its samples,
    // and every one of them merges with every segment of the pass.
    template <class Phase>
    void gather(const Photon& ph, const Vec3& p, Phase&& phase, double photonsPerSample, std::vector<FilmSplat>& out,
                uint64_t& merges) const;

    // A re-emitted photon about to scatter off an opaque surface at hit (n on its side): its merges with
    // the surface points within reach on the same shape, f_BSDF Φ / (π r²) each.
    void gatherOnSurface(const Photon& ph, const SurfaceHit& hit, const Vec3& n, double photonsPerSample, std::vector<FilmSplat>& out,
                         uint64_t& merges) const;

    size_t size() const { return segments_.size(); }

private:
    struct Crossing {
        int medium;
        double length;
    };
    // What a photon's vertex reads first of each candidate segment, in one cache line: the lateral test
    // rejects most of them (single precision: offsets of a kernel's size are far above its rounding).
    struct Reach {
        float origin[3], direction[3], axis[3];
        float invCosDepth, radius2;
        int32_t medium;  // kNone for surface points
    };
    // σt of a homogeneous medium at a wavelength (0 for none or vacuum-like).
    double extinction(int medium, double lambda) const;
    double prefixOpticalDepth(const CameraSegment& s, double lambda) const;
    int cellOf(const Vec3& p) const;

    const Scene& scene_;
    double samples_;  // per pixel in the pass
    std::vector<CameraSegment> segments_;
    std::vector<Reach> reach_;  // one per segment
    std::vector<Crossing> crossings_;
    // Where a side cuts the disc at distance d along its in-disc normal m, the kernel keeps only the strip
    // |w·m| < d, the cut disc's part that is symmetric about its centre: the light's gradient across the disc
    // then averages out, where dividing the cut disc by its part inside would read the light a third of a
    // radius further from the side (the vials' top and bottom rows, lit from above, came out 11 % darker at a
    // radius of 2 pixels than at 1). cut = m / d (zero: no cut); fraction = the kernel's area over π r².
    struct Inside {
        float fraction;
        float cut[3];
    };
    std::vector<Inside> inside_;
    // A uniform grid over the segments' reach: cellStart_[c]..cellStart_[c+1] in cellSegments_.
    Vec3 lo_;
    double cell_ = 1;
    int dims_[3] = {0, 0, 0};
    std::vector<uint32_t> cellStart_, cellSegments_;
};

template <class Phase>
void CameraSegments::gather(const Photon& ph, const Vec3& p, Phase&& phase, double photonsPerSample, std::vector<FilmSplat>& out,
                            uint64_t& merges) const {
    const int c = cellOf(p);
    if (c < 0) return;
    const double photonsPerSegment = photonsPerSample * samples_;
    double sigmaT = -1;
    for (uint32_t k = cellStart_[static_cast<size_t>(c)]; k < cellStart_[static_cast<size_t>(c) + 1]; ++k) {
        const Reach& r = reach_[cellSegments_[k]];
        if (r.medium != ph.medium) continue;
        // The point of the ray at p's depth, and p's offset from it along the disc: v less its part along the
        // ray (oblique to the disc unless cosDepth is 1).
        const Vec3 v(p.x - r.origin[0], p.y - r.origin[1], p.z - r.origin[2]);
        double t = (v.x * r.axis[0] + v.y * r.axis[1] + v.z * r.axis[2]) * r.invCosDepth;
        const Vec3 w(v.x - r.direction[0] * t, v.y - r.direction[1] * t, v.z - r.direction[2] * t);
        if (dot(w, w) > r.radius2) continue;
        const CameraSegment& s = segments_[cellSegments_[k]];
        // Under a curved entry surface, p's depth below the surface at that offset: the kernel is the disc
        // sheared along the ray onto the surface's parallel, still of volume π r² cosDepth per unit t.
        const auto& C = s.curvature;
        t -= (C[0] * w.x * w.x + C[1] * w.y * w.y + C[2] * w.z * w.z + 2 * (C[3] * w.x * w.y + C[4] * w.x * w.z + C[5] * w.y * w.z)) / s.cosDepth;
        if (!(t >= 0 && t <= s.length)) continue;
        const Inside& in = inside_[s.insideBegin + std::min(s.insideCount - 1, static_cast<uint32_t>(t / s.insideStep + 0.5))];
        if (std::abs(w.x * in.cut[0] + w.y * in.cut[1] + w.z * in.cut[2]) > 1) continue;
        ++merges;
        const double f = phase(-s.direction);
        if (!(f > 0)) continue;
        if (sigmaT < 0) sigmaT = ph.sigmaT >= 0 ? ph.sigmaT : extinction(ph.medium, ph.lambda);
        const double opticalDepth = sigmaT * t + prefixOpticalDepth(s, ph.lambda);
        const double value = ph.weight * f * std::exp(-opticalDepth) * s.weight / (photonsPerSegment * in.fraction);
        if (value > 0) out.push_back(FilmSplat{s.x, s.y, ph.lambda, value, ph.fluorescent});
    }
}

}  // namespace fluorosim
