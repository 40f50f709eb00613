#include "render/specular_chain.h"

#include <algorithm>
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
    // Along a chain through concentric spheres, L = n · (distance of the ray's line from the centre) is
    // conserved: within a layer the line does not change, and at an interface Snell's law is
    // n₁ r sin θ₁ = n₂ r sin θ₂. So in the plane of the centre, x and y, the polar angle the chain
    // turns through from x to radius |y - c| is a sum of arccosines of L: a scalar function of the
    // direction's angle α at x, whose roots are the chains. Total reflection cuts it off where L exceeds
    // n_k r_(k-1), which is known in advance.
    const Vec3 cx = x - s.center, cy = y - s.center;
    const double rho = length(cx), ry = length(cy);
    int found = 0;
    if (!(rho > 1e-12 * s.radius[0])) {  // x at the centre: every chain is radial
        const auto p = traceShells(s, x, normalize(cy));
        if (p) roots[static_cast<size_t>(found++)] = *p;
        return found;
    }
    const Vec3 e1 = cx / rho;
    Vec3 e2 = cy - e1 * dot(cy, e1);
    if (!(length(e2) > 1e-12 * ry)) e2 = Frame::fromNormal(e1).s;
    e2 = normalize(e2);
    const double psi = std::atan2(dot(cy, e2), dot(cy, e1));  // y's polar angle, in [0, π]
    const double n0 = s.ior[0];
    double lCrit = n0 * rho;  // a direction's L is at most n0 rho
    for (int k = 1; k <= s.count; ++k) lCrit = std::min(lCrit, s.ior[static_cast<size_t>(k)] * s.radius[static_cast<size_t>(k - 1)]);
    const double gammaMax = std::asin(std::min(1.0, lCrit / (n0 * rho)));
    auto acosClamped = [](double v) { return std::acos(std::min(1.0, v)); };
    // The polar angle turned from x to radius |y - c| by the chain leaving at angle γ in [0, π] from the
    // outward radius (toward e2).
    auto turned = [&](double gamma) {
        const double b0 = rho * std::sin(gamma), l = n0 * b0;
        double phi = gamma - kPi / 2 + acosClamped(b0 / s.radius[0]);
        for (int k = 1; k <= s.count; ++k) {
            const double bk = l / s.ior[static_cast<size_t>(k)];
            const double outer = k < s.count ? s.radius[static_cast<size_t>(k)] : ry;
            phi += acosClamped(bk / outer) - acosClamped(bk / s.radius[static_cast<size_t>(k - 1)]);
        }
        return phi;
    };
    // sign · turned − ψ wrapped to (−π, π]; `sign` −1 mirrors the chain (leaving toward −e2).
    auto wrapped = [](double v) {
        while (v > kPi) v -= 2 * kPi;
        while (v <= -kPi) v += 2 * kPi;
        return v;
    };
    auto turn = [&](double gamma, double sign) { return wrapped(sign * turned(gamma) - psi); };
    auto addRoot = [&](double alpha) {
        const auto p = traceShells(s, x, e1 * std::cos(alpha) + e2 * std::sin(alpha));
        if (!p || found >= static_cast<int>(roots.size())) return;
        for (int k = 0; k < found; ++k)  // the radial directions belong to both senses
            if (length(roots[static_cast<size_t>(k)].direction - p->direction) < 1e-12) return;
        const Vec3 last = p->points[static_cast<size_t>(s.count - 1)], toY = y - last;
        // The chain must leave toward y, through it (a check on the arithmetic above).
        if (dot(p->exitDirection, toY) <= 0 || length(toY - p->exitDirection * dot(toY, p->exitDirection)) > 1e-7 * (ry + s.radius[0])) return;
        roots[static_cast<size_t>(found++)] = *p;
    };
    // A root of turn(·, sign) in [lo, hi], where it changes sign: regula falsi with the Illinois step.
    auto refine = [&](double lo, double hi, double flo, double fhi, double sign) {
        int side = 0;
        double mid = lo;
        for (int it = 0; it < options.steps && hi - lo > 1e-15; ++it) {
            mid = std::clamp((lo * fhi - hi * flo) / (fhi - flo), lo, hi);
            const double fm = turn(mid, sign);
            if (fm == 0) break;
            if ((fm < 0) == (flo < 0)) {
                lo = mid, flo = fm;
                if (side == -1) fhi *= 0.5;
                side = -1;
            } else {
                hi = mid, fhi = fm;
                if (side == 1) flo *= 0.5;
                side = 1;
            }
        }
        addRoot(sign * mid);
    };
    // The valid angles: [0, γmax] (leaving outward) and [π - γmax, π] (inward first), one interval when
    // total reflection cuts nothing off; each scanned for sign changes that are not wrap-arounds.
    const int n = std::max(4, options.brackets);
    std::array<std::array<double, 2>, 2> intervals{{{0.0, gammaMax}, {kPi - gammaMax, kPi}}};
    const int intervalCount = gammaMax >= kPi / 2 ? 1 : 2;
    if (intervalCount == 1) intervals[0] = {0.0, kPi};
    std::array<double, 2> g0{}, f0{};
    for (int iv = 0; iv < intervalCount; ++iv) {
        const auto [from, to] = intervals[static_cast<size_t>(iv)];
        // One evaluation of the turned angle serves both senses.
        double t0 = turned(from);
        for (int j = 0; j < 2; ++j) g0[j] = from, f0[j] = wrapped((j ? -1 : 1) * t0 - psi);
        for (int i = 1; i <= n; ++i) {
            const double g1 = from + (to - from) * i / n, t1 = turned(g1);
            for (int j = 0; j < 2; ++j) {
                const double sign = j ? -1.0 : 1.0, f1 = wrapped(sign * t1 - psi);
                if (f0[j] == 0) addRoot(sign * g0[j]);
                else if ((f0[j] < 0) != (f1 < 0) && std::abs(f0[j] - f1) < kPi) refine(g0[j], g1, f0[j], f1, sign);
                g0[j] = g1;
                f0[j] = f1;
            }
        }
        for (int j = 0; j < 2; ++j)
            if (f0[j] == 0) addRoot((j ? -1.0 : 1.0) * g0[j]);
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
