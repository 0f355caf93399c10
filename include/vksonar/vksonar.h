// Umbrella header of the vksonar library.
#pragma once

#include "vksonar/config.h"
#include "vksonar/context.h"
#include "vksonar/frame.h"
#include "vksonar/host_depth.h"
#include "vksonar/renderer.h"
#include "vksonar/result.h"
#include "vksonar/scene.h"
#include "vksonar/validity.h"
