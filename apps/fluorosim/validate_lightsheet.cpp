// `fluorosim validate lightsheet --wavelength NM --waist UM [--n N] -o OUT.json`: the excitation the
// renderer's light-sheet connection delivers inside a clear medium with a uniform dye, measured across
// the sheet at positions along the beam spanning ±2 Rayleigh ranges, with the 1/e² half-width of each
// profile fitted (least squares of ln(rate) against z²) and compared with w(x) = w0 sqrt(1 + (x/zR)²).
#include <cmath>
#include <cstdio>
#include <fstream>
#include <memory>
#include <sstream>
#include <nlohmann/json.hpp>

#include "commands.h"
#include "core/errors.h"
#include "core/message.h"
#include "core/rng.h"
#include "core/units.h"
#include "core/math.h"
#include "database.h"
#include "core/output_checks.h"
#include "optics/light_sheet.h"
#include "render/path_tracer.h"
#include "scene/light_sampler.h"

namespace fluorosim::app {
namespace {

struct SheetArgs {
    double wavelength = 488, waistUm = 2, n = 1.33;
    int positions = 9, samples = 16;
    std::string sigmaS = "0 /mm";
    double g = 0.9;
    std::string output;
};

// A cube [-half, half]³ (outward normals) as the interface around `medium`.
void addMediumCube(Scene& scene, double half, int medium) {
    TriangleMesh box;
    const Vec3 lo(-half, -half, -half), d(2 * half, 2 * half, 2 * half);
    auto face = [&](const Vec3& o, const Vec3& e1, const Vec3& e2) {
        const uint32_t b = static_cast<uint32_t>(box.positions.size());
        box.positions.insert(box.positions.end(), {o, o + e1, o + e1 + e2, o + e2});
        box.indices.insert(box.indices.end(), {b, b + 1, b + 2, b, b + 2, b + 3});
    };
    const Vec3 ex(d.x, 0, 0), ey(0, d.y, 0), ez(0, 0, d.z);
    face(lo, ey, ex), face(lo + ez, ex, ey), face(lo, ex, ez), face(lo + ey, ez, ex), face(lo, ez, ey), face(lo + ex, ey, ez);
    scene.geometry.addMesh(std::move(box));
    ShapeInfo s;
    s.isInterface = true;
    s.insideMedium = medium;
    scene.shapes.push_back(s);
}

// The sheet under test: static, single sided, focused at the origin, travelling along +x.
void addStaticSheet(Scene& scene, const SheetArgs& a, double heightMm) {
    LightSheetSpec spec;
    spec.wavelengthNm = a.wavelength;
    spec.waistMm = a.waistUm * 1e-3;
    spec.refractiveIndex = a.n;
    spec.heightMm = heightMm;
    scene.lights.push_back(BeamLight{optics::makeLightSheet(spec), spec});
}

// Half-maximum width of a profile sampled at z (linear interpolation from the central maximum).
double fullWidthHalfMax(const std::vector<double>& z, const std::vector<double>& v) {
    const size_t c = v.size() / 2;
    const double half = 0.5 * v[c];
    auto crossing = [&](int dir) {
        for (size_t i = c; i + dir < v.size() && (dir > 0 || i > 0); i += dir)
            if (v[i + dir] < half) return z[i] + (z[i + dir] - z[i]) * (v[i] - half) / (v[i] - v[i + dir]);
        return dir > 0 ? z.back() : z.front();
    };
    return crossing(1) - crossing(-1);
}

// Scattering tissue: the fluence rate across the sheet (direct plus scattered light, estimated by
// paths that start at each point in an isotropic direction) at depths along the beam. The sheet
// thickness (full width at half maximum) and the contrast (peak over the value 3 w(x) off the sheet)
// fall with depth as scattered light builds up around the sheet.
void runScatteringDepth(const SheetArgs& a, double sigmaS) {
    const double w0 = a.waistUm * 1e-3, half = 0.5;
    const double zR = optics::rayleighRangeMm(w0, a.wavelength, a.n);
    Scene scene;
    scene.spectral.lambdaMin = 400;
    scene.spectral.lambdaMax = 700;
    scene.media.emplace_back("tissue", Spectrum::constant(0), Spectrum::constant(sigmaS), a.g, 1.0);
    addMediumCube(scene, half, 0);
    addStaticSheet(scene, a, 0.6);
    scene.render.fluorescence = FluorescenceModel::None;
    scene.finalize();
    const PathTracer tracer(scene);
    const SampledWavelengths wl = SampledWavelengths::atLine(a.wavelength, 1.0);
    nlohmann::json depths = nlohmann::json::array(), fwhm = nlohmann::json::array(), clearFwhm = nlohmann::json::array(),
                   contrast = nlohmann::json::array();
    PathStats stats;
    for (int i = 0; i < a.positions; ++i) {
        const double depth = 0.05 + 0.9 * i / (a.positions - 1);  // mm from the entry face at x = -0.5
        const double x = -half + depth;
        const double wx = w0 * std::sqrt(1 + (x / zR) * (x / zR));
        std::vector<double> zs, rate;
        for (int k = 0; k <= 60; ++k) {
            const double z = -3 * wx + 6 * wx * k / 60;
            double sum = 0;
            for (int n = 0; n < a.samples; ++n) {
                Rng rng = Rng::forKey(23, static_cast<uint64_t>(i * 1000 + k), static_cast<uint64_t>(n));
                sum += tracer.meanRadiance(Vec3(x, 0, z), 0, wl, rng, stats).total()[0];
            }
            zs.push_back(z);
            rate.push_back(4 * kPi * 1e-6 * sum / a.samples);  // fluence rate, W/mm²
        }
        depths.push_back(depth * 1e3);
        fwhm.push_back(fullWidthHalfMax(zs, rate) * 1e3);
        clearFwhm.push_back(wx * std::sqrt(2 * std::log(2.0)) * 1e3);  // FWHM of the unscattered Gaussian
        contrast.push_back(rate[30] / (0.5 * (rate.front() + rate.back())));
    }
    const nlohmann::json out = {{"wavelength_nm", a.wavelength}, {"waist_um", a.waistUm}, {"sigma_s_per_mm", sigmaS}, {"g", a.g},
                                {"depths_um", depths},           {"fwhm_um", fwhm},       {"unscattered_fwhm_um", clearFwhm},
                                {"contrast_at_3w", contrast},    {"paths", stats.paths}};
    std::ofstream f(a.output);
    if (!f) throw IoError(a.output + ": cannot write");
    f << out.dump(2) << "\n";
    if (!f) throw IoError(a.output + ": write failed");
    std::printf("%s\n", nlohmann::json{{"output", a.output}, {"depths_um", depths}, {"fwhm_um", fwhm}, {"contrast_at_3w", contrast}}.dump().c_str());
}

void runLightSheet(const SheetArgs& a) {
    auto got = [](double v) {
        std::ostringstream os;
        os << ", got " << v;
        return os.str();
    };
    if (!(a.wavelength >= 300 && a.wavelength <= 1100)) throw ConfigError("--wavelength: must lie in [300, 1100] nm" + got(a.wavelength));
    if (!(a.waistUm > 0.1 && a.waistUm < 1000)) throw ConfigError("--waist: must lie in (0.1, 1000) um" + got(a.waistUm));
    if (!(a.n >= 1 && a.n < 3)) throw ConfigError("--n: must lie in [1, 3)" + got(a.n));
    if (a.positions < 3 || a.positions > 101) throw ConfigError("--positions: must lie in [3, 101]" + got(a.positions));
    requireWritableFolder(a.output);  // before a scattering run of minutes
    if (a.samples < 1 || a.samples > 1000000) throw ConfigError("--samples: must lie in [1, 1e6]" + got(a.samples));
    const double sigmaS = parseQuantity(a.sigmaS, Dimension::InverseLength, "--sigma-s");
    if (!(sigmaS >= 0) || sigmaS > 1e4) throw ConfigError("--sigma-s: must lie in [0, 1e4 /mm], got \"" + excerpt(a.sigmaS) + "\"");
    if (!(a.g > -1 && a.g < 1)) throw ConfigError("--g: must lie in (-1, 1)" + got(a.g));
    if (sigmaS > 0) return runScatteringDepth(a, sigmaS);
    const spectra::Database db;
    const double w0 = a.waistUm * 1e-3;
    const double zR = optics::rayleighRangeMm(w0, a.wavelength, a.n);
    // A box of dilute AF488 in a medium of index 1 (so no boundary refracts the beam; the beam's own
    // index a.n sets its Rayleigh range) around the focus.
    const double half = std::max(4 * zR, 0.5);
    Scene scene;
    scene.spectral.lambdaMin = 400;
    scene.spectral.lambdaMax = 700;
    const Fluorophore dye = db.fluorophore("AF488");
    scene.media.emplace_back("dye", Spectrum::constant(0), Spectrum::constant(0), 0.0, 1.0, std::vector<DyeComponent>{{dye, 1e-6}});
    addMediumCube(scene, half, 0);
    addStaticSheet(scene, a, 1.0);
    scene.finalize();
    const PathTracer tracer(scene);
    const LightSampler lights(scene);
    const SampledWavelengths wl = SampledWavelengths::atLine(a.wavelength, 1.0);

    nlohmann::json positions = nlohmann::json::array(), widths = nlohmann::json::array(), expected = nlohmann::json::array(),
                   errors = nlohmann::json::array();
    double worst = 0;
    for (int i = 0; i < a.positions; ++i) {
        const double x = -2 * zR + 4 * zR * i / (a.positions - 1);
        const double wx = w0 * std::sqrt(1 + (x / zR) * (x / zR));
        // Excitation irradiance (W/mm²; the dye absorbs σa times it) at 61 points across the sheet, each
        // the mean of the renderer's connection estimates (light sample, transmittance back to where the
        // beam entered the box). It is independent of the dye, which may not absorb at this wavelength.
        double sxx = 0, sx = 0, sy = 0, sxy = 0, sw = 0;
        for (int k = 0; k <= 60; ++k) {
            const double z = -2.5 * wx + 5 * wx * k / 60;
            const Vec3 p(x, 0, z);
            double rate = 0;
            for (int n = 0; n < a.samples; ++n) {
                Rng rng = Rng::forKey(17, static_cast<uint64_t>(i * 1000 + k), static_cast<uint64_t>(n));
                const auto ls = lights.sample(p, rng.uniform(), rng.uniform(), rng.uniform(), wl);
                if (!ls || !(ls->pdf > 0)) continue;
                rate += ls->L[0] * 1e-6 * tracer.transmittance(p, ls->p, 0, wl, rng)[0] / ls->pdf / a.samples;
            }
            if (!(rate > 0)) continue;
            // ln(rate) = c - 2 z²/w²: weighted by rate² (the relative precision of ln rate).
            const double u = z * z, v = std::log(rate), wgt = rate * rate;
            sw += wgt, sx += wgt * u, sy += wgt * v, sxx += wgt * u * u, sxy += wgt * u * v;
        }
        const double slope = (sw * sxy - sx * sy) / (sw * sxx - sx * sx);
        const double fitted = std::sqrt(-2 / slope);
        if (!std::isfinite(fitted)) throw NumericError("validate lightsheet: no excitation profile to fit at x = " + std::to_string(x * 1e3) + " um");
        const double err = fitted / wx - 1;
        worst = std::max(worst, std::abs(err));
        positions.push_back(x * 1e3);
        widths.push_back(fitted * 1e3);
        expected.push_back(wx * 1e3);
        errors.push_back(err);
    }
    const nlohmann::json out = {{"wavelength_nm", a.wavelength},
                                {"waist_um", a.waistUm},
                                {"refractive_index", a.n},
                                {"rayleigh_range_um", zR * 1e3},
                                {"positions_um", positions},
                                {"widths_um", widths},
                                {"expected_widths_um", expected},
                                {"relative_errors", errors},
                                {"max_relative_error", worst}};
    std::ofstream f(a.output);
    if (!f) throw IoError(a.output + ": cannot write");
    f << out.dump(2) << "\n";
    if (!f) throw IoError(a.output + ": write failed");
    std::printf("%s\n", nlohmann::json{{"output", a.output}, {"max_relative_error", worst}, {"rayleigh_range_um", zR * 1e3}}.dump().c_str());
}

}  // namespace

void addLightSheetValidation(CLI::App& validate) {
    auto a = std::make_shared<SheetArgs>();
    CLI::App* cmd = validate.add_subcommand("lightsheet", "Width of the light sheet's excitation profile along the beam against w(x)");
    cmd->add_option("--wavelength", a->wavelength, "Laser wavelength, nm")->required();
    cmd->add_option("--waist", a->waistUm, "Waist w0 (1/e² half-width), um")->required();
    cmd->add_option("--n", a->n, "Refractive index of the medium the sheet is focused in (default 1.33)");
    cmd->add_option("--positions", a->positions, "Positions along the beam (default 9)");
    cmd->add_option("--sigma-s", a->sigmaS,
                    "Scattering of the medium, e.g. 2/mm: then the fluence across the sheet (direct and scattered) is "
                    "measured at depths 50-950 um, with its FWHM and contrast (default 0: clear, fitted widths against w(x))");
    cmd->add_option("--g", a->g, "Henyey-Greenstein anisotropy of the scattering (default 0.9)");
    cmd->add_option("--samples", a->samples, "Estimates per point (default 16; use about 512 with --sigma-s)");
    cmd->add_option("-o,--output", a->output, "Output JSON")->required();
    cmd->callback([a] { runLightSheet(*a); });
}

}  // namespace fluorosim::app
