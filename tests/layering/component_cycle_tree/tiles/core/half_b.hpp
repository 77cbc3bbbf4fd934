// The other half (see half_a.hpp).
#pragma once
int half_b();
