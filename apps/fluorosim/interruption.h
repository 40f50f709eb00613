#pragma once
// SIGINT/SIGTERM for long commands (render; acquire can use it too): the first signal sets a flag the
// command polls, so it can stop at a safe point and write what it has finished; a second signal ends
// the process at once (the default action), for someone who does not want to wait for the write.
#include <atomic>
#include <csignal>

namespace fluorosim::app {

inline std::atomic<bool>& interruptFlag() {
    static std::atomic<bool> flag{false};
    return flag;
}

extern "C" inline void onInterruptSignal(int sig) {
    interruptFlag().store(true);
    std::signal(sig, SIG_DFL);
}

// Installs the handlers and returns the flag they set.
inline const std::atomic<bool>& installInterruptHandlers() {
    std::signal(SIGINT, onInterruptSignal);
    std::signal(SIGTERM, onInterruptSignal);
    return interruptFlag();
}

}  // namespace fluorosim::app
