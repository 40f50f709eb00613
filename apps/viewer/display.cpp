// The display check: Debian's VTK 9.1 renders only through X (no OSMesa or EGL), and a failed X
// connection inside VTK aborts the process, so the viewer looks for a display first.
#include <X11/Xlib.h>

#include <cstdlib>
#include <string>

#include "viewer/viewer.h"

namespace fluorosim::viewer {

void requireDisplay() {
    const char* name = std::getenv("DISPLAY");
    if (!name || !*name)
        throw DisplayError("no X display (DISPLAY is not set); the viewer needs one: run it under xvfb-run -a, or use a desktop session");
    Display* display = XOpenDisplay(name);
    if (!display)
        throw DisplayError("cannot open X display \"" + std::string(name) + "\"; is the X server running (xvfb-run -a starts one)?");
    int opcode = 0, event = 0, error = 0;
    const bool glx = XQueryExtension(display, "GLX", &opcode, &event, &error);
    XCloseDisplay(display);
    if (!glx) throw DisplayError("X display \"" + std::string(name) + "\" has no GLX extension, so VTK cannot render through OpenGL");
}

}  // namespace fluorosim::viewer
