// The viewer's data and its public API: loading the scene, specimen, stack and EXR image, the
// channels' state, layouts, rendering, screenshots and movies. The VTK scene is built in
// viewer_scene.cpp and the key bindings live in viewer_interaction.cpp.
#include <vtkCamera.h>
#include <vtkImageData.h>
#include <vtkOggTheoraWriter.h>
#include <vtkPointData.h>
#include <vtkUnsignedCharArray.h>
#include <vtkWindowToImageFilter.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <sstream>

#include "optics/scene_files.h"
#include "viewer/image_compare.h"
#include "viewer/viewer_impl.h"

namespace fluorosim::viewer {
namespace fs = std::filesystem;
namespace {

constexpr std::pair<ViewPreset, const char*> kViewNames[] = {
    {ViewPreset::Overview, "overview"}, {ViewPreset::ThreeD, "3d"},     {ViewPreset::Top, "top"},
    {ViewPreset::Front, "front"},       {ViewPreset::Side, "side"},     {ViewPreset::SliceXy, "xy"},
    {ViewPreset::SliceXz, "xz"},        {ViewPreset::SliceYz, "yz"},    {ViewPreset::Compare, "compare"},
    {ViewPreset::Exr, "exr"},
};

std::string formatValue(double v) {
    char buf[32];
    std::snprintf(buf, sizeof buf, "%.4g", v);
    return buf;
}

// Which channels `--channels` shows: names or 1-based numbers. A name may name a dye (specimen
// channel), a channel of the stack, or both; one that names neither is an error.
std::vector<bool> selectChannels(const std::vector<std::string>& selection, const std::vector<ChannelState>& channels) {
    if (selection.empty()) return std::vector<bool>(channels.size(), true);
    std::vector<bool> on(channels.size(), false);
    for (const std::string& s : selection)
        for (size_t c = 0; c < channels.size(); ++c)
            if (channels[c].name == s || std::to_string(c + 1) == s) on[c] = true;
    return on;
}

void checkChannelSelection(const std::vector<std::string>& selection, const std::vector<ChannelState>& specimen,
                           const std::vector<ChannelState>& stack) {
    for (const std::string& s : selection) {
        bool found = false;
        for (const auto* list : {&specimen, &stack})
            for (size_t c = 0; c < list->size(); ++c) found = found || (*list)[c].name == s || std::to_string(c + 1) == s;
        if (found) continue;
        std::vector<std::string> listed;
        std::string names;
        for (const auto* list : {&specimen, &stack})
            for (const ChannelState& ch : *list)
                if (std::find(listed.begin(), listed.end(), ch.name) == listed.end()) listed.push_back(ch.name);
        for (const std::string& n : listed) names += (names.empty() ? "" : ", ") + n;
        throw ConfigError("--channels: no channel \"" + s + "\" (channels: " + (names.empty() ? "none" : names) + ")");
    }
}

// The first shown channel (0 when none is).
int firstVisible(const std::vector<ChannelState>& channels) {
    for (size_t c = 0; c < channels.size(); ++c)
        if (channels[c].visible) return static_cast<int>(c);
    return 0;
}

}  // namespace

std::optional<ViewPreset> viewPresetFromName(const std::string& name) {
    for (const auto& [v, n] : kViewNames)
        if (name == n) return v;
    return std::nullopt;
}

const char* viewPresetName(ViewPreset view) {
    for (const auto& [v, n] : kViewNames)
        if (view == v) return n;
    return "?";
}

std::vector<std::string> viewPresetNames() {
    std::vector<std::string> names;
    for (const auto& [v, n] : kViewNames) names.push_back(n);
    return names;
}

void ViewerOptions::validate() const {
    if (scene.empty() && !exr) throw ConfigError("give a scene file, or --exr IMAGE.exr");
    if (width < 64 || height < 64 || width > 8192 || height > 8192)
        throw ConfigError("--size: width and height must lie in [64, 8192], got " + std::to_string(width) + "x" + std::to_string(height));
    if (plane && *plane < 0) throw ConfigError("--plane: must be >= 0, got " + std::to_string(*plane));
    if (maxVoxels < 1000) throw ConfigError("--max-voxels: must be at least 1000, got " + std::to_string(maxVoxels));
    if (movieFrames < 0 || movieFrames > 10000) throw ConfigError("--frames: must lie in [0, 10000], got " + std::to_string(movieFrames));
    if (stack && scene.empty()) throw ConfigError("--stack: needs the scene the stack was acquired from");
    if (view == ViewPreset::Compare && !stack) throw ConfigError("--view compare: needs --stack STACK.ome.tif");
    if (view == ViewPreset::Exr && !exr) throw ConfigError("--view exr: needs --exr IMAGE.exr");
    if (band && !exr) throw ConfigError("--band: needs --exr IMAGE.exr");
    if (scene.empty() && view != ViewPreset::Exr && view != ViewPreset::Overview)
        throw ConfigError("--view " + std::string(viewPresetName(view)) + ": needs a scene file");
}

std::string Readout::text() const {
    if (!valid) return "";
    std::ostringstream s;
    s << view << "  ";
    if (view == "compare" || view == "exr") {
        s << "pixel (" << pixel[0] << ", " << pixel[1] << ")";
        if (view == "compare") s << " plane " << plane;
    } else {
        char buf[96];
        std::snprintf(buf, sizeof buf, "x %.2f  y %.2f  z %.2f \xC2\xB5m", positionUm.x, positionUm.y, positionUm.z);
        s << buf;
        if (insideGrid) s << "  voxel (" << voxel[0] << ", " << voxel[1] << ", " << voxel[2] << ")";
    }
    for (size_t i = 0; i < values.size(); ++i) s << "  " << names[i] << " " << formatValue(values[i]) << (units[i].empty() ? "" : " " + units[i]);
    return s.str();
}

Viewer::Impl::Impl(const ViewerOptions& o) : options(o), cmf(db.cie1931()) {
    blend = options.blend;
    view = options.view;
    showMicroscope = options.showMicroscope;
    showNeurons = options.showNeurons;
    loadData();
    initChannels();
    if (view == ViewPreset::Overview && !scene && exr) view = ViewPreset::Exr;
    if (view == ViewPreset::Overview && !volume && !exr) view = ViewPreset::ThreeD;
    if (view == ViewPreset::Overview && !options.scene.empty() && !volume && exr) view = ViewPreset::Exr;
}

Viewer::Impl::~Impl() = default;

void Viewer::Impl::loadData() {
    if (!options.scene.empty()) {
        scene.emplace(optics::loadSceneFile(options.scene, db));
        for (const std::string& w : scene->warnings) warnings.push_back(w);
        if (scene->microscope) microscope.emplace(optics::Microscope::fromScene(*scene, db));
        specimen = loadSpecimen(*scene, options.scene, {options.swc, options.findSwc});
        for (const std::string& n : specimen.notes) warnings.push_back(n);
        DisplayVolumeOptions vo;
        vo.maxVoxels = options.maxVoxels;
        if (microscope) overlay.emplace(*scene, *microscope, microscope->stack.planes, microscope->stack.stepMm * kUmPerMm);
        if (options.region == Region::FieldOfView) {
            if (!overlay) throw ConfigError("--region fov: the scene has no microscope block");
            // The field of view of the first and the last plane, with half a field of margin in z.
            std::array<Vec3, 2> box{overlay->fieldOfView(0).cornersUm[0], overlay->fieldOfView(0).cornersUm[0]};
            for (int k : {0, overlay->planes() - 1})
                for (const Vec3& p : overlay->fieldOfView(k).cornersUm)
                    for (int a = 0; a < 3; ++a) box[0][a] = std::min(box[0][a], p[a]), box[1][a] = std::max(box[1][a], p[a]);
            vo.regionUm = box;
        }
        volume = makeDisplayVolume(specimen, vo);
        size_t grids = 0;
        for (const DyeChannel& c : specimen.channels) grids += c.grid ? 1 : 0;
        if (volume && grids > size_t(volume->components()))
            warnings.push_back("only the first " + std::to_string(volume->components()) + " dye grids are rendered as volumes");
    }
    if (options.stack) {
        if (!microscope) throw ConfigError("--stack: the scene " + options.scene.string() + " has no microscope block to place the stack");
        stack.emplace(loadStackComparison(*options.stack, *scene, *microscope, specimen));
        // The stack's own z geometry places its planes.
        overlay.emplace(*scene, *microscope, stack->info.planes, stack->info.zStepUm);
    }
    if (options.fit)
        warnings.push_back("--fit " + options.fit->string() +
                           ": fitted concentrations are not available yet (the inverse problem has not landed); "
                           "the viewer shows the true ones");
    if (options.exr) {
        exr.emplace(loadSpectralImage(*options.exr));
        exrBand = options.band.value_or(-1);
        const auto bands = static_cast<int>(exr->layers[0].bands.size());
        if (options.band && *options.band >= bands)
            throw ConfigError("--band: the image has " + std::to_string(bands) + " bands (0 to " + std::to_string(bands - 1) + "), got " +
                              std::to_string(*options.band));
        exrExposure = autoExposure(*exr, exrLayer, exrBand);
    }
}

void Viewer::Impl::initChannels() {
    for (size_t c = 0; c < specimen.channels.size(); ++c) {
        ChannelState s;
        s.name = specimen.channels[c].name;
        s.units = specimen.channels[c].units;
        s.colour = c < options.colours.size() ? parseColour(options.colours[c], "--colors") : defaultChannelColour(static_cast<int>(c));
        s.low = 0;
        s.high = 1;
        specimenChannels.push_back(s);
    }
    if (options.colours.size() > specimenChannels.size() && !specimenChannels.empty())
        throw ConfigError("--colors: " + std::to_string(options.colours.size()) + " colours for " + std::to_string(specimenChannels.size()) +
                          " channels");
    const std::vector<bool> on = selectChannels(options.channels, specimenChannels);
    for (size_t c = 0; c < specimenChannels.size(); ++c) specimenChannels[c].visible = on[c];
    activeSpecimenChannel = firstVisible(specimenChannels);
    if (volume)
        for (int k = 0; k < volume->components(); ++k) {
            // Auto contrast: black at 0, white at the 99.5th percentile of the non-zero voxels.
            const auto c = size_t(volume->channels[size_t(k)]);
            const double high = nonZeroPercentile(*volume, k, 99.5) * volume->unitPerCount[size_t(k)];
            specimenChannels[c].high = high > 0 ? high : 1;
        }
    isosurfaceOn.assign(specimenChannels.size(), false);
    isosurfaceLevel.assign(specimenChannels.size(), 0);
    for (const std::string& iso : options.isosurfaces) {
        const size_t eq = iso.find('=');
        const std::string name = iso.substr(0, eq);
        int channel = -1;
        for (size_t c = 0; c < specimenChannels.size(); ++c)
            if (specimenChannels[c].name == name || std::to_string(c + 1) == name) channel = static_cast<int>(c);
        if (channel < 0 || !specimen.channels[size_t(channel)].grid)
            throw ConfigError("--iso: no dye grid \"" + name + "\" in the scene");
        isosurfaceOn[size_t(channel)] = true;
        isosurfaceLevel[size_t(channel)] = specimenChannels[size_t(channel)].high * 0.5;
        if (eq != std::string::npos) {
            try {
                isosurfaceLevel[size_t(channel)] = std::stod(iso.substr(eq + 1));
            } catch (const std::exception&) {
                throw ConfigError("--iso: expected NAME=VALUE with a number, got \"" + iso + "\"");
            }
        }
    }
    if (stack)
        for (size_t c = 0; c < stack->channels.size(); ++c) {
            const ChannelComparison& cc = stack->channels[c];
            ChannelState s;
            s.name = cc.name;
            s.units = stack->valueUnit();
            s.colour = cc.truthChannel >= 0 ? specimenChannels[size_t(cc.truthChannel)].colour : defaultChannelColour(static_cast<int>(c));
            std::vector<float> sorted = cc.simulated;
            std::sort(sorted.begin(), sorted.end());
            s.low = sorted.empty() ? 0 : sorted[sorted.size() / 100];
            s.high = sorted.empty() ? 1 : sorted[std::min(sorted.size() - 1, sorted.size() * 995 / 1000)];
            if (s.high <= s.low) s.high = s.low + 1;
            stackChannels.push_back(s);
        }
    // --channels applies to the stack's channels too (by their names or numbers).
    const std::vector<bool> stackOn = selectChannels(options.channels, stackChannels);
    for (size_t c = 0; c < stackChannels.size(); ++c) stackChannels[c].visible = stackOn[c];
    activeStackChannel = firstVisible(stackChannels);
    checkChannelSelection(options.channels, specimenChannels, stackChannels);
    plane = std::clamp(options.plane.value_or(planeCount() / 2), 0, std::max(0, planeCount() - 1));
    if (options.plane && *options.plane >= planeCount())
        throw ConfigError("--plane: the scene has " + std::to_string(planeCount()) + " planes (0 to " + std::to_string(planeCount() - 1) +
                          "), got " + std::to_string(*options.plane));
    if (volume) crosshairUm = volume->centreUm(0.5 * (volume->dims[0] - 1), 0.5 * (volume->dims[1] - 1), 0.5 * (volume->dims[2] - 1));
    if (overlay) crosshairUm = overlay->fieldOfView(plane).centreUm;
}

int Viewer::Impl::planeCount() const {
    if (overlay) return overlay->planes();
    if (volume) return volume->dims[2];
    return 1;
}

double Viewer::Impl::planeZUm(int k) const {
    if (overlay) return overlay->fieldOfView(k).centreUm.z;
    if (volume) return volume->centreUm(0, 0, k).z;
    return 0;
}

std::vector<ChannelState>& Viewer::Impl::currentChannels() { return inCompare() ? stackChannels : specimenChannels; }
int& Viewer::Impl::activeChannel() { return inCompare() ? activeStackChannel : activeSpecimenChannel; }

void Viewer::Impl::setPlane(int k) {
    plane = std::clamp(k, 0, std::max(0, planeCount() - 1));
    crosshairUm.z = planeZUm(plane);
    updateSlices();
    updateCompare();
    updateMicroscope();
    updateCrosshairs();
    updateStatus();
    if (slider.track) updateSlider();
}

void Viewer::Impl::stepPlane(int delta) {
    setPlane(plane + delta);
    lastStep = std::chrono::steady_clock::now();
    renderFast();
}

void Viewer::Impl::renderAll() {
    threeDStale = false;
    window->Render();
}

void Viewer::Impl::renderFast() {
    // The 3D view keeps the pixels of its last frame (VTK renders into its own framebuffer, which a
    // renderer that does not draw leaves alone); onTimer() redraws it once the steps stop.
    const bool threeDShown = threeD.renderer->GetDraw() && window->HasRenderer(threeD.renderer);
    if (threeDShown) {
        threeD.renderer->DrawOff();
        threeDStale = true;
    }
    window->Render();
    if (threeDShown) threeD.renderer->DrawOn();
}

FrameImage Viewer::Impl::capture() {
    vtkNew<vtkWindowToImageFilter> grab;
    grab->SetInput(window);
    grab->SetInputBufferTypeToRGB();
    grab->ReadFrontBufferOff();
    grab->ShouldRerenderOff();
    grab->Update();
    vtkImageData* img = grab->GetOutput();
    int dims[3];
    img->GetDimensions(dims);
    FrameImage f;
    f.width = dims[0];
    f.height = dims[1];
    auto* data = static_cast<const uint8_t*>(img->GetScalarPointer());
    f.rgb.assign(data, data + size_t(f.width) * f.height * 3);
    return f;
}

void Viewer::Impl::writeScreenshot(const fs::path& png) { writePng(capture(), png); }

void Viewer::Impl::writeMovie(const fs::path& out, MovieKind kind, int frames) {
    if (frames <= 0) frames = kind == MovieKind::ZSweep ? planeCount() : 72;
    const bool ogv = out.extension() == ".ogv";
    if (!ogv) {
        std::error_code ec;
        fs::create_directories(out, ec);
        if (!fs::is_directory(out)) throw IoError(out.string() + ": cannot create the folder for the movie's frames");
    }
    vtkNew<vtkWindowToImageFilter> grab;
    grab->SetInput(window);
    grab->SetInputBufferTypeToRGB();
    grab->ReadFrontBufferOff();
    grab->ShouldRerenderOff();
    vtkNew<vtkOggTheoraWriter> theora;
    if (ogv) {
        theora->SetInputConnection(grab->GetOutputPort());
        theora->SetFileName(out.string().c_str());
        theora->SetRate(kind == MovieKind::ZSweep ? 8 : 24);
        theora->SetQuality(2);
        theora->Start();
    }
    const int startPlane = plane;
    for (int i = 0; i < frames; ++i) {
        if (kind == MovieKind::ZSweep) setPlane(frames > 1 ? i * (planeCount() - 1) / (frames - 1) : plane);
        else if (i > 0) threeD.renderer->GetActiveCamera()->Azimuth(360.0 / frames);
        renderAll();
        grab->Modified();
        if (ogv) {
            theora->Write();
        } else {
            char name[32];
            std::snprintf(name, sizeof name, "frame_%04d.png", i);
            writePng(capture(), out / name);
        }
    }
    if (ogv) {
        theora->End();
        if (theora->GetError() || !fs::exists(out)) throw IoError(out.string() + ": cannot write the movie");
    }
    if (kind == MovieKind::Orbit) threeD.renderer->GetActiveCamera()->Azimuth(frames > 1 ? 360.0 / frames : 0);
    if (kind == MovieKind::ZSweep) setPlane(startPlane);
}

// --- the public API -------------------------------------------------------------------------

Viewer::Viewer(const ViewerOptions& options) {
    options.validate();
    requireDisplay();
    impl_ = std::make_unique<Impl>(options);
    impl_->createWindow();
}

Viewer::~Viewer() = default;

void Viewer::render() { impl_->renderAll(); }
void Viewer::renderInteractive() {
    // What vtkInteractorStyle does while a drag lasts: the window asks for the interactor's desired
    // rate (15 frames per second), and the volume mappers coarsen their sampling to meet it.
    impl_->window->SetDesiredUpdateRate(impl_->interactor->GetDesiredUpdateRate());
    impl_->renderAll();
    impl_->window->SetDesiredUpdateRate(impl_->interactor->GetStillUpdateRate());
}
FrameImage Viewer::capture() { return impl_->capture(); }
void Viewer::saveScreenshot(const fs::path& png) { impl_->writeScreenshot(png); }
void Viewer::writeMovie(const fs::path& out, MovieKind kind, int frames) { impl_->writeMovie(out, kind, frames); }
void Viewer::interact() {
    impl_->renderAll();
    impl_->interactor->Start();
}
int Viewer::planeCount() const { return impl_->planeCount(); }
int Viewer::plane() const { return impl_->plane; }
void Viewer::setPlane(int plane) { impl_->setPlane(plane); }
void Viewer::stepPlane(int delta) { impl_->stepPlane(delta); }
const std::vector<ChannelState>& Viewer::channels() const { return impl_->currentChannels(); }
int Viewer::activeChannel() const { return impl_->activeChannel(); }
BlendMode Viewer::blendMode() const { return impl_->blend; }
ViewPreset Viewer::view() const { return impl_->view; }
std::string Viewer::mapperName() const { return impl_->useGpuMapper ? "gpu" : "cpu"; }
Readout Viewer::pick(int x, int y) { return impl_->pick(x, y); }
std::string Viewer::helpText() const { return impl_->helpString(); }
void Viewer::playEvents(const std::string& log) { impl_->playEvents(log); }
void Viewer::resetCameras() { impl_->resetCameras(); }

void Viewer::setChannelVisible(int channel, bool visible) {
    auto& chs = impl_->currentChannels();
    chs.at(size_t(channel)).visible = visible;
    impl_->updateVisibility();
}

void Viewer::soloChannel(int channel) {
    auto& chs = impl_->currentChannels();
    for (size_t c = 0; c < chs.size(); ++c) chs[c].visible = static_cast<int>(c) == channel;
    impl_->activeChannel() = channel;
    impl_->updateVisibility();
}

void Viewer::setWindow(int channel, double low, double high) {
    auto& ch = impl_->currentChannels().at(size_t(channel));
    ch.low = low;
    ch.high = high;
    impl_->updateVisibility();
}

void Viewer::autoContrast(int channel) {
    impl_->activeChannel() = channel;
    impl_->onKey("a", false);
}

void Viewer::setBlendMode(BlendMode mode) {
    impl_->blend = mode;
    impl_->updateVolumeProperty();
    impl_->updateStatus();
}

void Viewer::setView(ViewPreset view) {
    if (view == ViewPreset::Compare && !impl_->stack) throw ConfigError("the compare view needs a stack (--stack)");
    if (view == ViewPreset::Exr && !impl_->exr) throw ConfigError("the EXR view needs an image (--exr)");
    impl_->view = view;
    impl_->layout();
}

void Viewer::orbit(double degrees) { impl_->threeD.renderer->GetActiveCamera()->Azimuth(degrees); }

std::optional<std::array<double, 2>> Viewer::displayPosition(ViewPreset view, const Vec3& worldUm) {
    View* v = nullptr;
    for (View* s : impl_->shownViews())
        if (!v && s->kind == view) v = s;  // the first of the compare panels: the simulated image
    if (!v) return std::nullopt;
    vtkRenderer* r = v->renderer;
    r->SetWorldPoint(worldUm.x, worldUm.y, worldUm.z, 1.0);
    r->WorldToDisplay();
    double d[3];
    r->GetDisplayPoint(d);
    if (!r->IsInViewport(static_cast<int>(d[0]), static_cast<int>(d[1]))) return std::nullopt;
    return std::array<double, 2>{d[0], d[1]};
}

const std::vector<std::string>& Viewer::warnings() const { return impl_->warnings; }

void runViewer(const ViewerOptions& options, const std::function<void(const std::string&)>& warn) {
    Viewer viewer(options);
    for (const std::string& w : viewer.warnings()) warn(w);
    if (options.screenshot) {
        viewer.render();
        viewer.saveScreenshot(*options.screenshot);
    }
    if (options.movie) viewer.writeMovie(*options.movie, options.movieKind, options.movieFrames);
    if (!options.screenshot && !options.movie) viewer.interact();
}

}  // namespace fluorosim::viewer
