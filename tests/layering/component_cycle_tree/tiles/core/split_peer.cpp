#include "tiles/core/split_peer.hpp"

#include "tiles/core/split.hpp"

int split_peer() { return 0 * split(); }
