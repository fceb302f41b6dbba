#!/usr/bin/env bash
# The runtime ThreadSanitizer needs to see the synchronisation of our thread pools (`make test-tsan`).
#   scripts/tsan-runtime.sh DIR      prepares DIR once, then prints the environment (KEY=VALUE lines) to run under.
# - TBB: Debian's libtbb is not instrumented, so TSan sees neither a parallel_for's start (the caller's writes
#   before it) nor its end (the workers' writes after): every parallel loop would be reported as racing. The same
#   oneTBB release as Debian's (its source package, fetched with apt-get source from a private list, so the
#   system's apt configuration is untouched) is built with -fsanitize=thread; its libtbb.so.12 replaces the
#   system one for the whole process (OpenCV's parallel loops included) via LD_LIBRARY_PATH.
# - OpenMP (libgomp, loaded with Ceres's sparse solvers (SuiteSparse) and with Open3D; Ceres 2.1 itself uses C++
#   threads, whose mutexes TSan sees): GCC's libgomp synchronises with futexes TSan does not see. LLVM's libomp implements libgomp's ABI and, with its Archer tool
#   (OMP_TOOL_LIBRARIES), tells TSan about every barrier and task; a libgomp.so.1 link to it in DIR stands in.
#   The Debian packages libomp5-14 and libomp-14-dev provide both.
set -euo pipefail
DIR=$(mkdir -p "$1" && cd "$1" && pwd)
LLVM=/usr/lib/llvm-14/lib
TBB_LIB=$DIR/tbb-lib
if [ ! -e "$TBB_LIB/libtbb.so.12" ]; then
  version=$(dpkg-query -W -f='${source:Version}' libtbb-dev)
  apt=$DIR/apt
  mkdir -p "$apt/lists/partial" "$apt/cache/archives/partial" "$DIR/src"
  . /etc/os-release
  printf 'deb-src http://deb.debian.org/debian %s main\n' "$VERSION_CODENAME" > "$apt/sources.list"
  printf 'deb-src http://deb.debian.org/debian-security %s-security main\n' "$VERSION_CODENAME" >> "$apt/sources.list"
  opts=(-o "Dir::Etc::SourceList=$apt/sources.list" -o Dir::Etc::SourceParts=/nonexistent
        -o "Dir::State::Lists=$apt/lists" -o "Dir::Cache=$apt/cache" -o Debug::NoLocking=1)
  apt-get "${opts[@]}" -qq update >&2
  (cd "$DIR/src" && apt-get "${opts[@]}" -qq source --download-only "onetbb=$version" >&2 &&
     rm -rf tbb && dpkg-source -x ./*.dsc tbb >&2)
  cmake -S "$DIR/src/tbb" -B "$DIR/src/tbb/build" -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo \
    -DCMAKE_CXX_FLAGS_RELWITHDEBINFO="-O1 -g1 -DNDEBUG" -DTBB_SANITIZE=thread -DTBB_TEST=OFF -DTBB_EXAMPLES=OFF \
    -DTBB_STRICT=OFF -DTBBMALLOC_BUILD=OFF > /dev/null
  cmake --build "$DIR/src/tbb/build" --target tbb >&2
  mkdir -p "$TBB_LIB"
  cp -P "$DIR"/src/tbb/build/*_relwithdebinfo/libtbb.so* "$TBB_LIB/"
fi
for f in "$LLVM/libomp.so.5" "$LLVM/libarcher.so"; do
  [ -e "$f" ] || { echo "tsan-runtime: $f missing (apt-get install libomp5-14 libomp-14-dev)" >&2; exit 1; }
done
mkdir -p "$DIR/gomp"
ln -sf "$LLVM/libomp.so.5" "$DIR/gomp/libgomp.so.1"
echo "LD_LIBRARY_PATH=$TBB_LIB:$DIR/gomp"
echo "OMP_TOOL_LIBRARIES=$LLVM/libarcher.so"
