// Command-line parsing helpers (see args.h).
#include "cli/args.h"

#include <fcntl.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <limits>
#include <string>

#include "config/config_keys.h"

namespace vksonar::cli {

void require_input_file(const std::string& what, const std::string& path) {
    std::error_code ec;
    const std::filesystem::file_status st = std::filesystem::status(path, ec);
    const std::string named = (what.empty() ? "" : what + " ") + path;
    if (ec == std::errc::too_many_symbolic_link_levels) throw BadInput(named + ": a loop of symbolic links");
    if (!std::filesystem::exists(st)) throw BadInput(named + ": no such file");
    if (std::filesystem::is_directory(st)) throw BadInput(named + ": is a directory, not a file");
    if (!std::filesystem::is_regular_file(st))
        throw BadInput(named + ": is not a regular file (a FIFO, socket or device: give a file)");
}

void require_writable_output(const std::string& what, const std::string& path, const std::string& written_at) {
    namespace fs = std::filesystem;
    if (path.empty()) throw BadInput(what + ": the path is empty");
    const fs::path target(written_at.empty() ? path : written_at);
    const fs::path folder = target.has_parent_path() ? target.parent_path() : fs::path(".");
    std::error_code ec;
    if (!fs::is_directory(folder, ec))
        throw BadInput(
            what + " " + path + ": " +
            (fs::exists(folder, ec) ? folder.string() + " is not a folder" : "no folder " + folder.string()));
    // A FIFO, socket or device there (or a link to one) is not a file this run may replace: the rename that
    // publishes the output would put a regular file in its place (/dev/full, a pipe a reader waits on).
    for (const fs::path& existing : {fs::path(path), target}) {
        const fs::file_status st = fs::status(existing, ec);
        if (fs::exists(st) && !fs::is_regular_file(st) && !fs::is_directory(st))
            throw BadInput(what + " " + path + ": is not a regular file (a FIFO, socket or device): not replacing it");
    }
    if (const std::string why = folder_refuses_files(folder.string(), target.filename().string()); !why.empty())
        throw BadInput(what + " " + path + ": cannot write in " + folder.string() + " (" + why + ")");
}

std::string folder_refuses_files(const std::string& folder, const std::string& name) {
    const std::filesystem::path probe =
        std::filesystem::path(folder) / (".~" + name + ".probe-" + std::to_string(::getpid()));
    const int fd = ::open(probe.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0600);
    if (fd < 0) return errno == EEXIST ? std::string() : std::strerror(errno);
    ::close(fd);
    ::unlink(probe.c_str());
    return {};
}

std::string trim(const std::string& text) {
    const auto first = text.find_first_not_of(" \t\r\n");
    if (first == std::string::npos) return {};
    const auto last = text.find_last_not_of(" \t\r\n");
    return text.substr(first, last - first + 1);
}

std::string Args::value(const std::string& name, const std::string& fallback) const {
    const auto it = options.find(name);
    return it == options.end() ? fallback : it->second.back();
}

const std::vector<std::string>& Args::values(const std::string& name) const {
    static const std::vector<std::string> none;
    const auto it = options.find(name);
    return it == options.end() ? none : it->second;
}

std::string closest_word(const std::string& word, const std::vector<std::string>& candidates) {
    std::string best;
    std::size_t best_distance = std::numeric_limits<std::size_t>::max();
    for (const auto& candidate : candidates) {
        const std::size_t distance = config_keys::edit_distance(word, candidate);
        if (distance < best_distance) {
            best_distance = distance;
            best = candidate;
        }
    }
    return best;
}

Args parse_args(const std::vector<std::string>& args, const std::vector<OptionSpec>& specs,
                const std::string& command) {
    Args parsed;
    for (std::size_t i = 0; i < args.size(); ++i) {
        const std::string& arg = args[i];
        if (arg.size() < 2 || arg.compare(0, 2, "--") != 0 || arg == "--") {
            if (arg.size() > 1 && arg[0] == '-' && arg != "-")
                throw BadInput(command + ": unknown option '" + arg + "' (options start with --; see --help)");
            parsed.positional.push_back(arg);
            continue;
        }
        std::string name = arg;
        std::string inline_value;
        bool has_inline = false;
        if (const auto equals = arg.find('='); equals != std::string::npos) {
            name = arg.substr(0, equals);
            inline_value = arg.substr(equals + 1);
            has_inline = true;
        }
        const auto spec = std::find_if(specs.begin(), specs.end(), [&](const OptionSpec& s) { return name == s.name; });
        if (spec == specs.end()) {
            std::vector<std::string> names;
            for (const auto& s : specs)
                names.emplace_back(s.name);
            const std::string hint = closest_word(name, names);
            throw BadInput(command + ": unknown option '" + name + "'" +
                           (hint.empty() ? std::string() : " (did you mean '" + hint + "'?)"));
        }
        std::string value;
        if (spec->takes_value) {
            if (has_inline) {
                value = inline_value;
            } else {
                if (i + 1 >= args.size()) throw BadInput(command + ": option " + name + " needs a value");
                value = args[++i];
            }
        } else if (has_inline) {
            throw BadInput(command + ": option " + name + " takes no value, got '" + inline_value + "'");
        }
        auto& slot = parsed.options[name];
        if (!slot.empty() && !spec->repeatable)
            throw BadInput(command + ": option " + name + " given twice ('" + slot.back() + "' and '" + value + "')");
        slot.push_back(value);
    }
    return parsed;
}

double parse_double(const std::string& text, const std::string& what) {
    const std::string t = trim(text);
    errno = 0;
    char* end = nullptr;
    const double value = t.empty() ? 0.0 : std::strtod(t.c_str(), &end);
    // (strtod reads hexadecimal too, "0x10" and "0x1p3": no number a person means here)
    if (t.empty() || end != t.c_str() + t.size() || t.find_first_of("xX") != std::string::npos)
        throw BadInput(what + ": '" + text + "' is not a number");
    if (!std::isfinite(value) || errno == ERANGE) throw BadInput(what + ": '" + text + "' is not a finite number");
    return value;
}

std::uint64_t parse_u64(const std::string& text, const std::string& what) {
    const std::string t = trim(text);
    errno = 0;
    char* end = nullptr;
    const unsigned long long value = t.empty() ? 0 : std::strtoull(t.c_str(), &end, 10);
    if (t.empty() || t[0] == '-' || t[0] == '+' || end != t.c_str() + t.size() || errno == ERANGE)
        throw BadInput(what + ": '" + text + "' is not a whole number >= 0");
    return value;
}

std::vector<std::string> split(const std::string& text, char separator) {
    std::vector<std::string> items;
    std::size_t start = 0;
    while (true) {
        const auto end = text.find(separator, start);
        items.push_back(trim(text.substr(start, end == std::string::npos ? std::string::npos : end - start)));
        if (end == std::string::npos) break;
        start = end + 1;
    }
    return items;
}

Pose parse_pose(const std::string& text, const std::string& what) {
    const auto items = split(text, ',');
    if (items.size() != 6)
        throw BadInput(what + ": '" + text + "' needs 6 numbers x,y,z,roll,pitch,yaw (metres, degrees), got " +
                       std::to_string(items.size()));
    static const char* const names[6] = {"x", "y", "z", "roll", "pitch", "yaw"};
    double v[6];
    for (int i = 0; i < 6; ++i) {
        try {
            v[i] = parse_double(items[static_cast<std::size_t>(i)], what);
        } catch (const BadInput&) {
            throw BadInput(what + ": '" + text + "': " + names[i] + " = '" + items[static_cast<std::size_t>(i)] +
                           "' is not a finite number (needs x,y,z,roll,pitch,yaw)");
        }
        if (!std::isfinite(static_cast<float>(v[i]))) // the renderer's transforms are float
            throw BadInput(what + ": '" + text + "': " + names[i] + " = '" + items[static_cast<std::size_t>(i)] +
                           "' is past a float's range");
    }
    return Pose{v[0], v[1], v[2], v[3], v[4], v[5]};
}

} // namespace vksonar::cli
