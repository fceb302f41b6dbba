# Precompiled headers for unity builds: the third-party headers most sources include (Eigen, nlohmann/json,
# spdlog/fmt, OpenCV core, TBB, the standard library) are compiled once, in fmv3d_pch, and every other C++ target
# reuses that one precompiled header (REUSE_FROM) instead of parsing them in each unity batch. One PCH for all
# targets, not one per target: building it costs as much as parsing the headers in a few batches. The gain is
# small, as a unity batch's time is mostly code generation: 3–7% of a batch's compile CPU (bench/results/ci6.md).
# GCC takes the PCH only when the compile flags and macros match those it was made with (CMake passes
# -Winvalid-pch, so a mismatch warns and the header is parsed as text: slower, never wrong). So every target gets
# fmv3d_pch's usage requirements (spdlog's macros, the include paths), and _GLIBCXX_USE_CXX11_ABI=1 (libstdc++'s
# default, which Open3D's targets pass explicitly) is defined everywhere, or half the targets would refuse the PCH.
# Off for per-file builds (`make UNITY=OFF`): there ccache already skips unchanged sources, and a PCH would make
# every compilation depend on it.
option(FMV3D_PCH "With FMV3D_UNITY: precompile the heavy third-party headers once for every target" ON)

# Every target defined in `dir` and its subdirectories.
function(fmv3d_targets_in dir out)
  get_property(targets DIRECTORY ${dir} PROPERTY BUILDSYSTEM_TARGETS)
  get_property(subdirs DIRECTORY ${dir} PROPERTY SUBDIRECTORIES)
  foreach(sub ${subdirs})
    fmv3d_targets_in(${sub} sub_targets)
    list(APPEND targets ${sub_targets})
  endforeach()
  set(${out} ${targets} PARENT_SCOPE)
endfunction()

# Call at the end of the top-level CMakeLists.txt, once every target exists.
function(fmv3d_precompile_headers)
  if(NOT FMV3D_UNITY OR NOT FMV3D_PCH OR FMV3D_FUZZ)
    return()
  endif()
  add_library(fmv3d_pch STATIC ${PROJECT_SOURCE_DIR}/cmake/pch.cc)
  target_link_libraries(fmv3d_pch PUBLIC Eigen3::Eigen spdlog::spdlog nlohmann_json::nlohmann_json TBB::tbb)
  target_include_directories(fmv3d_pch SYSTEM PUBLIC ${OpenCV_INCLUDE_DIRS})
  target_compile_definitions(fmv3d_pch PUBLIC _GLIBCXX_USE_CXX11_ABI=1)
  target_precompile_headers(fmv3d_pch PRIVATE
    <algorithm> <cmath> <cstdint> <filesystem> <fstream> <functional> <map> <memory> <optional> <random> <set>
    <string> <vector> <Eigen/Core> <Eigen/Geometry> <nlohmann/json.hpp> <spdlog/spdlog.h> <fmt/format.h>
    <opencv2/core.hpp> <opencv2/imgproc.hpp> <tbb/parallel_for.h>)
  fmv3d_targets_in(${PROJECT_SOURCE_DIR} targets)
  foreach(t ${targets})
    get_target_property(type ${t} TYPE)
    if(t STREQUAL "fmv3d_pch" OR NOT (type STREQUAL "STATIC_LIBRARY" OR type STREQUAL "EXECUTABLE"))
      continue()
    endif()
    target_precompile_headers(${t} REUSE_FROM fmv3d_pch)
    get_target_property(pch_defs fmv3d_pch INTERFACE_COMPILE_DEFINITIONS)
    get_target_property(pch_dirs fmv3d_pch INTERFACE_INCLUDE_DIRECTORIES)
    target_compile_definitions(${t} PRIVATE ${pch_defs})
    target_include_directories(${t} SYSTEM PRIVATE ${pch_dirs})
    target_link_libraries(${t} PRIVATE spdlog::spdlog)  # its macros (header-only or compiled spdlog, fmt)
  endforeach()
endfunction()
