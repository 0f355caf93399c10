// Command-line parsing for the vksonar tool: options, typed values and the two error kinds that map
// to exit codes (BadInput -> 2, Failure -> 1).
#pragma once

#include <cstdint>
#include <map>
#include <stdexcept>
#include <string>
#include <vector>

#include "vksonar/scene.h"

namespace vksonar::cli {

// The user gave something unusable (exit code 2). what() is the message after "error: ".
struct BadInput : std::runtime_error {
    using std::runtime_error::runtime_error;
};
// Valid input, but the work failed (exit code 1).
struct Failure : std::runtime_error {
    using std::runtime_error::runtime_error;
};

struct OptionSpec {
    const char* name; // "--scene"
    bool takes_value;
    bool repeatable;
};

struct Args {
    std::map<std::string, std::vector<std::string>> options; // flags map to {""}
    std::vector<std::string> positional;

    bool has(const std::string& name) const { return options.count(name) != 0; }
    // The value of a single-valued option, or `fallback` if it was not given.
    std::string value(const std::string& name, const std::string& fallback = {}) const;
    const std::vector<std::string>& values(const std::string& name) const;
};

// Parses `args` (after the subcommand) against `specs`. Accepts "--opt value" and "--opt=value".
// Throws BadInput for an unknown option (naming the closest one), a missing value, or a repeated
// single-valued option.
Args parse_args(const std::vector<std::string>& args, const std::vector<OptionSpec>& specs, const std::string& command);

// The candidate closest to `word` by edit distance (empty if there are no candidates).
std::string closest_word(const std::string& word, const std::vector<std::string>& candidates);

// Strict number parsing (the whole text, finite). `what` names the option in the error.
double parse_double(const std::string& text, const std::string& what);
std::uint64_t parse_u64(const std::string& text, const std::string& what);
// "x,y,z,roll,pitch,yaw" (metres, degrees). `what` names where the text came from.
Pose parse_pose(const std::string& text, const std::string& what);

// An input file the command reads whole: throws BadInput "WHAT PATH: no such file", ": is a directory" or
// ": is not a regular file" (a FIFO would block the run, /dev/zero fill memory). `what` names the option
// ("--trajectory"; empty for a positional argument).
void require_input_file(const std::string& what, const std::string& path);

// An output file the command will create: a name that is not empty, in a folder that exists and takes a
// new file (a probe file is made there and removed: access() says yes to root on a read-only mount or
// in /proc, where the write itself then failed naming a temporary file, exit 1). Throws BadInput
// "WHAT PATH: ..." (`what` names the option or argument). `written_at`: where the file is made when
// that is not PATH (PATH a symlink: the file goes beside its target); its folder is the one probed.
void require_writable_output(const std::string& what, const std::string& path, const std::string& written_at = {});
// Empty when `folder` takes a new file (a probe file `.~NAME.probe-PID` is made there and removed),
// else why not (strerror). The probe both output checks use: access() says yes to root everywhere.
std::string folder_refuses_files(const std::string& folder, const std::string& name);

// `text` without the spaces, tabs and line ends around it.
std::string trim(const std::string& text);
// Splits on `separator`, trimming spaces around each item.
std::vector<std::string> split(const std::string& text, char separator);

} // namespace vksonar::cli
