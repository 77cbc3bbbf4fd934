/* The shadowtile C API from C99: connect, list and open a map, prefetch for a camera and
 * around a region, answer a batch of world points, print the map's stats. Links libshadowtile.so (or the static libraries).
 *
 *   c_client HOST PORT MAP [RADIUS] < points
 *
 * points: "x y z" lines (world units). Prints one line per point: its visibility as the
 * float's bits in hex (exact, for comparing runs), then the value. The prefetch asks for
 * the tiles a camera looking straight down on the scene needs (shadowtile_map_request_view,
 * what a game calls each frame for each camera) and the finest-level texels within RADIUS
 * (default 256) of the map's centre, and waits until both are resident, so answers there
 * are exact. */
#define _POSIX_C_SOURCE 199309L
#include <shadowtile/shadowtile.h>

#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

static void on_error(void* user_data, shadowtile_status status, const char* message) {
  (void)user_data;
  fprintf(stderr, "c_client: %s: %s\n", shadowtile_status_name(status), message);
}

static int read_points(shadowtile_point** out, size_t* count) {
  size_t cap = 1024, n = 0;
  shadowtile_point* p = malloc(cap * sizeof *p);
  double x, y, z;
  if (!p) return 0;
  while (scanf("%lf %lf %lf", &x, &y, &z) == 3) {
    if (n == cap) {
      shadowtile_point* q = realloc(p, 2 * cap * sizeof *p);
      if (!q) {
        free(p);
        return 0;
      }
      p = q;
      cap *= 2;
    }
    p[n].x = x;
    p[n].y = y;
    p[n].z = z;
    ++n;
  }
  *out = p;
  *count = n;
  return 1;
}

int main(int argc, char** argv) {
  shadowtile_client_options options;
  shadowtile_endpoint server;
  shadowtile_client* client = NULL;
  shadowtile_map* map = NULL;
  shadowtile_map_listing* maps = NULL;
  shadowtile_map_info info;
  shadowtile_map_stats stats;
  shadowtile_scene_extent scene;
  shadowtile_view_stats view;
  double camera[16];
  shadowtile_point* points = NULL;
  float* lit = NULL;
  size_t n_maps = 0, n = 0, i;
  uint64_t side, radius, x0, y0, w;
  int32_t resident = 0;
  int listed = 0, rc = 1;
  time_t deadline;
  if (argc != 4 && argc != 5) {
    fprintf(stderr, "usage: c_client HOST PORT MAP [RADIUS] < points\n");
    return 2;
  }
  shadowtile_set_error_callback(on_error, NULL); /* or read shadowtile_last_error() */
  shadowtile_client_options_default(&options);
  options.cache_slots = 1024;
  server.host = argv[1];
  server.port = (uint16_t)atoi(argv[2]);
  if (shadowtile_client_create(&server, 1, &options, &client) != SHADOWTILE_OK) return 1;
  if (shadowtile_client_list_maps(client, &maps, &n_maps) != SHADOWTILE_OK) goto done;
  for (i = 0; i < n_maps; ++i) listed |= strcmp(maps[i].name, argv[3]) == 0;
  shadowtile_free_map_listings(maps);
  if (!listed) {
    fprintf(stderr, "c_client: %s is not in the server's list\n", argv[3]);
    goto done;
  }
  if (shadowtile_client_open_map(client, argv[3], &map) != SHADOWTILE_OK) goto done;
  shadowtile_map_get_info(map, &info);
  fprintf(stderr, "c_client: %s: %s, 2^%u texels a side, %llu tiles\n", info.name, info.encoding,
          (unsigned)info.finest_level, (unsigned long long)info.tile_count);

  /* A camera looking straight down on the scene's footprint: an orthographic
   * view-projection, column-major (element (row r, column c) at [c * 4 + r]): x across,
   * z up the screen, height into depth [0, 1] from above the top to below the ground. */
  shadowtile_map_get_scene_extent(map, &scene);
  memset(camera, 0, sizeof camera);
  camera[0] = 2.0 / (scene.x1 - scene.x0);
  camera[12] = -(scene.x1 + scene.x0) / (scene.x1 - scene.x0);
  camera[9] = 2.0 / (scene.z1 - scene.z0);
  camera[13] = -(scene.z1 + scene.z0) / (scene.z1 - scene.z0);
  camera[6] = -1.0 / (scene.top - scene.ground + 2.0);
  camera[14] = (scene.top + 1.0) / (scene.top - scene.ground + 2.0);
  camera[15] = 1.0;

  side = (uint64_t)1 << info.finest_level;
  radius = argc == 5 ? (uint64_t)strtoull(argv[4], NULL, 10) : 256;
  x0 = side / 2 > radius ? side / 2 - radius : 0;
  y0 = x0;
  w = 2 * radius;
  deadline = time(NULL) + 60;
  for (;;) {
    struct timespec pause = {0, 5000000};
    if (shadowtile_map_request_view(map, 0, camera, 640, 360, NULL, &view) != SHADOWTILE_OK) goto done;
    shadowtile_map_request_region(map, info.finest_level, x0, y0, w, w, 1, NULL);
    shadowtile_map_region_resident(map, info.finest_level, x0, y0, w, w, &resident);
    if (resident && view.resident == view.kept) break;
    if (time(NULL) > deadline) {
      fprintf(stderr, "c_client: the view or the region is not resident after 60 s\n");
      goto done;
    }
    nanosleep(&pause, NULL);
  }

  if (!read_points(&points, &n) || !(lit = malloc((n ? n : 1) * sizeof *lit))) goto done;
  fprintf(stderr, "c_client: the camera needs %u tiles, holds %u, all resident\n", (unsigned)view.wanted,
          (unsigned)view.kept);
  if (shadowtile_map_visibility(map, points, n, 1, lit) != SHADOWTILE_OK) goto done;
  for (i = 0; i < n; ++i) {
    uint32_t bits;
    memcpy(&bits, &lit[i], sizeof bits);
    printf("%08lx %g\n", (unsigned long)bits, lit[i]);
  }
  shadowtile_map_get_stats(map, &stats);
  fprintf(stderr, "c_client: %zu points, %llu tiles received, %llu failed, %u slots resident\n", n,
          (unsigned long long)stats.tiles_received, (unsigned long long)stats.tiles_failed,
          (unsigned)stats.slots_resident);
  rc = stats.tiles_failed == 0 ? 0 : 1;
done:
  free(points);
  free(lit);
  shadowtile_map_close(map);
  shadowtile_client_destroy(client);
  return rc;
}
