#!/usr/bin/env bash
# Installs the Debian packages arapp needs when they are missing:
#   EGL/Mesa (pyrender offscreen), OSMesa (fallback), the X/xkb/font libraries
#   Qt's offscreen platform loads, Xvfb (GUI screenshots), ffmpeg codecs,
#   libusb (Open3D's wheel, the scan benchmark's peer, links against it).
# Extra packages can be named as arguments (e.g. prusa-slicer).
set -euo pipefail
want=(libegl1 libegl-mesa0 libgl1-mesa-dri libgles2 libosmesa6 libglu1-mesa
      libxkbcommon0 libxkbcommon-x11-0 libfontconfig1 libdbus-1-3 libglib2.0-0
      libxcb-cursor0 libxcb-icccm4 libxcb-keysyms1 libxcb-shape0 libxcb-xinerama0
      libxcb-randr0 libxcb-render-util0 libxcb-image0 xvfb xauth libusb-1.0-0 "$@")
missing=()
for p in "${want[@]}"; do
    dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ ${#missing[@]} -eq 0 ]; then
    exit 0
fi
echo "system-deps: installing ${missing[*]}"
SUDO=""
if [ "$(id -u)" -ne 0 ]; then SUDO="sudo"; fi
export DEBIAN_FRONTEND=noninteractive
$SUDO apt-get update -qq
$SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
