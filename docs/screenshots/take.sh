#!/usr/bin/env bash
# Screenshots of the built site in headless Chromium (Debian's `chromium` package):
#   .venv/bin/mkdocs build --strict --site-dir /tmp/site && bash docs/screenshots/take.sh /tmp/site
# writes home.png, speed-and-accuracy.png, work-precision-notebook.png and scheme-zhao.png here.
set -euo pipefail
site="$(cd "${1:?usage: take.sh SITE_DIR}" && pwd)"
here="$(cd "$(dirname "$0")" && pwd)"
browser="$(command -v chromium || command -v chromium-browser)"
shoot() {  # page, output, window height
  "$browser" --headless --no-sandbox --disable-gpu --hide-scrollbars --window-size=1280,"$3" \
    --virtual-time-budget=5000 --screenshot="$here/$2" "file://$site/$1" 2>/dev/null
}
shoot index.html home.png 2200
shoot speed-and-accuracy.html speed-and-accuracy.png 3200
shoot examples/work_precision.html work-precision-notebook.png 5200
shoot schemes/zhao.html scheme-zhao.png 2400
ls -l "$here"/*.png
