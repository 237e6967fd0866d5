#!/usr/bin/env bash
# Use the repository's git hooks (tools/hooks: commit-msg checks the subject's length) by
# setting core.hooksPath in this checkout's own git config. tools/bootstrap_venv.sh runs it.
#
# Skipped silently outside a git work tree (an unpacked release), and for a checkout inside
# another repository's work tree (tools/hooks would be read from that one's top). A
# core.hooksPath this repository's config already sets to another folder is kept (one line says
# so). Note: with core.hooksPath set, git no longer runs the hooks in .git/hooks.
set -euo pipefail
root=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd -P)
top=$(git -C "$root" rev-parse --show-toplevel 2>/dev/null) || exit 0
[[ "$(cd "$top" && pwd -P)" == "$root" ]] || exit 0
current=$(git -C "$root" config --local --get core.hooksPath || true)
case "$current" in
  tools/hooks) ;;
  "")
    git -C "$root" config --local core.hooksPath tools/hooks
    echo "hooks: git runs tools/hooks (core.hooksPath)";;
  *)
    echo "hooks: core.hooksPath is $current in this checkout: tools/hooks not used" >&2;;
esac
