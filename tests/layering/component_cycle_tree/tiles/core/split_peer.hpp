// The other side of split.hpp's cycle.
#pragma once
int split_peer();
