# cmake -DROOT=<repository root> -P check_layering.cmake
# Fails (one line per offence) when a module's source includes a header of a module it
# may not see. The arrows are ARCHITECTURE.md's; a module always sees itself.
#
#   common      <- proto, net, tiles/core
#   proto       <- server, client
#   net         <- server, client
#   tiles/core  <- tiles/build <- tiles/bake
#   tiles/core  <- server, client
#   client      <- loadgen, gpu
#   everything  <- app (and tests/, bench/, which are not checked)
if(NOT ROOT)
  message(FATAL_ERROR "check_layering: pass -DROOT=<repository root>")
endif()

set(allowed_common "common")
set(allowed_proto "common;proto")
set(allowed_net "common;net")
set(allowed_tiles/core "common;tiles/core")
set(allowed_tiles/build "common;tiles/core;tiles/build")
set(allowed_tiles/bake "common;tiles/core;tiles/build;tiles/bake")
set(allowed_server "common;proto;net;tiles/core;server")
set(allowed_client "common;proto;net;tiles/core;client")
set(allowed_loadgen "common;proto;tiles/core;client;loadgen")
set(allowed_gpu "common;tiles/core;client;gpu")
set(modules common proto net tiles/core tiles/build tiles/bake server client loadgen gpu)
# Every folder that holds headers a module could include: an include of any other
# "x/..." path is not one of ours (a system or third-party header).
set(known_roots common proto net tiles/core tiles/build tiles/bake server client loadgen gpu app tests bench)

set(offences 0)
foreach(mod ${modules})
  file(GLOB_RECURSE srcs ${ROOT}/${mod}/*.hpp ${ROOT}/${mod}/*.cpp ${ROOT}/${mod}/*.h
       ${ROOT}/${mod}/*.glsl ${ROOT}/${mod}/*.comp)
  foreach(src ${srcs})
    file(STRINGS ${src} lines REGEX "^[ \t]*#[ \t]*include[ \t]*\"")
    foreach(line ${lines})
      string(REGEX REPLACE "^[ \t]*#[ \t]*include[ \t]*\"([^\"]+)\".*$" "\\1" inc "${line}")
      set(target "")
      foreach(root ${known_roots})
        string(LENGTH "${root}/" n)
        string(SUBSTRING "${inc}" 0 ${n} head)
        if(head STREQUAL "${root}/")
          set(target ${root})
        endif()
      endforeach()
      if(inc MATCHES "^shadowtile/")
        set(target client)  # the client's public header (client/include/shadowtile/)
      endif()
      if(target STREQUAL "")
        continue()  # not a project path (system header, or a path relative to the file)
      endif()
      list(FIND allowed_${mod} ${target} ok)
      if(ok EQUAL -1)
        file(RELATIVE_PATH rel ${ROOT} ${src})
        message("layering: ${rel} includes \"${inc}\": ${mod} may not see ${target}")
        math(EXPR offences "${offences} + 1")
      endif()
    endforeach()
  endforeach()
endforeach()
if(offences GREATER 0)
  message(FATAL_ERROR "layering: ${offences} include(s) against the module arrows (ARCHITECTURE.md)")
endif()
message(STATUS "layering: every module includes only what it may see")
