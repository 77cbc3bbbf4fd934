# shadowtile_module(NAME DIR [PUBLIC_DEPS ...] [PRIVATE_DEPS ...]): one library per module
# folder, target shadowtile_NAME with the alias shadowtile::NAME. Its sources are the
# folder's *.cpp files except main.cpp (a module's executable, declared beside it). The
# include root is the repository root ("tiles/core/x.hpp").
function(shadowtile_module name dir)
  cmake_parse_arguments(M "" "" "PUBLIC_DEPS;PRIVATE_DEPS" ${ARGN})
  file(GLOB srcs CONFIGURE_DEPENDS ${dir}/*.cpp)
  list(FILTER srcs EXCLUDE REGEX "/main\\.cpp$")
  # Always static (position-independent): with BUILD_SHARED_LIBS the client still ships as
  # the one libshadowtile.so (client/CMakeLists.txt), not as a .so per module.
  add_library(shadowtile_${name} STATIC ${srcs})
  add_library(shadowtile::${name} ALIAS shadowtile_${name})
  target_include_directories(shadowtile_${name} PUBLIC
    $<BUILD_INTERFACE:${PROJECT_SOURCE_DIR}> $<INSTALL_INTERFACE:include>)
  target_link_libraries(shadowtile_${name} PUBLIC ${M_PUBLIC_DEPS} PRIVATE $<BUILD_INTERFACE:shadowtile_warnings> ${M_PRIVATE_DEPS})
  set_target_properties(shadowtile_${name} PROPERTIES POSITION_INDEPENDENT_CODE ON EXPORT_NAME ${name})
endfunction()
