#include "viewer/key_bindings.h"

namespace fluorosim::viewer {

const std::vector<KeyBinding>& keyBindings() {
    static const std::vector<KeyBinding> kBindings = {
        {"1-9", "show or hide channel N and make it the active channel"},
        {"Shift+1-9", "show channel N alone"},
        {"0", "show every channel"},
        {"Tab", "make the next channel active"},
        {"Up / Down, wheel in XY or compare", "next / previous plane (z)"},
        {"PageUp / PageDown, Home / End", "10 planes up / down, first / last plane"},
        {"Left / Right", "previous / next plane; in the EXR view, previous / next band"},
        {"right drag", "window (horizontal) and level (vertical) of the active channel"},
        {"A / Shift+A", "auto contrast of the active channel / of every channel"},
        {"M", "maximum intensity projection or composite volume rendering"},
        {"I", "isosurface of the active channel at its level, on or off"},
        {"N", "neurons (SWC tubes) on or off"},
        {"O", "microscope (light sheet, collection cone, field of view) on or off"},
        {"V", "next view: overview, 3D, top, front, side, XY, XZ, YZ, compare, EXR"},
        {"C", "compare view: simulated stack, ground truth, overlay, difference"},
        {"E", "simulated counts or expected electrons (when both files exist)"},
        {"L", "next EXR layer (main, elastic, fluorescent)"},
        {"R", "reset the cameras and the crosshair"},
        {"S", "screenshot (PNG in the screenshot folder)"},
        {"Z / T", "z-sweep / turntable movie (PNG frames in the screenshot folder)"},
        {"?", "this help"},
        {"Q / Esc", "quit"},
        {"left click in a slice", "move the crosshair (the other slices follow)"},
        {"left drag", "rotate the 3D view; pan a slice or an image"},
        {"middle drag", "pan"},
        {"wheel in 3D, Ctrl+wheel elsewhere", "zoom"},
        {"wheel in XZ / YZ", "move that slice along y / x"},
    };
    return kBindings;
}

}  // namespace fluorosim::viewer
