#pragma once
// A stack read back: an OME-TIFF's pixels with what its OME-XML says they are (size, pixel size, z step,
// channel names, exposure, the camera), for fitting a model to it. Fluorosim's own stacks carry the
// camera in a MapAnnotation (optics/ome_tiff.h); other OME-TIFFs give it through OME's Detector, which
// has no units, so a caller may supply the camera instead (CameraMetadata).
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include "optics/ome_tiff.h"

namespace fluorosim::optics {

struct ObservedStack {
    std::filesystem::path path;
    int width = 0, height = 0, planes = 0, channels = 0;
    std::vector<std::string> channelNames;
    double pixelSizeUm = 0, zStepUm = 0;   // 0 when the file does not say
    double exposureS = 0;                  // 0 when the file does not say
    std::string values;                    // "adu", "electrons", or "" when the file does not say
    std::optional<CameraMetadata> camera;  // from Fluorosim's annotation
    bool integerPixels = false;            // uint16 (camera counts) rather than float
    std::vector<double> data;              // (channel, plane, y, x), x fastest

    double at(int c, int z, int y, int x) const {
        return data[((static_cast<size_t>(c) * planes + static_cast<size_t>(z)) * height + static_cast<size_t>(y)) * width + static_cast<size_t>(x)];
    }
    // The channel named `name`; ConfigError naming the file and listing the channels otherwise.
    int channelIndex(const std::string& name) const;
};

// Reads an OME-TIFF stack whole. Throws IoError for a file that is missing or not a TIFF, ConfigError
// (naming the file and the field) for a TIFF without OME-XML, sizes that disagree with its pages, a
// dimension order or SizeT it cannot hold, or units it does not know.
ObservedStack readOmeStack(const std::filesystem::path& path);

}  // namespace fluorosim::optics
