// McapDatasetWriter (dataset_mcap.h): frames -> ROS 2 messages (ros_msgs.h) -> MCAP (mcap_writer.h).
#include "cli/dataset_mcap.h"

#include <cmath>
#include <utility>
#include <vector>

#include "cli/mcap_writer.h"
#include "cli/ros_msgs.h"
#include "host/meta_fields.h"

namespace vksonar::cli {
namespace {

constexpr double kDegToRad = 3.14159265358979323846 / 180.0;

// rosbag2's offered_qos_profiles: a YAML list of one profile, in the numeric form every rosbag2 since
// Foxy reads (history 1 = keep_last, reliability 1 = reliable, durability 1 = transient_local,
// 2 = volatile, liveliness 1 = automatic; durations "infinite").
std::string qos_yaml(int depth, bool transient_local) {
    const std::string infinite = "\n    sec: 9223372036\n    nsec: 854775807";
    return "- history: 1\n  depth: " + std::to_string(depth) +
           "\n  reliability: 1\n  durability: " + (transient_local ? "1" : "2") + "\n  deadline:" + infinite +
           "\n  lifespan:" + infinite + "\n  liveliness: 1\n  liveliness_lease_duration:" + infinite +
           "\n  avoid_ros_namespace_conventions: false";
}

// A YAML double-quoted scalar.
std::string yaml_quoted(const std::string& s) {
    std::string out = "\"";
    for (char c : s) {
        if (c == '\n')
            out += "\\n";
        else if (c == '"' || c == '\\')
            out += std::string("\\") + c;
        else
            out += c;
    }
    return out + "\"";
}

// R = Rz(yaw) Ry(pitch) Rx(roll) as a quaternion x, y, z, w.
void pose_quaternion(const Pose& pose, double q[4]) {
    const double hr = 0.5 * pose.roll_deg * kDegToRad, hp = 0.5 * pose.pitch_deg * kDegToRad,
                 hy = 0.5 * pose.yaw_deg * kDegToRad;
    const double cr = std::cos(hr), sr = std::sin(hr), cp = std::cos(hp), sp = std::sin(hp), cy = std::cos(hy),
                 sy = std::sin(hy);
    q[0] = sr * cp * cy - cr * sp * sy;
    q[1] = cr * sp * cy + sr * cp * sy;
    q[2] = cr * cp * sy - sr * sp * cy;
    q[3] = cr * cp * cy + sr * sp * sy;
}

struct Topic {
    std::uint16_t channel = 0;
    std::string name, type, qos;
    std::uint32_t sequence = 0;
};

class McapWriterImpl final : public McapDatasetWriter {
public:
    McapWriterImpl(std::string path, const Plan& plan, McapOptions options)
        : path_(std::move(path)), plan_(plan), options_(std::move(options)) {}

    Result<void> open(const std::string& file) {
        mcap::WriterOptions writer_options;
        writer_options.profile = "ros2";
        writer_options.library = options_.library;
        writer_options.zstd = options_.zstd;
        if (auto opened = writer_.open(file, writer_options); !opened) return opened;
        const std::string& p = options_.prefix;
        if (options_.sonar_image)
            add(sonar_image_, p + "/sonar_image", "marine_acoustic_msgs/msg/ProjectedSonarImage", qos_yaml(10, false));
        if (options_.fan) add(fan_, p + "/fan", "sensor_msgs/msg/Image", qos_yaml(10, false));
        if (options_.polar) add(polar_, p + "/polar", "sensor_msgs/msg/Image", qos_yaml(10, false));
        if (options_.cloud) add(cloud_, p + "/points", "sensor_msgs/msg/PointCloud2", qos_yaml(10, false));
        if (options_.instance) add(instance_, p + "/instance", "sensor_msgs/msg/Image", qos_yaml(10, false));
        add(tf_, "/tf", "tf2_msgs/msg/TFMessage", qos_yaml(100, false));
        add(tf_static_, "/tf_static", "tf2_msgs/msg/TFMessage", qos_yaml(1, true));
        // A shard's record goes first, before any frame: a killed shard's bag still says which shard
        // of which run it holds, and its re-run can go on after its last whole chunk.
        if (!options_.shard.empty())
            if (auto written = writer_.write_metadata(kShardRecordName, options_.shard); !written) return written;

        // Constant parts of the sonar image: beam directions in the message's own frame (Z forward,
        // X up, so Y starboard: azimuth a, positive to port, is (0, -sin a, cos a)), bin ranges,
        // beamwidths (tx: the vertical fan, rx: one beam's horizontal width; two-way -3 dB, rad).
        const std::size_t beams = plan_.beams, bins = plan_.bins;
        sonar_.header.frame_id = options_.frame + "_acoustic";
        sonar_.frequency = static_cast<float>(plan_.config.frequency_hz);
        sonar_.sound_speed = static_cast<float>(plan_.config.sound_speed_mps);
        sonar_.tx_beamwidths.assign(beams, static_cast<float>(plan_.config.vfov_deg * kDegToRad));
        sonar_.rx_beamwidths.resize(beams); // a line array's beams widen off broadside (meta_fields.h)
        for (std::size_t j = 0; j < beams; ++j)
            sonar_.rx_beamwidths[j] = static_cast<float>(host::rx_beamwidth_rad(plan_, j));
        for (std::size_t j = 0; j < beams; ++j) {
            const double a = plan_.beam_angle_rad[j];
            sonar_.beam_directions.insert(sonar_.beam_directions.end(), {0.0, -std::sin(a), std::cos(a)});
        }
        for (std::size_t k = 0; k < bins; ++k)
            sonar_.ranges.push_back(static_cast<float>(plan_.bin_range_m[k]));
        sonar_.beam_count = static_cast<std::uint32_t>(beams);
        sonar_.dtype = options_.sonar_u16 ? ros::kDtypeUint16 : ros::kDtypeFloat32;
        if (options_.polar) flipped_.resize(beams * bins);
        if (options_.instance) instance_rows_.resize(beams * bins);
        return {};
    }

    Result<void> append(const Frame& frame, const Pose& pose, std::uint64_t stamp_ns, const host::Image* fan,
                        const std::uint16_t* display_u16) override {
        const std::size_t beams = plan_.beams, bins = plan_.bins, n = beams * bins;
        if (frames_ == 0) {
            first_ns_ = stamp_ns;
            ros::Transform acoustic;
            acoustic.header = {stamp_ns, options_.frame};
            acoustic.child_frame_id = options_.frame + "_acoustic";
            const double h = std::sqrt(0.5); // 180 deg about (x + z) / sqrt 2: x -> z, z -> x, y -> -y
            acoustic.rotation[0] = h;
            acoustic.rotation[1] = 0.0;
            acoustic.rotation[2] = h;
            acoustic.rotation[3] = 0.0;
            ros::serialize(std::vector<ros::Transform>{acoustic}, buffer_);
            if (auto w = put(tf_static_, stamp_ns); !w) return w;
        }
        last_ns_ = stamp_ns;
        ros::Transform t;
        t.header = {stamp_ns, options_.world_frame};
        t.child_frame_id = options_.frame;
        t.translation[0] = pose.x_m;
        t.translation[1] = pose.y_m;
        t.translation[2] = pose.z_m;
        pose_quaternion(pose, t.rotation);
        ros::serialize(std::vector<ros::Transform>{t}, buffer_);
        if (auto w = put(tf_, stamp_ns); !w) return w;

        if (options_.sonar_image) {
            sonar_.header.stamp_ns = stamp_ns;
            if (options_.sonar_u16) {
                sonar_.data = display_u16;
                sonar_.data_bytes = n * sizeof(std::uint16_t);
            } else {
                sonar_.data = frame.intensity.data();
                sonar_.data_bytes = n * sizeof(float);
            }
            ros::serialize(sonar_, buffer_);
            if (auto w = put(sonar_image_, stamp_ns); !w) return w;
        }
        if (options_.fan && fan) {
            ros::Image image;
            image.header = {stamp_ns, options_.frame};
            image.height = fan->height;
            image.width = fan->width;
            image.step = 3 * fan->width;
            image.encoding = "rgb8";
            image.data = fan->rgb.data();
            image.data_bytes = fan->rgb.size();
            ros::serialize(image, buffer_);
            if (auto w = put(fan_, stamp_ns); !w) return w;
        }
        if (options_.polar) {
            ros::serialize(polar_image(display_u16, flipped_, stamp_ns), buffer_);
            if (auto w = put(polar_, stamp_ns); !w) return w;
        }
        if (options_.instance) {
            // The same rows as PREFIX/polar, so an instance id sits on the pixel of the echo it labels.
            if (frame.instance.size() != n)
                return make_error(ErrorCode::invalid_argument,
                                  path_ + ": a frame without labels for " + instance_.name + " (SaveFlags::labels)");
            ros::serialize(polar_image(frame.instance.data(), instance_rows_, stamp_ns), buffer_);
            if (auto w = put(instance_, stamp_ns); !w) return w;
        }
        if (options_.cloud) {
            // cloud.ply's points: every cell the display shows, at elevation 0 in the sonar frame.
            points_.clear();
            for (std::size_t k = 0; k < bins; ++k)
                for (std::size_t j = 0; j < beams; ++j) {
                    const std::size_t i = k * beams + j;
                    if (!(frame.display[i] > 0.0f)) continue;
                    const double r = plan_.bin_range_m[k], a = plan_.beam_angle_rad[j];
                    points_.insert(points_.end(), {static_cast<float>(r * std::cos(a)),
                                                   static_cast<float>(r * std::sin(a)), 0.0f, frame.intensity[i]});
                }
            ros::PointCloud cloud;
            cloud.header = {stamp_ns, options_.frame};
            cloud.xyzi = points_.data();
            cloud.count = points_.size() / 4;
            ros::serialize(cloud, buffer_);
            if (auto w = put(cloud_, stamp_ns); !w) return w;
        }
        ++frames_;
        return writer_.end_batch();
    }

    Result<void> close() override {
        std::vector<BagTopic> topics;
        for (const Topic* t : {&sonar_image_, &fan_, &polar_, &cloud_, &instance_, &tf_, &tf_static_})
            if (t->channel) topics.push_back({t->name, t->type, t->qos, t->sequence});
        if (!options_.run.empty()) writer_.add_metadata(kRunRecordName, options_.run);
        writer_.add_metadata(
            "rosbag2", {{"serialized_metadata", rosbag2_metadata_yaml(path_.substr(path_.find_last_of('/') + 1), topics,
                                                                      first_ns_, last_ns_, writer_.message_count())}});
        return writer_.close();
    }

    Result<void> replay(const std::string& topic, std::uint64_t log_time, std::uint64_t publish_time,
                        const std::uint8_t* data, std::size_t size) override {
        Topic* t = nullptr;
        for (Topic* known : {&sonar_image_, &fan_, &polar_, &cloud_, &instance_, &tf_, &tf_static_})
            if (known->channel && known->name == topic) t = known;
        if (!t) return make_error(ErrorCode::invalid_argument, "topic " + topic + " is not one this run writes");
        if (t == &tf_) { // a frame begins: the one before is whole
            if (frames_ > 0)
                if (auto ended = writer_.end_batch(); !ended) return ended;
            if (frames_ == 0 && !tf_static_.sequence) first_ns_ = log_time;
            last_ns_ = log_time;
            ++frames_;
        } else if (t == &tf_static_) {
            first_ns_ = log_time;
        }
        return writer_.write(t->channel, t->sequence++, log_time, publish_time, data, size);
    }

    Result<void> flush() override { return writer_.flush(); }

    std::uint64_t frames() const override { return frames_; }

private:
    // A bins x beams uint16 grid as a mono16 image with the far range in row 0, as polar.png shows it:
    // row r is bin (bins - 1 - r), column j beam j (port-most first). `rows` holds the flipped copy.
    ros::Image polar_image(const std::uint16_t* grid, std::vector<std::uint16_t>& rows, std::uint64_t stamp_ns) const {
        const std::size_t beams = plan_.beams, bins = plan_.bins;
        for (std::size_t k = 0; k < bins; ++k)
            std::copy(grid + (bins - 1 - k) * beams, grid + (bins - k) * beams,
                      rows.begin() + static_cast<std::ptrdiff_t>(k * beams));
        ros::Image image;
        image.header = {stamp_ns, options_.frame};
        image.height = static_cast<std::uint32_t>(bins);
        image.width = static_cast<std::uint32_t>(beams);
        image.step = static_cast<std::uint32_t>(2 * beams);
        image.encoding = "mono16";
        image.data = rows.data();
        image.data_bytes = bins * beams * sizeof(std::uint16_t);
        return image;
    }

    void add(Topic& topic, const std::string& name, const std::string& type, const std::string& qos) {
        const std::uint16_t schema = schema_for(type);
        topic.name = name;
        topic.type = type;
        topic.qos = qos;
        topic.channel = writer_.add_channel(schema, name, "cdr", {{"offered_qos_profiles", qos + "\n"}});
    }
    std::uint16_t schema_for(const std::string& type) {
        for (const auto& [known, id] : schemas_)
            if (known == type) return id;
        const std::uint16_t id = writer_.add_schema(type, "ros2msg", ros::full_definition(type));
        schemas_.emplace_back(type, id);
        return id;
    }
    Result<void> put(Topic& topic, std::uint64_t stamp_ns) {
        return writer_.write(topic.channel, topic.sequence++, stamp_ns, stamp_ns, buffer_.data(), buffer_.size());
    }

    std::string path_;
    const Plan& plan_;
    McapOptions options_;
    mcap::Writer writer_;
    std::vector<std::pair<std::string, std::uint16_t>> schemas_;
    Topic sonar_image_, fan_, polar_, cloud_, instance_, tf_, tf_static_;
    ros::SonarImage sonar_;
    std::vector<std::uint8_t> buffer_;
    std::vector<std::uint16_t> flipped_;       // PREFIX/polar's rows
    std::vector<std::uint16_t> instance_rows_; // PREFIX/instance's rows
    std::vector<float> points_;
    std::uint64_t frames_ = 0, first_ns_ = 0, last_ns_ = 0;
};

} // namespace

std::string rosbag2_metadata_yaml(const std::string& file, const std::vector<BagTopic>& bag_topics,
                                  std::uint64_t first_ns, std::uint64_t last_ns, std::uint64_t messages) {
    std::string topics;
    for (const BagTopic& t : bag_topics) {
        topics += "  - topic_metadata:\n      name: " + t.name + "\n      type: " + t.type +
                  "\n      serialization_format: cdr\n      offered_qos_profiles: " + yaml_quoted(t.qos + "\n") +
                  "\n      type_description_hash: \"\"\n    message_count: " + std::to_string(t.messages) + "\n";
    }
    const std::uint64_t duration = last_ns - first_ns;
    return "version: 8\nstorage_identifier: mcap\nduration:\n  nanoseconds: " + std::to_string(duration) +
           "\nstarting_time:\n  nanoseconds_since_epoch: " + std::to_string(first_ns) +
           "\nmessage_count: " + std::to_string(messages) + "\ntopics_with_message_count:\n" + topics +
           "compression_format: \"\"\ncompression_mode: \"\"\nrelative_file_paths:\n  - " + yaml_quoted(file) +
           "\nfiles:\n  - path: " + yaml_quoted(file) +
           "\n    starting_time:\n      nanoseconds_since_epoch: " + std::to_string(first_ns) +
           "\n    duration:\n      nanoseconds: " + std::to_string(duration) +
           "\n    message_count: " + std::to_string(messages) + "\ncustom_data: {}\nros_distro: \"\"\n";
}

bool mcap_zstd_available() {
    return mcap::zstd_available();
}

Result<std::unique_ptr<McapDatasetWriter>> McapDatasetWriter::create(const std::string& path, const Plan& plan,
                                                                     const McapOptions& options,
                                                                     const std::string& write_to) {
    auto writer = std::make_unique<McapWriterImpl>(path, plan, options);
    if (auto opened = writer->open(write_to.empty() ? path : write_to); !opened) return opened.error();
    return std::unique_ptr<McapDatasetWriter>(std::move(writer));
}

} // namespace vksonar::cli
