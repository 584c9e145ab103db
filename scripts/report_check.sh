#!/usr/bin/env bash
# Draws a report.html in headless Chromium (Debian package chromium) and prints
# the page's own check (pipelines/report_html.h): every figure drew, no script
# error. Exit 0 when it passed, 1 when not, 77 when chromium is not installed
# (CTest's SKIP_RETURN_CODE in tests/sample_runs/arthrosim-post.cmake).
#   scripts/report_check.sh DIR/report.html
set -euo pipefail
page=$(realpath "$1")
chromium=${ARTHROSIM_CHROMIUM:-chromium}
if ! command -v "$chromium" >/dev/null 2>&1; then
  echo "report_check: chromium is not installed (scripts/install-deps.sh): $page not drawn, skipped"
  exit 77
fi
profile=$(mktemp -d)
trap 'rm -rf "$profile"' EXIT
dom=$(timeout 120 "$chromium" --headless --no-sandbox --no-first-run --disable-extensions \
  --use-angle=swiftshader --enable-unsafe-swiftshader --user-data-dir="$profile" \
  --virtual-time-budget=20000 --window-size=1280,900 --dump-dom "file://$page" 2>/dev/null)
check=$(printf '%s' "$dom" | sed -n 's|.*<pre id="report-check"[^>]*>\(.*\)</pre>.*|\1|p')
echo "report_check: $page: ${check:-(the page wrote no check)}"
case "$check" in
  '{"ok":true,'*) exit 0 ;;
  *) exit 1 ;;
esac
