# The product's libraries and executables are compiled in unity batches (CMake's
# UNITY_BUILD), as the test binaries are (tests/CMakeLists.txt): each batch of a target's
# .cpp files is one translation unit, so the standard library's, Boost's and our own
# headers are parsed, and their templates instantiated, once per batch instead of once per
# file. A file whose file-local names (anonymous-namespace helpers, statics, macros,
# using-directives) clash with another file of its target is kept out of the batches with
# SKIP_UNITY_BUILD_INCLUSION beside the target's declaration (or grouped with UNITY_GROUP);
# files with their own COMPILE_OPTIONS (the -ffp-contract=off files) are compiled alone by
# CMake anyway. SHADOWTILE_UNITY=OFF compiles every file on its own (quicker to rebuild
# after editing one file, and what finds a missing include a batch would hide).
option(SHADOWTILE_UNITY "Compile the product's libraries and executables in unity batches" ON)
set(SHADOWTILE_UNITY_BATCH 8 CACHE STRING "Product source files per unity translation unit")
function(shadowtile_unity target)
  if(SHADOWTILE_UNITY)
    set_target_properties(${target} PROPERTIES UNITY_BUILD ON UNITY_BUILD_BATCH_SIZE ${SHADOWTILE_UNITY_BATCH})
    # g++ warns when a class of a named namespace has a member whose type is in an
    # anonymous namespace (a pimpl's Impl over file-local helpers; Asio's coroutine frames)
    # only where the class is not defined in the main file, which a batched .cpp never is.
    target_compile_options(${target} PRIVATE $<$<CXX_COMPILER_ID:GNU>:-Wno-subobject-linkage>)
  endif()
endfunction()

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
  shadowtile_unity(shadowtile_${name})
endfunction()
