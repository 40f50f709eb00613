#include "optics/filter.h"

#include <algorithm>
#include <cmath>
#include <functional>
#include <utility>
#include <vector>

#include "core/errors.h"
#include "core/message.h"
#include "database.h"

namespace fluorosim::optics {
namespace {

std::string num(double v) { return messageNumber(v); }

void requirePositive(double v, const std::string& field, const std::string& unit) {
    if (!(v > 0) || !std::isfinite(v)) throw ConfigError(field + ": must be positive and finite, got " + num(v) + unit);
}

void requireTransmission(double t, const std::string& field) {
    if (!(t > 0 && t <= 1)) throw ConfigError(field + ": must lie in (0, 1], got " + num(t));
}

void requireBlocking(double od, double peak, const std::string& what) {
    if (!(od > 0 && od <= 12)) throw ConfigError(what + " blockingOd: must lie in (0, 12], got " + num(od));
    if (!(std::pow(10.0, -od) < peak))
        throw ConfigError(what + " blockingOd: the blocking level 10^-" + num(od) + " must lie below the peak transmission " +
                          num(peak));
}

double logistic(double t) { return 1.0 / (1.0 + std::exp(-t)); }

// s of σ((λ − λ0)/s) whose 10 %–90 % rise is `width` nm: σ(±ln 9) = 0.1, 0.9.
double edgeScale(double width) { return width / (2.0 * std::log(9.0)); }

TabulatedSpectrum tabulate(const FilterGrid& grid, const std::function<double(double)>& f, const std::string& name) {
    grid.validate();
    std::vector<double> lambda, value;
    const auto n = static_cast<size_t>(std::floor((grid.maxNm - grid.minNm) / grid.stepNm + 1e-9));
    for (size_t i = 0; i <= n; ++i) {
        const double l = grid.minNm + static_cast<double>(i) * grid.stepNm;
        lambda.push_back(l);
        value.push_back(f(l));
    }
    if (lambda.back() < grid.maxNm - 1e-9 * grid.stepNm) {
        lambda.push_back(grid.maxNm);
        value.push_back(f(grid.maxNm));
    }
    return TabulatedSpectrum(std::move(lambda), std::move(value), name);
}

Filter edgeFilter(const EdgeFilterOptions& o, const FilterGrid& grid, bool longPass) {
    o.validate();
    const double s = edgeScale(o.edgeWidthNm), tb = std::pow(10.0, -o.blockingOd), tp = o.peakTransmission;
    const std::string name = std::string(longPass ? "long-pass " : "short-pass ") + num(o.edgeNm);
    return {name, tabulate(grid, [&](double l) { return tb + (tp - tb) * logistic((longPass ? l - o.edgeNm : o.edgeNm - l) / s); },
                           name)};
}

}  // namespace

void FilterGrid::validate() const {
    requirePositive(minNm, "filter grid minNm", " nm");
    requirePositive(stepNm, "filter grid stepNm", " nm");
    if (!(maxNm > minNm) || !std::isfinite(maxNm))
        throw ConfigError("filter grid maxNm: must be finite and above minNm = " + num(minNm) + " nm, got " + num(maxNm) + " nm");
    if ((maxNm - minNm) / stepNm > 1e7)
        throw ConfigError("filter grid stepNm: " + num(stepNm) + " nm gives more than 10^7 samples over " + num(minNm) +
                          "-" + num(maxNm) + " nm");
}

void BandPassOptions::validate() const {
    requirePositive(centreNm, "band-pass centreNm", " nm");
    requirePositive(fwhmNm, "band-pass fwhmNm", " nm");
    if (!(fwhmNm < 2 * centreNm))
        throw ConfigError("band-pass fwhmNm: " + num(fwhmNm) + " nm would reach below 0 nm around the centre " + num(centreNm) +
                          " nm");
    requireTransmission(peakTransmission, "band-pass peakTransmission");
    requirePositive(edgeWidthNm, "band-pass edgeWidthNm", " nm");
    // Narrower bands would not reach their peak, and the FWHM would no longer be the given one.
    if (!(2 * edgeWidthNm <= fwhmNm))
        throw ConfigError("band-pass edgeWidthNm: must be at most half of fwhmNm = " + num(fwhmNm) + " nm, got " +
                          num(edgeWidthNm) + " nm");
    requireBlocking(blockingOd, peakTransmission, "band-pass");
}

void EdgeFilterOptions::validate() const {
    requirePositive(edgeNm, "edge filter edgeNm", " nm");
    requirePositive(edgeWidthNm, "edge filter edgeWidthNm", " nm");
    requireTransmission(peakTransmission, "edge filter peakTransmission");
    requireBlocking(blockingOd, peakTransmission, "edge filter");
}

Filter::Filter(std::string name, TabulatedSpectrum transmission) : name_(std::move(name)), curve_(std::move(transmission)) {
    if (curve_.empty()) throw ConfigError("filter \"" + name_ + "\": empty transmission curve");
    const auto& v = curve_.values();
    for (size_t i = 0; i < v.size(); ++i)
        if (v[i] > 1.0)
            throw ConfigError("filter \"" + name_ + "\": transmission must lie in [0, 1], got " + num(v[i]) + " at " +
                              num(curve_.wavelengths()[i]) + " nm");
}

Filter Filter::bandPass(const BandPassOptions& o, const FilterGrid& grid) {
    o.validate();
    const double s = edgeScale(o.edgeWidthNm), tb = std::pow(10.0, -o.blockingOd), tp = o.peakTransmission;
    const double l1 = o.centreNm - o.fwhmNm / 2, l2 = o.centreNm + o.fwhmNm / 2;
    const std::string name = "band-pass " + num(o.centreNm) + "/" + num(o.fwhmNm);
    return {name, tabulate(grid, [&](double l) { return tb + (tp - tb) * logistic((l - l1) / s) * logistic((l2 - l) / s); },
                           name)};
}

Filter Filter::longPass(const EdgeFilterOptions& o, const FilterGrid& grid) { return edgeFilter(o, grid, true); }
Filter Filter::shortPass(const EdgeFilterOptions& o, const FilterGrid& grid) { return edgeFilter(o, grid, false); }

Filter Filter::fromDatabase(const spectra::Database& db, const std::string& name) { return {name, db.filter(name)}; }

Filter Filter::open() { return {"open", TabulatedSpectrum({1.0, 1e6}, {1.0, 1.0}, "open filter")}; }

double FilterSet::emissionPath(double lambdaNm) const {
    return (dichroic ? dichroic->transmission(lambdaNm) : 1.0) * emission.transmission(lambdaNm);
}

double FilterSet::excitationPath(double lambdaNm) const {
    return excitation.transmission(lambdaNm) * (dichroic ? dichroic->reflection(lambdaNm) : 1.0);
}

TabulatedSpectrum FilterSet::emissionPathCurve(const FilterGrid& grid) const {
    return tabulate(grid, [this](double l) { return emissionPath(l); }, "filter set \"" + name + "\" emission path");
}

PassBand measurePassBand(const TabulatedSpectrum& curve) {
    const auto& l = curve.wavelengths();
    const auto& v = curve.values();
    PassBand band;
    if (v.empty()) return band;
    const size_t peak = static_cast<size_t>(std::max_element(v.begin(), v.end()) - v.begin());
    band.peakNm = l[peak];
    band.peakTransmission = v[peak];
    const double half = 0.5 * v[peak];
    // Linear crossing of `half` between samples i and j.
    const auto crossing = [&](size_t i, size_t j) { return l[i] + (half - v[i]) / (v[j] - v[i]) * (l[j] - l[i]); };
    band.lowNm = l.front();
    for (size_t i = peak; i > 0; --i)
        if (v[i - 1] < half) {
            band.lowNm = crossing(i - 1, i);
            break;
        }
    band.highNm = l.back();
    for (size_t i = peak; i + 1 < v.size(); ++i)
        if (v[i + 1] < half) {
            band.highNm = crossing(i, i + 1);
            break;
        }
    return band;
}

double emissionPathEfficiency(const FilterSet& set, const TabulatedSpectrum& emission) {
    if (emission.empty()) throw ConfigError("emission path efficiency: empty emission spectrum");
    constexpr double kStep = 0.05;  // nm; finer than every filter table (0.2 nm at best)
    const double a = emission.minLambda(), b = emission.maxLambda();
    const auto n = static_cast<size_t>(std::ceil((b - a) / kStep));
    const double h = (b - a) / static_cast<double>(n);
    double total = 0, passed = 0;
    for (size_t i = 0; i < n; ++i) {
        const double l = a + (static_cast<double>(i) + 0.5) * h;
        const double e = emission(l);
        total += e;
        passed += e * set.emissionPath(l);
    }
    if (!(total > 0)) throw ConfigError("emission path efficiency: the emission spectrum has no signal");
    return passed / total;
}

std::optional<std::string> emissionBlockingWarning(const FilterSet& set, const TabulatedSpectrum& emission,
                                                   const std::string& dyeName, double minEfficiency) {
    const double efficiency = emissionPathEfficiency(set, emission);
    if (efficiency >= minEfficiency) return std::nullopt;
    std::string path = set.dichroic ? "dichroic \"" + set.dichroic->name() + "\" x " : "";
    path += "emission filter \"" + set.emission.name() + "\"";
    return "filter set \"" + set.name + "\": the emission path (" + path + ") transmits " + num(efficiency) + " of the " +
           dyeName + " emission (below " + num(minEfficiency) + "); the detector will see almost none of this dye";
}

}  // namespace fluorosim::optics
