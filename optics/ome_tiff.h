#pragma once
// OME-TIFF stacks (OME 2016-06 schema): one single-sample page per (plane, channel), OME-XML in the
// first page's ImageDescription, DimensionOrder XYZCT (Z fastest, then C; T = 1). Pages are written in
// the order of the data: channel-major, then plane (z), then row, then column, i.e. sample
// (c, z, y, x) is data[((c * planes + z) * height + y) * width + x] and page c * planes + z (with
// StackMetadata::timePoints > 1, whole stacks follow one another along T).
// Uncompressed; BigTIFF when the pixel data exceed 3.5 GiB. libtiff stays inside ome_tiff.cpp.
#include <cstdint>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

namespace fluorosim::optics {

struct ChannelInfo {
    std::string name;
    double excitationNm = 0;  // written as ExcitationWavelength, unit nm
    double emissionNm = 0;    // written as EmissionWavelength, unit nm
};

// The camera behind a stack's values, so that a reader can turn ADU back into photoelectrons: written
// as OME's Detector (Type, Gain, Offset, AmplificationGain) and, unambiguously in these units, as a
// MapAnnotation in the namespace kCameraNamespace.
struct CameraMetadata {
    std::string sensor = "sCMOS";       // "sCMOS" or "EMCCD"
    double gainElectronsPerAdu = 0.46;  // electrons per ADU (after the EM gain)
    double offsetAdu = 100;
    double readNoiseElectrons = 1.4;    // rms
    double emGain = 1;
    double darkCurrentElectronsPerS = 0;
    double fullWellElectrons = 30000;
    int bitDepth = 16;
};
inline constexpr const char* kCameraNamespace = "https://fluorosim.org/ome/camera";

struct StackMetadata {
    double pixelSizeUm = 1;  // in the sample (PhysicalSizeX and PhysicalSizeY, µm)
    double zStepUm = 1;      // PhysicalSizeZ, µm
    std::vector<ChannelInfo> channels;  // one per channel of the stack
    double exposureS = 0.1;             // every plane's ExposureTime, s
    std::string description;            // Image/Description (free text, UTF-8)
    std::string imageName = "Fluorosim stack";
    int significantBits = 0;  // uint16 only: Pixels/SignificantBits (the ADC bit depth); 0 = not written
    std::optional<CameraMetadata> camera;  // the detector, with what the values are (below)
    std::string values = "adu";           // "adu" (camera counts) or "electrons" (expected photoelectrons)
    int timePoints = 1;                   // SizeT: pages run t-major, then channel, then plane (e.g. one per fit parameter)

    // Throws ConfigError naming the field: non-positive or non-finite sizes, exposure or wavelengths,
    // significantBits outside 0..16, text with control characters XML cannot carry.
    void validate() const;
};

// The OME-XML written into the first page (exposed for tests and for companion files).
// pixelType is "uint16" or "float".
std::string omeXml(int width, int height, int planes, int channels, const std::string& pixelType, const StackMetadata& meta);

// Write a stack. The file is written as `<path>.partial`, flushed to disk and renamed to `path`, so
// an interrupted write never leaves a truncated stack under the final name. Throws ConfigError for
// non-positive sizes, data.size() != width * height * planes * channels, meta.channels.size() !=
// channels or invalid metadata; IoError naming the path when the file cannot be written.
void writeOmeTiffUint16(const std::filesystem::path& path, int width, int height, int planes, int channels,
                        const std::vector<uint16_t>& data, const StackMetadata& meta);
// Same layout with 32-bit IEEE float samples (e.g. the expected photoelectrons), Type="float".
void writeOmeTiffFloat32(const std::filesystem::path& path, int width, int height, int planes, int channels,
                         const std::vector<float>& data, const StackMetadata& meta);

struct TiffStackInfo {
    int pages = 0;
    int width = 0, height = 0;      // of the first page
    int bitsPerSample = 0;          // of the first page
    int sampleFormat = 0;           // TIFF SampleFormat: 1 unsigned int, 3 IEEE float
    std::string imageDescription;   // of the first page ("" if absent)
    std::vector<double> pixels;     // every page in file order, if requested (uint16 and float32 only)
};

// Reads the structure (and optionally the pixels) of a TIFF file. Throws IoError naming the path.
TiffStackInfo readTiffStack(const std::filesystem::path& path, bool readPixels = false);

}  // namespace fluorosim::optics
