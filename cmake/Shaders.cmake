# Compiles GLSL to SPIR-V at build time and embeds it as a C array (glslangValidator --vn), so the
# binary needs no shader files at run time. Header dependencies are tracked through --depfile.
function(vksonar_compile_shaders target)
  cmake_parse_arguments(ARG "" "INCLUDE_DIR" "SOURCES" ${ARGN})
  set(out_dir ${CMAKE_CURRENT_BINARY_DIR}/shaders)
  file(MAKE_DIRECTORY ${out_dir})
  set(outputs)
  foreach(src ${ARG_SOURCES})
    get_filename_component(name ${src} NAME)
    string(REPLACE "." "_" var ${name})
    set(out ${out_dir}/${name}.spv.h)
    add_custom_command(
      OUTPUT ${out}
      COMMAND ${GLSLANG_VALIDATOR} -V --target-env vulkan1.1 -I${ARG_INCLUDE_DIR}
              --vn ${var}_spv --depfile ${out}.d -o ${out} ${src}
      DEPENDS ${src}
      DEPFILE ${out}.d
      COMMENT "GLSL -> SPIR-V ${name}"
      VERBATIM)
    list(APPEND outputs ${out})
  endforeach()
  add_custom_target(${target} DEPENDS ${outputs})
endfunction()
