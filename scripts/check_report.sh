#!/usr/bin/env bash
# Render a romosplat report.html in headless Chromium and check it displayed:
# the DOM dump must contain the report's tables, an inline SVG chart and the
# embedded images, and a screenshot must be written.
# Usage: scripts/check_report.sh out/report.html [screenshot.png]
set -euo pipefail
report=$(realpath "$1")
shot=${2:-${report%.html}.png}
chrome=$(command -v chromium || command -v chromium-browser || true)
if [ -z "$chrome" ]; then
  echo "check_report: chromium is not installed (apt-get install -y chromium)" >&2
  exit 1
fi
profile=$(mktemp -d)
flags=(--headless --no-sandbox --disable-gpu --disable-quic --no-first-run
       --disable-background-networking --disable-component-update --disable-sync
       --user-data-dir="$profile")
dom=$(timeout 120 "$chrome" "${flags[@]}" --dump-dom "file://$report" 2>/dev/null)
timeout 120 "$chrome" "${flags[@]}" --window-size=1280,2400 --screenshot="$shot" "file://$report" >/dev/null 2>&1
rm -rf "$profile"
fail=0
for needle in '<table' '<svg' 'data:image/png;base64' 'Stage timings'; do
  if ! grep -q "$needle" <<<"$dom"; then echo "check_report: rendered DOM lacks $needle" >&2; fail=1; fi
done
[ -s "$shot" ] || { echo "check_report: no screenshot written" >&2; fail=1; }
[ $fail -eq 0 ] && echo "check_report: $report rendered in $("$chrome" --version 2>/dev/null); screenshot $shot"
exit $fail
