#pragma once
// A one-line progress bar with ETA on stderr (redrawn only when stderr is a terminal, otherwise
// printed every 10%).
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
};

}  // namespace fluorosim::app
