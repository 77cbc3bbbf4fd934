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

uint32_t float_bits(float v) {
  uint32_t u;
  std::memcpy(&u, &v, 4);
  return u;
}
float bits_float(uint32_t u) {
  float v;
  std::memcpy(&v, &u, 4);
  return v;
}

// The stored nodes of one cell in bit order, each with the prediction of its value bits
// (map_preview.hpp "Values"): `stored(pred)` returns the node's bits. `grid` holds a
// level's answers (bit patterns), row-major; `parent` the level above.
template <class Stored>
void walk_cell_predictions(uint32_t p, const uint64_t* mask, uint32_t entry_bits, std::vector<uint32_t>& grid,
                           std::vector<uint32_t>& parent, Stored&& stored) {
  parent.assign(1, entry_bits);
  for (uint32_t j = 1; j <= p; ++j) {
    const uint64_t s = uint64_t(1) << j;
    grid.resize(s * s);
    for (uint64_t y = 0; y < s; ++y)
      for (uint64_t x = 0; x < s; ++x) {
        const uint32_t up = parent[(y / 2) * (s / 2) + x / 2];
        const uint32_t b = node_bit(j, x, y);
        uint32_t& v = grid[y * s + x];
        if (!(mask[b / 64] >> (b % 64) & 1)) {
          v = up;
          continue;
        }
        // Sums modulo 2^32: a plane's answers are nearly affine in their bit patterns.
        auto at = [&](uint64_t xx, uint64_t yy) { return grid[yy * s + xx]; };
        uint32_t pred = up;
        if (x >= 1 && y >= 1) pred = at(x - 1, y) + at(x, y - 1) - at(x - 1, y - 1);
        else if (x >= 2) pred = 2 * at(x - 1, y) - at(x - 2, y);
        else if (y >= 2) pred = 2 * at(x, y - 1) - at(x, y - 2);
        else if (x == 1) pred = at(0, y);
        else if (y == 1) pred = at(x, 0);
        v = stored(pred);
      }
    parent.swap(grid);
  }
}

uint32_t zigzag(uint32_t residual) { return (residual << 1) ^ uint32_t(int32_t(residual) >> 31); }
uint32_t unzigzag(uint32_t z) { return (z >> 1) ^ (0u - (z & 1)); }

void append_varint(std::vector<uint8_t>& out, uint32_t u) {
  for (; u >= 0x80; u >>= 7) out.push_back(uint8_t(u | 0x80));
  out.push_back(uint8_t(u));
}

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
  m.residuals_ = m.encode_values();
  return m;
}

std::vector<uint8_t> MapPreview::encode_values() const {
  std::vector<uint8_t> out;
  const uint32_t w = words(p_);
  std::vector<uint32_t> grid, parent;
  for (size_t o = 0; o < base_.size(); ++o) {
    size_t next = base_[o];
    walk_cell_predictions(p_, masks_.data() + o * w, float_bits(entry_value_[o]), grid, parent, [&](uint32_t pred) {
      const uint32_t v = float_bits(values_[next++]);
      append_varint(out, zigzag(v - pred));
      return v;
    });
  }
  return out;
}

std::vector<uint8_t> MapPreview::serialize() const {
  std::vector<uint8_t> out;
  out.reserve(serialized_size());
  append_le<uint32_t>(out, kPreviewMagic);
  append_le<uint32_t>(out, p_);
  append_le<uint32_t>(out, uint32_t(base_.size()));
  append_le<uint32_t>(out, uint32_t(residuals_.size()));
  for (uint64_t m : masks_) append_le<uint64_t>(out, m);
  out.insert(out.end(), residuals_.begin(), residuals_.end());
  return out;
}

MapPreview MapPreview::parse(std::span<const uint8_t> bytes, const CutGrid& grid, uint32_t map_level,
                             const std::string& what) {
  if (bytes.size() < kPreviewHeaderBytes)
    preview_error(what, bytes.size(), "truncated header (" + std::to_string(bytes.size()) + " bytes)");
  if (bytes.size() > kMaxPreviewBytes)
    preview_error(what, kMaxPreviewBytes, std::to_string(bytes.size()) + " bytes > the bound " +
                                              std::to_string(kMaxPreviewBytes));
  const uint32_t magic = load_le<uint32_t>(bytes, 0);
  if (magic == kPreviewMagicRaw)
    preview_error(what, 0, "the layout before residual values (\"STPV\"): rebuild the pack");
  if (magic != kPreviewMagic) preview_error(what, 0, "bad magic");
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
  const uint64_t want = kPreviewHeaderBytes + 8 * w * c + uint64_t(n);  // n: the residuals' bytes
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
  // Residuals: one varint a stored node (at most 5 bytes, below 2^32), exactly n bytes.
  if (count > n) preview_error(what, 12, std::to_string(n) + " residual bytes for " + std::to_string(count) + " values");
  m.values_.resize(count);
  const size_t end = bytes.size();
  std::vector<uint32_t> level_bits, parent_bits;
  for (uint32_t i = 0; i < c; ++i) {
    size_t next = m.base_[i];
    walk_cell_predictions(m.p_, m.masks_.data() + size_t(i) * w, float_bits(m.entry_value_[i]), level_bits, parent_bits,
                          [&](uint32_t pred) {
                            const size_t at = off;
                            uint64_t z = 0;
                            for (uint32_t shift = 0;; shift += 7) {
                              if (off == end) preview_error(what, off, "residuals end inside a value");
                              if (shift == 28 && bytes[off] > 0x0f) preview_error(what, off, "residual above 2^32");
                              if (shift > 0 && bytes[off] == 0) preview_error(what, off, "overlong residual");
                              const uint8_t byte = bytes[off++];
                              z |= uint64_t(byte & 0x7f) << shift;
                              if (!(byte & 0x80)) break;
                            }
                            const uint32_t v = pred + unzigzag(uint32_t(z));
                            const float f = bits_float(v);
                            if (std::isnan(f)) preview_error(what, at, "NaN value");
                            m.values_[next++] = f;
                            return v;
                          });
  }
  if (off != end) preview_error(what, off, std::to_string(end - off) + " residual bytes after the last value");
  m.residuals_.assign(bytes.begin() + long(end - n), bytes.end());
  return m;
}

float MapPreview::value(uint64_t ex, uint64_t ey, uint32_t j, uint64_t lx, uint64_t ly,
                        float fallback) const noexcept {
  const uint32_t o = ordinal_[(ey << k_) + ex];
  if (o == ~0u) return fallback;
  const uint32_t w = words(p_);
  const uint64_t* mask = masks_.data() + size_t(o) * w;  // no masks when the preview has no levels
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
