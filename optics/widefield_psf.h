#pragma once
// The 3-D widefield PSF of the detection objective (scalar Debye theory; Born–Wolf when the sample's
// index matches the immersion's, with the Gibson–Lanni aberration of focusing through an index step
// otherwise), tabulated once and used by every estimator of a plane (optics/imaging.h).
//
// Pupil coordinate ρ in [0, 1], NA ρ = n sin θ in each medium, k = 2π/λ (vacuum). A point at lateral
// distance r from the geometric image point and axial offset dz (toward the objective) from the plane
// of focus images with the amplitude
//     U(v, w) = ∫0^1 A(ρ) exp(i Φ(ρ, w)) J0(v ρ) ρ dρ,   v = k NA r, w = k dz,
//     Φ = −w n_s cos θ_s                                  (matched indices),
//     Φ = −w n_s cos θ_s + k d (n_s cos θ_s − f n_i cos θ_i)  (focus at depth d below an index step: a
//         point dz toward the objective lies at depth d − dz; f d is the objective's nominal focus depth in
//         the immersion medium, placing the plane of focus at the least-squares best focus of the
//         aberration over the pupil: tests/optics/widefield_psf_test.cpp checks the paraxial and marginal
//         foci against ray tracing),
// A(ρ) = sqrt(a(θ_s) / cos θ_s) with a the intensity apodisation (the medium's attenuation over the cone)
// and 1/sqrt(cos θ_s) the aplanatic (sine-condition) factor: an isotropic emitter sends equal power per
// solid angle, and a solid angle dΩ_s fills the pupil area ρ dρ dφ ∝ cos θ_s dΩ_s (also through an index
// step, since n_s sin θ_s = n_i sin θ_i). Far from focus h tends to the geometric landing disc of light
// uniform in solid angle, which the camera paths sample. The intensity h = |U|² is normalised by Parseval so that its integral over
// the whole plane is 1 at every dz; the model PSF is h cut at v = vCut (the light beyond, about 2/(π vCut)
// in focus, is left out, not redistributed). Tables interpolate h cubically in v and linearly in w. With
// matched indices and apodisation depending on θ alone h is λ-independent in (v, w): one table; under a
// mismatch the table is built at wavelength nodes and interpolated linearly in λ.
//
// Camera paths sample their focal-plane displacement from g = the in-focus row of the table raised to a
// quarter of the Airy rings' envelope where it is darker (its dark rings are not dark slightly out of focus), linear in v
// between nodes (normalised on v <= vCut), and a direction uniform in solid angle over the cone (half-angle θmax = asin(NA/n_s)). A
// point at dz then lands with density h_geo = g ⊗ D_a, D_a the landing offset |dz| tan θ of directions
// weighted by a(θ); `reweight` = h/h_geo turns the paths' image of a point into the model's. Beyond the
// table's axial range (|dz| > maxDz) the model is that geometric image (reweight 1, densities not
// tabulated).
#include <vector>

namespace fluorosim::optics {

struct PupilOptions {
    double na = 0.8;
    double immersionIndex = 1.33;
    double sampleIndex = 1.33;
    double depthMm = 0;                        // focus depth below the immersion/sample interface (mismatch only)
    std::vector<double> intensityApodization;  // a(θ) at sin θ / sin θmax = i / (size − 1); empty = none
    bool aplanatic = true;                     // false: a uniform pupil (the textbook closed forms)
    void validate() const;                     // ConfigError naming the field and value
    double collectionHalfAngle() const;        // asin(NA / n_s), in the sample
    bool matched() const { return sampleIndex == immersionIndex || depthMm == 0; }
};

struct PsfTableOptions {
    double vCut = 150;   // lateral cut, optical units
    double wMax = 200;   // axial half-range in w = k dz
    double dv = 0.25, dw = 0.5;
    int pupilNodes = 256;  // Gauss–Legendre nodes over the pupil
    // A stack's planes share a PSF while their pupils lie within this pupilDistance of their group's first
    // (makePlanePsfs): the shared PSF misplaces at most twice this fraction of a point's light.
    double depthTolerance = 0.0025;
    void validate() const;
};

class WidefieldPsf {
public:
    // `lambdaNodesNm`: wavelengths of the tables under a mismatch (ignored when matched). Throws ConfigError.
    WidefieldPsf(PupilOptions pupil, PsfTableOptions table = {}, std::vector<double> lambdaNodesNm = {});
    const PupilOptions& pupil() const { return pupil_; }
    const PsfTableOptions& table() const { return table_; }

    // The model PSF per mm² at lateral distance r (mm) from the geometric image point, axial offset dz
    // (mm), vacuum wavelength λ (nm); 0 beyond the cut and beyond the axial range.
    double density(double rMm, double dzMm, double lambdaNm) const;
    double enclosed(double dzMm, double lambdaNm) const;  // ∫ density over the plane (< 1: the cut)
    double cutRadiusMm(double lambdaNm) const;            // vCut / (k NA)
    double maxDzMm(double lambdaNm) const;                // wMax / k
    // The paths' displacement: a radius (mm) from u in [0, 1), and its density per mm² (on r <= cut).
    double sampleDisplacementMm(double u, double lambdaNm) const;
    double displacementDensity(double rMm, double lambdaNm) const;
    double geometricDensity(double rMm, double dzMm, double lambdaNm) const;  // h_geo per mm²
    double reweight(double rMm, double dzMm, double lambdaNm) const;         // density / geometricDensity; 1 beyond maxDz
    // Under a mismatch, f: the objective's nominal focus lies f d deep in immersion-medium terms (1 matched).
    double focusScale() const { return tables_.empty() ? 1.0 : tables_.front().focusScale; }
    // The pupil phase Φ(ρ, dz) at ρ in [0, 1] (radians), as the tables use it.
    double pupilPhase(double rho, double dzMm, double lambdaNm) const;
    // Full width at half maximum of the in-focus Airy pattern, 0.5145 λ/NA.
    static double fwhmInFocusMm(double lambdaNm, double na);

    // Table values in optical units (per unit v-area), for tests: the model PSF and h_geo at (v, w).
    double tableDensity(double v, double w, double lambdaNm) const;
    double tableGeometric(double v, double w, double lambdaNm) const;

    // One wavelength's tables. The model PSF h on v = i dv (i < nv), w = −wMax + j dw (j < nw), row-major
    // in w; h_geo on the same v nodes at |w| = geoW[j] (fine steps near focus, then growing in proportion
    // to |w|, as the landing disc does).
    struct Table {
        double lambdaNm = 0;
        int nv = 0, nw = 0;
        std::vector<float> h;
        std::vector<double> enclosed;  // ∫ h over the plane, per w row
        std::vector<double> geoW;
        std::vector<float> geo;
        // The displacement density g: the in-focus row, linear in v between nodes, per unit v-area
        // (normalised on v <= vCut), and its cumulative mass at each node.
        std::vector<double> g, cdf;
        double focusScale = 1;
    };

private:
    const Table& tableAt(double lambdaNm, const Table** other, double* f) const;
    const Table& samplerTable(double lambdaNm) const;
    template <class Get>
    double interpolateLambda(double lambdaNm, Get&& get) const;

    PupilOptions pupil_;
    PsfTableOptions table_;
    std::vector<double> lambdaNodes_;
    std::vector<Table> tables_;
};

// How far apart two pupils of one objective and sample are: the L2 distance of their in-focus amplitude
// PSFs, each normalised to unit energy, least over a constant phase; by Parseval, over the pupil,
// sqrt(2 − 2 |∫ A_a A_b e^{i(Φ_a − Φ_b)} ρ dρ| / sqrt(P_a P_b)). Small distances ε bound the change of the
// intensity PSF: ∫ |h_a − h_b| <= 2ε. Throws ConfigError when NA, indices or the aplanatic factor differ.
double pupilDistance(const PupilOptions& a, const PupilOptions& b, double lambdaNm);

}  // namespace fluorosim::optics
