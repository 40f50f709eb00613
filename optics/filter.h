#pragma once
// Optical filters of the microscope: excitation and emission filters and dichroic mirrors, as
// transmission curves T(λ) in [0, 1] (λ in vacuum nm). A filter is either a measured curve from the
// spectral database (spectra/data/filters, vendor data) or a parametric model tabulated on a grid
// (default 300–900 nm at 1 nm) and interpolated linearly between samples. Outside its table a filter
// transmits 0, as the database curves do; a dichroic there reflects 1.
//
// Parametric edges are logistic: σ(t) = 1/(1 + e^−t) with t = (λ − λ_edge)/s and s = edge/(2 ln 9),
// so `edgeWidthNm` is the 10 %–90 % width of the edge. Between the blocking level Tb = 10^−OD and
// the peak Tp:
//   band-pass   T = Tb + (Tp − Tb) σ((λ − λ1)/s) σ((λ2 − λ)/s),  λ1,2 = centre ∓ FWHM/2
//   long-pass   T = Tb + (Tp − Tb) σ((λ − λc)/s)   (passes long wavelengths, cut-on λc)
//   short-pass  T = Tb + (Tp − Tb) σ((λc − λ)/s)
// At λ1 and λ2 the band-pass is Tp/2 to a relative e^−FWHM/s, and its peak Tp σ(FWHM/(2s))² is
// within 2e^−FWHM/(2s) of Tp: 2.5 % at the narrowest band allowed (FWHM = 2·edge), 10⁻¹⁴ for a
// 45 nm band with 3 nm edges, so FWHM and centre are the given ones. T is (Tp + Tb)/2 at a long- or
// short-pass edge. A dichroic is taken as lossless: reflection R(λ) = 1 − T(λ).
//
// A filter set (fluorescence cube) gives
//   emission path    T_em(λ) = T_dichroic(λ) · T_emission(λ)   (the dichroic transmits the emission)
//   excitation path  T_ex(λ) = T_excitation(λ) · R_dichroic(λ)  (the dichroic reflects the excitation)
// A light-sheet detection arm has no dichroic (the excitation comes from the side): leave it out and
// its factor is 1 in both paths.
#include <optional>
#include <string>

#include "spectral/tabulated_spectrum.h"

namespace fluorosim::spectra {
class Database;
}

namespace fluorosim::optics {

// Wavelength grid on which parametric filters are tabulated: minNm, minNm + stepNm, …, up to maxNm.
struct FilterGrid {
    double minNm = 300, maxNm = 900, stepNm = 1;
    void validate() const;  // throws ConfigError
};

struct BandPassOptions {
    double centreNm = 525;
    double fwhmNm = 45;
    double peakTransmission = 0.95;  // in (0, 1]
    double edgeWidthNm = 3;          // 10 %–90 % width of each edge, > 0, at most FWHM/2
    double blockingOd = 6;           // out-of-band transmission 10^−OD, OD in (0, 12]
    void validate() const;  // throws ConfigError naming the field and value
};

// Long-pass or short-pass edge (dichroic mirrors, edge filters).
struct EdgeFilterOptions {
    double edgeNm = 495;             // cut-on (long-pass) or cut-off (short-pass) wavelength
    double edgeWidthNm = 3;          // 10 %–90 % width, > 0
    double peakTransmission = 0.95;  // in the pass band, in (0, 1]
    double blockingOd = 2;           // in the reflection band; dichroics are not built for deep blocking
    void validate() const;  // throws ConfigError naming the field and value
};

class Filter {
public:
    // A measured or computed curve. Throws ConfigError (naming `name` and the wavelength) for a
    // transmission above 1; TabulatedSpectrum already rejects negative values.
    Filter(std::string name, TabulatedSpectrum transmission);

    static Filter bandPass(const BandPassOptions& options, const FilterGrid& grid = {});
    static Filter longPass(const EdgeFilterOptions& options, const FilterGrid& grid = {});
    static Filter shortPass(const EdgeFilterOptions& options, const FilterGrid& grid = {});
    // A vendor curve from the spectral database, e.g. "semrock_FF01-525-45" (ConfigError with
    // suggestions for an unknown name).
    static Filter fromDatabase(const spectra::Database& db, const std::string& name);
    // No filter: T = 1 from 1 nm to 10⁶ nm.
    static Filter open();

    const std::string& name() const { return name_; }
    double transmission(double lambdaNm) const { return curve_(lambdaNm); }
    double operator()(double lambdaNm) const { return curve_(lambdaNm); }
    // For a dichroic: lossless, R = 1 − T.
    double reflection(double lambdaNm) const { return 1.0 - curve_(lambdaNm); }
    const TabulatedSpectrum& curve() const { return curve_; }

private:
    std::string name_;
    TabulatedSpectrum curve_;
};

struct FilterSet {
    std::string name;
    Filter excitation = Filter::open();
    std::optional<Filter> dichroic;  // none in a light-sheet detection arm
    Filter emission = Filter::open();

    double emissionPath(double lambdaNm) const;    // T_dichroic · T_emission
    double excitationPath(double lambdaNm) const;  // T_excitation · R_dichroic
    // The emission path tabulated on a grid (e.g. for a detector's spectral response).
    TabulatedSpectrum emissionPathCurve(const FilterGrid& grid = {}) const;
};

// The half-maximum band around the highest point of a curve: the crossings of half its peak value,
// interpolated linearly between samples. A side that never falls to half ends at the table's end
// (e.g. the upper side of a long-pass).
struct PassBand {
    double lowNm = 0, highNm = 0;
    double peakNm = 0, peakTransmission = 0;
    double centreNm() const { return 0.5 * (lowNm + highNm); }
    double fwhmNm() const { return highNm - lowNm; }
};
PassBand measurePassBand(const TabulatedSpectrum& curve);

// Fraction of a dye's emitted photons the emission path transmits, ∫ E(λ) T_em(λ) dλ / ∫ E(λ) dλ
// (midpoint rule, 0.05 nm steps over the emission table). Throws ConfigError for an emission
// spectrum with no signal.
double emissionPathEfficiency(const FilterSet& set, const TabulatedSpectrum& emission);

// A warning (not an error: the render is still valid, just dark) when the emission path transmits
// less than `minEfficiency` of the dye's emission, e.g. AF647 behind a 525/45 filter. nullopt when
// the filter set passes enough.
std::optional<std::string> emissionBlockingWarning(const FilterSet& set, const TabulatedSpectrum& emission,
                                                   const std::string& dyeName, double minEfficiency = 1e-3);

}  // namespace fluorosim::optics
