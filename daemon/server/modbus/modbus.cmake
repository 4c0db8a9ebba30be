# luxrad_modbus: the Modbus TCP server of luxradd (issue 5) -- modbus.c,
# mb_image.c, mb_config.c, regmap.c (and textutil.c, shared with the
# daemon's other parsers); the map is documented in MODBUS.md.  The
# listen address is parsed by the protocol library (rp_addr_parse_listen),
# as the daemon's other listeners are.
#
# Included by daemon/server/CMakeLists.txt (include(modbus.cmake)), or by
# tests/modbus when that line is not there yet.  libmodbus is linked
# PRIVATE on purpose: its pkg-config include directory (/usr/include/modbus)
# holds a modbus.h that would shadow ours in every consumer; modbus.c
# includes it as <modbus/modbus.h>.
pkg_check_modules(LIBMODBUS REQUIRED IMPORTED_TARGET GLOBAL libmodbus)
add_library(luxrad_modbus STATIC
  ${CMAKE_CURRENT_LIST_DIR}/modbus.c
  ${CMAKE_CURRENT_LIST_DIR}/mb_image.c
  ${CMAKE_CURRENT_LIST_DIR}/mb_config.c
  ${CMAKE_CURRENT_LIST_DIR}/regmap.c
  ${CMAKE_CURRENT_LIST_DIR}/textutil.c)
target_include_directories(luxrad_modbus PUBLIC ${CMAKE_CURRENT_LIST_DIR})
target_link_libraries(luxrad_modbus PRIVATE PkgConfig::LIBMODBUS
                      luxrad_protocol PUBLIC Threads::Threads m)
