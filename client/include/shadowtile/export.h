/* shadowtile: what the shared library (libshadowtile.so) exports. Every function and class
 * of the public API (shadowtile.h, client.hpp) carries SHADOWTILE_API; the library is
 * compiled with hidden visibility, so nothing else leaves it. Harmless in the static
 * libraries. C and C++. */
#ifndef SHADOWTILE_EXPORT_H
#define SHADOWTILE_EXPORT_H

#if defined(_WIN32)
#  if defined(SHADOWTILE_BUILDING_DLL)
#    define SHADOWTILE_API __declspec(dllexport)
#  elif defined(SHADOWTILE_USING_DLL)
#    define SHADOWTILE_API __declspec(dllimport)
#  else
#    define SHADOWTILE_API
#  endif
#elif defined(__GNUC__) || defined(__clang__)
#  define SHADOWTILE_API __attribute__((visibility("default")))
#else
#  define SHADOWTILE_API
#endif

#endif /* SHADOWTILE_EXPORT_H */
