// Text from files, shown on a terminal or in a log: printable_text() makes it one safe
// line, escaped the way JSON escapes strings, so a hostile file cannot move the cursor,
// rewrite earlier lines or forge log lines (ESC, CR, BS, C1 controls such as CSI).
// (Text sent on the wire follows the protocol's rule instead: proto::sanitize_text in
// proto/names.hpp replaces control bytes and bounds the length; it keeps no escapes.)
#pragma once
#include <string>
#include <string_view>

namespace st {

// Backslash -> "\\"; \b \f \n \r \t as those; other C0 controls, DEL and C1 controls
// (U+0080..U+009F) as "\u00XX"; bytes that are not valid UTF-8 as "\xNN". Valid UTF-8
// otherwise passes unchanged, so printable_text(s) == s for ordinary text.
std::string printable_text(std::string_view s);

}  // namespace st
