# Sourced by the build scripts: the compiler cache, when ccache is installed (scripts/install-deps.sh
# installs it). Its folder is outside the clone (CCACHE_DIR, default ~/.cache/ccache), so it
# survives between runs on the same machine, and paths are hashed relative to the clone
# (CCACHE_BASEDIR), so another clone of the same sources hits it too. GIMLOD_CCACHE=0 turns it off.
# Sets GIMLOD_CMAKE_CACHE_ARGS for cmake's configure step.
GIMLOD_CMAKE_CACHE_ARGS=()
if [ "${GIMLOD_CCACHE:-1}" != 0 ] && command -v ccache >/dev/null 2>&1; then
  export CCACHE_DIR=${CCACHE_DIR:-${XDG_CACHE_HOME:-${HOME:-/root}/.cache}/ccache}
  export CCACHE_BASEDIR=${CCACHE_BASEDIR:-$(pwd)}
  # note: debug builds carry the build folder's path; without this every clone would miss.
  export CCACHE_NOHASHDIR=${CCACHE_NOHASHDIR:-true}
  # note: the test binaries' precompiled header (tests/CMakeLists.txt); without these the cache
  # refuses every file compiled with it.
  export CCACHE_SLOPPINESS=${CCACHE_SLOPPINESS:-pch_defines,time_macros,include_file_mtime,include_file_ctime}
  GIMLOD_CMAKE_CACHE_ARGS=(-DCMAKE_CXX_COMPILER_LAUNCHER=ccache -DCMAKE_C_COMPILER_LAUNCHER=ccache)
fi
