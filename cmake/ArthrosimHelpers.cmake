# Warnings of the project's own code: GCC's (and clang's) -Wall -Wextra on
# every library, app, test, benchmark and fuzz target; -Werror on GCC when
# ARTHROSIM_WERROR is ON (CI: .ci/run -> scripts/build.sh). Third-party
# headers come in as SYSTEM include directories (imported targets, or
# target_include_directories(... SYSTEM ...)), so they never trip it.
option(ARTHROSIM_WERROR "Treat warnings of the project's own code as errors (GCC)" OFF)
function(arthrosim_warnings target)
  target_compile_options(${target} PRIVATE -Wall -Wextra
                         $<$<AND:$<BOOL:${ARTHROSIM_WERROR}>,$<CXX_COMPILER_ID:GNU>>:-Werror>)
endfunction()

# arthrosim_public_headers(TARGET FOLDER): the target's PUBLIC include
# directory is ${CMAKE_BINARY_DIR}/include/<target>, which holds only a link
# <folder-name> -> FOLDER. So `#include "common/mesh.h"` resolves only in
# targets that link arthrosim_common (directly or through a PUBLIC
# dependency): there is no repository-wide include root, and a layering
# violation is a compile error.
function(arthrosim_public_headers target folder)
  get_filename_component(_name ${folder} NAME)
  set(_inc ${CMAKE_BINARY_DIR}/include/${target})
  file(MAKE_DIRECTORY ${_inc})
  if(NOT EXISTS ${_inc}/${_name})
    file(CREATE_LINK ${folder} ${_inc}/${_name} SYMBOLIC)
  endif()
  get_target_property(_type ${target} TYPE)
  if(_type STREQUAL "INTERFACE_LIBRARY")
    target_include_directories(${target} INTERFACE ${_inc})
  else()
    target_include_directories(${target} PUBLIC ${_inc})
  endif()
endfunction()

# arthrosim_add_library(NAME DIR): one library per top-level folder. Sources are
# every *.cc directly in DIR (CONFIGURE_DEPENDS so new files are picked up).
function(arthrosim_add_library name dir)
  file(GLOB _srcs CONFIGURE_DEPENDS ${dir}/*.cc)
  file(GLOB _hdrs CONFIGURE_DEPENDS ${dir}/*.h)
  if(NOT _srcs)
    # A library whose folder has no sources yet still needs one translation unit.
    set(_anchor ${CMAKE_BINARY_DIR}/generated/${name}_anchor.cc)
    file(WRITE ${_anchor} "// generated: ${name} has no sources of its own yet\n")
    set(_srcs ${_anchor})
  endif()
  add_library(${name} STATIC ${_srcs} ${_hdrs})
  arthrosim_public_headers(${name} ${dir})
  target_link_libraries(${name} PUBLIC Eigen3::Eigen)
  arthrosim_warnings(${name})
endfunction()

# arthrosim_link_included(TARGET FILE...): links TARGET with exactly the
# project libraries whose headers FILE... include (`#include "<lib>/..."` ->
# arthrosim_<lib>), following the test-support headers they include
# (`#include "tests/..."` -> arthrosim_test_support) and the headers beside
# them (`#include "x.h"`). A test links what it tests, nothing more.
function(arthrosim_link_included target)
  set(_todo ${ARGN})
  set(_seen)
  set(_libs)
  while(_todo)
    list(POP_FRONT _todo _file)
    if(_file IN_LIST _seen OR NOT EXISTS ${_file})
      continue()
    endif()
    list(APPEND _seen ${_file})
    get_filename_component(_dir ${_file} DIRECTORY)
    file(STRINGS ${_file} _local REGEX "^#include \"[A-Za-z0-9_]+\\.h\"")
    foreach(_line ${_local})
      string(REGEX REPLACE "^#include \"([^\"]+)\".*" "\\1" _h "${_line}")
      list(APPEND _todo ${_dir}/${_h})
    endforeach()
    file(STRINGS ${_file} _lines REGEX "^#include \"[a-z_]+/")
    foreach(_line ${_lines})
      string(REGEX REPLACE "^#include \"([a-z_]+)/([^\"]+)\".*" "\\1;\\2" _parts "${_line}")
      list(GET _parts 0 _lib)
      list(GET _parts 1 _rest)
      if(_lib STREQUAL "tests")
        list(APPEND _libs arthrosim_test_support)
        list(APPEND _todo ${CMAKE_SOURCE_DIR}/tests/${_rest})
      elseif(TARGET arthrosim_${_lib})
        list(APPEND _libs arthrosim_${_lib})
      endif()
    endforeach()
  endwhile()
  # A file that gains an include re-runs the configure step.
  set_property(DIRECTORY APPEND PROPERTY CMAKE_CONFIGURE_DEPENDS ${_seen})
  if(_libs)
    list(REMOVE_DUPLICATES _libs)
    target_link_libraries(${target} PRIVATE ${_libs})
  endif()
endfunction()
