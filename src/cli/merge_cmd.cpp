// `vksonar merge OUT SHARD...` (merge.h): checks that the shards are the whole of one run, then lets
// the shards' format write OUT. Per-frame folders are merged here; HDF5 in merge_h5.cpp.
#include <unistd.h>

#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <set>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "cli/args.h"
#include "cli/commands.h"
#include "cli/merge.h"

namespace fs = std::filesystem;

namespace vksonar::cli {
namespace {

constexpr const char* kUsage =
    "usage: vksonar merge OUT SHARD...\n"
    "\n"
    "Merges the outputs of 'vksonar render --trajectory ... --shard i/N' into the output the unsharded run\n"
    "writes: frame folders (each shard's --out DIR, with its shard.json) into one folder OUT, .h5 shard\n"
    "files into one OUT.h5, or ROS 2 bags (.mcap) into one OUT.mcap. Every shard 0..N-1 of one run must be\n"
    "given once and be complete (a shard that stopped resumes when re-run); the shards must agree on\n"
    "config, seed, scene, backend, saved arrays and trajectory (bags: topics, frame id and rate too).\n"
    "Frame files are hard-linked into OUT where the file system allows, else copied. OUT must\n"
    "not exist. docs/scale.md\n";

// ---- per-frame folders ---------------------------------------------------------------------------

bool folder_accepts(const std::string& path) {
    std::error_code ec;
    return fs::is_directory(path, ec);
}

bool folder_output_ok(const std::string& out) {
    return !h5_merge_output_ok(out) && !mcap_merge_output_ok(out);
}

ShardInput folder_read(const std::string& path) {
    const FolderManifest m = read_manifest(path);
    ShardInput in;
    in.path = path;
    in.shard = m.shard;
    in.identity = m.identity;
    in.backend = m.backend;
    in.device = m.device;
    for (std::uint64_t line : m.lines) {
        const std::string name = frame_dir_name(line);
        const FrameFolderState state = frame_folder_check((fs::path(path) / name).string());
        if (state.kind == FrameFolderState::complete)
            ++in.frames;
        else if (state.kind == FrameFolderState::damaged) // meta.json is there but a file is not as it says
            throw BadInput("merge: " + (fs::path(path) / name).string() + "/" + state.problem +
                           ": a damaged frame, re-run the shard (it renders the frame again)");
        else if (in.first_missing.empty())
            in.first_missing = name + " (no meta.json)";
    }
    return in;
}

// A file into the merged folder: a hard link (the shard's files are never rewritten in place: every
// write is a new file renamed over the old), else a copy.
void link_or_copy(const fs::path& from, const fs::path& to) {
    std::error_code ec;
    fs::create_hard_link(from, to, ec);
    if (!ec) return;
    fs::copy_file(from, to, ec);
    if (ec) throw Failure("merge: cannot copy " + from.string() + " to " + to.string() + ": " + ec.message());
}

void folder_merge(const std::vector<ShardInput>& shards, const std::string& out) {
    const fs::path target(out);
    const fs::path temporary = (target.has_parent_path() ? target.parent_path() : fs::path(".")) /
                               (".~" + target.filename().string() + ".merging-" + std::to_string(::getpid()));
    std::error_code ec;
    fs::remove_all(temporary, ec);
    if (!fs::create_directories(temporary, ec) || ec)
        throw Failure("merge: cannot create " + temporary.string() + ": " + ec.message());
    try {
        nlohmann::ordered_json list = nlohmann::ordered_json::array();
        // Every frame of a run holds the same files (its --save list, one identity for all shards): the
        // first frame's names, to check the others against.
        std::set<std::string> first_files;
        fs::path first_frame;
        for (const ShardInput& s : shards) {
            const FolderManifest m = read_manifest(s.path);
            for (std::uint64_t line : m.lines) {
                const std::string name = frame_dir_name(line);
                const fs::path from = fs::path(s.path) / name, to = temporary / name;
                if (!fs::create_directory(to, ec) || ec)
                    throw BadInput("merge: " + name + " is in more than one shard (" + s.path + ")");
                std::set<std::string> files;
                for (const auto& entry : fs::directory_iterator(from)) {
                    const std::string file = entry.path().filename().string();
                    if (file.rfind(".~", 0) == 0 || !entry.is_regular_file()) continue; // a temporary of a killed run
                    if (entry.file_size(ec) == 0 || ec)
                        throw BadInput("merge: " + entry.path().string() + ": empty (a damaged frame: re-render it)");
                    files.insert(file);
                    link_or_copy(entry.path(), to / file);
                }
                if (first_frame.empty()) {
                    first_files = files;
                    first_frame = from;
                } else if (files != first_files) {
                    std::string missing, extra;
                    for (const std::string& f : first_files)
                        if (!files.count(f)) missing += (missing.empty() ? "" : ", ") + f;
                    for (const std::string& f : files)
                        if (!first_files.count(f)) extra += (extra.empty() ? "" : ", ") + f;
                    throw BadInput("merge: " + from.string() + " holds other files than " + first_frame.string() +
                                   (missing.empty() ? "" : " (lacks " + missing + ")") +
                                   (extra.empty() ? "" : " (has " + extra + " besides)") +
                                   ": a damaged frame, re-render it");
                }
            }
            list.push_back({{"index", s.shard.index},
                            {"path", s.path},
                            {"source", s.shard.source},
                            {"frames", s.frames},
                            {"backend", s.backend},
                            {"device", s.device}});
        }
        nlohmann::ordered_json merged;
        merged["format"] = "vksonar-merge-1";
        merged["frames"] = shards[0].shard.total;
        merged["trajectory"] = {{"path", shards[0].shard.trajectory}, {"fnv1a64", shards[0].shard.trajectory_hash}};
        merged["shards"] = list;
        std::ofstream file(temporary / "merged.json", std::ios::binary);
        // (a trajectory path that is not UTF-8: U+FFFD instead of dump() throwing)
        file << merged.dump(2, ' ', false, nlohmann::ordered_json::error_handler_t::replace) << "\n";
        if (!file.flush()) throw Failure("merge: cannot write " + (temporary / "merged.json").string());
        file.close();
        fs::rename(temporary, target, ec);
        if (ec) throw Failure("merge: cannot write " + out + ": " + ec.message());
    } catch (...) {
        fs::remove_all(temporary, ec);
        throw;
    }
}

// The formats merge knows, tried in order. One more format (e.g. MCAP) is one more entry.
const MergeFormat kFormats[] = {
    {"HDF5", h5_merge_accepts, h5_merge_output_ok, "a FILE.h5 (or .hdf5)", h5_merge_read, h5_merge},
    {"ROS 2 bags", mcap_merge_accepts, mcap_merge_output_ok, "a FILE.mcap", mcap_merge_read, mcap_merge},
    {"frame folders", folder_accepts, folder_output_ok, "a folder (not ending in .h5 or .mcap)", folder_read,
     folder_merge},
};

std::string shard_name(const ShardRecord& s) {
    return std::to_string(s.index) + "/" + std::to_string(s.count);
}

// Gaps, overlaps, mismatched runs and incomplete shards, each as one line; returns the shards sorted.
std::vector<ShardInput> check_shards(std::vector<ShardInput> shards) {
    const ShardInput& a = shards[0];
    for (const ShardInput& s : shards) {
        if (s.shard.count != a.shard.count)
            throw BadInput("merge: " + s.path + " is shard " + shard_name(s.shard) + " but " + a.path + " is shard " +
                           shard_name(a.shard) + ": shards of different splits");
        if (std::string d = identity_difference(a.identity, s.identity); !d.empty())
            throw BadInput("merge: " + s.path + " (shard " + shard_name(s.shard) + ") is from another run than " +
                           a.path + " (shard " + shard_name(a.shard) + "): " + d);
    }
    std::stable_sort(shards.begin(), shards.end(),
                     [](const ShardInput& x, const ShardInput& y) { return x.shard.index < y.shard.index; });
    for (std::size_t k = 1; k < shards.size(); ++k)
        if (shards[k].shard.index == shards[k - 1].shard.index)
            throw BadInput("merge: shard " + shard_name(shards[k].shard) + " is given twice: " + shards[k - 1].path +
                           " and " + shards[k].path + " (overlapping frames)");
    const std::uint64_t count = a.shard.count, total = a.shard.total;
    std::string have;
    for (const ShardInput& s : shards)
        have += (have.empty() ? "" : ",") + std::to_string(s.shard.index);
    std::uint64_t next = 0; // the first frame ordinal not yet covered
    for (std::uint64_t i = 0, k = 0; i < count; ++i) {
        if (k >= shards.size() || shards[k].shard.index != i) {
            const auto [first, end] = shard_block(i, count, total);
            throw BadInput("merge: shard " + std::to_string(i) + "/" + std::to_string(count) + " is missing (given: " +
                           have + "): a gap of frames " + std::to_string(first) + ".." + std::to_string(end - 1));
        }
        const ShardInput& s = shards[k++];
        if (s.shard.first != next)
            throw BadInput("merge: " + s.path + " (shard " + shard_name(s.shard) + ") starts at frame " +
                           std::to_string(s.shard.first) + ", not " + std::to_string(next) + ": " +
                           (s.shard.first < next ? "an overlap" : "a gap"));
        if (s.frames != s.shard.end - s.shard.first)
            throw BadInput("merge: " + s.path + " (shard " + shard_name(s.shard) + ") is incomplete: " +
                           std::to_string(s.frames) + " of " + std::to_string(s.shard.end - s.shard.first) +
                           " frames, first missing " + s.first_missing + "; re-run the shard (it resumes)");
        next = s.shard.end;
    }
    if (next != total)
        throw BadInput("merge: the shards end at frame " + std::to_string(next) + " of " + std::to_string(total));
    std::set<std::string> devices;
    for (const ShardInput& s : shards)
        devices.insert(s.device);
    if (devices.size() > 1)
        std::fprintf(stderr,
                     "warning: merge: the shards ran on %zu devices: frames agree within the renderer's "
                     "tolerance, not bit for bit, across devices\n",
                     devices.size());
    return shards;
}

} // namespace

int run_merge(const std::vector<std::string>& argv) {
    const Args args = parse_args(argv, {{"--help", false, false}}, "merge");
    if (args.has("--help")) {
        std::fputs(kUsage, stdout);
        return 0;
    }
    if (args.positional.size() < 2) throw BadInput("merge: give OUT and at least one SHARD (vksonar merge --help)");
    const std::string out = args.positional[0];
    if (out.empty()) throw BadInput("merge: OUT is empty");
    const std::vector<std::string> paths(args.positional.begin() + 1, args.positional.end());
    std::error_code ec;
    if (fs::exists(out, ec) || fs::is_symlink(out, ec))
        throw BadInput("merge: OUT " + out + " exists; merge writes a new file or folder");
    require_writable_output("merge: OUT", out); // its folder exists and takes a new file
    const MergeFormat* format = nullptr;
    std::string format_path;
    for (const std::string& path : paths) {
        if (!fs::exists(path, ec)) throw BadInput("merge: " + path + ": no such file or folder");
        const MergeFormat* found = nullptr;
        for (const MergeFormat& f : kFormats)
            if (!found && f.accepts(path)) found = &f;
        if (!found)
            throw BadInput("merge: " + path +
                           ": not a shard's output (a folder with shard.json, a .h5 or a .mcap file)");
        if (format && found != format)
            throw BadInput("merge: " + path + " is " + found->name + " but " + format_path + " is " + format->name +
                           ": merge shards of one format");
        format = found;
        format_path = path;
    }
    if (!format->output_ok(out))
        throw BadInput("merge: OUT " + out + ": the shards are " + format->name + "; OUT must be " +
                       format->output_hint);
    std::vector<ShardInput> shards;
    for (const std::string& path : paths)
        shards.push_back(format->read(path));
    shards = check_shards(std::move(shards));
    format->merge(shards, out);
    std::fprintf(stderr, "vksonar: merged %zu shards (%llu frames) into %s\n", shards.size(),
                 static_cast<unsigned long long>(shards[0].shard.total), out.c_str());
    return 0;
}

} // namespace vksonar::cli
