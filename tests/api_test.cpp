// The public API's compile-time contracts (the host-depth renderer and the scene renderer are separate
// types, an adopted context says it is borrowed, SaveFlags is a scoped flag type) and the checks of
// HostVulkan::functions that need no device (those that need one: embed_test.cpp).
#include <type_traits>
#include <utility>
#include <vector>

#include <gtest/gtest.h>

#include "vksonar/vksonar.h"

namespace vksonar::testing {
namespace {

template <class T, class = void> struct HasRender : std::false_type {};
template <class T>
struct HasRender<T, std::void_t<decltype(std::declval<T&>().render(Pose{}, 0, std::declval<Frame&>()))>>
    : std::true_type {};
template <class T, class = void> struct HasProcess : std::false_type {};
template <class T>
struct HasProcess<T, std::void_t<decltype(std::declval<T&>().process(HostDepthImage{}, 0, std::declval<Frame&>()))>>
    : std::true_type {};
template <class T, class = void> struct HasRecord : std::false_type {};
template <class T>
struct HasRecord<T, std::void_t<decltype(std::declval<T&>().record(VkCommandBuffer{}, HostDepthImage{}))>>
    : std::true_type {};
template <class T, class = void> struct HasReadBack : std::false_type {};
template <class T>
struct HasReadBack<T, std::void_t<decltype(std::declval<T&>().read_back(0, std::declval<Frame&>()))>> : std::true_type {
};

// A wrong call is a compile error, not a run-time one.
static_assert(HasRender<Renderer>::value && !HasRender<HostDepthRenderer>::value);
static_assert(HasProcess<HostDepthRenderer>::value && !HasProcess<Renderer>::value);
static_assert(HasRecord<HostDepthRenderer>::value && !HasRecord<Renderer>::value);
static_assert(HasReadBack<HostDepthRenderer>::value && !HasReadBack<Renderer>::value);
static_assert(!std::is_convertible_v<HostDepthRenderer&, Renderer&>);

// Owned vs borrowed in the type: create gives a Context, adopt an AdoptedContext, which the renderers
// take as a Context but which cannot be moved into a plain Context (that would hide the borrowing).
static_assert(std::is_same_v<decltype(Context::create()), Result<Context>>);
static_assert(std::is_same_v<decltype(Context::adopt(HostVulkan{})), Result<AdoptedContext>>);
static_assert(std::is_convertible_v<AdoptedContext&, Context&>);
static_assert(!std::is_constructible_v<Context, AdoptedContext&&>);
static_assert(!std::is_assignable_v<Context&, AdoptedContext&&>);

// SaveFlags: scoped, no implicit conversion from or to an integer.
static_assert(!std::is_convertible_v<SaveFlags, std::uint32_t>);
static_assert(!std::is_convertible_v<std::uint32_t, SaveFlags>);
static_assert(any(SaveFlags::depth | SaveFlags::echo));
static_assert(!any((SaveFlags::depth | SaveFlags::echo) & SaveFlags::normals));

TEST(Api, SaveFlagsCombine) {
    SaveFlags mask = SaveFlags::none;
    mask |= SaveFlags::normals;
    mask |= SaveFlags::profiles;
    EXPECT_TRUE(any(mask & SaveFlags::normals));
    EXPECT_FALSE(any(mask & SaveFlags::depth));
    mask &= ~SaveFlags::normals;
    EXPECT_EQ(mask, SaveFlags::profiles);
}

TEST(Api, AnEmptyRendererRefusesToRenderInsteadOfCrashing) {
    Renderer empty;
    Frame frame = empty.make_frame();
    EXPECT_TRUE(frame.clean.empty());
    auto r = empty.render(Pose{}, 0, frame);
    ASSERT_FALSE(r);
    EXPECT_EQ(r.error().code, ErrorCode::invalid_argument);
    EXPECT_NE(r.error().message.find("Renderer::create"), std::string::npos) << r.error().message;
    // Every other call on it answers as for nothing instead of dereferencing the missing renderer (an
    // audit's: seed(), set_seed(), config() and validity() segfaulted).
    empty.set_seed(5);
    EXPECT_EQ(empty.seed(), 0u);
    EXPECT_EQ(empty.config().beams, SonarConfig{}.beams);
    EXPECT_TRUE(empty.validity().empty());
    std::vector<float> flow;
    EXPECT_FALSE(empty.label_flow(frame, Pose{}, frame, Pose{}, flow));
}

TEST(Api, AnEmptyHostDepthRendererRefusesInsteadOfCrashing) {
    HostDepthRenderer empty;
    Frame frame = empty.make_frame();
    EXPECT_TRUE(frame.clean.empty());
    for (const auto& r : {empty.process(HostDepthImage{}, 0, frame), empty.record(VK_NULL_HANDLE, HostDepthImage{}),
                          empty.read_back(0, frame)}) {
        ASSERT_FALSE(r);
        EXPECT_EQ(r.error().code, ErrorCode::invalid_argument);
        EXPECT_NE(r.error().message.find("HostDepthRenderer::create"), std::string::npos) << r.error().message;
    }
    empty.set_seed(5);
    EXPECT_EQ(empty.seed(), 0u);
    EXPECT_EQ(empty.polar_buffer().buffer, VK_NULL_HANDLE);
    EXPECT_EQ(empty.config().bins, SonarConfig{}.bins);
    EXPECT_TRUE(empty.validity().empty());
}

TEST(Api, ValidateReturnsResult) {
    EXPECT_TRUE(SonarConfig{}.validate().ok());
    SonarConfig config;
    config.range_max_m = config.range_min_m;
    const Result<void> refused = config.validate();
    ASSERT_FALSE(refused.ok());
    EXPECT_EQ(refused.error().code, ErrorCode::invalid_argument);
    EXPECT_NE(refused.error().message.find("range_max"), std::string::npos) << refused.error().message;

    AcousticMaterial material;
    material.model = AcousticMaterial::Model::rough;
    material.rms_slope = 0.0;
    const Result<void> bad = material.validate();
    ASSERT_FALSE(bad.ok());
    EXPECT_EQ(bad.error().code, ErrorCode::invalid_argument);
    EXPECT_NE(bad.error().message.find("rms_slope"), std::string::npos) << bad.error().message;

    // A model cast from a number no model has: the plan took it as Lambert, the shaders as constant.
    material.model = static_cast<AcousticMaterial::Model>(7);
    const Result<void> unknown = material.validate();
    ASSERT_FALSE(unknown.ok());
    EXPECT_NE(unknown.error().message.find("model = 7"), std::string::npos) << unknown.error().message;
}

// RendererOptions set in C++ to a number no value has: refused naming the field (a Backend of 7 ran the
// CPU backend in silence); so are save_mask bits past labels, and a device_index below -1 (it was taken
// as -1, the first device).
TEST(Api, OptionsNoValueHasAreRefused) {
    Context context = Context::cpu_only();
    const SonarConfig config;
    Scene scene;
    RendererOptions options;
    options.backend = Backend::cpu;
    ASSERT_TRUE(Renderer::create(context, config, scene, options).ok());
    // each field set to one number past its last value
    const std::vector<std::pair<std::string, void (*)(RendererOptions&)>> cases = {
        {"backend", [](RendererOptions& o) { o.backend = static_cast<Backend>(7); }},
        {"tables", [](RendererOptions& o) { o.tables = static_cast<TableAccess>(2); }},
        {"resample", [](RendererOptions& o) { o.resample = static_cast<ResampleMethod>(5); }},
        {"layout", [](RendererOptions& o) { o.layout = static_cast<WorkLayout>(3); }},
        {"stage_timing", [](RendererOptions& o) { o.stage_timing = static_cast<StageTiming>(4); }},
        {"profile_rows", [](RendererOptions& o) { o.profile_rows = static_cast<ProfileRows>(2); }},
        {"save_mask", [](RendererOptions& o) { o.save_mask = static_cast<SaveFlags>(1u << 5); }},
    };
    for (const auto& [field, set] : cases) {
        RendererOptions bad = options;
        set(bad);
        auto renderer = Renderer::create(context, config, scene, bad);
        ASSERT_FALSE(renderer.ok()) << field;
        EXPECT_EQ(renderer.error().code, ErrorCode::invalid_argument);
        EXPECT_NE(renderer.error().message.find("RendererOptions: " + field + " = "), std::string::npos)
            << renderer.error().message;
    }

    ContextOptions below;
    below.device_index = -7;
    auto no_context = Context::create(below);
    ASSERT_FALSE(no_context.ok());
    EXPECT_EQ(no_context.error().code, ErrorCode::invalid_argument);
    EXPECT_NE(no_context.error().message.find("device_index = -7"), std::string::npos) << no_context.error().message;
}

// Handles that are never dereferenced: adopt checks HostVulkan::functions, and resolves every function
// through them, before any other Vulkan call.
HostVulkan fake_host() {
    HostVulkan host;
    host.instance = reinterpret_cast<VkInstance>(std::uintptr_t{0x1000});
    host.physical_device = reinterpret_cast<VkPhysicalDevice>(std::uintptr_t{0x2000});
    host.device = reinterpret_cast<VkDevice>(std::uintptr_t{0x3000});
    host.queue = reinterpret_cast<VkQueue>(std::uintptr_t{0x4000});
    return host;
}

TEST(Api, AdoptRefusesAFunctionTableWithANullEntry) {
    VulkanFunctions functions;
    functions.vkGetInstanceProcAddr = vkGetInstanceProcAddr;
    HostVulkan host = fake_host();
    host.functions = &functions;
    auto adopted = Context::adopt(host);
    ASSERT_FALSE(adopted.ok());
    EXPECT_EQ(adopted.error().code, ErrorCode::invalid_argument);
    EXPECT_NE(adopted.error().message.find("functions->vkGetDeviceProcAddr is null"), std::string::npos)
        << adopted.error().message;

    functions = VulkanFunctions{};
    functions.vkGetDeviceProcAddr = vkGetDeviceProcAddr;
    adopted = Context::adopt(host);
    ASSERT_FALSE(adopted.ok());
    EXPECT_NE(adopted.error().message.find("functions->vkGetInstanceProcAddr is null"), std::string::npos)
        << adopted.error().message;
}

// A host getter that resolves nothing: adopt names the first function it needs and calls nothing on
// the (fake) handles, since every function is resolved before the first call.
PFN_vkVoidFunction VKAPI_CALL resolves_nothing(VkInstance, const char*) {
    return nullptr;
}

TEST(Api, AdoptNamesTheFirstFunctionTheHostDoesNotResolve) {
    VulkanFunctions functions;
    functions.vkGetInstanceProcAddr = resolves_nothing;
    functions.vkGetDeviceProcAddr = vkGetDeviceProcAddr;
    HostVulkan host = fake_host();
    host.functions = &functions;
    auto adopted = Context::adopt(host);
    ASSERT_FALSE(adopted.ok());
    EXPECT_EQ(adopted.error().code, ErrorCode::unsupported);
    EXPECT_NE(adopted.error().message.find(
                  "HostVulkan.functions->vkGetInstanceProcAddr returns null for vkGetPhysicalDeviceFormatProperties"),
              std::string::npos)
        << adopted.error().message;
    EXPECT_EQ(adopted.error().message.find('\n'), std::string::npos) << "one line: " << adopted.error().message;
}

TEST(Api, HostDepthRendererNeedsAVulkanContext) {
    Context cpu = Context::cpu_only();
    auto refused = HostDepthRenderer::create(cpu, SonarConfig{}, HostDepthDesc{});
    ASSERT_FALSE(refused.ok());
    EXPECT_EQ(refused.error().code, ErrorCode::invalid_argument);
}

} // namespace
} // namespace vksonar::testing
