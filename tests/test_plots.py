"""Plot data of the analyst's bench (engine/analysis/plots.py), PNGs of figures.save_plots."""

from __future__ import annotations

import numpy as np
import pytest

from napari_polarseg.engine import Pipeline, PolarsegError, SegmentParams
from napari_polarseg.engine.analysis import plots
from napari_polarseg.engine.features import harmonics
from napari_polarseg.engine.features.harmonics import coefficient_index, degree_order
from napari_polarseg.engine.synthetic.scenes import make_scene


@pytest.fixture(scope="module")
def scene():
    return make_scene("leaves", shape=(60, 70), seed=0)


@pytest.fixture(scope="module")
def result(scene):
    params = SegmentParams(window=10, degree=5, n_segments=3)
    return Pipeline(scene.stack, np.deg2rad(scene.angles_deg), params).run()


def test_scatter_colours_are_the_labels_at_the_sampled_pixels(result):
    data = plots.scatter_data(result, max_points=500, seed=3)
    assert len(data) == 500
    np.testing.assert_array_equal(data.labels, result.labels[data.rows, data.cols])
    np.testing.assert_array_equal(data.intensity, result.intensity[data.rows, data.cols])
    np.testing.assert_array_equal(data.dop, result.dop[data.rows, data.cols])
    np.testing.assert_array_equal(data.phase, result.phase[data.rows, data.cols])
    flat = np.ravel_multi_index((data.rows, data.cols), result.labels.shape)
    assert np.unique(flat).size == 500  # without replacement
    again = plots.scatter_data(result, max_points=500, seed=3)
    np.testing.assert_array_equal(again.rows, data.rows)  # seeded


def test_scatter_takes_every_pixel_when_few_and_any_labels(result, scene):
    h, w = result.labels.shape
    data = plots.scatter_data(result, max_points=10**6)
    assert len(data) == h * w == data.n_pixels
    truth = np.asarray(scene.labels)
    other = plots.scatter_data(result, max_points=200, labels=truth)
    np.testing.assert_array_equal(other.labels, truth[other.rows, other.cols])
    with pytest.raises(PolarsegError):
        plots.scatter_data(result, labels=truth[:-1])


def test_explained_variance_matches_the_pca(result):
    ev = plots.explained_variance(result)
    np.testing.assert_allclose(ev.ratio, result.explained_variance_ratio)
    np.testing.assert_allclose(ev.cumulative, np.cumsum(result.explained_variance_ratio))
    assert ev.cumulative[-1] == pytest.approx(float(np.sum(result.explained_variance_ratio)))
    assert ev.cumulative[-1] <= 1 + 1e-12
    assert ev.cumulative[-1] >= result.params.variance - 1e-12


def test_coefficient_maps_are_the_coefficients(result):
    maps = plots.coefficient_maps(result)
    assert maps.maps.shape == (6, *result.block_labels.shape)
    ls, ms = degree_order(result.params.degree)
    for k, (l, m) in enumerate(maps.pairs):  # noqa: E741
        idx = l * l + l + m
        assert idx == coefficient_index(l, m) and (ls[idx], ms[idx]) == (l, m)
        np.testing.assert_array_equal(maps.maps[k], result.coefficients[..., idx])
    with pytest.raises(PolarsegError):
        plots.coefficient_maps(result, [(result.params.degree + 1, 0)])


def test_component_maps_on_blocks_and_pixels(result):
    comp = plots.component_maps(result, n=3)
    grid = result.block_labels.shape
    assert comp.blocks.shape == (3, *grid)
    assert comp.pixels.shape == (3, *result.labels.shape)
    for i in range(3):
        np.testing.assert_array_equal(comp.blocks[i].ravel(), result.features[:, i])
    w = result.params.window
    np.testing.assert_array_equal(comp.pixels[1, 3 * w + 2, 4 * w + 7], comp.blocks[1, 3, 4])
    # remainder pixels take the nearest block
    assert comp.pixels[0, -1, -1] == comp.blocks[0, -1, -1]
    many = plots.component_maps(result, n=500)
    assert many.blocks.shape[0] == result.features.shape[1]


def test_histograms_share_bins_and_higher_degree_fits_closer(result):
    hist = plots.result_histograms(result, degrees=(4, 12, 20))
    n = result.intensity.size
    assert hist.n_pixels == n and hist.sampled_blocks is None
    # the bins span the curves' robust ranges; the pixels beyond are counted apart
    assert hist.original.sum() + hist.outside_original == n
    assert 0 < hist.outside_original < 0.02 * n
    for d in (4, 12, 20):
        assert hist.reconstructed[d].sum() + hist.outside[d] == n
        assert hist.reconstructed[d].shape == hist.original.shape
    assert hist.edges.size == hist.original.size + 1
    assert hist.l1_distance(20) < hist.l1_distance(4)
    assert hist.mean_error[20] < hist.mean_error[4]


def test_sampled_histograms_reconstruct_the_sampled_blocks_as_in_the_image(result):
    w = result.params.window
    nby, nbx = result.block_labels.shape
    arrays = [result.intensity, result.zenith, result.azimuth]
    (I, zen, azi), k = plots.sample_blocks(arrays, w, max_blocks=7, seed=3)
    assert k == 7 and I.shape == (w, 7 * w)
    full = harmonics.reconstruct_intensity(*arrays, w, 6, ridge=result.params.ridge)
    strip = harmonics.reconstruct_intensity(I, zen, azi, w, 6, ridge=result.params.ridge)
    pick = np.sort(np.random.default_rng(3).choice(nby * nbx, 7, replace=False))
    for j, b in enumerate(pick):
        r, c = divmod(int(b), nbx)
        block = (slice(r * w, (r + 1) * w), slice(c * w, (c + 1) * w))
        np.testing.assert_array_equal(I[:, j * w : (j + 1) * w], result.intensity[block])
        np.testing.assert_allclose(strip[:, j * w : (j + 1) * w], full[block], atol=1e-9)
    hist = plots.result_histograms(result, (4,), max_blocks=7)
    assert hist.sampled_blocks == 7 and hist.n_pixels == 7 * w * w
    assert plots.sample_blocks(arrays, w, max_blocks=nby * nbx)[1] is None  # all kept


def test_error_table_decreases_with_degree(result):
    degrees = [0, 2, 4, 8, 12]
    table = plots.result_error_table(result, windows=[8, 10], degrees=degrees)
    assert table.errors.shape == (2, 5)
    assert np.all(np.diff(table.errors[0]) < 0)
    # the cell of the result's own (w, L) is the result's mean reconstruction error
    own = plots.result_error_table(result, [result.params.window], [result.params.degree])
    assert own.errors[0, 0] == pytest.approx(result.mean_reconstruction_error)


def test_save_plots_writes_non_empty_pngs(result, tmp_path):
    from napari_polarseg.outputs import PLOT_FILES
    from napari_polarseg.outputs.figures import save_plots

    paths = save_plots(result, tmp_path / "plots", degrees=(2, 6), windows=[10], dpi=50)
    assert set(paths) == set(PLOT_FILES)
    for path in paths.values():
        data = path.read_bytes()
        assert len(data) > 1000 and data[:8] == b"\x89PNG\r\n\x1a\n"
    assert sorted(p.name for p in (tmp_path / "plots").iterdir()) == sorted(PLOT_FILES)


def test_figures_hold_the_data(result):
    from napari_polarseg.outputs import figures

    data = plots.scatter_data(result, max_points=300)
    fig = figures.scatter_figure(data, "both")
    assert len(fig.axes) == 2
    assert all(len(ax.collections[0].get_offsets()) == 300 for ax in fig.axes)
    values = np.unique(data.labels)
    legend = [t.get_text() for t in fig.axes[0].get_legend().get_texts()]
    assert legend == [f"segment {v}" for v in values]  # as labels.tif numbers them
    fig = figures.scatter_figure(data, "dop", first_label=1)  # as the segments layer
    legend = [t.get_text() for t in fig.axes[0].get_legend().get_texts()]
    assert legend == [f"segment {v + 1}" for v in values]
    ev = plots.explained_variance(result)
    fig = figures.explained_variance_figure(ev, theme=figures.DARK)
    assert len(fig.axes[0].patches) == ev.ratio.size


def test_feature_importances_keep_the_largest_in_order():
    from napari_polarseg.outputs import figures

    values = {"a@1": 0.1, "b@2": 0.4, "c@4": 0.05, "d@8": 0.3, "e@16": 0.15}
    data = plots.feature_importances(values, top=3)
    assert data.names == ["b@2", "d@8", "e@16"]
    np.testing.assert_allclose(data.values, [0.4, 0.3, 0.15])
    assert data.n_features == 5 and data.shown_share == pytest.approx(0.85)
    assert plots.feature_importances(values, top=50).names == sorted(values, key=values.get)[::-1]
    assert plots.feature_importances({}).names == []
    with pytest.raises(PolarsegError, match="top must be >= 1"):
        plots.feature_importances(values, top=0)

    fig = figures.importances_figure(data, theme=figures.DARK)
    (ax,) = fig.axes
    assert [t.get_text() for t in ax.get_yticklabels()] == data.names  # largest on top
    np.testing.assert_allclose([p.get_width() for p in ax.patches], data.values)
    # the figure's title (centred on the figure: it fits a narrow dock, issue 25)
    assert " ".join(fig._suptitle.get_text().split()) == (
        "top 3 of 5 features (85% of the importance)"
    )
