// Internal access to a renderer's plan (for the CLI's images and meta.json, and for tests).
#pragma once

#include "core/access.h"

namespace vksonar {
const Plan& renderer_plan(const Renderer& renderer);
const Plan& renderer_plan(const HostDepthRenderer& renderer);
} // namespace vksonar
