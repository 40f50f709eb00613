#pragma once
// Private to apps/viewer: the viewer's state and its VTK objects. Only the viewer's .cpp files
// include this header (it pulls in VTK).
#include <vtkActor.h>
#include <vtkActor2D.h>
#include <vtkImageActor.h>
#include <vtkImageData.h>
#include <vtkOrientationMarkerWidget.h>
#include <vtkPlane.h>
#include <vtkPolyData.h>
#include <vtkRenderWindow.h>
#include <vtkRenderWindowInteractor.h>
#include <vtkRenderer.h>
#include <vtkSmartPointer.h>
#include <vtkTextActor.h>
#include <vtkVolume.h>
#include <vtkVolumeMapper.h>

#include <chrono>
#include <functional>
#include <optional>

#include "database.h"
#include "optics/microscope.h"
#include "scene/scene.h"
#include "viewer/colour.h"
#include "viewer/microscope_overlay.h"
#include "viewer/spectral_image.h"
#include "viewer/specimen.h"
#include "viewer/stack_comparison.h"
#include "viewer/viewer.h"

namespace fluorosim::viewer {

// A µm scale bar: a line and its label at the bottom right of a view, a round length (1, 2 or 5 × 10ⁿ
// µm) about a fifth of the view's width, recomputed before each render from the camera.
struct ScaleBar {
    vtkSmartPointer<vtkActor2D> line;
    vtkSmartPointer<vtkPolyData> lineData;
    vtkSmartPointer<vtkTextActor> label;
    void attach(vtkRenderer* renderer);
    void update(vtkRenderer* renderer, bool pixelsNotUm);
};

// A view: its renderer, a title, a scale bar, and an image actor for the 2D views.
struct View {
    ViewPreset kind = ViewPreset::ThreeD;  // SliceXy/Xz/Yz, ThreeD, Compare (one of four panels), Exr
    vtkSmartPointer<vtkRenderer> renderer;
    vtkSmartPointer<vtkTextActor> title;
    ScaleBar bar;
    vtkSmartPointer<vtkImageData> image;   // 2D views: RGB, 8 bits
    vtkSmartPointer<vtkImageActor> imageActor;
    vtkSmartPointer<vtkPolyData> crosshair;  // slice views
    vtkSmartPointer<vtkActor> crosshairActor;
    vtkSmartPointer<vtkPlane> cutPlane;      // slice views: overlays are cut by it
    std::vector<vtkSmartPointer<vtkActor>> cutActors;
    int normalAxis = 2;                      // slice views
    bool pixels = false;                     // image in pixels (EXR), not µm
};

struct Viewer::Impl {
    ViewerOptions options;
    spectra::Database db;
    ColorMatchingFunctions cmf;
    std::optional<Scene> scene;
    std::optional<optics::Microscope> microscope;
    Specimen specimen;
    std::optional<DisplayVolume> volume;
    std::optional<MicroscopeOverlay> overlay;
    std::optional<StackComparison> stack;
    std::optional<SpectralImage> exr;
    std::vector<std::string> warnings;

    // State the keys change.
    std::vector<ChannelState> specimenChannels, stackChannels;
    int activeSpecimenChannel = 0, activeStackChannel = 0;
    int plane = 0;
    Vec3 crosshairUm;
    BlendMode blend = BlendMode::Mip;
    ViewPreset view = ViewPreset::Overview;
    bool showMicroscope = true, showNeurons = true, showHelp = false;
    std::vector<bool> isosurfaceOn;          // per specimen channel
    std::vector<double> isosurfaceLevel;     // in the channel's units
    size_t exrLayer = 0;
    int exrBand = -1;
    double exrExposure = 1;
    Window dragStartWindow;                  // of the active channel when a right drag starts
    double dragStartExposure = 1;
    bool useGpuMapper = false;
    int screenshotCount = 0;
    bool threeDStale = false;
    std::chrono::steady_clock::time_point lastStep;

    // VTK.
    vtkSmartPointer<vtkRenderWindow> window;
    vtkSmartPointer<vtkRenderWindowInteractor> interactor;
    View threeD, sliceXy, sliceXz, sliceYz, exrView;
    std::array<View, 4> comparePanels;       // simulated, truth, overlay, difference
    vtkSmartPointer<vtkRenderer> statusBar, helpLayer;
    vtkSmartPointer<vtkTextActor> legend, readoutText, helpText;
    std::vector<vtkSmartPointer<vtkTextActor>> legendEntries;
    vtkSmartPointer<vtkVolume> volumeProp;
    vtkSmartPointer<vtkVolumeMapper> volumeMapper;
    vtkSmartPointer<vtkImageData> volumeImage;
    // Neurons: tubes per neuron (cut by the slice planes too) and their actors in every view.
    std::vector<vtkSmartPointer<vtkPolyData>> neuronTubes;
    std::vector<std::pair<int, vtkSmartPointer<vtkActor>>> neuronActors;  // (specimen channel, actor)
    std::vector<std::pair<int, vtkSmartPointer<vtkActor>>> shapeActors;   // dyed shapes
    std::vector<vtkSmartPointer<vtkActor>> isosurfaceActors;               // per specimen channel
    // The microscope at the current plane: the polydata change in place, so actors and cutters follow.
    struct MicroscopeGeometry {
        vtkSmartPointer<vtkPolyData> fovOutline, fovFill, stackBox, cone;
        std::vector<vtkSmartPointer<vtkPolyData>> sheets, sheetProfiles;
        std::vector<vtkSmartPointer<vtkActor>> actors;  // in every view
    } scope;
    vtkSmartPointer<vtkPolyData> planeOutlineData;                         // the XY slice in the 3D view
    vtkSmartPointer<vtkActor> planeOutline;
    vtkSmartPointer<vtkOrientationMarkerWidget> axesWidget;
    // The slider in the status bar: the plane (z), or the band in the EXR view.
    struct Slider {
        vtkSmartPointer<vtkPolyData> track, handle;
        vtkSmartPointer<vtkActor2D> trackActor, handleActor;
        vtkSmartPointer<vtkTextActor> label;
        double x0 = 0, x1 = 1, y = 0;
        int maximum = 0;
        bool shown = false;
    } slider;

    explicit Impl(const ViewerOptions& o);
    ~Impl();

    // Loading (viewer.cpp).
    void loadData();
    void initChannels();
    // Building the window (viewer_scene.cpp).
    void createWindow();
    void buildVolume();
    void buildNeurons();
    void buildShapes();
    void buildMicroscope();
    void buildIsosurface(int channel);
    void buildSlider();
    void updateSlider();
    bool onSlider(int x, int y) const;
    void dragSlider(int x);
    void setupSliceView(View& v, ViewPreset kind, int normalAxis);
    void setupImageView(View& v, ViewPreset kind, bool pixels);
    // Updating.
    void layout();
    void updateVolumeProperty();
    void updateSlices();
    void updateSlice(View& v);
    void updateCompare();
    void updateExr();
    void updateMicroscope();
    void updateCrosshairs();
    void updateStatus();
    void updateVisibility();
    void resetCameras();
    void resetSliceCamera(View& v);
    void fitImageCamera(View& v, double widthUnits, double heightUnits, double centreX, double centreY);
    void setThreeDPreset(ViewPreset preset);
    void renderAll();
    void renderFast();  // the slices and the status bar; the 3D view keeps its last image
    // Interaction (viewer_interaction.cpp).
    void onKey(const std::string& keySym, bool shift);
    void startWindowLevelDrag();
    void onWindowLevelDrag(int dx, int dy);  // pixels from where the drag started
    void onWheel(int direction, vtkRenderer* renderer, bool control);
    void onLeftClick(int x, int y);
    void onMouseMove(int x, int y);
    void installInteraction();
    void onTimer();
    void playEvents(const std::string& log);
    void renderStatusOnly();
    void reloadStack(const std::filesystem::path& file);
    std::string helpString() const;

    // Queries.
    std::vector<ChannelState>& currentChannels();
    int& activeChannel();
    ChannelState* activeState();  // the active channel of the current view; nullptr when there is none
    bool inCompare() const { return view == ViewPreset::Compare; }
    int planeCount() const;
    double planeZUm(int k) const;          // world z of plane k (the XY slice)
    View* viewAt(int x, int y);
    std::vector<View*> shownViews();
    Readout pick(int x, int y);
    Readout pickSlice(View& v, int x, int y);
    Readout pickThreeD(int x, int y);
    Readout pickCompare(View& v, int x, int y);
    Readout pickExr(int x, int y);
    FrameImage capture();
    void stepPlane(int delta);
    void setPlane(int k);
    void writeScreenshot(const std::filesystem::path& png);
    void writeMovie(const std::filesystem::path& out, MovieKind kind, int frames);
};

// Small VTK helpers shared by the viewer's files.
vtkSmartPointer<vtkPolyData> polyLines(const std::vector<std::vector<Vec3>>& lines);
vtkSmartPointer<vtkActor> actorFor(vtkPolyData* data, const Colour& colour, double opacity);
void setImageRgb(vtkImageData* image, const std::array<int, 3>& dims, const Vec3& origin, const std::array<double, 3>& spacing,
                 const std::vector<uint8_t>& rgb);

}  // namespace fluorosim::viewer
