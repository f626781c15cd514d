# Writes OUTPUT (the programs' version header) from version.hpp.in, run at
# build time so the git revision follows commits without a reconfigure.
# configure_file leaves the file untouched when the text is the same, so the
# programs are recompiled only when the revision changes.
#   cmake -DVERSION=x.y.z -DSOURCE_DIR=... -DOUTPUT=... -P version.cmake
set(MODALWATCH_VERSION_STRING "${VERSION}")
find_package(Git QUIET)
if(GIT_FOUND AND EXISTS "${SOURCE_DIR}/.git")
  execute_process(COMMAND "${GIT_EXECUTABLE}" -C "${SOURCE_DIR}" describe --always --dirty
                  OUTPUT_VARIABLE _revision OUTPUT_STRIP_TRAILING_WHITESPACE
                  RESULT_VARIABLE _result ERROR_QUIET)
  if(_result EQUAL 0 AND _revision)
    string(APPEND MODALWATCH_VERSION_STRING " (${_revision})")
  endif()
endif()
configure_file("${CMAKE_CURRENT_LIST_DIR}/version.hpp.in" "${OUTPUT}" @ONLY)
