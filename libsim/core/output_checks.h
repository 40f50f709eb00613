#pragma once
// Checks an output path before a long run, so a typo or a read-only folder fails at once.
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <string>

#include "core/errors.h"

namespace fluorosim {

// Throws IoError naming `out` when its folder is missing or cannot be written (probed with a file).
inline void requireWritableFolder(const std::filesystem::path& out) {
    namespace fs = std::filesystem;
    if (fs::is_directory(out)) throw IoError(out.string() + ": is a folder");
    const fs::path dir = out.has_parent_path() ? out.parent_path() : fs::path(".");
    if (!fs::is_directory(dir)) throw IoError(out.string() + ": output folder \"" + dir.string() + "\" does not exist");
    const fs::path probe = dir / (".fluorosim-write-test-" + std::to_string(::getpid()));
    std::ofstream f(probe);
    if (!f) throw IoError(out.string() + ": output folder \"" + dir.string() + "\" is not writable");
    f.close();
    fs::remove(probe);
}

}  // namespace fluorosim
