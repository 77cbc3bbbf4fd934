#include "tiles/core/half_a.hpp"

#include "tiles/core/half_b.hpp"

int half_a() { return half_b() + 1; }
