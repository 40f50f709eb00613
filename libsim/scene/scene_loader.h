#pragma once
// Loads a scene from JSON with explicit units (docs/scene-format.md). Every field is validated;
// errors are ConfigError/IoError messages of the form "<file>: <json path>: <problem> (got <value>)".
#include <filesystem>
#include <functional>
#include <string>

#include "scene/scene.h"
#include "spectral/tabulated_spectrum.h"

namespace fluorosim {

// Resolves named spectra ("illuminant:D65", "filter:...", a CSV path) relative to the scene's folder.
// Provided by the spectral database (spectra/), which libsim does not depend on.
using SpectrumResolver = std::function<TabulatedSpectrum(const std::string& reference, const std::filesystem::path& baseDir)>;

Scene loadScene(const std::filesystem::path& file, const SpectrumResolver& resolve);
// Same, from a JSON text; `file` is used for messages and relative paths.
Scene loadSceneFromString(const std::string& text, const std::filesystem::path& file, const SpectrumResolver& resolve);

}  // namespace fluorosim
