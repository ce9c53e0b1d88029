"""The libraries a first Labels layer imports are warmed ahead (issue 25: the first
segments froze the window while napari imported them on the GUI thread). Checked in a
fresh process that has run the default method, as the plugin has when its first
result arrives."""

from __future__ import annotations

import json
import subprocess
import sys

SCRIPT = """
import json, sys
import numpy as np
from napari.layers import Labels
from napari_polarseg.engine import PRESETS, Scene
from napari_polarseg.engine.synthetic.scenes import make_scene
from napari_polarseg.widgets.warm import warm_imports, warmed
scene = make_scene("leaves", shape=(64, 64), angles_deg=[0, 45, 90, 135])
Scene(scene.stack, np.deg2rad([0, 45, 90, 135])).segment(PRESETS["auto"])  # as a run does
warm_imports()
assert warmed(120)
before = set(sys.modules)
Labels(np.zeros((8, 8), dtype=np.int32))
new = sorted({name.split(".")[0] for name in set(sys.modules) - before})
print(json.dumps(new))
"""

#: Packages whose import takes a tenth of a second or more: none may be left for the
#: first Labels layer to import on the GUI thread.
HEAVY = {"pandas", "matplotlib", "scipy", "skimage", "sklearn", "dask"}


def test_a_first_labels_layer_imports_no_heavy_package_after_the_warm_up():
    out = subprocess.run(
        [sys.executable, "-c", SCRIPT], capture_output=True, text=True, timeout=300, check=True
    )
    new = set(json.loads(out.stdout.strip().splitlines()[-1]))
    assert not new & HEAVY, f"imported by the first Labels layer: {sorted(new & HEAVY)}"
