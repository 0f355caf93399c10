#include "cli/inputs.h"

#include <cstdlib>
#include <system_error>
#include <vector>

#include "cli/args.h"
#include "config/layers.h"
#include "host/backend_choice.h"
#include "vk/vulkan_context.h"

namespace fs = std::filesystem;

namespace vksonar::cli {
namespace {

fs::path executable_dir() {
    std::error_code ec;
    const fs::path exe = fs::read_symlink("/proc/self/exe", ec);
    return ec ? fs::path() : exe.parent_path();
}

bool looks_like_file(const std::string& text) {
    return text.find('/') != std::string::npos || (text.size() > 5 && text.compare(text.size() - 5, 5, ".json") == 0);
}

} // namespace

fs::path find_default_scene() {
    std::vector<fs::path> candidates;
#ifdef VKSONAR_ASSET_DIR
    candidates.emplace_back(fs::path(VKSONAR_ASSET_DIR) / "scenes" / "default.gltf");
#endif
    const fs::path exe_dir = executable_dir();
    if (!exe_dir.empty()) {
        candidates.push_back(exe_dir / ".." / "share" / "vksonar" / "assets" / "scenes" / "default.gltf");
        candidates.push_back(exe_dir / ".." / "assets" / "scenes" / "default.gltf");
    }
    std::string looked;
    for (const auto& candidate : candidates) {
        std::error_code ec;
        if (fs::is_regular_file(candidate, ec)) return candidate.lexically_normal();
        looked += (looked.empty() ? "" : ", ") + candidate.lexically_normal().string();
    }
    throw Failure("the bundled default scene is missing (looked in " + looked + "); pass --scene FILE.gltf");
}

SonarConfig sonar_base_config(const std::string& sonar) {
    std::error_code ec;
    if (looks_like_file(sonar) || (!sonar.empty() && fs::is_regular_file(sonar, ec) && !load_preset(sonar).ok())) {
        require_input_file("--sonar", sonar);
        auto config = load_sonar_file(sonar);
        if (!config) throw BadInput(config.error().message);
        return config.value();
    }
    auto preset = load_preset(sonar);
    if (!preset) throw BadInput("--sonar: " + preset.error().message);
    return preset.value();
}

namespace {
std::string config_problem(const SonarConfig& config) {
    const auto valid = config.validate();
    return valid ? std::string() : valid.error().message;
}
} // namespace

ProblemOrigin::ProblemOrigin(const SonarConfig& config, std::string origin)
    : problem_(config_problem(config)), origin_(std::move(origin)) {}

void ProblemOrigin::after(const SonarConfig& config, const std::string& layer) {
    // What is wrong is the message's "KEY = VALUE" (validate()'s messages start with it): a layer that
    // changes only the reason's wording (another key the rule names, e.g. accuracy.max_slice after an
    // hfov the legacy mode refuses) leaves the blame with the layer that gave the value.
    const auto subject = [](const std::string& problem) { return problem.substr(0, problem.find(": ")); };
    std::string problem = config_problem(config);
    if (subject(problem) != subject(problem_)) origin_ = layer;
    problem_ = std::move(problem);
}

void ProblemOrigin::throw_if_invalid() const {
    if (!problem_.empty()) throw BadInput("invalid config: " + origin_ + ": " + problem_);
}

namespace {
// A Vulkan context with what the environment asks for (VKSONAR_VALIDATION, VKSONAR_DEVICE).
Result<Context> create_context_from_env() {
    auto options = context_options_from_env();
    if (!options) return options.error();
    return Context::create(options.value());
}
} // namespace

Context make_context(Backend backend) {
    if (backend == Backend::cpu) return Context::cpu_only();
    auto created = create_context_from_env();
    if (!created) {
        // no_device errors already say to use --backend cpu; other failures get the hint here.
        const Error& e = created.error();
        throw Failure(e.code == ErrorCode::no_device ? e.message : e.message + " (try --backend cpu)");
    }
    return std::move(created.value());
}

Context choose_backend(Backend& backend, std::string& why) {
    const char* device = std::getenv("VKSONAR_DEVICE");
    auto chosen = host::choose_backend(create_context_from_env(), device && *device, backend, why);
    if (!chosen) throw BadInput(chosen.error().message);
    return std::move(chosen.value());
}

} // namespace vksonar::cli
