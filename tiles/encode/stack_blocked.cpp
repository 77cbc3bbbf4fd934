#include "tiles/encode/stack_blocked.hpp"

#include <fcntl.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cfloat>
#include <chrono>
#include <cmath>
#include <cstring>
#include <limits>

#include "common/error.hpp"
#include "common/parallel.hpp"
#include "tiles/encode/mh_octree_encode.hpp"
#include "tiles/encode/stack_pack.hpp"
#include "tiles/core/pack_format.hpp"

namespace st {
namespace {

static_assert(sizeof(Interval) == 8, "the spill stores intervals as two floats");

double since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

uint64_t node_texels(const moct::Geometry& g, uint32_t l) {
  return uint64_t(1) << (2 * (g.n - g.xy_bits(l)) + (g.k - g.w_bits(l)));
}

int open_file(const std::string& path, const char* what) {
  const int fd = ::open(path.c_str(), O_RDWR | O_CREAT | O_TRUNC | O_CLOEXEC, 0600);
  if (fd < 0) throw Error(std::string(what) + ": cannot create '" + path + "': " + std::strerror(errno));
  return fd;
}

void write_all(int fd, const void* data, size_t size, uint64_t off, const std::string& path) {
  const char* p = static_cast<const char*>(data);
  while (size) {
    const ssize_t r = ::pwrite(fd, p, size, off_t(off));
    if (r < 0 && errno == EINTR) continue;
    if (r <= 0) throw Error("stack spill: cannot write '" + path + "': " + std::strerror(r < 0 ? errno : ENOSPC));
    p += r, size -= size_t(r), off += uint64_t(r);
  }
}

void read_all(int fd, void* data, size_t size, uint64_t off, const std::string& path) {
  char* p = static_cast<char*>(data);
  while (size) {
    const ssize_t r = ::pread(fd, p, size, off_t(off));
    if (r < 0 && errno == EINTR) continue;
    if (r <= 0) throw Error("stack spill: cannot read '" + path + "'" + (r < 0 ? std::string(": ") + std::strerror(errno) : ": short file"));
    p += r, size -= size_t(r), off += uint64_t(r);
  }
}

// The per-slice form of level-K cell (x, y, w) of block `blk` (block-local cell
// coordinates): each real slice's square of the cell (stack_slices_encode.hpp).
std::vector<uint8_t> cell_slice_tiles(const IntervalStack& blk, const moct::Geometry& g, uint32_t K, uint32_t B,
                                      uint64_t x, uint64_t y, uint64_t w, const PlaneFitOptions* planes = nullptr,
                                      std::span<const uint8_t> plain = {}) {
  (void)B;
  const uint32_t m = g.n - g.xy_bits(K), j = g.k - g.w_bits(K);
  const uint64_t cs = uint64_t(1) << m, W = uint64_t(1) << j;
  std::vector<IntervalTile> slices;
  for (uint64_t s = w * W; s < std::min<uint64_t>(blk.slices, (w + 1) * W); ++s) {
    IntervalTile t;
    t.level = m;
    t.width = t.height = uint32_t(cs);
    t.data.resize(cs * cs);
    for (uint64_t ty = 0; ty < cs; ++ty)
      for (uint64_t tx = 0; tx < cs; ++tx) t.data[ty * cs + tx] = blk.at(x * cs + tx, y * cs + ty, s);
    slices.push_back(std::move(t));
  }
  return encode_slice_tiles(slices, m, j, planes, plain);
}

}  // namespace

uint32_t stack_block_level(const moct::Geometry& g, uint32_t K, uint64_t block_texels) {
  for (uint32_t l = 0; l < K; ++l)
    if (node_texels(g, l) <= block_texels) return l;
  return K;
}

StackSpill::StackSpill(std::string path, uint32_t level, uint32_t slices, uint32_t block_level)
    : path_(std::move(path)), slices_(slices), block_(block_level) {
  uint32_t k = 0;
  while (k < 31 && (1u << k) < slices) ++k;
  geo_ = moct::Geometry{level, k};
  if (slices < 1 || k > moct::kMaxWLevel || level > moct::kMaxXyLevel || block_level > geo_.depth())
    throw Error("stack spill: bad shape (" + std::to_string(slices) + " slices of 2^" + std::to_string(level) +
                ", block level " + std::to_string(block_level) + ")");
  bs_ = side() >> geo_.xy_bits(block_level);
  bw_ = 1u << (k - geo_.w_bits(block_level));
  nx_ = uint64_t(1) << geo_.xy_bits(block_level);
  fd_ = open_file(path_, "stack spill");
}

StackSpill::~StackSpill() {
  if (fd_ >= 0) ::close(fd_), ::unlink(path_.c_str());
}

uint64_t StackSpill::bytes() const { return side() * side() * slices_ * sizeof(Interval); }

uint64_t StackSpill::offset(uint64_t x, uint64_t y, uint64_t w) const {
  const uint64_t c = ((w / bw_) * nx_ + y / bs_) * nx_ + x / bs_;
  return sizeof(Interval) * (((c * bw_ + w % bw_) * bs_ + y % bs_) * bs_ + x % bs_);
}

void StackSpill::write_region(uint32_t w, uint64_t x0, uint64_t y0, uint64_t width, uint64_t rows,
                              std::span<const Interval> data) {
  const uint64_t s = side();
  if (w >= slices_ || x0 % bs_ || y0 % bs_ || width % bs_ || rows % bs_ || x0 + width > s || y0 + rows > s ||
      data.size() != rows * width)
    throw Error("stack spill: region (" + std::to_string(x0) + ", " + std::to_string(y0) + ") " +
                std::to_string(width) + " x " + std::to_string(rows) + " of slice " + std::to_string(w) +
                " does not fit the block layout");
  std::vector<Interval> buf(bs_ * bs_);
  for (uint64_t by = 0; by < rows; by += bs_)
    for (uint64_t bx = 0; bx < width; bx += bs_) {
      for (uint64_t y = 0; y < bs_; ++y)
        std::memcpy(&buf[y * bs_], &data[(by + y) * width + bx], bs_ * sizeof(Interval));
      write_all(fd_, buf.data(), buf.size() * sizeof(Interval), offset(x0 + bx, y0 + by, w), path_);
    }
}

IntervalStack StackSpill::read_block(uint64_t bx, uint64_t by, uint64_t bw) const {
  const uint64_t w0 = bw * bw_;
  if (bx >= nx_ || by >= nx_ || w0 >= slices_) throw Error("stack spill: no block (" + std::to_string(bx) + ", " +
                                                            std::to_string(by) + ", " + std::to_string(bw) + ")");
  IntervalStack st;
  st.level = geo_.n - geo_.xy_bits(block_);
  st.slices = uint32_t(std::min<uint64_t>(bw_, slices_ - w0));
  st.data.resize(bs_ * bs_ * st.slices);
  read_all(fd_, st.data.data(), st.data.size() * sizeof(Interval), offset(bx * bs_, by * bs_, w0), path_);
  return st;
}

Interval StackSpill::texel(uint64_t x, uint64_t y, uint32_t w) const {
  Interval v;
  read_all(fd_, &v, sizeof v, offset(x, y, w), path_);
  return v;
}

BlockedStackCut::BlockedStackCut(const StackSpill& spill, std::optional<uint32_t> skip_level, uint32_t tile_bytes,
                                 std::string tile_path, BlockedCutStats* stats, StackCells cells, bool split,
                                 std::optional<PlaneFitOptions> planes)
    : cells_(cells), split_(split), planes_(std::move(planes)), path_(std::move(tile_path)) {
  const moct::Geometry& g = spill.geo();
  const uint32_t L = g.depth(), B = spill.block_level();
  uint32_t K = skip_level.value_or(std::max(default_stack_skip_level(g), B));
  if (K > L) throw Error("stack cut: skip level " + std::to_string(K) + " exceeds the octree depth " + std::to_string(L));
  if (K < B)
    throw Error("stack cut: skip level " + std::to_string(K) + " lies above the spill's block level " +
                std::to_string(B));
  fd_ = open_file(path_, "stack cut");
  try {
    run(spill, K, tile_bytes, stats);
  } catch (...) {
    ::close(fd_), ::unlink(path_.c_str());
    fd_ = -1;
    throw;
  }
}

void BlockedStackCut::run(const StackSpill& spill, uint32_t K, uint32_t tile_bytes, BlockedCutStats* stats) {
  const moct::Geometry& g = spill.geo();
  const uint32_t L = g.depth(), B = spill.block_level();
  BlockedCutStats st;
  const uint32_t kB = g.k - g.w_bits(B);
  const uint64_t nxB = uint64_t(1) << g.xy_bits(B), nwB = uint64_t(1) << g.w_bits(B);
  for (;; ++K) {
    grid = StackGrid{};
    grid.geo = g;
    grid.slices = spill.slices();
    grid.skip_level = K;
    if (grid.cells(K) > kStackMaxCells)
      throw Error("stack cut: skip level " + std::to_string(K) + " has " + std::to_string(grid.cells(K)) +
                  " cells, above the 2^22 a stack grid holds; raise --tile-bytes");
    if (::ftruncate(fd_, 0) != 0) throw Error("stack cut: cannot truncate '" + path_ + "'");
    tiles_.clear();
    nodes_.clear();
    split_roots_.clear();
    split_cells = 0;
    const double earlier = st.reduce_seconds;
    st = BlockedCutStats{};
    st.reduce_seconds = earlier;
    auto t0 = std::chrono::steady_clock::now();
    std::vector<Interval> iv(grid.cells(B), Interval{-FLT_MAX, FLT_MAX});
    std::vector<uint8_t> mask(grid.cells(B), 0);
    std::vector<std::vector<float>> fine(K + 1);
    for (uint32_t l = B + 1; l <= K; ++l) fine[l].assign(grid.cells(l), std::numeric_limits<float>::quiet_NaN());
    uint64_t largest = 0, largest_cell = 0, at = 0;
    const uint32_t rel = K - B;
    // Past the tile bound the rest of this pass only probes: each remaining block (and
    // the one that failed) finds the shallowest cut >= `need` its own cells fit, so one
    // more pass at the deepest of those replaces a pass per level (that pass checks every
    // block again, so the result is cut_stack's whichever way the sizes go).
    bool probing = false;
    uint32_t need = K;
    // A cell fits when the form the cut would keep fits: the octree, or (cells other than
    // octree) its per-slice tiles where the octree does not fit, so a stack whose octree
    // cells outgrow the bound stays at the level where its per-slice cells still fit
    // instead of moving to one whose small cells pay a header per slice.
    auto block_fits = [&](const IntervalStack& blk, const OctHierarchy& sub, uint32_t Kp, uint64_t bx, uint64_t by,
                          uint64_t bw, uint64_t& size, uint64_t& cell) {
      const uint32_t r = Kp - B, da = g.xy_bits(Kp) - g.xy_bits(B), dw = g.w_bits(Kp) - g.w_bits(B);
      std::vector<size_t> cursor(sub.geo.depth() + 1, 0);
      size = 0;
      for (const OctNode& cr : sub.levels[r]) {
        if (!cr.child_mask) continue;
        const OctHierarchy cs = cell_subtree(sub, r, cr, 0.0f, cursor);  // advances the cursor
        uint64_t x, y, w;
        oct_coords(sub.geo, r, cr.code, x, y, w);
        uint64_t bytes = cells_ == StackCells::slices ? cell_slice_tiles(blk, g, Kp, B, x, y, w).size()
                                                      : encode_octree(cs).size();
        if (bytes > tile_bytes && cells_ == StackCells::smaller)
          bytes = std::min<uint64_t>(bytes, cell_slice_tiles(blk, g, Kp, B, x, y, w).size());
        if (bytes <= size) continue;
        size = bytes, cell = grid.index(Kp, (bx << da) + x, (by << da) + y, (bw << dw) + w);
      }
      return size <= tile_bytes;
    };
    auto too_big = [&](uint64_t cell, uint64_t size) {
      return Error("stack cut: cell " + std::to_string(cell) + " encodes to " + std::to_string(size) +
                   " bytes, above --tile-bytes " + std::to_string(tile_bytes) + " even one level above the leaves");
    };
    for (uint64_t bw = 0; bw < nwB && bw * spill.block_slices() < spill.slices(); ++bw)
      for (uint64_t by = 0; by < nxB; ++by)
        for (uint64_t bx = 0; bx < nxB; ++bx) {
          const IntervalStack blk = spill.read_block(bx, by, bw);
          const OctHierarchy sub = build_octree(blk, kB);
          if (!probing) {
            ++st.blocks;
            st.octree_nodes += sub.node_count() - 1;
            st.max_block_nodes = std::max<uint64_t>(st.max_block_nodes, sub.node_count());
            const OctNode& root = sub.levels[0][0];
            const uint64_t code = oct_code(g, B, bx, by, bw);
            iv[code] = Interval{root.lo, root.hi};
            mask[code] = root.child_mask;
            for (uint32_t j = 1; j <= rel; ++j) {
              const uint32_t l = B + j, da = g.xy_bits(l) - g.xy_bits(B), dw = g.w_bits(l) - g.w_bits(B);
              for (const OctNode& nd : sub.levels[j]) {
                if (!nd.has_value) continue;
                uint64_t x, y, w;
                oct_coords(sub.geo, j, nd.code, x, y, w);
                fine[l][grid.index(l, (bx << da) + x, (by << da) + y, (bw << dw) + w)] = nd.value;
              }
            }
            const uint32_t da = g.xy_bits(K) - g.xy_bits(B), dw = g.w_bits(K) - g.w_bits(B);
            std::vector<size_t> cursor(sub.geo.depth() + 1, 0);
            // The form a cell of block level r (octree level B + r; block-local x, y, w) keeps,
            // given its octree tile: the octree or its per-slice tiles (DAG-MH or MMH slices,
            // the cheap form, weighed first), and with planes, where that keeps the per-slice
            // form, its slices refitted with plane tiles (encode_slice_tiles reuses the plain
            // slices too small for planes), kept where the cell's stream is smaller still.
            // Plane fitting is most of a stack build's time: it runs only for cells the plain
            // per-slice form already takes (a cell the octree keeps fits no planes).
            auto slice_form = [&](uint32_t r, uint64_t x, uint64_t y, uint64_t w, std::vector<uint8_t> bytes,
                                  bool& octree) {
              octree = true;
              if (cells_ == StackCells::octree) return bytes;
              std::vector<uint8_t> per_slice = cell_slice_tiles(blk, g, B + r, B, x, y, w);
              size_t per_slice_z = SIZE_MAX;
              bool take = cells_ == StackCells::slices;
              if (!take && per_slice.size() <= tile_bytes) {
                per_slice_z = zlib_compress(group_slice_tiles(per_slice), 6).size();
                take = bytes.size() > tile_bytes || per_slice_z < zlib_compress(bytes, 6).size();
              }
              if (take && planes_) {
                std::vector<uint8_t> with = cell_slice_tiles(blk, g, B + r, B, x, y, w, &*planes_, per_slice);
                if (with.size() <= tile_bytes &&
                    (cells_ == StackCells::slices || zlib_compress(group_slice_tiles(with), 6).size() < per_slice_z))
                  per_slice = std::move(with);
              }
              if (take) bytes = std::move(per_slice), octree = false;
              return bytes;
            };
            auto form = [&](uint32_t r, const OctNode& cr, uint64_t x, uint64_t y, uint64_t w,
                            std::vector<size_t>& cur, bool& octree) {
              return slice_form(r, x, y, w, encode_octree(cell_subtree(sub, r, cr, 0.0f, cur)), octree);
            };
            uint64_t root_cell = 0;  // the level-K cell whose tiles are being put
            auto put_tile = [&](uint64_t cell, const std::vector<uint8_t>& bytes, bool octree, uint32_t level) {
              write_all(fd_, bytes.data(), bytes.size(), at, path_);
              tiles_.push_back({cell, at, uint32_t(bytes.size()), octree, root_cell, level});
              at += bytes.size();
              if (bytes.size() > largest) largest = bytes.size(), largest_cell = cell;
            };
            // The children of split cell `cr` (block level r) as nodes_[first ..]: each
            // kept whole where its form fits, else split again (a split one level above
            // the leaves has only constant children, so this always ends).
            auto split_children = [&](auto& self, uint32_t r, const OctNode& cr) -> uint32_t {
              ++split_cells;
              const uint32_t l = B + r, c = grid.children(l), bits = sub.geo.step_bits(r);
              const uint32_t first = uint32_t(nodes_.size());
              nodes_.resize(nodes_.size() + c, SplitNode{0, std::numeric_limits<float>::quiet_NaN(), 0});
              const auto& lv = sub.levels[r + 1];
              auto it = std::partition_point(lv.begin(), lv.end(), [&](const OctNode& nd) { return (nd.code >> bits) < cr.code; });
              for (; it != lv.end() && (it->code >> bits) == cr.code; ++it) {
                const OctNode& ch = *it;
                uint64_t x, y, w;
                oct_coords(sub.geo, r + 1, ch.code, x, y, w);
                const uint32_t slot = first + uint32_t(grid.child_offset(l, x, y, w));
                if (ch.has_value) nodes_[slot].value = ch.value;
                if (!ch.child_mask) continue;
                // cell_subtree's scan of each deeper level, started at this child's range.
                std::vector<size_t> cur(sub.geo.depth() + 1, 0);
                for (uint32_t d = r + 2, b = sub.geo.step_bits(r + 1); d <= sub.geo.depth(); b += sub.geo.step_bits(d), ++d) {
                  const auto& dl = sub.levels[d];
                  cur[d] = size_t(std::partition_point(dl.begin(), dl.end(),
                                                       [&](const OctNode& nd) { return (nd.code >> b) < ch.code; }) -
                                  dl.begin());
                }
                bool octree = true;
                const std::vector<uint8_t> bytes = form(r + 1, ch, x, y, w, cur, octree);
                if (bytes.size() <= tile_bytes) {
                  nodes_[slot].kind = 1, nodes_[slot].ref = uint32_t(tiles_.size());
                  put_tile(~uint64_t(0), bytes, octree, l + 1);
                } else {
                  const uint32_t children = self(self, r + 1, ch);
                  nodes_[slot].kind = kStackSplit, nodes_[slot].ref = children;
                }
              }
              return first;
            };
            // The level-K cells' octree tiles in order (cell_subtree's cursor), then their
            // forms on every hardware thread (each cell's alone, so the same bytes whatever
            // the threads), then the tiles put in cell order.
            struct Cell {
              const OctNode* cr;
              uint64_t x, y, w;
              std::vector<uint8_t> bytes;
              bool octree = true;
            };
            std::vector<Cell> cells;
            for (const OctNode& cr : sub.levels[rel]) {
              if (!cr.child_mask) continue;
              Cell c{&cr, 0, 0, 0, {}, true};
              oct_coords(sub.geo, rel, cr.code, c.x, c.y, c.w);
              c.bytes = encode_octree(cell_subtree(sub, rel, cr, 0.0f, cursor));
              cells.push_back(std::move(c));
            }
            for_each_index(cells.size(), cells_ == StackCells::octree ? 1 : 0, [&](size_t i) {
              Cell& c = cells[i];
              c.bytes = slice_form(rel, c.x, c.y, c.w, std::move(c.bytes), c.octree);
            });
            for (Cell& c : cells) {
              const uint64_t cell = grid.index(K, (bx << da) + c.x, (by << da) + c.y, (bw << dw) + c.w);
              root_cell = cell;
              if (split_ && c.bytes.size() > tile_bytes) {
                split_roots_.emplace_back(cell, split_children(split_children, rel, *c.cr));
                continue;
              }
              put_tile(cell, c.bytes, c.octree, K);
              std::vector<uint8_t>().swap(c.bytes);
            }
            if (largest <= tile_bytes) continue;
            if (K + 1 >= L) throw too_big(largest_cell, largest);
            probing = true, need = K + 1;
          }
          uint64_t size = 0, cell = 0;
          while (!block_fits(blk, sub, need, bx, by, bw, size, cell)) {
            if (need + 1 >= L) throw too_big(cell, size);
            ++need;
          }
        }
    st.reduce_seconds += since(t0);
    if (probing) {
      K = need - 1;  // the loop's ++K
      continue;
    }
    t0 = std::chrono::steady_clock::now();
    size_t top_nodes = 0;
    const auto top = octree_top_values(g, B, iv, mask, &top_nodes);
    st.octree_nodes += top_nodes;
    std::vector<std::vector<float>> vals(K + 1);
    for (uint32_t l = 0; l <= B; ++l) {
      vals[l].resize(grid.cells(l));
      for (uint64_t c = 0; c < top[l].size(); ++c) {
        uint64_t x, y, w;
        oct_coords(g, l, c, x, y, w);
        vals[l][grid.index(l, x, y, w)] = top[l][c];
      }
    }
    for (uint32_t l = B + 1; l <= K; ++l) {
      const uint32_t a = g.xy_bits(l), b = g.w_bits(l), dx = g.splits_xy(l - 1), dw = g.splits_w(l - 1);
      vals[l].resize(grid.cells(l));
      for (uint64_t w = 0; w < (uint64_t(1) << b); ++w)
        for (uint64_t y = 0; y < (uint64_t(1) << a); ++y)
          for (uint64_t x = 0; x < (uint64_t(1) << a); ++x) {
            const uint64_t i = grid.index(l, x, y, w);
            vals[l][i] = std::isnan(fine[l][i]) ? vals[l - 1][grid.index(l - 1, x >> dx, y >> dx, w >> dw)] : fine[l][i];
          }
    }
    grid.entries.resize(grid.cells(K));
    for (uint64_t i = 0; i < grid.entries.size(); ++i) grid.entries[i].value = vals[K][i];
    grid.coarse.assign(vals.begin(), vals.begin() + K);
    for (const Ref& r : tiles_)
      if (r.cell != ~uint64_t(0)) grid.entries[r.cell].kind = 1;
    // Split cells' children numbered breadth first (stack_grid.hpp): level K's split cells
    // in cell order, then each split child as its turn comes; a child that inherits takes
    // its parent's value.
    std::sort(split_roots_.begin(), split_roots_.end());
    std::vector<std::pair<uint64_t, uint32_t>> queue(split_roots_);
    for (size_t q = 0; q < queue.size(); ++q) {
      const auto [cell, first] = queue[q];
      grid.entries[cell].kind = kStackSplit;
      const uint32_t c = grid.children(q < split_roots_.size() ? K : grid.entries[cell].level);
      const float parent = grid.entries[cell].value;
      for (uint32_t j = 0; j < c; ++j) {
        const SplitNode& nd = nodes_[first + j];
        const uint64_t child = grid.entries.size();
        StackEntry e;
        e.value = std::isnan(nd.value) ? parent : nd.value;
        e.kind = nd.kind == kStackSplit ? 0 : nd.kind;  // a split kind once its turn comes
        e.level = uint8_t((q < split_roots_.size() ? K : grid.entries[cell].level) + 1);
        grid.entries.push_back(e);
        if (nd.kind == 1) tiles_[nd.ref].cell = child;
        if (nd.kind == kStackSplit) queue.emplace_back(child, nd.ref);
      }
    }
    grid.link();
    // Each tile's root is inner: its value is word 1 of the tree, which starts after the
    // header's shifts (MHOCT.md "Header"), levels L - l + 1 for a cell of level l.
    slice_cells = 0;
    for (const Ref& r : tiles_) {
      tile_bytes_total += r.size;
      if (!r.octree) {  // per-slice tiles: each slice's root is its own
        ++slice_cells;
        continue;
      }
      const StackEntry& e = grid.entries[r.cell];
      const uint64_t root_value = 20 + ((uint64_t(L - e.level + 1) + 3) & ~uint64_t(3)) + 4;
      write_all(fd_, &e.value, sizeof e.value, r.offset + root_value, path_);
    }
    std::sort(tiles_.begin(), tiles_.end(), [](const Ref& a, const Ref& b) { return a.cell < b.cell; });
    max_tile_bytes = largest;
    st.patch_seconds = since(t0);
    if (stats) *stats = st;
    return;
  }
}

BlockedStackCut::TilePlace BlockedStackCut::tile_place(size_t i) const {
  const Ref& r = tiles_.at(i);
  return {r.root, r.level, r.octree};
}

BlockedStackCut::~BlockedStackCut() {
  if (fd_ >= 0) ::close(fd_), ::unlink(path_.c_str());
}

std::pair<uint64_t, std::vector<uint8_t>> BlockedStackCut::tile(size_t i) const {
  const Ref& r = tiles_.at(i);
  std::vector<uint8_t> b(r.size);
  read_all(fd_, b.data(), b.size(), r.offset, path_);
  return {r.cell, std::move(b)};
}

}  // namespace st
