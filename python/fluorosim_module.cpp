// `import fluorosim`: scenes (a file or a dict), render and acquire, returning NumPy arrays. The only
// file that includes pybind11. Library errors become Python exceptions carrying the messages the CLI
// prints: ConfigError -> ValueError, IoError -> OSError, other errors -> RuntimeError. The GIL is
// released while rendering.
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>
#include <pybind11/stl/filesystem.h>

#include <atomic>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "core/errors.h"
#include "core/units.h"
#include "database.h"
#include "optics/acquisition.h"
#include "optics/acquisition_summary.h"
#include "optics/concentration_fit.h"
#include "optics/ground_truth.h"
#include "optics/observed_stack.h"
#include "optics/stack_files.h"
#include "render/fluorescence.h"
#include "render/renderer.h"
#include "volume/density_grid.h"
#include "optics/acquire_request.h"
#include "optics/scene_files.h"
#include "optics/setup_checks.h"
#include "optics/voxelize_request.h"

namespace py = pybind11;
namespace fs = std::filesystem;
using namespace fluorosim;

namespace {

const spectra::Database& database() {
    static const spectra::Database db;
    return db;
}

// A scene from a path, or from a dict in the scene format (relative file names then resolve against
// `base`, the current folder by default).
Scene loadAnyScene(const py::object& scene, const std::optional<std::string>& base) {
    const spectra::Database& db = database();
    if (py::isinstance<py::dict>(scene)) {
        const std::string text = py::module_::import("json").attr("dumps")(scene).cast<std::string>();
        const fs::path where = fs::path(base.value_or(fs::current_path().string())) / "<dict>";
        return loadSceneFromString(
            text, where, [&db](const std::string& ref, const fs::path& b) { return db.resolve(ref, b); },
            [&db](const std::string& name, std::optional<double> ec, std::optional<double> qy) { return db.fluorophore(name, ec, qy); },
            [](const LightSheetSpec& spec) { return optics::makeLightSheet(spec); });
    }
    return optics::loadSceneFile(py::str(scene).cast<std::string>(), db);
}

template <typename T>
py::array_t<T> toArray(const std::vector<T>& values, std::vector<py::ssize_t> shape) {
    py::array_t<T> a(shape);
    std::copy(values.begin(), values.end(), a.mutable_data());
    return a;
}

// Runs `work(cancel, fraction)` without the GIL on a worker thread while this thread, holding the GIL
// between naps of 0.1 s, passes the work's progress to `progress` (a callable taking a fraction in
// [0, 1], or None) and watches for Ctrl-C: it sets `cancel`, the work stops at its next check, and the
// KeyboardInterrupt is raised once the worker has ended (finished work is dropped; nothing is written).
template <class Work>
void runInterruptible(const py::object& progress, Work&& work) {
    std::atomic<bool> cancel{false}, done{false};
    std::atomic<double> fraction{0.0};
    std::exception_ptr failure;
    std::thread worker([&] {
        try {
            work(cancel, fraction);
        } catch (...) {
            failure = std::current_exception();
        }
        done = true;
    });
    bool interrupted = false;
    double reported = -1;
    std::exception_ptr callbackFailure;
    while (!done) {
        {
            py::gil_scoped_release release;
            for (int i = 0; i < 10 && !done; ++i) std::this_thread::sleep_for(std::chrono::milliseconds(10));
        }
        if (!interrupted && PyErr_CheckSignals() != 0) {
            interrupted = true;
            cancel = true;
            PyErr_Clear();
        }
        const double f = fraction.load();
        if (!progress.is_none() && !cancel && f != reported) {
            reported = f;
            try {
                progress(f);
            } catch (...) {  // an error in the callback stops the work and is raised
                callbackFailure = std::current_exception();
                cancel = true;
            }
        }
    }
    {
        py::gil_scoped_release release;
        worker.join();
    }
    if (callbackFailure) std::rethrow_exception(callbackFailure);
    if (interrupted) throw Cancelled("interrupted (Ctrl-C)");
    if (failure) std::rethrow_exception(failure);
    if (!progress.is_none() && reported != 1.0) progress(1.0);
}

py::dict renderScene(const py::object& sceneArg, std::optional<int> spp, std::optional<uint64_t> seed, int threads,
                const std::optional<std::string>& base, const py::object& progress) {
    const Scene scene = [&] {
        Scene s = loadAnyScene(sceneArg, base);
        if (seed) s.render.seed = *seed;
        return s;
    }();
    RenderOptions opt;
    opt.spp = spp.value_or(scene.render.spp);
    opt.threads = threads;
    opt.seed = scene.render.seed;
    opt.sppPerPass = 0;  // automatic: passes of at least kMinPathsPerPass paths
    opt.validate();
    Film film(scene.camera.width, scene.camera.height, scene.spectral.lambdaMin, scene.spectral.lambdaMax, scene.spectral.binWidth,
              database().cie1931(), FluorescencePlan(scene).active());
    RenderSummary summary;
    runInterruptible(progress, [&](std::atomic<bool>& cancel, std::atomic<double>& fraction) {
        opt.cancel = &cancel;
        opt.progress = [&](double f) { fraction = f; };
        summary = fluorosim::render(scene, film, opt);
    });
    const ExrImage img = film.image(summary.sppCompleted);
    const auto h = static_cast<py::ssize_t>(img.height), w = static_cast<py::ssize_t>(img.width);
    py::dict out, layers, spectral;
    out["rgb"] = toArray(img.rgb, {h, w, 3});
    for (const RgbLayer& l : img.rgbLayers) layers[py::str(l.prefix)] = toArray(l.rgb, {h, w, 3});
    for (const SpectralLayer& l : img.spectral) {
        const auto bins = static_cast<py::ssize_t>(l.wavelengthsNm.size());
        spectral[py::str(l.prefix.empty() ? "total" : l.prefix)] = toArray(l.values, {bins, h, w});
    }
    out["rgb_layers"] = layers;
    out["spectral"] = spectral;  // per layer: (bins, height, width), spectral radiance per nm
    out["wavelengths_nm"] = toArray(img.spectral.at(0).wavelengthsNm, {static_cast<py::ssize_t>(img.spectral.at(0).wavelengthsNm.size())});
    out["spp"] = summary.sppCompleted;
    out["seed"] = opt.seed;
    out["seconds"] = summary.seconds;
    out["paths"] = summary.stats.paths;
    out["non_finite_samples"] = summary.nonFiniteSamples;
    return out;
}

// Library warnings as Python warnings (UserWarning), so that filters and pytest see them.
void warnAll(const std::vector<std::string>& messages) {
    for (const std::string& w : messages)
        if (PyErr_WarnEx(PyExc_UserWarning, w.c_str(), 1) != 0) throw py::error_already_set();
}

// Where a stack's pixels and planes lie in the scene: axes, world positions of the first pixel's centre
// and the unit steps of x (columns), y (rows) and z (planes), in µm.
void addGeometry(py::dict& out, const optics::Microscope& m) {
    const Vec3 origin = optics::pixelCentreMm(m, 0, 0, 0);
    const Vec3 dx = optics::pixelCentreMm(m, 0, 1, 0) - origin, dy = optics::pixelCentreMm(m, 0, 0, 1) - origin;
    const Vec3 dz = m.stack.planes > 1 ? optics::pixelCentreMm(m, 1, 0, 0) - origin : normalize(m.focus.towardObjective) * m.stack.stepMm;
    auto um = [](const Vec3& v) { return std::vector<double>{v.x * 1e3, v.y * 1e3, v.z * 1e3}; };
    out["axes"] = "CZYX";
    out["origin_um"] = um(origin);
    out["x_step_um"] = um(dx);
    out["y_step_um"] = um(dy);
    out["z_step_vector_um"] = um(dz);
    out["pixel_size_um"] = m.pixelSizeMm() * 1e3;
    out["z_step_um"] = m.stack.stepMm * 1e3;
}

// A stack's scene, microscope and options from Python's arguments: the request checked before the
// scene loads, the channels selected (`what` names the option in errors), the library's warnings raised
// as Python warnings. Built in place: the scene is not moved once loaded.
struct StackSetup {
    const Scene scene;
    optics::Microscope microscope;
    optics::AcquireOptions options;
    std::vector<size_t> channels;
    StackSetup(const py::object& sceneArg, const std::optional<std::string>& base, const optics::AcquireRequest& request,
               const std::vector<std::string>& names, const std::string& what)
        : scene((optics::checkAcquireRequest(request), loadAnyScene(sceneArg, base))), microscope(optics::Microscope::fromScene(scene, database())) {
        options = optics::applyAcquireRequest(request, scene, microscope);
        channels = microscope.selectChannels(names, what);
        warnAll(scene.warnings);
        warnAll(microscope.warnings);
        for (size_t c : channels) warnAll(microscope.channels[c].warnings);
        warnAll(optics::checkSetup(scene, microscope, channels));
    }
};

py::dict acquireScene(const py::object& sceneArg, std::optional<int> planes, const std::optional<std::string>& step, std::optional<int> spp,
                 std::optional<int64_t> seed, const std::vector<std::string>& channels, int threads, const std::optional<std::string>& base,
                 const std::string& estimator, std::optional<int> directSpp, std::optional<double> noiseRatio, std::optional<int> maxSpp,
                 const py::object& progress, const std::optional<std::string>& exposure, std::optional<int64_t> fieldPhotons,
                 std::optional<int64_t> emissionPhotons, std::optional<double> fieldMarginUm, std::optional<double> fieldReachUm,
                 std::optional<double> fieldDiffuseUm) {
    optics::AcquireRequest request;
    request.exposure = exposure;
    request.fieldPhotons = fieldPhotons;
    request.fieldMarginUm = fieldMarginUm;
    request.fieldReachUm = fieldReachUm;
    request.fieldDiffuseUm = fieldDiffuseUm;
    request.emissionPhotons = emissionPhotons;
    request.planes = planes;
    request.step = step;
    request.spp = spp;
    request.seed = seed;
    request.threads = threads;
    request.estimator = estimator;
    if (directSpp)
        throw ConfigError("direct_spp: removed: the split estimator now computes the unscattered image (no samples); spp sets the paths for "
                          "the scattered light");
    request.noiseRatio = noiseRatio;
    request.maxSpp = maxSpp;
    StackSetup setup(sceneArg, base, request, channels, "--channels");
    const Scene& scene = setup.scene;
    optics::Microscope& m = setup.microscope;
    optics::AcquireOptions& o = setup.options;
    const std::vector<size_t>& selected = setup.channels;
    optics::Stack stack = optics::emptyStack(m, selected);
    optics::AcquisitionSummary report(m, stack, o);
    std::vector<std::string> planeWarnings;
    runInterruptible(progress, [&](std::atomic<bool>& cancel, std::atomic<double>& fraction) {
        o.cancel = &cancel;
        optics::StackCallbacks callbacks;
        callbacks.progress = [&](double f) { fraction = f; };
        callbacks.planeDone = [&](size_t slot, int plane, const optics::PlaneImage& image) {
            if (std::string w = report.addPlane(slot, plane, image); !w.empty()) planeWarnings.push_back(std::move(w));
        };
        if (!optics::acquireStack(scene, m, stack, o, callbacks)) throw Cancelled("acquire cancelled");
    });
    warnAll(planeWarnings);
    std::optional<optics::AutoExposure> chosen;
    if (const optics::ExposureRequest e = optics::parseExposure(exposure); e.autoFraction) chosen = optics::autoExpose(stack, m, *e.autoFraction, o.seed);
    warnAll(report.warnings(stack, m));
    const std::vector<py::ssize_t> shape{static_cast<py::ssize_t>(stack.channels.size()), stack.planes, stack.height, stack.width};
    py::dict out;
    out["counts"] = toArray(stack.counts, shape);  // (channel, z, y, x), ADU, one noisy read-out
    out["expected"] = toArray(stack.expected, shape);
    out["stderr"] = toArray(stack.stderrElectrons, shape);
    py::list names;
    for (size_t c : stack.channels) names.append(m.channels[c].name);
    out["channels"] = names;
    addGeometry(out, m);
    out["spp"] = o.spp;
    out["seed"] = o.seed;
    out["estimator"] = optics::estimatorName(o.estimator);
    // The CLI's summary, the same numbers under the same names.
    py::dict summary;
    for (const optics::AcquisitionSummary::Entry& e : report.entries(stack, m, chosen, 1)) {
        const py::object value = e.null ? py::none() : e.count ? py::object(py::int_(static_cast<int64_t>(e.value))) : py::object(py::float_(e.value));
        if (e.group.empty()) summary[e.name.c_str()] = value;
        else {
            if (!summary.contains(e.group.c_str())) summary[e.group.c_str()] = py::dict();
            summary[e.group.c_str()].cast<py::dict>()[e.name.c_str()] = value;
        }
    }
    summary["seed"] = o.seed;
    summary["estimator"] = optics::estimatorName(o.estimator);
    out["summary"] = summary;
    out["exposure_s"] = m.detector.exposureS;
    return out;
}

// The ground truth on the stack's grid: concentrations per dye and the perfect microscope's image.
py::dict groundTruthOf(const py::object& sceneArg, std::optional<int> planes, const std::optional<std::string>& step,
                       const std::vector<std::string>& channels, int threads, const std::optional<std::string>& base) {
    optics::AcquireRequest request;
    request.planes = planes;
    request.step = step;
    request.threads = threads;
    StackSetup setup(sceneArg, base, request, channels, "channels");
    const Scene& scene = setup.scene;
    const optics::Microscope& m = setup.microscope;
    optics::AcquireOptions& o = setup.options;
    const std::vector<size_t>& selected = setup.channels;
    optics::GroundTruth truth;
    runInterruptible(py::none(), [&](std::atomic<bool>& cancel, std::atomic<double>&) {
        o.cancel = &cancel;
        truth = optics::groundTruth(scene, m, selected, o);
        if (cancel) throw Cancelled("ground truth cancelled");
    });
    const py::ssize_t z = truth.planes, y = truth.height, x = truth.width;
    const size_t stackPixels = static_cast<size_t>(z * y * x);
    py::dict concentration;
    for (size_t d = 0; d < truth.dyes.size(); ++d)
        concentration[py::str(truth.dyes[d])] =
            toArray(std::vector<float>(truth.concentration.begin() + static_cast<std::ptrdiff_t>(d * stackPixels),
                                       truth.concentration.begin() + static_cast<std::ptrdiff_t>((d + 1) * stackPixels)),
                    {z, y, x});
    py::dict out;
    out["concentration"] = concentration;  // per dye id, (z, y, x), mol/L
    out["ideal"] = toArray(truth.ideal, {static_cast<py::ssize_t>(selected.size()), z, y, x});
    py::list names;
    for (size_t c : selected) names.append(m.channels[c].name);
    out["channels"] = names;
    addGeometry(out, m);
    return out;
}

std::vector<double> checkedWavelengths(const std::vector<double>& wavelengthsNm) {
    for (double l : wavelengthsNm)
        if (!(l > 0) || !std::isfinite(l)) throw ConfigError("wavelengths_nm: must be positive and finite, got " + std::to_string(l));
    return wavelengthsNm;
}

// A dye of the database on the caller's wavelengths: ε(λ) in M^-1 cm^-1 and the emission density in 1/nm.
py::dict dyeSpectra(const std::string& name, const std::vector<double>& wavelengthsNm) {
    const Fluorophore f = database().fluorophore(name);
    const std::vector<double> l = checkedWavelengths(wavelengthsNm);
    std::vector<double> extinction, emission;
    for (double x : l) {
        extinction.push_back(f.molarExtinction(x));
        emission.push_back(f.emissionPdf(x));
    }
    const auto n = static_cast<py::ssize_t>(l.size());
    py::dict out;
    out["id"] = f.id();
    out["wavelengths_nm"] = toArray(l, {n});
    out["molar_extinction"] = toArray(extinction, {n});
    out["emission_pdf"] = toArray(emission, {n});
    out["extinction_peak"] = f.extinctionPeak();
    out["quantum_yield"] = f.quantumYield();
    return out;
}

// A filter of the database: its transmission (0..1) on the caller's wavelengths.
py::array_t<double> filterTransmission(const std::string& name, const std::vector<double>& wavelengthsNm) {
    const TabulatedSpectrum t = database().filter(name);
    const std::vector<double> l = checkedWavelengths(wavelengthsNm);
    std::vector<double> values;
    for (double x : l) values.push_back(t(x));
    return toArray(values, {static_cast<py::ssize_t>(l.size())});
}

// NumPy arrays (z, y, x) into an OpenVDB file a scene's "volume" can name: one float grid per entry of
// `grids` (concentrations in `units`), and an optional Int32 label grid. Voxel (i, j, k) = array[k, j, i]
// has its centre at origin + (i, j, k) × voxel, so array[0, 0, 0] lies at `origin`.
py::dict writeVolume(const fs::path& file, const py::dict& grids, const std::string& voxel, const std::vector<std::string>& origin,
                     const std::string& units, const std::optional<py::array_t<int32_t, py::array::c_style | py::array::forcecast>>& labels,
                     const std::string& labelName) {
    const double voxelMm = parseQuantity(voxel, Dimension::Length, "voxel");
    if (!(voxelMm > 0)) throw ConfigError("voxel: must be positive, got " + voxel);
    if (origin.size() != 3) throw ConfigError("origin: expected three lengths, e.g. [\"0 um\", \"0 um\", \"0 um\"]");
    const Vec3 o(parseQuantity(origin[0], Dimension::Length, "origin[0]"), parseQuantity(origin[1], Dimension::Length, "origin[1]"),
                 parseQuantity(origin[2], Dimension::Length, "origin[2]"));
    if (!unitScale(units, Dimension::MolarConcentration)) throw ConfigError("units: expected a molar concentration unit (M, mM, uM, nM, pM), got \"" + units + "\"");
    if (grids.empty()) throw ConfigError("grids: expected at least one {name: array (z, y, x)}");
    const Affine worldFromIndex = Affine::scaling(voxelMm).then(Affine::translation(o));
    std::vector<DensityGrid> made;
    std::vector<std::string> names;
    std::array<py::ssize_t, 3> shape{};
    auto boxOf = [&](const std::array<py::ssize_t, 3>& zyx) {
        IndexBox b;
        b.hi = {static_cast<int32_t>(zyx[2] - 1), static_cast<int32_t>(zyx[1] - 1), static_cast<int32_t>(zyx[0] - 1)};
        return b;
    };
    for (const auto& [key, value] : grids) {
        const std::string name = py::str(key);
        const auto a = py::array_t<double, py::array::c_style | py::array::forcecast>::ensure(value);
        if (!a || a.ndim() != 3) throw ConfigError("grids[\"" + name + "\"]: expected a 3-D array (z, y, x)");
        const std::array<py::ssize_t, 3> s{a.shape(0), a.shape(1), a.shape(2)};
        if (names.empty()) shape = s;
        else if (s != shape) throw ConfigError("grids[\"" + name + "\"]: shape differs from the first grid's");
        const double* data = a.data();
        for (py::ssize_t i = 0; i < a.size(); ++i)
            if (!(data[i] >= 0) || !std::isfinite(data[i]))
                throw ConfigError("grids[\"" + name + "\"]: values must be finite and >= 0, got " + std::to_string(data[i]) + " at flat index " + std::to_string(i));
        made.push_back(DensityGrid::fromVoxels(
            name, boxOf(s), worldFromIndex, [&](int i, int j, int k) { return data[(static_cast<size_t>(k) * s[1] + j) * s[2] + i]; }, GridMetadata{units, "mm"}));
        names.push_back(name);
    }
    if (labels) {
        const auto& l = *labels;
        if (l.ndim() != 3 || l.shape(0) != shape[0] || l.shape(1) != shape[1] || l.shape(2) != shape[2])
            throw ConfigError("labels: expected an integer array of the grids' shape (z, y, x)");
        const int32_t* data = l.data();
        made.push_back(DensityGrid::fromVoxels(labelName, boxOf(shape), worldFromIndex,
                                               [&](int i, int j, int k) { return data[(static_cast<size_t>(k) * shape[1] + j) * shape[2] + i]; },
                                               GridMetadata{"", "mm"}));
        names.push_back(labelName);
    }
    std::vector<GridToWrite> out;
    for (size_t g = 0; g < made.size(); ++g) out.push_back({names[g], &made[g], labels && g + 1 == made.size()});
    writeDensityGrids(file.string(), out);
    py::dict result;
    result["output"] = file.string();
    result["grids"] = names;
    result["voxel_size_um"] = voxelMm * 1e3;
    return result;
}

// `fluorosim voxelize` from Python: the same checks and messages, the grids written to `output`.
// Paths as str or any os.PathLike (pathlib.Path), as Python users hold them.
py::dict voxelizeSwc(const std::vector<fs::path>& swc, const std::string& voxel, const std::vector<std::string>& dyes,
                     const std::vector<std::string>& concentrations, const fs::path& output, const std::vector<std::string>& grids,
                     const std::string& mode, const std::optional<std::string>& membraneThickness, int supersampling, int threads,
                     const std::vector<std::string>& offsets, const std::vector<std::string>& rotations) {
    optics::VoxelizeArgs a;
    a.offsets = offsets;
    a.rotations = rotations;
    for (const fs::path& f : swc) a.swc.push_back(f.string());
    a.voxel = voxel;
    a.dyes = dyes;
    a.concentrations = concentrations;
    a.output = output.string();
    a.grids = grids;
    a.mode = mode;
    a.membraneThickness = membraneThickness;
    a.supersampling = supersampling;
    a.threads = threads;
    if (a.swc.empty()) throw ConfigError("swc: give at least one SWC file");
    VoxelizeSummary s;
    {
        py::gil_scoped_release release;
        s = optics::voxelizeFiles(a, database(), nullptr);
    }
    py::list gridList;
    for (const VoxelizedGridSummary& g : s.grids) {
        py::dict d;
        d["name"] = g.name;
        d["units"] = g.units;
        d["active_voxels"] = g.activeVoxels;
        d["covered_volume_um3"] = g.coveredVolumeUm3;
        d["analytic_volume_um3"] = g.analyticVolumeUm3;
        d["max_value"] = g.maxValue;
        gridList.append(d);
    }
    py::dict out;
    out["output"] = output;
    out["grids"] = gridList;
    out["label_voxels"] = s.labelVoxels;
    out["voxel_size_um"] = s.voxelSizeMm * 1e3;
    out["seconds"] = s.seconds;
    return out;
}


py::dict parameterDict(const Scene& scene, const optics::FitParameter& p) {
    py::dict d;
    d["name"] = p.name;
    if (p.node) d["node"] = py::make_tuple(p.cell[0], p.cell[1], p.cell[2]);
    else {
        d["label"] = p.label.value;
        d["medium"] = scene.media[static_cast<size_t>(p.label.medium)].name();
    }
    d["centre_mm"] = py::make_tuple(p.centreMm.x, p.centreMm.y, p.centreMm.z);
    d["reference_uM"] = p.referenceMolar * 1e6;
    return d;
}

optics::FitOptions fitOptionsFrom(const std::string& params, const std::string& scattered, int scatteredSpp, const std::string& likelihood, int outer,
                                  int iterations, std::optional<double> priorWeight, const std::vector<int>& labels, bool unlabelled,
                                  const std::vector<std::string>& channels, std::optional<std::vector<double>> start, int threads,
                                  std::optional<int64_t> seed, const Scene& scene) {
    optics::FitOptions o;
    optics::setParametrisation(o, params, "params");
    optics::setScatteredModel(o, scattered, "scattered");
    optics::setLikelihood(o, likelihood, "likelihood");
    o.scatteredSpp = scatteredSpp;
    o.outerIterations = outer;
    o.maxIterations = iterations;
    o.priorWeight = priorWeight;
    o.labels = labels;
    o.fitUnlabelled = unlabelled;
    o.channels = channels;
    o.start = std::move(start);
    if (threads < 0 || threads > 4096) throw ConfigError("threads: must lie in [0, 4096], got " + std::to_string(threads));
    if (seed && *seed < 0) throw ConfigError("seed: must be >= 0, got " + std::to_string(*seed));
    o.acquisition.threads = threads;
    o.acquisition.seed = seed ? static_cast<uint64_t>(*seed) : scene.render.seed;
    o.validate();
    return o;
}

// An observed stack from a path (an OME-TIFF, read as the CLI reads it) or from an array (C, Z, Y, X)
// with what the caller says about it; what the caller leaves out comes from the scene's microscope.
optics::ObservedStack observedStack(const py::object& stack, const optics::Microscope& m, const std::optional<std::vector<std::string>>& channels,
                                    std::optional<double> pixelSizeUm, std::optional<double> zStepUm, const std::optional<py::dict>& camera,
                                    const std::string& values) {
    if (py::isinstance<py::str>(stack) || py::hasattr(stack, "__fspath__"))
        return optics::readOmeStack(py::str(py::module_::import("os").attr("fspath")(stack)).cast<std::string>());
    const auto a = py::array_t<double, py::array::c_style | py::array::forcecast>::ensure(stack);
    if (!a || a.ndim() != 4) throw ConfigError("stack: expected a path or an array of shape (channels, planes, height, width)");
    optics::ObservedStack s;
    s.path = "<array>";
    s.channels = static_cast<int>(a.shape(0));
    s.planes = static_cast<int>(a.shape(1));
    s.height = static_cast<int>(a.shape(2));
    s.width = static_cast<int>(a.shape(3));
    s.data.assign(a.data(), a.data() + a.size());
    s.pixelSizeUm = pixelSizeUm.value_or(m.pixelSizeMm() * 1e3);
    s.zStepUm = zStepUm.value_or(m.stack.stepMm * 1e3);
    s.exposureS = m.detector.exposureS;
    if (values != "adu" && values != "electrons") throw ConfigError("values: expected \"adu\" or \"electrons\", got \"" + values + "\"");
    s.values = values;
    s.integerPixels = values == "adu";
    if (channels) s.channelNames = *channels;
    else
        for (const optics::MicroscopeChannel& c : m.channels) s.channelNames.push_back(c.name);
    if (static_cast<int>(s.channelNames.size()) != s.channels)
        throw ConfigError("stack: " + std::to_string(s.channels) + " channels in the array, " + std::to_string(s.channelNames.size()) + " names");
    optics::CameraMetadata cam = optics::cameraMetadata(m.detector);
    if (camera) {
        const py::dict& c = *camera;
        for (const auto& item : c) {
            const std::string k = py::str(item.first);
            if (k == "sensor") cam.sensor = py::str(item.second);
            else if (k == "gain_e_per_adu") cam.gainElectronsPerAdu = item.second.cast<double>();
            else if (k == "offset_adu") cam.offsetAdu = item.second.cast<double>();
            else if (k == "read_noise_e") cam.readNoiseElectrons = item.second.cast<double>();
            else if (k == "em_gain") cam.emGain = item.second.cast<double>();
            else if (k == "dark_current_e_per_s") cam.darkCurrentElectronsPerS = item.second.cast<double>();
            else if (k == "full_well_e") cam.fullWellElectrons = item.second.cast<double>();
            else if (k == "bit_depth") cam.bitDepth = item.second.cast<int>();
            else
                throw ConfigError("camera: unknown key \"" + k + "\" (known: sensor, gain_e_per_adu, offset_adu, read_noise_e, em_gain, dark_current_e_per_s, "
                                  "full_well_e, bit_depth)");
        }
    }
    s.camera = cam;
    return s;
}

py::dict fitStack(const py::object& sceneArg, const py::object& stackArg, std::optional<int> planes, const std::optional<std::string>& step,
                  const std::optional<std::vector<std::string>>& stackChannels,
                  std::optional<double> pixelSizeUm, std::optional<double> zStepUm, const std::optional<py::dict>& camera, const std::string& values,
                  const std::string& params, const std::vector<std::string>& channels, const std::string& scattered, int scatteredSpp,
                  const std::string& likelihood, int outer, int iterations, std::optional<double> priorWeight, const std::vector<int>& labels,
                  bool unlabelled, std::optional<std::vector<double>> start, int threads, std::optional<int64_t> seed,
                  const std::optional<std::string>& base) {
    Scene scene = loadAnyScene(sceneArg, base);
    optics::Microscope m = optics::Microscope::fromScene(scene, database());
    optics::applyStackOverrides(m, scene, planes, step);
    optics::FitOptions o =
        fitOptionsFrom(params, scattered, scatteredSpp, likelihood, outer, iterations, priorWeight, labels, unlabelled, channels, std::move(start), threads, seed, scene);
    const optics::ObservedStack observed = observedStack(stackArg, m, stackChannels, pixelSizeUm, zStepUm, camera, values);
    const optics::FitData data = optics::fitData(observed, m, o);
    optics::FitResult r;
    runInterruptible(py::none(), [&](std::atomic<bool>& cancel, std::atomic<double>&) {
        o.cancel = &cancel;
        r = optics::fitConcentrations(scene, m, data, o);
    });
    py::list ps;
    std::vector<double> theta, se, crb, conc, concSe;
    for (const optics::FittedParameter& p : r.parameters) {
        py::dict d = parameterDict(scene, p.parameter);
        d["theta"] = p.theta;
        d["standard_error"] = p.standardError;
        d["cramer_rao_bound"] = p.cramerRao;
        d["snr"] = p.snr;
        d["concentration_uM"] = p.concentrationUm;
        d["concentration_standard_error_uM"] = p.concentrationStandardErrorUm;
        d["at_bound"] = p.atBound;
        ps.append(d);
        theta.push_back(p.theta);
        se.push_back(p.standardError);
        crb.push_back(p.cramerRao);
        conc.push_back(p.concentrationUm);
        concSe.push_back(p.concentrationStandardErrorUm);
    }
    const auto n = static_cast<py::ssize_t>(theta.size());
    const std::vector<py::ssize_t> shape{static_cast<py::ssize_t>(data.channels.size()), m.stack.planes, m.height, m.width};
    py::dict out;
    out["parameters"] = ps;
    out["theta"] = toArray(theta, {n});
    out["standard_error"] = toArray(se, {n});
    out["cramer_rao_bound"] = toArray(crb, {n});
    out["concentration_uM"] = toArray(conc, {n});
    out["concentration_standard_error_uM"] = toArray(concSe, {n});
    py::list names;
    for (size_t c : data.channels) names.append(m.channels[c].name);
    out["channels"] = names;
    out["model"] = toArray(r.model, shape);
    out["residual"] = toArray(r.residual, shape);
    out["normalised_residual"] = toArray(r.normalisedResidual, shape);
    out["deviance"] = r.deviance;
    out["chi2"] = r.chi2;
    out["degrees_of_freedom"] = r.degreesOfFreedom;
    out["pixels"] = r.pixels;
    out["saturated_pixels_left_out"] = r.saturatedPixels;
    out["iterations"] = r.iterations;
    out["outer_iterations"] = r.outerIterations;
    out["forward_image_equivalents"] = r.forwardEquivalents;
    out["prior_weight"] = r.priorWeight;
    out["seconds"] = r.seconds;
    out["warnings"] = r.warnings;
    out["solver_report"] = r.solverReport;
    return out;
}

py::dict gradientOf(const py::object& sceneArg, const std::string& params, const std::vector<std::string>& channels, int threads,
                    const std::optional<std::string>& base) {
    const Scene scene = loadAnyScene(sceneArg, base);
    const optics::Microscope m = optics::Microscope::fromScene(scene, database());
    optics::FitOptions o;
    optics::setParametrisation(o, params, "params");
    o.channels = channels;
    if (threads < 0 || threads > 4096) throw ConfigError("threads: must lie in [0, 4096], got " + std::to_string(threads));
    o.acquisition.threads = threads;
    optics::Gradient g;
    {
        py::gil_scoped_release release;
        g = optics::fitGradient(scene, m, o);
    }
    std::vector<float> all;
    for (const auto& c : g.columns) all.insert(all.end(), c.begin(), c.end());
    py::list ps, names;
    for (const optics::FitParameter& p : g.parameters) ps.append(parameterDict(scene, p));
    for (size_t c : g.channels) names.append(m.channels[c].name);
    py::dict out;
    out["columns"] = toArray(all, {static_cast<py::ssize_t>(g.columns.size()), static_cast<py::ssize_t>(g.channels.size()), m.stack.planes, m.height, m.width});
    out["parameters"] = ps;
    out["channels"] = names;
    out["pixel_size_um"] = m.pixelSizeMm() * 1e3;
    out["z_step_um"] = m.stack.stepMm * 1e3;
    return out;
}

}  // namespace

PYBIND11_MODULE(fluorosim, mod) {
    mod.doc() = "Fluorosim: spectral Monte Carlo simulation of fluorescence microscopy (docs/python.md)";
    // Registered most derived first, so that each error reaches its own Python type.
    py::register_exception_translator([](std::exception_ptr p) {
        try {
            if (p) std::rethrow_exception(p);
        } catch (const Cancelled& e) {
            PyErr_SetString(PyExc_KeyboardInterrupt, e.what());
        } catch (const ConfigError& e) {
            PyErr_SetString(PyExc_ValueError, e.what());
        } catch (const IoError& e) {
            PyErr_SetString(PyExc_OSError, e.what());
        } catch (const Error& e) {
            PyErr_SetString(PyExc_RuntimeError, e.what());
        }
    });
    mod.def("render", &renderScene, py::arg("scene"), py::kw_only(), py::arg("spp") = py::none(), py::arg("seed") = py::none(),
            py::arg("threads") = 0, py::arg("base") = py::none(), py::arg("progress") = py::none(),
            "Render a scene (a path or a dict). Returns a dict: rgb (H, W, 3), rgb_layers, spectral {layer: (bins, H, W)}, "
            "wavelengths_nm, spp, seed, seconds, paths, non_finite_samples. progress: a callable given the fraction done (0..1), "
            "about every 0.1 s. Ctrl-C stops the render and raises KeyboardInterrupt.");
    mod.def("acquire", &acquireScene, py::arg("scene"), py::kw_only(), py::arg("planes") = py::none(), py::arg("step") = py::none(),
            py::arg("spp") = py::none(), py::arg("seed") = py::none(), py::arg("channels") = std::vector<std::string>{},
            py::arg("threads") = 0, py::arg("base") = py::none(), py::arg("estimator") = "split", py::arg("direct_spp") = py::none(),
            py::arg("noise_ratio") = py::none(), py::arg("max_spp") = py::none(), py::arg("progress") = py::none(),
            py::arg("exposure") = py::none(), py::arg("field_photons") = py::none(), py::arg("emission_photons") = py::none(),
            py::arg("field_margin_um") = py::none(), py::arg("field_reach_um") = py::none(), py::arg("field_diffuse_um") = py::none(),
            "Acquire a light-sheet z-stack of a scene with a microscope block. Returns a dict: counts (uint16), expected and "
            "stderr (float32), each (channel, z, y, x); channels, the geometry (axes, origin_um, x/y_step_um, z_step_vector_um, "
            "pixel_size_um, z_step_um), spp, seed, exposure_s, and summary (the CLI's JSON summary as a dict). Same numbers as "
            "`fluorosim acquire` with the same options (estimator: split or path; noise_ratio and max_spp: adaptive sampling; "
            "exposure: a time such as \"20 ms\", or \"auto\" / \"auto:F\" to put the brightest pixel at F of the full well; "
            "field_photons: the excitation field's photons per beam line and plane, 0 for none; emission_photons: the photons per "
            "plane and channel that trace the computed emission's scattered light forward, default 4 per pixel, 0 to leave it to "
            "camera paths; field_margin_um and field_reach_um: how far the field reaches beyond the computed region and from the "
            "focal plane, where the traced photons carry the dye's light, default 100 and 120 um, more in strongly scattering tissue; "
            "field_diffuse_um: the node spacing of the light of photons that have scattered ten times, default a tenth of the "
            "transport length within 4-50 um, 0 for none). "
            "progress: a callable given the fraction done (0..1), about every 0.1 s. Ctrl-C stops the run and raises "
            "KeyboardInterrupt.");
    mod.def("ground_truth", &groundTruthOf, py::arg("scene"), py::kw_only(), py::arg("planes") = py::none(), py::arg("step") = py::none(),
            py::arg("channels") = std::vector<std::string>{}, py::arg("threads") = 0, py::arg("base") = py::none(),
            "The ground truth of the scene's stack on the detector grid: {'concentration': {dye id: (z, y, x) mol/L at the pixel "
            "centres}, 'ideal': (channel, z, y, x) expected photoelectrons of a perfect microscope (no attenuation, no scattered "
            "light, no dark current, no noise), 'channels', and the stack's geometry: 'axes' 'CZYX', 'origin_um' (the first "
            "pixel's centre), 'x_step_um', 'y_step_um', 'z_step_vector_um' (world vectors of one column, row and plane), "
            "'pixel_size_um', 'z_step_um'}.");
    mod.def("write_volume", &writeVolume, py::arg("path"), py::arg("grids"), py::kw_only(), py::arg("voxel"),
            py::arg("origin") = std::vector<std::string>{"0 um", "0 um", "0 um"}, py::arg("units") = "uM", py::arg("labels") = py::none(),
            py::arg("label_grid") = "label",
            "Writes NumPy concentration arrays (z, y, x) into an OpenVDB file for a scene's \"volume\": grids = {name: array} in "
            "`units` (a molar unit), voxel = its edge with a unit, origin = the centre of array[0, 0, 0] as three lengths; labels = "
            "an optional integer array of the same shape (neuron ids, 0 for none), written as `label_grid`.");
    mod.def("voxelize", &voxelizeSwc, py::arg("swc"), py::kw_only(), py::arg("voxel"), py::arg("dyes"), py::arg("concentrations"),
            py::arg("output"), py::arg("grids") = std::vector<std::string>{}, py::arg("mode") = "filled",
            py::arg("membrane_thickness") = py::none(), py::arg("supersampling") = 4, py::arg("threads") = 0,
            py::arg("offsets") = std::vector<std::string>{}, py::arg("rotations") = std::vector<std::string>{},
            "Voxelize SWC neurons into an OpenVDB file, as `fluorosim voxelize` (one dye and concentration, or one per file; "
            "offsets [\"100um,0um,0um\", ...] and rotations [\"z:90,x:15\", ...] place each neuron as --offset and --rotate do). "
            "Returns a dict: output, grids [{name, units, active_voxels, covered_volume_um3, analytic_volume_um3, max_value}], "
            "label_voxels, voxel_size_um, seconds.");
    mod.def("fit", &fitStack, py::arg("scene"), py::arg("stack"), py::kw_only(), py::arg("planes") = py::none(), py::arg("step") = py::none(),
            py::arg("stack_channels") = py::none(),
            py::arg("pixel_size_um") = py::none(), py::arg("z_step_um") = py::none(), py::arg("camera") = py::none(), py::arg("values") = "adu",
            py::arg("params") = "labels", py::arg("channels") = std::vector<std::string>{}, py::arg("scattered") = "auto",
            py::arg("scattered_spp") = 64, py::arg("likelihood") = "deviance", py::arg("outer") = 3, py::arg("iterations") = 100,
            py::arg("prior_weight") = py::none(), py::arg("labels") = std::vector<int>{}, py::arg("unlabelled") = false,
            py::arg("start") = py::none(), py::arg("threads") = 0, py::arg("seed") = py::none(), py::arg("base") = py::none(),
            "Fit dye concentrations to an observed stack, as `fluorosim fit` (planes and step as given to acquire). `stack`: an OME-TIFF path, or an array (C, Z, Y, X) of "
            "ADU (values='adu') or photoelectrons (values='electrons') with stack_channels (names), pixel_size_um, z_step_um and "
            "camera (a dict: sensor, gain_e_per_adu, offset_adu, read_noise_e, em_gain, dark_current_e_per_s, full_well_e, "
            "bit_depth); what is not given comes from the scene's microscope. Returns a dict: parameters [{name, label, medium, "
            "theta, standard_error, cramer_rao_bound, concentration_uM, concentration_standard_error_uM, at_bound}], theta, "
            "standard_error, concentration_uM (arrays), model, residual, normalised_residual (C, Z, Y, X), deviance, chi2, "
            "degrees_of_freedom, iterations, outer_iterations, seconds, warnings, solver_report.");
    mod.def("gradient", &gradientOf, py::arg("scene"), py::kw_only(), py::arg("params") = "labels",
            py::arg("channels") = std::vector<std::string>{}, py::arg("threads") = 0, py::arg("base") = py::none(),
            "The model's Jacobian at the scene's concentrations, as `fluorosim gradient`: columns (P, C, Z, Y, X) of expected "
            "photoelectrons per unit of each parameter, parameters, channels, pixel_size_um, z_step_um.");
    mod.def("dyes", [] { return database().dyeIds(); }, "The dyes of the spectral database.");
    mod.def("filters", [] { return database().filterNames(); }, "The filters of the spectral database.");
    mod.def("dye", &dyeSpectra, py::arg("name"), py::arg("wavelengths_nm"),
            "A dye on the given wavelengths: dict with molar_extinction (M^-1 cm^-1), emission_pdf (1/nm), extinction_peak, "
            "quantum_yield, id.");
    mod.def("filter_transmission", &filterTransmission, py::arg("name"), py::arg("wavelengths_nm"),
            "A filter's transmission (0..1) on the given wavelengths.");
}
