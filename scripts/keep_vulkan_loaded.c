// Preloaded by scripts/sanitize.sh: keeps lavapipe and the validation layer loaded for the whole life
// of each test process, so that LeakSanitizer's exit-time scan still sees their globals (the Vulkan
// loader would dlclose them in vkDestroyInstance). They are opened RTLD_LOCAL | RTLD_NODELETE from
// here instead of being preloaded themselves: a preloaded layer's exported vkGetInstanceProcAddr,
// vkGetDeviceProcAddr and vkEnumerateInstance*Properties would interpose the loader's for the whole
// process, and vksonar (which loads every function through vkGetInstanceProcAddr) would then create
// its instance through the layer's entry points instead of the loader's. A library that is not
// installed is skipped.
#include <dlfcn.h>

__attribute__((constructor)) static void keep_vulkan_loaded(void) {
    static const char* const libraries[] = {"libvulkan_lvp.so", "libVkLayer_khronos_validation.so"};
    for (unsigned i = 0; i < sizeof(libraries) / sizeof(libraries[0]); ++i)
        (void)dlopen(libraries[i], RTLD_NOW | RTLD_LOCAL | RTLD_NODELETE);
}
