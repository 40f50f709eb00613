#pragma once
// The in-focus diffraction PSF of a circular pupil (Airy pattern), I(v) = (2 J1(v)/v)² with
// v = 2π NA r / λ (λ in vacuum). Camera paths displace their focal-plane point by a sample of it at the
// hero wavelength; the other wavelengths take the spectral-MIS weight PSF_j(δ) / mean_k PSF_k(δ).
// Defocus stays geometric (paths cross the focal plane at the displaced point and spread over the
// collection cone), so it is not counted twice. Truncated at v = vMax (default 60, where 98.9 % of the
// energy is enclosed) and renormalised.
#include <vector>

namespace fluorosim::optics {

class AiryPattern {
public:
    explicit AiryPattern(double vMax = 60, int cells = 24000);
    // Radius (mm) of a sample at wavelength λ (nm) for numerical aperture na, from u in [0, 1).
    double sampleRadiusMm(double u, double lambdaNm, double na) const;
    // Its density per mm² at radius r (the 2-D pdf, zero beyond vMax).
    double densityPerMm2(double rMm, double lambdaNm, double na) const;
    // Full width at half maximum of I: 0.5145 λ/NA.
    static double fwhmMm(double lambdaNm, double na);
    static double intensity(double v);  // (2 J1(v)/v)², 1 at v = 0

private:
    double vMax_;
    std::vector<double> v_, cdf_;
    double norm_ = 0;  // ∫0^vMax I(v) 2π v dv
};

}  // namespace fluorosim::optics
