// GpuMap's header inside the repository: the public one, <shadowtile/gpu.hpp>.
#pragma once
#include "shadowtile/gpu.hpp"
