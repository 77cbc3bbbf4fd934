/* as CMake writes a unity batch (check_unity_clash.py's fixture) */

#include "../../../a.cpp"

#include "../../../b.cpp"
