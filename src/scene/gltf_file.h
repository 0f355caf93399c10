// Reading a .gltf / .glb file into a tinygltf::Model, for Scene::load_gltf (gltf_loader.cpp): the
// checks that come before tinygltf sees the bytes, and tinygltf itself. Internal to src/scene.
#pragma once
#if defined(__GNUC__)
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wshadow"
#pragma GCC diagnostic ignored "-Wunused-parameter"
#pragma GCC diagnostic ignored "-Wmissing-field-initializers"
#endif
#define TINYGLTF_NO_STB_IMAGE
#define TINYGLTF_NO_STB_IMAGE_WRITE
#define TINYGLTF_NO_EXTERNAL_IMAGE
#include <tiny_gltf.h>
#if defined(__GNUC__)
#pragma GCC diagnostic pop
#endif

#include <cstddef>
#include <string>
#include <vector>

#include "vksonar/result.h"

namespace vksonar::gltf {

// What went wrong while loading; load_gltf prefixes the file's path and returns it as an Error.
// Errors travel as this exception inside src/scene only, never across the API.
struct LoadFailure {
    ErrorCode code;
    std::string what; // without the file prefix
};

[[noreturn]] void fail(ErrorCode code, std::string what);

// tinygltf messages are multi-line and may embed a whole data: URI; make them one short line.
std::string one_line(const std::string& text, std::size_t max_chars = 300);

// Reads and checks the file at `path` (size, GLB container, JSON nesting depth, required extensions)
// and has tinygltf parse it, buffers included. An external buffer's uri is relative to the file's
// folder and must resolve (symlinks and ".." followed) to a regular file of exactly its byteLength
// inside `asset_root` (empty: the file's folder); images are never read. tinygltf's warnings are
// appended to `warnings`. Throws LoadFailure.
tinygltf::Model read_model(const std::string& path, const std::string& asset_root, std::vector<std::string>& warnings);

} // namespace vksonar::gltf
