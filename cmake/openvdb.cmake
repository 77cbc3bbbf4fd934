# OpenVDB (.vdb density grids read as scene volumes; scene/scene_vdb.cpp). Only shadowtile::scene
# links it: never the client library or the server.
#
# Debian 12's libopenvdb-dev ships OpenVDB's own find module in lib/cmake/OpenVDB, but next
# to its own FindTBB.cmake and FindOpenEXR.cmake, which would shadow the CONFIG packages this
# project already found (and FindTBB redefines TBB::tbb). So the library is found directly:
# the header and the shared library (its own dependencies, blosc, boost_iostreams,
# log4cplus, are its DT_NEEDED), plus what its headers need at compile and link time: Imath
# (openvdb/Types.h includes <Imath/half.h> when OPENVDB_USE_IMATH_HALF, as Debian's
# version.h says) and TBB (templates instantiated in our code call it).
#
# SHADOWTILE_OPENVDB=OFF builds without it: "vdb:" scenes then fail with one line saying so.
option(SHADOWTILE_OPENVDB "Read OpenVDB volumes (.vdb; needs libopenvdb-dev)" ON)
if(SHADOWTILE_OPENVDB)
  find_path(OPENVDB_INCLUDE_DIR openvdb/openvdb.h)
  find_library(OPENVDB_LIBRARY openvdb)
  find_package(Imath CONFIG)
  if(NOT OPENVDB_INCLUDE_DIR OR NOT OPENVDB_LIBRARY OR NOT Imath_FOUND)
    message(FATAL_ERROR "OpenVDB not found (header ${OPENVDB_INCLUDE_DIR}, library ${OPENVDB_LIBRARY}, "
                        "Imath ${Imath_FOUND}): run scripts/deps (libopenvdb-dev), or configure with "
                        "-DSHADOWTILE_OPENVDB=OFF to build without .vdb volumes")
  endif()
  if(NOT TARGET OpenVDB::openvdb)
    add_library(OpenVDB::openvdb UNKNOWN IMPORTED)
    set_target_properties(OpenVDB::openvdb PROPERTIES
      IMPORTED_LOCATION ${OPENVDB_LIBRARY}
      INTERFACE_INCLUDE_DIRECTORIES ${OPENVDB_INCLUDE_DIR}
      INTERFACE_LINK_LIBRARIES "Imath::Imath;TBB::tbb")
  endif()
  message(STATUS "OpenVDB: ${OPENVDB_LIBRARY}")
endif()
