#include "tiles/core/half_b.hpp"

#include "tiles/core/half_a.hpp"

int half_b() { return 0 * half_a(); }
