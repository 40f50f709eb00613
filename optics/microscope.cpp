#include "optics/microscope.h"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <set>

#include "core/errors.h"
#include "core/message.h"
#include "database.h"
#include "optics/ome_tiff.h"

namespace fluorosim::optics {
namespace {

std::string num(double v) { return messageNumber(v); }

// A beam moved by a fixed vector (a z-stack step): the profile at p is the original's at p - shift.
class ShiftedBeam final : public BeamProfile {
public:
    ShiftedBeam(std::shared_ptr<BeamProfile> beam, const Vec3& shift) : beam_(std::move(beam)), shift_(shift) {}
    int sides() const override { return beam_->sides(); }
    Vec3 direction(int side) const override { return beam_->direction(side); }
    double irradiance(const Vec3& p, int side, double lambdaNm) const override { return beam_->irradiance(p - shift_, side, lambdaNm); }
    const Spectrum& spectrum() const override { return beam_->spectrum(); }
    bool inCore(const Vec3& p, int side, double lambdaNm) const override { return beam_->inCore(p - shift_, side, lambdaNm); }
    BeamCore coreAlong(const Ray& ray, int side, double lambdaNm) const override {
        return beam_->coreAlong(Ray{ray.o - shift_, ray.d}, side, lambdaNm);
    }
    std::optional<Vec3> axisPoint() const override {
        const auto p = beam_->axisPoint();
        return p ? std::optional<Vec3>(*p + shift_) : std::nullopt;
    }
    std::optional<CrossSectionPoint> sampleCrossSection(const Vec3& axisPoint, int side, double lambdaNm, double u1, double u2) const override {
        auto c = beam_->sampleCrossSection(axisPoint - shift_, side, lambdaNm, u1, u2);
        if (c) c->p = c->p + shift_;
        return c;
    }

private:
    std::shared_ptr<BeamProfile> beam_;
    Vec3 shift_;
};

// A beam seen through a channel's excitation path (excitation filter, dichroic reflection).
class FilteredBeam final : public BeamProfile {
public:
    FilteredBeam(std::shared_ptr<BeamProfile> beam, FilterSet filters) : beam_(std::move(beam)), filters_(std::move(filters)) {}
    int sides() const override { return beam_->sides(); }
    Vec3 direction(int side) const override { return beam_->direction(side); }
    double irradiance(const Vec3& p, int side, double lambdaNm) const override {
        return beam_->irradiance(p, side, lambdaNm) * filters_.excitationPath(lambdaNm);
    }
    const Spectrum& spectrum() const override { return beam_->spectrum(); }
    bool inCore(const Vec3& p, int side, double lambdaNm) const override { return beam_->inCore(p, side, lambdaNm); }
    BeamCore coreAlong(const Ray& ray, int side, double lambdaNm) const override { return beam_->coreAlong(ray, side, lambdaNm); }
    std::optional<Vec3> axisPoint() const override { return beam_->axisPoint(); }
    std::optional<CrossSectionPoint> sampleCrossSection(const Vec3& axisPoint, int side, double lambdaNm, double u1, double u2) const override {
        return beam_->sampleCrossSection(axisPoint, side, lambdaNm, u1, u2);
    }

private:
    std::shared_ptr<BeamProfile> beam_;
    FilterSet filters_;
};

// A filter: a database name, {"center", "fwhm"} (band-pass) or {"long_pass": edge} (a dichroic).
Filter parseFilter(const SceneField& f, const spectra::Database& db) {
    auto wrap = [&](auto&& make) -> Filter {
        try {
            return make();
        } catch (const Error& e) {
            f.fail(e.what());
        }
    };
    if (f.isString()) return wrap([&] { return Filter::fromDatabase(db, f.str()); });
    if (f.has("long_pass")) {
        f.allowOnly({"long_pass"});
        EdgeFilterOptions e;
        e.edgeNm = f.at("long_pass").positiveQuantity(Dimension::Wavelength);
        return wrap([&] { return Filter::longPass(e); });
    }
    f.allowOnly({"center", "fwhm"});
    BandPassOptions b;
    b.centreNm = f.at("center").positiveQuantity(Dimension::Wavelength);
    b.fwhmNm = f.at("fwhm").positiveQuantity(Dimension::Wavelength);
    return wrap([&] { return Filter::bandPass(b); });
}

DetectorOptions parseDetector(const SceneField& d) {
    d.allowOnly({"type", "pixel_pitch", "width", "height", "qe", "exposure_s", "gain_e_per_adu", "offset_adu", "read_noise_e",
                 "dark_current_e_per_s", "full_well_e", "bit_depth", "em_gain", "offset_map", "gain_map", "read_noise_map", "dark_current_map",
                 "row_noise_e", "hot_pixel_fraction", "hot_pixel_dark_e_per_s", "hot_pixel_seed"});
    DetectorOptions o;
    if (d.has("type")) {
        const std::string t = d.at("type").str();
        if (t == "EMCCD") o.type = SensorType::Emccd;
        else if (t != "sCMOS") d.at("type").fail("expected \"sCMOS\" or \"EMCCD\"");
    }
    if (d.has("pixel_pitch")) o.pixelPitchUm = d.at("pixel_pitch").positiveQuantity(Dimension::Length) * 1e3;
    if (d.has("qe")) o.qe = Spectrum::constant(d.at("qe").number(0, 1));
    if (d.has("exposure_s")) o.exposureS = d.at("exposure_s").quantity(Dimension::Time, "s");
    if (d.has("gain_e_per_adu")) o.gainElectronsPerAdu = d.at("gain_e_per_adu").number();
    if (d.has("offset_adu")) o.offsetAdu = d.at("offset_adu").number();
    if (d.has("read_noise_e")) o.readNoiseElectrons = d.at("read_noise_e").number();
    if (d.has("dark_current_e_per_s")) o.darkCurrentElectronsPerS = d.at("dark_current_e_per_s").number();
    if (d.has("full_well_e")) o.fullWellElectrons = d.at("full_well_e").number();
    if (d.has("bit_depth")) o.bitDepth = static_cast<int>(d.at("bit_depth").integer(8, 16));
    if (d.has("em_gain")) o.emGain = d.at("em_gain").number();
    if (d.has("width")) o.sensorWidth = static_cast<int>(d.at("width").integer(1, 8192));
    // Calibration maps: one-page TIFF files (float32 or uint16) of the sensor's width x height, relative to
    // the scene file.
    auto map = [&](const char* key, std::vector<double>& out) {
        if (!d.has(key)) return;
        const SceneField f = d.at(key);
        const std::filesystem::path path = f.file().parent_path() / f.str();
        TiffStackInfo tiff;
        try {
            tiff = readTiffStack(path, true);
        } catch (const IoError& e) {
            throw IoError(f.prefix() + e.what());
        }
        const int height = d.has("height") ? static_cast<int>(d.at("height").integer(1, 8192)) : 0;
        if (tiff.pages != 1 || tiff.width != o.sensorWidth || tiff.height != height)
            f.failQuoted("the map " + path.string() + " is " + std::to_string(tiff.width) + " x " + std::to_string(tiff.height) + " pixels in " +
                         std::to_string(tiff.pages) + " pages; the sensor is " + std::to_string(o.sensorWidth) + " x " + std::to_string(height) +
                         " (one page)");
        out = std::move(tiff.pixels);
    };
    map("offset_map", o.offsetMapAdu);
    map("gain_map", o.gainMapElectronsPerAdu);
    map("read_noise_map", o.readNoiseMapElectrons);
    map("dark_current_map", o.darkCurrentMapElectronsPerS);
    if (d.has("row_noise_e")) o.rowNoiseElectrons = d.at("row_noise_e").number();
    if (d.has("hot_pixel_fraction")) o.hotPixelFraction = d.at("hot_pixel_fraction").number(0, 1);
    if (d.has("hot_pixel_dark_e_per_s")) o.hotPixelDarkCurrentElectronsPerS = d.at("hot_pixel_dark_e_per_s").number();
    if (d.has("hot_pixel_seed")) o.hotPixelSeed = static_cast<uint64_t>(d.at("hot_pixel_seed").integer(0, int64_t(1) << 53));
    try {
        o.validate();
    } catch (const ConfigError& e) {
        d.failQuoted(e.what());
    }
    return o;
}

}  // namespace

void ObjectiveOptions::validate() const {
    if (!(immersionIndex >= 1) || !std::isfinite(immersionIndex))
        throw ConfigError("objective immersion_index must be >= 1, got " + num(immersionIndex));
    if (!(na > 0) || !std::isfinite(na)) throw ConfigError("objective na must be positive, got " + num(na));
    if (na >= immersionIndex)
        throw ConfigError("objective na " + num(na) + " is not below the immersion index " + num(immersionIndex) +
                          " (NA = n sin θ cannot reach n)");
    if (!(magnification > 0) || !std::isfinite(magnification))
        throw ConfigError("objective magnification must be positive, got " + num(magnification));
    if (!(workingDistanceMm > 0) || !std::isfinite(workingDistanceMm))
        throw ConfigError("objective working_distance must be positive, got " + num(workingDistanceMm) + " mm");
}

double ObjectiveOptions::collectionHalfAngle() const { return std::asin(na / immersionIndex); }

void FocalPlane::validate() const {
    if (!isFinite(centreMm)) throw ConfigError("focus center must be finite");
    if (!isFinite(towardObjective) || !(length(towardObjective) > 0)) throw ConfigError("focus toward_objective must be a non-zero vector");
    if (!isFinite(up) || !(length(cross(up, towardObjective)) > 1e-9 * length(up) * length(towardObjective)))
        throw ConfigError("focus up must be a non-zero vector not parallel to toward_objective");
}

size_t stackBytes(int width, int height, int planes, int channels) {
    // Saturates instead of overflowing: the product of four ints can exceed 2^64 only in theory.
    const double bytes = double(width) * height * planes * channels * (2 * sizeof(float) + sizeof(uint16_t));
    return bytes >= 1.8e19 ? SIZE_MAX : static_cast<size_t>(bytes);
}

Microscope Microscope::fromScene(const Scene& scene, const spectra::Database& db) {
    if (!scene.microscope) throw ConfigError("the scene has no \"microscope\" block (docs/optics.md)");
    const SceneField& m = *scene.microscope;
    m.allowOnly({"objective", "focus", "detector", "channels", "stack"});
    // Channels switch lights on and off by index; emitting shapes keep indices of their own.
    for (const Light& l : scene.lights)
        if (std::holds_alternative<AreaLight>(l))
            m.failQuoted("acquisition supports light sheets, widefield, point and spot lights, not emitting shapes");

    Microscope out;
    const SceneField obj = m.at("objective");
    obj.allowOnly({"na", "magnification", "immersion_index", "working_distance"});
    out.objective.na = obj.at("na").number();
    out.objective.magnification = obj.at("magnification").number();
    if (obj.has("immersion_index")) out.objective.immersionIndex = obj.at("immersion_index").number();
    if (obj.has("working_distance")) out.objective.workingDistanceMm = obj.at("working_distance").positiveQuantity(Dimension::Length);
    try {
        out.objective.validate();
    } catch (const ConfigError& e) {
        obj.failQuoted(e.what());
    }

    const SceneField det = m.at("detector");
    out.detector = parseDetector(det);
    out.width = static_cast<int>(det.at("width").integer(1, 8192));
    out.height = static_cast<int>(det.at("height").integer(1, 8192));

    const SceneField f = m.at("focus");
    f.allowOnly({"center", "toward_objective", "up"});
    out.focus.centreMm = f.at("center").vec3(Dimension::Length);
    if (f.has("toward_objective")) {
        const Vec3 w = f.at("toward_objective").vec3(Dimension::Dimensionless);
        if (!(length(w) > 0)) f.at("toward_objective").fail("must be a non-zero vector");
        out.focus.towardObjective = normalize(w);
    }
    if (f.has("up")) out.focus.up = f.at("up").vec3(Dimension::Dimensionless);
    try {
        out.focus.validate();
    } catch (const ConfigError& e) {
        f.failQuoted(e.what());
    }

    if (m.has("stack")) {
        const SceneField s = m.at("stack");
        s.allowOnly({"planes", "step"});
        if (s.has("planes")) out.stack.planes = static_cast<int>(s.at("planes").integer(1, 4096));
        if (s.has("step")) out.stack.stepMm = s.at("step").positiveQuantity(Dimension::Length);
    }

    const SceneField ch = m.at("channels");
    if (!ch.isArray() || ch.size() == 0) ch.fail("expected a non-empty array of channels");
    for (size_t i = 0; i < ch.size(); ++i) {
        const SceneField c = ch.at(i);
        c.allowOnly({"name", "emission_filter", "excitation_filter", "dichroic", "lights"});
        MicroscopeChannel mc;
        mc.name = c.at("name").str();
        if (mc.name.empty()) c.at("name").fail("must not be empty");
        for (const MicroscopeChannel& other : out.channels)
            if (other.name == mc.name) c.at("name").fail("two channels have this name");
        // Emission path: dichroic transmission times emission filter; excitation path: excitation
        // filter times dichroic reflection (a light-sheet's illumination arm has no dichroic: omit it).
        mc.filters = FilterSet{mc.name, Filter::open(), std::nullopt, parseFilter(c.at("emission_filter"), db)};
        if (c.has("excitation_filter")) mc.filters.excitation = parseFilter(c.at("excitation_filter"), db);
        if (c.has("dichroic")) mc.filters.dichroic = parseFilter(c.at("dichroic"), db);
        mc.emissionPath = mc.filters.dichroic ? Filter(mc.name + " emission path", mc.filters.emissionPathCurve()) : mc.filters.emission;
        mc.filteredExcitation = c.has("excitation_filter") || c.has("dichroic");
        if (c.has("lights")) {
            const SceneField lights = c.at("lights");
            if (!lights.isArray() || lights.size() == 0) lights.fail("expected a non-empty array of light indices");
            const auto last = static_cast<int64_t>(scene.lights.size()) - 1;
            for (size_t k = 0; k < lights.size(); ++k) mc.lights.push_back(static_cast<size_t>(lights.at(k).integer(0, last)));
        } else {
            for (size_t l = 0; l < scene.lights.size(); ++l) mc.lights.push_back(l);
        }
        for (size_t l : mc.lights)
            if (const auto lines = emissionSpectrum(scene.lights[l]).spectralLines(); !lines.empty() && mc.excitationNm == 0)
                mc.excitationNm = lines[0].lambdaNm;
        if (mc.excitationNm == 0) c.failQuoted("its lights have no laser line; the stack's metadata needs an excitation wavelength");
        mc.emissionNm = measurePassBand(mc.emissionPath.curve()).centreNm();
        mc.warnings = channelDyeWarnings(scene, mc);
        out.channels.push_back(std::move(mc));
    }
    // The objective looks through the camera's medium: its index is the immersion the PSF assumes.
    if (const double n = scene.ior(scene.camera.medium); std::abs(n - out.objective.immersionIndex) > 1e-3)
        out.warnings.push_back("objective immersion_index " + num(out.objective.immersionIndex) + " differs from the index " + num(n) +
                               " of the camera's medium" + (scene.camera.medium == kNone ? std::string(" (none: vacuum)") : " \"" + scene.media[static_cast<size_t>(scene.camera.medium)].name() + "\"") +
                               ", which the objective looks through: the PSF assumes the first, the rays cross the second; give the camera the immersion medium");
    try {
        out.validate(scene);
    } catch (const ConfigError& e) {
        m.failQuoted(e.what());
    }
    return out;
}

std::vector<std::string> channelDyeWarnings(const Scene& scene, const MicroscopeChannel& channel) {
    // A channel exists to see the dyes its own lasers excite: warn when it sees almost none of them (an
    // AF594 channel behind a 525/45 filter), not for other channels' dyes it is meant to block.
    constexpr double kExcited = 0.02, kSeen = 1e-3;
    std::vector<double> lines;
    for (size_t l : channel.lights)
        for (const SpectralLine& line : emissionSpectrum(scene.lights[l]).spectralLines()) lines.push_back(line.lambdaNm);
    std::string lineText;
    for (double l : lines) lineText += (lineText.empty() ? "" : ", ") + num(l) + " nm";
    std::vector<std::string> excited, blocked;
    std::set<std::string> seenDyes;
    for (const Medium& med : scene.media)
        for (const DyeComponent& d : med.dyes()) {
            if (!seenDyes.insert(d.dye.id()).second) continue;
            double excitation = 0;
            for (double l : lines) excitation = std::max(excitation, d.dye.molarExtinction(l) / d.dye.extinctionPeak());
            if (excitation < kExcited) continue;
            excited.push_back(d.dye.id());
            const double seen = emissionPathEfficiency(channel.filters, d.dye.emission());
            if (seen >= kSeen) return {};
            blocked.push_back(d.dye.id() + " (" + num(std::round(100 * excitation)) + " % of its peak; the emission path passes " + num(seen) +
                              " of its emission)");
        }
    if (seenDyes.empty() || lines.empty()) return {};
    const std::string name = "channel \"" + channel.name + "\": ";
    if (excited.empty())
        return {name + "its laser lines (" + lineText + ") excite none of the scene's dyes above " + num(100 * kExcited) + " % of their peak"};
    std::string list;
    for (const std::string& b : blocked) list += (list.empty() ? "" : ", ") + b;
    return {name + "its laser lines (" + lineText + ") excite " + list + ", but its emission path (" + channel.filters.emission.name() +
            ") passes almost none of them: the channel will record almost nothing"};
}

void Microscope::validate(const Scene& scene) const {
    objective.validate();
    focus.validate();
    detector.validate();
    if (width < 1 || height < 1 || width > 8192 || height > 8192)
        throw ConfigError("detector width and height must lie in [1, 8192], got " + std::to_string(width) + " x " + std::to_string(height));
    const size_t maps = detector.mapPixels();
    if ((maps != 0 || detector.rowNoiseElectrons > 0) &&
        (detector.sensorWidth != width || (maps != 0 && maps != static_cast<size_t>(width) * static_cast<size_t>(height))))
        throw ConfigError("the detector's calibration maps and row noise are for a sensor " + std::to_string(detector.sensorWidth) +
                          " pixels wide (maps of " + std::to_string(maps) + " pixels); the microscope images " + std::to_string(width) + " x " +
                          std::to_string(height));
    if (stack.planes < 1 || stack.planes > 4096) throw ConfigError("stack planes must lie in [1, 4096], got " + std::to_string(stack.planes));
    if (!(stack.stepMm > 0) || !std::isfinite(stack.stepMm)) throw ConfigError("stack step must be positive, got " + num(stack.stepMm) + " mm");
    if (channels.empty()) throw ConfigError("the microscope has no channel");
    for (const MicroscopeChannel& c : channels)
        for (size_t l : c.lights)
            if (l >= scene.lights.size())
                throw ConfigError("channel \"" + c.name + "\": light " + std::to_string(l) + " is not in the scene (it has " +
                                  std::to_string(scene.lights.size()) + ")");
    const size_t bytes = stackBytes(width, height, stack.planes, static_cast<int>(channels.size()));
    if (bytes > kMaxStackBytes)
        throw ConfigError("a stack of " + std::to_string(width) + " x " + std::to_string(height) + " pixels x " + std::to_string(stack.planes) +
                          " planes x " + std::to_string(channels.size()) + " channels needs " + num(double(bytes) / (1 << 30)) +
                          " GiB, over the cap of " + std::to_string(kMaxStackBytes >> 30) + " GiB");
}

FocalPlane Microscope::focalPlaneAt(double offsetMm) const {
    FocalPlane f = focus;
    f.centreMm = focus.centreMm + normalize(focus.towardObjective) * offsetMm;
    return f;
}

std::vector<Light> Microscope::lightsAt(const Scene& scene, const MicroscopeChannel& channel, double offsetMm) const {
    std::vector<Light> out;
    const Vec3 axis = normalize(focus.towardObjective);
    for (size_t l : channel.lights) {
        Light light = scene.lights.at(l);
        if (BeamLight* b = std::get_if<BeamLight>(&light)) {
            // The sheet and the focal plane move together along the detection axis; a widefield field
            // fills every depth and stays.
            if (!b->spec.widefield && offsetMm != 0) {
                const Vec3 n = normalize(b->spec.normal);
                b->profile = std::make_shared<ShiftedBeam>(b->profile, n * (offsetMm * dot(n, axis)));
            }
            if (channel.filteredExcitation) b->profile = std::make_shared<FilteredBeam>(b->profile, channel.filters);
        }
        out.push_back(std::move(light));
    }
    return out;
}

size_t Microscope::channelIndex(const std::string& name) const {
    std::string names;
    for (size_t i = 0; i < channels.size(); ++i) {
        if (channels[i].name == name) return i;
        names += (i ? ", " : "") + channels[i].name;
    }
    throw ConfigError("no channel named \"" + name + "\" in the microscope (channels: " + names + ")");
}

std::vector<size_t> Microscope::selectChannels(const std::vector<std::string>& names, const std::string& what) const {
    std::vector<size_t> selected;
    for (const std::string& name : names) {
        try {
            selected.push_back(channelIndex(name));
        } catch (const ConfigError& e) {
            throw ConfigError(what + ": " + e.what());
        }
    }
    if (selected.empty())
        for (size_t c = 0; c < channels.size(); ++c) selected.push_back(c);
    return selected;
}

}  // namespace fluorosim::optics
