#include "tiles/encode/stack_slices_encode.hpp"

#include <cstring>
#include <string>

#include "common/error.hpp"
#include "tiles/core/dagmh_format.hpp"
#include "tiles/core/mh_quadtree_format.hpp"
#include "tiles/encode/encode.hpp"
#include "tiles/encode/mh_build.hpp"
#include "tiles/core/pack_format.hpp"
#include "tiles/core/plane_pack.hpp"
#include "tiles/core/plane_tile.hpp"
#include "tiles/core/stack_slices.hpp"
#include "tiles/encode/tile_cut.hpp"

namespace st {
namespace {
// A slice whose plain tile (DAG-MH or MMH) deflates to at most this many bytes is kept as it
// is instead of fitted with planes: a plane tile holds a 24-byte header and 24 bytes a plane
// ahead of its inner tile, so it rarely deflates smaller. Measured on the demo's day (engine,
// 16 suns, 1024^2): the smallest plane slice deflates to 61 bytes; the 1,040 slices at or
// below 80 bytes, 43% of those fitted, took 8% of the fitting time and won 11 bytes in all.
constexpr size_t kPlaneSliceMinZlibBytes = 80;
}  // namespace

StackCells parse_stack_cells(const std::string& text) {
  if (text == "octree") return StackCells::octree;
  if (text == "slices") return StackCells::slices;
  if (text == "smaller") return StackCells::smaller;
  throw Error("--stack-cells: expected octree, slices or smaller, got '" + text + "'");
}

std::vector<uint8_t> encode_slice_tiles(std::span<const IntervalTile> slices, uint32_t m, uint32_t j,
                                        const PlaneFitOptions* planes, std::span<const uint8_t> plain) {
  const uint64_t count = uint64_t(1) << j;
  if (slices.size() > count) throw Error("slice tiles: " + std::to_string(slices.size()) + " slices for 2^" + std::to_string(j) + " entries");
  std::vector<uint8_t> out(kSliceTilesHeaderBytes + kSliceTilesEntryBytes * count, 0);
  auto put32 = [&](size_t at, uint32_t v) { std::memcpy(out.data() + at, &v, 4); };
  put32(0, kSliceTilesMagic);
  const uint16_t version = kSliceTilesVersion;
  std::memcpy(out.data() + 4, &version, 2);
  out[6] = uint8_t(m);
  out[7] = uint8_t(j);
  std::vector<std::pair<std::vector<uint8_t>, uint32_t>> seen;  // buffer, its offset (compared in full)
  // A 2D pack's tile codec, every candidate fitting (a cell's bound is the cut's business):
  // DAG-MH or MMH, whichever deflates smaller; with planes, plane tiles over either too.
  const TileCodec codec = planes ? TileCodec::with_planes(TileCodec::dagmh_or_mmh(true), UINT32_MAX, *planes)
                                 : TileCodec::dagmh_or_mmh(true);
  const bool reuse = planes && !plain.empty();
  if (reuse && (plain.size() < out.size() || std::memcmp(plain.data(), out.data(), 8) != 0))
    throw Error("slice tiles: the plain buffer given is not this cell's");
  auto plain32 = [&](size_t off) {
    uint32_t v;
    std::memcpy(&v, plain.data() + off, 4);
    return v;
  };
  for (uint64_t w = 0; w < count; ++w) {
    const size_t at = kSliceTilesHeaderBytes + kSliceTilesEntryBytes * w;
    if (w >= slices.size()) {
      const float lit = kLitDepth;
      uint32_t bits;
      std::memcpy(&bits, &lit, 4);
      put32(at + 4, bits);
      continue;
    }
    const IntervalTile& t = slices[w];
    if (t.width != (uint32_t(1) << m) || t.height != t.width || t.data.size() != uint64_t(t.width) * t.height)
      throw Error("slice tiles: slice " + std::to_string(w) + " is not 2^" + std::to_string(m) + " a side");
    std::vector<uint8_t> buf;
    bool kept = false;
    if (reuse) {
      // The plain cell's slice: a constant stays one, a tile too small for a plane tile to
      // store smaller is kept (kPlaneSliceMinZlibBytes), the rest encoded again with planes.
      const uint32_t off = plain32(at), word = plain32(at + 4);
      if (off == 0) {
        put32(at + 4, word);
        continue;
      }
      if (uint64_t(off) + word > plain.size()) throw Error("slice tiles: the plain buffer given is not this cell's");
      buf.assign(plain.begin() + off, plain.begin() + off + word);
      kept = zlib_compress(buf, kEncodingChoiceZlibLevel).size() <= kPlaneSliceMinZlibBytes;
    }
    if (!kept) {
      const Hierarchy h = build_hierarchy(t);
      const HNode& root = h.levels[0][0];
      if (!root.has_value) throw Error("slice tiles: internal error: slice " + std::to_string(w) + "'s root has no value");
      if (!root.child_mask) {
        uint32_t bits;
        std::memcpy(&bits, &root.value, 4);
        put32(at + 4, bits);
        continue;
      }
      buf = codec.encode_smaller(h);
    }
    size_t s = 0;
    while (s < seen.size() && seen[s].first != buf) ++s;
    if (s == seen.size()) {
      if (out.size() + buf.size() + 3 > 0xFFFFFFF0ull) throw Error("slice tiles: cell too large for one buffer");
      seen.emplace_back(buf, uint32_t(out.size()));
      out.insert(out.end(), buf.begin(), buf.end());
      out.resize((out.size() + 3) & ~size_t(3), 0);
    }
    put32(at, seen[s].second);
    put32(at + 4, uint32_t(buf.size()));
  }
  put32(8, uint32_t(out.size()));
  return out;
}

std::vector<uint8_t> group_slice_tiles(std::span<const uint8_t> b, bool predict_plane_labels) {
  const std::vector<uint8_t> same(b.begin(), b.end());
  if (!is_slice_tiles(b) || b.size() < kSliceTilesHeaderBytes || b[7] > 12) return same;
  auto u32 = [&](uint64_t off) {
    uint32_t v;
    std::memcpy(&v, b.data() + off, 4);
    return v;
  };
  const uint64_t count = uint64_t(1) << b[7];
  const uint64_t first = kSliceTilesHeaderBytes + kSliceTilesEntryBytes * count;
  if (first > b.size() || u32(8) != b.size()) return same;
  struct Buf {
    uint64_t off = 0, size = 0, head = 0, structure = 0;
    bool dagmh = false;
    std::vector<uint8_t> role;
    std::vector<uint8_t> packed;  // a plane slice: its packed form, stored whole among the heads
  };
  std::vector<Buf> bufs;
  uint64_t next = first;
  for (uint64_t w = 0; w < count; ++w) {
    const uint32_t off = u32(kSliceTilesHeaderBytes + kSliceTilesEntryBytes * w);
    const uint32_t word = u32(kSliceTilesHeaderBytes + kSliceTilesEntryBytes * w + 4);
    if (off == 0 || off < next) continue;
    if (off != next || word < 8 || uint64_t(off) + word > b.size()) return same;
    Buf f;
    f.off = off, f.size = word;
    const uint32_t magic = u32(off);
    if (magic == dagmh::kMagic && word >= 40) {
      const uint32_t S = b[off + 9];
      f.dagmh = true, f.head = 32;
      f.structure = (S ? uint64_t(16) << (2 * S) : 0) + 4 * uint64_t(u32(off + 16)) + 12 * uint64_t(u32(off + 20)) +
                    20 * ((uint64_t(u32(off + 24)) + 31) / 32);
      if (S > 6 || f.structure > word - f.head) return same;
    } else if (magic == mhq::kMagicMmh) {
      const uint32_t levels = b[off + 6];
      f.head = mhq::tree_offset(levels);
      if (levels < 1 || levels > mhq::kMaxLevels || word < f.head || (word - f.head) % 4) return same;
    } else if (is_plane_buffer(b.subspan(off, word))) {
      f.packed = pack_plane_tile(b.subspan(off, word), nullptr, predict_plane_labels);
      if (f.packed.size() != word) return same;
      f.head = word;
    } else {
      return same;
    }
    bufs.push_back(std::move(f));
    next = (uint64_t(off) + word + 3) & ~uint64_t(3);
  }
  if (next != b.size() || bufs.empty()) return same;  // constants only: nothing to group
  std::vector<uint8_t> out(b.begin(), b.begin() + first);
  out.reserve(b.size());
  const uint32_t magic = kGroupedSliceTilesMagic;
  std::memcpy(out.data(), &magic, 4);
  auto put = [&](uint64_t from, uint64_t n) { out.insert(out.end(), b.begin() + from, b.begin() + from + n); };
  for (const Buf& f : bufs) {
    if (!f.packed.empty()) out.insert(out.end(), f.packed.begin(), f.packed.end());
    else put(f.off, f.head);
  }
  for (const Buf& f : bufs)
    if (f.dagmh) put(f.off + f.head, f.structure);
  for (Buf& f : bufs) {
    if (f.dagmh || !f.packed.empty()) continue;
    const uint64_t tree = f.off + f.head;
    mmh_word_roles((f.size - f.head) / 4, b[f.off + mhq::kOffFlags] & mhq::kFlagRootLeaf, f.role, [&](uint64_t i) {
      put(tree + 4 * i, 4);
      return u32(tree + 4 * i);
    });
  }
  for (const Buf& f : bufs)
    if (f.dagmh) put(f.off + f.head + f.structure, f.size - f.head - f.structure);
  for (const Buf& f : bufs)
    for (uint64_t i = 0; i < f.role.size(); ++i)
      if (f.role[i] == 2) put(f.off + f.head + 4 * i, 4);
  if (out.size() > b.size()) return same;
  out.resize(b.size(), 0);
  // The permutation drops nothing only where every byte it leaves out is zero (padding):
  // undo it and compare, so a buffer that does not group is stored as it was.
  std::vector<uint8_t> back = out;
  try {
    ungroup_slice_tiles(back);
  } catch (const FormatError&) {
    return same;
  }
  return back == same ? out : same;
}

}  // namespace st
