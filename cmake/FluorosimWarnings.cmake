add_library(fluorosim_warnings INTERFACE)
target_compile_options(fluorosim_warnings INTERFACE -Wall -Wextra -Wpedantic -Wno-missing-field-initializers)
# -Wshadow=local is gcc's spelling; clang (used only for the fuzzers) has no equivalent of that name.
if(CMAKE_CXX_COMPILER_ID STREQUAL "GNU")
  target_compile_options(fluorosim_warnings INTERFACE -Wshadow=local)
endif()
