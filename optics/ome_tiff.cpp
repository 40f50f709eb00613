#include "optics/ome_tiff.h"

#include <tiffio.h>
#include <unistd.h>

#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstdarg>
#include <cstdio>
#include <system_error>

#include "core/errors.h"

namespace fluorosim::optics {
namespace fs = std::filesystem;
namespace {

// Shortest decimal text that reads back as the same double; locale-independent, as XML needs.
std::string num(double v) {
    char buf[64];
    const auto [end, ec] = std::to_chars(buf, buf + sizeof buf, v);
    return ec == std::errc() ? std::string(buf, end) : std::string("?");
}

// XML 1.0 cannot carry control characters other than tab, LF and CR, even escaped.
bool hasForbiddenControl(const std::string& s) {
    return std::any_of(s.begin(), s.end(), [](char ch) {
        const auto c = static_cast<unsigned char>(ch);
        return c < 0x20 && c != '\t' && c != '\n' && c != '\r';
    });
}

// Escapes text for an attribute value or element content. Tab, LF and CR become character
// references, which attribute-value normalisation would otherwise turn into spaces.
std::string xmlEscape(const std::string& s) {
    std::string out;
    out.reserve(s.size());
    for (const char ch : s) {
        switch (ch) {
            case '&': out += "&amp;"; break;
            case '<': out += "&lt;"; break;
            case '>': out += "&gt;"; break;
            case '"': out += "&quot;"; break;
            case '\'': out += "&apos;"; break;
            case '\t': out += "&#9;"; break;
            case '\n': out += "&#10;"; break;
            case '\r': out += "&#13;"; break;
            default: out += ch;
        }
    }
    return out;
}

std::string attr(const char* name, const std::string& value) { return std::string(" ") + name + "=\"" + xmlEscape(value) + "\""; }
std::string attr(const char* name, double value) { return attr(name, num(value)); }

// A physical size as it was meant: 12 significant digits drop the last bits of arithmetic
// (6.5 um / 16 = 0.40625, not 0.40625000000000006); readers compare sizes to 1e-6.
std::string measured(const char* name, double value) {
    char buf[64];
    const auto [end, ec] = std::to_chars(buf, buf + sizeof buf, value, std::chars_format::general, 12);
    return attr(name, ec == std::errc() ? std::string(buf, end) : num(value));
}
std::string attr(const char* name, long long value) { return attr(name, std::to_string(value)); }

// libtiff reports through handlers; these collect the messages for the exception instead of the
// default handlers' printing to stderr.
int collectMessage(TIFF*, void* userData, const char* module, const char* fmt, va_list ap) {
    char buf[1024];
    std::vsnprintf(buf, sizeof buf, fmt, ap);
    auto* messages = static_cast<std::string*>(userData);
    if (!messages->empty()) *messages += "; ";
    if (module && *module) *messages += std::string(module) + ": ";
    *messages += buf;
    return 1;  // handled: do not call the global handler
}
int ignoreMessage(TIFF*, void*, const char*, const char*, va_list) { return 1; }

TIFF* openTiff(const fs::path& path, const char* mode, std::string& errors) {
    TIFFOpenOptions* opts = TIFFOpenOptionsAlloc();
    TIFFOpenOptionsSetErrorHandlerExtR(opts, collectMessage, &errors);
    TIFFOpenOptionsSetWarningHandlerExtR(opts, ignoreMessage, nullptr);
    TIFF* tif = TIFFOpenExt(path.c_str(), mode, opts);  // copies the handlers into the TIFF
    TIFFOpenOptionsFree(opts);
    return tif;
}

std::string writeError(const fs::path& path, const std::string& reason) {
    return path.string() + ": cannot write OME-TIFF: " + reason;
}

template <class T>
struct PixelTraits;
template <>
struct PixelTraits<uint16_t> {
    static constexpr const char* omeType = "uint16";
    static constexpr int bits = 16;
    static constexpr int sampleFormat = SAMPLEFORMAT_UINT;
};
template <>
struct PixelTraits<float> {
    static constexpr const char* omeType = "float";
    static constexpr int bits = 32;
    static constexpr int sampleFormat = SAMPLEFORMAT_IEEEFP;
};

// Closes the TIFF and removes the temporary file unless released (i.e. on every error path).
class PartialFile {
public:
    explicit PartialFile(fs::path tmp) : tmp_(std::move(tmp)) {}
    ~PartialFile() {
        if (tif_) TIFFClose(tif_);
        if (armed_) {
            std::error_code ec;
            fs::remove(tmp_, ec);
        }
    }
    PartialFile(const PartialFile&) = delete;
    PartialFile& operator=(const PartialFile&) = delete;
    TIFF*& tif() { return tif_; }
    void release() { armed_ = false; }

private:
    fs::path tmp_;
    TIFF* tif_ = nullptr;
    bool armed_ = true;
};

template <class T>
void writeStack(const fs::path& path, int width, int height, int planes, int channels, const std::vector<T>& data,
                const StackMetadata& meta) {
    if (width < 1 || height < 1 || planes < 1 || channels < 1)
        throw ConfigError(path.string() + ": stack size " + std::to_string(width) + " x " + std::to_string(height) + " x " +
                          std::to_string(planes) + " planes x " + std::to_string(channels) + " channels: every size must be >= 1");
    const uint64_t planePixels = static_cast<uint64_t>(width) * static_cast<uint64_t>(height);
    const uint64_t pages = static_cast<uint64_t>(planes) * static_cast<uint64_t>(channels) * static_cast<uint64_t>(std::max(1, meta.timePoints));
    if (data.size() != planePixels * pages)
        throw ConfigError(path.string() + ": stack data has " + std::to_string(data.size()) + " samples, expected " +
                          std::to_string(planePixels * pages) + " (width * height * planes * channels)");
    if (meta.channels.size() != static_cast<size_t>(channels))
        throw ConfigError(path.string() + ": metadata lists " + std::to_string(meta.channels.size()) + " channels, the stack has " +
                          std::to_string(channels));
    const std::string xml = omeXml(width, height, planes, channels, PixelTraits<T>::omeType, meta);  // validates meta

    // libtiff's message for a missing directory is "No such file or directory" without saying which.
    const fs::path parent = path.parent_path();
    std::error_code ec;
    if (!parent.empty() && !fs::is_directory(parent, ec))
        throw IoError(writeError(path, "directory '" + parent.string() + "' does not exist"));

    // Classic TIFF addresses 4 GiB; leave room for the IFDs and the XML.
    const uint64_t bytes = planePixels * pages * sizeof(T);
    const bool bigTiff = bytes + xml.size() > (uint64_t(7) << 29);
    const fs::path tmp = path.string() + ".partial";
    std::string errors;  // declared first: TIFFClose in ~PartialFile may still report into it
    PartialFile partial(tmp);
    partial.tif() = openTiff(tmp, bigTiff ? "w8" : "w", errors);
    TIFF* tif = partial.tif();
    if (!tif) throw IoError(writeError(path, errors.empty() ? "cannot create '" + tmp.string() + "'" : errors));

    const size_t rowBytes = static_cast<size_t>(width) * sizeof(T);
    const uint32_t rowsPerStrip = static_cast<uint32_t>(std::clamp<size_t>((size_t(1) << 20) / rowBytes, 1, size_t(height)));
    std::vector<T> strip(static_cast<size_t>(rowsPerStrip) * static_cast<size_t>(width));
    const double pixelsPerCm = 1e4 / meta.pixelSizeUm;
    for (uint64_t page = 0; page < pages; ++page) {
        bool ok = TIFFSetField(tif, TIFFTAG_IMAGEWIDTH, static_cast<uint32_t>(width)) &&
                  TIFFSetField(tif, TIFFTAG_IMAGELENGTH, static_cast<uint32_t>(height)) &&
                  TIFFSetField(tif, TIFFTAG_BITSPERSAMPLE, PixelTraits<T>::bits) &&
                  TIFFSetField(tif, TIFFTAG_SAMPLEFORMAT, PixelTraits<T>::sampleFormat) &&
                  TIFFSetField(tif, TIFFTAG_SAMPLESPERPIXEL, 1) && TIFFSetField(tif, TIFFTAG_PHOTOMETRIC, PHOTOMETRIC_MINISBLACK) &&
                  TIFFSetField(tif, TIFFTAG_PLANARCONFIG, PLANARCONFIG_CONTIG) &&
                  TIFFSetField(tif, TIFFTAG_COMPRESSION, COMPRESSION_NONE) && TIFFSetField(tif, TIFFTAG_ROWSPERSTRIP, rowsPerStrip) &&
                  TIFFSetField(tif, TIFFTAG_RESOLUTIONUNIT, RESUNIT_CENTIMETER) &&
                  TIFFSetField(tif, TIFFTAG_XRESOLUTION, pixelsPerCm) && TIFFSetField(tif, TIFFTAG_YRESOLUTION, pixelsPerCm) &&
                  TIFFSetField(tif, TIFFTAG_SOFTWARE, "Fluorosim");
        // OME-TIFF: the XML lives in the first IFD only.
        if (ok && page == 0) ok = TIFFSetField(tif, TIFFTAG_IMAGEDESCRIPTION, xml.c_str());
        if (!ok) throw IoError(writeError(path, "cannot set TIFF tags: " + errors));
        const T* src = data.data() + page * planePixels;
        for (uint32_t row = 0, s = 0; row < static_cast<uint32_t>(height); row += rowsPerStrip, ++s) {
            const uint32_t rows = std::min<uint32_t>(rowsPerStrip, static_cast<uint32_t>(height) - row);
            const size_t n = static_cast<size_t>(rows) * static_cast<size_t>(width);
            // libtiff may byte-swap the buffer in place, so it gets a copy, never the caller's data.
            std::copy(src + static_cast<size_t>(row) * width, src + static_cast<size_t>(row) * width + n, strip.begin());
            if (TIFFWriteEncodedStrip(tif, s, strip.data(), static_cast<tmsize_t>(n * sizeof(T))) < 0)
                throw IoError(writeError(path, "writing page " + std::to_string(page) + ": " + errors));
        }
        if (!TIFFWriteDirectory(tif)) throw IoError(writeError(path, "writing page " + std::to_string(page) + ": " + errors));
    }
    if (!TIFFFlush(tif)) throw IoError(writeError(path, "flush: " + errors));
    // The rename must not reach the disk before the data, or a crash could leave a truncated file
    // under the final name.
    if (::fsync(TIFFFileno(tif)) != 0)
        throw IoError(writeError(path, std::string("fsync: ") + std::generic_category().message(errno)));
    TIFFClose(tif);
    partial.tif() = nullptr;
    fs::rename(tmp, path, ec);
    if (ec) throw IoError(writeError(path, "cannot rename '" + tmp.string() + "' to it: " + ec.message()));
    partial.release();
}

template <class T>
void readPage(TIFF* tif, const fs::path& path, int page, std::vector<double>& out) {
    uint32_t w = 0, h = 0;
    TIFFGetField(tif, TIFFTAG_IMAGEWIDTH, &w);
    TIFFGetField(tif, TIFFTAG_IMAGELENGTH, &h);
    std::vector<T> row(std::max<size_t>(w, static_cast<size_t>(TIFFScanlineSize64(tif) / sizeof(T))));
    for (uint32_t y = 0; y < h; ++y) {
        if (TIFFReadScanline(tif, row.data(), y, 0) < 0)
            throw IoError(path.string() + ": cannot read TIFF page " + std::to_string(page) + " row " + std::to_string(y));
        out.insert(out.end(), row.begin(), row.begin() + w);
    }
}

}  // namespace

void StackMetadata::validate() const {
    auto positive = [](const char* field, double v, const char* unit) {
        if (!(v > 0) || !std::isfinite(v)) throw ConfigError(std::string("stack metadata: ") + field + " = " + num(v) + ": must be > 0 " + unit);
    };
    positive("pixelSizeUm", pixelSizeUm, "µm");
    positive("zStepUm", zStepUm, "µm");
    positive("exposureS", exposureS, "s");
    if (timePoints < 1 || timePoints > 1000000) throw ConfigError("stack metadata: timePoints = " + std::to_string(timePoints) + ": must be in 1..1000000");
    if (significantBits < 0 || significantBits > 16)
        throw ConfigError("stack metadata: significantBits = " + std::to_string(significantBits) + ": must be in 0..16");
    auto text = [](const std::string& field, const std::string& s) {
        if (hasForbiddenControl(s)) throw ConfigError("stack metadata: " + field + " contains a control character XML cannot carry");
    };
    text("description", description);
    if (values != "adu" && values != "electrons") throw ConfigError("stack metadata: values = \"" + values + "\": must be \"adu\" or \"electrons\"");
    if (camera) {
        if (camera->sensor != "sCMOS" && camera->sensor != "EMCCD") throw ConfigError("stack metadata: camera.sensor = \"" + camera->sensor + "\": must be sCMOS or EMCCD");
        positive("camera.gainElectronsPerAdu", camera->gainElectronsPerAdu, "e-/ADU");
        positive("camera.emGain", camera->emGain, "");
        positive("camera.fullWellElectrons", camera->fullWellElectrons, "e-");
        if (!(camera->offsetAdu >= 0) || !(camera->readNoiseElectrons >= 0) || !(camera->darkCurrentElectronsPerS >= 0) ||
            !std::isfinite(camera->offsetAdu + camera->readNoiseElectrons + camera->darkCurrentElectronsPerS))
            throw ConfigError("stack metadata: camera offset, read noise and dark current must be finite and >= 0");
    }
    text("imageName", imageName);
    for (size_t c = 0; c < channels.size(); ++c) {
        const std::string field = "channels[" + std::to_string(c) + "]";
        text(field + ".name", channels[c].name);
        positive((field + ".excitationNm").c_str(), channels[c].excitationNm, "nm");
        positive((field + ".emissionNm").c_str(), channels[c].emissionNm, "nm");
    }
}

std::string omeXml(int width, int height, int planes, int channels, const std::string& pixelType, const StackMetadata& meta) {
    meta.validate();
    // "µm" is the OME UnitsLength spelling, with U+00B5 MICRO SIGN; the XML is UTF-8.
    const std::string um = "\xC2\xB5m";
    std::string x;
    x += "<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n";
    x += "<OME xmlns=\"http://www.openmicroscopy.org/Schemas/OME/2016-06\" "
         "xmlns:xsi=\"http://www.w3.org/2001/XMLSchema-instance\" "
         "xsi:schemaLocation=\"http://www.openmicroscopy.org/Schemas/OME/2016-06 "
         "http://www.openmicroscopy.org/Schemas/OME/2016-06/ome.xsd\" Creator=\"Fluorosim\">\n";
    const CameraMetadata* cam = meta.camera ? &*meta.camera : nullptr;
    if (cam)
        x += "  <Instrument" + attr("ID", std::string("Instrument:0")) + ">\n    <Detector" + attr("ID", std::string("Detector:0")) +
             attr("Type", std::string(cam->sensor == "EMCCD" ? "EMCCD" : "CMOS")) + attr("Gain", cam->gainElectronsPerAdu) +
             attr("Offset", cam->offsetAdu) + attr("AmplificationGain", cam->emGain) + "/>\n  </Instrument>\n";
    x += "  <Image" + attr("ID", std::string("Image:0")) + attr("Name", meta.imageName) + ">\n";
    if (!meta.description.empty()) x += "    <Description>" + xmlEscape(meta.description) + "</Description>\n";
    if (cam) x += "    <InstrumentRef" + attr("ID", std::string("Instrument:0")) + "/>\n";
    x += "    <Pixels" + attr("ID", std::string("Pixels:0")) + attr("DimensionOrder", std::string("XYZCT")) + attr("Type", pixelType);
    if (pixelType == "uint16" && meta.significantBits > 0) x += attr("SignificantBits", static_cast<long long>(meta.significantBits));
    x += attr("SizeX", static_cast<long long>(width)) + attr("SizeY", static_cast<long long>(height)) +
         attr("SizeZ", static_cast<long long>(planes)) + attr("SizeC", static_cast<long long>(channels)) +
         attr("SizeT", static_cast<long long>(meta.timePoints));
    x += measured("PhysicalSizeX", meta.pixelSizeUm) + attr("PhysicalSizeXUnit", um) + measured("PhysicalSizeY", meta.pixelSizeUm) +
         attr("PhysicalSizeYUnit", um) + measured("PhysicalSizeZ", meta.zStepUm) + attr("PhysicalSizeZUnit", um) + ">\n";
    // Schema order inside Pixels: Channel*, then TiffData*, then Plane*.
    for (int c = 0; c < channels; ++c) {
        const ChannelInfo& ch = meta.channels.at(static_cast<size_t>(c));
        x += "      <Channel" + attr("ID", "Channel:0:" + std::to_string(c)) + attr("Name", ch.name) + attr("SamplesPerPixel", 1LL) +
             attr("ExcitationWavelength", ch.excitationNm) + attr("ExcitationWavelengthUnit", std::string("nm")) +
             // The emission path's centroid to 0.1 nm, as a filter's centre is quoted (not 525.4445925268271).
             measured("EmissionWavelength", std::round(ch.emissionNm * 10) / 10) + attr("EmissionWavelengthUnit", std::string("nm"));
        if (cam)
            x += ">\n        <DetectorSettings" + attr("ID", std::string("Detector:0")) + attr("Gain", cam->gainElectronsPerAdu) +
                 attr("Offset", cam->offsetAdu) + "/>\n      </Channel>\n";
        else x += "/>\n";
    }
    const long long pages = static_cast<long long>(planes) * channels * meta.timePoints;
    x += "      <TiffData" + attr("IFD", 0LL) + attr("PlaneCount", pages) + "/>\n";
    for (int t = 0; t < meta.timePoints; ++t)
        for (int c = 0; c < channels; ++c)
            for (int z = 0; z < planes; ++z)
                x += "      <Plane" + attr("TheZ", static_cast<long long>(z)) + attr("TheT", static_cast<long long>(t)) + attr("TheC", static_cast<long long>(c)) +
                 attr("ExposureTime", meta.exposureS) + attr("ExposureTimeUnit", std::string("s")) +
                 attr("PositionZ", z * meta.zStepUm) + attr("PositionZUnit", um) + "/>\n";
    x += "    </Pixels>\n";
    if (cam) x += "    <AnnotationRef" + attr("ID", std::string("Annotation:0")) + "/>\n";
    x += "  </Image>\n";
    if (cam) {
        // What the values are and the camera that made them, in explicit units (OME's Detector Gain has none).
        auto entry = [](const char* key, const std::string& value) { return "        <M" + attr("K", std::string(key)) + ">" + xmlEscape(value) + "</M>\n"; };
        x += "  <StructuredAnnotations>\n    <MapAnnotation" + attr("ID", std::string("Annotation:0")) + attr("Namespace", std::string(kCameraNamespace)) +
             ">\n      <Value>\n";
        x += entry("values", meta.values) + entry("sensor", cam->sensor) + entry("gain_e_per_adu", num(cam->gainElectronsPerAdu)) +
             entry("offset_adu", num(cam->offsetAdu)) + entry("read_noise_e", num(cam->readNoiseElectrons)) + entry("em_gain", num(cam->emGain)) +
             entry("dark_current_e_per_s", num(cam->darkCurrentElectronsPerS)) + entry("full_well_e", num(cam->fullWellElectrons)) +
             entry("bit_depth", std::to_string(cam->bitDepth)) + entry("exposure_s", num(meta.exposureS));
        x += "      </Value>\n    </MapAnnotation>\n  </StructuredAnnotations>\n";
    }
    x += "</OME>\n";
    return x;
}

void writeOmeTiffUint16(const fs::path& path, int width, int height, int planes, int channels, const std::vector<uint16_t>& data,
                        const StackMetadata& meta) {
    writeStack(path, width, height, planes, channels, data, meta);
}

void writeOmeTiffFloat32(const fs::path& path, int width, int height, int planes, int channels, const std::vector<float>& data,
                         const StackMetadata& meta) {
    writeStack(path, width, height, planes, channels, data, meta);
}

TiffStackInfo readTiffStack(const fs::path& path, bool readPixels) {
    std::string errors;
    TIFF* tif = openTiff(path, "r", errors);
    if (!tif) throw IoError(path.string() + ": cannot read TIFF: " + (errors.empty() ? std::string("cannot open") : errors));
    struct Closer {
        TIFF* t;
        ~Closer() { TIFFClose(t); }
    } closer{tif};

    TiffStackInfo info;
    uint32_t w = 0, h = 0;
    uint16_t bits = 0, format = 0;
    TIFFGetField(tif, TIFFTAG_IMAGEWIDTH, &w);
    TIFFGetField(tif, TIFFTAG_IMAGELENGTH, &h);
    TIFFGetFieldDefaulted(tif, TIFFTAG_BITSPERSAMPLE, &bits);
    TIFFGetFieldDefaulted(tif, TIFFTAG_SAMPLEFORMAT, &format);
    char* desc = nullptr;
    if (TIFFGetField(tif, TIFFTAG_IMAGEDESCRIPTION, &desc) && desc) info.imageDescription = desc;
    info.width = static_cast<int>(w);
    info.height = static_cast<int>(h);
    info.bitsPerSample = bits;
    info.sampleFormat = format;
    do {
        if (readPixels) {
            uint16_t b = 0, f = 0, spp = 0;
            TIFFGetFieldDefaulted(tif, TIFFTAG_BITSPERSAMPLE, &b);
            TIFFGetFieldDefaulted(tif, TIFFTAG_SAMPLEFORMAT, &f);
            TIFFGetFieldDefaulted(tif, TIFFTAG_SAMPLESPERPIXEL, &spp);
            if (spp == 1 && b == 16 && f == SAMPLEFORMAT_UINT)
                readPage<uint16_t>(tif, path, info.pages, info.pixels);
            else if (spp == 1 && b == 32 && f == SAMPLEFORMAT_IEEEFP)
                readPage<float>(tif, path, info.pages, info.pixels);
            else
                throw IoError(path.string() + ": TIFF page " + std::to_string(info.pages) + " has " + std::to_string(spp) + " samples of " +
                              std::to_string(b) + " bits, format " + std::to_string(f) +
                              "; only single-sample uint16 and float32 pixels can be read");
        }
        ++info.pages;
    } while (TIFFReadDirectory(tif));
    return info;
}

}  // namespace fluorosim::optics
