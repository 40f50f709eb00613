#include "render/specular_chain.h"

#include <cmath>

#include "core/math.h"
#include "materials/fresnel.h"

namespace fluorosim {
namespace {

// Where a ray from inside a sphere (|o - c| < r) leaves it.
Vec3 exitPoint(const Vec3& c, double r, const Vec3& o, const Vec3& d) {
    const Vec3 oc = o - c;
    const double b = dot(oc, d);
    const double disc = r * r - dot(oc - d * b, oc - d * b);  // Hearn–Baker: r² minus the squared miss distance
    const double t = -b + std::sqrt(std::max(0.0, disc));
    return o + d * t;
}

// Direction w in the plane (e1, e2) at angle a.
Vec3 inPlane(const Vec3& e1, const Vec3& e2, double a) { return e1 * std::cos(a) + e2 * std::sin(a); }

}  // namespace

std::optional<ShellPath> traceShells(const SphericalShells& s, const Vec3& x, const Vec3& w) {
    ShellPath path;
    path.direction = w;
    Vec3 o = x, d = w;
    for (int k = 0; k < s.count; ++k) {
        const Vec3 p = exitPoint(s.center, s.radius[static_cast<size_t>(k)], o, d);
        const Vec3 n = normalize(p - s.center);
        const double inside = s.ior[static_cast<size_t>(k)], outside = s.ior[static_cast<size_t>(k) + 1];
        if (inside != outside) {
            Vec3 t;
            if (!refract(-d, n, inside / outside, &t)) return std::nullopt;
            path.fresnel *= 1 - fresnelDielectric(dot(-d, -n), outside / inside);
            d = normalize(t);
        }
        path.points[static_cast<size_t>(k)] = p;
        o = p;
    }
    path.exitDirection = d;
    return path;
}

int shellPaths(const SphericalShells& s, const Vec3& x, const Vec3& y, std::array<ShellPath, 4>& roots, const ShellRootOptions& options) {
    // The plane through the centre, x and y; any plane through the line when they are collinear.
    Vec3 e1 = x - s.center;
    if (!(length(e1) > 1e-12 * s.radius[0])) e1 = y - s.center;
    e1 = normalize(e1);
    Vec3 e2 = (y - s.center) - e1 * dot(y - s.center, e1);
    if (!(length(e2) > 1e-12 * length(y - s.center))) e2 = Frame::fromNormal(e1).s;
    e2 = normalize(e2);
    // Signed miss of the exit ray at y, in the plane: sin of the angle from the exit direction to y;
    // nullopt where the chain reflects totally or leaves away from y.
    auto miss = [&](double a, ShellPath* out) -> std::optional<double> {
        const auto p = traceShells(s, x, inPlane(e1, e2, a));
        if (!p) return std::nullopt;
        const Vec3 last = p->points[static_cast<size_t>(s.count - 1)];
        const Vec3 toY = y - last;
        const double dist = length(toY);
        if (!(dist > 0) || dot(p->exitDirection, toY) <= 0) return std::nullopt;
        if (out) *out = *p;
        const Vec3 c = cross(p->exitDirection, toY / dist);
        return dot(c, cross(e1, e2));
    };
    int found = 0;
    // A root of `miss` between a0 and a1, where it changes sign; its path into roots.
    auto refine = [&](double lo, double hi, double flo) {
        for (int b = 0; b < options.bisections; ++b) {
            const double mid = 0.5 * (lo + hi);
            const std::optional<double> fm = miss(mid, nullptr);
            if (!fm) return;  // not a bracket of one continuous branch
            if ((*fm <= 0) == (flo <= 0)) lo = mid, flo = *fm;
            else hi = mid;
        }
        ShellPath p;
        const std::optional<double> fr = miss(0.5 * (lo + hi), &p);
        if (fr && std::abs(*fr) < 1e-9 && found < static_cast<int>(roots.size())) roots[static_cast<size_t>(found++)] = p;
    };
    // Between a valid direction and one where the chain reflects totally or turns away: the edge of the
    // valid branch, by bisection, and a root between the valid end and the edge if the sign changes.
    auto edge = [&](double valid, double fValid, double invalid) {
        double lo = valid, hi = invalid, fLo = fValid;
        for (int b = 0; b < options.bisections; ++b) {
            const double mid = 0.5 * (lo + hi);
            const std::optional<double> fm = miss(mid, nullptr);
            if (fm) lo = mid, fLo = *fm;
            else hi = mid;
        }
        if ((fLo <= 0) != (fValid <= 0)) refine(valid, lo, fValid);
    };
    const int n = std::max(8, options.brackets);
    const double step = 2 * kPi / n;
    double a0 = -kPi;
    std::optional<double> f0 = miss(a0, nullptr);
    for (int i = 1; i <= n; ++i) {
        const double a1 = -kPi + i * step;
        const std::optional<double> f1 = miss(a1, nullptr);
        if (f0 && f1 && ((*f0 <= 0) != (*f1 <= 0))) refine(a0, a1, *f0);
        else if (f0 && !f1) edge(a0, *f0, a1);
        else if (!f0 && f1) edge(a1, *f1, a0);
        a0 = a1;
        f0 = f1;
    }
    return found;
}

double areaPerSolidAngle(const SphericalShells& s, const Vec3& x, const ShellPath& path, const Vec3& y, const Vec3& n) {
    const Frame f = Frame::fromNormal(path.direction);
    const double h = 1e-6;
    // Where the perturbed chain's exit ray meets the plane through y with normal n.
    auto landing = [&](const Vec3& w, Vec3* out) {
        const auto p = traceShells(s, x, normalize(w));
        if (!p) return false;
        const Vec3 o = p->points[static_cast<size_t>(s.count - 1)];
        const double denom = dot(p->exitDirection, n);
        if (denom == 0) return false;
        *out = o + p->exitDirection * (dot(y - o, n) / denom);
        return true;
    };
    Vec3 sp, sm, tp, tm;
    if (!landing(path.direction + f.s * h, &sp) || !landing(path.direction - f.s * h, &sm) || !landing(path.direction + f.t * h, &tp) ||
        !landing(path.direction - f.t * h, &tm))
        return 0.0;
    return length(cross((sp - sm) / (2 * h), (tp - tm) / (2 * h)));
}

}  // namespace fluorosim
