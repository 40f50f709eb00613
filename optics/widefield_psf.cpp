#include "optics/widefield_psf.h"

#include <algorithm>
#include <cmath>
#include <complex>
#include <string>

#include "core/errors.h"
#include "core/math.h"
#include "core/parallel.h"
#include "core/quadrature.h"

namespace fluorosim::optics {
namespace {

std::string num(double v) { return std::to_string(v); }

double waveNumberPerMm(double lambdaNm) { return 2 * kPi / (lambdaNm * 1e-6); }

}  // namespace

void PupilOptions::validate() const {
    auto require = [](bool ok, const std::string& what) {
        if (!ok) throw ConfigError(what);
    };
    require(immersionIndex >= 1 && std::isfinite(immersionIndex), "PSF immersion index must be >= 1, got " + num(immersionIndex));
    require(sampleIndex >= 1 && std::isfinite(sampleIndex), "PSF sample index must be >= 1, got " + num(sampleIndex));
    require(na > 0 && std::isfinite(na), "PSF numerical aperture must be positive, got " + num(na));
    require(na < std::min(immersionIndex, sampleIndex),
            "PSF numerical aperture " + num(na) + " must lie below the immersion index " + num(immersionIndex) + " and the sample index " + num(sampleIndex));
    require(depthMm >= 0 && std::isfinite(depthMm), "PSF focus depth must be >= 0, got " + num(depthMm) + " mm");
    if (!intensityApodization.empty()) {
        require(intensityApodization.size() >= 2, "PSF apodization needs at least 2 values, got " + std::to_string(intensityApodization.size()));
        for (double a : intensityApodization) require(a >= 0 && a <= 1 && std::isfinite(a), "PSF apodization values must lie in [0, 1], got " + num(a));
        require(intensityApodization.front() > 0, "PSF apodization must be positive on the axis, got " + num(intensityApodization.front()));
    }
}

double PupilOptions::collectionHalfAngle() const { return std::asin(na / sampleIndex); }

void PsfTableOptions::validate() const {
    auto require = [](bool ok, const std::string& what) {
        if (!ok) throw ConfigError(what);
    };
    require(vCut >= 10 && vCut <= 2000, "PSF table vCut must lie in [10, 2000], got " + num(vCut));
    require(wMax > 0 && wMax <= 2000, "PSF table wMax must lie in (0, 2000], got " + num(wMax));
    require(dv > 0 && dv <= 1 && dw > 0 && dw <= 4, "PSF table steps must lie in (0, 1] (dv) and (0, 4] (dw), got " + num(dv) + " and " + num(dw));
    require(pupilNodes >= 16 && pupilNodes <= 4096, "PSF pupil nodes must lie in [16, 4096], got " + std::to_string(pupilNodes));
    require(depthTolerance >= 0 && depthTolerance <= 1, "PSF depth tolerance must lie in [0, 1], got " + num(depthTolerance));
}


namespace {

constexpr double kGeoFineW = 4.0;   // h_geo rows every dw up to this |w| ...
constexpr double kGeoGrowth = 0.02;  // ... then each row 2% further out than the last

// Cubic (Catmull–Rom) interpolation along a row at fractional index x in [0, n − 1], mirrored at 0
// (h is even in v) and clamped at the end; never negative.
double cubicInRow(const float* row, int n, double x) {
    const int i = std::min(static_cast<int>(x), n - 2);
    const double t = x - i;
    auto at = [&](int k) { return static_cast<double>(row[k < 0 ? -k : std::min(k, n - 1)]); };
    const double p0 = at(i - 1), p1 = at(i), p2 = at(i + 1), p3 = at(i + 2);
    const double value = p1 + 0.5 * t * (p2 - p0 + t * (2 * p0 - 5 * p1 + 4 * p2 - p3 + t * (3 * (p1 - p2) + p3 - p0)));
    return std::max(0.0, value);
}

double linearInRow(const float* row, int n, double x) {
    const int i = std::min(static_cast<int>(x), n - 2);
    return lerp(x - i, static_cast<double>(row[i]), static_cast<double>(row[i + 1]));
}

double apodization(const PupilOptions& p, double rho) {  // a(θ) at sin θ / sin θmax = ρ
    if (p.intensityApodization.empty()) return 1.0;
    const double x = std::clamp(rho, 0.0, 1.0) * (p.intensityApodization.size() - 1);
    const size_t i = std::min(p.intensityApodization.size() - 2, static_cast<size_t>(x));
    return lerp(x - i, p.intensityApodization[i], p.intensityApodization[i + 1]);
}

constexpr double kRingFill = 0.25;  // g's floor, as a fraction of the Airy rings' envelope

// Fractional row of |w| in the h_geo rows.
double geoRow(double dw, double w) {
    const double a = std::abs(w);
    const int fine = static_cast<int>(std::lround(kGeoFineW / dw));
    if (a <= kGeoFineW) return a / dw;
    return fine + std::log(a / kGeoFineW) / std::log1p(kGeoGrowth);
}

// Mass of g within the annulus [v0, v0 + x] where g is linear from g0 (at v0) with slope s, per 2π.
double annulusMass(double v0, double g0, double s, double x) { return g0 * (v0 * x + 0.5 * x * x) + s * (0.5 * v0 * x * x + x * x * x / 3); }

// The pupil at Gauss–Legendre nodes in ρ: |A(ρ)|², cos θ_s and, under a mismatch, the constant phase of
// focusing d deep through the step.
struct PupilNodes {
    QuadratureRule gl;
    std::vector<double> intensity, cosS, fixedPhase;
    double power = 0;  // ∫ |A|² ρ dρ
    double focusScale = 1;
};

PupilNodes pupilNodes(const PupilOptions& pupil, int count, double lambdaNm) {
    PupilNodes p;
    p.gl = gaussLegendre01(count);
    const size_t N = p.gl.nodes.size();
    p.intensity.resize(N);
    p.cosS.resize(N);
    p.fixedPhase.assign(N, 0.0);
    for (size_t n = 0; n < N; ++n) {
        const double rho = p.gl.nodes[n];
        p.cosS[n] = std::sqrt(1 - sqr(pupil.na * rho / pupil.sampleIndex));
        p.intensity[n] = apodization(pupil, rho) / (pupil.aplanatic ? p.cosS[n] : 1.0);
        p.power += p.gl.weights[n] * rho * p.intensity[n];
    }
    if (!pupil.matched()) {
        // Focusing to depth d through the step: d (n_s cos θ_s − f n_i cos θ_i), with f placing the plane
        // of focus at the least-squares best focus (the aberration has no defocus component over the pupil).
        std::vector<double> ds(N), di(N), weight(N);
        double wsum = 0, ms = 0, mi = 0;
        for (size_t n = 0; n < N; ++n) {
            const double rho = p.gl.nodes[n];
            weight[n] = p.gl.weights[n] * rho * p.intensity[n];
            ds[n] = pupil.sampleIndex * p.cosS[n];
            di[n] = pupil.immersionIndex * std::sqrt(1 - sqr(pupil.na * rho / pupil.immersionIndex));
            wsum += weight[n];
            ms += weight[n] * ds[n];
            mi += weight[n] * di[n];
        }
        double sss = 0, sis = 0;
        for (size_t n = 0; n < N; ++n) {
            sss += weight[n] * sqr(ds[n] - ms / wsum);
            sis += weight[n] * (di[n] - mi / wsum) * (ds[n] - ms / wsum);
        }
        p.focusScale = sss / sis;
        const double kd = waveNumberPerMm(lambdaNm) * pupil.depthMm;
        for (size_t n = 0; n < N; ++n) p.fixedPhase[n] = kd * (ds[n] - p.focusScale * di[n]);
    }
    return p;
}

WidefieldPsf::Table buildTable(const PupilOptions& pupil, const PsfTableOptions& o, double lambdaNm) {
    WidefieldPsf::Table t;
    t.lambdaNm = lambdaNm;
    t.nv = static_cast<int>(std::ceil(o.vCut / o.dv)) + 1;
    const int half = static_cast<int>(std::ceil(o.wMax / o.dw));
    t.nw = 2 * half + 1;
    const PupilNodes p = pupilNodes(pupil, o.pupilNodes, lambdaNm);
    const QuadratureRule& gl = p.gl;
    const size_t N = gl.nodes.size();
    // Pupil nodes: weight × ρ × amplitude.
    std::vector<double> c(N);
    for (size_t n = 0; n < N; ++n) c[n] = gl.weights[n] * gl.nodes[n] * std::sqrt(p.intensity[n]);
    const std::vector<double>& cosS = p.cosS;
    const std::vector<double>& fixedPhase = p.fixedPhase;
    const double power = p.power;
    t.focusScale = p.focusScale;
    const double norm = 2 * kPi * power;  // Parseval: ∫ |U|² d²v over the plane
    // J0(v ρ_n) for every v node: the pupil integral is then a matrix-vector product per w.
    std::vector<double> j0(static_cast<size_t>(t.nv) * N);
    parallelFor(static_cast<size_t>(t.nv), 0, [&](size_t i) {
        const double v = static_cast<double>(i) * o.dv;
        for (size_t n = 0; n < N; ++n) j0[i * N + n] = std::cyl_bessel_j(0.0, v * gl.nodes[n]);
    });
    t.h.assign(static_cast<size_t>(t.nv) * t.nw, 0.0f);
    t.enclosed.assign(static_cast<size_t>(t.nw), 0.0);
    // Matched: h is even in w (the phase changes sign), so rows above focus mirror those below.
    const bool even = pupil.matched();
    const size_t rows = even ? static_cast<size_t>(half) + 1 : static_cast<size_t>(t.nw);
    parallelFor(rows, 0, [&](size_t r) {
        const size_t j = even ? static_cast<size_t>(half) + r : r;
        const double w = (static_cast<double>(j) - half) * o.dw;
        std::vector<double> re(N), im(N);
        for (size_t n = 0; n < N; ++n) {
            // A point dz toward the objective lies at depth d − dz: its sample path shortens as the fixed
            // term's lengthens (Gibson–Lanni: k [(d − dz) n_s cos θ_s − f d n_i cos θ_i]).
            const double phase = -w * pupil.sampleIndex * cosS[n] + fixedPhase[n];
            re[n] = c[n] * std::cos(phase);
            im[n] = c[n] * std::sin(phase);
        }
        float* out = &t.h[j * static_cast<size_t>(t.nv)];
        for (int i = 0; i < t.nv; ++i) {
            double ur = 0, ui = 0;
            const double* row = &j0[static_cast<size_t>(i) * N];
            for (size_t n = 0; n < N; ++n) {
                ur += row[n] * re[n];
                ui += row[n] * im[n];
            }
            out[i] = static_cast<float>((ur * ur + ui * ui) / norm);
        }
        // ∫ h 2πv dv by Simpson's rule (trapezoid on a last odd interval).
        double sum = 0;
        const int last = (t.nv - 1) % 2 == 0 ? t.nv - 1 : t.nv - 2;
        for (int i = 0; i + 2 <= last; i += 2)
            sum += (out[i] * i + 4.0 * out[i + 1] * (i + 1) + out[i + 2] * (i + 2)) * o.dv / 3;
        if (last != t.nv - 1) sum += 0.5 * (out[last] * last + out[last + 1] * (last + 1.0)) * o.dv;
        t.enclosed[j] = 2 * kPi * o.dv * sum;
        if (even) {
            const size_t mirror = static_cast<size_t>(2 * half) - j;
            std::copy(out, out + t.nv, &t.h[mirror * static_cast<size_t>(t.nv)]);
            t.enclosed[mirror] = t.enclosed[j];
        }
    });

    // The displacement density g: the in-focus row, linear in v between nodes, normalised on v <= vCut.
    const float* focusRow = &t.h[static_cast<size_t>(half) * t.nv];
    t.g.assign(static_cast<size_t>(t.nv), 0.0);
    t.cdf.assign(static_cast<size_t>(t.nv), 0.0);
    // Where the in-focus pattern has its dark rings, a point slightly out of focus does not: g is kept at
    // least a quarter of the rings' envelope, 1/(4π) / (1 + π v³/8) (the Airy asymptote 2/(π² v³) far
    // out), so that h/h_geo stays bounded near focus (it reached 10^4 there, as rare hot pixels).
    for (int i = 0; i < t.nv; ++i) {
        const double v = i * o.dv, envelope = 1 / (4 * kPi) / (1 + kPi * v * v * v / 8);
        t.g[static_cast<size_t>(i)] = std::max(kRingFill * envelope, static_cast<double>(focusRow[i]));
    }
    for (int i = 0; i + 1 < t.nv; ++i) {
        const double g0 = t.g[static_cast<size_t>(i)], s = (t.g[static_cast<size_t>(i) + 1] - g0) / o.dv;
        t.cdf[static_cast<size_t>(i) + 1] = t.cdf[static_cast<size_t>(i)] + 2 * kPi * annulusMass(i * o.dv, g0, s, o.dv);
    }
    const double total = t.cdf.back();
    for (double& x : t.g) x /= total;
    for (double& x : t.cdf) x /= total;
    auto g = [&](double v) {
        const double x = v / o.dv;
        if (!(x >= 0) || x > t.nv - 1) return 0.0;
        const int i = std::min(static_cast<int>(x), t.nv - 2);
        return lerp(x - i, t.g[static_cast<size_t>(i)], t.g[static_cast<size_t>(i) + 1]);
    };

    // h_geo rows: fine near focus, then geometric in |w| up to wMax.
    const int fine = static_cast<int>(std::lround(kGeoFineW / o.dw));
    for (int j = 0; j <= fine && j * o.dw <= o.wMax; ++j) t.geoW.push_back(j * o.dw);
    while (t.geoW.back() < o.wMax) t.geoW.push_back(kGeoFineW * std::pow(1 + kGeoGrowth, static_cast<double>(t.geoW.size()) - fine));

    // Ring averages of g: G(v, ρ) = (1/π) ∫0^π g(|v − ρ e^{iφ}|) dφ (symmetric in v and ρ), by the
    // midpoint rule in φ with about one node per table step of arc.
    const double tanMax = std::tan(pupil.collectionHalfAngle());
    const double reachMax = pupil.na * t.geoW.back() * tanMax;
    const int nr = std::min(t.nv, static_cast<int>(std::ceil(reachMax / o.dv)) + 2);
    // The node count depends on min(v, ρ) = ρ alone on the computed half (ρ <= v): cosines per ρ row, once.
    auto nodesFor = [&](int r) { return static_cast<int>(std::ceil(kPi * r)) + 8; };
    std::vector<std::vector<double>> cosines(static_cast<size_t>(nr));
    for (int r = 1; r < nr; ++r) {
        const int n = nodesFor(r);
        cosines[static_cast<size_t>(r)].resize(static_cast<size_t>(n));
        for (int k = 0; k < n; ++k) cosines[static_cast<size_t>(r)][static_cast<size_t>(k)] = std::cos(kPi * (k + 0.5) / n);
    }
    std::vector<float> ring(static_cast<size_t>(t.nv) * nr, 0.0f);
    parallelFor(static_cast<size_t>(t.nv), 0, [&](size_t i) {
        const double v = static_cast<double>(i) * o.dv;
        for (int r = 0; r < nr; ++r) {
            if (static_cast<size_t>(r) > i && i < static_cast<size_t>(nr)) continue;  // filled by symmetry below
            const double rho = r * o.dv;
            double value;
            if (rho == 0 || v == 0) {
                value = g(std::max(rho, v));
            } else {
                // Past the reach of v (i >= nr) ρ < v still holds, so the ρ row's cosines apply.
                const std::vector<double>& cosPhi = cosines[static_cast<size_t>(r)];
                const double sumSq = v * v + rho * rho, twoVRho = 2 * v * rho;
                value = 0;
                for (double cosine : cosPhi) value += g(std::sqrt(std::max(0.0, sumSq - twoVRho * cosine)));
                value /= static_cast<double>(cosPhi.size());
            }
            ring[i * static_cast<size_t>(nr) + static_cast<size_t>(r)] = static_cast<float>(value);
        }
    });
    for (int i = 0; i < nr; ++i)
        for (int r = i + 1; r < nr; ++r) ring[static_cast<size_t>(i) * nr + static_cast<size_t>(r)] = ring[static_cast<size_t>(r) * nr + static_cast<size_t>(i)];

    // h_geo(v, w) = ∫ landing(θ) G(v, NA |w| tan θ) dθ, landing ∝ a(θ) sin θ over the cone (the paths pick
    // directions uniformly in solid angle; a is their transmittance).
    const double thetaMax = pupil.collectionHalfAngle();
    t.geo.assign(t.geoW.size() * static_cast<size_t>(t.nv), 0.0f);
    parallelFor(t.geoW.size(), 0, [&](size_t j) {
        const double reach = pupil.na * t.geoW[j] * tanMax;
        const int n = std::max(16, static_cast<int>(std::ceil(2 * reach / o.dv)));
        std::vector<double> weight(static_cast<size_t>(n)), rhoAt(static_cast<size_t>(n));
        double sum = 0;
        for (int k = 0; k < n; ++k) {
            // Nodes uniform in tan θ (the landing radius), weighted by the density of θ per unit tan θ.
            const double tanT = tanMax * (k + 0.5) / n, theta = std::atan(tanT);
            weight[static_cast<size_t>(k)] = apodization(pupil, std::sin(theta) / std::sin(thetaMax)) * std::sin(theta) / (1 + tanT * tanT);
            rhoAt[static_cast<size_t>(k)] = pupil.na * t.geoW[j] * tanT / o.dv;
            sum += weight[static_cast<size_t>(k)];
        }
        for (int i = 0; i < t.nv; ++i) {
            double value = 0;
            const float* row = &ring[static_cast<size_t>(i) * nr];
            for (int k = 0; k < n; ++k) value += weight[static_cast<size_t>(k)] * linearInRow(row, nr, std::min(rhoAt[static_cast<size_t>(k)], nr - 1.0));
            t.geo[j * static_cast<size_t>(t.nv) + static_cast<size_t>(i)] = static_cast<float>(value / sum);
        }
    });
    return t;
}

}  // namespace

WidefieldPsf::WidefieldPsf(PupilOptions pupil, PsfTableOptions table, std::vector<double> lambdaNodesNm)
    : pupil_(std::move(pupil)), table_(table) {
    pupil_.validate();
    table_.validate();
    if (pupil_.matched()) {
        tables_.push_back(buildTable(pupil_, table_, 0.0));
        return;
    }
    if (lambdaNodesNm.empty()) throw ConfigError("a PSF under an index mismatch needs wavelength nodes");
    std::sort(lambdaNodesNm.begin(), lambdaNodesNm.end());
    for (double l : lambdaNodesNm) {
        if (!(l > 0) || !std::isfinite(l)) throw ConfigError("PSF wavelength nodes must be positive, got " + num(l));
        lambdaNodes_.push_back(l);
        tables_.push_back(buildTable(pupil_, table_, l));
    }
}

const WidefieldPsf::Table& WidefieldPsf::tableAt(double lambdaNm, const Table** other, double* f) const {
    *other = nullptr;
    *f = 0;
    if (tables_.size() == 1) return tables_[0];
    if (lambdaNm <= lambdaNodes_.front()) return tables_.front();
    if (lambdaNm >= lambdaNodes_.back()) return tables_.back();
    const size_t i = static_cast<size_t>(std::upper_bound(lambdaNodes_.begin(), lambdaNodes_.end(), lambdaNm) - lambdaNodes_.begin()) - 1;
    *other = &tables_[i + 1];
    *f = (lambdaNm - lambdaNodes_[i]) / (lambdaNodes_[i + 1] - lambdaNodes_[i]);
    return tables_[i];
}

const WidefieldPsf::Table& WidefieldPsf::samplerTable(double lambdaNm) const {
    // The paths' sampler runs on the nearest table; its densities are that table's.
    const Table* other = nullptr;
    double f = 0;
    const Table& t = tableAt(lambdaNm, &other, &f);
    return other && f > 0.5 ? *other : t;
}

template <class Get>
double WidefieldPsf::interpolateLambda(double lambdaNm, Get&& get) const {
    const Table* other = nullptr;
    double f = 0;
    const Table& t = tableAt(lambdaNm, &other, &f);
    return other ? (1 - f) * get(t) + f * get(*other) : get(t);
}

double WidefieldPsf::tableDensity(double v, double w, double lambdaNm) const {
    const double iv = v / table_.dv;
    return interpolateLambda(lambdaNm, [&](const Table& t) {
        const double iw = w / table_.dw + 0.5 * (t.nw - 1);
        if (!(iv >= 0) || !(iw >= 0) || iv > t.nv - 1 || iw > t.nw - 1) return 0.0;
        const int j = std::min(static_cast<int>(iw), t.nw - 2);
        const float* row = &t.h[static_cast<size_t>(j) * t.nv];
        return lerp(iw - j, cubicInRow(row, t.nv, iv), cubicInRow(row + t.nv, t.nv, iv));
    });
}

double WidefieldPsf::tableGeometric(double v, double w, double lambdaNm) const {
    const Table& t = samplerTable(lambdaNm);
    const double iv = v / table_.dv, iw = geoRow(table_.dw, w);
    if (!(iv >= 0) || iv > t.nv - 1 || !(iw <= static_cast<double>(t.geoW.size()) - 1)) return 0.0;
    const int rows = static_cast<int>(t.geoW.size());
    const int j = std::min(static_cast<int>(iw), rows - 2);
    const float* row = &t.geo[static_cast<size_t>(j) * t.nv];
    return lerp(iw - j, linearInRow(row, t.nv, iv), linearInRow(row + t.nv, t.nv, iv));
}

double WidefieldPsf::density(double rMm, double dzMm, double lambdaNm) const {
    const double k = waveNumberPerMm(lambdaNm), kna = k * pupil_.na;
    return tableDensity(kna * rMm, k * dzMm, lambdaNm) * kna * kna;
}

double WidefieldPsf::enclosed(double dzMm, double lambdaNm) const {
    const double w = waveNumberPerMm(lambdaNm) * dzMm;
    return interpolateLambda(lambdaNm, [&](const Table& t) {
        const double x = w / table_.dw + 0.5 * (t.nw - 1);
        if (!(x >= 0) || x > t.nw - 1) return 0.0;
        const int j = std::min(static_cast<int>(x), t.nw - 2);
        return lerp(x - j, t.enclosed[static_cast<size_t>(j)], t.enclosed[static_cast<size_t>(j) + 1]);
    });
}

double WidefieldPsf::pupilPhase(double rho, double dzMm, double lambdaNm) const {
    const double k = waveNumberPerMm(lambdaNm);
    const double ds = pupil_.sampleIndex * std::sqrt(1 - sqr(pupil_.na * rho / pupil_.sampleIndex));
    double phase = -k * dzMm * ds;
    if (!pupil_.matched()) {
        const double di = pupil_.immersionIndex * std::sqrt(1 - sqr(pupil_.na * rho / pupil_.immersionIndex));
        phase += k * pupil_.depthMm * (ds - focusScale() * di);
    }
    return phase;
}

double WidefieldPsf::cutRadiusMm(double lambdaNm) const { return (tables_[0].nv - 1) * table_.dv / (waveNumberPerMm(lambdaNm) * pupil_.na); }

double WidefieldPsf::maxDzMm(double lambdaNm) const { return std::min(0.5 * (tables_[0].nw - 1) * table_.dw, tables_[0].geoW.back()) / waveNumberPerMm(lambdaNm); }

double WidefieldPsf::sampleDisplacementMm(double u, double lambdaNm) const {
    const Table& t = samplerTable(lambdaNm);
    u = std::clamp(u, 0.0, 1.0);
    const size_t i = std::min(t.cdf.size() - 2, static_cast<size_t>(std::upper_bound(t.cdf.begin(), t.cdf.end(), u) - t.cdf.begin()) - 1);
    // Within the annulus g is linear in v: solve the cubic mass equation by safeguarded Newton steps.
    const double v0 = static_cast<double>(i) * table_.dv, g0 = t.g[i], s = (t.g[i + 1] - g0) / table_.dv;
    const double target = (u - t.cdf[i]) / (2 * kPi);
    double lo = 0, hi = table_.dv, x = 0.5 * table_.dv;
    for (int it = 0; it < 40; ++it) {
        const double f = annulusMass(v0, g0, s, x) - target, df = (g0 + s * x) * (v0 + x);
        if (f > 0) hi = x;
        else lo = x;
        double next = df > 0 ? x - f / df : 0.5 * (lo + hi);
        if (!(next > lo && next < hi)) next = 0.5 * (lo + hi);
        if (std::abs(next - x) < 1e-12 * table_.dv) {
            x = next;
            break;
        }
        x = next;
    }
    return (v0 + x) / (waveNumberPerMm(lambdaNm) * pupil_.na);
}

double WidefieldPsf::displacementDensity(double rMm, double lambdaNm) const {
    const Table& t = samplerTable(lambdaNm);
    const double kna = waveNumberPerMm(lambdaNm) * pupil_.na;
    const double x = kna * rMm / table_.dv;
    if (!(x >= 0) || x > t.nv - 1) return 0.0;
    const int i = std::min(static_cast<int>(x), t.nv - 2);
    return lerp(x - i, t.g[static_cast<size_t>(i)], t.g[static_cast<size_t>(i) + 1]) * kna * kna;
}

double WidefieldPsf::geometricDensity(double rMm, double dzMm, double lambdaNm) const {
    const double k = waveNumberPerMm(lambdaNm), kna = k * pupil_.na;
    return tableGeometric(kna * rMm, k * dzMm, lambdaNm) * kna * kna;
}

double WidefieldPsf::reweight(double rMm, double dzMm, double lambdaNm) const {
    if (std::abs(dzMm) > maxDzMm(lambdaNm)) return 1.0;
    const double k = waveNumberPerMm(lambdaNm), kna = k * pupil_.na;
    const double geo = tableGeometric(kna * rMm, k * dzMm, lambdaNm);
    return geo > 0 ? tableDensity(kna * rMm, k * dzMm, lambdaNm) / geo : 0.0;
}

double WidefieldPsf::fwhmInFocusMm(double lambdaNm, double na) { return 1.61634 / kPi * lambdaNm * 1e-6 / na; }

double pupilDistance(const PupilOptions& a, const PupilOptions& b, double lambdaNm) {
    a.validate();
    b.validate();
    if (a.na != b.na || a.sampleIndex != b.sampleIndex || a.immersionIndex != b.immersionIndex || a.aplanatic != b.aplanatic)
        throw ConfigError("pupilDistance compares pupils of one objective and sample (the same NA, indices and factor)");
    constexpr int kNodes = 256;
    const PupilNodes p = pupilNodes(a, kNodes, lambdaNm), q = pupilNodes(b, kNodes, lambdaNm);
    std::complex<double> overlap = 0;
    for (size_t n = 0; n < p.gl.nodes.size(); ++n)
        overlap += p.gl.weights[n] * p.gl.nodes[n] * std::sqrt(p.intensity[n] * q.intensity[n]) * std::polar(1.0, p.fixedPhase[n] - q.fixedPhase[n]);
    return std::sqrt(std::max(0.0, 2 - 2 * std::abs(overlap) / std::sqrt(p.power * q.power)));
}

}  // namespace fluorosim::optics
