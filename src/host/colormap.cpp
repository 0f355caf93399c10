// Colormaps for the display images: [0, 1] -> 8-bit RGB (the formulas: host/colormap.h).
#include "host/colormap.h"
#include "host/host_stages.h"

namespace vksonar::host {

Rgb8 colormap(Colormap map, float value01) {
    switch (map) {
    case Colormap::gray:
        return colormap_of<Colormap::gray>(value01);
    case Colormap::viridis:
        return colormap_of<Colormap::viridis>(value01);
    case Colormap::sonar:
        return colormap_of<Colormap::sonar>(value01);
    case Colormap::jet:
        return colormap_of<Colormap::jet>(value01);
    }
    return {0, 0, 0};
}

} // namespace vksonar::host
