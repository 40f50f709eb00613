#pragma once
// Light paths through concentric smooth spherical interfaces (a glass shell holding a liquid): from a
// point x inside the innermost sphere, across every interface once, outward, to a point y outside.
// These are the chains that next-event estimation from a medium vertex cannot make (a straight shadow
// ray meets the glass) and that a phase-sampled direction finds only by chance. Such a path lies in the
// plane through the centre, x and y, and conserves n times its line's distance from the centre, so the
// angle it turns through is a sum of arccosines of one scalar: its roots are bracketed on a grid of
// directions in that plane and refined by regula falsi (manifold next-event estimation, Hanika et al.
// 2015, reduced to 1-D by the symmetry). Pure geometry: the path tracer decides what the chains carry
// (render/path_tracer.cpp).
#include <array>
#include <cstdint>
#include <optional>
#include <vector>

#include "core/vec3.h"

namespace fluorosim {

inline constexpr int kMaxShellInterfaces = 4;

struct SphericalShells {
    Vec3 center;
    int count = 0;                                           // interfaces, innermost first
    std::array<double, kMaxShellInterfaces> radius{};        // increasing
    std::array<double, kMaxShellInterfaces + 1> ior{};       // ior[k]: inside interface k; ior[count]: outside
    std::array<uint32_t, kMaxShellInterfaces> shape{};       // the scene's shape of each interface
    std::array<int, kMaxShellInterfaces + 1> medium{};       // media in the same order as ior
};

// One refracted path leaving x in `direction`: where it crosses each interface and leaves the last.
struct ShellPath {
    Vec3 direction;                                 // unit, at x
    std::array<Vec3, kMaxShellInterfaces> points{}; // crossing of interface k
    Vec3 exitDirection;                             // unit, after the outermost interface
    double fresnel = 1;                             // product of the interfaces' Fresnel transmittances
};

// The chain traced forward from x (inside the innermost interface) along unit w; nullopt under total
// internal reflection.
std::optional<ShellPath> traceShells(const SphericalShells& s, const Vec3& x, const Vec3& w);

struct ShellRootOptions {
    int brackets = 32;    // directions per interval of valid directions (up to four) that bracket roots; two
                          // roots within one bracket are missed (tested against 4096)
    int steps = 60;  // at most this many steps of regula falsi per root
};

// Every refracted path from x (inside) to y (outside the outermost interface), at most `maxRoots`.
int shellPaths(const SphericalShells& s, const Vec3& x, const Vec3& y, std::array<ShellPath, 4>& roots, const ShellRootOptions& options = {});

// Area swept on the plane through y with normal n per unit solid angle of the direction at x (the
// generalized geometry term's inverse: |cos| / r² for a straight line), by central differences of the
// traced chain. 0 when a perturbed chain is totally reflected.
double areaPerSolidAngle(const SphericalShells& s, const Vec3& x, const ShellPath& path, const Vec3& y, const Vec3& n);

}  // namespace fluorosim
