// What `--backend auto` (the CLI's default) and `Renderer(backend="auto")` (Python's) run on, one rule
// for both (backend_choice.cpp).
#pragma once

#include <string>

#include "vksonar/context.h"
#include "vksonar/renderer.h"
#include "vksonar/result.h"

namespace vksonar::host {

// `vulkan` is the Vulkan context the caller's environment asks for (or why there is none). A GPU
// keeps it. No usable Vulkan device, or a device that is a CPU implementation (lavapipe), gives the
// CPU backend: on such a machine it runs the same math as fast or faster (docs/benchmarks.md, "How
// cost grows"). `backend` and `why` say which and why (meta.json's backend and backend_reason).
// device_named: the user named a device (VKSONAR_DEVICE): then no usable context is their mistake to
// hear of (a value that is not an index, an index no device has), returned as the error, not a quiet
// fall-back to the CPU backend on a machine whose GPU they meant.
Result<Context> choose_backend(Result<Context> vulkan, bool device_named, Backend& backend, std::string& why);

} // namespace vksonar::host
