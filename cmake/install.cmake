# `cmake --install build --prefix P`: the libraries (static), their headers under include/gimlod,
# and a CMake package (lib/cmake/gimlod) whose targets are gimlod::core, gimlod::hierarchy,
# gimlod::runtime and, in the full build, gimlod::runtime_gl, gimlod::terrain_input,
# gimlod::mesh_atlas, gimlod::fidelity, gimlod::atlas, gimlod::pipeline and gimlod::inspect.
# The public API is the documented subset of these headers (docs/architecture.md).
include(GNUInstallDirs)
include(CMakePackageConfigHelpers)

# Installs the given library targets (gimlod_X exported as gimlod::X), every module's headers and
# the package's config files.
function(gimlod_install)
  foreach(target IN LISTS ARGN)
    string(REGEX REPLACE "^gimlod_" "" name ${target})
    set_target_properties(${target} PROPERTIES EXPORT_NAME ${name})
  endforeach()
  install(TARGETS ${ARGN} EXPORT gimlodTargets
          ARCHIVE DESTINATION ${CMAKE_INSTALL_LIBDIR}
          LIBRARY DESTINATION ${CMAKE_INSTALL_LIBDIR}
          INCLUDES DESTINATION ${CMAKE_INSTALL_INCLUDEDIR}/gimlod)
  set(modules core hierarchy runtime)
  if(NOT GIMLOD_RUNTIME_ONLY)
    list(APPEND modules atlas pipeline inspect)
  endif()
  foreach(module IN LISTS modules)
    install(DIRECTORY ${PROJECT_SOURCE_DIR}/${module} DESTINATION ${CMAKE_INSTALL_INCLUDEDIR}/gimlod
            FILES_MATCHING PATTERN "*.h" PATTERN "*_internal.h" EXCLUDE)
  endforeach()
  set(config_dir ${CMAKE_INSTALL_LIBDIR}/cmake/gimlod)
  install(EXPORT gimlodTargets NAMESPACE gimlod:: DESTINATION ${config_dir})
  configure_package_config_file(${PROJECT_SOURCE_DIR}/cmake/gimlodConfig.cmake.in
                                ${PROJECT_BINARY_DIR}/gimlodConfig.cmake INSTALL_DESTINATION ${config_dir})
  write_basic_package_version_file(${PROJECT_BINARY_DIR}/gimlodConfigVersion.cmake
                                   COMPATIBILITY SameMinorVersion)
  install(FILES ${PROJECT_BINARY_DIR}/gimlodConfig.cmake ${PROJECT_BINARY_DIR}/gimlodConfigVersion.cmake
          DESTINATION ${config_dir})
endfunction()
