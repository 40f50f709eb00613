# `cmake --install build --prefix P` installs the libraries (Fluorosim::sim, ::spectra, ::optics), their
# headers under P/include/fluorosim, the CLI, the spectral data under P/share/fluorosim/spectra and a
# package config, so that another project can find_package(Fluorosim) (tests/package builds one).
include(CMakePackageConfigHelpers)
set(FLUOROSIM_CMAKE_DIR ${CMAKE_INSTALL_LIBDIR}/cmake/Fluorosim)

set_target_properties(fluorosim_sim PROPERTIES EXPORT_NAME sim)
set_target_properties(fluorosim_spectra PROPERTIES EXPORT_NAME spectra)
set_target_properties(fluorosim_optics PROPERTIES EXPORT_NAME optics)
install(TARGETS fluorosim_sim fluorosim_spectra fluorosim_optics EXPORT FluorosimTargets
        ARCHIVE DESTINATION ${CMAKE_INSTALL_LIBDIR} INCLUDES DESTINATION ${CMAKE_INSTALL_INCLUDEDIR}/fluorosim)
install(TARGETS fluorosim RUNTIME DESTINATION ${CMAKE_INSTALL_BINDIR})
install(EXPORT FluorosimTargets NAMESPACE Fluorosim:: DESTINATION ${FLUOROSIM_CMAKE_DIR})

# Headers keep the include paths the sources use: "core/math.h", "database.h", "optics/microscope.h".
install(DIRECTORY ${PROJECT_SOURCE_DIR}/libsim/ DESTINATION ${CMAKE_INSTALL_INCLUDEDIR}/fluorosim FILES_MATCHING PATTERN "*.h")
install(FILES ${PROJECT_SOURCE_DIR}/spectra/database.h DESTINATION ${CMAKE_INSTALL_INCLUDEDIR}/fluorosim)
install(DIRECTORY ${PROJECT_SOURCE_DIR}/optics/ DESTINATION ${CMAKE_INSTALL_INCLUDEDIR}/fluorosim/optics FILES_MATCHING PATTERN "*.h")
install(DIRECTORY ${FLUOROSIM_SPECTRA_DIR}/ DESTINATION ${CMAKE_INSTALL_DATADIR}/fluorosim/spectra)

configure_package_config_file(${PROJECT_SOURCE_DIR}/cmake/FluorosimConfig.cmake.in ${PROJECT_BINARY_DIR}/FluorosimConfig.cmake
                              INSTALL_DESTINATION ${FLUOROSIM_CMAKE_DIR} PATH_VARS CMAKE_INSTALL_DATADIR)
write_basic_package_version_file(${PROJECT_BINARY_DIR}/FluorosimConfigVersion.cmake COMPATIBILITY SameMajorVersion)
install(FILES ${PROJECT_BINARY_DIR}/FluorosimConfig.cmake ${PROJECT_BINARY_DIR}/FluorosimConfigVersion.cmake DESTINATION ${FLUOROSIM_CMAKE_DIR})
