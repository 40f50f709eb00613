#include "scene/scene.h"

#include "core/errors.h"

namespace fluorosim {

std::optional<FluorescenceModel> fluorescenceModelFromName(const std::string& name) {
    if (name == "full") return FluorescenceModel::Full;
    if (name == "paper") return FluorescenceModel::Paper;
    if (name == "none") return FluorescenceModel::None;
    return std::nullopt;
}

std::optional<Integrator> integratorFromName(const std::string& name) {
    if (name == "path") return Integrator::Path;
    if (name == "mnee") return Integrator::Mnee;
    if (name == "light") return Integrator::Light;
    return std::nullopt;
}

const char* integratorName(Integrator integrator) {
    switch (integrator) {
        case Integrator::Mnee: return "mnee";
        case Integrator::Light: return "light";
        case Integrator::Path: break;
    }
    return "path";
}

const Spectrum& emissionSpectrum(const Light& light) {
    return std::visit(
        [](const auto& l) -> const Spectrum& {
            using T = std::decay_t<decltype(l)>;
            if constexpr (std::is_same_v<T, AreaLight>) return l.emission.radiance;
            else if constexpr (std::is_same_v<T, BeamLight>) return l.profile->spectrum();
            else return l.intensity;
        },
        light);
}

const char* fluorescenceModelName(FluorescenceModel model) {
    switch (model) {
        case FluorescenceModel::Full: return "full";
        case FluorescenceModel::Paper: return "paper";
        case FluorescenceModel::None: return "none";
    }
    return "full";
}

void Scene::addAreaLight(uint32_t shape, AreaEmission emission) {
    AreaLight light{shape, std::move(emission), {}};
    if (!geometry.isSphere(shape)) {
        const TriangleMesh& m = geometry.mesh(shape);
        double sum = 0;
        for (size_t t = 0; t < m.indices.size(); t += 3) {
            const Vec3 &a = m.positions[m.indices[t]], &b = m.positions[m.indices[t + 1]], &c = m.positions[m.indices[t + 2]];
            sum += 0.5 * length(cross(b - a, c - a));
            light.triangleCdf.push_back(sum);
        }
        if (!(sum > 0)) throw ConfigError("shape \"" + shapes[shape].name + "\": an area light needs a non-zero area");
        for (double& v : light.triangleCdf) v /= sum;
    }
    shapes[shape].areaLight = static_cast<int>(lights.size());
    lights.emplace_back(std::move(light));
}

void Scene::finalize() {
    if (shapes.size() != geometry.shapeCount()) throw Error("scene: shape table and geometry disagree");
    geometry.commit();
}

}  // namespace fluorosim
