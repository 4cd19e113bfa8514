#!/usr/bin/env bash
# Regenerate src/posturegen/data/js/ (the JavaScript inlined into `posturegen view` HTML files)
# from the pinned npm package three@$THREE_VERSION: build/three.module.min.js,
# examples/jsm/controls/OrbitControls.js and the package's LICENSE (MIT), plus VERSION with the
# tarball's integrity hash. Needs npm and network access; run from anywhere.
set -euo pipefail
THREE_VERSION=0.170.0
cd "$(dirname "$0")/.."
dest=src/posturegen/data/js
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
(cd "$tmp" && npm pack --silent --json "three@$THREE_VERSION" >pack.json)
integrity=$(python3 -c 'import json,sys; print(json.load(open(sys.argv[1]))[0]["integrity"])' "$tmp/pack.json")
tar -xzf "$tmp/three-$THREE_VERSION.tgz" -C "$tmp"
mkdir -p "$dest"
cp "$tmp/package/build/three.module.min.js" "$dest/three.module.min.js"
cp "$tmp/package/examples/jsm/controls/OrbitControls.js" "$dest/OrbitControls.js"
cp "$tmp/package/LICENSE" "$dest/LICENSE"
printf 'three@%s %s\n' "$THREE_VERSION" "$integrity" >"$dest/VERSION"
echo "vendored three@$THREE_VERSION into $dest ($integrity)"
