#!/usr/bin/env bash
# Regenerate the README's figures, docs/figures/NAME.png, from the shipped demos: each demo is
# solved afresh and drawn by `posturegen render` (small PNGs: DPI 75 gives 1200x675 pixels).
# DEMOS is the one list to extend (one demo per paper scene). Run from anywhere, in the
# environment where posturegen is installed (`pip install -e .`).
set -euo pipefail
DEMOS=(stand-reach)
DPI=${DPI:-75}
cd "$(dirname "$0")/.."
out=docs/figures
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
mkdir -p "$out"
for name in "${DEMOS[@]}"; do
    posturegen demo "$name" --out "$tmp/$name" --quiet
    posturegen render "$tmp/$name/posture.json" -o "$out/$name.png" --dpi "$DPI" \
        --title "posturegen demo $name"
done
# 256-colour palettes: a third of the size, no visible change
python3 - "${DEMOS[@]/#/$out/}" <<'PY'
import sys
from PIL import Image

for name in sys.argv[1:]:
    path = f"{name}.png"
    im = Image.open(path).convert("RGB")
    im.quantize(256, method=Image.Quantize.FASTOCTREE).save(path, optimize=True)
PY
