#include "tiles/core/map_preview.hpp"

#include <algorithm>
#include <cmath>
#include <cstring>

#include "common/bit_count.hpp"
#include "common/bytes.hpp"
#include "common/error.hpp"

namespace st {

namespace {

uint32_t node_bit(uint32_t j, uint64_t x, uint64_t y) {
  return uint32_t(((uint64_t(1) << (2 * j)) - 4) / 3 + (y << j) + x);
}

[[noreturn]] void preview_error(const std::string& what, uint64_t offset, const std::string& msg) {
  throw FormatError(what + ": map preview: " + msg + " at byte " + std::to_string(offset));
}

bool same_bits(float a, float b) { return std::memcmp(&a, &b, sizeof a) == 0; }

}  // namespace

MapPreview MapPreview::build(const CutGrid& grid, uint32_t p,
                             const std::function<float(uint32_t, uint64_t, uint64_t)>& depth) {
  MapPreview m;
  m.p_ = p;
  m.k_ = grid.levels;
  m.ordinal_.assign(grid.entries.size(), ~0u);
  const uint32_t w = words(p), k = grid.levels;
  std::vector<float> level_values, parent;
  for (uint64_t ey = 0; ey < (uint64_t(1) << k); ++ey)
    for (uint64_t ex = 0; ex < (uint64_t(1) << k); ++ex) {
      const GridEntry& e = grid.entry(ex, ey);
      if (e.kind == EntryKind::constant) continue;
      m.ordinal_[(ey << k) + ex] = uint32_t(m.base_.size());
      m.base_.push_back(uint32_t(m.values_.size()));
      m.entry_value_.push_back(e.value);
      const size_t mask0 = m.masks_.size();
      m.masks_.resize(mask0 + w, 0);
      parent.assign(1, e.value);
      for (uint32_t j = 1; j <= p; ++j) {
        const uint64_t s = uint64_t(1) << j;
        level_values.resize(s * s);
        for (uint64_t y = 0; y < s; ++y)
          for (uint64_t x = 0; x < s; ++x) {
            const float v = depth(k + j, (ex << j) + x, (ey << j) + y);
            level_values[y * s + x] = v;
            if (!same_bits(v, parent[(y / 2) * (s / 2) + x / 2])) {
              const uint32_t b = node_bit(j, x, y);
              m.masks_[mask0 + b / 64] |= uint64_t(1) << (b % 64);
            }
          }
        parent.swap(level_values);
      }
      // Values in bit order: levels coarse to fine, each row-major (the bit order).
      for (uint32_t j = 1; j <= p; ++j) {
        const uint64_t s = uint64_t(1) << j;
        for (uint64_t y = 0; y < s; ++y)
          for (uint64_t x = 0; x < s; ++x) {
            const uint32_t b = node_bit(j, x, y);
            if (m.masks_[mask0 + b / 64] >> (b % 64) & 1)
              m.values_.push_back(depth(k + j, (ex << j) + x, (ey << j) + y));
          }
      }
    }
  return m;
}

std::vector<uint8_t> MapPreview::serialize() const {
  std::vector<uint8_t> out;
  out.reserve(serialized_size());
  append_le<uint32_t>(out, kPreviewMagic);
  append_le<uint32_t>(out, p_);
  append_le<uint32_t>(out, uint32_t(base_.size()));
  append_le<uint32_t>(out, uint32_t(values_.size()));
  for (uint64_t m : masks_) append_le<uint64_t>(out, m);
  for (float v : values_) append_le<float>(out, v);
  return out;
}

MapPreview MapPreview::parse(std::span<const uint8_t> bytes, const CutGrid& grid, uint32_t map_level,
                             const std::string& what) {
  if (bytes.size() < kPreviewHeaderBytes)
    preview_error(what, bytes.size(), "truncated header (" + std::to_string(bytes.size()) + " bytes)");
  if (bytes.size() > kMaxPreviewBytes)
    preview_error(what, kMaxPreviewBytes, std::to_string(bytes.size()) + " bytes > the bound " +
                                              std::to_string(kMaxPreviewBytes));
  if (load_le<uint32_t>(bytes, 0) != kPreviewMagic) preview_error(what, 0, "bad magic");
  MapPreview m;
  m.p_ = load_le<uint32_t>(bytes, 4);
  m.k_ = grid.levels;
  if (m.p_ > kMaxPreviewLevels || grid.levels + m.p_ > map_level)
    preview_error(what, 4, "levels " + std::to_string(m.p_) + " (at most " + std::to_string(kMaxPreviewLevels) +
                               " and K + p <= the map level)");
  const uint32_t c = load_le<uint32_t>(bytes, 8), n = load_le<uint32_t>(bytes, 12);
  m.ordinal_.assign(grid.entries.size(), ~0u);
  uint32_t cells = 0;
  for (size_t i = 0; i < grid.entries.size(); ++i)
    if (grid.entries[i].kind != EntryKind::constant) {
      m.ordinal_[i] = cells++;
      m.entry_value_.push_back(grid.entries[i].value);
    }
  if (c != cells)
    preview_error(what, 8, std::to_string(c) + " cells, the skip grid has " + std::to_string(cells) +
                               " non-constant entries");
  const uint64_t w = words(m.p_);
  const uint64_t want = kPreviewHeaderBytes + 8 * w * c + 4ull * n;
  if (bytes.size() != want)
    preview_error(what, std::min<uint64_t>(bytes.size(), want),
                  "needs " + std::to_string(want) + " bytes, has " + std::to_string(bytes.size()));
  m.masks_.resize(w * c);
  m.base_.resize(c);
  const uint32_t nb = nodes(m.p_);
  uint64_t count = 0;
  size_t off = kPreviewHeaderBytes;
  for (uint32_t i = 0; i < c; ++i) {
    m.base_[i] = uint32_t(count);
    for (uint64_t k = 0; k < w; ++k, off += 8) {
      const uint64_t word = load_le<uint64_t>(bytes, off);
      const uint32_t valid = nb - uint32_t(k * 64);  // bits of this word that are nodes
      if (valid < 64 && (word >> valid) != 0) preview_error(what, off, "mask bits beyond the last node");
      m.masks_[i * w + k] = word;
      count += bit_count(word);
    }
  }
  if (count != n) preview_error(what, 12, std::to_string(n) + " values, the masks store " + std::to_string(count));
  m.values_.resize(n);
  for (uint32_t i = 0; i < n; ++i, off += 4) {
    const float v = load_le<float>(bytes, off);
    if (std::isnan(v)) preview_error(what, off, "NaN value");
    m.values_[i] = v;
  }
  return m;
}

float MapPreview::value(uint64_t ex, uint64_t ey, uint32_t j, uint64_t lx, uint64_t ly,
                        float fallback) const noexcept {
  const uint32_t o = ordinal_[(ey << k_) + ex];
  if (o == ~0u) return fallback;
  const uint32_t w = words(p_);
  const uint64_t* mask = &masks_[size_t(o) * w];
  for (; j >= 1; --j, lx >>= 1, ly >>= 1) {
    const uint32_t b = node_bit(j, lx, ly);
    if (!(mask[b / 64] >> (b % 64) & 1)) continue;
    uint32_t rank = 0;  // stored nodes before bit b
    for (uint32_t i = 0; i < b / 64; ++i) rank += bit_count(mask[i]);
    rank += bit_count(mask[b / 64] & ((uint64_t(1) << (b % 64)) - 1));
    return values_[base_[o] + rank];
  }
  return entry_value_[o];  // relative level 0: the skip-grid entry
}

float MapPreview::coarse_answer(uint32_t k, const PageHit& hit, uint32_t level, uint64_t x,
                                uint64_t y) const noexcept {
  if (p_ == 0 || level <= k || hit.kind == PageHit::Kind::value) return hit.value;
  const uint32_t reached = tile_level(hit.tile);  // the entry's level
  const uint32_t j = std::min(level - k, p_);
  if (k + j <= reached) return hit.value;
  const uint32_t s = level - k;  // texel -> cell
  const uint64_t ex = x >> s, ey = y >> s;
  const uint64_t lx = (x >> (s - j)) - (ex << j), ly = (y >> (s - j)) - (ey << j);
  return value(ex, ey, j, lx, ly, hit.value);
}

uint32_t MapPreview::coarse_region_shift(uint32_t k, const PageHit& hit, uint32_t level) const noexcept {
  const uint32_t reached = tile_level(hit.tile);
  const uint32_t whole = level - std::min(level, reached);
  if (p_ == 0 || level <= k) return whole;
  const uint32_t j = std::min(level - k, p_);
  return k + j <= reached ? whole : level - (k + j);
}

}  // namespace st
