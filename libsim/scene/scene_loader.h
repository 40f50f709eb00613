#pragma once
// Loads a scene from JSON with explicit units (docs/scene-format.md). Every field is validated;
// errors are ConfigError/IoError messages of the form "<file>: <json path>: <problem> (got <value>)".
#include <filesystem>
#include <functional>
#include <optional>
#include <string>

#include "media/fluorophore.h"
#include "scene/scene.h"
#include "spectral/tabulated_spectrum.h"

namespace fluorosim {

// Resolves named spectra ("illuminant:D65", "filter:...", a CSV path) relative to the scene's folder.
// Provided by the spectral database (spectra/), which libsim does not depend on.
using SpectrumResolver = std::function<TabulatedSpectrum(const std::string& reference, const std::filesystem::path& baseDir)>;

// Looks a dye up by name or alias (the spectral database); throws ConfigError with suggestions.
using DyeResolver = std::function<Fluorophore(const std::string& name, std::optional<double> extinctionPeak,
                                              std::optional<double> quantumYield)>;

// Builds the profile of a "light_sheet" light (optics/, which libsim does not depend on); throws
// ConfigError for bad parameters.
using BeamResolver = std::function<std::shared_ptr<BeamProfile>(const LightSheetSpec& spec)>;

Scene loadScene(const std::filesystem::path& file, const SpectrumResolver& resolve, const DyeResolver& dyes = {},
                const BeamResolver& beams = {});
// Same, from a JSON text; `file` is used for messages and relative paths.
Scene loadSceneFromString(const std::string& text, const std::filesystem::path& file, const SpectrumResolver& resolve,
                          const DyeResolver& dyes = {}, const BeamResolver& beams = {});

}  // namespace fluorosim
