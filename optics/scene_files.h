#pragma once
// Loads a scene file with everything the CLI provides: the spectral database for spectra and dyes,
// and the optics library for light sheets.
#include <filesystem>

#include "database.h"
#include "optics/light_sheet.h"
#include "scene/scene_loader.h"

namespace fluorosim::optics {

inline Scene loadSceneFile(const std::filesystem::path& file, const spectra::Database& db) {
    return loadScene(
        file, [&db](const std::string& ref, const std::filesystem::path& base) { return db.resolve(ref, base); },
        [&db](const std::string& name, std::optional<double> ec, std::optional<double> qy) { return db.fluorophore(name, ec, qy); },
        [](const LightSheetSpec& spec) { return makeLightSheet(spec); });
}

}  // namespace fluorosim::optics
