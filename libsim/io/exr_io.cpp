// OpenEXR output and input. The spectral channel layout follows Fichet, Pacanowski & Wilkie 2021,
// "An OpenEXR Layout for Spectral Images", JCGT 10(3).
#include <OpenEXR/ImfChannelList.h>
#include <OpenEXR/ImfCompression.h>
#include <OpenEXR/ImfFrameBuffer.h>
#include <OpenEXR/ImfHeader.h>
#include <OpenEXR/ImfInputFile.h>
#include <OpenEXR/ImfOutputFile.h>
#include <OpenEXR/ImfStringAttribute.h>

#include <charconv>
#include <cmath>
#include <cstddef>
#include <exception>
#include <filesystem>
#include <set>
#include <string>
#include <system_error>
#include <vector>

#include "core/errors.h"
#include "io/image_io.h"

namespace fluorosim {
namespace {

constexpr const char* kSpectralLayoutVersion = "1.0";
// As written by the layout's reference implementation and pbrt-v4; the S0 channels hold values per nm.
constexpr const char* kEmissiveUnits = "W.m^-2.sr^-1";

std::string writeError(const std::string& path, const std::string& reason) {
    return path + ": cannot write OpenEXR file: " + reason;
}

// One channel to write: its name and where its pixels start in the caller's buffer.
struct ChannelSource {
    std::string name;
    const float* base;
    std::size_t xStride;  // bytes
};

void validate(const std::string& path, const ExrImage& image) {
    if (image.width <= 0 || image.height <= 0)
        throw ConfigError(path + ": image size must be positive, got " + std::to_string(image.width) + "x" +
                          std::to_string(image.height));
    const std::size_t pixels = static_cast<std::size_t>(image.width) * static_cast<std::size_t>(image.height);
    if (image.rgb.size() != 3 * pixels)
        throw ConfigError(path + ": rgb has " + std::to_string(image.rgb.size()) + " values, expected " +
                          std::to_string(3 * pixels) + " (3 x width x height)");
    for (const RgbLayer& layer : image.rgbLayers)
        if (layer.prefix.empty() || layer.rgb.size() != 3 * pixels)
            throw ConfigError(path + ": RGB layer '" + layer.prefix + "' needs a prefix and 3 x width x height values");
    for (const SpectralLayer& layer : image.spectral) {
        const std::size_t expected = layer.wavelengthsNm.size() * pixels;
        if (layer.values.size() != expected)
            throw ConfigError(path + ": spectral layer '" + layer.prefix + "' has " +
                              std::to_string(layer.values.size()) + " values, expected " +
                              std::to_string(expected) + " (bins x width x height)");
    }
    for (const auto& [name, value] : image.attributes) {
        if (name.empty()) throw ConfigError(path + ": empty EXR attribute name");
    }
}

}  // namespace

std::string spectralChannelName(double wavelengthNm) {
    if (!std::isfinite(wavelengthNm) || wavelengthNm <= 0)
        throw ConfigError("spectral channel wavelength must be positive and finite, got " +
                          std::to_string(wavelengthNm));
    // std::to_chars is locale-independent, unlike printf, so the decimal point is always '.' before we swap it.
    char buffer[64];
    const auto result = std::to_chars(buffer, buffer + sizeof buffer, wavelengthNm, std::chars_format::fixed, 6);
    if (result.ec != std::errc())
        throw ConfigError("spectral channel wavelength too large: " + std::to_string(wavelengthNm));
    std::string number(buffer, result.ptr);
    // The layout uses ',' as decimal separator because '.' separates layers in EXR channel names.
    for (char& c : number)
        if (c == '.') c = ',';
    return "S0." + number + "nm";
}

void writeExr(const std::string& path, const ExrImage& image) {
    validate(path, image);

    const std::size_t width = static_cast<std::size_t>(image.width);
    const std::size_t pixels = width * static_cast<std::size_t>(image.height);

    std::vector<ChannelSource> sources;
    const char* rgbNames[3] = {"R", "G", "B"};
    for (std::size_t c = 0; c < 3; ++c) sources.push_back({rgbNames[c], image.rgb.data() + c, 3 * sizeof(float)});
    for (const RgbLayer& layer : image.rgbLayers)
        for (std::size_t c = 0; c < 3; ++c)
            sources.push_back({layer.prefix + "." + rgbNames[c], layer.rgb.data() + c, 3 * sizeof(float)});
    for (const SpectralLayer& layer : image.spectral) {
        for (std::size_t bin = 0; bin < layer.wavelengthsNm.size(); ++bin) {
            std::string name = spectralChannelName(layer.wavelengthsNm[bin]);
            if (!layer.prefix.empty()) name = layer.prefix + "." + name;
            sources.push_back({std::move(name), layer.values.data() + bin * pixels, sizeof(float)});
        }
    }
    // OpenEXR would silently keep only one of two equally named channels.
    std::set<std::string> seen;
    for (const ChannelSource& source : sources)
        if (!seen.insert(source.name).second)
            throw ConfigError(path + ": duplicate EXR channel '" + source.name + "' (repeated wavelength or prefix)");

    // OpenEXR's own message for a missing directory is vague; name the directory instead.
    const std::filesystem::path parent = std::filesystem::path(path).parent_path();
    std::error_code ec;
    if (!parent.empty() && !std::filesystem::is_directory(parent, ec))
        throw IoError(writeError(path, "directory '" + parent.string() + "' does not exist"));

    bool opened = false;
    try {
        Imf::Header header(image.width, image.height);
        header.compression() = Imf::ZIP_COMPRESSION;
        Imf::FrameBuffer frameBuffer;
        for (const ChannelSource& source : sources) {
            header.channels().insert(source.name, Imf::Channel(Imf::FLOAT));
            // OpenEXR's Slice takes a non-const pointer but only reads from it when writing.
            char* base = reinterpret_cast<char*>(const_cast<float*>(source.base));
            frameBuffer.insert(source.name, Imf::Slice(Imf::FLOAT, base, source.xStride, source.xStride * width));
        }

        std::map<std::string, std::string> attributes = {{"spectralLayoutVersion", kSpectralLayoutVersion},
                                                         {"emissiveUnits", kEmissiveUnits}};
        for (const auto& [name, value] : image.attributes) attributes[name] = value;  // caller's values override
        for (const auto& [name, value] : attributes) {
            // Standard attributes such as "compression" have other types; replacing them would corrupt the header.
            if (header.find(name) != header.end() && !header.findTypedAttribute<Imf::StringAttribute>(name))
                throw ConfigError(path + ": EXR attribute '" + name + "' is reserved by OpenEXR");
            header.insert(name, Imf::StringAttribute(value));
        }

        Imf::OutputFile file(path.c_str(), header);
        opened = true;
        file.setFrameBuffer(frameBuffer);
        file.writePixels(image.height);
    } catch (const ConfigError&) {
        throw;
    } catch (const std::exception& e) {
        // A truncated file would otherwise be mistaken for a finished render by later steps.
        if (opened) std::filesystem::remove(path, ec);
        throw IoError(writeError(path, e.what()));
    }
}

ExrChannels readExr(const std::string& path) {
    try {
        Imf::InputFile file(path.c_str());
        const Imf::Header& header = file.header();
        const Imath::Box2i dataWindow = header.dataWindow();
        ExrChannels result;
        result.width = dataWindow.max.x - dataWindow.min.x + 1;
        result.height = dataWindow.max.y - dataWindow.min.y + 1;
        const std::size_t pixels = static_cast<std::size_t>(result.width) * static_cast<std::size_t>(result.height);

        Imf::FrameBuffer frameBuffer;
        for (auto it = header.channels().begin(); it != header.channels().end(); ++it) {
            if (it.channel().xSampling != 1 || it.channel().ySampling != 1)
                throw IoError(path + ": cannot read OpenEXR file: channel '" + it.name() + "' is subsampled");
            std::vector<float>& values = result.channels[it.name()];
            values.assign(pixels, 0.0f);
            // Slice::Make offsets the pointer by the data window origin, which need not be (0, 0).
            frameBuffer.insert(it.name(), Imf::Slice::Make(Imf::FLOAT, values.data(), dataWindow));
        }
        file.setFrameBuffer(frameBuffer);
        file.readPixels(dataWindow.min.y, dataWindow.max.y);

        for (auto it = header.begin(); it != header.end(); ++it) {
            if (const auto* text = dynamic_cast<const Imf::StringAttribute*>(&it.attribute()))
                result.attributes[it.name()] = text->value();
        }
        return result;
    } catch (const IoError&) {
        throw;
    } catch (const std::exception& e) {
        throw IoError(path + ": cannot read OpenEXR file: " + e.what());
    }
}

}  // namespace fluorosim
