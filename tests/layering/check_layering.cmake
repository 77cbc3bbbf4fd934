# cmake -DROOT=<repository root> -P check_layering.cmake
# Fails (one line per offence) when a module's source includes a header of a module it
# may not see. The arrows are ARCHITECTURE.md's; a module always sees itself.
#
#   common      <- proto, net, tiles/core
#   proto       <- server, client
#   net         <- server, client
#   tiles/core  <- image <- scene <- tiles/bake <- render
#   tiles/core  <- tiles/encode <- tiles/bake
#   tiles/core  <- server, client
#   client      <- loadgen, gpu
#   client, gpu <- examples/raster (the rasterizer the view, the example and bench_raster
#                  share; also the header-only camera, and its flat_mesh.hpp reads a scene)
#   everything  <- app (and tests/, bench/, the other examples, which are not checked)
# No module includes tests/, bench/ or examples/ (test, bench and example code stays out
# of the product libraries), and no module holds a header that tests/ or bench/ include
# but no product source does (the modules, app/, examples/): such a header and its code
# serve only tests or benchmarks and belong in tests/ or bench/ (as the GPU passes' CPU
# twins, tests/gpu/shadow_twins.hpp, and the scene writer, tests/tiles/scene_export.hpp).
#
# And no include cycle among the modules' components (a component is a header with the
# .cpp of the same name, or with the parts its .cpp is split in when there is no a.cpp:
# a_x.cpp, a_y.cpp without headers of their own. a.hpp or a.cpp includes b.hpp, b.hpp or
# b.cpp includes a.hpp ... back to a). Among headers alone such a cycle compiles or not by include order (with
# `#pragma once`); through a .cpp it means neither part can be understood, tested or moved
# without the other.
cmake_minimum_required(VERSION 3.25)  # IN_LIST
if(NOT ROOT)
  message(FATAL_ERROR "check_layering: pass -DROOT=<repository root>")
endif()

set(allowed_common "common")
set(allowed_proto "common;proto")
set(allowed_net "common;net")
set(allowed_tiles/core "common;tiles/core")
set(allowed_tiles/encode "common;tiles/core;tiles/encode")
set(allowed_image "common;tiles/core;image")
set(allowed_scene "common;tiles/core;image;scene")
set(allowed_tiles/bake "common;tiles/core;tiles/encode;scene;tiles/bake")
set(allowed_render "common;tiles/core;tiles/encode;image;scene;tiles/bake;render")
set(allowed_server "common;proto;net;tiles/core;server")
set(allowed_client "common;proto;net;tiles/core;client")
set(allowed_loadgen "common;proto;tiles/core;client;loadgen")
set(allowed_gpu "common;tiles/core;client;gpu")
set(allowed_examples/raster "tiles/core;scene;client;examples")  # gpu: its public header only (shadowtile/)
set(modules common proto net tiles/core tiles/encode image scene tiles/bake render server client loadgen gpu examples/raster)
# Every folder that holds headers a module could include: an include of any other
# "x/..." path is not one of ours (a system or third-party header).
set(known_roots common proto net tiles/core tiles/encode image scene tiles/bake render server client loadgen gpu app tests bench
    examples)

# The folder among ARGN that the include path `inc` starts with ("" when none).
function(root_of inc out)
  set(found "")
  foreach(root ${ARGN})
    string(LENGTH "${root}/" n)
    string(SUBSTRING "${inc}" 0 ${n} head)
    if(head STREQUAL "${root}/")
      set(found ${root})
    endif()
  endforeach()
  set(${out} "${found}" PARENT_SCOPE)
endfunction()

set(offences 0)
set(components "")
foreach(mod ${modules})
  file(GLOB_RECURSE srcs ${ROOT}/${mod}/*.hpp ${ROOT}/${mod}/*.cpp ${ROOT}/${mod}/*.h
       ${ROOT}/${mod}/*.glsl ${ROOT}/${mod}/*.comp)
  foreach(src ${srcs})
    file(STRINGS ${src} lines REGEX "^[ \t]*#[ \t]*include[ \t]*\"")
    foreach(line ${lines})
      string(REGEX REPLACE "^[ \t]*#[ \t]*include[ \t]*\"([^\"]+)\".*$" "\\1" inc "${line}")
      root_of("${inc}" target ${known_roots})
      if(inc MATCHES "^shadowtile/")
        set(target client)  # the client's public header (client/include/shadowtile/)
      endif()
      if(target STREQUAL "")
        continue()  # not a project path (system header, or a path relative to the file)
      endif()
      # The header graph (include cycles, below).
      file(RELATIVE_PATH rel_src ${ROOT} ${src})
      string(REGEX REPLACE "\\.[^./]+$" "" from "${rel_src}")
      # A header whose .cpp is split in parts (a.hpp with a_x.cpp, a_y.cpp and no a.cpp:
      # client/remote_map_lookups.cpp, remote_map_residency.cpp) is one component with them.
      if(src MATCHES "\\.cpp$" AND NOT EXISTS ${ROOT}/${from}.hpp)
        set(stem "${from}")
        while(stem MATCHES "_[^_/]*$")
          string(REGEX REPLACE "_[^_/]*$" "" stem "${stem}")
          if(EXISTS ${ROOT}/${stem}.hpp)
            if(NOT EXISTS ${ROOT}/${stem}.cpp)
              set(from "${stem}")
            endif()
            break()
          endif()
        endwhile()
      endif()
      set(inc_path "${inc}")
      if(inc MATCHES "^shadowtile/")
        set(inc_path "client/include/${inc}")
      endif()
      string(REGEX REPLACE "\\.[^./]+$" "" to "${inc_path}")
      if(NOT from STREQUAL to AND EXISTS ${ROOT}/${inc_path})
        list(APPEND "deps_${from}" "${to}")
        list(APPEND components "${from}" "${to}")
        list(APPEND product_includes "${inc_path}")
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

# Headers of the modules that only tests/ or bench/ include. The product's other sources
# (app/, examples/) count as includers; a header's own .cpp does not (above).
function(includes_under root out)
  file(GLOB_RECURSE files ${ROOT}/${root}/*.hpp ${ROOT}/${root}/*.cpp ${ROOT}/${root}/*.h ${ROOT}/${root}/*.c)
  set(found "")
  foreach(f ${files})
    file(STRINGS ${f} lines REGEX "^[ \t]*#[ \t]*include[ \t]*\"")
    foreach(line ${lines})
      string(REGEX REPLACE "^[ \t]*#[ \t]*include[ \t]*\"([^\"]+)\".*$" "\\1" inc "${line}")
      list(APPEND found "${inc}")
    endforeach()
  endforeach()
  list(REMOVE_DUPLICATES found)
  set(${out} "${found}" PARENT_SCOPE)
endfunction()
includes_under(app app_includes)
includes_under(examples example_includes)
list(APPEND product_includes ${app_includes} ${example_includes})
includes_under(tests test_includes)
includes_under(bench bench_includes)
set(support_includes ${test_includes} ${bench_includes})
list(REMOVE_DUPLICATES support_includes)
# Library code that only tests and benchmarks reach today, each with its reason.
set(support_only_known
  # The reference lookups of a stack (the contract StackMap answers bit for bit; its header
  # is installed with the client's documentation).
  tiles/core/stack_lookup.hpp
  # The DAG-MH encoder's entry with statistics (the product calls encode_dagmh, encode.hpp).
  tiles/encode/dagmh_encode.hpp
  # The measure of subtree sharing in stack octrees behind the format's design (MHOCT.md).
  tiles/encode/mh_octree_share.hpp)
foreach(inc ${support_includes})
  root_of("${inc}" mod ${modules})
  if(mod STREQUAL "" OR inc MATCHES "/include/" OR NOT EXISTS ${ROOT}/${inc} OR "${inc}" IN_LIST product_includes
     OR "${inc}" IN_LIST support_only_known)
    continue()
  endif()
  message("layering: ${inc} is included by tests/ or bench/ but by no product source: its code serves only "
          "tests or benchmarks and belongs in tests/ or bench/")
  math(EXPR offences "${offences} + 1")
endforeach()

# Include cycles among components: drop every component that depends on no remaining one
# (a sink), then every one no remaining one depends on (a source), until nothing changes;
# every cycle lies in what is left (with what lies between two cycles).
list(REMOVE_DUPLICATES components)
set(left ${components})
set(changed TRUE)
while(changed)
  set(changed FALSE)
  set(keep "")
  foreach(c ${left})
    foreach(d ${deps_${c}})
      if("${d}" IN_LIST left)
        list(APPEND keep "${c}")
        break()
      endif()
    endforeach()
  endforeach()
  set(needed "")
  foreach(c ${keep})
    foreach(d ${deps_${c}})
      if("${d}" IN_LIST keep)
        list(APPEND needed "${d}")
      endif()
    endforeach()
  endforeach()
  set(next "")
  foreach(c ${keep})
    if("${c}" IN_LIST needed)
      list(APPEND next "${c}")
    endif()
  endforeach()
  list(REMOVE_DUPLICATES next)
  list(LENGTH left n_left)
  list(LENGTH next n_next)
  if(NOT n_next EQUAL n_left)
    set(changed TRUE)
  endif()
  set(left ${next})
endwhile()
# What each remaining component reaches (within what is left: a cycle never leaves it);
# a cycle is the components that reach each other.
foreach(c ${left})
  set(reach_${c} "")
  set(todo ${c})
  while(todo)
    list(POP_FRONT todo x)
    foreach(d ${deps_${x}})
      if("${d}" IN_LIST left AND NOT "${d}" IN_LIST reach_${c})
        list(APPEND reach_${c} "${d}")
        list(APPEND todo "${d}")
      endif()
    endforeach()
  endwhile()
endforeach()
# Cycles written down with the reason they are still there; any other cycle fails, and so
# does a listed one that has grown (its members are compared whole).
set(known_cycles
  # messages.cpp checks with message_rules and frames with tile_prefix, whose headers take
  # messages.hpp's types: the message types want a header of their own.
  "proto/message_rules,proto/messages,proto/tile_prefix"
  # server.cpp starts connections, whose core state holds ServerOptions (server.hpp).
  "server/connection,server/server,server/server_core"
  # deep_part.cpp fills RemoteMap's deep state; remote_map.hpp holds a DeepPart.
  "client/deep_part,client/remote_map"
  # gpu_map.cpp drives the kernels, layout and context, whose headers take gpu_map.hpp's types.
  "gpu/gpu_deep,gpu/gpu_map,gpu/kernels,gpu/layout,gpu/shadow_reference,gpu/vk_context")
set(reported "")
foreach(c ${left})
  if(NOT "${c}" IN_LIST reach_${c} OR "${c}" IN_LIST reported)
    continue()
  endif()
  set(cycle ${c})
  foreach(x ${reach_${c}})
    if("${c}" IN_LIST reach_${x})
      list(APPEND cycle "${x}")
    endif()
  endforeach()
  list(REMOVE_DUPLICATES cycle)
  list(SORT cycle)
  list(APPEND reported ${cycle})
  string(REPLACE ";" "," key "${cycle}")
  if("${key}" IN_LIST known_cycles)
    continue()
  endif()
  foreach(x ${cycle})
    set(on "")
    foreach(d ${deps_${x}})
      if("${d}" IN_LIST cycle)
        list(APPEND on "${d}")
      endif()
    endforeach()
    list(REMOVE_DUPLICATES on)
    string(REPLACE ";" ", " on "${on}")
    message("layering: include cycle: ${x} includes ${on}, which lead back to it")
    math(EXPR offences "${offences} + 1")
  endforeach()
endforeach()

if(offences GREATER 0)
  message(FATAL_ERROR "layering: ${offences} include(s) against the module arrows, in a cycle or of test code in a module (ARCHITECTURE.md)")
endif()
message(STATUS "layering: every module includes only what it may see, and no include cycle but the listed ones")
