// Half of a component-level include cycle, for layering.check_refuses_component_cycles:
// no header includes another, but half_a.cpp includes half_b.hpp and half_b.cpp this one.
#pragma once
int half_a();
