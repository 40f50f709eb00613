#include <assimp/Importer.hpp>
#include <assimp/postprocess.h>
#include <assimp/scene.h>

#include <filesystem>

#include "core/errors.h"
#include "geometry/geometry.h"

namespace fluorosim {

TriangleMesh loadMesh(const std::string& file) {
    if (!std::filesystem::exists(file)) throw IoError(file + ": mesh file not found");
    Assimp::Importer importer;
    const aiScene* scene = importer.ReadFile(file, aiProcess_Triangulate | aiProcess_JoinIdenticalVertices |
                                                       aiProcess_PreTransformVertices | aiProcess_SortByPType);
    if (!scene || !scene->mRootNode) throw IoError(file + ": cannot read mesh: " + importer.GetErrorString());
    TriangleMesh out;
    for (unsigned m = 0; m < scene->mNumMeshes; ++m) {
        const aiMesh* mesh = scene->mMeshes[m];
        const auto base = static_cast<uint32_t>(out.positions.size());
        for (unsigned v = 0; v < mesh->mNumVertices; ++v)
            out.positions.emplace_back(mesh->mVertices[v].x, mesh->mVertices[v].y, mesh->mVertices[v].z);
        for (unsigned f = 0; f < mesh->mNumFaces; ++f) {
            const aiFace& face = mesh->mFaces[f];
            if (face.mNumIndices != 3) continue;  // points and lines carry no area
            for (int k = 0; k < 3; ++k) out.indices.push_back(base + face.mIndices[k]);
        }
    }
    if (out.indices.empty()) throw ConfigError(file + ": mesh has no triangles");
    return out;
}

}  // namespace fluorosim
