add_library(fluorosim_warnings INTERFACE)
target_compile_options(fluorosim_warnings INTERFACE -Wall -Wextra -Wpedantic -Wshadow=local -Wno-missing-field-initializers)
