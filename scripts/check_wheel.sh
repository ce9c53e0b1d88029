#!/usr/bin/env bash
# What a user who installs the package (not the repository) gets: builds the wheel, makes
# a fresh virtual environment WITHOUT the system's or the project's packages and WITHOUT
# the test extras, installs the wheel there (its declared dependencies come from the
# package index) plus npe2 (napari's plugin engine, for the manifest check), then
#   - runs `polarseg demo` from an empty folder (the installed copy, not the sources),
#   - checks the npe2 manifest is found through the installed entry point and is valid,
#   - checks that no test tool came along (pytest, hypothesis).
# It downloads every dependency, so it takes ~4-5 min on a fresh machine: not part of
# scripts/test.sh. Usage: bash scripts/check_wheel.sh   (PYTHON=python3.X to choose)
set -euo pipefail
cd "$(dirname "$0")/.."
root=$(pwd)
PY=${PYTHON:-python3}
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
t0=$SECONDS

echo "check_wheel: building the wheel"
"$PY" -m pip wheel --no-deps -q --disable-pip-version-check . -w "$work/dist" >/dev/null
wheel=$(ls "$work"/dist/napari_polarseg-*.whl)
rm -rf build  # setuptools' build folder, from the wheel build
echo "check_wheel: $(basename "$wheel") ($((SECONDS - t0)) s)"

"$PY" -m venv "$work/venv"
"$work/venv/bin/python" -m pip install -q --disable-pip-version-check "$wheel" npe2
echo "check_wheel: installed into a fresh venv ($((SECONDS - t0)) s)"

mkdir "$work/run"
cd "$work/run"
"$work/venv/bin/python" - "$work/venv" <<'EOF'
import importlib.util, sys
import napari_polarseg
where = napari_polarseg.__file__
assert where.startswith(sys.argv[1]), f"napari_polarseg imported from {where}, not the venv"
extras = [m for m in ("pytest", "hypothesis", "napari", "magicgui") if importlib.util.find_spec(m)]
assert not extras, f"installed without the test extras, yet found {extras}"
print(f"check_wheel: napari_polarseg from {where}; no pytest, hypothesis, napari")
EOF
"$work/venv/bin/polarseg" demo --out demo | tee "$work/demo.txt"
grep -q "adjusted Rand index against the ground truth" "$work/demo.txt"
test -s demo/overview.png && test -s demo/labels.tif
"$work/venv/bin/npe2" validate napari-polarseg
"$work/venv/bin/python" -c "
from npe2 import PluginManager
pm = PluginManager()
pm.discover()
manifest = pm.get_manifest('napari-polarseg')
print(f'check_wheel: npe2 discovers {manifest.name}: {len(manifest.contributions.commands)} commands')
"
cd "$root"
echo "check_wheel: ok in $((SECONDS - t0)) s"
