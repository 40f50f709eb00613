// Refracted chains through concentric spheres (render/specular_chain.h): the roots reach their target
// by Snell's law, the brackets miss none that a 64-times finer scan finds, and the area swept per
// solid angle matches a count of traced directions landing on a patch (an independent estimator).
#include <gtest/gtest.h>

#include <cmath>

#include "core/math.h"
#include "core/rng.h"
#include "render/specular_chain.h"

namespace fluorosim {
namespace {

// The spheres sample's container: liquid n 1.33 inside 34 mm, glass n 1.5 to 36 mm, air outside.
SphericalShells glassSphere(double liquid = 1.33, double glass = 1.5) {
    SphericalShells s;
    s.center = Vec3(10, 36, 200);
    s.count = 2;
    s.radius = {34, 36};
    s.ior = {liquid, glass, 1.0};
    return s;
}

// Uniform in the cone of directions within acos(cosMax) of +z.
Vec3 inCone(double u1, double u2, double cosMax) {
    const double c = 1 - u1 * (1 - cosMax), s = std::sqrt(std::max(0.0, 1 - c * c)), phi = 2 * kPi * u2;
    return {s * std::cos(phi), s * std::sin(phi), c};
}

Vec3 pointInBall(Rng& rng, const Vec3& c, double r) {
    while (true) {
        const Vec3 p(2 * rng.uniform() - 1, 2 * rng.uniform() - 1, 2 * rng.uniform() - 1);
        if (dot(p, p) < 1) return c + p * r;
    }
}

// Distance from y to the exit ray of the chain traced from x along the root's direction.
double exitMiss(const SphericalShells& s, const Vec3& x, const ShellPath& root, const Vec3& y) {
    const auto p = traceShells(s, x, root.direction);
    if (!p) return INFINITY;
    const Vec3 o = p->points[static_cast<size_t>(s.count - 1)], toY = y - o;
    return length(toY - p->exitDirection * dot(toY, p->exitDirection));
}

TEST(SpecularChain, RootsReachTheirTargetAndAreFoundAsAFineScanFindsThem) {
    const SphericalShells s = glassSphere();
    Rng rng(11, 0);
    int configurations = 0, roots = 0, fineRoots = 0;
    ShellRootOptions fine;
    fine.brackets = 4096;
    for (int i = 0; i < 400; ++i) {
        const Vec3 x = pointInBall(rng, s.center, 33.9);
        // Lights above the sphere, as in the sample, and anywhere around it.
        const Vec3 y = i % 2 ? s.center + Vec3(60 * rng.uniform() - 30, 56 + 10 * rng.uniform(), 60 * rng.uniform() - 30)
                             : s.center + normalize(Vec3(rng.uniform() - 0.5, rng.uniform() - 0.5, rng.uniform() - 0.5)) * (40 + 200 * rng.uniform());
        std::array<ShellPath, 4> r, rf;
        const int n = shellPaths(s, x, y, r), nf = shellPaths(s, x, y, rf, fine);
        ++configurations;
        roots += n;
        fineRoots += nf;
        EXPECT_EQ(n, nf) << "x " << x.x << " " << x.y << " " << x.z << ", y " << y.x << " " << y.y << " " << y.z;
        for (int k = 0; k < n; ++k) EXPECT_LT(exitMiss(s, x, r[static_cast<size_t>(k)], y), 1e-7 * length(y - x));
    }
    // Some points outside are not reached from some points inside: the branch that would reach them is
    // cut by total internal reflection at the glass–air surface (the chain's shadow). Most are.
    EXPECT_GT(roots, configurations * 3 / 4);
    EXPECT_EQ(roots, fineRoots);
}

TEST(SpecularChain, IndexMatchedChainIsTheStraightLine) {
    const SphericalShells s = glassSphere(1.0, 1.0);
    Rng rng(3, 0);
    for (int i = 0; i < 100; ++i) {
        const Vec3 x = pointInBall(rng, s.center, 33);
        const Vec3 y = s.center + Vec3(40 * rng.uniform() - 20, 60 + 20 * rng.uniform(), 40 * rng.uniform() - 20);
        std::array<ShellPath, 4> r;
        ASSERT_EQ(shellPaths(s, x, y, r), 1);
        const Vec3 w = normalize(y - x);
        EXPECT_NEAR(length(r[0].direction - w), 0.0, 1e-9);
        EXPECT_EQ(r[0].fresnel, 1.0);
        const Vec3 n(0, -1, 0);  // a light facing down
        const double expected = dot(y - x, y - x) / std::abs(dot(w, n));
        EXPECT_NEAR(areaPerSolidAngle(s, x, r[0], y, n) / expected, 1.0, 1e-7);
    }
}

// Directions drawn uniformly in a cone around a root, traced, and counted where they land within a
// square patch around y: the count over the draws times the cone's solid angle estimates
// patch area / (area per solid angle). Poisson error 0.5 %; the patch's size biases it by about
// (side / distance)², 0.2 %.
TEST(SpecularChain, AreaPerSolidAngleMatchesACountOfTracedDirections) {
    const SphericalShells s = glassSphere();
    const Vec3 n(0, -1, 0);
    const Frame light = Frame::fromNormal(n);
    Rng rng(5, 0);
    for (const Vec3& offset : {Vec3(3, 5, -2), Vec3(-12, 15, 8), Vec3(8, -10, 4)}) {
        const Vec3 x = s.center + offset;
        const Vec3 y = s.center + Vec3(12, 60, -9);
        std::array<ShellPath, 4> r;
        ASSERT_EQ(shellPaths(s, x, y, r), 1);
        const double dAdw = areaPerSolidAngle(s, x, r[0], y, n);
        const double side = 2.0, cosCone = std::cos(0.15);
        const Frame cone = Frame::fromNormal(r[0].direction);
        const int draws = 400000;
        int hits = 0;
        for (int i = 0; i < draws; ++i) {
            const Vec3 w = cone.toWorld(inCone(rng.uniform(), rng.uniform(), cosCone));
            const auto p = traceShells(s, x, w);
            if (!p) continue;
            const Vec3 o = p->points[1];
            const double denom = dot(p->exitDirection, n);
            if (!(denom < 0)) continue;
            const Vec3 q = o + p->exitDirection * (dot(y - o, n) / denom) - y;
            if (std::abs(dot(q, light.s)) < side / 2 && std::abs(dot(q, light.t)) < side / 2) ++hits;
        }
        const double omega = 2 * kPi * (1 - cosCone);
        const double counted = omega * hits / draws, expected = side * side / dAdw;
        const double sigma = counted / std::sqrt(static_cast<double>(hits));
        EXPECT_NEAR(counted, expected, 4 * sigma) << "hits " << hits;
    }
}

}  // namespace
}  // namespace fluorosim
