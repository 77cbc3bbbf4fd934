// DAG-MH validation: hostile input is the normal case (ARCHITECTURE.md "Rules a change must keep"). Never trusts a length:
// every section's extent is derived from counts in 64-bit arithmetic and compared to
// the header's offsets and to the buffer's size.
#include "tiles/core/dagmh_validate.hpp"

#include <bit>
#include <string>
#include <vector>

#include "common/error.hpp"
#include "tiles/core/interval.hpp"
#include "tiles/core/pack_format.hpp"

namespace st::dagmh {
namespace {

[[noreturn]] void fail(const std::string& field, uint64_t offset, const std::string& what) {
  throw FormatError("dagmh: " + field + " at byte " + std::to_string(offset) + ": " + what);
}

void expect_field(const char* name, uint32_t offset, uint64_t value, uint64_t expected) {
  if (value != expected)
    fail(name, offset, "is " + std::to_string(value) + ", expected " + std::to_string(expected));
}

Sections check_header(const Header& h, size_t size) {
  expect_field("magic", offsetof(Header, magic), h.magic, kMagic);
  if (h.version == 1 || h.version == 2)
    fail("version", offsetof(Header, version),
         "is " + std::to_string(h.version) +
             ": a DAG-MH tile of the layout before version 3 (72-byte header, 24-byte chunk infos), which this "
             "reader no longer reads; rebuild the pack");
  if (h.version != kVersion)
    fail("version", offsetof(Header, version), "is " + std::to_string(h.version) + ", this reader knows 3");
  if (h.flags & ~kFlagDictionary) fail("flags", offsetof(Header, flags), "reserved bits set");
  expect_field("reserved", offsetof(Header, reserved), h.reserved, 0);
  if (!(h.flags & kFlagDictionary)) expect_field("dictionary_crc", offsetof(Header, dictionary_crc), h.dictionary_crc, 0);
  if (h.finest_level > kMaxLevel) fail("finest_level", offsetof(Header, finest_level), "exceeds 20");
  if (h.skip_level > std::min<uint32_t>(h.finest_level, kMaxSkipListLevel))
    fail("skip_level", offsetof(Header, skip_level), "exceeds min(finest_level, 6)");
  if (h.node_words > kRefIndexMask) fail("node_words", offsetof(Header, node_words), "exceeds 2^30");
  if (h.treelet_count > kRefIndexMask)
    fail("treelet_count", offsetof(Header, treelet_count), "exceeds 2^30");
  if (h.value_count == 0) fail("value_count", offsetof(Header, value_count), "is zero (the root has a value)");
  const Sections s = sections_of(h, size);
  // The multiplier section is the rest of the buffer: a multiple of 4 of at least 8 bytes.
  if (s.multipliers + kMultiplierPadBytes > size)
    fail("sections", s.multipliers,
         "the counts need " + std::to_string(s.multipliers + kMultiplierPadBytes) + " bytes but the buffer has " +
             std::to_string(size));
  if ((size - s.multipliers) % 4 != 0)
    fail("multipliers", s.multipliers, "section of " + std::to_string(size - s.multipliers) + " bytes is not a multiple of 4");
  return s;
}

// Inner nodes and treelets: extents, references, value counts, reachability.
void check_structure(const Header& h, const Sections& s, const uint8_t* base, const Dictionary* dict) {
  const uint8_t* nodes = base + s.nodes;
  const uint32_t words = h.node_words;
  auto node_byte = [&](uint64_t w) { return s.nodes + 4 * w; };
  // Flag dictionary: references below D / T are the dictionary's, the rest the tile's offset by them.
  const uint32_t D = dict ? dict->node_words() : 0, T = dict ? dict->treelet_count() : 0;
  std::vector<uint32_t> starts;
  std::vector<uint8_t> is_start(words, 0);
  for (uint32_t w = 0; w < words;) {
    const uint32_t flags = st::load_le<uint32_t>(nodes + 4 * size_t(w));
    if (flags & ~kNodeFlagBits) fail("node flags", node_byte(w), "reserved bits set");
    const uint32_t mask = flags & kNodeChildMask;
    if (mask == 0) fail("node flags", node_byte(w), "inner node without children");
    if ((flags >> kNodeTreeletShift) & ~mask & 0xF)
      fail("node flags", node_byte(w), "treelet bit for an absent child");
    if (uint64_t(w) + node_words(flags) > words)
      fail("node", node_byte(w), "overruns the node section");
    is_start[w] = 1;
    starts.push_back(w);
    w += node_words(flags);
  }
  const uint8_t* treelets = base + s.treelets;
  std::vector<uint32_t> treelet_values(h.treelet_count);
  for (uint32_t t = 0; t < h.treelet_count; ++t) {
    const uint8_t* p = treelets + size_t(t) * kTreeletBytes;
    if (st::load_le<uint32_t>(p + 8) >> (kTreeletNodes - 64))
      fail("treelet", s.treelets + uint64_t(t) * kTreeletBytes + 8, "bits past 85 set");
    treelet_values[t] = uint32_t(std::popcount(st::load_le<uint64_t>(p)) + std::popcount(st::load_le<uint32_t>(p + 8)));
  }
  // References and value counts, children first (they lie after their parents).
  std::vector<uint32_t> count(words, 0);
  for (size_t i = starts.size(); i-- > 0;) {
    const uint32_t w = starts[i];
    const uint32_t flags = st::load_le<uint32_t>(nodes + 4 * size_t(w));
    uint64_t expected = (flags & kNodeValuedBit) ? 1 : 0;
    uint32_t rank = 0;
    for (uint32_t c = 0; c < 4; ++c) {
      if (!((flags >> c) & 1)) continue;
      const uint64_t at = uint64_t(w) + 1 + 2 * rank++;
      const uint32_t ref = st::load_le<uint32_t>(nodes + 4 * at);
      const uint32_t offset = st::load_le<uint32_t>(nodes + 4 * (at + 1));
      uint64_t child_count;
      if ((flags >> (kNodeTreeletShift + c)) & 1) {
        if (ref < T) child_count = dict->treelet_values(ref);
        else if (ref - T < h.treelet_count) child_count = treelet_values[ref - T];
        else fail("node child reference", node_byte(at), "treelet out of range");
      } else if (ref < D) {  // the dictionary's node
        child_count = dict->node_values(ref);
        if (child_count == 0) fail("node child reference", node_byte(at), "not a dictionary node's start");
      } else {
        const uint32_t local = ref - D;
        if (local <= w || local >= words || !is_start[local])
          fail("node child reference", node_byte(at), "not a later node's start");
        child_count = count[local];
      }
      if (offset != expected) fail("node value offset", node_byte(at + 1), "disagrees with the value counts");
      expected += child_count;
      if (child_count == 0) fail("node child reference", node_byte(at), "subtree without values");
    }
    if (expected > h.value_count) fail("node", node_byte(w), "subtree has more values than value_count");
    count[w] = uint32_t(expected);
  }
  // The root: valued, holding exactly value_count values; everything reachable from it.
  const uint32_t tag = h.root_ref & kRefTagMask, index = h.root_ref & kRefIndexMask;
  const uint32_t root_field = offsetof(Header, root_ref);
  std::vector<uint8_t> reached(words, 0), treelet_reached(h.treelet_count, 0);
  if (tag == kRefInner && index < D) {  // the whole structure is shared
    if (dict->node_values(index) == 0) fail("root_ref", root_field, "not a dictionary node's start");
    if (!(st::load_le<uint32_t>(dict->nodes() + 4 * size_t(index)) & kNodeValuedBit)) fail("root_ref", root_field, "root has no value");
    if (dict->node_values(index) != h.value_count) fail("root_ref", root_field, "root's values != value_count");
  } else if (tag == kRefInner) {
    const uint32_t local = index - D;
    if (local >= words || !is_start[local]) fail("root_ref", root_field, "not a node start");
    if (!(st::load_le<uint32_t>(nodes + 4 * size_t(local)) & kNodeValuedBit)) fail("root_ref", root_field, "root has no value");
    if (count[local] != h.value_count) fail("root_ref", root_field, "root's values != value_count");
    reached[local] = 1;
  } else if (tag == kRefTreelet && index < T) {
    if (!(dict->treelets()[size_t(index) * kTreeletBytes] & 1)) fail("root_ref", root_field, "root has no value");
    if (dict->treelet_values(index) != h.value_count) fail("root_ref", root_field, "root's values != value_count");
  } else if (tag == kRefTreelet) {
    const uint32_t local = index - T;
    if (local >= h.treelet_count) fail("root_ref", root_field, "treelet out of range");
    if (!(treelets[size_t(local) * kTreeletBytes] & 1)) fail("root_ref", root_field, "root has no value");
    if (treelet_values[local] != h.value_count) fail("root_ref", root_field, "root's values != value_count");
    treelet_reached[local] = 1;
  } else {
    fail("root_ref", root_field, "bad tag");
  }
  for (uint32_t w : starts) {
    if (!reached[w]) fail("node", node_byte(w), "unreachable from the root");
    const uint32_t flags = st::load_le<uint32_t>(nodes + 4 * size_t(w));
    uint32_t rank = 0;
    for (uint32_t c = 0; c < 4; ++c) {
      if (!((flags >> c) & 1)) continue;
      const uint32_t ref = st::load_le<uint32_t>(nodes + 4 * (size_t(w) + 1 + 2 * rank++));
      const bool treelet = (flags >> (kNodeTreeletShift + c)) & 1;
      const uint32_t below = treelet ? T : D;  // the dictionary's (checked above) below it
      if (ref >= below) (treelet ? treelet_reached : reached)[ref - below] = 1;
    }
  }
  for (uint32_t t = 0; t < h.treelet_count; ++t)
    if (!treelet_reached[t]) fail("treelet", s.treelets + uint64_t(t) * kTreeletBytes, "unreachable");
}

void check_chunks(const Header& h, const Sections& s, const uint8_t* base) {
  const uint64_t usable_bits = (s.end - s.multipliers - kMultiplierPadBytes) * 8;
  uint64_t last_bit = 0;
  for (uint32_t c = 0; c < s.chunk_count; ++c) {
    const uint64_t at = s.chunks + uint64_t(c) * sizeof(ChunkInfo);
    const ChunkInfo info = load_chunk(base + s.chunks, c);
    const uint32_t code = info.factor_code();
    if (code > kMaxFactorBits && code != kRawFactorCode)
      fail("chunk factor code", at + offsetof(ChunkInfo, packed), "not 0..24 or 31 (raw)");
    const uint32_t k = info.factor_bits();
    const uint64_t in_chunk = std::min<uint64_t>(kChunkValues, uint64_t(h.value_count) - uint64_t(c) * kChunkValues);
    if (in_chunk < kChunkValues && (info.mask >> in_chunk) != 0)
      fail("chunk mask", at + 4, "bits set past the last value");
    const uint64_t end = uint64_t(info.bit_offset()) + uint64_t(std::popcount(info.mask)) * k;
    if (end > usable_bits) fail("chunk bit_offset", at + offsetof(ChunkInfo, packed), "multipliers run past the multiplier section");
    last_bit = std::max(last_bit, end);
  }
  // The section is exactly what the multipliers need (whole words) plus the zero padding:
  // the buffer has no trailing bytes.
  const uint64_t need = align4((last_bit + 7) / 8) + kMultiplierPadBytes;
  if (s.end - s.multipliers != need)
    fail("multipliers", s.multipliers,
         "section of " + std::to_string(s.end - s.multipliers) + " bytes, the chunks need " + std::to_string(need) +
             " (no trailing bytes)");
}

void check_skip_table(const Header& h, const Sections& s, const View& view) {
  if (h.skip_level == 0) return;  // no table: lookups start at the root
  const uint64_t side = uint64_t(1) << h.skip_level;
  for (uint64_t y = 0; y < side; ++y)
    for (uint64_t x = 0; x < side; ++x) {
      const Cursor want = view.descend(view.root(), h.skip_level, h.skip_level, x, y);
      const Cursor got = view.skip_entry(h.skip_level, x, y);
      if (std::memcmp(&want, &got, sizeof(Cursor)) != 0)
        fail("skip entry", s.skip + (y * side + x) * kSkipEntryBytes, "disagrees with the DAG");
    }
}

}  // namespace

View validate(std::span<const uint8_t> bytes, const Dictionary* dict) {
  if (bytes.size() < sizeof(Header))
    fail("header", 0, "buffer of " + std::to_string(bytes.size()) + " bytes is shorter than the header");
  const Header h = load_header(bytes.data());
  const Sections s = check_header(h, bytes.size());
  const uint8_t* base = bytes.data();
  if (!(h.flags & kFlagDictionary)) {
    dict = nullptr;
  } else {
    if (!dict) fail("flags", offsetof(Header, flags), "the tile references a pack dictionary and none was given");
    if (dict->crc() != h.dictionary_crc)
      fail("dictionary_crc", offsetof(Header, dictionary_crc), "does not match the dictionary given");
    if (uint64_t(h.node_words) + dict->node_words() > kRefIndexMask ||
        uint64_t(h.treelet_count) + dict->treelet_count() > kRefIndexMask)
      fail("node_words", offsetof(Header, node_words), "with the dictionary's, exceeds 2^30");
  }
  check_structure(h, s, base, dict);
  check_chunks(h, s, base);
  View view;
  view.skip = base + s.skip;
  view.nodes = base + s.nodes;
  view.treelets = base + s.treelets;
  view.chunks = base + s.chunks;
  view.multipliers = base + s.multipliers;
  view.finest_level = h.finest_level;
  view.skip_level = h.skip_level;
  view.root_ref = h.root_ref;
  view.value_count = h.value_count;
  if (dict) {
    view.dict_node_words = dict->node_words();
    view.dict_treelet_count = dict->treelet_count();
    view.dict_nodes = dict->nodes();
    view.dict_treelets = dict->treelets();
  }
  check_skip_table(h, s, view);
  return view;
}

uint32_t Dictionary::treelet_values(uint32_t t) const {
  const uint8_t* p = treelets() + size_t(t) * kTreeletBytes;
  return uint32_t(std::popcount(st::load_le<uint64_t>(p)) + std::popcount(st::load_le<uint32_t>(p + 8)));
}

std::shared_ptr<const Dictionary> Dictionary::open(std::vector<uint8_t> bytes) {
  auto bad = [](const std::string& field, uint64_t offset, const std::string& what) {
    throw FormatError("dagmh dictionary: " + field + " at byte " + std::to_string(offset) + ": " + what);
  };
  if (bytes.size() < sizeof(DictHeader))
    bad("header", 0, "buffer of " + std::to_string(bytes.size()) + " bytes is shorter than the header");
  DictHeader h;
  std::memcpy(&h, bytes.data(), sizeof h);
  auto expect = [&](const char* name, uint32_t offset, uint64_t value, uint64_t want) {
    if (value != want) bad(name, offset, "is " + std::to_string(value) + ", expected " + std::to_string(want));
  };
  expect("magic", offsetof(DictHeader, magic), h.magic, kDictMagic);
  expect("version", offsetof(DictHeader, version), h.version, kDictVersion);
  expect("header_bytes", offsetof(DictHeader, header_bytes), h.header_bytes, sizeof(DictHeader));
  if (h.node_words > kRefIndexMask) bad("node_words", offsetof(DictHeader, node_words), "exceeds 2^30");
  if (h.treelet_count > kRefIndexMask) bad("treelet_count", offsetof(DictHeader, treelet_count), "exceeds 2^30");
  const uint64_t treelet_at = sizeof(DictHeader) + uint64_t(h.node_words) * 4;
  const uint64_t end = treelet_at + uint64_t(h.treelet_count) * kTreeletBytes;
  expect("node_offset", offsetof(DictHeader, node_offset), h.node_offset, sizeof(DictHeader));
  expect("treelet_offset", offsetof(DictHeader, treelet_offset), h.treelet_offset, treelet_at);
  expect("total_bytes", offsetof(DictHeader, total_bytes), h.total_bytes, end);
  if (end != bytes.size())
    bad("sections", end, "end at byte " + std::to_string(end) + " but the buffer has " + std::to_string(bytes.size()) + " bytes");
  auto d = std::make_shared<Dictionary>();
  d->node_words_ = h.node_words;
  d->treelet_count_ = h.treelet_count;
  d->bytes_ = std::move(bytes);
  const uint8_t* nodes = d->nodes();
  for (uint32_t t = 0; t < h.treelet_count; ++t)
    if (st::load_le<uint32_t>(d->treelets() + size_t(t) * kTreeletBytes + 8) >> (kTreeletNodes - 64))
      bad("treelet", treelet_at + uint64_t(t) * kTreeletBytes + 8, "bits past 85 set");
  std::vector<uint32_t> starts;
  for (uint32_t w = 0; w < h.node_words;) {
    const uint32_t flags = st::load_le<uint32_t>(nodes + 4 * size_t(w));
    const uint64_t at = sizeof(DictHeader) + 4 * uint64_t(w);
    const uint32_t mask = flags & kNodeChildMask;
    if (flags & ~kNodeFlagBits) bad("node flags", at, "reserved bits set");
    if (mask == 0) bad("node flags", at, "inner node without children");
    if ((flags >> kNodeTreeletShift) & ~mask & 0xF) bad("node flags", at, "treelet bit for an absent child");
    if (uint64_t(w) + dagmh::node_words(flags) > h.node_words) bad("node", at, "overruns the node section");
    starts.push_back(w);
    w += dagmh::node_words(flags);
  }
  // Value counts, children first (they lie after their parents): a start's count is >= 1,
  // every other word's 0, so node_values() also tells node starts.
  d->values_.assign(h.node_words, 0);
  for (size_t i = starts.size(); i-- > 0;) {
    const uint32_t w = starts[i];
    const uint32_t flags = st::load_le<uint32_t>(nodes + 4 * size_t(w));
    uint64_t expected = (flags & kNodeValuedBit) ? 1 : 0;
    uint32_t rank = 0;
    for (uint32_t c = 0; c < 4; ++c) {
      if (!((flags >> c) & 1)) continue;
      const uint64_t word = uint64_t(w) + 1 + 2 * rank++;
      const uint64_t at = sizeof(DictHeader) + 4 * word;
      const uint32_t ref = st::load_le<uint32_t>(nodes + 4 * word);
      uint64_t child;
      if ((flags >> (kNodeTreeletShift + c)) & 1) {
        if (ref >= h.treelet_count) bad("node child reference", at, "treelet out of range");
        child = d->treelet_values(ref);
      } else {
        if (ref <= w || ref >= h.node_words || d->values_[ref] == 0) bad("node child reference", at, "not a later node's start");
        child = d->values_[ref];
      }
      if (child == 0) bad("node child reference", at, "subtree without values");
      if (st::load_le<uint32_t>(nodes + 4 * (word + 1)) != expected)
        bad("node value offset", at + 4, "disagrees with the value counts");
      expected += child;
    }
    if (expected > 0xFFFFFFFFull) bad("node", sizeof(DictHeader) + 4 * uint64_t(w), "more than 2^32 values");
    d->values_[w] = uint32_t(expected);
  }
  d->crc_ = crc32_of(d->bytes_);
  return d;
}

}  // namespace st::dagmh
