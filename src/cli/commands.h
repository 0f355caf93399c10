// The vksonar subcommands. Each takes the arguments after its name and returns the exit code;
// bad input is thrown as cli::BadInput (exit 2), other failures as cli::Failure (exit 1).
#pragma once

#include <string>
#include <vector>

namespace vksonar::cli {

int run_render(const std::vector<std::string>& args);
int run_presets(const std::vector<std::string>& args);
int run_info(const std::vector<std::string>& args);
int run_compare(const std::vector<std::string>& args);
int run_bench(const std::vector<std::string>& args);
int run_merge(const std::vector<std::string>& args);      // merge_cmd.cpp: shards of a trajectory into one output
int run_export(const std::vector<std::string>& args);     // export_cmd.cpp: boxes.json of a run -> COCO
int run_bench_load(const std::vector<std::string>& args); // bench_load.cpp; needs no Google Benchmark

} // namespace vksonar::cli
