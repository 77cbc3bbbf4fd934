// Where a shadow-map stack's bytes go, set against the same samples as separate DAG-MH
// packs, and how much of each slice's 2D DAG-MH repeats in its neighbours' (MH 2016 §4,
// DAG-MH 2021 §3.1; tiles/core/MHOCT.md "Stack against separate DAG-MH packs").
//
//   bench_stack_slices [--res 4k] [--samples 32] [--area-samples 64]
//                      [--case city|hairball|engine|demo|all] [--json PATH] [--spill-dir /tmp]
//                      [--bytes-only] [--dump-tiles DIR] [--adaptive] [--split-only] [--split-k 0,-1]
//                      [--no-planes] [--own-frames] [--slice-delta 4,8 [--delta-only]]
//
// Plane tiles (tiles/core/PLANES.md) are on for both sides, as `shadowtile build` makes
// them: the separate packs' tiles and the per-slice cells' slices; --no-planes: neither.
//
// --bytes-only skips the octree pack, the dictionary measure, the slices' own 2D tiles of
// the stack's cells, the whole-slice DAG-MH sections and the open values (those lines
// print 0); --dump-tiles writes the per-cell pack's raw tiles (STSL or STOC) to
// DIR/<cell>.bin for offline study. --adaptive estimates a cut that goes deeper
// only where a cell overflows (no such format yet): the uniform cuts at every level from the
// default K to the level the default pack ended at, with no tile bound, combined per cell.
// --split-only skips the uniform-cut pack (its lines print 0); --split-k writes the split
// pack at each listed shift of the default K (0: the default; -1: cells twice as large),
// each with its bytes per cell kind and section against the separate packs, and the same
// under other stored-tile codecs (bench/stored_codec.hpp: LZMA, zstd 19; every tile of the
// split pack and of the separate packs coded, decoded and compared), their decode speed,
// and the MMH value words' order-0 estimates raw and against three predictions.
//
// Per case every slice is traced into a spill (trace_stack_to_spill, as `shadowtile build`
// does), then:
//   separate packs: each slice written as the 2D pack `shadowtile build --encoding dagmh`
//     writes (DAG-MH tiles or MMH where smaller, the pack's own dictionary, zlib), file bytes;
//     and each slice's whole-map DAG-MH buffer's sections (dagmh::EncodeStats: inner nodes,
//     treelets, value chunks, multipliers, header and skip list).
//   stack pack: the out-of-core octree cut (BlockedStackCut) written as a stack pack, file
//     bytes; its tiles' raw bytes split into headers, node words (structure), value words and
//     far words (+ zero padding), by walking every tile as a reader does.
//   per-cell pack: the stack pack `shadowtile build` writes by default (--stack-cells
//     smaller): each cell its octree or its slices' own 2D tiles (stack_slices.hpp),
//     whichever stores smaller, file bytes; and the same cells with the per-slice cells
//     written as STSL instead of grouped (StackPackParams::group_slice_tiles off), and in
//     the journal layout (records, plain index, raw grid: payloads_only, compress_grid off).
//   open values: for the texels off each slice's most common interval (an open mesh's own
//     values), the mean bits of the bit pattern's residual against slice w-1's texel, the
//     left neighbour, the planar L + U - UL, and slice w-1's texel moved by the left step.
//   the slices' 2D tiles of the stack's default cells (split_hierarchy, each DAG-MH or
//     MMH, the smaller zlib stream, as the 2D packs choose), stored bytes.
//   repetition between neighbours: the share of slice w's 2D tiles (bytes) byte-equal to
//     slice w-1's in the same cell; the share of texels whose interval equals / meets
//     slice w-1's; and a DAG-MH dictionary (dagmh::share_across_tiles) over every slice's
//     DAG-MH tiles at once against one per slice (structure and treelets shared across
//     slices; values stay per tile).
// --own-frames also traces each sample as the sun alone, in its own box fitted to the scene
// (`shadowtile build --light sun:...`, as scripts/demo-day's separate packs), writes it as a
// 2D pack the same way, and prints per slice both frames' box side, ground area per texel,
// texels whose first hit stands above the ground, empty texels, tiles and bytes.
// --slice-delta N,...: every slice also kept in memory (32 x 8 B a texel), and every level-K
// cell written in delta-slice forms (a keyframe every N slices of the cell, the others as
// change sets: slice_delta_measure below) against the same cell with each slice its own
// tile; --delta-only traces and measures that alone (the packs' lines print 0).
// Cases: procedural:city under a day's sun (azimuth 100..260, elevation 25..65, ground
// frame), procedural:hairball under a 4 m x 4 m area light 25 m above it (window frame),
// and a real open mesh, assimp's 2CylinderEngine.glb, under the same day's sun; `demo`
// (not in `all`): scripts/demo-day's day, the engine on its ground quad under
// azimuth 90..270, elevation 25..60 (pass --samples 16 for the demo's stack).
#include <sys/resource.h>
#include <time.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <bit>
#include <unordered_map>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "bench/options.hpp"
#include "bench/stored_codec.hpp"
#include "common/error.hpp"
#include "scene/scene.hpp"
#include "tiles/bake/stack_build.hpp"
#include "tiles/encode/dagmh_dictionary.hpp"
#include "tiles/encode/dagmh_encode.hpp"
#include "tiles/encode/encode.hpp"
#include "tiles/encode/mh_build.hpp"
#include "tiles/encode/pack_writer.hpp"
#include "tiles/encode/stack_blocked.hpp"
#include "tiles/encode/stack_pack.hpp"
#include "tiles/encode/stack_slices_encode.hpp"
#include "tiles/core/pack_reader.hpp"
#include "tiles/encode/tile_cut.hpp"
#include "tiles/core/dagmh_format.hpp"
#include "tiles/core/mh_quadtree_format.hpp"
#include "tiles/core/pack_format.hpp"
#include "tiles/core/resolution.hpp"
#include "tiles/core/stack_slices.hpp"

namespace {

using Clock = std::chrono::steady_clock;
double since(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

struct Case {
  std::string name, scene, light;
};

// An MH octree buffer's raw bytes by role (MHOCT.md "Header", "Tree words", "Far words").
struct OctBytes {
  uint64_t header = 0, node = 0, value = 0, far = 0, pad = 0;
  uint64_t total() const { return header + node + value + far + pad; }
};

void add_octree_bytes(const std::vector<uint8_t>& b, OctBytes& out) {
  auto u32 = [&](uint64_t off) {
    uint32_t v;
    std::memcpy(&v, b.data() + off, 4);
    return v;
  };
  const uint32_t n = b[6], k = b[7], L = std::max(n, k) + 1;
  const uint64_t T = 20 + ((uint64_t(L) + 3) & ~uint64_t(3));
  const uint64_t words = (b.size() - T) / 4;
  std::vector<uint8_t> role(words, 0);  // 1 node, 2 value, 3 far
  struct Item {
    uint64_t p;
    uint32_t level, kind;
  };
  std::vector<Item> todo{{0, 0, (b[10] & 1) ? 1u : 3u}};
  while (!todo.empty()) {
    const Item it = todo.back();
    todo.pop_back();
    if (it.kind == 1) {
      role[it.p] = 2;
      continue;
    }
    if (role[it.p] == 1) continue;  // a shared block's node reached again
    role[it.p] = 1;
    if (it.kind == 3) role[it.p + 1] = 2;
    const uint32_t word = u32(T + 4 * it.p), mask = word & 0xffffu;
    const int32_t off = int16_t(uint16_t(word >> 16));
    uint64_t block;
    if (off <= -32737) {
      const uint64_t fw = it.p + 1 + uint64_t(off + 32768);
      role[fw] = 3;
      block = u32(T + 4 * fw);
    } else {
      const uint32_t s = b[20 + it.level];
      block = uint64_t((int64_t(it.p >> s) + off) << s);
    }
    for (uint32_t c = 0; c < 8; ++c) {
      const uint32_t kind = (mask >> (2 * c)) & 3u;
      if (!kind) continue;
      const uint64_t at = block + uint64_t(__builtin_popcount(mask & ((1u << (2 * c)) - 1)));
      todo.push_back({at, it.level + 1, kind == 2 ? 2u : kind});
    }
  }
  out.header += T;
  for (uint8_t r : role) (r == 1 ? out.node : r == 2 ? out.value : r == 3 ? out.far : out.pad) += 4;
}

// A per-slice cell's raw bytes by section, in the grouped layout's order (STSP,
// stack_slices.hpp): STSL header and entries, 2D heads, DAG-MH structure, MMH node words,
// DAG-MH multipliers, MMH values, zero bytes. Empty when `b` is not a per-slice cell.
// Plane tiles on both sides (off: --no-planes): the separate packs' tiles and the stack's
// per-slice cells' slices, as `shadowtile build` makes them by default.
bool g_planes = true;
std::optional<st::PlaneFitOptions> stack_planes() {
  return g_planes ? std::optional<st::PlaneFitOptions>(st::PlaneFitOptions{}) : std::nullopt;
}

std::vector<uint64_t> slice_cell_sections(const std::vector<uint8_t>& b) {
  if (!st::is_slice_tiles(b) || b.size() < st::kSliceTilesHeaderBytes) return {};
  auto u32 = [&](uint64_t off) {
    uint32_t v;
    std::memcpy(&v, b.data() + off, 4);
    return v;
  };
  std::vector<uint64_t> sec(7, 0);
  const uint64_t count = uint64_t(1) << b[7];
  const uint64_t first = st::kSliceTilesHeaderBytes + st::kSliceTilesEntryBytes * count;
  sec[0] = first;
  uint64_t next = first;
  std::vector<uint8_t> role;
  for (uint64_t w = 0; w < count; ++w) {
    const uint32_t off = u32(st::kSliceTilesHeaderBytes + st::kSliceTilesEntryBytes * w);
    const uint32_t size = u32(st::kSliceTilesHeaderBytes + st::kSliceTilesEntryBytes * w + 4);
    if (off == 0 || off < next) continue;
    if (u32(off) == 0x4E505453u) {  // a plane slice ("STPN"): grouped whole among the heads
      sec[1] += size;
    } else if (u32(off) == st::dagmh::kMagic) {
      const uint32_t S = b[off + 9];
      const uint64_t structure = (S ? uint64_t(16) << (2 * S) : 0) + 4 * uint64_t(u32(off + 16)) +
                                 12 * uint64_t(u32(off + 20)) + 20 * ((uint64_t(u32(off + 24)) + 31) / 32);
      sec[1] += 32, sec[2] += structure, sec[4] += size - 32 - structure;
    } else {
      const uint64_t head = st::mhq::tree_offset(b[off + 6]);
      sec[1] += head;
      st::mmh_word_roles((size - head) / 4, b[off + st::mhq::kOffFlags] & st::mhq::kFlagRootLeaf, role, [&](uint64_t i) {
        return u32(off + head + 4 * i);
      });
      for (uint8_t r : role) sec[r == 1 ? 3 : r == 2 ? 5 : 6] += 4;
    }
    next = (uint64_t(off) + size + 3) & ~uint64_t(3);
  }
  uint64_t sum = 0;
  for (uint64_t v : sec) sum += v;
  sec[6] += b.size() - sum;  // buffer padding
  return sec;
}

// ---- Stored-tile codecs (bench/stored_codec.hpp; MHOCT.md "Stored-tile codecs against zlib")
// Codec c: 0 zlib (level 6, as packs store tiles), 1 lzma, 2 zstd 19. A tile's bytes under
// codec c are the smaller of its zlib stream and the codec's stream + 1 byte (the form a
// per-tile stored form would record), so no codec makes a tile larger than today.
constexpr size_t kCodecs = 3;
const char* const kCodecName[kCodecs] = {"zlib 6", "lzma", "zstd 19"};
using CodecBytes = std::array<uint64_t, kCodecs>;

double thread_seconds() {
  timespec t{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &t);
  return double(t.tv_sec) + 1e-9 * double(t.tv_nsec);
}

// Decode CPU seconds per codec over the tiles measured with timing, and their raw bytes.
struct CodecDecode {
  std::array<double, kCodecs> seconds{};
  uint64_t raw = 0;
};

// `raw`: the tile's stored-form raw bytes (what the pack deflates: a grouped per-slice cell
// as STSP); `zlib`: its zlib stream. Every codec's stream is decoded and compared with `raw`
// (throws on a mismatch); with `dec`, each decode is timed (thread CPU time).
CodecBytes codec_bytes(std::span<const uint8_t> raw, std::span<const uint8_t> zlib, CodecDecode* dec) {
  CodecBytes out{};
  out[0] = zlib.size();
  std::vector<uint8_t> back(raw.size());
  auto timed = [&](size_t c, auto&& decode) {
    std::fill(back.begin(), back.end(), uint8_t(0xA5));
    const double t0 = thread_seconds();
    decode();
    if (dec) dec->seconds[c] += thread_seconds() - t0;
    if (!std::equal(back.begin(), back.end(), raw.begin())) throw st::Error(std::string(kCodecName[c]) + ": round trip differs");
  };
  timed(0, [&] { st::zlib_decompress_into(zlib, back, "bench tile"); });
#if ST_BENCH_LZMA
  const std::vector<uint8_t> lz = st::bench::lzma_tile_compress(raw);
  timed(1, [&] { st::bench::lzma_tile_decompress_into(lz, back); });
  out[1] = std::min<uint64_t>(zlib.size(), lz.size() + 1);
#else
  out[1] = zlib.size();  // built without liblzma: the column equals zlib's
#endif
  const std::vector<uint8_t> zs = st::bench::zstd_tile_compress(raw);
  timed(2, [&] { st::bench::zstd_tile_decompress_into(zs, back); });
  out[2] = std::min<uint64_t>(zlib.size(), zs.size() + 1);
  if (dec) dec->raw += raw.size();
  return out;
}

void add_codec(CodecBytes& to, const CodecBytes& b) {
  for (size_t c = 0; c < kCodecs; ++c) to[c] += b[c];
}

// What an entropy coder of MMH value words could take (adaptive order-0 per byte position,
// reset per tile, st::bench::WordCost): the value words of every MMH buffer of a per-slice
// cell, raw and as the xor of their bit patterns with three predictions: the previous value
// word of the tree (word order), the nearest valued ancestor's stored word, and the previous
// value in the same child block (else raw). MMH values are already relative to that
// ancestor (MHQUAD.md "Values and lookups"), which is why none of these predicts much.
struct ValueCosts {
  uint64_t words = 0;
  std::array<double, 4> bits{};  // raw, previous word, ancestor, previous sibling
};
const char* const kValuePredictor[4] = {"raw", "xor previous value word", "xor ancestor's stored value",
                                        "xor previous sibling"};

void mmh_value_costs(std::span<const uint8_t> b, ValueCosts& out) {
  if (!st::is_slice_tiles(b) || b.size() < st::kSliceTilesHeaderBytes || b[7] > 12) return;
  auto u32 = [&](uint64_t off) {
    uint32_t v;
    std::memcpy(&v, b.data() + off, 4);
    return v;
  };
  std::array<st::bench::WordCost, 4> cost;
  const uint64_t count = uint64_t(1) << b[7];
  uint64_t next = st::kSliceTilesHeaderBytes + st::kSliceTilesEntryBytes * count;
  for (uint64_t w = 0; w < count; ++w) {
    const uint32_t off = u32(st::kSliceTilesHeaderBytes + st::kSliceTilesEntryBytes * w);
    const uint32_t size = u32(st::kSliceTilesHeaderBytes + st::kSliceTilesEntryBytes * w + 4);
    if (off == 0 || off < next) continue;
    next = (uint64_t(off) + size + 3) & ~uint64_t(3);
    if (u32(off) != st::mhq::kMagicMmh) continue;
    const uint64_t head = st::mhq::tree_offset(b[off + 6]), W = (size - head) / 4, tree = off + head;
    const bool root_leaf = b[off + st::mhq::kOffFlags] & st::mhq::kFlagRootLeaf;
    // Forward scan as mmh_word_roles (stack_slices.hpp): role 1 node word, 2 value word;
    // anc: a node's or value's nearest valued ancestor's value word; own: a node's value word.
    std::vector<uint8_t> role(W, 0);
    std::vector<int64_t> anc(W, -1), own(W, -1), sib(W, -1);
    if (W == 0) continue;
    role[0] = root_leaf ? 2 : 1;
    if (!root_leaf && W > 1) role[1] = 2, own[0] = 1;
    uint32_t prev = 0;
    for (uint64_t i = 0; i < W; ++i) {
      if (role[i] == 1) {
        const uint32_t word = u32(tree + 4 * i), mask = word & 0xFFu, shift = (word >> 12) & 0xFu, o = word >> 16;
        const int64_t valued = own[i] >= 0 ? own[i] : anc[i];
        uint64_t at = ((i >> shift) + o) << shift;
        int64_t last = -1;
        for (uint32_t c = 0; c < 4; ++c) {
          const uint32_t code = (mask >> (2 * c)) & 3u;
          if (code == 0) continue;
          if (at > i && at < W && role[at] == 0) {
            role[at] = code == 1 ? 2 : 1, anc[at] = valued;
            if (code == 1) sib[at] = last, last = int64_t(at);
            if (code == 3 && at + 1 < W && role[at + 1] == 0)
              role[at + 1] = 2, anc[at + 1] = valued, own[at] = int64_t(at + 1), sib[at + 1] = last, last = int64_t(at + 1);
          }
          at += code == 3 ? 2 : 1;
        }
      } else if (role[i] == 2) {
        const uint32_t v = u32(tree + 4 * i);
        ++out.words;
        cost[0].code(v);
        cost[1].code(v ^ prev);
        cost[2].code(anc[i] >= 0 ? v ^ u32(tree + 4 * uint64_t(anc[i])) : v);
        cost[3].code(sib[i] >= 0 ? v ^ u32(tree + 4 * uint64_t(sib[i])) : v);
        prev = v;
      }
    }
  }
  for (size_t j = 0; j < 4; ++j) out.bits[j] += cost[j].bits;
}

// Where a stack pack's bytes go, per cell kind and section, against the separate 2D packs'
// bytes of the same squares and slices (the stack's level-K cells). `sq` is each slice's
// stored bytes per level-K square (the bench's 2D tiles of the stack's cells) scaled to
// the separate packs' file bytes.
struct KindBytes {
  uint64_t tiles = 0, raw = 0, stored = 0, cells = 0;
  double separate = 0;                       // the separate packs' bytes for those cells
  CodecBytes codec{}, separate_codec{};      // stored under each codec (codec_bytes), stack and separate
  std::vector<uint64_t> sec_raw, sec_stored;  // sections (octree: header, node, value, far, pad)
};

// The codec tables of one split pack: per level-K cell kind and codec its tiles' stored
// bytes against the separate packs' tiles of the same squares and slices, under zlib and
// under the same codec; the whole files; decode speed; the per-slice sections under lzma
// alone; the MMH value words' estimates (ValueCosts).
nlohmann::json print_codec_tables(const std::vector<KindBytes>& kinds, const char* const* kind_name,
                                  const CodecBytes& tiles_codec, uint64_t file, const CodecBytes& packs_tiles_codec,
                                  uint64_t packs_bytes, const CodecDecode& stack_decode, const CodecDecode& packs_decode,
                                  const std::vector<uint64_t>& sec_lzma, const char* const* sec_name, const ValueCosts& vc) {
  nlohmann::json out = nlohmann::json::object();
  std::printf("  stored-tile codecs (bench/stored_codec.hpp; each tile the smaller of its zlib stream and the codec's + 1 "
              "byte, the separate packs' tiles the same)%s:\n",
              ST_BENCH_LZMA ? "" : " [built without liblzma: lzma = zlib]");
  std::printf("  | level-K cells | codec | stored | separate, same codec | separate, zlib | / separate zlib | / separate same codec |\n");
  std::printf("  | --- | --- | ---: | ---: | ---: | ---: | ---: |\n");
  nlohmann::json kj = nlohmann::json::object();
  for (size_t j = 0; j < kinds.size(); ++j) {
    const KindBytes& kb = kinds[j];
    if (kb.tiles == 0) continue;
    for (size_t c = 0; c < kCodecs; ++c) {
      const double sep = double(kb.separate_codec[c]), sep0 = double(kb.separate_codec[0]);
      std::printf("  | %s | %s | %llu | %.0f | %.0f | %.3f | %.3f |\n", kind_name[j], kCodecName[c],
                  (unsigned long long)kb.codec[c], sep, sep0, sep0 > 0 ? double(kb.codec[c]) / sep0 : 0.0,
                  sep > 0 ? double(kb.codec[c]) / sep : 0.0);
      kj[kind_name[j]][kCodecName[c]] = {{"stored", kb.codec[c]}, {"separate_same_codec", sep}, {"separate_zlib", sep0}};
    }
  }
  out["kinds"] = kj;
  nlohmann::json wj = nlohmann::json::object();
  for (size_t c = 0; c < kCodecs; ++c) {
    const uint64_t stack = file - tiles_codec[0] + tiles_codec[c];
    const uint64_t sep = packs_bytes - packs_tiles_codec[0] + packs_tiles_codec[c];
    std::printf("  | whole files (grid, index, dictionaries as stored) | %s | %llu | %llu | %llu | %.3f | %.3f |\n",
                kCodecName[c], (unsigned long long)stack, (unsigned long long)sep, (unsigned long long)packs_bytes,
                double(stack) / double(packs_bytes), double(stack) / double(sep));
    wj[kCodecName[c]] = {{"stack", stack}, {"separate_same_codec", sep}, {"separate_zlib", packs_bytes}};
  }
  out["whole_files"] = wj;
  auto mbs = [](const CodecDecode& d, size_t c) { return d.seconds[c] > 0 ? double(d.raw) / d.seconds[c] / 1e6 : 0.0; };
  std::printf("  decode, raw MB/s of thread CPU time (each tile decoded once): stack tiles (%.1f MB) zlib %.0f, lzma %.0f, "
              "zstd %.0f; separate packs' tiles (%.1f MB) zlib %.0f, lzma %.0f, zstd %.0f\n",
              double(stack_decode.raw) / 1e6, mbs(stack_decode, 0), mbs(stack_decode, 1), mbs(stack_decode, 2),
              double(packs_decode.raw) / 1e6, mbs(packs_decode, 0), mbs(packs_decode, 1), mbs(packs_decode, 2));
  out["decode_mb_s"] = {{"stack", {mbs(stack_decode, 0), mbs(stack_decode, 1), mbs(stack_decode, 2)}},
                        {"separate", {mbs(packs_decode, 0), mbs(packs_decode, 1), mbs(packs_decode, 2)}}};
  std::printf("  per-slice sections, lzma alone:");
  for (size_t j = 0; j < sec_lzma.size(); ++j) std::printf(" %s %llu;", sec_name[j], (unsigned long long)sec_lzma[j]);
  std::printf("\n  MMH value words of per-slice cells (%llu): adaptive order-0 bits a word (per byte position, reset per "
              "tile):",
              (unsigned long long)vc.words);
  nlohmann::json vj = nlohmann::json::object();
  for (size_t j = 0; j < vc.bits.size(); ++j) {
    const double b = vc.words ? vc.bits[j] / double(vc.words) : 0.0;
    std::printf(" %s %.2f;", kValuePredictor[j], b);
    vj[kValuePredictor[j]] = b;
  }
  std::printf("\n");
  out["mmh_value_bits_per_word"] = vj;
  out["mmh_value_words"] = vc.words;
  return out;
}

double peak_rss_mib() {
  rusage ru{};
  getrusage(RUSAGE_SELF, &ru);
  return double(ru.ru_maxrss) / 1024.0;
}

// One slice's 2D map in one frame: its light box, the ground area one texel covers, the
// texels whose first hit stands above the ground (the occluder's own texels) and the
// texels that hit nothing, and its 2D pack's bytes and tiles (--own-frames).
struct SliceFrame {
  double side = 0, ground_area = 0;
  uint64_t above = 0, empty = 0, bytes = 0, tiles = 0;
};
struct SliceRow {
  double azimuth = 0, elevation = 0;
  SliceFrame ground, own;  // the stack's frame (its slice as a 2D pack); the sun's own box
};

// The ground area of one texel: a ground-frame texel is a square of the ground; a sun's
// texel (a square across the sun's rays) falls on level ground as a strip 1 / sin E long.
SliceFrame measure_slice(const st::LightSpace& l, const st::IntervalTile& t, uint32_t level, double ground, uint64_t bytes,
                         size_t tiles) {
  SliceFrame f;
  const double R = double(uint64_t(1) << level), e = l.extent_uv() / R;
  f.side = l.extent_uv();
  f.ground_area = l.kind() == st::LightKind::sun_ground ? e * e : e * e / std::abs(l.forward().y);
  f.bytes = bytes, f.tiles = tiles;
  for (uint32_t j = 0; j < t.height; ++j)
    for (uint32_t i = 0; i < t.width; ++i) {
      const st::Interval iv = t.at(i, j);
      if (iv.lo == st::kLitDepth) {
        ++f.empty;
        continue;
      }
      const st::Vec3d p = l.to_world((double(t.x0 + i) + 0.5) / R, (double(t.y0 + j) + 0.5) / R, double(iv.lo));
      f.above += p.y > ground + 1e-3 * l.extent_uv();
    }
  return f;
}

// ---- Delta slices (--slice-delta; MHOCT.md "Delta slices: the per-texel repetition, measured")
// A concrete exact form of a per-slice cell that stores a slice as a change set over the
// slices before it: within a cell's slices, every N-th slice (local 0, N, 2N, ...) is a
// keyframe, stored as today (its own 2D DAG-MH or MMH tile of the cell); any other slice s
// stores (1) a change bit per texel and (2) its own 2D tile over the changed texels only,
// the unchanged ones given the whole depth range [lo, hi] of the cell (any value answers
// for them, so MH §3.1's merge takes them with their neighbours). A texel unchanged at s
// answers what it answered at s - 1, so a lookup at slice s reads the texel's change bits
// of its keyframe group, takes the last slice r <= s whose bit is set (or the keyframe) and
// walks slice r's tile: one walk, whatever the chain. The change bits are stored as one
// column per texel (N - 1 bits, byte-aligned, the cell's texels in Morton order): one load
// gives the whole chain. Also measured: the same bits as one bitmap a non-key slice (Morton
// order) after the tiles instead of the columns (a lookup then tests up to N - 1 bits).
// Criteria for "unchanged" (each measured, each also in a "+marker" form, kDeltaMarker):
//   prev   interval equal to slice s - 1's (the measured 58-89%);
//   runs   a texel's run of slices keeps one value while the intersection of their intervals
//          is not empty: the run's first slice gets that intersection (narrowed; any value
//          in it lies in every interval of the run), the others the whole range;
//   key    interval equal to the keyframe's (no chain: one bit, one walk).
// Each variant's cell is written as real bytes: the STSL buffer of its (partly wildcard)
// slices, grouped (STSP) as the pack stores it, followed by the change columns, deflated as
// one zlib stream (level 6); the base is the same cell with every slice its own tile.
// The construction is checked per texel: the interval a lookup reaches contains the slice's
// own interval's answer set (resolved interval subset of the slice's interval).
struct DeltaVariant {
  std::string name;
  int crit = 0;  // 0 prev, 1 runs, 2 key
  uint32_t N = 8;
  uint64_t raw = 0, stored = 0, tiles_stored = 0, cols_stored = 0, changed = 0, texels = 0, max_raw = 0;
  uint64_t planar_stored = 0, planar_alone = 0;  // the change bits as one bitmap a slice instead of columns
  double ctx_bits = 0;  // the change bits under an adaptive context model (an estimate: no such coder built)
  uint64_t hit = 0, hit_changed = 0;  // of the non-key texels, those that hit something (lo != kLitDepth)
  double seconds = 0;
};

const char* const kDeltaCriterion[6] = {"prev", "runs", "key", "prev+marker", "runs+marker", "key+marker"};
// The "+marker" forms store no change columns: an unchanged texel holds this interval in its
// slice's tile (a depth no texel has: depths lie in [0, 1]), and a lookup that reads it walks
// the slice the criterion names (s - 1, or the keyframe) next: a chain of walks.
constexpr st::Interval kDeltaMarker{2.0f, 2.0f};

uint64_t morton2(uint64_t x, uint64_t y) {
  uint64_t r = 0;
  for (uint32_t b = 0; b < 32; ++b) r |= ((x >> b) & 1u) << (2 * b) | ((y >> b) & 1u) << (2 * b + 1);
  return r;
}

nlohmann::json slice_delta_measure(const std::vector<st::IntervalTile>& all, const st::moct::Geometry& g, uint32_t K,
                                   const std::vector<uint32_t>& keyframe_every) {
  const uint32_t a = g.xy_bits(K), m = g.n - a, j = g.k - g.w_bits(K);
  const uint64_t cs = uint64_t(1) << m, W = uint64_t(1) << j, cells_x = uint64_t(1) << a, side = uint64_t(1) << g.n;
  const uint64_t T = cs * cs, groups = (all.size() + W - 1) / W;
  std::vector<DeltaVariant> vars;
  for (uint32_t N : keyframe_every) {
    N = uint32_t(std::min<uint64_t>(std::max<uint32_t>(N, 2), W));
    for (int crit = 0; crit < 6; ++crit)
      vars.push_back({std::string(kDeltaCriterion[crit]) + " N=" + std::to_string(N), crit, N});
  }
  uint64_t base_raw = 0, base_stored = 0, base_max_raw = 0, cells = 0, slices_total = 0;
  double base_s = 0;
  std::vector<uint32_t> morton(T);
  for (uint64_t y = 0; y < cs; ++y)
    for (uint64_t x = 0; x < cs; ++x) morton[y * cs + x] = uint32_t(morton2(x, y));
  auto time_of = [](Clock::time_point t0) { return since(t0); };
  for (uint64_t cy = 0; cy < cells_x; ++cy)
    for (uint64_t cx = 0; cx < cells_x; ++cx)
      for (uint64_t cw = 0; cw < groups; ++cw) {
        std::vector<st::IntervalTile> S;
        float lo = st::kLitDepth, hi = st::kLitDepth;
        for (uint64_t s = cw * W; s < std::min<uint64_t>(all.size(), (cw + 1) * W); ++s) {
          st::IntervalTile t;
          t.level = m;
          t.width = t.height = uint32_t(cs);
          t.data.resize(T);
          for (uint64_t ty = 0; ty < cs; ++ty)
            for (uint64_t tx = 0; tx < cs; ++tx) {
              const st::Interval iv = all[s].data[(cy * cs + ty) * side + cx * cs + tx];
              t.data[ty * cs + tx] = iv;
              lo = std::min(lo, iv.lo), hi = std::max(hi, iv.hi);
            }
          S.push_back(std::move(t));
        }
        const st::Interval wild{lo, hi};
        ++cells, slices_total += S.size();
        auto t0 = Clock::now();
        const std::vector<uint8_t> base = st::group_slice_tiles(st::encode_slice_tiles(S, m, j));
        base_raw += base.size(), base_max_raw = std::max<uint64_t>(base_max_raw, base.size());
        base_stored += st::zlib_compress(base, 6).size();
        base_s += time_of(t0);
        for (DeltaVariant& v : vars) {
          t0 = Clock::now();
          std::vector<st::IntervalTile> D = S;
          const bool marked = v.crit >= 3;  // unchanged texels marked in the tile, no change columns
          const int crit = v.crit % 3;
          const uint64_t bpt = (v.N - 1 + 7) / 8;  // change-column bytes a texel, per keyframe group
          const uint64_t key_groups = (S.size() + v.N - 1) / v.N;
          std::vector<uint8_t> cols(marked ? 0 : key_groups * T * bpt, 0);
          const uint64_t bmp = (T + 7) / 8;  // one bitmap a non-key slice, Morton order
          std::vector<uint8_t> planar(marked ? 0 : (S.size() - key_groups) * bmp, 0);
          for (uint64_t t = 0; t < T; ++t) {
            uint64_t run = 0;  // the slice whose tile answers the current run
            st::Interval R = S[0].data[t];
            auto close_run = [&] { D[run].data[t] = R; };
            for (uint64_t s = 0; s < S.size(); ++s) {
              const st::Interval iv = S[s].data[t];
              const uint64_t key = s - s % v.N;
              bool same;
              if (s == key) same = false;
              else if (crit == 0) same = iv == S[s - 1].data[t];
              else if (crit == 2) same = iv == S[key].data[t];
              else same = std::max(R.lo, iv.lo) <= std::min(R.hi, iv.hi);
              if (!same) {
                if (crit == 1) close_run();
                run = s, R = iv;
                if (s != key) {
                  const uint64_t bit = s - key - 1;
                  if (!marked) {
                    cols[((key / v.N) * T + morton[t]) * bpt + bit / 8] |= uint8_t(1u << (bit % 8));
                    planar[(s - s / v.N - 1) * bmp + morton[t] / 8] |= uint8_t(1u << (morton[t] % 8));
                  }
                  ++v.changed;
                }
              } else {
                if (crit == 1) R = {std::max(R.lo, iv.lo), std::min(R.hi, iv.hi)};
                D[s].data[t] = marked ? kDeltaMarker : wild;
              }
              v.texels += s != key;
              if (s != key && iv.lo != st::kLitDepth) ++v.hit, v.hit_changed += !same;
            }
            if (crit == 1) close_run();
            // Check the construction: what a lookup of (t, s) reaches lies in S[s]'s interval.
            for (uint64_t s = 0; s < S.size(); ++s) {
              const uint64_t key = s - s % v.N;
              uint64_t r = s;
              if (marked) {
                while (r != key && D[r].data[t] == kDeltaMarker) r = crit == 2 ? key : r - 1;
              } else if (crit == 2) {
                const uint64_t bit = s - key - 1;
                if (s != key && !(cols[((key / v.N) * T + morton[t]) * bpt + bit / 8] >> (bit % 8) & 1u)) r = key;
              } else {
                while (r != key) {
                  const uint64_t bit = r - key - 1;
                  if (cols[((key / v.N) * T + morton[t]) * bpt + bit / 8] >> (bit % 8) & 1u) break;
                  --r;
                }
              }
              const st::Interval got = D[r].data[t], want = S[s].data[t];
              if (!(want.lo <= got.lo && got.hi <= want.hi))
                throw st::Error("slice delta " + v.name + ": texel " + std::to_string(t) + " slice " + std::to_string(s) +
                                " resolves to slice " + std::to_string(r) + " outside its interval");
            }
          }
          const std::vector<uint8_t> tiles = st::group_slice_tiles(st::encode_slice_tiles(D, m, j));
          std::vector<uint8_t> raw = tiles;
          raw.insert(raw.end(), cols.begin(), cols.end());
          v.raw += raw.size(), v.max_raw = std::max<uint64_t>(v.max_raw, raw.size());
          v.stored += st::zlib_compress(raw, 6).size();
          v.tiles_stored += st::zlib_compress(tiles, 6).size();
          v.cols_stored += cols.empty() ? 0 : st::zlib_compress(cols, 6).size();
          if (!marked) {
            std::vector<uint8_t> alt = tiles;
            alt.insert(alt.end(), planar.begin(), planar.end());
            v.planar_stored += st::zlib_compress(alt, 6).size();
            v.planar_alone += st::zlib_compress(planar, 6).size();
            // An adaptive binary model of the bits, reset per cell: context = the left, upper
            // and upper-left bits of the same slice and the same texel's bit one slice earlier
            // (0 at a keyframe's first follower); KT counts; the ideal code length.
            auto bit = [&](uint64_t idx, uint64_t x, uint64_t y) {
              const uint32_t mo = morton[y * cs + x];
              return uint32_t(planar[idx * bmp + mo / 8] >> (mo % 8) & 1u);
            };
            std::array<std::array<double, 2>, 16> cnt{};
            double bits = 0;
            for (uint64_t s = 0; s < S.size(); ++s) {
              if (s % v.N == 0) continue;
              const uint64_t idx = s - s / v.N - 1;
              const bool first = s % v.N == 1;
              for (uint64_t y = 0; y < cs; ++y)
                for (uint64_t x = 0; x < cs; ++x) {
                  const uint32_t c = (x ? bit(idx, x - 1, y) : 0u) | (y ? bit(idx, x, y - 1) : 0u) << 1 |
                                     (x && y ? bit(idx, x - 1, y - 1) : 0u) << 2 | (first ? 0u : bit(idx - 1, x, y)) << 3;
                  const uint32_t b = bit(idx, x, y);
                  bits -= std::log2((cnt[c][b] + 0.5) / (cnt[c][0] + cnt[c][1] + 1.0));
                  cnt[c][b] += 1;
                }
            }
            v.ctx_bits += std::ceil(bits / 8.0) * 8.0;
          }
          v.seconds += time_of(t0);
        }
      }
  std::printf("  delta slices over every level-K cell (K = %u: %llu cells of %llu^2 texels x %llu slices; no plane tiles either "
              "side; one zlib stream a cell):\n",
              K, (unsigned long long)cells, (unsigned long long)cs, (unsigned long long)W);
  std::printf("  | form | changed texels | of those that hit | raw | max cell raw | stored | tiles alone | change columns alone | / base | stored, bitmaps a slice | bitmaps alone | / base | bits, context model (estimate) | tiles + that / base | encode s |\n");
  std::printf("  | --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |\n");
  std::printf("  | base: each slice its own tile | | | %llu | %llu | %llu | | | 1.000 | | | | | | %.1f |\n", (unsigned long long)base_raw,
              (unsigned long long)base_max_raw, (unsigned long long)base_stored, base_s);
  nlohmann::json out = {{"K", K}, {"cells", cells}, {"cell_side", cs}, {"cell_slices", W},
                        {"base", {{"raw", base_raw}, {"stored", base_stored}, {"max_cell_raw", base_max_raw}, {"seconds", base_s}}}};
  nlohmann::json vj = nlohmann::json::array();
  for (const DeltaVariant& v : vars) {
    const double share = v.texels ? double(v.changed) / double(v.texels) : 0.0;
    const double hit_share = v.hit ? double(v.hit_changed) / double(v.hit) : 0.0;
    const double ctx_bytes = v.ctx_bits / 8.0;
    std::printf("  | %s | %.1f%% | %.1f%% | %llu | %llu | %llu | %llu | %llu | %.3f | %llu | %llu | %.3f | %.0f | %.3f | %.1f |\n",
                v.name.c_str(),
                100.0 * share,
                100.0 * hit_share,
                (unsigned long long)v.raw, (unsigned long long)v.max_raw, (unsigned long long)v.stored,
                (unsigned long long)v.tiles_stored, (unsigned long long)v.cols_stored,
                double(v.stored) / double(std::max<uint64_t>(base_stored, 1)), (unsigned long long)v.planar_stored,
                (unsigned long long)v.planar_alone, double(v.planar_stored) / double(std::max<uint64_t>(base_stored, 1)), ctx_bytes,
                (double(v.tiles_stored) + ctx_bytes) / double(std::max<uint64_t>(base_stored, 1)), v.seconds);
    vj.push_back({{"form", v.name}, {"criterion", kDeltaCriterion[v.crit]}, {"keyframe_every", v.N},
                  {"changed_share", share}, {"hit_texels", v.hit}, {"hit_changed_share", hit_share}, {"raw", v.raw}, {"max_cell_raw", v.max_raw}, {"stored", v.stored},
                  {"tiles_alone", v.tiles_stored}, {"columns_alone", v.cols_stored},
                  {"stored_with_bitmaps", v.planar_stored}, {"bitmaps_alone", v.planar_alone},
                  {"bits_context_model_bytes", ctx_bytes},
                  {"over_base", double(v.stored) / double(std::max<uint64_t>(base_stored, 1))}, {"seconds", v.seconds}});
  }
  out["variants"] = vj;
  std::fflush(stdout);
  return out;
}

nlohmann::json run_case(const Case& c, uint32_t level, const std::string& spill_dir, bool bytes_only,
                        const std::string& dump_dir, bool adaptive, bool split_only, std::vector<int> split_shifts,
                        bool own_frames, const std::vector<uint32_t>& delta, bool delta_only) {
  std::printf("\n== %s: %s, %s, %u^2 per slice\n", c.name.c_str(), c.scene.c_str(), c.light.c_str(), 1u << level);
  std::fflush(stdout);
  const st::Scene scene = st::load_scene(c.scene);
  const st::LightSet set = st::fit_light_set(scene, st::LightSetSpec::parse(c.light));
  const uint32_t n = set.size();
  uint32_t k = 0;
  while ((1u << k) < n) ++k;
  const st::moct::Geometry g{level, k};
  const uint32_t K = st::default_stack_skip_level(g);
  const uint32_t a = g.xy_bits(K);
  const uint32_t K2 = st::default_skip_level(level);
  if (a != K2)
    std::printf("note: the stack's cells are 2^%u a side, the 2D packs' 2^%u: per-cell figures use the stack's\n", a, K2);
  const uint64_t cells_xy = uint64_t(1) << (2 * a);
  const std::string tmp = spill_dir + "/bench_stack_slices_" + std::to_string(::getpid());
  const std::string spill_path = tmp + ".spill";
  st::StackSpill spill(spill_path, level, n, st::stack_block_level(g, K, st::kStackBlockTexels));

  // Per slice: the 2D pack, the whole-map DAG-MH's sections, the 2D tiles of the stack's
  // cells (stored sizes, bytes for equality with the previous slice), repetition figures.
  uint64_t packs_bytes = 0;
  st::dagmh::EncodeStats sum{};
  std::vector<std::vector<uint8_t>> prev_raw(cells_xy), cur_raw(cells_xy);
  std::vector<std::vector<std::vector<uint8_t>>> dag_tiles(n);  // DAG-MH tiles per slice (dictionary measure)
  // The separate packs' stored tile bytes per slice w and level-K square c: [w * cells_xy + c].
  std::vector<uint64_t> sq_pack(cells_xy * n, 0);
  // The same under each stored-tile codec (codec_bytes), and every tile of the packs.
  std::vector<CodecBytes> sq_codec(cells_xy * n, CodecBytes{});
  CodecBytes packs_tiles_codec{};
  CodecDecode packs_decode;
  uint64_t packs_other = 0;
  uint64_t res_count = 0, res_prev = 0, res_prev_zero = 0, res_left = 0, res_left_zero = 0, res_lin = 0, res_both = 0;
  uint64_t stored_2d = 0, raw_2d = 0, raw_equal_prev = 0, texels_equal = 0, texels_meet = 0, texels_compared = 0;
  st::IntervalTile prev_tile;
  const st::LightSpace header_light = st::LightSpace::fit(st::LightSpec{}, scene.bounds());
  double pack_s = 0, cells_s = 0;
  auto t0 = Clock::now();
  std::vector<SliceRow> rows;
  // The reference height "above the ground" counts from: the ground frame's plane, or the box's bottom.
  const double ground_y = std::isnan(set.spec.ground) ? scene.bounds().lo.y : set.spec.ground;
  std::vector<st::IntervalTile> keep(delta.empty() ? 0 : n);  // every slice, for --slice-delta
  st::trace_stack_to_spill(scene, set, spill, nullptr, {}, [&](uint32_t w, const st::IntervalTile& tile) {
    if (!delta.empty()) keep[w] = tile;
    if (delta_only) {
      std::printf("  slice %u/%u (%.0f s)\r", w + 1, n, since(t0));
      std::fflush(stdout);
      return;
    }
    const st::Hierarchy h = st::build_hierarchy(tile);
    SliceRow row;
    row.azimuth = set.samples[w].spec().azimuth_deg, row.elevation = set.samples[w].spec().elevation_deg;
    auto p0 = Clock::now();
    {
      st::CutParams cut;
      cut.map_level = level;
      cut.skip_level = K2;
      cut.codec = st::TileCodec::dagmh_or_mmh();
      if (g_planes) cut.codec = st::TileCodec::with_planes(cut.codec, cut.tile_bytes);
      // A 2D pack holds a plain sun or spot (the ground and window frames are stack-only
      // header kinds): the header's light is a plain sun of the same box; the tiles are
      // this slice's, byte for byte what its own build would cut (the header is 256 bytes
      // whatever the light).
      st::PackParams pp = st::PackParams::from(header_light, cut);
      pp.dagmh_dictionary = true;
      const std::string path = tmp + "_2d.pack";
      st::write_pack(path, h, cut, pp);
      const uint64_t file = std::filesystem::file_size(path);
      packs_bytes += file;
      {
        // Each tile's stored bytes to the stack's level-K square holding it (tiles above
        // that level, and the header, grid, index and dictionary, to packs_other).
        const auto reader = st::PackReader::open(path);
        uint64_t in_tiles = 0;
        for (const st::TileIndexEntry& e : reader->tiles()) {
          const st::TileAddress t = st::tile_address(e.id);
          const std::vector<uint8_t> stored = reader->read_stored(e.id);
          const CodecBytes cb = codec_bytes(st::zlib_decompress(stored, e.raw_size, "bench tile"), stored, &packs_decode);
          add_codec(packs_tiles_codec, cb);
          if (t.level >= a) add_codec(sq_codec[w * cells_xy + ((uint64_t(t.y) >> (t.level - a)) << a) + (t.x >> (t.level - a))], cb);
          if (t.level < a) continue;
          sq_pack[w * cells_xy + ((uint64_t(t.y) >> (t.level - a)) << a) + (t.x >> (t.level - a))] += e.stored_size;
          in_tiles += e.stored_size;
        }
        packs_other += file - in_tiles;
        row.ground = measure_slice(set.samples[w], tile, level, ground_y, file, reader->tiles().size());
      }
      std::filesystem::remove(path);
      if (own_frames) {
        // The same sun in its own fitted box (`shadowtile build --light sun:...`), the
        // 2D pack a user builds one sun at a time: traced, cut and written the same way.
        const st::LightSpace own = st::LightSpace::fit(set.samples[w].spec(), scene.bounds());
        const st::IntervalTile ot = st::trace_slice(scene, own, {level, 0, 0, 1u << level, 1u << level});
        st::write_pack(path, st::build_hierarchy(ot), cut, st::PackParams::from(own, cut));
        row.own = measure_slice(own, ot, level, ground_y, std::filesystem::file_size(path), st::PackReader::open(path)->tiles().size());
        std::filesystem::remove(path);
      }
      rows.push_back(row);
      if (!bytes_only) {
        st::dagmh::EncodeStats s;
        st::dagmh::encode(h, &s);
        sum.header_bytes += s.header_bytes, sum.skip_bytes += s.skip_bytes, sum.node_bytes += s.node_bytes;
        sum.treelet_bytes += s.treelet_bytes, sum.chunk_bytes += s.chunk_bytes;
        sum.multiplier_bytes += s.multiplier_bytes, sum.total_bytes += s.total_bytes;
      }
    }
    pack_s += since(p0);
    p0 = Clock::now();
    // --bytes-only: the slices' own 2D tiles of the stack's cells are not encoded (0 below).
    st::SplitResult split = bytes_only ? st::SplitResult{} : st::split_hierarchy(h, a);
    for (uint64_t cell = 0; cell < cells_xy && !bytes_only; ++cell) {
      cur_raw[cell].clear();
      // split's subtrees are row-major (j * 2^a + i), as the stack grid's (y, x).
      const auto& sub = split.subtrees[cell];
      if (!sub) continue;
      std::vector<uint8_t> dag = st::encode_dagmh(*sub), mmh = st::encode_mmh(*sub);
      const auto sd = st::zlib_compress(dag, 6), sm = st::zlib_compress(mmh, 6);
      const bool use_dag = sd.size() <= sm.size();
      cur_raw[cell] = use_dag ? dag : mmh;
      stored_2d += use_dag ? sd.size() : sm.size();
      raw_2d += cur_raw[cell].size();
      if (w > 0 && cur_raw[cell] == prev_raw[cell]) raw_equal_prev += cur_raw[cell].size();
      if (use_dag && !bytes_only) dag_tiles[w].push_back(std::move(dag));
    }
    std::swap(prev_raw, cur_raw);
    if (!bytes_only) {  // --bytes-only: not measured (0 below)
      // The texels off the slice's most common interval (an open mesh's own values): the
      // bits of each one's bit-pattern residual (zigzag) against four predictions.
      auto key = [](const st::Interval& iv) {
        return uint64_t(std::bit_cast<uint32_t>(iv.lo)) << 32 | std::bit_cast<uint32_t>(iv.hi);
      };
      auto lo = [](const st::IntervalTile& t, size_t i) { return std::bit_cast<uint32_t>(t.data[i].lo); };
      auto bits_of = [](uint32_t v, uint32_t pred) {
        const int32_t d = int32_t(v - pred);
        const uint32_t z = (uint32_t(d) << 1) ^ uint32_t(d >> 31);
        return uint64_t(z ? 32 - std::countl_zero(z) : 0);
      };
      std::unordered_map<uint64_t, uint64_t> freq;
      for (const st::Interval& iv : tile.data) ++freq[key(iv)];
      uint64_t mode = 0, most = 0;
      for (const auto& [k, c] : freq)
        if (c > most) most = c, mode = k;
      const size_t side = tile.width;
      for (size_t i = 0; i < tile.data.size(); ++i) {
        if (key(tile.data[i]) == mode) continue;
        ++res_count;
        const uint32_t v = lo(tile, i);
        const bool left = i % side != 0, up = i >= side;
        if (w > 0) {
          const uint64_t b = bits_of(v, lo(prev_tile, i));
          res_prev += b, res_prev_zero += b == 0;
        }
        if (left) {
          const uint64_t b = bits_of(v, lo(tile, i - 1));
          res_left += b, res_left_zero += b == 0;
        }
        if (left && up) res_lin += bits_of(v, lo(tile, i - 1) + lo(tile, i - side) - lo(tile, i - side - 1));
        if (left && w > 0) res_both += bits_of(v, lo(prev_tile, i) + lo(tile, i - 1) - lo(prev_tile, i - 1));
      }
    }
    if (w > 0) {
      for (size_t i = 0; i < tile.data.size(); ++i) {
        const st::Interval u = tile.data[i], v = prev_tile.data[i];
        texels_equal += u.lo == v.lo && u.hi == v.hi;
        texels_meet += std::max(u.lo, v.lo) <= std::min(u.hi, v.hi);
      }
      texels_compared += tile.data.size();
    }
    prev_tile = tile;
    cells_s += since(p0);
    std::printf("  slice %u/%u (%.0f s)\r", w + 1, n, since(t0));
    std::fflush(stdout);
  });
  std::printf("\n");
  prev_tile = {};
  const double trace_s = since(t0) - pack_s - cells_s;
  nlohmann::json delta_json;
  if (!delta.empty()) {
    delta_json = slice_delta_measure(keep, g, K, delta);
    keep = {};
    if (delta_only)
      return {{"case", c.name}, {"resolution", 1u << level}, {"slices", n}, {"separate_dagmh_packs_bytes", 0},
              {"stack_pack_bytes", 0}, {"stack_over_separate", 0.0}, {"stack_pack_smaller_bytes", 0},
              {"stack_pack_smaller_over_separate", 0.0}, {"stack_pack_split_bytes", 0}, {"stack_pack_split_over_separate", 0.0},
              {"slice_delta", delta_json}, {"trace_s", trace_s}, {"peak_rss_mib", peak_rss_mib()}};
  }

  // The stack pack and its tiles by role; the per-cell choice.
  t0 = Clock::now();
  st::StackGrid lights_grid;
  lights_grid.light_kind = set.samples[0].kind();
  for (const st::LightSpace& l : set.samples) lights_grid.lights.push_back(l.to_array());
  lights_grid.spec = set.spec.to_string();
  OctBytes ob;
  uint64_t oct_stored = 0, grid_bytes = 0, stack_file = 0;
  double cut_s = 0;
  st::StackPackParams sp;
  const std::string stack_path = tmp + "_stack.pack";
  if (!bytes_only) {
  st::BlockedStackCut cut(spill, K, 64 * 1024, spill_path + ".tiles");
  cut.grid.light_kind = lights_grid.light_kind;
  cut.grid.lights = lights_grid.lights;
  cut.grid.spec = lights_grid.spec;
  cut_s = since(t0);
  for (size_t i = 0; i < cut.tile_count(); ++i) {
    const auto [cell, buf] = cut.tile(i);
    add_octree_bytes(buf, ob);
    oct_stored += st::zlib_compress(buf, 6).size();
  }
  grid_bytes = cut.grid.serialize().size();
  stack_file = st::write_stack_pack(stack_path, cut.grid, cut.tile_count(), [&](size_t i) { return cut.tile(i); }, sp);
  std::filesystem::remove(stack_path);
  }
  const double stack_s = since(t0);

  // The pack the builder writes by default (--stack-cells smaller): each cell the smaller
  // of its octree and per-slice tiles, both measured, as written.
  t0 = Clock::now();
  uint64_t smaller_file = 0, ungrouped_file = 0, journal_file = 0, smaller_slice_cells = 0, smaller_tiles = 0;
  uint64_t pick_stored = 0, pick_grid = 0, pick_level = K;
  if (!split_only) {
    st::BlockedStackCut pick(spill, K, 64 * 1024, spill_path + ".pick", nullptr, st::StackCells::smaller, false, stack_planes());
    pick.grid.light_kind = lights_grid.light_kind;
    pick.grid.lights = lights_grid.lights;
    pick.grid.spec = lights_grid.spec;
    smaller_file = st::write_stack_pack(stack_path, pick.grid, pick.tile_count(), [&](size_t i) { return pick.tile(i); }, sp);
    st::StackPackParams plain = sp;
    plain.group_slice_tiles = false;
    ungrouped_file = st::write_stack_pack(stack_path, pick.grid, pick.tile_count(), [&](size_t i) { return pick.tile(i); }, plain);
    st::StackPackParams journal = sp;
    journal.payloads_only = journal.compress_grid = false;
    journal_file = st::write_stack_pack(stack_path, pick.grid, pick.tile_count(), [&](size_t i) { return pick.tile(i); }, journal);
    smaller_slice_cells = pick.slice_cells, smaller_tiles = pick.tile_count();
    pick_level = pick.grid.skip_level;
    pick_grid = pick.grid.serialize().size();
    if (adaptive)
      for (size_t i = 0; i < pick.tile_count(); ++i)
        pick_stored += st::zlib_compress(st::group_slice_tiles(pick.tile(i).second), 6).size();
    if (!dump_dir.empty()) {
      for (size_t i = 0; i < pick.tile_count(); ++i) {
        const auto [cell, buf] = pick.tile(i);
        std::ofstream(dump_dir + "/" + std::to_string(cell) + ".bin", std::ios::binary)
            .write(reinterpret_cast<const char*>(buf.data()), std::streamsize(buf.size()));
      }
    }
    std::filesystem::remove(stack_path);
  }
  const double smaller_s = since(t0);

  // The split-cells pack (stack_grid.hpp "Split cells", build --split-cells): K stays at
  // the default (or the default + each of --split-k's shifts), only a cell whose kept form
  // overflows 64 KiB is split below it; written as the builder writes it, opened and
  // verified (every tile opens as its cell's geometry). Where its bytes go: per level-K
  // cell kind (octree tile, per-slice tile, split) and per section, against the separate
  // packs' stored tiles of the same squares and slices (each 2D pack's index).
  t0 = Clock::now();
  uint64_t split_file = 0, split_tiles = 0, split_cells = 0, split_max_tile = 0;
  nlohmann::json split_runs = nlohmann::json::array();
  for (const int shift : split_shifts) {
    const uint32_t Ks = uint32_t(int(K) + shift);
    if (int(K) + shift < 0 || g.xy_bits(Ks) > a) {
      std::printf("split cells at K = %d: skipped (the breakdown needs K <= the default)\n", int(K) + shift);
      continue;
    }
    const auto r0 = Clock::now();
    st::BlockedStackCut cut(spill, Ks, 64 * 1024, spill_path + ".split", nullptr, st::StackCells::smaller, true, stack_planes());
    cut.grid.light_kind = lights_grid.light_kind;
    cut.grid.lights = lights_grid.lights;
    cut.grid.spec = lights_grid.spec;
    const uint64_t file = st::write_stack_pack(stack_path, cut.grid, cut.tile_count(), [&](size_t i) { return cut.tile(i); }, sp);
    st::PackReader::open(stack_path)->verify();
    std::filesystem::remove(stack_path);
    const double run_s = since(r0);
    if (cut.grid.skip_level != Ks) throw st::Error("split cells: the cut moved K from " + std::to_string(Ks));
    // Level-Ks cell -> its region's separate bytes: squares of the default level a, slices of its w range.
    const uint32_t as = g.xy_bits(Ks), bs = g.w_bits(Ks), da = a - as, dwb = k - bs;
    auto separate_of = [&](uint64_t root) {
      const uint64_t x = root & ((uint64_t(1) << as) - 1), y = (root >> as) & ((uint64_t(1) << as) - 1), w = root >> (2 * as);
      double sum = 0;
      for (uint64_t sw = w << dwb; sw < std::min<uint64_t>((w + 1) << dwb, n); ++sw)
        for (uint64_t sy = y << da; sy < (y + 1) << da; ++sy)
          for (uint64_t sx = x << da; sx < (x + 1) << da; ++sx) sum += double(sq_pack[sw * cells_xy + (sy << a) + sx]);
      return sum;
    };
    auto separate_codec_of = [&](uint64_t root) {
      const uint64_t x = root & ((uint64_t(1) << as) - 1), y = (root >> as) & ((uint64_t(1) << as) - 1), w = root >> (2 * as);
      CodecBytes sum{};
      for (uint64_t sw = w << dwb; sw < std::min<uint64_t>((w + 1) << dwb, n); ++sw)
        for (uint64_t sy = y << da; sy < (y + 1) << da; ++sy)
          for (uint64_t sx = x << da; sx < (x + 1) << da; ++sx) add_codec(sum, sq_codec[sw * cells_xy + (sy << a) + sx]);
      return sum;
    };
    // Kinds: 0 octree cell, 1 per-slice cell, 2 split cell (its tiles any form), 3 constant.
    std::vector<KindBytes> kinds(4);
    std::vector<int> root_kind(cut.grid.cells(Ks), 3);
    uint64_t tiles_stored = 0;
    KindBytes oct_sec, sl_sec;  // sections over every tile of each form, split or not
    oct_sec.sec_raw.assign(5, 0), sl_sec.sec_raw.assign(7, 0), sl_sec.sec_stored.assign(7, 0);
    std::vector<uint64_t> sec_lzma(7, 0);  // a per-slice section's lzma stream alone (codec 1)
    CodecBytes tiles_codec{};
    CodecDecode stack_decode;
    ValueCosts value_costs;
    for (size_t i = 0; i < cut.tile_count(); ++i) {
      const auto place = cut.tile_place(i);
      const auto [cell, raw] = cut.tile(i);
      const std::vector<uint8_t> grouped = st::group_slice_tiles(raw);  // as the writer stores it
      const std::vector<uint8_t> zlib = st::zlib_compress(grouped, 6);
      const uint64_t stored = zlib.size();
      tiles_stored += stored;
      const int kind = place.level > Ks ? 2 : place.octree ? 0 : 1;
      root_kind[place.root] = kind;
      KindBytes& kb = kinds[size_t(kind)];
      ++kb.tiles, kb.raw += raw.size(), kb.stored += stored;
      const CodecBytes cb = codec_bytes(grouped, zlib, &stack_decode);
      add_codec(kb.codec, cb), add_codec(tiles_codec, cb);
      if (!place.octree) mmh_value_costs(raw, value_costs);
      KindBytes& form = place.octree ? oct_sec : sl_sec;
      ++form.tiles, form.raw += raw.size(), form.stored += stored;
      if (place.octree) {
        OctBytes o;
        add_octree_bytes(raw, o);
        oct_sec.sec_raw[0] += o.header, oct_sec.sec_raw[1] += o.node, oct_sec.sec_raw[2] += o.value;
        oct_sec.sec_raw[3] += o.far, oct_sec.sec_raw[4] += o.pad;
      } else {
        const std::vector<uint64_t> sec = slice_cell_sections(raw);
        uint64_t at = 0;
        for (size_t j = 0; j < sec.size(); ++j) {
          sl_sec.sec_raw[j] += sec[j];
          if (sec[j] && st::is_grouped_slice_tiles(grouped)) {
            const std::span<const uint8_t> part(grouped.data() + at, sec[j]);
            sl_sec.sec_stored[j] += st::zlib_compress(part, 6).size();
#if ST_BENCH_LZMA
            sec_lzma[j] += st::bench::lzma_tile_compress(part).size();
#endif
          }
          at += sec[j];
        }
      }
    }
    for (uint64_t root = 0; root < root_kind.size(); ++root) {
      KindBytes& kb = kinds[size_t(root_kind[root])];
      ++kb.cells, kb.separate += separate_of(root);
      add_codec(kb.separate_codec, separate_codec_of(root));
    }
    const uint64_t other = file - tiles_stored;  // header, params, grid, index, padding
    std::printf("split cells at K = %u (cells 2^%u a side x %u slices): %llu bytes = %.3f x the separate packs (%llu cells "
                "split, %zu tiles, largest %llu B; cut + write + verify %.1f s)\n",
                Ks, level - as, 1u << dwb, (unsigned long long)file, double(file) / double(packs_bytes),
                (unsigned long long)cut.split_cells, cut.tile_count(), (unsigned long long)cut.max_tile_bytes, run_s);
    std::printf("  | level-K cells | cells | tiles | raw | stored | separate packs, same squares x slices | stored / separate |\n");
    std::printf("  | --- | ---: | ---: | ---: | ---: | ---: | ---: |\n");
    const char* kind_name[4] = {"octree tile", "per-slice tile", "split (tiles below K)", "constant"};
    nlohmann::json kj = nlohmann::json::object();
    for (size_t j = 0; j < 4; ++j) {
      const KindBytes& kb = kinds[j];
      std::printf("  | %s | %llu | %llu | %llu | %llu | %.0f | %.3f |\n", kind_name[j], (unsigned long long)kb.cells,
                  (unsigned long long)kb.tiles, (unsigned long long)kb.raw, (unsigned long long)kb.stored, kb.separate,
                  kb.separate > 0 ? double(kb.stored) / kb.separate : 0.0);
      kj[kind_name[j]] = {{"cells", kb.cells}, {"tiles", kb.tiles}, {"raw", kb.raw}, {"stored", kb.stored}, {"separate", kb.separate}};
    }
    std::printf("  | header, params, grid, index (separate packs: and dictionary) | | | | %llu | %llu | %.3f |\n",
                (unsigned long long)other, (unsigned long long)packs_other, double(other) / double(std::max<uint64_t>(packs_other, 1)));
    std::printf("  octree-form tiles (%llu, stored %llu): raw %llu = header %llu, node words %llu, value words %llu, far "
                "words %llu, padding %llu\n",
                (unsigned long long)oct_sec.tiles, (unsigned long long)oct_sec.stored, (unsigned long long)oct_sec.raw,
                (unsigned long long)oct_sec.sec_raw[0], (unsigned long long)oct_sec.sec_raw[1],
                (unsigned long long)oct_sec.sec_raw[2], (unsigned long long)oct_sec.sec_raw[3],
                (unsigned long long)oct_sec.sec_raw[4]);
    const char* sec_name[7] = {"STSL header+entries", "2D heads", "DAG-MH structure", "MMH node words",
                               "DAG-MH multipliers", "MMH values", "zero bytes"};
    std::printf("  per-slice tiles (%llu, stored %llu; a section's stored bytes: that section of each grouped tile "
                "deflated alone):\n",
                (unsigned long long)sl_sec.tiles, (unsigned long long)sl_sec.stored);
    nlohmann::json sj = nlohmann::json::object();
    for (size_t j = 0; j < 7; ++j) {
      std::printf("    %-20s raw %10llu  stored alone %10llu\n", sec_name[j], (unsigned long long)sl_sec.sec_raw[j],
                  (unsigned long long)sl_sec.sec_stored[j]);
      sj[sec_name[j]] = {{"raw", sl_sec.sec_raw[j]}, {"stored_alone", sl_sec.sec_stored[j]}, {"lzma_alone", sec_lzma[j]}};
    }
    const nlohmann::json cj = print_codec_tables(kinds, kind_name, tiles_codec, file, packs_tiles_codec, packs_bytes,
                                                 stack_decode, packs_decode, sec_lzma, sec_name, value_costs);
    std::fflush(stdout);
    split_runs.push_back({{"skip_level", Ks},
                          {"bytes", file},
                          {"over_separate", double(file) / double(packs_bytes)},
                          {"split_cells", cut.split_cells},
                          {"tiles", cut.tile_count()},
                          {"kinds", kj},
                          {"slice_sections", sj},
                          {"codecs", cj},
                          {"octree_sections",
                           {{"header", oct_sec.sec_raw[0]}, {"node", oct_sec.sec_raw[1]}, {"value", oct_sec.sec_raw[2]},
                            {"far", oct_sec.sec_raw[3]}, {"pad", oct_sec.sec_raw[4]}}},
                          {"other", other}});
    if (split_file == 0) split_file = file, split_tiles = cut.tile_count(), split_cells = cut.split_cells, split_max_tile = cut.max_tile_bytes;
  }
  const double split_s = since(t0);

  // --adaptive: what a cut deeper only where a cell overflows would store (an estimate, no
  // such format yet): the cuts at every level K..K' (K' the uniform cut's level) with no
  // tile bound, each cell its smaller form; a cell of level l < K' whose form's raw bytes
  // fit the 64 KiB bound is kept, else its children at l + 1 are. Bytes: the kept tiles
  // stored as write_stack_pack stores them, each with the uniform pack's per-tile share of
  // records, index and header, the level-K grid and 8 bytes per child entry of a split cell:
  // the journal layout's bytes (compare with that line), the finished layout's gain apart.
  uint64_t adaptive_bytes = 0, adaptive_tiles = 0, adaptive_split = 0;
  if (adaptive) {
    t0 = Clock::now();
    struct CellBytes {
      uint64_t raw = 0, stored = 0;
    };
    std::vector<std::unordered_map<uint64_t, CellBytes>> at;
    std::vector<uint64_t> level_stored;
    const uint32_t Kp = uint32_t(pick_level);
    const double per_tile = double(journal_file - pick_stored - pick_grid) / double(std::max<uint64_t>(smaller_tiles, 1));
    for (uint32_t l = K; l <= Kp; ++l) {
      st::BlockedStackCut cut(spill, l, st::kMaxTileBytes, spill_path + ".adaptive", nullptr, st::StackCells::smaller, false, stack_planes());
      auto& m = at.emplace_back();
      uint64_t total = 0;
      for (size_t i = 0; i < cut.tile_count(); ++i) {
        const auto [cell, buf] = cut.tile(i);
        const uint64_t stored = st::zlib_compress(st::group_slice_tiles(buf), 6).size();
        m[cell] = {buf.size(), stored};
        total += stored;
      }
      level_stored.push_back(total);
      if (l == K) adaptive_bytes += cut.grid.serialize().size();
      std::printf("  uniform cut at K = %u, no bound: %zu tiles, %llu stored\n", l, cut.tile_count(), (unsigned long long)total);
    }
    st::StackGrid gg;
    gg.geo = g;
    std::function<void(uint32_t, uint64_t)> take = [&](uint32_t l, uint64_t cell) {
      const auto it = at[l - K].find(cell);
      if (it == at[l - K].end()) return;  // a constant cell
      if (l == Kp || it->second.raw <= 64 * 1024) {
        adaptive_bytes += it->second.stored + uint64_t(per_tile);
        ++adaptive_tiles;
        return;
      }
      ++adaptive_split;
      const uint32_t a0 = g.xy_bits(l);
      const uint64_t x = cell & ((uint64_t(1) << a0) - 1), y = (cell >> a0) & ((uint64_t(1) << a0) - 1), w = cell >> (2 * a0);
      const uint32_t dx = g.splits_xy(l), dw = g.splits_w(l);
      for (uint64_t cw = 0; cw <= dw; ++cw)
        for (uint64_t cy = 0; cy <= dx; ++cy)
          for (uint64_t cx = 0; cx <= dx; ++cx) {
            adaptive_bytes += 8;
            take(l + 1, gg.index(l + 1, (x << dx) + cx, (y << dx) + cy, (w << dw) + cw));
          }
    };
    for (const auto& [cell, b] : at[0]) take(K, cell);
    std::printf("adaptive cut estimate, journal layout (K = %u, split where a cell's raw > 64 KiB, down to %u): %llu "
                "bytes = %.3f x the separate packs (%llu tiles, %llu cells split; per-tile overhead %.0f B; %.1f s)\n",
                K, Kp, (unsigned long long)adaptive_bytes, double(adaptive_bytes) / double(packs_bytes),
                (unsigned long long)adaptive_tiles, (unsigned long long)adaptive_split, per_tile, since(t0));
  }

  // DAG-MH structure shared across slices: one dictionary over all slices against one per slice.
  t0 = Clock::now();
  uint64_t per_slice_after = 0, per_slice_before = 0;
  std::vector<std::vector<uint8_t>> all;
  for (uint32_t w = 0; w < n && !bytes_only; ++w) {
    if (dag_tiles[w].empty()) continue;
    const st::dagmh::SharedTiles s = st::dagmh::share_across_tiles(dag_tiles[w]);
    per_slice_before += s.bytes_before, per_slice_after += s.bytes_after + s.dictionary.size();
    for (auto& t : dag_tiles[w]) all.push_back(std::move(t));
  }
  dag_tiles.clear();
  uint64_t across_after = 0;
  if (!bytes_only) {
    const st::dagmh::SharedTiles whole = st::dagmh::share_across_tiles(all);
    across_after = whole.bytes_after + whole.dictionary.size();
  }
  const double dict_s = since(t0);

  const double r_stack = double(stack_file) / double(packs_bytes);
  std::printf("separate DAG-MH packs: %llu bytes (%u packs, %.1f s to write)\n", (unsigned long long)packs_bytes, n, pack_s);
  SliceFrame sum_g, sum_o;
  if (own_frames) {
    // The stack's slices in its one frame against each sun in its own fitted box: the
    // separate packs above are the former; `shadowtile build --light sun:...` writes the latter.
    std::printf("  per slice: the stack's frame (its slice as a 2D pack) | the sun's own box (a user's 2D pack)\n");
    std::printf("  | w | azimuth | elevation | box side | own box side | ground area per texel | own | texels above "
                "the ground | own | empty texels | own | tiles | own | bytes | own | bytes / own |\n");
    std::printf("  | --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |\n");
    for (size_t w = 0; w < rows.size(); ++w) {
      const SliceRow& r = rows[w];
      std::printf("  | %zu | %.1f | %.1f | %.1f | %.1f | %.3f | %.3f | %llu | %llu | %llu | %llu | %llu | %llu | %llu | %llu | %.3f |\n",
                  w, r.azimuth, r.elevation, r.ground.side, r.own.side, r.ground.ground_area, r.own.ground_area,
                  (unsigned long long)r.ground.above, (unsigned long long)r.own.above, (unsigned long long)r.ground.empty,
                  (unsigned long long)r.own.empty, (unsigned long long)r.ground.tiles, (unsigned long long)r.own.tiles,
                  (unsigned long long)r.ground.bytes, (unsigned long long)r.own.bytes,
                  double(r.ground.bytes) / double(r.own.bytes));
      for (auto [a, b] : {std::pair{&sum_g, &r.ground}, std::pair{&sum_o, &r.own}}) {
        a->ground_area += b->ground_area / double(rows.size());
        a->above += b->above, a->empty += b->empty, a->tiles += b->tiles, a->bytes += b->bytes;
      }
    }
    std::printf("  | all | | | | | %.3f | %.3f | %llu | %llu | %llu | %llu | %llu | %llu | %llu | %llu | %.3f |\n",
                sum_g.ground_area, sum_o.ground_area, (unsigned long long)sum_g.above, (unsigned long long)sum_o.above,
                (unsigned long long)sum_g.empty, (unsigned long long)sum_o.empty, (unsigned long long)sum_g.tiles,
                (unsigned long long)sum_o.tiles, (unsigned long long)sum_g.bytes, (unsigned long long)sum_o.bytes,
                double(sum_g.bytes) / double(sum_o.bytes));
    std::printf("  each sun in its own box: %llu bytes; the split stack pack = %.3f x those\n",
                (unsigned long long)sum_o.bytes, double(split_file) / double(sum_o.bytes));
  }
  std::printf("  whole-slice DAG-MH raw: %llu = nodes %llu + treelets %llu + value chunks %llu + multipliers %llu + "
              "header/skip %llu\n",
              (unsigned long long)sum.total_bytes, (unsigned long long)sum.node_bytes, (unsigned long long)sum.treelet_bytes,
              (unsigned long long)sum.chunk_bytes, (unsigned long long)sum.multiplier_bytes,
              (unsigned long long)(sum.header_bytes + sum.skip_bytes));
  std::printf("stack pack (octree, K = %u): %llu bytes = %.3f x the separate packs (cut %.1f s)\n", K,
              (unsigned long long)stack_file, r_stack, cut_s);
  std::printf("  octree tiles raw %llu: headers %llu, node words %llu (%.1f%%), value words %llu (%.1f%%), far words "
              "%llu, padding %llu; grid %llu\n",
              (unsigned long long)ob.total(), (unsigned long long)ob.header, (unsigned long long)ob.node,
              100.0 * double(ob.node) / double(ob.total()), (unsigned long long)ob.value,
              100.0 * double(ob.value) / double(ob.total()), (unsigned long long)ob.far, (unsigned long long)ob.pad,
              (unsigned long long)grid_bytes);
  std::printf("the slices' 2D tiles of the stack's cells (2^%u a side; DAG-MH or MMH, the smaller): %llu stored "
              "(octree tiles %llu stored)\n",
              a, (unsigned long long)stored_2d, (unsigned long long)oct_stored);
  std::printf("stack pack, cells the smaller form, uniform cut (build --no-split-cells): %llu bytes = %.3f x the separate packs (%llu of %llu "
              "tiles per slice; cut %.1f s)\n",
              (unsigned long long)smaller_file, double(smaller_file) / double(packs_bytes),
              (unsigned long long)smaller_slice_cells, (unsigned long long)smaller_tiles, smaller_s);
  std::printf("stack pack, split cells (build's default): %llu bytes = %.3f x the separate packs (K = %u, %llu "
              "cells split, %llu tiles, largest %llu B; cut + write + verify %.1f s)\n",
              (unsigned long long)split_file, double(split_file) / double(packs_bytes), K,
              (unsigned long long)split_cells, (unsigned long long)split_tiles, (unsigned long long)split_max_tile, split_s);
  std::printf("  the same cells with per-slice cells stored as STSL (not grouped): %llu bytes = %.3f x the separate packs\n",
              (unsigned long long)ungrouped_file, double(ungrouped_file) / double(packs_bytes));
  std::printf("  the same pack with journal records, a plain index and a raw grid (no payloads_only, compressed_grid): "
              "%llu bytes = %.3f x the separate packs (K = %llu, grid %llu raw)\n",
              (unsigned long long)journal_file, double(journal_file) / double(packs_bytes), (unsigned long long)pick_level,
              (unsigned long long)pick_grid);
  std::printf("neighbours: 2D tile bytes equal to the previous slice's %.2f%%; texels with an equal interval %.2f%%, "
              "meeting %.2f%%\n",
              100.0 * double(raw_equal_prev) / double(raw_2d), 100.0 * double(texels_equal) / double(texels_compared),
              100.0 * double(texels_meet) / double(texels_compared));
  std::printf("DAG-MH dictionary: per slice %llu -> %llu raw; across all slices -> %llu (%.3f of per slice; %.1f s)\n",
              (unsigned long long)per_slice_before, (unsigned long long)per_slice_after, (unsigned long long)across_after,
              double(across_after) / double(per_slice_after), dict_s);
  std::printf("open values: %llu texels off the mode; residual bits against slice w-1 %.2f (%.1f%% equal), left %.2f (%.1f%% equal), planar L+U-UL %.2f, w-1 + left - (w-1 left) %.2f\n",
              (unsigned long long)res_count, double(res_prev) / double(res_count), 100.0 * double(res_prev_zero) / double(res_count),
              double(res_left) / double(res_count), 100.0 * double(res_left_zero) / double(res_count), double(res_lin) / double(res_count), double(res_both) / double(res_count));
  std::printf("trace %.1f s, peak RSS %.0f MiB\n", trace_s, peak_rss_mib());

  return {{"case", c.name},
          {"scene", c.scene},
          {"light", set.spec.to_string()},
          {"resolution", 1u << level},
          {"slices", n},
          {"skip_level", K},
          {"separate_dagmh_packs_bytes", packs_bytes},
          {"whole_slice_dagmh",
           {{"total", sum.total_bytes},
            {"nodes", sum.node_bytes},
            {"treelets", sum.treelet_bytes},
            {"value_chunks", sum.chunk_bytes},
            {"multipliers", sum.multiplier_bytes},
            {"header_skip", sum.header_bytes + sum.skip_bytes}}},
          {"stack_pack_bytes", stack_file},
          {"stack_over_separate", r_stack},
          {"octree_tiles_raw",
           {{"headers", ob.header}, {"node_words", ob.node}, {"value_words", ob.value}, {"far_words", ob.far}, {"padding", ob.pad}}},
          {"octree_tiles_stored", oct_stored},
          {"grid_bytes", grid_bytes},
          {"slice_tiles_stored", stored_2d},
          {"stack_pack_smaller_bytes", smaller_file},
          {"stack_pack_smaller_over_separate", double(smaller_file) / double(packs_bytes)},
          {"stack_pack_smaller_slice_cells", smaller_slice_cells},
          {"stack_pack_smaller_ungrouped_bytes", ungrouped_file},
          {"stack_pack_smaller_journal_layout_bytes", journal_file},
          {"open_value_texels", res_count},
          {"open_value_residual_bits",
           {{"previous_slice", double(res_prev) / double(std::max<uint64_t>(res_count, 1))},
            {"left", double(res_left) / double(std::max<uint64_t>(res_count, 1))},
            {"planar", double(res_lin) / double(std::max<uint64_t>(res_count, 1))},
            {"previous_slice_and_left", double(res_both) / double(std::max<uint64_t>(res_count, 1))}}},
          {"stack_pack_smaller_tiles", smaller_tiles},
          {"stack_pack_split_bytes", split_file},
          {"stack_pack_split_over_separate", double(split_file) / double(packs_bytes)},
          {"stack_pack_split_tiles", split_tiles},
          {"stack_pack_split_cells", split_cells},
          {"split_runs", split_runs},
          {"slice_delta", delta_json},
          {"adaptive_estimate_bytes", adaptive_bytes},
          {"adaptive_estimate_tiles", adaptive_tiles},
          {"adaptive_estimate_split_cells", adaptive_split},
          {"uniform_cut_level", pick_level},
          {"tiles_2d_raw", raw_2d},
          {"tiles_2d_equal_previous_raw", raw_equal_prev},
          {"texels_equal_previous", double(texels_equal) / double(texels_compared)},
          {"texels_meet_previous", double(texels_meet) / double(texels_compared)},
          {"dictionary_per_slice_raw", per_slice_after},
          {"dictionary_across_slices_raw", across_after},
          {"dagmh_tiles_raw", per_slice_before},
          {"own_frame_packs_bytes", sum_o.bytes},
          {"stack_pack_split_over_own_frame_packs", own_frames ? double(split_file) / double(sum_o.bytes) : 0.0},
          {"slices_in_frames", [&] {
             nlohmann::json a = nlohmann::json::array();
             for (const SliceRow& r : rows) {
               auto one = [](const SliceFrame& f) {
                 return nlohmann::json{{"box_side", f.side}, {"ground_area_per_texel", f.ground_area}, {"texels_above_ground", f.above},
                                       {"empty_texels", f.empty}, {"tiles", f.tiles}, {"bytes", f.bytes}};
               };
               a.push_back({{"azimuth", r.azimuth}, {"elevation", r.elevation}, {"stack_frame", one(r.ground)}, {"own_frame", one(r.own)}});
             }
             return a;
           }()},
          {"trace_s", trace_s},
          {"packs_s", pack_s},
          {"stack_s", stack_s},
          {"peak_rss_mib", peak_rss_mib()}};
}

}  // namespace

int main(int argc, char** argv) {
  try {
    uint32_t level = 12, samples = 32, area_samples = 64;
    bool bytes_only = false, adaptive = false, split_only = false, no_planes = false, own_frames = false;
    std::vector<int> split_shifts{0};
    std::vector<uint32_t> delta;
    bool delta_only = false;
    std::string dump_dir;
    std::string which = "all", json_path = "build/bench_stack_slices.json", spill_dir = "/tmp";
    st::bench::Options opt("bench_stack_slices", "Where a shadow-map stack's bytes go, against the same samples as separate DAG-MH packs");
    opt.with("--res", [&](const std::string& v) { level = st::parse_resolution(v); }, "Map side per slice [4k]")
        .value("--samples", samples, "Sun samples of the day's path")
        .value("--area-samples", area_samples, "Area light samples (hairball)")
        .value("--case", which, "city, engine, hairball, demo or all (demo: not in all)")
        .value("--json", json_path, "Write the rows as JSON to PATH (after each case)")
        .value("--spill-dir", spill_dir, "Folder for the traced slices' spill")
        .flag("--bytes-only", bytes_only, "Skip the octree pack, the dictionary measure and their DAG-MH tiles")
        .flag("--adaptive", adaptive, "Estimate a cut that goes deeper only where a cell overflows")
        .flag("--split-only", split_only, "Write only the split pack")
        .flag("--own-frames", own_frames, "Also build each sun in its own fitted box (a user's 2D pack) and compare per slice")
        .flag("--no-planes", no_planes, "No plane tiles in the separate packs nor in the stack's per-slice cells")
        .with("--split-k", [&](const std::string& v) {  // comma-separated shifts of K for the split pack, e.g. 0,-1
                split_shifts.clear();
                for (size_t at = 0; at <= v.size();) {
                  const size_t end = std::min(v.find(',', at), v.size());
                  split_shifts.push_back(std::stoi(v.substr(at, end - at)));
                  at = end + 1;
                }
              }, "Write the split pack at these shifts of K (comma-separated, e.g. 0,-1)")
        .with("--slice-delta", [&](const std::string& v) {  // keyframe spacings, e.g. 4,8,32
                delta.clear();
                for (size_t at = 0; at <= v.size();) {
                  const size_t end = std::min(v.find(',', at), v.size());
                  delta.push_back(uint32_t(std::stoul(v.substr(at, end - at))));
                  at = end + 1;
                }
              }, "Measure delta slices (a keyframe every N slices of a cell; comma-separated N)")
        .flag("--delta-only", delta_only, "With --slice-delta: trace and measure the delta slices only")
        .value("--dump-tiles", dump_dir, "Write the per-cell pack's raw tiles to DIR/<cell>.bin");
    opt.parse(argc, argv);
    g_planes = !no_planes;
    const std::string day = "sun-path:azimuth=100..260,elevation=25..65,samples=" + std::to_string(samples) + ",frame=ground";
    std::vector<Case> cases;
    if (which == "all" || which == "city") cases.push_back({"city-day", "procedural:city", day});
    if (which == "all" || which == "engine")
      cases.push_back({"engine-day", "/usr/share/assimp/models/glTF2/2CylinderEngine-glTF-Binary/2CylinderEngine.glb", day});
    if (which == "demo")  // scripts/demo-day's day: the engine on its ground quad, its sun path
      cases.push_back({"demo-day", "grid:/usr/share/assimp/models/glTF2/2CylinderEngine-glTF-Binary/2CylinderEngine.glb,n=1,gap=1.5",
                       "sun-path:azimuth=90..270,elevation=25..60,samples=" + std::to_string(samples)});
    if (which == "all" || which == "hairball")
      cases.push_back({"hairball-area", "procedural:hairball",
                       "area:pos=0,25,0,target=0,0,0,size=4,4,samples=" + std::to_string(area_samples) +
                           ",jitter=0.5,frame=window"});
    if (cases.empty()) throw st::Error("--case: expected city, engine, hairball, demo or all");
    nlohmann::json out = nlohmann::json::array();
    for (const Case& c : cases) {
      out.push_back(run_case(c, level, spill_dir, bytes_only, dump_dir, adaptive, split_only, split_shifts, own_frames, delta, delta_only && !delta.empty()));
      std::ofstream(json_path) << out.dump(2) << "\n";  // after each case: long runs keep what finished
    }
    std::printf("\n| case | N | separate DAG-MH packs | octree stack pack | / separate | per-cell pack, uniform cut | / "
                "separate | split cells (default) | / separate |\n");
    std::printf("| --- | --- | --- | --- | --- | --- | --- | --- | --- |\n");
    for (const auto& r : out)
      std::printf("| %s %u^2 | %u | %llu | %llu | %.3f | %llu | %.3f | %llu | %.3f |\n", r["case"].get<std::string>().c_str(),
                  r["resolution"].get<uint32_t>(), r["slices"].get<uint32_t>(),
                  (unsigned long long)r["separate_dagmh_packs_bytes"].get<uint64_t>(),
                  (unsigned long long)r["stack_pack_bytes"].get<uint64_t>(), r["stack_over_separate"].get<double>(),
                  (unsigned long long)r["stack_pack_smaller_bytes"].get<uint64_t>(),
                  r["stack_pack_smaller_over_separate"].get<double>(),
                  (unsigned long long)r["stack_pack_split_bytes"].get<uint64_t>(),
                  r["stack_pack_split_over_separate"].get<double>());
    std::ofstream(json_path) << out.dump(2) << "\n";
    std::printf("\nwrote %s\n", json_path.c_str());
  } catch (const std::exception& e) {
    std::fprintf(stderr, "bench_stack_slices: %s\n", e.what());
    return 1;
  }
  return 0;
}
