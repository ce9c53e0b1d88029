"""Real spherical harmonics of intensity over (zenith, azimuth), per image block.

Thesis eqs. 4.15–4.21. Angles are radians: θ is the zenith (polar angle from the view
axis, [0, π/2] for visible surfaces) and φ the azimuth.

Normalisation (stated because the thesis leaves it open)
--------------------------------------------------------
The real harmonics are orthonormal over the whole sphere, ∫ Y_lm Y_l'm' dΩ = δ_ll' δ_mm',
built from scipy's spherical Legendre functions (which carry the Condon–Shortley phase
(−1)^m) with that phase removed again:

    Y_l0  = Ȳ_l^0(θ)
    Y_lm  = √2 (−1)^m Ȳ_l^m(θ) cos(mφ)      m > 0
    Y_l−m = √2 (−1)^m Ȳ_l^m(θ) sin(mφ)      m > 0

where Ȳ_l^m(θ) = Y_l^m(θ, 0) is ``scipy.special.sph_legendre_p``. The coefficient vector
is ordered as the thesis's A = [a00, a1−1, a10, a11, a2−2, …]: index l² + l + m.

Evaluation (speed)
------------------
The harmonics are evaluated by the standard three-term recurrences of the normalised
associated Legendre functions, run directly on the real harmonics in thesis order (see
:func:`_fill_harmonics`), vectorised over points and over m, in chunks of a few thousand
points (cache-sized, bounded memory) spread over the CPU cores. This is hand-written only
because no library evaluates *all* degrees and orders fast enough
(``scipy.special.sph_harm_y_all`` and ``sph_legendre_p_all`` are an order of magnitude
slower; the figures are in ``docs/performance.md``). ``tests/test_harmonics.py`` checks
it against ``scipy.special.sph_harm_y`` to 1e-10 up to L = 30.

Estimators
----------
- ``"thesis"`` (eq. 4.21): a_lm = (1/M) Σ_i Î_i Y_lm(θ_i, φ_i) over the M pixels of a
  block. This is the inner product under the *empirical* measure of the block's samples,
  not a projection onto the orthonormal basis: only if the samples covered the sphere
  uniformly would it equal a_lm/(4π) of eq. 4.17. With the block Gram matrix
  G = (1/M) Yᵀ Y, the reconstruction consistent with it is Î ≈ Y (G + λI)⁻¹ a, which is
  the ridge fit below.
- ``"ridge"``: per-block ridge least squares, argmin ‖Y a − Î‖² + λ' ‖a‖² with
  λ' = ``ridge`` · M/(4π) (``ridge`` is relative to the mean diagonal of Yᵀ Y, which
  is M/(4π) for any sample positions).
"""

from __future__ import annotations

from functools import cache

import numpy as np

from ..chunks import CHUNK_BYTES, Progress, chunk_bounds, run_chunks, scratch
from ..errors import PolarsegError

#: Points per chunk of the recurrence: small enough to stay in cache (8192 was fastest
#: at L = 12 on the reference machine), large enough to amortise Python overhead.
CHUNK_POINTS = 8192


def n_coefficients(degree: int) -> int:
    """Length (L + 1)² of the coefficient vector for degree L."""
    return (degree + 1) ** 2


def coefficient_index(l: int, m: int) -> int:  # noqa: E741 - thesis notation
    """Position of a_lm in the thesis vector A (eq. 4.21 ordering): l² + l + m."""
    if not (l >= 0 and -l <= m <= l):
        raise PolarsegError(f"need l >= 0 and -l <= m <= l, got l={l}, m={m}")
    return l * l + l + m


def degree_order(degree: int) -> tuple[np.ndarray, np.ndarray]:
    """Arrays (l, m) for every entry of the coefficient vector, in thesis order."""
    ls = np.concatenate([np.full(2 * l + 1, l) for l in range(degree + 1)])  # noqa: E741
    ms = np.concatenate([np.arange(-l, l + 1) for l in range(degree + 1)])  # noqa: E741
    return ls, ms


# -- evaluation ---------------------------------------------------------------------------


def _points_per_chunk(k: int, multiple: int = 1) -> int:
    """Points per chunk for K harmonics: cache-sized, memory-capped, a multiple of M."""
    pts = max(1, min(CHUNK_POINTS, CHUNK_BYTES // (8 * max(k, 1))))
    return max(multiple, (pts // multiple) * multiple)


@cache
def _recurrence_tables(degree: int) -> tuple[tuple[np.ndarray, np.ndarray, float, float], ...]:
    """Coefficients of the recurrences for l = 2..L (see :func:`_fill_harmonics`)."""
    tables = []
    for l in range(2, degree + 1):  # noqa: E741
        m = np.abs(np.arange(-(l - 2), l - 1)).astype(float)
        a = np.sqrt((4.0 * l * l - 1.0) / (l * l - m * m))
        b = np.sqrt(((l - 1.0) ** 2 - m * m) / (4.0 * (l - 1.0) ** 2 - 1.0))
        tables.append(
            (
                a[:, None],
                (a * b)[:, None],
                np.sqrt(2.0 * l + 1.0),
                np.sqrt((2.0 * l + 1.0) / (2.0 * l)),
            )
        )
    return tuple(tables)


def _fill_harmonics(
    degree: int,
    z: np.ndarray,
    x: np.ndarray,
    y: np.ndarray,
    out: np.ndarray,
    seed: np.ndarray | None = None,
) -> None:
    """Write s · Y_lm at n points into ``out[:(L+1)², :n]`` in thesis order.

    Points are unit normals (x, y, z) = (sin θ cos φ, sin θ sin φ, cos θ); ``seed`` is an
    optional per-point factor s (default 1), e.g. Î for the eq. 4.21 sums. The normalised
    associated Legendre functions P̄_l^m (without the Condon–Shortley phase) satisfy

        P̄_l^m   = a_lm (cos θ P̄_{l−1}^m − b_lm P̄_{l−2}^m),   |m| <= l − 2,
        P̄_l^l−1 = √(2l + 1) cos θ P̄_{l−1}^l−1,
        P̄_l^l   = √((2l + 1)/(2l)) sin θ P̄_{l−1}^l−1,

    with a_lm = √((4l² − 1)/(l² − m²)) and b_lm = √(((l − 1)² − m²)/(4(l − 1)² − 1)).
    The first two are linear in l at fixed m, so they hold for P̄_l^m cos mφ and
    P̄_l^m sin mφ alike and run on the real harmonics directly; the third, applied to
    (cos, sin) pairs, is the rotation (C, S)_l ∝ (x C − y S, y C + x S)_{l−1}. All
    values of one degree come from the two previous degrees in a few array operations
    (vectorised over m), and no trigonometric function is evaluated beyond θ and φ.
    """
    n = z.shape[0]
    row0 = out[0, :n]
    c0 = 0.5 / np.sqrt(np.pi)
    if seed is None:
        row0.fill(c0)
    else:
        np.multiply(seed, c0, out=row0)
    if degree == 0:
        return
    tmp = scratch("rec_tmp", (max(2 * degree - 3, 2), n))
    t = tmp[0]
    np.multiply(row0, np.sqrt(3.0), out=t)
    np.multiply(t, y, out=out[1, :n])
    np.multiply(t, z, out=out[2, :n])
    np.multiply(t, x, out=out[3, :n])
    for l, (a, ab, c_edge, c_sect) in enumerate(_recurrence_tables(degree), start=2):  # noqa: E741
        b0, p1, p2 = l * l, (l - 1) ** 2, (l - 2) ** 2
        # |m| <= l - 2: rows b0+2 .. b0+2l-2 from degree l-1 rows p1+1.. and all of degree l-2
        t = tmp[: 2 * l - 3]
        np.multiply(out[p1 + 1 : p1 + 2 * l - 2, :n], z, out=t)
        t *= a
        u = out[b0 + 2 : b0 + 2 * l - 1, :n]
        np.multiply(out[p2 : p2 + 2 * l - 3, :n], ab, out=u)
        np.subtract(t, u, out=u)
        # |m| = l - 1: rows b0+1 and b0+2l-1 from rows p1 and p1+2l-2 (one strided op)
        t = tmp[0]
        np.multiply(z, c_edge, out=t)
        np.multiply(
            out[p1 : p1 + 2 * l - 1 : 2 * l - 2, :n],
            t,
            out=out[b0 + 1 : b0 + 2 * l : 2 * l - 2, :n],
        )
        # |m| = l: C_l = c (x C - y S) -> row b0+2l, S_l = c (y C + x S) -> row b0
        cos_prev, sin_prev = out[p1 + 2 * l - 2, :n], out[p1, :n]
        t1, t2 = tmp[0], tmp[1]
        np.multiply(x, cos_prev, out=t1)
        np.multiply(y, sin_prev, out=t2)
        np.subtract(t1, t2, out=t1)
        np.multiply(y, cos_prev, out=t2)
        cos_prev = out[b0 + 2 * l, :n]
        np.multiply(t1, c_sect, out=cos_prev)
        np.multiply(x, sin_prev, out=t1)
        np.add(t1, t2, out=t1)
        np.multiply(t1, c_sect, out=out[b0, :n])


def _unit_vectors(zenith: np.ndarray, azimuth: np.ndarray) -> tuple[np.ndarray, ...]:
    """(z, x, y) = (cos θ, sin θ cos φ, sin θ sin φ) of flat angle arrays."""
    s = np.sin(zenith)
    return np.cos(zenith), s * np.cos(azimuth), s * np.sin(azimuth)


def real_sph_harm(degree: int, zenith: np.ndarray, azimuth: np.ndarray) -> np.ndarray:
    """Real orthonormal spherical harmonics Y_lm up to ``degree`` (see module docstring).

    Thesis eqs. 4.15–4.16 (real form, orthonormal on the sphere).

    Parameters
    ----------
    degree : int
        Highest degree L (>= 0).
    zenith, azimuth : arrays of the same shape S
        Polar angle θ and azimuth φ, radians.

    Returns
    -------
    ndarray, shape S + ((L + 1)²,)
        Y_lm(θ, φ) in thesis order a00, a1−1, a10, a11, a2−2, … (dimensionless).
    """
    if degree < 0:
        raise PolarsegError(f"degree must be >= 0, got {degree}")
    zenith = np.asarray(zenith, dtype=float)
    azimuth = np.asarray(azimuth, dtype=float)
    if zenith.shape != azimuth.shape:
        raise PolarsegError(
            f"zenith and azimuth must have the same shape, got {zenith.shape} and {azimuth.shape}"
        )
    shape = zenith.shape
    k = n_coefficients(degree)
    th, ph = zenith.ravel(), azimuth.ravel()
    out = np.empty((th.size, k))

    def work(a: int, b: int) -> None:
        buf = scratch("harm_out", (k, b - a))
        _fill_harmonics(degree, *_unit_vectors(th[a:b], ph[a:b]), buf)
        out[a:b] = buf.T

    run_chunks(chunk_bounds(th.size, _points_per_chunk(k)), work, th.size)
    return out.reshape(shape + (k,))


# -- blocks ------------------------------------------------------------------------------


def block_grid(shape: tuple[int, int], window: int) -> tuple[int, int]:
    """Number of whole w × w blocks along rows and columns (remainder strips excluded)."""
    h, w = shape
    if window > h or window > w:
        raise PolarsegError(f"window size {window} is larger than the image ({h} x {w} pixels)")
    return h // window, w // window


def blockify(a: np.ndarray, window: int) -> np.ndarray:
    """(R*w, C*w, ...) -> (R, C, w*w, ...) without copying more than once."""
    r, c = a.shape[0] // window, a.shape[1] // window
    rest = a.shape[2:]
    a = a[: r * window, : c * window].reshape((r, window, c, window) + rest)
    return np.moveaxis(a, 2, 1).reshape((r, c, window * window) + rest)


def _unblockify(a: np.ndarray, window: int) -> np.ndarray:
    """(R, C, w*w) -> (R*w, C*w), the inverse of :func:`blockify`."""
    r, c = a.shape[:2]
    return a.reshape(r, c, window, window).transpose(0, 2, 1, 3).reshape(r * window, c * window)


def _block_inputs(
    intensity: np.ndarray,
    zenith: np.ndarray,
    azimuth: np.ndarray,
    window: int,
    weights: np.ndarray | None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray | None]:
    """Per-block pixel arrays (n_blocks, M) of Î, θ, φ and weights, M = w²."""
    m = window * window

    def flat(a: np.ndarray) -> np.ndarray:
        return blockify(np.asarray(a, dtype=float), window).reshape(-1, m)

    wts = None if weights is None else flat(weights)
    return flat(intensity), flat(zenith), flat(azimuth), wts


def block_coefficients(
    intensity: np.ndarray,
    zenith: np.ndarray,
    azimuth: np.ndarray,
    window: int,
    degree: int,
    method: str = "thesis",
    ridge: float = 1e-3,
    weights: np.ndarray | None = None,
    progress: Progress | None = None,
) -> np.ndarray:
    """Spherical-harmonic coefficients of Î(θ, φ) per non-overlapping w × w block.

    Thesis eq. 4.21 (``method="thesis"``) or a per-block ridge least-squares fit.

    Parameters
    ----------
    intensity, zenith, azimuth : arrays (H, W)
        Î (any units) and θ, φ (radians) per pixel.
    window : int
        Block side w in pixels. Only whole blocks are used; the remainder strips (when
        H or W is not a multiple of w) are labelled from their nearest block later.
    degree : int
        Highest degree L.
    method : {"thesis", "ridge"}
        Eq. 4.21 mean estimator, or per-block ridge least squares (module docstring).
    ridge : float
        Relative ridge penalty for ``method="ridge"``.
    weights : array (H, W) of {0, 1}, optional
        Pixels to use (1) or ignore (0), e.g. saturated or invalid pixels.
    progress : callable(share), optional
        Called with the share of the blocks done after each chunk of them
        (:func:`run_chunks`).

    Returns
    -------
    ndarray (H // w, W // w, (L + 1)²)
        Coefficients in the units of ``intensity``.

    Notes
    -----
    The eq. 4.21 sums are formed by seeding the harmonic recurrence with Î (every Y_lm
    is linear in Y_00), so a block's coefficients are plain sums over its M pixels of
    one chunk of values: no separate product with Î.
    """
    if method not in ("thesis", "ridge"):
        raise PolarsegError(f"coefficient method must be 'thesis' or 'ridge', got {method!r}")
    nby, nbx = block_grid(intensity.shape, window)
    if method == "ridge":
        coef, _ = _ridge_blocks(
            intensity, zenith, azimuth, window, degree, ridge, weights, progress=progress
        )
        return coef.reshape(nby, nbx, -1)
    k = n_coefficients(degree)
    m = window * window
    f, th, ph, wts = _block_inputs(intensity, zenith, azimuth, window, weights)
    nb = f.shape[0]
    if wts is not None:
        f = f * wts
        count = np.maximum(wts.sum(axis=1), 1.0)
    else:
        count = np.full(nb, float(m))
    out = np.empty((nb, k))
    per = _points_per_chunk(k, m) // m

    def work(b0: int, b1: int) -> None:
        n = (b1 - b0) * m
        buf = scratch("harm_out", (k, n))
        sl = slice(b0, b1)
        _fill_harmonics(degree, *_unit_vectors(th[sl].ravel(), ph[sl].ravel()), buf, f[sl].ravel())
        out[sl] = buf.reshape(k, b1 - b0, m).sum(axis=2).T / count[sl, None]

    run_chunks(chunk_bounds(nb, per), work, nb * m, progress)
    return out.reshape(nby, nbx, k)


def _ridge_blocks(
    intensity: np.ndarray,
    zenith: np.ndarray,
    azimuth: np.ndarray,
    window: int,
    degree: int,
    ridge: float,
    weights: np.ndarray | None,
    reconstruct: bool = False,
    coefficients: bool = True,
    progress: Progress | None = None,
) -> tuple[np.ndarray | None, np.ndarray | None]:
    """Per-block ridge fit: coefficients (n_blocks, K) and, optionally, Y a per pixel.

    argmin ‖Y a − Î‖² + λ' ‖a‖², λ' = ``ridge`` · M/(4π), solved per block in the dual
    (M × M) form α = (Y Yᵀ + λ'I)⁻¹ Î, a = Yᵀ α when M < K, else in the primal form
    a = (Yᵀ Y + λ'I)⁻¹ Yᵀ Î: one batched matrix product and one batched LAPACK solve per
    chunk of blocks, chunks spread over the cores with single-threaded BLAS.

    In the dual form without weights the reconstruction needs no coefficients: with the
    M × M Gram matrix G (Y Yᵀ above, rows = pixels), Y a = G α = (G + λ'I) α − λ'α =
    Î − λ'α. ``coefficients=False`` then skips a and returns None for it.
    """
    k = n_coefficients(degree)
    m = window * window
    f, th, ph, wts = _block_inputs(intensity, zenith, azimuth, window, weights)
    nb = f.shape[0]
    lam = ridge * m / (4 * np.pi)
    dual = m < k
    shortcut = reconstruct and dual and wts is None  # Y a = Î − λ'α (docstring)
    coef = np.empty((nb, k)) if coefficients or not shortcut else None
    rec = np.empty((nb, m)) if reconstruct else None
    size = m if dual else k
    per = _points_per_chunk(k, m) // m

    def work(b0: int, b1: int) -> None:
        nbc = b1 - b0
        sl = slice(b0, b1)
        buf = scratch("harm_out", (k, nbc * m))
        _fill_harmonics(degree, *_unit_vectors(th[sl].ravel(), ph[sl].ravel()), buf)
        Y = buf.reshape(k, nbc, m).transpose(1, 0, 2)  # (blocks, K, M) view
        fb = f[sl]
        Yw = Y
        if wts is not None:
            Yw = Y * wts[sl, None, :]
            fb = fb * wts[sl]
        if dual:
            gram = np.matmul(Yw.transpose(0, 2, 1), Yw)  # (blocks, M, M)
            rhs = fb[..., None]
        else:
            gram = np.matmul(Yw, Yw.transpose(0, 2, 1))  # (blocks, K, K)
            rhs = np.matmul(Yw, fb[..., None])
        gram.reshape(nbc, size * size)[:, :: size + 1] += lam
        sol = np.linalg.solve(gram, rhs)
        if shortcut:
            rec[sl] = fb - lam * sol[..., 0]
            if coef is None:
                return
        a = np.matmul(Yw, sol)[..., 0] if dual else sol[..., 0]
        coef[sl] = a
        if rec is not None and not shortcut:
            rec[sl] = np.matmul(a[:, None, :], Y)[:, 0, :]

    run_chunks(chunk_bounds(nb, per), work, nb * m, progress)
    return coef, rec


def pixel_block_index(shape: tuple[int, int], window: int) -> tuple[np.ndarray, np.ndarray]:
    """Block row and column of every pixel row and column, remainder strips included.

    Pixels in the remainder strips (when the size is not a multiple of w) belong to the
    nearest whole block, so that labels and reconstructions cover the full image.
    """
    nby, nbx = block_grid(shape, window)
    rows = np.minimum(np.arange(shape[0]) // window, nby - 1)
    cols = np.minimum(np.arange(shape[1]) // window, nbx - 1)
    return rows, cols


def upsample_block_labels(
    block_labels: np.ndarray, shape: tuple[int, int], window: int
) -> np.ndarray:
    """Pixel-resolution labels (H, W) from block labels, covering every input pixel."""
    rows, cols = pixel_block_index(shape, window)
    return block_labels[rows[:, None], cols[None, :]]


def top_left_block_labels(labels: np.ndarray, window: int) -> np.ndarray:
    """Block labels (R, C) of pixel labels (H, W): the label at each whole w × w block's
    top-left pixel (the block grid of :func:`block_grid`), for results whose labels are
    found per pixel rather than per block."""
    rows, cols = block_grid(labels.shape, window)
    return np.ascontiguousarray(labels[: rows * window : window, : cols * window : window])


def evaluate_expansion(
    degree: int, zenith: np.ndarray, azimuth: np.ndarray, coefficients: np.ndarray
) -> np.ndarray:
    """Σ_lm a_lm Y_lm(θ_i, φ_i) at each point i with its own coefficient vector.

    Thesis eq. 4.17 truncated at L. ``zenith``, ``azimuth``: (n,) radians;
    ``coefficients``: (n, (L + 1)²). Returns (n,) in the coefficients' units.
    """
    th = np.asarray(zenith, dtype=float).ravel()
    ph = np.asarray(azimuth, dtype=float).ravel()
    k = n_coefficients(degree)
    out = np.empty(th.size)

    def work(a: int, b: int) -> None:
        buf = scratch("harm_out", (k, b - a))
        _fill_harmonics(degree, *_unit_vectors(th[a:b], ph[a:b]), buf)
        out[a:b] = np.einsum("ki,ik->i", buf, coefficients[a:b])

    run_chunks(chunk_bounds(th.size, _points_per_chunk(k)), work, th.size)
    return out


def reconstruct_intensity(
    intensity: np.ndarray,
    zenith: np.ndarray,
    azimuth: np.ndarray,
    window: int,
    degree: int,
    ridge: float = 1e-3,
    weights: np.ndarray | None = None,
    progress: Progress | None = None,
) -> np.ndarray:
    """Î rebuilt per pixel from its block's harmonic expansion (thesis section 5.5).

    Uses the reconstruction consistent with both estimators: the ridge least-squares
    coefficients of each block (equal to (G + λI)⁻¹ a_thesis, see module docstring),
    evaluated at every pixel's own (θ, φ) — in the same pass that fits them, so the
    harmonics of the block pixels are evaluated once. Remainder-strip pixels use the
    nearest block's coefficients. Returns an (H, W) array in the units of ``intensity``.
    ``progress`` is called with the share of the blocks fitted after each chunk of them.
    """
    nby, nbx = block_grid(intensity.shape, window)
    h, w = intensity.shape
    hb, wb = nby * window, nbx * window
    coef, rec = _ridge_blocks(
        intensity,
        zenith,
        azimuth,
        window,
        degree,
        ridge,
        weights,
        reconstruct=True,
        coefficients=hb < h or wb < w,  # only the remainder strips need them
        progress=progress,
    )
    out = np.empty((h, w))
    out[:hb, :wb] = _unblockify(rec.reshape(nby, nbx, -1), window)
    if hb < h or wb < w:
        rows, cols = pixel_block_index(intensity.shape, window)
        strip = np.ones((h, w), dtype=bool)
        strip[:hb, :wb] = False
        rr, cc = np.nonzero(strip)
        zen = np.asarray(zenith, dtype=float)
        azi = np.asarray(azimuth, dtype=float)
        block = rows[rr] * nbx + cols[cc]
        out[rr, cc] = evaluate_expansion(degree, zen[rr, cc], azi[rr, cc], coef[block])
    return out
