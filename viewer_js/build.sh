#!/bin/sh
# Rebuild the viewer's one inline script from src/ (three.js pinned in package-lock.json):
#   cd viewer_js && ./build.sh
# writes ../cassi_fit/viewer/assets/viewer.js (an IIFE: module scripts are blocked on file://)
# and copies three.js's licence beside it. Needs node and npm; the built file is committed,
# so installing or using cassi_fit needs neither.
set -eu
cd "$(dirname "$0")"
npm ci --no-audit --no-fund
out=../cassi_fit/viewer/assets
mkdir -p "$out"
npx esbuild src/main.js --bundle --format=iife --minify --target=es2020 \
  --legal-comments=none --outfile="$out/viewer.js"
cp node_modules/three/LICENSE "$out/THREE_LICENSE"
echo "three $(node -p "require('./node_modules/three/package.json').version")" > "$out/VERSIONS"
echo "esbuild $(npx esbuild --version)" >> "$out/VERSIONS"
