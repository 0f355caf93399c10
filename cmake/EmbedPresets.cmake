# Embeds assets/presets/*.json into the library so presets work without the source tree.
function(vksonar_embed_presets output)
  add_custom_command(
    OUTPUT ${output}
    COMMAND ${CMAKE_COMMAND} -DOUTPUT=${output} "-DFILES=${ARGN}" -P ${CMAKE_CURRENT_SOURCE_DIR}/cmake/embed_presets_script.cmake
    DEPENDS ${ARGN} ${CMAKE_CURRENT_SOURCE_DIR}/cmake/embed_presets_script.cmake
    COMMENT "Embedding sonar presets"
    VERBATIM)
endfunction()
