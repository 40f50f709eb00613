// `fluorosim view SCENE.json [--stack STACK.ome.tif] [--fit FITDIR]`: the VTK viewer (apps/viewer,
// docs/viewer.md). Built only with FLUOROSIM_WITH_VIEWER; interactive unless --screenshot or --movie.
#include <cstdio>
#include <filesystem>
#include <optional>
#include <regex>

#include "commands.h"
#include "core/errors.h"
#include "core/output_checks.h"
#include "viewer/viewer.h"

namespace fluorosim::app {
namespace fs = std::filesystem;
namespace {

struct ViewArgs {
    std::string scene, stack, fit, exr, screenshot, movie, size = "1280x800", view = "overview", blend = "mip", mapper = "auto";
    std::string region = "all", movieKind = "zsweep", screenshotFolder = ".";
    std::vector<std::string> swc, channels, colours, iso;
    std::optional<int> plane, band;
    int frames = 0;
    int64_t maxVoxels = int64_t(1) << 24;
    bool noSwc = false, noMicroscope = false, noNeurons = false;
};

viewer::ViewerOptions toOptions(const ViewArgs& a) {
    viewer::ViewerOptions o;
    o.scene = a.scene;
    if (!a.stack.empty()) o.stack = a.stack;
    if (!a.fit.empty()) o.fit = a.fit;
    if (!a.exr.empty()) o.exr = a.exr;
    for (const std::string& s : a.swc) o.swc.emplace_back(s);
    o.findSwc = !a.noSwc;
    o.channels = a.channels;
    o.colours = a.colours;
    o.isosurfaces = a.iso;
    const auto view = viewer::viewPresetFromName(a.view);
    if (!view) {
        std::string names;
        for (const std::string& n : viewer::viewPresetNames()) names += (names.empty() ? "" : ", ") + n;
        throw ConfigError("--view: unknown view \"" + a.view + "\" (views: " + names + ")");
    }
    o.view = *view;
    o.plane = a.plane;
    o.band = a.band;
    if (a.band && *a.band < 0) throw ConfigError("--band: must be >= 0, got " + std::to_string(*a.band));
    if (a.blend != "mip" && a.blend != "composite") throw ConfigError("--blend: expected mip or composite, got \"" + a.blend + "\"");
    o.blend = a.blend == "mip" ? viewer::BlendMode::Mip : viewer::BlendMode::Composite;
    if (a.mapper != "auto" && a.mapper != "cpu" && a.mapper != "gpu")
        throw ConfigError("--volume-mapper: expected auto, cpu or gpu, got \"" + a.mapper + "\"");
    o.mapper = a.mapper == "cpu" ? viewer::MapperChoice::Cpu : a.mapper == "gpu" ? viewer::MapperChoice::Gpu : viewer::MapperChoice::Auto;
    if (a.region != "all" && a.region != "fov") throw ConfigError("--region: expected all or fov, got \"" + a.region + "\"");
    o.region = a.region == "fov" ? viewer::Region::FieldOfView : viewer::Region::All;
    if (a.maxVoxels < 1000) throw ConfigError("--max-voxels: must be at least 1000, got " + std::to_string(a.maxVoxels));
    o.maxVoxels = static_cast<size_t>(a.maxVoxels);
    std::smatch m;
    if (!std::regex_match(a.size, m, std::regex(R"((\d{1,5})x(\d{1,5}))")))
        throw ConfigError("--size: expected WIDTHxHEIGHT in pixels, e.g. 1280x800, got \"" + a.size + "\"");
    o.width = std::stoi(m[1].str());
    o.height = std::stoi(m[2].str());
    if (!a.screenshot.empty()) {
        requireWritableFolder(a.screenshot);
        o.screenshot = a.screenshot;
    }
    if (!a.movie.empty()) {
        const fs::path movie = a.movie;
        if (movie.extension() == ".ogv") requireWritableFolder(movie);
        o.movie = movie;
    }
    if (a.movieKind != "zsweep" && a.movieKind != "orbit") throw ConfigError("--movie-kind: expected zsweep or orbit, got \"" + a.movieKind + "\"");
    o.movieKind = a.movieKind == "orbit" ? viewer::MovieKind::Orbit : viewer::MovieKind::ZSweep;
    o.movieFrames = a.frames;
    o.screenshotFolder = a.screenshotFolder;
    o.showMicroscope = !a.noMicroscope;
    o.showNeurons = !a.noNeurons;
    o.validate();
    return o;
}

}  // namespace

void addViewCommand(CLI::App& app) {
    auto args = std::make_shared<ViewArgs>();
    CLI::App* cmd = app.add_subcommand("view", "Inspect a scene, its microscope and simulated stacks (VTK); docs/viewer.md");
    cmd->add_option("scene", args->scene, "scene file (JSON)");
    cmd->add_option("--stack", args->stack, "simulated stack (STACK.ome.tif or STACK.expected.ome.tif) to compare with the ground truth");
    cmd->add_option("--fit", args->fit, "fitted concentrations (not available yet)");
    cmd->add_option("--exr", args->exr, "spectral EXR image from fluorosim render");
    cmd->add_option("--swc", args->swc, "SWC morphologies (default: every *.swc beside the scene's volume file)");
    cmd->add_flag("--no-swc", args->noSwc, "show no SWC morphologies");
    cmd->add_option("--channels", args->channels, "channels to show, by name or number (default: all)")->delimiter(',');
    cmd->add_option("--colors", args->colours, "channel colours: green, magenta, cyan, yellow, red, blue, orange, white or #rrggbb")
        ->delimiter(',');
    cmd->add_option("--iso", args->iso, "isosurfaces: CHANNEL or CHANNEL=VALUE (in the grid's units)")->delimiter(',');
    cmd->add_option("--view", args->view, "overview, 3d, top, front, side, xy, xz, yz, compare or exr");
    cmd->add_option("--plane", args->plane, "plane of the stack (0-based; default the middle one)");
    cmd->add_option("--band", args->band, "EXR band (0-based; default the sRGB composite)");
    cmd->add_option("--blend", args->blend, "volume rendering: mip or composite");
    cmd->add_option("--volume-mapper", args->mapper, "auto, cpu (fixed-point ray casting) or gpu");
    cmd->add_option("--region", args->region, "all (the whole grid) or fov (the microscope's field of view at full resolution)");
    cmd->add_option("--max-voxels", args->maxVoxels, "display volume budget (default 16777216 = 256^3)");
    cmd->add_option("--size", args->size, "window size WIDTHxHEIGHT in pixels");
    cmd->add_option("--screenshot", args->screenshot, "render one frame to this PNG and exit (batch mode)");
    cmd->add_option("--movie", args->movie, "write a movie and exit: OUT.ogv, or a folder for PNG frames");
    cmd->add_option("--movie-kind", args->movieKind, "zsweep (every plane) or orbit (360 degrees)");
    cmd->add_option("--frames", args->frames, "movie frames (default: every plane, or 72 for an orbit)");
    cmd->add_option("--screenshot-folder", args->screenshotFolder, "where the S, Z and T keys write");
    cmd->add_flag("--no-microscope", args->noMicroscope, "hide the light sheet, collection cone and field of view");
    cmd->add_flag("--no-neurons", args->noNeurons, "hide the SWC neurons");
    cmd->callback([args] {
        viewer::runViewer(toOptions(*args), [](const std::string& w) { std::fprintf(stderr, "fluorosim: warning: %s\n", w.c_str()); });
    });
}

}  // namespace fluorosim::app
