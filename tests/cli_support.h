// Helpers for the tests that run the vksonar executable as a process or work on files (cli_test.cpp,
// hard_cases/bad_input_test.cpp, boxes_test.cpp and the scene-file tests): shell quoting, whole-file
// text I/O, one run of the CLI with its exit code and output, and a folder per test.
#pragma once
#include <sys/wait.h>
#include <unistd.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <system_error>
#include <vector>

#include <gtest/gtest.h>

namespace vksonar::testing {

// `arg` in single quotes for /bin/sh, every ' inside written as '\''.
inline std::string quote(const std::string& arg) {
    std::string quoted = "'";
    for (char ch : arg) {
        if (ch == '\'')
            quoted += "'\\''";
        else
            quoted += ch;
    }
    return quoted + "'";
}

inline std::string read_text(const std::filesystem::path& path) {
    std::ifstream file(path, std::ios::binary);
    std::stringstream text;
    text << file.rdbuf();
    return text.str();
}

inline void write_text(const std::filesystem::path& path, const std::string& text) {
    std::ofstream file(path, std::ios::binary);
    file << text;
}

// One run of the CLI: its exit code (-1 if it did not exit), stdout and stderr.
struct CliRun {
    int exit_code = -1;
    std::string out, err;
    std::vector<std::string> err_lines() const {
        std::vector<std::string> lines;
        std::stringstream stream(err);
        std::string line;
        while (std::getline(stream, line))
            lines.push_back(line);
        return lines;
    }
};

// An empty folder for the running test: <temp>/<prefix><pid>_<test name>, emptied first (a crashed
// earlier run may have left files there). The fixtures remove it in TearDown with remove_test_dir.
inline std::filesystem::path fresh_test_dir(const std::string& prefix) {
    const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
    const std::filesystem::path dir =
        std::filesystem::temp_directory_path() / (prefix + std::to_string(::getpid()) + "_" + info->name());
    std::filesystem::remove_all(dir);
    std::filesystem::create_directories(dir);
    return dir;
}

// Removes a test's folder; errors are ignored (TearDown must not throw, and a leftover folder in the
// temp directory is harmless).
inline void remove_test_dir(const std::filesystem::path& dir) {
    std::error_code ec;
    std::filesystem::remove_all(dir, ec);
}

// Runs VKSONAR_CLI with `args` (stdin from /dev/null), its stdout and stderr caught in files in `dir`.
inline CliRun run_cli(const std::filesystem::path& dir, const std::vector<std::string>& args) {
    std::string command = quote(VKSONAR_CLI);
    for (const auto& arg : args)
        command += " " + quote(arg);
    const std::filesystem::path out = dir / "stdout.txt", err = dir / "stderr.txt";
    command += " > " + quote(out.string()) + " 2> " + quote(err.string()) + " < /dev/null";
    const int status = std::system(command.c_str());
    CliRun result;
    result.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
    result.out = read_text(out);
    result.err = read_text(err);
    return result;
}

} // namespace vksonar::testing
