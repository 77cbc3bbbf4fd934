// Exit-depth counting on synthetic hit sequences, without Embree: a ray from the origin
// along +z, faces perpendicular to it (so a face's exact plane t is its float t unless a
// test says otherwise), and a small traversal loop that offers hits the way Embree does.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <map>
#include <random>
#include <set>
#include <vector>

#include "tiles/bake/exit_depth.hpp"

namespace st {
namespace exit_depth_test {

constexpr float kNoHit = ExitDepthRay::kNoHit;
const Vec3d kOrigin{0, 0, 0}, kDir{0, 0, 1};

struct Hit {
  float t;
  bool closed;
  uint32_t prim;
  uint32_t hidden_before = 0;  // culled by traversals numbered below this (1 = the first)
};

// Closed faces of the synthetic scene; facing as a sun would classify it.
struct Faces {
  ClosedFaces closed;

  // A face perpendicular to the ray at exact plane t `plane_t`.
  uint32_t add(uint32_t mesh, Facing facing, double plane_t, bool touchable = false) {
    // Outward normal towards the light for a front face, away from it for a back face.
    const Vec3d n = facing == Facing::back ? Vec3d{0, 0, 1} : Vec3d{0, 0, -1};
    const Vec3d normal = facing == Facing::edge_on ? Vec3d{1, 0, 0} : n;
    closed.add(mesh, facing, normal, dot(normal, kDir * plane_t));
    closed.touchable.push_back(touchable ? 1 : 0);
    return uint32_t(closed.size() - 1);
  }
  // A face whose facing is left to the ray (a spot light's faces).
  uint32_t add_per_ray(uint32_t mesh, const Vec3d& normal, double plane_t) {
    closed.add(mesh, Facing::per_ray, normal, dot(normal, kDir * plane_t));
    closed.touchable.push_back(0);
    return uint32_t(closed.size() - 1);
  }
};

struct Outcome {
  float lo = kNoHit, hi = kNoHit;
  bool fell_back = false;
  uint32_t traversals = 0;
};

// One traversal as Embree runs it: every hit in [tnear, tfar] is offered in the given
// order, and an accepted hit shrinks tfar to its t (later candidates beyond are culled).
bool traverse(ExitDepthRay& ray, const std::vector<Hit>& hits, float tnear, float tfar,
              uint32_t traversal) {
  bool accepted = false;
  for (const Hit& h : hits) {
    if (h.t < tnear || h.t > tfar || traversal < h.hidden_before) continue;
    if (ray.offer(h.t, h.closed, h.prim)) tfar = h.t, accepted = true;
  }
  return accepted;
}

Outcome run(const Faces& f, const std::vector<Hit>& hits) {
  ExitDepthRay ray;
  ray.start(f.closed, kOrigin, kDir, 0.0f, 1.0f);
  Outcome o;
  o.traversals = 1;
  if (traverse(ray, hits, ray.tnear(), ray.tfar(), 1) && ray.first_traversal_done()) {
    do traverse(ray, hits, ray.tnear(), ray.tfar(), ++o.traversals);
    while (ray.traversal_done());
  }
  o.lo = ray.lo_t(), o.hi = ray.hi_t(), o.fell_back = ray.fell_back();
  return o;
}

Hit face_hit(const Faces& f, uint32_t prim) {
  return {float(f.closed.plane_t(prim, kOrigin, kDir)), true, prim};
}

// A closed box of its own mesh from t = a to t = b: its front and back face hits.
std::vector<Hit> box(Faces& f, uint32_t mesh, double a, double b, bool touchable = false) {
  const uint32_t front = f.add(mesh, Facing::front, a, touchable);
  const uint32_t back = f.add(mesh, Facing::back, b, touchable);
  return {face_hit(f, front), face_hit(f, back)};
}

std::vector<Hit> operator+(std::vector<Hit> a, const std::vector<Hit>& b) {
  a.insert(a.end(), b.begin(), b.end());
  return a;
}

Aabb unit_box() {
  Aabb b;
  b.extend({-1, -1, -1});
  b.extend({1, 1, 1});
  return b;
}

void expect_interval(const Outcome& o, float lo, float hi, bool fell_back) {
  EXPECT_EQ(o.lo, lo);
  EXPECT_EQ(o.hi, hi);
  EXPECT_EQ(o.fell_back, fell_back);
}

TEST(ExitDepth, SingleClosedBoxEntersAndLeaves) {
  Faces f;
  const auto hits = box(f, 0, 0.25, 0.5);
  const Outcome o = run(f, hits);
  expect_interval(o, 0.25f, 0.5f, false);
  EXPECT_EQ(o.traversals, 2u);  // the entry, then the exit; no look-ahead (not touchable)
  // Offered in any order, with the back face first, it is the same ray.
  expect_interval(run(f, {hits[1], hits[0]}), 0.25f, 0.5f, false);

  // A touchable exit costs one look-ahead traversal that finds nothing.
  Faces g;
  const Outcome t = run(g, box(g, 0, 0.25, 0.5, true));
  expect_interval(t, 0.25f, 0.5f, false);
  EXPECT_EQ(t.traversals, 3u);
}

TEST(ExitDepth, NestedAndOverlappingClosedObjectsExitTheirUnion) {
  Faces f;
  // Nested: B inside A; the ray leaves at A's back face.
  expect_interval(run(f, box(f, 0, 0.2, 0.6) + box(f, 1, 0.3, 0.4)), 0.2f, 0.6f, false);
  // Overlapping: A [0.2, 0.5], B [0.4, 0.7]: the union ends at 0.7.
  Faces g;
  expect_interval(run(g, box(g, 0, 0.2, 0.5) + box(g, 1, 0.4, 0.7)), 0.2f, 0.7f, false);
  // Disjoint: the gap ends the interval at the first object.
  Faces h;
  expect_interval(run(h, box(h, 0, 0.2, 0.3) + box(h, 1, 0.5, 0.6)), 0.2f, 0.3f, false);
  // One mesh crossed several times (a concave object) counts up to 3 and back.
  Faces c;
  auto hits = box(c, 0, 0.1, 0.6) + box(c, 0, 0.2, 0.3) + box(c, 0, 0.25, 0.7);
  expect_interval(run(c, hits), 0.1f, 0.7f, false);
}

TEST(ExitDepth, TouchingFacesAtEqualTContinueIntoTheNeighbour) {
  // A ends where B begins, at exactly the same t: one group where A counts -1 and B +1,
  // so the counter never reaches 0 there.
  for (bool b_first : {false, true}) {
    Faces f;
    auto a = box(f, 0, 0.2, 0.4), b = box(f, 1, 0.4, 0.6);
    auto hits = b_first ? b + a : a + b;
    const Outcome o = run(f, hits);
    expect_interval(o, 0.2f, 0.6f, false);
    EXPECT_EQ(o.traversals, 3u);  // 0.2, the touching group at 0.4, 0.6
  }
  // Two boxes touching exactly on their entry faces enter both at once.
  Faces g;
  expect_interval(run(g, box(g, 0, 0.2, 0.4) + box(g, 1, 0.2, 0.7)), 0.2f, 0.7f, false);
}

TEST(ExitDepth, TouchingFacesAnUlpApartAreJoinedByTheLookAhead) {
  // The tracer reported B's entry face an ulp after A's exit face, although both planes
  // are exactly at t = 0.4f: the look-ahead finds it and the ray goes on into B.
  const float exit = 0.4f, late = std::nextafter(exit, 1.0f);
  {
    Faces f;
    const uint32_t a_in = f.add(0, Facing::front, 0.2), a_out = f.add(0, Facing::back, exit, true);
    const uint32_t b_in = f.add(1, Facing::front, exit, true), b_out = f.add(1, Facing::back, 0.6);
    const std::vector<Hit> hits = {face_hit(f, a_in), face_hit(f, a_out), {late, true, b_in},
                                   face_hit(f, b_out)};
    const Outcome o = run(f, hits);
    expect_interval(o, 0.2f, 0.6f, false);
    EXPECT_EQ(o.traversals, 4u);  // 0.2, 0.4, the look-ahead (B enters), 0.6
  }
  {
    // B's plane is really 1e-6 further: a gap, whatever the float t says.
    Faces f;
    const uint32_t a_in = f.add(0, Facing::front, 0.2), a_out = f.add(0, Facing::back, exit, true);
    const uint32_t b_in = f.add(1, Facing::front, double(exit) + 1e-6, true);
    const uint32_t b_out = f.add(1, Facing::back, 0.6);
    const std::vector<Hit> hits = {face_hit(f, a_in), face_hit(f, a_out), {late, true, b_in},
                                   face_hit(f, b_out)};
    expect_interval(run(f, hits), 0.2f, exit, false);
  }
  {
    // An exit that cannot touch anything skips the look-ahead: the ulp-late entry is a
    // new object and the interval ends at A's exit.
    Faces f;
    const uint32_t a_in = f.add(0, Facing::front, 0.2), a_out = f.add(0, Facing::back, exit);
    const uint32_t b_in = f.add(1, Facing::front, exit), b_out = f.add(1, Facing::back, 0.6);
    const std::vector<Hit> hits = {face_hit(f, a_in), face_hit(f, a_out), {late, true, b_in},
                                   face_hit(f, b_out)};
    const Outcome o = run(f, hits);
    expect_interval(o, 0.2f, exit, false);
    EXPECT_EQ(o.traversals, 2u);
  }
}

TEST(ExitDepth, AHitCulledJustBelowTheLastGroupIsFoundByTheNextTraversal) {
  // Inside A, the tracer's box culling hid B's entry an ulp below C's entry in the
  // traversal that accepted C. The next one starts a little below C's t and finds it;
  // starting exactly at C's t would miss it, and B's exit would then look like a stray
  // back face.
  Faces f;
  const float below = std::nextafter(0.4f, 0.0f);
  auto a = box(f, 0, 0.2, 0.8), c = box(f, 2, 0.4, 0.5);
  const uint32_t b_in = f.add(1, Facing::front, below), b_out = f.add(1, Facing::back, 0.6);
  const std::vector<Hit> hits = a + c + std::vector<Hit>{{below, true, b_in, 3}, face_hit(f, b_out)};
  const Outcome o = run(f, hits);
  expect_interval(o, 0.2f, 0.8f, false);
  EXPECT_EQ(o.traversals, 6u);  // 0.2, 0.4 (C), just below 0.4 (B), 0.5, 0.6, 0.8
}

TEST(ExitDepth, DuplicatePrimitiveIdsCountOnce) {
  // The same primitive offered twice in one traversal (and again in later ones) counts
  // once, or the counter would never return to 0.
  Faces f;
  auto hits = box(f, 0, 0.25, 0.5);
  expect_interval(run(f, {hits[0], hits[0], hits[1], hits[0], hits[1]}), 0.25f, 0.5f, false);
  // Two triangles of one mesh met at their shared edge: two ids, one crossing.
  Faces g;
  const uint32_t in1 = g.add(0, Facing::front, 0.25), in2 = g.add(0, Facing::front, 0.25);
  const uint32_t out1 = g.add(0, Facing::back, 0.5), out2 = g.add(0, Facing::back, 0.5);
  expect_interval(run(g, {face_hit(g, in1), face_hit(g, in2), face_hit(g, out2),
                          face_hit(g, out1)}),
                  0.25f, 0.5f, false);
  // A silhouette edge (front and back of one mesh at one t) enters nothing: hi = lo.
  Faces s;
  const uint32_t sf = s.add(0, Facing::front, 0.3), sb = s.add(0, Facing::back, 0.3);
  expect_interval(run(s, {face_hit(s, sf), face_hit(s, sb)}), 0.3f, 0.3f, false);
}

TEST(ExitDepth, OpenSurfacesGiveZeroWidthFirstAndAreIgnoredInside) {
  Faces f;
  // An open surface first: the plain shadow-map depth, hi = lo, counting stops there.
  const auto behind = box(f, 0, 0.5, 0.7);
  const Outcome o = run(f, {Hit{0.3f, false, 0}, behind[0], behind[1]});
  expect_interval(o, 0.3f, 0.3f, false);
  EXPECT_EQ(o.traversals, 1u);
  // Inside a closed box an open surface changes nothing.
  Faces g;
  expect_interval(run(g, box(g, 0, 0.2, 0.6) + std::vector<Hit>{{0.4f, false, 0}}), 0.2f, 0.6f,
                  false);
  // Open and closed hits at one t: the closed one counts.
  Faces h;
  expect_interval(run(h, box(h, 0, 0.2, 0.6) + std::vector<Hit>{{0.2f, false, 3}}), 0.2f, 0.6f,
                  false);
  // Open primitive ids and closed ones are distinct even when the numbers match.
  Faces k;
  expect_interval(run(k, box(k, 0, 0.2, 0.6) + std::vector<Hit>{{0.4f, false, 1}}), 0.2f, 0.6f,
                  false);
}

TEST(ExitDepth, BackFaceFirstAndNegativeCountersFallBack) {
  Faces f;
  const uint32_t back = f.add(0, Facing::back, 0.3);
  expect_interval(run(f, {face_hit(f, back)}), 0.3f, 0.3f, true);
  // Inside A, the back face of a B never entered (inverted winding): not trusted.
  Faces g;
  const uint32_t stray = g.add(1, Facing::back, 0.3);
  expect_interval(run(g, box(g, 0, 0.2, 0.6) + std::vector<Hit>{face_hit(g, stray)}), 0.2f, 0.2f,
                  true);
  // A leaves twice.
  Faces h;
  const uint32_t again = h.add(0, Facing::back, 0.8);
  auto hits = box(h, 0, 0.2, 0.6) + box(h, 1, 0.5, 0.9) + std::vector<Hit>{face_hit(h, again)};
  expect_interval(run(h, hits), 0.2f, 0.2f, true);
}

TEST(ExitDepth, NoHitIsLitAndLeavingTheSceneInsideFallsBack) {
  Faces f;
  const Outcome o = run(f, {});
  EXPECT_EQ(o.lo, kNoHit);
  EXPECT_FALSE(o.fell_back);
  ExitDepthRay ray;
  ray.start(f.closed, kOrigin, kDir, 0.0f, 1.0f);
  EXPECT_FALSE(ray.hit());
  const LightSpace sun =
      LightSpace::fit(LightSpec::parse("sun:azimuth=30,elevation=50"), unit_box());
  EXPECT_EQ(ray.interval(sun), (Interval{kLitDepth, kLitDepth}));
  // Hits outside the ray's t range are never offered: still lit.
  Faces g;
  const uint32_t far = g.add(0, Facing::front, 1.5);
  EXPECT_EQ(run(g, {face_hit(g, far)}).lo, kNoHit);
  // Entered and never left: hi = lo.
  Faces h;
  const uint32_t in = h.add(0, Facing::front, 0.4);
  expect_interval(run(h, {face_hit(h, in)}), 0.4f, 0.4f, true);
}

TEST(ExitDepth, EdgeOnAndPerRayFacings) {
  // An edge-on face counts 0: inside the box it changes nothing; first, it enters nothing.
  Faces f;
  const uint32_t edge = f.add(1, Facing::edge_on, 0.4);
  expect_interval(run(f, box(f, 0, 0.2, 0.6) + std::vector<Hit>{{0.4f, true, edge}}), 0.2f, 0.6f,
                  false);
  expect_interval(run(f, {{0.4f, true, edge}}), 0.4f, 0.4f, false);
  // Under a spot the facing comes from the normal and the ray: against the outward
  // normal enters, along it leaves.
  Faces s;
  const uint32_t in = s.add_per_ray(0, {0.3, 0, -1}, 0.25);
  const uint32_t out = s.add_per_ray(0, {0, 0.2, 1}, 0.5);
  expect_interval(run(s, {face_hit(s, in), face_hit(s, out)}), 0.25f, 0.5f, false);
  expect_interval(run(s, {face_hit(s, out)}), 0.5f, 0.5f, true);
}

TEST(ExitDepth, LongRunsOfHitsAndTableBounds) {
  // 16 nested boxes: 16 meshes and 32 primitives, within the per-ray tables.
  Faces f;
  std::vector<Hit> hits;
  for (uint32_t m = 0; m < 16; ++m) hits = hits + box(f, m, 0.01 * (m + 1), 0.99 - 0.01 * m);
  const Outcome o = run(f, hits);
  expect_interval(o, 0.01f, 0.99f, false);
  EXPECT_EQ(o.traversals, 32u);
  // A 17th mesh entered at once overflows the mesh table.
  Faces g;
  hits.clear();
  for (uint32_t m = 0; m < 17; ++m) hits = hits + box(g, m, 0.01 * (m + 1), 0.99 - 0.01 * m);
  expect_interval(run(g, hits), 0.01f, 0.01f, true);
  // 25 disjoint boxes in a row: the first one bounds the interval.
  Faces d;
  hits.clear();
  for (uint32_t m = 0; m < 25; ++m) hits = hits + box(d, m, 0.02 + 0.03 * m, 0.03 + 0.03 * m);
  expect_interval(run(d, hits), 0.02f, 0.03f, false);
  // Inside one box, more processed primitives than the table holds: not trusted. With 46
  // open hits inside, the exit is the 48th primitive and still fits.
  for (uint32_t open : {46u, 47u}) {
    Faces b;
    hits = box(b, 0, 0.01, 0.99);
    for (uint32_t k = 0; k < open; ++k) hits.push_back({0.02f + 0.02f * float(k), false, k});
    expect_interval(run(b, hits), 0.01f, open == 46 ? 0.99f : 0.01f, open != 46);
  }
  // More than 16 primitives at one t: the group overflows.
  for (uint32_t n : {16u, 17u}) {
    Faces e;
    hits = box(e, 0, 0.2, 0.6);
    for (uint32_t k = 0; k + 1 < n; ++k) hits.push_back({0.4f, false, k});
    hits.push_back({0.4f, true, e.add(1, Facing::edge_on, 0.4)});
    expect_interval(run(e, hits), 0.2f, n == 16 ? 0.6f : 0.2f, n != 16);
  }
}

// The plain rule for hits at well-separated t (further apart than the look-ahead
// window): sort, group equal t, count per mesh, stop at 0.
using FaceTable = std::map<uint64_t, std::pair<uint32_t, int>>;  // closed key -> mesh, facing

Outcome reference(const std::vector<Hit>& hits, const FaceTable& face,
                  const std::set<uint64_t>& touchable) {
  std::map<float, std::set<uint64_t>> groups;
  for (const Hit& h : hits) groups[h.t].insert((uint64_t(h.closed ? 0 : 1) << 32) | h.prim);
  Outcome o;
  o.traversals = 1;
  if (groups.empty()) return o;
  o.lo = o.hi = groups.begin()->first;
  std::map<uint32_t, int> count;  // per mesh entered
  int total = 0;
  uint32_t done = 0;
  auto apply = [&](const std::set<uint64_t>& g, uint32_t& closed_hits) {
    if (g.size() > ExitDepthRay::kMaxGroup) return false;
    std::map<uint32_t, int> sum;
    closed_hits = 0;
    for (uint64_t k : g)
      if (face.count(k)) ++closed_hits, sum[face.at(k).first] += face.at(k).second;
    for (auto [mesh, s] : sum) {
      const int net = std::clamp(s, -1, 1);
      if (net == 0) continue;
      if (!count.count(mesh) && (net < 0 || count.size() == ExitDepthRay::kMaxMeshes)) return false;
      total += net;
      if ((count[mesh] += net) < 0) return false;
    }
    return true;
  };
  auto fall_back = [&] {
    o.hi = o.lo, o.fell_back = true;
    return o;
  };
  bool first = true;
  for (const auto& [t, g] : groups) {
    uint32_t closed_hits = 0;
    if (first) {
      if (!apply(g, closed_hits)) return fall_back();
      if (closed_hits == 0 || total == 0) return o;
      first = false;
    } else {
      ++o.traversals;
      if (done + g.size() > ExitDepthRay::kMaxDone || !apply(g, closed_hits) ||
          o.traversals >= ExitDepthRay::kMaxTraversals)
        return fall_back();
      if (total == 0) {
        bool look_ahead = false;
        for (uint64_t k : g) look_ahead |= touchable.count(k) != 0;
        o.traversals += look_ahead;
        o.hi = t;
        return o;
      }
    }
    done += uint32_t(g.size());
  }
  ++o.traversals;  // the traversal that found nothing more, inside a closed object
  return fall_back();
}

TEST(ExitDepth, RandomHitSequencesMatchThePlainRule) {
  std::mt19937 rng(20240611);
  uint64_t closed_rays = 0, fallbacks = 0;
  for (int trial = 0; trial < 4000; ++trial) {
    Faces f;
    std::vector<Hit> hits;
    FaceTable face;
    std::set<uint64_t> touchable;
    // t on a 1/64 grid (exact floats, far apart against the look-ahead window), so
    // equal t happen often; few slots make crowded groups and coincident faces likely.
    const int slots = 4 + int(rng() % 60);
    auto t_of = [&] { return float(1 + rng() % slots) / 64.0f; };
    const uint32_t meshes = 1 + rng() % (trial % 10 == 0 ? 20 : 5);
    for (uint32_t m = 0; m < meshes; ++m) {
      const uint32_t crossings = 1 + rng() % 3;
      for (uint32_t c = 0; c < crossings; ++c) {
        float a = t_of(), b = t_of();
        if (a > b) std::swap(a, b);
        std::pair<Facing, Facing> fb{Facing::front, Facing::back};
        if (rng() % 12 == 0) std::swap(fb.first, fb.second);  // inverted winding
        if (rng() % 15 == 0) fb.second = Facing::edge_on;
        for (auto [t, facing] : {std::pair{a, fb.first}, std::pair{b, fb.second}}) {
          if (rng() % 20 == 0) continue;  // a hole: the object is not closed along this ray
          const bool touch = rng() % 3 == 0;
          const uint32_t prim = f.add(m, facing, t, touch);
          const int sign = facing == Facing::front ? 1 : (facing == Facing::back ? -1 : 0);
          face[prim] = {m, sign};
          if (touch) touchable.insert(prim);
          hits.push_back({t, true, prim});
          if (rng() % 6 == 0) {  // a second triangle of the mesh at the same crossing
            const uint32_t twin = f.add(m, facing, t, touch);
            face[twin] = {m, sign};
            if (touch) touchable.insert(twin);
            hits.push_back({t, true, twin});
          }
        }
      }
    }
    const uint32_t open = rng() % 4 == 0 ? rng() % 6 : 0;
    // Open ids start at 0 like the closed ones: keys must tell them apart.
    for (uint32_t k = 0; k < open; ++k) hits.push_back({t_of(), false, k});
    const size_t unique = hits.size();
    for (size_t k = 0; k < unique; ++k)
      if (rng() % 8 == 0) hits.push_back(hits[rng() % unique]);  // reported again
    std::shuffle(hits.begin(), hits.end(), rng);

    const Outcome want = reference(hits, face, touchable);
    const Outcome got = run(f, hits);
    ASSERT_EQ(got.lo, want.lo) << "trial " << trial;
    ASSERT_EQ(got.hi, want.hi) << "trial " << trial;
    ASSERT_EQ(got.fell_back, want.fell_back) << "trial " << trial;
    ASSERT_EQ(got.traversals, want.traversals) << "trial " << trial;
    closed_rays += got.hi > got.lo, fallbacks += got.fell_back;
  }
  // The generator reaches every outcome often.
  EXPECT_GT(closed_rays, 1000u);
  EXPECT_GT(fallbacks, 200u);
}

TEST(ExitDepth, DepthsOfASpotMapTheRayRange) {
  const LightSpace spot =
      LightSpace::fit(LightSpec::parse("spot:pos=0,10,0,target=0,0,0,fov=40"), unit_box());
  const double near = spot.near_plane(), far = spot.far_plane();
  ExitDepthRay ray;
  ClosedFaces none;
  ray.start(none, kOrigin, kDir, float(near), float(far));
  const float t = float(near + 0.25 * (far - near));
  ray.take_first_hit(t);
  const Interval iv = ray.interval(spot);
  EXPECT_EQ(iv.lo, float((double(t) - near) / (far - near)));
  EXPECT_EQ(iv.hi, iv.lo);
  EXPECT_EQ(depth_of_t(spot, float(far) * 2), 1.0f);
  EXPECT_EQ(depth_of_t(spot, 0.0f), 0.0f);
}

}  // namespace exit_depth_test
}  // namespace st
