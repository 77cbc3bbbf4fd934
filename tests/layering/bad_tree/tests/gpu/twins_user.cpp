// The test that includes gpu/twins_only.hpp; no product source does.
#include "gpu/twins_only.hpp"
