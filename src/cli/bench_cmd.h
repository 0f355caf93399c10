// The three `vksonar bench` modes (bench_speed.cpp, bench_effects.cpp, bench_accuracy.cpp). Each takes
// the arguments after the mode name and returns the exit code (errors are thrown as in commands.h).
#pragma once

#include <string>
#include <vector>

namespace vksonar::cli::bench {

int run_bench_speed(const std::vector<std::string>& args);
int run_bench_effects(const std::vector<std::string>& args);
int run_bench_accuracy(const std::vector<std::string>& args);

} // namespace vksonar::cli::bench
