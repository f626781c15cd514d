# Installation (cmake --install), the exported CMake package (find_package
# modalwatch), the pkg-config file, the man pages, the programs' --version and
# the Debian package (cpack). Included at the end of CMakeLists.txt, once every
# target exists.
#
# Layout under the prefix (GNUInstallDirs):
#   bin/                           modalwatch, modalwatchd
#   include/modalwatch/            the public headers and the generated LCM types
#   lib[/<multiarch>]/             the static libraries, cmake/modalwatch/, pkgconfig/
#   lib/systemd/system/            modalwatch@.service (its paths filled in here)
#   share/modalwatch/lcmtypes/     the .lcm definitions (and the Java types jar)
#   share/modalwatch/systemd/      the opt-in realtime drop-in, in its directory
#   share/doc/modalwatch/          README.md, config/README.md
#   share/man/man{1,5,8}/          modalwatch(1), modalwatch.yaml(5), modalwatchd(8)
#   <sysconfdir>/modalwatch/       example.yaml (/etc for the prefix /usr)
include(GNUInstallDirs)
include(CMakePackageConfigHelpers)

set(_modalwatch_packaging_dir "${CMAKE_CURRENT_LIST_DIR}")
set(_modalwatch_generated "${CMAKE_BINARY_DIR}/generated")

# ------------------------------------------------------------ --version
# The project version plus `git describe --always --dirty` when built from a
# checkout, rewritten at every build (only when it changes) by version.cmake.
add_custom_target(modalwatch_version
  COMMAND ${CMAKE_COMMAND} -DVERSION=${PROJECT_VERSION} -DSOURCE_DIR=${PROJECT_SOURCE_DIR}
          -DOUTPUT=${_modalwatch_generated}/modalwatch_version.hpp -P ${_modalwatch_packaging_dir}/version.cmake
  BYPRODUCTS ${_modalwatch_generated}/modalwatch_version.hpp
  VERBATIM)
foreach(_program modalwatch modalwatchd)
  target_include_directories(${_program} PRIVATE ${_modalwatch_generated})
  add_dependencies(${_program} modalwatch_version)
endforeach()

# ------------------------------------------------------------ programs, libraries, headers
# The libraries are static and compiled as the toolchain's default (PIE on
# Debian): enough for executables. A shared library linking them needs a build
# configured with -DCMAKE_POSITION_INDEPENDENT_CODE=ON.
install(TARGETS modalwatch modalwatchd RUNTIME DESTINATION ${CMAKE_INSTALL_BINDIR})

set_target_properties(modalwatch_core PROPERTIES EXPORT_NAME core)
set_target_properties(modalwatch_io PROPERTIES EXPORT_NAME io)
set_target_properties(modalwatch_lcmtypes PROPERTIES EXPORT_NAME lcmtypes)
set_target_properties(modalwatch_daemon PROPERTIES EXPORT_NAME daemon)
install(TARGETS modalwatch_core modalwatch_io modalwatch_lcmtypes
  EXPORT modalwatchTargets
  ARCHIVE DESTINATION ${CMAKE_INSTALL_LIBDIR}
  INCLUDES DESTINATION ${CMAKE_INSTALL_INCLUDEDIR})
# The daemon's library needs spdlog and libsystemd: a component of its own
# (find_package(modalwatch COMPONENTS daemon)), so that the others do not.
install(TARGETS modalwatch_daemon
  EXPORT modalwatchDaemonTargets
  ARCHIVE DESTINATION ${CMAKE_INSTALL_LIBDIR}
  INCLUDES DESTINATION ${CMAKE_INSTALL_INCLUDEDIR})

# The whole public tree, whatever its folders, and lcm-gen's C++ headers
# (#include <modalwatch/sample_t.hpp>) beside it.
install(DIRECTORY ${PROJECT_SOURCE_DIR}/include/modalwatch DESTINATION ${CMAKE_INSTALL_INCLUDEDIR})
install(DIRECTORY ${CMAKE_BINARY_DIR}/lcmtypes/modalwatch DESTINATION ${CMAKE_INSTALL_INCLUDEDIR}
  FILES_MATCHING PATTERN "*.hpp")

# ------------------------------------------------------------ CMake package, pkg-config
set(_modalwatch_cmake_dir ${CMAKE_INSTALL_LIBDIR}/cmake/modalwatch)
install(EXPORT modalwatchTargets NAMESPACE modalwatch:: DESTINATION ${_modalwatch_cmake_dir})
install(EXPORT modalwatchDaemonTargets NAMESPACE modalwatch:: DESTINATION ${_modalwatch_cmake_dir})
configure_package_config_file(${_modalwatch_packaging_dir}/modalwatchConfig.cmake.in
  ${CMAKE_BINARY_DIR}/modalwatchConfig.cmake INSTALL_DESTINATION ${_modalwatch_cmake_dir})
# 0.x: a new minor version may change the API.
write_basic_package_version_file(${CMAKE_BINARY_DIR}/modalwatchConfigVersion.cmake
  COMPATIBILITY SameMinorVersion)
install(FILES ${CMAKE_BINARY_DIR}/modalwatchConfig.cmake ${CMAKE_BINARY_DIR}/modalwatchConfigVersion.cmake
  DESTINATION ${_modalwatch_cmake_dir})

# The prefix relative to the .pc file, so that `cmake --install --prefix` anywhere works.
file(RELATIVE_PATH MODALWATCH_PC_PREFIX "/${CMAKE_INSTALL_LIBDIR}/pkgconfig" "/")
configure_file(${_modalwatch_packaging_dir}/modalwatch.pc.in ${CMAKE_BINARY_DIR}/modalwatch.pc @ONLY)
install(FILES ${CMAKE_BINARY_DIR}/modalwatch.pc DESTINATION ${CMAKE_INSTALL_LIBDIR}/pkgconfig)

# ------------------------------------------------------------ systemd, config, data, docs
# The configuration directory: /etc for the prefix /usr (GNUInstallDirs), else
# under the prefix, where `cmake --install --prefix` moves it along.
if(CMAKE_INSTALL_FULL_SYSCONFDIR STREQUAL "${CMAKE_INSTALL_PREFIX}/${CMAKE_INSTALL_SYSCONFDIR}")
  set(_modalwatch_sysconf ${CMAKE_INSTALL_SYSCONFDIR}/modalwatch)
else()
  set(_modalwatch_sysconf ${CMAKE_INSTALL_FULL_SYSCONFDIR}/modalwatch)
endif()
configure_file(${PROJECT_SOURCE_DIR}/systemd/modalwatch@.service.in
  ${CMAKE_BINARY_DIR}/systemd/modalwatch@.service @ONLY)
install(FILES ${CMAKE_BINARY_DIR}/systemd/modalwatch@.service DESTINATION lib/systemd/system)
# Opt-in: copied by the administrator to /etc/systemd/system/modalwatch@.service.d/.
install(FILES ${PROJECT_SOURCE_DIR}/systemd/realtime.conf
  DESTINATION ${CMAKE_INSTALL_DATADIR}/modalwatch/systemd/modalwatch@.service.d)
install(FILES ${PROJECT_SOURCE_DIR}/config/flexible-beam.yaml DESTINATION ${_modalwatch_sysconf}
  RENAME example.yaml)

install(FILES ${MODALWATCH_LCM_FILES} DESTINATION ${CMAKE_INSTALL_DATADIR}/modalwatch/lcmtypes)
if(TARGET modalwatch_lcmtypes_jar)
  install(FILES ${MODALWATCH_LCMTYPES_JAR} DESTINATION ${CMAKE_INSTALL_DATADIR}/modalwatch/lcmtypes)
endif()
# config/README.md keeps its folder, so that README.md's links to it still resolve.
install(FILES ${PROJECT_SOURCE_DIR}/README.md DESTINATION ${CMAKE_INSTALL_DOCDIR})
install(FILES ${PROJECT_SOURCE_DIR}/config/README.md DESTINATION ${CMAKE_INSTALL_DOCDIR}/config)

# ------------------------------------------------------------ man pages
# modalwatch(1) and modalwatchd(8) from the programs' --help and --version
# (help2man), modalwatch.yaml(5) from config/README.md behind a NAME section
# (pandoc); each only when its tool is found.
find_program(HELP2MAN_EXECUTABLE help2man)
find_program(PANDOC_EXECUTABLE pandoc)
find_program(GZIP_EXECUTABLE gzip)
set(_modalwatch_man "${CMAKE_BINARY_DIR}/man")
set(_modalwatch_man_pages "")
if(HELP2MAN_EXECUTABLE AND GZIP_EXECUTABLE)
  foreach(_page "modalwatch;1;identification of continuous-time modal models (additive RSRIVC)"
                "modalwatchd;8;online modal estimation and fault flags from LCM samples")
    list(GET _page 0 _program)
    list(GET _page 1 _section)
    list(GET _page 2 _name)
    set(_out "${_modalwatch_man}/${_program}.${_section}")
    add_custom_command(OUTPUT "${_out}.gz"
      COMMAND ${CMAKE_COMMAND} -E make_directory "${_modalwatch_man}"
      COMMAND ${HELP2MAN_EXECUTABLE} --no-info --section=${_section} --name=${_name}
              --output=${_out} $<TARGET_FILE:${_program}>
      COMMAND ${GZIP_EXECUTABLE} -9nf "${_out}"
      DEPENDS ${_program}
      COMMENT "help2man: ${_program}(${_section})"
      VERBATIM)
    list(APPEND _modalwatch_man_pages "${_out}.gz")
    install(FILES "${_out}.gz" DESTINATION ${CMAKE_INSTALL_MANDIR}/man${_section})
  endforeach()
else()
  message(STATUS "help2man not found: no man pages modalwatch(1), modalwatchd(8) (Debian: help2man)")
endif()
if(PANDOC_EXECUTABLE AND GZIP_EXECUTABLE)
  set(_out "${_modalwatch_man}/modalwatch.yaml.5")
  add_custom_command(OUTPUT "${_out}.gz"
    COMMAND ${CMAKE_COMMAND} -E make_directory "${_modalwatch_man}"
    COMMAND ${PANDOC_EXECUTABLE} -s -f gfm -t man -M title=modalwatch.yaml -M section=5
            -M "header=modalwatch configuration" -M "footer=modalwatch ${PROJECT_VERSION}"
            -o ${_out} ${_modalwatch_packaging_dir}/modalwatch.yaml.5.md ${PROJECT_SOURCE_DIR}/config/README.md
    COMMAND ${GZIP_EXECUTABLE} -9nf "${_out}"
    DEPENDS ${_modalwatch_packaging_dir}/modalwatch.yaml.5.md ${PROJECT_SOURCE_DIR}/config/README.md
    COMMENT "pandoc: modalwatch.yaml(5)"
    VERBATIM)
  list(APPEND _modalwatch_man_pages "${_out}.gz")
  install(FILES "${_out}.gz" DESTINATION ${CMAKE_INSTALL_MANDIR}/man5)
else()
  message(STATUS "pandoc not found: no man page modalwatch.yaml(5) (Debian: pandoc)")
endif()
if(_modalwatch_man_pages)
  add_custom_target(modalwatch_man ALL DEPENDS ${_modalwatch_man_pages})
endif()

# Everything the installation needs and nothing else (no tests): what
# scripts/check/package.sh builds, configured with CMAKE_SKIP_INSTALL_ALL_DEPENDENCY.
add_custom_target(modalwatch_installation)
add_dependencies(modalwatch_installation modalwatch modalwatchd modalwatch_core modalwatch_io
  modalwatch_daemon)
foreach(_optional modalwatch_man modalwatch_lcmtypes_jar)
  if(TARGET ${_optional})
    add_dependencies(modalwatch_installation ${_optional})
  endif()
endforeach()

# ------------------------------------------------------------ test: a consumer of the installation
# Installs this build into a temporary prefix and builds tests/consumer against
# it with find_package and with pkg-config. Not in the sanitizer and fuzz
# builds, whose instrumented libraries a plain consumer cannot link.
if(NOT MODALWATCH_FUZZ AND NOT MODALWATCH_SANITIZE)
  add_test(NAME install_consumer
    COMMAND ${PROJECT_SOURCE_DIR}/scripts/check/install-consumer.sh ${CMAKE_BINARY_DIR} ${CMAKE_CXX_COMPILER})
  set_tests_properties(install_consumer PROPERTIES TIMEOUT 300)
endif()

# ------------------------------------------------------------ Debian package (cpack)
# modalwatch_<version>_<arch>.deb with the prefix of this build: configure
# with -DCMAKE_INSTALL_PREFIX=/usr for a system package (scripts/check/package.sh).
# Depends from dpkg-shlibdeps on the programs; the headers and static libraries
# ride along, their build dependencies suggested.
file(WRITE ${CMAKE_BINARY_DIR}/debian/conffiles "${CMAKE_INSTALL_FULL_SYSCONFDIR}/modalwatch/example.yaml\n")
set(CPACK_GENERATOR DEB)
set(CPACK_PACKAGE_NAME modalwatch)
set(CPACK_PACKAGE_VERSION ${PROJECT_VERSION})
set(CPACK_PACKAGE_DESCRIPTION_SUMMARY "online identification of continuous-time modal models and fault flags")
set(CPACK_PACKAGE_DESCRIPTION
  "modalwatch identifies the mechanics beside a motion controller as a sum of resonant modes (additive RSRIVC) and raises fault flags when a mode drifts. The package holds the programs modalwatch and modalwatchd, the systemd template unit modalwatch@.service, the C++ headers and static libraries (CMake package and pkg-config file) and the LCM message types.")
set(CPACK_PACKAGING_INSTALL_PREFIX ${CMAKE_INSTALL_PREFIX})
set(CPACK_STRIP_FILES ON)
set(MODALWATCH_PACKAGE_MAINTAINER "modalwatch maintainers <root@localhost>" CACHE STRING
    "Maintainer field of the Debian package")
set(CPACK_DEBIAN_PACKAGE_MAINTAINER "${MODALWATCH_PACKAGE_MAINTAINER}")
set(CPACK_DEBIAN_FILE_NAME DEB-DEFAULT)
set(CPACK_DEBIAN_PACKAGE_SECTION science)
set(CPACK_DEBIAN_PACKAGE_SHLIBDEPS ON)
set(CPACK_DEBIAN_PACKAGE_SUGGESTS "libeigen3-dev, libyaml-cpp-dev, libspdlog-dev, prometheus-cpp-dev, liblcm-dev, libsystemd-dev, liblcm-java")
set(CPACK_DEBIAN_PACKAGE_CONTROL_EXTRA
  ${PROJECT_SOURCE_DIR}/systemd/postinst ${PROJECT_SOURCE_DIR}/systemd/postrm ${CMAKE_BINARY_DIR}/debian/conffiles)
set(CPACK_DEBIAN_PACKAGE_CONTROL_STRICT_PERMISSION ON)
include(CPack)
