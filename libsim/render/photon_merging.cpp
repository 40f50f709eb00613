#include "render/photon_merging.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>

#include "core/errors.h"
#include "core/math.h"
#include "core/memory_cap.h"
#include "core/rng.h"
#include "materials/fresnel.h"
#include "materials/material.h"
#include "render/renderer.h"

namespace fluorosim {
namespace {

// Branches of a chain lighter than this survive Russian roulette with probability weight / kMinBranchWeight
// (and then weigh that much), so a camera sample follows at most about 1 / kMinBranchWeight branches.
constexpr double kMinBranchWeight = 0.01;
// Progressive photon mapping's α: the radius of sample s is r₀ (s + 1)^((α - 1) / 2).
constexpr double kAlpha = 2.0 / 3.0;
// Below this cosine between a segment and its entry surface's normal, its kernel disc lies across the ray.
constexpr double kMinCosDepth = 0.25;
// The part of a kernel disc inside the medium: measured by kInsideRays rays along the disc from its centre, at
// most kInsideDepths depths a half radius apart along the segment, and never taken below kMinInside (a disc
// whose centre hugs an edge). The nearest side's strip (CameraSegments::Inside) is kept only where it is at
// least kMinInside of the disc; closer to the side the kernel is the cut disc, divided by its part inside.
constexpr int kInsideRays = 8;
constexpr int kInsideDepths = 8;
constexpr double kMinInside = 0.25;
// A surface the disc meets counts as the medium's side where its normal is this far from the disc's.
constexpr double kSideCos = 0.7071;
// The entry surface's curvature around a segment's entry point: its depth below the disc's plane, probed by
// kCurvatureProbes rays along the disc's normal at the kernel's radius, at angles π k / kCurvatureProbes (a
// quadratic form is even: the opposite half circle repeats them).
constexpr int kCurvatureProbes = 4;
// The grid has at most this many cells along an axis.
constexpr int kMaxCellsPerAxis = 128;
// Cells are this many times the widest segment's radius: smaller cells hold fewer segments that a vertex
// must test, at more entries per segment (on the vials 1 was 6 % faster than 2, and 0.5 slower than both).
constexpr double kCellsPerRadius = 1.0;

struct Branch {
    Ray ray;
    int medium = kNone;
    double tMin = 0;
    double weight = 1;
    double distance = 0;  // from the camera along the chain
    Vec3 entryNormal;     // of the last surface crossed or left, on the side the ray goes
    uint32_t entryShape = 0;
    int events = 0;
    std::vector<std::pair<int, double>> crossed;  // (medium, length) of the media passed through
    StackEntry entry;  // the connections' partition, as the camera paths track it
};

double extinctionAt(const Medium& m, double lambda) {
    const MediumSample c = m.coefficients(Vec3(0, 0, 0), SampledWavelengths::atLine(lambda, 1.0));
    return c.sigmaA[0] + c.sigmaS[0];
}

// The lowest extinction of a homogeneous medium over the scene's spectral range (at its bins' edges and
// centres): Russian roulette through a medium survives with e^(-σ_low L), a bound on the transmittance there.
double lowestExtinction(const Scene& scene, const Medium& m) {
    double low = std::numeric_limits<double>::infinity();
    const double step = scene.spectral.binWidth / 2;
    for (double l = scene.spectral.lambdaMin; l <= scene.spectral.lambdaMax + 1e-9; l += step)
        low = std::min(low, extinctionAt(m, std::min(l, scene.spectral.lambdaMax)));
    return std::max(0.0, low);
}

// The depth of a segment's entry surface below its disc's plane, as a quadratic form a u² + 2 b u v + c v² of
// the offset (u, v) in the disc's frame, fitted to kCurvatureProbes probes at the kernel's radius (a Fourier
// fit: mean, cos 2φ and sin 2φ), stored as the symmetric matrix of that form in world coordinates. A probe
// that finds no surface within the radius (past an edge of it, as at a vial's top) is taken on the opposite
// side, where an even form has the same depth; if neither finds it, the surface is left flat.
void probeCurvature(const Scene& scene, const Frame& disc, CameraSegment& s) {
    const auto depthAt = [&](double phi) {
        const Vec3 q = s.origin + disc.toWorld(Vec3(std::cos(phi), std::sin(phi), 0)) * s.radius;
        Ray probe{q - s.depthAxis * s.radius, s.depthAxis};
        double travelled = 0;
        for (int hits = 0; hits < 4; ++hits) {
            const auto hit = scene.geometry.intersect(probe, 0, 2 * s.radius - travelled);
            if (!hit) break;
            travelled += hit->t;
            if (hit->shape == s.entryShape) return travelled - s.radius;
            probe = Ray{hit->p + s.depthAxis * hit->epsilon, s.depthAxis};
        }
        return std::numeric_limits<double>::quiet_NaN();
    };
    double m0 = 0, mc = 0, ms = 0;
    for (int k = 0; k < kCurvatureProbes; ++k) {
        const double phi = kPi * k / kCurvatureProbes;
        double h = depthAt(phi);
        if (std::isnan(h)) h = depthAt(phi + kPi);
        if (std::isnan(h)) return;
        const double scaled = h / sqr(s.radius);
        m0 += scaled / kCurvatureProbes;
        mc += 2 * scaled * std::cos(2 * phi) / kCurvatureProbes;
        ms += 2 * scaled * std::sin(2 * phi) / kCurvatureProbes;
    }
    const double a = m0 + mc, b = ms, c = m0 - mc;
    const Vec3 &u = disc.s, &v = disc.t;
    const auto entry = [&](int i, int j) { return a * u[i] * u[j] + b * (u[i] * v[j] + v[i] * u[j]) + c * v[i] * v[j]; };
    s.curvature = {entry(0, 0), entry(1, 1), entry(2, 2), entry(0, 1), entry(0, 2), entry(1, 2)};
}

}  // namespace

CameraSegments::CameraSegments(const Scene& scene, const PathTracer& tracer, uint64_t seed, int sampleBegin, int sampleEnd,
                               ThreadArena& threads)
    : scene_(scene), samples_(sampleEnd - sampleBegin) {
    const Camera& cam = scene.camera;
    const double footprint = 2 * cam.tanHalfFovY / cam.height * scene.render.mergeRadiusPixels;  // radians per pixel, times the setting
    std::vector<double> lowSigma(scene.media.size(), 0.0);
    for (size_t m = 0; m < scene.media.size(); ++m)
        if (scene.media[m].isHomogeneous()) lowSigma[m] = lowestExtinction(scene, scene.media[m]);
    const auto& shells = tracer.shells();

    std::vector<std::vector<CameraSegment>> rowSegments(static_cast<size_t>(cam.height));
    std::vector<std::vector<Crossing>> rowCrossings(static_cast<size_t>(cam.height));
    threads.parallelFor(static_cast<size_t>(cam.height), [&](size_t row) {
        const int y = static_cast<int>(row);
        auto& segs = rowSegments[row];
        auto& cross = rowCrossings[row];
        std::vector<Branch> stack;
        for (int x = 0; x < cam.width; ++x) {
            const uint64_t pixel = static_cast<uint64_t>(y) * static_cast<uint64_t>(cam.width) + static_cast<uint64_t>(x);
            for (int s = sampleBegin; s < sampleEnd; ++s) {
                Rng rng = Rng::forKey(seed, pixel, static_cast<uint64_t>(s) ^ 0x6d65726765000000ULL);
                const double radiusScale = std::pow(s + 1.0, (kAlpha - 1) / 2);
                // A segment or surface point of branch b: its radius, kernel weight, pixel and the media before it.
                auto store = [&](CameraSegment& seg, const Branch& b, double cosDepth) {
                    seg.radius = std::max(footprint * b.distance * radiusScale, 1e-9 * scene.geometry.extent());
                    seg.weight = b.weight / (kPi * sqr(seg.radius) * cosDepth);
                    seg.x = x;
                    seg.y = y;
                    seg.prefixBegin = static_cast<uint32_t>(cross.size());
                    seg.prefixCount = static_cast<uint32_t>(b.crossed.size());
                    for (const auto& [m, l] : b.crossed) cross.push_back({m, l});
                    segs.push_back(seg);
                };
                Branch first;
                first.ray = cameraRay(cam, x, y, rng.uniform(), rng.uniform());
                first.medium = cam.medium;
                first.entry.open = true;
                stack.assign(1, first);
                while (!stack.empty()) {
                    Branch b = stack.back();
                    stack.pop_back();
                    while (true) {
                        const auto hit = scene.geometry.intersect(b.ray, b.tMin, std::numeric_limits<double>::infinity());
                        b.tMin = 0;
                        if (b.medium != kNone && !scene.media[static_cast<size_t>(b.medium)].isVacuumLike()) {
                            const Medium& med = scene.media[static_cast<size_t>(b.medium)];
                            if (!med.isHomogeneous() || !hit) break;  // where the camera paths end their chains too
                            if (!b.entry.inLiquid && b.events >= 1) {
                                CameraSegment seg;
                                seg.origin = b.ray.o;
                                seg.direction = b.ray.d;
                                seg.length = hit->t;
                                seg.cosDepth = dot(b.ray.d, b.entryNormal);
                                seg.depthAxis = b.entryNormal;
                                seg.entryShape = b.entryShape;
                                if (!(seg.cosDepth >= kMinCosDepth)) {
                                    seg.depthAxis = b.ray.d;
                                    seg.cosDepth = 1;
                                    seg.entryShape = kNoEntryShape;
                                }
                                seg.medium = b.medium;
                                store(seg, b, seg.cosDepth);
                            }
                            // On through the medium, by Russian roulette on a bound of its transmittance.
                            const double survive = std::exp(-lowSigma[static_cast<size_t>(b.medium)] * hit->t);
                            if (!(rng.uniform() < survive)) break;
                            b.weight /= survive;
                            b.crossed.emplace_back(b.medium, hit->t);
                        }
                        if (!hit) break;
                        b.distance += hit->t;
                        const ShapeInfo& shape = scene.shapes[hit->shape];
                        const bool entering = dot(b.ray.d, hit->n) < 0;
                        if (shape.material == kNone) {
                            if (!shape.isInterface) break;
                            b.entry.meet(shells, hit->shape, entering, true);
                            b.medium = entering ? shape.insideMedium : shape.outsideMedium;
                            b.entryNormal = entering ? -hit->n : hit->n;
                            b.entryShape = hit->shape;
                            b.ray.o = hit->p;
                            b.tMin = hit->epsilon / std::max(std::abs(dot(hit->n, b.ray.d)), 1e-2);
                            continue;
                        }
                        const Material& mat = *scene.materials[static_cast<size_t>(shape.material)];
                        if (!(shape.isInterface && mat.isSpecular() && mat.isTransmissive())) {
                            // The chain ends on an opaque, non-specular surface: its re-emitted light is the photons'.
                            if (b.events >= 1 && !mat.isSpecular() && !mat.isTransmissive()) {
                                CameraSegment seg;
                                seg.surface = true;
                                seg.origin = hit->p;
                                seg.direction = b.ray.d;
                                seg.normal = shape.isInterface ? hit->n : faceForward(hit->n, -b.ray.d);
                                seg.material = &mat;
                                seg.eta = scene.ior(shape.insideMedium) / scene.ior(shape.outsideMedium);
                                seg.shape = hit->shape;
                                store(seg, b, 1.0);
                            }
                            break;
                        }
                        if (++b.events > kMaxMergedChainEvents) break;
                        const int next = entering ? shape.insideMedium : shape.outsideMedium;
                        const double n1 = scene.ior(b.medium), n2 = scene.ior(next);
                        const Vec3 nFacing = entering ? hit->n : -hit->n;
                        const double cosI = -dot(b.ray.d, nFacing);
                        Vec3 wt;
                        const bool refracts = refract(-b.ray.d, nFacing, n2 / n1, &wt);
                        const double R = refracts ? fresnelDielectric(cosI, n2 / n1) : 1.0;
                        // Radiance crossing into index n2 toward the camera's side scales by (n1 / n2)².
                        Branch t = b;
                        t.weight *= (1 - R) * sqr(n1 / n2);
                        b.weight *= R;
                        auto survives = [&](Branch& c) {
                            if (!(c.weight > 0)) return false;
                            if (c.weight >= kMinBranchWeight) return true;
                            if (rng.uniform() * kMinBranchWeight >= c.weight) return false;
                            c.weight = kMinBranchWeight;
                            return true;
                        };
                        if (refracts && survives(t)) {
                            t.entry.meet(shells, hit->shape, dot(wt, hit->n) < 0, false);
                            t.medium = next;
                            t.entryNormal = -nFacing;
                            t.entryShape = hit->shape;
                            t.ray = Ray{hit->p, wt};
                            t.tMin = hit->epsilon / std::max(std::abs(dot(hit->n, wt)), 1e-2);
                            stack.push_back(t);
                        }
                        if (!survives(b)) break;
                        b.entry.meet(shells, hit->shape, false, false);
                        const Vec3 dir = normalize(b.ray.d + nFacing * (2 * cosI));
                        b.entryNormal = nFacing;
                        b.entryShape = hit->shape;
                        b.ray = Ray{hit->p, dir};
                        b.tMin = hit->epsilon / std::max(std::abs(dot(hit->n, dir)), 1e-2);
                    }
                }
            }
        }
    });
    for (size_t row = 0; row < rowSegments.size(); ++row) {
        const uint32_t offset = static_cast<uint32_t>(crossings_.size());
        for (CameraSegment s : rowSegments[row]) {
            s.prefixBegin += offset;
            segments_.push_back(s);
        }
        crossings_.insert(crossings_.end(), rowCrossings[row].begin(), rowCrossings[row].end());
    }
    if (segments_.empty()) return;

    // The kernel discs' cuts by their media's sides, by rays from each disc's centre along it: the nearest
    // side's symmetric strip, or (close to a side) the cut disc over its part inside, a star-shaped region
    // of area ½∫ min(d(φ), r)² dφ. Consistent either way (both tend to the disc as r shrinks); they take out
    // the loss at a box's or a vial's edges, the strip also its first order in the light's gradient (docs/model.md).
    std::vector<std::array<Inside, kInsideDepths>> cuts(segments_.size());
    constexpr size_t kChunk = 256;
    threads.parallelFor((segments_.size() + kChunk - 1) / kChunk, [&](size_t chunk) {
        for (size_t i = chunk * kChunk; i < std::min(segments_.size(), (chunk + 1) * kChunk); ++i) {
            CameraSegment& s = segments_[i];
            if (s.surface) {
                s.insideCount = 1;
                cuts[i][0] = Inside{1, {0, 0, 0}};
                continue;
            }
            const Frame disc = Frame::fromNormal(s.depthAxis);
            if (s.entryShape != kNoEntryShape) probeCurvature(scene, disc, s);
            s.insideStep = std::max(s.radius / 2, s.length / kInsideDepths);
            s.insideCount = static_cast<uint32_t>(std::min<double>(kInsideDepths, std::floor(s.length / s.insideStep) + 1));
            for (uint32_t j = 0; j < s.insideCount; ++j) {
                // The disc's centre, nudged off the entry surface.
                const Vec3 c = s.origin + s.direction * std::max(j * s.insideStep, 1e-3 * s.radius);
                // Each ray's reach inside, in radii; the nearest side's in-disc normal m and distance d.
                std::array<double, kInsideRays> reach;
                std::array<Vec3, kInsideRays> along;
                double d = 1, cutDisc = 0;
                Vec3 m;
                for (int k = 0; k < kInsideRays; ++k) {
                    const double phi = 2 * kPi * (k + 0.5) / kInsideRays;
                    along[k] = disc.toWorld(Vec3(std::cos(phi), std::sin(phi), 0));
                    // Only the medium's sides cut the disc: where the entry surface itself curves away (a
                    // sphere), the light follows the surface, and the disc's far part is no loss.
                    const auto hit = scene.geometry.intersect(Ray{c, along[k]}, 0, s.radius);
                    const bool side = hit && std::abs(dot(hit->n, s.depthAxis)) < kSideCos;
                    reach[k] = side ? hit->t / s.radius : 1.0;
                    cutDisc += sqr(reach[k]) / kInsideRays;
                    if (!side) continue;
                    Vec3 normal = hit->n - s.depthAxis * dot(hit->n, s.depthAxis);
                    normal = normalize(dot(normal, along[k]) < 0 ? -normal : normal);
                    if (const double dk = reach[k] * dot(along[k], normal); dk < d) d = dk, m = normal;
                }
                Inside& in = cuts[i][j];
                in = Inside{static_cast<float>(std::max(kMinInside, cutDisc)), {0, 0, 0}};
                if (!(d < 1)) continue;
                // The strip |w·m| < d against the disc: its area over π r² in closed form, less what the other
                // rays (a corner's second side), mirrored through the centre, find cut off beyond it.
                double stripRays = 0, symmetricRays = 0;
                for (int k = 0; k < kInsideRays; ++k) {
                    const double edge = std::min(1.0, d / std::max(1e-12, std::abs(dot(along[k], m))));
                    stripRays += sqr(edge);
                    symmetricRays += sqr(std::min({edge, reach[k], reach[(k + kInsideRays / 2) % kInsideRays]}));
                }
                const double symmetric = 2 / kPi * (std::asin(d) + d * std::sqrt(1 - d * d)) * symmetricRays / stripRays;
                if (symmetric < kMinInside) continue;
                const Vec3 cut = m / (d * s.radius);
                in = Inside{static_cast<float>(symmetric), {static_cast<float>(cut.x), static_cast<float>(cut.y), static_cast<float>(cut.z)}};
            }
        }
    });
    for (size_t i = 0; i < segments_.size(); ++i) {
        segments_[i].insideBegin = static_cast<uint32_t>(inside_.size());
        inside_.insert(inside_.end(), cuts[i].begin(), cuts[i].begin() + segments_[i].insideCount);
    }

    reach_.resize(segments_.size());
    for (size_t i = 0; i < segments_.size(); ++i) {
        const CameraSegment& s = segments_[i];
        Reach& r = reach_[i];
        for (int a = 0; a < 3; ++a) {
            r.origin[a] = static_cast<float>(s.origin[a]);
            r.direction[a] = static_cast<float>(s.direction[a]);
            r.axis[a] = static_cast<float>(s.depthAxis[a]);
        }
        r.invCosDepth = static_cast<float>(1 / s.cosDepth);
        r.radius2 = static_cast<float>(sqr(s.radius));
        r.medium = s.surface ? kNone : s.medium;
    }

    // The grid: every segment is entered in every cell within its reach, so a vertex looks in its own cell.
    constexpr double inf = std::numeric_limits<double>::infinity();
    Vec3 lo(inf, inf, inf), hi(-inf, -inf, -inf);
    double maxRadius = 0;
    for (const CameraSegment& s : segments_) {
        const Vec3 end = s.origin + s.direction * s.length;
        for (int a = 0; a < 3; ++a) {
            lo[a] = std::min({lo[a], s.origin[a] - s.radius, end[a] - s.radius});
            hi[a] = std::max({hi[a], s.origin[a] + s.radius, end[a] + s.radius});
        }
        maxRadius = std::max(maxRadius, s.radius);
    }
    const Vec3 extent = hi - lo;
    cell_ = std::max(kCellsPerRadius * maxRadius, std::max({extent.x, extent.y, extent.z}) / kMaxCellsPerAxis);
    lo_ = lo;
    for (int a = 0; a < 3; ++a) dims_[a] = std::max(1, static_cast<int>(std::ceil(extent[a] / cell_)));
    const size_t cells = static_cast<size_t>(dims_[0]) * static_cast<size_t>(dims_[1]) * static_cast<size_t>(dims_[2]);
    // Every point within r of a segment lies within r + h/2 of one of its points spaced h apart.
    std::vector<std::pair<uint32_t, uint32_t>> entries;  // (cell, segment)
    std::vector<uint32_t> mine;
    for (size_t i = 0; i < segments_.size(); ++i) {
        const CameraSegment& s = segments_[i];
        const double h = cell_ / 2, pad = s.radius + h / 2;
        const int steps = static_cast<int>(std::ceil(s.length / h));
        mine.clear();
        for (int j = 0; j <= steps; ++j) {
            const Vec3 q = s.origin + s.direction * std::min(s.length, j * h);
            int a0[3], a1[3];
            for (int a = 0; a < 3; ++a) {
                a0[a] = std::clamp(static_cast<int>(std::floor((q[a] - pad - lo_[a]) / cell_)), 0, dims_[a] - 1);
                a1[a] = std::clamp(static_cast<int>(std::floor((q[a] + pad - lo_[a]) / cell_)), 0, dims_[a] - 1);
            }
            for (int cz = a0[2]; cz <= a1[2]; ++cz)
                for (int cy = a0[1]; cy <= a1[1]; ++cy)
                    for (int cx = a0[0]; cx <= a1[0]; ++cx) mine.push_back(static_cast<uint32_t>((cz * dims_[1] + cy) * dims_[0] + cx));
        }
        std::sort(mine.begin(), mine.end());
        mine.erase(std::unique(mine.begin(), mine.end()), mine.end());
        requireMemory(static_cast<double>(entries.size() + mine.size()) * sizeof(entries[0]) + static_cast<double>(cells) * sizeof(uint32_t),
                      "photon merging's grid of " + std::to_string(segments_.size()) + " camera segments");
        for (uint32_t c : mine) entries.push_back({c, static_cast<uint32_t>(i)});
    }
    cellStart_.assign(cells + 1, 0);
    for (const auto& e : entries) ++cellStart_[e.first + 1];
    for (size_t c = 0; c < cells; ++c) cellStart_[c + 1] += cellStart_[c];
    cellSegments_.resize(entries.size());
    std::vector<uint32_t> fill(cellStart_.begin(), cellStart_.end() - 1);
    for (const auto& e : entries) cellSegments_[fill[e.first]++] = e.second;
}

int CameraSegments::cellOf(const Vec3& p) const {
    if (segments_.empty()) return -1;
    int c[3];
    for (int a = 0; a < 3; ++a) {
        const double u = (p[a] - lo_[a]) / cell_;
        if (!(u >= 0 && u < dims_[a])) return -1;
        c[a] = std::min(dims_[a] - 1, static_cast<int>(u));
    }
    return (c[2] * dims_[1] + c[1]) * dims_[0] + c[0];
}

double CameraSegments::prefixOpticalDepth(const CameraSegment& s, double lambda) const {
    double depth = 0;
    for (uint32_t i = s.prefixBegin; i < s.prefixBegin + s.prefixCount; ++i) depth += extinction(crossings_[i].medium, lambda) * crossings_[i].length;
    return depth;
}

void CameraSegments::gatherOnSurface(const Photon& ph, const SurfaceHit& hit, const Vec3& n, double photonsPerSample, std::vector<FilmSplat>& out,
                                     uint64_t& merges) const {
    const int c = cellOf(hit.p);
    if (c < 0) return;
    const double photonsPerSegment = photonsPerSample * samples_;
    for (uint32_t k = cellStart_[static_cast<size_t>(c)]; k < cellStart_[static_cast<size_t>(c) + 1]; ++k) {
        const CameraSegment& s = segments_[cellSegments_[k]];
        if (!s.surface || s.shape != hit.shape || dot(s.normal, n) < 0.99) continue;
        const Vec3 v = hit.p - s.origin;
        if (dot(v, v) > s.radius * s.radius) continue;
        ++merges;
        const Frame frame = Frame::fromNormal(s.normal);
        const Vec3 wo = frame.toLocal(-s.direction), wi = frame.toLocal(-ph.ray.d);
        if (!(wo.z > 0 && wi.z > 0)) continue;
        const double f = s.material->f(wo, wi, SampledWavelengths::atLine(ph.lambda, 1.0), s.eta, TransportMode::Radiance)[0];
        if (!(f > 0)) continue;
        const double value = ph.weight * f * std::exp(-prefixOpticalDepth(s, ph.lambda)) * s.weight / photonsPerSegment;
        if (value > 0) out.push_back(FilmSplat{s.x, s.y, ph.lambda, value, true});
    }
}

double CameraSegments::extinction(int medium, double lambda) const {
    if (medium == kNone) return 0;
    const Medium& m = scene_.media[static_cast<size_t>(medium)];
    return m.isVacuumLike() ? 0 : extinctionAt(m, lambda);
}

}  // namespace fluorosim
