// Internal access to a renderer's host-stage threads (apart from renderer_access.h, whose includers may
// have a `host` namespace of their own).
#pragma once

#include "host/workers.h"
#include "vksonar/renderer.h"

namespace vksonar {
// The host-stage threads of a renderer that Renderer::create made (not a moved-from one), for work between
// its renders (the fan's lookup as a run starts). Not while a render() runs.
host::Workers* renderer_workers(const Renderer& renderer);
} // namespace vksonar
