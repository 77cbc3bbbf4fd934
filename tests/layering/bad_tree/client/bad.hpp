// A client header that includes the server: the layering check must refuse it.
#pragma once
#include <vector>
#include "server/server.hpp"
#include "tiles/core/light.hpp"
