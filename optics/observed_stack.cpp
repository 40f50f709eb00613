#include "optics/observed_stack.h"

#include <charconv>
#include <cmath>
#include <map>

#include "core/errors.h"
#include "core/message.h"

namespace fluorosim::optics {
namespace {

// The few XML facts a stack's OME-XML needs, read without a full parser: element start tags by name,
// their attributes, and the text of <M K="..."> map entries. Entities are decoded.
std::string unescape(const std::string& s) {
    std::string out;
    for (size_t i = 0; i < s.size(); ++i) {
        if (s[i] != '&') {
            out += s[i];
            continue;
        }
        const size_t end = s.find(';', i);
        if (end == std::string::npos) {
            out += s[i];
            continue;
        }
        const std::string e = s.substr(i + 1, end - i - 1);
        if (e == "amp") out += '&';
        else if (e == "lt") out += '<';
        else if (e == "gt") out += '>';
        else if (e == "quot") out += '"';
        else if (e == "apos") out += '\'';
        else if (!e.empty() && e[0] == '#') {
            const long code = e.size() > 1 && (e[1] == 'x' || e[1] == 'X') ? std::strtol(e.c_str() + 2, nullptr, 16) : std::strtol(e.c_str() + 1, nullptr, 10);
            if (code > 0 && code < 0x80) out += static_cast<char>(code);
            else out += "?";
        } else {
            out += s.substr(i, end - i + 1);
        }
        i = end;
    }
    return out;
}

// Start tags named `name` (with or without a namespace prefix), each as the text between '<' and '>'.
std::vector<std::string> startTags(const std::string& xml, const std::string& name) {
    std::vector<std::string> tags;
    for (size_t pos = xml.find('<'); pos != std::string::npos; pos = xml.find('<', pos + 1)) {
        size_t p = pos + 1;
        if (p >= xml.size() || xml[p] == '/' || xml[p] == '?' || xml[p] == '!') continue;
        size_t e = p;
        while (e < xml.size() && !std::isspace(static_cast<unsigned char>(xml[e])) && xml[e] != '>' && xml[e] != '/') ++e;
        std::string tag = xml.substr(p, e - p);
        if (const size_t colon = tag.find(':'); colon != std::string::npos) tag = tag.substr(colon + 1);
        if (tag != name) continue;
        const size_t close = xml.find('>', pos);
        if (close == std::string::npos) break;
        tags.push_back(xml.substr(pos + 1, close - pos - 1));
    }
    return tags;
}

std::optional<std::string> attribute(const std::string& tag, const std::string& name) {
    for (size_t pos = tag.find(name); pos != std::string::npos; pos = tag.find(name, pos + 1)) {
        if (pos == 0 || !std::isspace(static_cast<unsigned char>(tag[pos - 1]))) continue;
        size_t p = pos + name.size();
        while (p < tag.size() && std::isspace(static_cast<unsigned char>(tag[p]))) ++p;
        if (p >= tag.size() || tag[p] != '=') continue;
        ++p;
        while (p < tag.size() && std::isspace(static_cast<unsigned char>(tag[p]))) ++p;
        if (p >= tag.size() || (tag[p] != '"' && tag[p] != '\'')) continue;
        const char quote = tag[p];
        const size_t end = tag.find(quote, p + 1);
        if (end == std::string::npos) return std::nullopt;
        return unescape(tag.substr(p + 1, end - p - 1));
    }
    return std::nullopt;
}

class OmeFields {
public:
    OmeFields(std::filesystem::path path, std::string xml) : path_(std::move(path)), xml_(std::move(xml)) {}
    [[noreturn]] void fail(const std::string& field, const std::string& what) const {
        throw ConfigError(path_.string() + ": OME " + field + ": " + what);
    }
    double number(const std::string& tag, const std::string& name, const std::string& value) const {
        double v = 0;
        const auto [end, ec] = std::from_chars(value.data(), value.data() + value.size(), v);
        if (ec != std::errc() || end != value.data() + value.size() || !std::isfinite(v))
            fail(tag + "/@" + name, "expected a number, got \"" + excerpt(value) + "\"");
        return v;
    }
    int integer(const std::string& tag, const std::string& name, const std::string& value, int lo, int hi) const {
        const double v = number(tag, name, value);
        if (v != std::floor(v) || v < lo || v > hi)
            fail(tag + "/@" + name, "expected an integer in [" + std::to_string(lo) + ", " + std::to_string(hi) + "], got " + excerpt(value));
        return static_cast<int>(v);
    }
    const std::string& xml() const { return xml_; }

private:
    std::filesystem::path path_;
    std::string xml_;
};

// A length in µm from an OME value and its unit attribute (default µm).
double lengthUm(const OmeFields& f, const std::string& field, double v, const std::optional<std::string>& unit) {
    static const std::map<std::string, double> units = {{"\xC2\xB5m", 1.0}, {"\xCE\xBCm", 1.0}, {"um", 1.0}, {"nm", 1e-3},
                                                       {"mm", 1e3},         {"cm", 1e4},        {"m", 1e6}};
    const std::string u = unit.value_or("\xC2\xB5m");
    const auto it = units.find(u);
    if (it == units.end()) f.fail(field + "Unit", "unknown length unit \"" + excerpt(u) + "\" (known: µm, um, nm, mm, cm, m)");
    return v * it->second;
}

double timeS(const OmeFields& f, const std::string& field, double v, const std::optional<std::string>& unit) {
    static const std::map<std::string, double> units = {{"s", 1.0}, {"ms", 1e-3}, {"\xC2\xB5s", 1e-6}, {"us", 1e-6}, {"ns", 1e-9}, {"min", 60.0}};
    const std::string u = unit.value_or("s");
    const auto it = units.find(u);
    if (it == units.end()) f.fail(field + "Unit", "unknown time unit \"" + excerpt(u) + "\" (known: s, ms, µs, ns, min)");
    return v * it->second;
}

}  // namespace

int ObservedStack::channelIndex(const std::string& name) const {
    for (size_t c = 0; c < channelNames.size(); ++c)
        if (channelNames[c] == name) return static_cast<int>(c);
    std::string known;
    for (const std::string& n : channelNames) known += (known.empty() ? "" : ", ") + ("\"" + n + "\"");
    throw ConfigError(path.string() + ": no channel named \"" + excerpt(name) + "\" (the stack has " + (known.empty() ? "no named channels" : known) + ")");
}

ObservedStack readOmeStack(const std::filesystem::path& path) {
    const TiffStackInfo tiff = readTiffStack(path, true);
    const OmeFields f(path, tiff.imageDescription);
    if (tiff.imageDescription.find("<OME") == std::string::npos)
        throw ConfigError(path.string() + ": not an OME-TIFF (its first page's ImageDescription holds no OME-XML)");
    const std::vector<std::string> pixels = startTags(f.xml(), "Pixels");
    if (pixels.empty()) f.fail("Pixels", "missing");
    if (pixels.size() > 1) f.fail("Image", "the file holds " + std::to_string(pixels.size()) + " images; only one can be read");
    const std::string& px = pixels[0];
    auto required = [&](const std::string& name) {
        const auto v = attribute(px, name);
        if (!v) f.fail("Pixels/@" + name, "missing");
        return *v;
    };
    ObservedStack s;
    s.path = path;
    s.width = f.integer("Pixels", "SizeX", required("SizeX"), 1, 1 << 20);
    s.height = f.integer("Pixels", "SizeY", required("SizeY"), 1, 1 << 20);
    s.planes = f.integer("Pixels", "SizeZ", required("SizeZ"), 1, 1 << 20);
    s.channels = f.integer("Pixels", "SizeC", required("SizeC"), 1, 1 << 16);
    const int sizeT = f.integer("Pixels", "SizeT", attribute(px, "SizeT").value_or("1"), 1, 1 << 20);
    if (sizeT != 1) f.fail("Pixels/@SizeT", "the stack has " + std::to_string(sizeT) + " time points; only one can be fitted");
    const std::string order = required("DimensionOrder");
    if (order.size() != 5 || order.rfind("XY", 0) != 0) f.fail("Pixels/@DimensionOrder", "unknown order \"" + excerpt(order) + "\"");
    const bool zBeforeC = order.find('Z') < order.find('C');
    if (tiff.width != s.width || tiff.height != s.height)
        f.fail("Pixels/@SizeX", "says " + std::to_string(s.width) + " x " + std::to_string(s.height) + " pixels, the TIFF pages hold " +
                                    std::to_string(tiff.width) + " x " + std::to_string(tiff.height));
    if (tiff.pages != s.planes * s.channels)
        f.fail("Pixels/@SizeZ", "SizeZ " + std::to_string(s.planes) + " x SizeC " + std::to_string(s.channels) + " planes, the TIFF holds " +
                                    std::to_string(tiff.pages) + " pages");
    s.integerPixels = tiff.sampleFormat != 3;
    if (const auto v = attribute(px, "PhysicalSizeX"))
        s.pixelSizeUm = lengthUm(f, "Pixels/@PhysicalSizeX", f.number("Pixels", "PhysicalSizeX", *v), attribute(px, "PhysicalSizeXUnit"));
    if (const auto v = attribute(px, "PhysicalSizeY")) {
        const double y = lengthUm(f, "Pixels/@PhysicalSizeY", f.number("Pixels", "PhysicalSizeY", *v), attribute(px, "PhysicalSizeYUnit"));
        if (s.pixelSizeUm > 0 && std::abs(y - s.pixelSizeUm) > 1e-6 * s.pixelSizeUm)
            f.fail("Pixels/@PhysicalSizeY", "pixels of " + std::to_string(s.pixelSizeUm) + " x " + std::to_string(y) + " um are not square");
    }
    if (const auto v = attribute(px, "PhysicalSizeZ"))
        s.zStepUm = lengthUm(f, "Pixels/@PhysicalSizeZ", f.number("Pixels", "PhysicalSizeZ", *v), attribute(px, "PhysicalSizeZUnit"));
    const std::vector<std::string> channels = startTags(f.xml(), "Channel");
    for (int c = 0; c < s.channels; ++c)
        s.channelNames.push_back(c < static_cast<int>(channels.size()) ? attribute(channels[static_cast<size_t>(c)], "Name").value_or("") : "");
    const std::vector<std::string> planeTags = startTags(f.xml(), "Plane");
    if (!planeTags.empty())
        if (const auto v = attribute(planeTags[0], "ExposureTime"))
            s.exposureS = timeS(f, "Plane/@ExposureTime", f.number("Plane", "ExposureTime", *v), attribute(planeTags[0], "ExposureTimeUnit"));
    // Fluorosim's camera annotation: <M K="key">value</M> entries of the MapAnnotation in its namespace.
    const size_t ns = f.xml().find(std::string("Namespace=\"") + kCameraNamespace + "\"");
    if (ns != std::string::npos) {
        const size_t end = f.xml().find("MapAnnotation>", ns);
        const std::string block = f.xml().substr(ns, end == std::string::npos ? std::string::npos : end - ns);
        std::map<std::string, std::string> entries;
        for (size_t pos = block.find("<M "); pos != std::string::npos; pos = block.find("<M ", pos + 1)) {
            const size_t close = block.find('>', pos), stop = block.find("</M>", pos);
            if (close == std::string::npos || stop == std::string::npos) break;
            if (const auto k = attribute(block.substr(pos + 1, close - pos - 1), "K")) entries[*k] = unescape(block.substr(close + 1, stop - close - 1));
        }
        auto entry = [&](const char* key) {
            const auto it = entries.find(key);
            if (it == entries.end()) f.fail(std::string("MapAnnotation/M[@K='") + key + "']", "missing from the camera annotation");
            return it->second;
        };
        auto value = [&](const char* key) { return f.number(std::string("MapAnnotation/M[@K='") + key + "']", "value", entry(key)); };
        CameraMetadata cam;
        cam.sensor = entry("sensor");
        if (cam.sensor != "sCMOS" && cam.sensor != "EMCCD") f.fail("MapAnnotation/M[@K='sensor']", "expected sCMOS or EMCCD, got \"" + excerpt(cam.sensor) + "\"");
        cam.gainElectronsPerAdu = value("gain_e_per_adu");
        cam.offsetAdu = value("offset_adu");
        cam.readNoiseElectrons = value("read_noise_e");
        cam.emGain = value("em_gain");
        cam.darkCurrentElectronsPerS = value("dark_current_e_per_s");
        cam.fullWellElectrons = value("full_well_e");
        cam.bitDepth = f.integer("MapAnnotation/M[@K='bit_depth']", "value", entry("bit_depth"), 1, 32);
        if (!(cam.gainElectronsPerAdu > 0) || !(cam.emGain >= 1) || !(cam.readNoiseElectrons >= 0) || !(cam.offsetAdu >= 0))
            f.fail("MapAnnotation", "camera gain " + std::to_string(cam.gainElectronsPerAdu) + " e-/ADU, EM gain " + std::to_string(cam.emGain) +
                                        ", read noise " + std::to_string(cam.readNoiseElectrons) + " e-, offset " + std::to_string(cam.offsetAdu) +
                                        " ADU: gain must be > 0, EM gain >= 1, the others >= 0");
        s.camera = cam;
        s.values = entry("values");
        if (s.values != "adu" && s.values != "electrons") f.fail("MapAnnotation/M[@K='values']", "expected adu or electrons, got \"" + excerpt(s.values) + "\"");
        if (entries.count("exposure_s") && !(s.exposureS > 0)) s.exposureS = value("exposure_s");
    }
    // Pages in file order -> (channel, plane).
    const size_t planePixels = static_cast<size_t>(s.width) * s.height;
    s.data.resize(planePixels * static_cast<size_t>(s.planes) * s.channels);
    for (int c = 0; c < s.channels; ++c)
        for (int z = 0; z < s.planes; ++z) {
            const size_t page = zBeforeC ? static_cast<size_t>(c) * s.planes + z : static_cast<size_t>(z) * s.channels + c;
            std::copy(tiff.pixels.begin() + static_cast<std::ptrdiff_t>(page * planePixels),
                      tiff.pixels.begin() + static_cast<std::ptrdiff_t>((page + 1) * planePixels),
                      s.data.begin() + static_cast<std::ptrdiff_t>((static_cast<size_t>(c) * s.planes + z) * planePixels));
        }
    return s;
}

}  // namespace fluorosim::optics
