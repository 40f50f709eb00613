// The viewer's VTK scene: the window and its views, the volume and its transfer functions, slices,
// neurons, dyed shapes, isosurfaces, the microscope, scale bars, the status bar and the layouts.
#include <vtkAppendPolyData.h>
#include <vtkAxesActor.h>
#include <vtkBox.h>
#include <vtkCallbackCommand.h>
#include <vtkClipPolyData.h>
#include <vtkCamera.h>
#include <vtkCellArray.h>
#include <vtkColorTransferFunction.h>
#include <vtkCoordinate.h>
#include <vtkCutter.h>
#include <vtkDoubleArray.h>
#include <vtkFixedPointVolumeRayCastMapper.h>
#include <vtkFlyingEdges3D.h>
#include <vtkGPUVolumeRayCastMapper.h>
#include <vtkImageExtractComponents.h>
#include <vtkPiecewiseFunction.h>
#include <vtkPointData.h>
#include <vtkPoints.h>
#include <vtkPolyDataMapper.h>
#include <vtkPolyDataMapper2D.h>
#include <vtkProperty.h>
#include <vtkProperty2D.h>
#include <vtkRendererCollection.h>
#include <vtkSphereSource.h>
#include <vtkTextProperty.h>
#include <vtkTubeFilter.h>
#include <vtkUnsignedCharArray.h>
#include <vtkUnsignedShortArray.h>
#include <vtkVolumeProperty.h>

#include <algorithm>
#include <cmath>
#include <cstdio>

#include "core/math.h"
#include "viewer/viewer_impl.h"

namespace fluorosim::viewer {
namespace {

constexpr int kStatusBarPixels = 70;
constexpr Colour kCrosshairColour{1.0, 0.85, 0.2};
constexpr Colour kFieldColour{1.0, 0.9, 0.3};
constexpr Colour kConeColour{0.75, 0.8, 1.0};

vtkSmartPointer<vtkTextActor> makeText(int fontSize, const Colour& colour, bool monospace = false) {
    auto t = vtkSmartPointer<vtkTextActor>::New();
    vtkTextProperty* p = t->GetTextProperty();
    p->SetFontSize(fontSize);
    p->SetColor(colour[0], colour[1], colour[2]);
    if (monospace) p->SetFontFamilyToCourier();
    return t;
}

void onRendererStart(vtkObject*, unsigned long, void* clientData, void*) {
    auto* view = static_cast<View*>(clientData);
    view->bar.update(view->renderer, view->pixels);
}

vtkSmartPointer<vtkPolyData> triangles(const std::vector<Vec3>& points, const std::vector<std::array<vtkIdType, 3>>& tris) {
    auto pts = vtkSmartPointer<vtkPoints>::New();
    for (const Vec3& p : points) pts->InsertNextPoint(p.x, p.y, p.z);
    auto cells = vtkSmartPointer<vtkCellArray>::New();
    for (const auto& t : tris) cells->InsertNextCell(3, t.data());
    auto poly = vtkSmartPointer<vtkPolyData>::New();
    poly->SetPoints(pts);
    poly->SetPolys(cells);
    return poly;
}

// The sheet's 1/e² envelope z = ±w(x) across `heightUm` of its height, as a closed surface in world µm.
vtkSmartPointer<vtkPolyData> sheetSurface(const SheetEnvelope& e, double halfLengthUm, double heightUm) {
    constexpr int kSteps = 64;
    std::vector<Vec3> pts;
    std::vector<std::array<vtkIdType, 3>> tris;
    for (int i = 0; i <= kSteps; ++i) {
        const double x = -halfLengthUm + 2 * halfLengthUm * i / kSteps, w = e.halfWidthUm(x);
        for (double y : {-0.5 * heightUm, 0.5 * heightUm})
            for (double s : {-1.0, 1.0}) pts.push_back(e.centreUm + e.u * x + e.h * y + e.n * (s * w));
    }
    // Point (i, y, s) sits at 4 i + 2 y + s; faces: the two sides z = ±w and the two ends y = ±H/2.
    auto at = [](int i, int y, int s) { return vtkIdType(4 * i + 2 * y + s); };
    for (int i = 0; i < kSteps; ++i) {
        for (int s = 0; s < 2; ++s) {
            tris.push_back({at(i, 0, s), at(i + 1, 0, s), at(i + 1, 1, s)});
            tris.push_back({at(i, 0, s), at(i + 1, 1, s), at(i, 1, s)});
        }
        for (int y = 0; y < 2; ++y) {
            tris.push_back({at(i, y, 0), at(i + 1, y, 0), at(i + 1, y, 1)});
            tris.push_back({at(i, y, 0), at(i + 1, y, 1), at(i, y, 1)});
        }
    }
    return triangles(pts, tris);
}

// The waist profile ±w(x) in the sheet's mid-height plane, as two lines.
vtkSmartPointer<vtkPolyData> sheetProfile(const SheetEnvelope& e, double halfLengthUm) {
    constexpr int kSteps = 64;
    std::vector<Vec3> upper, lower;
    for (int i = 0; i <= kSteps; ++i) {
        const double x = -halfLengthUm + 2 * halfLengthUm * i / kSteps, w = e.halfWidthUm(x);
        upper.push_back(e.centreUm + e.u * x + e.n * w);
        lower.push_back(e.centreUm + e.u * x - e.n * w);
    }
    return polyLines({upper, lower});
}

vtkSmartPointer<vtkPolyData> coneSurface(const CollectionCone& c, double lengthUm) {
    constexpr int kSides = 48;
    const Frame f = Frame::fromNormal(c.axis);
    const double r = lengthUm * std::tan(c.halfAngleRad);
    std::vector<Vec3> pts{c.apexUm};
    std::vector<std::array<vtkIdType, 3>> tris;
    for (int i = 0; i < kSides; ++i) {
        const double a = 2 * kPi * i / kSides;
        pts.push_back(c.apexUm + c.axis * lengthUm + (f.s * std::cos(a) + f.t * std::sin(a)) * r);
        tris.push_back({0, vtkIdType(1 + i), vtkIdType(1 + (i + 1) % kSides)});
    }
    return triangles(pts, tris);
}

vtkSmartPointer<vtkActor2D> actor2D(vtkPolyData* data, const Colour& colour, double lineWidth) {
    vtkNew<vtkCoordinate> viewport;
    viewport->SetCoordinateSystemToViewport();
    vtkNew<vtkPolyDataMapper2D> mapper;
    mapper->SetInputData(data);
    mapper->SetTransformCoordinate(viewport);
    auto a = vtkSmartPointer<vtkActor2D>::New();
    a->SetMapper(mapper);
    a->GetProperty()->SetColor(colour[0], colour[1], colour[2]);
    a->GetProperty()->SetLineWidth(static_cast<float>(lineWidth));
    return a;
}

}  // namespace

vtkSmartPointer<vtkPolyData> polyLines(const std::vector<std::vector<Vec3>>& lines) {
    auto pts = vtkSmartPointer<vtkPoints>::New();
    auto cells = vtkSmartPointer<vtkCellArray>::New();
    for (const auto& line : lines) {
        cells->InsertNextCell(static_cast<vtkIdType>(line.size()));
        for (const Vec3& p : line) cells->InsertCellPoint(pts->InsertNextPoint(p.x, p.y, p.z));
    }
    auto poly = vtkSmartPointer<vtkPolyData>::New();
    poly->SetPoints(pts);
    poly->SetLines(cells);
    return poly;
}

vtkSmartPointer<vtkActor> actorFor(vtkPolyData* data, const Colour& colour, double opacity) {
    vtkNew<vtkPolyDataMapper> mapper;
    mapper->SetInputData(data);
    mapper->ScalarVisibilityOff();
    auto actor = vtkSmartPointer<vtkActor>::New();
    actor->SetMapper(mapper);
    actor->GetProperty()->SetColor(colour[0], colour[1], colour[2]);
    actor->GetProperty()->SetOpacity(opacity);
    return actor;
}

void setImageRgb(vtkImageData* image, const std::array<int, 3>& dims, const Vec3& origin, const std::array<double, 3>& spacing,
                 const std::vector<uint8_t>& rgb) {
    image->SetDimensions(dims[0], dims[1], dims[2]);
    image->SetOrigin(origin.x, origin.y, origin.z);
    image->SetSpacing(spacing[0], spacing[1], spacing[2]);
    image->AllocateScalars(VTK_UNSIGNED_CHAR, 3);
    std::copy(rgb.begin(), rgb.end(), static_cast<uint8_t*>(image->GetScalarPointer()));
    image->Modified();
}

void ScaleBar::attach(vtkRenderer* renderer) {
    lineData = polyLines({{Vec3(), Vec3(1, 0, 0)}});
    line = actor2D(lineData, {1, 1, 1}, 3);
    label = makeText(13, {1, 1, 1});
    label->GetTextProperty()->SetJustificationToCentered();
    renderer->AddActor2D(line);
    renderer->AddActor2D(label);
}

void ScaleBar::update(vtkRenderer* renderer, bool pixelsNotUm) {
    const int* size = renderer->GetSize();
    if (size[0] < 40 || size[1] < 40) return;
    vtkCamera* cam = renderer->GetActiveCamera();
    const double viewHeight = cam->GetParallelProjection() ? 2 * cam->GetParallelScale()
                                                          : 2 * cam->GetDistance() * std::tan(0.5 * cam->GetViewAngle() * kPi / 180);
    const double unitsPerPixel = viewHeight / size[1];
    const double target = 0.2 * size[0] * unitsPerPixel;
    double length = std::pow(10.0, std::floor(std::log10(target)));
    for (double m : {5.0, 2.0})
        if (m * length <= target) {
            length *= m;
            break;
        }
    const double px = length / unitsPerPixel, x1 = size[0] - 20.0, x0 = x1 - px, y = 18.0;
    vtkPoints* pts = lineData->GetPoints();
    pts->SetPoint(0, x0, y, 0);
    pts->SetPoint(1, x1, y, 0);
    pts->Modified();
    char text[48];
    if (pixelsNotUm) std::snprintf(text, sizeof text, "%g px", length);
    else if (length >= 1000) std::snprintf(text, sizeof text, "%g mm", length / 1000);
    else std::snprintf(text, sizeof text, "%g \xC2\xB5m", length);
    label->SetInput(text);
    label->SetPosition(0.5 * (x0 + x1), y + 6);
}

void Viewer::Impl::createWindow() {
    window = vtkSmartPointer<vtkRenderWindow>::New();
    window->SetOffScreenRendering(options.offscreen || options.screenshot || options.movie ? 1 : 0);
    window->SetSize(options.width, options.height);
    window->SetMultiSamples(0);  // the same pixels on every run, for the baseline images
    window->SetNumberOfLayers(2);
    window->SetWindowName(("Fluorosim view: " + (options.scene.empty() ? options.exr->string() : options.scene.string())).c_str());
    if (!window->SupportsOpenGL()) throw DisplayError("the X display offers no OpenGL 3.2 context; VTK cannot render");
    interactor = vtkSmartPointer<vtkRenderWindowInteractor>::New();
    interactor->SetRenderWindow(window);
    window->Start();  // creates the window and its GL context, which ReportCapabilities needs
    // The GPU ray caster needs the OpenGL 3.2 context checked above; it is also the faster one on Mesa's
    // llvmpipe for still frames of large, dense volumes (docs/viewer.md, "Speed": 435-477 ms against
    // 1237-1344 ms for the CPU caster in two runs), and meets every frame-time goal there.
    useGpuMapper = options.mapper != MapperChoice::Cpu;

    threeD.renderer = vtkSmartPointer<vtkRenderer>::New();
    threeD.renderer->SetBackground(0.06, 0.06, 0.08);
    threeD.kind = ViewPreset::ThreeD;
    threeD.title = makeText(14, {1, 1, 1});
    threeD.bar.attach(threeD.renderer);
    threeD.renderer->AddActor2D(threeD.title);
    setupSliceView(sliceXy, ViewPreset::SliceXy, 2);
    setupSliceView(sliceXz, ViewPreset::SliceXz, 1);
    setupSliceView(sliceYz, ViewPreset::SliceYz, 0);
    for (View& p : comparePanels) setupImageView(p, ViewPreset::Compare, false);
    for (size_t i = 1; i < comparePanels.size(); ++i) comparePanels[i].renderer->SetActiveCamera(comparePanels[0].renderer->GetActiveCamera());
    setupImageView(exrView, ViewPreset::Exr, true);
    for (View* v : {&threeD, &sliceXy, &sliceXz, &sliceYz, &comparePanels[0], &comparePanels[1], &comparePanels[2], &comparePanels[3],
                    &exrView}) {
        vtkNew<vtkCallbackCommand> cb;
        cb->SetCallback(onRendererStart);
        cb->SetClientData(v);
        v->renderer->AddObserver(vtkCommand::StartEvent, cb);
        v->title->GetPositionCoordinate()->SetCoordinateSystemToNormalizedViewport();
        v->title->GetTextProperty()->SetVerticalJustificationToTop();
        v->title->SetPosition(0.01, 0.985);
    }

    statusBar = vtkSmartPointer<vtkRenderer>::New();
    statusBar->SetBackground(0.13, 0.13, 0.15);
    statusBar->InteractiveOff();
    readoutText = makeText(13, {0.9, 0.9, 0.9});
    readoutText->SetPosition(8, 6);
    statusBar->AddActor2D(readoutText);
    helpLayer = vtkSmartPointer<vtkRenderer>::New();
    helpLayer->SetLayer(1);
    helpLayer->InteractiveOff();
    helpText = makeText(14, {1, 1, 1}, true);
    helpText->GetTextProperty()->SetBackgroundColor(0.05, 0.05, 0.08);
    helpText->GetTextProperty()->SetBackgroundOpacity(0.9);
    helpText->GetPositionCoordinate()->SetCoordinateSystemToNormalizedViewport();
    helpText->SetPosition(0.05, 0.08);
    helpText->SetInput(helpString().c_str());
    helpText->SetVisibility(false);
    helpLayer->AddActor2D(helpText);

    if (volume) buildVolume();
    buildNeurons();
    buildShapes();
    if (overlay) buildMicroscope();
    for (size_t c = 0; c < isosurfaceOn.size(); ++c)
        if (isosurfaceOn[c]) buildIsosurface(static_cast<int>(c));
    vtkNew<vtkAxesActor> axes;
    axes->SetXAxisLabelText("x");
    axes->SetYAxisLabelText("y");
    axes->SetZAxisLabelText("z");
    axesWidget = vtkSmartPointer<vtkOrientationMarkerWidget>::New();
    axesWidget->SetOrientationMarker(axes);
    axesWidget->SetInteractor(interactor);
    axesWidget->SetDefaultRenderer(threeD.renderer);
    buildSlider();
    installInteraction();

    setPlane(plane);
    updateVolumeProperty();
    updateCompare();
    updateExr();
    updateVisibility();
    layout();
    resetCameras();
    if (options.view == ViewPreset::Top || options.view == ViewPreset::Front || options.view == ViewPreset::Side) setThreeDPreset(options.view);
}

void Viewer::Impl::setupSliceView(View& v, ViewPreset kind, int normalAxis) {
    setupImageView(v, kind, false);  // voxels stay voxels: no interpolation
    v.normalAxis = normalAxis;
    v.crosshair = polyLines({});
    v.crosshairActor = actorFor(v.crosshair, kCrosshairColour, 0.55);
    v.renderer->AddActor(v.crosshairActor);
    v.cutPlane = vtkSmartPointer<vtkPlane>::New();
    v.cutPlane->SetNormal(normalAxis == 0, normalAxis == 1, normalAxis == 2);
}

void Viewer::Impl::setupImageView(View& v, ViewPreset kind, bool pixels) {
    v.kind = kind;
    v.pixels = pixels;
    v.renderer = vtkSmartPointer<vtkRenderer>::New();
    v.renderer->SetBackground(0, 0, 0);
    v.renderer->GetActiveCamera()->ParallelProjectionOn();
    v.image = vtkSmartPointer<vtkImageData>::New();
    v.imageActor = vtkSmartPointer<vtkImageActor>::New();
    v.imageActor->SetInputData(v.image);
    v.imageActor->InterpolateOff();
    v.renderer->AddActor(v.imageActor);
    v.title = makeText(14, {1, 1, 1});
    v.renderer->AddActor2D(v.title);
    v.bar.attach(v.renderer);
}

// Adds an overlay to the slice views as its cut by each slice plane, nudged towards the camera so it
// draws over the slice image.
static void addCuts(View& v, vtkPolyData* source, const Colour& colour, double nudgeUm) {
    vtkNew<vtkCutter> cutter;
    cutter->SetInputData(source);
    cutter->SetCutFunction(v.cutPlane);
    vtkNew<vtkPolyDataMapper> mapper;
    mapper->SetInputConnection(cutter->GetOutputPort());
    mapper->ScalarVisibilityOff();
    auto actor = vtkSmartPointer<vtkActor>::New();
    actor->SetMapper(mapper);
    actor->GetProperty()->SetColor(colour[0], colour[1], colour[2]);
    actor->GetProperty()->SetLineWidth(2);
    const double towardCamera[3] = {v.normalAxis == 0 ? 1.0 : 0.0, v.normalAxis == 1 ? -1.0 : 0.0, v.normalAxis == 2 ? 1.0 : 0.0};
    actor->SetPosition(towardCamera[0] * nudgeUm, towardCamera[1] * nudgeUm, towardCamera[2] * nudgeUm);
    v.renderer->AddActor(actor);
    v.cutActors.push_back(actor);
}

static double nudgeFor(const std::optional<DisplayVolume>& volume) {
    return volume ? 0.5 * std::min({volume->spacingUm[0], volume->spacingUm[1], volume->spacingUm[2]}) : 0.1;
}

void Viewer::Impl::buildVolume() {
    volumeImage = vtkSmartPointer<vtkImageData>::New();
    volumeImage->SetDimensions(volume->dims[0], volume->dims[1], volume->dims[2]);
    volumeImage->SetOrigin(volume->originUm.x, volume->originUm.y, volume->originUm.z);
    volumeImage->SetSpacing(volume->spacingUm[0], volume->spacingUm[1], volume->spacingUm[2]);
    vtkNew<vtkUnsignedShortArray> counts;
    counts->SetNumberOfComponents(volume->components());
    // VTK reads the viewer's own buffer (save = 1: VTK never frees it).
    counts->SetArray(volume->counts.data(), static_cast<vtkIdType>(volume->counts.size()), 1);
    volumeImage->GetPointData()->SetScalars(counts);
    if (useGpuMapper) {
        auto m = vtkSmartPointer<vtkGPUVolumeRayCastMapper>::New();
        m->LockSampleDistanceToInputSpacingOn();
        volumeMapper = m;
    } else {
        auto m = vtkSmartPointer<vtkFixedPointVolumeRayCastMapper>::New();
        m->LockSampleDistanceToInputSpacingOn();
        volumeMapper = m;
    }
    volumeMapper->SetInputData(volumeImage);
    volumeProp = vtkSmartPointer<vtkVolume>::New();
    volumeProp->SetMapper(volumeMapper);
    vtkNew<vtkVolumeProperty> property;
    property->IndependentComponentsOn();
    property->SetInterpolationTypeToLinear();
    property->ShadeOff();
    volumeProp->SetProperty(property);
    threeD.renderer->AddVolume(volumeProp);
    planeOutlineData = polyLines({});
    planeOutline = actorFor(planeOutlineData, kCrosshairColour, 0.5);
    threeD.renderer->AddActor(planeOutline);
}

void Viewer::Impl::updateVolumeProperty() {
    if (!volumeProp) return;
    vtkVolumeProperty* p = volumeProp->GetProperty();
    volumeMapper->SetBlendMode(blend == BlendMode::Mip ? vtkVolumeMapper::MAXIMUM_INTENSITY_BLEND : vtkVolumeMapper::COMPOSITE_BLEND);
    const double minSpacing = std::min({volume->spacingUm[0], volume->spacingUm[1], volume->spacingUm[2]});
    for (int k = 0; k < volume->components(); ++k) {
        const ChannelState& ch = specimenChannels[size_t(volume->channels[size_t(k)])];
        const double low = ch.low / volume->unitPerCount[size_t(k)];
        const double high = std::max(low + 1, ch.high / volume->unitPerCount[size_t(k)]);
        vtkNew<vtkColorTransferFunction> colour;
        colour->AddRGBPoint(low, 0, 0, 0);
        colour->AddRGBPoint(high, ch.colour[0], ch.colour[1], ch.colour[2]);
        vtkNew<vtkPiecewiseFunction> opacity;
        opacity->AddPoint(low, 0);
        // A projection shows the brightest voxel; composite rendering lets dim voxels in front show.
        opacity->AddPoint(high, blend == BlendMode::Mip ? 1.0 : 0.6);
        p->SetColor(k, colour);
        p->SetScalarOpacity(k, opacity);
        p->SetScalarOpacityUnitDistance(k, 2 * minSpacing);
        p->SetComponentWeight(k, ch.visible ? 1.0 : 0.0);
    }
}

void Viewer::Impl::buildNeurons() {
    for (const NeuronModel& n : specimen.neurons) {
        // Round cones as tubes whose radius runs from ra to rb; somata (and single samples) as spheres.
        vtkNew<vtkPoints> pts;
        vtkNew<vtkDoubleArray> radius;
        vtkNew<vtkCellArray> lines;
        vtkNew<vtkAppendPolyData> all;
        for (const MorphologyPiece& p : n.pieces) {
            if (p.sphere) {
                vtkNew<vtkSphereSource> sphere;
                sphere->SetCenter(p.aUm.x, p.aUm.y, p.aUm.z);
                sphere->SetRadius(p.raUm);
                sphere->SetThetaResolution(24);
                sphere->SetPhiResolution(16);
                all->AddInputConnection(sphere->GetOutputPort());
                continue;
            }
            const vtkIdType ids[2] = {pts->InsertNextPoint(p.aUm.x, p.aUm.y, p.aUm.z), pts->InsertNextPoint(p.bUm.x, p.bUm.y, p.bUm.z)};
            radius->InsertNextValue(p.raUm);
            radius->InsertNextValue(p.rbUm);
            lines->InsertNextCell(2, ids);
        }
        vtkNew<vtkPolyData> skeleton;
        skeleton->SetPoints(pts);
        skeleton->SetLines(lines);
        skeleton->GetPointData()->SetScalars(radius);
        vtkNew<vtkTubeFilter> tubes;
        tubes->SetInputData(skeleton);
        tubes->SetVaryRadiusToVaryRadiusByAbsoluteScalar();  // the SWC radii, in µm
        tubes->SetNumberOfSides(10);
        tubes->CappingOn();
        if (lines->GetNumberOfCells()) all->AddInputConnection(tubes->GetOutputPort());
        if (!all->GetNumberOfInputConnections(0)) continue;
        all->Update();
        auto tube = vtkSmartPointer<vtkPolyData>::New();
        tube->ShallowCopy(all->GetOutput());
        if (options.region == Region::FieldOfView && volume) {
            // Only the part inside the region, like the volume.
            const auto [lo, hi] = volume->boundsUm();
            vtkNew<vtkBox> box;
            box->SetBounds(lo.x, hi.x, lo.y, hi.y, lo.z, hi.z);
            vtkNew<vtkClipPolyData> clip;
            clip->SetInputData(tube);
            clip->SetClipFunction(box);
            clip->InsideOutOn();
            clip->Update();
            tube->ShallowCopy(clip->GetOutput());
        }
        tube->GetPointData()->SetScalars(nullptr);
        const Colour colour = n.channel >= 0 ? Colour(specimenChannels[size_t(n.channel)].colour) : Colour{0.8, 0.8, 0.8};
        // Tubes are paler than the volume's colour so that both read where they overlap.
        const Colour pale{0.5 + 0.5 * colour[0], 0.5 + 0.5 * colour[1], 0.5 + 0.5 * colour[2]};
        auto actor = actorFor(tube, pale, 1.0);
        threeD.renderer->AddActor(actor);
        neuronActors.push_back({n.channel, actor});
        neuronTubes.push_back(tube);
        for (View* v : {&sliceXy, &sliceXz, &sliceYz}) {
            addCuts(*v, tube, pale, nudgeFor(volume));
            v->cutActors.back()->GetProperty()->SetLineWidth(1);
            v->cutActors.back()->GetProperty()->SetOpacity(0.6);
            neuronActors.push_back({n.channel, v->cutActors.back()});
        }
    }
}

void Viewer::Impl::buildShapes() {
    for (const DyedShape& d : specimen.shapes) {
        vtkSmartPointer<vtkPolyData> poly;
        if (d.sphere) {
            vtkNew<vtkSphereSource> s;
            s->SetCenter(d.centreUm.x, d.centreUm.y, d.centreUm.z);
            s->SetRadius(d.radiusUm);
            s->SetThetaResolution(24);
            s->SetPhiResolution(16);
            s->Update();
            poly = s->GetOutput();
        } else {
            std::vector<std::array<vtkIdType, 3>> tris;
            for (size_t i = 0; i + 2 < d.meshUm.indices.size(); i += 3)
                tris.push_back({vtkIdType(d.meshUm.indices[i]), vtkIdType(d.meshUm.indices[i + 1]), vtkIdType(d.meshUm.indices[i + 2])});
            poly = triangles(d.meshUm.positions, tris);
        }
        auto actor = actorFor(poly, specimenChannels[size_t(d.channel)].colour, 1.0);
        threeD.renderer->AddActor(actor);
        shapeActors.push_back({d.channel, actor});
    }
}

void Viewer::Impl::buildIsosurface(int channel) {
    if (!volume) return;
    const auto it = std::find(volume->channels.begin(), volume->channels.end(), channel);
    if (it == volume->channels.end()) return;
    const auto k = static_cast<int>(it - volume->channels.begin());
    if (isosurfaceActors.empty()) isosurfaceActors.resize(specimenChannels.size());
    if (isosurfaceActors[size_t(channel)]) threeD.renderer->RemoveActor(isosurfaceActors[size_t(channel)]);
    vtkNew<vtkImageExtractComponents> component;
    component->SetInputData(volumeImage);
    component->SetComponents(k);
    vtkNew<vtkFlyingEdges3D> surface;
    surface->SetInputConnection(component->GetOutputPort());
    surface->SetValue(0, isosurfaceLevel[size_t(channel)] / volume->unitPerCount[size_t(k)]);
    surface->ComputeNormalsOn();
    surface->ComputeScalarsOff();
    surface->Update();
    auto poly = vtkSmartPointer<vtkPolyData>::New();
    poly->ShallowCopy(surface->GetOutput());
    isosurfaceActors[size_t(channel)] = actorFor(poly, specimenChannels[size_t(channel)].colour, 0.7);
    threeD.renderer->AddActor(isosurfaceActors[size_t(channel)]);
}

void Viewer::Impl::buildMicroscope() {
    scope.fovOutline = polyLines({});
    scope.fovFill = vtkSmartPointer<vtkPolyData>::New();
    scope.stackBox = polyLines({});
    scope.cone = vtkSmartPointer<vtkPolyData>::New();
    auto add3d = [&](vtkPolyData* data, const Colour& colour, double opacity) {
        auto a = actorFor(data, colour, opacity);
        threeD.renderer->AddActor(a);
        scope.actors.push_back(a);
        return a;
    };
    add3d(scope.fovOutline, kFieldColour, 1.0)->GetProperty()->SetLineWidth(2);
    add3d(scope.fovFill, kFieldColour, 0.12);
    add3d(scope.stackBox, kFieldColour, 0.35);
    add3d(scope.cone, kConeColour, 0.12);
    const double nudge = nudgeFor(volume);
    sliceXy.renderer->AddActor(actorFor(scope.fovOutline, kFieldColour, 1.0));
    sliceXy.cutActors.push_back(vtkActor::SafeDownCast(sliceXy.renderer->GetActors()->GetLastProp()));
    sliceXy.cutActors.back()->SetPosition(0, 0, nudge);
    scope.actors.push_back(sliceXy.cutActors.back());
    for (View* v : {&sliceXz, &sliceYz}) {
        addCuts(*v, scope.cone, kConeColour, nudge);
        scope.actors.push_back(v->cutActors.back());
    }
    for (const SheetEnvelope& e : overlay->sheets(plane)) {
        auto sheet = vtkSmartPointer<vtkPolyData>::New();
        auto profile = vtkSmartPointer<vtkPolyData>::New();
        scope.sheets.push_back(sheet);
        scope.sheetProfiles.push_back(profile);
        const Colour colour = wavelengthColour(e.lambdaNm, cmf);
        add3d(sheet, colour, 0.15);
        add3d(profile, colour, 1.0)->GetProperty()->SetLineWidth(2);
        for (View* v : {&sliceXz, &sliceYz}) {
            addCuts(*v, sheet, colour, nudge);
            scope.actors.push_back(v->cutActors.back());
        }
    }
}

void Viewer::Impl::updateMicroscope() {
    if (planeOutlineData && volume) {
        const double z = planeZUm(plane);
        const Vec3 lo = volume->centreUm(-0.5, -0.5, 0), hi = volume->centreUm(volume->dims[0] - 0.5, volume->dims[1] - 0.5, 0);
        planeOutlineData->ShallowCopy(polyLines({{Vec3(lo.x, lo.y, z), Vec3(hi.x, lo.y, z), Vec3(hi.x, hi.y, z), Vec3(lo.x, hi.y, z),
                                                  Vec3(lo.x, lo.y, z)}}));
    }
    if (!overlay || !scope.cone) return;
    const FieldOfView fov = overlay->fieldOfView(plane);
    const auto& c = fov.cornersUm;
    scope.fovOutline->ShallowCopy(polyLines({{c[0], c[1], c[2], c[3], c[0]}}));
    scope.fovFill->ShallowCopy(triangles({c[0], c[1], c[2], c[3]}, {{0, 1, 2}, {0, 2, 3}}));
    const auto& a = overlay->fieldOfView(0).cornersUm;
    const auto& b = overlay->fieldOfView(overlay->planes() - 1).cornersUm;
    scope.stackBox->ShallowCopy(polyLines({{a[0], a[1], a[2], a[3], a[0]}, {b[0], b[1], b[2], b[3], b[0]}, {a[0], b[0]}, {a[1], b[1]},
                                           {a[2], b[2]}, {a[3], b[3]}}));
    // The cone is drawn to two field diagonals (or the working distance, if shorter): the objective
    // itself is usually much farther away than the specimen is large.
    const CollectionCone cone = overlay->cone(plane);
    const double diagonal = length(c[2] - c[0]);
    scope.cone->ShallowCopy(coneSurface(cone, std::min(cone.lengthUm, 2 * diagonal)));
    const std::vector<SheetEnvelope> sheets = overlay->sheets(plane);
    // Sheets are drawn over the field of view and its surroundings: their full height (often a few
    // fields) would hide the specimen.
    for (size_t i = 0; i < sheets.size() && i < scope.sheets.size(); ++i) {
        const double halfLength = std::max(2 * sheets[i].rayleighUm, diagonal);
        scope.sheets[i]->ShallowCopy(sheetSurface(sheets[i], halfLength, std::min(sheets[i].heightUm, 1.5 * diagonal)));
        scope.sheetProfiles[i]->ShallowCopy(sheetProfile(sheets[i], halfLength));
    }
}

void Viewer::Impl::buildSlider() {
    slider.track = polyLines({});
    slider.handle = vtkSmartPointer<vtkPolyData>::New();
    slider.trackActor = actor2D(slider.track, {0.55, 0.55, 0.6}, 3);
    slider.handleActor = actor2D(slider.handle, kCrosshairColour, 1);
    slider.label = makeText(13, {0.9, 0.9, 0.9});
    statusBar->AddActor2D(slider.trackActor);
    statusBar->AddActor2D(slider.handleActor);
    statusBar->AddActor2D(slider.label);
}

void Viewer::Impl::updateSlider() {
    const int* size = window->GetSize();
    slider.y = kStatusBarPixels - 15;
    slider.x0 = 16;
    slider.x1 = std::max(160.0, 0.5 * size[0]);
    char text[160];
    double fraction = 0;
    if (view == ViewPreset::Exr && exr) {
        // Position 0 is the sRGB composite, 1.. the bands.
        const SpectralLayerImage& layer = exr->layers[exrLayer];
        slider.maximum = static_cast<int>(layer.bands.size());
        fraction = slider.maximum ? double(exrBand + 1) / slider.maximum : 0;
        if (exrBand < 0) std::snprintf(text, sizeof text, "sRGB composite (%zu bands)", layer.bands.size());
        else std::snprintf(text, sizeof text, "band %d / %zu   %.1f nm", exrBand + 1, layer.bands.size(), layer.bands[size_t(exrBand)].lambdaNm);
    } else {
        slider.maximum = planeCount() - 1;
        fraction = slider.maximum > 0 ? double(plane) / slider.maximum : 0;
        if (overlay)
            std::snprintf(text, sizeof text, "plane %d / %d   z = %.2f \xC2\xB5m (focus %+.2f \xC2\xB5m)", plane + 1, planeCount(),
                          planeZUm(plane), overlay->offsetUm(plane));
        else std::snprintf(text, sizeof text, "plane %d / %d   z = %.2f \xC2\xB5m", plane + 1, planeCount(), planeZUm(plane));
    }
    slider.shown = slider.maximum > 0;
    const double hx = slider.x0 + fraction * (slider.x1 - slider.x0), y = slider.y;
    slider.track->ShallowCopy(polyLines({{Vec3(slider.x0, y, 0), Vec3(slider.x1, y, 0)}}));
    slider.handle->ShallowCopy(triangles({Vec3(hx - 5, y - 7, 0), Vec3(hx + 5, y - 7, 0), Vec3(hx + 5, y + 7, 0), Vec3(hx - 5, y + 7, 0)},
                                         {{0, 1, 2}, {0, 2, 3}}));
    slider.label->SetInput(text);
    slider.label->SetPosition(slider.x1 + 16, y - 7);
    slider.trackActor->SetVisibility(slider.shown);
    slider.handleActor->SetVisibility(slider.shown);
}

bool Viewer::Impl::onSlider(int x, int y) const {
    return slider.shown && std::abs(y - slider.y) <= 9 && x >= slider.x0 - 9 && x <= slider.x1 + 9;
}

void Viewer::Impl::dragSlider(int x) {
    const double fraction = std::clamp((x - slider.x0) / (slider.x1 - slider.x0), 0.0, 1.0);
    const int value = static_cast<int>(std::lround(fraction * slider.maximum));
    if (view == ViewPreset::Exr && exr) {
        if (value - 1 == exrBand) return;
        exrBand = value - 1;
        updateExr();
        updateSlider();
        renderAll();
    } else if (value != plane) {
        stepPlane(value - plane);
    }
}

std::vector<View*> Viewer::Impl::shownViews() {
    switch (view) {
    case ViewPreset::Overview: return {&sliceXy, &threeD, &sliceXz, &sliceYz};
    case ViewPreset::SliceXy: return {&sliceXy};
    case ViewPreset::SliceXz: return {&sliceXz};
    case ViewPreset::SliceYz: return {&sliceYz};
    case ViewPreset::Compare: return {&comparePanels[0], &comparePanels[1], &comparePanels[2], &comparePanels[3]};
    case ViewPreset::Exr: return {&exrView};
    default: return {&threeD};
    }
}

void Viewer::Impl::layout() {
    window->GetRenderers()->RemoveAllItems();
    const int* size = window->GetSize();
    const double s = std::min(0.5, double(kStatusBarPixels) / std::max(1, size[1]));
    const std::vector<View*> views = shownViews();
    const double mid = s + 0.5 * (1 - s);
    for (size_t i = 0; i < views.size(); ++i) {
        double vp[4] = {0, s, 1, 1};
        if (views.size() == 4) {
            const bool right = i % 2 == 1, bottom = i >= 2;
            vp[0] = right ? 0.5 : 0;
            vp[2] = right ? 1 : 0.5;
            vp[1] = bottom ? s : mid;
            vp[3] = bottom ? mid : 1;
        }
        views[i]->renderer->SetViewport(vp);
        window->AddRenderer(views[i]->renderer);
    }
    statusBar->SetViewport(0, 0, 1, s);
    window->AddRenderer(statusBar);
    helpLayer->SetViewport(0, 0, 1, 1);
    window->AddRenderer(helpLayer);
    const bool threeDShown = std::find(views.begin(), views.end(), &threeD) != views.end();
    if (threeDShown) {
        // VTK 9.1 places the marker relative to the 3D view's own viewport.
        axesWidget->SetViewport(0, 0, 0.16, 0.2);
        axesWidget->SetEnabled(1);
        axesWidget->InteractiveOff();
    } else if (axesWidget->GetEnabled()) {
        axesWidget->SetEnabled(0);
    }
    updateSlider();
    updateStatus();
}

void Viewer::Impl::updateVisibility() {
    auto visible = [&](int channel) { return channel < 0 || specimenChannels[size_t(channel)].visible; };
    for (auto& [channel, actor] : neuronActors) actor->SetVisibility(showNeurons && visible(channel));
    for (auto& [channel, actor] : shapeActors) actor->SetVisibility(visible(channel));
    for (size_t c = 0; c < isosurfaceActors.size(); ++c)
        if (isosurfaceActors[c]) isosurfaceActors[c]->SetVisibility(isosurfaceOn[c] && visible(static_cast<int>(c)));
    for (auto& a : scope.actors) a->SetVisibility(showMicroscope);
    updateVolumeProperty();
    updateSlices();
    updateCompare();
    updateStatus();
}

void Viewer::Impl::updateSlices() {
    if (!volume || !sliceXy.renderer) return;
    for (View* v : {&sliceXy, &sliceXz, &sliceYz}) updateSlice(*v);
    updateCrosshairs();
}

void Viewer::Impl::updateSlice(View& v) {
    const DisplayVolume& vol = *volume;
    const Vec3 at(crosshairUm.x, crosshairUm.y, planeZUm(plane));
    // Axes of the image: (a, b) = (x, y), (x, z) or (y, z); the slice index along the normal.
    const int a = v.normalAxis == 0 ? 1 : 0, b = v.normalAxis == 2 ? 1 : 2, n = v.normalAxis;
    const int slice = static_cast<int>(std::lround((at[n] - vol.originUm[n]) / vol.spacingUm[size_t(n)]));
    const bool inside = slice >= 0 && slice < vol.dims[size_t(n)];
    const int w = vol.dims[size_t(a)], h = vol.dims[size_t(b)];
    Composite composite(w, h);
    std::vector<float> values(size_t(w) * h);
    for (int k = 0; k < vol.components() && inside; ++k) {
        const ChannelState& ch = specimenChannels[size_t(vol.channels[size_t(k)])];
        if (!ch.visible) continue;
        std::array<int, 3> ijk{};
        ijk[size_t(n)] = slice;
        for (int j = 0; j < h; ++j)
            for (int i = 0; i < w; ++i) {
                ijk[size_t(a)] = i;
                ijk[size_t(b)] = j;
                values[size_t(j) * w + i] = static_cast<float>(vol.value(ijk[0], ijk[1], ijk[2], k));
            }
        composite.add(values.data(), Window{ch.low, ch.high}, ch.colour);
    }
    std::array<int, 3> dims{1, 1, 1};
    dims[size_t(a)] = w;
    dims[size_t(b)] = h;
    Vec3 origin = vol.originUm;
    origin[n] = at[n];
    setImageRgb(v.image, dims, origin, vol.spacingUm, composite.rgb8());
    // An explicit display extent makes the actor show the single slice in its own orientation.
    v.imageActor->SetDisplayExtent(0, dims[0] - 1, 0, dims[1] - 1, 0, dims[2] - 1);
    v.cutPlane->SetOrigin(at.x, at.y, at.z);
    char title[128];
    const char* names[] = {"YZ", "XZ", "XY"};
    const char axisName = "xyz"[n];
    if (v.normalAxis == 2)
        std::snprintf(title, sizeof title, "%s   z = %.2f \xC2\xB5m   plane %d / %d%s", names[n], at[n], plane + 1, planeCount(),
                      inside ? "" : "   (outside the volume)");
    else
        std::snprintf(title, sizeof title, "%s   %c = %.2f \xC2\xB5m%s", names[n], axisName, at[n], inside ? "" : "   (outside the volume)");
    v.title->SetInput(title);
}

void Viewer::Impl::updateCrosshairs() {
    if (!volume) return;
    const auto [lo, hi] = volume->boundsUm();
    const Vec3 c(crosshairUm.x, crosshairUm.y, planeZUm(plane));
    const double e = nudgeFor(volume);
    sliceXy.crosshair->ShallowCopy(polyLines({{Vec3(c.x, lo.y, c.z + e), Vec3(c.x, hi.y, c.z + e)},
                                              {Vec3(lo.x, c.y, c.z + e), Vec3(hi.x, c.y, c.z + e)}}));
    sliceXz.crosshair->ShallowCopy(polyLines({{Vec3(c.x, c.y - e, lo.z), Vec3(c.x, c.y - e, hi.z)},
                                              {Vec3(lo.x, c.y - e, c.z), Vec3(hi.x, c.y - e, c.z)}}));
    sliceYz.crosshair->ShallowCopy(polyLines({{Vec3(c.x + e, c.y, lo.z), Vec3(c.x + e, c.y, hi.z)},
                                              {Vec3(c.x + e, lo.y, c.z), Vec3(c.x + e, hi.y, c.z)}}));
}

void Viewer::Impl::updateCompare() {
    if (!stack || !comparePanels[0].renderer) return;
    const StackComparison& s = *stack;
    const int w = s.info.width, h = s.info.height;
    const size_t off = s.planeOffset(plane);
    // Camera rows run from the top; VTK images from the bottom.
    auto flipped = [&](const std::vector<float>& data, auto transform) {
        std::vector<float> out(size_t(w) * h);
        for (int y = 0; y < h; ++y)
            for (int x = 0; x < w; ++x) out[size_t(h - 1 - y) * w + x] = static_cast<float>(transform(data[off + size_t(y) * w + x]));
        return out;
    };
    Composite simulated(w, h), truth(w, h), overlayImage(w, h);
    for (size_t c = 0; c < s.channels.size(); ++c) {
        const ChannelState& ch = stackChannels[c];
        if (!ch.visible) continue;
        const ChannelComparison& cc = s.channels[c];
        const Window window{ch.low, ch.high};
        simulated.add(flipped(cc.simulated, [](double v) { return v; }).data(), window, ch.colour);
        // The truth through the fit, so it shares the simulated image's window.
        truth.add(flipped(cc.truth, [&](double v) { return cc.fitScale * v + cc.fitOffset; }).data(), window, ch.colour);
    }
    const int active = std::clamp(activeStackChannel, 0, static_cast<int>(s.channels.size()) - 1);
    const ChannelComparison& cc = s.channels[size_t(active)];
    const Window window{stackChannels[size_t(active)].low, stackChannels[size_t(active)].high};
    overlayImage.add(flipped(cc.simulated, [](double v) { return v; }).data(), window, {1, 0, 1});
    overlayImage.add(flipped(cc.truth, [&](double v) { return cc.fitScale * v + cc.fitOffset; }).data(), window, {0, 1, 0});
    const std::vector<float> residual = flipped(cc.residual, [](double v) { return v; });
    std::vector<uint8_t> difference(size_t(w) * h * 3);
    for (size_t i = 0; i < residual.size(); ++i) {
        const auto rgb = divergingColour(residual[i], 3 * cc.residualRms);
        std::copy(rgb.begin(), rgb.end(), difference.begin() + static_cast<std::ptrdiff_t>(3 * i));
    }
    const double pix = s.info.pixelSizeUm;
    const Vec3 origin(0.5 * pix, 0.5 * pix, 0);
    setImageRgb(comparePanels[0].image, {w, h, 1}, origin, {pix, pix, 1}, simulated.rgb8());
    setImageRgb(comparePanels[1].image, {w, h, 1}, origin, {pix, pix, 1}, truth.rgb8());
    setImageRgb(comparePanels[2].image, {w, h, 1}, origin, {pix, pix, 1}, overlayImage.rgb8());
    setImageRgb(comparePanels[3].image, {w, h, 1}, origin, {pix, pix, 1}, difference);
    char t[200];
    std::snprintf(t, sizeof t, "simulated, %s   plane %d / %d", s.valueUnit(), plane + 1, s.info.planes);
    comparePanels[0].title->SetInput(t);
    comparePanels[1].title->SetInput("ground truth: a c + b");
    comparePanels[2].title->SetInput((cc.name + ": simulated (magenta), truth (green)").c_str());
    std::snprintf(t, sizeof t, "%s: simulated - truth (+-%.3g)", cc.name.c_str(), 3 * cc.residualRms);
    comparePanels[3].title->SetInput(t);
}

void Viewer::Impl::updateExr() {
    if (!exr || !exrView.renderer) return;
    const std::vector<uint8_t> rgb = spectralImageRgb8(*exr, exrLayer, exrBand, exrExposure, cmf);
    setImageRgb(exrView.image, {exr->width, exr->height, 1}, Vec3(0.5, 0.5, 0), {1, 1, 1}, rgb);
    const SpectralLayerImage& layer = exr->layers[exrLayer];
    char t[200];
    const std::string layerName = layer.prefix.empty() ? "main layer" : layer.prefix + " layer";
    if (exrBand < 0)
        std::snprintf(t, sizeof t, "%s   %s   sRGB composite   exposure x%.3g", options.exr->filename().string().c_str(), layerName.c_str(),
                      exrExposure);
    else
        std::snprintf(t, sizeof t, "%s   %s   band %d / %zu: %.1f nm   exposure x%.3g", options.exr->filename().string().c_str(),
                      layerName.c_str(), exrBand + 1, layer.bands.size(), layer.bands[size_t(exrBand)].lambdaNm, exrExposure);
    exrView.title->SetInput(t);
}

void Viewer::Impl::updateStatus() {
    if (!statusBar) return;
    for (auto& e : legendEntries) statusBar->RemoveActor2D(e);
    legendEntries.clear();
    const std::vector<ChannelState>& chs = currentChannels();
    double x = 8;
    const double y = 26;
    auto addEntry = [&](const std::string& text, const Colour& colour) {
        auto t = makeText(13, colour);
        t->SetInput(text.c_str());
        t->SetPosition(x, y);
        statusBar->AddActor2D(t);
        legendEntries.push_back(t);
        x += 7.5 * static_cast<double>(text.size()) + 14;
    };
    if (view == ViewPreset::Exr) {
        addEntry("EXR: drag right to change the exposure, arrows for bands, L for layers", {0.9, 0.9, 0.9});
    } else {
        for (size_t c = 0; c < chs.size(); ++c) {
            char text[160];
            std::snprintf(text, sizeof text, "%s%zu %s %.3g-%.3g %s%s", static_cast<int>(c) == activeChannel() ? ">" : "", c + 1,
                          chs[c].name.c_str(), chs[c].low, chs[c].high, chs[c].units.c_str(), chs[c].visible ? "" : " (off)");
            addEntry(text, chs[c].visible ? Colour(chs[c].colour) : Colour{0.45, 0.45, 0.45});
        }
        if (inCompare()) {
            const ChannelComparison& cc = stack->channels[size_t(std::clamp(activeStackChannel, 0, static_cast<int>(chs.size()) - 1))];
            const std::string truthUnits = cc.truthChannel >= 0 ? specimenChannels[size_t(cc.truthChannel)].units : "";
            char text[200];
            std::snprintf(text, sizeof text, "%s: a = %.4g %s/%s, b = %.4g %s, r = %.3f", stack->file.filename().string().c_str(), cc.fitScale,
                          stack->valueUnit(), truthUnits.c_str(), cc.fitOffset, stack->valueUnit(), cc.correlation);
            addEntry(text, {0.8, 0.8, 0.8});
        }
        std::string mode = blend == BlendMode::Mip ? "MIP" : "composite";
        mode += volume ? std::string(" (") + (useGpuMapper ? "gpu" : "cpu") + ")" : "";
        addEntry(mode, {0.8, 0.8, 0.8});
    }
    for (const std::string& w : warnings) addEntry("note: " + w, {1, 0.6, 0.3});
    threeD.title->SetInput(("3D   " + std::string(blend == BlendMode::Mip ? "maximum intensity projection" : "composite")).c_str());
}

void Viewer::Impl::resetSliceCamera(View& v) {
    const auto [lo, hi] = volume->boundsUm();
    const int a = v.normalAxis == 0 ? 1 : 0, b = v.normalAxis == 2 ? 1 : 2;
    fitImageCamera(v, hi[a] - lo[a], hi[b] - lo[b], 0.5 * (lo[a] + hi[a]), 0.5 * (lo[b] + hi[b]));
}

void Viewer::Impl::fitImageCamera(View& v, double widthUnits, double heightUnits, double centreA, double centreB) {
    vtkCamera* cam = v.renderer->GetActiveCamera();
    cam->ParallelProjectionOn();
    const int n = v.kind == ViewPreset::SliceXy || v.kind == ViewPreset::Compare || v.kind == ViewPreset::Exr ? 2 : v.normalAxis;
    const int a = n == 0 ? 1 : 0, b = n == 2 ? 1 : 2;
    Vec3 focal;
    focal[a] = centreA;
    focal[b] = centreB;
    focal[n] = n == 2 && volume && v.kind == ViewPreset::SliceXy ? planeZUm(plane) : crosshairUm[n];
    if (v.kind == ViewPreset::Compare || v.kind == ViewPreset::Exr) focal[2] = 0;
    // XY seen from +z, XZ from -y, YZ from +x, each with z (or y) up.
    Vec3 toCamera(0, 0, 1), up(0, 1, 0);
    if (n == 1) toCamera = Vec3(0, -1, 0), up = Vec3(0, 0, 1);
    if (n == 0) toCamera = Vec3(1, 0, 0), up = Vec3(0, 0, 1);
    const double distance = 10 * std::max({widthUnits, heightUnits, 1.0});
    cam->SetFocalPoint(focal.x, focal.y, focal.z);
    const Vec3 pos = focal + toCamera * distance;
    cam->SetPosition(pos.x, pos.y, pos.z);
    cam->SetViewUp(up.x, up.y, up.z);
    const int* size = v.renderer->GetSize();
    const double aspect = size[1] > 0 ? double(size[0]) / size[1] : 1.0;
    cam->SetParallelScale(0.52 * std::max(heightUnits, widthUnits / aspect));
    v.renderer->ResetCameraClippingRange();
}

void Viewer::Impl::resetCameras() {
    if (volume)
        for (View* v : {&sliceXy, &sliceXz, &sliceYz}) resetSliceCamera(*v);
    if (stack) {
        const double pix = stack->info.pixelSizeUm, w = stack->info.width * pix, h = stack->info.height * pix;
        fitImageCamera(comparePanels[0], w, h, 0.5 * w, 0.5 * h);
    }
    if (exr) fitImageCamera(exrView, exr->width, exr->height, 0.5 * exr->width, 0.5 * exr->height);
    setThreeDPreset(view == ViewPreset::Top || view == ViewPreset::Front || view == ViewPreset::Side ? view : ViewPreset::ThreeD);
}

void Viewer::Impl::setThreeDPreset(ViewPreset preset) {
    vtkCamera* cam = threeD.renderer->GetActiveCamera();
    // Top looks down -z like the objective of the samples; front from -y; side from +x; 3D obliquely.
    Vec3 toCamera(0.35, -0.75, 0.55), up(0, 0, 1);
    if (preset == ViewPreset::Top) toCamera = Vec3(0, 0, 1), up = Vec3(0, 1, 0);
    if (preset == ViewPreset::Front) toCamera = Vec3(0, -1, 0);
    if (preset == ViewPreset::Side) toCamera = Vec3(1, 0, 0);
    cam->SetFocalPoint(0, 0, 0);
    cam->SetPosition(toCamera.x, toCamera.y, toCamera.z);
    cam->SetViewUp(up.x, up.y, up.z);
    // Frame the volume (or the rest of the specimen) and the stack, not the long cone or sheet.
    std::optional<std::array<Vec3, 2>> box;
    if (volume) {
        box = volume->boundsUm();
    } else {
        box = geometryBoundsUm(specimen);
    }
    if (overlay)
        for (int k : {0, overlay->planes() - 1})
            for (const Vec3& p : overlay->fieldOfView(k).cornersUm) {
                if (!box) box = std::array<Vec3, 2>{p, p};
                for (int a = 0; a < 3; ++a) (*box)[0][a] = std::min((*box)[0][a], p[a]), (*box)[1][a] = std::max((*box)[1][a], p[a]);
            }
    if (box) {
        double bounds[6] = {(*box)[0].x, (*box)[1].x, (*box)[0].y, (*box)[1].y, (*box)[0].z, (*box)[1].z};
        threeD.renderer->ResetCamera(bounds);
    } else {
        threeD.renderer->ResetCamera();
    }
    threeD.renderer->ResetCameraClippingRange();
}

}  // namespace fluorosim::viewer
