#!/usr/bin/env bash
# Install the SLZ Lander companion on a Jetson (JetPack 6: Ubuntu 22.04, Python 3.10, aarch64).
#
#   sudo deploy/jetson/install.sh [--cpu-only] [--no-service] [--prefix DIR] [--dry-run]
#
# What it does, idempotently (a second run changes nothing that is already right):
#   1. a virtualenv in PREFIX/venv with the companion's dependencies only (no SITL, no training packages), the
#      versions of requirements/drone.lock with their hashes;
#   2. onnxruntime with the CUDA and TensorRT execution providers from the Jetson AI Lab index for JetPack 6
#      (ORT_INDEX_URL, see deploy/README.md); with --cpu-only, or when that index cannot be reached, PyPI's CPU
#      build: the companion then logs its CPU fallback at every start;
#   3. the system user `slz`, /var/lib/slz/{flights,trt-cache} (flight logs, TensorRT engine cache: persistent);
#   4. /etc/slz/mission.yaml from mission_configs/px4_serial.yaml (never overwritten), the udev rule for TELEM2 and
#      the systemd unit (enabled, not started: start it when the vehicle is wired).
# Anything it cannot do it says, and exits non-zero.
set -euo pipefail

PREFIX=/opt/slz
ORT_INDEX_URL="${ORT_INDEX_URL:-https://pypi.jetson-ai-lab.io/jp6/cu126}"
CPU_ONLY=0
SERVICE=1
DRY_RUN=0
REPO="$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)"

usage() {  # the comment block above `set -euo pipefail`
    sed -n '2,/^set /{/^#/p}' "${BASH_SOURCE[0]}" | sed 's/^# \{0,1\}//'
}

while [ $# -gt 0 ]; do
    case "$1" in
        --cpu-only) CPU_ONLY=1 ;;
        --no-service) SERVICE=0 ;;
        --prefix) PREFIX="${2:?--prefix needs a directory}"; shift ;;
        --dry-run) DRY_RUN=1 ;;
        -h|--help) usage; exit 0 ;;
        *) echo "install.sh: unknown option $1" >&2; usage >&2; exit 2 ;;
    esac
    shift
done

say() { echo "install.sh: $*"; }
fail() { echo "install.sh: $*" >&2; exit 1; }
run() {
    if [ "$DRY_RUN" -eq 1 ]; then
        echo "+ $*"
    else
        "$@"
    fi
}

# -- the board ------------------------------------------------------------------------------------------------------
arch="$(uname -m)"
[ "$arch" = "aarch64" ] || fail "this is $arch: the script installs on a Jetson (aarch64); elsewhere use 'pip install .'"
if [ -r /etc/nv_tegra_release ]; then
    say "L4T: $(head -n 1 /etc/nv_tegra_release)"
else
    say "no /etc/nv_tegra_release: not a Jetson; installing the CPU build"
    CPU_ONLY=1
fi
python=python3.10
command -v "$python" >/dev/null 2>&1 || fail "$python not found (JetPack 6 ships it: apt-get install python3.10-venv)"
[ "$(id -u)" -eq 0 ] || [ "$DRY_RUN" -eq 1 ] || fail "run as root (sudo): it creates a user, /var/lib/slz and a unit"

# -- the virtualenv ---------------------------------------------------------------------------------------------------
venv="$PREFIX/venv"
if [ ! -x "$venv/bin/python" ]; then
    say "creating $venv"
    run "$python" -m venv "$venv"
fi
# The companion alone, from the drone's lock: every distribution pinned and hashed (pip, setuptools and wheel
# included), the versions CI tested; the project itself then adds nothing unlocked.
run "$venv/bin/python" -m pip install --quiet --require-hashes --no-deps -r "$REPO/requirements/drone.lock"
run mkdir -p "$PREFIX/src"
run cp -r "$REPO/companion" "$REPO/models" "$REPO/mission_configs" "$REPO/pyproject.toml" "$REPO/README.md" "$PREFIX/src/"
run "$venv/bin/python" -m pip install --quiet --no-deps --no-build-isolation "$PREFIX/src"
run "$venv/bin/python" -m pip check

# -- onnxruntime with the GPU providers -------------------------------------------------------------------------------
if [ "$CPU_ONLY" -eq 0 ]; then
    # The one package outside the lock (the Jetson AI Lab index is not PyPI, so the lock has no hash of it): --no-deps,
    # its dependencies are the locked CPU build's; importing it below (the providers line) says if they fall short.
    say "onnxruntime-gpu from $ORT_INDEX_URL"
    if run "$venv/bin/python" -m pip install --quiet --no-deps --extra-index-url "$ORT_INDEX_URL" onnxruntime-gpu; then
        # Two onnxruntime distributions in one venv shadow each other: keep only the GPU one.
        run "$venv/bin/python" -m pip uninstall --quiet --yes onnxruntime || true
        run "$venv/bin/python" -m pip install --quiet --force-reinstall --no-deps --extra-index-url "$ORT_INDEX_URL" \
            onnxruntime-gpu
    else
        say "WARNING: $ORT_INDEX_URL not reachable: keeping the CPU build (the companion logs the fallback)"
    fi
fi
if [ "$DRY_RUN" -eq 0 ]; then
    providers="$("$venv/bin/python" -c 'import onnxruntime as o; print(" ".join(o.get_available_providers()))')"
    say "onnxruntime providers: $providers"
fi

# -- user, state, config, udev, unit ----------------------------------------------------------------------------------
if ! id slz >/dev/null 2>&1; then
    run useradd --system --home-dir /var/lib/slz --shell /usr/sbin/nologin --groups dialout,video slz
fi
run install -d -o slz -g slz -m 0750 /var/lib/slz /var/lib/slz/flights /var/lib/slz/trt-cache
run install -d -m 0755 /etc/slz
if [ ! -e /etc/slz/mission.yaml ]; then
    # A config's relative paths are taken from its own folder: the shipped one names the model from mission_configs/
    # (../models/...); in /etc/slz it names the installed copy's.
    if [ "$DRY_RUN" -eq 1 ]; then
        echo "+ sed 's#: ../models/#: $PREFIX/src/models/#' mission_configs/px4_serial.yaml > /etc/slz/mission.yaml"
    else
        sed "s#: \.\./models/#: $PREFIX/src/models/#" "$REPO/mission_configs/px4_serial.yaml" >/etc/slz/mission.yaml
        chmod 0644 /etc/slz/mission.yaml
    fi
    say "wrote /etc/slz/mission.yaml: set the geofence, the serial port and the camera before the first flight"
else
    say "/etc/slz/mission.yaml exists: left as it is"
fi
run "$venv/bin/slz" fly --help >/dev/null
run install -m 0644 "$REPO/deploy/udev/99-slz-telem2.rules" /etc/udev/rules.d/99-slz-telem2.rules
run udevadm control --reload-rules
if [ "$SERVICE" -eq 1 ]; then
    run install -m 0644 "$REPO/deploy/systemd/slz-lander.service" /etc/systemd/system/slz-lander.service
    run systemctl daemon-reload
    run systemctl enable slz-lander.service
    say "enabled slz-lander.service (start: systemctl start slz-lander; logs: journalctl -u slz-lander)"
fi
say "done. Check the board before flight: sudo -u slz $venv/bin/slz doctor --config /etc/slz/mission.yaml"
