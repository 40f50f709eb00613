#include "progress.h"

#include <unistd.h>

#include <cmath>
#include <cstdio>

namespace fluorosim::app {
namespace {

std::string formatSeconds(double s) {
    if (!std::isfinite(s)) return "--";
    char buf[32];
    const int t = static_cast<int>(s + 0.5);
    if (t >= 3600) std::snprintf(buf, sizeof buf, "%dh%02dm", t / 3600, (t / 60) % 60);
    else if (t >= 60) std::snprintf(buf, sizeof buf, "%dm%02ds", t / 60, t % 60);
    else std::snprintf(buf, sizeof buf, "%ds", t);
    return buf;
}

}  // namespace

ProgressBar::ProgressBar(std::string label)
    : label_(std::move(label)), start_(std::chrono::steady_clock::now()), tty_(isatty(fileno(stderr)) != 0) {}

void ProgressBar::update(double f) {
    const double elapsed = std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count();
    // The rate since the first progress, so that set-up before it (a scene, a PSF, the computed image's
    // lattice) is not extrapolated over the run; no ETA until 2 % and a second of work have been seen.
    if (firstFraction_ < 0 && f > 0) firstFraction_ = f, firstElapsed_ = elapsed;
    double eta = NAN;
    if (firstFraction_ >= 0 && f - firstFraction_ >= 0.02 && elapsed - firstElapsed_ >= 1)
        eta = (elapsed - firstElapsed_) * (1 - f) / (f - firstFraction_);
    if (f >= 1) eta = 0;
    if (tty_) {
        if (elapsed - lastDraw_ < 0.1 && f < 1) return;
        lastDraw_ = elapsed;
        const int width = 30, filled = static_cast<int>(f * width);
        std::string bar(static_cast<size_t>(filled), '#');
        bar.resize(width, '.');
        std::fprintf(stderr, "\r%s [%s] %5.1f%%  elapsed %s  ETA %s   ", label_.c_str(), bar.c_str(), 100 * f,
                     formatSeconds(elapsed).c_str(), formatSeconds(eta).c_str());
    } else {
        const int decile = static_cast<int>(f * 10);
        if (decile == lastDecile_) return;
        lastDecile_ = decile;
        std::fprintf(stderr, "%s %3d%%  elapsed %s  ETA %s\n", label_.c_str(), decile * 10, formatSeconds(elapsed).c_str(),
                     formatSeconds(eta).c_str());
    }
    std::fflush(stderr);
}

void ProgressBar::finish() {
    if (tty_) std::fprintf(stderr, "\n");
}

}  // namespace fluorosim::app
