// Manifold next-event estimation through glass shells (Integrator::Mnee): a scattering liquid in a
// glass sphere, lit by a small spherical lamp above it, seen from outside. Against the path tracer
// (which finds the lamp only by phase sampling through the glass) and, with glass and liquid of index 1,
// against plain next-event estimation through index-matched interfaces. z-scores from the estimators'
// own standard errors, fixed seeds.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <string>

#include "support/fluorescent_scenes.h"
#include "support/test_scenes.h"

namespace fluorosim {
namespace {

using testing::addInterfaceSphere;
using testing::addMedium;
using testing::Estimate;
using testing::meanRadiance;

struct ShellScene {
    double liquidIor = 1.33, glassIor = 1.5;
    double lampRadius = 0.3;  // 0: a point light of the intensity a lamp of radius `pointAs` would have
    double pointAs = 0.02;
    bool dyed = false;  // AF488 at 20 µM in the liquid, and a lamp of one line at 495 nm
    bool dielectricSurfaces = true;  // false: index-matched interfaces without a material
    Integrator integrator = Integrator::Mnee;
};

Scene shellScene(const ShellScene& o) {
    Scene scene;
    const int liquid = o.dyed ? testing::addDyedMedium(scene, "liquid", 0.0, 2.0, 0.3, o.liquidIor, {{testing::databaseDye("AF488"), 20e-6}})
                              : addMedium(scene, "liquid", 0.3, 2.0, 0.3, o.liquidIor);
    const int glass = addMedium(scene, "glass", 0.0, 0.0, 0.0, o.glassIor);
    int material = kNone;
    if (o.dielectricSurfaces) {
        scene.materials.push_back(makeDielectric(0.0));
        material = 0;
    }
    addInterfaceSphere(scene, Vec3(0, 0, 0), 1.0, liquid, glass, material);
    addInterfaceSphere(scene, Vec3(0, 0, 0), 1.2, glass, kNone, material);
    // The lamp above the glass: a sphere glowing outward with radiance 10, or a point light of the
    // intensity of such a sphere (radiance × its cross-section, π r², in m²).
    const Vec3 lampAt(0.2, 2.0, 0.1);
    if (o.lampRadius > 0) {
        const uint32_t lamp = scene.geometry.addSphere(lampAt, o.lampRadius);
        ShapeInfo info;
        info.name = "lamp";
        scene.shapes.push_back(info);
        scene.addAreaLight(lamp, AreaEmission{o.dyed ? Spectrum::lines({{495.0, 10.0}}) : Spectrum::constant(10.0), false});
    } else {
        scene.lights.push_back(PointLight{lampAt, Spectrum::constant(10.0 * kPi * sqr(o.pointAs * 1e-3))});
    }
    scene.render.integrator = o.integrator;
    scene.finalize();
    return scene;
}

std::string text(const Estimate& e) {
    char buf[64];
    std::snprintf(buf, sizeof buf, "%.4g +- %.2g", e.mean, e.stderr_);
    return buf;
}

// Records both estimates (in the test's XML output) and requires them to agree within 4 standard errors.
void expectAgreement(const char* aName, const Estimate& a, const char* bName, const Estimate& b) {
    ::testing::Test::RecordProperty(aName, text(a));
    ::testing::Test::RecordProperty(bName, text(b));
    ASSERT_GT(a.mean, 0);
    ASSERT_GT(b.mean, 0);
    const double z = (a.mean - b.mean) / std::sqrt(sqr(a.stderr_) + sqr(b.stderr_));
    EXPECT_LT(std::abs(z), 4.0) << aName << " " << text(a) << " against " << bName << " " << text(b);
}

// Rays from the side into the ball of liquid.
Estimate seen(const Scene& scene, int paths, uint64_t seed) { return meanRadiance(scene, Vec3(0, -0.3, -5), kNone, Vec3(0, 0, 0), 0.9, paths, seed); }

TEST(Mnee, AgreesWithThePathTracerBehindGlass) {
    ShellScene o;
    const Estimate mnee = seen(shellScene(o), 40000, 21);
    o.integrator = Integrator::Path;
    const Estimate path = seen(shellScene(o), 400000, 22);
    expectAgreement("mnee", mnee, "path", path);
    // The point of the method: the same answer at a fraction of the error per path.
    EXPECT_LT(mnee.stderr_ * std::sqrt(40000.0), 0.5 * path.stderr_ * std::sqrt(400000.0));
}

TEST(Mnee, IndexOneGlassEqualsPlainNextEventEstimation) {
    ShellScene o;
    o.liquidIor = o.glassIor = 1.0;
    const Estimate mnee = seen(shellScene(o), 40000, 31);
    o.dielectricSurfaces = false;
    o.integrator = Integrator::Path;
    const Estimate nee = seen(shellScene(o), 40000, 32);
    expectAgreement("mnee", mnee, "nee", nee);
}

// Fluorescence across the chains: the camera path (at emission wavelengths) branches at the dye, and the
// excitation sub-path, at the lamp's line, reaches the lamp through the glass by a chain. The lamp's
// line is dark at the camera path's wavelengths, so everything seen is re-emitted light.
TEST(Mnee, FluorescenceBehindGlassAgreesWithThePathTracer) {
    ShellScene o;
    o.dyed = true;
    const Estimate mnee = seen(shellScene(o), 100000, 51);
    o.integrator = Integrator::Path;
    const Estimate path = seen(shellScene(o), 2000000, 52);
    expectAgreement("mnee", mnee, "path", path);
    EXPECT_LT(mnee.stderr_, 0.1 * mnee.mean);
}

// A point light behind glass: the path tracer cannot reach it at all (its energy is simply missing), and
// manifold next-event estimation must give what a small spherical lamp of the same intensity gives
// (whose chains are weighed against phase sampling, and whose size changes the answer by about
// (radius / distance)², 10⁻⁴ here).
TEST(Mnee, PointLightBehindGlassEqualsASmallSphericalLamp) {
    ShellScene o;
    o.lampRadius = 0;
    const Estimate point = seen(shellScene(o), 40000, 41);
    o.integrator = Integrator::Path;
    EXPECT_EQ(seen(shellScene(o), 2000, 42).mean, 0.0) << "the path tracer reaches a point light through glass";
    o.integrator = Integrator::Mnee;
    o.lampRadius = o.pointAs;
    const Estimate lamp = seen(shellScene(o), 40000, 43);
    expectAgreement("point", point, "lamp", lamp);
}

}  // namespace
}  // namespace fluorosim
