# Sanitizer and fuzzing builds (docs/testing.md). Included once from the top
# CMakeLists.txt before the libraries are added.
#
#   ARTHROSIM_SANITIZE   "" (default) or a comma list for -fsanitize=, e.g.
#                        "address,undefined". Every library, test and program
#                        of the build is compiled and linked with it; UB
#                        reports abort (-fno-sanitize-recover) so a test or a
#                        fuzz input fails on the first one.
#   ARTHROSIM_FUZZ       ON: also build the libFuzzer targets of tests/fuzz
#                        (needs clang; coverage instrumentation is added to the
#                        libraries that hold the readers, common and
#                        musculoskeletal, see tests/fuzz/CMakeLists.txt).
#
# Use a build type of its own, "Sanitize" (-O1, line tables for symbolized
# reports, assertions on), in a build folder of its own (scripts/sanitize.sh
# uses build-sanitize/ with clang).
set(ARTHROSIM_SANITIZE "" CACHE STRING "Sanitizers for -fsanitize= (e.g. address,undefined); empty = none")
option(ARTHROSIM_FUZZ "Build the libFuzzer targets of tests/fuzz (clang only)" OFF)

# The Sanitize build type: -O1 keeps ASan's slowdown small while leaving
# stack traces readable; NDEBUG is NOT defined, so assert() and Eigen's index
# checks run too.
# (Normal variables: CMake creates empty cache entries for a custom build type.)
set(CMAKE_C_FLAGS_SANITIZE "-O1 -g1")
set(CMAKE_CXX_FLAGS_SANITIZE "-O1 -g1")

if(ARTHROSIM_SANITIZE)
  set(_san_flags -fsanitize=${ARTHROSIM_SANITIZE} -fno-omit-frame-pointer -fno-sanitize-recover=all)
  add_compile_options(${_san_flags})
  add_link_options(-fsanitize=${ARTHROSIM_SANITIZE})
  message(STATUS "arthrosim: sanitizers ${ARTHROSIM_SANITIZE} (build type ${CMAKE_BUILD_TYPE})")
endif()

if(ARTHROSIM_FUZZ)
  if(NOT CMAKE_CXX_COMPILER_ID MATCHES "Clang")
    message(FATAL_ERROR "ARTHROSIM_FUZZ needs clang (libFuzzer): configure with "
                        "-DCMAKE_CXX_COMPILER=clang++-14 -DCMAKE_C_COMPILER=clang-14")
  endif()
  if(NOT ARTHROSIM_SANITIZE)
    message(WARNING "ARTHROSIM_FUZZ without ARTHROSIM_SANITIZE finds crashes only; "
                    "use -DARTHROSIM_SANITIZE=address,undefined")
  endif()
endif()
