// The viewer's key and mouse bindings (key_bindings.cpp lists them), picking and the readout, event
// playback for tests, and the idle redraw of the 3D view after z steps.
#include <vtkCallbackCommand.h>
#include <vtkCamera.h>
#include <vtkInteractorEventRecorder.h>
#include <vtkInteractorStyleTrackballCamera.h>
#include <vtkObjectFactory.h>
#include <vtkVolumePicker.h>

#include <algorithm>
#include <cmath>
#include <sstream>

#include "viewer/key_bindings.h"
#include "viewer/viewer_impl.h"

namespace fluorosim::viewer {
namespace fs = std::filesystem;
namespace {

// Trackball rotation in the 3D view; everything else goes to the viewer. VTK's own key bindings
// (w, s, e, q, 3, f, p, j, t, u, r) are off: OnChar does nothing.
class ViewerStyle : public vtkInteractorStyleTrackballCamera {
public:
    static ViewerStyle* New();
    vtkTypeMacro(ViewerStyle, vtkInteractorStyleTrackballCamera)
    Viewer::Impl* viewer = nullptr;

    void OnChar() override {}
    void OnKeyPress() override {
        vtkRenderWindowInteractor* rwi = this->Interactor;
        viewer->onKey(rwi->GetKeySym() ? rwi->GetKeySym() : "", rwi->GetShiftKey());
    }
    void OnKeyRelease() override {}

    void OnLeftButtonDown() override {
        const int* p = this->Interactor->GetEventPosition();
        if (viewer->onSlider(p[0], p[1])) {
            sliding_ = true;
            viewer->dragSlider(p[0]);
            return;
        }
        this->FindPokedRenderer(p[0], p[1]);
        downX_ = p[0], downY_ = p[1];
        if (!this->CurrentRenderer) return;
        View* v = viewer->viewAt(p[0], p[1]);
        if (v && v->kind == ViewPreset::ThreeD) this->Superclass::OnLeftButtonDown();
        else this->StartPan();
    }
    void OnLeftButtonUp() override {
        const int* p = this->Interactor->GetEventPosition();
        if (sliding_) {
            sliding_ = false;
            viewer->renderAll();
            return;
        }
        const bool click = std::abs(p[0] - downX_) <= 2 && std::abs(p[1] - downY_) <= 2;
        if (this->State == VTKIS_PAN) this->EndPan();
        else this->Superclass::OnLeftButtonUp();
        if (click) viewer->onLeftClick(p[0], p[1]);
    }
    void OnRightButtonDown() override {
        const int* p = this->Interactor->GetEventPosition();
        this->FindPokedRenderer(p[0], p[1]);
        windowLevel_ = true;
        dragX_ = p[0], dragY_ = p[1];
        viewer->startWindowLevelDrag();
        // Interactive quality while dragging, as VTK's own interactions do.
        this->Interactor->GetRenderWindow()->SetDesiredUpdateRate(this->Interactor->GetDesiredUpdateRate());
    }
    void OnRightButtonUp() override {
        windowLevel_ = false;
        this->Interactor->GetRenderWindow()->SetDesiredUpdateRate(this->Interactor->GetStillUpdateRate());
        viewer->renderAll();
    }
    void OnMouseMove() override {
        const int* p = this->Interactor->GetEventPosition();
        if (sliding_) {
            viewer->dragSlider(p[0]);
            return;
        }
        if (windowLevel_) {
            viewer->onWindowLevelDrag(p[0] - dragX_, p[1] - dragY_);
            return;
        }
        if (this->State != VTKIS_NONE) {
            this->Superclass::OnMouseMove();
            return;
        }
        viewer->onMouseMove(p[0], p[1]);
    }
    void OnMouseWheelForward() override { wheel(1); }
    void OnMouseWheelBackward() override { wheel(-1); }

private:
    void wheel(int direction) {
        const int* p = this->Interactor->GetEventPosition();
        this->FindPokedRenderer(p[0], p[1]);
        View* v = viewer->viewAt(p[0], p[1]);
        if (v && v->kind == ViewPreset::ThreeD) {
            if (direction > 0) this->Superclass::OnMouseWheelForward();
            else this->Superclass::OnMouseWheelBackward();
            return;
        }
        viewer->onWheel(direction, this->CurrentRenderer, this->Interactor->GetControlKey());
    }
    int downX_ = 0, downY_ = 0, dragX_ = 0, dragY_ = 0;
    bool windowLevel_ = false, sliding_ = false;
};
vtkStandardNewMacro(ViewerStyle);

// Shift+1..9 as the keyboard sends them.
const char* const kShiftedDigits[] = {"exclam", "at", "numbersign", "dollar", "percent", "asciicircum", "ampersand", "asterisk", "parenleft"};

fs::path nextFreePath(const fs::path& folder, const std::string& stem, const std::string& extension, int& counter) {
    fs::path p;
    do p = folder / (stem + std::to_string(++counter) + extension);
    while (fs::exists(p));
    return p;
}

}  // namespace

void Viewer::Impl::installInteraction() {
    vtkNew<ViewerStyle> style;
    style->viewer = this;
    interactor->SetInteractorStyle(style);
    vtkNew<vtkCallbackCommand> timer;
    timer->SetClientData(this);
    timer->SetCallback([](vtkObject*, unsigned long, void* self, void*) { static_cast<Viewer::Impl*>(self)->onTimer(); });
    interactor->AddObserver(vtkCommand::TimerEvent, timer);
}

void Viewer::Impl::onTimer() {
    using namespace std::chrono;
    if (threeDStale && steady_clock::now() - lastStep > milliseconds(250)) renderAll();
}

View* Viewer::Impl::viewAt(int x, int y) {
    for (View* v : shownViews())
        if (v->renderer->IsInViewport(x, y)) return v;
    return nullptr;
}

void Viewer::Impl::renderStatusOnly() {
    // Only the status bar changes: the views keep their pixels (see renderFast).
    std::vector<vtkRenderer*> drawn;
    for (View* v : shownViews())
        if (v->renderer->GetDraw()) v->renderer->DrawOff(), drawn.push_back(v->renderer);
    window->Render();
    for (vtkRenderer* r : drawn) r->DrawOn();
}

void Viewer::Impl::onMouseMove(int x, int y) {
    const Readout r = pick(x, y);
    readoutText->SetInput(r.valid ? r.text().c_str() : "");
    renderStatusOnly();
}

Readout Viewer::Impl::pick(int x, int y) {
    View* v = viewAt(x, y);
    if (!v) return {};
    switch (v->kind) {
    case ViewPreset::SliceXy:
    case ViewPreset::SliceXz:
    case ViewPreset::SliceYz: return pickSlice(*v, x, y);
    case ViewPreset::Compare: return pickCompare(*v, x, y);
    case ViewPreset::Exr: return pickExr(x, y);
    default: return pickThreeD(x, y);
    }
}

static Vec3 displayToWorld(vtkRenderer* r, int x, int y) {
    r->SetDisplayPoint(x, y, 0);
    r->DisplayToWorld();
    double w[4];
    r->GetWorldPoint(w);
    return w[3] != 0 ? Vec3(w[0] / w[3], w[1] / w[3], w[2] / w[3]) : Vec3(w[0], w[1], w[2]);
}

static void addSpecimenValues(Readout& r, const Specimen& specimen, const std::vector<ChannelState>& channels, const VoxelProbe& probe) {
    r.voxel = probe.index;
    r.insideGrid = probe.insideGrid;
    for (size_t c = 0; c < specimen.channels.size(); ++c) {
        if (!specimen.channels[c].grid) continue;
        r.names.push_back(channels[c].name);
        r.values.push_back(probe.values[c]);
        r.units.push_back(channels[c].units);
    }
}

Readout Viewer::Impl::pickSlice(View& v, int x, int y) {
    Readout r;
    r.valid = true;
    r.view = v.kind == ViewPreset::SliceXy ? "xy" : v.kind == ViewPreset::SliceXz ? "xz" : "yz";
    Vec3 p = displayToWorld(v.renderer, x, y);
    // The parallel camera looks along the slice normal: the in-plane coordinates are exact.
    const Vec3 at(crosshairUm.x, crosshairUm.y, planeZUm(plane));
    p[v.normalAxis] = at[v.normalAxis];
    r.positionUm = p;
    r.plane = plane;
    addSpecimenValues(r, specimen, specimenChannels, probeVoxel(specimen, p));
    return r;
}

Readout Viewer::Impl::pickThreeD(int x, int y) {
    Readout r;
    r.view = "3d";
    vtkNew<vtkVolumePicker> picker;
    picker->SetTolerance(0.002);
    picker->SetVolumeOpacityIsovalue(0.1);
    picker->PickFromListOn();
    if (volumeProp && volumeProp->GetVisibility()) picker->AddPickList(volumeProp);
    for (auto& [channel, actor] : neuronActors)
        if (actor->GetVisibility()) picker->AddPickList(actor);
    for (auto& [channel, actor] : shapeActors)
        if (actor->GetVisibility()) picker->AddPickList(actor);
    if (!picker->Pick(x, y, 0, threeD.renderer)) return r;
    double p[3];
    picker->GetPickPosition(p);
    r.valid = true;
    r.positionUm = Vec3(p[0], p[1], p[2]);
    addSpecimenValues(r, specimen, specimenChannels, probeVoxel(specimen, r.positionUm));
    return r;
}

Readout Viewer::Impl::pickCompare(View& v, int x, int y) {
    Readout r;
    const Vec3 p = displayToWorld(v.renderer, x, y);
    const double pix = stack->info.pixelSizeUm;
    const int col = static_cast<int>(std::floor(p.x / pix)), fromBottom = static_cast<int>(std::floor(p.y / pix));
    const int row = stack->info.height - 1 - fromBottom;
    if (col < 0 || row < 0 || col >= stack->info.width || row >= stack->info.height) return r;
    r.valid = true;
    r.view = "compare";
    r.pixel = {col, row};
    r.plane = plane;
    const size_t i = stack->planeOffset(plane) + size_t(row) * stack->info.width + size_t(col);
    for (const ChannelComparison& cc : stack->channels) {
        const std::string truthUnits = cc.truthChannel >= 0 ? specimenChannels[size_t(cc.truthChannel)].units : "";
        r.names.insert(r.names.end(), {cc.name + " simulated", cc.name + " truth", cc.name + " residual"});
        r.values.insert(r.values.end(), {cc.simulated[i], cc.truth[i], cc.residual[i]});
        r.units.insert(r.units.end(), {stack->valueUnit(), truthUnits, stack->valueUnit()});
    }
    return r;
}

Readout Viewer::Impl::pickExr(int x, int y) {
    Readout r;
    const Vec3 p = displayToWorld(exrView.renderer, x, y);
    const int col = static_cast<int>(std::floor(p.x)), row = exr->height - 1 - static_cast<int>(std::floor(p.y));
    if (col < 0 || row < 0 || col >= exr->width || row >= exr->height) return r;
    r.valid = true;
    r.view = "exr";
    r.pixel = {col, row};
    const SpectralLayerImage& layer = exr->layers[exrLayer];
    const size_t i = size_t(row) * exr->width + size_t(col);
    if (!layer.rgb.empty())
        for (int c = 0; c < 3; ++c) r.names.push_back(std::string(1, "RGB"[c])), r.values.push_back(layer.rgb[i * 3 + size_t(c)]), r.units.push_back("");
    if (exrBand >= 0) {
        char name[32];
        std::snprintf(name, sizeof name, "%.1f nm", layer.bands[size_t(exrBand)].lambdaNm);
        r.names.push_back(name);
        r.values.push_back(layer.bands[size_t(exrBand)].values[i]);
        r.units.push_back("");
    }
    return r;
}

void Viewer::Impl::onLeftClick(int x, int y) {
    View* v = viewAt(x, y);
    if (!v || (v->kind != ViewPreset::SliceXy && v->kind != ViewPreset::SliceXz && v->kind != ViewPreset::SliceYz)) return;
    const Vec3 p = displayToWorld(v->renderer, x, y);
    for (int a = 0; a < 2; ++a)
        if (a != v->normalAxis) crosshairUm[a] = p[a];
    if (v->normalAxis != 2) {
        // The nearest plane to the clicked depth.
        int best = plane;
        for (int k = 0; k < planeCount(); ++k)
            if (std::abs(planeZUm(k) - p.z) < std::abs(planeZUm(best) - p.z)) best = k;
        plane = best;
    }
    setPlane(plane);
    renderAll();
}

void Viewer::Impl::onWheel(int direction, vtkRenderer* renderer, bool control) {
    View* v = nullptr;
    for (View* s : shownViews())
        if (s->renderer == renderer) v = s;
    if (!v) return;
    if (control) {
        renderer->GetActiveCamera()->Zoom(direction > 0 ? 1.1 : 1 / 1.1);
        renderAll();
        return;
    }
    if (v->kind == ViewPreset::SliceXz || v->kind == ViewPreset::SliceYz) {
        // The wheel moves this slice through the volume, one display voxel at a time.
        const int axis = v->normalAxis;
        crosshairUm[axis] += direction * volume->spacingUm[size_t(axis)];
        updateSlices();
        renderFast();
        return;
    }
    onKey(direction > 0 ? "Up" : "Down", false);
}

ChannelState* Viewer::Impl::activeState() {
    std::vector<ChannelState>& chs = currentChannels();
    return chs.empty() ? nullptr : &chs[size_t(std::clamp(activeChannel(), 0, static_cast<int>(chs.size()) - 1))];
}

void Viewer::Impl::startWindowLevelDrag() {
    dragStartExposure = exrExposure;
    if (const ChannelState* ch = activeState()) dragStartWindow = {ch->low, ch->high};
}

void Viewer::Impl::onWindowLevelDrag(int dx, int dy) {
    if (view == ViewPreset::Exr) {
        exrExposure = dragStartExposure * std::exp(dx / 150.0);
        updateExr();
        renderAll();
        return;
    }
    ChannelState* ch = activeState();
    if (!ch) return;
    // Measured from where the drag started: 400 pixels to the right add the starting window's width
    // once more, 400 pixels up raise the level by it.
    const double span = std::max(dragStartWindow.width(), 1e-12);
    const Window w = Window::fromWidthLevel(std::max(1e-6 * span, span * (1 + dx / 400.0)), dragStartWindow.level() + span * dy / 400.0);
    ch->low = w.low;
    ch->high = w.high;
    updateVisibility();
    renderAll();
}

void Viewer::Impl::playEvents(const std::string& log) {
    vtkNew<vtkInteractorEventRecorder> recorder;
    recorder->SetInteractor(interactor);
    recorder->ReadFromInputStringOn();
    recorder->SetInputString(log.c_str());
    recorder->Play();
    recorder->Off();
}

void Viewer::Impl::reloadStack(const fs::path& file) {
    stack.emplace(loadStackComparison(file, *scene, *microscope, specimen));
    updateCompare();
}

std::string Viewer::Impl::helpString() const {
    std::ostringstream s;
    s << "Fluorosim viewer: keys and mouse (press ? again to close)\n\n";
    for (const KeyBinding& b : keyBindings()) {
        std::string keys = b.keys;
        keys.resize(std::max<size_t>(keys.size(), 36), ' ');
        s << "  " << keys << b.action << "\n";
    }
    return s.str();
}

void Viewer::Impl::onKey(const std::string& key, bool shift) {
    std::vector<ChannelState>& chs = currentChannels();
    const int n = static_cast<int>(chs.size());
    int solo = -1;
    for (int i = 0; i < 9; ++i)
        if (key == kShiftedDigits[i] || (shift && key == std::to_string(i + 1))) solo = i;
    if (solo >= 0) {
        if (solo >= n) return;
        for (int c = 0; c < n; ++c) chs[size_t(c)].visible = c == solo;
        activeChannel() = solo;
        updateVisibility();
        renderAll();
        return;
    }
    if (key.size() == 1 && key[0] >= '1' && key[0] <= '9') {
        const int c = key[0] - '1';
        if (c >= n) return;
        chs[size_t(c)].visible = !chs[size_t(c)].visible;
        activeChannel() = c;
        updateVisibility();
        renderAll();
        return;
    }
    const bool exrView = view == ViewPreset::Exr && exr;
    if (exrView && (key == "Up" || key == "Down" || key == "Left" || key == "Right")) {
        const int bands = static_cast<int>(exr->layers[exrLayer].bands.size());
        const int delta = key == "Up" || key == "Right" ? 1 : -1;
        exrBand = std::clamp(exrBand + delta, -1, bands - 1);
        updateExr();
        updateSlider();
        renderAll();
        return;
    }
    if (key == "Up" || key == "Right") return stepPlane(1);
    if (key == "Down" || key == "Left") return stepPlane(-1);
    if (key == "Prior") return stepPlane(10);
    if (key == "Next") return stepPlane(-10);
    if (key == "Home") return stepPlane(-plane);
    if (key == "End") return stepPlane(planeCount() - 1 - plane);
    const std::string k = key.size() == 1 ? std::string(1, static_cast<char>(std::tolower(key[0]))) : key;
    const bool upper = shift || (key.size() == 1 && std::isupper(static_cast<unsigned char>(key[0])));
    if (k == "0") {
        for (ChannelState& c : chs) c.visible = true;
        updateVisibility();
    } else if (k == "Tab" || k == "ISO_Left_Tab") {
        if (n) activeChannel() = (activeChannel() + 1) % n;
        updateStatus();
    } else if (k == "a") {
        if (exrView) {
            exrExposure = autoExposure(*exr, exrLayer, exrBand);
            updateExr();
        }
        for (int c = 0; c < n; ++c) {
            if (!upper && c != activeChannel()) continue;
            if (inCompare()) {
                std::vector<float> v = stack->channels[size_t(c)].simulated;
                std::sort(v.begin(), v.end());
                chs[size_t(c)].low = v[v.size() / 1000];
                chs[size_t(c)].high = std::max<double>(v[std::min(v.size() - 1, v.size() * 999 / 1000)], chs[size_t(c)].low + 1e-6);
            } else if (volume) {
                const auto it = std::find(volume->channels.begin(), volume->channels.end(), c);
                if (it == volume->channels.end()) continue;
                const auto comp = static_cast<int>(it - volume->channels.begin());
                chs[size_t(c)].low = 0;
                chs[size_t(c)].high = std::max(nonZeroPercentile(*volume, comp, 99.5), 1.0) * volume->unitPerCount[size_t(comp)];
            }
        }
        updateVisibility();
    } else if (k == "m") {
        blend = blend == BlendMode::Mip ? BlendMode::Composite : BlendMode::Mip;
        updateVolumeProperty();
        updateStatus();
    } else if (k == "i") {
        const int c = activeSpecimenChannel;
        if (c < static_cast<int>(isosurfaceOn.size())) {
            isosurfaceOn[size_t(c)] = !isosurfaceOn[size_t(c)];
            isosurfaceLevel[size_t(c)] = 0.5 * (specimenChannels[size_t(c)].low + specimenChannels[size_t(c)].high);
            if (isosurfaceOn[size_t(c)]) buildIsosurface(c);
            updateVisibility();
        }
    } else if (k == "n") {
        showNeurons = !showNeurons;
        updateVisibility();
    } else if (k == "o") {
        showMicroscope = !showMicroscope;
        updateVisibility();
    } else if (k == "v") {
        static const ViewPreset cycle[] = {ViewPreset::Overview, ViewPreset::ThreeD, ViewPreset::Top,     ViewPreset::Front, ViewPreset::Side,
                                           ViewPreset::SliceXy,  ViewPreset::SliceXz, ViewPreset::SliceYz, ViewPreset::Compare, ViewPreset::Exr};
        const auto available = [&](ViewPreset p) {
            if (p == ViewPreset::Compare) return stack.has_value();
            if (p == ViewPreset::Exr) return exr.has_value();
            if (p == ViewPreset::Overview || p == ViewPreset::SliceXy || p == ViewPreset::SliceXz || p == ViewPreset::SliceYz)
                return volume.has_value();
            return scene.has_value();
        };
        const auto at = std::find(std::begin(cycle), std::end(cycle), view) - std::begin(cycle);
        for (size_t i = 1; i <= std::size(cycle); ++i) {
            const ViewPreset next = cycle[(size_t(at) + i) % std::size(cycle)];
            if (!available(next)) continue;
            view = next;
            break;
        }
        if (view == ViewPreset::Top || view == ViewPreset::Front || view == ViewPreset::Side) setThreeDPreset(view);
        if (view == ViewPreset::ThreeD) setThreeDPreset(ViewPreset::ThreeD);
        layout();
    } else if (k == "c") {
        if (!stack) return;
        view = view == ViewPreset::Compare ? (volume ? ViewPreset::Overview : ViewPreset::ThreeD) : ViewPreset::Compare;
        layout();
    } else if (k == "e") {
        if (!stack || !stack->sibling) return;
        reloadStack(*stack->sibling);
    } else if (k == "l") {
        if (!exr) return;
        exrLayer = (exrLayer + 1) % exr->layers.size();
        exrBand = std::min(exrBand, static_cast<int>(exr->layers[exrLayer].bands.size()) - 1);
        updateExr();
        updateSlider();
    } else if (k == "r") {
        if (volume) crosshairUm = volume->centreUm(0.5 * (volume->dims[0] - 1), 0.5 * (volume->dims[1] - 1), 0.5 * (volume->dims[2] - 1));
        if (overlay) crosshairUm = overlay->fieldOfView(plane).centreUm;
        setPlane(plane);
        resetCameras();
    } else if (k == "s") {
        const fs::path png = nextFreePath(options.screenshotFolder, "fluorosim-view-", ".png", screenshotCount);
        renderAll();
        writeScreenshot(png);
        readoutText->SetInput(("screenshot: " + png.string()).c_str());
    } else if (k == "z" || k == "t") {
        int movies = 0;
        const fs::path folder = nextFreePath(options.screenshotFolder, k == "z" ? "fluorosim-zsweep-" : "fluorosim-orbit-", "", movies);
        writeMovie(folder, k == "z" ? MovieKind::ZSweep : MovieKind::Orbit, 0);
        readoutText->SetInput(("movie frames: " + folder.string()).c_str());
    } else if (k == "question" || (k == "slash" && shift)) {
        showHelp = !showHelp;
        helpText->SetVisibility(showHelp);
    } else if (k == "q" || k == "Escape") {
        interactor->TerminateApp();
        return;
    } else {
        return;
    }
    renderAll();
}

}  // namespace fluorosim::viewer
