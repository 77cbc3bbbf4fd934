// Structural check of Quake 3 maps (.bsp inside a .pk3 zip) before assimp sees them:
// assimp 5.2.5's Q3BSP parser trusts every lump offset and index in the file and reads
// out of bounds on hostile input (a crash, even with aiProcess_ValidateDataStructure,
// which runs only after parsing). See MACHINE.md.
#pragma once
#include <string>

namespace st {

// Throws st::Error naming the archive, the map and the field when a .bsp in the archive
// at `path` is malformed: header shorter than 144 bytes, magic not "IBSP", version not
// 46, a lump outside the file or with a size that is not a whole number of records, a
// face whose mesh-vertex range, texture or lightmap index is out of range; also when the
// zip structure itself is inconsistent (offsets outside the file, members that do not
// inflate to their size). Does nothing if `path` is not a zip archive (no end record):
// assimp then reports that itself.
void check_quake3_archive(const std::string& path);

}  // namespace st
