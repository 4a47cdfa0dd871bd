#!/usr/bin/env bash
# Debian packages the project needs: Mesa's EGL and software rasterizer for offscreen rendering (the SITL camera),
# python3-venv, and for the deployment checks in `make test`: shellcheck (deploy/jetson/install.sh) and systemd's
# systemd-analyze (deploy/systemd/slz-lander.service). Idempotent: installs only what is missing; needs root (or sudo) only when something is.
set -euo pipefail

packages=(libegl1 libegl-mesa0 libgl1-mesa-dri libgbm1 libgles2 python3-venv shellcheck systemd)
missing=()
for p in "${packages[@]}"; do
    dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ ${#missing[@]} -eq 0 ]; then
    exit 0
fi
if ! command -v apt-get >/dev/null 2>&1; then
    echo "install-system-deps: missing ${missing[*]} and no apt-get: install them with your package manager" >&2
    exit 1
fi
sudo=""
if [ "$(id -u)" -ne 0 ]; then
    command -v sudo >/dev/null 2>&1 || { echo "install-system-deps: need root to install ${missing[*]}" >&2; exit 1; }
    sudo="sudo"
fi
echo "install-system-deps: installing ${missing[*]}"
$sudo apt-get update -qq
DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq --no-install-recommends "${missing[@]}"
