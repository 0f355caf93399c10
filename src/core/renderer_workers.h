// Internal access to a renderer's host-stage threads (apart from renderer_access.h, whose includers may
// have a `host` namespace of their own).
#pragma once

#include "host/workers.h"
#include "vksonar/renderer.h"

namespace vksonar {
// The renderer's host-stage threads, for work between its renders (the fan's lookup as a run starts); null
// for a moved-from renderer. Not while a render() runs.
host::Workers* renderer_workers(const Renderer& renderer);
} // namespace vksonar
