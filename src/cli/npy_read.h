// A small reader for NumPy .npy files (versions 1-3, C order, little-endian float32/float64/uint16/
// uint8/int32), enough to compare vksonar outputs.
#pragma once

#include <cstddef>
#include <string>
#include <vector>

namespace vksonar::cli {

struct NpyArray {
    std::string dtype;              // as in the header, e.g. "<f4"
    std::vector<std::size_t> shape; // C order
    std::vector<double> values;     // converted to double, in file order
};

// Reads `path`. Throws BadInput naming the file and what is wrong.
NpyArray read_npy(const std::string& path);

} // namespace vksonar::cli
