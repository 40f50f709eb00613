#pragma once
// A small labelled specimen for the fit's tests: three rods in a tissue block under two light sheets, a
// 0.8 NA water objective and a 40 × 40 sCMOS camera, two planes. Label 1 (AF488) runs along x at
// y = −3 µm, label 2 (AF594) along y at x = +3 µm (y ≥ 0), label 3 (AF488) along x at y = +5 µm
// (x ≤ −1 µm); none touches another. Written as a scene file with its OpenVDB volume, as a user's.
#include <array>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <functional>
#include <string>

#include "volume/density_grid.h"

namespace fluorosim::testing {

struct FitSceneOptions {
    std::array<double, 3> concentrationsUm{10, 10, 10};  // per label
    double sigmaSPerMm = 0;                               // the tissue's scattering (g 0.9)
    double tissueIndex = 1.33;
    int planes = 2;
    double stepUm = 1;
    int pixels = 40;
    double power488mW = 0.05, power561mW = 0.05;
    double exposureS = 0.02;
    int spp = 4;
    // A factor on every rod's concentration along x (µm), e.g. a gradient; 1 by default.
    std::function<double(double)> profile;
    // Instead of the rods: this many AF488 beads (radius 0.6 µm) on a square grid 2 µm apart in the focal
    // plane, bead l (1-based) labelled l at (5 + l mod 7) µM: a per-label fit of many labels.
    int beads = 0;
};

inline std::string fitSceneJson(const FitSceneOptions& o) {
    auto n = [](double v) {
        char buf[64];
        std::snprintf(buf, sizeof buf, "%.10g", v);
        return std::string(buf);
    };
    return R"({
 "fluorosim_scene": 1,
 "spectral": {"range": ["450 nm", "750 nm"], "bin_width": "10 nm"},
 "render": {"spp": )" + std::to_string(o.spp) + R"(, "seed": 1},
 "camera": {"position": ["0 mm", "0 mm", "0.2 mm"], "look_at": ["0 mm", "0 mm", "0 mm"], "up": [0, 1, 0], "fov_y_deg": 5, "resolution": [16, 16], "medium": "water"},
 "media": {
  "water": {"ior": 1.33, "sigma_a": "solvent-absorption:water"},
  "tissue": {"ior": )" + n(o.tissueIndex) + R"(, "g": 0.9, "sigma_s": ")" + n(o.sigmaSPerMm) + R"( /mm", "sigma_a": "solvent-absorption:water",
   "dyes": [{"dye": "AF488", "grid": "af488"}, {"dye": "AF594", "grid": "af594"}],
   "volume": {"file": "rods.vdb", "interpolation": "trilinear", "label_grid": "label"}}
 },
 "shapes": [
  {"type": "mesh", "name": "water bath", "file": "bath.obj", "unit": "um", "interior": "water"},
  {"type": "mesh", "name": "tissue block", "file": "block.obj", "unit": "um", "interior": "tissue", "exterior": "water"}
 ],
 "lights": [
  {"type": "light_sheet", "wavelength": "488 nm", "power_mW": )" + n(o.power488mW) + R"(, "propagation": [1, 0, 0], "normal": [0, 0, 1],
   "center": ["0 mm", "0 mm", "0 mm"], "waist": "1.5 um", "height": "0.1 mm", "refractive_index": 1.33, "mode": "static", "sides": 1},
  {"type": "light_sheet", "wavelength": "561 nm", "power_mW": )" + n(o.power561mW) + R"(, "propagation": [1, 0, 0], "normal": [0, 0, 1],
   "center": ["0 mm", "0 mm", "0 mm"], "waist": "1.5 um", "height": "0.1 mm", "refractive_index": 1.33, "mode": "static", "sides": 1}
 ],
 "microscope": {
  "objective": {"na": 0.8, "magnification": 16, "immersion_index": 1.33, "working_distance": "0.1 mm"},
  "focus": {"center": ["0 mm", "0 mm", "0 mm"], "toward_objective": [0, 0, 1], "up": [0, 1, 0]},
  "detector": {"type": "sCMOS", "pixel_pitch": "6.5 um", "width": )" + std::to_string(o.pixels) + R"(, "height": )" + std::to_string(o.pixels) +
           R"(, "exposure_s": )" + n(o.exposureS) + R"(,
   "gain_e_per_adu": 0.46, "offset_adu": 100, "read_noise_e": 1.4, "dark_current_e_per_s": 0.5, "full_well_e": 30000, "bit_depth": 16, "qe": 0.8},
  "channels": [
   {"name": "AF488", "emission_filter": "semrock_FF01-525-45", "lights": [0]},
   {"name": "AF594", "emission_filter": "semrock_FF01-609-54", "lights": [1]}
  ],
  "stack": {"planes": )" + std::to_string(o.planes) + R"(, "step": ")" + n(o.stepUm) + R"( um"}
 }
})";
}

inline void writeBoxObj(const std::filesystem::path& file, double half, double halfZ, const char* what) {
    std::ofstream f(file);
    f << "# " << what << "\n";
    // The vertex order and outward faces of samples/lightsheet/bath.obj.
    const double xs[4] = {-half, half, half, -half}, ys[4] = {-half, -half, half, half};
    for (int z = 0; z < 2; ++z)
        for (int c = 0; c < 4; ++c) f << "v " << xs[c] << " " << ys[c] << " " << (z ? halfZ : -halfZ) << "\n";
    f << "f 1 4 3 2\nf 5 6 7 8\nf 1 2 6 5\nf 2 3 7 6\nf 3 4 8 7\nf 4 1 5 8\n";
}

// The rods' concentration (µM) and label at a voxel of 0.5 µm: full inside radius 0.7 µm, a linear
// edge of one voxel, cut at the rod's ends.
inline std::pair<double, int> fitRodVoxel(const FitSceneOptions& o, int i, int j, int k, bool af594) {
    const double h = 0.5, x = i * h, y = j * h, z = k * h, r = 0.7;
    if (o.beads > 0) {
        if (af594) return {0, 0};
        const int side = static_cast<int>(std::ceil(std::sqrt(double(o.beads))));
        const double spacing = 2, first = -0.5 * (side - 1) * spacing;
        const int bx = static_cast<int>(std::lround((x - first) / spacing)), by = static_cast<int>(std::lround((y - first) / spacing));
        const int label = by * side + bx + 1;
        if (bx < 0 || by < 0 || bx >= side || by >= side || label > o.beads) return {0, 0};
        const double d = std::sqrt(sqr(x - first - bx * spacing) + sqr(y - first - by * spacing) + z * z);
        const double c = std::clamp((0.6 + 0.25 - d) / 0.5, 0.0, 1.0);
        return c > 0 ? std::pair<double, int>{(5 + label % 7) * c, label} : std::pair<double, int>{0, 0};
    }
    auto coverage = [&](double d) { return std::clamp((r + 0.25 - d) / 0.5, 0.0, 1.0); };
    if (!af594) {
        const double d1 = std::hypot(y + 3, z - 0.2), d3 = std::hypot(y - 5, z - 0.4);
        if (x >= -10 && x <= 10 && coverage(d1) > 0)
            return {o.concentrationsUm[0] * coverage(d1) * (o.profile ? o.profile(x) : 1.0), 1};
        if (x >= -10 && x <= -1 && coverage(d3) > 0) return {o.concentrationsUm[2] * coverage(d3) * (o.profile ? o.profile(x) : 1.0), 3};
        return {0, 0};
    }
    const double d2 = std::hypot(x - 3, z + 0.3);
    if (y >= 0 && y <= 10 && coverage(d2) > 0) return {o.concentrationsUm[1] * coverage(d2) * (o.profile ? o.profile(x) : 1.0), 2};
    return {0, 0};
}

// Writes scene.json, rods.vdb, bath.obj and block.obj into `dir`; returns the scene's path.
inline std::filesystem::path writeFitScene(const std::filesystem::path& dir, const FitSceneOptions& o = {}) {
    const IndexBox box{{-24, -24, -8}, {24, 24, 8}};
    const GridMetadata meta{"uM", "mm"};
    writeVoxelGrids((dir / "rods.vdb").string(), Affine::scaling(0.0005),
                    {{"af488", box, [&](int i, int j, int k) { return fitRodVoxel(o, i, j, k, false).first; }, meta},
                     {"af594", box, [&](int i, int j, int k) { return fitRodVoxel(o, i, j, k, true).first; }, meta},
                     {"label", box,
                      [&](int i, int j, int k) {
                          const int a = fitRodVoxel(o, i, j, k, false).second, b = fitRodVoxel(o, i, j, k, true).second;
                          return static_cast<double>(a ? a : b);
                      },
                      {"", "mm"}, true}});
    writeBoxObj(dir / "bath.obj", 300, 300, "water bath");
    writeBoxObj(dir / "block.obj", 60, 15, "tissue block");
    std::ofstream(dir / "scene.json") << fitSceneJson(o);
    return dir / "scene.json";
}

}  // namespace fluorosim::testing
