#pragma once
// The microscope of a scene: detection objective, focal plane, camera, channels (which lights each
// switches on, with its excitation, dichroic and emission filters) and the z-stack, as parsed from a
// scene's "microscope" block (docs/optics.md) or built in code. Immutable: a plane at some offset is
// an argument (lightsAt, focalPlaneAt), never a mutation, so several planes can render at once.
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "optics/detector.h"
#include "optics/filter.h"
#include "scene/scene.h"

namespace fluorosim::spectra {
class Database;
}

namespace fluorosim::optics {

struct ObjectiveOptions {
    double na = 0.8;
    double magnification = 16;
    double immersionIndex = 1.33;
    double workingDistanceMm = 1.0;  // where camera paths start, in front of the focal plane
    void validate() const;           // NA < immersion index, positive values; ConfigError naming them
    double collectionHalfAngle() const;  // asin(NA / n)
};

struct FocalPlane {
    Vec3 centreMm;                  // of the field of view, in focus
    Vec3 towardObjective{0, 0, 1};  // unit axis from the sample to the objective
    Vec3 up{0, 1, 0};               // image rows run along -up
    void validate() const;          // finite, non-zero, up not parallel to the axis
    // The image's frame: the unit axis toward the objective, `right` along the columns (up × axis) and
    // `imageUp` = axis × right, the part of `up` in the plane (rows run along -imageUp).
    Vec3 axis() const { return normalize(towardObjective); }
    Vec3 right() const { return normalize(cross(up, axis())); }
    Vec3 imageUp() const { return cross(axis(), right()); }
};

struct MicroscopeChannel {
    std::string name;
    std::vector<size_t> lights;  // indices into the scene's lights
    FilterSet filters;           // excitation, dichroic, emission
    Filter emissionPath = Filter::open();  // dichroic transmission times emission filter
    bool filteredExcitation = false;       // an excitation filter or a dichroic acts on the lights
    double excitationNm = 0, emissionNm = 0;  // for the stack's metadata
    std::vector<std::string> warnings;        // channelDyeWarnings, printed only when the channel is acquired
};

// Warns when a channel's emission path passes almost none (< 1e-3) of every dye its own laser lines excite
// (above 2 % of the dye's peak), or when its lines excite none of the scene's dyes.
std::vector<std::string> channelDyeWarnings(const Scene& scene, const MicroscopeChannel& channel);

struct StackGeometry {
    int planes = 1;
    double stepMm = 0.001;
};

struct Microscope {
    ObjectiveOptions objective;
    FocalPlane focus;
    DetectorOptions detector;
    int width = 64, height = 64;
    std::vector<MicroscopeChannel> channels;
    StackGeometry stack;

    // Parses the scene's "microscope" block; errors name the scene file and the field. Also checks
    // what acquisition cannot do (emitting shapes, channels without a laser line).
    static Microscope fromScene(const Scene& scene, const spectra::Database& db);
    // Throws ConfigError for inconsistent values (sizes, a stack larger than the memory cap, light
    // indices outside the scene).
    void validate(const Scene& scene) const;
    std::vector<std::string> warnings;  // of the microscope as a whole; each channel has its own

    double pixelSizeMm() const { return detector.pixelPitchUm * 1e-3 / objective.magnification; }
    // Plane k of the stack sits at this offset along the detection axis from the focus centre.
    double planeOffsetMm(int plane) const { return (plane - 0.5 * (stack.planes - 1)) * stack.stepMm; }
    FocalPlane focalPlaneAt(double offsetMm) const;
    // The channel's lights for a plane: light sheets moved with the focal plane, every beam seen
    // through the channel's excitation filter and dichroic. The scene is not changed.
    std::vector<Light> lightsAt(const Scene& scene, const MicroscopeChannel& channel, double offsetMm) const;
    // The channel named `name`; ConfigError listing the channels otherwise.
    size_t channelIndex(const std::string& name) const;
    // The channels named, in that order, or every channel when `names` is empty; ConfigError prefixed
    // with `what` (the option that named them) for a name that is not a channel.
    std::vector<size_t> selectChannels(const std::vector<std::string>& names, const std::string& what) const;
};

// Bytes a stack of this size holds in memory (float expected electrons and standard errors, 16-bit
// counts), and the cap above which acquisition refuses it.
size_t stackBytes(int width, int height, int planes, int channels);
inline constexpr size_t kMaxStackBytes = size_t(8) << 30;

}  // namespace fluorosim::optics
