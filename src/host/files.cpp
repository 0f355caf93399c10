// Output files: PNG, NumPy .npy, PLY point cloud and meta.json. Every error names the path.
#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstddef>
#include <cstdio>
#include <cstring>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "core/angles.h"
#include "core/sonar_math.hpp"
#include "host/host_stages.h"
#include "host/meta_fields.h"

#if defined(__GNUC__)
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wunused-function"
#pragma GCC diagnostic ignored "-Wmissing-field-initializers"
#pragma GCC diagnostic ignored "-Wsign-compare"
#pragma GCC diagnostic ignored "-Wshadow"
#pragma GCC diagnostic ignored "-Wunused-parameter"
#endif
#define STB_IMAGE_WRITE_IMPLEMENTATION
#define STB_IMAGE_WRITE_STATIC // private copy: no clash with any other stb user in the program
#include <stb_image_write.h>
#if defined(__GNUC__)
#pragma GCC diagnostic pop
#endif

#if VKSONAR_HAVE_ZLIB
#include <zlib.h>
#endif

#if defined(__BYTE_ORDER__) && __BYTE_ORDER__ != __ORDER_LITTLE_ENDIAN__
#error "vksonar writes little-endian .npy/.ply by copying memory; add byte swapping for this target"
#endif

namespace vksonar::host {
namespace {

Error io_error(const std::string& path, const std::string& what) {
    return make_error(ErrorCode::io, "cannot write " + path + ": " + what);
}

// Writes header + body in one go; on failure the message carries strerror(errno).
Result<void> write_file(const std::string& path, const void* header, std::size_t header_size, const void* body,
                        std::size_t body_size) {
    errno = 0;
    std::FILE* f = std::fopen(path.c_str(), "wb");
    if (!f) return io_error(path, errno ? std::strerror(errno) : "cannot open");
    bool ok = true;
    if (header_size) ok = std::fwrite(header, 1, header_size, f) == header_size;
    if (ok && body_size) ok = std::fwrite(body, 1, body_size, f) == body_size;
    const int write_errno = errno;
    const bool closed = std::fclose(f) == 0;
    if (!ok || !closed) {
        const int e = write_errno ? write_errno : errno;
        return io_error(path, e ? std::strerror(e) : "write failed");
    }
    return {};
}

// NumPy format 1.0: magic, version, little-endian u16 header length, a Python dict literal padded
// with spaces and terminated by '\n' so the data starts at a multiple of 64 bytes.
std::string npy_header(const char* descr, std::uint32_t rows, std::uint32_t cols, std::uint32_t channels) {
    std::string dict = std::string("{'descr': '") + descr + "', 'fortran_order': False, 'shape': (" +
                       std::to_string(rows) + ", " + std::to_string(cols);
    if (channels > 1) dict += ", " + std::to_string(channels);
    dict += "), }";
    const std::size_t preamble = 10; // magic (6) + version (2) + header length (2)
    std::size_t total = preamble + dict.size() + 1;
    total = (total + 63) / 64 * 64;
    dict.append(total - preamble - dict.size() - 1, ' ');
    dict += '\n';
    const auto len = static_cast<std::uint16_t>(dict.size());
    std::string header("\x93NUMPY\x01\x00", 8);
    header += static_cast<char>(len & 0xff);
    header += static_cast<char>(len >> 8);
    return header + dict;
}

#if VKSONAR_HAVE_ZLIB
// An 8-bit RGB PNG (signature, IHDR, IDAT chunks, IEND; each chunk's CRC-32 over its type and data)
// whose rows all use filter type 0 (None), deflated by zlib at its fastest level. On the speckled fan
// and polar images that is about 5x faster than stb_image_write (which deflates with its own encoder
// after trying the five filters on every row) and 35 % smaller: speckle leaves the other filters
// nothing to predict. Empty on failure.
std::vector<unsigned char> encode_png(const Image& image) {
    const std::size_t row_bytes = static_cast<std::size_t>(image.width) * 3;
    std::vector<unsigned char> rows((row_bytes + 1) * image.height);
    for (std::size_t y = 0; y < image.height; ++y) {
        unsigned char* row = rows.data() + y * (row_bytes + 1);
        row[0] = 0; // filter None
        std::memcpy(row + 1, image.rgb.data() + y * row_bytes, row_bytes);
    }
    z_stream z{};
    if (deflateInit(&z, Z_BEST_SPEED) != Z_OK) return {};
    std::vector<unsigned char> idat(deflateBound(&z, static_cast<uLong>(rows.size())));
    // zlib counts in uInt: feed and drain at most 1 GiB a call
    constexpr std::size_t kStep = std::size_t(1) << 30;
    std::size_t in = 0, out = 0;
    int status = Z_OK;
    while (status == Z_OK) {
        if (out == idat.size()) idat.resize(idat.size() + idat.size() / 2 + 4096); // past deflateBound: not expected
        const std::size_t in_now = std::min(kStep, rows.size() - in), out_now = std::min(kStep, idat.size() - out);
        z.next_in = rows.data() + in;
        z.avail_in = static_cast<uInt>(in_now);
        z.next_out = idat.data() + out;
        z.avail_out = static_cast<uInt>(out_now);
        status = deflate(&z, in + in_now == rows.size() ? Z_FINISH : Z_NO_FLUSH);
        in += in_now - z.avail_in;
        out += out_now - z.avail_out;
        if (status == Z_BUF_ERROR) status = Z_OK; // no progress possible without more room: the loop adds it
    }
    deflateEnd(&z);
    if (status != Z_STREAM_END) return {};

    std::vector<unsigned char> png{137, 80, 78, 71, 13, 10, 26, 10};
    png.reserve(png.size() + 25 + out + 12 * (out / kStep + 1) + 12);
    auto put32 = [&](std::uint32_t v) {
        for (int shift = 24; shift >= 0; shift -= 8)
            png.push_back(static_cast<unsigned char>(v >> shift));
    };
    auto chunk = [&](const char* type, const unsigned char* data, std::size_t size) {
        put32(static_cast<std::uint32_t>(size));
        const std::size_t start = png.size();
        png.insert(png.end(), type, type + 4);
        png.insert(png.end(), data, data + size);
        put32(static_cast<std::uint32_t>(crc32(0L, png.data() + start, static_cast<uInt>(size + 4))));
    };
    unsigned char header[13] = {};
    for (int i = 0; i < 4; ++i) {
        header[i] = static_cast<unsigned char>(image.width >> (24 - 8 * i));
        header[4 + i] = static_cast<unsigned char>(image.height >> (24 - 8 * i));
    }
    header[8] = 8; // bits per channel
    header[9] = 2; // RGB; compression 0, filter method 0, no interlace
    chunk("IHDR", header, sizeof header);
    for (std::size_t at = 0; at < out; at += kStep) // a chunk's length must stay below 2^31
        chunk("IDAT", idat.data() + at, std::min(kStep, out - at));
    chunk("IEND", nullptr, 0);
    return png;
}
#endif

} // namespace

Result<void> write_png(const std::string& path, const Image& image) {
    const std::size_t n = static_cast<std::size_t>(image.width) * image.height * 3;
    if (image.width == 0 || image.height == 0 || image.rgb.size() < n)
        return make_error(ErrorCode::invalid_argument, "cannot write " + path + ": image is empty or smaller than " +
                                                           std::to_string(image.width) + "x" +
                                                           std::to_string(image.height));
        // Encode in memory, then write with stdio so that a failure reports the OS reason.
#if VKSONAR_HAVE_ZLIB
    const std::vector<unsigned char> png = encode_png(image);
    if (png.empty()) return make_error(ErrorCode::internal, "cannot write " + path + ": PNG encoding failed");
    return write_file(path, nullptr, 0, png.data(), png.size());
#else
    std::vector<unsigned char> png;
    auto sink = [](void* context, void* data, int size) {
        auto* out = static_cast<std::vector<unsigned char>*>(context);
        const auto* bytes = static_cast<const unsigned char*>(data);
        out->insert(out->end(), bytes, bytes + size);
    };
    const int ok = stbi_write_png_to_func(sink, &png, static_cast<int>(image.width), static_cast<int>(image.height), 3,
                                          image.rgb.data(), static_cast<int>(image.width * 3));
    if (!ok || png.empty()) return make_error(ErrorCode::internal, "cannot write " + path + ": PNG encoding failed");
    return write_file(path, nullptr, 0, png.data(), png.size());
#endif
}

Result<void> write_npy_f32(const std::string& path, const float* data, std::uint32_t rows, std::uint32_t cols,
                           std::uint32_t channels) {
    const std::size_t count = static_cast<std::size_t>(rows) * cols * (channels ? channels : 1);
    if (count && !data) return make_error(ErrorCode::invalid_argument, "cannot write " + path + ": no data");
    const std::string header = npy_header("<f4", rows, cols, channels);
    return write_file(path, header.data(), header.size(), data, count * sizeof(float));
}

Result<void> write_npy_u16(const std::string& path, const std::uint16_t* data, std::uint32_t rows, std::uint32_t cols) {
    const std::size_t count = static_cast<std::size_t>(rows) * cols;
    if (count && !data) return make_error(ErrorCode::invalid_argument, "cannot write " + path + ": no data");
    const std::string header = npy_header("<u2", rows, cols, 1);
    return write_file(path, header.data(), header.size(), data, count * sizeof(std::uint16_t));
}

Result<void> write_cloud_ply(const std::string& path, const Plan& plan, const Frame& frame) {
    const std::size_t beams = plan.beams, bins = plan.bins;
    const std::size_t n = beams * bins;
    if (frame.display.size() < n || frame.intensity.size() < n || plan.beam_angle_rad.size() < beams ||
        plan.bin_range_m.size() < bins)
        return make_error(ErrorCode::invalid_argument, "cannot write " + path + ": frame does not match the plan (" +
                                                           std::to_string(beams) + " beams x " + std::to_string(bins) +
                                                           " bins)");
    std::vector<float> points;
    points.reserve(4 * 1024);
    for (std::size_t k = 0; k < bins; ++k) {
        const double r = plan.bin_range_m[k];
        for (std::size_t j = 0; j < beams; ++j) {
            const std::size_t i = k * beams + j;
            if (!(frame.display[i] > 0.0f)) continue;
            const double az = plan.beam_angle_rad[j];
            // Sonar frame: x forward, y port (left), z up; the scan lies at elevation 0.
            points.push_back(static_cast<float>(r * std::cos(az)));
            points.push_back(static_cast<float>(r * std::sin(az)));
            points.push_back(0.0f);
            points.push_back(frame.intensity[i]);
        }
    }
    return write_points_ply(path, points.data(), points.size() / 4,
                            "vksonar polar scan in the sonar frame: x forward, y port (left), z up; intensity "
                            "linear uPa^2");
}

Result<void> write_points_ply(const std::string& path, const float* xyzi, std::size_t count,
                              const std::string& comment) {
    if (count && !xyzi) return make_error(ErrorCode::invalid_argument, "cannot write " + path + ": no points");
    // A newline in the comment would end the header line early and corrupt the file.
    std::string one_line = comment;
    for (char& ch : one_line)
        if (ch == '\n' || ch == '\r') ch = ' ';
    const std::string header = "ply\n"
                               "format binary_little_endian 1.0\n"
                               "comment " +
                               one_line +
                               "\n"
                               "element vertex " +
                               std::to_string(count) +
                               "\n"
                               "property float x\n"
                               "property float y\n"
                               "property float z\n"
                               "property float intensity\n"
                               "end_header\n";
    return write_file(path, header.data(), header.size(), xyzi, count * 4 * sizeof(float));
}

std::string meta_json_plan_part(const Plan& plan) {
    using json = nlohmann::ordered_json; // keeps the documented field order in the file
    const SonarConfig& cfg = plan.config;
    json m = json::object();
    m["format"] = "vksonar-frame-1";
    m["frame_convention"] =
        "Sonar frame (REP-103): x forward, y port (left), z up; azimuth is positive to port, beam 0 is the "
        "port-most beam. beam_directions follow marine_acoustic_msgs/ProjectedSonarImage instead: Z forward, "
        "X up, Y starboard (right), so azimuth a maps to (x = 0, y = -sin a, z = cos a).";
    m["beams"] = plan.beams;
    m["bins"] = plan.bins;
    // How a beam divides the directions: cones around the array axis (line_array: beam_angles_rad are
    // steering angles, sin(theta) = cos(elevation) sin(azimuth)) or half-planes of one azimuth (planar).
    m["beam_geometry"] = {{"used", plan.line_array ? "line_array" : "planar"}, {"why", plan.beam_geometry_why}};
    json angles = json::array(), directions = json::array(), tx = json::array(), rx = json::array();
    for (std::size_t j = 0; j < plan.beams && j < plan.beam_angle_rad.size(); ++j) {
        const double a = plan.beam_angle_rad[j];
        angles.push_back(a);
        directions.push_back({{"x", 0.0}, {"y", -std::sin(a)}, {"z", std::cos(a)}});
        tx.push_back(cfg.vfov_deg * kDegToRad);
        rx.push_back(rx_beamwidth_rad(plan, j)); // a line array's beams widen off broadside
    }
    m["beam_angles_rad"] = std::move(angles);
    m["beam_directions"] = std::move(directions);
    json ranges = json::array();
    for (std::size_t k = 0; k < plan.bins && k < plan.bin_range_m.size(); ++k)
        ranges.push_back(plan.bin_range_m[k]);
    m["ranges_m"] = std::move(ranges);
    m["range_min_m"] = cfg.range_min_m;
    m["range_max_m"] = cfg.range_max_m;
    m["bin_width_m"] = plan.bin_width_m;
    m["frequency_hz"] = cfg.frequency_hz;
    m["sound_speed_mps"] = cfg.sound_speed_mps;
    m["tx_beamwidths_rad"] = std::move(tx);
    m["rx_beamwidths_rad"] = std::move(rx);
    m["noise"] = noise_json(plan);
    std::string text = m.dump(2, ' ', false, json::error_handler_t::replace);
    text.resize(text.size() - 2); // the closing "\n}": the frame's fields follow
    return text;
}

std::string meta_json_text(const Plan& plan, const Frame& frame, const std::string& extra_json_fields,
                           const std::string* plan_part) {
    using json = nlohmann::ordered_json;
    json m = json::object();
    m["seed"] = frame.seed;
    m["frame_index"] = frame.frame_index;
    m["effects"] = effects_json(frame.effects.empty() ? plan.effects.states : frame.effects);
    m["validity"] = validity_json(plan.validity);
    m["stages_run"] = frame.stages_run;
    json timings = json::object();
    for (const StageTime& t : frame.times) {
        const double prev = timings.contains(t.stage) ? timings[t.stage].get<double>() : 0.0;
        timings[t.stage] = prev + t.ms; // a stage that ran twice reports its total
    }
    m["timings_ms"] = std::move(timings);
    m["polar_layout"] = "float32 (bins, beams) range-major, beam 0 = port";
    m["intensity_unit"] = "uPa^2 (10 log10 -> dB re 1 uPa)";

    if (!extra_json_fields.empty()) {
        json extra = json::parse(extra_json_fields, nullptr, /*allow_exceptions=*/false);
        if (extra.is_discarded() || !extra.is_object()) return {};
        for (auto it = extra.begin(); it != extra.end(); ++it)
            m[it.key()] = it.value();
    }
    // The frame's fields dumped on their own have the indentation they have inside the whole object.
    const std::string frame_part = m.dump(2, ' ', false, json::error_handler_t::replace);
    return (plan_part ? *plan_part : meta_json_plan_part(plan)) + ",\n" + frame_part.substr(2) + "\n";
}

Result<void> write_text_file(const std::string& path, const std::string& text) {
    return write_file(path, nullptr, 0, text.data(), text.size());
}

Result<void> write_meta_json(const std::string& path, const Plan& plan, const Frame& frame,
                             const std::string& extra_json_fields, const std::string* plan_part) {
    const std::string text = meta_json_text(plan, frame, extra_json_fields, plan_part);
    if (text.empty())
        return make_error(ErrorCode::internal, "cannot write " + path + ": extra fields are not a JSON object");
    return write_file(path, nullptr, 0, text.data(), text.size());
}

void quantize_display(const Frame& frame, std::vector<std::uint16_t>& quantized) {
    quantized.resize(frame.display.size());
    for (std::size_t i = 0; i < frame.display.size(); ++i) {
        const float value = std::isfinite(frame.display[i]) ? std::clamp(frame.display[i], 0.0f, 1.0f) : 0.0f;
        quantized[i] = static_cast<std::uint16_t>(std::lround(value * 65535.0f));
    }
}

// shaders/sonar_math.h's pixel_coord, view_z_from_depth and slant_range, in double.
void depth_to_view_range(const Plan& plan, const Frame& frame, std::vector<float>& range) {
    range.assign(frame.depth.size(), 0.0f);
    if (plan.slice_columns == 0) return;
    for (std::uint32_t row = 0; row < frame.rows; ++row) {
        for (std::uint32_t column = 0; column < frame.columns; ++column) {
            const std::size_t p = static_cast<std::size_t>(row) * frame.columns + column;
            if (p >= frame.depth.size()) return;
            const double d = frame.depth[p];
            if (!(d > 0.0) || d <= plan.depth_b) continue;
            // each view its own half extents and width (a tier view's differ from a slice's); every plan
            // carries its views' geometry (plan_pixel_grid, use_host_grid)
            const std::uint32_t view = std::min(view_of_column(plan, column), plan.views - 1);
            const ViewGeometry& g = plan.view_geometry[view];
            const double u =
                math_f64::pixel_coord(column - view_first_column(plan, view), view_columns(plan, view), g.tan_half_h);
            const double v = math_f64::pixel_coord(row, frame.rows, g.tan_half_v);
            const double r = math_f64::slant_range(math_f64::view_z_from_depth(d, plan.depth_a, plan.depth_b), u, v);
            range[p] = std::isfinite(r) ? static_cast<float>(r) : 0.0f;
        }
    }
}

} // namespace vksonar::host
