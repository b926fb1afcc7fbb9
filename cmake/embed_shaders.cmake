# Writes OUT, a header with one string constant per shader file in SHADERS (name: file name with
# '.' replaced by '_', prefixed by kShader_).
set(content "// Generated from shaders/; do not edit.\n#pragma once\n")
foreach(f ${SHADERS})
  get_filename_component(name ${f} NAME)
  string(REPLACE "." "_" name ${name})
  file(READ ${f} text)
  string(APPEND content "inline constexpr const char* kShader_${name} = R\"glsl(${text})glsl\";\n")
endforeach()
file(WRITE ${OUT}.tmp "${content}")
file(RENAME ${OUT}.tmp ${OUT})
