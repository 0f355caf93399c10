// `vksonar render --shard` and `vksonar merge` as a process: bad shards (flag and engine environment)
// are one line naming the flag or variable, exit 2, nothing written; frame-folder shards merge into
// the unsharded run's files byte for byte; shard.json and meta.json say which shard a frame came from.
// (.h5 shards, kill-and-resume: tests/python/check_shards.py.)
#include <fcntl.h>
#include <signal.h>
#include <spawn.h>
#include <sys/file.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdlib>
#include <filesystem>
#include <functional>
#include <set>
#include <sstream>
#include <string>
#include <thread>
#include <tuple>
#include <vector>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "cli/frame_files.h"
#include "cli/shard.h"
#include "cli_support.h"

namespace fs = std::filesystem;
using vksonar::testing::fresh_test_dir;
using vksonar::testing::quote;
using vksonar::testing::read_text;
using vksonar::testing::remove_test_dir;
using vksonar::testing::write_text;

namespace {

// Makes meta.json as a run before it listed the frame's files wrote it.
void strip_files(const fs::path& meta) {
    auto json = nlohmann::ordered_json::parse(read_text(meta));
    json.erase("files");
    write_text(meta, json.dump());
}

struct ShardRun {
    int exit_code = -1;
    std::string err;
    std::size_t err_lines() const {
        std::size_t n = 0;
        for (char c : err)
            n += c == '\n';
        return n;
    }
};

class Shard : public ::testing::Test {
protected:
    void SetUp() override {
        dir_ = fresh_test_dir("vksonar_shard_test_");
        std::string poses = "x,y,z,roll,pitch,yaw\n";
        for (int i = 0; i < 7; ++i)
            poses +=
                std::to_string(0.3 * i) + ",0," + std::to_string(-0.1 * i) + ",0,10," + std::to_string(4 * i) + "\n";
        write_text(dir_ / "poses.csv", poses);
    }
    void TearDown() override { remove_test_dir(dir_); }

    // Runs vksonar with `env` (NAME=value ...) in an environment cleared of the engines' variables.
    ShardRun run(const std::vector<std::string>& args, const std::vector<std::string>& env = {}) const {
        std::string command = "env -u SLURM_ARRAY_TASK_ID -u SLURM_ARRAY_TASK_MIN -u SLURM_ARRAY_TASK_MAX "
                              "-u SLURM_ARRAY_TASK_STEP -u SLURM_ARRAY_TASK_COUNT -u JOB_COMPLETION_INDEX "
                              "-u VKSONAR_SHARD_COUNT";
        for (const auto& e : env)
            command += " " + quote(e);
        command += " " + quote(VKSONAR_CLI);
        for (const auto& a : args)
            command += " " + quote(a);
        const fs::path err = dir_ / "stderr.txt";
        command += " > /dev/null 2> " + quote(err.string()) + " < /dev/null";
        const int status = std::system(command.c_str());
        ShardRun r;
        r.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
        r.err = read_text(err);
        return r;
    }

    std::vector<std::string> render_args(const std::string& out, std::vector<std::string> extra = {}) const {
        std::vector<std::string> args = {"render",
                                         "--backend",
                                         "cpu",
                                         "--set",
                                         "bins=32",
                                         "--set",
                                         "beams=16",
                                         "--set",
                                         "horizontal_beamwidth=9",
                                         "--set",
                                         "range_min=6",
                                         "--set",
                                         "display.fan_width=64",
                                         "--trajectory",
                                         (dir_ / "poses.csv").string(),
                                         "--out",
                                         (dir_ / out).string()};
        args.insert(args.end(), extra.begin(), extra.end());
        return args;
    }

    // Exit 2, one line "error: ..." holding every `expected`, and no output folder.
    void expect_bad(const std::vector<std::string>& extra, const std::vector<std::string>& env,
                    const std::vector<std::string>& expected) const {
        const ShardRun r = run(render_args("never", extra), env);
        std::string what;
        for (const auto& e : env)
            what += e + " ";
        for (const auto& e : extra)
            what += e + " ";
        EXPECT_EQ(r.exit_code, 2) << what << r.err;
        EXPECT_EQ(r.err_lines(), 1u) << what << r.err;
        EXPECT_EQ(r.err.rfind("error: ", 0), 0u) << what << r.err;
        for (const auto& text : expected)
            EXPECT_NE(r.err.find(text), std::string::npos) << what << "\nwanted: " << text << "\ngot: " << r.err;
        EXPECT_FALSE(fs::exists(dir_ / "never")) << what;
    }

    fs::path dir_;
};

TEST(ShardBlocks, ContiguousBalancedAndCovering) {
    using vksonar::cli::shard_block;
    for (std::uint64_t total : {0u, 1u, 7u, 10u, 1000u})
        for (std::uint64_t count : {1u, 2u, 3u, 4u, 11u}) {
            std::uint64_t next = 0, smallest = ~0ull, largest = 0;
            for (std::uint64_t i = 0; i < count; ++i) {
                const auto [first, end] = shard_block(i, count, total);
                EXPECT_EQ(first, next) << i << "/" << count << " of " << total;
                next = end;
                smallest = std::min(smallest, end - first);
                largest = std::max(largest, end - first);
            }
            EXPECT_EQ(next, total);
            EXPECT_LE(largest - smallest, 1u) << count << " shards of " << total;
        }
    EXPECT_EQ(shard_block(1, 3, 10), std::make_pair(std::uint64_t(3), std::uint64_t(6)));
}

TEST_F(Shard, BadShardFlagIsOneLine) {
    expect_bad({"--shard", "3/2"}, {}, {"--shard '3/2'", "index 3 is not below the count 2"});
    expect_bad({"--shard", "2/2"}, {}, {"--shard '2/2'", "numbered 0..1"});
    expect_bad({"--shard", "0/0"}, {}, {"--shard '0/0'", "at least 1"});
    expect_bad({"--shard", "abc"}, {}, {"--shard 'abc'", "INDEX/COUNT"});
    expect_bad({"--shard", "-1/4"}, {}, {"--shard '-1/4'", "INDEX/COUNT"});
    expect_bad({"--shard", "1/4", "--shard-count", "4"}, {}, {"--shard-count", "only with JOB_COMPLETION_INDEX"});
    expect_bad({"--shard-count", "4"}, {}, {"--shard-count 4", "no JOB_COMPLETION_INDEX"});
    expect_bad({}, {"VKSONAR_SHARD_COUNT=4"}, {"VKSONAR_SHARD_COUNT=4", "no JOB_COMPLETION_INDEX"});
    // Without a trajectory there is nothing to split.
    const ShardRun r = run({"render", "--backend", "cpu", "--shard", "0/2", "--out", (dir_ / "never").string()});
    EXPECT_EQ(r.exit_code, 2) << r.err;
    EXPECT_NE(r.err.find("--shard: shards split a trajectory"), std::string::npos) << r.err;
}

// ROS 2 bags: each shard (flag, Slurm array or Kubernetes Indexed Job environment) writes its block of
// frames as a bag with its shard record; `vksonar merge` joins them into the unsharded run's bag byte
// for byte (same file name: rosbag2's metadata names the file), zstd chunks too. Refused in one line
// each, OUT not written: a gap, an overlap, a shard of another run (seed, --rate), a bag cut short (a
// killed shard), an unsharded bag.
TEST_F(Shard, BagShardsMergeIntoTheUnshardedBag) {
    auto bag_args = [&](const fs::path& bag, std::vector<std::string> extra) {
        std::vector<std::string> args = render_args("unused", std::move(extra));
        for (std::size_t i = 0; i + 1 < args.size(); ++i)
            if (args[i] == "--out") args[i + 1] = bag.string();
        return args;
    };
    for (const bool zstd : {false, true}) {
        const fs::path dir = dir_ / (zstd ? "zstd" : "plain");
        fs::create_directories(dir / "whole");
        fs::create_directories(dir / "merged");
        const std::vector<std::string> compress =
            zstd ? std::vector<std::string>{"--compress"} : std::vector<std::string>{};
        ASSERT_EQ(run(bag_args(dir / "whole" / "run.mcap", compress)).exit_code, 0);
        std::vector<std::string> merge = {"merge", (dir / "merged" / "run.mcap").string()};
        for (int i = 0; i < 3; ++i) {
            std::vector<std::string> extra = compress;
            std::vector<std::string> env;
            if (i == 1) { // the middle one from a Slurm array's environment, the last from a K8s Job's
                env = {"SLURM_ARRAY_TASK_ID=1", "SLURM_ARRAY_TASK_COUNT=3"};
            } else if (i == 2) {
                env = {"JOB_COMPLETION_INDEX=2", "VKSONAR_SHARD_COUNT=3"};
            } else {
                extra.insert(extra.end(), {"--shard", std::to_string(i) + "/3"});
            }
            const fs::path part = dir / ("part" + std::to_string(i) + ".mcap");
            const ShardRun r = run(bag_args(part, extra), env);
            ASSERT_EQ(r.exit_code, 0) << r.err;
            merge.push_back(part.string());
        }
        const ShardRun merged = run(merge);
        ASSERT_EQ(merged.exit_code, 0) << merged.err;
        const std::string whole = read_text(dir / "whole" / "run.mcap"),
                          joined = read_text(dir / "merged" / "run.mcap");
        EXPECT_GT(whole.size(), 1000u);
        EXPECT_TRUE(whole == joined) << "merged bag differs from the unsharded one (" << joined.size() << " vs "
                                     << whole.size() << " bytes), zstd " << zstd;
    }
    const fs::path dir = dir_ / "plain";
    auto refused = [&](std::vector<std::string> shards, const std::string& text) {
        std::vector<std::string> args = {"merge", (dir_ / "never.mcap").string()};
        for (const auto& name : shards)
            args.push_back((dir / name).string());
        const ShardRun r = run(args);
        EXPECT_EQ(r.exit_code, 2) << r.err;
        EXPECT_EQ(r.err_lines(), 1u) << r.err;
        EXPECT_NE(r.err.find(text), std::string::npos) << r.err;
        EXPECT_FALSE(fs::exists(dir_ / "never.mcap"));
    };
    refused({"part0.mcap", "part2.mcap"}, "shard 1/3 is missing");
    refused({"part0.mcap", "part1.mcap", "part1.mcap", "part2.mcap"}, "given twice");
    ASSERT_EQ(run(bag_args(dir / "seed7.mcap", {"--shard", "1/3", "--seed", "7"})).exit_code, 0);
    refused({"part0.mcap", "seed7.mcap", "part2.mcap"}, "seed: 1 vs 7");
    // The stamps are ordinal / --rate: a shard at another rate is another run.
    ASSERT_EQ(run(bag_args(dir / "rate5.mcap", {"--shard", "1/3", "--rate", "5"})).exit_code, 0);
    refused({"part0.mcap", "rate5.mcap", "part2.mcap"}, "rate: 10 vs 5");
    const std::string part1 = read_text(dir / "part1.mcap");
    write_text(dir / "cut.mcap", part1.substr(0, part1.size() / 2));
    refused({"part0.mcap", "cut.mcap", "part2.mcap"}, "is incomplete: 0 of 2 frames");
    refused({"whole/run.mcap"}, "not a shard");
    const ShardRun nowhere =
        run({"merge", (dir_ / "no_such_folder" / "run.mcap").string(), (dir / "part0.mcap").string(),
             (dir / "part1.mcap").string(), (dir / "part2.mcap").string()});
    EXPECT_EQ(nowhere.exit_code, 2) << nowhere.err;
    EXPECT_EQ(nowhere.err_lines(), 1u) << nowhere.err;
    EXPECT_NE(nowhere.err.find("no folder"), std::string::npos) << nowhere.err;
    std::string flipped = read_text(dir / "part1.mcap");
    flipped[flipped.size() / 2] = static_cast<char>(flipped[flipped.size() / 2] ^ 0x5a); // inside its chunk
    write_text(dir / "flipped.mcap", flipped);
    refused({"part0.mcap", "flipped.mcap", "part2.mcap"}, "flipped.mcap: a chunk's CRC does not match");
}

// A bag's stamps of a trajectory without a time column are frame / --rate s: a rate that puts the last
// frame past a ROS stamp's int32 seconds, or frames less than its 1 ns step apart, is refused (an audit's:
// 1e-10 stamped two frames 9223372036854775808 ns, 1e300 every frame 0, exit 0).
TEST_F(Shard, BagRateOutsideRosTimeIsOneLine) {
    const std::pair<const char*, const char*> cases[] = {{"1e-10", "past a ROS time stamp's 2147483647 s"},
                                                         {"1e300", "less than 1 ns apart"}};
    for (const auto& [rate, text] : cases) {
        std::vector<std::string> args = render_args("unused", {"--rate", rate});
        for (std::size_t i = 0; i + 1 < args.size(); ++i)
            if (args[i] == "--out") args[i + 1] = (dir_ / "never.mcap").string();
        const ShardRun r = run(args);
        EXPECT_EQ(r.exit_code, 2) << rate << r.err;
        EXPECT_EQ(r.err_lines(), 1u) << r.err;
        EXPECT_NE(r.err.find(std::string("--rate: ") + rate), std::string::npos) << r.err;
        EXPECT_NE(r.err.find(text), std::string::npos) << r.err;
        EXPECT_FALSE(fs::exists(dir_ / "never.mcap"));
    }
}

// More shards than frames: a shard whose block is empty writes a bag with its record and no chunk
// (so no Schema or Channel record; /tf_static comes with a first frame). Merged, the bags are still
// the unsharded bag byte for byte (shard 0 here is empty: topics and /tf_static come from shard 1).
TEST_F(Shard, BagShardsWithEmptyBlocksMerge) {
    auto bag_args = [&](const fs::path& bag, std::vector<std::string> extra) {
        std::vector<std::string> args = render_args("unused", std::move(extra));
        for (std::size_t i = 0; i + 1 < args.size(); ++i)
            if (args[i] == "--out") args[i + 1] = bag.string();
        return args;
    };
    fs::create_directories(dir_ / "whole");
    fs::create_directories(dir_ / "merged");
    ASSERT_EQ(run(bag_args(dir_ / "whole" / "run.mcap", {})).exit_code, 0);
    std::vector<std::string> merge = {"merge", (dir_ / "merged" / "run.mcap").string()};
    for (int i = 0; i < 9; ++i) { // 7 frames in 9 shards: blocks 0 and 4 are empty
        const fs::path part = dir_ / ("part" + std::to_string(i) + ".mcap");
        const ShardRun r = run(bag_args(part, {"--shard", std::to_string(i) + "/9"}));
        ASSERT_EQ(r.exit_code, 0) << r.err;
        if (i == 0) {
            EXPECT_NE(r.err.find("no frames"), std::string::npos) << r.err;
        }
        merge.push_back(part.string());
    }
    const ShardRun merged = run(merge);
    ASSERT_EQ(merged.exit_code, 0) << merged.err;
    EXPECT_TRUE(read_text(dir_ / "whole" / "run.mcap") == read_text(dir_ / "merged" / "run.mcap"));
}

// A bag shard run again: a complete one is left as it is (nothing rendered); one of another shard or
// run is refused in one line and kept; one cut short (its frames not closed into a chunk) is written
// again and then merges into the unsharded bag. (A killed shard whose bag has whole chunks keeps their
// frames: tests/python/check_shards.py kills one.)
TEST_F(Shard, BagShardReRuns) {
    auto bag_args = [&](const fs::path& bag, std::vector<std::string> extra) {
        std::vector<std::string> args = render_args("unused", std::move(extra));
        for (std::size_t i = 0; i + 1 < args.size(); ++i)
            if (args[i] == "--out") args[i + 1] = bag.string();
        return args;
    };
    fs::create_directories(dir_ / "whole");
    fs::create_directories(dir_ / "merged");
    ASSERT_EQ(run(bag_args(dir_ / "whole" / "run.mcap", {})).exit_code, 0);
    for (int i = 0; i < 3; ++i)
        ASSERT_EQ(run(bag_args(dir_ / ("part" + std::to_string(i) + ".mcap"), {"--shard", std::to_string(i) + "/3"}))
                      .exit_code,
                  0);
    const fs::path part1 = dir_ / "part1.mcap";
    const std::string complete = read_text(part1);

    ShardRun r = run(bag_args(part1, {"--shard", "1/3"}));
    ASSERT_EQ(r.exit_code, 0) << r.err;
    EXPECT_NE(r.err.find("2 already on disk"), std::string::npos) << r.err;
    EXPECT_NE(r.err.find(": 0 frames rendered"), std::string::npos) << r.err;
    EXPECT_TRUE(read_text(part1) == complete) << "a complete bag shard was rewritten";

    r = run(bag_args(part1, {"--shard", "1/3", "--seed", "7"}));
    EXPECT_EQ(r.exit_code, 2) << r.err;
    EXPECT_EQ(r.err_lines(), 1u) << r.err;
    EXPECT_NE(r.err.find("holds another run (seed: 1 vs 7)"), std::string::npos) << r.err;
    r = run(bag_args(part1, {"--shard", "1/3", "--rate", "20"}));
    EXPECT_EQ(r.exit_code, 2) << r.err;
    EXPECT_NE(r.err.find("holds another run (rate: 10 vs 20)"), std::string::npos) << r.err;
    r = run(bag_args(part1, {"--shard", "2/3"}));
    EXPECT_EQ(r.exit_code, 2) << r.err;
    EXPECT_EQ(r.err_lines(), 1u) << r.err;
    EXPECT_NE(r.err.find("holds shard 1/3, not shard 2/3"), std::string::npos) << r.err;
    r = run(bag_args(part1, {}));
    EXPECT_EQ(r.exit_code, 0) << r.err; // unsharded: a new bag over it, as any unsharded run
    write_text(part1, complete);
    EXPECT_TRUE(read_text(part1) == complete);

    // Cut inside its only chunk: the record is there, no frame is whole; the re-run writes it whole.
    write_text(part1, complete.substr(0, complete.size() / 2));
    r = run(bag_args(part1, {"--shard", "1/3"}));
    ASSERT_EQ(r.exit_code, 0) << r.err;
    EXPECT_NE(r.err.find(": 2 frames rendered"), std::string::npos) << r.err;
    r = run({"merge", (dir_ / "merged" / "run.mcap").string(), (dir_ / "part0.mcap").string(), part1.string(),
             (dir_ / "part2.mcap").string()});
    ASSERT_EQ(r.exit_code, 0) << r.err;
    EXPECT_TRUE(read_text(dir_ / "whole" / "run.mcap") == read_text(dir_ / "merged" / "run.mcap"));
}

TEST_F(Shard, NonsenseEnvironmentIsOneLine) {
    expect_bad({}, {"SLURM_ARRAY_TASK_ID=abc", "SLURM_ARRAY_TASK_COUNT=4"}, {"SLURM_ARRAY_TASK_ID", "'abc'"});
    expect_bad({}, {"SLURM_ARRAY_TASK_ID=1", "SLURM_ARRAY_TASK_MIN=0", "SLURM_ARRAY_TASK_MAX=x"},
               {"SLURM_ARRAY_TASK_MAX", "'x'"});
    expect_bad({}, {"SLURM_ARRAY_TASK_ID=9", "SLURM_ARRAY_TASK_MIN=0", "SLURM_ARRAY_TASK_MAX=3"},
               {"SLURM_ARRAY_TASK_ID=9", "not in the array's", "0..3"});
    expect_bad({}, {"SLURM_ARRAY_TASK_ID=1"}, {"SLURM_ARRAY_TASK_ID=1", "--shard INDEX/COUNT"});
    // An array "0,1,5" is not one range: MIN..MAX says 6 tasks, COUNT 3.
    expect_bad(
        {}, {"SLURM_ARRAY_TASK_ID=5", "SLURM_ARRAY_TASK_MIN=0", "SLURM_ARRAY_TASK_MAX=5", "SLURM_ARRAY_TASK_COUNT=3"},
        {"SLURM_ARRAY_TASK_COUNT=3", "not one range"});
    expect_bad({}, {"SLURM_ARRAY_TASK_ID=4", "SLURM_ARRAY_TASK_COUNT=4"}, {"SLURM_ARRAY_TASK_ID=4", "COUNT=4"});
    expect_bad({}, {"JOB_COMPLETION_INDEX=2"}, {"JOB_COMPLETION_INDEX=2", "--shard-count N", "VKSONAR_SHARD_COUNT"});
    expect_bad({}, {"JOB_COMPLETION_INDEX=2", "VKSONAR_SHARD_COUNT=two"}, {"VKSONAR_SHARD_COUNT", "'two'"});
    expect_bad({}, {"JOB_COMPLETION_INDEX=5", "VKSONAR_SHARD_COUNT=5"}, {"JOB_COMPLETION_INDEX=5", "count 5"});
    expect_bad({}, {"JOB_COMPLETION_INDEX=-1", "VKSONAR_SHARD_COUNT=5"}, {"JOB_COMPLETION_INDEX", "'-1'"});
    expect_bad({"--shard-count", "3"}, {"SLURM_ARRAY_TASK_ID=0", "SLURM_ARRAY_TASK_COUNT=4"},
               {"--shard-count 3", "does not match", "4 tasks"});
}

TEST_F(Shard, StepArrayAndFlagBeatsEnvironment) {
    // --array=10-40:10 (4 tasks): task 30 is shard 2/4, frames 3..4 of 7 (lines 5..6).
    ShardRun r = run(render_args("step", {"--save", "polar"}),
                     {"SLURM_ARRAY_TASK_ID=30", "SLURM_ARRAY_TASK_MIN=10", "SLURM_ARRAY_TASK_MAX=40",
                      "SLURM_ARRAY_TASK_STEP=10", "SLURM_ARRAY_TASK_COUNT=4"});
    ASSERT_EQ(r.exit_code, 0) << r.err;
    EXPECT_NE(r.err.find("shard 2/4 (SLURM_ARRAY_TASK_ID=30"), std::string::npos) << r.err;
    EXPECT_TRUE(fs::exists(dir_ / "step" / "frame_000005" / "polar.npy"));
    EXPECT_TRUE(fs::exists(dir_ / "step" / "frame_000006" / "polar.npy"));
    EXPECT_FALSE(fs::exists(dir_ / "step" / "frame_000004"));
    EXPECT_FALSE(fs::exists(dir_ / "step" / "frame_000007"));
    // --shard wins over the environment.
    r = run(render_args("flag", {"--save", "polar", "--shard", "0/7"}),
            {"SLURM_ARRAY_TASK_ID=30", "SLURM_ARRAY_TASK_MIN=10", "SLURM_ARRAY_TASK_MAX=40"});
    ASSERT_EQ(r.exit_code, 0) << r.err;
    EXPECT_TRUE(fs::exists(dir_ / "flag" / "frame_000002" / "meta.json"));
    EXPECT_FALSE(fs::exists(dir_ / "flag" / "frame_000003"));
    // An Indexed Job's index with --shard-count: pod 1 of 3 renders frames 2..3 (lines 4..5).
    r = run(render_args("k8s", {"--save", "polar", "--shard-count", "3"}), {"JOB_COMPLETION_INDEX=1"});
    ASSERT_EQ(r.exit_code, 0) << r.err;
    EXPECT_NE(r.err.find("shard 1/3 (JOB_COMPLETION_INDEX=1 (--shard-count 3))"), std::string::npos) << r.err;
    EXPECT_TRUE(fs::exists(dir_ / "k8s" / "frame_000004" / "meta.json"));
    EXPECT_TRUE(fs::exists(dir_ / "k8s" / "frame_000005" / "meta.json"));
    EXPECT_FALSE(fs::exists(dir_ / "k8s" / "frame_000003"));
    EXPECT_FALSE(fs::exists(dir_ / "k8s" / "frame_000006"));
    // More shards than frames: an empty shard is a success with its shard.json.
    r = run(render_args("empty", {"--save", "polar", "--shard", "0/9"}));
    ASSERT_EQ(r.exit_code, 0) << r.err;
    EXPECT_NE(r.err.find("no frames"), std::string::npos) << r.err;
    EXPECT_TRUE(fs::exists(dir_ / "empty" / "shard.json"));
}

TEST_F(Shard, FolderShardsMergeIntoTheUnshardedRun) {
    ASSERT_EQ(run(render_args("whole")).exit_code, 0);
    std::vector<std::string> merge = {"merge", (dir_ / "merged").string()};
    for (int i = 2; i >= 0; --i) { // any order
        const std::string name = "part" + std::to_string(i);
        const ShardRun r = run(render_args(name, {"--shard", std::to_string(i) + "/3"}));
        ASSERT_EQ(r.exit_code, 0) << r.err;
        merge.push_back((dir_ / name).string());
    }
    // shard.json and meta.json say which shard: 7 frames in 3 shards are 0..1, 2..3, 4..6.
    const auto manifest = nlohmann::json::parse(read_text(dir_ / "part1" / "shard.json"));
    EXPECT_EQ(manifest["shard"]["index"], 1);
    EXPECT_EQ(manifest["frames"]["first"], 2);
    EXPECT_EQ(manifest["frames"]["end"], 4);
    EXPECT_EQ(manifest["lines"], nlohmann::json::parse("[[4, 5]]"));
    const auto meta = nlohmann::json::parse(read_text(dir_ / "part1" / "frame_000004" / "meta.json"));
    EXPECT_EQ(meta["shard"]["index"], 1);
    EXPECT_EQ(meta["shard"]["count"], 3);
    const ShardRun merged = run(merge);
    ASSERT_EQ(merged.exit_code, 0) << merged.err;
    std::size_t files = 0;
    for (int line = 2; line <= 8; ++line) {
        const std::string frame = vksonar::cli::frame_dir_name(line);
        for (const char* name : {"fan.png", "polar.npy", "polar.png", "polar_u16.npy"}) {
            const std::string a = read_text(dir_ / "whole" / frame / name),
                              b = read_text(dir_ / "merged" / frame / name);
            EXPECT_FALSE(a.empty()) << frame << "/" << name;
            EXPECT_TRUE(a == b) << frame << "/" << name << " differs from the unsharded run";
            ++files;
        }
        auto whole = nlohmann::json::parse(read_text(dir_ / "whole" / frame / "meta.json"));
        auto part = nlohmann::json::parse(read_text(dir_ / "merged" / frame / "meta.json"));
        part.erase("shard");
        EXPECT_EQ(whole["frame_index"], line);
        whole.erase("timings_ms"); // measured, so never the same
        part.erase("timings_ms");
        EXPECT_TRUE(whole == part) << frame << ": meta.json differs beyond its shard and timings";
    }
    EXPECT_EQ(files, 28u);
    EXPECT_FALSE(fs::exists(dir_ / "merged" / "frame_000009"));
    const auto record = nlohmann::json::parse(read_text(dir_ / "merged" / "merged.json"));
    EXPECT_EQ(record["frames"], 7);
    EXPECT_EQ(record["shards"].size(), 3u);
}

TEST_F(Shard, MergeRefusesGapsOverlapsAndOtherRuns) {
    for (int i = 0; i < 3; ++i)
        ASSERT_EQ(run(render_args("p" + std::to_string(i), {"--save", "polar", "--shard", std::to_string(i) + "/3"}))
                      .exit_code,
                  0);
    ASSERT_EQ(run(render_args("other", {"--save", "polar", "--shard", "1/3", "--set", "beams=24", "--set",
                                        "horizontal_beamwidth=6"}))
                  .exit_code,
              0);
    ASSERT_EQ(run(render_args("more", {"--save", "polar,polar_png", "--shard", "1/3"})).exit_code, 0);
    const auto p = [&](const char* name) { return (dir_ / name).string(); };
    auto refused = [&](const std::vector<std::string>& shards, const std::vector<std::string>& expected) {
        std::vector<std::string> args = {"merge", p("out")};
        args.insert(args.end(), shards.begin(), shards.end());
        const ShardRun r = run(args);
        EXPECT_EQ(r.exit_code, 2) << r.err;
        EXPECT_EQ(r.err_lines(), 1u) << r.err;
        for (const auto& text : expected)
            EXPECT_NE(r.err.find(text), std::string::npos) << "wanted: " << text << "\ngot: " << r.err;
        EXPECT_FALSE(fs::exists(p("out")));
    };
    refused({p("p0"), p("p2")}, {"shard 1/3 is missing", "frames 2..3"});
    refused({p("p0"), p("p1"), p("p1"), p("p2")}, {"shard 1/3 is given twice"});
    refused({p("p0"), p("other"), p("p2")}, {"another run", "config.beams: 16 vs 24"});
    refused({p("p0"), p("more"), p("p2")}, {"another run", "save: polar vs polar,polar_png"});
    refused({p("p0"), p("poses.csv")}, {"poses.csv", "not a shard's output"});
    refused({p("p0"), p("nothing")}, {"nothing", "no such file"});
    // a shard.json that is JSON but no shard record: named, without nlohmann's exception tag
    fs::create_directories(dir_ / "odd");
    write_text(dir_ / "odd" / "shard.json", "{\"shard\": 1}");
    refused({p("p0"), p("odd")}, {"odd/shard.json: not a shard record (key 'format' not found)"});
    // A frame folder without meta.json: the shard is incomplete.
    fs::remove(dir_ / "p2" / "frame_000007" / "meta.json");
    refused({p("p0"), p("p1"), p("p2")}, {"p2 (shard 2/3) is incomplete", "2 of 3 frames", "frame_000007"});
    // ...and re-running the shard renders just that frame.
    const ShardRun again = run(render_args("p2", {"--save", "polar", "--shard", "2/3"}));
    ASSERT_EQ(again.exit_code, 0) << again.err;
    EXPECT_NE(again.err.find("2 already on disk"), std::string::npos) << again.err;
    EXPECT_NE(again.err.find(": 1 frames rendered"), std::string::npos) << again.err;
    // A re-run with another config into the same folder is refused, and the folder kept.
    const ShardRun clash = run(render_args("p2", {"--save", "polar", "--shard", "2/3", "--seed", "9"}));
    EXPECT_EQ(clash.exit_code, 2) << clash.err;
    EXPECT_NE(clash.err.find("another run (seed: 1 vs 9)"), std::string::npos) << clash.err;
    EXPECT_TRUE(fs::exists(dir_ / "p2" / "frame_000007" / "meta.json"));
    const ShardRun wrong = run(render_args("p2", {"--save", "polar", "--shard", "1/3"}));
    EXPECT_EQ(wrong.exit_code, 2) << wrong.err;
    EXPECT_NE(wrong.err.find("holds shard 2/3, not shard 1/3"), std::string::npos) << wrong.err;
    const ShardRun ok = run({"merge", p("out"), p("p0"), p("p1"), p("p2")});
    EXPECT_EQ(ok.exit_code, 0) << ok.err;
    EXPECT_TRUE(fs::exists(dir_ / "out" / "frame_000008" / "polar.npy"));
}

// A cluster's nodes (or a requeued task on another node) may see the scene under different paths: shards
// whose scene files hold the same content merge, and a re-run finds its frames; a scene whose content
// changed is another run, refused naming the content hash. (identity_difference compares the path only
// where no hash is recorded.)
TEST_F(Shard, SceneMayMoveBetweenNodesButNotChange) {
    const std::string scene_text = read_text(fs::path(VKSONAR_ASSET_DIR) / "scenes" / "default.gltf");
    fs::create_directories(dir_ / "node_a");
    fs::create_directories(dir_ / "node_b");
    write_text(dir_ / "node_a" / "scene.gltf", scene_text);
    write_text(dir_ / "node_b" / "seabed.gltf", scene_text);
    // the same scene moved 1 m: another run, though its file name is node_a's
    nlohmann::json moved = nlohmann::json::parse(scene_text);
    for (auto& node : moved.at("nodes"))
        if (node.contains("translation")) node["translation"][0] = node["translation"][0].get<double>() + 1.0;
    fs::create_directories(dir_ / "node_c");
    write_text(dir_ / "node_c" / "scene.gltf", moved.dump());
    const auto shard = [&](const char* out, const char* index, const fs::path& scene) {
        return run(render_args(out, {"--save", "polar", "--shard", index, "--scene", scene.string()}));
    };
    ASSERT_EQ(shard("p0", "0/2", dir_ / "node_a" / "scene.gltf").exit_code, 0);
    ASSERT_EQ(shard("p1", "1/2", dir_ / "node_b" / "seabed.gltf").exit_code, 0);
    ASSERT_EQ(shard("p1c", "1/2", dir_ / "node_c" / "scene.gltf").exit_code, 0);
    const auto p = [&](const char* name) { return (dir_ / name).string(); };
    const ShardRun changed = run({"merge", p("never"), p("p0"), p("p1c")});
    EXPECT_EQ(changed.exit_code, 2) << changed.err;
    EXPECT_EQ(changed.err_lines(), 1u) << changed.err;
    EXPECT_NE(changed.err.find("another run than"), std::string::npos) << changed.err;
    EXPECT_NE(changed.err.find(": scene_fnv1a64: "), std::string::npos) << changed.err;
    EXPECT_FALSE(fs::exists(p("never")));
    const ShardRun ok = run({"merge", p("out"), p("p0"), p("p1")});
    ASSERT_EQ(ok.exit_code, 0) << ok.err;
    EXPECT_EQ(read_text(dir_ / "out" / "frame_000006" / "polar.npy"),
              read_text(dir_ / "p1" / "frame_000006" / "polar.npy"));
    // A re-run of shard 1 seeing the scene at node_a's path finds its frames on disk.
    fs::remove(dir_ / "p1" / "frame_000006" / "meta.json");
    const ShardRun again = shard("p1", "1/2", dir_ / "node_a" / "scene.gltf");
    ASSERT_EQ(again.exit_code, 0) << again.err;
    EXPECT_NE(again.err.find("3 already on disk"), std::string::npos) << again.err;
    // ...and one seeing the changed scene there is refused, the folder kept.
    fs::remove(dir_ / "p1" / "frame_000006" / "meta.json");
    const ShardRun clash = shard("p1", "1/2", dir_ / "node_c" / "scene.gltf");
    EXPECT_EQ(clash.exit_code, 2) << clash.err;
    EXPECT_NE(clash.err.find("scene_fnv1a64: "), std::string::npos) << clash.err;
    EXPECT_TRUE(fs::exists(dir_ / "p1" / "frame_000005" / "meta.json"));
}

// A folder shard and an unsharded run never share a folder: an unsharded run into a shard's folder left
// the stale shard.json beside its own frames, and merge then took frames of two runs (seeds 1 and 9 here)
// as one; a shard into an unsharded run's folder took that run's frames as its own. Both are refused in
// one line, the folder left as it was.
TEST_F(Shard, FolderShardAndUnshardedRunNeverShareAFolder) {
    ASSERT_EQ(run(render_args("p0", {"--save", "polar", "--shard", "0/2"})).exit_code, 0);
    const std::string record = read_text(dir_ / "p0" / "shard.json");
    const std::string frame = read_text(dir_ / "p0" / "frame_000001" / "polar.npy");
    ShardRun r = run(render_args("p0", {"--save", "polar", "--seed", "9"}));
    EXPECT_EQ(r.exit_code, 2) << r.err;
    EXPECT_EQ(r.err_lines(), 1u) << r.err;
    EXPECT_NE(r.err.find("holds shard 0/2 of a run (shard.json): give the unsharded run another --out"),
              std::string::npos)
        << r.err;
    EXPECT_EQ(read_text(dir_ / "p0" / "shard.json"), record);
    EXPECT_TRUE(read_text(dir_ / "p0" / "frame_000001" / "polar.npy") == frame);

    ASSERT_EQ(run(render_args("whole", {"--save", "polar"})).exit_code, 0);
    r = run(render_args("whole", {"--save", "polar", "--shard", "1/2"}));
    EXPECT_EQ(r.exit_code, 2) << r.err;
    EXPECT_EQ(r.err_lines(), 1u) << r.err;
    EXPECT_NE(r.err.find("holds an unsharded run, not shard 1/2: give each shard its own --out"), std::string::npos)
        << r.err;
    EXPECT_FALSE(fs::exists(dir_ / "whole" / "shard.json"));
    // an unsharded run over an unsharded run's folder, and a shard into an empty folder, as before
    EXPECT_EQ(run(render_args("whole", {"--save", "polar"})).exit_code, 0);
    fs::create_directories(dir_ / "empty");
    EXPECT_EQ(run(render_args("empty", {"--save", "polar", "--shard", "1/2"})).exit_code, 0);
}

// ---- the writers: nothing this run did not make is removed or truncated --------------------------

// The Shard fixture's small run, for the output writers (not sharded unless a test says so).
class Writer : public Shard {
protected:
    // `commands` run at once (each a CLI run: its arguments), waited for; their exit codes in order.
    std::vector<int> run_together(const std::vector<std::vector<std::string>>& commands) const {
        std::string script;
        for (std::size_t i = 0; i < commands.size(); ++i) {
            std::string command = quote(VKSONAR_CLI);
            for (const auto& a : commands[i])
                command += " " + quote(a);
            const std::string rc = quote((dir_ / ("rc" + std::to_string(i))).string());
            script += "( " + command + " > /dev/null 2>&1 < /dev/null; echo $? > " + rc + " ) & ";
        }
        script += "wait";
        EXPECT_EQ(std::system(script.c_str()), 0);
        std::vector<int> codes;
        for (std::size_t i = 0; i < commands.size(); ++i)
            codes.push_back(std::atoi(read_text(dir_ / ("rc" + std::to_string(i))).c_str()));
        return codes;
    }
    // Writes a trajectory of `frames` poses to dir_/NAME; returns its path.
    std::string long_trajectory(const std::string& name, int frames) const {
        std::string poses = "x,y,z,roll,pitch,yaw\n";
        for (int i = 0; i < frames; ++i)
            poses += std::to_string(0.001 * i) + ",0,0,0,10," + std::to_string(0.01 * i) + "\n";
        write_text(dir_ / name, poses);
        return (dir_ / name).string();
    }
    // The names in dir_ that start with ".~" (temporaries and locks left behind).
    std::vector<std::string> leftovers() const {
        std::vector<std::string> names;
        for (const auto& entry : fs::directory_iterator(dir_))
            if (entry.path().filename().string().rfind(".~", 0) == 0) names.push_back(entry.path().filename());
        return names;
    }
    // Skips the test where this build has no HDF5.
    bool no_hdf5(const ShardRun& r) const { return r.err.find("this build has no HDF5") != std::string::npos; }
};

// A complete .h5 held open by a reader (HDF5 takes a shared flock, as h5py does): an unsharded run to it
// failed on HDF5's file lock with no reason given and removed the reader's file. It now writes a new
// file beside it and renames it over: the run succeeds, the reader keeps the file it opened.
TEST_F(Writer, AnUnshardedH5ReplacesAFileHeldOpenWhole) {
    const ShardRun first = run(render_args("held.h5"));
    if (no_hdf5(first)) GTEST_SKIP() << "no HDF5 in this build";
    ASSERT_EQ(first.exit_code, 0) << first.err;
    const std::string before = read_text(dir_ / "held.h5");
    const int fd = ::open((dir_ / "held.h5").c_str(), O_RDONLY | O_CLOEXEC);
    ASSERT_GE(fd, 0);
    ASSERT_EQ(::flock(fd, LOCK_SH | LOCK_NB), 0);
    const ShardRun again = run(render_args("held.h5", {"--seed", "5"}));
    EXPECT_EQ(again.exit_code, 0) << again.err;
    EXPECT_TRUE(fs::is_regular_file(dir_ / "held.h5"));
    EXPECT_NE(read_text(dir_ / "held.h5"), before) << "not replaced by the new run";
    struct stat held {};
    ASSERT_EQ(::fstat(fd, &held), 0);
    EXPECT_EQ(static_cast<std::size_t>(held.st_size), before.size()) << "the reader's file was truncated";
    ::close(fd);
    EXPECT_TRUE(leftovers().empty());
}

// Two unsharded runs to the same .h5 or bag at once: the second failed and removed the first's .h5, and
// two bags interleaved into one corrupt file while both exited 0. Each now renames its own whole file
// onto OUT: both succeed and OUT is one run's file (a bag byte for byte the run's alone).
TEST_F(Writer, ConcurrentUnshardedRunsLeaveOneWholeFile) {
    const std::string poses = long_trajectory("long.csv", 300);
    auto args = [&](const std::string& out) {
        std::vector<std::string> a = render_args(out);
        for (std::size_t i = 0; i + 1 < a.size(); ++i)
            if (a[i] == "--trajectory") a[i + 1] = poses;
        return a;
    };
    fs::create_directories(dir_ / "alone");
    ASSERT_EQ(run(args("alone/run.mcap")).exit_code, 0);
    EXPECT_EQ(run_together({args("run.mcap"), args("run.mcap")}), (std::vector<int>{0, 0}));
    EXPECT_TRUE(read_text(dir_ / "run.mcap") == read_text(dir_ / "alone" / "run.mcap"))
        << "the bag is not one run's whole bag";

    const ShardRun probe = run(render_args("probe.h5"));
    if (!no_hdf5(probe)) {
        EXPECT_EQ(run_together({args("run.h5"), args("run.h5")}), (std::vector<int>{0, 0}));
        EXPECT_TRUE(fs::is_regular_file(dir_ / "run.h5"));
    }
    EXPECT_TRUE(leftovers().empty());
}

// One shard run twice at once: the second truncated the file the first was writing (the first then
// exited 0 with a corrupt file). A shard now holds a lock beside its file; a second writer is refused
// in one line and touches nothing.
TEST_F(Writer, ASecondWriterOfAShardIsRefused) {
    const ShardRun probe = run(render_args("probe.h5"));
    for (const std::string name : {"cs.mcap", "cs.h5"}) {
        if (name == "cs.h5" && no_hdf5(probe)) continue;
        const fs::path lock = dir_ / (".~" + name + ".lock");
        const int fd = ::open(lock.c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0644);
        ASSERT_GE(fd, 0);
        ASSERT_EQ(::flock(fd, LOCK_EX | LOCK_NB), 0); // as a run of the shard holds it
        const ShardRun r = run(render_args(name, {"--shard", "0/2"}));
        EXPECT_EQ(r.exit_code, 1) << name << r.err;
        EXPECT_EQ(r.err_lines(), 1u) << name << r.err;
        EXPECT_NE(r.err.find("error: --out " + (dir_ / name).string() + ": another vksonar run is writing this shard"),
                  std::string::npos)
            << r.err;
        EXPECT_FALSE(fs::exists(dir_ / name)) << name;
        ::close(fd);
        fs::remove(lock);
        const ShardRun alone = run(render_args(name, {"--shard", "0/2"}));
        EXPECT_EQ(alone.exit_code, 0) << name << alone.err;
        EXPECT_TRUE(fs::is_regular_file(dir_ / name)) << name;
    }
    // A frame-folder shard: the lock is DIR/.~shard.json.lock.
    fs::create_directories(dir_ / "cs");
    const fs::path lock = dir_ / "cs" / ".~shard.json.lock";
    const int fd = ::open(lock.c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0644);
    ASSERT_GE(fd, 0);
    ASSERT_EQ(::flock(fd, LOCK_EX | LOCK_NB), 0);
    const ShardRun r = run(render_args("cs", {"--save", "polar", "--shard", "0/2"}));
    EXPECT_EQ(r.exit_code, 1) << r.err;
    EXPECT_EQ(r.err_lines(), 1u) << r.err;
    EXPECT_NE(r.err.find("another vksonar run is writing this shard"), std::string::npos) << r.err;
    EXPECT_FALSE(fs::exists(dir_ / "cs" / "shard.json"));
    ::close(fd);
    fs::remove(lock);
    EXPECT_EQ(run(render_args("cs", {"--save", "polar", "--shard", "0/2"})).exit_code, 0);
    EXPECT_FALSE(fs::exists(lock)) << "the lock is removed at the end of the run";
    EXPECT_TRUE(leftovers().empty()) << "the lock is removed at the end of the run";
}

// A shard's --out that is a symlink: the resume renamed its new file onto the link, replacing it with a
// regular file and leaving the target stale. It now writes and renames onto the link's target.
TEST_F(Writer, ASymlinkedShardOutStaysALink) {
    fs::create_directories(dir_ / "real");
    for (const std::string name : {"s1.h5", "s1.mcap"}) {
        fs::create_symlink(fs::path("real") / name, dir_ / ("ln" + name));
        const ShardRun r = run(render_args("ln" + name, {"--shard", "1/2"}));
        if (name == "s1.h5" && no_hdf5(r)) continue;
        ASSERT_EQ(r.exit_code, 0) << r.err;
        const ShardRun again = run(render_args("ln" + name, {"--shard", "1/2"})); // a re-run: resumes (.h5 copies)
        ASSERT_EQ(again.exit_code, 0) << again.err;
        EXPECT_TRUE(fs::is_symlink(dir_ / ("ln" + name))) << name << ": the link was replaced";
        EXPECT_TRUE(fs::is_regular_file(dir_ / "real" / name)) << name;
        // an unsharded run through the link replaces the target, not the link
        EXPECT_EQ(run(render_args("ln" + name)).exit_code, 0) << name;
        EXPECT_TRUE(fs::is_symlink(dir_ / ("ln" + name))) << name;
    }
    EXPECT_TRUE(leftovers().empty());
}

// The output folder removed during a frame-folder run: the run made the path again for each frame and
// exited 0 with the earlier frames missing. Now it stops with one line naming the folder.
TEST_F(Writer, AFolderRemovedDuringTheRunStopsIt) {
    const std::string poses = long_trajectory("long.csv", 3000);
    std::vector<std::string> a = render_args("gone", {"--save", "polar"});
    for (std::size_t i = 0; i + 1 < a.size(); ++i)
        if (a[i] == "--trajectory") a[i + 1] = poses;
    std::string command = quote(VKSONAR_CLI);
    for (const auto& x : a)
        command += " " + quote(x);
    const fs::path out = dir_ / "gone", err = dir_ / "gone.err", rc = dir_ / "gone.rc";
    const std::string script =
        "( " + command + " > /dev/null 2> " + quote(err.string()) + " < /dev/null; echo $? > " + quote(rc.string()) +
        " ) & pid=$!; n=0; while [ ! -e " + quote((out / "frame_000003" / "meta.json").string()) +
        " ] && [ $n -lt 3000 ]; do sleep 0.01; n=$((n+1)); done; n=0; while [ -e " + quote(out.string()) +
        " ] && [ $n -lt 100 ]; do rm -rf " + quote(out.string()) + " 2> /dev/null; n=$((n+1)); done; wait $pid";
    ASSERT_EQ(std::system(script.c_str()), 0);
    const std::string text = read_text(err);
    EXPECT_NE(std::atoi(read_text(rc).c_str()), 0) << text;
    ShardRun r;
    r.err = text;
    EXPECT_EQ(r.err_lines(), 1u) << text;
    EXPECT_EQ(text.rfind("error: ", 0), 0u) << text;
    EXPECT_NE(text.find(out.string()), std::string::npos) << text;
    EXPECT_FALSE(fs::exists(out)) << "the folder was made again";
}

// A trajectory that starts with a UTF-8 byte order mark (with and without a header) reads as without.
TEST_F(Writer, ATrajectoryByteOrderMarkIsSkipped) {
    write_text(dir_ / "bom_header.csv", "\xEF\xBB\xBFx,y,z,roll,pitch,yaw\n0,0,0,0,10,0\n0.1,0,0,0,10,1\n");
    write_text(dir_ / "bom.csv", "\xEF\xBB\xBF"
                                 "0,0,0,0,10,0\n0.1,0,0,0,10,1\n");
    for (const std::string name : {"bom_header.csv", "bom.csv"}) {
        std::vector<std::string> a = render_args("out_" + name, {"--save", "polar"});
        for (std::size_t i = 0; i + 1 < a.size(); ++i)
            if (a[i] == "--trajectory") a[i + 1] = (dir_ / name).string();
        const ShardRun r = run(a);
        EXPECT_EQ(r.exit_code, 0) << name << r.err;
        EXPECT_TRUE(fs::exists(dir_ / ("out_" + name) / "frame_000002" / "meta.json")) << name;
    }
}

// A re-run shard with the scene file changed at the same path: the identity held the scene's path only,
// so the shard resumed with frames of two scenes. It now holds a hash of the loaded scene's content;
// the same content re-saved (here: another layout of the JSON) still resumes.
TEST_F(Writer, AReRunShardRefusesAChangedScene) {
    const std::string original = read_text(fs::path(VKSONAR_ASSET_DIR) / "scenes" / "default.gltf");
    const std::string key = "\"backscatter_db\": -30";
    ASSERT_NE(original.find(key), std::string::npos);
    for (const std::string out : {"scene_shard", "scene_shard.mcap"}) {
        write_text(dir_ / "scene.gltf", original);
        const std::vector<std::string> args =
            render_args(out, {"--scene", (dir_ / "scene.gltf").string(), "--save", "polar", "--shard", "0/2"});
        ASSERT_EQ(run(args).exit_code, 0) << out;
        write_text(dir_ / "scene.gltf", original + "\n\n");
        ShardRun r = run(args);
        EXPECT_EQ(r.exit_code, 0) << out << r.err;
        std::string changed = original;
        changed.replace(changed.find(key), key.size(), "\"backscatter_db\": -31");
        write_text(dir_ / "scene.gltf", changed);
        r = run(args);
        EXPECT_EQ(r.exit_code, 2) << out << r.err;
        EXPECT_EQ(r.err_lines(), 1u) << out << r.err;
        EXPECT_NE(r.err.find("holds "), std::string::npos) << r.err;
        EXPECT_NE(r.err.find("another run (scene_fnv1a64: "), std::string::npos) << out << r.err;
    }
}

// A reused frame folder: a shorter run with another --save kept the earlier run's files beside its own
// (frame_000002's fan.png beside the new meta.json) and its later frames whole. An unsharded run now
// removes the earlier run's frame folders and files first, and nothing else.
TEST_F(Writer, AnUnshardedFolderRunReplacesTheEarlierRun) {
    // `args` with --trajectory's value replaced (empty: a single --pose instead).
    auto with = [&](std::vector<std::string> args, const std::string& poses) {
        for (std::size_t i = 0; i + 1 < args.size(); ++i)
            if (args[i] == "--trajectory") {
                if (poses.empty()) {
                    args[i] = "--pose";
                    args[i + 1] = "0,0,0,0,10,0";
                } else {
                    args[i + 1] = poses;
                }
            }
        return args;
    };
    write_text(dir_ / "two.csv", "x,y,z,roll,pitch,yaw\n0,0,0,0,10,0\n0.1,0,0,0,10,1\n");
    // A single pose: its files in kd itself, every kind a frame writes but flow (a trajectory's), the
    // uuv-legacy mode's own among them.
    ShardRun r = run(with(render_args("kd", {"--sonar", "uuv-legacy", "--save",
                                             "default,depth,normals,echo,cloud,multibeam,raw_scan,labels"}),
                          ""));
    ASSERT_EQ(r.exit_code, 0) << r.err;
    ASSERT_TRUE(fs::exists(dir_ / "kd" / "raw_scan.npy"));
    ASSERT_TRUE(fs::exists(dir_ / "kd" / "boxes.json"));
    r = run(render_args("kd", {"--save", "default,depth,normals,echo,cloud,labels,flow"}));
    ASSERT_EQ(r.exit_code, 0) << r.err; // 7 frames, frame_000002..frame_000008
    ASSERT_TRUE(fs::exists(dir_ / "kd" / "frame_000008" / "flow.npy"));
    write_text(dir_ / "kd" / "notes.txt", "mine");
    fs::create_directories(dir_ / "kd" / "frame_extra");
    write_text(dir_ / "kd" / ".~fan.png", "a killed run's temporary");
    ASSERT_EQ(run(with(render_args("kd", {"--save", "polar"}), (dir_ / "two.csv").string())).exit_code, 0);
    std::vector<std::string> names;
    for (const auto& entry : fs::directory_iterator(dir_ / "kd"))
        names.push_back(entry.path().filename());
    std::sort(names.begin(), names.end());
    EXPECT_EQ(names, (std::vector<std::string>{"frame_000002", "frame_000003", "frame_extra", "notes.txt"}));
    for (const std::string frame : {"frame_000002", "frame_000003"}) {
        names.clear();
        for (const auto& entry : fs::directory_iterator(dir_ / "kd" / frame))
            names.push_back(entry.path().filename());
        std::sort(names.begin(), names.end());
        EXPECT_EQ(names, (std::vector<std::string>{"meta.json", "polar.npy"})) << frame;
    }
    EXPECT_EQ(read_text(dir_ / "kd" / "notes.txt"), "mine");

    // A run that fails before its first frame leaves the earlier run as it was.
    EXPECT_EQ(
        run(with(render_args("kd", {"--save", "polar", "--set", "bins=-1"}), (dir_ / "two.csv").string())).exit_code,
        2);
    EXPECT_TRUE(fs::exists(dir_ / "kd" / "frame_000003" / "meta.json"));

    // Only what a vksonar run wrote goes. A user's folder whose files merely bear a frame file's name
    // (no vksonar meta.json beside them) keeps them; a frame folder holding a file no run writes, or a
    // meta.json that is not a vksonar frame's, is refused in one line, nothing removed. (An audit found
    // `--out` into such a folder deleted fan.png, depth.npy and whole frame_* folders, exit 0.)
    fs::create_directories(dir_ / "mine");
    write_text(dir_ / "mine" / "fan.png", "the user's");
    write_text(dir_ / "mine" / "depth.npy", "the user's");
    write_text(dir_ / "mine" / "meta.json", "{\"not\": \"vksonar\"}");
    r = run(with(render_args("mine", {"--save", "polar"}), ""));
    ASSERT_EQ(r.exit_code, 0) << r.err;
    EXPECT_EQ(read_text(dir_ / "mine" / "fan.png"), "the user's");
    EXPECT_EQ(read_text(dir_ / "mine" / "depth.npy"), "the user's");
    EXPECT_TRUE(fs::exists(dir_ / "mine" / "polar.npy"));
    // a frame folder of frame-named files, no meta.json, no vksonar run beside it: someone's own
    fs::create_directories(dir_ / "mine2" / "frame_000001");
    write_text(dir_ / "mine2" / "frame_000001" / "fan.png", "the user's");
    r = run(with(render_args("mine2", {"--save", "polar"}), ""));
    EXPECT_EQ(r.exit_code, 2) << r.err;
    EXPECT_NE(r.err.find("frame_000001 has no meta.json, and no vksonar run's frame lies beside it"), std::string::npos)
        << r.err;
    EXPECT_EQ(read_text(dir_ / "mine2" / "frame_000001" / "fan.png"), "the user's");
    write_text(dir_ / "kd" / "frame_000002" / "notes.txt", "mine too");
    r = run(with(render_args("kd", {"--save", "polar"}), (dir_ / "two.csv").string()));
    EXPECT_EQ(r.exit_code, 2) << r.err;
    EXPECT_EQ(r.err_lines(), 1u) << r.err;
    EXPECT_NE(r.err.find("frame_000002 holds notes.txt, which no vksonar run writes"), std::string::npos) << r.err;
    EXPECT_TRUE(fs::exists(dir_ / "kd" / "frame_000003" / "meta.json"));
    fs::remove(dir_ / "kd" / "frame_000002" / "notes.txt");
    write_text(dir_ / "kd" / "frame_000003" / "meta.json", "{\"format\": \"something else\"}");
    r = run(with(render_args("kd", {"--save", "polar"}), (dir_ / "two.csv").string()));
    EXPECT_EQ(r.exit_code, 2) << r.err;
    EXPECT_NE(r.err.find("frame_000003/meta.json is not a vksonar frame's"), std::string::npos) << r.err;
    EXPECT_TRUE(fs::exists(dir_ / "kd" / "frame_000002" / "polar.npy"));
}

// Every file a frame writes is in frame_files.h's table, which an unsharded re-run clears OUT by (a file
// written under another name would survive the re-run and mix two runs); every entry of the table is
// written by one of these renders and names a --save item the CLI offers. Renders with every item the
// CLI offers, in each mode.
TEST_F(Writer, EveryFileAFrameWritesIsInTheFrameFileTable) {
    // The items as the CLI's own error lists them, so an item added there is rendered here too.
    const ShardRun bad = run(render_args("never", {"--save", "no_such_item"}));
    ASSERT_EQ(bad.exit_code, 2) << bad.err;
    const std::size_t valid = bad.err.find("valid: ");
    ASSERT_NE(valid, std::string::npos) << bad.err;
    std::set<std::string> items;
    std::istringstream list(bad.err.substr(valid + 7, bad.err.find(')', valid) - valid - 7));
    for (std::string item; std::getline(list, item, ',');)
        items.insert(item);
    ASSERT_TRUE(items.count("labels") && items.count("flow") && items.count("raw_scan")) << bad.err;
    for (const vksonar::cli::FrameFile& file : vksonar::cli::kFrameFiles)
        EXPECT_TRUE(file.save.empty() || items.count(std::string(file.save))) << file.name << ": " << file.save;

    write_text(dir_ / "two.csv", "x,y,z,roll,pitch,yaw\n0,0,0,0,10,0\n0.1,0,0,0,10,1\n");
    std::set<std::string> written;
    for (const std::string mode : {"physical", "uuv-legacy", "gtri-legacy"}) {
        std::string save;
        for (const std::string& item : items) // multibeam and raw_scan: refused but in uuv-legacy
            if (mode == "uuv-legacy" || (item != "multibeam" && item != "raw_scan"))
                save += (save.empty() ? "" : ",") + item;
        const fs::path out = dir_ / mode;
        std::vector<std::string> args = {"render",
                                         "--backend",
                                         "cpu",
                                         "--set",
                                         "bins=32",
                                         "--set",
                                         "beams=16",
                                         "--set",
                                         "horizontal_beamwidth=9",
                                         "--save",
                                         save,
                                         "--trajectory",
                                         (dir_ / "two.csv").string(),
                                         "--out",
                                         out.string()};
        if (mode != "physical") args.insert(args.end(), {"--sonar", mode});
        const ShardRun r = run(args);
        ASSERT_EQ(r.exit_code, 0) << mode << ": " << r.err;
        std::size_t files = 0;
        for (const auto& entry : fs::recursive_directory_iterator(out)) {
            if (entry.is_directory()) continue;
            const std::string name = entry.path().filename().string();
            EXPECT_TRUE(vksonar::cli::is_frame_file(name)) << entry.path() << ": not in frame_files.h's table";
            written.insert(name);
            ++files;
        }
        EXPECT_GT(files, 0u) << mode;
    }
    for (const vksonar::cli::FrameFile& file : vksonar::cli::kFrameFiles)
        EXPECT_TRUE(written.count(std::string(file.name))) << file.name << ": in the table, written by no run";
}

// merge took frame folders whose arrays were missing or empty as whole frames. A frame folder now
// holds the files every other frame of the run holds, none of them empty, or merge refuses in one line.
TEST_F(Writer, MergeRefusesAFrameFolderWithMissingOrEmptyArrays) {
    ASSERT_EQ(run(render_args("m0", {"--save", "polar,fan", "--shard", "0/2"})).exit_code, 0);
    ASSERT_EQ(run(render_args("m1", {"--save", "polar,fan", "--shard", "1/2"})).exit_code, 0);
    const fs::path merged = dir_ / "merged";
    const fs::path polar = dir_ / "m1" / "frame_000007" / "polar.npy";
    const std::string bytes = read_text(polar);
    // A frame of a run from before meta.json listed its files: merge's own checks find the damage
    // (MergeNamesTheDamagedFileAndItsSizes: a frame whose meta.json lists them).
    strip_files(dir_ / "m1" / "frame_000007" / "meta.json");
    write_text(polar, "");
    ShardRun r = run({"merge", merged.string(), (dir_ / "m0").string(), (dir_ / "m1").string()});
    EXPECT_EQ(r.exit_code, 2) << r.err;
    EXPECT_EQ(r.err_lines(), 1u) << r.err;
    EXPECT_NE(r.err.find(polar.string() + ": empty"), std::string::npos) << r.err;
    EXPECT_FALSE(fs::exists(merged));
    fs::remove(polar);
    r = run({"merge", merged.string(), (dir_ / "m0").string(), (dir_ / "m1").string()});
    EXPECT_EQ(r.exit_code, 2) << r.err;
    EXPECT_EQ(r.err_lines(), 1u) << r.err;
    EXPECT_NE(r.err.find("frame_000007 holds other files than"), std::string::npos) << r.err;
    EXPECT_NE(r.err.find("(lacks polar.npy)"), std::string::npos) << r.err;
    EXPECT_FALSE(fs::exists(merged));
    write_text(polar, bytes);
    r = run({"merge", merged.string(), (dir_ / "m0").string(), (dir_ / "m1").string()});
    EXPECT_EQ(r.exit_code, 0) << r.err;
}

// A frame whose meta.json lists a file of another size than the file's, or one that is not there (a
// node crash before the data reached the disk): merge names the file and both sizes.
TEST_F(Writer, MergeNamesTheDamagedFileAndItsSizes) {
    ASSERT_EQ(run(render_args("m0", {"--save", "polar,fan", "--shard", "0/2"})).exit_code, 0);
    ASSERT_EQ(run(render_args("m1", {"--save", "polar,fan", "--shard", "1/2"})).exit_code, 0);
    const fs::path merged = dir_ / "merged";
    const fs::path polar = dir_ / "m1" / "frame_000007" / "polar.npy";
    const std::string bytes = read_text(polar);
    const std::string says = ", meta.json says " + std::to_string(bytes.size());
    const std::vector<std::string> merge = {"merge", merged.string(), (dir_ / "m0").string(), (dir_ / "m1").string()};
    for (const auto& [text, wanted] : std::vector<std::pair<std::string, std::string>>{
             {"", "frame_000007/polar.npy: 0 bytes" + says},
             {bytes + "x", "frame_000007/polar.npy: " + std::to_string(bytes.size() + 1) + " bytes" + says},
             {"-", "frame_000007/polar.npy: missing" + says}}) {
        if (text == "-")
            fs::remove(polar);
        else
            write_text(polar, text);
        const ShardRun r = run(merge);
        EXPECT_EQ(r.exit_code, 2) << r.err;
        EXPECT_EQ(r.err_lines(), 1u) << r.err;
        EXPECT_NE(r.err.find(wanted), std::string::npos) << "wanted: " << wanted << "\ngot: " << r.err;
        EXPECT_NE(r.err.find("re-run the shard"), std::string::npos) << r.err;
        EXPECT_FALSE(fs::exists(merged));
    }
    write_text(polar, bytes);
    EXPECT_EQ(run(merge).exit_code, 0);
}

// Names of a folder's entries, sorted.
std::vector<std::string> entries(const fs::path& dir) {
    std::vector<std::string> names;
    for (const auto& entry : fs::directory_iterator(dir))
        names.push_back(entry.path().filename().string());
    std::sort(names.begin(), names.end());
    return names;
}

// A folder shard of 4 frames whose meta.json is on disk but whose files are not as it says (a node
// crash before the data reached the disk: one array empty, one gone) is re-rendered by the re-run,
// which says so; the folder then equals an uninterrupted shard's, file for file and byte for byte.
TEST_F(Writer, AReRunShardReRendersDamagedFrames) {
    write_text(dir_ / "four.csv", "x,y,z,roll,pitch,yaw\n0,0,0,0,10,0\n0.3,0,-0.1,0,10,4\n"
                                  "0.6,0,-0.2,0,10,8\n0.9,0,-0.3,0,10,12\n");
    auto args = [&](const std::string& out) {
        std::vector<std::string> a =
            render_args(out, {"--shard", "0/1", "--set", "accuracy.rows_per_vfov=4", "--save", "default,labels"});
        for (std::size_t i = 0; i + 1 < a.size(); ++i)
            if (a[i] == "--trajectory") a[i + 1] = (dir_ / "four.csv").string();
        return a;
    };
    ShardRun r = run(args("part"));
    ASSERT_EQ(r.exit_code, 0) << r.err;
    ASSERT_EQ(run(args("whole")).exit_code, 0);
    // meta.json lists every other file of its frame with its size.
    const fs::path f3 = dir_ / "part" / "frame_000003", f4 = dir_ / "part" / "frame_000004";
    const auto meta = nlohmann::json::parse(read_text(f3 / "meta.json"));
    ASSERT_TRUE(meta.contains("files")) << "meta.json has no files";
    std::vector<std::string> listed;
    for (auto it = meta["files"].begin(); it != meta["files"].end(); ++it) {
        listed.push_back(it.key());
        EXPECT_EQ(it.value().get<std::uintmax_t>(), fs::file_size(f3 / it.key())) << it.key();
    }
    listed.push_back("meta.json");
    std::sort(listed.begin(), listed.end());
    EXPECT_EQ(listed, entries(f3));

    write_text(f3 / "polar.npy", "");   // delayed allocation: the name there, the data not
    fs::remove(f4 / "boxes.json");      // the rename lost
    write_text(f4 / "flow.npy", "old"); // a file this run does not write: must not survive the re-render
    r = run(args("part"));
    ASSERT_EQ(r.exit_code, 0) << r.err;
    EXPECT_NE(r.err.find(", 2 already on disk, 2 damaged (re-rendered): frame_000003, frame_000004"), std::string::npos)
        << r.err;
    for (int line = 2; line <= 5; ++line) {
        const std::string frame = vksonar::cli::frame_dir_name(line);
        const fs::path a = dir_ / "whole" / frame, b = dir_ / "part" / frame;
        ASSERT_EQ(entries(a), entries(b)) << frame;
        for (const std::string& name : entries(a)) {
            if (name == "meta.json") continue;
            EXPECT_TRUE(read_text(a / name) == read_text(b / name)) << frame << "/" << name << " differs";
        }
        auto ma = nlohmann::json::parse(read_text(a / "meta.json"));
        auto mb = nlohmann::json::parse(read_text(b / "meta.json"));
        ma.erase("timings_ms"); // measured, so never the same
        mb.erase("timings_ms");
        EXPECT_TRUE(ma == mb) << frame << ": meta.json differs beyond its timings";
    }
    r = run(args("part"));
    EXPECT_EQ(r.exit_code, 0) << r.err;
    EXPECT_NE(r.err.find(", 4 already on disk"), std::string::npos) << r.err;
    EXPECT_EQ(r.err.find("damaged"), std::string::npos) << r.err;
    EXPECT_EQ(run({"merge", (dir_ / "merged").string(), (dir_ / "part").string()}).exit_code, 0);
}

// A frame folder from a run before meta.json listed its files (no "files" key) is done when its
// meta.json is there, as then: an older shard resumes without rendering its frames again.
TEST_F(Writer, AMetaJsonWithoutFilesStillCountsAsDone) {
    ASSERT_EQ(run(render_args("part", {"--save", "polar", "--shard", "0/1"})).exit_code, 0);
    for (int line = 2; line <= 8; ++line) {
        const fs::path meta = dir_ / "part" / vksonar::cli::frame_dir_name(line) / "meta.json";
        ASSERT_TRUE(nlohmann::json::parse(read_text(meta)).contains("files")) << meta; // this run's record
        strip_files(meta);
    }
    // Even a frame of such a run with an empty array counts (there is no record to see it by); merge's
    // own check still refuses it (MergeRefusesAFrameFolderWithMissingOrEmptyArrays).
    write_text(dir_ / "part" / "frame_000004" / "polar.npy", "");
    const ShardRun r = run(render_args("part", {"--save", "polar", "--shard", "0/1"}));
    EXPECT_EQ(r.exit_code, 0) << r.err;
    EXPECT_NE(r.err.find(", 7 already on disk"), std::string::npos) << r.err;
    EXPECT_EQ(r.err.find("damaged"), std::string::npos) << r.err;
    EXPECT_EQ(read_text(dir_ / "part" / "frame_000004" / "polar.npy"), "");
}

// ---- SIGINT and SIGTERM: a render stops at a frame boundary and says what it left ----------------

// Starts VKSONAR_CLI with `args` as a child process that a test can signal: stdin and stdout
// /dev/null, stderr to `err`, SIGINT and SIGTERM at their default actions and unblocked whatever this
// process has, the engines' variables unset (as Shard::run). -1 when it cannot be started.
pid_t start_cli(const std::vector<std::string>& args, const fs::path& err) {
    std::vector<std::string> words = {VKSONAR_CLI};
    words.insert(words.end(), args.begin(), args.end());
    std::vector<char*> argv;
    for (std::string& word : words)
        argv.push_back(word.data());
    argv.push_back(nullptr);
    std::vector<char*> envp;
    for (char** entry = environ; *entry; ++entry) {
        const std::string name = std::string(*entry).substr(0, std::string(*entry).find('='));
        if (name.rfind("SLURM_ARRAY_TASK_", 0) == 0 || name == "JOB_COMPLETION_INDEX" || name == "VKSONAR_SHARD_COUNT")
            continue;
        envp.push_back(*entry);
    }
    envp.push_back(nullptr);
    posix_spawn_file_actions_t files;
    posix_spawn_file_actions_init(&files);
    posix_spawn_file_actions_addopen(&files, 0, "/dev/null", O_RDONLY, 0);
    posix_spawn_file_actions_addopen(&files, 1, "/dev/null", O_WRONLY, 0);
    posix_spawn_file_actions_addopen(&files, 2, err.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    posix_spawnattr_t attr;
    posix_spawnattr_init(&attr);
    sigset_t defaults, none;
    sigemptyset(&defaults);
    sigaddset(&defaults, SIGINT);
    sigaddset(&defaults, SIGTERM);
    sigemptyset(&none);
    posix_spawnattr_setsigdefault(&attr, &defaults);
    posix_spawnattr_setsigmask(&attr, &none);
    posix_spawnattr_setflags(&attr, POSIX_SPAWN_SETSIGDEF | POSIX_SPAWN_SETSIGMASK);
    pid_t pid = -1;
    const int started = posix_spawn(&pid, argv[0], &files, &attr, argv.data(), envp.data());
    posix_spawnattr_destroy(&attr);
    posix_spawn_file_actions_destroy(&files);
    return started == 0 ? pid : -1;
}

// Polls `ready` every 5 ms until it holds or `seconds` have passed; whether it held.
bool wait_until(const std::function<bool()>& ready, double seconds) {
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::duration<double>(seconds);
    for (;;) {
        if (ready()) return true;
        if (std::chrono::steady_clock::now() > deadline) return false;
        std::this_thread::sleep_for(std::chrono::milliseconds(5));
    }
}

// The wait status of `pid` once it ends, within `seconds`; else it is killed (SIGKILL) and -1 returned.
int wait_exit(pid_t pid, double seconds) {
    int status = 0;
    if (wait_until([&] { return ::waitpid(pid, &status, WNOHANG) == pid; }, seconds)) return status;
    ::kill(pid, SIGKILL);
    ::waitpid(pid, &status, 0);
    return -1;
}

// The lines of `text` that contain `part`.
std::vector<std::string> lines_with(const std::string& text, const std::string& part) {
    std::vector<std::string> found;
    std::stringstream stream(text);
    std::string line;
    while (std::getline(stream, line))
        if (line.find(part) != std::string::npos) found.push_back(line);
    return found;
}

// The number after `prefix` in `text` (-1 where `prefix` is not there).
long number_after(const std::string& text, const std::string& prefix) {
    const std::size_t at = text.find(prefix);
    return at == std::string::npos ? -1 : std::atol(text.c_str() + at + prefix.size());
}

// The Writer fixture's run over a long trajectory, started as a process to signal. The run takes
// about a second or more on two busy cores: long enough that it is still rendering when the signal
// comes, short enough to be resumed in a test.
class Interrupt : public Writer {
protected:
    static constexpr int kFrames = 400;

    void SetUp() override {
        Writer::SetUp();
        poses_ = long_trajectory("long.csv", kFrames);
    }
    // render_args(out, extra) over the long trajectory, with fewer pixel rows (a few ms a frame).
    std::vector<std::string> long_args(const std::string& out, std::vector<std::string> extra = {}) const {
        extra.insert(extra.begin(), {"--set", "accuracy.rows_per_vfov=4"});
        std::vector<std::string> a = render_args(out, std::move(extra));
        for (std::size_t i = 0; i + 1 < a.size(); ++i)
            if (a[i] == "--trajectory") a[i + 1] = poses_;
        return a;
    }
    // Starts the run, waits until `ready` holds (at most 10 s: then the test fails), sends `signal`
    // and waits for the exit (at most 20 s); its wait status and stderr.
    ShardRun interrupt(const std::vector<std::string>& args, const std::function<bool(pid_t)>& ready, int signal) {
        const fs::path err = dir_ / "interrupted.err";
        const pid_t pid = start_cli(args, err);
        EXPECT_GT(pid, 0) << "cannot start " << VKSONAR_CLI;
        ShardRun r;
        if (pid <= 0) return r;
        EXPECT_TRUE(wait_until([&] { return ready(pid); }, 10.0)) << "the run never got to its frames";
        EXPECT_EQ(::kill(pid, signal), 0);
        const int status = wait_exit(pid, 20.0);
        r.err = read_text(err);
        EXPECT_NE(status, -1) << "still running 20 s after the signal: " << r.err;
        EXPECT_TRUE(status != -1 && WIFEXITED(status))
            << "ended by the signal (" << (status != -1 && WIFSIGNALED(status) ? WTERMSIG(status) : 0)
            << ") instead of stopping: " << r.err;
        r.exit_code = status != -1 && WIFEXITED(status) ? WEXITSTATUS(status) : -1;
        return r;
    }
    // True once `file` is there and has grown since it was first seen, or 300 ms after it appeared
    // (a bag's frames reach the file a chunk at a time): a frame or more is on its way to disk.
    std::function<bool(pid_t)> file_written(const std::function<fs::path(pid_t)>& file) {
        seen_size_ = -1;
        return [this, file](pid_t pid) {
            std::error_code ec;
            const auto size = fs::file_size(file(pid), ec);
            if (ec) return false;
            const auto now = std::chrono::steady_clock::now();
            if (seen_size_ < 0) {
                seen_size_ = static_cast<long long>(size);
                seen_at_ = now;
            }
            return static_cast<long long>(size) > seen_size_ || now - seen_at_ > std::chrono::milliseconds(300);
        };
    }
    bool have_hdf5() const { return !no_hdf5(run(render_args("probe.h5"))); }

    std::string poses_;
    long long seen_size_ = -1;
    std::chrono::steady_clock::time_point seen_at_;
};

// Ctrl-C during an unsharded .h5 or bag run: the default action ended it (no message, exit by signal)
// and left its temporary `.~NAME.writing-PID` beside OUT. Now the run stops at a frame boundary, removes
// its temporary, says so in one line and exits 130; an earlier file at OUT is left as it was.
TEST_F(Interrupt, CtrlCLeavesAnUnshardedFileAsItWas) {
    const bool hdf5 = have_hdf5();
    for (const std::string name : {"run.mcap", "run.h5"}) {
        if (name == "run.h5" && !hdf5) continue;
        write_text(dir_ / name, "an earlier run's file\n");
        const ShardRun r = interrupt(
            long_args(name),
            file_written([&](pid_t pid) { return dir_ / (".~" + name + ".writing-" + std::to_string(pid)); }), SIGINT);
        EXPECT_EQ(r.exit_code, 130) << name << ": " << r.err;
        EXPECT_EQ(r.err_lines(), 1u) << name << ": " << r.err;
        EXPECT_EQ(r.err.rfind("vksonar render: interrupted (SIGINT) after ", 0), 0u) << r.err;
        EXPECT_NE(r.err.find("; " + (dir_ / name).string() + " was not written\n"), std::string::npos) << r.err;
        EXPECT_LT(number_after(r.err, "after "), kFrames) << r.err;
        EXPECT_EQ(read_text(dir_ / name), "an earlier run's file\n") << name << " was changed";
        EXPECT_TRUE(leftovers().empty()) << name << ": " << (leftovers().empty() ? "" : leftovers()[0]);
    }
}

// SIGTERM during a frame-folder run: exit 143 and one line naming the frames on disk, every one of them
// whole (its meta.json, written last, is there) and no temporary left in any.
TEST_F(Interrupt, SigtermStopsAFolderRunAfterWholeFrames) {
    const fs::path out = dir_ / "frames";
    const ShardRun r = interrupt(
        long_args("frames", {"--save", "polar"}),
        [&](pid_t) { return fs::exists(out / vksonar::cli::frame_dir_name(3) / "meta.json"); }, SIGTERM);
    EXPECT_EQ(r.exit_code, 143) << r.err;
    EXPECT_EQ(r.err_lines(), 1u) << r.err;
    const long written = number_after(r.err, "vksonar render: interrupted (SIGTERM) after ");
    ASSERT_GE(written, 2) << r.err;
    ASSERT_LT(written, kFrames) << r.err;
    EXPECT_NE(r.err.find(" of " + std::to_string(kFrames) + " frames; " + out.string() + " holds this run's first " +
                         std::to_string(written) + " frames, each whole (frame_000002 to " +
                         vksonar::cli::frame_dir_name(written + 1) + ")"),
              std::string::npos)
        << r.err;
    std::size_t folders = 0;
    for (const auto& entry : fs::recursive_directory_iterator(out)) {
        const std::string name = entry.path().filename().string();
        EXPECT_NE(name.rfind(".~", 0), 0u) << entry.path() << " left behind";
        if (name.rfind("frame_", 0) != 0) continue;
        ++folders;
        const long line = std::atol(name.c_str() + 6);
        EXPECT_TRUE(line >= 2 && line <= written + 1) << name << " is not one of the frames the line names";
        EXPECT_TRUE(fs::exists(entry.path() / "meta.json") && fs::exists(entry.path() / "polar.npy"))
            << name << " is not whole";
    }
    EXPECT_EQ(folders, static_cast<std::size_t>(written));
}

// Ctrl-C during a shard (--shard 0/1: the whole trajectory in one shard): exit 130 and one line saying
// how many frames the shard keeps; the shard is left as a resume takes it (its lock removed), so running
// the same command again renders only the rest, and the merged shard is the uninterrupted run's output.
class InterruptShard : public Interrupt {
protected:
    // `out` is the shard's --out, `whole` the unsharded run's, `merged` the merge of the resumed shard;
    // `ready` says when a frame is on its way to disk. Returns the frames the interrupted run kept.
    long interrupt_and_resume(const std::string& out, const std::string& whole, const std::string& merged,
                              const std::function<bool(pid_t)>& ready, const std::vector<std::string>& extra = {}) {
        std::vector<std::string> shard = extra;
        shard.insert(shard.end(), {"--shard", "0/1"});
        const ShardRun r = interrupt(long_args(out, shard), ready, SIGINT);
        EXPECT_EQ(r.exit_code, 130) << r.err;
        const std::vector<std::string> said = lines_with(r.err, "interrupted");
        EXPECT_EQ(said.size(), 1u) << r.err;
        const long kept = number_after(r.err, "shard " + (dir_ / out).string() + " keeps ");
        EXPECT_GE(kept, 0) << r.err;
        EXPECT_LT(kept, kFrames) << "the run was not interrupted: " << r.err;
        EXPECT_NE(r.err.find(" of its " + std::to_string(kFrames) + " frames, re-run the same command to resume"),
                  std::string::npos)
            << r.err;
        EXPECT_TRUE(leftovers().empty()) << (leftovers().empty() ? "" : leftovers()[0]);
        const ShardRun again = run(long_args(out, shard));
        EXPECT_EQ(again.exit_code, 0) << again.err;
        EXPECT_NE(again.err.find(", " + std::to_string(kept) + " already on disk"), std::string::npos)
            << "the re-run did not resume after the kept frames: " << again.err;
        EXPECT_EQ(again.err.find("warning"), std::string::npos) << again.err;
        EXPECT_EQ(run(long_args(whole, extra)).exit_code, 0);
        const ShardRun joined = run({"merge", (dir_ / merged).string(), (dir_ / out).string()});
        EXPECT_EQ(joined.exit_code, 0) << joined.err;
        return kept;
    }
};

TEST_F(InterruptShard, AFolderShardResumesIntoTheUninterruptedRun) {
    interrupt_and_resume(
        "part", "whole", "merged",
        [&](pid_t) { return fs::exists(dir_ / "part" / vksonar::cli::frame_dir_name(2) / "meta.json"); },
        {"--save", "polar"});
    for (int line = 2; line < kFrames + 2; ++line) {
        const std::string frame = vksonar::cli::frame_dir_name(line);
        const std::string a = read_text(dir_ / "whole" / frame / "polar.npy"),
                          b = read_text(dir_ / "merged" / frame / "polar.npy");
        ASSERT_FALSE(a.empty()) << frame;
        ASSERT_TRUE(a == b) << frame << " differs from the uninterrupted run";
    }
}

TEST_F(InterruptShard, ABagShardResumesIntoTheUninterruptedBag) {
    fs::create_directories(dir_ / "whole");
    fs::create_directories(dir_ / "merged");
    interrupt_and_resume("part.mcap", "whole/run.mcap", "merged/run.mcap",
                         file_written([&](pid_t) { return dir_ / "part.mcap"; }));
    const std::string whole = read_text(dir_ / "whole" / "run.mcap");
    EXPECT_GT(whole.size(), 1000u);
    EXPECT_TRUE(whole == read_text(dir_ / "merged" / "run.mcap")) << "the merged bag differs from the unsharded one";
}

// (The values of a resumed .h5 against the uninterrupted one: tests/python/check_shards.py; here the
// resume must take the frames and the merge the shard as whole.)
TEST_F(InterruptShard, AnH5ShardResumesAndMerges) {
    if (!have_hdf5()) GTEST_SKIP() << "no HDF5 in this build";
    interrupt_and_resume("part.h5", "whole.h5", "merged.h5", file_written([&](pid_t) { return dir_ / "part.h5"; }));
}

} // namespace
