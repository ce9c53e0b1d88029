#!/usr/bin/env bash
# The main job on bundled sample data: sets up (idempotent), then segments the bundled
# synthetic leaves scene and writes labels, maps, params/summary JSON and overview.png.
# Usage: bash scripts/demo.sh [--out DIR] [--scene leaves|camouflage|fruit]
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
.venv/bin/polarseg demo "$@"
# The command lives in the project's virtual environment, not on PATH:
cat <<'EOF'
demo: `polarseg` is installed in .venv/ (not on your PATH). Call it as
demo:   .venv/bin/polarseg segment --help
demo: or first `source .venv/bin/activate`, then `polarseg ...` and `napari` (Plugins menu).
EOF
