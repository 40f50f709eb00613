// `fluorosim acquire SCENE.json -o STACK.ome.tif`: moves the light sheet and the focal plane together
// through the sample, renders each plane's expected photoelectrons, applies the detector's noise and
// writes a 16-bit OME-TIFF stack plus a float32 OME-TIFF of the expected photoelectrons.
// The scene's "microscope" block (docs/optics.md) describes objective, detector, channels and stack.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <optional>

#include "commands.h"
#include "core/errors.h"
#include "core/units.h"
#include "io/image_io.h"
#include "optics/acquisition.h"
#include "optics/ome_tiff.h"
#include "output_checks.h"
#include "progress.h"
#include "scene_files.h"

namespace fluorosim::app {
namespace fs = std::filesystem;
namespace {

using json = nlohmann::json;

struct AcquireArgs {
    std::string scene, output;
    std::optional<int> planes, spp;
    std::optional<std::string> step;
    std::optional<uint64_t> seed;
    int threads = 0;
    std::vector<std::string> channels;  // names to acquire (default: all)
};

// Field access that names the JSON path in every error.
struct Field {
    const json& j;
    std::string path;
    [[noreturn]] void fail(const std::string& what) const { throw ConfigError("microscope" + path + ": " + what + " (got " + j.dump() + ")"); }
    bool has(const char* k) const { return j.is_object() && j.contains(k); }
    // Every key must be one of `keys`: a misspelt field is an error, not a silent default.
    void allowOnly(std::initializer_list<const char*> keys) const {
        if (!j.is_object()) fail("expected an object");
        for (auto it = j.begin(); it != j.end(); ++it) {
            bool known = false;
            for (const char* k : keys) known = known || it.key() == k;
            if (!known) throw ConfigError("microscope" + path + ": unknown field \"" + it.key() + "\"");
        }
    }
    Field at(const char* k) const {
        if (!has(k)) throw ConfigError("microscope" + path + ": missing required field \"" + k + "\"");
        return {j.at(k), path + "/" + k};
    }
    double number() const {
        if (!j.is_number() || !std::isfinite(j.get<double>())) fail("expected a number");
        return j.get<double>();
    }
    std::string str() const {
        if (!j.is_string()) fail("expected a string");
        return j.get<std::string>();
    }
    double quantity(Dimension d) const {
        try {
            return parseQuantity(str(), d, "microscope" + path);
        } catch (const ConfigError&) {
            fail(std::string("expected a ") + dimensionName(d) + " with a unit");
        }
    }
    Vec3 vec(Dimension d) const {
        if (!j.is_array() || j.size() != 3) fail("expected 3 values");
        Vec3 v;
        for (int i = 0; i < 3; ++i) {
            const Field e{j.at(static_cast<size_t>(i)), path + "/" + std::to_string(i)};
            v[i] = d == Dimension::Dimensionless ? e.number() : e.quantity(d);
        }
        return v;
    }
};

// A filter: a database name, {"center", "fwhm"} (band-pass) or {"long_pass": edge} (a dichroic).
optics::Filter parseFilter(const Field& f, const spectra::Database& db) {
    if (f.j.is_string()) {
        try {
            return optics::Filter::fromDatabase(db, f.str());
        } catch (const Error& e) {
            f.fail(e.what());
        }
    }
    if (f.has("long_pass")) {
        f.allowOnly({"long_pass"});
        optics::EdgeFilterOptions e;
        e.edgeNm = f.at("long_pass").quantity(Dimension::Wavelength);
        try {
            return optics::Filter::longPass(e);
        } catch (const ConfigError& err) {
            f.fail(err.what());
        }
    }
    f.allowOnly({"center", "fwhm"});
    optics::BandPassOptions b;
    b.centreNm = f.at("center").quantity(Dimension::Wavelength);
    b.fwhmNm = f.at("fwhm").quantity(Dimension::Wavelength);
    try {
        return optics::Filter::bandPass(b);
    } catch (const ConfigError& e) {
        f.fail(e.what());
    }
}

optics::DetectorOptions detectorOptions(const Field& d) {
    d.allowOnly({"type", "pixel_pitch", "width", "height", "qe", "exposure_s", "gain_e_per_adu", "offset_adu", "read_noise_e",
                 "dark_current_e_per_s", "full_well_e", "bit_depth", "em_gain"});
    optics::DetectorOptions o;
    if (d.has("type")) {
        const std::string t = d.at("type").str();
        if (t == "EMCCD") o.type = optics::SensorType::Emccd;
        else if (t != "sCMOS") d.at("type").fail("expected \"sCMOS\" or \"EMCCD\"");
    }
    if (d.has("pixel_pitch")) o.pixelPitchUm = d.at("pixel_pitch").quantity(Dimension::Length) * 1e3;
    if (d.has("qe")) o.qe = Spectrum::constant(d.at("qe").number());
    if (d.has("exposure_s")) o.exposureS = d.at("exposure_s").number();
    if (d.has("gain_e_per_adu")) o.gainElectronsPerAdu = d.at("gain_e_per_adu").number();
    if (d.has("offset_adu")) o.offsetAdu = d.at("offset_adu").number();
    if (d.has("read_noise_e")) o.readNoiseElectrons = d.at("read_noise_e").number();
    if (d.has("dark_current_e_per_s")) o.darkCurrentElectronsPerS = d.at("dark_current_e_per_s").number();
    if (d.has("full_well_e")) o.fullWellElectrons = d.at("full_well_e").number();
    if (d.has("bit_depth")) o.bitDepth = static_cast<int>(d.at("bit_depth").number());
    if (d.has("em_gain")) o.emGain = d.at("em_gain").number();
    try {
        o.validate();
    } catch (const ConfigError& e) {
        throw ConfigError("microscope/detector: " + std::string(e.what()));
    }
    return o;
}

// A beam seen through a channel's excitation path (excitation filter, dichroic reflection).
class FilteredBeam final : public BeamProfile {
public:
    FilteredBeam(std::shared_ptr<BeamProfile> beam, optics::FilterSet filters) : beam_(std::move(beam)), filters_(std::move(filters)) {}
    int sides() const override { return beam_->sides(); }
    Vec3 direction(int side) const override { return beam_->direction(side); }
    double irradiance(const Vec3& p, int side, double lambdaNm) const override {
        return beam_->irradiance(p, side, lambdaNm) * filters_.excitationPath(lambdaNm);
    }
    const Spectrum& spectrum() const override { return beam_->spectrum(); }
    void moveTo(double offsetMm) override { beam_->moveTo(offsetMm); }

private:
    std::shared_ptr<BeamProfile> beam_;
    optics::FilterSet filters_;
};

// A preview PNG of the expected photoelectrons: the maximum projection along z (left) and the x-z
// slice through the middle row (right, z stretched to the true aspect). Channel colours: green,
// magenta, red, cyan; each channel scaled to its 99.5th percentile.
void writeStackPreview(const fs::path& png, const std::vector<float>& e, int width, int height, int planes, int channels, double zOverPixel) {
    static const float colours[4][3] = {{0, 1, 0}, {1, 0, 1}, {1, 0, 0}, {0, 1, 1}};
    const int stretch = std::max(1, static_cast<int>(std::lround(zOverPixel)));
    const int sliceRows = planes * stretch, gap = 4, outW = 2 * width + gap, outH = std::max(height, sliceRows);
    std::vector<float> rgb(static_cast<size_t>(outW) * outH * 3, 0.0f);
    const size_t plane = static_cast<size_t>(width) * height;
    for (int c = 0; c < channels; ++c) {
        const float* base = e.data() + static_cast<size_t>(c) * plane * planes;
        std::vector<float> mip(plane, 0.0f);
        for (int k = 0; k < planes; ++k)
            for (size_t i = 0; i < plane; ++i) mip[i] = std::max(mip[i], base[k * plane + i]);
        std::vector<float> sorted = mip;
        std::sort(sorted.begin(), sorted.end());
        const float scale = sorted[static_cast<size_t>(0.995 * (sorted.size() - 1))];
        if (!(scale > 0)) continue;
        const float* col = colours[c % 4];
        auto put = [&](int x, int y, float v) {
            const float t = std::min(1.0f, v / scale);
            for (int k = 0; k < 3; ++k) rgb[(static_cast<size_t>(y) * outW + x) * 3 + k] += col[k] * t;
        };
        for (int y = 0; y < height; ++y)
            for (int x = 0; x < width; ++x) put(x, y, mip[static_cast<size_t>(y) * width + x]);
        for (int k = 0; k < planes; ++k)
            for (int r = 0; r < stretch; ++r)
                for (int x = 0; x < width; ++x) put(width + gap + x, k * stretch + r, base[k * plane + static_cast<size_t>(height / 2) * width + x]);
    }
    // The PNG writer applies the sRGB curve; these values are already display-scaled in [0, 1].
    writePngPreview(png.string(), outW, outH, rgb, 1.0);
}

void runAcquire(const AcquireArgs& a) {
    const spectra::Database db;
    Scene scene = loadSceneFile(a.scene, db);
    for (const std::string& w : scene.warnings) std::fprintf(stderr, "fluorosim: warning: %s\n", w.c_str());
    if (scene.microscopeJson.empty()) throw ConfigError(a.scene + ": the scene has no \"microscope\" block (docs/optics.md)");
    const json mj = json::parse(scene.microscopeJson);
    const Field m{mj, ""};
    m.allowOnly({"objective", "focus", "detector", "channels", "stack"});
    // Channels switch lights on and off by index; emitting shapes keep indices of their own.
    for (const Light& l : scene.lights)
        if (std::holds_alternative<AreaLight>(l))
            throw ConfigError(a.scene + ": acquire supports light sheets, widefield, point and spot lights, not emitting shapes");
    if (a.seed) scene.render.seed = *a.seed;

    optics::ObjectiveOptions objective;
    const Field obj = m.at("objective");
    obj.allowOnly({"na", "magnification", "immersion_index", "working_distance"});
    objective.na = obj.at("na").number();
    objective.magnification = obj.at("magnification").number();
    if (obj.has("immersion_index")) objective.immersionIndex = obj.at("immersion_index").number();
    if (obj.has("working_distance")) objective.workingDistanceMm = obj.at("working_distance").quantity(Dimension::Length);
    try {
        objective.validate();
    } catch (const ConfigError& e) {
        throw ConfigError("microscope/objective: " + std::string(e.what()));
    }
    const Field det = m.at("detector");
    const optics::DetectorOptions detector = detectorOptions(det);
    const int width = static_cast<int>(det.at("width").number()), height = static_cast<int>(det.at("height").number());
    if (width < 1 || height < 1 || width > 8192 || height > 8192) det.fail("width and height must lie in [1, 8192]");
    optics::FocalPlane focus;
    const Field f = m.at("focus");
    f.allowOnly({"center", "toward_objective", "up"});
    focus.centreMm = f.at("center").vec(Dimension::Length);
    if (f.has("toward_objective")) focus.towardObjective = normalize(f.at("toward_objective").vec(Dimension::Dimensionless));
    if (f.has("up")) focus.up = f.at("up").vec(Dimension::Dimensionless);

    // Stack: the scene's defaults, overridden on the command line.
    int planes = 1;
    double stepMm = 0.001;
    if (m.has("stack")) {
        const Field s = m.at("stack");
        s.allowOnly({"planes", "step"});
        if (s.has("planes")) planes = static_cast<int>(s.at("planes").number());
        if (s.has("step")) stepMm = s.at("step").quantity(Dimension::Length);
    }
    if (a.planes) planes = *a.planes;
    if (a.step) stepMm = parseQuantity(*a.step, Dimension::Length, "--step");
    if (planes < 1 || planes > 4096) throw ConfigError("--planes: must lie in [1, 4096], got " + std::to_string(planes));
    if (!(stepMm > 0)) throw ConfigError("--step: must be positive");
    const int spp = a.spp.value_or(scene.render.spp);
    if (spp < 1) throw ConfigError("--spp: must be positive, got " + std::to_string(spp));

    // Channels: each with its lights on (default all) and an emission filter.
    struct Channel {
        std::string name;
        std::vector<size_t> lights;
        optics::Filter filter = optics::Filter::open();  // the whole emission path
        std::optional<optics::FilterSet> filters;
        bool filteredExcitation = false;  // an excitation filter or a dichroic acts on the lights
        double excitationNm = 0, emissionNm = 0;
    };
    std::vector<Channel> channels;
    const Field ch = m.at("channels");
    if (!ch.j.is_array() || ch.j.empty()) ch.fail("expected a non-empty array of channels");
    for (size_t i = 0; i < ch.j.size(); ++i) {
        const Field c{ch.j.at(i), "/channels/" + std::to_string(i)};
        c.allowOnly({"name", "emission_filter", "excitation_filter", "dichroic", "lights"});
        Channel out;
        out.name = c.at("name").str();
        // Emission path: dichroic transmission times emission filter; excitation path: excitation
        // filter times dichroic reflection (a light-sheet's illumination arm has no dichroic: omit it).
        optics::FilterSet filters{out.name, optics::Filter::open(), std::nullopt, parseFilter(c.at("emission_filter"), db)};
        if (c.has("excitation_filter")) filters.excitation = parseFilter(c.at("excitation_filter"), db);
        if (c.has("dichroic")) filters.dichroic = parseFilter(c.at("dichroic"), db);
        out.filter = filters.dichroic ? optics::Filter(out.name + " emission path", filters.emissionPathCurve()) : filters.emission;
        out.filters = filters;
        out.filteredExcitation = c.has("excitation_filter") || c.has("dichroic");
        if (c.has("lights")) {
            for (const auto& l : c.at("lights").j) {
                if (!l.is_number_integer() || l.get<int>() < 0 || static_cast<size_t>(l.get<int>()) >= scene.lights.size())
                    c.at("lights").fail("expected indices into the scene's lights (0 .. " + std::to_string(scene.lights.size() - 1) + ")");
                out.lights.push_back(static_cast<size_t>(l.get<int>()));
            }
        } else {
            for (size_t l = 0; l < scene.lights.size(); ++l) out.lights.push_back(l);
        }
        for (size_t l : out.lights)
            if (const auto lines = emissionSpectrum(scene.lights[l]).spectralLines(); !lines.empty() && out.excitationNm == 0)
                out.excitationNm = lines[0].lambdaNm;
        if (out.excitationNm == 0)
            c.fail("its lights have no laser line; the stack's metadata needs an excitation wavelength");
        out.emissionNm = optics::measurePassBand(out.filter.curve()).centreNm();
        // A filter that passes almost none of a dye's emission is worth a warning, not an error.
        for (const Medium& med : scene.media)
            for (const DyeComponent& d : med.dyes())
                if (const auto w = optics::emissionBlockingWarning(*out.filters, d.dye.emission(), d.dye.id()))
                    std::fprintf(stderr, "fluorosim: warning: channel \"%s\": %s\n", out.name.c_str(), w->c_str());
        if (a.channels.empty() || std::find(a.channels.begin(), a.channels.end(), out.name) != a.channels.end())
            channels.push_back(std::move(out));
    }
    for (const std::string& want : a.channels) {
        bool found = false;
        for (const Channel& c : channels) found = found || c.name == want;
        if (!found) throw ConfigError("--channels: no channel named \"" + want + "\" in the scene's microscope block");
    }

    fs::path out = a.output;
    const std::string outText = out.string();
    const std::string suffix = ".ome.tif";
    if (outText.size() <= suffix.size() || outText.compare(outText.size() - suffix.size(), suffix.size(), suffix) != 0)
        throw ConfigError(outText + ": output must end in .ome.tif");
    const fs::path expectedPath = outText.substr(0, outText.size() - suffix.size()) + ".expected.ome.tif";
    requireWritableFolder(out);

    const optics::Detector camera(detector);
    const size_t pixels = static_cast<size_t>(width) * height;
    std::vector<uint16_t> adu;
    std::vector<float> expected;
    adu.reserve(pixels * planes * channels.size());
    expected.reserve(adu.capacity());
    std::vector<Light> allLights = std::move(scene.lights);
    ProgressBar bar("acquire");
    const int total = planes * static_cast<int>(channels.size());
    int done = 0;
    double seconds = 0;
    for (size_t c = 0; c < channels.size(); ++c) {
        for (int k = 0; k < planes; ++k) {
            const double offset = (k - 0.5 * (planes - 1)) * stepMm;
            scene.lights.clear();
            for (size_t l : channels[c].lights) {
                Light light = allLights[l];
                const optics::FilterSet& fs = *channels[c].filters;
                if (BeamLight* b = std::get_if<BeamLight>(&light); b && channels[c].filteredExcitation)
                    b->profile = std::make_shared<FilteredBeam>(b->profile, fs);
                scene.lights.push_back(std::move(light));
            }
            // The sheet and the focal plane move together along the detection axis.
            for (Light& l : scene.lights)
                if (BeamLight* b = std::get_if<BeamLight>(&l); b && !b->spec.widefield)
                    b->profile->moveTo(offset * dot(normalize(b->spec.normal), focus.towardObjective));
            optics::FocalPlane plane = focus;
            plane.centreMm = focus.centreMm + focus.towardObjective * offset;
            optics::PlaneRenderOptions po;
            po.width = width;
            po.height = height;
            po.spp = spp;
            po.seed = scene.render.seed;
            po.planeKey = c * 4096 + static_cast<uint64_t>(k);
            po.threads = a.threads;
            po.progress = [&](double f) { bar.update((done + f) / total); };
            const optics::PlaneResult r = optics::renderPlane(scene, objective, plane, channels[c].filter, detector, po);
            seconds += r.seconds;
            double signal = 0;
            for (double e : r.electrons) signal += e;
            if (!(signal > 0))
                std::fprintf(stderr, "fluorosim: warning: channel \"%s\", plane %d: no signal (the sheet or the focal plane misses the labelled volume)\n",
                             channels[c].name.c_str(), k);
            const std::vector<double> withDark = camera.expectedElectrons(r.electrons);
            const std::vector<uint16_t> frame = camera.readOut(withDark, scene.render.seed, po.planeKey);
            adu.insert(adu.end(), frame.begin(), frame.end());
            for (double e : withDark) expected.push_back(static_cast<float>(e));
            ++done;
        }
    }
    bar.finish();
    optics::StackMetadata meta;
    meta.pixelSizeUm = detector.pixelPitchUm / objective.magnification;
    meta.zStepUm = stepMm * 1e3;
    meta.exposureS = detector.exposureS;
    meta.significantBits = detector.bitDepth;
    meta.description = "Fluorosim acquisition of " + a.scene + ", " + std::to_string(spp) + " spp";
    for (const Channel& c : channels) meta.channels.push_back({c.name, c.excitationNm, c.emissionNm});
    optics::writeOmeTiffUint16(out, width, height, planes, static_cast<int>(channels.size()), adu, meta);
    meta.description += "; expected photoelectrons (with dark current, before noise)";
    optics::writeOmeTiffFloat32(expectedPath, width, height, planes, static_cast<int>(channels.size()), expected, meta);
    double maxE = 0;
    for (float e : expected) maxE = std::max(maxE, double(e));
    const fs::path preview = outText.substr(0, outText.size() - suffix.size()) + ".preview.png";
    writeStackPreview(preview, expected, width, height, planes, static_cast<int>(channels.size()), meta.zStepUm / meta.pixelSizeUm);
    const json summary = {{"stack", out.string()},          {"expected", expectedPath.string()}, {"preview", preview.string()}, {"planes", planes},
                          {"channels", channels.size()},     {"width", width},                    {"height", height},
                          {"pixel_size_um", meta.pixelSizeUm}, {"z_step_um", meta.zStepUm},       {"spp", spp},
                          {"seconds", seconds},              {"max_expected_electrons", maxE}};
    std::printf("%s\n", summary.dump().c_str());
}

}  // namespace

void addAcquireCommand(CLI::App& app) {
    auto a = std::make_shared<AcquireArgs>();
    CLI::App* cmd = app.add_subcommand("acquire", "Simulate a light-sheet z-stack and write it as OME-TIFF");
    cmd->add_option("scene", a->scene, "Scene file with a \"microscope\" block")->required();
    cmd->add_option("-o,--output", a->output, "Output STACK.ome.tif (STACK.expected.ome.tif is written next to it)")->required();
    cmd->add_option("--planes", a->planes, "Number of planes (default: the scene's stack)");
    cmd->add_option("--step", a->step, "Distance between planes with a unit, e.g. 2um");
    cmd->add_option("--spp", a->spp, "Samples per pixel");
    cmd->add_option("--seed", a->seed, "Random seed");
    cmd->add_option("--threads", a->threads, "Threads (0 = all cores)");
    cmd->add_option("--channels", a->channels, "Channels to acquire, by name (default: all)")->delimiter(',');
    cmd->callback([a] { runAcquire(*a); });
}

}  // namespace fluorosim::app
