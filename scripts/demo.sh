#!/usr/bin/env bash
# The main job on bundled sample data: sets up (idempotent), then segments the bundled
# synthetic leaves scene and writes labels, maps, params/summary JSON and overview.png.
# Usage: bash scripts/demo.sh [--out DIR] [--scene leaves|camouflage|fruit]
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
exec .venv/bin/polarseg demo "$@"
