# Every dependency comes from Debian packages (scripts/install-deps.sh).
# Order matters: TBB's config before OpenVDB's find module, which would otherwise define TBB::tbb itself.
find_package(Threads REQUIRED)
find_package(TBB CONFIG REQUIRED)
# Ceres (the concentration fit, optics/concentration_fit.cpp) before OpenVDB: its SuiteSparse finder loads
# TBB's config, which must not meet the TBB::tbb that OpenVDB's find module would define.
find_package(Ceres 2.1 REQUIRED)
# OpenEXR's own config (with Imath include paths), before OpenVDB's find modules shadow it.
find_package(OpenEXR 3 CONFIG REQUIRED)

list(APPEND CMAKE_MODULE_PATH /usr/lib/x86_64-linux-gnu/cmake/OpenVDB /usr/lib/cmake/OpenVDB)
find_package(OpenVDB REQUIRED)

find_package(embree 3 REQUIRED)
find_package(PNG REQUIRED)
find_package(TIFF REQUIRED)
find_package(CLI11 CONFIG REQUIRED)
find_package(nlohmann_json 3 REQUIRED)
find_package(assimp REQUIRED)
# FFTW (libfftw3-dev) has no CMake config in Debian; its pkg-config file gives an imported target.
find_package(PkgConfig REQUIRED)
pkg_check_modules(FFTW3 REQUIRED IMPORTED_TARGET fftw3)
if(FLUOROSIM_WITH_VIEWER)
  # Debian's VTK 9.1 (libvtk9-dev). Only apps/viewer links it. Its config loads TBB through TBB's own
  # config, which is already loaded above, so the targets are not defined twice.
  find_package(VTK 9.1 REQUIRED COMPONENTS
    CommonCore CommonDataModel CommonColor FiltersCore FiltersGeneral FiltersModeling FiltersSources
    ImagingCore IOImage IOOggTheora InteractionStyle InteractionWidgets RenderingCore RenderingOpenGL2
    RenderingVolume RenderingVolumeOpenGL2 RenderingAnnotation RenderingFreeType RenderingImage)
  find_package(X11 REQUIRED)
endif()
if(FLUOROSIM_WITH_MPI)
  find_package(MPI COMPONENTS C)
  if(NOT MPI_C_FOUND)
    message(FATAL_ERROR "FLUOROSIM_WITH_MPI is ON but no MPI was found: install libopenmpi-dev and openmpi-bin, or configure with -DFLUOROSIM_WITH_MPI=OFF")
  endif()
endif()
if(FLUOROSIM_WITH_PYTHON)
  # Debian's interpreter, the one its python3-numpy and python3-pytest belong to.
  set(Python_EXECUTABLE /usr/bin/python3 CACHE FILEPATH "Python for the fluorosim module and its tests")
  set(PYBIND11_FINDPYTHON ON)
  find_package(Python 3 COMPONENTS Interpreter Development.Module REQUIRED)
  find_package(pybind11 CONFIG)
  if(NOT pybind11_FOUND)
    message(FATAL_ERROR "FLUOROSIM_WITH_PYTHON is ON but pybind11 was not found: install pybind11-dev, or configure with -DFLUOROSIM_WITH_PYTHON=OFF")
  endif()
endif()
if(FLUOROSIM_BUILD_TESTS)
  find_package(GTest REQUIRED)
endif()
if(FLUOROSIM_BUILD_BENCH)
  find_package(benchmark REQUIRED)
endif()
