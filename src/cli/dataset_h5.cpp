// DatasetWriter (dataset_h5.h) on the HDF5 C library (Debian's libhdf5-dev, serial). Without it the
// build still works and `--out run.h5` says how to get it.
#include "cli/dataset_h5.h"

#include <algorithm>
#include <array>
#include <cstring>
#include <utility>
#include <vector>

#ifdef VKSONAR_HAVE_HDF5
#include <fcntl.h>
#include <unistd.h>

#include <cerrno>

#include <filesystem>
#include <fstream>
#include <memory>

#include "cli/h5_util.h"
#include "host/meta_fields.h"
#include "host/workers.h"
#ifdef VKSONAR_HAVE_ZLIB
#include <zlib.h>
#endif
#endif

namespace vksonar::cli {

namespace {
// The arrays a file holds, as the --save list of its identity: shards merge only with the same arrays.
std::string saved_arrays(bool polar_u16, bool labels, bool flow) {
    return std::string(polar_u16 ? "polar,polar_u16" : "polar") + (labels ? ",labels" : "") + (flow ? ",flow" : "");
}
} // namespace

Identity dataset_identity(const DatasetMeta& meta, const DatasetOptions& options) {
    return run_identity(meta.config_json, meta.seed, meta.scene, meta.backend,
                        saved_arrays(options.polar_u16, options.labels, options.flow), options.has_time,
                        meta.shard ? &*meta.shard : nullptr);
}

#ifndef VKSONAR_HAVE_HDF5

bool hdf5_available() {
    return false;
}

void skip_hdf5_exit_cleanup() {}

Result<std::unique_ptr<DatasetWriter>> DatasetWriter::create(const std::string& path, const Plan&, const DatasetMeta&,
                                                             const DatasetOptions&, const std::string&) {
    return make_error(ErrorCode::unsupported,
                      "--out " + path + ": this build has no HDF5 (install libhdf5-dev and rebuild)");
}

Result<std::unique_ptr<DatasetWriter>> DatasetWriter::resume(const std::string& path, const Plan&, const DatasetMeta&,
                                                             const DatasetOptions&) {
    return make_error(ErrorCode::unsupported, path + ": this build has no HDF5 (install libhdf5-dev and rebuild)");
}

Result<DatasetInfo> read_dataset_info(const std::string& path) {
    return make_error(ErrorCode::unsupported, path + ": this build has no HDF5 (install libhdf5-dev and rebuild)");
}

#else

bool hdf5_available() {
    return true;
}

void skip_hdf5_exit_cleanup() {
    H5dont_atexit();
}

namespace {

using h5::Hid;

constexpr std::uint64_t kHashSeed = 0xcbf29ce484222325ull;

// A dataset creation list without HDF5's object timestamps: with them every dataset's header holds
// its creation and change times, so two runs of one command wrote files whose arrays and attributes
// were equal but whose bytes were not (a checksum of the file said they differed).
Hid dataset_create_list() {
    Hid create(H5Pcreate(H5P_DATASET_CREATE), H5Pclose);
    if (create.ok() && H5Pset_obj_track_times(create.get(), 0) < 0) create.reset();
    return create;
}

// A dataset of rows that grows by one row per frame: [frames, row_dims...], one row per chunk.
struct RowDataset {
    Hid id;
    const char* name = "";
    hid_t memory_type = H5I_INVALID_HID;
    std::vector<hsize_t> row;       // the dimensions after the frame axis
    std::size_t row_bytes = 0;      // one row in memory (a pointer for /boxes' text)
    bool text = false;              // /boxes: a row is a pointer to UTF-8 text
    std::uint64_t hash = kHashSeed; // row_hash over the rows written so far, in order
    // --compress with zlib at hand: the writer shuffles and deflates the row itself (deflate_row), on
    // the deflate threads beside the other rows of the frame, and writes the chunk as it is
    // (H5Dwrite_chunk): the bytes HDF5's own shuffle and deflate filters would store.
    bool deflate = false;
    std::size_t element_bytes = 0;       // the shuffle's element: the file type's size
    std::vector<unsigned char> shuffled; // row_bytes
    std::vector<unsigned char> packed;   // room for the deflated row (compressBound)
    std::size_t packed_bytes = 0;        // this frame's deflated row; 0: not made (HDF5 filters it)
};

// Deflate level of --compress (HDF5's deflate filter, and deflate_row).
constexpr int kDeflateLevel = 4;

#ifdef VKSONAR_HAVE_ZLIB
// One row as HDF5's shuffle filter then its deflate filter at kDeflateLevel store it: byte i of element j
// at i * n + j (n elements), then zlib's compress2, as H5Z_filter_deflate calls it. Sets packed_bytes
// (0 where zlib fails: the row then goes through HDF5's filters).
void deflate_row(RowDataset& d, const void* row) {
    const auto* in = static_cast<const unsigned char*>(row);
    const std::size_t size = d.element_bytes, n = d.row_bytes / size;
    for (std::size_t i = 0; i < size; ++i)
        for (std::size_t j = 0; j < n; ++j)
            d.shuffled[i * n + j] = in[j * size + i];
    uLongf packed = static_cast<uLongf>(d.packed.size());
    d.packed_bytes =
        compress2(d.packed.data(), &packed, d.shuffled.data(), static_cast<uLong>(d.row_bytes), kDeflateLevel) == Z_OK
            ? packed
            : 0;
}
#endif

// ---- the commit record ---------------------------------------------------------------------------
// HDF5 does not write a file in an order that survives a kill: one H5Fflush writes the new chunks, then
// the metadata about in address order (the root group's attributes, frames_written among them, before
// the chunk indexes), then the superblock with the end of the file last, and it rewrites index nodes
// that hold earlier frames in place. A run killed inside a flush can leave frames_written counting a
// frame whose chunk is not indexed (read back as zeros), chunks past the recorded end of the file (a
// resume allocates the next frame over them), or, when a write is cut short, an index that loses
// earlier frames (tests/python/check_resume_torn.py kills at each write). So the frames that count for a
// resume are the ones of the last flush that returned: after it the writer records their number and a
// hash of each dataset's rows in the file's user block (which HDF5 leaves alone), in two slots used in
// turn, each with its own check, so a record cut off by the kill leaves the one before it. A resume
// copies that many frames into a new file, checks them against the hashes, and starts the shard over
// when they differ: the result is the uninterrupted run's, or a warning and a fresh start.
constexpr hsize_t kUserBlock = 512;
constexpr std::size_t kSlotBytes = 256, kMaxHashes = 16;
constexpr char kCommitMagic[8] = {'v', 'k', 's', 'c', 'm', 't', '0', '1'};

struct CommitRecord {
    std::uint64_t frames = 0;
    std::vector<std::uint64_t> hashes; // one per row dataset, in the writer's order
};

// One 8-byte word into a 64-bit hash state.
inline std::uint64_t hash_word(std::uint64_t h, std::uint64_t w) {
    h = (h ^ w) * 0x9E3779B97F4A7C15ull;
    return (h << 31) | (h >> 33);
}

// Bytes into a 64-bit hash, 32 at a time in four lanes (not cryptographic: it tells a torn or stale
// frame from the frame that was written, at several GB/s on the writer thread).
std::uint64_t hash_bytes(std::uint64_t h, const void* data, std::size_t n) {
    constexpr std::uint64_t k = 0x9E3779B97F4A7C15ull;
    const auto* p = static_cast<const unsigned char*>(data);
    std::size_t i = 0;
    if (n >= 32) {
        std::uint64_t lane[4] = {h, h ^ 0x1, h ^ 0x2, h ^ 0x3};
        for (; i + 32 <= n; i += 32) {
            std::uint64_t w[4];
            std::memcpy(w, p + i, 32);
            for (int j = 0; j < 4; ++j)
                lane[j] = hash_word(lane[j], w[j]);
        }
        h = hash_word(hash_word(hash_word(hash_word(h, lane[0]), lane[1]), lane[2]), lane[3]);
    }
    for (; i + 8 <= n; i += 8) {
        std::uint64_t w;
        std::memcpy(&w, p + i, 8);
        h = hash_word(h, w);
    }
    std::uint64_t tail = n;
    for (std::size_t j = 0; i + j < n; ++j)
        tail ^= std::uint64_t(p[i + j]) << (8 * j + 8);
    h = (h ^ tail) * k;
    return (h << 29) | (h >> 35);
}

// One row of `d` (its memory layout) into d.hash.
void hash_row(RowDataset& d, const void* row) {
    if (!d.text) {
        d.hash = hash_bytes(d.hash, row, d.row_bytes);
        return;
    }
    const char* text = *static_cast<const char* const*>(row);
    d.hash = hash_bytes(d.hash, text, text ? std::strlen(text) : 0);
}

std::vector<unsigned char> commit_slot(const CommitRecord& r) {
    std::vector<unsigned char> slot(kSlotBytes, 0);
    std::memcpy(slot.data(), kCommitMagic, 8);
    const std::uint64_t count = r.hashes.size();
    std::memcpy(slot.data() + 8, &r.frames, 8);
    std::memcpy(slot.data() + 16, &count, 8);
    std::memcpy(slot.data() + 24, r.hashes.data(), 8 * r.hashes.size());
    const std::uint64_t check = hash_bytes(kHashSeed, slot.data(), 24 + 8 * kMaxHashes);
    std::memcpy(slot.data() + 24 + 8 * kMaxHashes, &check, 8);
    return slot;
}

// The record of the last flush that returned: the valid slot with the most frames.
std::optional<CommitRecord> read_commit(const std::string& path) {
    std::ifstream file(path, std::ios::binary);
    std::vector<unsigned char> block(2 * kSlotBytes, 0);
    if (!file.read(reinterpret_cast<char*>(block.data()), std::streamsize(block.size()))) return std::nullopt;
    std::optional<CommitRecord> best;
    for (std::size_t s = 0; s < 2; ++s) {
        const unsigned char* slot = block.data() + s * kSlotBytes;
        std::uint64_t frames, count, check;
        std::memcpy(&frames, slot + 8, 8);
        std::memcpy(&count, slot + 16, 8);
        std::memcpy(&check, slot + 24 + 8 * kMaxHashes, 8);
        if (std::memcmp(slot, kCommitMagic, 8) != 0 || count > kMaxHashes ||
            check != hash_bytes(kHashSeed, slot, 24 + 8 * kMaxHashes))
            continue;
        if (best && best->frames >= frames) continue;
        best.emplace();
        best->frames = frames;
        best->hashes.resize(count);
        std::memcpy(best->hashes.data(), slot + 24, 8 * count);
    }
    return best;
}

// Why H5Fcreate failed: H5Fcreate's own error says only that; the innermost entry of HDF5's error stack
// says why ("unable to lock file": another process has it open), else errno.
std::string create_failure_reason(const std::string& path) {
    const int saved = errno;
    std::string innermost;
    H5Ewalk2(
        H5E_DEFAULT, H5E_WALK_DOWNWARD,
        [](unsigned, const H5E_error2_t* e, void* data) -> herr_t {
            if (e && e->desc) *static_cast<std::string*>(data) = e->desc;
            return 0;
        },
        &innermost);
    std::error_code ec;
    if (innermost.find("lock") != std::string::npos)
        return "it is open in another process (HDF5 file lock: " + innermost + ")";
    if (std::filesystem::exists(path, ec)) return "a file of that name is already there";
    if (saved != 0) return std::strerror(saved);
    return innermost.empty() ? std::string("HDF5 gave no reason") : innermost;
}

// The label arrays (--save labels): all of them or none, as the run asked. `boxes` holds one
// boxes.json text per frame.
struct LabelRows {
    RowDataset instance, instance_fraction, object_class, elevation, elevation_spread, point, boxes;
};

class H5Writer final : public DatasetWriter {
public:
    explicit H5Writer(std::string path, std::string name = std::string())
        : path_(std::move(path)), name_(name.empty() ? path_ : std::move(name)) {}
    ~H5Writer() override { abandon(); }
    H5Writer(const H5Writer&) = delete;
    H5Writer& operator=(const H5Writer&) = delete;

    Result<void> open(const Plan& plan, const DatasetMeta& meta, const DatasetOptions& options) {
        H5Eset_auto2(H5E_DEFAULT, nullptr, nullptr); // errors come back as one line, not a stack dump
        if (!make_text_type()) return fail("cannot make the text type");
        // The user block holds the commit record (read_commit).
        const Hid create(H5Pcreate(H5P_FILE_CREATE), H5Pclose);
        if (!create.ok() || H5Pset_userblock(create.get(), kUserBlock) < 0) return fail("cannot make the user block");
        // EXCL: a file that is there is not this run's to truncate (the caller writes a new name).
        file_ = Hid(H5Fcreate(path_.c_str(), H5F_ACC_EXCL, create.get(), H5P_DEFAULT), H5Fclose);
        if (!file_.ok()) return fail("cannot create " + path_ + ": " + create_failure_reason(path_));
        commit_fd_ = ::open(path_.c_str(), O_WRONLY | O_CLOEXEC);
        if (commit_fd_ < 0) return fail("cannot open the user block");
        const hsize_t bins = plan.bins, beams = plan.beams;
        bool ok = rows(polar_, "polar", H5T_IEEE_F32LE, H5T_NATIVE_FLOAT, {bins, beams}, options.compress) &&
                  rows(pose_, "pose", H5T_IEEE_F64LE, H5T_NATIVE_DOUBLE, {6}, false) &&
                  rows(frame_index_, "frame_index", H5T_STD_U64LE, H5T_NATIVE_UINT64, {}, false) &&
                  rows(time_, "time", H5T_IEEE_F64LE, H5T_NATIVE_DOUBLE, {}, false);
        if (ok && options.polar_u16)
            ok = rows(polar_u16_, "polar_u16", H5T_STD_U16LE, H5T_NATIVE_UINT16, {bins, beams}, options.compress);
        if (ok && options.labels) {
            const bool z = options.compress;
            LabelRows& l = labels_;
            ok = rows(l.instance, "instance", H5T_STD_U16LE, H5T_NATIVE_UINT16, {bins, beams}, z) &&
                 rows(l.instance_fraction, "instance_fraction", H5T_IEEE_F32LE, H5T_NATIVE_FLOAT, {bins, beams}, z) &&
                 rows(l.object_class, "class", H5T_STD_U16LE, H5T_NATIVE_UINT16, {bins, beams}, z) &&
                 rows(l.elevation, "elevation", H5T_IEEE_F32LE, H5T_NATIVE_FLOAT, {bins, beams}, z) &&
                 rows(l.elevation_spread, "elevation_spread", H5T_IEEE_F32LE, H5T_NATIVE_FLOAT, {bins, beams}, z) &&
                 rows(l.point, "point", H5T_IEEE_F32LE, H5T_NATIVE_FLOAT, {bins, beams, 3}, z) &&
                 // Not filtered: deflate would see the heap references, not the text.
                 rows(l.boxes, "boxes", text_type_.get(), text_type_.get(), {}, false);
        }
        if (ok && options.flow)
            ok = rows(flow_, "flow", H5T_IEEE_F32LE, H5T_NATIVE_FLOAT, {bins, beams, 2}, options.compress);
        std::vector<double> angles(plan.beam_angle_rad.begin(), plan.beam_angle_rad.begin() + plan.beams);
        std::vector<double> ranges(plan.bin_range_m.begin(), plan.bin_range_m.begin() + plan.bins);
        ok = ok && vector(file_.get(), "beam_angles_rad", angles) && vector(file_.get(), "ranges_m", ranges);
        const SonarConfig& c = plan.config;
        ok = ok && text("format", "vksonar-dataset-1") &&
             text("frame_convention", "Sonar frame (REP-103): x forward, y port (left), z up; azimuth is positive "
                                      "to port, beam 0 is the port-most beam (as meta.json)") &&
             text("polar_layout", "float32 (frames, bins, beams) range-major, beam 0 = port") &&
             text("intensity_unit", "uPa^2 (10 log10 -> dB re 1 uPa)") &&
             text("time_unit", options.has_time ? "s (the trajectory's time column)"
                                                : "frame ordinal (the trajectory has no time column)") &&
             count("beams", plan.beams) && count("bins", plan.bins) && number("bin_width_m", plan.bin_width_m) &&
             number("range_min_m", c.range_min_m) && number("range_max_m", c.range_max_m) &&
             number("frequency_hz", c.frequency_hz) && number("sound_speed_mps", c.sound_speed_mps) &&
             count("seed", meta.seed) && text("config", meta.config_json) && text("effects", meta.effects_json) &&
             text("validity", meta.validity_json) && text("beam_geometry", plan.line_array ? "line_array" : "planar") &&
             text("beam_geometry_why", plan.beam_geometry_why) && text("objects", meta.objects_json) &&
             text("noise", host::noise_json(plan).dump()) && text("scene", meta.scene) &&
             text("backend", meta.backend) && text("device", meta.device) &&
             text("vksonar_version", host::vksonar_version()) &&
             (meta.scene_hash.empty() || text("scene_fnv1a64", meta.scene_hash)) && count("frames_written", 0) &&
             count("complete", 0);
        if (ok && meta.shard) {
            const ShardRecord& r = *meta.shard;
            ok = count("shard_index", r.index) && count("shard_count", r.count) && text("shard_source", r.source) &&
                 count("shard_first", r.first) && count("shard_end", r.end) && count("trajectory_frames", r.total) &&
                 text("trajectory", r.trajectory) && text("trajectory_fnv1a64", r.trajectory_hash);
        }
        if (!ok) return fail("cannot write the dataset's layout");
        std::uint32_t deflating = 0;
        for (const RowDataset* d : row_sets())
            deflating += d->deflate ? 1u : 0u;
        const std::uint32_t threads = std::min({deflating, host::usable_cpus(), host::Workers::kMaxThreads});
        deflaters_ = threads > 1 ? std::make_unique<host::Workers>(threads) : nullptr;
        if (H5Fflush(file_.get(), H5F_SCOPE_LOCAL) < 0 || !write_commit()) return fail("cannot flush");
        return {};
    }

    // Goes on with an existing shard file (DatasetWriter::resume): its frames of the last flush that
    // returned (the commit record) are copied into a new file made as open() makes one, checked against
    // the record's hashes, and the new file replaces the old one; this writer then appends to it.
    Result<void> resume_from(const Plan& plan, const DatasetMeta& meta, const DatasetOptions& options) {
        auto info = read_dataset_info(path_);
        if (!info) return info.error();
        const ShardRecord& want = *meta.shard;
        if (!info->shard || info->shard->index != want.index || info->shard->count != want.count ||
            info->shard->first != want.first || info->shard->end != want.end)
            return make_error(ErrorCode::invalid_argument,
                              path_ + " holds " +
                                  (info->shard ? "shard " + std::to_string(info->shard->index) + "/" +
                                                     std::to_string(info->shard->count)
                                               : std::string("an unsharded run")) +
                                  ", not shard " + std::to_string(want.index) + "/" + std::to_string(want.count) +
                                  ": give each shard its own --out");
        const Identity expected = dataset_identity(meta, options);
        if (std::string d = identity_difference(info->identity, expected); !d.empty())
            return make_error(ErrorCode::invalid_argument,
                              path_ + " holds another run (" + d + "): remove it or give another --out");
        if (info->frames_written > want.end - want.first)
            return make_error(ErrorCode::invalid_argument, path_ + ": frames_written is larger than the shard");
        const auto record = read_commit(path_);
        if (!record)
            return make_error(ErrorCode::io, path_ + ": no record of its whole frames (cut off before its first "
                                                     "flush, or written by an older vksonar)");
        if (record->frames > info->frames_written)
            return make_error(ErrorCode::io, path_ + ": its commit record counts " + std::to_string(record->frames) +
                                                 " frames, frames_written " + std::to_string(info->frames_written));
        const std::string target = path_;
        const std::filesystem::path where(target);
        const std::filesystem::path temporary =
            (where.has_parent_path() ? where.parent_path() : std::filesystem::path(".")) /
            (".~" + where.filename().string() + ".resuming-" + std::to_string(::getpid()));
        path_ = temporary.string();
        auto copied = copy_frames(target, *record, plan, meta, options);
        std::error_code ec;
        if (copied) std::filesystem::rename(temporary, where, ec);
        path_ = target;
        if (!copied || ec) {
            abandon();
            std::filesystem::remove(temporary, ec);
            if (!copied) return copied.error();
            return fail("cannot replace it with the resumed file");
        }
        return {};
    }

    std::uint64_t frames_written() const override { return frames_; }

    Result<void> append(const Frame& frame, const Pose& pose, double time_s, const std::uint16_t* display_u16,
                        const float* flow, const std::string* boxes_json) override {
        // (HDF5's error printing is per thread in a thread-safe build, and frames are written on the
        // write-behind thread, not the one that opened the file: a full disk printed its whole stack)
        H5Eset_auto2(H5E_DEFAULT, nullptr, nullptr);
        const double pose_row[6] = {pose.x_m, pose.y_m, pose.z_m, pose.roll_deg, pose.pitch_deg, pose.yaw_deg};
        const std::uint64_t index = frame.frame_index;
        // A Renderer made without SaveFlags::labels leaves the label arrays empty (refused below).
        const std::size_t cells = std::size_t(frame.bins) * frame.beams;
        const bool has_labels = frame.instance.size() == cells && frame.point.size() == 3 * cells;
        const auto label = [&](const auto& array) -> const void* { return has_labels ? array.data() : nullptr; };
        LabelRows& l = labels_;
        deflate_rows({{&polar_, frame.intensity.data()},
                      {&polar_u16_, display_u16},
                      {&flow_, flow},
                      {&l.instance, label(frame.instance)},
                      {&l.instance_fraction, label(frame.instance_fraction)},
                      {&l.object_class, label(frame.object_class)},
                      {&l.elevation, label(frame.elevation)},
                      {&l.elevation_spread, label(frame.elevation_spread)},
                      {&l.point, label(frame.point)}});
        bool ok = append_row(polar_, frame.intensity.data()) && append_row(pose_, pose_row) &&
                  append_row(frame_index_, &index) && append_row(time_, &time_s);
        if (ok && polar_u16_.id.ok()) ok = append_row(polar_u16_, display_u16);
        if (ok && labels_.instance.id.ok()) {
            // refused rather than read past the empty arrays
            if (!has_labels)
                return fail("frame " + std::to_string(frames_) + " has no labels (render with SaveFlags::labels)");
            if (boxes_json == nullptr) return fail("frame " + std::to_string(frames_) + " has no boxes");
            // The variable-length string type takes a pointer to the text; HDF5 copies it out.
            const char* boxes_text = boxes_json->c_str();
            ok = append_row(l.instance, frame.instance.data()) &&
                 append_row(l.instance_fraction, frame.instance_fraction.data()) &&
                 append_row(l.object_class, frame.object_class.data()) &&
                 append_row(l.elevation, frame.elevation.data()) &&
                 append_row(l.elevation_spread, frame.elevation_spread.data()) &&
                 append_row(l.point, frame.point.data()) && append_row(l.boxes, &boxes_text);
        }
        if (ok && flow_.id.ok()) {
            if (flow == nullptr) return fail("frame " + std::to_string(frames_) + " has no flow");
            ok = append_row(flow_, flow);
        }
        if (!ok) return fail("cannot write frame " + std::to_string(frames_));
        ++frames_;
        // The frame counts only once its rows and their indexes are in the file: flushed, then
        // frames_written flushed on its own (one flush would write it before the indexes), so a reader of
        // a killed run finds it readable; then recorded for a resume (read_commit).
        if (H5Fflush(file_.get(), H5F_SCOPE_LOCAL) < 0 || !set_count("frames_written", frames_) ||
            H5Fflush(file_.get(), H5F_SCOPE_LOCAL) < 0 || !write_commit())
            return fail("cannot flush frame " + std::to_string(frames_ - 1));
        return {};
    }

    Result<void> close() override {
        H5Eset_auto2(H5E_DEFAULT, nullptr, nullptr);
        if (!set_count("complete", 1)) return fail("cannot mark the file complete");
        close_datasets();
        if (H5Fclose(file_.release()) < 0) return fail("cannot close the file");
        if (commit_fd_ >= 0 && ::close(std::exchange(commit_fd_, -1)) != 0) return fail("cannot close the file");
        return {};
    }

private:
    struct PendingRow {
        RowDataset* set;
        const void* data; // null: the frame has no such row (the append checks it)
    };
    static constexpr std::size_t kMaxDeflatedRows = 9;

    // The frame's rows of the datasets that deflate their own chunks, deflated side by side on the
    // deflate threads (each row by one thread, so the bytes do not depend on the threads): on the
    // bundled scene with labels, --compress otherwise runs the writer thread at 90 ms a frame.
    void deflate_rows(std::initializer_list<PendingRow> rows) {
#ifdef VKSONAR_HAVE_ZLIB
        struct Work {
            std::array<PendingRow, kMaxDeflatedRows> rows;
            std::uint32_t count = 0;
        } work;
        for (const PendingRow& r : rows)
            if (r.set->id.ok() && r.set->deflate && r.data != nullptr && work.count < kMaxDeflatedRows)
                work.rows[work.count++] = r;
        if (work.count == 0) return;
        const auto one = [](void* context, std::uint32_t block, std::uint32_t) {
            const PendingRow& r = static_cast<Work*>(context)->rows[block];
            deflate_row(*r.set, r.data);
        };
        if (!deflaters_) {
            for (std::uint32_t i = 0; i < work.count; ++i)
                one(&work, i, 0);
            return;
        }
        deflaters_->run_blocks(one, &work, work.count);
#else
        (void)rows;
#endif
    }

    // The row datasets this file has, in a fixed order: the commit record's hashes follow it.
    std::vector<RowDataset*> row_sets() {
        std::vector<RowDataset*> sets;
        LabelRows& l = labels_;
        for (RowDataset* d : {&polar_, &pose_, &frame_index_, &time_, &polar_u16_, &l.instance, &l.instance_fraction,
                              &l.object_class, &l.elevation, &l.elevation_spread, &l.point, &l.boxes, &flow_})
            if (d->id.ok()) sets.push_back(d);
        return sets;
    }

    // Records frames_ and the rows' hashes in the user block, in slot frames_ % 2 (read_commit).
    bool write_commit() {
        CommitRecord record;
        record.frames = frames_;
        for (const RowDataset* d : row_sets())
            record.hashes.push_back(d->hash);
        if (commit_fd_ < 0 || record.hashes.size() > kMaxHashes) return false;
        const std::vector<unsigned char> slot = commit_slot(record);
        return ::pwrite(commit_fd_, slot.data(), slot.size(), off_t((frames_ % 2) * kSlotBytes)) ==
               ssize_t(slot.size());
    }

    // The datasets and the string type, closed before the file.
    void close_datasets() {
        polar_ = {};
        polar_u16_ = {};
        labels_ = {};
        flow_ = {};
        pose_ = {};
        frame_index_ = {};
        time_ = {};
        text_type_ = {};
    }

    // Closes everything without marking the file complete.
    void abandon() {
        close_datasets();
        file_ = {};
        if (commit_fd_ >= 0) ::close(std::exchange(commit_fd_, -1));
    }

    // resume_from's copy: a new file at path_ with the record's frames of `source`, checked.
    Result<void> copy_frames(const std::string& source, const CommitRecord& record, const Plan& plan,
                             const DatasetMeta& meta, const DatasetOptions& options) {
        if (auto opened = open(plan, meta, options); !opened) return opened.error();
        const Hid old(H5Fopen(source.c_str(), H5F_ACC_RDONLY, H5P_DEFAULT), H5Fclose);
        if (!old.ok()) return make_error(ErrorCode::io, "cannot open " + source + " to resume it");
        const std::vector<RowDataset*> sets = row_sets();
        if (sets.size() != record.hashes.size())
            return make_error(ErrorCode::io, source + ": its commit record covers other arrays");
        for (std::size_t k = 0; k < sets.size(); ++k) {
            if (!copy_rows(old.get(), *sets[k], record.frames))
                return make_error(ErrorCode::io, source + ": cannot read its first " + std::to_string(record.frames) +
                                                     " rows of /" + sets[k]->name);
            if (sets[k]->hash != record.hashes[k])
                return make_error(ErrorCode::io, source + ": its " + std::to_string(record.frames) +
                                                     " whole frames do not match their commit record (/" +
                                                     sets[k]->name + ")");
        }
        frames_ = record.frames;
        if (!set_count("frames_written", frames_) || H5Fflush(file_.get(), H5F_SCOPE_LOCAL) < 0 || !write_commit())
            return fail("cannot flush the resumed frames");
        return {};
    }

    // Copies rows 0..n-1 of dataset d.name in `source` into d (empty, as open() made it), hashing them.
    bool copy_rows(hid_t source, RowDataset& d, hsize_t n) {
        const Hid in(H5Dopen2(source, d.name, H5P_DEFAULT), H5Dclose);
        const Hid in_space(in.ok() ? H5Dget_space(in.get()) : H5I_INVALID_HID, H5Sclose);
        if (!in_space.ok() || H5Sget_simple_extent_ndims(in_space.get()) != int(d.row.size() + 1)) return false;
        std::vector<hsize_t> dims(d.row.size() + 1);
        H5Sget_simple_extent_dims(in_space.get(), dims.data(), nullptr);
        if (dims[0] < n || !std::equal(d.row.begin(), d.row.end(), dims.begin() + 1)) return false;
        dims[0] = n;
        if (H5Dset_extent(d.id.get(), dims.data()) < 0) return false;
        const Hid out_space(H5Dget_space(d.id.get()), H5Sclose);
        if (!out_space.ok()) return false;
        const hsize_t block = std::max<hsize_t>(1, (hsize_t(8) << 20) / std::max<std::size_t>(1, d.row_bytes));
        std::vector<unsigned char> buffer;
        std::vector<hsize_t> start(dims.size(), 0), count(dims);
        for (hsize_t at = 0; at < n; at += block) {
            start[0] = at;
            count[0] = std::min(block, n - at);
            buffer.assign(count[0] * d.row_bytes, 0);
            const Hid memory(H5Screate_simple(int(count.size()), count.data(), nullptr), H5Sclose);
            if (!memory.ok() ||
                H5Sselect_hyperslab(in_space.get(), H5S_SELECT_SET, start.data(), nullptr, count.data(), nullptr) < 0 ||
                H5Sselect_hyperslab(out_space.get(), H5S_SELECT_SET, start.data(), nullptr, count.data(), nullptr) <
                    0 ||
                H5Dread(in.get(), d.memory_type, memory.get(), in_space.get(), H5P_DEFAULT, buffer.data()) < 0)
                return false;
            for (hsize_t r = 0; r < count[0]; ++r)
                hash_row(d, buffer.data() + r * d.row_bytes);
            const bool written =
                H5Dwrite(d.id.get(), d.memory_type, memory.get(), out_space.get(), H5P_DEFAULT, buffer.data()) >= 0;
            if (d.text) {
#if H5_VERSION_GE(1, 12, 0)
                H5Treclaim(d.memory_type, memory.get(), H5P_DEFAULT, buffer.data());
#else
                H5Dvlen_reclaim(d.memory_type, memory.get(), H5P_DEFAULT, buffer.data());
#endif
            }
            if (!written) return false;
        }
        return true;
    }

    Error fail(const std::string& what) const {
        return make_error(ErrorCode::io, "cannot write " + name_ + ": " + what);
    }

    // UTF-8 text of variable length (h5py: .asstr() reads str): /boxes' type in the file and in memory.
    bool make_text_type() {
        text_type_ = Hid(H5Tcopy(H5T_C_S1), H5Tclose);
        return text_type_.ok() && H5Tset_size(text_type_.get(), H5T_VARIABLE) >= 0 &&
               H5Tset_cset(text_type_.get(), H5T_CSET_UTF8) >= 0;
    }

    bool rows(RowDataset& out, const char* name, hid_t file_type, hid_t memory_type, std::vector<hsize_t> row,
              bool compress) {
        std::vector<hsize_t> dims{0}, max{H5S_UNLIMITED}, chunk{1};
        for (hsize_t d : row) {
            dims.push_back(d);
            max.push_back(d);
            chunk.push_back(d);
        }
        if (row.empty()) chunk[0] = 1024; // scalars per frame: one chunk holds many frames
        const Hid space(H5Screate_simple(int(dims.size()), dims.data(), max.data()), H5Sclose);
        const Hid create(dataset_create_list());
        if (!space.ok() || !create.ok() || H5Pset_chunk(create.get(), int(chunk.size()), chunk.data()) < 0)
            return false;
        if (compress && (H5Pset_shuffle(create.get()) < 0 || H5Pset_deflate(create.get(), unsigned(kDeflateLevel)) < 0))
            return false;
        out.id = Hid(H5Dcreate2(file_.get(), name, file_type, space.get(), H5P_DEFAULT, create.get(), H5P_DEFAULT),
                     H5Dclose);
        out.name = name;
        out.memory_type = memory_type;
        out.row_bytes = H5Tget_size(memory_type);
        for (hsize_t d : row)
            out.row_bytes *= d;
        out.text = H5Tis_variable_str(memory_type) > 0;
        out.hash = kHashSeed;
        out.row = std::move(row);
#ifdef VKSONAR_HAVE_ZLIB
        // Deflated here only where memory holds the file's bytes (the same type, byte order included),
        // since a chunk written as it is skips HDF5's conversion.
        out.deflate = compress && !out.text && H5Tequal(file_type, memory_type) > 0 && out.row_bytes > 0;
        if (out.deflate) {
            out.element_bytes = H5Tget_size(file_type);
            out.shuffled.assign(out.row_bytes, 0);
            out.packed.assign(compressBound(static_cast<uLong>(out.row_bytes)), 0);
        }
#endif
        return out.id.ok();
    }

    bool append_row(RowDataset& d, const void* data) {
        std::vector<hsize_t> dims{frames_ + 1}, start{frames_}, count{1};
        for (hsize_t r : d.row) {
            dims.push_back(r);
            start.push_back(0);
            count.push_back(r);
        }
        if (H5Dset_extent(d.id.get(), dims.data()) < 0) return false;
        if (d.packed_bytes > 0) { // deflated already (deflate_rows): the chunk as it is, both filters applied
            const bool written =
                H5Dwrite_chunk(d.id.get(), H5P_DEFAULT, 0, start.data(), d.packed_bytes, d.packed.data()) >= 0;
            d.packed_bytes = 0;
            if (!written) return false;
            hash_row(d, data);
            return true;
        }
        const Hid file_space(H5Dget_space(d.id.get()), H5Sclose);
        const Hid memory_space(H5Screate_simple(int(count.size()), count.data(), nullptr), H5Sclose);
        if (!file_space.ok() || !memory_space.ok() ||
            H5Sselect_hyperslab(file_space.get(), H5S_SELECT_SET, start.data(), nullptr, count.data(), nullptr) < 0 ||
            H5Dwrite(d.id.get(), d.memory_type, memory_space.get(), file_space.get(), H5P_DEFAULT, data) < 0)
            return false;
        hash_row(d, data);
        return true;
    }

    static bool vector(hid_t file, const char* name, const std::vector<double>& values) {
        const hsize_t n = values.size();
        const Hid space(H5Screate_simple(1, &n, nullptr), H5Sclose);
        const Hid create(dataset_create_list());
        const Hid set(H5Dcreate2(file, name, H5T_IEEE_F64LE, space.get(), H5P_DEFAULT, create.get(), H5P_DEFAULT),
                      H5Dclose);
        return set.ok() && H5Dwrite(set.get(), H5T_NATIVE_DOUBLE, H5S_ALL, H5S_ALL, H5P_DEFAULT, values.data()) >= 0;
    }

    // Attributes of the root group: UTF-8 text of variable length (h5py reads str), doubles, counts.
    bool text(const char* name, const std::string& value) {
        const Hid type(H5Tcopy(H5T_C_S1), H5Tclose);
        if (!type.ok() || H5Tset_size(type.get(), H5T_VARIABLE) < 0 || H5Tset_cset(type.get(), H5T_CSET_UTF8) < 0)
            return false;
        const char* data = value.c_str();
        return attribute(name, type.get(), type.get(), &data);
    }
    bool number(const char* name, double value) {
        return attribute(name, H5T_IEEE_F64LE, H5T_NATIVE_DOUBLE, &value);
    }
    bool count(const char* name, std::uint64_t value) {
        return attribute(name, H5T_STD_U64LE, H5T_NATIVE_UINT64, &value);
    }
    bool attribute(const char* name, hid_t file_type, hid_t memory_type, const void* data) {
        const Hid space(H5Screate(H5S_SCALAR), H5Sclose);
        const Hid attr(H5Acreate2(file_.get(), name, file_type, space.get(), H5P_DEFAULT, H5P_DEFAULT), H5Aclose);
        return attr.ok() && H5Awrite(attr.get(), memory_type, data) >= 0;
    }
    bool set_count(const char* name, std::uint64_t value) {
        const Hid attr(H5Aopen(file_.get(), name, H5P_DEFAULT), H5Aclose);
        return attr.ok() && H5Awrite(attr.get(), H5T_NATIVE_UINT64, &value) >= 0;
    }

    std::string path_;
    Hid text_type_; // /boxes' type, in the file and in memory (make_text_type)
    Hid file_;
    RowDataset polar_, polar_u16_, pose_, frame_index_, time_;
    // --compress: threads that deflate a frame's rows side by side (deflate_rows), the writer's thread
    // among them; made once with the file, one per row up to the machine's hardware threads.
    std::unique_ptr<host::Workers> deflaters_;
    LabelRows labels_;
    RowDataset flow_;
    hsize_t frames_ = 0;
    std::string name_;   // the file as messages name it (path_ may be a temporary beside it)
    int commit_fd_ = -1; // the file again, for the commit record in its user block
};

} // namespace

Result<std::unique_ptr<DatasetWriter>> DatasetWriter::resume(const std::string& path, const Plan& plan,
                                                             const DatasetMeta& meta, const DatasetOptions& options) {
    H5Eset_auto2(H5E_DEFAULT, nullptr, nullptr);
    auto writer = std::make_unique<H5Writer>(path);
    if (auto opened = writer->resume_from(plan, meta, options); !opened) return opened.error();
    return std::unique_ptr<DatasetWriter>(std::move(writer));
}

Result<DatasetInfo> read_dataset_info(const std::string& path) {
    H5Eset_auto2(H5E_DEFAULT, nullptr, nullptr); // errors come back as one line, not a stack dump
    const Hid file(H5Fopen(path.c_str(), H5F_ACC_RDONLY, H5P_DEFAULT), H5Fclose);
    if (!file.ok()) return make_error(ErrorCode::io, path + ": cannot open as HDF5 (cut off before its first flush?)");
    const hid_t f = file.get();
    const auto format = h5::read_text(f, "format");
    if (!format || *format != "vksonar-dataset-1")
        return make_error(ErrorCode::io, path + ": not a vksonar dataset (attribute format is not vksonar-dataset-1)");
    DatasetInfo info;
    const auto config = h5::read_text(f, "config"), scene = h5::read_text(f, "scene"),
               backend = h5::read_text(f, "backend"), time_unit = h5::read_text(f, "time_unit");
    const auto seed = h5::read_count(f, "seed"), written = h5::read_count(f, "frames_written"),
               complete = h5::read_count(f, "complete");
    if (!config || !scene || !backend || !time_unit || !seed || !written || !complete)
        return make_error(ErrorCode::io, path + ": a vksonar dataset without its attributes (config, seed, ...)");
    info.backend = *backend;
    info.device = h5::read_text(f, "device").value_or("");
    info.frames_written = *written;
    info.complete = *complete != 0;
    if (const auto index = h5::read_count(f, "shard_index")) {
        ShardRecord r;
        r.index = *index;
        const auto count = h5::read_count(f, "shard_count"), first = h5::read_count(f, "shard_first"),
                   end = h5::read_count(f, "shard_end"), total = h5::read_count(f, "trajectory_frames");
        const auto source = h5::read_text(f, "shard_source"), hash = h5::read_text(f, "trajectory_fnv1a64");
        if (!count || !first || !end || !total || !source || !hash || *count == 0 || r.index >= *count ||
            *end < *first || *end > *total)
            return make_error(ErrorCode::io, path + ": its shard attributes are incomplete or inconsistent");
        r.count = *count;
        r.first = *first;
        r.end = *end;
        r.total = *total;
        r.source = *source;
        r.trajectory = h5::read_text(f, "trajectory").value_or("");
        r.trajectory_hash = *hash;
        r.scene_hash = h5::read_text(f, "scene_fnv1a64").value_or(""); // absent: written before it was recorded
        info.shard = r;
    }
    const bool u16 = H5Lexists(f, "polar_u16", H5P_DEFAULT) > 0;
    const bool labels = H5Lexists(f, "instance", H5P_DEFAULT) > 0;
    const bool flow = H5Lexists(f, "flow", H5P_DEFAULT) > 0;
    info.identity = run_identity(*config, *seed, *scene, *backend, saved_arrays(u16, labels, flow),
                                 time_unit->rfind("s ", 0) == 0, info.shard ? &*info.shard : nullptr);
    return info;
}

Result<std::unique_ptr<DatasetWriter>> DatasetWriter::create(const std::string& path, const Plan& plan,
                                                             const DatasetMeta& meta, const DatasetOptions& options,
                                                             const std::string& write_to) {
    auto writer = std::make_unique<H5Writer>(write_to.empty() ? path : write_to, path);
    if (auto opened = writer->open(plan, meta, options); !opened) return opened.error();
    return std::unique_ptr<DatasetWriter>(std::move(writer));
}

#endif

} // namespace vksonar::cli
