// Half of an include cycle, for layering.check_refuses_cycles.
#pragma once
#include "tiles/core/ring_b.hpp"
