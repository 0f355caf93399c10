// Helpers for the tests that run the vksonar executable as a process (cli_test.cpp,
// hard_cases/bad_input_test.cpp): shell quoting and whole-file text I/O.
#pragma once
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>

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

} // namespace vksonar::testing
