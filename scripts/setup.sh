# Shared by scripts/demo and scripts/test (sourced, not run): the Debian packages and the build
# directory's generator.

# ensure_packages NAME PACKAGE...: installs the Debian packages that are missing (apt-get update
# once, then one apt-get install); nothing when all are installed. NAME prefixes the messages.
ensure_packages() {
  local name="$1"
  shift
  if ! command -v dpkg-query >/dev/null 2>&1; then
    echo "$name: no dpkg-query (not Debian?); assuming the dependencies are installed" >&2
    return
  fi
  local missing=() p
  for p in "$@"; do
    if ! dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed"; then missing+=("$p"); fi
  done
  if ((${#missing[@]} == 0)); then return; fi
  echo "$name: installing ${missing[*]}" >&2
  local sudo=()
  if [[ "$(id -u)" -ne 0 ]]; then sudo=(sudo); fi
  "${sudo[@]}" apt-get update
  "${sudo[@]}" env DEBIAN_FRONTEND=noninteractive apt-get install -y --no-install-recommends "${missing[@]}"
}

# The packages every build needs (chromium, chromium-driver and python3-selenium: the browser test of
# `duplex view`'s page).
build_packages=(build-essential cmake ninja-build libopenmesh-dev libopenvdb-dev libboost-iostreams-dev libblosc-dev zlib1g-dev libglm-dev
                libspdlog-dev libtbb-dev libgtest-dev nlohmann-json3-dev libcli11-dev libstb-dev libpng-dev
                python3-matplotlib libembree-dev libopenexr-dev libxxhash-dev libtinyxml2-dev
                pybind11-dev python3-dev python3-numpy python3-pytest libopenmpi-dev openmpi-bin
                libcpp-httplib-dev chromium chromium-driver python3-selenium)

# generator_args DIR: prints "-G Ninja" for a new build directory when ninja is installed (it starts
# a target's compiles before its dependencies have linked, which keeps both cores busy), nothing for
# an existing one (CMake refuses to change the generator of a configured directory).
generator_args() {
  if [[ ! -f "$1/CMakeCache.txt" ]] && command -v ninja >/dev/null 2>&1; then echo "-G Ninja"; fi
}
