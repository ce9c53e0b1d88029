#!/usr/bin/env bash
# Run the whole test suite on a fresh machine: installs what is missing (system libraries
# for Qt/napari, a virtualenv with the package), then runs pytest under a virtual X
# server with Mesa GL so that the napari GUI tests get a real canvas.
# Usage: bash scripts/test.sh [pytest args]
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
export MPLBACKEND=Agg
# software OpenGL from Mesa for napari's vispy canvas under Xvfb
export LIBGL_ALWAYS_SOFTWARE=1
# Qt 6 bindings (napari deprecates PyQt5); an older .venv may still hold PyQt5 too
export QT_API=pyqt6
.venv/bin/ruff check .
exec xvfb-run -a -s "-screen 0 1600x1000x24" .venv/bin/python -m pytest "$@"
