#!/usr/bin/env bash
# Run tools/drake_peer.py (posturegen's exported problems solved with Drake) in Drake's own
# virtual environment, created on first use at ${DRAKE_VENV:-$HOME/.cache/posturegen-drake-venv}
# with drake==$DRAKE_VERSION and numpy (Drake is no dependency of posturegen). Arguments go to
# the script; run from anywhere:
#   tools/drake_peer.sh PROBLEMS.jsonl --out RESULTS.jsonl [--solvers ipopt,snopt] [--max N]
#     [--time-limit S]
set -euo pipefail
DRAKE_VERSION=1.51.0
here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
venv="${DRAKE_VENV:-$HOME/.cache/posturegen-drake-venv}"
check="import importlib.metadata as m, numpy, pydrake; \
raise SystemExit(m.version('drake') != '$DRAKE_VERSION')"
if ! "$venv/bin/python" -c "$check" >/dev/null 2>&1; then
  echo "drake_peer: installing drake==$DRAKE_VERSION and numpy into $venv" >&2
  python3 -m venv "$venv"
  "$venv/bin/python" -m pip install --quiet "drake==$DRAKE_VERSION" numpy >&2
fi
exec "$venv/bin/python" "$here/drake_peer.py" "$@"
