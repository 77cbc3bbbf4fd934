// Shared by the loadgen tests: a small city pack and an in-process server on port 0.
#pragma once
#include <unistd.h>
#include <cstdlib>
#include <memory>
#include <string>

#include "server/server.hpp"
#include "tiles/bake/map_build.hpp"
#include "scene/scene.hpp"

namespace st::loadtest {

inline bool small_scale() {
  const char* s = std::getenv("SHADOWTILE_TEST_SCALE");
  return s && std::string(s) == "small";
}

struct CityPack {
  Scene scene;
  LightSpace light;
  std::string path;
};

// procedural:city (small) at 2^level, built once per process per level.
inline const CityPack& city_pack(uint32_t level) {
  static std::unique_ptr<CityPack> cached[21];
  if (!cached[level]) {
    auto p = std::make_unique<CityPack>();
    p->scene = make_procedural("procedural:city,size=6");
    p->light = LightSpace::fit(LightSpec::parse("sun:azimuth=30,elevation=50"), p->scene.bounds());
    p->path = std::string(SHADOWTILE_TEST_TMP) + "/loadgen_city_" + std::to_string(level) + "_" +
              std::to_string(::getpid()) + ".pack";  // ctest runs tests in parallel processes
    MapBuildOptions o;
    o.map_level = level;
    o.encoding = Encoding::dagmh;
    o.tile_bytes = 16 * 1024;
    build_map(p->scene, p->light, o, p->path);
    cached[level] = std::move(p);
  }
  return *cached[level];
}

inline std::unique_ptr<server::Server> start_server(const std::string& name, const std::string& path) {
  server::Catalog cat;
  cat.add(name, path);
  server::ServerOptions o;
  o.port = 0;
  o.log = [](const std::string&) {};
  auto s = std::make_unique<server::Server>(std::move(cat), o);
  s->start();
  return s;
}

}  // namespace st::loadtest
