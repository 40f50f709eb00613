#include <assimp/Importer.hpp>
#include <assimp/postprocess.h>
#include <assimp/scene.h>

#include <filesystem>
#include <new>
#include <stdexcept>

#include "core/errors.h"
#include "core/memory_cap.h"
#include "core/message.h"
#include "geometry/geometry.h"

namespace fluorosim {

// Assimp's importers hold several copies of the mesh (file, parsed lists, post-processed mesh), and the
// scene then holds it in double precision and in Embree's BVH. Measured peaks: 15 bytes per byte of
// file for a 77.5 MB ASCII OBJ of 2M triangles, 19 for the same mesh as a 38 MB binary PLY.
constexpr double kImportBytesPerFileByte = 32;

TriangleMesh loadMesh(const std::string& file) {
    namespace fs = std::filesystem;
    std::error_code ec;
    if (!fs::exists(file, ec)) throw IoError(file + ": mesh file not found");
    if (fs::is_directory(file, ec)) throw IoError(file + ": is a folder, expected a mesh file (OBJ, PLY, ...)");
    if (!fs::is_regular_file(file, ec)) throw IoError(file + ": not a regular file, expected a mesh file (OBJ, PLY, ...)");
    const auto size = fs::file_size(file, ec);
    if (!ec) requireMemory(kImportBytesPerFileByte * static_cast<double>(size), file + ": importing a mesh file of " +
                                                                                  formatBytes(static_cast<double>(size)));
    Assimp::Importer importer;
    const aiScene* scene = nullptr;
    try {
        scene = importer.ReadFile(file, aiProcess_Triangulate | aiProcess_JoinIdenticalVertices | aiProcess_PreTransformVertices |
                                            aiProcess_SortByPType);
    } catch (const std::bad_alloc&) {
        // A corrupt header can announce billions of elements.
        throw IoError(file + ": cannot read mesh: the importer ran out of memory (is the file corrupt?)");
    } catch (const std::length_error&) {
        throw IoError(file + ": cannot read mesh: the importer ran out of memory (is the file corrupt?)");
    }
    if (!scene || !scene->mRootNode) throw IoError(file + ": cannot read mesh: " + excerpt(importer.GetErrorString(), 200));
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
