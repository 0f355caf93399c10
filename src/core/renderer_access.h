// Internal access to a Renderer's plan (for the CLI's images and meta.json, and for tests).
#pragma once

namespace vksonar {
struct Plan;
class Renderer;
const Plan& renderer_plan(const Renderer& renderer);
} // namespace vksonar
