#!/usr/bin/env bash
# Create the project virtual environment.
#
# ROS 2 Jazzy comes from one of two places:
#   * a ROS install (ROS_DISTRO=jazzy sourced, or /opt/ros/jazzy present, e.g. Ubuntu 24.04 apt):
#     the venv is made with that Python and --system-site-packages, so rclpy and the messages
#     are the system's;
#   * otherwise the ros-jazzy-* wheels from PyPI, which exist for CPython 3.11 only.
# Without either, the core library still installs and the ROS tests skip.
set -euo pipefail
VENV=${1:-.venv}
ROS_SETUP=""
if [[ "${ROS_DISTRO:-}" == "jazzy" && -n "${AMENT_PREFIX_PATH:-}" ]]; then
  ROS_SETUP="sourced"
elif [[ -f /opt/ros/jazzy/setup.bash ]]; then
  ROS_SETUP=/opt/ros/jazzy/setup.bash
fi

pick_python() {
  if [[ -n "${PYTHON:-}" ]]; then echo "$PYTHON"; return; fi
  if [[ -n "$ROS_SETUP" ]]; then command -v python3; return; fi
  for cand in python3.11 python3; do
    if command -v "$cand" >/dev/null 2>&1 && "$cand" -c 'import sys' >/dev/null 2>&1; then
      echo "$cand"; return
    fi
  done
  echo "bootstrap: no python3 found" >&2; exit 1
}

if [[ -n "$ROS_SETUP" && "$ROS_SETUP" != "sourced" ]]; then
  # shellcheck disable=SC1090
  set +u; source "$ROS_SETUP"; set -u
fi
PYTHON_BIN=$(pick_python)
PYVER=$("$PYTHON_BIN" -c 'import sys; print(f"{sys.version_info[0]}.{sys.version_info[1]}")')
echo "bootstrap: python $PYVER ($PYTHON_BIN), ROS: ${ROS_SETUP:-from PyPI wheels}"

if [[ ! -x "$VENV/bin/python" ]]; then
  if [[ -n "$ROS_SETUP" ]]; then
    "$PYTHON_BIN" -m venv --system-site-packages "$VENV"
  else
    "$PYTHON_BIN" -m venv "$VENV"
  fi
fi
PIP=("$VENV/bin/python" -m pip install --disable-pip-version-check -q)
"${PIP[@]}" -U "pip>=24"

ROS_PKGS=()
if [[ -z "$ROS_SETUP" ]]; then
  if [[ "$PYVER" == "3.11" ]]; then
    ROS_PKGS=("ros-jazzy-rclpy[fastrtps]" ros-jazzy-common-interfaces ros-jazzy-ament-package
              ros-jazzy-ament-index-python)
  else
    echo "bootstrap: ROS 2 Jazzy wheels need CPython 3.11 (found $PYVER) and no ROS install was" \
         "found: installing the core library only; ROS nodes and their tests are unavailable." >&2
  fi
fi

# torch is pinned. On Linux PyPI serves a CUDA build (several GB); TORCH_INDEX_URL (e.g.
# https://download.pytorch.org/whl/cpu) takes a CPU build instead.
if [[ -n "${TORCH_INDEX_URL:-}" ]]; then
  "${PIP[@]}" --index-url "$TORCH_INDEX_URL" "torch==2.13.0"
else
  "${PIP[@]}" "torch==2.13.0"
fi
"${PIP[@]}" "${ROS_PKGS[@]}" -r requirements.txt
"${PIP[@]}" --no-deps -e .
# The commit-msg hook (tools/hooks); a checkout without git skips it, and a failure is no reason
# to refuse the venv.
bash "$(dirname "${BASH_SOURCE[0]}")/install_hooks.sh" || echo "bootstrap: git hooks not set up" >&2
echo "bootstrap: $VENV ready"
