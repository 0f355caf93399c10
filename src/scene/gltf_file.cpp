// Reading a glTF file (gltf_file.h): the file and its container are checked before tinygltf parses
// them. Before tinygltf sees a file we validate the GLB container (tinygltf 2.7 can read 8 bytes past
// a short BIN chunk), cap JSON nesting (its extras conversion recurses), and reject required
// extensions, which would otherwise fail later with a less useful message.
#define TINYGLTF_IMPLEMENTATION
#include "scene/gltf_file.h"

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>

#include <nlohmann/json.hpp>

namespace vksonar::gltf {
namespace {

using nlohmann::json;

constexpr std::size_t max_file_bytes = std::size_t(1) << 31; // tinygltf takes unsigned int sizes
constexpr int max_json_depth = 128;

std::vector<unsigned char> read_file(const std::string& path) {
    std::error_code ec;
    const std::filesystem::file_status st = std::filesystem::status(path, ec);
    if (!std::filesystem::exists(st)) fail(ErrorCode::io, "file not found");
    if (std::filesystem::is_directory(st)) fail(ErrorCode::io, "is a directory, not a glTF file");
    std::ifstream in(path, std::ios::binary);
    if (!in) fail(ErrorCode::io, std::string("cannot open: ") + std::strerror(errno));
    std::vector<unsigned char> bytes;
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

// Validates the GLB container; returns the JSON chunk and shrinks `bytes` to the declared length.
std::string glb_json_chunk(std::vector<unsigned char>& bytes) {
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
        if (bin_start + 8 + bin_length > length)
            fail(ErrorCode::parse, "GLB BIN chunk length " + std::to_string(bin_length) + " exceeds the file");
    }
    bytes.resize(static_cast<std::size_t>(length));
    return std::string(reinterpret_cast<const char*>(&bytes[20]), static_cast<std::size_t>(json_length));
}

// nlohmann parses iteratively, but tinygltf converts extras recursively: cap the nesting first.
void check_json_depth(const std::string& text) {
    int depth = 0;
    bool in_string = false, escaped = false;
    for (char c : text) {
        if (in_string) {
            if (escaped)
                escaped = false;
            else if (c == '\\')
                escaped = true;
            else if (c == '"')
                in_string = false;
        } else if (c == '"') {
            in_string = true;
        } else if (c == '{' || c == '[') {
            if (++depth > max_json_depth)
                fail(ErrorCode::parse, "JSON nests deeper than " + std::to_string(max_json_depth) + " levels");
        } else if (c == '}' || c == ']') {
            --depth;
        }
    }
}

json parse_json(const std::string& text) {
    check_json_depth(text);
    try {
        json doc = json::parse(text);
        if (!doc.is_object()) fail(ErrorCode::parse, "top level JSON value is not an object");
        return doc;
    } catch (const json::parse_error& e) {
        std::string what = e.what();
        const std::size_t bracket = what.find("] ");
        if (what.rfind("[json.exception", 0) == 0 && bracket != std::string::npos) what = what.substr(bracket + 2);
        fail(ErrorCode::parse, "invalid JSON: " + one_line(what));
    }
}

void check_required_extensions(const json& doc) {
    const auto it = doc.find("extensionsRequired");
    if (it == doc.end()) return;
    if (!it->is_array()) fail(ErrorCode::parse, "extensionsRequired is not an array");
    for (const json& name : *it) {
        fail(ErrorCode::unsupported,
             "unsupported required extension " + (name.is_string() ? name.get<std::string>() : name.dump()));
    }
}

// External buffers are looked up only next to the scene file (tinygltf would also try the current
// directory), and a missing one is remembered so it can be reported as an I/O error.
struct ExternalFiles {
    std::string base_dir;
    std::vector<std::string> missing;
};

bool file_exists_beside_scene(const std::string& path, void* user) {
    auto* files = static_cast<ExternalFiles*>(user);
    const std::string prefix = files->base_dir + "/";
    if (path.compare(0, prefix.size(), prefix) != 0) return false;
    const bool exists = tinygltf::FileExists(path, nullptr);
    if (!exists) files->missing.push_back(path.substr(prefix.size()));
    return exists;
}

std::string expand_nothing(const std::string& path, void*) {
    return path;
}

// vksonar uses no textures; images are accepted and their bytes dropped.
bool ignore_image(tinygltf::Image*, const int, std::string*, std::string*, int, int, const unsigned char*, int, void*) {
    return true;
}

tinygltf::Model run_tinygltf(const std::vector<unsigned char>& bytes, bool binary, const std::string& base_dir,
                             std::vector<std::string>& warnings) {
    ExternalFiles files{base_dir, {}};
    tinygltf::FsCallbacks fs{};
    fs.FileExists = &file_exists_beside_scene;
    fs.ExpandFilePath = &expand_nothing;
    fs.ReadWholeFile = &tinygltf::ReadWholeFile;
    fs.WriteWholeFile = &tinygltf::WriteWholeFile;
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
        if (!files.missing.empty())
            fail(ErrorCode::io, "external buffer '" + files.missing.front() + "' not found in " + base_dir);
        fail(ErrorCode::parse, one_line(err.empty() ? std::string("tinygltf failed without a message") : err));
    }
    return model;
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

tinygltf::Model read_model(const std::string& path, std::vector<std::string>& warnings) {
    std::vector<unsigned char> bytes = read_file(path);
    const bool binary = bytes.size() >= 4 && std::memcmp(bytes.data(), "glTF", 4) == 0;
    if (has_extension(path, ".glb") && !binary)
        fail(ErrorCode::parse, "not a binary glTF (bad magic; expected 'glTF')");
    const json doc = parse_json(binary ? glb_json_chunk(bytes) : std::string(bytes.begin(), bytes.end()));
    check_required_extensions(doc);
    std::string base_dir = std::filesystem::path(path).parent_path().string();
    if (base_dir.empty()) base_dir = ".";
    return run_tinygltf(bytes, binary, base_dir, warnings);
}

} // namespace vksonar::gltf
