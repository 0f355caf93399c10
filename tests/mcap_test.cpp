// The CLI's MCAP writer and ROS 2 CDR serializers (src/cli/mcap_writer.h, ros_msgs.h) against bytes
// worked out by hand from the MCAP specification and the CDR rules; tests/mcap/check_mcap.js reads
// whole bags with independent readers. A bag the CLI writes is read back with its own reader
// (mcap_reader.h) where a topic's pixels must equal a per-frame file.
#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <map>
#include <string>
#include <vector>

#include "cli/cdr.h"
#include "cli/mcap_reader.h"
#include "cli/mcap_writer.h"
#include "cli/npy_read.h"
#include "cli/ros_msgs.h"
#include "cli_support.h"

namespace {

using Bytes = std::vector<std::uint8_t>;
using namespace vksonar::cli;

std::uint64_t le(const Bytes& b, std::size_t at, int n) {
    std::uint64_t v = 0;
    for (int i = 0; i < n; ++i)
        v |= std::uint64_t(b.at(at + i)) << (8 * i);
    return v;
}

std::vector<std::string> msg_blocks(const std::string& text) {
    const std::string delimiter = "\n" + std::string(80, '=') + "\nMSG: ";
    std::vector<std::string> names;
    for (std::size_t at = text.find(delimiter); at != std::string::npos; at = text.find(delimiter, at + 1)) {
        const std::size_t start = at + delimiter.size();
        names.push_back(text.substr(start, text.find('\n', start) - start));
    }
    return names;
}

TEST(Mcap, Crc32IsTheZlibCrc) {
    const char* text = "123456789";
    EXPECT_EQ(mcap::crc32(text, 9), 0xCBF43926u); // the standard check value
    EXPECT_EQ(mcap::crc32(text + 4, 5, mcap::crc32(text, 4)), 0xCBF43926u);
    EXPECT_EQ(mcap::crc32(text, 0), 0u);
    // Against a bit-at-a-time CRC written here, for every length 0..300 and split points that cut
    // the 8-byte table steps and the 16- and 64-byte carry-less steps anywhere (from 64 bytes on,
    // where the CPU has PCLMULQDQ), then at lengths up to 5000 from odd offsets.
    std::vector<std::uint8_t> bytes(5003);
    std::uint32_t state = 12345;
    for (auto& b : bytes)
        b = static_cast<std::uint8_t>((state = state * 1103515245u + 12345u) >> 24);
    auto bitwise = [&](std::size_t n) {
        std::uint32_t c = 0xFFFFFFFFu;
        for (std::size_t i = 0; i < n; ++i) {
            c ^= bytes[i];
            for (int k = 0; k < 8; ++k)
                c = (c & 1u) ? 0xEDB88320u ^ (c >> 1) : c >> 1;
        }
        return c ^ 0xFFFFFFFFu;
    };
    for (std::size_t n = 0; n <= 300; ++n) {
        const std::uint32_t want = bitwise(n);
        ASSERT_EQ(mcap::crc32(bytes.data(), n), want) << n;
        const std::size_t cut = (n * 7) / 13;
        ASSERT_EQ(mcap::crc32(bytes.data() + cut, n - cut, mcap::crc32(bytes.data(), cut)), want) << n;
    }
    for (std::size_t n : {511u, 1024u, 1999u, 4096u, 5000u}) {
        const std::uint32_t want = bitwise(n + 3);
        const std::size_t cut = 3 + (n * 5) / 11; // the second part starts at an odd address
        ASSERT_EQ(mcap::crc32(bytes.data(), n + 3), want) << n;
        ASSERT_EQ(mcap::crc32(bytes.data() + cut, n + 3 - cut, mcap::crc32(bytes.data(), cut)), want) << n;
    }
}

TEST(Cdr, ImageBytesByHand) {
    const std::uint8_t pixels[6] = {1, 2, 3, 4, 5, 6};
    ros::Image m;
    m.header = {1000000002ull, "ab"}; // 1 s + 2 ns
    m.height = 2;
    m.width = 3;
    m.step = 3;
    m.encoding = "mono8";
    m.data = pixels;
    m.data_bytes = 6;
    Bytes out;
    ros::serialize(m, out);
    const Bytes expected = {0x00, 0x01, 0x00, 0x00,                                 // encapsulation: CDR_LE
                            0x01, 0x00, 0x00, 0x00,                                 // stamp.sec
                            0x02, 0x00, 0x00, 0x00,                                 // stamp.nanosec
                            0x03, 0x00, 0x00, 0x00, 'a', 'b', 0x00,                 // frame_id: length with the NUL
                            0x00,                                                   // pad to 4 (offset 15 -> 16)
                            0x02, 0x00, 0x00, 0x00,                                 // height
                            0x03, 0x00, 0x00, 0x00,                                 // width
                            0x06, 0x00, 0x00, 0x00, 'm', 'o', 'n',  'o', '8', 0x00, // encoding
                            0x00,                                                   // is_bigendian (uint8, offset 34)
                            0x00,                                                   // pad to 4 (offset 35 -> 36)
                            0x03, 0x00, 0x00, 0x00,                                 // step
                            0x06, 0x00, 0x00, 0x00, 1,   2,   3,    4,   5,   6};   // data
    EXPECT_EQ(out, expected);
}

TEST(Cdr, Float64AlignsToEightAfterTheHeader) {
    ros::Transform t;
    t.header = {0, "w"};
    t.child_frame_id = "s";
    t.translation[0] = 1.5;
    Bytes out;
    ros::serialize(std::vector<ros::Transform>{t}, out);
    // count 4 + stamp 8 + "w" 6 + pad 2 + "s" 6 = 26 bytes after the header; pad 6 to 32; 7 doubles.
    ASSERT_EQ(out.size(), 4u + 32u + 56u);
    for (std::size_t i = 4 + 26; i < 4 + 32; ++i)
        EXPECT_EQ(out[i], 0) << i;
    double x = 0;
    std::memcpy(&x, out.data() + 4 + 32, 8);
    EXPECT_EQ(x, 1.5);
    double w = 0;
    std::memcpy(&w, out.data() + 4 + 32 + 48, 8);
    EXPECT_EQ(w, 1.0); // identity rotation's w, the last field
}

TEST(Cdr, SonarImageLayout) {
    const float intensities[2] = {0.25f, 4.0f};
    ros::SonarImage m;
    m.header = {0, ""};
    m.frequency = 1.0f;
    m.sound_speed = 2.0f;
    m.beam_directions = {0.0, -0.5, 0.75};
    m.ranges = {3.0f, 4.0f};
    m.beam_count = 1;
    m.data = intensities;
    m.data_bytes = sizeof intensities;
    Bytes out;
    ros::serialize(m, out);
    // header 8 + "" (len 1) 5 -> pad to 16; frequency, sound_speed, two empty float32[] -> 32;
    // Vector3[] count 4 -> 36, pad to 40, 3 doubles -> 64; ranges 4 + 8 -> 76; is_bigendian 1 -> 77,
    // pad -> 80, dtype, beam_count -> 88, data 4 + 8 -> 100.
    ASSERT_EQ(out.size(), 4u + 100u);
    EXPECT_EQ(le(out, 4 + 32, 4), 1u); // one beam direction
    EXPECT_EQ(le(out, 4 + 80, 4), 8u); // DTYPE_FLOAT32
    EXPECT_EQ(le(out, 4 + 84, 4), 1u); // beam_count
    EXPECT_EQ(le(out, 4 + 88, 4), 8u); // uint8[] data: 8 bytes
    float first = 0;
    std::memcpy(&first, out.data() + 4 + 92, 4);
    EXPECT_EQ(first, 0.25f);
}

TEST(RosSchema, DependenciesAsRosbag2WritesThem) {
    const std::string tf = ros::full_definition("tf2_msgs/msg/TFMessage");
    EXPECT_EQ(msg_blocks(tf), (std::vector<std::string>{"geometry_msgs/TransformStamped", "geometry_msgs/Transform",
                                                        "geometry_msgs/Quaternion", "geometry_msgs/Vector3",
                                                        "std_msgs/Header", "builtin_interfaces/Time"}));
    EXPECT_EQ(tf.rfind("geometry_msgs/TransformStamped[] transforms\n", 0), 0u);
    EXPECT_EQ(msg_blocks(ros::full_definition("marine_acoustic_msgs/msg/ProjectedSonarImage")),
              (std::vector<std::string>{"geometry_msgs/Vector3", "marine_acoustic_msgs/PingInfo",
                                        "marine_acoustic_msgs/SonarImageData", "std_msgs/Header",
                                        "builtin_interfaces/Time"}));
    EXPECT_EQ(msg_blocks(ros::full_definition("sensor_msgs/msg/PointCloud2")),
              (std::vector<std::string>{"sensor_msgs/PointField", "std_msgs/Header", "builtin_interfaces/Time"}));
    // Each block is the dependency's .msg verbatim.
    const std::string image = ros::full_definition("sensor_msgs/msg/Image");
    const std::string header_block = "\n" + std::string(80, '=') + "\nMSG: std_msgs/Header\n";
    const std::size_t at = image.find(header_block);
    ASSERT_NE(at, std::string::npos);
    std::string header_msg;
    for (const ros::MsgFile& f : ros::msg_files())
        if (std::string(f.type) == "std_msgs/msg/Header") header_msg = f.text;
    EXPECT_EQ(image.compare(at + header_block.size(), header_msg.size(), header_msg), 0);
    EXPECT_EQ(ros::full_definition("no_msgs/msg/Nothing"), "");
}

// A small file, taken apart record by record.
TEST(Mcap, RecordLayoutAndCrcs) {
    const std::filesystem::path path = std::filesystem::temp_directory_path() / "vksonar_mcap_layout_test.mcap";
    mcap::Writer writer;
    mcap::WriterOptions options;
    options.profile = "ros2";
    options.library = "test";
    ASSERT_TRUE(writer.open(path.string(), options));
    const std::uint16_t schema = writer.add_schema("std_msgs/msg/Empty", "ros2msg", "");
    const std::uint16_t channel = writer.add_channel(schema, "/t", "cdr", {{"k", "v"}});
    const std::uint8_t payload[4] = {0, 1, 0, 0};
    ASSERT_TRUE(writer.write(channel, 0, 5, 6, payload, 4));
    ASSERT_TRUE(writer.write(channel, 1, 7, 7, payload, 4));
    writer.add_metadata("rosbag2", {{"serialized_metadata", "x"}});
    ASSERT_TRUE(writer.close());
    std::ifstream in(path, std::ios::binary);
    const Bytes b((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    std::filesystem::remove(path);

    const Bytes magic = {0x89, 'M', 'C', 'A', 'P', '0', '\r', '\n'};
    ASSERT_GT(b.size(), 16u);
    EXPECT_TRUE(std::equal(magic.begin(), magic.end(), b.begin()));
    EXPECT_TRUE(std::equal(magic.begin(), magic.end(), b.end() - 8));
    // Header: profile "ros2", library "test".
    std::size_t at = 8;
    EXPECT_EQ(b[at], 0x01);
    EXPECT_EQ(le(b, at + 1, 8), 4u + 4 + 4 + 4);
    EXPECT_EQ(le(b, at + 9, 4), 4u);
    at += 9 + le(b, at + 1, 8);
    // Chunk: times, sizes, the CRC of its records; the records are Schema, Channel, Message, Message.
    ASSERT_EQ(b[at], 0x06);
    const std::size_t chunk = at, chunk_length = 9 + le(b, at + 1, 8);
    EXPECT_EQ(le(b, at + 9, 8), 5u);  // message_start_time
    EXPECT_EQ(le(b, at + 17, 8), 7u); // message_end_time
    const std::uint64_t records_size = le(b, at + 25, 8);
    const std::uint32_t crc = static_cast<std::uint32_t>(le(b, at + 33, 4));
    EXPECT_EQ(le(b, at + 37, 4), 0u); // compression ""
    EXPECT_EQ(le(b, at + 41, 8), records_size);
    const std::size_t records = at + 49;
    EXPECT_EQ(crc, mcap::crc32(b.data() + records, records_size));
    EXPECT_EQ(b[records], 0x03); // Schema first, then the Channel
    const std::size_t channel_record = records + 9 + le(b, records + 1, 8);
    EXPECT_EQ(b[channel_record], 0x04);
    const std::size_t first_message = channel_record + 9 + le(b, channel_record + 1, 8);
    EXPECT_EQ(b[first_message], 0x05);
    EXPECT_EQ(le(b, first_message + 9, 2), channel);
    EXPECT_EQ(le(b, first_message + 15, 8), 5u); // log_time
    EXPECT_EQ(le(b, first_message + 23, 8), 6u); // publish_time
    at = chunk + chunk_length;
    // Message Index: channel, then (log_time, offset into the records) per message.
    ASSERT_EQ(b[at], 0x07);
    EXPECT_EQ(le(b, at + 9, 2), channel);
    EXPECT_EQ(le(b, at + 11, 4), 32u);
    EXPECT_EQ(le(b, at + 15, 8), 5u);
    EXPECT_EQ(le(b, at + 23, 8), first_message - records);
    at += 9 + le(b, at + 1, 8);
    // Metadata, then Data End with the CRC of every byte before it.
    ASSERT_EQ(b[at], 0x0C);
    at += 9 + le(b, at + 1, 8);
    ASSERT_EQ(b[at], 0x0F);
    EXPECT_EQ(le(b, at + 9, 4), mcap::crc32(b.data(), at));
    const std::size_t summary_start = at + 13;
    // Footer: summary offsets, and the CRC from the summary start through summary_offset_start.
    const std::size_t footer = b.size() - 8 - 29;
    ASSERT_EQ(b[footer], 0x02);
    EXPECT_EQ(le(b, footer + 1, 8), 20u);
    EXPECT_EQ(le(b, footer + 9, 8), summary_start);
    const std::size_t summary_offsets = le(b, footer + 17, 8);
    EXPECT_EQ(le(b, footer + 25, 4), mcap::crc32(b.data() + summary_start, footer + 25 - summary_start));
    // The summary groups, each named by a Summary Offset: schema, channel, statistics, chunk index,
    // metadata index, in that order, covering the summary exactly.
    std::vector<int> groups;
    std::size_t expected_start = summary_start;
    for (at = summary_offsets; at < footer; at += 9 + le(b, at + 1, 8)) {
        ASSERT_EQ(b[at], 0x0E);
        groups.push_back(b[at + 9]);
        EXPECT_EQ(le(b, at + 10, 8), expected_start);
        EXPECT_EQ(b[le(b, at + 10, 8)], b[at + 9]);
        expected_start += le(b, at + 18, 8);
    }
    EXPECT_EQ(expected_start, summary_offsets);
    EXPECT_EQ(groups, (std::vector<int>{0x03, 0x04, 0x0B, 0x08, 0x0D}));
}

// sensor_msgs/msg/Image read back from CDR (the layout Cdr.ImageBytesByHand spells out).
struct DecodedImage {
    std::uint64_t stamp_ns = 0;
    std::string frame_id, encoding;
    std::uint32_t height = 0, width = 0, step = 0;
    Bytes data;
};

DecodedImage decode_image(const std::uint8_t* bytes, std::size_t size) {
    std::size_t at = 4; // after the encapsulation; alignment counts from here
    auto align = [&](std::size_t n) { at = 4 + ((at - 4 + n - 1) / n) * n; };
    auto u32 = [&] {
        align(4);
        std::uint32_t v = 0;
        EXPECT_LE(at + 4, size);
        std::memcpy(&v, bytes + at, 4);
        at += 4;
        return v;
    };
    auto text = [&] {
        const std::uint32_t n = u32(); // with the NUL
        std::string t(reinterpret_cast<const char*>(bytes + at), n ? n - 1 : 0);
        at += n;
        return t;
    };
    DecodedImage m;
    const std::uint32_t sec = u32(), nsec = u32();
    m.stamp_ns = std::uint64_t(sec) * 1000000000ull + nsec;
    m.frame_id = text();
    m.height = u32();
    m.width = u32();
    m.encoding = text();
    EXPECT_EQ(bytes[at], 0) << "is_bigendian";
    ++at;
    m.step = u32();
    const std::uint32_t n = u32();
    EXPECT_EQ(at + n, size);
    m.data.assign(bytes + at, bytes + at + n);
    return m;
}

// --save labels in a bag: PREFIX/instance is instance.npy of the same frame, rows flipped exactly as
// PREFIX/polar flips polar_u16.npy, with the polar image's stamp and frame id, one message a frame.
TEST(McapBag, InstanceTopicOverlaysThePolarImage) {
    namespace fs = std::filesystem;
    using vksonar::testing::quote;
    const fs::path dir = fs::temp_directory_path() / ("vksonar_mcap_labels_" + std::to_string(::getpid()));
    fs::remove_all(dir);
    fs::create_directories(dir);
    vksonar::testing::write_text(dir / "poses.csv", "x,y,z,roll,pitch,yaw\n0,0,0,0,10,0\n0.5,0.2,-0.1,0,12,6\n");
    auto render = [&](const std::string& out, const std::string& save) {
        std::string command = quote(VKSONAR_CLI) +
                              " render --backend cpu --set bins=40 --set beams=24 --set "
                              "range_min=6 --seed 3 --trajectory " +
                              quote((dir / "poses.csv").string()) + " --save " + save + " --out " +
                              quote((dir / out).string()) + " 2> " + quote((dir / "stderr.txt").string());
        const int status = std::system(command.c_str());
        return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
    };
    ASSERT_EQ(render("frames", "polar_u16,labels"), 0) << vksonar::testing::read_text(dir / "stderr.txt");
    ASSERT_EQ(render("run.mcap", "polar_u16,labels"), 0) << vksonar::testing::read_text(dir / "stderr.txt");

    std::map<std::uint16_t, std::string> topics;
    std::map<std::string, std::vector<DecodedImage>> images;
    std::size_t tf_messages = 0;
    mcap::ReadCallbacks cb;
    cb.channel = [&](const mcap::ReadChannel& c) { topics[c.id] = c.topic; };
    cb.message = [&](const mcap::ReadMessage& m) {
        const std::string& topic = topics[m.channel_id];
        if (topic == "/tf") ++tf_messages;
        if (topic == "/vksonar/instance" || topic == "/vksonar/polar") {
            images[topic].push_back(decode_image(m.data, m.size));
            EXPECT_EQ(images[topic].back().stamp_ns, m.log_time) << topic;
        }
    };
    auto read = mcap::read((dir / "run.mcap").string(), cb);
    ASSERT_TRUE(read) << read.error().message;
    EXPECT_TRUE(read->complete);
    const auto& instance = images["/vksonar/instance"];
    const auto& polar = images["/vksonar/polar"];
    ASSERT_EQ(tf_messages, 2u);
    ASSERT_EQ(instance.size(), 2u);
    ASSERT_EQ(polar.size(), 2u);
    std::size_t labelled = 0;
    for (std::size_t f = 0; f < 2; ++f) {
        const fs::path frame = dir / "frames" / ("frame_00000" + std::to_string(f + 2));
        const NpyArray ids = read_npy((frame / "instance.npy").string());
        const NpyArray display = read_npy((frame / "polar_u16.npy").string());
        ASSERT_EQ(ids.dtype, "<u2");
        ASSERT_EQ(ids.shape, (std::vector<std::size_t>{40, 24}));
        const DecodedImage& image = instance[f];
        EXPECT_EQ(image.encoding, "mono16");
        EXPECT_EQ(image.frame_id, polar[f].frame_id);
        EXPECT_EQ(image.frame_id, "sonar");
        EXPECT_EQ(image.stamp_ns, polar[f].stamp_ns);
        EXPECT_EQ(image.stamp_ns, f * 100000000ull); // ordinal / --rate 10
        EXPECT_EQ(image.height, polar[f].height);
        EXPECT_EQ(image.width, polar[f].width);
        EXPECT_EQ(image.step, polar[f].step);
        EXPECT_EQ(image.height, 40u);
        EXPECT_EQ(image.width, 24u);
        ASSERT_EQ(image.data.size(), 40u * 24u * 2u);
        // Row r of both images is bin (bins - 1 - r): pixel (r, j) of the polar image is polar_u16.npy
        // (bins - 1 - r, j), and the instance image's same pixel is instance.npy's same cell.
        for (std::size_t r = 0; r < 40; ++r)
            for (std::size_t j = 0; j < 24; ++j) {
                const std::size_t pixel = 2 * (r * 24 + j), cell = (39 - r) * 24 + j;
                const unsigned id = image.data[pixel] | unsigned(image.data[pixel + 1]) << 8;
                const unsigned shown = polar[f].data[pixel] | unsigned(polar[f].data[pixel + 1]) << 8;
                ASSERT_EQ(id, ids.values[cell]) << "frame " << f << " row " << r << " beam " << j;
                ASSERT_EQ(shown, display.values[cell]) << "frame " << f << " row " << r << " beam " << j;
                labelled += id != 0;
            }
    }
    EXPECT_GT(labelled, 100u); // the bundled scene labels many cells: the comparison is not of zeros
    std::error_code ec;
    fs::remove_all(dir, ec);
}

} // namespace
