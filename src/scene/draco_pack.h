// Writing a glTF scene as KHR_draco_mesh_compression, with draco's own encoder (draco::Encoder): what
// Blender's compressed export does, for the Draco tests and `vksonar bench load`. Internal to the
// project (not part of the API).
#pragma once

#include <string>

namespace vksonar::gltf {

// Reads the glTF at `in` (through the loader's checks) and writes `out` (.glb, or .gltf with the
// buffer embedded as a data: URI) with every triangle primitive's POSITION and indices replaced by one
// Draco stream, positions quantized to `position_bits` (0: not quantized), the extension required;
// nodes, scenes, materials and their extras kept, other vertex attributes dropped. Morph targets,
// non-float positions, non-triangle primitives and node extensions are refused. Returns "" on success,
// else the reason in one line (also when this build has no libdraco).
std::string write_draco_gltf(const std::string& in, const std::string& out, int position_bits, int speed = 5);

} // namespace vksonar::gltf
