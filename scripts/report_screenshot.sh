#!/usr/bin/env bash
# Screenshot of a report.html as a reader sees it (headless Chromium, Debian
# package chromium; WebGL by SwiftShader), for docs/figures/.
#   scripts/report_screenshot.sh DIR/report.html OUT.png [WIDTH HEIGHT [SECTION]]
# The page is loaded from its folder (plotly-gl3d.min.js next to it), drawn,
# and captured from the top; HEIGHT (default 2400 px) sets how much of it.
# SECTION (an id, e.g. sec-scenario-1) shows the title and that section only
# (a copy of the page with the other parts hidden, removed afterwards).
set -euo pipefail
page=$(realpath "$1")
out=$(realpath -m "$2")
width=${3:-1280}
height=${4:-2400}
chromium=${ARTHROSIM_CHROMIUM:-chromium}
section=${5:-}
profile=$(mktemp -d)
trap 'rm -rf "$profile"' EXIT
if [ -n "$section" ]; then
  copy="$(dirname "$page")/.screenshot_$section.html"
  sed "s|</head>|<style>body>*:not(h1):not(#$section){display:none !important}</style></head>|" "$page" > "$copy"
  trap 'rm -rf "$profile" "$copy"' EXIT
  page="$copy"
fi
"$chromium" --headless --no-sandbox --no-first-run --disable-extensions --hide-scrollbars \
  --use-angle=swiftshader --enable-unsafe-swiftshader --user-data-dir="$profile" \
  --virtual-time-budget=20000 --window-size="$width,$height" --screenshot="$out" "file://$page" 2>/dev/null
echo "report_screenshot: $out"
