#!/usr/bin/env bash
# Bundle the viewer's browser side (viewer/src/main.js and the parts of three.js it imports) into
# one minified script, tether_gym/viewer/static/viewer.js, which the Python package inlines into
# every page it serves or exports. The bundle is committed, so that users and CI need no Node.js;
# run this after changing viewer/src (tests/viewer/test_bundle.py checks the bundle is current).
set -euo pipefail
cd "$(dirname "$0")/../viewer"
npm ci --no-audit --no-fund --ignore-scripts >/dev/null
out=../tether_gym/viewer/static
# The sources' digest heads the bundle, so that a test can tell a bundle older than its sources.
digest=$(cat src/main.js package-lock.json | sha256sum | cut -d' ' -f1)
./node_modules/.bin/esbuild src/main.js --bundle --minify --format=iife --target=es2020 \
    --legal-comments=none "--banner:js=/* tether-gym viewer bundle, sources sha256 $digest */" --outfile="$out/viewer.js" --log-level=warning
# three.js is MIT-licensed: its licence travels with the bundle.
cp node_modules/three/LICENSE "$out/THREE_LICENSE"
echo "built $out/viewer.js ($(wc -c <"$out/viewer.js") bytes, three $(node -p "JSON.parse(require(\"fs\").readFileSync(\"node_modules/three/package.json\")).version"))"
