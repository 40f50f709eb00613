// `fluorosim validate emission` and `validate sweep`: a dyed, highly scattering ball lit by one
// spectral line. `emission` renders it and compares the image-averaged fluorescent spectrum with the
// dye's emission spectrum; `sweep` moves the line across the excitation band and compares the
// fluorescence it produces with the dye's excitation spectrum.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <memory>
#include <sstream>

#include <nlohmann/json.hpp>

#include "cli_checks.h"
#include "commands.h"
#include "core/output_checks.h"
#include "core/errors.h"
#include "core/message.h"
#include "core/parallel.h"
#include "core/units.h"
#include "database.h"
#include "progress.h"
#include "render/flux_sensor.h"
#include "render/renderer.h"

namespace fluorosim::app {
namespace {

struct BallArgs {
    std::string dye;
    std::string concentration = "0.2 uM";  // dilute: dye absorption along a typical scattered path stays below 1 %
    std::string sigmaS = "10 /mm";
    std::string output;
    int threads = 0;
    uint64_t seed = 1;
};

constexpr double kRadius = 1.0;  // mm

struct DyedBall {
    Fluorophore dye;
    double molar;
    double sigmaS;
};

std::string numberText(double v) {
    std::ostringstream os;
    os << v;
    return os.str();
}

DyedBall parseBall(const BallArgs& a, const spectra::Database& db) {
    checkThreadCount(a.threads, "--threads");
    const Fluorophore dye = db.fluorophore(a.dye);
    const double c = parseQuantity(a.concentration, Dimension::MolarConcentration, "--concentration");
    if (!(c >= 0) || c > 10) throw ConfigError("--concentration: must lie in [0, 10 M], got \"" + excerpt(a.concentration) + "\"");
    const double s = parseQuantity(a.sigmaS, Dimension::InverseLength, "--sigma-s");
    if (!(s >= 0) || s > 1e5) throw ConfigError("--sigma-s: must lie in [0, 1e5 /mm], got \"" + excerpt(a.sigmaS) + "\"");
    return {dye, c, s};
}

// The ball (index-matched, so no caustics) and a point light 5 mm away emitting `power` W/sr at the line.
Scene ballScene(const DyedBall& b, double excitationNm, double power, double lambdaMin, double lambdaMax) {
    Scene scene;
    scene.spectral.lambdaMin = lambdaMin;
    scene.spectral.lambdaMax = lambdaMax;
    scene.spectral.binWidth = 1.0;
    scene.media.emplace_back("dyed solvent", Spectrum::constant(0), Spectrum::constant(b.sigmaS), 0.0, 1.0,
                             std::vector<DyeComponent>{{b.dye, b.molar}});
    scene.geometry.addSphere(Vec3(0, 0, 0), kRadius);
    ShapeInfo ball;
    ball.name = "ball";
    ball.isInterface = true;
    ball.insideMedium = 0;
    scene.shapes.push_back(ball);
    scene.lights.push_back(PointLight{Vec3(0, 0, 5), Spectrum::lines({{excitationNm, power}})});
    // Seen from the side, at right angles to the light.
    scene.camera.position = Vec3(5, 0, 0);
    scene.camera.frame = Frame::fromNormal(Vec3(-1, 0, 0));
    scene.camera.tanHalfFovY = 1.15 * kRadius / 5;
    scene.camera.width = scene.camera.height = 32;
    scene.finalize();
    return scene;
}

double pearson(const std::vector<double>& a, const std::vector<double>& b) {
    const double n = static_cast<double>(a.size());
    double ma = 0, mb = 0;
    for (size_t i = 0; i < a.size(); ++i) ma += a[i] / n, mb += b[i] / n;
    double sab = 0, saa = 0, sbb = 0;
    for (size_t i = 0; i < a.size(); ++i) {
        sab += (a[i] - ma) * (b[i] - mb);
        saa += sqr(a[i] - ma);
        sbb += sqr(b[i] - mb);
    }
    return saa > 0 && sbb > 0 ? sab / std::sqrt(saa * sbb) : 0.0;
}

size_t argmax(const std::vector<double>& v) { return static_cast<size_t>(std::max_element(v.begin(), v.end()) - v.begin()); }

void normalizeToMax(std::vector<double>& v) {
    const double m = *std::max_element(v.begin(), v.end());
    if (m > 0)
        for (double& x : v) x /= m;
}

void writeJson(const std::string& path, const nlohmann::json& j) {
    std::ofstream f(path);
    if (!f) throw IoError(path + ": cannot open for writing");
    f << j.dump(1) << "\n";
    if (!f) throw IoError(path + ": write failed");
}

struct EmissionArgs : BallArgs {
    double excitation = 0;
    int spp = 32768;
};

void runEmission(const EmissionArgs& a) {
    requireWritableFolder(a.output);  // before minutes of rendering
    const spectra::Database db;
    const DyedBall b = parseBall(a, db);
    if (!(a.excitation >= 200 && a.excitation <= 1200))
        throw ConfigError("--excitation: must lie in [200, 1200] nm, got " + numberText(a.excitation));
    if (a.spp < 1 || a.spp > 1 << 20) throw ConfigError("--spp: must lie in [1, 1048576], got " + std::to_string(a.spp));
    const auto [emLo, emHi] = b.dye.emissionSupport();
    const double lo = std::floor(std::min(a.excitation - 1, emLo)), hi = std::ceil(std::max(a.excitation + 1, emHi));
    const Scene scene = ballScene(b, a.excitation, 1.0, lo, hi);
    Film film(scene.camera.width, scene.camera.height, lo, hi, 1.0, db.cie1931(), true);
    RenderOptions opt;
    opt.spp = a.spp;
    opt.threads = a.threads;
    opt.seed = a.seed;
    opt.sppPerPass = 0;  // automatic: 32x32 pixels would otherwise give passes of 1024 paths
    ProgressBar bar("validate emission");
    opt.progress = [&](double f) { bar.update(f); };
    const RenderSummary s = render(scene, film, opt);
    bar.finish();
    const ExrImage img = film.image(a.spp);
    const SpectralLayer& fl = *std::find_if(img.spectral.begin(), img.spectral.end(), [](const SpectralLayer& l) { return l.prefix == "fluorescent"; });
    const size_t pixels = static_cast<size_t>(img.width) * static_cast<size_t>(img.height);
    const size_t bins = fl.wavelengthsNm.size();
    std::vector<char> lit(pixels, 0);
    for (size_t bIdx = 0; bIdx < bins; ++bIdx)
        for (size_t p = 0; p < pixels; ++p) lit[p] = lit[p] || fl.values[bIdx * pixels + p] > 0;
    const double litCount = static_cast<double>(std::count(lit.begin(), lit.end(), 1));
    if (litCount == 0) throw Error("no pixel received fluorescence: is the dye excited at " + std::to_string(a.excitation) + " nm?");
    // Energy radiance x λ is proportional to photon radiance, the units of the dye's emission spectrum.
    std::vector<double> wavelength, rendered, reference;
    for (size_t bIdx = 0; bIdx < bins; ++bIdx) {
        const double l = fl.wavelengthsNm[bIdx];
        if (l < emLo || l > emHi) continue;
        double sum = 0;
        for (size_t p = 0; p < pixels; ++p)
            if (lit[p]) sum += fl.values[bIdx * pixels + p];
        wavelength.push_back(l);
        rendered.push_back(sum / litCount * l);
        reference.push_back(b.dye.emissionPdf(l));
    }
    normalizeToMax(rendered);
    normalizeToMax(reference);
    const double r = pearson(rendered, reference);
    const double peakR = wavelength[argmax(rendered)], peakRef = wavelength[argmax(reference)];
    const nlohmann::json out = {{"dye", b.dye.id()},
                                {"excitation_nm", a.excitation},
                                {"concentration_M", b.molar},
                                {"sigma_s_per_mm", b.sigmaS},
                                {"spp", a.spp},
                                {"seconds", s.seconds},
                                {"illuminated_pixels", litCount},
                                {"units", "rendered: image-averaged fluorescent radiance x wavelength (photon units), normalized to its maximum"},
                                {"wavelength_nm", wavelength},
                                {"rendered", rendered},
                                {"reference", reference},
                                {"pearson", r},
                                {"rendered_peak_nm", peakR},
                                {"reference_peak_nm", peakRef}};
    writeJson(a.output, out);
    std::printf("%s\n", nlohmann::json{{"dye", b.dye.id()}, {"pearson", r}, {"rendered_peak_nm", peakR}, {"reference_peak_nm", peakRef},
                                       {"seconds", s.seconds}, {"output", a.output}}.dump().c_str());
}

struct SweepArgs : BallArgs {
    double from = 300, to = 700, step = 10;
    double paths = 100000;
};

void runSweep(const SweepArgs& a) {
    requireWritableFolder(a.output);  // before minutes of simulation
    const spectra::Database db;
    const DyedBall b = parseBall(a, db);
    if (!(a.from >= 200 && a.to <= 1200 && a.from <= a.to && a.step > 0) || (a.to - a.from) / a.step > 1000)
        throw ConfigError("--from/--to/--step: need 200 <= from <= to <= 1200 nm, step > 0 and at most 1000 steps, got " +
                          numberText(a.from) + ", " + numberText(a.to) + ", " + numberText(a.step));
    if (!(a.paths >= 100 && a.paths <= 1e9)) throw ConfigError("--paths: must lie in [100, 1e9], got " + numberText(a.paths));
    const auto [emLo, emHi] = b.dye.emissionSupport();
    // The peak: where the dye's excitation spectrum (peak 1) is largest, on a 1 nm grid.
    double peak = a.from, best = -1;
    for (double l = 200; l <= 1200; l += 1.0)
        if (b.dye.molarExtinction(l) > best) best = b.dye.molarExtinction(l), peak = l;
    std::vector<double> edges;
    // 5 nm bands: the emission spectra are smooth on that scale, and narrower bands only add noise.
    for (double l = std::floor(emLo); l < emHi + 5; l += 5) edges.push_back(l);
    std::vector<double> reference;
    for (size_t i = 0; i + 1 < edges.size(); ++i) reference.push_back(b.dye.emission().integral(edges[i], edges[i + 1]));
    normalizeToMax(reference);
    // Equal photon rates at every wavelength (power ∝ 1/λ), so absorbed photons follow ε(λ).
    auto measure = [&](double lambda) {
        const double lo = std::floor(std::min(lambda - 1, emLo)), hi = std::ceil(std::max(lambda + 1, emHi));
        const Scene scene = ballScene(b, lambda, peak / lambda, lo, hi);
        FluxSensorOptions o;
        o.radius = kRadius * 1.0001;
        o.paths = static_cast<uint64_t>(a.paths);
        o.seed = a.seed;
        o.threads = a.threads;
        o.binEdgesNm = edges;
        return measureExitantFlux(scene, o);
    };
    const FluxSensorResult atPeak = measure(peak);
    const double peakPhotons = atPeak.fluorescentPowerTimesLambda.mean;
    if (!(peakPhotons > 0)) throw Error("no fluorescence at the excitation peak " + std::to_string(peak) + " nm");
    nlohmann::json rows = nlohmann::json::array();
    ProgressBar bar("validate sweep");
    const int steps = static_cast<int>(std::floor((a.to - a.from) / a.step + 1e-9)) + 1;
    double worstScale = 0, worstCorrelation = 1;
    for (int i = 0; i < steps; ++i) {
        const double lambda = a.from + i * a.step;
        const FluxSensorResult r = measure(lambda);
        std::vector<double> shape;
        for (const TallyValue& t : r.binPower) shape.push_back(t.mean);
        // Band power x band centre ~ photons per band.
        for (size_t k = 0; k < shape.size(); ++k) shape[k] *= 0.5 * (edges[k] + edges[k + 1]);
        normalizeToMax(shape);
        const double emitted = r.fluorescentPowerTimesLambda.mean / peakPhotons;
        const double excitation = b.dye.molarExtinction(lambda) / b.dye.extinctionPeak();
        const bool signal = r.fluorescentPowerTimesLambda.mean > 5 * r.fluorescentPowerTimesLambda.stderr_ && excitation > 0.05;
        const double corr = signal ? pearson(shape, reference) : 0.0;
        if (signal) {
            worstScale = std::max(worstScale, std::abs(emitted - excitation));
            worstCorrelation = std::min(worstCorrelation, corr);
        }
        rows.push_back({{"excitation_nm", lambda},
                        {"emitted_photons_relative", emitted},
                        {"emitted_photons_relative_stderr", r.fluorescentPowerTimesLambda.stderr_ / peakPhotons},
                        {"excitation_spectrum_relative", excitation},
                        {"signal", signal},
                        {"emission_shape_pearson", corr}});
        bar.update(static_cast<double>(i + 1) / steps);
    }
    bar.finish();
    const nlohmann::json out = {{"dye", b.dye.id()},
                                {"concentration_M", b.molar},
                                {"sigma_s_per_mm", b.sigmaS},
                                {"excitation_peak_nm", peak},
                                {"paths_per_wavelength", a.paths},
                                {"units", "emitted photons per incident photon, relative to the excitation peak; light of equal photon rate at every wavelength"},
                                {"max_abs_scale_error_with_signal", worstScale},
                                {"min_shape_pearson_with_signal", worstCorrelation},
                                {"rows", rows}};
    writeJson(a.output, out);
    std::printf("%s\n", nlohmann::json{{"dye", b.dye.id()}, {"max_abs_scale_error_with_signal", worstScale},
                                       {"min_shape_pearson_with_signal", worstCorrelation}, {"output", a.output}}.dump().c_str());
}

void addBallOptions(CLI::App* cmd, BallArgs* a) {
    cmd->add_option("--dye", a->dye, "Dye id or alias from spectra/data/dyes.json (e.g. AF488)")->required();
    cmd->add_option("--concentration", a->concentration, "Dye concentration (e.g. 1uM, 0.1mM)");
    cmd->add_option("--sigma-s", a->sigmaS, "Scattering coefficient of the solvent (e.g. 10/mm)");
    cmd->add_option("-o,--output", a->output, "Output JSON")->required();
    cmd->add_option("--threads", a->threads, "Threads (0 = all cores)");
    cmd->add_option("--seed", a->seed, "Random seed")->check(nonNegativeInteger());
}

}  // namespace

void addFluorescenceValidations(CLI::App& validate) {
    auto emission = std::make_shared<EmissionArgs>();
    CLI::App* e = validate.add_subcommand("emission", "Rendered fluorescence spectrum of a dyed ball against the dye's emission spectrum");
    addBallOptions(e, emission.get());
    e->add_option("--excitation", emission->excitation, "Excitation line, nm")->required();
    e->add_option("--spp", emission->spp, "Samples per pixel on 32x32 pixels (the default takes about 2 minutes on 2 cores)");
    e->callback([emission] { runEmission(*emission); });

    auto sweep = std::make_shared<SweepArgs>();
    CLI::App* s = validate.add_subcommand("sweep", "Fluorescence of a dyed ball against the dye's excitation spectrum, over excitation wavelengths");
    addBallOptions(s, sweep.get());
    s->add_option("--from", sweep->from, "First excitation wavelength, nm");
    s->add_option("--to", sweep->to, "Last excitation wavelength, nm");
    s->add_option("--step", sweep->step, "Step, nm");
    s->add_option("--paths", sweep->paths, "Paths per wavelength");
    s->callback([sweep] { runSweep(*sweep); });
}

}  // namespace fluorosim::app
