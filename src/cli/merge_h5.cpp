// `vksonar merge` for HDF5 shard files (merge.h): the merged file is shard 0's file (its layout,
// chunking, filters and attributes) with the other shards' frames appended in order, the shard
// attributes removed, frames_written the whole trajectory and complete = 1.
#include <unistd.h>

#include <algorithm>
#include <cctype>
#include <filesystem>
#include <set>
#include <vector>

#include "cli/args.h"
#include "cli/dataset_h5.h"
#include "cli/merge.h"

#ifdef VKSONAR_HAVE_HDF5
#include "cli/h5_util.h"
#endif

namespace fs = std::filesystem;

namespace vksonar::cli {

namespace {
bool h5_extension(const std::string& path) {
    std::string ext = fs::path(path).extension().string();
    std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return char(std::tolower(c)); });
    return ext == ".h5" || ext == ".hdf5";
}
} // namespace

bool h5_merge_accepts(const std::string& path) {
    std::error_code ec;
    return h5_extension(path) && fs::is_regular_file(path, ec);
}

bool h5_merge_output_ok(const std::string& out) {
    return h5_extension(out);
}

ShardInput h5_merge_read(const std::string& path) {
    auto info = read_dataset_info(path);
    if (!info) throw BadInput("merge: " + info.error().message);
    if (!info->shard)
        throw BadInput("merge: " + path + ": not a shard (no shard_index attribute): render it with --shard");
    ShardInput in;
    in.path = path;
    in.shard = *info->shard;
    in.identity = info->identity;
    in.backend = info->backend;
    in.device = info->device;
    in.frames = info->frames_written;
    if (in.frames < in.shard.end - in.shard.first)
        in.first_missing = "frame ordinal " + std::to_string(in.shard.first + in.frames);
    return in;
}

#ifndef VKSONAR_HAVE_HDF5

void h5_merge(const std::vector<ShardInput>&, const std::string& out) {
    throw BadInput("merge: " + out + ": this build has no HDF5 (install libhdf5-dev and rebuild)");
}

#else

namespace {

using h5::Hid;

// The per-frame arrays, in the order the writer creates them. polar_u16, the labels (instance ...
// boxes) and flow are there only when the run asked for them; the shards' identities agree on which.
constexpr const char* kRowSets[] = {
    "polar", "pose",      "frame_index",      "time",  "polar_u16", "instance", "instance_fraction",
    "class", "elevation", "elevation_spread", "point", "boxes",     "flow"};

struct Rows {
    Hid set;
    Hid native; // memory type
    std::vector<hsize_t> dims;
    std::size_t row_bytes = 0;
    // Text of variable length (/boxes): a row read is a pointer to text HDF5 allocated, written back
    // as it is and then freed (free_row).
    bool variable = false;
};

bool open_rows(hid_t file, const char* name, Rows& r) {
    r.set = Hid(H5Dopen2(file, name, H5P_DEFAULT), H5Dclose);
    if (!r.set.ok()) return false;
    const Hid type(H5Dget_type(r.set.get()), H5Tclose);
    r.native = Hid(H5Tget_native_type(type.get(), H5T_DIR_ASCEND), H5Tclose);
    const Hid space(H5Dget_space(r.set.get()), H5Sclose);
    const int rank = space.ok() ? H5Sget_simple_extent_ndims(space.get()) : -1;
    if (!r.native.ok() || rank < 1) return false;
    r.dims.resize(static_cast<std::size_t>(rank));
    H5Sget_simple_extent_dims(space.get(), r.dims.data(), nullptr);
    r.row_bytes = H5Tget_size(r.native.get());
    r.variable = H5Tis_variable_str(r.native.get()) > 0;
    for (std::size_t d = 1; d < r.dims.size(); ++d)
        r.row_bytes *= r.dims[d];
    return true;
}

// Reads (write = false) or writes one row of `r` at `row`.
bool row_io(const Rows& r, hsize_t row, void* data, bool write) {
    std::vector<hsize_t> start(r.dims.size(), 0), count(r.dims);
    start[0] = row;
    count[0] = 1;
    const Hid file_space(H5Dget_space(r.set.get()), H5Sclose);
    const Hid memory_space(H5Screate_simple(int(count.size()), count.data(), nullptr), H5Sclose);
    if (!file_space.ok() || !memory_space.ok() ||
        H5Sselect_hyperslab(file_space.get(), H5S_SELECT_SET, start.data(), nullptr, count.data(), nullptr) < 0)
        return false;
    return write ? H5Dwrite(r.set.get(), r.native.get(), memory_space.get(), file_space.get(), H5P_DEFAULT, data) >= 0
                 : H5Dread(r.set.get(), r.native.get(), memory_space.get(), file_space.get(), H5P_DEFAULT, data) >= 0;
}

// Frees what reading one row of variable-length text allocated (a no-op for fixed-size rows).
void free_row(const Rows& r, void* data) {
    if (!r.variable) return;
    const hsize_t one = 1;
    const Hid space(H5Screate_simple(1, &one, nullptr), H5Sclose);
#if H5_VERSION_GE(1, 12, 0)
    H5Treclaim(r.native.get(), space.get(), H5P_DEFAULT, data);
#else
    H5Dvlen_reclaim(r.native.get(), space.get(), H5P_DEFAULT, data);
#endif
}

void merge_into(const std::vector<ShardInput>& shards, const std::string& temporary, const std::string& out) {
    const Hid file(H5Fopen(temporary.c_str(), H5F_ACC_RDWR, H5P_DEFAULT), H5Fclose);
    if (!file.ok()) throw Failure("merge: cannot open " + temporary);
    auto fail = [&](const std::string& what) { return Failure("merge: cannot write " + out + ": " + what); };
    std::uint64_t frames = shards[0].frames;
    std::uint64_t last_index = 0;
    bool any_index = false;
    std::vector<std::uint64_t> indices;
    std::vector<unsigned char> buffer;
    for (const char* name : kRowSets) {
        if (H5Lexists(file.get(), name, H5P_DEFAULT) <= 0) continue; // an array this run did not ask for
        Rows out_rows;
        if (!open_rows(file.get(), name, out_rows)) throw fail(std::string("cannot open /") + name);
        // Shard 0's file may hold rows after frames_written (a frame cut off before a resume): drop them.
        hsize_t at = shards[0].frames;
        out_rows.dims[0] = at;
        if (H5Dset_extent(out_rows.set.get(), out_rows.dims.data()) < 0)
            throw fail("cannot resize /" + std::string(name));
        for (std::size_t k = 1; k < shards.size(); ++k) {
            const Hid in(H5Fopen(shards[k].path.c_str(), H5F_ACC_RDONLY, H5P_DEFAULT), H5Fclose);
            Rows in_rows;
            if (!in.ok() || !open_rows(in.get(), name, in_rows))
                throw BadInput("merge: " + shards[k].path + ": cannot read /" + name);
            if (in_rows.row_bytes != out_rows.row_bytes || in_rows.dims.size() != out_rows.dims.size() ||
                !std::equal(in_rows.dims.begin() + 1, in_rows.dims.end(), out_rows.dims.begin() + 1))
                throw BadInput("merge: " + shards[k].path + ": /" + name + " has another shape than in " +
                               shards[0].path);
            if (in_rows.variable != out_rows.variable)
                throw BadInput("merge: " + shards[k].path + ": /" + name + " has another type than in " +
                               shards[0].path);
            buffer.assign(in_rows.row_bytes, 0);
            for (hsize_t row = 0; row < shards[k].frames; ++row) {
                out_rows.dims[0] = at + 1;
                if (!row_io(in_rows, row, buffer.data(), false))
                    throw BadInput("merge: " + shards[k].path + ": cannot read /" + name + " row " +
                                   std::to_string(row));
                const bool written = H5Dset_extent(out_rows.set.get(), out_rows.dims.data()) >= 0 &&
                                     row_io(out_rows, at, buffer.data(), true);
                free_row(in_rows, buffer.data());
                if (!written) throw fail("cannot append to /" + std::string(name));
                ++at;
            }
        }
        if (std::string(name) == "frame_index") {
            // The frames must come out in trajectory order: frame indices strictly increasing.
            indices.resize(at);
            for (hsize_t row = 0; row < at; ++row)
                if (!row_io(out_rows, row, &indices[row], false)) throw fail("cannot read /frame_index back");
            for (std::uint64_t index : indices) {
                if (any_index && index <= last_index)
                    throw BadInput("merge: frame index " + std::to_string(index) + " follows " +
                                   std::to_string(last_index) + ": the shards overlap or are out of order");
                last_index = index;
                any_index = true;
            }
        }
        frames = at;
    }
    for (const char* name : {"shard_index", "shard_count", "shard_source", "shard_first", "shard_end"})
        if (H5Aexists(file.get(), name) > 0 && H5Adelete(file.get(), name) < 0) throw fail("cannot remove attribute");
    std::set<std::string> devices;
    for (const auto& s : shards)
        devices.insert(s.device);
    std::string device;
    for (const auto& d : devices)
        device += (device.empty() ? "" : "; ") + d;
    if (!h5::write_count(file.get(), "frames_written", frames) || !h5::write_count(file.get(), "complete", 1) ||
        !h5::write_count(file.get(), "merged_shards", shards.size()) || !h5::write_text(file.get(), "device", device))
        throw fail("cannot write the attributes");
}

} // namespace

void h5_merge(const std::vector<ShardInput>& shards, const std::string& out) {
    const fs::path target(out);
    const fs::path temporary = (target.has_parent_path() ? target.parent_path() : fs::path(".")) /
                               (".~" + target.filename().string() + ".merging-" + std::to_string(::getpid()));
    std::error_code ec;
    fs::copy_file(shards[0].path, temporary, fs::copy_options::overwrite_existing, ec);
    if (ec) {
        const std::string why = ec.message();
        fs::remove(temporary, ec); // a copy cut off by a full disk is not left behind
        throw Failure("merge: cannot write " + temporary.string() + ": " + why);
    }
    try {
        merge_into(shards, temporary.string(), out);
    } catch (...) {
        fs::remove(temporary, ec);
        throw;
    }
    fs::rename(temporary, target, ec);
    if (ec) {
        const std::string why = ec.message();
        fs::remove(temporary, ec);
        throw Failure("merge: cannot write " + out + ": " + why);
    }
}

#endif

} // namespace vksonar::cli
