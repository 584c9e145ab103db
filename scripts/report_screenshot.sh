#!/usr/bin/env bash
# Screenshot of a report.html as a reader sees it (headless Chromium, Debian
# package chromium; WebGL by SwiftShader), for docs/figures/.
#   scripts/report_screenshot.sh DIR/report.html OUT.png [WIDTH HEIGHT]
# The page is loaded from its folder (plotly-gl3d.min.js next to it), drawn,
# and captured from the top; HEIGHT (default 2400 px) sets how much of it.
set -euo pipefail
page=$(realpath "$1")
out=$(realpath -m "$2")
width=${3:-1280}
height=${4:-2400}
chromium=${ARTHROSIM_CHROMIUM:-chromium}
profile=$(mktemp -d)
trap 'rm -rf "$profile"' EXIT
"$chromium" --headless --no-sandbox --no-first-run --disable-extensions --hide-scrollbars \
  --use-angle=swiftshader --enable-unsafe-swiftshader --user-data-dir="$profile" \
  --virtual-time-budget=20000 --window-size="$width,$height" --screenshot="$out" "file://$page" 2>/dev/null
echo "report_screenshot: $out"
