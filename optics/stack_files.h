#pragma once
// Files of an acquisition: the OME-TIFF stacks (16-bit counts, float expected electrons and their
// Monte Carlo standard errors), a preview PNG, and a checkpoint that holds every finished plane so
// that an interrupted run resumes to the same result.
#include <filesystem>
#include <string>

#include "optics/acquisition.h"
#include "optics/ome_tiff.h"

namespace fluorosim::optics {

struct StackOutputs {
    std::filesystem::path counts, expected, stderrElectrons, preview;
    // NAME.ome.tif -> NAME.expected.ome.tif, NAME.stderr.ome.tif, NAME.preview.png. ConfigError if
    // `stack` does not end in .ome.tif.
    static StackOutputs forStack(const std::filesystem::path& stack);
};

// The camera of a detector, as a stack's metadata records it.
CameraMetadata cameraMetadata(const DetectorOptions& detector);

// Writes planes 0 .. planes-1 (all channels) of `stack`. `description` goes into the OME metadata.
void writeStackFiles(const StackOutputs& out, const Stack& stack, const Microscope& microscope, int planes,
                     const std::string& description);

// The preview of the expected electrons, as a microscopist looks at a stack: the x-y maximum projection
// of each channel in its colour (green, magenta, red, cyan, each scaled to its 99.5th percentile), then
// their merge (with two or more channels), side by side, with a white scale bar of
// previewScaleBarUm(...) in the bottom left of each panel. Under them, the x-z maximum over y at the true
// aspect, only when the stack is at least a tenth of the field deep (a thin stack's strip says nothing).
void writeStackPreview(const std::filesystem::path& png, const Stack& stack, int planes, double pixelSizeUm, double zStepUm);
// The scale bar: the largest of 1, 2, 5 × 10^k µm not over a fifth of the field's width.
double previewScaleBarUm(double pixelSizeUm, int width);

// Checkpoint: a header with a fingerprint of everything that determines the result, then one record
// per finished plane, each flushed to disk as it is written.
class StackCheckpoint {
public:
    // Starts a new checkpoint file (replacing any). Throws IoError.
    StackCheckpoint(std::filesystem::path path, const std::string& fingerprint);
    // Opens an existing checkpoint to append to it, after loading its planes into `stack` (through
    // storePlane, so the read-out is the same). Throws ConfigError if the fingerprint differs (another
    // scene, seed or option), IoError if it cannot be read. A last record cut short by a kill is dropped.
    static StackCheckpoint resume(std::filesystem::path path, const std::string& fingerprint, Stack& stack, const Microscope& microscope,
                                  uint64_t seed);
    void append(size_t channelSlot, int plane, const PlaneImage& image);
    const std::filesystem::path& path() const { return path_; }

private:
    explicit StackCheckpoint(std::filesystem::path path) : path_(std::move(path)) {}
    std::filesystem::path path_;
};

}  // namespace fluorosim::optics
