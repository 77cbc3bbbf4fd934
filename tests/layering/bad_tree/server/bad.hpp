// A server header that includes the baking module: the layering check must refuse it.
#pragma once
#include "scene/scene.hpp"
