// Checks of scene files made before assimp reads them, for what assimp trusts:
//   - PLY and OFF headers state element counts that assimp allocates for (a 309-byte OFF
//     file made it reserve 15.8 GB): each count is checked against the bytes the file has
//     after its header, at the fewest bytes one element can take (ASCII: 2 per number,
//     "0 "; binary: the sizes of its properties, a list's count alone);
//   - XML formats (COLLADA and the others assimp reads as XML) are read by recursion over
//     their element nesting: elements may nest at most kMaxXmlNesting deep.
// Both throw st::Error of one line naming the file and what is wrong; a file of another
// format (by extension and by content, as assimp picks its importer) passes untouched.
#pragma once
#include <cstdint>
#include <string>

namespace st {

inline constexpr uint32_t kMaxXmlNesting = 1024;

void check_header_counts(const std::string& path);
void check_xml_nesting(const std::string& path);

}  // namespace st
