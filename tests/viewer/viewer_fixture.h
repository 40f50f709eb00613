#pragma once
// A small scene the viewer tests build themselves: two Gaussian dye blobs on a 1 µm grid (AF488 left,
// AF594 right), a light sheet and a light-sheet microscope looking down -z at them, plus helpers to
// write stacks and read PNG sizes. Every test runs under xvfb-run (tests/CMakeLists.txt).
#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "optics/ome_tiff.h"
#include "support/cli_runner.h"
#include "viewer/microscope_overlay.h"
#include "viewer/viewer.h"
#include "volume/density_grid.h"

namespace fluorosim::testing {

namespace fs = std::filesystem;
using json = nlohmann::json;

// Grid: voxels (0..39, 0..39, 0..23) of 1 µm, voxel (i, j, k) centred at (i, j, k) µm.
struct Blob {
    std::array<int, 3> centre;
    double peakUm = 10, sigmaVoxels = 2;  // peak in µM
    double at(double i, double j, double k) const {
        const double d2 = (i - centre[0]) * (i - centre[0]) + (j - centre[1]) * (j - centre[1]) + (k - centre[2]) * (k - centre[2]);
        return peakUm * std::exp(-d2 / (2 * sigmaVoxels * sigmaVoxels));
    }
};
inline const Blob kGreenBlob{{12, 20, 12}};
inline const Blob kMagentaBlob{{28, 20, 12}};
inline constexpr double kVoxelUm = 1.0;
// The microscope: 64 x 64 pixels of 6.5 µm / 16 = 0.40625 µm, focused on the blobs' plane (z = 12 µm),
// 5 planes of 2 µm, so plane 2 is the focal plane.
inline constexpr int kDetectorPixels = 64, kPlanes = 5;
inline constexpr double kPixelUm = 6.5 / 16, kStepUm = 2;
// The focus is off the blobs' row (y = 20), so a flipped image would not fit the truth.
inline const Vec3 kFocusUm(20, 18, 12);

class ViewerScene {
public:
    explicit ViewerScene(const TempDir& dir) : dir_(dir.path()) {
        auto blobValue = [](const Blob& b) { return [b](int i, int j, int k) { return b.at(i, j, k) > 1e-3 ? b.at(i, j, k) : 0.0; }; };
        writeVoxelGrids((dir_ / "blobs.vdb").string(), Affine::scaling(kVoxelUm * 1e-3),
                        {{"green", {{0, 0, 0}, {39, 39, 23}}, blobValue(kGreenBlob), {"uM", "mm"}},
                         {"magenta", {{0, 0, 0}, {39, 39, 23}}, blobValue(kMagentaBlob), {"uM", "mm"}}});
        scene_ = sceneJson();
        write();
    }

    fs::path path() const { return dir_ / "scene.json"; }
    const fs::path& dir() const { return dir_; }
    json& scene() { return scene_; }
    void write() const { std::ofstream(path()) << scene_.dump(1); }

    viewer::ViewerOptions options(int width = 400, int height = 300) const {
        viewer::ViewerOptions o;
        o.scene = path();
        o.width = width;
        o.height = height;
        o.offscreen = true;
        o.findSwc = false;
        return o;
    }

    // Writes a float32 stack of `planes` planes in the microscope's layout, value(plane, x, y) per
    // pixel (row y from the top), and returns its path.
    template <class Value>
    fs::path writeStack(const std::string& name, int width, int height, int planes, double pixelUm, const std::vector<std::string>& channels,
                        Value value) const {
        std::vector<float> data;
        for (size_t c = 0; c < channels.size(); ++c)
            for (int z = 0; z < planes; ++z)
                for (int y = 0; y < height; ++y)
                    for (int x = 0; x < width; ++x) data.push_back(static_cast<float>(value(static_cast<int>(c), z, x, y)));
        optics::StackMetadata meta;
        meta.pixelSizeUm = pixelUm;
        meta.zStepUm = kStepUm;
        for (const std::string& ch : channels) meta.channels.push_back({ch, 488, 525});
        const fs::path p = dir_ / name;
        optics::writeOmeTiffFloat32(p, width, height, planes, static_cast<int>(channels.size()), data, meta);
        return p;
    }

private:
    json sceneJson() const {
        const auto mm = [](double um) { return std::to_string(um * 1e-3) + " mm"; };
        const json centre = {mm(kFocusUm.x), mm(kFocusUm.y), mm(kFocusUm.z)};
        return json{
            {"fluorosim_scene", 1},
            {"spectral", {{"range", {"450 nm", "700 nm"}}}},
            {"camera", {{"position", {mm(20), mm(20), mm(500)}}, {"look_at", centre}, {"fov_y_deg", 10}, {"resolution", {8, 8}},
                        {"medium", "tissue"}}},
            {"media",
             {{"tissue",
               {{"ior", 1.33},
                {"dyes", json::array({json{{"dye", "AF488"}, {"grid", "green"}}, json{{"dye", "AF594"}, {"grid", "magenta"}}})},
                {"volume", {{"file", "blobs.vdb"}}}}}}},
            {"shapes", json::array({json{{"type", "sphere"}, {"name", "bath"}, {"center", centre}, {"radius", "0.1 mm"}, {"interior", "tissue"}}})},
            {"lights", json::array({json{{"type", "light_sheet"}, {"wavelength", "488 nm"}, {"power_mW", 1}, {"propagation", {1, 0, 0}},
                                         {"normal", {0, 0, 1}}, {"center", centre}, {"waist", "2 um"}, {"height", "0.05 mm"}}})},
            {"microscope",
             {{"objective", {{"na", 0.8}, {"magnification", 16}, {"immersion_index", 1.33}, {"working_distance", "0.05 mm"}}},
              {"focus", {{"center", centre}, {"toward_objective", {0, 0, 1}}, {"up", {0, 1, 0}}}},
              {"detector", {{"width", kDetectorPixels}, {"height", kDetectorPixels}, {"pixel_pitch", "6.5 um"}}},
              {"channels", json::array({json{{"name", "AF488"}, {"emission_filter", "semrock_FF01-525-45"}, {"lights", {0}}}})},
              {"stack", {{"planes", kPlanes}, {"step", "2 um"}}}}}};
    }

    fs::path dir_;
    json scene_;
};

// Width and height from a PNG's IHDR chunk.
inline std::array<int, 2> pngSize(const fs::path& png) {
    std::ifstream in(png, std::ios::binary);
    unsigned char header[24] = {};
    in.read(reinterpret_cast<char*>(header), sizeof header);
    if (!in || header[1] != 'P' || header[2] != 'N' || header[3] != 'G') return {-1, -1};
    auto be32 = [&](int at) { return int(header[at]) << 24 | int(header[at + 1]) << 16 | int(header[at + 2]) << 8 | int(header[at + 3]); };
    return {be32(16), be32(20)};
}

// One key press as vtkInteractorEventRecorder writes it (# StreamVersion 1.1: x y modifiers keycode
// repeat keysym; modifiers 1 = Shift).
inline std::string keyPress(const std::string& keySym, int x = 10, int y = 10, bool shift = false) {
    const int code = keySym.size() == 1 ? keySym[0] : 0;
    const std::string fields = std::to_string(x) + " " + std::to_string(y) + " " + (shift ? "1" : "0") + " " + std::to_string(code) + " 1 " + keySym;
    return "KeyPressEvent " + fields + "\nCharEvent " + fields + "\nKeyReleaseEvent " + fields + "\n";
}

inline std::string mouseEvent(const std::string& event, int x, int y) { return event + " " + std::to_string(x) + " " + std::to_string(y) + " 0 0 0 0\n"; }

}  // namespace fluorosim::testing
