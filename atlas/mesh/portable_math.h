// Elementary functions whose results do not depend on the CPU, for every computation of the mesh
// stage whose bits reach an atlas. glibc's libm picks its code path by the CPU (FMA and AVX2
// variants of exp, log, pow, sin, atan2...), and their last bits differ; the layout's discrete
// choices (a patch's neighbours, a chart's size, a cut) turn such a bit into other charts. A mesh
// atlas built on one x86-64 machine was then not the one built on another, so sharded builds
// across machines, or figures from two machines, could not be compared byte for byte.
// These are SLEEF's scalar pure-C functions (Sleef_*d1_u10purec, at most 1 ULP from the exact
// result): the same instructions on every x86-64 CPU, so the same bits. Square roots need none:
// IEEE rounds them exactly.
#pragma once

#include <sleef.h>

namespace gimlod::pmath {

inline double sin(double x) { return Sleef_sind1_u10purec(x); }
inline double cos(double x) { return Sleef_cosd1_u10purec(x); }
inline double acos(double x) { return Sleef_acosd1_u10purec(x); }
inline double atan2(double y, double x) { return Sleef_atan2d1_u10purec(y, x); }
inline double pow(double x, double y) { return Sleef_powd1_u10purec(x, y); }
inline double log2(double x) { return Sleef_log2d1_u10purec(x); }
inline double cbrt(double x) { return Sleef_cbrtd1_u10purec(x); }

}  // namespace gimlod::pmath
