// Map name and free-text rules (PROTOCOL.md §4.2).
#include "proto/names.hpp"

#include <string>

namespace st::proto {
namespace {

bool name_char(char c) {
  return (c >= 'A' && c <= 'Z') || (c >= 'a' && c <= 'z') || (c >= '0' && c <= '9') ||
         c == '.' || c == '_' || c == '-';
}

}  // namespace

Status validate_map_name(std::string_view name) {
  if (name.empty()) return Status::fail(ErrorCode::bad_map_name, "map name is empty");
  if (name.size() > kMaxMapNameBytes)
    return Status::fail(ErrorCode::bad_map_name, "map name of " + std::to_string(name.size()) +
                                                     " bytes exceeds " +
                                                     std::to_string(kMaxMapNameBytes));
  for (std::size_t i = 0; i < name.size(); ++i) {
    if (!name_char(name[i]))
      return Status::fail(ErrorCode::bad_map_name,
                          "map name byte " + std::to_string(i) + " (code " +
                              std::to_string(static_cast<unsigned char>(name[i])) +
                              ") is not in [A-Za-z0-9._-]");
  }
  if (name[0] == '.' || name[0] == '-')
    return Status::fail(ErrorCode::bad_map_name, "map name starts with '.' or '-'");
  return {};
}

bool is_valid_map_name(std::string_view name) { return validate_map_name(name).ok(); }

Status validate_text(std::string_view text, std::size_t max_bytes, const char* field) {
  if (text.size() > max_bytes)
    return Status::fail(ErrorCode::invalid_field, std::string(field) + " of " +
                                                      std::to_string(text.size()) +
                                                      " bytes exceeds " +
                                                      std::to_string(max_bytes));
  for (std::size_t i = 0; i < text.size(); ++i) {
    const auto c = static_cast<unsigned char>(text[i]);
    if (c < 0x20 || c == 0x7f)
      return Status::fail(ErrorCode::invalid_field, std::string(field) + " byte " +
                                                        std::to_string(i) +
                                                        " is control code " +
                                                        std::to_string(c));
  }
  return {};
}

std::string sanitize_text(std::string_view text, std::size_t max_bytes) {
  std::string out(text.substr(0, max_bytes));
  for (char& c : out) {
    const auto u = static_cast<unsigned char>(c);
    if (u < 0x20 || u == 0x7f) c = '?';
  }
  return out;
}

}  // namespace st::proto
