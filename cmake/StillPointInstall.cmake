# `cmake --install BUILD [--prefix P]`: the library, its public headers, the stillpoint binary and the
# run-time data, laid out so that both find share/stillpoint from where they are (common/data_dir.hpp):
#
#   P/bin/stillpoint                          the CLI
#   P/lib/libstillpoint.so*                   the public API (StillPoint::stillpoint)
#   P/include/stillpoint/{stillpoint,version}.hpp
#   P/lib/cmake/StillPoint/                   StillPointConfig.cmake, ...ConfigVersion.cmake, targets
#   P/lib/pkgconfig/stillpoint.pc
#   P/share/stillpoint/config/                stillpoint.yaml, camera/ and dynamic/ presets
#   P/share/stillpoint/data/vocab/            the ORB vocabulary
#   P/share/stillpoint/data/demo/             the bundled demo sequence
#   P/share/stillpoint/models/yolox_nano/     the default detector (with its LICENSE and NOTICE)
#   P/share/stillpoint/models/parc_netvlad/   ParC_NetVLAD weights (only with STILLPOINT_WITH_TORCH)
#   P/lib/python3/dist-packages/              the Python module (when built)
include(CMakePackageConfigHelpers)

set(SP_INSTALL_DATADIR ${CMAKE_INSTALL_DATADIR}/stillpoint)
set(SP_INSTALL_CMAKEDIR ${CMAKE_INSTALL_LIBDIR}/cmake/StillPoint)

if(TARGET stillpoint)
  install(TARGETS stillpoint RUNTIME DESTINATION ${CMAKE_INSTALL_BINDIR})
endif()
if(TARGET stillpoint_lib)
  install(TARGETS stillpoint_lib EXPORT StillPointTargets
    LIBRARY DESTINATION ${CMAKE_INSTALL_LIBDIR}
    INCLUDES DESTINATION ${CMAKE_INSTALL_INCLUDEDIR})
  install(FILES ${CMAKE_SOURCE_DIR}/include/stillpoint/stillpoint.hpp
                ${CMAKE_BINARY_DIR}/include/stillpoint/version.hpp
          DESTINATION ${CMAKE_INSTALL_INCLUDEDIR}/stillpoint)
  install(EXPORT StillPointTargets NAMESPACE StillPoint:: DESTINATION ${SP_INSTALL_CMAKEDIR})
  configure_package_config_file(${CMAKE_SOURCE_DIR}/cmake/StillPointConfig.cmake.in
    ${CMAKE_BINARY_DIR}/StillPointConfig.cmake INSTALL_DESTINATION ${SP_INSTALL_CMAKEDIR}
    PATH_VARS SP_INSTALL_DATADIR)
  # 0.x: a minor version may change the API.
  write_basic_package_version_file(${CMAKE_BINARY_DIR}/StillPointConfigVersion.cmake
    VERSION ${PROJECT_VERSION} COMPATIBILITY SameMinorVersion)
  install(FILES ${CMAKE_BINARY_DIR}/StillPointConfig.cmake ${CMAKE_BINARY_DIR}/StillPointConfigVersion.cmake
          DESTINATION ${SP_INSTALL_CMAKEDIR})
  # Relocatable: the prefix is found from the .pc file's own folder, so `--prefix` at install time works.
  file(RELATIVE_PATH SP_PC_PREFIX "/root/${CMAKE_INSTALL_LIBDIR}/pkgconfig" "/root")
  string(REGEX REPLACE "/$" "" SP_PC_PREFIX "${SP_PC_PREFIX}")
  configure_file(${CMAKE_SOURCE_DIR}/cmake/stillpoint.pc.in ${CMAKE_BINARY_DIR}/stillpoint.pc @ONLY)
  install(FILES ${CMAKE_BINARY_DIR}/stillpoint.pc DESTINATION ${CMAKE_INSTALL_LIBDIR}/pkgconfig)
endif()

install(DIRECTORY ${CMAKE_SOURCE_DIR}/config/ DESTINATION ${SP_INSTALL_DATADIR}/config)
install(DIRECTORY ${CMAKE_SOURCE_DIR}/data/vocab ${CMAKE_SOURCE_DIR}/data/demo
        DESTINATION ${SP_INSTALL_DATADIR}/data)
install(DIRECTORY ${CMAKE_SOURCE_DIR}/models/yolox_nano DESTINATION ${SP_INSTALL_DATADIR}/models)
if(STILLPOINT_WITH_TORCH)
  install(DIRECTORY ${CMAKE_SOURCE_DIR}/models/parc_netvlad DESTINATION ${SP_INSTALL_DATADIR}/models)
endif()
install(PROGRAMS ${CMAKE_SOURCE_DIR}/python/examples/track_sequence.py DESTINATION ${SP_INSTALL_DATADIR}/examples)
install(FILES ${CMAKE_SOURCE_DIR}/tests/install/consumer/main.cpp DESTINATION ${SP_INSTALL_DATADIR}/examples
        RENAME consumer.cpp)
