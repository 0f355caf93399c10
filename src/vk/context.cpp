// vksonar::Context: creates (and owns) a Vulkan instance and device, optionally with the Khronos
// validation layer and a messenger that counts warnings and errors.
#include "vksonar/context.h"

#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>
#include <vector>

#include "vk/vk_error.h"
#include "vk/vulkan_context.h"

namespace vksonar {
namespace {

constexpr const char* kValidationLayer = "VK_LAYER_KHRONOS_validation";

VKAPI_ATTR VkBool32 VKAPI_CALL debug_callback(VkDebugUtilsMessageSeverityFlagBitsEXT severity,
                                              VkDebugUtilsMessageTypeFlagsEXT /*types*/,
                                              const VkDebugUtilsMessengerCallbackDataEXT* data, void* user) {
    if ((severity &
         (VK_DEBUG_UTILS_MESSAGE_SEVERITY_WARNING_BIT_EXT | VK_DEBUG_UTILS_MESSAGE_SEVERITY_ERROR_BIT_EXT)) == 0) {
        return VK_FALSE;
    }
    auto* context = static_cast<VulkanContext*>(user);
    context->validation_messages.fetch_add(1, std::memory_order_relaxed);
    const char* level = (severity & VK_DEBUG_UTILS_MESSAGE_SEVERITY_ERROR_BIT_EXT) ? "error" : "warning";
    std::fprintf(stderr, "vksonar: Vulkan validation %s: %s\n", level,
                 data && data->pMessage ? data->pMessage : "(no message)");
    return VK_FALSE;
}

bool env_flag(const char* name) {
    const char* value = std::getenv(name);
    return value && (std::strcmp(value, "1") == 0 || std::strcmp(value, "true") == 0 || std::strcmp(value, "on") == 0);
}

bool has_layer(const vk::Functions& fn, const char* name) {
    std::uint32_t count = 0;
    if (fn.vkEnumerateInstanceLayerProperties(&count, nullptr) != VK_SUCCESS) {
        return false;
    }
    std::vector<VkLayerProperties> layers(count);
    if (fn.vkEnumerateInstanceLayerProperties(&count, layers.data()) != VK_SUCCESS) {
        return false;
    }
    for (const auto& layer : layers) {
        if (std::strcmp(layer.layerName, name) == 0) {
            return true;
        }
    }
    return false;
}

bool has_instance_extension(const vk::Functions& fn, const char* layer, const char* name) {
    std::uint32_t count = 0;
    if (fn.vkEnumerateInstanceExtensionProperties(layer, &count, nullptr) != VK_SUCCESS) {
        return false;
    }
    std::vector<VkExtensionProperties> extensions(count);
    if (fn.vkEnumerateInstanceExtensionProperties(layer, &count, extensions.data()) != VK_SUCCESS) {
        return false;
    }
    for (const auto& extension : extensions) {
        if (std::strcmp(extension.extensionName, name) == 0) {
            return true;
        }
    }
    return false;
}

bool has_device_extension(const vk::Functions& fn, VkPhysicalDevice device, const char* name) {
    std::uint32_t count = 0;
    if (fn.vkEnumerateDeviceExtensionProperties(device, nullptr, &count, nullptr) != VK_SUCCESS) {
        return false;
    }
    std::vector<VkExtensionProperties> extensions(count);
    if (fn.vkEnumerateDeviceExtensionProperties(device, nullptr, &count, extensions.data()) != VK_SUCCESS) {
        return false;
    }
    for (const auto& extension : extensions) {
        if (std::strcmp(extension.extensionName, name) == 0) {
            return true;
        }
    }
    return false;
}

// The first queue family with graphics and compute, or -1.
int find_queue_family(const vk::Functions& fn, VkPhysicalDevice device, std::uint32_t* timestamp_valid_bits) {
    std::uint32_t count = 0;
    fn.vkGetPhysicalDeviceQueueFamilyProperties(device, &count, nullptr);
    std::vector<VkQueueFamilyProperties> families(count);
    fn.vkGetPhysicalDeviceQueueFamilyProperties(device, &count, families.data());
    for (std::uint32_t i = 0; i < count; ++i) {
        VkQueueFlags needed = VK_QUEUE_GRAPHICS_BIT | VK_QUEUE_COMPUTE_BIT;
        if ((families[i].queueFlags & needed) == needed && families[i].queueCount > 0) {
            *timestamp_valid_bits = families[i].timestampValidBits;
            return static_cast<int>(i);
        }
    }
    return -1;
}

std::string describe(const VkPhysicalDeviceProperties& properties) {
    std::string text = properties.deviceName;
    text += " (Vulkan " + std::to_string(VK_API_VERSION_MAJOR(properties.apiVersion)) + "." +
            std::to_string(VK_API_VERSION_MINOR(properties.apiVersion)) + "." +
            std::to_string(VK_API_VERSION_PATCH(properties.apiVersion)) + ", driver 0x";
    char version[16];
    std::snprintf(version, sizeof(version), "%x", properties.driverVersion);
    text += version;
    switch (properties.deviceType) {
    case VK_PHYSICAL_DEVICE_TYPE_DISCRETE_GPU:
        text += ", discrete GPU";
        break;
    case VK_PHYSICAL_DEVICE_TYPE_INTEGRATED_GPU:
        text += ", integrated GPU";
        break;
    case VK_PHYSICAL_DEVICE_TYPE_VIRTUAL_GPU:
        text += ", virtual GPU";
        break;
    case VK_PHYSICAL_DEVICE_TYPE_CPU:
        text += ", CPU";
        break;
    default:
        break;
    }
    return text + ")";
}

Error no_device(const std::string& why) {
    return make_error(ErrorCode::no_device, why + "; use `--backend cpu` to render without Vulkan");
}

// A missing function is named as "Context::create: the Vulkan loader's vkGetInstanceProcAddr returns null for ...".
constexpr const char* kWhose = "Context::create: the Vulkan loader's ";

Result<void> create_instance(VulkanContext& context, bool want_validation) {
    vk::Functions& fn = context.fn;
    // The bootstrap: the one function vksonar takes from the loader it links (vk/functions.h).
    fn.vkGetInstanceProcAddr = vkGetInstanceProcAddr;
    if (auto loaded = vk::load_global_functions(fn, kWhose); !loaded) return loaded.error();
    std::vector<const char*> layers;
    std::vector<const char*> extensions;
    bool debug_utils = false;
    bool validation_features = false;
    if (want_validation && has_layer(fn, kValidationLayer)) {
        layers.push_back(kValidationLayer);
        context.validation = true;
        if (has_instance_extension(fn, nullptr, VK_EXT_DEBUG_UTILS_EXTENSION_NAME) ||
            has_instance_extension(fn, kValidationLayer, VK_EXT_DEBUG_UTILS_EXTENSION_NAME)) {
            extensions.push_back(VK_EXT_DEBUG_UTILS_EXTENSION_NAME);
            debug_utils = true;
        }
        if (has_instance_extension(fn, kValidationLayer, VK_EXT_VALIDATION_FEATURES_EXTENSION_NAME)) {
            extensions.push_back(VK_EXT_VALIDATION_FEATURES_EXTENSION_NAME);
            validation_features = true;
        }
    }
    VkInstanceCreateFlags flags = 0;
#ifdef VK_KHR_portability_enumeration
    if (has_instance_extension(fn, nullptr, VK_KHR_PORTABILITY_ENUMERATION_EXTENSION_NAME)) {
        extensions.push_back(VK_KHR_PORTABILITY_ENUMERATION_EXTENSION_NAME);
        flags |= VK_INSTANCE_CREATE_ENUMERATE_PORTABILITY_BIT_KHR;
    }
#endif

    VkApplicationInfo app{};
    app.sType = VK_STRUCTURE_TYPE_APPLICATION_INFO;
    app.pApplicationName = "vksonar";
    app.pEngineName = "vksonar";
    app.apiVersion = VK_API_VERSION_1_1;

    VkDebugUtilsMessengerCreateInfoEXT messenger_info{};
    messenger_info.sType = VK_STRUCTURE_TYPE_DEBUG_UTILS_MESSENGER_CREATE_INFO_EXT;
    messenger_info.messageSeverity =
        VK_DEBUG_UTILS_MESSAGE_SEVERITY_WARNING_BIT_EXT | VK_DEBUG_UTILS_MESSAGE_SEVERITY_ERROR_BIT_EXT;
    messenger_info.messageType = VK_DEBUG_UTILS_MESSAGE_TYPE_GENERAL_BIT_EXT |
                                 VK_DEBUG_UTILS_MESSAGE_TYPE_VALIDATION_BIT_EXT |
                                 VK_DEBUG_UTILS_MESSAGE_TYPE_PERFORMANCE_BIT_EXT;
    messenger_info.pfnUserCallback = debug_callback;
    messenger_info.pUserData = &context;

    VkInstanceCreateInfo info{};
    info.sType = VK_STRUCTURE_TYPE_INSTANCE_CREATE_INFO;
    info.pNext = debug_utils ? &messenger_info : nullptr; // also covers vkCreateInstance/vkDestroyInstance
    // The layer otherwise skips SPIR-V it finds in its on-disk cache (~/.cache), so whether a shader
    // error is reported would depend on what an earlier process on the machine validated.
    const VkValidationFeatureDisableEXT no_shader_cache = VK_VALIDATION_FEATURE_DISABLE_SHADER_VALIDATION_CACHE_EXT;
    VkValidationFeaturesEXT features{};
    features.sType = VK_STRUCTURE_TYPE_VALIDATION_FEATURES_EXT;
    features.disabledValidationFeatureCount = 1;
    features.pDisabledValidationFeatures = &no_shader_cache;
    if (validation_features) {
        features.pNext = info.pNext;
        info.pNext = &features;
    }
    info.flags = flags;
    info.pApplicationInfo = &app;
    info.enabledLayerCount = static_cast<std::uint32_t>(layers.size());
    info.ppEnabledLayerNames = layers.data();
    info.enabledExtensionCount = static_cast<std::uint32_t>(extensions.size());
    info.ppEnabledExtensionNames = extensions.data();
    VkResult result = fn.vkCreateInstance(&info, context.allocator, &context.instance);
    if (result == VK_ERROR_INCOMPATIBLE_DRIVER) {
        return no_device("no Vulkan driver (vkCreateInstance: VK_ERROR_INCOMPATIBLE_DRIVER)");
    }
    if (result != VK_SUCCESS) {
        return vk::vk_error(result, "vkCreateInstance");
    }
    const auto loaded = vk::load_instance_functions(fn, context.instance, true, kWhose);
    // Owned even when a later function failed to load: vkDestroyInstance is then null only if the
    // table failed before it, and the instance cannot be destroyed through it either.
    context.owned_instance.take(context.instance, context.allocator, fn.vkDestroyInstance);
    if (!loaded) return loaded.error();

    if (debug_utils) {
        vk::load_debug_utils_functions(fn, context.instance);
        if (fn.vkCreateDebugUtilsMessengerEXT && fn.vkDestroyDebugUtilsMessengerEXT) {
            VkDebugUtilsMessengerEXT messenger = VK_NULL_HANDLE;
            VKS_VK_TRY(
                fn.vkCreateDebugUtilsMessengerEXT(context.instance, &messenger_info, context.allocator, &messenger));
            context.debug_messenger.take(context.instance, messenger, context.allocator,
                                         fn.vkDestroyDebugUtilsMessengerEXT);
        }
    }
    return {};
}

Result<void> create_device(VulkanContext& context, int device_index) {
    vk::Functions& fn = context.fn;
    std::uint32_t count = 0;
    VKS_VK_TRY(fn.vkEnumeratePhysicalDevices(context.instance, &count, nullptr));
    std::vector<VkPhysicalDevice> devices(count);
    VKS_VK_TRY(fn.vkEnumeratePhysicalDevices(context.instance, &count, devices.data()));
    if (count == 0) {
        return no_device("no Vulkan device found");
    }
    int family = -1;
    std::uint32_t timestamp_bits = 0;
    if (device_index >= 0) {
        if (static_cast<std::uint32_t>(device_index) >= count) {
            return no_device("Vulkan device index " + std::to_string(device_index) + " does not exist (" +
                             std::to_string(count) + " device(s))");
        }
        context.physical_device = devices[static_cast<std::size_t>(device_index)];
        family = find_queue_family(fn, context.physical_device, &timestamp_bits);
        if (family < 0) {
            return no_device("Vulkan device " + std::to_string(device_index) + " has no graphics+compute queue");
        }
    } else {
        for (VkPhysicalDevice device : devices) {
            family = find_queue_family(fn, device, &timestamp_bits);
            if (family >= 0) {
                context.physical_device = device;
                break;
            }
        }
        if (family < 0) {
            return no_device("no Vulkan device has a graphics+compute queue");
        }
    }
    context.queue_family = static_cast<std::uint32_t>(family);
    context.timestamp_valid_bits = timestamp_bits;
    fn.vkGetPhysicalDeviceProperties(context.physical_device, &context.properties);
    context.description = describe(context.properties);
    if (context.properties.apiVersion < VK_API_VERSION_1_1) {
        return no_device("Vulkan device " + context.description + " supports only Vulkan 1.0 (1.1 needed)");
    }

    std::vector<const char*> extensions;
    if (has_device_extension(fn, context.physical_device, "VK_KHR_portability_subset")) {
        extensions.push_back("VK_KHR_portability_subset");
    }
    float priority = 1.0f;
    VkDeviceQueueCreateInfo queue_info{};
    queue_info.sType = VK_STRUCTURE_TYPE_DEVICE_QUEUE_CREATE_INFO;
    queue_info.queueFamilyIndex = context.queue_family;
    queue_info.queueCount = 1;
    queue_info.pQueuePriorities = &priority;
    VkDeviceCreateInfo info{};
    info.sType = VK_STRUCTURE_TYPE_DEVICE_CREATE_INFO;
    info.queueCreateInfoCount = 1;
    info.pQueueCreateInfos = &queue_info;
    info.enabledExtensionCount = static_cast<std::uint32_t>(extensions.size());
    info.ppEnabledExtensionNames = extensions.data();
    VKS_VK_TRY(fn.vkCreateDevice(context.physical_device, &info, context.allocator, &context.device));
    const auto loaded = vk::load_device_functions(fn, context.device, true, kWhose);
    context.owned_device.take(context.device, context.allocator, fn.vkDestroyDevice); // as for the instance
    if (!loaded) return loaded.error();
    fn.vkGetDeviceQueue(context.device, context.queue_family, 0, &context.queue);
    return {};
}

} // namespace

// The owners destroy the device, messenger and instance after this (vulkan_context.h); a device
// vksonar made first finishes its work. A borrowed device is the host engine's to wait for.
VulkanContext::~VulkanContext() {
    if (owned_device && fn.vkDeviceWaitIdle != nullptr) fn.vkDeviceWaitIdle(device);
}

Context::Context() = default;
Context::~Context() = default;
Context::Context(Context&&) noexcept = default;
Context& Context::operator=(Context&&) noexcept = default;

Result<Context> Context::create(const ContextOptions& options) {
    if (!options.vulkan) {
        return cpu_only();
    }
    if (options.device_index < -1) {
        return make_error(ErrorCode::invalid_argument,
                          "ContextOptions: device_index = " + std::to_string(options.device_index) +
                              " (expected -1, the first device, or an index from 0)");
    }
    // The messenger keeps a pointer to the VulkanContext: it lives on the heap and never moves.
    auto vulkan = std::make_unique<VulkanContext>();
    vulkan->allocator = options.allocator;
    if (auto created = create_instance(*vulkan, options.enable_validation); !created) {
        return created.error();
    }
    if (auto created = create_device(*vulkan, options.device_index); !created) {
        return created.error();
    }
    Context context;
    context.vk_ = std::move(vulkan);
    return context;
}

Result<ContextOptions> context_options_from_env(ContextOptions base) {
    if (env_flag("VKSONAR_VALIDATION")) base.enable_validation = true;
    if (base.device_index < 0) {
        if (const char* env = std::getenv("VKSONAR_DEVICE"); env && *env) {
            char* end = nullptr;
            const long index = std::strtol(env, &end, 10);
            if (*end != '\0' || index < 0 || index > 1 << 16) {
                return make_error(ErrorCode::invalid_argument,
                                  std::string("VKSONAR_DEVICE: '") + env + "' is not a device index (0, 1, ...)");
            }
            base.device_index = static_cast<int>(index);
        }
    }
    return base;
}

VulkanContext* detail::Access::vulkan(const Context& context) {
    return context.vk_.get();
}

Context Context::cpu_only() {
    return Context();
}

bool Context::has_vulkan() const {
    return vk_ != nullptr;
}

std::string Context::device_description() const {
    return vk_ ? vk_->description : std::string("CPU (no Vulkan)");
}

std::uint32_t Context::validation_messages() const {
    return vk_ ? vk_->validation_messages.load(std::memory_order_relaxed) : 0u;
}

} // namespace vksonar
