#!/usr/bin/env bash
# Install the Debian packages uvms-mj needs (idempotent; as root, or through sudo):
# python3-venv; a C compiler for the native hydrodynamics (uvms_mj.planar.native; without it the plant
# runs the pure-Python reference and the native tests are skipped); and the GL libraries for
# headless rendering: EGL with Mesa's software renderer (llvmpipe), OSMesa as the fallback.
set -euo pipefail
pkgs=()
python3 -c "import venv, ensurepip" 2>/dev/null || pkgs+=(python3-venv)
command -v cc >/dev/null 2>&1 || pkgs+=(gcc libc6-dev)
for p in libegl1 libegl-mesa0 libgl1-mesa-dri libopengl0 libosmesa6; do
  dpkg -s "$p" >/dev/null 2>&1 || pkgs+=("$p")
done
[ ${#pkgs[@]} -eq 0 ] && exit 0
if ! command -v apt-get >/dev/null 2>&1; then
  echo "warning: not a Debian system; install the equivalents of: ${pkgs[*]}" >&2
  exit 0
fi
sudo=""
if [ "$(id -u)" != 0 ]; then
  if command -v sudo >/dev/null 2>&1; then sudo="sudo"; else
    echo "warning: missing Debian packages (${pkgs[*]}); run this script as root" >&2; exit 0
  fi
fi
$sudo apt-get update -qq
DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq --no-install-recommends "${pkgs[@]}" >/dev/null
