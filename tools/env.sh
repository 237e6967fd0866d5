# Source me: environment for running id_learning from the project venv (used by the Makefile).
# Usage: source tools/env.sh [.venv]
_venv=${1:-.venv}
if [[ -z "${ROS_DISTRO:-}" && -f /opt/ros/jazzy/setup.bash ]]; then
  # ROS's setup reads unset variables: nounset off while it runs, back as the caller had it.
  case $- in *u*) _nounset=1;; *) _nounset=;; esac
  set +u; source /opt/ros/jazzy/setup.bash; [[ -z "$_nounset" ]] || set -u
  unset _nounset
fi
_venv_abs=$(cd "$_venv" && pwd)
# ament_index_python needs a prefix; the PyPI wheels install their resource index into the venv.
export AMENT_PREFIX_PATH="$_venv_abs${AMENT_PREFIX_PATH:+:$AMENT_PREFIX_PATH}"
# Never multicast discovery beyond this machine.
export ROS_AUTOMATIC_DISCOVERY_RANGE=${ROS_AUTOMATIC_DISCOVERY_RANGE:-LOCALHOST}
export PATH="$_venv_abs/bin:$PATH"
unset _venv _venv_abs
