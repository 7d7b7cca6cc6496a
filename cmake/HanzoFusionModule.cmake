# hanzo_add_module(NAME SOURCES ... [PUBLIC_DEPS ...] [PRIVATE_DEPS ...])
# One static library per module: target hanzo_<NAME>, alias hanzo::<NAME>, headers under
# include/hanzo/fusion/<NAME>/, installed and exported as hanzo::<NAME>.

function(hanzo_project_warnings target)
  target_compile_options(${target} PRIVATE $<$<COMPILE_LANGUAGE:CXX>:-Wall -Wextra -Wpedantic -Wshadow -Wnon-virtual-dtor>)
  if(HANZO_WERROR)
    target_compile_options(${target} PRIVATE $<$<COMPILE_LANGUAGE:CXX>:-Werror>)
  endif()
endfunction()

function(hanzo_add_module name)
  cmake_parse_arguments(ARG "" "" "SOURCES;PUBLIC_DEPS;PRIVATE_DEPS" ${ARGN})
  add_library(hanzo_${name} ${ARG_SOURCES})
  add_library(hanzo::${name} ALIAS hanzo_${name})
  set_target_properties(hanzo_${name} PROPERTIES EXPORT_NAME ${name} OUTPUT_NAME hanzo_fusion_${name})
  target_include_directories(hanzo_${name} PUBLIC
    $<BUILD_INTERFACE:${PROJECT_SOURCE_DIR}/include>
    $<INSTALL_INTERFACE:${CMAKE_INSTALL_INCLUDEDIR}>)
  target_compile_features(hanzo_${name} PUBLIC cxx_std_20)
  target_link_libraries(hanzo_${name} PUBLIC ${ARG_PUBLIC_DEPS} PRIVATE ${ARG_PRIVATE_DEPS})
  hanzo_project_warnings(hanzo_${name})
  install(TARGETS hanzo_${name} EXPORT hanzo_fusion_targets
    ARCHIVE DESTINATION ${CMAKE_INSTALL_LIBDIR}
    LIBRARY DESTINATION ${CMAKE_INSTALL_LIBDIR})
endfunction()
