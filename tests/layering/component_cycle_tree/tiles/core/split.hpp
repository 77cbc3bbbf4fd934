// A header whose .cpp is split in parts (split_x.cpp, no split.cpp), for
// layering.check_refuses_component_cycles: the part includes split_peer.hpp and
// split_peer.cpp includes this one, a cycle only if the parts count as this component.
#pragma once
int split();
