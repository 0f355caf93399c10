// `vksonar render`'s per-frame outputs (render_frame.h).
#include "cli/render_frame.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <filesystem>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include <nlohmann/json.hpp>

#include "cli/args.h"
#include "cli/frame_files.h"
#include "core/plan.h"
#include "host/boxes.h"
#include "host/host_stages.h"
#include "host/meta_fields.h"
#include "legacy/legacy.h"
#include "vksonar/vksonar.h"

namespace fs = std::filesystem;

namespace vksonar::cli {
namespace {

// Writes one file of the frame (write_atomically) and notes its name and size for meta.json's
// "files": meta.json is the frame's commit record, and a re-run shard or merge checks the files
// against it (shard.h, frame_folder_check). Without fsync a crash can leave meta.json on disk but an
// earlier file empty or missing; the sizes are how that is seen.
template <class WriteFn> void put(Outputs& out, const fs::path& path, WriteFn&& write) {
    write_atomically(path, std::forward<WriteFn>(write));
    std::error_code ec;
    const std::uintmax_t size = fs::file_size(path, ec);
    if (ec) throw Failure("cannot read the size of " + path.string() + ": " + ec.message());
    out.written.emplace_back(path.filename().string(), size);
}

// `time_s`: the trajectory's time column, or null when it has none.
std::string extra_meta_fields(const Outputs& out, const Pose& pose, const double* time_s) {
    nlohmann::ordered_json extra;
    extra["effects"] = out.effects; // in place of the plan's, where meta_json_text put it
    extra["vksonar_version"] = host::vksonar_version();
    extra["config"] = out.config_parsed;
    extra["scene"] = out.scene_path;
    extra["scene_fnv1a64"] = out.scene_hash;
    if (time_s) extra["time_s"] = *time_s;
    extra["pose"] = {{"x_m", pose.x_m},
                     {"y_m", pose.y_m},
                     {"z_m", pose.z_m},
                     {"roll_deg", pose.roll_deg},
                     {"pitch_deg", pose.pitch_deg},
                     {"yaw_deg", pose.yaw_deg}};
    extra["objects"] = out.objects;
    extra["backend"] = out.backend;
    extra["backend_reason"] = out.backend_reason;
    extra["device"] = out.device;
    if (out.shard)
        extra["shard"] = {{"index", out.shard->index}, {"count", out.shard->count}, {"source", out.shard->source}};
    if (out.legacy && out.legacy->mode == SonarMode::uuv_legacy) {
        extra["mode"] = "uuv-legacy";
        extra["legacy"] = {
            {kFanPng, "uuv_simulator visual scan (400 rows, fixed 17 m range), see docs/legacy.md"},
            {"polar", "polar.npy/png/u16 hold vksonar's physical model of the same ping, not the legacy scan"},
            {"raw_scan", "raw_scan.npy (--save raw_scan): the legacy 400-row float scan after dilation and speckle"},
            {"scan_rows", out.legacy->uuv.scan_rows},
            {"scan_cols", out.legacy->uuv.scan_cols},
            {"scan_range_m", legacy::kUuvRangeM},
            {"depth_image", {{"width", out.legacy->uuv.width}, {"height", out.legacy->uuv.height}}}};
    } else if (out.legacy && out.legacy->mode == SonarMode::gtri_legacy) {
        extra["mode"] = "gtri-legacy";
        extra["legacy"] = {
            {kFanPng, "GTRI 600x600 image (forward up, apex at the centre), see docs/legacy.md"},
            {"polar", "polar.npy/png/u16 hold vksonar's physical model of the same ping, not the legacy image"},
            {kCloudPly, "the GTRI point cloud before the x jitter, intensity = retro 0..255 (--save cloud)"},
            {"points", out.legacy->cloud.size()},
            {"pixels_per_m", legacy::kGtriRangePixels / out.plan.config.range_max_m}};
    } else {
        extra["mode"] = "physical";
    }
    // Every other file of this frame, name -> bytes, in the order written (docs/scale.md, "Restarting").
    nlohmann::ordered_json files = nlohmann::ordered_json::object();
    for (const auto& [name, size] : out.written)
        files[name] = size;
    extra["files"] = std::move(files);
    // The scene path (and --asset-root in the config) may hold bytes that are not UTF-8 (a Latin-1
    // folder name): written as U+FFFD instead of dump() throwing.
    return extra.dump(-1, ' ', false, nlohmann::ordered_json::error_handler_t::replace);
}

// One channel of floats as a grey PNG: value in [0, 1] -> 0..255 (the plugin's convertTo(CV_8U, 255)).
void gray_image(const float* values, std::size_t stride, std::uint32_t width, std::uint32_t height,
                host::Image& image) {
    image.width = width;
    image.height = height;
    image.rgb.resize(static_cast<std::size_t>(width) * height * 3);
    for (std::size_t i = 0; i < static_cast<std::size_t>(width) * height; ++i) {
        const float v = values[i * stride];
        const auto g =
            static_cast<std::uint8_t>(std::lround(std::isfinite(v) ? std::clamp(v, 0.0f, 1.0f) * 255.0f : 0.0f));
        image.rgb[i * 3 + 0] = image.rgb[i * 3 + 1] = image.rgb[i * 3 + 2] = g;
    }
}

// Runs the legacy chain on this frame's depth pass and writes fan.png (the legacy image) and the
// requested legacy intermediates.
void write_legacy(LegacyState& legacy_state, Outputs& out, const fs::path& dir, const Frame& frame) {
    const Plan& plan = out.plan;
    LegacyState& L = legacy_state;
    legacy::legacy_depth_from_frame(plan, frame, L.depth);
    if (L.depth.empty()) throw Failure("legacy mode: the depth pass returned no depth image");
    constexpr double kDegToRad = 3.14159265358979323846 / 180.0;
    const double hfov = plan.config.hfov_deg * kDegToRad;
    auto write_ply = [&](const char* comment) {
        put(out, dir / kCloudPly, [&](const std::string& p) {
            return host::write_points_ply(p, reinterpret_cast<const float*>(L.cloud.data()), L.cloud.size(), comment);
        });
    };
    if (L.mode == SonarMode::uuv_legacy) {
        legacy::uuv_legacy(L.depth.data(), plan.columns, plan.rows, hfov, frame.seed, frame.frame_index, L.uuv);
        if (out.save.fan)
            put(out, dir / kFanPng, [&](const std::string& p) { return host::write_png(p, L.uuv.visual); });
        const legacy::UuvImages& u = L.uuv;
        if (out.save.normals) {
            L.gray.width = u.width;
            L.gray.height = u.height;
            L.gray.rgb.resize(u.normals.size());
            for (std::size_t i = 0; i < u.normals.size(); ++i)
                L.gray.rgb[i] = static_cast<std::uint8_t>(std::lround(std::clamp(u.normals[i], 0.0f, 1.0f) * 255.0f));
            put(out, dir / kNormalsPng, [&](const std::string& p) { return host::write_png(p, L.gray); });
        }
        if (out.save.multibeam) {
            gray_image(u.multibeam.data(), 1, u.width, u.height, L.gray);
            put(out, dir / kMultibeamPng, [&](const std::string& p) { return host::write_png(p, L.gray); });
            put(out, dir / kMultibeamNpy,
                [&](const std::string& p) { return host::write_npy_f32(p, u.multibeam.data(), u.height, u.width); });
        }
        if (out.save.raw_scan) {
            gray_image(u.raw_scan.data(), 1, u.scan_cols, u.scan_rows, L.gray);
            put(out, dir / kRawScanPng, [&](const std::string& p) { return host::write_png(p, L.gray); });
            put(out, dir / kRawScanNpy, [&](const std::string& p) {
                return host::write_npy_f32(p, u.raw_scan.data(), u.scan_rows, u.scan_cols);
            });
        }
        if (out.save.cloud) {
            legacy::uuv_cloud_from_frame(plan, frame, L.uuv, L.cloud);
            write_ply("uuv-legacy depth-camera cloud in the sonar frame: x forward, y port (left), z up; "
                      "intensity = multibeam value 0..1");
        }
    } else {
        legacy::gtri_cloud_from_frame(plan, frame, L.cloud);
        legacy::gtri_legacy(L.cloud, hfov, plan.config.range_max_m, frame.seed, frame.frame_index, L.gtri);
        if (out.save.fan)
            put(out, dir / kFanPng, [&](const std::string& p) { return host::write_png(p, L.gtri.color); });
        if (out.save.cloud)
            write_ply("gtri-legacy cloud in the sonar frame: x forward, y port (left), z up; intensity = retro 0..255");
    }
}

} // namespace

const std::string& frame_boxes(Outputs& out, const Frame& frame) {
    const std::uint32_t width = out.fan.width(), height = out.fan.height();
    out.fan.nearest_cell(frame.instance, out.fan_ids);
    out.box_finder.find(frame, out.fan_ids, width, height, out.boxes);
    out.boxes_text = host::boxes_json_text(frame, width, height, out.boxes, out.class_names);
    return out.boxes_text;
}

namespace {

// --save labels: the per-cell label arrays (as polar.npy's [bins, beams]), the fan-image versions of
// instance and class, nearest cell (docs/labels.md), and each object's box (boxes.json, docs/datasets.md).
void write_labels(Outputs& out, const fs::path& dir, const Frame& frame) {
    const std::uint32_t bins = frame.bins, beams = frame.beams;
    const auto u16 = [&](std::string_view name, const std::vector<std::uint16_t>& v, std::uint32_t rows,
                         std::uint32_t cols) {
        put(out, dir / name, [&](const std::string& p) { return host::write_npy_u16(p, v.data(), rows, cols); });
    };
    const auto f32 = [&](std::string_view name, const std::vector<float>& v, std::uint32_t channels) {
        put(out, dir / name,
            [&](const std::string& p) { return host::write_npy_f32(p, v.data(), bins, beams, channels); });
    };
    u16(kInstanceNpy, frame.instance, bins, beams);
    f32(kInstanceFractionNpy, frame.instance_fraction, 1);
    u16(kClassNpy, frame.object_class, bins, beams);
    f32(kElevationNpy, frame.elevation, 1);
    f32(kElevationSpreadNpy, frame.elevation_spread, 1);
    f32(kPointNpy, frame.point, 3);
    const std::uint32_t width = out.fan.width(), height = out.fan.height();
    out.fan.nearest_cell(frame.object_class, out.fan_ids);
    u16(kClassFanNpy, out.fan_ids, height, width);
    const std::string& boxes = frame_boxes(out, frame);
    u16(kInstanceFanNpy, out.fan_ids, height, width);
    put(out, dir / kBoxesJson, [&](const std::string& p) { return host::write_text_file(p, boxes); });
    host::label_image(out.fan_ids, width, height, out.image);
    put(out, dir / kInstanceFanPng, [&](const std::string& p) { return host::write_png(p, out.image); });
}

} // namespace

void write_frame(Outputs& out, const fs::path& dir, const Frame& frame, const Pose& pose, const double* time_s,
                 const std::vector<float>* flow) {
    const Plan& plan = out.plan;
    out.written.clear();
    if (out.legacy) {
        write_legacy(*out.legacy, out, dir, frame);
    } else if (out.save.fan) {
        out.fan.render(frame, out.image, out.image_workers);
        put(out, dir / kFanPng, [&](const std::string& p) { return host::write_png(p, out.image); });
    }
    if (out.save.polar_png) {
        host::polar_image(plan, frame, out.image);
        put(out, dir / kPolarPng, [&](const std::string& p) { return host::write_png(p, out.image); });
    }
    if (out.save.polar)
        put(out, dir / kPolarNpy, [&](const std::string& p) {
            return host::write_npy_f32(p, frame.intensity.data(), frame.bins, frame.beams);
        });
    if (out.save.polar_u16) {
        host::quantize_display(frame, out.quantized);
        put(out, dir / kPolarU16Npy, [&](const std::string& p) {
            return host::write_npy_u16(p, out.quantized.data(), frame.bins, frame.beams);
        });
    }
    if (out.save.depth) {
        host::depth_to_view_range(plan, frame, out.view_range);
        put(out, dir / kDepthNpy, [&](const std::string& p) {
            return host::write_npy_f32(p, out.view_range.data(), frame.rows, frame.columns);
        });
    }
    if (out.save.normals)
        put(out, dir / kNormalsNpy, [&](const std::string& p) {
            return host::write_npy_f32(p, frame.normals.data(), frame.rows, frame.columns, 4);
        });
    if (out.save.echo)
        put(out, dir / kEchoNpy, [&](const std::string& p) {
            return host::write_npy_f32(p, frame.echo.data(), frame.rows, frame.columns, 2);
        });
    if (out.save.labels) write_labels(out, dir, frame);
    if (flow)
        put(out, dir / kFlowNpy,
            [&](const std::string& p) { return host::write_npy_f32(p, flow->data(), frame.bins, frame.beams, 2); });
    if (out.save.cloud && !out.legacy)
        put(out, dir / kCloudPly, [&](const std::string& p) { return host::write_cloud_ply(p, plan, frame); });
    const std::string extra = extra_meta_fields(out, pose, time_s);
    write_atomically(dir / kMetaJson, [&](const std::string& p) {
        return host::write_meta_json(p, plan, frame, extra, &out.meta_plan_part);
    });
}

} // namespace vksonar::cli
