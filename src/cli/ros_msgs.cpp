// ROS 2 schemas and CDR serializers (ros_msgs.h).
#include "cli/ros_msgs.h"

#include <cctype>
#include <functional>
#include <set>
#include <sstream>

#include "cli/cdr.h"

namespace vksonar::cli::ros {
namespace {

const char* find_text(const std::string& type) {
    for (const MsgFile& f : msg_files())
        if (type == f.type) return f.text;
    return nullptr;
}

bool is_primitive(const std::string& t) {
    static const std::set<std::string> primitives = {"bool",   "byte",  "char",   "float32", "float64",
                                                     "int8",   "uint8", "int16",  "uint16",  "int32",
                                                     "uint32", "int64", "uint64", "string"};
    return primitives.count(t) != 0;
}

// The non-primitive field types a .msg names ("pkg/Name", or "Name" in the message's own package),
// as "pkg/Name": the first word of each line that is not a comment, with any [..] after it.
std::set<std::string> dependencies(const std::string& text, const std::string& package) {
    std::set<std::string> out;
    std::istringstream lines(text);
    std::string line;
    while (std::getline(lines, line)) {
        std::size_t i = 0;
        while (i < line.size() && std::isspace(static_cast<unsigned char>(line[i])))
            ++i;
        const std::size_t start = i;
        while (i < line.size() &&
               (std::isalnum(static_cast<unsigned char>(line[i])) || line[i] == '_' || line[i] == '/'))
            ++i;
        if (i == start) continue; // blank or comment
        std::string type = line.substr(start, i - start);
        if (i < line.size() && line[i] == '[')
            i = line.find(']', i) == std::string::npos ? line.size() : line.find(']', i) + 1;
        if (i >= line.size() || !std::isspace(static_cast<unsigned char>(line[i]))) continue; // not "type name"
        if (is_primitive(type)) continue;
        out.insert(type.find('/') == std::string::npos ? package + "/" + type : type);
    }
    return out;
}

// "pkg/Name" -> "pkg/msg/Name".
std::string msg_path(const std::string& name) {
    const std::size_t slash = name.find('/');
    return name.substr(0, slash) + "/msg/" + name.substr(slash + 1);
}

void header(CdrWriter& w, const Header& h) {
    w.i32(static_cast<std::int32_t>(h.stamp_ns / 1000000000ull));
    w.u32(static_cast<std::uint32_t>(h.stamp_ns % 1000000000ull));
    w.string(h.frame_id);
}

} // namespace

std::string full_definition(const std::string& type) {
    const char* root = find_text(type);
    if (!root) return {};
    std::set<std::string> seen;
    std::function<std::string(const std::string&, const std::string&)> append = [&](const std::string& path,
                                                                                    const std::string& text) {
        std::string result = text;
        const std::string package = path.substr(0, path.find('/'));
        for (const std::string& dep : dependencies(text, package)) {
            if (!seen.insert(dep).second) continue;
            const char* dep_text = find_text(msg_path(dep));
            result += "\n================================================================================\nMSG: ";
            result += dep;
            result += "\n";
            result += dep_text ? append(msg_path(dep), dep_text) : std::string();
        }
        return result;
    };
    return append(type, root);
}

void serialize(const SonarImage& m, std::vector<std::uint8_t>& out) {
    CdrWriter w(out);
    header(w, m.header);
    // PingInfo
    w.f32(m.frequency);
    w.f32(m.sound_speed);
    w.floats(m.tx_beamwidths.data(), m.tx_beamwidths.size());
    w.floats(m.rx_beamwidths.data(), m.rx_beamwidths.size());
    // geometry_msgs/Vector3[] beam_directions
    const std::size_t beams = m.beam_directions.size() / 3;
    w.count(beams);
    for (std::size_t i = 0; i < 3 * beams; ++i)
        w.f64(m.beam_directions[i]);
    w.floats(m.ranges.data(), m.ranges.size());
    // SonarImageData
    w.boolean(false); // is_bigendian
    w.u32(m.dtype);
    w.u32(m.beam_count);
    w.bytes(m.data, m.data_bytes);
}

void serialize(const Image& m, std::vector<std::uint8_t>& out) {
    CdrWriter w(out);
    header(w, m.header);
    w.u32(m.height);
    w.u32(m.width);
    w.string(m.encoding);
    w.u8(0); // is_bigendian
    w.u32(m.step);
    w.bytes(m.data, m.data_bytes);
}

void serialize(const PointCloud& m, std::vector<std::uint8_t>& out) {
    constexpr std::uint8_t kFloat32 = 7; // sensor_msgs/PointField FLOAT32
    CdrWriter w(out);
    header(w, m.header);
    w.u32(1);                                   // height: unordered
    w.u32(static_cast<std::uint32_t>(m.count)); // width
    const char* names[4] = {"x", "y", "z", "intensity"};
    w.count(4);
    for (std::uint32_t i = 0; i < 4; ++i) {
        w.string(names[i]);
        w.u32(4 * i); // offset
        w.u8(kFloat32);
        w.u32(1); // count
    }
    w.boolean(false);                                // is_bigendian
    w.u32(16);                                       // point_step
    w.u32(static_cast<std::uint32_t>(16 * m.count)); // row_step
    w.bytes(m.xyzi, 16 * m.count);
    w.boolean(true); // is_dense: every point is finite
}

void serialize(const std::vector<Transform>& transforms, std::vector<std::uint8_t>& out) {
    CdrWriter w(out);
    w.count(transforms.size());
    for (const Transform& t : transforms) {
        header(w, t.header);
        w.string(t.child_frame_id);
        for (double v : t.translation)
            w.f64(v);
        for (double v : t.rotation)
            w.f64(v);
    }
}

} // namespace vksonar::cli::ros
