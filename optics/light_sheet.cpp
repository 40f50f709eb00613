#include "optics/light_sheet.h"

#include <cmath>
#include <sstream>
#include <string_view>
#include <utility>

#include "core/errors.h"
#include "core/math.h"
#include "core/sampling.h"

namespace fluorosim::optics {
namespace {

constexpr double kNmToMm = 1e-6;
constexpr double kMwToW = 1e-3;
const double kSqrt2OverPi = std::sqrt(2.0 / kPi);
const double kSqrt2 = std::sqrt(2.0);

std::string num(double v) {
    std::ostringstream os;
    os << v;
    return os.str();
}

std::string vecText(const Vec3& v) { return "(" + num(v.x) + ", " + num(v.y) + ", " + num(v.z) + ")"; }

bool positiveFinite(double v) { return v > 0 && std::isfinite(v); }

// Names as views: these checks run per beam evaluation (per point of the computed image), and a
// std::string parameter built from a literal of 16 characters or more allocated on every call.
void requirePositive(double v, std::string_view field, std::string_view unit) {
    if (!positiveFinite(v)) throw ConfigError(std::string(field) + ": must be positive and finite, got " + num(v) + std::string(unit));
}

void requireIndex(double n, std::string_view field) {
    if (!(n >= 1.0) || !std::isfinite(n)) throw ConfigError(std::string(field) + ": must be a finite index >= 1, got " + num(n));
}

void requireDirection(const Vec3& v, const std::string& field) {
    if (!isFinite(v) || !(length(v) > 0)) throw ConfigError(field + ": must be a finite non-zero vector, got " + vecText(v));
}

void checkSide(int side, int sides, const char* what) {
    if (side < 0 || side >= sides)
        throw ConfigError(std::string(what) + " side: must lie in [0, " + std::to_string(sides - 1) + "], got " +
                          std::to_string(side));
}

}  // namespace

const char* sheetModeName(SheetMode mode) { return mode == SheetMode::Static ? "static" : "scanned"; }
const char* sheetSidesName(SheetSides sides) { return sides == SheetSides::Single ? "single" : "dual"; }

double rayleighRangeMm(double waistMm, double lambdaNm, double refractiveIndex) {
    requirePositive(waistMm, "waist", " mm");
    requirePositive(lambdaNm, "wavelength", " nm");
    requireIndex(refractiveIndex, "refractive index");
    return kPi * waistMm * waistMm * refractiveIndex / (lambdaNm * kNmToMm);
}

double beamRadiusMm(double waistMm, double xMm, double lambdaNm, double refractiveIndex) {
    const double zr = rayleighRangeMm(waistMm, lambdaNm, refractiveIndex);
    return waistMm * std::sqrt(1.0 + sqr(xMm / zr));
}

double waistFromNa(double na, double lambdaNm, double refractiveIndex) {
    requirePositive(lambdaNm, "wavelength", " nm");
    requireIndex(refractiveIndex, "refractive index");
    if (!(na > 0 && na < refractiveIndex))
        throw ConfigError("illumination NA: must lie in (0, n) with n = " + num(refractiveIndex) + ", got " + num(na));
    const double theta = std::asin(na / refractiveIndex);
    return lambdaNm * kNmToMm / (kPi * refractiveIndex * theta);
}

double naFromWaist(double waistMm, double lambdaNm, double refractiveIndex) {
    requirePositive(waistMm, "waist", " mm");
    requirePositive(lambdaNm, "wavelength", " nm");
    requireIndex(refractiveIndex, "refractive index");
    const double theta = lambdaNm * kNmToMm / (kPi * refractiveIndex * waistMm);
    if (theta > kPi / 2)
        throw ConfigError("waist: " + num(waistMm) + " mm is far below the wavelength (" + num(lambdaNm) +
                          " nm): the divergence angle would exceed 90 degrees");
    return refractiveIndex * std::sin(theta);
}

Spectrum normalisedIlluminationSpectrum(const std::optional<double>& wavelengthNm, const std::optional<Spectrum>& spectrum,
                                        const std::string& what) {
    if (wavelengthNm && spectrum)
        throw ConfigError(what + ": give either wavelengthNm (" + num(*wavelengthNm) +
                          " nm) or a spectrum, not both (set wavelengthNm = std::nullopt to use the spectrum)");
    if (!wavelengthNm && !spectrum) throw ConfigError(what + ": give wavelengthNm or a spectrum");
    if (wavelengthNm) {
        requirePositive(*wavelengthNm, what + " wavelengthNm", " nm");
        return Spectrum::lines({{*wavelengthNm, 1.0}});
    }
    const Spectrum& s = *spectrum;
    double total = 0;
    for (const SpectralLine& line : s.spectralLines()) {
        requirePositive(line.lambdaNm, what + " spectrum line wavelength", " nm");
        if (!(line.power >= 0) || !std::isfinite(line.power))
            throw ConfigError(what + " spectrum: the line at " + num(line.lambdaNm) +
                              " nm needs a non-negative finite weight, got " + num(line.power));
        total += line.power;
    }
    if (s.hasContinuousPart()) {
        const auto range = s.tableRange();
        // A constant has no finite integral: the illumination would carry infinite power.
        if (!range) throw ConfigError(what + " spectrum: a constant spectrum has no finite power; give lines or a table");
        const double continuous = s.integral(range->first, range->second);
        if (!(continuous >= 0) || !std::isfinite(continuous))
            throw ConfigError(what + " spectrum: the continuous part integrates to " + num(continuous));
        total += continuous;
    }
    if (!positiveFinite(total)) throw ConfigError(what + " spectrum: carries no power (total weight " + num(total) + ")");
    return s.scaled(1.0 / total);
}

double Illumination::totalIrradiance(const Vec3& p, double lambdaNm) const {
    double sum = 0;
    for (int side = 0; side < sides(); ++side) sum += irradiance(p, side, lambdaNm);
    return sum;
}

void LightSheetOptions::validate() const {
    normalisedIlluminationSpectrum(wavelengthNm, spectrum, "light sheet");
    requirePositive(powerMw, "light sheet powerMw", " mW");
    requireDirection(propagation, "light sheet propagation");
    requireDirection(normal, "light sheet normal");
    const double cosAngle = dot(normalize(propagation), normalize(normal));
    if (std::abs(cosAngle) > 1e-6)
        throw ConfigError("light sheet normal: must be orthogonal to propagation " + vecText(propagation) + ", got " +
                          vecText(normal) + " (cosine of the angle between them " + num(cosAngle) + ")");
    if (!isFinite(centreMm)) throw ConfigError("light sheet centreMm: must be finite, got " + vecText(centreMm));
    requireIndex(refractiveIndex, "light sheet refractiveIndex");
    if (waistMm && illuminationNa)
        throw ConfigError("light sheet: give either waistMm (" + num(*waistMm) + " mm) or illuminationNa (" +
                          num(*illuminationNa) + "), not both (set waistMm = std::nullopt to use the NA)");
    if (!waistMm && !illuminationNa) throw ConfigError("light sheet: give waistMm or illuminationNa");
    if (waistMm) requirePositive(*waistMm, "light sheet waistMm", " mm");
    if (illuminationNa && !(*illuminationNa > 0 && *illuminationNa < refractiveIndex))
        throw ConfigError("light sheet illuminationNa: must lie in (0, refractiveIndex = " + num(refractiveIndex) +
                          "), got " + num(*illuminationNa));
    // The paraxial divergence λ/(π n w0) must stay below 90 degrees, or the waist is meaningless.
    if (waistMm && wavelengthNm && *wavelengthNm * kNmToMm / (kPi * refractiveIndex * *waistMm) > kPi / 2)
        throw ConfigError("light sheet waistMm: " + num(*waistMm) + " mm is far below the wavelength (" +
                          num(*wavelengthNm) + " nm): the divergence angle would exceed 90 degrees");
    requirePositive(heightMm, "light sheet heightMm", " mm");
    if (mode == SheetMode::Scanned && heightProfile != HeightProfile::TopHat)
        throw ConfigError("light sheet heightProfile: a Gaussian height profile applies to the static sheet only; "
                          "the scanned sheet's profile follows from the scan range");
}

LightSheet::LightSheet(LightSheetOptions options) : options_(std::move(options)) {
    options_.validate();
    spectrum_ = normalisedIlluminationSpectrum(options_.wavelengthNm, options_.spectrum, "light sheet");
    u_ = normalize(options_.propagation);
    n_ = normalize(options_.normal);
    // Remove the (tolerated, < 1e-6) non-orthogonal part so the frame is exactly orthonormal.
    n_ = normalize(n_ - u_ * dot(n_, u_));
    h_ = cross(n_, u_);
    centre_ = options_.centreMm;
    sidePowerW_ = options_.powerMw * kMwToW / sides();
}

Vec3 LightSheet::direction(int side) const {
    checkSide(side, sides(), "light sheet");
    return side == 0 ? u_ : -u_;
}

double LightSheet::waistMm(double lambdaNm) const {
    return options_.waistMm ? *options_.waistMm : waistFromNa(*options_.illuminationNa, lambdaNm, options_.refractiveIndex);
}

double LightSheet::rayleighRangeMm(double lambdaNm) const {
    return optics::rayleighRangeMm(waistMm(lambdaNm), lambdaNm, options_.refractiveIndex);
}

double LightSheet::waistAt(double xMm, double lambdaNm) const {
    return beamRadiusMm(waistMm(lambdaNm), xMm, lambdaNm, options_.refractiveIndex);
}

SheetCoordinates LightSheet::local(const Vec3& p) const {
    const Vec3 d = p - centre_;
    return {dot(d, u_), dot(d, h_), dot(d, n_)};
}

double LightSheet::irradiance(const Vec3& p, int side, double lambdaNm) const {
    checkSide(side, sides(), "light sheet");
    const SheetCoordinates c = local(p);
    const double w = waistAt(c.x, lambdaNm);
    const double across = kSqrt2OverPi / w * std::exp(-2.0 * sqr(c.z / w));
    const double height = options_.heightMm;
    double along = 0;
    if (options_.mode == SheetMode::Scanned) {
        // erf(a) − erf(b) with a > b; on the far side of the scan range both are near 1, so use
        // erfc(b) − erfc(a) there (by symmetry in y) to avoid cancellation.
        const double y = std::abs(c.y);
        const double a = kSqrt2 * (y + height / 2) / w, b = kSqrt2 * (y - height / 2) / w;
        along = (std::erfc(b) - std::erfc(a)) / (2.0 * height);
    } else if (options_.heightProfile == HeightProfile::Gaussian) {
        const double wy = height / 2;
        along = kSqrt2OverPi / wy * std::exp(-2.0 * sqr(c.y / wy));
    } else {
        along = std::abs(c.y) <= height / 2 ? 1.0 / height : 0.0;
    }
    return sidePowerW_ * across * along;
}

bool LightSheet::inCore(const Vec3& p, int side, double lambdaNm) const {
    checkSide(side, sides(), "light sheet");
    const SheetCoordinates c = local(p);
    return std::abs(c.z) <= kCoreWidths * waistAt(c.x, lambdaNm);
}

BeamCore LightSheet::coreAlong(const Ray& ray, int side, double lambdaNm) const {
    checkSide(side, sides(), "light sheet");
    // z(t)² <= k² w0² (1 + x(t)²/zR²) with x(t) = x0 + t dx, z(t) = z0 + t dz.
    const SheetCoordinates o = local(ray.o);
    const double dx = dot(ray.d, u_), dz = dot(ray.d, n_);
    const double a = kCoreWidths * waistMm(lambdaNm), b = a / rayleighRangeMm(lambdaNm);
    BeamCore core = quadraticCore(dz * dz - b * b * dx * dx, 2 * (o.z * dz - b * b * o.x * dx), o.z * o.z - a * a - b * b * o.x * o.x);
    if (std::abs(dz) > 0) {
        // Across the sheet the profile is exp(-2 z²/w²): a normal density of z with deviation w/2.
        const double tc = -o.z / dz;
        for (int i = 0; i < core.count; ++i) {
            core.intervals[static_cast<size_t>(i)].centre = tc;
            core.intervals[static_cast<size_t>(i)].sigma = 0.5 * waistAt(o.x + tc * dx, lambdaNm) / std::abs(dz);
        }
    }
    return core;
}

std::optional<BeamProfile::CrossSectionPoint> LightSheet::sampleCrossSection(const Vec3& axisPoint, int side, double lambdaNm, double u1,
                                                                             double u2) const {
    checkSide(side, sides(), "light sheet");
    const double x = local(axisPoint).x;
    const Vec3 onAxis = centre_ + u_ * x;
    const double sigma = 0.5 * waistAt(x, lambdaNm);
    // Truncated at 8 deviations: 1.2e-15 of the profile lies beyond.
    double pdfZ = 0;
    const double z = sampleTruncatedNormal(u1, 0.0, sigma, -8 * sigma, 8 * sigma, &pdfZ);
    const double height = options_.heightMm;
    double y = 0, pdfY = 0;
    if (options_.mode == SheetMode::Static && options_.heightProfile == HeightProfile::Gaussian) {
        const double sy = height / 4;
        y = sampleTruncatedNormal(u2, 0.0, sy, -8 * sy, 8 * sy, &pdfY);
    } else {
        const double half = 0.5 * height + (options_.mode == SheetMode::Scanned ? 3 * sigma * 2 : 0.0);
        y = (2 * u2 - 1) * half;
        pdfY = 1 / (2 * half);
    }
    if (!(pdfZ > 0) || !(pdfY > 0)) return std::nullopt;
    return CrossSectionPoint{onAxis + n_ * z + h_ * y, pdfZ * pdfY};
}

std::optional<BeamProfile::CrossSectionPoint> WidefieldIllumination::sampleCrossSection(const Vec3& axisPoint, int side, double, double u1,
                                                                                        double u2) const {
    checkSide(side, 1, "widefield");
    const Vec3 onAxis = options_.centreMm + axis_ * dot(axisPoint - options_.centreMm, axis_);
    const Frame f = Frame::fromNormal(axis_);
    const double r = radiusMm_ * std::sqrt(u1), phi = 2 * kPi * u2;
    return CrossSectionPoint{onAxis + f.toWorld(Vec3(r * std::cos(phi), r * std::sin(phi), 0)), 1 / (kPi * radiusMm_ * radiusMm_)};
}

void WidefieldOptions::validate() const {
    normalisedIlluminationSpectrum(wavelengthNm, spectrum, "widefield");
    requirePositive(powerMw, "widefield powerMw", " mW");
    requireDirection(axis, "widefield axis");
    if (!isFinite(centreMm)) throw ConfigError("widefield centreMm: must be finite, got " + vecText(centreMm));
    requirePositive(fieldDiameterMm, "widefield fieldDiameterMm", " mm");
}

WidefieldIllumination::WidefieldIllumination(WidefieldOptions options) : options_(std::move(options)) {
    options_.validate();
    spectrum_ = normalisedIlluminationSpectrum(options_.wavelengthNm, options_.spectrum, "widefield");
    axis_ = normalize(options_.axis);
    radiusMm_ = options_.fieldDiameterMm / 2;
    irradianceWPerMm2_ = options_.powerMw * kMwToW / (kPi * radiusMm_ * radiusMm_);
}

Vec3 WidefieldIllumination::direction(int side) const {
    checkSide(side, 1, "widefield");
    return axis_;
}

double WidefieldIllumination::irradiance(const Vec3& p, int side, double) const {
    checkSide(side, 1, "widefield");
    const Vec3 d = p - options_.centreMm;
    const Vec3 radial = d - axis_ * dot(d, axis_);
    return dot(radial, radial) <= radiusMm_ * radiusMm_ ? irradianceWPerMm2_ : 0.0;
}

bool WidefieldIllumination::inCore(const Vec3& p, int side, double lambdaNm) const { return irradiance(p, side, lambdaNm) > 0; }

BeamCore WidefieldIllumination::coreAlong(const Ray& ray, int side, double) const {
    checkSide(side, 1, "widefield");
    const Vec3 o = ray.o - options_.centreMm;
    const Vec3 orad = o - axis_ * dot(o, axis_), drad = ray.d - axis_ * dot(ray.d, axis_);
    return quadraticCore(dot(drad, drad), 2 * dot(orad, drad), dot(orad, orad) - radiusMm_ * radiusMm_);
}

std::shared_ptr<BeamProfile> makeLightSheet(const LightSheetSpec& spec) {
    if (spec.widefield) {
        WidefieldOptions w;
        w.wavelengthNm = spec.wavelengthNm;
        w.spectrum = spec.spectrum;
        w.powerMw = spec.powerMw;
        w.axis = spec.propagation;
        w.centreMm = spec.centreMm;
        w.fieldDiameterMm = spec.fieldDiameterMm;
        return std::make_shared<WidefieldIllumination>(std::move(w));
    }
    LightSheetOptions o;
    o.wavelengthNm = spec.wavelengthNm;
    o.spectrum = spec.spectrum;
    o.powerMw = spec.powerMw;
    o.propagation = spec.propagation;
    o.normal = spec.normal;
    o.centreMm = spec.centreMm;
    o.waistMm = spec.waistMm;
    o.illuminationNa = spec.illuminationNa;
    o.heightMm = spec.heightMm;
    o.refractiveIndex = spec.refractiveIndex;
    o.mode = spec.scanned ? SheetMode::Scanned : SheetMode::Static;
    o.sides = spec.dual ? SheetSides::Dual : SheetSides::Single;
    return std::make_shared<LightSheet>(std::move(o));
}

}  // namespace fluorosim::optics
