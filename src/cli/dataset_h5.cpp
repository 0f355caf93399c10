// DatasetWriter (dataset_h5.h) on the HDF5 C library (Debian's libhdf5-dev, serial). Without it the
// build still works and `--out run.h5` says how to get it.
#include "cli/dataset_h5.h"

#include <cstring>
#include <utility>
#include <vector>

#ifdef VKSONAR_HAVE_HDF5
#include <hdf5.h>
#endif

namespace vksonar::cli {

#ifndef VKSONAR_HAVE_HDF5

bool hdf5_available() {
    return false;
}

Result<std::unique_ptr<DatasetWriter>> DatasetWriter::create(const std::string& path, const Plan&, const DatasetMeta&,
                                                             const DatasetOptions&) {
    return make_error(ErrorCode::unsupported,
                      "--out " + path + ": this build has no HDF5 (install libhdf5-dev and rebuild)");
}

#else

bool hdf5_available() {
    return true;
}

namespace {

// An HDF5 identifier and the function that closes it: owned, closed once, movable.
class Hid {
public:
    Hid() = default;
    Hid(hid_t id, herr_t (*close)(hid_t)) : id_(id), close_(close) {}
    ~Hid() { reset(); }
    Hid(Hid&& o) noexcept : id_(std::exchange(o.id_, H5I_INVALID_HID)), close_(o.close_) {}
    Hid& operator=(Hid&& o) noexcept {
        if (this != &o) {
            reset();
            id_ = std::exchange(o.id_, H5I_INVALID_HID);
            close_ = o.close_;
        }
        return *this;
    }
    Hid(const Hid&) = delete;
    Hid& operator=(const Hid&) = delete;
    hid_t get() const { return id_; }
    hid_t release() { return std::exchange(id_, H5I_INVALID_HID); }
    bool ok() const { return id_ >= 0; }
    void reset() {
        if (id_ >= 0 && close_) close_(id_);
        id_ = H5I_INVALID_HID;
    }

private:
    hid_t id_ = H5I_INVALID_HID;
    herr_t (*close_)(hid_t) = nullptr;
};

// A dataset of rows that grows by one row per frame: [frames, row_dims...], one row per chunk.
struct RowDataset {
    Hid id;
    hid_t memory_type = H5I_INVALID_HID;
    std::vector<hsize_t> row; // the dimensions after the frame axis
};

class H5Writer final : public DatasetWriter {
public:
    explicit H5Writer(std::string path) : path_(std::move(path)) {}

    Result<void> open(const Plan& plan, const DatasetMeta& meta, const DatasetOptions& options) {
        H5Eset_auto2(H5E_DEFAULT, nullptr, nullptr); // errors come back as one line, not a stack dump
        file_ = Hid(H5Fcreate(path_.c_str(), H5F_ACC_TRUNC, H5P_DEFAULT, H5P_DEFAULT), H5Fclose);
        if (!file_.ok()) return fail("cannot create the file");
        const hsize_t bins = plan.bins, beams = plan.beams;
        bool ok = rows(polar_, "polar", H5T_IEEE_F32LE, H5T_NATIVE_FLOAT, {bins, beams}, options.compress) &&
                  rows(pose_, "pose", H5T_IEEE_F64LE, H5T_NATIVE_DOUBLE, {6}, false) &&
                  rows(frame_index_, "frame_index", H5T_STD_U64LE, H5T_NATIVE_UINT64, {}, false) &&
                  rows(time_, "time", H5T_IEEE_F64LE, H5T_NATIVE_DOUBLE, {}, false);
        if (ok && options.polar_u16)
            ok = rows(polar_u16_, "polar_u16", H5T_STD_U16LE, H5T_NATIVE_UINT16, {bins, beams}, options.compress);
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
             text("validity", meta.validity_json) && text("scene", meta.scene) && text("backend", meta.backend) &&
             text("device", meta.device) && count("frames_written", 0) && count("complete", 0);
        if (!ok) return fail("cannot write the dataset's layout");
        if (H5Fflush(file_.get(), H5F_SCOPE_LOCAL) < 0) return fail("cannot flush");
        return {};
    }

    Result<void> append(const Frame& frame, const Pose& pose, double time_s,
                        const std::uint16_t* display_u16) override {
        const double pose_row[6] = {pose.x_m, pose.y_m, pose.z_m, pose.roll_deg, pose.pitch_deg, pose.yaw_deg};
        const std::uint64_t index = frame.frame_index;
        bool ok = append_row(polar_, frame.intensity.data()) && append_row(pose_, pose_row) &&
                  append_row(frame_index_, &index) && append_row(time_, &time_s);
        if (ok && polar_u16_.id.ok()) ok = append_row(polar_u16_, display_u16);
        if (!ok) return fail("cannot write frame " + std::to_string(frames_));
        ++frames_;
        // The frame counts only once all its rows are written; flushed so a killed run leaves it readable.
        if (!set_count("frames_written", frames_) || H5Fflush(file_.get(), H5F_SCOPE_LOCAL) < 0)
            return fail("cannot flush frame " + std::to_string(frames_ - 1));
        return {};
    }

    Result<void> close() override {
        if (!set_count("complete", 1)) return fail("cannot mark the file complete");
        polar_ = {};
        polar_u16_ = {};
        pose_ = {};
        frame_index_ = {};
        time_ = {};
        if (H5Fclose(file_.release()) < 0) return fail("cannot close the file");
        return {};
    }

private:
    Error fail(const std::string& what) const {
        return make_error(ErrorCode::io, "cannot write " + path_ + ": " + what);
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
        const Hid create(H5Pcreate(H5P_DATASET_CREATE), H5Pclose);
        if (!space.ok() || !create.ok() || H5Pset_chunk(create.get(), int(chunk.size()), chunk.data()) < 0)
            return false;
        if (compress && (H5Pset_shuffle(create.get()) < 0 || H5Pset_deflate(create.get(), 4) < 0)) return false;
        out.id = Hid(H5Dcreate2(file_.get(), name, file_type, space.get(), H5P_DEFAULT, create.get(), H5P_DEFAULT),
                     H5Dclose);
        out.memory_type = memory_type;
        out.row = std::move(row);
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
        const Hid file_space(H5Dget_space(d.id.get()), H5Sclose);
        const Hid memory_space(H5Screate_simple(int(count.size()), count.data(), nullptr), H5Sclose);
        return file_space.ok() && memory_space.ok() &&
               H5Sselect_hyperslab(file_space.get(), H5S_SELECT_SET, start.data(), nullptr, count.data(), nullptr) >=
                   0 &&
               H5Dwrite(d.id.get(), d.memory_type, memory_space.get(), file_space.get(), H5P_DEFAULT, data) >= 0;
    }

    static bool vector(hid_t file, const char* name, const std::vector<double>& values) {
        const hsize_t n = values.size();
        const Hid space(H5Screate_simple(1, &n, nullptr), H5Sclose);
        const Hid set(H5Dcreate2(file, name, H5T_IEEE_F64LE, space.get(), H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT),
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
    bool number(const char* name, double value) { return attribute(name, H5T_IEEE_F64LE, H5T_NATIVE_DOUBLE, &value); }
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
    Hid file_;
    RowDataset polar_, polar_u16_, pose_, frame_index_, time_;
    hsize_t frames_ = 0;
};

} // namespace

Result<std::unique_ptr<DatasetWriter>> DatasetWriter::create(const std::string& path, const Plan& plan,
                                                             const DatasetMeta& meta, const DatasetOptions& options) {
    auto writer = std::make_unique<H5Writer>(path);
    if (auto opened = writer->open(plan, meta, options); !opened) return opened.error();
    return std::unique_ptr<DatasetWriter>(std::move(writer));
}

#endif

} // namespace vksonar::cli
