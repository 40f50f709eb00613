#include "optics/setup_checks.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>

#include "core/errors.h"
#include "core/message.h"
#include "render/straight_line.h"

namespace fluorosim::optics {
namespace {

constexpr double kUmPerMm = 1000;

std::string num(double v) { return messageNumber(v); }

std::string um(double mm) { return num(mm * kUmPerMm) + " um"; }

bool scatters(const Scene& scene, int medium) {
    if (medium == kNone) return false;
    const Medium& m = scene.media[static_cast<size_t>(medium)];
    for (double l = scene.spectral.lambdaMin; l <= scene.spectral.lambdaMax; l += 10)
        if (m.scatteringAt(l) > 0) return true;
    return false;
}

bool dyed(const Scene& scene, int medium) { return medium != kNone && !scene.media[static_cast<size_t>(medium)].dyes().empty(); }

// Planes as "plane 3" or "planes 3-7", with their offsets from the focus.
std::string planeRange(const Microscope& m, int first, int last) {
    const std::string offsets = first == last ? "at " + um(m.planeOffsetMm(first)) : um(m.planeOffsetMm(first)) + " to " + um(m.planeOffsetMm(last));
    return (first == last ? "plane " + std::to_string(first) : "planes " + std::to_string(first) + "-" + std::to_string(last)) + " (" + offsets +
           " from the focus)";
}

}  // namespace

std::vector<std::string> checkSetup(const Scene& scene, const Microscope& m, const std::vector<size_t>& channels) {
    std::vector<std::string> out;
    const Vec3 axis = m.focus.axis(), right = m.focus.right(), up = m.focus.imageUp();
    const double halfW = 0.5 * m.width * m.pixelSizeMm(), halfH = 0.5 * m.height * m.pixelSizeMm();
    const std::vector<std::pair<double, double>> field{{0, 0}, {-halfW, -halfH}, {halfW, -halfH}, {-halfW, halfH}, {halfW, halfH},
                                                       {0, -halfH}, {0, halfH}, {-halfW, 0}, {halfW, 0}};

    // Where camera rays start: the objective's front, the working distance above the first and last plane.
    const int cameraMedium = scene.camera.medium;
    for (int k : {0, m.stack.planes - 1}) {
        const Vec3 front = m.focalPlaneAt(m.planeOffsetMm(k)).centreMm + axis * m.objective.workingDistanceMm;
        const int medium = mediumAt(scene, front, axis);
        if (!scatters(scene, medium)) continue;
        const std::string name = scene.media[static_cast<size_t>(medium)].name();
        if (!scene.geometry.intersect(Ray{front, axis}, 0.0, std::numeric_limits<double>::infinity()))
            throw ConfigError("the objective's front (working distance " + um(m.objective.workingDistanceMm) + " above plane " + std::to_string(k) +
                              ") lies in the scattering medium \"" + name + "\" and no surface bounds it: camera rays would random-walk without end; " +
                              "give the camera a clear immersion medium and put the specimen in a shape");
        out.push_back("the objective's front (working distance " + um(m.objective.workingDistanceMm) + " above plane " + std::to_string(k) +
                      ") lies inside the scattering medium \"" + name + "\": camera rays start in the specimen; the objective should sit in the immersion medium");
        break;
    }

    // Planes whose field, within a few depths of field, meets no dyed shape's bounding box. Dye that only
    // fills space outside shapes cannot be bounded this way: then planes are not checked.
    const double n = scene.ior(mediumAt(scene, m.focus.centreMm, axis));
    const double depthOfField = 520e-6 * n / (m.objective.na * m.objective.na);
    std::vector<std::array<double, 6>> dyedBoxes;  // in the focal frame: right, up and axis intervals
    bool bounded = !dyed(scene, cameraMedium);
    for (size_t i = 0; i < scene.shapes.size() && bounded; ++i) {
        const ShapeInfo& s = scene.shapes[i];
        if (!s.isInterface) continue;
        if (dyed(scene, s.outsideMedium)) bounded = false;
        if (!dyed(scene, s.insideMedium)) continue;
        std::vector<Vec3> points;
        const auto id = static_cast<uint32_t>(i);
        if (scene.geometry.isSphere(id)) {
            const Vec3 c = scene.geometry.sphereCenter(id);
            const double r = scene.geometry.sphereRadius(id);
            for (int k = 0; k < 8; ++k) points.push_back(c + Vec3(k & 1 ? r : -r, k & 2 ? r : -r, k & 4 ? r : -r));
        } else {
            points = scene.geometry.mesh(id).positions;
        }
        std::array<double, 6> box{1e300, -1e300, 1e300, -1e300, 1e300, -1e300};
        for (const Vec3& p : points) {
            const Vec3 d = p - m.focus.centreMm;
            const double c[3] = {dot(d, right), dot(d, up), dot(d, axis)};
            for (int a = 0; a < 3; ++a) {
                box[static_cast<size_t>(2 * a)] = std::min(box[static_cast<size_t>(2 * a)], c[a]);
                box[static_cast<size_t>(2 * a + 1)] = std::max(box[static_cast<size_t>(2 * a + 1)], c[a]);
            }
        }
        dyedBoxes.push_back(box);
    }
    if (bounded && !dyedBoxes.empty()) {
        int runStart = -1;
        auto flush = [&](int last) {
            if (runStart >= 0)
                out.push_back(planeRange(m, runStart, last) + ": the field of view (" + um(2 * halfW) + " x " + um(2 * halfH) +
                              ") meets no dyed shape within " + um(3 * depthOfField) + " of its plane; the image will hold only out-of-focus light");
            runStart = -1;
        };
        for (int k = 0; k < m.stack.planes; ++k) {
            const double z = m.planeOffsetMm(k), slack = 3 * depthOfField;
            bool hit = false;
            for (const auto& b : dyedBoxes)
                hit = hit || (b[0] <= halfW && b[1] >= -halfW && b[2] <= halfH && b[3] >= -halfH && b[4] <= z + slack && b[5] >= z - slack);
            if (!hit && runStart < 0) runStart = k;
            if (hit) flush(k - 1);
        }
        flush(m.stack.planes - 1);
    }

    // Sheets against the focal plane and the depth of field (the sheets move with the plane: once is enough).
    for (size_t c : channels) {
        const MicroscopeChannel& ch = m.channels[c];
        const double channelDepthOfField = (ch.emissionNm > 0 ? ch.emissionNm : 520.0) * 1e-6 * n / (m.objective.na * m.objective.na);
        for (size_t l : ch.lights) {
            const auto* beam = std::get_if<BeamLight>(&scene.lights[l]);
            if (!beam || beam->spec.widefield || !beam->spec.waistMm) continue;
            const double waist = *beam->spec.waistMm;
            const double offset = std::abs(dot(m.focus.centreMm - beam->spec.centreMm, normalize(beam->spec.normal)));
            if (offset > 3 * waist)
                out.push_back("channel \"" + ch.name + "\": the focal plane lies " + um(offset) + " from the centre plane of light " + std::to_string(l) +
                              " (waist " + um(waist) + "): the sheet misses the focal plane and the image will hold only haze");
            if (waist > 30 * channelDepthOfField)
                out.push_back("channel \"" + ch.name + "\": light " + std::to_string(l) + "'s waist " + um(waist) + " is " + num(waist / channelDepthOfField) +
                              " times the objective's depth of field (" + um(channelDepthOfField) +
                              "): it lights far more than the focal plane, as widefield illumination would; was a smaller unit meant?");
        }
    }
    if (m.detector.exposureS > 10)
        out.push_back("exposure " + num(m.detector.exposureS) + " s is long for one plane (light-sheet exposures are 1-100 ms): were milliseconds meant? (\"exposure_s\": \"20 ms\")");
    return out;
}

}  // namespace fluorosim::optics
