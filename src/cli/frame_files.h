// The files a frame can write: a frame_NNNNNN folder's entries, or OUT's own for a single pose. One
// table, read by the code that writes them (render_frame.cpp), by the unsharded re-run that clears an
// earlier run's entries from OUT (render_cmd.cpp: a name missing here would survive the re-run and mix
// two runs) and by the readers of a run's folders (export_cmd.cpp, shard.cpp). A file written under
// any other name fails Writer.EveryFileAFrameWritesIsInTheFrameFileTable.
// The descriptions are docs/datasets.md's, docs/labels.md's and docs/legacy.md's tables in short.
#pragma once

#include <string_view>

namespace vksonar::cli {

inline constexpr std::string_view kMetaJson = "meta.json";
inline constexpr std::string_view kFanPng = "fan.png";
inline constexpr std::string_view kPolarNpy = "polar.npy";
inline constexpr std::string_view kPolarPng = "polar.png";
inline constexpr std::string_view kPolarU16Npy = "polar_u16.npy";
inline constexpr std::string_view kDepthNpy = "depth.npy";
inline constexpr std::string_view kNormalsNpy = "normals.npy";
inline constexpr std::string_view kEchoNpy = "echo.npy";
inline constexpr std::string_view kCloudPly = "cloud.ply";
inline constexpr std::string_view kFlowNpy = "flow.npy";
inline constexpr std::string_view kInstanceNpy = "instance.npy";
inline constexpr std::string_view kInstanceFractionNpy = "instance_fraction.npy";
inline constexpr std::string_view kClassNpy = "class.npy";
inline constexpr std::string_view kElevationNpy = "elevation.npy";
inline constexpr std::string_view kElevationSpreadNpy = "elevation_spread.npy";
inline constexpr std::string_view kPointNpy = "point.npy";
inline constexpr std::string_view kClassFanNpy = "class_fan.npy";
inline constexpr std::string_view kInstanceFanNpy = "instance_fan.npy";
inline constexpr std::string_view kInstanceFanPng = "instance_fan.png";
inline constexpr std::string_view kBoxesJson = "boxes.json";
inline constexpr std::string_view kNormalsPng = "normals.png";
inline constexpr std::string_view kMultibeamPng = "multibeam.png";
inline constexpr std::string_view kMultibeamNpy = "multibeam.npy";
inline constexpr std::string_view kRawScanPng = "raw_scan.png";
inline constexpr std::string_view kRawScanNpy = "raw_scan.npy";

struct FrameFile {
    std::string_view name;
    std::string_view save; // the --save item that writes it; empty: always written
    std::string_view what;
};

inline constexpr FrameFile kFrameFiles[] = {
    {kMetaJson, "",
     "what the arrays are: config, pose, beams, ranges, objects, backend; files: the others, written last"},
    {kFanPng, "fan", "the fan image (in legacy modes the legacy plugin's image)"},
    {kPolarNpy, "polar", "float32 [bins, beams], received intensity in uPa^2"},
    {kPolarPng, "polar_png", "the polar image as the display shows it"},
    {kPolarU16Npy, "polar_u16", "uint16 [bins, beams], the display value x 65535"},
    {kDepthNpy, "depth", "float32 [rows, columns], the depth pass's view range per pixel, m"},
    {kNormalsNpy, "normals", "float32 [rows, columns, 4], normal xyz + cos incidence per pixel"},
    {kEchoNpy, "echo", "float32 [rows, columns, 2], energy and range per pixel"},
    {kCloudPly, "cloud", "the point cloud, x y z intensity (legacy modes: the legacy plugin's cloud)"},
    {kFlowNpy, "flow", "float32 [bins, beams, 2], each labelled cell's d_bin, d_beam to the next frame"},
    {kInstanceNpy, "labels", "uint16 [bins, beams], the object that put the most energy into the cell, 0 none"},
    {kInstanceFractionNpy, "labels", "float32 [bins, beams], that object's share of the cell's energy"},
    {kClassNpy, "labels", "uint16 [bins, beams], that object's class id, 0 none"},
    {kElevationNpy, "labels", "float32 [bins, beams], the cell's energy-weighted mean elevation, rad"},
    {kElevationSpreadNpy, "labels", "float32 [bins, beams], its energy-weighted standard deviation, rad"},
    {kPointNpy, "labels", "float32 [bins, beams, 3], the point of the object's strongest return in the cell, m"},
    {kClassFanNpy, "labels", "uint16 [height, width], class.npy on the fan image (nearest cell)"},
    {kInstanceFanNpy, "labels", "uint16 [height, width], instance.npy on the fan image (nearest cell)"},
    {kInstanceFanPng, "labels", "instance_fan.npy, each id a fixed colour, for looking at"},
    {kBoxesJson, "labels", "each object's box in the polar and fan images"},
    {kNormalsPng, "normals", "uuv-legacy: the plugin's normal image"},
    {kMultibeamPng, "multibeam", "uuv-legacy: the normalized SNR image"},
    {kMultibeamNpy, "multibeam", "uuv-legacy: the normalized SNR image, float32"},
    {kRawScanPng, "raw_scan", "uuv-legacy: the raw scan after dilation and speckle"},
    {kRawScanNpy, "raw_scan", "uuv-legacy: the raw scan after dilation and speckle, float32"},
};

constexpr bool is_frame_file(std::string_view name) {
    for (const FrameFile& file : kFrameFiles)
        if (file.name == name) return true;
    return false;
}

// Two entries of one name would be one file written twice.
constexpr bool frame_file_names_unique() {
    for (const FrameFile& a : kFrameFiles)
        for (const FrameFile& b : kFrameFiles)
            if (&a != &b && a.name == b.name) return false;
    return true;
}
static_assert(frame_file_names_unique());

} // namespace vksonar::cli
