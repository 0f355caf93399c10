// Small helpers over the HDF5 C library shared by the dataset writer (dataset_h5.cpp) and `vksonar
// merge` (merge_h5.cpp): an owning identifier and the root attributes the dataset file uses. Only
// included where VKSONAR_HAVE_HDF5 is defined.
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <utility>

#include <hdf5.h>

namespace vksonar::cli::h5 {

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

// A text attribute of `object` (variable or fixed length), or nullopt when absent or not text.
inline std::optional<std::string> read_text(hid_t object, const char* name) {
    if (H5Aexists(object, name) <= 0) return std::nullopt;
    const Hid attr(H5Aopen(object, name, H5P_DEFAULT), H5Aclose);
    const Hid type(attr.ok() ? H5Aget_type(attr.get()) : H5I_INVALID_HID, H5Tclose);
    if (!type.ok() || H5Tget_class(type.get()) != H5T_STRING) return std::nullopt;
    if (H5Tis_variable_str(type.get()) > 0) {
        const Hid memory(H5Tcopy(H5T_C_S1), H5Tclose);
        H5Tset_size(memory.get(), H5T_VARIABLE);
        H5Tset_cset(memory.get(), H5Tget_cset(type.get()));
        char* data = nullptr;
        if (H5Aread(attr.get(), memory.get(), &data) < 0 || !data) return std::nullopt;
        std::string text(data);
        H5free_memory(data);
        return text;
    }
    const std::size_t size = H5Tget_size(type.get());
    std::string text(size, '\0');
    if (H5Aread(attr.get(), type.get(), text.data()) < 0) return std::nullopt;
    text.resize(text.find('\0') == std::string::npos ? size : text.find('\0'));
    return text;
}

// An unsigned integer attribute, or nullopt when absent or not an integer.
inline std::optional<std::uint64_t> read_count(hid_t object, const char* name) {
    if (H5Aexists(object, name) <= 0) return std::nullopt;
    const Hid attr(H5Aopen(object, name, H5P_DEFAULT), H5Aclose);
    const Hid type(attr.ok() ? H5Aget_type(attr.get()) : H5I_INVALID_HID, H5Tclose);
    if (!type.ok() || H5Tget_class(type.get()) != H5T_INTEGER) return std::nullopt;
    std::uint64_t value = 0;
    if (H5Aread(attr.get(), H5T_NATIVE_UINT64, &value) < 0) return std::nullopt;
    return value;
}

// Writes a scalar attribute, creating it when absent.
inline bool write_attribute(hid_t object, const char* name, hid_t file_type, hid_t memory_type, const void* data) {
    Hid attr;
    if (H5Aexists(object, name) > 0) {
        attr = Hid(H5Aopen(object, name, H5P_DEFAULT), H5Aclose);
    } else {
        const Hid space(H5Screate(H5S_SCALAR), H5Sclose);
        attr = Hid(H5Acreate2(object, name, file_type, space.get(), H5P_DEFAULT, H5P_DEFAULT), H5Aclose);
    }
    return attr.ok() && H5Awrite(attr.get(), memory_type, data) >= 0;
}
inline bool write_text(hid_t object, const char* name, const std::string& value) {
    const Hid type(H5Tcopy(H5T_C_S1), H5Tclose);
    if (!type.ok() || H5Tset_size(type.get(), H5T_VARIABLE) < 0 || H5Tset_cset(type.get(), H5T_CSET_UTF8) < 0)
        return false;
    const char* data = value.c_str();
    return write_attribute(object, name, type.get(), type.get(), &data);
}
inline bool write_count(hid_t object, const char* name, std::uint64_t value) {
    return write_attribute(object, name, H5T_STD_U64LE, H5T_NATIVE_UINT64, &value);
}

} // namespace vksonar::cli::h5
