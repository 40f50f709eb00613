#pragma once
// The Fluorosim viewer (`fluorosim view`): the specimen (dye grids as volumes and slices, SWC
// neurons as tubes, isosurfaces), the microscope (light sheet, collection cone, field of view), the
// simulated stack beside the ground truth, and spectral EXR images. VTK renders it; VTK and X11 stay
// inside apps/viewer/*.cpp, so this header shows only project types. docs/viewer.md has the views,
// options and key bindings.
//
// Rendering needs an X server (Debian's VTK 9.1 has no offscreen OSMesa or EGL backend): the viewer
// checks DISPLAY and the connection before it creates a window and throws DisplayError otherwise,
// so a headless run ends with a one-line error instead of VTK's abort.
#include <array>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "core/errors.h"
#include "core/vec3.h"

namespace fluorosim::viewer {

// No usable X display (DISPLAY unset, no server, no GLX). The CLI exits with code 4.
struct DisplayError : Error {
    using Error::Error;
};

enum class MapperChoice { Auto, Cpu, Gpu };
enum class BlendMode { Mip, Composite };
// Layouts and camera presets. Overview: XY slice, 3D, XZ and YZ slices (Slicer's four-up).
enum class ViewPreset { Overview, ThreeD, Top, Front, Side, SliceXy, SliceXz, SliceYz, Compare, Exr };
enum class MovieKind { ZSweep, Orbit };
enum class Region { All, FieldOfView };

// "overview", "3d", "top", ...; nullopt for an unknown name.
std::optional<ViewPreset> viewPresetFromName(const std::string& name);
const char* viewPresetName(ViewPreset view);
std::vector<std::string> viewPresetNames();

struct ViewerOptions {
    std::filesystem::path scene;                    // empty: only --exr
    std::optional<std::filesystem::path> stack;     // STACK.ome.tif (counts) or STACK.expected.ome.tif
    std::optional<std::filesystem::path> fit;       // a fit folder: accepted, shown as not available yet
    std::optional<std::filesystem::path> exr;       // a spectral EXR image
    std::vector<std::filesystem::path> swc;         // SWC files; empty: found beside the volume file
    bool findSwc = true;
    std::vector<std::string> channels;              // names or 1-based numbers to show; empty: all
    std::vector<std::string> colours;               // per channel, e.g. "green", "#ff8800"
    std::vector<std::string> isosurfaces;           // "AF594" (at the channel's level) or "AF594=2.5"
    ViewPreset view = ViewPreset::Overview;
    std::optional<int> plane;                       // 0-based; default the middle plane
    BlendMode blend = BlendMode::Mip;
    MapperChoice mapper = MapperChoice::Auto;
    Region region = Region::All;
    size_t maxVoxels = size_t(1) << 24;             // display volume budget (256³)
    int width = 1280, height = 800;
    std::optional<int> band;                        // EXR band (0-based); default the sRGB composite
    std::optional<std::filesystem::path> screenshot;  // batch: write this PNG and return
    std::optional<std::filesystem::path> movie;       // batch: .ogv, or a folder for PNG frames
    MovieKind movieKind = MovieKind::ZSweep;
    int movieFrames = 0;                            // 0: every plane (z-sweep) or 72 (orbit)
    std::filesystem::path screenshotFolder = ".";   // where the S key writes
    bool showMicroscope = true, showNeurons = true;
    bool offscreen = false;                         // no window on the screen (batch mode, tests)

    void validate() const;  // ConfigError naming the option
};

// What lies under a display position.
struct Readout {
    bool valid = false;
    std::string view;                 // "xy", "3d", "compare", ...
    Vec3 positionUm;
    std::array<int, 3> voxel{};       // full-resolution grid index (specimen views)
    bool insideGrid = false;
    std::array<int, 2> pixel{};       // detector or EXR pixel (image views)
    int plane = 0;
    std::vector<std::string> names;   // per value
    std::vector<double> values;
    std::vector<std::string> units;
    std::string text() const;         // one line, as the viewer shows it
};

struct ChannelState {
    std::string name;
    std::array<double, 3> colour{};
    bool visible = true;
    double low = 0, high = 1;         // window in the channel's units
    std::string units;
};

// One rendered frame as 8-bit RGB, rows from the bottom.
struct FrameImage {
    int width = 0, height = 0;
    std::vector<uint8_t> rgb;
    std::array<uint8_t, 3> at(int x, int y) const {
        const size_t i = (size_t(y) * size_t(width) + size_t(x)) * 3;
        return {rgb[i], rgb[i + 1], rgb[i + 2]};
    }
};

// The viewer as an object, for the CLI, tests and benchmarks. Loading happens in the constructor;
// the window is created there too (after the display check).
class Viewer {
public:
    explicit Viewer(const ViewerOptions& options);
    ~Viewer();
    Viewer(const Viewer&) = delete;
    Viewer& operator=(const Viewer&) = delete;

    void render();                       // one full-quality frame
    void renderInteractive();            // one frame at the interactive rate, as while the 3D view is dragged
    FrameImage capture();                // the last frame
    void saveScreenshot(const std::filesystem::path& png);
    void writeMovie(const std::filesystem::path& out, MovieKind kind, int frames);
    void interact();                     // the event loop, until the window closes or Q

    // State, as the keys change it.
    int planeCount() const;
    int plane() const;
    void setPlane(int plane);            // clamped
    void stepPlane(int delta);           // a z step: redraws the slices now, the 3D view when idle
    const std::vector<ChannelState>& channels() const;
    void setChannelVisible(int channel, bool visible);
    void soloChannel(int channel);
    void setWindow(int channel, double low, double high);
    void autoContrast(int channel);
    int activeChannel() const;
    BlendMode blendMode() const;
    void setBlendMode(BlendMode mode);
    ViewPreset view() const;
    void setView(ViewPreset view);
    void resetCameras();
    void orbit(double degrees);          // turns the 3D camera about its view-up axis
    std::string mapperName() const;      // "cpu" or "gpu", as chosen

    // Display position (pixels from the bottom-left) of a world point in a view; nullopt when the
    // view is not shown or the point is outside it.
    std::optional<std::array<double, 2>> displayPosition(ViewPreset view, const Vec3& worldUm);
    Readout pick(int x, int y);
    // Plays a vtkInteractorEventRecorder log ("# StreamVersion 1.1" lines) through the key bindings.
    void playEvents(const std::string& log);
    std::string helpText() const;
    // What the viewer does not show (e.g. grids beyond the fourth, --fit), for the CLI to print.
    const std::vector<std::string>& warnings() const;

    struct Impl;

private:
    std::unique_ptr<Impl> impl_;
};

// The command: a screenshot or movie in batch mode, else the interactive window. Warnings about what
// is not shown go to `warn`.
void runViewer(const ViewerOptions& options, const std::function<void(const std::string&)>& warn);

// Throws DisplayError when no X display can be opened (DISPLAY unset or wrong, no GLX).
void requireDisplay();

}  // namespace fluorosim::viewer
