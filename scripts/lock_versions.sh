#!/usr/bin/env bash
# Refresh constraints.txt: the exact version of every package a fresh `pip install -e ".[all]"`
# resolves today, so that README's commands and .ci/run install what was tested.
#   bash scripts/lock_versions.sh        (then run the tests, commit constraints.txt)
# It builds a throw-away virtual environment with the python3 on PATH; the file it writes holds
# that interpreter's and platform's resolution (see its header).  pip applies a constraint only to
# a package it installs, so the x86-64-only lines (embreex, open3d-cpu) are harmless elsewhere.
set -euo pipefail
cd "$(dirname "$0")/.."
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
python3 -m venv "$tmp/venv"
"$tmp/venv/bin/pip" install -q -e ".[all]"
py=$("$tmp/venv/bin/python" -c 'import platform, sys; print(f"Python {sys.version.split()[0]} on {platform.system()} {platform.machine()}")')
{
  echo "# Exact versions of explore3d's dependencies (pip constraints: pip install -c constraints.txt -e \".[all]\")."
  echo "# Resolved by scripts/lock_versions.sh with $py on $(date -u +%Y-%m-%d); refresh with that script."
  "$tmp/venv/bin/pip" freeze --exclude-editable --all | grep -vE '^(pip|setuptools|wheel)=='
} > constraints.txt.part
mv constraints.txt.part constraints.txt
echo "wrote constraints.txt ($(grep -vc '^#' constraints.txt) packages)"
