// Sharding: parsing, the engines' environment, the block of a shard, and DIR/shard.json (shard.h).
#include "cli/shard.h"

#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>

#include <nlohmann/json.hpp>

#include "cli/args.h"
#include "cli/frame_files.h"
#include "core/access.h"
#include "core/json_depth.h"
#include "scene/scene_data.h"

namespace fs = std::filesystem;

namespace vksonar::cli {

std::pair<std::uint64_t, std::uint64_t> shard_block(std::uint64_t index, std::uint64_t count, std::uint64_t total) {
    // index * total fits in 128 bits; trajectories are far below 2^32 frames, so 64 bits do too.
    const auto at = [&](std::uint64_t i) {
        return static_cast<std::uint64_t>((static_cast<unsigned __int128>(i) * total) / count);
    };
    return {at(index), at(index + 1)};
}

std::pair<std::uint64_t, std::uint64_t> parse_shard(const std::string& given, const std::string& what) {
    const std::string text = trim(given); // spaces around it, as every number option takes them
    const auto slash = text.find('/');
    const auto digits = [](const std::string& s) {
        return !s.empty() && s.size() <= 18 && s.find_first_not_of("0123456789") == std::string::npos;
    };
    if (slash == std::string::npos || !digits(text.substr(0, slash)) || !digits(text.substr(slash + 1)))
        throw BadInput(what + " '" + text + "': expected INDEX/COUNT, e.g. 0/4 (INDEX counts from 0)");
    const std::uint64_t index = std::stoull(text.substr(0, slash)), count = std::stoull(text.substr(slash + 1));
    if (count == 0) throw BadInput(what + " '" + text + "': the count must be at least 1");
    if (index >= count)
        throw BadInput(what + " '" + text + "': index " + std::to_string(index) + " is not below the count " +
                       std::to_string(count) + " (shards are numbered 0.." + std::to_string(count - 1) + ")");
    return {index, count};
}

EnvLookup process_env() {
    return [](const char* name) { return static_cast<const char*>(std::getenv(name)); };
}

namespace {

std::optional<std::uint64_t> env_u64(const EnvLookup& env, const char* name) {
    const char* value = env(name);
    if (!value) return std::nullopt;
    return parse_u64(value, std::string(name) + " (environment)");
}

// A Slurm job array: the task's place in the array's range MIN..MAX (step STEP), or, without the
// range, its id among COUNT tasks numbered from 0.
ShardRecord slurm_shard(const EnvLookup& env) {
    const std::uint64_t id = *env_u64(env, "SLURM_ARRAY_TASK_ID");
    const auto min = env_u64(env, "SLURM_ARRAY_TASK_MIN"), max = env_u64(env, "SLURM_ARRAY_TASK_MAX");
    const auto step_env = env_u64(env, "SLURM_ARRAY_TASK_STEP"), task_count = env_u64(env, "SLURM_ARRAY_TASK_COUNT");
    ShardRecord s;
    const std::string ids = "SLURM_ARRAY_TASK_ID=" + std::to_string(id);
    if (min && max) {
        const std::uint64_t step = step_env ? *step_env : 1;
        const std::string range = "SLURM_ARRAY_TASK_MIN..MAX " + std::to_string(*min) + ".." + std::to_string(*max) +
                                  (step != 1 ? " step " + std::to_string(step) : std::string());
        if (step == 0) throw BadInput("SLURM_ARRAY_TASK_STEP (environment): '0' is not a step");
        if (*max < *min || id < *min || id > *max || (id - *min) % step != 0)
            throw BadInput(ids + " (environment) is not in the array's " + range);
        s.index = (id - *min) / step;
        s.count = (*max - *min) / step + 1;
        if (task_count && *task_count != s.count)
            throw BadInput("SLURM_ARRAY_TASK_COUNT=" + std::to_string(*task_count) + " (environment) does not match " +
                           range + " (" + std::to_string(s.count) +
                           " tasks): the array is not one range; give --shard INDEX/COUNT");
        s.source = ids + " (" + range + ")";
    } else if (task_count) {
        if (*task_count == 0) throw BadInput("SLURM_ARRAY_TASK_COUNT (environment): '0' tasks");
        if (id >= *task_count)
            throw BadInput(ids + " (environment) is not below SLURM_ARRAY_TASK_COUNT=" + std::to_string(*task_count) +
                           " and no SLURM_ARRAY_TASK_MIN/MAX say where the array starts");
        s.index = id;
        s.count = *task_count;
        s.source = ids + " (SLURM_ARRAY_TASK_COUNT " + std::to_string(*task_count) + ")";
    } else {
        throw BadInput(ids + " (environment) without SLURM_ARRAY_TASK_MIN/MAX or SLURM_ARRAY_TASK_COUNT: "
                             "cannot tell the array's size; give --shard INDEX/COUNT");
    }
    return s;
}

} // namespace

std::optional<ShardRecord> resolve_shard(const std::optional<std::string>& flag,
                                         const std::optional<std::string>& count_flag, std::uint64_t total,
                                         const EnvLookup& env) {
    std::optional<ShardRecord> shard;
    if (flag) {
        if (count_flag)
            throw BadInput("--shard-count: only with JOB_COMPLETION_INDEX; --shard " + *flag +
                           " already gives the count");
        const auto [index, count] = parse_shard(*flag, "--shard");
        shard.emplace();
        shard->index = index;
        shard->count = count;
        shard->source = "--shard " + *flag;
    } else {
        std::optional<std::uint64_t> count;
        std::string count_name;
        if (count_flag) {
            count = parse_u64(*count_flag, "--shard-count");
            count_name = "--shard-count " + *count_flag;
        } else if (env("VKSONAR_SHARD_COUNT")) {
            count = env_u64(env, "VKSONAR_SHARD_COUNT");
            count_name = std::string("VKSONAR_SHARD_COUNT=") + env("VKSONAR_SHARD_COUNT");
        }
        if (count && *count == 0) throw BadInput(count_name + ": the count must be at least 1");
        if (env("SLURM_ARRAY_TASK_ID")) {
            shard = slurm_shard(env);
            if (count && *count != shard->count)
                throw BadInput(count_name + " does not match the Slurm array's " + std::to_string(shard->count) +
                               " tasks (" + shard->source + ")");
        } else if (env("JOB_COMPLETION_INDEX")) {
            const std::uint64_t index = *env_u64(env, "JOB_COMPLETION_INDEX");
            const std::string where = "JOB_COMPLETION_INDEX=" + std::to_string(index);
            if (!count)
                throw BadInput(where + " (environment) but no shard count: give --shard-count N or set "
                                       "VKSONAR_SHARD_COUNT (the Job's completions)");
            if (index >= *count)
                throw BadInput(where + " (environment) is not below the shard count " + std::to_string(*count) + " (" +
                               count_name + ")");
            shard.emplace();
            shard->index = index;
            shard->count = *count;
            shard->source = where + " (" + count_name + ")";
        } else if (count) { // (VKSONAR_SHARD_COUNT alone rendered the whole trajectory, as if unsharded)
            throw BadInput(count_name + ": no JOB_COMPLETION_INDEX in the environment; give --shard INDEX/COUNT");
        }
    }
    if (shard) {
        const auto [first, end] = shard_block(shard->index, shard->count, total);
        shard->first = first;
        shard->end = end;
        shard->total = total;
    }
    return shard;
}

std::string file_fnv1a64(const std::string& path) {
    std::ifstream file(path, std::ios::binary);
    std::uint64_t hash = 0xcbf29ce484222325ull;
    char buffer[65536];
    while (file) {
        file.read(buffer, sizeof buffer);
        for (std::streamsize i = 0; i < file.gcount(); ++i) {
            hash ^= static_cast<unsigned char>(buffer[i]);
            hash *= 0x100000001b3ull;
        }
    }
    char text[17];
    std::snprintf(text, sizeof text, "%016llx", static_cast<unsigned long long>(hash));
    return text;
}

// ---- shard.json ------------------------------------------------------------------------------------

namespace {

// An identity value that is a JSON object or array is stored as JSON, anything else as text.
nlohmann::json identity_value(const std::string& text) {
    if (!text.empty() && (text[0] == '{' || text[0] == '[')) {
        auto parsed = nlohmann::json::parse(text, nullptr, false);
        if (!parsed.is_discarded()) return parsed;
    }
    return text;
}

std::string shorten(std::string text) {
    if (text.size() > 80) text = text.substr(0, 77) + "...";
    return text;
}

// The first leaf where two JSON values differ, as "path: a vs b".
std::string json_difference(const nlohmann::json& a, const nlohmann::json& b, const std::string& path) {
    if (a.is_object() && b.is_object()) {
        for (auto it = a.begin(); it != a.end(); ++it) {
            const std::string key = path.empty() ? it.key() : path + "." + it.key();
            if (!b.contains(it.key())) return key + ": " + shorten(it.value().dump()) + " vs (absent)";
            if (std::string d = json_difference(it.value(), b[it.key()], key); !d.empty()) return d;
        }
        for (auto it = b.begin(); it != b.end(); ++it)
            if (!a.contains(it.key()))
                return (path.empty() ? it.key() : path + "." + it.key()) + ": (absent) vs " +
                       shorten(it.value().dump());
        return {};
    }
    if (a == b) return {};
    return path + ": " + shorten(a.dump()) + " vs " + shorten(b.dump());
}

} // namespace

std::string identity_difference(const Identity& a, const Identity& b) {
    const auto find = [](const Identity& identity, const std::string& name) -> const std::string* {
        for (const auto& entry : identity)
            if (entry.first == name) return &entry.second;
        return nullptr;
    };
    // Where both record the scene's content hash, the hash is compared and the path is not: a
    // cluster's nodes, or a requeued task on another node, often see one scene file under different
    // mount points, as they see the trajectory (compared by its hash only). Without the hash (a shard
    // rendered before it was recorded) the path is all there is to compare.
    const std::string *hash_a = find(a, "scene_fnv1a64"), *hash_b = find(b, "scene_fnv1a64");
    const bool scene_by_content = hash_a && hash_b && !hash_a->empty() && !hash_b->empty();
    for (const auto& [name, value] : a) {
        const std::string* found = find(b, name);
        const std::string other = found ? *found : "(absent)";
        if (other == value || (name == "scene" && found && scene_by_content)) continue;
        const nlohmann::json ja = identity_value(value), jb = identity_value(other);
        if (ja.is_object() && jb.is_object()) {
            if (std::string d = json_difference(ja, jb, name); !d.empty()) return d;
            continue; // equal as JSON, only written differently
        }
        return name + ": " + shorten(value) + " vs " + shorten(other);
    }
    for (const auto& [name, value] : b)
        if (!find(a, name)) return name + ": (absent) vs " + shorten(value);
    return {};
}

Identity run_identity(const std::string& config_json, std::uint64_t seed, const std::string& scene,
                      const std::string& backend, const std::string& save, bool timed, const ShardRecord* shard) {
    const auto config = nlohmann::json::parse(config_json, nullptr, false);
    Identity identity = {{"config", config.is_discarded() ? config_json : config.dump()},
                         {"seed", std::to_string(seed)},
                         {"scene", scene},
                         {"backend", backend},
                         {"save", save},
                         {"time", timed ? "trajectory column" : "frame ordinal"}};
    if (shard) {
        identity.emplace_back("trajectory", shard->trajectory_hash);
        identity.emplace_back("frames", std::to_string(shard->total));
        if (!shard->scene_hash.empty()) identity.emplace_back("scene_fnv1a64", shard->scene_hash);
    }
    return identity;
}

std::string manifest_json(const FolderManifest& m) {
    nlohmann::ordered_json j;
    j["format"] = "vksonar-shard-1";
    j["shard"] = {{"index", m.shard.index}, {"count", m.shard.count}, {"source", m.shard.source}};
    j["frames"] = {{"first", m.shard.first}, {"end", m.shard.end}, {"total", m.shard.total}};
    j["trajectory"] = {{"path", m.shard.trajectory}, {"fnv1a64", m.shard.trajectory_hash}};
    // The block's frame lines as inclusive ranges of consecutive lines (a trajectory without comments
    // is one range).
    nlohmann::ordered_json ranges = nlohmann::ordered_json::array();
    for (std::size_t i = 0; i < m.lines.size();) {
        std::size_t j2 = i;
        while (j2 + 1 < m.lines.size() && m.lines[j2 + 1] == m.lines[j2] + 1)
            ++j2;
        ranges.push_back({m.lines[i], m.lines[j2]});
        i = j2 + 1;
    }
    j["lines"] = ranges;
    j["backend"] = m.backend;
    j["device"] = m.device;
    nlohmann::ordered_json identity = nlohmann::ordered_json::object();
    for (const auto& [name, value] : m.identity)
        identity[name] = identity_value(value);
    j["identity"] = identity;
    // paths that are not UTF-8 (a Latin-1 folder name): U+FFFD instead of dump() throwing
    return j.dump(2, ' ', false, nlohmann::ordered_json::error_handler_t::replace) + "\n";
}

FolderManifest read_manifest(const std::string& dir) {
    const fs::path path = fs::path(dir) / "shard.json";
    std::ifstream file(path);
    if (!file) throw BadInput(path.string() + ": no such file (not a shard's output folder: render it with --shard)");
    std::stringstream text;
    text << file.rdbuf();
    if (json_nests_too_deep(text.str()))
        throw BadInput(path.string() + ": invalid JSON (nests deeper than " + std::to_string(kMaxJsonDepth) +
                       " levels)");
    const auto j = nlohmann::json::parse(text.str(), nullptr, false);
    if (j.is_discarded() || !j.is_object()) throw BadInput(path.string() + ": invalid JSON");
    FolderManifest m;
    try {
        if (j.at("format") != "vksonar-shard-1")
            throw BadInput(path.string() + ": format " + j.at("format").dump() + " is not vksonar-shard-1");
        m.shard.index = j.at("shard").at("index").get<std::uint64_t>();
        m.shard.count = j.at("shard").at("count").get<std::uint64_t>();
        m.shard.source = j.at("shard").at("source").get<std::string>();
        m.shard.first = j.at("frames").at("first").get<std::uint64_t>();
        m.shard.end = j.at("frames").at("end").get<std::uint64_t>();
        m.shard.total = j.at("frames").at("total").get<std::uint64_t>();
        m.shard.trajectory = j.at("trajectory").at("path").get<std::string>();
        m.shard.trajectory_hash = j.at("trajectory").at("fnv1a64").get<std::string>();
        for (const auto& range : j.at("lines")) {
            const auto a = range.at(0).get<std::uint64_t>(), b = range.at(1).get<std::uint64_t>();
            if (b < a || b - a > (std::uint64_t(1) << 32)) throw BadInput(path.string() + ": bad line range");
            for (std::uint64_t line = a; line <= b; ++line)
                m.lines.push_back(line);
        }
        m.backend = j.at("backend").get<std::string>();
        m.device = j.at("device").get<std::string>();
        for (auto it = j.at("identity").begin(); it != j.at("identity").end(); ++it)
            m.identity.emplace_back(it.key(),
                                    it.value().is_string() ? it.value().get<std::string>() : it.value().dump());
    } catch (const nlohmann::json::exception& e) {
        // nlohmann's "[json.exception.out_of_range.403] key 'format' not found": the part after the tag
        std::string what = e.what();
        if (const auto tag = what.find("] "); tag != std::string::npos) what = what.substr(tag + 2);
        throw BadInput(path.string() + ": not a shard record (" + what + ")");
    }
    if (m.shard.count == 0 || m.shard.index >= m.shard.count || m.shard.end < m.shard.first ||
        m.lines.size() != m.shard.end - m.shard.first)
        throw BadInput(path.string() + ": inconsistent shard record");
    return m;
}

void start_folder_shard(const std::string& dir, const FolderManifest& manifest, std::vector<char>& done,
                        std::vector<std::string>* damaged) {
    const fs::path path = fs::path(dir) / "shard.json";
    const std::string name = std::to_string(manifest.shard.index) + "/" + std::to_string(manifest.shard.count);
    std::error_code ec;
    if (fs::exists(path, ec)) {
        const FolderManifest old = read_manifest(dir);
        if (old.shard.index != manifest.shard.index || old.shard.count != manifest.shard.count)
            throw BadInput("--out " + dir + " holds shard " + std::to_string(old.shard.index) + "/" +
                           std::to_string(old.shard.count) + ", not shard " + name + ": give each shard its own --out");
        if (std::string d = identity_difference(old.identity, manifest.identity); !d.empty())
            throw BadInput("--out " + dir + " holds shard " + name + " of another run (" + d +
                           "): remove it or give another --out");
        for (std::uint64_t k = 0; k < manifest.lines.size(); ++k) {
            const std::string frame = frame_dir_name(manifest.lines[k]);
            const FrameFolderState state = frame_folder_check((fs::path(dir) / frame).string());
            if (state.kind == FrameFolderState::complete)
                done[manifest.shard.first + k] = 1;
            else if (state.kind == FrameFolderState::damaged && damaged)
                damaged->push_back(frame);
        }
    }
    const fs::path temporary = fs::path(dir) / ".~shard.json";
    {
        std::ofstream file(temporary, std::ios::binary | std::ios::trunc);
        file << manifest_json(manifest);
        if (!file.flush()) throw Failure("cannot write " + path.string());
    }
    fs::rename(temporary, path, ec);
    if (ec) throw Failure("cannot write " + path.string() + ": " + ec.message());
}

std::string shard_summary(const ShardRecord& shard, std::uint64_t first_line, std::uint64_t last_line,
                          std::uint64_t already_done, const std::vector<std::string>& damaged) {
    std::string text =
        "shard " + std::to_string(shard.index) + "/" + std::to_string(shard.count) + " (" + shard.source + "): ";
    if (shard.end == shard.first)
        return text + "no frames (" + std::to_string(shard.total) + " frames in " + std::to_string(shard.count) +
               " shards)";
    text += "frames " + std::to_string(shard.first) + ".." + std::to_string(shard.end - 1) + " of " +
            std::to_string(shard.total) + " (lines " + std::to_string(first_line) + ".." + std::to_string(last_line) +
            ")";
    if (already_done) text += ", " + std::to_string(already_done) + " already on disk";
    if (!damaged.empty()) {
        // The first few by name (a crash damages the frames in flight, a handful); the count says the rest.
        constexpr std::size_t kNamed = 5;
        text += ", " + std::to_string(damaged.size()) + " damaged (re-rendered): ";
        for (std::size_t i = 0; i < damaged.size() && i < kNamed; ++i)
            text += (i ? ", " : "") + damaged[i];
        if (damaged.size() > kNamed) text += ", ...";
    }
    return text;
}

FrameFolderState frame_folder_check(const std::string& frame_dir) {
    const fs::path meta_path = fs::path(frame_dir) / kMetaJson;
    std::error_code ec;
    FrameFolderState state;
    if (!fs::is_regular_file(meta_path, ec)) return state;
    state.kind = FrameFolderState::damaged;
    std::ifstream in(meta_path, std::ios::binary);
    std::stringstream text;
    text << in.rdbuf();
    if (json_nests_too_deep(text.str())) {
        state.problem = std::string(kMetaJson) + ": nests deeper than " + std::to_string(kMaxJsonDepth) + " levels";
        return state;
    }
    nlohmann::json meta = nlohmann::json::parse(text.str(), nullptr, /*allow_exceptions=*/false);
    if (meta.is_discarded() || !meta.is_object()) {
        state.problem = std::string(kMetaJson) + ": not a JSON object";
        return state;
    }
    const auto files = meta.find("files");
    if (files == meta.end()) { // written before meta.json recorded the files: its presence is all there is
        state.kind = FrameFolderState::complete;
        return state;
    }
    if (!files->is_object()) {
        state.problem = std::string(kMetaJson) + ": \"files\" is not an object";
        return state;
    }
    for (auto it = files->begin(); it != files->end(); ++it) {
        const std::string& name = it.key();
        // Only the frame's own file names: a meta.json can never send the check outside the folder.
        if (!is_frame_file(name) || name == kMetaJson || !it.value().is_number_unsigned()) {
            state.problem = std::string(kMetaJson) + ": \"files\" has a bad entry " + nlohmann::json(name).dump();
            return state;
        }
        const std::uintmax_t want = it.value().get<std::uintmax_t>();
        const fs::path path = fs::path(frame_dir) / name;
        const std::string says = ", meta.json says " + std::to_string(want);
        if (!fs::is_regular_file(path, ec)) {
            state.problem = name + ": missing" + says;
            return state;
        }
        const std::uintmax_t size = fs::file_size(path, ec);
        if (ec || size != want) {
            state.problem =
                name + ": " + (ec ? "size unreadable (" + ec.message() + ")" : std::to_string(size) + " bytes") + says;
            return state;
        }
    }
    state.kind = FrameFolderState::complete;
    return state;
}

bool frame_folder_done(const std::string& frame_dir) {
    return frame_folder_check(frame_dir).kind == FrameFolderState::complete;
}

std::string frame_dir_name(std::uint64_t line) {
    char name[32];
    std::snprintf(name, sizeof name, "frame_%06llu", static_cast<unsigned long long>(line));
    return name;
}

} // namespace vksonar::cli
