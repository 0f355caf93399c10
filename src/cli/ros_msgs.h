// The ROS 2 messages of `vksonar render --out run.mcap`: their .msg definitions (ros_msg_definitions.cpp),
// the schema text rosbag2 stores for a type, and CDR serializers (cdr.h) written field by field after
// those definitions.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

namespace vksonar::cli::ros {

struct MsgFile {
    const char* type; // "package/msg/Name"
    const char* text; // the .msg file
};
const std::vector<MsgFile>& msg_files();

// The schema data rosbag2 (LocalMessageDefinitionSource) writes for `type` ("package/msg/Name"):
// the type's .msg, then every type it depends on, once, depth first in sorted name order, each
// after "\n", a line of 80 '=' and a line "MSG: package/Name". Empty if `type` is not known here.
std::string full_definition(const std::string& type);

struct Header {
    std::uint64_t stamp_ns = 0; // builtin_interfaces/Time: sec = ns / 1e9, nanosec = the rest
    std::string frame_id;
};

// marine_acoustic_msgs/msg/SonarImageData dtype values.
constexpr std::uint32_t kDtypeUint16 = 2;
constexpr std::uint32_t kDtypeFloat32 = 8;

// marine_acoustic_msgs/msg/ProjectedSonarImage.
struct SonarImage {
    Header header;
    float frequency = 0, sound_speed = 0;            // PingInfo
    std::vector<float> tx_beamwidths, rx_beamwidths; // PingInfo, rad
    std::vector<double> beam_directions;             // 3 per beam: geometry_msgs/Vector3 x, y, z
    std::vector<float> ranges;                       // m, centre of each bin
    std::uint32_t dtype = kDtypeFloat32;             // SonarImageData
    std::uint32_t beam_count = 0;
    const void* data = nullptr; // little endian, range-major: [bin][beam]
    std::size_t data_bytes = 0;
};
void serialize(const SonarImage& m, std::vector<std::uint8_t>& out);

// sensor_msgs/msg/Image.
struct Image {
    Header header;
    std::uint32_t height = 0, width = 0, step = 0;
    std::string encoding;
    const void* data = nullptr;
    std::size_t data_bytes = 0;
};
void serialize(const Image& m, std::vector<std::uint8_t>& out);

// sensor_msgs/msg/PointCloud2 of `count` points x, y, z, intensity (float32 each, 16 bytes a point).
struct PointCloud {
    Header header;
    const float* xyzi = nullptr;
    std::size_t count = 0;
};
void serialize(const PointCloud& m, std::vector<std::uint8_t>& out);

// tf2_msgs/msg/TFMessage of geometry_msgs/msg/TransformStamped.
struct Transform {
    Header header; // frame_id: the parent frame
    std::string child_frame_id;
    double translation[3] = {0, 0, 0};
    double rotation[4] = {0, 0, 0, 1}; // quaternion x, y, z, w
};
void serialize(const std::vector<Transform>& transforms, std::vector<std::uint8_t>& out);

} // namespace vksonar::cli::ros
