// Reading glTF accessors (gltf_accessors.h).
#include "scene/gltf_accessors.h"

#include <algorithm>
#include <cstdint>
#include <cstring>
#include <limits>

namespace vksonar::gltf {

std::size_t component_bytes(int component_type) {
    switch (component_type) {
    case TINYGLTF_COMPONENT_TYPE_BYTE:
    case TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE:
        return 1;
    case TINYGLTF_COMPONENT_TYPE_SHORT:
    case TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT:
        return 2;
    case TINYGLTF_COMPONENT_TYPE_INT:
    case TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT:
    case TINYGLTF_COMPONENT_TYPE_FLOAT:
        return 4;
    default:
        return 0;
    }
}

// Checks, without overflow, that every element of the accessor lies inside its buffer view and
// the view inside its buffer: offset + stride * (count - 1) + element_size <= available.
AccessorView view_accessor(const tinygltf::Model& model, int index, std::size_t element_bytes,
                           const std::string& where) {
    if (index < 0 || std::size_t(index) >= model.accessors.size())
        fail(ErrorCode::parse, where + " does not exist (" + std::to_string(model.accessors.size()) + " accessors)");
    const tinygltf::Accessor& acc = model.accessors[std::size_t(index)];
    if (acc.bufferView < 0 || std::size_t(acc.bufferView) >= model.bufferViews.size())
        fail(ErrorCode::parse, where + " has no valid bufferView (" + std::to_string(acc.bufferView) + ")");
    const tinygltf::BufferView& bv = model.bufferViews[std::size_t(acc.bufferView)];
    const std::string bv_name = "bufferView " + std::to_string(acc.bufferView);
    if (bv.buffer < 0 || std::size_t(bv.buffer) >= model.buffers.size())
        fail(ErrorCode::parse, where + ": " + bv_name + " refers to missing buffer " + std::to_string(bv.buffer));
    const std::vector<unsigned char>& buffer = model.buffers[std::size_t(bv.buffer)].data;
    if (bv.byteOffset > buffer.size() || bv.byteLength > buffer.size() - bv.byteOffset)
        fail(ErrorCode::parse, where + ": " + bv_name + " (offset " + std::to_string(bv.byteOffset) + ", length " +
                                   std::to_string(bv.byteLength) + ") runs past the end of buffer " +
                                   std::to_string(bv.buffer) + " (" + std::to_string(buffer.size()) + " bytes)");
    AccessorView view;
    view.count = acc.count;
    view.stride = bv.byteStride != 0 ? bv.byteStride : element_bytes;
    if (view.stride < element_bytes)
        fail(ErrorCode::parse, where + ": byteStride " + std::to_string(view.stride) +
                                   " is smaller than the element (" + std::to_string(element_bytes) + " bytes)");
    if (acc.count == 0) return view;
    const std::size_t available = bv.byteLength;
    const bool fits = acc.byteOffset <= available && element_bytes <= available - acc.byteOffset &&
                      acc.count - 1 <= (available - acc.byteOffset - element_bytes) / view.stride;
    if (!fits)
        fail(ErrorCode::parse, where + ": count " + std::to_string(acc.count) + " at offset " +
                                   std::to_string(acc.byteOffset) + " (stride " + std::to_string(view.stride) +
                                   ") does not fit in " + bv_name + " (" + std::to_string(available) +
                                   " bytes); buffer shorter than the accessor claims");
    view.data = buffer.data() + bv.byteOffset + acc.byteOffset;
    return view;
}

int type_components(int type) {
    switch (type) {
    case TINYGLTF_TYPE_SCALAR:
        return 1;
    case TINYGLTF_TYPE_VEC2:
        return 2;
    case TINYGLTF_TYPE_VEC3:
        return 3;
    case TINYGLTF_TYPE_VEC4:
        return 4;
    case TINYGLTF_TYPE_MAT2:
        return 4;
    case TINYGLTF_TYPE_MAT3:
        return 9;
    case TINYGLTF_TYPE_MAT4:
        return 16;
    default:
        return 0;
    }
}

namespace {

// One component at p, as the glTF rules read it (little-endian, as every platform vksonar runs on).
double component(const unsigned char* p, int type, bool normalized) {
    switch (type) {
    case TINYGLTF_COMPONENT_TYPE_BYTE: {
        const auto c = static_cast<std::int8_t>(*p);
        return normalized ? std::max(c / 127.0, -1.0) : c;
    }
    case TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE:
        return normalized ? *p / 255.0 : *p;
    case TINYGLTF_COMPONENT_TYPE_SHORT: {
        std::int16_t c;
        std::memcpy(&c, p, 2);
        return normalized ? std::max(c / 32767.0, -1.0) : c;
    }
    case TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT: {
        std::uint16_t c;
        std::memcpy(&c, p, 2);
        return normalized ? c / 65535.0 : c;
    }
    case TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT: {
        std::uint32_t c;
        std::memcpy(&c, p, 4);
        return c;
    }
    case TINYGLTF_COMPONENT_TYPE_INT: {
        std::int32_t c;
        std::memcpy(&c, p, 4);
        return c;
    }
    default: {
        float c;
        std::memcpy(&c, p, 4);
        return c;
    }
    }
}

// A sparse part's bytes: `count` elements of `element_bytes` at `offset` in buffer view `view_index`.
const unsigned char* sparse_bytes(const tinygltf::Model& model, int view_index, std::size_t offset, std::size_t count,
                                  std::size_t element_bytes, const std::string& where) {
    if (view_index < 0 || std::size_t(view_index) >= model.bufferViews.size())
        fail(ErrorCode::parse, where + " has no valid bufferView (" + std::to_string(view_index) + ")");
    const tinygltf::BufferView& bv = model.bufferViews[std::size_t(view_index)];
    if (bv.buffer < 0 || std::size_t(bv.buffer) >= model.buffers.size())
        fail(ErrorCode::parse, where + " refers to missing buffer " + std::to_string(bv.buffer));
    const std::vector<unsigned char>& buffer = model.buffers[std::size_t(bv.buffer)].data;
    const bool fits = bv.byteOffset <= buffer.size() && bv.byteLength <= buffer.size() - bv.byteOffset &&
                      offset <= bv.byteLength && count <= (bv.byteLength - offset) / element_bytes;
    if (!fits)
        fail(ErrorCode::parse, where + ": " + std::to_string(count) + " elements at offset " + std::to_string(offset) +
                                   " do not fit in bufferView " + std::to_string(view_index));
    return buffer.data() + bv.byteOffset + offset;
}

std::size_t total_buffer_bytes(const tinygltf::Model& model) {
    std::size_t total = 0;
    for (const tinygltf::Buffer& b : model.buffers)
        total += b.data.size();
    return total;
}

} // namespace

template <class T>
void append_accessor(const tinygltf::Model& model, int index, const std::string& where, std::vector<T>& out) {
    if (index < 0 || std::size_t(index) >= model.accessors.size())
        fail(ErrorCode::parse, where + " does not exist (" + std::to_string(model.accessors.size()) + " accessors)");
    const tinygltf::Accessor& acc = model.accessors[std::size_t(index)];
    const std::size_t bytes = component_bytes(acc.componentType);
    const int n = type_components(acc.type);
    if (bytes == 0 || n == 0) fail(ErrorCode::parse, where + ": unknown component type or type");
    const std::size_t element_bytes = bytes * std::size_t(n);
    const std::size_t base = out.size();
    if (acc.bufferView >= 0) {
        const AccessorView view = view_accessor(model, index, element_bytes, where); // bounds the count
        out.resize(base + view.count * std::size_t(n));
        T* values = out.data() + base;
        for (std::size_t i = 0; i < view.count; ++i)
            for (int c = 0; c < n; ++c)
                values[i * std::size_t(n) + std::size_t(c)] = static_cast<T>(
                    component(view.data + view.stride * i + bytes * std::size_t(c), acc.componentType, acc.normalized));
    } else {
        // No bufferView: zeros (glTF: "MUST be initialized with zeros"), with sparse substitutions where it
        // has them. Nothing in the file bounds the count, so the file's own size does (a zero-filled accessor
        // longer than every byte of data the file holds is refused).
        const std::size_t limit = std::max<std::size_t>(std::size_t(1) << 20, total_buffer_bytes(model));
        if (acc.count > limit)
            fail(ErrorCode::parse, where + ": " + std::to_string(acc.count) +
                                       " elements without a bufferView, more than " + std::to_string(limit) +
                                       " (the file's buffer bytes)");
        out.resize(base + acc.count * std::size_t(n), static_cast<T>(0.0));
    }
    if (!acc.sparse.isSparse) return;
    T* values = out.data() + base;

    const std::string sparse_where = where + ": sparse";
    const std::size_t count = std::size_t(std::max(acc.sparse.count, 0));
    if (acc.sparse.count < 1 || count > acc.count)
        fail(ErrorCode::parse, sparse_where + " count " + std::to_string(acc.sparse.count) + " is not in [1, " +
                                   std::to_string(acc.count) + "]");
    const int index_type = acc.sparse.indices.componentType;
    const std::size_t index_bytes = component_bytes(index_type);
    if (index_type != TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE && index_type != TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT &&
        index_type != TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT)
        fail(ErrorCode::parse, sparse_where + " indices are not unsigned byte/short/int");
    const unsigned char* indices =
        sparse_bytes(model, acc.sparse.indices.bufferView, std::size_t(std::max(acc.sparse.indices.byteOffset, 0)),
                     count, index_bytes, sparse_where + " indices");
    const unsigned char* substitutes =
        sparse_bytes(model, acc.sparse.values.bufferView, std::size_t(std::max(acc.sparse.values.byteOffset, 0)), count,
                     element_bytes, sparse_where + " values");
    for (std::size_t s = 0; s < count; ++s) {
        const auto target = static_cast<std::size_t>(component(indices + s * index_bytes, index_type, false));
        if (target >= acc.count)
            fail(ErrorCode::parse, sparse_where + " index " + std::to_string(target) + " is out of range (" +
                                       std::to_string(acc.count) + " elements)");
        for (int c = 0; c < n; ++c)
            values[target * std::size_t(n) + std::size_t(c)] = static_cast<T>(
                component(substitutes + s * element_bytes + bytes * std::size_t(c), acc.componentType, acc.normalized));
    }
}

template void append_accessor(const tinygltf::Model&, int, const std::string&, std::vector<double>&);
template void append_accessor(const tinygltf::Model&, int, const std::string&, std::vector<float>&);
template void append_accessor(const tinygltf::Model&, int, const std::string&, std::vector<std::uint32_t>&);

std::vector<double> read_accessor(const tinygltf::Model& model, int index, const std::string& where) {
    std::vector<double> values;
    append_accessor(model, index, where, values);
    return values;
}

} // namespace vksonar::gltf
