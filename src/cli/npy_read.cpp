// .npy reader (see npy_read.h). Format: magic "\x93NUMPY", version, header length, a Python dict
// literal {'descr': '<f4', 'fortran_order': False, 'shape': (bins, beams), }, then the raw data.
#include "cli/npy_read.h"

#include <cstdint>
#include <cstring>
#include <fstream>
#include <iterator>
#include <limits>
#include <string>

#include "cli/args.h"

namespace vksonar::cli {
namespace {

// The text after 'key': in the header dict, up to the next ',' or '}' (or the closing ')' of a tuple).
std::string dict_value(const std::string& header, const std::string& key, const std::string& path) {
    const auto at = header.find("'" + key + "'");
    if (at == std::string::npos) throw BadInput(path + ": .npy header has no '" + key + "'");
    auto start = header.find(':', at);
    if (start == std::string::npos) throw BadInput(path + ": malformed .npy header");
    ++start;
    while (start < header.size() && header[start] == ' ')
        ++start;
    std::size_t end;
    if (start < header.size() && header[start] == '(')
        end = header.find(')', start) + 1;
    else
        end = header.find_first_of(",}", start);
    if (end == std::string::npos || end == 0) throw BadInput(path + ": malformed .npy header");
    return header.substr(start, end - start);
}

template <class T> void convert(const std::vector<char>& raw, std::vector<double>& out) {
    const std::size_t n = raw.size() / sizeof(T);
    out.resize(n);
    for (std::size_t i = 0; i < n; ++i) {
        T value;
        std::memcpy(&value, raw.data() + i * sizeof(T), sizeof(T));
        out[i] = static_cast<double>(value);
    }
}

} // namespace

NpyArray read_npy(const std::string& path) {
    static_assert(sizeof(float) == 4 && sizeof(double) == 8, "IEEE floats expected");
    require_input_file("", path);
    std::ifstream file(path, std::ios::binary);
    if (!file) throw BadInput(path + ": cannot open");
    std::vector<char> bytes((std::istreambuf_iterator<char>(file)), std::istreambuf_iterator<char>());
    if (bytes.size() < 10 || std::memcmp(bytes.data(), "\x93NUMPY", 6) != 0)
        throw BadInput(path + ": not a .npy file (bad magic)");
    const auto major = static_cast<unsigned char>(bytes[6]);
    std::size_t header_length = 0, offset = 0;
    auto byte = [&](std::size_t i) { return static_cast<std::size_t>(static_cast<unsigned char>(bytes[i])); };
    if (major == 1) {
        header_length = byte(8) | (byte(9) << 8);
        offset = 10;
    } else if (major == 2 || major == 3) {
        if (bytes.size() < 12) throw BadInput(path + ": truncated .npy header");
        header_length = byte(8) | (byte(9) << 8) | (byte(10) << 16) | (byte(11) << 24);
        offset = 12;
    } else {
        throw BadInput(path + ": unsupported .npy version " + std::to_string(major));
    }
    if (bytes.size() < offset + header_length) throw BadInput(path + ": truncated .npy header");
    const std::string header(bytes.data() + offset, header_length);
    // The header is one Python dict literal, padded with spaces and ended by a newline: '{' first, its '}'
    // last before the padding (a header cut short, or one with anything after its dict, is no .npy's).
    const std::size_t dict_end = header.find_last_not_of(" \n");
    if (header.empty() || header.front() != '{' || dict_end == std::string::npos || header[dict_end] != '}')
        throw BadInput(path + ": malformed .npy header (not one {...} dict)");

    NpyArray array;
    std::string descr = dict_value(header, "descr", path);
    if (descr.size() < 2 || (descr.front() != '\'' && descr.front() != '"'))
        throw BadInput(path + ": malformed dtype " + descr);
    array.dtype = descr.substr(1, descr.size() - 2);
    if (dict_value(header, "fortran_order", path) != "False")
        throw BadInput(path + ": Fortran-order .npy files are not supported");
    const std::string shape = dict_value(header, "shape", path);
    if (shape.size() < 2 || shape.front() != '(' || shape.back() != ')')
        throw BadInput(path + ": .npy header 'shape' is not a tuple: '" + shape + "'");
    // The element count, checked: a crafted header's dimensions may multiply past 2^64.
    constexpr std::uint64_t max_count = std::numeric_limits<std::uint64_t>::max();
    std::uint64_t count = 1;
    for (const auto& item : split(shape.substr(1, shape.size() - 2), ',')) {
        if (item.empty()) continue; // "(5,)"
        const auto dim = parse_u64(item, path + ": shape");
        if (dim != 0 && count > max_count / dim)
            throw BadInput(path + ": .npy shape " + shape + " has more than 2^64 elements");
        array.shape.push_back(static_cast<std::size_t>(dim));
        count *= dim;
    }

    std::size_t element = 0;
    if (array.dtype == "<f4")
        element = 4;
    else if (array.dtype == "<f8")
        element = 8;
    else if (array.dtype == "<u2")
        element = 2;
    else if (array.dtype == "|u1" || array.dtype == "<u1")
        element = 1;
    else if (array.dtype == "<i4")
        element = 4;
    else
        throw BadInput(path + ": unsupported dtype '" + array.dtype + "' (float32, float64, uint16, uint8, int32)");

    if (count > max_count / element) throw BadInput(path + ": .npy shape " + shape + " has more than 2^64 data bytes");
    const std::size_t data_offset = offset + header_length;
    // (equal to the file's byte count, the element count fits std::size_t)
    if (std::uint64_t(bytes.size() - data_offset) != count * element)
        throw BadInput(path + ": expected " + std::to_string(count * element) + " data bytes for shape " + shape +
                       ", found " + std::to_string(bytes.size() - data_offset));
    const std::vector<char> raw(bytes.begin() + static_cast<std::ptrdiff_t>(data_offset), bytes.end());
    if (array.dtype == "<f4")
        convert<float>(raw, array.values);
    else if (array.dtype == "<f8")
        convert<double>(raw, array.values);
    else if (array.dtype == "<u2")
        convert<std::uint16_t>(raw, array.values);
    else if (array.dtype == "<i4")
        convert<std::int32_t>(raw, array.values);
    else
        convert<std::uint8_t>(raw, array.values);
    return array;
}

} // namespace vksonar::cli
