// The other half: ring_a.hpp includes this header, and this one includes it.
#pragma once
#include "tiles/core/ring_a.hpp"
