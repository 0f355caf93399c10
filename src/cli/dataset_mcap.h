// One rosbag2-compatible MCAP file per run (`vksonar render --out run.mcap`): what `ros2 bag play`,
// `ros2 bag info` and Foxglove open. Profile ros2, schemas ros2msg (the .msg with its dependencies,
// as rosbag2 stores them), messages cdr. Topics (docs/ros2.md), PREFIX = --ros-prefix:
//   PREFIX/sonar_image  marine_acoustic_msgs/msg/ProjectedSonarImage  frame FRAME_acoustic
//   PREFIX/fan          sensor_msgs/msg/Image rgb8 (fan.png)          frame FRAME
//   PREFIX/polar        sensor_msgs/msg/Image mono16 (polar_u16.npy)  frame FRAME
//   PREFIX/points       sensor_msgs/msg/PointCloud2 x,y,z,intensity (cloud.ply; with --save cloud)
//   PREFIX/instance     sensor_msgs/msg/Image mono16 (instance.npy)   frame FRAME (with --save labels),
//                       rows as PREFIX/polar's, so the two overlay
//   /tf                 tf2_msgs/msg/TFMessage: world -> FRAME, the pose of each frame
//   /tf_static          tf2_msgs/msg/TFMessage: FRAME -> FRAME_acoustic (Z forward, X up), once
// Every message of a frame has the frame's time stamp (header.stamp, log and publish time).
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "cli/mcap_writer.h"
#include "core/plan.h"
#include "host/host_stages.h"
#include "vksonar/frame.h"
#include "vksonar/result.h"
#include "vksonar/scene.h"

namespace vksonar::cli {

struct McapOptions {
    std::string prefix = "/vksonar"; // topic prefix
    std::string frame = "sonar";     // the sonar's frame id (REP-103: x forward, y port, z up)
    std::string world_frame = "world";
    bool sonar_image = true; // PREFIX/sonar_image
    bool sonar_u16 = false;  // its data as uint16 display values instead of float32 uPa^2
    bool fan = true;         // PREFIX/fan
    bool polar = true;       // PREFIX/polar
    bool cloud = false;      // PREFIX/points
    bool instance = false;   // PREFIX/instance (the frames must carry labels: SaveFlags::labels)
    bool zstd = false;       // zstd chunk compression
    double rate = 10.0;      // --rate: frames/s of a trajectory without a time column (frame i at i / rate s)
    std::string library;     // the MCAP header's library field
    // A shard's record and run identity (render --shard): a "vksonar_shard" Metadata record, written
    // right after the Header, that `vksonar merge` and a re-run of the shard read; empty for an
    // unsharded run (then there is no such record).
    mcap::KeyValues shard;
    // An unsharded run's record (run_metadata in merge.h): a "vksonar_run" Metadata record written at
    // close(), before rosbag2's; a merged bag gets the same one. Empty: none (a shard's bag).
    mcap::KeyValues run;
};

// The name of a shard bag's Metadata record (McapOptions::shard), written before its first frame.
inline constexpr const char* kShardRecordName = "vksonar_shard";
// The name of an unsharded or merged bag's run record (McapOptions::run).
inline constexpr const char* kRunRecordName = "vksonar_run";

// One topic of a bag as rosbag2's metadata lists it.
struct BagTopic {
    std::string name, type, qos; // qos: the offered_qos_profiles YAML
    std::uint64_t messages = 0;
};
// rosbag2's own metadata record (BagMetadata as YAML, version 8: QoS as text), which `ros2 bag info`
// reads beside the summary: the bag file's name, its topics, and its first and last time stamps.
std::string rosbag2_metadata_yaml(const std::string& file, const std::vector<BagTopic>& topics, std::uint64_t first_ns,
                                  std::uint64_t last_ns, std::uint64_t messages);

bool mcap_zstd_available();

class McapDatasetWriter {
public:
    // Creates (or truncates) `path` and registers the topics. Fails with one line naming the file.
    // `write_to`, when given, is the file written instead, to be renamed to `path` by the caller
    // (rosbag2's metadata names `path`'s file).
    static Result<std::unique_ptr<McapDatasetWriter>> create(const std::string& path, const Plan& plan,
                                                             const McapOptions& options,
                                                             const std::string& write_to = std::string());
    virtual ~McapDatasetWriter() = default;
    // Appends one frame at `stamp_ns`: `fan` when options.fan, `display_u16` (bins * beams) when
    // options.polar or sonar_u16. Whole frames end a batch: a killed run leaves the chunks before it.
    virtual Result<void> append(const Frame& frame, const Pose& pose, std::uint64_t stamp_ns, const host::Image* fan,
                                const std::uint16_t* display_u16) = 0;
    // Writes the summary and closes the file.
    virtual Result<void> close() = 0;

    // Resuming a shard (bag_shard_resume, merge.h): appends one message of a whole frame read back
    // from the bag a killed run left, with the next sequence number of its topic; a /tf message
    // begins a frame (as append writes them: /tf_static before the first frame's /tf).
    virtual Result<void> replay(const std::string& topic, std::uint64_t log_time, std::uint64_t publish_time,
                                const std::uint8_t* data, std::size_t size) = 0;
    // Closes the open chunk and hands the file to the operating system.
    virtual Result<void> flush() = 0;
    // Frames written (appended or replayed).
    virtual std::uint64_t frames() const = 0;
};

} // namespace vksonar::cli
