// Map-name and free-text rules (names.hpp, PROTOCOL.md §4.2).
#include <gtest/gtest.h>

#include "proto/proto.hpp"

namespace st::proto {
namespace {

TEST(MapNames, AcceptTheDocumentedAlphabet) {
  for (const char* ok : {"a", "Z", "0", "_", "city", "city_2048.v2-final", "A.B.C", "x..y",
                         "tile-pack_01"}) {
    EXPECT_TRUE(is_valid_map_name(ok)) << ok;
  }
  EXPECT_TRUE(is_valid_map_name(std::string(kMaxMapNameBytes, 'm')));
}

TEST(MapNames, RejectEverythingThatCouldNameAPath) {
  for (const char* bad : {"", ".", "..", ".git", "-x", "a/b", "/", "../x", "a\\b", "C:x",
                          "a b", "a\tb", "~root", "$HOME", "a*", "a?", "%2e%2e", "\xc3\xa9"}) {
    const Status s = validate_map_name(bad);
    EXPECT_EQ(s.code, ErrorCode::bad_map_name) << bad;
    EXPECT_FALSE(s.detail.empty());
  }
  EXPECT_FALSE(is_valid_map_name(std::string(kMaxMapNameBytes + 1, 'm')));
  EXPECT_FALSE(is_valid_map_name(std::string("ab\0cd", 5)));
}

TEST(MapNames, EveryByteOutsideTheAlphabetIsRejectedAtEveryPosition) {
  for (int c = 0; c < 256; ++c) {
    const bool allowed = (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') ||
                         (c >= '0' && c <= '9') || c == '.' || c == '_' || c == '-';
    for (std::size_t pos : {0, 1, 4}) {
      std::string n = "abcde";
      n[pos] = static_cast<char>(c);
      const bool leading_bad = pos == 0 && (c == '.' || c == '-');
      EXPECT_EQ(is_valid_map_name(n), allowed && !leading_bad) << c << " at " << pos;
    }
  }
}

TEST(Text, ControlBytesAndOverlongTextAreRejected) {
  EXPECT_TRUE(validate_text("plain text, with UTF-8 \xc3\xa9", 100, "f"));
  EXPECT_EQ(validate_text("a\nb", 100, "f").code, ErrorCode::invalid_field);
  EXPECT_EQ(validate_text("a\x7f", 100, "f").code, ErrorCode::invalid_field);
  EXPECT_EQ(validate_text(std::string(101, 'a'), 100, "f").code, ErrorCode::invalid_field);
}

}  // namespace
}  // namespace st::proto
