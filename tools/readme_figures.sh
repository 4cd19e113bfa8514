#!/usr/bin/env bash
# Regenerate the README's figures, docs/figures/SCENE.png: each scene's demo is solved afresh
# (`posturegen demo SCENE`, on the scene's default robot unless --robot is given) and its final
# posture drawn by `posturegen render`, then reduced to a 256-colour palette (about a third of
# the size, no visible change).
#
#   tools/readme_figures.sh [--robot NAME] [--dpi N] [SCENE ...]     (default: every scene)
#
# A scene whose demo finds no verified posture gets no figure: the script says which and why,
# leaves that scene's old figure as it was, goes on with the others and exits 1. Run it from
# anywhere, in the environment where posturegen is installed (`pip install -e .`).
set -euo pipefail
SCENES=(stand-reach wall-brace ladder-inclined ladder-vertical stairs)
robot=()
dpi=100
chosen=()
while (($#)); do
    case "$1" in
        --robot) robot=(--robot "$2"); shift 2 ;;
        --dpi) dpi=$2; shift 2 ;;
        -h | --help) sed -n '2,13p' "$0" | cut -c3-; exit 0 ;;
        -*) echo "readme_figures: unknown option $1 (see --help)" >&2; exit 2 ;;
        *) chosen+=("$1"); shift ;;
    esac
done
((${#chosen[@]})) || chosen=("${SCENES[@]}")
cd "$(dirname "$0")/.."
out=docs/figures
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
mkdir -p "$out"
failed=()
for name in "${chosen[@]}"; do
    start=$SECONDS
    if ! posturegen demo "$name" "${robot[@]}" --out "$tmp/$name" --quiet 2>"$tmp/$name.err"; then
        echo "readme_figures: $name: NO FIGURE: $(tail -n 1 "$tmp/$name.err")" >&2
        failed+=("$name")
        continue
    fi
    title="posturegen demo $name ${robot[*]}"
    posturegen render "$tmp/$name/posture.json" -o "$tmp/$name.png" --dpi "$dpi" \
        --title "${title% }" >/dev/null
    python3 - "$tmp/$name.png" <<'PY'
import sys
from PIL import Image

path = sys.argv[1]
im = Image.open(path).convert("RGB")
im.quantize(256, method=Image.Quantize.FASTOCTREE).save(path, optimize=True)
PY
    mv "$tmp/$name.png" "$out/$name.png"
    echo "$out/$name.png: $(($(stat -c %s "$out/$name.png") / 1024)) kB, $((SECONDS - start)) s"
done
if ((${#failed[@]})); then
    echo "readme_figures: no verified posture, figure not written: ${failed[*]}" >&2
    exit 1
fi
