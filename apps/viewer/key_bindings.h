#pragma once
// The viewer's key and mouse bindings, after napari, BigDataViewer and 3D Slicer. One table serves
// the `?` overlay and docs/viewer.md (a test checks that the page lists every entry).
#include <vector>

namespace fluorosim::viewer {

struct KeyBinding {
    const char* keys;
    const char* action;
};

const std::vector<KeyBinding>& keyBindings();

}  // namespace fluorosim::viewer
