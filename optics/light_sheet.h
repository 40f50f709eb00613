#pragma once
// Illumination of the light-sheet microscope, as pure models: a Gaussian light sheet (static, from a
// cylindrical lens, or digitally scanned, DSLM), single or dual sided, and widefield epi-illumination
// for comparison. For a world point p a model gives the direction the light travels and the
// irradiance of the unattenuated beam at p. The renderer "connects to the sheet exactly": it traces
// back from p along -direction(side) to where the beam enters the sample and multiplies this
// irradiance by the transmittance of that segment. Scattering and absorption before p are the
// renderer's business; these models know nothing of the sample.
//
// Units: lengths mm, wavelengths nm in vacuum, power mW in the options, irradiance W/mm²
// (1 W/mm² = 10⁶ W/m²).
//
// Spectrum. The options give one laser line (wavelengthNm) or a power spectrum of any scale (lines
// and/or a table). The model stores it normalised to a total weight of 1 (line weights plus the
// integral of the continuous part), as spectrum(). irradiance(p, side, λ) is the irradiance that
// side would give if its whole power were at λ (W/mm² per unit of normalised spectral weight).
// So a line of weight a at λ contributes a·irradiance(p, side, λ) W/mm², and a continuous part
// s(λ) (1/nm) gives the spectral irradiance s(λ)·irradiance(p, side, λ) in W/mm²/nm. For a single
// laser line the weight is 1 and irradiance() is simply W/mm².
//
// Gaussian beams (paraxial, λ in vacuum, n the medium's index, x along the propagation from the
// focus):
//   zR   = π w0² n / λ                    Rayleigh range
//   w(x) = w0 sqrt(1 + (x/zR)²)           1/e² half-width (intensity)
//   w0   = λ / (π n θ), θ = asin(NA / n)  waist from the illumination NA; θ is the far-field
//                                         half-angle of divergence in the medium (the paraxial
//                                         relation θ = λ/(π n w0) solved for w0), so NA = n sin θ.
// A one-dimensional (cylindrically focused) Gaussian beam has the same zR and w(x) as a circular one.
//
// Sheet frame: u = propagation, n = normal to the sheet, h = n × u the height axis (right-handed
// u, h, n). With d = p − centre, x = d·u, y = d·h, z = d·n. The focus (waist) lies at the centre.
//
// Static sheet (cylindrical lens), per side of power P (W), top-hat height H:
//   E(x, y, z) = P · sqrt(2/π)/w(x) · exp(−2 z²/w(x)²) · [|y| ≤ H/2] / H
// Across the sheet this is the 1-D Gaussian of 1/e² half-width w(x); ∫ exp(−2z²/w²) dz = w sqrt(π/2),
// so the integral over any plane normal to u is P. With HeightProfile::Gaussian the top-hat becomes
// sqrt(2/π)/wy · exp(−2 y²/wy²) with wy = H/2 (H is then the 1/e² full height; the beam is taken
// as collimated along y, which holds when wy is much larger than w0).
//
// Scanned sheet (DSLM): a circular Gaussian beam of waist w0 and power P,
//   I(r) = 2P/(π w²) exp(−2 r²/w²),  r² = (y − s)² + z²,
// whose axis is scanned at constant speed over s ∈ [−H/2, H/2]. Averaged over an exposure that
// holds whole scan periods, s is uniform with density 1/H:
//   E = (1/H) ∫ I ds = 2P/(π w² H) · exp(−2z²/w²) · ∫_{−H/2}^{H/2} exp(−2(y − s)²/w²) ds,
// and ∫ exp(−2t²/w²) dt from y − H/2 to y + H/2 is w sqrt(π/8) [erf(√2 (y + H/2)/w) − erf(√2 (y − H/2)/w)], so
//   E = P · sqrt(2/π)/w(x) · exp(−2 z²/w(x)²) · [erf(√2 (y + H/2)/w) − erf(√2 (y − H/2)/w)] / (2H).
// Across the sheet it is the same 1-D Gaussian with the beam's own w(x); along the height it is the
// top-hat of height H blurred by the beam (soft edges about w wide). The erf bracket integrates to
// 2H over y, so the integral over a plane normal to u is again P. Well inside the scan range the
// value equals the static sheet's.
//
// Dual-sided illumination: two counter-propagating beams along +u (side 0) and −u (side 1) with a
// common focus at the centre, each carrying half of powerMw. The total irradiance is the sum over
// sides; the renderer connects to each side separately because each has its own path into the
// sample. Single-sided: one beam along +u with the whole power.
//
// Direction: the light at p travels along ±u. The tilt of the curved wavefronts off axis (at most
// the divergence angle θ) is neglected, as in the paraxial beam itself.
#include <optional>
#include <string>

#include "core/vec3.h"
#include "scene/beam.h"
#include "spectral/spectrum.h"

namespace fluorosim::optics {

enum class SheetMode { Static, Scanned };
enum class SheetSides { Single, Dual };
enum class HeightProfile { TopHat, Gaussian };

const char* sheetModeName(SheetMode mode);
const char* sheetSidesName(SheetSides sides);

// Paraxial Gaussian-beam relations (waist and x in mm, λ in vacuum nm, n ≥ 1). Throw ConfigError for
// non-positive or non-finite arguments.
double rayleighRangeMm(double waistMm, double lambdaNm, double refractiveIndex);
double beamRadiusMm(double waistMm, double xMm, double lambdaNm, double refractiveIndex);
// w0 = λ / (π n asin(NA/n)); NA must lie in (0, n).
double waistFromNa(double na, double lambdaNm, double refractiveIndex);
// NA = n sin(λ / (π n w0)); throws when the divergence angle λ/(π n w0) exceeds π/2 (a waist far below
// the wavelength, where the paraxial relation means nothing).
double naFromWaist(double waistMm, double lambdaNm, double refractiveIndex);

// The spectral content of an illumination, normalised to total weight 1 (see above). Exactly one of
// `wavelengthNm` and `spectrum` must be given; a spectrum needs finite total power (a constant
// spectrum has none), non-negative lines at positive wavelengths. `what` prefixes error messages.
Spectrum normalisedIlluminationSpectrum(const std::optional<double>& wavelengthNm, const std::optional<Spectrum>& spectrum,
                                        const std::string& what);

// Common interface of the illumination models; the renderer sees them as libsim's BeamProfile.
class Illumination : public BeamProfile {
public:
    // Number of beams (1, or 2 for a dual-sided sheet). Sides are 0 .. sides() − 1.
    virtual int sides() const = 0;
    // Unit direction in which the light of `side` travels. Throws ConfigError for a bad side.
    virtual Vec3 direction(int side) const = 0;
    // Irradiance of the unattenuated beam of `side` at p, W/mm² per unit of normalised spectral weight.
    virtual double irradiance(const Vec3& p, int side, double lambdaNm) const = 0;
    // The illumination spectrum, normalised to total weight 1.
    virtual const Spectrum& spectrum() const = 0;

    // Sum over the sides.
    double totalIrradiance(const Vec3& p, double lambdaNm) const;
    // The ray from p back towards the source of `side`; the renderer intersects it with the sample to
    // find where the beam enters.
    Ray towardSource(const Vec3& p, int side) const { return {p, -direction(side)}; }
};

struct LightSheetOptions {
    // Exactly one of these: a laser line (vacuum nm) or a relative power spectrum (any scale).
    std::optional<double> wavelengthNm = 488.0;
    std::optional<Spectrum> spectrum;
    double powerMw = 1.0;  // total over both sides, within the height
    Vec3 propagation{1, 0, 0};  // any length; normalised
    Vec3 normal{0, 0, 1};       // any length; normalised; must be orthogonal to propagation
    Vec3 centreMm{0, 0, 0};     // the focus, in the middle of the height
    // Exactly one of these. With a spectrum, a given waist holds at every wavelength, whereas a given
    // NA gives w0(λ) = λ/(π n θ) (so zR(λ) = λ/(π n θ²)).
    std::optional<double> waistMm = 0.002;  // 1/e² half-width at the focus
    std::optional<double> illuminationNa;
    double heightMm = 0.2;        // top-hat height, or DSLM scan range, or Gaussian 1/e² full height
    double refractiveIndex = 1.33;  // of the medium the beam is focused in
    SheetMode mode = SheetMode::Static;
    SheetSides sides = SheetSides::Single;
    HeightProfile heightProfile = HeightProfile::TopHat;  // Gaussian only for the static sheet

    void validate() const;  // throws ConfigError naming the field and value
};

// Position of a point in the sheet frame (mm): x along propagation from the focus, y along the
// height, z along the normal from the sheet plane.
struct SheetCoordinates {
    double x = 0, y = 0, z = 0;
};

class LightSheet final : public Illumination {
public:
    explicit LightSheet(LightSheetOptions options);  // validates

    const LightSheetOptions& options() const { return options_; }
    int sides() const override { return options_.sides == SheetSides::Dual ? 2 : 1; }
    Vec3 direction(int side) const override;
    double irradiance(const Vec3& p, int side, double lambdaNm) const override;
    const Spectrum& spectrum() const override { return spectrum_; }
    // Core: |z| <= kCoreWidths w(x), where the irradiance is at least e^-8 (3.4e-4) of the peak at that x
    // and which holds all but 6.3e-5 of the sheet's power; the computed image leaves the rest to the
    // paths, so the split stays exact (2.5 w cost 25 % more computed layers for 4e-7).
    // Along a ray it is a quadric condition in t; the proposal is the Gaussian across the sheet.
    static constexpr double kCoreWidths = 2.0;
    bool inCore(const Vec3& p, int side, double lambdaNm) const override;
    BeamCore coreAlong(const Ray& ray, int side, double lambdaNm) const override;
    // Across the sheet the normal density of its profile at w(x); along the height uniform over the top
    // hat (and 3 w beyond it for a scanned sheet, e^-18 of its edge), or the Gaussian height's density.
    std::optional<Vec3> axisPoint() const override { return centre_; }
    std::optional<CrossSectionPoint> sampleCrossSection(const Vec3& axisPoint, int side, double lambdaNm, double u1, double u2) const override;

    // Waist w0 at λ (the given waist, or from the NA), zR and the 1/e² half-width w(x) at λ.
    double waistMm(double lambdaNm) const;
    double rayleighRangeMm(double lambdaNm) const;
    double waistAt(double xMm, double lambdaNm) const;
    // Power of one side, W (half of powerMw when dual).
    double sidePowerW() const { return sidePowerW_; }

    Vec3 centre() const { return centre_; }
    Vec3 propagationAxis() const { return u_; }
    Vec3 normalAxis() const { return n_; }
    Vec3 heightAxis() const { return h_; }
    SheetCoordinates local(const Vec3& p) const;

private:
    LightSheetOptions options_;
    Spectrum spectrum_;
    Vec3 u_, n_, h_, centre_;
    double sidePowerW_ = 0;
};

// Widefield (epi) illumination for comparison: Köhler illumination through the objective, modelled
// as a uniform irradiance P/(π R²) over a circular field of radius R = fieldDiameterMm/2 around the
// objective axis, travelling along `axis`, and 0 outside the field. It does not depend on the
// position along the axis (no defocus, no divergence), so its integral over any plane normal to the
// axis is P.
struct WidefieldOptions {
    std::optional<double> wavelengthNm = 488.0;
    std::optional<Spectrum> spectrum;
    double powerMw = 1.0;         // within the field
    Vec3 axis{0, 0, -1};          // the direction the light travels (any length; normalised)
    Vec3 centreMm{0, 0, 0};       // a point on the objective axis (the field centre)
    double fieldDiameterMm = 0.5;

    void validate() const;  // throws ConfigError naming the field and value
};

class WidefieldIllumination final : public Illumination {
public:
    explicit WidefieldIllumination(WidefieldOptions options);  // validates

    const WidefieldOptions& options() const { return options_; }
    int sides() const override { return 1; }
    Vec3 direction(int side) const override;
    double irradiance(const Vec3& p, int side, double lambdaNm) const override;
    const Spectrum& spectrum() const override { return spectrum_; }
    // Core: the whole illuminated cylinder (the field does not fall off with depth); uniform proposal.
    bool inCore(const Vec3& p, int side, double lambdaNm) const override;
    // Uniform over the field's disc.
    std::optional<Vec3> axisPoint() const override { return options_.centreMm; }
    std::optional<CrossSectionPoint> sampleCrossSection(const Vec3& axisPoint, int side, double lambdaNm, double u1, double u2) const override;
    BeamCore coreAlong(const Ray& ray, int side, double lambdaNm) const override;

private:
    WidefieldOptions options_;
    Spectrum spectrum_;
    Vec3 axis_;
    double irradianceWPerMm2_ = 0;
    double radiusMm_ = 0;
};

// The scene loader's hook: a LightSheet from a scene file's light_sheet entry.
std::shared_ptr<BeamProfile> makeLightSheet(const LightSheetSpec& spec);

}  // namespace fluorosim::optics
