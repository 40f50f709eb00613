#include "scene/scene_loader.h"
#include "scene/tissue_presets.h"

#include <cerrno>
#include <charconv>
#include <cstring>
#include <cmath>
#include <fstream>
#include <limits>
#include <map>
#include <nlohmann/json.hpp>
#include <set>
#include <sstream>

#include "core/errors.h"
#include "core/math.h"
#include "core/memory_cap.h"
#include "core/message.h"
#include "core/units.h"
#include "volume/density_grid.h"
#include "volume/volume_fields.h"

namespace fluorosim {
namespace {

using json = nlohmann::json;
namespace fs = std::filesystem;

// Nesting deeper than this is refused while parsing: scenes need about 8 levels, and deeper values
// would make every recursive walk (serialising a value for a message, destroying it) a stack risk.
constexpr int kMaxJsonDepth = 64;
// Scene files are small: data belongs in CSV, mesh and VDB files. A parsed value takes up to about
// 16 times its text, so the limit also keeps the parsed tree well below the memory cap.
constexpr uint64_t kMaxSceneBytes = uint64_t(64) << 20;
constexpr double kMaxEmission = 1e30;

// Appends about `budget` characters of `j` to `out`, written like json::dump(); stops early so a huge
// value costs no more than its excerpt.
void dumpInto(const json& j, std::string& out, size_t budget, int depth = 0) {
    if (out.size() >= budget) return;
    if (depth > 8 && (j.is_object() || j.is_array())) {
        out += j.is_object() ? "{...}" : "[...]";
        return;
    }
    if (j.is_object() || j.is_array()) {
        out += j.is_object() ? '{' : '[';
        bool first = true;
        for (auto it = j.begin(); it != j.end() && out.size() < budget; ++it) {
            if (!first) out += ',';
            first = false;
            if (j.is_object()) out += json(excerpt(it.key(), budget)).dump() + ':';
            dumpInto(it.value(), out, budget, depth + 1);
        }
        out += j.is_object() ? '}' : ']';
    } else if (j.is_string()) {
        out += json(excerpt(j.get_ref<const std::string&>(), budget)).dump();
    } else {
        out += j.dump();
    }
}

std::string shortDump(const json& j) {
    std::string s;
    dumpInto(j, s, kExcerptChars);
    return s.size() > kExcerptChars ? s.substr(0, kExcerptChars - 3) + "..." : s;
}

// Thrown from the parser callback; becomes a ConfigError naming the file.
struct JsonRejected {
    std::string path, what;
};

// Parses `text`, refusing nesting deeper than kMaxJsonDepth and repeated keys in an object (nlohmann
// would silently keep the last one). Messages name the JSON path.
json parseScene(const std::string& text, const fs::path& file) {
    struct Frame {
        bool object = false;
        std::set<std::string> keys;
        std::string key;   // objects: the member being parsed
        size_t index = 0;  // arrays: children started so far
    };
    std::vector<Frame> frames;
    auto path = [&frames] {
        std::string p;
        for (const Frame& f : frames) {
            if (f.object && !f.key.empty()) p += "/" + excerpt(f.key, 40);
            else if (!f.object && f.index > 0) p += "/" + std::to_string(f.index - 1);
            if (p.size() > 200) return p.substr(0, 200) + "...";
        }
        return p.empty() ? std::string("/") : p;
    };
    auto childStarts = [&frames] {
        if (!frames.empty() && !frames.back().object) ++frames.back().index;
    };
    const json::parser_callback_t callback = [&](int depth, json::parse_event_t event, json& parsed) {
        switch (event) {
            case json::parse_event_t::object_start:
            case json::parse_event_t::array_start:
                childStarts();
                if (depth >= kMaxJsonDepth)
                    throw JsonRejected{path(), "nested deeper than " + std::to_string(kMaxJsonDepth) + " levels"};
                frames.push_back(Frame{event == json::parse_event_t::object_start, {}, {}, 0});
                break;
            case json::parse_event_t::object_end:
            case json::parse_event_t::array_end:
                frames.pop_back();
                break;
            case json::parse_event_t::key: {
                Frame& f = frames.back();
                f.key = parsed.get<std::string>();
                if (!f.keys.insert(f.key).second)
                    throw JsonRejected{path(), "duplicate key \"" + excerpt(f.key) + "\" (each key may appear once in an object)"};
                break;
            }
            case json::parse_event_t::value:
                childStarts();
                break;
        }
        return true;
    };
    try {
        return json::parse(text, callback);
    } catch (const JsonRejected& e) {
        throw ConfigError(file.string() + ": " + e.path + ": " + e.what);
    } catch (const json::exception& e) {
        // parse_error, and out_of_range for a number beyond double ("1e999"). The path is where the
        // parser had got to; the message quotes the last token, which may be huge.
        throw ConfigError(file.string() + ": " + path() + ": malformed JSON: " + excerpt(e.what(), 240));
    }
}

// A JSON value with its path, so every error names file, field and value.
class Node {
public:
    Node(const json& j, std::string path, const fs::path& file) : j_(j), path_(std::move(path)), file_(file) {}
    const json& raw() const { return j_; }
    const std::string& path() const { return path_; }

    [[noreturn]] void fail(const std::string& what) const {
        throw ConfigError(prefix() + what + " (got " + shortDump(j_) + ")");
    }
    // For messages that already quote the value.
    [[noreturn]] void failQuoted(const std::string& what) const { throw ConfigError(prefix() + what); }
    [[noreturn]] void failIo(const std::string& what) const { throw IoError(prefix() + what + " (got " + shortDump(j_) + ")"); }
    std::string prefix() const { return file_.string() + ": " + (path_.empty() ? "/" : path_) + ": "; }
    bool has(const std::string& key) const { return j_.is_object() && j_.contains(key); }
    Node at(const std::string& key) const {
        if (!j_.is_object()) fail("expected an object");
        if (!j_.contains(key)) fail("missing required field \"" + key + "\"");
        return Node(j_.at(key), path_ + "/" + excerpt(key), file_);
    }
    Node at(size_t i) const { return Node(j_.at(i), path_ + "/" + std::to_string(i), file_); }
    size_t size() const { return j_.size(); }
    void requireObject() const {
        if (!j_.is_object()) fail("expected an object");
    }
    void allowOnly(std::initializer_list<const char*> keys) const {
        requireObject();
        std::set<std::string> allowed(keys.begin(), keys.end());
        for (auto it = j_.begin(); it != j_.end(); ++it)
            if (!allowed.count(it.key())) {
                std::string list;
                for (const auto& k : allowed) list += (list.empty() ? "" : ", ") + k;
                Node(it.value(), path_ + "/" + excerpt(it.key()), file_).fail("unknown field \"" + excerpt(it.key()) + "\" (allowed: " + list + ")");
            }
    }
    double number() const {
        if (!j_.is_number()) fail("expected a number");
        const double v = j_.get<double>();
        if (!std::isfinite(v)) fail("expected a finite number");
        return v;
    }
    double number(double lo, double hi, bool openLo = false, bool openHi = false) const {
        const double v = number();
        if (v < lo || v > hi || (openLo && v == lo) || (openHi && v == hi))
            fail("must lie in " + std::string(openLo ? "(" : "[") + fmt(lo) + ", " + fmt(hi) + (openHi ? ")" : "]"));
        return v;
    }
    int integer(int lo, int hi) const {
        if (!j_.is_number_integer()) fail("expected an integer");
        const std::string range = "must lie in [" + std::to_string(lo) + ", " + std::to_string(hi) + "]";
        // Values from 2^63 up are stored unsigned; read as int64_t they would wrap to negative numbers.
        if (j_.is_number_unsigned() && j_.get<uint64_t>() > static_cast<uint64_t>(std::numeric_limits<int64_t>::max())) fail(range);
        const auto v = j_.get<int64_t>();
        if (v < lo || v > hi) fail(range);
        return static_cast<int>(v);
    }
    std::string str() const {
        if (!j_.is_string()) fail("expected a string");
        return j_.get<std::string>();
    }
    bool boolean() const {
        if (!j_.is_boolean()) fail("expected true or false");
        return j_.get<bool>();
    }
    double quantity(Dimension dim) const {
        if (!j_.is_string()) fail(std::string("expected a string with a unit, ") + dimensionName(dim));
        try {
            return parseQuantity(j_.get<std::string>(), dim, "value");
        } catch (const ConfigError& e) {
            failQuoted(e.what());
        }
    }
    double positiveQuantity(Dimension dim) const {
        const double v = quantity(dim);
        if (!(v > 0)) fail("must be positive");
        return v;
    }
    // A bare number in the unit the field's name carries ("power_mW": 3), or a string with any unit of
    // the dimension ("3 mW", "0.5 W").
    double quantity(Dimension dim, std::string_view bareUnit) const {
        if (j_.is_number()) return number() * *unitScale(bareUnit, dim);
        if (!j_.is_string()) fail(std::string("expected a number (in ") + std::string(bareUnit) + ") or a string with a unit, " + dimensionName(dim));
        try {
            return parseQuantity(j_.get<std::string>(), dim, "value", bareUnit);
        } catch (const ConfigError& e) {
            failQuoted(e.what());
        }
    }
    // ["1 mm", "2 mm", "3 mm"] or {"value": [1, 2, 3], "unit": "mm"}; dimensionless: [0, 1, 0].
    Vec3 vec3(Dimension dim) const {
        if (j_.is_object()) {
            allowOnly({"value", "unit"});
            const Node v = at("value");
            const std::string unit = at("unit").str();
            const auto scale = unitScale(unit, dim);
            if (!scale) at("unit").fail(std::string("unit does not fit ") + dimensionName(dim));
            if (!v.raw().is_array() || v.size() != 3) v.fail("expected 3 numbers");
            return Vec3(v.at(0).number(), v.at(1).number(), v.at(2).number()) * *scale;
        }
        if (!j_.is_array() || j_.size() != 3) fail("expected an array of 3 values");
        Vec3 r;
        for (size_t i = 0; i < 3; ++i) r[static_cast<int>(i)] = dim == Dimension::Dimensionless ? at(i).number() : at(i).quantity(dim);
        return r;
    }

private:
    static std::string fmt(double v) {
        std::ostringstream os;
        os << v;
        return os.str();
    }
    const json& j_;
    std::string path_;
    const fs::path& file_;
};

// "0.5 /mm", "-1/mm", "inf /mm", "nan /mm": a quantity (possibly invalid), not a spectrum name.
bool startsWithNumber(const std::string& s) {
    double v = 0;
    const char* b = s.data() + (s.size() > 0 && s[0] == '+' ? 1 : 0);
    const auto [ptr, ec] = std::from_chars(b, s.data() + s.size(), v);
    return (ec == std::errc() || ec == std::errc::result_out_of_range) && ptr != b;
}

// References whose values the spectral database already delivers as coefficients in 1/mm.
bool knownCoefficientUnit(const std::string& reference) { return reference.rfind("solvent-absorption:", 0) == 0; }

enum class SpectrumKind { Reflectance, Coefficient, Emission, Unitless };

class Loader {
public:
    Loader(const fs::path& file, const SpectrumResolver& resolve, const DyeResolver& dyes, const BeamResolver& beams)
        : file_(file), resolve_(resolve), dyes_(dyes), beams_(beams) {
        baseDir_ = file.has_parent_path() ? file.parent_path() : fs::path(".");
    }

    Scene load(const json& root) {
        const Node r(root, "", file_);
        r.allowOnly({"fluorosim_scene", "description", "spectral", "render", "camera", "media", "materials", "shapes", "lights", "microscope"});
        if (r.at("fluorosim_scene").integer(1, 1000) != 1) r.at("fluorosim_scene").fail("unsupported scene format version (this build reads 1)");
        if (r.has("description")) r.at("description").str();
        Scene scene;
        if (r.has("microscope")) {
            r.at("microscope").requireObject();
            scene.microscope = SceneField::parse(r.at("microscope").raw().dump(), "/microscope", file_);
        }
        if (r.has("spectral")) loadSpectral(r.at("spectral"), scene);
        if (r.has("render")) loadRender(r.at("render"), scene);
        if (r.has("media")) loadMedia(r.at("media"), scene);
        if (r.has("materials")) loadMaterials(r.at("materials"), scene);
        loadShapes(r.at("shapes"), scene);
        if (r.has("lights")) loadLights(r.at("lights"), scene);
        if (scene.lights.empty()) r.fail("the scene has no light (add an \"emission\" to a shape or a \"lights\" entry)");
        checkLinesCovered(scene);
        loadCamera(r.at("camera"), scene);
        scene.warnings.insert(scene.warnings.end(), warnings_.begin(), warnings_.end());
        scene.finalize();
        return scene;
    }

private:
    // A light's spectral line outside a medium's tabulated coefficient or a dye's excitation table
    // would meet a coefficient of 0 by extrapolation, not by data: refuse it.
    void checkLinesCovered(const Scene& scene) const {
        std::vector<double> lines;
        for (const Light& light : scene.lights)
            for (const SpectralLine& line : emissionSpectrum(light).spectralLines()) lines.push_back(line.lambdaNm);
        auto check = [&](const std::string& where, std::optional<std::pair<double, double>> range) {
            if (!range) return;
            for (double l : lines)
                if (l < range->first || l > range->second)
                    throw ConfigError(file_.string() + ": " + where + ": tabulated from " + fmtNm(range->first) + " to " + fmtNm(range->second) +
                                      " nm, which does not cover the light's spectral line at " + fmtNm(l) + " nm");
        };
        for (const Medium& m : scene.media) {
            check("/media/" + m.name() + "/sigma_a", m.solventAbsorption().tableRange());
            check("/media/" + m.name() + "/sigma_s", m.scattering().tableRange());
            for (size_t i = 0; i < m.dyes().size(); ++i)
                check("/media/" + m.name() + "/dyes/" + std::to_string(i) + " (" + m.dyes()[i].dye.id() + " excitation spectrum)",
                      m.dyes()[i].dye.excitationTableRange());
        }
    }

    void loadSpectral(const Node& n, Scene& scene) {
        n.allowOnly({"range", "bin_width"});
        if (n.has("range")) {
            const Node range = n.at("range");
            if (!range.raw().is_array() || range.size() != 2) range.fail("expected [min, max], e.g. [\"300 nm\", \"800 nm\"]");
            const double lo = range.at(0).quantity(Dimension::Wavelength), hi = range.at(1).quantity(Dimension::Wavelength);
            if (!(lo >= 100 && hi <= 20000 && lo < hi)) range.fail("wavelength range must satisfy 100 nm <= min < max <= 20000 nm");
            scene.spectral.lambdaMin = lambdaMin_ = lo;
            scene.spectral.lambdaMax = lambdaMax_ = hi;
        }
        if (n.has("bin_width")) {
            const double w = n.at("bin_width").positiveQuantity(Dimension::Wavelength);
            if ((scene.spectral.lambdaMax - scene.spectral.lambdaMin) / w > 4000) n.at("bin_width").fail("too many spectral bins (over 4000)");
            scene.spectral.binWidth = w;
        }
    }

    void loadRender(const Node& n, Scene& scene) {
        n.allowOnly({"spp", "max_depth", "seed", "fluorescence", "integrator", "photons_per_pixel", "merge_radius_pixels"});
        if (n.has("integrator")) {
            const auto integrator = integratorFromName(n.at("integrator").str());
            if (!integrator) n.at("integrator").fail("expected \"path\", \"mnee\" or \"light\"");
            scene.render.integrator = *integrator;
        }
        if (n.has("fluorescence")) {
            const auto model = fluorescenceModelFromName(n.at("fluorescence").str());
            if (!model) n.at("fluorescence").fail("expected \"full\", \"paper\" or \"none\"");
            scene.render.fluorescence = *model;
        }
        if (n.has("spp")) scene.render.spp = n.at("spp").integer(1, 1 << 24);
        if (n.has("photons_per_pixel")) scene.render.photonsPerPixel = n.at("photons_per_pixel").integer(1, 4096);
        if (n.has("merge_radius_pixels")) scene.render.mergeRadiusPixels = n.at("merge_radius_pixels").number(0, 64);
        if (n.has("max_depth")) scene.render.maxDepth = n.at("max_depth").integer(1, 100000000);
        if (n.has("seed")) scene.render.seed = static_cast<uint64_t>(n.at("seed").integer(0, 2147483647));
    }

    Spectrum spectrum(const Node& n, SpectrumKind kind) {
        const bool coefficient = kind == SpectrumKind::Coefficient;
        if (n.raw().is_number()) {
            if (coefficient) n.fail("a coefficient needs a unit, e.g. \"0.5 /mm\"");
            return checked(n, Spectrum::constant(n.number()), kind);
        }
        if (n.raw().is_string()) {
            const std::string s = n.str();
            if (coefficient && startsWithNumber(s)) return checked(n, Spectrum::constant(n.quantity(Dimension::InverseLength)), kind);
            if (startsWithNumber(s)) n.fail("write a dimensionless value as a JSON number, not a string");
            if (coefficient && !knownCoefficientUnit(s))
                n.fail("a coefficient spectrum needs its unit: write {\"reference\": \"" + excerpt(s) + "\", \"unit\": \"/mm\"}");
            return checked(n, Spectrum::tabulated(resolveNamed(n, s)), kind);
        }
        if (!n.raw().is_object()) n.fail("expected a number, a quantity, a spectrum name or a spectrum object");
        if (n.has("lines")) {
            n.allowOnly({"lines"});
            if (kind != SpectrumKind::Emission) n.fail("spectral lines are only allowed in emission spectra");
            const Node lines = n.at("lines");
            if (!lines.raw().is_array() || lines.size() == 0) lines.fail("expected a non-empty array of lines");
            std::vector<SpectralLine> out;
            for (size_t i = 0; i < lines.size(); ++i) {
                const Node l = lines.at(i);
                l.allowOnly({"wavelength", "power"});
                const double lambda = l.at("wavelength").positiveQuantity(Dimension::Wavelength);
                const double power = l.at("power").number(0, 1e30);
                if (lambda < lambdaMin() || lambda > lambdaMax())
                    l.at("wavelength").fail("line lies outside the spectral range [" + std::to_string(lambdaMin()) + ", " +
                                            std::to_string(lambdaMax()) + "] nm");
                out.push_back({lambda, power});
            }
            return Spectrum::lines(std::move(out));
        }
        n.allowOnly({"reference", "tabulated", "scale", "unit"});
        double scale = n.has("scale") ? n.at("scale").number(0, 1e30) : 1.0;
        const bool knownUnit = n.has("reference") && n.at("reference").raw().is_string() && knownCoefficientUnit(n.at("reference").str());
        if (coefficient && knownUnit) {
            // The database delivers these in 1/mm; a stated unit must agree.
            if (n.has("unit") && unitScale(n.at("unit").str(), Dimension::InverseLength) != std::optional<double>(1.0))
                n.at("unit").fail("this reference is in 1/mm; omit \"unit\" or write \"/mm\"");
        } else if (coefficient) {
            const std::string unit = n.at("unit").str();
            const auto s = unitScale(unit, Dimension::InverseLength);
            if (!s) n.at("unit").fail("expected an inverse length unit such as \"/mm\"");
            scale *= *s;
        } else if (n.has("unit")) {
            n.at("unit").fail("\"unit\" is only used for coefficients");
        }
        TabulatedSpectrum table;
        if (n.has("reference") == n.has("tabulated")) n.fail("give exactly one of \"reference\" and \"tabulated\"");
        if (n.has("reference")) table = resolveNamed(n.at("reference"), n.at("reference").str());
        else {
            const Node t = n.at("tabulated");
            t.allowOnly({"wavelength_nm", "values"});
            std::vector<double> l, v;
            const Node ln = t.at("wavelength_nm"), vn = t.at("values");
            if (!ln.raw().is_array() || !vn.raw().is_array() || ln.size() != vn.size())
                t.fail("\"wavelength_nm\" and \"values\" must be arrays of equal length");
            for (size_t i = 0; i < ln.size(); ++i) {
                l.push_back(ln.at(i).number());
                v.push_back(vn.at(i).number());
            }
            try {
                table = TabulatedSpectrum(l, v, "tabulated spectrum");
            } catch (const ConfigError& e) {
                t.fail(e.what());
            }
        }
        return checked(n, Spectrum::tabulated(std::move(table), scale), kind);
    }

    TabulatedSpectrum resolveNamed(const Node& n, const std::string& ref) {
        try {
            return resolve_(ref, baseDir_);
        } catch (const IoError& e) {
            n.failIo(e.what());
        } catch (const Error& e) {
            n.fail(e.what());
        }
    }

    Spectrum checked(const Node& n, Spectrum s, SpectrumKind kind) {
        if (const auto range = s.tableRange(); range && (range->first > lambdaMin() || range->second < lambdaMax())) {
            const std::string what = "tabulated from " + fmtNm(range->first) + " to " + fmtNm(range->second) + " nm, inside the spectral range " +
                                     fmtNm(lambdaMin()) + "-" + fmtNm(lambdaMax()) + " nm";
            // A zero refractive index is meaningless; elsewhere zero outside the table is a legal (if
            // surprising) value, so the user is told rather than stopped.
            if (kind == SpectrumKind::Unitless) n.fail(what + "; a refractive index must cover the whole range");
            warnings_.push_back(file_.string() + ": " + n.path() + ": " + what + "; it is 0 outside its table");
        }
        const double maxV = s.maxValue();
        if (!std::isfinite(maxV) || maxV < 0)
            n.fail("spectrum values must be finite and non-negative");
        if (kind == SpectrumKind::Reflectance && maxV > 1.0) n.fail("a reflectance must not exceed 1");
        // Transport multiplies emission by throughputs and inverse pdfs; 1e308 would overflow to a
        // black image made of dropped non-finite samples. 1e30 is the bound lines and scales have too.
        if (kind == SpectrumKind::Emission && maxV > kMaxEmission)
            n.fail("emission values must not exceed 1e30 (larger ones overflow in transport)");
        return s;
    }

    static std::string fmtNm(double v) {
        std::ostringstream os;
        os << v;
        return os.str();
    }
    double lambdaMin() const { return lambdaMin_; }
    double lambdaMax() const { return lambdaMax_; }

    void loadMedia(const Node& n, Scene& scene) {
        n.requireObject();
        for (auto it = n.raw().begin(); it != n.raw().end(); ++it) {
            const Node m(it.value(), n.path() + "/" + excerpt(it.key()), file_);
            m.allowOnly({"tissue", "sigma_a", "sigma_s", "g", "ior", "dyes", "volume"});
            // A tissue preset gives the defaults; the medium's own fields override them.
            const TissuePreset* tissue = nullptr;
            if (m.has("tissue")) {
                const std::string name = m.at("tissue").str();
                tissue = findTissuePreset(name);
                if (!tissue) m.at("tissue").failQuoted("unknown tissue preset \"" + excerpt(name) + "\" (presets: " + tissuePresetNames() + ")");
            }
            const Spectrum sa = m.has("sigma_a") ? spectrum(m.at("sigma_a"), SpectrumKind::Coefficient)
                                : Spectrum::constant(tissue ? tissue->absorption : 0.0);
            const Spectrum ss = m.has("sigma_s") ? spectrum(m.at("sigma_s"), SpectrumKind::Coefficient)
                                : tissue ? Spectrum::tabulated(tissue->scattering()) : Spectrum::constant(0);
            const double g = m.has("g") ? m.at("g").number(-1, 1, true, true) : tissue ? tissue->g : 0.0;
            const double ior = m.has("ior") ? m.at("ior").number(1, 10) : tissue ? tissue->ior : 1.0;
            std::vector<DyeEntry> entries;
            if (m.has("dyes")) entries = loadDyes(m.at("dyes"));
            std::vector<DyeComponent> dyes;
            bool anyGrid = false;
            for (const DyeEntry& e : entries) {
                dyes.push_back(e.component);
                anyGrid = anyGrid || e.grid.has_value();
            }
            std::shared_ptr<const VolumeFields> volume;
            if (m.has("volume")) volume = loadVolume(m.at("volume"), entries);
            else if (anyGrid) m.fail("a dye takes its concentration from a grid, but the medium has no \"volume\"");
            mediumIndex_[it.key()] = static_cast<int>(scene.media.size());
            try {
                scene.media.emplace_back(it.key(), sa, ss, g, ior, std::move(dyes), std::move(volume));
            } catch (const ConfigError& e) {
                m.failQuoted(e.what());
            }
        }
    }

    struct DyeEntry {
        DyeComponent component;             // molar: the constant concentration, or mol/L per grid unit
        std::optional<std::string> grid;    // the grid holding its concentration
        std::optional<Node> gridNode;
        std::optional<Node> entryNode;
    };

    // {"file": "neurons.vdb", "length_unit": "mm", "translate": [...], "scale": 1, "interpolation":
    // "trilinear", "scattering_grid": "...", "absorption_grid": "...", "label_grid": "...",
    // "majorant_cell_voxels": 0}
    std::shared_ptr<const VolumeFields> loadVolume(const Node& v, const std::vector<DyeEntry>& dyes) {
        v.allowOnly({"file", "length_unit", "translate", "scale", "interpolation", "scattering_grid", "absorption_grid", "label_grid",
                     "majorant_cell_voxels"});
        fs::path f = v.at("file").str();
        if (f.is_relative()) f = baseDir_ / f;
        auto readGrid = [&](const Node& name, bool labels = false) {
            try {
                return DensityGrid::read(f.string(), name.str(), labels);
            } catch (const IoError& e) {
                v.at("file").failIo(e.what());
            } catch (const Error& e) {
                name.failQuoted(e.what());
            }
        };
        Interpolation interpolation = Interpolation::Trilinear;
        if (v.has("interpolation")) {
            const std::string i = v.at("interpolation").str();
            if (i == "nearest") interpolation = Interpolation::Nearest;
            else if (i != "trilinear") v.at("interpolation").fail("expected \"trilinear\" or \"nearest\"");
        }
        MajorantGridOptions majorants;
        if (v.has("majorant_cell_voxels")) majorants.cellVoxels = v.at("majorant_cell_voxels").integer(-1, 1 << 20);
        std::vector<VolumeChannel> channels(kFirstDyeChannel + dyes.size());
        std::optional<DensityGrid> reference;  // sets the length unit
        auto gridChannel = [&](const char* key, VolumeChannel& c) {
            if (!v.has(key)) return;
            c.grid = readGrid(v.at(key));
            if (!reference) reference = c.grid;
        };
        gridChannel("absorption_grid", channels[kSolventChannel]);
        gridChannel("scattering_grid", channels[kScatteringChannel]);
        if (!channels[kSolventChannel].grid) channels[kSolventChannel].offset = 1;
        if (!channels[kScatteringChannel].grid) channels[kScatteringChannel].offset = 1;
        for (size_t i = 0; i < dyes.size(); ++i) {
            VolumeChannel& c = channels[kFirstDyeChannel + i];
            if (!dyes[i].grid) {
                c.offset = dyes[i].component.molar;
                continue;
            }
            c.grid = readGrid(*dyes[i].gridNode);
            if (!reference) reference = c.grid;
            c.scale = gridConcentrationScale(*dyes[i].entryNode, *c.grid);
        }
        std::optional<DensityGrid> labels;  // kept for fits and tools; transport never reads it
        if (v.has("label_grid")) labels = readGrid(v.at("label_grid"), true);
        if (!reference) v.fail("the volume names no grid (give a dye \"grid\", \"scattering_grid\" or \"absorption_grid\")");
        // Length unit of the file's coordinates: the scene's word first, then the file's metadata.
        std::string unit = v.has("length_unit") ? v.at("length_unit").str() : reference->metadata().lengthUnit;
        if (unit.empty())
            v.fail("the grids in " + excerpt(f.string(), 200) + " carry no \"length_unit\" metadata; give \"length_unit\" (e.g. \"um\") for the file's coordinates");
        const auto unitScaleMm = unitScale(unit, Dimension::Length);
        if (!unitScaleMm) {
            if (v.has("length_unit")) v.at("length_unit").fail("expected a length unit such as \"mm\" or \"um\"");
            v.fail("the file's length_unit metadata \"" + excerpt(unit) + "\" is not a length unit");
        }
        const double scale = v.has("scale") ? v.at("scale").number(0, 1e9, true) : 1.0;
        Affine worldFromFile = Affine::scaling(*unitScaleMm * scale);
        if (v.has("translate")) worldFromFile = worldFromFile.then(Affine::translation(v.at("translate").vec3(Dimension::Length)));
        try {
            return std::make_shared<const VolumeFields>(std::move(channels), worldFromFile, interpolation, majorants, std::move(labels));
        } catch (const ConfigError& e) {
            v.failQuoted(e.what());
        }
    }

    // mol/L per unit value of a concentration grid: "grid_units" in the scene, else the grid's "units".
    double gridConcentrationScale(const Node& d, const DensityGrid& grid) {
        const std::string units = d.has("grid_units") ? d.at("grid_units").str() : grid.metadata().units;
        if (units.empty())
            d.fail("grid \"" + excerpt(grid.name()) + "\" carries no \"units\" metadata; give \"grid_units\" (e.g. \"uM\")");
        if (const auto molar = unitScale(units, Dimension::MolarConcentration)) {
            if (d.has("molar_mass")) d.at("molar_mass").fail("a molar mass is only used with mass concentration units such as \"g/L\"");
            return *molar;
        }
        if (const auto mass = unitScale(units, Dimension::MassConcentration)) {
            if (!d.has("molar_mass")) d.fail("grid units \"" + excerpt(units) + "\" are a mass concentration; give \"molar_mass\"");
            return *mass / d.at("molar_mass").positiveQuantity(Dimension::MolarMass);
        }
        if (d.has("grid_units")) d.at("grid_units").fail("expected concentration units such as \"uM\", \"mM\" or \"g/L\"");
        d.fail("grid \"" + excerpt(grid.name()) + "\" has units \"" + excerpt(units) + "\", which are not a concentration");
    }

    // [{"dye": "AF488", "concentration": "10 uM"}, {"dye": "...", "concentration": "0.1 g/L", "molar_mass": "643.4 g/mol"},
    //  {"dye": "AF488", "grid": "AF488", "grid_units": "uM"}]
    std::vector<DyeEntry> loadDyes(const Node& n) {
        if (!n.raw().is_array()) n.fail("expected an array of dyes");
        if (!dyes_) n.fail("no dye database is available to this loader");
        std::vector<DyeEntry> out;
        for (size_t i = 0; i < n.size(); ++i) {
            const Node d = n.at(i);
            d.allowOnly({"dye", "concentration", "grid", "grid_units", "molar_mass", "extinction_peak_M-1cm-1", "quantum_yield"});
            const std::optional<double> epsilon =
                d.has("extinction_peak_M-1cm-1") ? std::optional(d.at("extinction_peak_M-1cm-1").number(0, 1e7, true)) : std::nullopt;
            const std::optional<double> qy = d.has("quantum_yield") ? std::optional(d.at("quantum_yield").number(0, 1)) : std::nullopt;
            std::optional<Fluorophore> dye;
            try {
                dye = dyes_(d.at("dye").str(), epsilon, qy);
            } catch (const IoError& e) {
                d.at("dye").failIo(e.what());
            } catch (const Error& e) {
                d.at("dye").fail(e.what());
            }
            if (d.has("grid")) {
                if (d.has("concentration")) d.at("concentration").fail("give either \"concentration\" or \"grid\", not both");
                out.push_back({{*dye, 0.0}, d.at("grid").str(), d.at("grid"), d});
            } else {
                if (d.has("grid_units")) d.at("grid_units").fail("\"grid_units\" needs \"grid\"");
                out.push_back({{*dye, concentration(d)}, std::nullopt, std::nullopt, d});
            }
        }
        return out;
    }

    // Molar ("10 uM") or mass concentration ("0.1 g/L", which needs "molar_mass"), in mol/L.
    static double concentration(const Node& d) {
        const Node c = d.at("concentration");
        const std::string text = c.str();
        for (Dimension dim : {Dimension::MolarConcentration, Dimension::MassConcentration}) {
            const auto space = text.find_first_not_of("0123456789.eE+- ");
            if (space == std::string::npos || !unitScale(text.substr(space), dim)) continue;
            const double v = c.quantity(dim);
            if (v < 0) c.fail("concentration must be non-negative");
            if (dim == Dimension::MolarConcentration) {
                if (d.has("molar_mass")) d.at("molar_mass").fail("a molar mass is only used with a mass concentration such as \"g/L\"");
                return v;
            }
            if (!d.has("molar_mass")) c.fail("a mass concentration needs \"molar_mass\" (e.g. \"643.4 g/mol\")");
            return v / d.at("molar_mass").positiveQuantity(Dimension::MolarMass);
        }
        c.fail("expected a concentration such as \"10 uM\", \"1 mM\", \"5 nM\" or \"0.1 g/L\" with \"molar_mass\"");
    }

    void loadMaterials(const Node& n, Scene& scene) {
        n.requireObject();
        for (auto it = n.raw().begin(); it != n.raw().end(); ++it) {
            const Node m(it.value(), n.path() + "/" + excerpt(it.key()), file_);
            const std::string type = m.at("type").str();
            std::unique_ptr<Material> mat;
            if (type == "diffuse") {
                m.allowOnly({"type", "reflectance"});
                mat = makeDiffuse(spectrum(m.at("reflectance"), SpectrumKind::Reflectance));
            } else if (type == "plastic") {
                m.allowOnly({"type", "diffuse", "ior", "roughness"});
                mat = makePlastic(spectrum(m.at("diffuse"), SpectrumKind::Reflectance), m.has("ior") ? m.at("ior").number(1, 10, true) : 1.5,
                                  m.has("roughness") ? m.at("roughness").number(0, 1) : 0.1);
            } else if (type == "conductor") {
                m.allowOnly({"type", "eta", "k", "roughness"});
                mat = makeConductor(spectrum(m.at("eta"), SpectrumKind::Unitless), spectrum(m.at("k"), SpectrumKind::Unitless),
                                    m.has("roughness") ? m.at("roughness").number(0, 1) : 0.0);
            } else if (type == "dielectric") {
                m.allowOnly({"type", "roughness"});
                mat = makeDielectric(m.has("roughness") ? m.at("roughness").number(0, 1) : 0.0);
                dielectrics_.insert(it.key());
            } else {
                m.at("type").fail("unknown material type (known: diffuse, plastic, conductor, dielectric)");
            }
            materialIndex_[it.key()] = static_cast<int>(scene.materials.size());
            scene.materials.push_back(std::move(mat));
            scene.materialNames.push_back(it.key());
        }
    }

    int mediumRef(const Node& n) const {
        const std::string name = n.str();
        const auto it = mediumIndex_.find(name);
        if (it == mediumIndex_.end()) n.fail("unknown medium \"" + excerpt(name) + "\"" + known(mediumIndex_));
        return it->second;
    }

    template <class Map>
    static std::string known(const Map& m) {
        std::string s;
        for (const auto& [k, v] : m) s += (s.empty() ? "" : ", ") + excerpt(k, 40);
        return s.empty() ? " (none defined)" : " (defined: " + excerpt(s, 200) + ")";
    }

    void loadShapes(const Node& n, Scene& scene) {
        if (!n.raw().is_array() || n.size() == 0) n.fail("expected a non-empty array of shapes");
        for (size_t i = 0; i < n.size(); ++i) {
            const Node s = n.at(i);
            const std::string type = s.at("type").str();
            uint32_t id = 0;
            try {
                if (type == "sphere") {
                    s.allowOnly({"type", "name", "center", "radius", "material", "interior", "exterior", "emission"});
                    id = scene.geometry.addSphere(s.at("center").vec3(Dimension::Length), s.at("radius").positiveQuantity(Dimension::Length));
                } else if (type == "quad") {
                    s.allowOnly({"type", "name", "origin", "edge1", "edge2", "material", "interior", "exterior", "emission"});
                    const Vec3 o = s.at("origin").vec3(Dimension::Length), e1 = s.at("edge1").vec3(Dimension::Length),
                               e2 = s.at("edge2").vec3(Dimension::Length);
                    if (!(length(cross(e1, e2)) > 0)) s.fail("quad has zero area");
                    id = scene.geometry.addMesh(TriangleMesh{{o, o + e1, o + e1 + e2, o + e2}, {0, 1, 2, 0, 2, 3}});
                } else if (type == "mesh") {
                    s.allowOnly({"type", "name", "file", "unit", "translate", "material", "interior", "exterior", "emission"});
                    fs::path f = s.at("file").str();
                    if (f.is_relative()) f = baseDir_ / f;
                    const auto scale = unitScale(s.at("unit").str(), Dimension::Length);
                    if (!scale) s.at("unit").fail("expected a length unit for the file's coordinates, e.g. \"mm\"");
                    TriangleMesh mesh;
                    try {
                        mesh = loadMesh(f.string());
                    } catch (const ConfigError& e) {
                        s.at("file").fail(e.what());  // the file's content, reported at the field naming it
                    }
                    const Vec3 offset = s.has("translate") ? s.at("translate").vec3(Dimension::Length) : Vec3();
                    for (Vec3& p : mesh.positions) p = p * *scale + offset;
                    id = scene.geometry.addMesh(std::move(mesh));
                } else {
                    s.at("type").fail("unknown shape type (known: sphere, quad, mesh)");
                }
            } catch (const ConfigError& e) {
                if (std::string(e.what()).find(file_.string()) == 0) throw;
                s.fail(e.what());
            } catch (const IoError& e) {
                s.at("file").failIo(e.what());
            }
            ShapeInfo info;
            info.name = s.has("name") ? s.at("name").str() : type + " " + std::to_string(i);
            const bool interface = s.has("interior") || s.has("exterior");
            info.isInterface = interface;
            if (interface) {
                info.insideMedium = s.has("interior") ? mediumRef(s.at("interior")) : kNone;
                info.outsideMedium = s.has("exterior") ? mediumRef(s.at("exterior")) : kNone;
            }
            if (s.has("material")) {
                const Node mn = s.at("material");
                const auto it = materialIndex_.find(mn.str());
                if (it == materialIndex_.end()) mn.fail("unknown material \"" + excerpt(mn.str()) + "\"" + known(materialIndex_));
                const bool dielectric = dielectrics_.count(mn.str()) > 0;
                if (interface && !dielectric) mn.fail("a shape with interior/exterior media must use a dielectric material or none");
                if (!interface && dielectric) mn.fail("a dielectric needs \"interior\" and/or \"exterior\" media (their ior set the index ratio)");
                // A dielectric between equal indices does not bend light: treat it as a null interface
                // so that shadow rays pass.
                const bool matched = interface && scene.ior(info.insideMedium) == scene.ior(info.outsideMedium);
                info.material = dielectric && matched ? kNone : it->second;
            } else if (interface && scene.ior(info.insideMedium) != scene.ior(info.outsideMedium)) {
                // Index mismatch with no material given: a smooth dielectric interface.
                info.material = static_cast<int>(scene.materials.size());
                scene.materials.push_back(makeDielectric(0.0));
                scene.materialNames.push_back("(smooth interface)");
            } else if (!interface && !s.has("emission")) {
                s.fail("a shape needs a \"material\", or \"interior\"/\"exterior\" media, or an \"emission\"");
            }
            scene.shapes.push_back(info);
            if (s.has("emission")) {
                const Node e = s.at("emission");
                e.allowOnly({"radiance", "two_sided"});
                AreaEmission em{spectrum(e.at("radiance"), SpectrumKind::Emission), e.has("two_sided") && e.at("two_sided").boolean()};
                if (!(em.radiance.integral(lambdaMin(), lambdaMax()) > 0)) e.at("radiance").fail("emits no power inside the spectral range");
                scene.addAreaLight(id, std::move(em));
            }
        }
    }

    void loadLights(const Node& n, Scene& scene) {
        if (!n.raw().is_array()) n.fail("expected an array of lights");
        for (size_t i = 0; i < n.size(); ++i) {
            const Node l = n.at(i);
            const std::string type = l.at("type").str();
            if (type == "point") {
                l.allowOnly({"type", "position", "intensity"});
                PointLight p{l.at("position").vec3(Dimension::Length), spectrum(l.at("intensity"), SpectrumKind::Emission)};
                requirePower(l.at("intensity"), p.intensity);
                scene.lights.emplace_back(std::move(p));
            } else if (type == "light_sheet") {
                scene.lights.emplace_back(loadLightSheet(l));
            } else if (type == "widefield") {
                scene.lights.emplace_back(loadWidefield(l));
            } else if (type == "spot") {
                l.allowOnly({"type", "position", "look_at", "intensity", "cone_angle_deg", "falloff_start_deg"});
                const Vec3 pos = l.at("position").vec3(Dimension::Length);
                const Vec3 dir = l.at("look_at").vec3(Dimension::Length) - pos;
                if (!(length(dir) > 0)) l.at("look_at").fail("must differ from position");
                const double cone = l.at("cone_angle_deg").number(0, 180, true, false);
                const double falloff = l.has("falloff_start_deg") ? l.at("falloff_start_deg").number(0, cone) : cone;
                SpotLight sp{pos, normalize(dir), spectrum(l.at("intensity"), SpectrumKind::Emission), std::cos(cone * kPi / 180),
                             std::cos(falloff * kPi / 180)};
                requirePower(l.at("intensity"), sp.intensity);
                scene.lights.emplace_back(std::move(sp));
            } else {
                l.at("type").fail("unknown light type (known: point, spot; area lights are shapes with \"emission\")");
            }
        }
    }

    // A beam's "wavelength" (a laser line) or "spectrum", and its "power_mW".
    void beamSpectrumAndPower(const Node& l, LightSheetSpec& spec) {
        if (l.has("wavelength") == l.has("spectrum")) l.fail("give exactly one of \"wavelength\" and \"spectrum\"");
        if (l.has("wavelength")) spec.wavelengthNm = l.at("wavelength").positiveQuantity(Dimension::Wavelength);
        else spec.spectrum = spectrum(l.at("spectrum"), SpectrumKind::Emission);
        spec.powerMw = l.at("power_mW").quantity(Dimension::Power, "mW");
        if (!(spec.powerMw > 0 && spec.powerMw <= 1e6)) l.at("power_mW").fail("must lie in (0, 1e6] mW");
    }

    // {"type": "light_sheet", "wavelength": "488 nm" (or "spectrum": ...), "power_mW": 10,
    //  "propagation": [1, 0, 0], "normal": [0, 0, 1], "center": [...], "waist": "2 um" (or
    //  "illumination_na": 0.05), "height": "0.5 mm", "refractive_index": 1.33,
    //  "mode": "static" | "scanned", "sides": 1 | 2}
    BeamLight loadLightSheet(const Node& l) {
        l.allowOnly({"type", "wavelength", "spectrum", "power_mW", "propagation", "normal", "center", "waist", "illumination_na", "height",
                     "refractive_index", "mode", "sides"});
        if (!beams_) l.fail("light sheets need the optics library (this program cannot load them)");
        LightSheetSpec spec;
        beamSpectrumAndPower(l, spec);
        spec.propagation = l.at("propagation").vec3(Dimension::Dimensionless);
        spec.normal = l.at("normal").vec3(Dimension::Dimensionless);
        spec.centreMm = l.at("center").vec3(Dimension::Length);
        if (l.has("waist") == l.has("illumination_na")) l.fail("give exactly one of \"waist\" and \"illumination_na\"");
        if (l.has("waist")) spec.waistMm = l.at("waist").positiveQuantity(Dimension::Length);
        else spec.illuminationNa = l.at("illumination_na").number(0, 2, true);
        spec.heightMm = l.at("height").positiveQuantity(Dimension::Length);
        spec.refractiveIndex = l.has("refractive_index") ? l.at("refractive_index").number(1, 3) : 1.33;
        if (l.has("mode")) {
            const std::string m = l.at("mode").str();
            if (m != "static" && m != "scanned") l.at("mode").fail("expected \"static\" or \"scanned\"");
            spec.scanned = m == "scanned";
        }
        if (l.has("sides")) spec.dual = l.at("sides").integer(1, 2) == 2;
        try {
            return BeamLight{beams_(spec), spec};
        } catch (const ConfigError& e) {
            l.failQuoted(e.what());
        }
    }

    // {"type": "widefield", "wavelength": "488 nm" (or "spectrum"), "power_mW": 1, "direction": [0, 0, -1],
    //  "center": [...], "field_diameter": "0.5 mm"}: epi-illumination for comparison with the sheet.
    BeamLight loadWidefield(const Node& l) {
        l.allowOnly({"type", "wavelength", "spectrum", "power_mW", "direction", "center", "field_diameter"});
        if (!beams_) l.fail("widefield lights need the optics library (this program cannot load them)");
        LightSheetSpec spec;
        spec.widefield = true;
        beamSpectrumAndPower(l, spec);
        spec.propagation = l.at("direction").vec3(Dimension::Dimensionless);
        spec.centreMm = l.at("center").vec3(Dimension::Length);
        spec.fieldDiameterMm = l.at("field_diameter").positiveQuantity(Dimension::Length);
        try {
            return BeamLight{beams_(spec), spec};
        } catch (const ConfigError& e) {
            l.failQuoted(e.what());
        }
    }

    void requirePower(const Node& n, const Spectrum& s) const {
        if (!(s.integral(lambdaMin(), lambdaMax()) > 0)) n.fail("emits no power inside the spectral range");
    }

    void loadCamera(const Node& n, Scene& scene) {
        n.allowOnly({"position", "look_at", "up", "fov_y_deg", "resolution", "medium"});
        Camera& c = scene.camera;
        c.position = n.at("position").vec3(Dimension::Length);
        const Vec3 forward = n.at("look_at").vec3(Dimension::Length) - c.position;
        const Vec3 up = n.has("up") ? n.at("up").vec3(Dimension::Dimensionless) : Vec3(0, 1, 0);
        if (!(length(forward) > 0)) n.at("look_at").fail("must differ from position");
        const Vec3 right = cross(normalize(forward), up);
        if (!(length(right) > 1e-9)) n.at("up").fail("must not be parallel to the viewing direction");
        c.frame.n = normalize(forward);
        c.frame.s = normalize(right);
        c.frame.t = cross(c.frame.s, c.frame.n);
        const double fov = n.at("fov_y_deg").number(0, 180, true, true);
        c.tanHalfFovY = std::tan(0.5 * fov * kPi / 180);
        const Node res = n.at("resolution");
        if (!res.raw().is_array() || res.size() != 2) res.fail("expected [width, height]");
        c.width = res.at(0).integer(1, 16384);
        c.height = res.at(1).integer(1, 16384);
        if (static_cast<int64_t>(c.width) * c.height > (int64_t(1) << 26)) res.fail("at most 2^26 pixels");
        if (n.has("medium")) c.medium = mediumRef(n.at("medium"));
    }

    const fs::path& file_;
    fs::path baseDir_;
    const SpectrumResolver& resolve_;
    const DyeResolver& dyes_;
    const BeamResolver& beams_;
    std::map<std::string, int> mediumIndex_, materialIndex_;
    std::set<std::string> dielectrics_;
    std::vector<std::string> warnings_;
    double lambdaMin_ = 300, lambdaMax_ = 800;
};

}  // namespace

Scene loadSceneFromString(const std::string& text, const fs::path& file, const SpectrumResolver& resolve, const DyeResolver& dyes,
                          const BeamResolver& beams) {
    if (text.size() > kMaxSceneBytes)
        throw ConfigError(file.string() + ": scene text of " + formatBytes(static_cast<double>(text.size())) + " is over the limit of " +
                          formatBytes(kMaxSceneBytes) + " (put large data in CSV, mesh or VDB files)");
    const json root = parseScene(text, file);
    return Loader(file, resolve, dyes, beams).load(root);
}

Scene loadScene(const fs::path& file, const SpectrumResolver& resolve, const DyeResolver& dyes, const BeamResolver& beams) {
    std::error_code ec;
    if (fs::is_directory(file, ec)) throw IoError(file.string() + ": is a folder, expected a scene file (JSON)");
    std::ifstream in(file, std::ios::binary);
    if (!in) throw IoError(file.string() + ": cannot open scene file (" + std::strerror(errno) + ")");
    // Refuse before reading: the text and its parsed tree must stay small (kMaxSceneBytes).
    const auto size = fs::file_size(file, ec);
    if (!ec && size > kMaxSceneBytes)
        throw ConfigError(file.string() + ": scene file of " + formatBytes(static_cast<double>(size)) + " is over the limit of " +
                          formatBytes(kMaxSceneBytes) + " (put large data in CSV, mesh or VDB files)");
    std::string text;
    char buf[1 << 16];
    while (in.read(buf, sizeof buf) || in.gcount() > 0) {
        text.append(buf, static_cast<size_t>(in.gcount()));
        if (text.size() > kMaxSceneBytes) break;  // a file that grows, or /dev/zero: refused below
    }
    if (in.bad()) throw IoError(file.string() + ": cannot read scene file");
    return loadSceneFromString(text, file, resolve, dyes, beams);
}

}  // namespace fluorosim
