// Reading a glTF file (gltf_file.h): the file and its container are checked before tinygltf parses
// them. Before tinygltf sees a file we validate the GLB container (tinygltf 2.7 can read 8 bytes past
// a short BIN chunk), cap JSON nesting (its extras conversion recurses), and reject required
// extensions, which would otherwise fail later with a less useful message.
#define TINYGLTF_IMPLEMENTATION
#include "scene/gltf_file.h"
#include "scene/gltf_draco.h"
#include "scene/gltf_meshopt.h"

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <initializer_list>
#include <map>
#include <vector>

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <nlohmann/json.hpp>

#include "core/json_depth.h"
#include "core/json_member_names.h"

namespace vksonar::gltf {
namespace {

using nlohmann::json;

constexpr std::size_t max_file_bytes = std::size_t(1) << 31; // tinygltf takes unsigned int sizes

std::vector<unsigned char> read_file(const std::string& path) {
    std::error_code ec;
    const std::filesystem::file_status st = std::filesystem::status(path, ec);
    if (!std::filesystem::exists(st)) fail(ErrorCode::io, "file not found");
    if (std::filesystem::is_directory(st)) fail(ErrorCode::io, "is a directory, not a glTF file");
    std::ifstream in(path, std::ios::binary);
    if (!in) fail(ErrorCode::io, std::string("cannot open: ") + std::strerror(errno));
    std::vector<unsigned char> bytes;
    // A regular file is read into an array of its size at once (growing one chunk at a time would hold
    // a file-sized array and its double while the array grows); whatever follows, if the file grew in
    // between, and anything that is not a regular file, a chunk at a time.
    if (std::filesystem::is_regular_file(st)) {
        const std::uintmax_t size = std::filesystem::file_size(path, ec);
        if (!ec && size > max_file_bytes) fail(ErrorCode::unsupported, "file is larger than 2 GiB");
        if (!ec && size > 0) {
            bytes.resize(static_cast<std::size_t>(size));
            in.read(reinterpret_cast<char*>(bytes.data()), static_cast<std::streamsize>(size));
            bytes.resize(static_cast<std::size_t>(in.gcount()));
        }
    }
    char chunk[1 << 16];
    while (in) {
        in.read(chunk, sizeof chunk);
        bytes.insert(bytes.end(), chunk, chunk + in.gcount());
        if (bytes.size() > max_file_bytes) fail(ErrorCode::unsupported, "file is larger than 2 GiB");
    }
    if (in.bad()) fail(ErrorCode::io, "read error");
    if (bytes.empty()) fail(ErrorCode::parse, "file is empty");
    return bytes;
}

std::uint32_t read_u32_le(const unsigned char* p) {
    return std::uint32_t(p[0]) | std::uint32_t(p[1]) << 8 | std::uint32_t(p[2]) << 16 | std::uint32_t(p[3]) << 24;
}

// Validates the GLB container; returns the JSON chunk's length (it starts at byte 20) and shrinks
// `bytes` to the declared length.
std::size_t glb_json_chunk(std::vector<unsigned char>& bytes) {
    if (bytes.size() < 20)
        fail(ErrorCode::parse, "GLB is " + std::to_string(bytes.size()) + " bytes, shorter than its header");
    if (std::memcmp(bytes.data(), "glTF", 4) != 0)
        fail(ErrorCode::parse, "not a binary glTF (bad magic; expected 'glTF')");
    const std::uint32_t version = read_u32_le(&bytes[4]);
    const std::uint64_t length = read_u32_le(&bytes[8]);
    if (version != 2) fail(ErrorCode::unsupported, "GLB version " + std::to_string(version) + " (only 2 is supported)");
    if (length > bytes.size())
        fail(ErrorCode::parse, "GLB header declares " + std::to_string(length) + " bytes but the file has " +
                                   std::to_string(bytes.size()) + " (truncated?)");
    const std::uint64_t json_length = read_u32_le(&bytes[12]);
    if (read_u32_le(&bytes[16]) != 0x4E4F534Au) fail(ErrorCode::parse, "GLB first chunk is not JSON");
    if (json_length == 0 || 20 + json_length > length)
        fail(ErrorCode::parse, "GLB JSON chunk length " + std::to_string(json_length) + " exceeds the file");
    const std::uint64_t bin_start = 20 + json_length;
    if (bin_start < length) {
        if (bin_start + 8 > length) fail(ErrorCode::parse, "GLB BIN chunk header is truncated");
        const std::uint64_t bin_length = read_u32_le(&bytes[bin_start]);
        if (bin_start + 8 + bin_length > length) {
            // a chunk that is no BIN chunk there is most likely JSON text: the JSON chunk's length is wrong
            if (read_u32_le(&bytes[bin_start + 4]) != 0x004E4942u)
                fail(ErrorCode::parse, "GLB JSON chunk length " + std::to_string(json_length) +
                                           " does not end where a chunk starts (what follows is no BIN chunk header)");
            fail(ErrorCode::parse, "GLB BIN chunk length " + std::to_string(bin_length) + " exceeds the file");
        }
    }
    bytes.resize(static_cast<std::size_t>(length));
    return static_cast<std::size_t>(json_length);
}

// nlohmann parses iteratively, but tinygltf converts extras recursively: cap the nesting first.
void check_json_depth(const char* text, std::size_t size) {
    if (json_nests_too_deep(std::string_view(text, size)))
        fail(ErrorCode::parse, "JSON nests deeper than " + std::to_string(kMaxJsonDepth) + " levels");
}

// The JSON text in place (the file's bytes), without a copy.
json parse_json(const unsigned char* bytes, std::size_t size) {
    const char* text = reinterpret_cast<const char*>(bytes);
    check_json_depth(text, size);
    // A member name twice in one object (a merge or hand edit gone wrong: a second "nodes" array): glTF's
    // JSON asks for unique names, and JSON would keep the last in silence (MemberNames).
    MemberNames names;
    const json::parser_callback_t names_once = [&names](int, json::parse_event_t event, json& parsed) {
        return names.on(event, parsed);
    };
    try {
        json doc = json::parse(text, text + size, names_once);
        if (!names.twice().empty())
            fail(ErrorCode::parse, "invalid JSON: member '" + one_line(names.twice(), 60) +
                                       "' is given twice in one object (one would be lost)");
        if (!doc.is_object()) fail(ErrorCode::parse, "top level JSON value is not an object");
        return doc;
    } catch (const json::parse_error& e) {
        std::string what = e.what();
        const std::size_t bracket = what.find("] ");
        if (what.rfind("[json.exception", 0) == 0 && bracket != std::string::npos) what = what.substr(bracket + 2);
        fail(ErrorCode::parse, "invalid JSON: " + one_line(what));
    }
}

// The numbers tinygltf takes without a word where the file is wrong: a negative byteOffset read as 0, a
// translation of strings ignored, a glTF 1.0 file read as 2.0. Checked on the JSON (the spec's types:
// indices and offsets integers >= 0, node transforms arrays of 3, 4, 3 and 16 numbers) so that such a
// file fails naming the field and value instead of loading as something else.
std::string value_text(const json& v) {
    return one_line(v.dump(-1, ' ', false, json::error_handler_t::replace), 60);
}
void require_whole(const json& v, const std::string& name) {
    // A JSON integer: tinygltf reads a whole-number float (0.0) as no value at all, in silence for an id
    // (a mesh, a child, a material, the indices dropped).
    const bool whole = v.is_number_unsigned() || (v.is_number_integer() && v.get<std::int64_t>() >= 0);
    if (!whole)
        fail(ErrorCode::parse, name + " = " + value_text(v) + ": must be an integer >= 0" +
                                   (v.is_number_float() ? " written without a fraction or exponent" : ""));
}
void require_count(const json& object, const char* key, const std::string& where) {
    if (!object.is_object() || !object.contains(key)) return;
    require_whole(object[key], (where.empty() ? "" : where + ".") + key);
}
void require_counts(const json& object, const char* key, const std::string& where) {
    if (!object.is_object() || !object.contains(key)) return;
    const json& list = object[key];
    if (!list.is_array()) fail(ErrorCode::parse, where + "." + key + " = " + value_text(list) + ": must be an array");
    for (std::size_t i = 0; i < list.size(); ++i)
        require_whole(list[i], where + "." + key + "[" + std::to_string(i) + "]");
}
void require_numbers(const json& object, const char* key, std::size_t count, const std::string& where) {
    if (!object.is_object() || !object.contains(key)) return;
    const json& v = object[key];
    bool ok = v.is_array() && v.size() == count;
    for (std::size_t i = 0; ok && i < count; ++i)
        ok = v[i].is_number();
    if (!ok)
        fail(ErrorCode::parse,
             where + "." + key + " = " + value_text(v) + ": must be an array of " + std::to_string(count) + " numbers");
}
// Each entry of the top-level array `name` (objects), checked by `check(entry, "name[i]")`.
template <class Check> void each(const json& doc, const char* name, Check&& check) {
    if (!doc.contains(name)) return;
    const json& list = doc[name];
    if (!list.is_array()) fail(ErrorCode::parse, std::string(name) + ": must be an array");
    for (std::size_t i = 0; i < list.size(); ++i) {
        const std::string where = std::string(name) + "[" + std::to_string(i) + "]";
        if (!list[i].is_object()) fail(ErrorCode::parse, where + ": must be an object");
        check(list[i], where);
    }
}

void check_structure(const json& doc) {
    if (doc.contains("asset") && doc["asset"].is_object() && doc["asset"].contains("version")) {
        const json& version = doc["asset"]["version"];
        if (!version.is_string() || version.get<std::string>().rfind("2.", 0) != 0)
            fail(ErrorCode::unsupported, "asset.version = " + value_text(version) + ": vksonar reads glTF 2.x");
    }
    require_count(doc, "scene", "");
    each(doc, "scenes", [](const json& scene, const std::string& where) { require_counts(scene, "nodes", where); });
    each(doc, "nodes", [](const json& node, const std::string& where) {
        for (const char* key : {"mesh", "skin", "camera"})
            require_count(node, key, where);
        require_counts(node, "children", where);
        require_numbers(node, "translation", 3, where);
        require_numbers(node, "rotation", 4, where);
        require_numbers(node, "scale", 3, where);
        require_numbers(node, "matrix", 16, where);
        // glTF: a matrix or translation / rotation / scale, not both (tinygltf keeps the matrix in silence).
        // Default ones beside a matrix (0 0 0, 0 0 0 1, 1 1 1: some exporters write them) change nothing.
        const auto non_default = [&node](const char* key, std::initializer_list<double> identity) {
            if (!node.contains(key)) return false;
            const json& v = node[key];
            if (!v.is_array() || v.size() != identity.size()) return true;
            std::size_t k = 0;
            for (double expected : identity)
                if (!v[k].is_number() || v[k++].get<double>() != expected) return true;
            return false;
        };
        if (node.is_object() && node.contains("matrix") &&
            (non_default("translation", {0, 0, 0}) || non_default("rotation", {0, 0, 0, 1}) ||
             non_default("scale", {1, 1, 1})))
            fail(ErrorCode::parse, where + ": has both a matrix and translation / rotation / scale (glTF allows one "
                                           "or the other)");
    });
    each(doc, "meshes", [](const json& mesh, const std::string& where) {
        if (!mesh.contains("primitives")) return;
        const json& primitives = mesh["primitives"];
        if (!primitives.is_array()) fail(ErrorCode::parse, where + ".primitives: must be an array");
        for (std::size_t p = 0; p < primitives.size(); ++p) {
            const std::string at = where + ".primitives[" + std::to_string(p) + "]";
            const json& primitive = primitives[p];
            if (!primitive.is_object()) fail(ErrorCode::parse, at + ": must be an object");
            for (const char* key : {"indices", "material", "mode"})
                require_count(primitive, key, at);
            if (primitive.contains("attributes") && primitive["attributes"].is_object())
                for (const auto& attribute : primitive["attributes"].items())
                    require_count(primitive["attributes"], attribute.key().c_str(), at + ".attributes");
            if (primitive.contains("targets") && primitive["targets"].is_array()) // morph targets' accessors
                for (std::size_t t = 0; t < primitive["targets"].size(); ++t)
                    if (primitive["targets"][t].is_object())
                        for (const auto& attribute : primitive["targets"][t].items())
                            require_count(primitive["targets"][t], attribute.key().c_str(),
                                          at + ".targets[" + std::to_string(t) + "]");
        }
    });
    each(doc, "skins", [](const json& skin, const std::string& where) {
        require_count(skin, "inverseBindMatrices", where);
        require_count(skin, "skeleton", where);
        require_counts(skin, "joints", where);
    });
    each(doc, "accessors", [](const json& accessor, const std::string& where) {
        for (const char* key : {"bufferView", "byteOffset", "count", "componentType"})
            require_count(accessor, key, where);
        if (accessor.contains("sparse") && accessor["sparse"].is_object()) {
            const json& sparse = accessor["sparse"];
            require_count(sparse, "count", where + ".sparse");
            for (const char* part : {"indices", "values"})
                if (sparse.contains(part))
                    for (const char* key : {"bufferView", "byteOffset", "componentType"})
                        require_count(sparse[part], key, where + ".sparse." + part);
        }
    });
    each(doc, "bufferViews", [](const json& view, const std::string& where) {
        for (const char* key : {"buffer", "byteOffset", "byteLength", "byteStride"})
            require_count(view, key, where);
    });
    each(doc, "buffers",
         [](const json& buffer, const std::string& where) { require_count(buffer, "byteLength", where); });
}

// What vksonar does with each glTF extension (README, "glTF extensions"). A sonar reads geometry
// only: an extension is decoded if it changes geometry and vksonar reads it, accepted with one warning
// if it only changes appearance (materials, textures, lights, cameras, metadata), and refused if it
// changes geometry and vksonar cannot read it, required or not, since drawing without it would be a
// silently wrong image. An unknown extension is refused when the file requires it, else warned about.
enum class ExtensionUse { decoded, appearance, refused, unknown };

ExtensionUse extension_use(const std::string& name) {
    static const char* const decoded[] = {"KHR_mesh_quantization", "EXT_mesh_gpu_instancing"};
    static const char* const refused[] = {"KHR_meshopt_compression"};
    if (name == "EXT_meshopt_compression") return meshopt_available() ? ExtensionUse::decoded : ExtensionUse::refused;
    if (name == "KHR_draco_mesh_compression") return draco_available() ? ExtensionUse::decoded : ExtensionUse::refused;
    static const char* const appearance_prefixes[] = {"KHR_materials_", "KHR_texture_", "EXT_texture_",
                                                      "MSFT_texture_",  "KHR_lights_",  "EXT_lights_"};
    static const char* const appearance[] = {"KHR_xmp",
                                             "KHR_xmp_json_ld",
                                             "MSFT_packing_normalRoughnessMetallic",
                                             "MSFT_packing_occlusionRoughnessMetallic",
                                             "KHR_animation_pointer",
                                             "EXT_materials_bump"};
    for (const char* d : decoded)
        if (name == d) return ExtensionUse::decoded;
    for (const char* r : refused)
        if (name == r) return ExtensionUse::refused;
    for (const char* p : appearance_prefixes)
        if (name.rfind(p, 0) == 0) return ExtensionUse::appearance;
    for (const char* a : appearance)
        if (name == a) return ExtensionUse::appearance;
    return ExtensionUse::unknown; // refused if the file requires it (the caller decides)
}

std::string join(const std::vector<std::string>& names) {
    std::string out;
    for (const std::string& n : names)
        out += (out.empty() ? "" : ", ") + n;
    return out;
}

// Every extension the file uses or requires, sorted into the three uses above: refusals are one
// error naming all of them; appearance-only and unknown optional ones one warning line each kind.
void check_extensions(const json& doc, std::vector<std::string>& warnings) {
    std::vector<std::string> required, used;
    for (const char* key : {"extensionsRequired", "extensionsUsed"}) {
        const auto it = doc.find(key);
        if (it == doc.end()) continue;
        if (!it->is_array()) fail(ErrorCode::parse, std::string(key) + " is not an array");
        for (const json& name : *it) {
            std::string text = name.is_string() ? name.get<std::string>() : name.dump();
            std::vector<std::string>& list = std::string(key) == "extensionsRequired" ? required : used;
            if (std::find(list.begin(), list.end(), text) == list.end()) list.push_back(std::move(text));
        }
    }
    for (const std::string& name : required)
        if (std::find(used.begin(), used.end(), name) == used.end()) used.push_back(name);
    std::vector<std::string> refused, appearance, unknown_optional;
    for (const std::string& name : used) {
        const bool is_required = std::find(required.begin(), required.end(), name) != required.end();
        switch (extension_use(name)) {
        case ExtensionUse::decoded:
            break;
        case ExtensionUse::appearance:
            appearance.push_back(name);
            break;
        case ExtensionUse::refused:
            refused.push_back(name);
            break;
        case ExtensionUse::unknown:
            (is_required ? refused : unknown_optional).push_back(name);
            break;
        }
    }
    if (refused.size() == 1)
        fail(ErrorCode::unsupported,
             std::string("unsupported ") +
                 (std::find(required.begin(), required.end(), refused[0]) != required.end() ? "required " : "") +
                 "extension " + refused[0] + " (it changes geometry and this build does not decode it)");
    if (refused.size() > 1)
        fail(ErrorCode::unsupported,
             "unsupported extensions " + join(refused) + " (they change geometry and this build does not decode them)");
    if (!appearance.empty())
        warnings.push_back("extensions that only change appearance, which a sonar does not see, ignored: " +
                           join(appearance));
    if (!unknown_optional.empty())
        warnings.push_back("unknown optional extensions ignored (the file does not require them): " +
                           join(unknown_optional));
}

// Files named inside a scene (external buffers) are read by these callbacks, never by tinygltf 2.7's own
// (which sizes a directory as 2^63 - 1 bytes, blocks forever opening a FIFO, and follows any path).
// check_external_buffers resolves each buffer's uri before tinygltf runs and refuses, with the uri in
// the message, what is not a plain file of the declared size inside the asset root; FileExists then
// answers yes only for the exact paths it accepted, and ReadWholeFile opens them again with the same
// checks (the file may have changed in between) and reads exactly the declared bytes.
struct ExternalBuffer {
    std::string uri;            // as written in the scene, for messages
    std::filesystem::path file; // resolved: absolute, no symlink, no "..", inside the asset root
    std::uint64_t byte_length;  // what the buffer declares
};

struct ExternalFiles {
    std::map<std::string, ExternalBuffer> by_joined_path; // keyed by the path tinygltf will ask for
    std::string error;                                    // the first refusal while tinygltf reads
};

// tinygltf 2.7's uri decoding (dlib::urldecode), so that the path checked here is the one it asks for.
std::string url_decode(const std::string& uri) {
    auto hex = [](char c) -> unsigned {
        if (c >= '0' && c <= '9') return unsigned(c - '0');
        if (c >= 'a' && c <= 'f') return unsigned(c - 'a' + 10);
        if (c >= 'A' && c <= 'F') return unsigned(c - 'A' + 10);
        return 0;
    };
    std::string out;
    for (std::size_t i = 0; i < uri.size(); ++i) {
        if (uri[i] == '+') {
            out += ' ';
        } else if (uri[i] == '%' && uri.size() > i + 2) {
            out += static_cast<char>((hex(uri[i + 1]) << 4) | hex(uri[i + 2]));
            i += 2;
        } else {
            out += uri[i];
        }
    }
    return out;
}

bool has_scheme(const std::string& uri) {
    const std::size_t colon = uri.find(':');
    if (colon == std::string::npos || colon == 0 || !std::isalpha(static_cast<unsigned char>(uri[0]))) return false;
    return std::all_of(uri.begin(), uri.begin() + static_cast<std::ptrdiff_t>(colon), [](char c) {
        return std::isalnum(static_cast<unsigned char>(c)) || c == '+' || c == '-' || c == '.';
    });
}

bool lies_inside(const std::filesystem::path& file, const std::filesystem::path& root) {
    auto f = file.begin();
    for (auto r = root.begin(); r != root.end(); ++r, ++f) {
        if (r->empty()) continue; // a trailing separator
        if (f == file.end() || *f != *r) return false;
    }
    return true;
}

// Opens a resolved external file without blocking (a FIFO or device would block in open()), without
// following a symlink that appeared since it was resolved, and checks that it is a regular file of
// exactly `byte_length` bytes. Returns the descriptor, or -1 with `why` set.
int open_checked(const ExternalBuffer& b, std::string& why) {
    why.clear();
    const int fd = ::open(b.file.c_str(), O_RDONLY | O_NONBLOCK | O_NOFOLLOW | O_CLOEXEC | O_NOCTTY);
    if (fd < 0) {
        why = std::string("cannot open: ") + std::strerror(errno);
        return -1;
    }
    struct stat st {};
    if (::fstat(fd, &st) != 0)
        why = std::string("cannot stat: ") + std::strerror(errno);
    else if (S_ISDIR(st.st_mode))
        why = "is a directory";
    else if (!S_ISREG(st.st_mode))
        why = "is not a regular file";
    if (!why.empty()) {
        ::close(fd);
        return -1;
    }
    if (std::uint64_t(st.st_size) != b.byte_length) {
        why = "is " + std::to_string(st.st_size) + " bytes, byteLength says " + std::to_string(b.byte_length);
        ::close(fd);
        return -1;
    }
    return fd;
}

std::string refusal(std::size_t index, const std::string& uri, const std::string& why) {
    return "buffer " + std::to_string(index) + " uri '" + uri + "' " + why;
}

// Every external buffer of `doc`, checked before tinygltf reads any (see ExternalFiles).
ExternalFiles check_external_buffers(const json& doc, const std::string& base_dir, const std::string& asset_root,
                                     bool binary) {
    ExternalFiles files;
    const auto buffers = doc.find("buffers");
    if (buffers == doc.end() || !buffers->is_array()) return files; // tinygltf reports what is wrong
    std::error_code ec;
    const std::string root_text = asset_root.empty() ? base_dir : asset_root;
    const std::filesystem::path root = std::filesystem::canonical(root_text, ec);
    if (ec || !std::filesystem::is_directory(root, ec))
        fail(ErrorCode::io, "asset root '" + root_text + "' is not a folder (" +
                                (ec ? ec.message() : std::string("not a directory")) + ")");
    for (std::size_t i = 0; i < buffers->size(); ++i) {
        const json& buffer = (*buffers)[i];
        if (!buffer.is_object()) continue;
        const auto uri_it = buffer.find("uri");
        if (uri_it == buffer.end() || !uri_it->is_string()) continue;
        const std::string uri = uri_it->get<std::string>();
        if (uri.empty()) {
            if (binary) continue; // tinygltf takes it as the BIN chunk, as an absent uri (which the spec asks for)
            fail(ErrorCode::parse, "buffer " + std::to_string(i) + " uri is empty (name the buffer's file)");
        }
        if (uri.rfind("data:", 0) == 0) {
            // embedded base64: its bytes must hold byteLength (tinygltf said only "Failed to decode 'uri'")
            const std::size_t comma = uri.find(',');
            const auto length_it = buffer.find("byteLength");
            if (comma != std::string::npos && comma >= 7 && uri.compare(comma - 7, 7, ";base64") == 0 &&
                length_it != buffer.end() && length_it->is_number_unsigned()) {
                const std::size_t text = uri.size() - comma - 1, rest = text % 4;
                std::size_t padding = 0;
                while (padding < 2 && text > padding && uri[uri.size() - 1 - padding] == '=')
                    ++padding;
                // 3 bytes a 4 characters, less the padding; unpadded, 2 or 3 characters left over hold 1 or 2
                const std::uint64_t holds = text / 4 * 3 - (rest == 0 ? padding : 0) + (rest > 1 ? rest - 1 : 0);
                if (length_it->get<std::uint64_t>() > holds)
                    fail(ErrorCode::parse, "buffer " + std::to_string(i) + " byteLength " +
                                               std::to_string(length_it->get<std::uint64_t>()) +
                                               " is more than its data uri holds (" + std::to_string(holds) +
                                               " bytes)");
            }
            continue;
        }
        // a '%' starts an escape of two hex digits ("%20"); another was decoded as a NUL and named as one
        for (std::size_t at = uri.find('%'); at != std::string::npos; at = uri.find('%', at + 1))
            if (at + 2 >= uri.size() || !std::isxdigit(static_cast<unsigned char>(uri[at + 1])) ||
                !std::isxdigit(static_cast<unsigned char>(uri[at + 2])))
                fail(ErrorCode::parse, refusal(i, uri, "has a '%' not followed by two hex digits (a space is %20)"));
        const std::string decoded = url_decode(uri);
        if (decoded.find('\0') != std::string::npos) fail(ErrorCode::parse, refusal(i, uri, "holds a NUL byte"));
        if (has_scheme(decoded))
            fail(ErrorCode::unsupported,
                 refusal(i, uri, "is not a relative path (only files beside the scene are read)"));
        if (decoded.front() == '/')
            fail(ErrorCode::unsupported,
                 refusal(i, uri, "is an absolute path (uris are relative to the scene's folder)"));
        const auto length_it = buffer.find("byteLength");
        if (length_it == buffer.end() || !length_it->is_number_unsigned() || length_it->get<std::uint64_t>() == 0)
            fail(ErrorCode::parse, "buffer " + std::to_string(i) + " byteLength is missing or not a positive integer");
        const std::uint64_t byte_length = length_it->get<std::uint64_t>();
        if (byte_length > max_file_bytes)
            fail(ErrorCode::unsupported, refusal(i, uri,
                                                 "declares " + std::to_string(byte_length) +
                                                     " bytes, over the 2 GiB limit of a file vksonar reads"));
        const std::string joined = base_dir.back() == '/' ? base_dir + decoded : base_dir + "/" + decoded;
        const std::filesystem::path file = std::filesystem::canonical(joined, ec); // symlinks and ".." resolved
        if (ec) fail(ErrorCode::io, refusal(i, uri, "not found in " + base_dir + " (" + ec.message() + ")"));
        if (!lies_inside(file, root))
            fail(ErrorCode::io,
                 refusal(i, uri,
                         "lies outside the asset root " + root.string() +
                             (asset_root.empty()
                                  ? " (a wider asset root: --asset-root DIR, config scene.asset_root, Python "
                                    "Scene.load(asset_root=))"
                                  : "")));
        ExternalBuffer b{uri, file, byte_length};
        std::string why;
        const int fd = open_checked(b, why);
        // A size that disagrees is the scene's inconsistency (as a short GLB chunk is); the rest is I/O.
        if (fd < 0)
            fail(why.find("byteLength") != std::string::npos ? ErrorCode::parse : ErrorCode::io, refusal(i, uri, why));
        ::close(fd);
        files.by_joined_path.emplace(joined, std::move(b));
    }
    return files;
}

bool external_file_exists(const std::string& path, void* user) {
    return static_cast<ExternalFiles*>(user)->by_joined_path.count(path) != 0;
}

bool read_external_file(std::vector<unsigned char>* out, std::string* err, const std::string& path, void* user) {
    auto* files = static_cast<ExternalFiles*>(user);
    const auto it = files->by_joined_path.find(path);
    std::string why = "was not checked"; // cannot happen: FileExists said no
    int fd = -1;
    if (it != files->by_joined_path.end()) fd = open_checked(it->second, why);
    if (fd >= 0) {
        out->assign(static_cast<std::size_t>(it->second.byte_length), 0);
        std::size_t done = 0;
        while (done < out->size()) {
            const ssize_t n = ::read(fd, out->data() + done, out->size() - done);
            if (n < 0 && errno == EINTR) continue;
            if (n <= 0) break;
            done += static_cast<std::size_t>(n);
        }
        ::close(fd);
        if (done == out->size()) return true;
        why = "was shorter than byteLength while it was read (changed on disk?)";
    }
    const std::string uri = it != files->by_joined_path.end() ? it->second.uri : path;
    if (files->error.empty()) files->error = "buffer uri '" + uri + "' " + why;
    if (err) *err = why;
    return false;
}

std::string expand_nothing(const std::string& path, void*) {
    return path;
}

bool refuse_write(std::string* err, const std::string&, const std::vector<unsigned char>&, void*) {
    if (err) *err = "vksonar writes no glTF files";
    return false;
}

// vksonar uses no textures; images are accepted and their bytes dropped.
bool ignore_image(tinygltf::Image*, const int, std::string*, std::string*, int, int, const unsigned char*, int, void*) {
    return true;
}

tinygltf::Model run_tinygltf(const std::vector<unsigned char>& bytes, bool binary, const std::string& base_dir,
                             ExternalFiles& files, std::vector<std::string>& warnings) {
    tinygltf::FsCallbacks fs{};
    fs.FileExists = &external_file_exists;
    fs.ExpandFilePath = &expand_nothing;
    fs.ReadWholeFile = &read_external_file;
    fs.WriteWholeFile = &refuse_write;
    fs.user_data = &files;

    tinygltf::TinyGLTF loader;
    loader.SetFsCallbacks(fs);
    loader.SetImageLoader(&ignore_image, nullptr);
    loader.SetStoreOriginalJSONForExtrasAndExtensions(true);

    tinygltf::Model model;
    std::string err, warn;
    const auto size = static_cast<unsigned int>(bytes.size());
    const bool ok = binary ? loader.LoadBinaryFromMemory(&model, &err, &warn, bytes.data(), size, base_dir)
                           : loader.LoadASCIIFromString(&model, &err, &warn,
                                                        reinterpret_cast<const char*>(bytes.data()), size, base_dir);
    if (!warn.empty()) warnings.push_back("glTF: " + one_line(warn));
    if (!ok) {
        if (!files.error.empty()) fail(ErrorCode::io, files.error);
        fail(ErrorCode::parse, one_line(err.empty() ? std::string("tinygltf failed without a message") : err));
    }
    return model;
}

// The file's bytes with its JSON replaced: the text itself, or a GLB with a new JSON chunk (padded
// with spaces to 4 bytes, as the container asks) before the original BIN chunk.
std::vector<unsigned char> with_json(const std::vector<unsigned char>& bytes, bool binary, const std::string& text) {
    if (!binary) return std::vector<unsigned char>(text.begin(), text.end());
    std::string padded = text;
    while (padded.size() % 4)
        padded += ' ';
    const std::size_t old_json = read_u32_le(&bytes[12]);
    const std::size_t rest = bytes.size() - 20 - old_json; // the BIN chunk, header included, or nothing
    const std::size_t total = 20 + padded.size() + rest;
    if (total > max_file_bytes) fail(ErrorCode::unsupported, "file is larger than 2 GiB");
    std::vector<unsigned char> out(total);
    auto put_u32 = [&](std::size_t at, std::uint32_t v) {
        for (int i = 0; i < 4; ++i)
            out[at + std::size_t(i)] = static_cast<unsigned char>(v >> (8 * i));
    };
    std::memcpy(out.data(), bytes.data(), 8); // magic, version
    put_u32(8, static_cast<std::uint32_t>(total));
    put_u32(12, static_cast<std::uint32_t>(padded.size()));
    put_u32(16, 0x4E4F534Au);
    std::memcpy(out.data() + 20, padded.data(), padded.size());
    std::memcpy(out.data() + 20 + padded.size(), bytes.data() + 20 + old_json, rest);
    return out;
}

bool has_extension(const std::string& path, const char* ext) {
    std::string e = std::filesystem::path(path).extension().string();
    std::transform(e.begin(), e.end(), e.begin(), [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
    return e == ext;
}

} // namespace

void fail(ErrorCode code, std::string what) {
    throw LoadFailure{code, std::move(what)};
}

std::string one_line(const std::string& text, std::size_t max_chars) {
    std::string in = text;
    for (std::size_t at = in.find("data:"); at != std::string::npos; at = in.find("data:", at + 1)) {
        const std::size_t comma = in.find(',', at);
        const std::size_t end = in.find_first_of(" \n\r'\"", at);
        if (comma != std::string::npos && comma < end) in.replace(comma + 1, end - comma - 1, "...");
    }
    std::string out;
    bool pending_separator = false;
    for (char c : in) {
        if (c == '\n' || c == '\r') {
            pending_separator = !out.empty();
            continue;
        }
        if (pending_separator) out += "; ";
        pending_separator = false;
        out += c;
    }
    if (out.size() > max_chars) out = out.substr(0, max_chars) + "...";
    return out;
}

tinygltf::Model read_model(const std::string& path, const std::string& asset_root, std::vector<std::string>& warnings) {
    std::vector<unsigned char> bytes = read_file(path);
    const bool binary = bytes.size() >= 4 && std::memcmp(bytes.data(), "glTF", 4) == 0;
    if (has_extension(path, ".glb") && !binary)
        fail(ErrorCode::parse, "not a binary glTF (bad magic; expected 'glTF')");
    std::string base_dir = std::filesystem::path(path).parent_path().string();
    if (base_dir.empty()) base_dir = ".";
    ExternalFiles files;
    MeshoptPlan meshopt;
    std::vector<DracoIndices> draco;
    { // the parsed JSON is freed before tinygltf parses the text again
        const std::size_t json_length = binary ? glb_json_chunk(bytes) : bytes.size();
        json doc = parse_json(bytes.data() + (binary ? 20 : 0), json_length);
        check_structure(doc);
        check_extensions(doc, warnings);
        files = check_external_buffers(doc, base_dir, asset_root, binary);
        meshopt = prepare_meshopt(doc); // edits doc only where the file uses the extension
        draco = prepare_draco(doc);     // likewise
        if (!meshopt.empty() || !draco.empty()) bytes = with_json(bytes, binary, doc.dump());
    }
    tinygltf::Model model = run_tinygltf(bytes, binary, base_dir, files, warnings);
    std::vector<unsigned char>().swap(bytes); // tinygltf has copied the buffers it needs
    decode_meshopt(meshopt, model);
    restore_draco(draco, model);
    return model;
}

} // namespace vksonar::gltf
