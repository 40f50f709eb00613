// The 3-D widefield PSF (optics/widefield_psf.h) against closed forms and independent integrals: with a
// uniform pupil the Airy pattern in focus, the on-axis intensity, the paraxial sinc² law; Parseval's
// energy; the aplanatic pupil against the Richards–Wolf integral and geometric optics; the Gibson–Lanni
// mismatch against brute force; the pupil distance against the PSFs' difference; the displacement
// sampler (chi-square), the geometric landing density against a Monte Carlo histogram, and table
// refinement.
#include <gtest/gtest.h>

#include <cmath>
#include <complex>
#include <cstdio>

#include "core/errors.h"
#include "core/math.h"
#include "core/rng.h"
#include "optics/widefield_psf.h"

namespace fluorosim {
namespace {

using optics::PsfTableOptions;
using optics::PupilOptions;
using optics::WidefieldPsf;

// A uniform pupil (no aplanatic factor), as the textbook closed forms assume.
PupilOptions water(double na = 0.8) {
    PupilOptions p;
    p.na = na;
    p.aplanatic = false;
    return p;
}

double airy(double v) {  // per unit v-area, normalised over the plane
    if (v < 1e-8) return 1 / (4 * kPi);
    const double j = std::cyl_bessel_j(1.0, v) / v;
    return j * j / kPi;
}

// The amplitude by brute force: U(v, w) = ∫ A e^{iΦ} J0(vρ) ρ dρ by the composite Simpson rule.
std::complex<double> bruteAmplitude(const PupilOptions& p, double v, double w, double extraPhasePerRho(double) = nullptr, int n = 20000) {
    std::complex<double> sum = 0;
    for (int i = 0; i <= n; ++i) {
        const double rho = double(i) / n, weight = (i == 0 || i == n) ? 1 : (i % 2 ? 4 : 2);
        const double cosS = std::sqrt(1 - sqr(p.na * rho / p.sampleIndex));
        // A point w = k dz toward the objective is k dz nearer: its sample path is shorter.
        const double phase = -w * p.sampleIndex * cosS + (extraPhasePerRho ? extraPhasePerRho(rho) : 0.0);
        sum += weight * std::polar(rho * std::cyl_bessel_j(0.0, v * rho), phase);
    }
    return sum / (3.0 * n);
}

TEST(WidefieldPsf, InFocusIsTheAiryPattern) {
    const WidefieldPsf psf(water());
    // Near the Airy zeros the interpolated table is compared in units of the peak; elsewhere relatively.
    double worstAbsolute = 0, worstRelative = 0;
    for (double v = 0; v <= 40; v += 0.037) {
        const double expected = airy(v), error = std::abs(psf.tableDensity(v, 0, 520) - expected);
        worstAbsolute = std::max(worstAbsolute, error / airy(0));
        if (expected > 0.1 * airy(0)) worstRelative = std::max(worstRelative, error / expected);
    }
    std::printf("  against the Airy pattern: largest error %.2e of the peak, %.2e relative where above 10%% of the peak\n", worstAbsolute, worstRelative);
    EXPECT_LT(worstAbsolute, 5e-4);
    EXPECT_LT(worstRelative, 1e-3);
    // Half maximum at 0.5145 λ/NA.
    const double lambda = 520, na = 0.8, half = 0.5 * WidefieldPsf::fwhmInFocusMm(lambda, na);
    EXPECT_NEAR(psf.density(half, 0, lambda) / psf.density(0, 0, lambda), 0.5, 2e-3);
}

TEST(WidefieldPsf, OnAxisFollowsTheClosedFormAndTheParaxialLaw) {
    // Uniform pupil in ρ: ρ dρ = (n/NA)² cos θ sin θ dθ, so U(0, w) ∝ ∫_{cosθm}^1 c e^{i w n c} dc, which
    // has a closed form; normalised by its value in focus.
    for (double na : {0.8, 1.0}) {
        const PupilOptions p = water(na);
        const WidefieldPsf psf(p);
        const double n = p.sampleIndex, c0 = std::sqrt(1 - sqr(na / n));
        auto onAxis = [&](double w) {
            const double a = w * n;
            std::complex<double> integral;
            if (std::abs(a) < 1e-9) integral = 0.5 * (1 - c0 * c0);
            else {
                const std::complex<double> i(0, 1);
                auto F = [&](double c) { return std::exp(i * a * c) * (c / (i * a) + 1.0 / (a * a)); };
                integral = F(1.0) - F(c0);
            }
            return std::norm(integral);
        };
        double worst = 0;
        for (double w = -60; w <= 60; w += 1.3) {
            const double expected = onAxis(w) / onAxis(0) * psf.tableDensity(0, 0, 500);
            worst = std::max(worst, std::abs(psf.tableDensity(0, w, 500) - expected) / psf.tableDensity(0, 0, 500));
        }
        std::printf("  NA %.1f: on-axis intensity against the closed form, largest error %.2e of the peak\n", na, worst);
        EXPECT_LT(worst, 2e-3);
    }
    // Paraxial: NA 0.1, I(0, u) ∝ (sin(u/4)/(u/4))², u = k NA² dz / n = w NA² / n.
    const PupilOptions p = water(0.1);
    const WidefieldPsf psf(p);
    double worst = 0;
    for (double w = -150; w <= 150; w += 2.1) {
        const double u = w * p.na * p.na / p.sampleIndex;
        const double sinc = std::abs(u) < 1e-9 ? 1.0 : std::sin(u / 4) / (u / 4);
        worst = std::max(worst, std::abs(psf.tableDensity(0, w, 500) / psf.tableDensity(0, 0, 500) - sinc * sinc));
    }
    std::printf("  NA 0.1: against the paraxial sinc² law, largest error %.2e of the peak\n", worst);
    EXPECT_LT(worst, 1e-2);
}

TEST(WidefieldPsf, EnergyIsTheSameInEveryPlaneUpToTheCut) {
    const WidefieldPsf psf(water());
    for (double dzUm : {0.0, 1.0, 3.0, 10.0}) {
        const double enclosed = psf.enclosed(dzUm * 1e-3, 520);
        // Beyond the cut the in-focus tail holds about 2/(π v) (Airy's asymptote).
        const double tail = 2 / (kPi * psf.table().vCut);
        std::printf("  dz %4.1f um: enclosed %.5f, with the asymptotic tail %.5f\n", dzUm, enclosed, enclosed + tail);
        EXPECT_NEAR(enclosed + tail, 1.0, 3e-3);
    }
}

TEST(WidefieldPsf, ConstantApodizationChangesNothingAndAStrongOneWidens) {
    PupilOptions flat = water();
    flat.intensityApodization = {0.5, 0.5, 0.5};
    PupilOptions steep = water();
    steep.intensityApodization = {1.0, 0.6, 0.2};
    const WidefieldPsf plain(water()), constant(flat), apodised(steep);
    for (double v : {0.0, 1.0, 2.5, 5.0})
        EXPECT_NEAR(constant.tableDensity(v, 7.0, 500), plain.tableDensity(v, 7.0, 500), 1e-6 * plain.tableDensity(0, 0, 500));
    // A pupil darker at its edge makes the in-focus core wider: the peak per unit energy drops (by about 4 %
    // for this ramp, since the peak is (∫√a ρ dρ)² / ∫a ρ dρ relative to a uniform pupil).
    EXPECT_LT(apodised.tableDensity(0, 0, 500), 0.98 * plain.tableDensity(0, 0, 500));
    // Against brute force with the same amplitude.
    auto bruteApodised = [&](double v, double w) {
        std::complex<double> sum = 0;
        const int n = 20000;
        double power = 0;
        for (int i = 0; i <= n; ++i) {
            const double rho = double(i) / n, weight = (i == 0 || i == n) ? 1 : (i % 2 ? 4 : 2);
            const double a = rho < 0.5 ? lerp(rho / 0.5, 1.0, 0.6) : lerp((rho - 0.5) / 0.5, 0.6, 0.2);
            const double cosS = std::sqrt(1 - sqr(steep.na * rho / steep.sampleIndex));
            sum += weight * std::polar(rho * std::sqrt(a) * std::cyl_bessel_j(0.0, v * rho), w * steep.sampleIndex * cosS);
            power += weight * rho * a;
        }
        return std::norm(sum / (3.0 * n)) / (2 * kPi * power / (3.0 * n));
    };
    for (double v : {0.0, 2.0, 6.0})
        for (double w : {0.0, 10.0})
            EXPECT_NEAR(apodised.tableDensity(v, w, 500), bruteApodised(v, w), 2e-3 * apodised.tableDensity(0, 0, 500)) << v << " " << w;
}

TEST(WidefieldPsf, AplanaticPupilIsTheRichardsWolfIntegralAndTendsToTheGeometricDisc) {
    // An aplanatic objective collecting an isotropic emitter: in the angle θ of the sample the scalar
    // Richards–Wolf amplitude is U ∝ ∫0^θm √cos θ sin θ J0(k r n sin θ) e^{−i k dz n cos θ} dθ, an integral
    // independent of the table's pupil coordinate.
    PupilOptions p = water();
    p.aplanatic = true;
    const WidefieldPsf psf(p);
    const double n = p.sampleIndex, thetaM = std::asin(p.na / n);
    auto richardsWolf = [&](double v, double w) {
        std::complex<double> sum = 0;
        const int steps = 20000;
        for (int i = 0; i <= steps; ++i) {
            const double t = thetaM * i / steps, weight = (i == 0 || i == steps) ? 1 : (i % 2 ? 4 : 2);
            sum += weight * std::polar(std::sqrt(std::cos(t)) * std::sin(t) * std::cyl_bessel_j(0.0, v * std::sin(t) / std::sin(thetaM)),
                                       -w * n * std::cos(t));
        }
        return std::norm(sum);
    };
    const double peak = psf.tableDensity(0, 0, 520), reference = richardsWolf(0, 0);
    double worst = 0;
    for (double v : {0.0, 1.0, 2.5, 4.0, 7.0})
        for (double w : {-12.0, 0.0, 5.0, 20.0})
            worst = std::max(worst, std::abs(psf.tableDensity(v, w, 520) / peak - richardsWolf(v, w) / reference));
    std::printf("  aplanatic pupil against the Richards-Wolf integral in theta: largest error %.2e of the peak\n", worst);
    EXPECT_LT(worst, 2e-3);
    // The factor narrows the in-focus core (the pupil's edge weighs more).
    auto halfWidth = [](const WidefieldPsf& h) {
        double lo = 0, hi = 3;
        for (int i = 0; i < 60; ++i) {
            const double mid = 0.5 * (lo + hi);
            (h.tableDensity(mid, 0, 520) > 0.5 * h.tableDensity(0, 0, 520) ? lo : hi) = mid;
        }
        return lo;
    };
    const WidefieldPsf uniform(water());
    const double narrowing = halfWidth(psf) / halfWidth(uniform) - 1;
    std::printf("  in-focus FWHM, aplanatic against a uniform pupil at NA 0.8 in water: %+.2f %%\n", 100 * narrowing);
    EXPECT_LT(narrowing, -0.005);
    // Far from focus both tend to geometric optics. The emitter's light is uniform in solid angle, so the
    // disc within the landing radius of θ1 holds (1 − cos θ1)/(1 − cos θm); a uniform pupil puts
    // sin²θ1/sin²θm there instead. θ1 halves the pupil's area: 0.472 against 0.5. Diffraction adds the
    // same small, oscillating excess to both (Fresnel zones at the disc's edge), so their difference is
    // the sharp test.
    const double sin1 = std::sin(thetaM) / std::sqrt(2.0), cos1 = std::sqrt(1 - sin1 * sin1);
    const double geometric = (1 - cos1) / (1 - std::cos(thetaM));
    for (double w : {100.0, 190.0}) {
        const double v1 = w * p.na * sin1 / cos1;
        auto encircled = [&](const WidefieldPsf& h) {  // h holds 1 over the whole plane (Parseval)
            double inside = 0;
            const double dv = 0.01;
            for (double v = 0.5 * dv; v < v1; v += dv) inside += h.tableDensity(v, w, 520) * 2 * kPi * v * dv;
            return inside;
        };
        const double aplanatic = encircled(psf), flat = encircled(uniform);
        std::printf("  w %3.0f: energy within the landing radius of theta1: aplanatic %.4f, uniform pupil %.4f; geometric optics %.4f and 0.5\n", w,
                    aplanatic, flat, geometric);
        EXPECT_NEAR(aplanatic - flat, geometric - 0.5, 1.5e-3) << "w " << w;
        EXPECT_NEAR(aplanatic, geometric, 0.01) << "w " << w;
    }
}

TEST(WidefieldPsf, MismatchReducesToTheMatchedCaseAndAgreesWithBruteForce) {
    PupilOptions same = water();
    same.depthMm = 0.1;  // a depth with equal indices changes nothing
    const WidefieldPsf matched(water()), sameIndex(same);
    for (double v : {0.0, 3.0})
        for (double w : {-20.0, 0.0, 20.0}) EXPECT_DOUBLE_EQ(sameIndex.tableDensity(v, w, 520), matched.tableDensity(v, w, 520));

    // Cleared tissue (n 1.45) behind water immersion, 100 µm deep (0.45 rad RMS of spherical aberration).
    PupilOptions p = water(0.8);
    p.sampleIndex = 1.45;
    p.depthMm = 0.1;
    const WidefieldPsf psf(p, {}, {500, 520, 540});
    const double k = 2 * kPi / (520e-6);
    // The same phase as the table's: k d (n_s cos θ_s − f n_i cos θ_i) with f the least-squares best focus.
    const int n = 4000;
    double wsum = 0, ms = 0, mi = 0, sss = 0, sis = 0;
    std::vector<double> ds(n + 1), di(n + 1);
    for (int i = 0; i <= n; ++i) {
        const double rho = double(i) / n;
        ds[i] = p.sampleIndex * std::sqrt(1 - sqr(p.na * rho / p.sampleIndex));
        di[i] = p.immersionIndex * std::sqrt(1 - sqr(p.na * rho / p.immersionIndex));
        wsum += rho, ms += rho * ds[i], mi += rho * di[i];
    }
    for (int i = 0; i <= n; ++i) {
        const double rho = double(i) / n;
        sss += rho * sqr(ds[i] - ms / wsum);
        sis += rho * (di[i] - mi / wsum) * (ds[i] - ms / wsum);
    }
    static double f, kd;
    static PupilOptions pp;
    f = sss / sis, kd = k * p.depthMm, pp = p;
    auto aberration = [](double rho) {
        const double a = pp.sampleIndex * std::sqrt(1 - sqr(pp.na * rho / pp.sampleIndex)), b = pp.immersionIndex * std::sqrt(1 - sqr(pp.na * rho / pp.immersionIndex));
        return kd * (a - f * b);
    };
    double worst = 0;
    const double peak = psf.tableDensity(0, 0, 520);
    for (double v : {0.0, 1.5, 4.0})
        for (double w : {-30.0, -8.0, 0.0, 8.0, 30.0}) {
            const double expected = std::norm(bruteAmplitude(p, v, w, aberration)) / (kPi);  // ∫ρ dρ = 1/2, norm 2π/2
            worst = std::max(worst, std::abs(psf.tableDensity(v, w, 520) - expected) / peak);
        }
    std::printf("  n_s 1.45 under water, 100 um deep: largest error against brute force %.2e of the peak\n", worst);
    EXPECT_LT(worst, 3e-3);
    // The paraxial and marginal foci against ray tracing. A ray leaving an on-axis point at depth z in the
    // sample at angle θ_s refracts into θ_i; traced back through the immersion medium it meets the axis at
    // depth z tan θ_s / tan θ_i: the objective (nominally focused f d deep) sees the zone of that ray in
    // focus for the point at z = f d tan θ_i / tan θ_s, i.e. at dz = d − z toward the objective. In the
    // phase the same zone is stationary where ∂Φ/∂ρ = 0.
    {
        const double fd = psf.focusScale() * p.depthMm;
        auto rayTraced = [&](double rho) {
            const double sinS = p.na * rho / p.sampleIndex, sinI = p.na * rho / p.immersionIndex;
            const double ratio = rho < 1e-6 ? p.sampleIndex / p.immersionIndex : (sinI / std::sqrt(1 - sinI * sinI)) / (sinS / std::sqrt(1 - sinS * sinS));
            return p.depthMm - fd * ratio;
        };
        auto stationary = [&](double rho) {  // dz where ∂Φ/∂ρ = 0 (Φ is linear in dz)
            const double h = 1e-6;
            const double r = std::max(rho, 1e-3);
            const double a = (psf.pupilPhase(r + h, 0, 520) - psf.pupilPhase(r - h, 0, 520)) / (2 * h);
            const double b = (psf.pupilPhase(r + h, 1e-3, 520) - psf.pupilPhase(r - h, 1e-3, 520)) / (2 * h) - a;  // per mm of dz, × 1e-3
            return -a / b * 1e-3;
        };
        for (double rho : {1e-3, 0.5, 0.999}) {
            std::printf("  zone rho %.3f: in focus at dz %+.4f um (phase), %+.4f um (ray tracing)\n", rho, stationary(rho) * 1e3, rayTraced(rho) * 1e3);
            EXPECT_NEAR(stationary(rho), rayTraced(rho), 2e-6) << "rho " << rho;
        }
        // The figures: paraxial focus 1.84 um toward the objective, marginal 2.47 um away from it.
        EXPECT_NEAR(rayTraced(0) * 1e3, 1.845, 0.01);
        EXPECT_NEAR(rayTraced(1) * 1e3, -2.475, 0.01);
    }
    // A spherical aberration makes the axial profile asymmetric about the best focus.
    const double asymmetry = std::abs(psf.tableDensity(0, 15, 520) - psf.tableDensity(0, -15, 520)) / peak;
    std::printf("  axial asymmetry at w = ±15: %.3f of the peak\n", asymmetry);
    EXPECT_GT(asymmetry, 0.03);  // 0.043 by the brute-force amplitude
}

TEST(WidefieldPsf, PupilDistanceBoundsHowFarTwoPsfsDiffer) {
    // Two focus depths under a mismatch, and two apodisations: the intensity PSFs (unit energy) differ by
    // at most twice the pupils' distance in L1 over the plane, and the distance is 0 for equal pupils.
    PupilOptions a = water(0.8);
    a.aplanatic = true;
    a.sampleIndex = 1.45;
    a.depthMm = 0.03;
    EXPECT_DOUBLE_EQ(optics::pupilDistance(a, a, 520), 0.0);
    for (double otherDepthUm : {30.5, 31.0, 33.0}) {
        PupilOptions b = a;
        b.depthMm = otherDepthUm * 1e-3;
        const double distance = optics::pupilDistance(a, b, 520);
        const WidefieldPsf ha(a, {}, {520}), hb(b, {}, {520});
        double l1 = 0;
        const double dv = 0.05;
        for (double w : {-10.0, 0.0, 10.0}) {
            double sum = 0;
            for (double v = 0.5 * dv; v < 60; v += dv) sum += std::abs(ha.tableDensity(v, w, 520) - hb.tableDensity(v, w, 520)) * 2 * kPi * v * dv;
            l1 = std::max(l1, sum);
        }
        std::printf("  depth 30 against %.1f um in n 1.45: pupil distance %.4f, largest L1 of the PSFs' difference %.4f\n", otherDepthUm, distance, l1);
        EXPECT_GT(distance, 0.0);
        EXPECT_LE(l1, 2 * distance);
    }
    PupilOptions c = water(0.8), d = c;
    d.intensityApodization = {1.0, 0.9, 0.7};
    EXPECT_GT(optics::pupilDistance(c, d, 520), 0.0);
    PupilOptions other = a;
    other.sampleIndex = 1.52;
    EXPECT_THROW(optics::pupilDistance(a, other, 520), ConfigError);
}

TEST(WidefieldPsf, DisplacementSamplerFollowsItsDensity) {
    const WidefieldPsf psf(water());
    const double lambda = 600, cut = psf.cutRadiusMm(lambda);
    // Bins in r² (equal area) over the core, chi-square of the counts against the density's masses.
    const int bins = 40, samples = 400000;
    const double rMax = 4 * WidefieldPsf::fwhmInFocusMm(lambda, 0.8);
    std::vector<double> counts(bins + 1, 0.0), expected(bins + 1, 0.0);
    Rng rng(7, 1);
    for (int s = 0; s < samples; ++s) {
        const double r = psf.sampleDisplacementMm(rng.uniform(), lambda);
        const int b = r >= rMax ? bins : static_cast<int>(r * r / (rMax * rMax) * bins);
        counts[static_cast<size_t>(b)] += 1;
    }
    double inside = 0;
    for (int b = 0; b < bins; ++b) {
        const int sub = 200;
        for (int k = 0; k < sub; ++k) {
            const double r2a = rMax * rMax * (b + double(k) / sub) / bins, r2b = rMax * rMax * (b + double(k + 1) / sub) / bins;
            const double r = std::sqrt(0.5 * (r2a + r2b));
            expected[static_cast<size_t>(b)] += psf.displacementDensity(r, lambda) * kPi * (r2b - r2a) * samples;
        }
        inside += expected[static_cast<size_t>(b)];
    }
    expected[bins] = samples - inside;
    double chi2 = 0;
    for (int b = 0; b <= bins; ++b) chi2 += sqr(counts[static_cast<size_t>(b)] - expected[static_cast<size_t>(b)]) / expected[static_cast<size_t>(b)];
    std::printf("  chi-square %.1f for %d degrees of freedom (cut at %.1f um)\n", chi2, bins, cut * 1e3);
    EXPECT_LT(chi2, bins + 5 * std::sqrt(2.0 * bins));
}

TEST(WidefieldPsf, LandingDensityMatchesAMonteCarloOfThePathsSampling) {
    PupilOptions p = water();
    p.intensityApodization = {1.0, 0.8, 0.5};  // a scattering medium over the cone
    const WidefieldPsf psf(p);
    const double lambda = 520, k = 2 * kPi / (lambda * 1e-6), thetaMax = p.collectionHalfAngle();
    Rng rng(11, 2);
    for (double dzUm : {0.0, 1.5, 6.0}) {
        const double dz = dzUm * 1e-3;
        // The paths' sampling: a displacement from g, a direction uniform in solid angle over the cone with
        // weight a(θ), landing at the displaced point + dz tan θ in the direction's azimuth.
        const int samples = 300000, bins = 30;
        const double rMax = std::max(3 * WidefieldPsf::fwhmInFocusMm(lambda, p.na), 1.3 * dz * std::tan(thetaMax));
        std::vector<double> counts(bins, 0.0);
        double total = 0;
        for (int s = 0; s < samples; ++s) {
            const double r = psf.sampleDisplacementMm(rng.uniform(), lambda), a = 2 * kPi * rng.uniform();
            const double cosT = 1 - rng.uniform() * (1 - std::cos(thetaMax)), sinT = std::sqrt(1 - cosT * cosT);
            const double phi = 2 * kPi * rng.uniform();
            const double x = std::min(1.0, sinT / std::sin(thetaMax));
            const double weight = x < 0.5 ? lerp(2 * x, 1.0, 0.8) : lerp(2 * x - 1, 0.8, 0.5);
            const double px = r * std::cos(a) + dz * sinT / cosT * std::cos(phi), py = r * std::sin(a) + dz * sinT / cosT * std::sin(phi);
            const double d = std::hypot(px, py);
            total += weight;
            if (d < rMax) counts[static_cast<size_t>(d * d / (rMax * rMax) * bins)] += weight;
        }
        double worst = 0;
        for (int b = 0; b < bins; ++b) {
            const double r2a = rMax * rMax * b / bins, r2b = rMax * rMax * (b + 1) / bins;
            double mass = 0;
            for (int q = 0; q < 40; ++q) {
                const double r = std::sqrt(r2a + (r2b - r2a) * (q + 0.5) / 40);
                mass += psf.geometricDensity(r, dz, lambda) * kPi * (r2b - r2a) / 40;
            }
            const double observed = counts[static_cast<size_t>(b)] / total;
            const double sigma = std::sqrt(mass / samples) + 1e-12;
            worst = std::max(worst, std::abs(observed - mass) / sigma);
        }
        std::printf("  dz %.1f um: largest |z| of the landing histogram against h_geo %.2f\n", dzUm, worst);
        EXPECT_LT(worst, 5.0);
        // The reweight turns h_geo into the model PSF, and stays bounded inside the cut.
        double largest = 0;
        for (double r = 0; r < psf.cutRadiusMm(lambda); r += 2e-5) {
            const double w = psf.reweight(r, dz, lambda);
            if (psf.geometricDensity(r, dz, lambda) > 0) {
                EXPECT_NEAR(w * psf.geometricDensity(r, dz, lambda), psf.density(r, dz, lambda), 1e-6 * psf.density(0, 0, lambda));
            }
            largest = std::max(largest, w);
        }
        std::printf("  dz %.1f um: largest reweight %.2f\n", dzUm, largest);
        EXPECT_LT(largest, 100.0);
        (void)k;
    }
}

TEST(WidefieldPsf, FinerTablesChangeTheDensityBelowTheStatedBound) {
    PsfTableOptions fine;
    fine.dv = 0.125;
    fine.dw = 0.25;
    fine.pupilNodes = 800;
    const WidefieldPsf psf(water()), finer(water(), fine);
    double worst = 0, worstGeo = 0;
    const double peak = psf.tableDensity(0, 0, 500);
    for (double v = 0; v < 30; v += 0.31)
        for (double w = -60; w <= 60; w += 1.7) {
            worst = std::max(worst, std::abs(psf.tableDensity(v, w, 500) - finer.tableDensity(v, w, 500)) / peak);
            worstGeo = std::max(worstGeo, std::abs(psf.tableGeometric(v, w, 500) - finer.tableGeometric(v, w, 500)) / peak);
        }
    // The geometric density is only the paths' sampling density (any positive density is unbiased); it is
    // printed, not bounded.
    std::printf("  default against finer tables: model %.2e, geometric %.2e of the peak\n", worst, worstGeo);
    EXPECT_LT(worst, 2e-3);
}

TEST(WidefieldPsf, BadOptionsAreRefusedNamingTheField) {
    PupilOptions p = water();
    p.na = 1.4;
    EXPECT_THROW(WidefieldPsf{p}, ConfigError);
    p = water();
    p.intensityApodization = {0.0, 1.0};
    EXPECT_THROW(WidefieldPsf{p}, ConfigError);
    PsfTableOptions t;
    t.dv = 0;
    EXPECT_THROW((WidefieldPsf{water(), t}), ConfigError);
    p = water();
    p.sampleIndex = 1.45;
    p.depthMm = 0.01;
    EXPECT_THROW(WidefieldPsf{p}, ConfigError);  // a mismatch needs wavelength nodes
    try {
        p = water();
        p.na = -1;
        WidefieldPsf{p};
    } catch (const ConfigError& e) {
        EXPECT_NE(std::string(e.what()).find("numerical aperture"), std::string::npos);
    }
}

}  // namespace
}  // namespace fluorosim
