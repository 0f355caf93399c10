// Boxes of the labelled objects from a frame's labels (host/boxes.h).
#include "host/boxes.h"

#include <algorithm>
#include <cstddef>
#include <limits>

#include <nlohmann/json.hpp>

namespace vksonar::host {

void BoxFinder::find(const Frame& frame, const std::vector<std::uint16_t>& fan_ids, std::uint32_t width,
                     std::uint32_t height, std::vector<Box>& boxes) {
    boxes.clear();
    const std::size_t beams = frame.beams, bins = frame.bins, cells = beams * bins;
    if (frame.instance.size() < cells || frame.object_class.size() < cells || frame.instance_fraction.size() < cells)
        return; // no labels in this frame
    // Every uint16 id has a slot: 256 KiB once, instead of a map that would allocate per object.
    if (slot_.empty()) slot_.assign(std::size_t{std::numeric_limits<std::uint16_t>::max()} + 1, 0);
    const bool has_clean = frame.clean.size() >= cells;

    // A row's cells in runs of one id (an object's cells lie side by side along a bin): one box update a
    // run. Its cells' energy still goes into the box one by one, in the order of the cells.
    for (std::size_t k = 0; k < bins; ++k) {
        const std::uint16_t* ids = frame.instance.data() + k * beams;
        for (std::size_t j = 0; j < beams;) {
            const std::uint16_t id = ids[j];
            std::size_t end = j + 1;
            while (end < beams && ids[end] == id)
                ++end;
            if (id == 0) {
                j = end;
                continue;
            }
            const std::size_t i = k * beams + j;
            std::uint32_t& slot = slot_[id];
            if (slot == 0) {
                Box box;
                box.instance_id = id;
                box.class_id = frame.object_class[i];
                box.bin_first = box.bin_last = static_cast<std::uint32_t>(k);
                box.beam_first = box.beam_last = static_cast<std::uint32_t>(j);
                boxes.push_back(box);
                slot = static_cast<std::uint32_t>(boxes.size());
            }
            Box& box = boxes[slot - 1];
            // Cells are visited bin by bin, so bin_first is the first bin seen and bin_last the latest.
            box.bin_last = static_cast<std::uint32_t>(k);
            box.beam_first = std::min(box.beam_first, static_cast<std::uint32_t>(j));
            box.beam_last = std::max(box.beam_last, static_cast<std::uint32_t>(end - 1));
            box.cells += end - j;
            for (std::size_t c = i; c < i + (end - j) && has_clean; ++c)
                box.energy += static_cast<double>(frame.clean[c]) * static_cast<double>(frame.instance_fraction[c]);
            j = end;
        }
    }

    // Fan pixels carry the ids of cells, so every id found there has a box already; a pixel whose id has
    // none (fan_ids from another frame) is skipped rather than invented a box. Runs of one id per row.
    if (fan_ids.size() >= static_cast<std::size_t>(width) * height) {
        for (std::uint32_t y = 0; y < height; ++y) {
            const std::uint16_t* row = fan_ids.data() + static_cast<std::size_t>(y) * width;
            for (std::uint32_t x = 0; x < width;) {
                const std::uint16_t id = row[x];
                std::uint32_t end = x + 1;
                while (end < width && row[end] == id)
                    ++end;
                if (id != 0 && slot_[id] != 0) {
                    Box& box = boxes[slot_[id] - 1];
                    if (box.fan_pixels == 0) {
                        box.x0 = box.x1 = x;
                        box.y0 = box.y1 = y;
                    }
                    box.x0 = std::min(box.x0, x);
                    box.x1 = std::max(box.x1, end - 1);
                    box.y1 = y; // rows in order: the latest row is the lowest
                    box.fan_pixels += end - x;
                }
                x = end;
            }
        }
    }

    for (Box& box : boxes) {
        slot_[box.instance_id] = 0; // the table is all zeros again for the next frame
        box.at_window_edge =
            box.bin_first == 0 || box.beam_first == 0 || box.bin_last + 1 == bins || box.beam_last + 1 == beams;
        box.has_visibility = false;
        const auto seen = std::lower_bound(
            frame.visibility.begin(), frame.visibility.end(), box.instance_id,
            [](const ObjectVisibility& v, std::uint32_t id) { return v.instance < id; }); // increasing ids
        if (seen != frame.visibility.end() && seen->instance == box.instance_id && seen->pixels > 0) {
            box.has_visibility = true;
            box.projected_pixels = seen->pixels;
            box.hidden_fraction = double(seen->hidden) / seen->pixels;
            box.outside_fraction = double(seen->outside) / seen->pixels;
        }
    }
    std::sort(boxes.begin(), boxes.end(), [](const Box& a, const Box& b) { return a.instance_id < b.instance_id; });
}

std::string boxes_json_text(const Frame& frame, std::uint32_t width, std::uint32_t height,
                            const std::vector<Box>& boxes, const std::vector<std::string>& class_names) {
    using json = nlohmann::ordered_json;
    json list = json::array();
    for (const Box& b : boxes) {
        json box = {{"instance_id", b.instance_id},
                    {"class_id", b.class_id},
                    {"class",
                     b.class_id >= 1 && b.class_id <= class_names.size() ? class_names[b.class_id - 1] : std::string()},
                    {"polar",
                     {{"bin_first", b.bin_first},
                      {"bin_last", b.bin_last},
                      {"beam_first", b.beam_first},
                      {"beam_last", b.beam_last}}},
                    {"cells", b.cells},
                    {"energy", b.energy}};
        if (b.fan_pixels > 0)
            box["fan"] = {{"x0", b.x0}, {"y0", b.y0}, {"x1", b.x1}, {"y1", b.y1}, {"pixels", b.fan_pixels}};
        else
            box["fan"] = nullptr;
        box["at_window_edge"] = b.at_window_edge;
        if (b.has_visibility)
            box["visibility"] = {{"projected_pixels", b.projected_pixels},
                                 {"hidden_fraction", b.hidden_fraction},
                                 {"outside_fraction", b.outside_fraction},
                                 {"hidden_or_outside_fraction", b.hidden_fraction + b.outside_fraction}};
        else
            box["visibility"] = nullptr;
        list.push_back(std::move(box));
    }
    const json doc = {{"frame_index", frame.frame_index},
                      {"image_size", {{"width", width}, {"height", height}}},
                      {"polar_size", {{"bins", frame.bins}, {"beams", frame.beams}}},
                      {"boxes", std::move(list)}};
    return doc.dump(2, ' ', false, json::error_handler_t::replace) + "\n";
}

} // namespace vksonar::host
