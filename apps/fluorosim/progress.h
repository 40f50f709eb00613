#pragma once
// A one-line progress bar with ETA on stderr (redrawn only when stderr is a terminal, otherwise
// printed every 10%). The ETA extrapolates the rate since progress first moved, and shows "--" until
// it has seen 2 % and a second of work.
#include <chrono>
#include <string>

namespace fluorosim::app {

class ProgressBar {
public:
    explicit ProgressBar(std::string label);
    void update(double fraction);
    void finish();

private:
    std::string label_;
    std::chrono::steady_clock::time_point start_;
    bool tty_;
    int lastDecile_ = -1;
    double lastDraw_ = -1;
    double firstFraction_ = -1, firstElapsed_ = 0;  // when progress first moved
};

}  // namespace fluorosim::app
