// Reading glTF accessors for the loader (gltf_loader.cpp): every element bounds-checked against its
// buffer view and buffer before it is read (tinygltf checks neither), integer components dequantized
// as KHR_mesh_quantization and the core spec define them, sparse accessors applied. Internal to
// src/scene; failures throw gltf::LoadFailure with the accessor named.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "scene/gltf_file.h"

namespace vksonar::gltf {

// The bytes of an accessor inside its buffer view: element i at data + stride * i.
struct AccessorView {
    const unsigned char* data = nullptr; // first element
    std::size_t stride = 0;
    std::size_t count = 0;
};

// Bytes of one component of a glTF component type (5120 byte ... 5126 float), 0 if unknown.
std::size_t component_bytes(int component_type);

// Components of a glTF accessor type (SCALAR 1 ... MAT4 16), 0 if unknown.
int type_components(int type);

// The view of accessor `index` (a dense accessor with a bufferView), `element_bytes` per element,
// checked to lie inside its buffer view and buffer. `where` names it in errors.
AccessorView view_accessor(const tinygltf::Model& model, int index, std::size_t element_bytes,
                           const std::string& where);

// Every element of accessor `index` as count x components doubles: floats as they are, integers as
// their value or, when the accessor is normalized, as the glTF rule maps them (unsigned c / max,
// signed max(c / max, -1)). An accessor without a bufferView is zeros; a sparse accessor's
// substitutions are applied (indices bounds-checked). Counts are checked against the bytes present
// before anything of that size is allocated.
std::vector<double> read_accessor(const tinygltf::Model& model, int index, const std::string& where);

// The same values appended to `out`, each as static_cast<T> of the double read_accessor returns (T is
// double, float or std::uint32_t), with no array of doubles in between: `out` grows by exactly count x
// components. On failure `out` may have grown; the load fails as a whole.
template <class T>
void append_accessor(const tinygltf::Model& model, int index, const std::string& where, std::vector<T>& out);

} // namespace vksonar::gltf
