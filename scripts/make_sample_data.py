#!/usr/bin/env python
"""Write the bundled sample angle stacks and their README.

Renders every scene of :data:`napari_polarseg.engine.synthetic.scenes.SCENES` with the defaults
(seed 0, 120 × 130 pixels, 7 angles 0..180° in 30° steps, 12-bit, 0.3 % noise) and saves

    napari_polarseg/sample_data/<name>.npz   stack (uint16, N × H × W),
                                             angles (float64, degrees),
                                             labels (uint8, H × W ground truth)
    napari_polarseg/sample_data/README.md    scenes, materials, parameters, format

Usage::

    python scripts/make_sample_data.py [--out DIR] [--seed 0]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from napari_polarseg.engine.synthetic.scenes import (  # noqa: E402
    SCENES,
    SyntheticScene,
    make_scene,
)

DEFAULT_OUT = ROOT / "napari_polarseg" / "sample_data"

DESCRIPTIONS = {
    "leaves": (
        "Natural leaves (left half) and moulded plastic leaves (right half), overlapping "
        "in the middle, on a matte board; modelled on thesis figures 5.1 and 5.5. Both "
        "kinds of leaf have the same shape statistics (pointed ellipses, tilted, arched "
        "or cupped, a folded midrib, fine waviness): only the material differs."
    ),
    "camouflage": (
        "A folded camouflage net with garnish cut-outs (holes through which the foliage "
        "shows) draped over dense foliage of small, randomly oriented leaves; modelled "
        "on thesis figure 5.7. The net's folds and garnish flaps give it a normal "
        "distribution similar to the foliage's."
    ),
    "fruit": (
        "Close-up of a large near-spherical fruit that fills the frame, with a bruised, "
        "slightly dented patch; modelled on the thesis's 240 x 240 inspection crops "
        "(section 5.3, bruised before it shows). Healthy and bruised skin share one "
        "albedo, so there is no intensity edge at the bruise; the task is healthy "
        "against bruised skin on a strongly curved surface."
    ),
}


def write_scene(name: str, out: Path, seed: int) -> tuple[Path, SyntheticScene]:
    """Render ``name`` with the defaults and save it as a compressed npz."""
    scene = make_scene(name, seed=seed)
    path = out / f"{name}.npz"
    np.savez_compressed(
        path,
        stack=scene.stack.astype(np.uint16),
        angles=np.asarray(scene.angles_deg, dtype=np.float64),
        labels=scene.labels.astype(np.uint8),
    )
    return path, scene


def scene_section(name: str, scene: SyntheticScene, size: int) -> str:
    """Markdown section describing one scene."""
    lines = [
        f"## `{name}.npz`",
        "",
        DESCRIPTIONS[name],
        "",
        f"File size: {size / 1024:.0f} KiB. Labels: "
        + ", ".join(f"{k} = {m}" for k, m in enumerate(scene.material_names))
        + ".",
        "",
        "| label | material | n | depolarisation d | roughness (°) | albedo "
        "| pixels | mean Î | mean ρ | mean zenith (°) |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for k, label in enumerate(scene.material_names):
        m = scene.params["materials"][label]
        sel = scene.labels == k
        lines.append(
            f"| {k} {label} | {m['material']} | {m['refractive_index']:.2f} "
            f"| {m['depolarisation']:.2f} | {m['roughness_deg']:.0f} | {m['albedo']:.3f} "
            f"| {sel.mean():.1%} | {scene.intensity[sel].mean():.3f} "
            f"| {scene.dop[sel].mean():.4f} | {np.rad2deg(scene.zenith[sel]).mean():.1f} |"
        )
    lines += ["", "Materials:", ""]
    for label in scene.material_names:
        m = scene.params["materials"][label]
        lines.append(f"- **{label}** ({m['material']}): {m['description']}.")
    lines.append("")
    return "\n".join(lines)


def readme_text(sections: list[str], params: dict) -> str:
    """The sample-data README."""
    angles = ", ".join(f"{a:g}" for a in params["angles_deg"])
    header = f"""# Sample data

Synthetic polarisation angle stacks with ground-truth material labels, rendered from
physics by `napari_polarseg.engine.synthetic.scenes.make_scene` and written by
`scripts/make_sample_data.py` (do not edit by hand; rerun the script). Any scene can be
re-rendered with its full ground truth (noise-free Î, ρ, φ, zenith, azimuth, refractive
index) with `make_scene(name, seed={params["seed"]})`.

## File format

Each `<name>.npz` (NumPy `savez_compressed`) holds:

- `stack`: uint16, shape (N, H, W) = ({len(params["angles_deg"])}, {params["shape"][0]}, \
{params["shape"][1]}), {params["bit_depth"]}-bit values (full scale = \
{2 ** params["bit_depth"] - 1});
  frame k is the image through a linear polariser at `angles[k]`.
- `angles`: float64, shape (N,), polariser angles in **degrees** ({angles});
  0 and 180 are the same polariser state. Angles and the phase φ are measured from the
  image's column axis (increasing column index) towards its row axis (increasing row
  index).
- `labels`: uint8, shape (H, W), ground-truth material of each pixel (0..K−1, majority
  of its sub-pixels).

The images follow I(α) = Î (1 + ρ cos(2α − 2φ)) (thesis eq. 3.14).

## Rendering model (common to all scenes)

- Orthographic camera looking down the z axis; surface normals from a height field,
  n ∝ (−∂z/∂col, −∂z/∂row, 1).
- Each pixel is {params["supersample"]} × {params["supersample"]} sub-pixels with \
{params["facets_per_subpixel"]} random micro-facets
  each; the facet slopes are the macroscopic slope plus Gaussian slopes of standard
  deviation tan(roughness).
- Shading: Lambertian under a distant light {params["light_zenith_deg"]:g}° off the \
view axis (thesis section
  5.1), from azimuth {params["light_azimuth_deg"]:g}° (upper left), plus \
{params["ambient"]:.0%} ambient; times a smooth
  albedo texture ({params["texture_std"]:.0%} standard deviation, correlation \
{params["texture_sigma_px"]:g} px) with the same
  statistics in every material; no specular highlights, no cast shadows.
- Diffuse polarisation: ρ from the Fresnel transmission coefficients for light leaving
  the material at the facet's zenith (`diffuse_dop_from_transmission`), times (1 − d)
  for depolarisation by volume/sub-surface scattering; φ = facet azimuth (mod 180°).
- The Stokes components (Î, Î ρ cos 2φ, Î ρ sin 2φ) of all facets of a pixel are
  averaged: roughness lowers ρ and scatters φ.
- Matched albedo: each material's albedo is calibrated so that its mean Î is \
{params["target_intensity"]:.0%} of
  full scale (for the fruit, healthy and bruised skin share one albedo); intensity alone
  does not separate the materials.
- Sensor: Gaussian noise σ = {params["noise_sigma"]:.1%} of full scale, then \
{params["bit_depth"]}-bit quantisation. Seed {params["seed"]}.

The parameter values are plausible, not measured; see the material descriptions.
The mean ρ of most materials is of the order of 0.01–0.05, close to the noise floor of
a single pixel (σ(ρ) ≈ 0.004 at Î = 0.4 with 7 frames): these scenes are hard on
purpose.

This README covers the synthetic scenes only; other files in this folder (if any) are
described by their own notes.

"""
    return header + "\n".join(sections)


def main(argv: list[str] | None = None) -> int:
    """Write all scenes and the README; print the file sizes."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT, help="output folder")
    parser.add_argument("--seed", type=int, default=0, help="seed (default 0)")
    args = parser.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    sections = []
    params: dict = {}
    for name in SCENES:
        path, scene = write_scene(name, args.out, args.seed)
        size = path.stat().st_size
        print(f"{path}: {size / 1024:.0f} KiB")
        sections.append(scene_section(name, scene, size))
        params = scene.params
    (args.out / "README.md").write_text(readme_text(sections, params), encoding="utf-8")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
