#pragma once
// A simulated z-stack (the OME-TIFF files `fluorosim acquire` writes) next to the ground truth: each
// channel's dye concentration resampled onto the detector grid at every plane (the pixel's footprint
// on the focal plane, supersampled when pixels are larger than voxels), a least-squares fit
// simulated ≈ a·truth + b over the whole channel, and the residual simulated − (a·truth + b).
//
// The stack is read with optics::readTiffStack (VTK's OME-TIFF reader returns plane 0 for every
// plane in 9.1). Layout: CZYX, channel-major, as optics/ome_tiff.h writes it. Images are stored with
// row 0 at the top, as the camera reads out.
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include "optics/microscope.h"
#include "viewer/specimen.h"

namespace fluorosim::viewer {

struct OmeStackInfo {
    int width = 0, height = 0, planes = 0, channels = 0;
    double pixelSizeUm = 0, zStepUm = 0;
    std::string pixelType;                  // "uint16" or "float"
    std::vector<std::string> channelNames;
};
// Parses the OME-XML of a stack written by optics/ome_tiff. Throws ConfigError naming `file`.
OmeStackInfo parseOmeXml(const std::string& xml, const std::filesystem::path& file);

struct ChannelComparison {
    std::string name;                 // the microscope channel
    int truthChannel = -1;            // specimen channel of its dye; -1 when no dye grid matches
    std::vector<float> simulated;     // planes × height × width
    std::vector<float> truth;         // in the dye grid's units
    std::vector<float> residual;      // simulated − (fitScale·truth + fitOffset)
    double fitScale = 0, fitOffset = 0, correlation = 0;
    double residualRms = 0;
};

struct StackComparison {
    std::filesystem::path file;
    OmeStackInfo info;
    bool counts = true;               // uint16 camera counts (ADU), else float expected electrons
    std::vector<ChannelComparison> channels;
    std::optional<std::filesystem::path> sibling;  // the expected stack of a counts stack, or back

    size_t planeOffset(int plane) const { return size_t(plane) * size_t(info.width) * size_t(info.height); }
    const char* valueUnit() const { return counts ? "ADU" : "e-"; }
};

// Reads `stack` and checks it against the scene's microscope (detector size, pixel size, channel
// names). Throws IoError for a missing or unreadable file, ConfigError for a stack that does not
// belong to this microscope.
StackComparison loadStackComparison(const std::filesystem::path& stack, const Scene& scene, const optics::Microscope& microscope,
                                    const Specimen& specimen);

// The specimen channel a microscope channel images: the dye of the same name, else the grid dye its
// emission path passes best; -1 when the specimen has no grid.
int truthChannelFor(const optics::MicroscopeChannel& channel, const Specimen& specimen);

}  // namespace fluorosim::viewer
