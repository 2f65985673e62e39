#!/usr/bin/env bash
# The Python reference environment of the benchmarks: `bench/venv.sh TOPIC...` makes sure
# bench/.venv (git-ignored) exists and holds bench/requirements-TOPIC.txt for every TOPIC
# (opencv, open3d, colmap, xatlas, plyfile), installing what is missing from PyPI, then prints
# the path of its python. The scripts call it as
#     PYTHON=${PYTHON:-$(bench/venv.sh open3d)}
# so PYTHON=/path/to/python still chooses another environment. Each requirements file is
# installed once; a changed file is installed again (its checksum is kept in the venv).
set -euo pipefail
cd "$(dirname "$0")/.."
VENV=bench/.venv
if [[ ! -x $VENV/bin/python ]]; then
    echo "bench/venv.sh: creating $VENV" >&2
    python3 -m venv "$VENV" >&2
    "$VENV/bin/python" -m pip install --quiet --upgrade pip >&2
fi
for topic in "$@"; do
    req=bench/requirements-$topic.txt
    if [[ ! -f $req ]]; then
        echo "bench/venv.sh: no $req" >&2
        exit 2
    fi
    stamp=$VENV/.installed-$topic
    sum=$(sha256sum "$req" | cut -d' ' -f1)
    if [[ ! -f $stamp || $(cat "$stamp") != "$sum" ]]; then
        echo "bench/venv.sh: installing $req into $VENV" >&2
        "$VENV/bin/python" -m pip install --quiet -r "$req" >&2
        echo "$sum" > "$stamp"
    fi
done
echo "$PWD/$VENV/bin/python"
