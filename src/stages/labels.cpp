// The labels stage (labels.h): one beam at a time, every pixel that feeds the beam, each of its range
// shares into the cell it lands in, with the pixel's instance, elevation and 3-D point.
#include "stages/labels.h"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <utility>

#include "core/pixel_views.h"
#include "core/sonar_math.hpp"
#include "core/tier_extent.h"
#include "host/workers.h"
#include "scene/scene_data.h"
#include "stages/cpu_stages.h"
#include "stages/labels_flow.h"
#include "stages/pixel_spread.h"

namespace vksonar::cpu {

namespace {
using M = Math<double>;

struct Slot {
    double energy;
    double peak; // the strongest single contribution (one pixel's share) and its point
    float x, y, z;
    std::uint32_t id;
};

struct Cell {
    Slot slots[kLabelSlots];
    std::uint32_t used;
    double energy;      // every contribution, told apart or not
    double psi, psi_sq; // energy-weighted sums of the elevation and its square
};

} // namespace

// A thread labels a block of neighbouring beams at a time (label_beams): with a line array they share
// most of their pixels, which the block reads once. Blocks of kMaxBeamBlock beams where every thread
// still gets kBlocksPerThread blocks (a line array's edge beams gather from more columns, and the blocks
// are dealt out in turn), else half or a quarter of that (beam_block_of: many threads keep the blocks of
// 8 they had; nothing here measured more than 2 threads). On the 2-core development machine, two
// threads with blocks of 32 instead of 8: labels:beams 7.0-7.8 ms against 7.4-9.8 (4 interleaved
// rounds; earlier runs 7.1-8.8 against 9.6-10.0, with blocks of 16 at 8.4-8.5 and 64 at 7.5-9.0). One
// thread: no change. The slow rounds of blocks of 8 fit two threads on neighbouring blocks writing into
// the same cache lines of the label arrays (8 uint16 or floats a bin per block).
constexpr std::uint32_t kMaxBeamBlock = 32, kMinBeamBlock = 8, kBlocksPerThread = 4;
constexpr std::uint32_t beam_block_of(std::uint32_t beams, std::uint32_t threads) {
    std::uint32_t block = kMaxBeamBlock;
    while (block > kMinBeamBlock && std::uint64_t(beams) < std::uint64_t(block) * kBlocksPerThread * threads)
        block /= 2;
    return block;
}

// What the beams need of a pixel, worked out once per frame (a pixel feeds up to four beams).
constexpr int kCachedShares = 8; // most pixels spread over fewer bins; wider footprints keep theirs apart
// Wider spreads keep their shares in double in Pixels::wide_shares, up to kWideSharesPerPixel per pixel
// of a row on average (a row that needs more recomputes the rest where the beams read them).
constexpr std::size_t kWideSharesPerPixel = 2;
// Rows of the pixel cache a thread takes at a time (LabelsStage::run).
constexpr std::uint32_t kCacheRows = 4;
// Bands of rows per thread for each object drawn alone (LabelsStage::visibility), each at least
// kAloneBandRows rows (a triangle across several bands is set up in each).
constexpr std::uint32_t kAloneBandsPerPart = 4, kAloneBandRows = 8;
constexpr std::uint32_t kNoWideShares = ~0u;

struct PixelLabel {
    M::RangeSpread spread;       // k_last < k_first: no energy in the window
    float shares[kCachedShares]; // range_share(spread, k_first + i), when the spread spans <= kCachedShares bins
    float range;                 // slant range, m
    std::uint32_t instance;
    std::uint32_t wide_shares; // spreads wider than kCachedShares: range_share's values (double) start here
                               // in Pixels::wide_shares (kNoWideShares: computed where they are read)
};

struct LabelsStage::Scratch {
    // bins of the beams being labelled (Pixels::beam_block * bins, beam after beam): value-initialised here, and
    // label_beams resets every cell it touched, so each beam starts from zeros without a per-frame clear
    std::vector<Cell> cells;
};

// A pixel's direction, a function of the grid alone (made once with the stage).
struct PixelRay {
    float dir[3];    // unit direction, sonar frame (x forward, y port, z up)
    float elevation; // rad, up positive
};

struct LabelsStage::Pixels {
    // The spreads and shares as the float profile loop makes them, else in double (LabelsStage's
    // float_spreads).
    bool float_spreads = true;
    // rows * columns; written for the pixels with echo energy only (a frame's empty pixels keep an earlier
    // frame's entry: every reader tests the echo first; marking them empty cost 0.5-0.9 ms a frame here)
    std::vector<PixelLabel> pixels;
    std::vector<PixelRay> rays;       // rows * columns
    std::vector<double> slant_factor; // rows * columns: a pixel's slant range / its view-space z
    // per (row, view): the columns [first, end) between the view's first and last hit pixel in that row
    // (first == end: none), which are all that the beams need to visit there
    std::vector<std::uint32_t> hit_columns; // rows * views * 2
    // rows * columns * kWideSharesPerPixel: the shares of the wide spreads, each thread's part of the
    // array its own (LabelsStage::run)
    std::vector<double> wide_shares;
    // beams per block (beam_block_of the beams and the threads)
    std::uint32_t beam_block = kMinBeamBlock;
    // line_array: per block of beam_block beams, row and view, the first pixel column whose cone coordinate
    // reaches the block's (block_first_pixel): a function of the plan, made once with the stage. (Each frame
    // used to scan for it from the thread's last block: perf put 4-5 % of label_beams' samples there, but
    // the stage's time did not move measurably without it.)
    std::vector<std::uint32_t> block_first;
};

// One labelled object's counts drawn alone by one thread (ObjectVisibility's, and `own`: its pixels that
// the frame's depth image also shows it in).
struct AloneTally {
    std::uint32_t pixels = 0, hidden = 0, outside = 0, own = 0;
};

// Frame::visibility: the scene's depth clusters, culled per frame, and per thread a depth image into which
// it draws one labelled object alone at a time (the CPU rasterizer: the same coverage rule as the depth
// pass on either backend).
struct LabelsStage::Alone {
    const SceneData* scene;
    std::vector<shared::DepthPush> draws;
    std::vector<DepthCluster> clusters;
    std::vector<std::uint8_t> drawn; // slices * clusters
    // A thread's image: all 0 (nothing drawn) between two bands; each band's tally puts the pixels it drew
    // back to 0 as it counts them, so nothing is cleared (15 MiB a frame for the bundled scene's seven
    // objects when it was). The material is the rasterizer's output, never read.
    struct Image {
        std::vector<float> depth;
        std::vector<std::uint32_t> material;
        std::vector<std::uint8_t> drawn_alone; // slices * clusters: object `alone_id`'s runs this frame
        std::uint32_t alone_id = 0;            // 0: drawn_alone not made this frame
        std::vector<AloneTally> tally;         // per labelled object (objects' order), this frame
    };
    std::vector<Image> images;            // one per thread
    std::vector<std::uint32_t> objects;   // the labelled ids this frame, increasing
    std::atomic<std::uint32_t> next_band; // the next (object, band) to draw
    std::vector<std::uint8_t> labelled;   // 65536: the ids with a labelled cell this frame
    // With sub-pixel objects possible (Plan::subpixel_capacity > 0), per instance id up to the scene's
    // largest: the tally of its sub-pixel returns this frame (one pass over the list), zeroed once read.
    std::vector<ObjectVisibility> from_returns;
};

namespace {
// The slant range of pixel (row, column) per unit of view-space z: M::slant_range(z, u, v) is z times
// this, the same operations (the echo stage reconstructs a pixel's range so).
double pixel_slant_factor(const Plan& plan, std::uint32_t row, std::uint32_t column) {
    const std::uint32_t index = view_of_column(plan, column);
    const ViewGeometry& view = plan.view_geometry[index];
    const double u =
        M::pixel_coord(column - view_first_column(plan, index), view_columns(plan, index), view.tan_half_h);
    const double v = M::pixel_coord(row, plan.rows, view.tan_half_v);
    return M::slant_range(1.0, u, v);
}

PixelRay pixel_ray_of(const Plan& plan, std::uint32_t row, std::uint32_t column) {
    const std::uint32_t index = view_of_column(plan, column);
    const M::PixelView view = pixel_view<double>(plan, index);
    const double u =
        M::pixel_coord(column - view_first_column(plan, index), view_columns(plan, index), view.tan_half_h);
    const double v = M::pixel_coord(row, plan.rows, view.tan_half_v);
    const M::vec3 ray = M::pixel_ray(u, v, view);
    const double inv_length = 1.0 / std::sqrt(1.0 + u * u + v * v);
    PixelRay out;
    for (int i = 0; i < 3; ++i)
        out.dir[i] = static_cast<float>(ray[i] * inv_length);
    out.elevation = static_cast<float>(std::asin(std::clamp(ray.z * inv_length, -1.0, 1.0)));
    return out;
}

// line_array: the first pixel column of row `row` in view `view` whose cone coordinate reaches the lower
// bound of the block of beams from j_begin (label_beams visits the pixels within one cone column of its
// beams' columns, a tier view's widened by their reach: x >= its first column - 1 - reach). Along a
// view's row the cone coordinate increases with the column (plan_cone_table): a binary search.
std::uint32_t block_first_pixel(const Plan& plan, std::uint32_t j_begin, std::uint32_t row, std::uint32_t view) {
    const float reach = view >= plan.slices ? plan.tier_cone_reach : 0.0f;
    const float lo = static_cast<float>(plan.beam_column_begin[j_begin]) - 1.0f - reach;
    const float* cone_x = plan.pixel_cone_coord.data() + static_cast<std::size_t>(row) * plan.columns;
    const float* view_x = cone_x + view_first_column(plan, view);
    return static_cast<std::uint32_t>(std::lower_bound(view_x, view_x + view_columns(plan, view), lo) - cone_x);
}
} // namespace

LabelsStage::LabelsStage(const Plan& plan, std::vector<std::uint16_t> class_of_instance, host::Workers* workers,
                         const SceneData* scene, bool float_spreads)
    : plan_(plan), class_of_instance_(std::move(class_of_instance)), workers_(workers) {
    const std::uint32_t parts = workers_ != nullptr ? workers_->count() : 1;
    const std::uint32_t beam_block = beam_block_of(plan_.beams, parts);
    for (std::uint32_t i = 0; i < parts; ++i) {
        scratch_.push_back(std::make_unique<Scratch>());
        scratch_.back()->cells.resize(std::size_t(beam_block) * plan_.bins);
    }
    pixels_ = std::make_unique<Pixels>();
    pixels_->float_spreads = float_spreads;
    pixels_->beam_block = beam_block;
    pixels_->pixels.resize(static_cast<std::size_t>(plan_.rows) * plan_.columns);
    pixels_->rays.resize(pixels_->pixels.size());
    pixels_->hit_columns.resize(std::size_t(plan_.rows) * plan_.views * 2);
    pixels_->slant_factor.resize(pixels_->pixels.size());
    for (std::uint32_t row = 0; row < plan_.rows; ++row)
        for (std::uint32_t column = 0; column < plan_.columns; ++column) {
            pixels_->rays[std::size_t(row) * plan_.columns + column] = pixel_ray_of(plan_, row, column);
            pixels_->slant_factor[std::size_t(row) * plan_.columns + column] = pixel_slant_factor(plan_, row, column);
        }
    pixels_->wide_shares.resize(pixels_->pixels.size() * kWideSharesPerPixel);
    if (plan_.line_array) {
        const std::uint32_t blocks = (plan_.beams + beam_block - 1) / beam_block;
        pixels_->block_first.resize(std::size_t(blocks) * plan_.rows * plan_.views);
        for (std::uint32_t block = 0; block < blocks; ++block)
            for (std::uint32_t row = 0; row < plan_.rows; ++row)
                for (std::uint32_t view = 0; view < plan_.views; ++view)
                    pixels_->block_first[(std::size_t(block) * plan_.rows + row) * plan_.views + view] =
                        block_first_pixel(plan_, block * beam_block, row, view);
    }
    beam_buckets_ = BeamBuckets(plan_.beam_angle_rad);
    if (scene != nullptr) {
        alone_ = std::make_unique<Alone>();
        alone_->scene = scene;
        alone_->draws.resize(static_cast<std::size_t>(plan_.views) * scene->draws.size());
        build_depth_clusters(*scene, alone_->clusters);
        alone_->drawn.resize(static_cast<std::size_t>(plan_.views) * alone_->clusters.size());
        // (ids are uint16 with labels on: at most 65535 objects)
        const std::size_t objects = std::min<std::size_t>(scene->draws.size(), 65535);
        alone_->objects.reserve(objects);
        alone_->images.resize(parts);
        for (Alone::Image& image : alone_->images) {
            image.depth.resize(static_cast<std::size_t>(plan_.rows) * plan_.columns);
            image.material.resize(image.depth.size());
            image.drawn_alone.resize(alone_->drawn.size());
            image.tally.resize(objects);
        }
        alone_->labelled.assign(65536, 0);
        if (plan_.subpixel_capacity > 0) {
            std::uint32_t largest = 0;
            for (const SceneDraw& draw : scene->draws)
                largest = std::max(largest, draw.instance);
            alone_->from_returns.assign(std::size_t(largest) + 1, ObjectVisibility{});
        }
    }
}

LabelsStage::~LabelsStage() = default;

namespace {

struct Job {
    const Plan* plan;
    const std::vector<std::uint16_t>* class_of_instance;
    std::vector<std::unique_ptr<LabelsStage::Scratch>>* scratch;
    LabelsStage::Pixels* pixels;
    Frame* frame;
    const SubpixelReturns* subpixel; // null or empty: no sub-pixel returns this frame
};

// The instance a pixel of the depth pass's id image shows (material | instance << 16; 0 where nothing
// was hit).
inline std::uint32_t instance_of(std::uint32_t material_id) {
    return material_id == shared::kNoMaterial ? 0u : material_id >> shared::kInstanceShift;
}

// Adds w (energy) of a pixel of `instance` at elevation psi and point p to the cell.
inline void add(Cell& cell, std::uint32_t instance, double w, double psi, const double p[3]) {
    cell.energy += w;
    cell.psi += w * psi;
    cell.psi_sq += w * psi * psi;
    for (std::uint32_t s = 0; s < cell.used; ++s) {
        Slot& slot = cell.slots[s];
        if (slot.id != instance) continue;
        slot.energy += w;
        if (w > slot.peak) { // the first of equal contributions stays (visit order is fixed)
            slot.peak = w;
            slot.x = static_cast<float>(p[0]);
            slot.y = static_cast<float>(p[1]);
            slot.z = static_cast<float>(p[2]);
        }
        return;
    }
    if (cell.used == kLabelSlots) return; // counted in the total only (labels.h)
    cell.slots[cell.used++] = {w,       w, static_cast<float>(p[0]), static_cast<float>(p[1]), static_cast<float>(p[2]),
                               instance};
}

// Where a pixel's shares go in the cache: its entry's (kCachedShares or fewer), else the room of its part of
// cache_rows in Pixels::wide_shares while there is some (else add_pixel computes them where it reads them).
struct ShareRoom {
    std::vector<double>& wide_shares;
    std::size_t next, end;
};
template <class Share> void cache_shares(PixelLabel& out, int spread_bins, ShareRoom& room, const Share& share) {
    out.wide_shares = kNoWideShares;
    if (spread_bins <= kCachedShares) {
        for (int i = 0; i < spread_bins; ++i)
            out.shares[i] = static_cast<float>(share(i));
    } else if (room.end - room.next >= std::size_t(spread_bins) &&
               room.next + std::size_t(spread_bins) < kNoWideShares) { // (offsets fit 32 bits)
        // once here instead of in every beam the pixel feeds (three or four)
        out.wide_shares = static_cast<std::uint32_t>(room.next);
        for (int i = 0; i < spread_bins; ++i)
            room.wide_shares[room.next++] = share(i);
    }
}

// A range spread in the other precision, field by field (float -> double -> float gives the same floats).
template <class To, class From> typename Math<To>::RangeSpread spread_in(const From& s) {
    typename Math<To>::RangeSpread out;
    out.kernel = s.kernel;
    out.k_first = s.k_first;
    out.k_last = s.k_last;
    out.tent_k0 = s.tent_k0;
    out.tent_w1 = static_cast<To>(s.tent_w1);
    out.origin = s.origin;
    out.lo = static_cast<To>(s.lo);
    out.hi = static_cast<To>(s.hi);
    out.centre = static_cast<To>(s.centre);
    out.g = static_cast<To>(s.g);
    out.inv_norm = static_cast<To>(s.inv_norm);
    return out;
}

// spread_row_pixels's callback (float spreads): the spread's fields into the pixel's entry (in double,
// from which add_pixel gets the same floats back where it computes a share), and its shares.
struct FloatRow {
    PixelLabel* pixels; // the row's entries
    ShareRoom* room;
};
void cache_float_spread(void* context, std::uint32_t column, const Math<float>::RangeSpread& s, int spread_bins,
                        const float* shares) {
    const FloatRow& row = *static_cast<const FloatRow*>(context);
    PixelLabel& out = row.pixels[column];
    out.spread = spread_in<double>(s);
    out.spread.k_last = spread_bins > 0 ? s.k_first + spread_bins - 1 : s.k_first - 1;
    cache_shares(out, spread_bins, *row.room, [&](int i) { return double(shares[i]); });
}

// Rows [row_begin, row_end) of the pixel cache: each hit pixel's range spread and shares as the beamform
// stage makes them (Pixels::float_spreads: the float profile loop's own code; else in double, as the
// CPU backend's double precision), range and instance, and each view's hit columns (its direction is in
// Pixels::rays).
// room: the calling thread's room for the wide spreads' shares (Pixels::wide_shares).
void cache_rows(const Plan& plan, const Frame& frame, LabelsStage::Pixels& cache, std::uint32_t row_begin,
                std::uint32_t row_end, ShareRoom& room) {
    std::vector<PixelLabel>& pixels = cache.pixels;
    const double range_min = plan.config.range_min_m, inv_bin_width = 1.0 / plan.bin_width_m;
    for (std::uint32_t row = row_begin; row < row_end; ++row) {
        std::uint32_t* hits = cache.hit_columns.data() + std::size_t(row) * plan.views * 2;
        PixelLabel* row_pixels = pixels.data() + std::size_t(row) * plan.columns;
        for (std::uint32_t view = 0, column = 0; view < plan.views; ++view) {
            const std::uint32_t view_first = column, view_end = column + view_columns(plan, view);
            hits[2 * view] = hits[2 * view + 1] = column; // none yet
            for (; column < view_end; ++column) {
                const std::size_t p = static_cast<std::size_t>(row) * plan.columns + column;
                const double e = frame.echo[2 * p];
                if (!(e > 0.0)) continue;
                PixelLabel& out = pixels[p];
                if (hits[2 * view] == hits[2 * view + 1]) hits[2 * view] = column;
                hits[2 * view + 1] = column + 1;
                out.range = frame.echo[2 * p + 1];
                out.instance = instance_of(frame.material[p]);
                if (cache.float_spreads) continue; // spread below, a view's pixels at a time
                out.spread = pixel_spread<double>(plan, frame.echo.data(), row, column, e, range_min, inv_bin_width);
                const M::RangeSpread& spread = out.spread;
                cache_shares(out, spread.k_last - spread.k_first + 1, room,
                             [&](int i) { return M::range_share(spread, spread.k_first + i); });
            }
            if (cache.float_spreads && hits[2 * view] < hits[2 * view + 1]) {
                FloatRow context{row_pixels, &room};
                spread_row_pixels(plan, frame.echo.data(), row, hits[2 * view], hits[2 * view + 1], view_first,
                                  view_end, cache_float_spread, &context);
            }
        }
    }
}

// One pixel's energy into the cells of up to kMaxBeamBlock beams along its range shares: beam b (< beams) takes
// weight[b] > 0 of it into cells[b], and widens its touched bins [*k_low[b], *k_high[b]]. Its point in a cell lies
// along its direction at the range of the part of its footprint inside the cell's bin (the footprint kernel spreads one
// pixel over many bins at grazing incidence; the tent and nearest kernels keep its range). Each beam's cells receive
// what add_pixel gave them when it took one beam at a time: the same values in the same order; the share, range and
// point of a bin are worked out once for all the beams.
void add_pixel(const Plan& plan, const Frame& frame, const LabelsStage::Pixels& cache, std::size_t p,
               Cell* const* cells, const double* weight, std::uint32_t beams, int* const* k_low, int* const* k_high) {
    const PixelLabel& pixel = cache.pixels[p];
    const PixelRay& ray = cache.rays[p];
    const M::RangeSpread& spread = pixel.spread;
    if (spread.k_last < spread.k_first) return;
    double e[kMaxBeamBlock];
    for (std::uint32_t b = 0; b < beams; ++b)
        e[b] = frame.echo[2 * p] * weight[b];
    const bool footprint = spread.kernel == shared::kRangeKernelFootprint;
    const bool cached = spread.k_last - spread.k_first < kCachedShares;
    const double* wide =
        pixel.wide_shares != kNoWideShares ? cache.wide_shares.data() + pixel.wide_shares - spread.k_first : nullptr;
    // float spreads: the float kernel's share from the spread's fields (float -> double -> float is exact)
    const auto computed_share = [&](int k) {
        return cache.float_spreads ? double(Math<float>::range_share(spread_in<float>(spread), k))
                                   : M::range_share(spread, k);
    };
    // each beam's first and last bin that took energy, widening [*k_low[b], *k_high[b]] once at the end (locals
    // the compiler keeps apart from the cells: through the pointers every addition reloaded and stored them)
    int low[kMaxBeamBlock], high[kMaxBeamBlock];
    for (std::uint32_t b = 0; b < beams; ++b) {
        low[b] = spread.k_last + 1;
        high[b] = spread.k_first - 1;
    }
    for (int k = spread.k_first; k <= spread.k_last; ++k) {
        const double share = cached ? double(pixel.shares[k - spread.k_first]) : (wide ? wide[k] : computed_share(k));
        double range = pixel.range;
        if (footprint) {
            const double x = spread.origin + 0.5 * (std::max(spread.lo, double(k - spread.origin)) +
                                                    std::min(spread.hi, double(k - spread.origin + 1)));
            range = plan.config.range_min_m + x * plan.bin_width_m;
        }
        const double point[3] = {ray.dir[0] * range, ray.dir[1] * range, ray.dir[2] * range};
        for (std::uint32_t b = 0; b < beams; ++b) {
            const double w = share * e[b];
            if (!(w > 0.0)) continue;
            add(cells[b][static_cast<std::size_t>(k)], pixel.instance, w, ray.elevation, point);
            low[b] = std::min(low[b], k);
            high[b] = k;
        }
    }
    for (std::uint32_t b = 0; b < beams; ++b) {
        if (high[b] < low[b]) continue; // no energy
        *k_low[b] = std::min(*k_low[b], low[b]);
        *k_high[b] = std::max(*k_high[b], high[b]);
    }
}

// The sub-pixel returns of profile column q (core/subpixel.h) that the frame's depth image does not hide,
// into the beam's cells with the beam's share `weight` of the column: each at its centroid, with the
// tent's range shares, as the profile stage adds its echo (profile.comp add_subpixel).
void add_subpixel_returns(const Plan& plan, const Frame& frame, const SubpixelReturns& subpixel, std::uint32_t q,
                          double weight, Cell* cells, int& k_low, int& k_high) {
    const double range_min = plan.config.range_min_m, inv_bin_width = 1.0 / plan.bin_width_m;
    const shared::SubpixelReturn* returns = subpixel.returns();
    const SubpixelLabel* labels = subpixel.labels();
    for (std::uint32_t i = subpixel.column_begin()[q]; i < subpixel.column_begin()[q + 1]; ++i) {
        const shared::SubpixelReturn& r = returns[i];
        if (!M::subpixel_visible(frame.depth[r.pixel], frame.material[r.pixel], plan.subpixel_silent_material, r.view_z,
                                 plan.depth_a, plan.depth_b))
            continue;
        const double e = double(r.energy) * weight;
        const M::vec2 none(0.0);
        const M::RangeSpread spread = M::range_spread(shared::kRangeKernelTent, none, none, M::vec2(e, r.range_m), none,
                                                      none, 0.0, 0.0, range_min, inv_bin_width, 0.0, plan.bins, 0.0);
        const SubpixelLabel& label = labels[i];
        const double point[3] = {label.x, label.y, label.z};
        const double elevation = std::asin(std::clamp(point[2] / double(r.range_m), -1.0, 1.0));
        for (int k = spread.k_first; k <= spread.k_last; ++k) {
            const double w = M::range_share(spread, k) * e;
            if (!(w > 0.0)) continue;
            add(cells[static_cast<std::size_t>(k)], label.instance, w, elevation, point);
            k_low = std::min(k_low, k);
            k_high = std::max(k_high, k);
        }
    }
}

// The share of profile column q that beam j takes (the resample's tent on the beam table).
inline double beam_weight(const Plan& plan, std::uint32_t j, std::uint32_t q) {
    const std::uint32_t share = M::resample_share(plan.column_beam[q], j, plan.beams, plan.circular);
    const double cw = plan.column_weight[q];
    return share == 1 ? cw : (share == 2 ? 1.0 - cw : 0.0);
}

// Labels beams [j_begin, j_end) (a block: cache.beam_block beams from a multiple of it, or fewer at the end) into the
// frame's label arrays. Each beam has its own cells (scratch.cells from (j - j_begin) * bins) and receives its pixels
// in the order of one beam labelled alone: rows, then views, then columns, then bins. With a line array the block walks
// each row of each view once and gives each pixel to all the beams it feeds, so that the pixels they share are read
// once, not once per beam (each beam's own order, and so every cell's sums and ties, unchanged).
void label_beams(const Plan& plan, const std::vector<std::uint16_t>& class_of_instance,
                 const LabelsStage::Pixels& cache, const SubpixelReturns* subpixel, LabelsStage::Scratch& scratch,
                 Frame& frame, std::uint32_t j_begin, std::uint32_t j_end) {
    const std::uint32_t beams = plan.beams, PC = plan.profile_columns, bins = plan.bins;
    int k_low[kMaxBeamBlock], k_high[kMaxBeamBlock];
    for (std::uint32_t j = j_begin; j < j_end; ++j) {
        k_low[j - j_begin] = static_cast<int>(bins);
        k_high[j - j_begin] = -1;
    }
    auto cells_of = [&](std::uint32_t j) { return scratch.cells.data() + std::size_t(j - j_begin) * bins; };
    if (!plan.line_array) {
        for (std::uint32_t j = j_begin; j < j_end; ++j) {
            // one beam at a time: add_pixel's lists of one
            Cell* cells = cells_of(j);
            int* low = &k_low[j - j_begin];
            int* high = &k_high[j - j_begin];
            for (std::uint32_t q = plan.beam_column_begin[j]; q < plan.beam_column_end[j]; ++q) {
                const double weight = beam_weight(plan, j, q);
                if (!(weight > 0.0)) continue;
                for (std::uint32_t row = 0; row < plan.rows; ++row) {
                    const std::size_t p = static_cast<std::size_t>(row) * plan.columns + q;
                    if (frame.echo[2 * p] > 0.0f) add_pixel(plan, frame, cache, p, &cells, &weight, 1, &low, &high);
                }
            }
        }
    }
    // line_array: the block's pixels of each row, each visited once for all the beams it feeds.
    const std::uint32_t block = j_end - j_begin;
    Cell* block_cells[kMaxBeamBlock];
    float block_hi = -std::numeric_limits<float>::infinity();
    for (std::uint32_t j = j_begin; j < j_end; ++j) {
        block_cells[j - j_begin] = cells_of(j);
        block_hi = std::max(block_hi, static_cast<float>(plan.beam_column_end[j]));
    }
    for (std::uint32_t row = 0; row < plan.rows && plan.line_array && block > 0; ++row) {
        // The pixels of this row within one cone column of a beam's [q_begin, q_end): x in [q_begin - 1,
        // q_end) (a tier view's: widened by its pixels' reach), each visited once with the sum of its cone
        // columns' shares of each beam (two, or those a tier pixel's extent touches). Per view:
        // along a view's row the cone coordinate increases with the column (not across views).
        const float* cone_x = plan.pixel_cone_coord.data() + static_cast<std::size_t>(row) * plan.columns;
        const std::uint32_t* block_first =
            cache.block_first.data() + (std::size_t(j_begin / cache.beam_block) * plan.rows + row) * plan.views;
        for (std::uint32_t view = 0; view < plan.views; ++view) {
            // no hit in this row of the view: nothing to visit
            const std::uint32_t* hits = cache.hit_columns.data() + (std::size_t(row) * plan.views + view) * 2;
            if (hits[0] == hits[1]) continue;
            // a tier view's pixel feeds the cone columns its extent touches (the profile's shares)
            const bool tier = view >= plan.slices;
            const float view_hi = block_hi + (tier ? plan.tier_cone_reach : 0.0f);
            const std::uint32_t view_first = view_first_column(plan, view);
            const std::uint32_t view_end = view_first + view_columns(plan, view);
            std::uint32_t b_low = 0;
            for (std::uint32_t c = std::max(block_first[view], hits[0]); c < hits[1] && cone_x[c] < view_hi; ++c) {
                const std::size_t p = static_cast<std::size_t>(row) * plan.columns + c;
                // the echo (8 bytes a pixel, contiguous) says which pixels are empty without touching
                // their cache entry
                if (!(frame.echo[2 * p] > 0.0f)) continue;
                const double x = cone_x[c];
                ConeExtent extent{cone_x[c], cone_x[c]};
                if (tier) extent = tier_cone_extent(cone_x, c, view_first, view_end);
                const ConeColumns columns = cone_columns_fed(cone_x[c], extent);
                const std::int64_t first = columns.first, last = columns.last;
                // the beams whose cone columns hold one of [first, last]: from the first that does not end
                // at or before `first` (x and the extent grow along the view's row, as do the beams' columns; a
                // beam without columns, [0, 0) in assign_columns_to_beams, is passed over or gets no weight)
                while (b_low < block && std::int64_t(plan.beam_column_end[j_begin + b_low]) <= first)
                    ++b_low;
                Cell* cells[kMaxBeamBlock];
                double weight[kMaxBeamBlock];
                int* low[kMaxBeamBlock];
                int* high[kMaxBeamBlock];
                std::uint32_t fed = 0;
                for (std::uint32_t b = b_low; b < block; ++b) {
                    const std::uint32_t j = j_begin + b;
                    const std::int64_t q_begin = plan.beam_column_begin[j], q_end = plan.beam_column_end[j];
                    if (q_begin > last) break;
                    double w = 0.0;
                    for (std::int64_t q = std::max(first, q_begin); q <= last && q < q_end; ++q) {
                        const double share = tier ? M::cone_extent_share(x, double(extent.lo), double(extent.hi),
                                                                         static_cast<int>(q), static_cast<int>(PC))
                                                  : M::cone_share(x, static_cast<int>(q), static_cast<int>(PC));
                        w += share * beam_weight(plan, j, static_cast<std::uint32_t>(q));
                    }
                    if (!(w > 0.0)) continue;
                    cells[fed] = block_cells[b];
                    weight[fed] = w;
                    low[fed] = &k_low[b];
                    high[fed] = &k_high[b];
                    ++fed;
                }
                if (fed > 0) add_pixel(plan, frame, cache, p, cells, weight, fed, low, high);
            }
        }
    }

    for (std::uint32_t j = j_begin; j < j_end; ++j) {
        const std::uint32_t b = j - j_begin;
        Cell* cells = cells_of(j);
        // then each profile column's sub-pixel returns, after the beam's pixels (as the profile stage adds them)
        if (subpixel != nullptr && subpixel->count() > 0) {
            for (std::uint32_t q = plan.beam_column_begin[j]; q < plan.beam_column_end[j]; ++q) {
                const double weight = beam_weight(plan, j, q);
                if (weight > 0.0) add_subpixel_returns(plan, frame, *subpixel, q, weight, cells, k_low[b], k_high[b]);
            }
        }
        // (cells without energy keep the values run() filled in)
        for (int k = k_low[b]; k <= k_high[b]; ++k) {
            Cell& cell = cells[static_cast<std::size_t>(k)];
            if (cell.energy > 0.0 && cell.used > 0) {
                // The most energy wins; an exact tie goes to the lower id.
                const Slot* best = &cell.slots[0];
                for (std::uint32_t s = 1; s < cell.used; ++s) {
                    const Slot& slot = cell.slots[s];
                    if (slot.energy > best->energy || (slot.energy == best->energy && slot.id < best->id)) best = &slot;
                }
                const std::size_t out = static_cast<std::size_t>(k) * beams + j;
                frame.instance[out] = static_cast<std::uint16_t>(best->id);
                frame.instance_fraction[out] = static_cast<float>(best->energy / cell.energy);
                frame.object_class[out] = best->id < class_of_instance.size() ? class_of_instance[best->id] : 0;
                const double mean = cell.psi / cell.energy;
                frame.elevation[out] = static_cast<float>(mean);
                frame.elevation_spread[out] =
                    static_cast<float>(std::sqrt(std::max(0.0, cell.psi_sq / cell.energy - mean * mean)));
                frame.point[3 * out] = best->x;
                frame.point[3 * out + 1] = best->y;
                frame.point[3 * out + 2] = best->z;
            }
            // what add() reads of an unused cell (a slot is read only below `used`, and written whole)
            cell.used = 0;
            cell.energy = cell.psi = cell.psi_sq = 0.0;
        }
    }
}

} // namespace

void LabelsStage::run(Frame& frame, const Pose& pose, const SubpixelReturns* subpixel) {
    // set_part_timing: each part's host time into frame.times (the clock is read only then)
    std::chrono::steady_clock::time_point part_start;
    if (part_timing_) part_start = std::chrono::steady_clock::now();
    const auto part_done = [&](const char* name) {
        if (!part_timing_) return;
        const auto now = std::chrono::steady_clock::now();
        frame.times.push_back({name, std::chrono::duration<double, std::milli>(now - part_start).count()});
        part_start = now;
    };
    Job job{&plan_, &class_of_instance_, &scratch_, pixels_.get(), &frame, subpixel};
    // Each thread clears its share of the label arrays (7 MiB at the default: 0.8 ms on one thread of an
    // H100's host), then takes blocks of kCacheRows rows in turn: the hit pixels crowd into some rows (a
    // seabed fills the lower ones), and one contiguous part of the rows per thread left most of them to
    // one thread (the pixel cache: 11.1 ms on one of that host's threads, 2.1 on 16). Its wide shares go
    // to its own part of Pixels::wide_shares, as large as a contiguous part's was.
    const auto cache = [](void* context, std::uint32_t part, std::uint32_t parts) {
        const Job& t = *static_cast<const Job*>(context);
        Frame& f = *t.frame;
        const std::size_t cells = f.instance.size(), cell_begin = cells * part / parts,
                          cell_end = cells * (part + 1) / parts;
        const float nan = std::numeric_limits<float>::quiet_NaN();
        std::fill(f.instance.begin() + cell_begin, f.instance.begin() + cell_end, std::uint16_t(0));
        std::fill(f.instance_fraction.begin() + cell_begin, f.instance_fraction.begin() + cell_end, 0.0f);
        std::fill(f.object_class.begin() + cell_begin, f.object_class.begin() + cell_end, std::uint16_t(0));
        std::fill(f.elevation.begin() + cell_begin, f.elevation.begin() + cell_end, nan);
        std::fill(f.elevation_spread.begin() + cell_begin, f.elevation_spread.begin() + cell_end, nan);
        std::fill(f.point.begin() + 3 * cell_begin, f.point.begin() + 3 * cell_end, nan);
        std::vector<double>& wide = t.pixels->wide_shares;
        ShareRoom room{wide, wide.size() * part / parts, wide.size() * (part + 1) / parts};
        const std::uint32_t rows = t.plan->rows;
        for (std::uint32_t begin = part * kCacheRows; begin < rows; begin += parts * kCacheRows)
            cache_rows(*t.plan, f, *t.pixels, begin, std::min(begin + kCacheRows, rows), room);
    };
    // Beams dealt out in blocks in turn: a line array's edge beams gather from more columns.
    const auto task = [](void* context, std::uint32_t part, std::uint32_t parts) {
        const Job& t = *static_cast<const Job*>(context);
        LabelsStage::Scratch& scratch = *(*t.scratch)[part];
        const std::uint32_t beams = t.plan->beams, block = t.pixels->beam_block;
        for (std::uint32_t begin = part * block; begin < beams; begin += parts * block)
            label_beams(*t.plan, *t.class_of_instance, *t.pixels, t.subpixel, scratch, *t.frame, begin,
                        std::min(begin + block, beams));
    };
    host::run_parts(workers_, cache, &job);
    part_done("labels:pixels");
    host::run_parts(workers_, task, &job);
    part_done("labels:beams");
    frame.visibility.clear();
    if (alone_) visibility(frame, pose, subpixel);
    part_done("labels:visible");
    // The material image as without labels: the material id alone.
    for (std::uint32_t& m : frame.material)
        if (m != shared::kNoMaterial) m &= shared::kMaterialIdMask;
}

namespace {

// The (object, band) pairs of LabelsStage::visibility, taken in turn by the threads: the object's runs
// (where the frustum does not rule them out) drawn alone into the thread's image in one band of rows, and
// counted into the thread's tally of the object (counts, so the sums do not depend on who drew what).
struct AloneJob {
    const Plan* plan;
    const SceneData* scene;
    LabelsStage::Alone* alone;
    const Frame* frame;
    const double* slant_factor; // Pixels::slant_factor
};

void draw_alone_band(const AloneJob& job, LabelsStage::Alone::Image& image, std::uint32_t object,
                     std::uint32_t row_begin, std::uint32_t row_end) {
    const Plan& plan = *job.plan;
    LabelsStage::Alone& a = *job.alone;
    const std::uint32_t id = a.objects[object];
    if (row_begin == row_end) return;
    if (image.alone_id != id) { // this object's runs, once per thread and object
        image.alone_id = id;
        const std::size_t runs = a.clusters.size();
        for (std::size_t i = 0; i < a.drawn.size(); ++i)
            image.drawn_alone[i] = job.scene->draws[a.clusters[i % runs].draw].instance == id ? a.drawn[i] : 0;
    }
    const DepthClusters only{a.clusters, image.drawn_alone};
    DepthRegion band;
    band.row_begin = row_begin;
    band.row_end = row_end;
    band.clear = false; // the image is all 0 between two bands (Alone::Image)
    PixelBox drawn;     // the tally visits only this box: most objects cover a few rows and columns
    band.drawn = &drawn;
    depth_pass(plan, *job.scene, a.draws, image.depth.data(), image.material.data(), nullptr, &only, band);
    // The depth test is strict GREATER against 0: every drawn pixel holds a depth > 0.
    AloneTally& tally = image.tally[object];
    float* depth = image.depth.data();
    for (std::int64_t row = drawn.y0; row < drawn.y1 && drawn.x0 < drawn.x1; ++row) {
        for (std::int64_t column = drawn.x0; column < drawn.x1; ++column) {
            const std::size_t p = std::size_t(row) * plan.columns + std::size_t(column);
            const float d = depth[p];
            if (!(d > 0.0f)) continue;
            depth[p] = 0.0f; // back to nothing drawn, for the next band
            ++tally.pixels;
            if (instance_of(job.frame->material[p]) != id) {
                ++tally.hidden;
                continue;
            }
            ++tally.own;
            const double range = M::view_z_from_depth(double(d), plan.depth_a, plan.depth_b) * job.slant_factor[p];
            if (range < plan.config.range_min_m || range >= plan.config.range_max_m) ++tally.outside;
        }
    }
}

// Part `part` takes the (object, band) pairs in turn until none is left: objects one after another (the
// bundled scene's seabed, then small ones covering a few rows each), each in kAloneBandsPerPart bands of
// rows per part (at least kAloneBandRows rows each),
// so that small objects run side by side on the threads instead of one after another on all of them.
void draw_alone_bands(void* context, std::uint32_t part, std::uint32_t parts) {
    const AloneJob& job = *static_cast<const AloneJob*>(context);
    LabelsStage::Alone& a = *job.alone;
    LabelsStage::Alone::Image& image = a.images[part];
    const std::uint32_t rows = job.plan->rows;
    const std::uint32_t bands = std::max<std::uint32_t>(1, std::min(parts * kAloneBandsPerPart, rows / kAloneBandRows));
    const std::uint32_t count = static_cast<std::uint32_t>(a.objects.size()) * bands;
    for (std::uint32_t i = a.next_band.fetch_add(1, std::memory_order_relaxed); i < count;
         i = a.next_band.fetch_add(1, std::memory_order_relaxed)) {
        const std::uint32_t band = i % bands;
        draw_alone_band(job, image, i / bands, static_cast<std::uint32_t>(std::uint64_t(rows) * band / bands),
                        static_cast<std::uint32_t>(std::uint64_t(rows) * (band + 1) / bands));
    }
}

} // namespace

void LabelsStage::visibility(Frame& frame, const Pose& pose, const SubpixelReturns* subpixel) {
    Alone& a = *alone_;
    const SceneData& scene = *a.scene;
    for (std::uint16_t id : frame.instance)
        a.labelled[id] = 1;
    a.labelled[0] = 0;
    compose_depth_draws(plan_, scene, pose, a.draws);
    cull_depth_clusters(a.clusters, scene.draws.size(), a.draws, a.drawn);
    // Objects taken out of the depth pass this frame (below the pixel grid's size, core/subpixel.h) have no
    // pixel of their own there, and drawn alone they look hidden by whatever lies behind them: their
    // returns say instead (a piece of it in each profile column it feeds: one or two), hidden as the profile stage
    // hides them. One pass over the list tallies every labelled object's.
    if (subpixel != nullptr && !a.from_returns.empty()) {
        const shared::SubpixelReturn* returns = subpixel->returns();
        const SubpixelLabel* labels = subpixel->labels();
        for (std::uint32_t i = 0; i < subpixel->count(); ++i) {
            const std::uint32_t id = labels[i].instance;
            if (id >= a.from_returns.size() || !a.labelled[id]) continue;
            ObjectVisibility& tally = a.from_returns[id];
            const shared::SubpixelReturn& r = returns[i];
            ++tally.pixels;
            if (!M::subpixel_visible(frame.depth[r.pixel], frame.material[r.pixel], plan_.subpixel_silent_material,
                                     r.view_z, plan_.depth_a, plan_.depth_b))
                ++tally.hidden;
            else if (r.range_m < plan_.config.range_min_m || r.range_m >= plan_.config.range_max_m)
                ++tally.outside;
        }
    }
    a.objects.clear();
    for (std::uint32_t id = 1; id < a.labelled.size(); ++id) {
        if (!a.labelled[id]) continue;
        a.labelled[id] = 0;
        // (no more ids than the scene's draws, which sized each Image::tally)
        if (a.objects.size() < a.images.front().tally.size()) a.objects.push_back(id);
    }
    // Each object in bands of rows dealt to the threads as they come free (draw_alone_bands).
    a.next_band.store(0, std::memory_order_relaxed);
    for (Alone::Image& image : a.images) {
        image.alone_id = 0;
        std::fill(image.tally.begin(), image.tally.begin() + a.objects.size(), AloneTally{});
    }
    AloneJob job{&plan_, &scene, &a, &frame, pixels_->slant_factor.data()};
    host::run_parts(workers_, draw_alone_bands, &job);
    for (std::size_t object = 0; object < a.objects.size(); ++object) {
        const std::uint32_t id = a.objects[object];
        ObjectVisibility v;
        v.instance = id;
        std::uint32_t own = 0; // its pixels in the frame's own depth image
        for (const Alone::Image& image : a.images) {
            const AloneTally& t = image.tally[object];
            v.pixels += t.pixels;
            v.hidden += t.hidden;
            v.outside += t.outside;
            own += t.own;
        }
        if (id < a.from_returns.size()) { // its returns' tally, when it has no pixel of its own
            ObjectVisibility& tally = a.from_returns[id];
            if (own == 0 && tally.pixels > 0) {
                v = tally;
                v.instance = id;
            }
            tally = ObjectVisibility{};
        }
        frame.visibility.push_back(v); // capacity reserved by make_frame (one per instance of the scene)
    }
}

void LabelsStage::flow(const Frame& from, const Pose& from_pose, const Frame& to, const Pose& to_pose,
                       float* flow) const {
    const std::array<double, 16> a = sonar_from_world(from_pose), b = sonar_from_world(to_pose);
    FlowJob job{&plan_, &from, &to, a, b, a == b, flow, pixels_->slant_factor.data(), &beam_buckets_};
    const std::size_t cells = static_cast<std::size_t>(plan_.bins) * plan_.beams;
    if (workers_ == nullptr) {
        flow_cells(job, 0, cells);
        return;
    }
    const auto block = [](void* context, std::uint32_t index, std::uint32_t) {
        const FlowJob& t = *static_cast<const FlowJob*>(context);
        const std::size_t all = static_cast<std::size_t>(t.plan->bins) * t.plan->beams;
        flow_cells(t, std::size_t(index) * kFlowBlock, std::min(all, std::size_t(index + 1) * kFlowBlock));
    };
    workers_->run_blocks(block, &job, static_cast<std::uint32_t>((cells + kFlowBlock - 1) / kFlowBlock));
}

} // namespace vksonar::cpu
