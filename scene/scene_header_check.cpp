// Scene file checks before assimp: see scene_header_check.hpp.
#include "scene/scene_header_check.hpp"

#include <algorithm>
#include <cctype>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <vector>

#include "common/error.hpp"

namespace st {
namespace {

constexpr size_t kMaxHeaderBytes = size_t(1) << 16;  // a PLY header longer than this is refused

std::string lower_extension(const std::string& path) {
  std::string ext = std::filesystem::path(path).extension().string();
  for (char& c : ext) c = char(std::tolower(static_cast<unsigned char>(c)));
  return ext;
}

uint64_t file_size(const std::string& path) {
  std::error_code ec;
  const auto n = std::filesystem::file_size(path, ec);
  return ec ? 0 : uint64_t(n);
}

// A decimal count, saturated at 2^63 (a file's counts are compared with its size).
bool parse_count(const std::string& token, uint64_t& out) {
  if (token.empty() || token.size() > 64) return false;
  uint64_t v = 0;
  for (char c : token) {
    if (c < '0' || c > '9') return false;
    v = v > (uint64_t(1) << 59) ? uint64_t(1) << 63 : v * 10 + uint64_t(c - '0');
  }
  out = v;
  return true;
}

uint64_t mul_sat(uint64_t a, uint64_t b) {
  if (a != 0 && b > UINT64_MAX / a) return UINT64_MAX;
  return a * b;
}

// Bytes of one binary PLY scalar type, 0 if unknown.
uint64_t ply_type_bytes(const std::string& t) {
  if (t == "char" || t == "uchar" || t == "int8" || t == "uint8") return 1;
  if (t == "short" || t == "ushort" || t == "int16" || t == "uint16") return 2;
  if (t == "int" || t == "uint" || t == "float" || t == "int32" || t == "uint32" || t == "float32") return 4;
  if (t == "double" || t == "float64") return 8;
  return 0;
}

// PLY (Greg Turk's format): "ply", "format ascii|binary_little_endian|binary_big_endian
// 1.0", then "element NAME COUNT" each followed by its "property TYPE NAME" or "property
// list COUNT_TYPE ITEM_TYPE NAME" lines, up to "end_header".
void check_ply(const std::string& path, std::ifstream& in, uint64_t size) {
  std::string header;
  std::string line;
  bool ascii = true, ended = false;
  struct Element {
    std::string name;
    uint64_t count = 0, min_bytes = 0;
  };
  std::vector<Element> elements;
  while (std::getline(in, line)) {
    header += line;
    header += '\n';
    if (header.size() > kMaxHeaderBytes)
      throw Error(path + ": PLY header longer than " + std::to_string(kMaxHeaderBytes) + " bytes");
    if (!line.empty() && line.back() == '\r') line.pop_back();
    std::istringstream words(line);
    std::string key;
    words >> key;
    if (key == "end_header") {
      ended = true;
      break;
    }
    if (key == "format") {
      std::string f;
      words >> f;
      ascii = f == "ascii";
    } else if (key == "element") {
      Element e;
      std::string count;
      words >> e.name >> count;
      if (!parse_count(count, e.count)) return;  // assimp's own error
      elements.push_back(e);
    } else if (key == "property" && !elements.empty()) {
      std::string type;
      words >> type;
      if (type == "list") words >> type;  // a list's count: its items may be none
      const uint64_t b = ascii ? 2 : ply_type_bytes(type);
      if (b == 0) return;  // an unknown type: assimp's own error
      elements.back().min_bytes += b;
    }
  }
  if (!ended) return;  // no header end: assimp's own error
  const uint64_t body = size > header.size() ? size - header.size() : 0;
  uint64_t need = 0;
  for (const Element& e : elements) {
    // An element without properties still takes a line in ASCII; count it as a byte.
    const uint64_t one = std::max<uint64_t>(e.min_bytes, 1);
    const uint64_t bytes = mul_sat(e.count, one);
    need = need + bytes < need ? UINT64_MAX : need + bytes;
    if (need > body + 1)  // + 1: the last ASCII number needs no separator
      throw Error(path + ": PLY header claims " + std::to_string(e.count) + " '" + e.name + "' elements (at least " +
                  std::to_string(one) + " bytes each), more than the " + std::to_string(body) +
                  " bytes after its header can hold");
  }
}

// OFF (Geomview): an optional "[ST][C][N][4][n]OFF" line, then "VERTICES FACES EDGES",
// then a line per vertex (3 numbers at least: 6 bytes) and per face (its index count at
// least: 2 bytes). Comments ('#') only add bytes.
void check_off(const std::string& path, std::ifstream& in, uint64_t size) {
  std::vector<std::string> tokens;
  std::string line;
  size_t lines = 0;
  while (tokens.size() < 4 && std::getline(in, line) && ++lines < 64) {
    if (const size_t hash = line.find('#'); hash != std::string::npos) line.resize(hash);
    std::istringstream words(line);
    for (std::string w; words >> w;) tokens.push_back(w);
  }
  size_t at = 0;
  if (!tokens.empty() && tokens[0].size() >= 3 && tokens[0].compare(tokens[0].size() - 3, 3, "OFF") == 0) {
    if (tokens[0].find('n') != std::string::npos) ++at;  // nOFF: a dimension follows
    ++at;
  }
  uint64_t vertices = 0, faces = 0;
  if (tokens.size() < at + 2 || !parse_count(tokens[at], vertices) || !parse_count(tokens[at + 1], faces)) return;
  const uint64_t need = mul_sat(vertices, 6) / 2 + mul_sat(faces, 2) / 2;  // halved: no overflow in the sum
  if (need > size / 2 + 1)
    throw Error(path + ": OFF header claims " + std::to_string(vertices) + " vertices and " + std::to_string(faces) +
                " faces, more than its " + std::to_string(size) + " bytes can hold (6 bytes a vertex, 2 a face)");
}

}  // namespace

void check_header_counts(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return;
  char head[4] = {};
  in.read(head, sizeof head);
  const std::string start(head, size_t(in.gcount()));
  in.clear();
  in.seekg(0);
  const std::string ext = lower_extension(path);
  const uint64_t size = file_size(path);
  if (ext == ".ply" || start == "ply\n" || start == "ply\r") {
    if (start.rfind("ply", 0) == 0) check_ply(path, in, size);
  } else if (ext == ".off") {
    check_off(path, in, size);
  }
}

void check_xml_nesting(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return;
  // XML by content: '<' first after an optional UTF-8 byte order mark and white space.
  char head[256];
  in.read(head, sizeof head);
  const size_t got = size_t(in.gcount());
  size_t i = got >= 3 && std::equal(head, head + 3, "\xEF\xBB\xBF") ? 3 : 0;
  while (i < got && (head[i] == ' ' || head[i] == '\t' || head[i] == '\r' || head[i] == '\n')) ++i;
  if (i >= got || head[i] != '<') return;
  in.clear();
  in.seekg(0);
  // A streaming scan of tags: comments, CDATA, declarations and processing instructions
  // are skipped, quoted attribute values too; "<a>" opens, "</a>" closes, "<a/>" is both.
  enum class State { text, open, bang, comment, cdata, skip, tag, end_tag } state = State::text;
  std::string bang;   // what follows "<!" until it is told apart
  char quote = 0;     // inside a quoted attribute value
  char prev = 0, prev2 = 0;
  uint32_t depth = 0;
  uint64_t offset = 0;
  std::vector<char> buf(size_t(1) << 20);
  while (in) {
    in.read(buf.data(), std::streamsize(buf.size()));
    const size_t n = size_t(in.gcount());
    for (size_t k = 0; k < n; ++k, ++offset) {
      const char c = buf[k];
      switch (state) {
        case State::text:
          if (c == '<') state = State::open;
          break;
        case State::open:
          if (c == '!') state = State::bang, bang.clear();
          else if (c == '?') state = State::skip;
          else if (c == '/') state = State::end_tag;
          else state = State::tag, quote = 0;
          break;
        case State::bang:
          bang += c;
          if (bang == "--") state = State::comment;
          else if (bang == "[CDATA[") state = State::cdata;
          else if (std::string("[CDATA[").rfind(bang, 0) != 0 && std::string("--").rfind(bang, 0) != 0)
            state = c == '>' ? State::text : State::skip;
          break;
        case State::comment:
          if (c == '>' && prev == '-' && prev2 == '-') state = State::text;
          break;
        case State::cdata:
          if (c == '>' && prev == ']' && prev2 == ']') state = State::text;
          break;
        case State::skip:
          if (c == '>') state = State::text;
          break;
        case State::end_tag:
          if (c == '>') {
            state = State::text;
            if (depth > 0) --depth;
          }
          break;
        case State::tag:
          if (quote) {
            if (c == quote) quote = 0;
          } else if (c == '"' || c == '\'') {
            quote = c;
          } else if (c == '>') {
            state = State::text;
            if (prev != '/' && ++depth > kMaxXmlNesting)
              throw Error(path + ": XML elements nest deeper than " + std::to_string(kMaxXmlNesting) +
                          " levels (at byte " + std::to_string(offset) + ")");
          }
          break;
      }
      prev2 = prev;
      prev = c;
    }
  }
}

}  // namespace st
