// The interface between the C++ renderer and the shaders, written once: included by
// runtime/gl/atlas_renderer.cpp and by the GLSL (cmake/embed_shaders.cmake inlines `#include`
// lines when it embeds the shaders). Plain #defines, valid C++ and GLSL;
// tests/gl/shader_interface_gl_test.cpp checks the linked programs against them.
#ifndef GIMLOD_SHADERS_INTERFACE_H
#define GIMLOD_SHADERS_INTERFACE_H

// Vertex attribute locations of atlas.vert: the grid vertex (i, j), and the node record as two
// per-instance ivec4s (divisor 1; the draw's baseinstance selects the node).
#define GIMLOD_ATTRIB_GRID 0
#define GIMLOD_ATTRIB_NODE_A 1
#define GIMLOD_ATTRIB_NODE_B 2
// Vertex position of the static baseline meshes (static_mesh.vert, static_terrain.vert).
#define GIMLOD_ATTRIB_POSITION 0

// Shader storage binding of the stitching tables (atlas.vert, block Stitch).
#define GIMLOD_STITCH_BINDING 1
// Shader storage binding of the per-node overlays (atlas.frag, block Overlay; runtime/overlay.h).
#define GIMLOD_OVERLAY_BINDING 2

// Texture units of the page pool: u_samples (heights or positions), u_normals and u_colours.
#define GIMLOD_SAMPLES_UNIT 0
#define GIMLOD_NORMALS_UNIT 1
#define GIMLOD_COLOURS_UNIT 2

#endif
