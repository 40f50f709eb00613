// `fluorosim fit SCENE.json --stack OBSERVED.ome.tif -o FITDIR`: dye concentrations fitted back from an
// observed stack (optics/concentration_fit.h), and `fluorosim gradient SCENE.json -o GRAD.ome.tif`: the
// model's Jacobian columns for users with their own optimiser. The scene is the template: its
// microscope images the stack and its labelled volume says what each parameter scales.
#include <atomic>
#include <csignal>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>

#include "commands.h"
#include "core/errors.h"
#include "core/output_checks.h"
#include "optics/acquire_request.h"
#include "optics/concentration_fit.h"
#include "optics/observed_stack.h"
#include "optics/scene_files.h"
#include "optics/stack_files.h"

namespace fluorosim::app {
namespace fs = std::filesystem;
namespace {

std::atomic<bool> gCancel{false};
extern "C" void onFitSignal(int) { gCancel.store(true); }

struct FitArgs {
    std::optional<int> planes;
    std::optional<std::string> step;
    std::string scene, stack, output, params = "labels", scattered = "auto", likelihood = "deviance";
    std::vector<std::string> channels;
    std::vector<int> labels;
    int scatteredSpp = 64, outer = 3, iterations = 100, threads = 0;
    std::optional<int64_t> seed;
    std::optional<double> priorWeight;
    bool unlabelled = false;
};

optics::FitOptions fitOptions(const FitArgs& a, const Scene& scene) {
    optics::FitOptions o;
    optics::setParametrisation(o, a.params, "--params");
    optics::setScatteredModel(o, a.scattered, "--scattered");
    optics::setLikelihood(o, a.likelihood, "--likelihood");
    o.channels = a.channels;
    o.labels = a.labels;
    o.scatteredSpp = a.scatteredSpp;
    o.outerIterations = a.outer;
    o.maxIterations = a.iterations;
    o.priorWeight = a.priorWeight;
    o.fitUnlabelled = a.unlabelled;
    if (a.threads < 0 || a.threads > 4096) throw ConfigError("--threads: must lie in [0, 4096], got " + std::to_string(a.threads));
    if (a.seed && *a.seed < 0) throw ConfigError("--seed: must be >= 0, got " + std::to_string(*a.seed));
    o.acquisition.threads = a.threads;
    o.acquisition.seed = a.seed ? static_cast<uint64_t>(*a.seed) : scene.render.seed;
    o.cancel = &gCancel;
    o.validate();
    return o;
}

nlohmann::json parameterJson(const Scene& scene, const optics::FitParameter& p) {
    nlohmann::json j = {{"name", p.name}, {"centre_mm", {p.centreMm.x, p.centreMm.y, p.centreMm.z}}, {"reference_uM", p.referenceMolar * 1e6}};
    if (!p.node) {
        j["label"] = p.label.value;
        j["medium"] = scene.media[static_cast<size_t>(p.label.medium)].name();
    } else {
        j["node"] = {p.cell[0], p.cell[1], p.cell[2]};
    }
    return j;
}

void writeText(const fs::path& file, const std::string& text) {
    std::ofstream f(file);
    f << text;
    if (!f) throw IoError(file.string() + ": cannot write");
}

void runFit(const FitArgs& a) {
    // The folder first: a typo should not cost a fit.
    const fs::path dir = a.output;
    if (fs::exists(dir) && !fs::is_directory(dir)) throw IoError(dir.string() + ": exists and is not a folder");
    if (!fs::exists(dir)) {
        const fs::path parent = dir.has_parent_path() ? dir.parent_path() : fs::path(".");
        if (!fs::is_directory(parent)) throw IoError(dir.string() + ": parent folder \"" + parent.string() + "\" does not exist");
        fs::create_directory(dir);
    }
    requireWritableFolder(dir / "fit.json");
    const spectra::Database db;
    Scene scene = optics::loadSceneFile(a.scene, db);
    for (const std::string& w : scene.warnings) std::fprintf(stderr, "fluorosim: warning: %s\n", w.c_str());
    optics::Microscope m = optics::Microscope::fromScene(scene, db);
    optics::applyStackOverrides(m, scene, a.planes, a.step);
    optics::FitOptions o = fitOptions(a, scene);
    o.log = [](const std::string& line) { std::fprintf(stderr, "fit: %s\n", line.c_str()); };
    const optics::ObservedStack observed = optics::readOmeStack(a.stack);
    const optics::FitData data = optics::fitData(observed, m, o);
    std::signal(SIGINT, onFitSignal);
    std::signal(SIGTERM, onFitSignal);
    optics::FitResult r;
    try {
        r = optics::fitConcentrations(scene, m, data, o);
    } catch (const Cancelled& e) {
        throw Interrupted(std::string(e.what()) + "; nothing was written");
    }
    for (const std::string& w : r.warnings) std::fprintf(stderr, "fluorosim: warning: %s\n", w.c_str());

    // Outputs: fit.json, the log, Ceres' reports, the fitted volume, and model and residual stacks.
    nlohmann::json params = nlohmann::json::array();
    for (const optics::FittedParameter& p : r.parameters) {
        nlohmann::json j = parameterJson(scene, p.parameter);
        j["theta"] = p.theta;
        j["standard_error"] = p.standardError;
        j["cramer_rao_bound"] = p.cramerRao;
        j["snr"] = p.snr;
        j["concentration_uM"] = p.concentrationUm;
        j["concentration_standard_error_uM"] = p.concentrationStandardErrorUm;
        j["at_bound"] = p.atBound;
        params.push_back(j);
    }
    nlohmann::json channels = nlohmann::json::array();
    for (size_t c : data.channels) channels.push_back(m.channels[c].name);
    const nlohmann::json summary = {
        {"scene", a.scene},
        {"stack", a.stack},
        {"parametrisation", optics::fitParametrisationName(o.parametrisation)},
        {"grid_cell_um", o.parametrisation == optics::FitParametrisation::Grid ? nlohmann::json(o.gridCellUm) : nlohmann::json(nullptr)},
        {"likelihood", optics::fitLikelihoodName(o.likelihood)},
        {"scattered", optics::scatteredModelName(o.scattered)},
        {"values", data.adu ? "adu" : "electrons"},
        {"saturated_pixels", "left out"},
        {"channels", channels},
        {"parameters", params},
        {"deviance", r.deviance},
        {"chi2", r.chi2},
        {"degrees_of_freedom", r.degreesOfFreedom},
        {"chi2_per_dof", r.chi2 / std::max(1.0, r.degreesOfFreedom)},
        {"deviance_per_dof", r.deviance / std::max(1.0, r.degreesOfFreedom)},
        {"pixels", r.pixels},
        {"saturated_pixels_left_out", r.saturatedPixels},
        {"iterations", r.iterations},
        {"outer_iterations", r.outerIterations},
        {"forward_image_equivalents", r.forwardEquivalents},
        {"prior_weight", r.priorWeight},
        {"seconds", r.seconds},
        {"warnings", r.warnings},
        {"solver_report", r.solverReport}};
    writeText(dir / "fit.json", summary.dump(1) + "\n");
    std::string log;
    for (const std::string& l : r.logLines) log += l + "\n";
    writeText(dir / "fit.log", log);
    writeText(dir / "solver_report.txt", r.solverReport);
    bool volume = false;
    for (const Medium& med : scene.media) volume = volume || med.volume();
    if (volume) optics::writeFittedConcentrations(dir / "concentrations.vdb", scene, r);

    optics::StackMetadata meta;
    meta.pixelSizeUm = m.pixelSizeMm() * 1e3;
    meta.zStepUm = m.stack.stepMm * 1e3;
    meta.exposureS = m.detector.exposureS;
    meta.camera = optics::cameraMetadata(m.detector);
    meta.values = "electrons";
    for (size_t c : data.channels) meta.channels.push_back({m.channels[c].name, m.channels[c].excitationNm, m.channels[c].emissionNm});
    const int nc = static_cast<int>(data.channels.size());
    auto write = [&](const char* name, const std::vector<double>& v, const std::string& what) {
        meta.description = "Fluorosim fit of " + a.stack + ": " + what;
        optics::writeOmeTiffFloat32(dir / name, m.width, m.height, m.stack.planes, nc, std::vector<float>(v.begin(), v.end()), meta);
    };
    write("model.ome.tif", r.model, "the model's expected photoelectrons (with dark current) at the fit");
    write("residual.ome.tif", r.residual, "observed minus model, photoelectrons");
    write("normalised_residual.ome.tif", r.normalisedResidual, "signed-root deviance per pixel (0 where not fitted)");
    nlohmann::json out = summary;
    out.erase("solver_report");
    out["output"] = dir.string();
    std::printf("%s\n", out.dump(1).c_str());
}

struct GradientArgs {
    std::string scene, output, params = "labels";
    std::vector<std::string> channels;
    int threads = 0;
};

void runGradient(const GradientArgs& a) {
    const fs::path out = a.output;
    const std::string text = out.string(), suffix = ".ome.tif";
    if (text.size() <= suffix.size() || text.compare(text.size() - suffix.size(), suffix.size(), suffix) != 0)
        throw ConfigError(text + ": output must end in .ome.tif");
    requireWritableFolder(out);
    const spectra::Database db;
    const Scene scene = optics::loadSceneFile(a.scene, db);
    for (const std::string& w : scene.warnings) std::fprintf(stderr, "fluorosim: warning: %s\n", w.c_str());
    const optics::Microscope m = optics::Microscope::fromScene(scene, db);
    optics::FitOptions o;
    optics::setParametrisation(o, a.params, "--params");
    o.channels = a.channels;
    if (a.threads < 0 || a.threads > 4096) throw ConfigError("--threads: must lie in [0, 4096], got " + std::to_string(a.threads));
    o.acquisition.threads = a.threads;
    o.cancel = &gCancel;
    std::signal(SIGINT, onFitSignal);
    std::signal(SIGTERM, onFitSignal);
    optics::Gradient g;
    try {
        g = optics::fitGradient(scene, m, o);
    } catch (const Cancelled& e) {
        throw Interrupted(std::string(e.what()) + "; nothing was written");
    }
    optics::StackMetadata meta;
    meta.pixelSizeUm = m.pixelSizeMm() * 1e3;
    meta.zStepUm = m.stack.stepMm * 1e3;
    meta.exposureS = m.detector.exposureS;
    meta.camera = optics::cameraMetadata(m.detector);
    meta.values = "electrons";
    meta.timePoints = static_cast<int>(g.columns.size());
    meta.description = "Fluorosim gradient of " + a.scene + ": per parameter (T), the expected photoelectrons per unit of the parameter";
    for (size_t c : g.channels) meta.channels.push_back({m.channels[c].name, m.channels[c].excitationNm, m.channels[c].emissionNm});
    std::vector<float> data;
    for (const auto& c : g.columns) data.insert(data.end(), c.begin(), c.end());
    optics::writeOmeTiffFloat32(out, m.width, m.height, m.stack.planes, static_cast<int>(g.channels.size()), data, meta);
    nlohmann::json params = nlohmann::json::array();
    for (size_t j = 0; j < g.parameters.size(); ++j) {
        nlohmann::json p = parameterJson(scene, g.parameters[j]);
        p["t"] = j;
        params.push_back(p);
    }
    nlohmann::json channels = nlohmann::json::array();
    for (size_t c : g.channels) channels.push_back(m.channels[c].name);
    const nlohmann::json summary = {{"gradient", out.string()}, {"parametrisation", optics::fitParametrisationName(o.parametrisation)},
                                    {"channels", channels}, {"parameters", params}};
    const fs::path index = fs::path(text.substr(0, text.size() - suffix.size()) + ".json");
    writeText(index, summary.dump(1) + "\n");
    std::printf("%s\n", summary.dump(1).c_str());
}

}  // namespace

void addFitCommands(CLI::App& app) {
    auto a = std::make_shared<FitArgs>();
    CLI::App* fit = app.add_subcommand("fit", "Fit dye concentrations to an observed OME-TIFF stack (maximum likelihood, Ceres)");
    fit->add_option("scene", a->scene, "Scene file: the template (its labelled volume and microscope)")->required()->check(CLI::ExistingFile);
    fit->add_option("--stack", a->stack, "Observed stack (OME-TIFF with Fluorosim's camera metadata, or expected photoelectrons)")->required();
    fit->add_option("-o,--output", a->output, "Output folder: fit.json, fit.log, solver_report.txt, concentrations.vdb, model/residual stacks")->required();
    fit->add_option("--planes", a->planes, "Planes of the stack, as given to acquire (default: the scene's)");
    fit->add_option("--step", a->step, "Plane step, as given to acquire, e.g. 1um (default: the scene's)");
    fit->add_option("--params", a->params, "labels (one scale per label), grid:CELL (e.g. grid:8um), or coarse to fine, e.g. grid:16um>8um>4um");
    fit->add_option("--channels", a->channels, "Channels to fit (default: every channel of the stack)")->delimiter(',');
    fit->add_option("--scattered", a->scattered, "Scattered light in the model: labels (one render tallied per label; the default per label), reestimated (a render per outer iteration, held fixed; the default with a grid), none");
    fit->add_option("--scattered-spp", a->scatteredSpp, "Paths per pixel of the scattered light's render");
    fit->add_option("--likelihood", a->likelihood, "deviance (maximum likelihood) or pearson (biased; for comparison)");
    fit->add_option("--outer", a->outer, "Outer iterations at most (attenuation and scattered light refreshed between)");
    fit->add_option("--iterations", a->iterations, "Trust-region iterations per outer iteration, at most");
    fit->add_option("--prior-weight", a->priorWeight, "Grid: weight of the gradient prior (default: the discrepancy rule)");
    fit->add_option("--labels", a->labels, "Per label: fit only these labels (others stay at the scene's concentrations)")->delimiter(',');
    fit->add_flag("--unlabelled", a->unlabelled, "Fit dye outside every label (and homogeneous dyed media) too");
    fit->add_option("--threads", a->threads, "Threads (0: all cores)");
    fit->add_option("--seed", a->seed, "Seed of the scattered light's render");
    fit->callback([a] { runFit(*a); });

    auto g = std::make_shared<GradientArgs>();
    CLI::App* grad = app.add_subcommand("gradient", "Write the model's Jacobian columns (one stack per parameter, along T) at the scene's concentrations");
    grad->add_option("scene", g->scene, "Scene file")->required()->check(CLI::ExistingFile);
    grad->add_option("-o,--output", g->output, "Output OME-TIFF (parameters along T; a .json beside it lists them)")->required();
    grad->add_option("--params", g->params, "labels or grid:CELL");
    grad->add_option("--channels", g->channels, "Channels (default: all)")->delimiter(',');
    grad->add_option("--threads", g->threads, "Threads (0: all cores)");
    grad->callback([g] { runGradient(*g); });
}

}  // namespace fluorosim::app
