#!/usr/bin/env bash
# Installs the Debian 12 packages toposlice needs to build, test and benchmark; skips what is present.
set -euo pipefail
packages=(
  build-essential cmake ninja-build pkg-config git
  libtbb-dev libembree-dev libopenvdb-dev libboost-iostreams-dev libopenexr-dev
  zlib1g-dev libdeflate-dev libisal-dev libspng-dev libzip-dev libminizip-dev nlohmann-json3-dev libcli11-dev lib3mf-dev libtinyobjloader-dev
  libgtest-dev libgmock-dev libbenchmark-dev libtinyexr-dev libpolyclipping-dev
  openexr libopenvdb-tools
  openmpi-bin libopenmpi-dev
  python3-matplotlib
)
missing=()
for p in "${packages[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q 'install ok installed' || missing+=("$p")
done
if [ ${#missing[@]} -eq 0 ]; then
  echo "install-deps: all ${#packages[@]} packages present"
  exit 0
fi
echo "install-deps: installing ${missing[*]}"
sudo=""
[ "$(id -u)" -eq 0 ] || sudo="sudo"
$sudo apt-get update -qq
DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
