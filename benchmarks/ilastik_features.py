"""ilastik's pixel-classification filter bank, written with SciPy and scikit-image.

The features ilastik's Pixel Classification offers (its feature-selection dialog, all
boxes ticked), computed on every raw angle frame of a stack:

- Gaussian smoothing at σ = 0.3, 0.7, 1.0, 1.6, 3.5, 5.0, 10.0 px;
- at σ = 0.7 … 10.0 (ilastik offers 0.3 for the smoothing only):
  Laplacian of Gaussian, Gaussian gradient magnitude, difference of Gaussians
  G(σ) − G(0.66 σ), the two structure-tensor eigenvalues (inner scale σ, outer scale
  σ / 2) and the two Hessian-of-Gaussian eigenvalues.

That is 7 + 6 × 7 = 49 features per frame, 196 for a four-angle camera. Everything is
float32 and written into one preallocated (H, W, F) array, frame by frame, so a
1224 × 1024 four-angle frame needs about 1 GB for the features and a few tens of MB of
temporaries. ilastik computes these with VIGRA; the scikit-image structure tensor takes
finite-difference gradients of the image smoothed at the inner scale, a close stand-in
for VIGRA's Gaussian-derivative gradients.
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage
from skimage.feature import (
    hessian_matrix,
    hessian_matrix_eigvals,
    structure_tensor,
    structure_tensor_eigenvalues,
)

#: ilastik's scales (pixels); the smallest is offered for the smoothing only.
SIGMAS = (0.3, 0.7, 1.0, 1.6, 3.5, 5.0, 10.0)
#: The smaller scale of ilastik's difference of Gaussians, as a share of σ.
DOG_RATIO = 0.66
#: Channels per scale of the filters beyond the smoothing (LoG, GGM, DoG, ST ×2, HoG ×2).
PER_SCALE = 7


def n_features_per_frame(sigmas: tuple[float, ...] = SIGMAS) -> int:
    """Features of one frame: the smoothing at every σ, the rest at σ ≥ 0.7."""
    return len(sigmas) + PER_SCALE * sum(1 for s in sigmas if s >= 0.7)


def feature_names(n_frames: int, sigmas: tuple[float, ...] = SIGMAS) -> list[str]:
    """Names in the order :func:`ilastik_features` stores the features."""
    names = []
    for f in range(n_frames):
        names += [f"frame{f} gaussian {s}" for s in sigmas]
        for s in (s for s in sigmas if s >= 0.7):
            names += [f"frame{f} {kind} {s}" for kind in ("log", "ggm", "dog")]
            names += [f"frame{f} structure tensor ev{i} {s}" for i in (1, 2)]
            names += [f"frame{f} hessian ev{i} {s}" for i in (1, 2)]
    return names


def frame_features(frame: np.ndarray, out: np.ndarray, sigmas: tuple[float, ...] = SIGMAS):
    """Fill ``out`` (H, W, :func:`n_features_per_frame`) with one frame's features."""
    img = np.asarray(frame, dtype=np.float32)
    j = 0
    for s in sigmas:
        ndimage.gaussian_filter(img, s, output=out[..., j])
        j += 1
    for s in (s for s in sigmas if s >= 0.7):
        ndimage.gaussian_laplace(img, s, output=out[..., j])
        ndimage.gaussian_gradient_magnitude(img, s, output=out[..., j + 1])
        out[..., j + 2] = ndimage.gaussian_filter(img, s) - ndimage.gaussian_filter(
            img, DOG_RATIO * s
        )
        tensor = structure_tensor(ndimage.gaussian_filter(img, s), sigma=s / 2, order="rc")
        out[..., j + 3 : j + 5] = np.moveaxis(structure_tensor_eigenvalues(tensor), 0, -1)
        hessian = hessian_matrix(img, s, order="rc", use_gaussian_derivatives=True)
        out[..., j + 5 : j + 7] = np.moveaxis(hessian_matrix_eigvals(hessian), 0, -1)
        j += PER_SCALE
    return out


def ilastik_features(stack: np.ndarray, sigmas: tuple[float, ...] = SIGMAS) -> np.ndarray:
    """(H, W, N × 49) float32: ilastik's filter bank on each of the N frames of ``stack``."""
    stack = np.asarray(stack)
    n, h, w = stack.shape
    per = n_features_per_frame(sigmas)
    out = np.empty((h, w, n * per), dtype=np.float32)
    for f in range(n):
        frame_features(stack[f], out[..., f * per : (f + 1) * per], sigmas)
    return out
