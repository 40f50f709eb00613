#pragma once
// Image output. OpenEXR and libpng are included only in io/*.cpp.
#include <map>
#include <string>
#include <vector>

namespace fluorosim {

// One spectral layer: bins centred at `wavelengthsNm`, values[bin * width * height + y * width + x].
struct SpectralLayer {
    std::string prefix;                // "" for the main layer, else e.g. "fluorescent"
    std::vector<double> wavelengthsNm;
    std::vector<float> values;
};

// Extra RGB channels "<prefix>.R", "<prefix>.G", "<prefix>.B", interleaved like ExrImage::rgb.
struct RgbLayer {
    std::string prefix;
    std::vector<float> rgb;
};

struct ExrImage {
    int width = 0, height = 0;
    std::vector<float> rgb;            // linear sRGB, interleaved, row-major from the top
    std::vector<RgbLayer> rgbLayers;
    std::vector<SpectralLayer> spectral;
    std::map<std::string, std::string> attributes;  // written as string header attributes
};

// Writes RGB channels R,G,B plus spectral channels named after Fichet, Pacanowski & Wilkie 2021
// ("An OpenEXR Layout for Spectral Images", JCGT 10(3)): emissive channel "S0.550,000000nm"; a layer
// prefix becomes "<prefix>.S0.550,000000nm". Also writes the "spectralLayoutVersion" = "1.0" and
// "emissiveUnits" attributes. Throws IoError naming the path.
void writeExr(const std::string& path, const ExrImage& image);

// Channel name of the spectral layout for one wavelength, e.g. spectralChannelName(550) == "S0.550,000000nm".
std::string spectralChannelName(double wavelengthNm);

// Reads every float or half channel of an EXR file (for tests and tools). Throws IoError.
struct ExrChannels {
    int width = 0, height = 0;
    std::map<std::string, std::vector<float>> channels;
    std::map<std::string, std::string> attributes;
};
ExrChannels readExr(const std::string& path);

// 8-bit sRGB PNG from linear RGB, scaled by `exposure` then encoded with the sRGB curve. Throws IoError.
void writePngPreview(const std::string& path, int width, int height, const std::vector<float>& linearRgb, double exposure);

}  // namespace fluorosim
