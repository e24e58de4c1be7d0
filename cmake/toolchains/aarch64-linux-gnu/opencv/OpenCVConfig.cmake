# OpenCV for the aarch64 cross build (cmake/toolchains/aarch64-linux-gnu.cmake sets OpenCV_DIR).
#
# Debian bookworm's libopencv-dev:arm64 cannot be installed next to the host's, so the cross build
# links against the arm64 runtime libraries that scripts/fetch_arm64_opencv.sh unpacks into
# ACT_ARM64_OPENCV_ROOT, with the host's headers (the same OpenCV version; architecture-independent).
# Those libraries' own dependencies (FFmpeg, GDAL, ...) are not there: the link allows symbols left
# undefined in them (the Pi's loader resolves them from the runtime packages the .deb depends on).
# Defines what the Debian package's OpenCVConfig does for the components asked for: OpenCV_LIBS,
# OpenCV_INCLUDE_DIRS, OpenCV_VERSION; and ACT_OPENCV_DEB_DEPENDS (the runtime packages, for CPack).
if(NOT ACT_ARM64_OPENCV_ROOT AND DEFINED ENV{ACT_ARM64_OPENCV_ROOT})
  set(ACT_ARM64_OPENCV_ROOT "$ENV{ACT_ARM64_OPENCV_ROOT}")
endif()
set(_act_cv_libdir "${ACT_ARM64_OPENCV_ROOT}/usr/lib/${CMAKE_LIBRARY_ARCHITECTURE}")
set(_act_cv_fetch_hint "run scripts/fetch_arm64_opencv.sh DIR and configure with -DACT_ARM64_OPENCV_ROOT=DIR/root")
if(NOT ACT_ARM64_OPENCV_ROOT OR NOT EXISTS "${ACT_ARM64_OPENCV_ROOT}/depends.txt")
  set(OpenCV_FOUND FALSE)
  set(OpenCV_NOT_FOUND_MESSAGE "no arm64 OpenCV libraries (ACT_ARM64_OPENCV_ROOT='${ACT_ARM64_OPENCV_ROOT}'): \
${_act_cv_fetch_hint}, or configure with -DACT_WITH_OPENCV=OFF to build without act_convert and act_drive")
  return()
endif()
find_path(_act_cv_include opencv2/core.hpp PATHS /usr/include/opencv4 NO_DEFAULT_PATH NO_CMAKE_FIND_ROOT_PATH)
if(NOT _act_cv_include)
  set(OpenCV_FOUND FALSE)
  set(OpenCV_NOT_FOUND_MESSAGE "no OpenCV headers in /usr/include/opencv4: run scripts/install_deps.sh")
  return()
endif()

set(OpenCV_LIBS "")
foreach(_act_cv_module IN LISTS OpenCV_FIND_COMPONENTS)
  file(GLOB _act_cv_so "${_act_cv_libdir}/libopencv_${_act_cv_module}.so.[0-9][0-9][0-9]")
  if(NOT _act_cv_so)
    set(OpenCV_FOUND FALSE)
    set(OpenCV_NOT_FOUND_MESSAGE "no arm64 libopencv_${_act_cv_module} in ${_act_cv_libdir}: ${_act_cv_fetch_hint}")
    return()
  endif()
  if(NOT TARGET opencv_${_act_cv_module})
    add_library(opencv_${_act_cv_module} SHARED IMPORTED)
    get_filename_component(_act_cv_soname "${_act_cv_so}" NAME)
    set_target_properties(opencv_${_act_cv_module} PROPERTIES
      IMPORTED_LOCATION "${_act_cv_so}"
      IMPORTED_SONAME "${_act_cv_soname}"
      INTERFACE_INCLUDE_DIRECTORIES "${_act_cv_include}"
      # The libraries OpenCV itself needs are on the Pi, not here.
      INTERFACE_LINK_OPTIONS "LINKER:--allow-shlib-undefined;LINKER:-rpath-link,${_act_cv_libdir}")
  endif()
  list(APPEND OpenCV_LIBS opencv_${_act_cv_module})
endforeach()
set(OpenCV_INCLUDE_DIRS "${_act_cv_include}")
file(GLOB _act_cv_full "${_act_cv_libdir}/libopencv_core.so.*.*.*")
string(REGEX MATCH "[0-9]+\\.[0-9]+\\.[0-9]+$" OpenCV_VERSION "${_act_cv_full}")
file(READ "${ACT_ARM64_OPENCV_ROOT}/depends.txt" ACT_OPENCV_DEB_DEPENDS)
string(STRIP "${ACT_OPENCV_DEB_DEPENDS}" ACT_OPENCV_DEB_DEPENDS)
set(ACT_OPENCV_DEB_DEPENDS "${ACT_OPENCV_DEB_DEPENDS}" CACHE INTERNAL "arm64 OpenCV runtime packages")
set(ACT_OPENCV_LIBDIR "${_act_cv_libdir}" CACHE INTERNAL "arm64 OpenCV libraries, for dpkg-shlibdeps")
set(OpenCV_FOUND TRUE)
