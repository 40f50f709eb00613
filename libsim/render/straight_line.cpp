#include "render/straight_line.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "materials/fresnel.h"
#include "media/free_flight.h"

namespace fluorosim {

bool refracts(const Scene& scene, const ShapeInfo& s) {
    return s.isInterface && s.material != kNone && scene.materials[static_cast<size_t>(s.material)]->isSpecular();
}

StraightLine traceStraightLine(const Scene& scene, const Ray& ray, int medium, double tMin, double tMax, LineSurfaces surfaces) {
    StraightLine line;
    Ray r = ray;
    double tBase = 0, localTMin = tMin;
    int current = medium;
    // Every crossing advances along the ray; the cap only guards against numerical stalls.
    for (int crossings = 0; crossings < 1000000; ++crossings) {
        const double remaining = tMax - tBase;
        const auto hit = remaining > localTMin ? scene.geometry.intersect(r, localTMin, remaining) : std::nullopt;
        const double t1 = hit ? tBase + hit->t : tMax;
        if (t1 > tBase) line.segments.push_back({tBase, t1, current});
        if (!hit) {
            line.end = LineEnd::Open;
            line.tEnd = tMax;
            return line;
        }
        const ShapeInfo& s = scene.shapes[hit->shape];
        const bool nullInterface = s.isInterface && s.material == kNone;
        if (!nullInterface && surfaces != LineSurfaces::ThroughAll) {
            line.tEnd = t1;
            line.endHit = *hit;
            if (surfaces == LineSurfaces::StopAtAny) {
                line.end = LineEnd::Surface;
            } else {
                line.end = refracts(scene, s) ? LineEnd::Refraction : LineEnd::Blocked;
            }
            return line;
        }
        if (s.isInterface) current = dot(r.d, hit->n) < 0 ? s.insideMedium : s.outsideMedium;
        r.o = hit->p;
        tBase = t1;
        // Rays leave a surface from on it and skip it with tMin, as the path tracer's do.
        localTMin = hit->epsilon / std::max(std::abs(dot(hit->n, r.d)), 1e-2);
    }
    line.end = LineEnd::Blocked;
    line.tEnd = tBase;
    return line;
}

BentLine traceBentLine(const Scene& scene, const Ray& ray, int medium, const Vec3& planePoint, const Vec3& planeNormal) {
    BentLine out;
    Ray r = ray;
    double tMin = 0;
    int current = medium;
    SurfaceHit crossing;
    // Each piece crosses one refracting surface; the cap only guards against a line trapped between two.
    for (int pieces = 0; pieces < 64; ++pieces) {
        const double approach = dot(r.d, planeNormal);
        if (!(approach > 0)) return out;
        const double tPlane = dot(planePoint - r.o, planeNormal) / approach;
        if (!(tPlane > tMin)) {
            // A start beyond the plane is not seen; a crossing on the plane itself is.
            if (out.pieces.empty()) return out;
            out.pieces.push_back({r, {}, crossing});
            out.open = true;
            return out;
        }
        StraightLine line = traceStraightLine(scene, r, current, tMin, tPlane, LineSurfaces::UntilRefraction);
        out.pieces.push_back({r, std::move(line.segments), crossing});
        if (line.end == LineEnd::Open) {
            out.open = true;
            return out;
        }
        if (line.end != LineEnd::Refraction) return out;
        const ShapeInfo& s = scene.shapes[line.endHit.shape];
        const Vec3 n = line.endHit.n;
        const bool entering = dot(r.d, n) < 0;
        const int next = entering ? s.insideMedium : s.outsideMedium, from = entering ? s.outsideMedium : s.insideMedium;
        const double etaCrossed = scene.ior(next) / scene.ior(from);
        Vec3 bent;
        if (!refract(-r.d, n, scene.ior(s.insideMedium) / scene.ior(s.outsideMedium), &bent)) return out;
        out.fresnel *= 1 - fresnelDielectric(std::abs(dot(r.d, n)), etaCrossed);
        crossing = line.endHit;
        r = Ray{line.endHit.p, normalize(bent)};
        tMin = line.endHit.epsilon / std::max(std::abs(dot(n, r.d)), 1e-2);
        current = next;
    }
    return out;
}

bool hasRefractingSurfaces(const Scene& scene) {
    for (const ShapeInfo& s : scene.shapes)
        if (refracts(scene, s)) return true;
    return false;
}

int mediumAt(const Scene& scene, const Vec3& p, const Vec3& direction) {
    for (const Vec3& d : {normalize(direction), -normalize(direction)}) {
        Ray r{p, d};
        double tMin = 0;
        for (int crossings = 0; crossings < 1000; ++crossings) {
            const auto hit = scene.geometry.intersect(r, tMin, std::numeric_limits<double>::infinity());
            if (!hit) break;
            const ShapeInfo& s = scene.shapes[hit->shape];
            if (s.isInterface) return dot(d, hit->n) > 0 ? s.insideMedium : s.outsideMedium;
            r.o = hit->p;
            tMin = hit->epsilon / std::max(std::abs(dot(hit->n, d)), 1e-2);
        }
    }
    return scene.camera.medium;
}

SampledSpectrum quadratureTransmittance(const Scene& scene, const Ray& ray, const std::vector<RaySegment>& segments,
                                        const SampledWavelengths& wl, double stepVoxels) {
    SampledSpectrum opticalDepth(0.0);
    for (const RaySegment& seg : segments) {
        if (seg.medium == kNone) continue;
        const Medium& med = scene.media[static_cast<size_t>(seg.medium)];
        if (med.isVacuumLike() || !(seg.t1 > seg.t0)) continue;
        const MediumSpectra spec = med.spectra(wl);
        const double length = seg.t1 - seg.t0;
        if (!std::isfinite(length)) return SampledSpectrum(0.0);
        const ChannelValues& floor = med.channelFloor();
        const MediumSample base = spec.at(floor.data());
        opticalDepth += (base.sigmaA + base.sigmaS) * length;
        const VolumeFields* volume = med.volume();
        if (!volume) continue;
        const int channels = med.channelCount();
        const double step = stepVoxels * volume->voxelSizeMm();
        VolumeFields::Traversal cells = volume->traverse(ray, seg.t0, seg.t1);
        ChannelValues values{}, residual{};
        while (const auto cell = cells.next()) {
            bool varies = false;
            for (int c = 0; c < channels; ++c) varies = varies || cell->maxValues[c] > floor[c];
            const double cellLength = cell->tMax - cell->tMin;
            if (!varies || !(cellLength > 0)) continue;
            const int n = std::max(1, static_cast<int>(std::ceil(cellLength / step)));
            const double h = cellLength / n;
            for (int i = 0; i < n; ++i) {
                med.channelValues(ray.at(cell->tMin + (i + 0.5) * h), values.data());
                for (int c = 0; c < channels; ++c) residual[c] = std::max(0.0, values[c] - floor[c]);
                const MediumSample s = spec.at(residual.data());
                opticalDepth += (s.sigmaA + s.sigmaS) * h;
            }
        }
    }
    return expNeg(opticalDepth);
}

SampledSpectrum quadratureTransmittance(const Scene& scene, const BentLine& line, const SampledWavelengths& wl, double stepVoxels,
                                        size_t firstPiece) {
    if (!line.open) return SampledSpectrum(0.0);
    SampledSpectrum t(1.0);
    for (size_t i = firstPiece; i < line.pieces.size(); ++i)
        t *= quadratureTransmittance(scene, line.pieces[i].ray, line.pieces[i].segments, wl, stepVoxels);
    return t * line.fresnel;
}

}  // namespace fluorosim
