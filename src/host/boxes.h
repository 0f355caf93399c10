// Per-frame boxes of the labelled objects (docs/datasets.md, "Boxes and COCO export"): for every
// instance that owns at least one polar cell (Frame::instance), its extent in the polar image and on the
// fan image, its cell count and its own energy. Computed on the host from the labels alone, after
// render; nothing here changes a frame.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "vksonar/frame.h"

namespace vksonar::host {

// Thread-safety: a plain value: safe to read from many threads at once, to write from one.
struct Box {
    std::uint16_t instance_id = 0; // SceneInstance::id
    std::uint16_t class_id = 0;    // SceneInstance::class_id (Frame::object_class of its cells)
    // Polar extent, inclusive: every cell whose Frame::instance is instance_id lies inside, and each
    // bound is a cell of it (so the box is tight).
    std::uint32_t bin_first = 0, bin_last = 0, beam_first = 0, beam_last = 0;
    std::uint64_t cells = 0;
    // Sum over its cells of Frame::clean x Frame::instance_fraction: the part of those cells' echo
    // (linear, relative to the source level, before noise) that is this object's by its share of the
    // cells' main-lobe energy. Energy the object puts into cells that another object owns is not in it.
    double energy = 0.0;
    // Fan extent in pixels, inclusive (x right, y down): the fan pixels whose nearest cell
    // (FanRenderer::nearest_cell) is one of its cells. fan_pixels 0 (a sliver of cells that no fan pixel
    // is nearest to, e.g. near the apex of a small fan image) leaves x0 ... y1 at 0.
    std::uint32_t x0 = 0, y0 = 0, x1 = 0, y1 = 0;
    std::uint64_t fan_pixels = 0;
    // Its polar extent reaches the first or last beam or bin: the object may go on outside the range
    // window or the fan (false does not rule that out in elevation, which the polar image does not show).
    bool at_window_edge = false;
    // Frame::visibility of the object (absent without a scene: has_visibility false): its pixels in the
    // depth pass's view drawn alone, and the fractions of them hidden by a nearer object and outside the
    // range window (of the unhidden ones); hidden + outside is the part of its projection not seen.
    bool has_visibility = false;
    std::uint32_t projected_pixels = 0;
    double hidden_fraction = 0.0, outside_fraction = 0.0;
};

// Finds the boxes of one frame. Its scratch (an id -> box table) is allocated on first use and kept,
// and `boxes` keeps its capacity, so a run of frames allocates nothing once the largest frame was seen.
class BoxFinder {
public:
    // frame: with labels (an unlabelled frame gives no boxes). fan_ids: Frame::instance on the fan
    // image (FanRenderer::nearest_cell), width * height, row-major; empty: no fan extents. `boxes` is
    // refilled in increasing instance id.
    void find(const Frame& frame, const std::vector<std::uint16_t>& fan_ids, std::uint32_t width, std::uint32_t height,
              std::vector<Box>& boxes);

private:
    std::vector<std::uint32_t> slot_; // instance id -> index in `boxes` + 1 (0: none yet); all 0 between calls
};

// boxes.json as text: {"frame_index", "image_size": {"width", "height"}, "polar_size": {"bins",
// "beams"}, "boxes": [...]}. class_names[class_id - 1] names a class (Scene::classes()).
std::string boxes_json_text(const Frame& frame, std::uint32_t width, std::uint32_t height,
                            const std::vector<Box>& boxes, const std::vector<std::string>& class_names);

} // namespace vksonar::host
