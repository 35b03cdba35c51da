"""Figures a paper can use (issue 9): smooth references, readable kappa ticks, the designed
curve on top, missing bounds marked, no fake rho = 1 points, no white band in contours."""

from __future__ import annotations

import itertools

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402

from sosalgo.batch.sweeps import reference_curves  # noqa: E402
from sosalgo.report import grid_figure, rate_figure  # noqa: E402
from sosalgo.spec import load_spec  # noqa: E402

from .conftest import SPECS  # noqa: E402


@pytest.fixture(autouse=True)
def _close():
    yield
    plt.close("all")


def _labels_overlap(fig, ax) -> bool:
    fig.canvas.draw()
    r = fig.canvas.get_renderer()
    boxes = [t.get_window_extent(r) for t in ax.get_xticklabels(minor=False)
             + ax.get_xticklabels(minor=True) if t.get_visible() and t.get_text()]
    x0, x1 = ax.get_window_extent(r).x0 - 5, ax.get_window_extent(r).x1 + 5
    boxes = [b for b in boxes if b.x1 >= x0 and b.x0 <= x1]
    return any(a.overlaps(b) for a, b in itertools.combinations(boxes, 2))


@pytest.mark.parametrize("span", [(100.0, 100.0001), (2.0, 3.0), (1.5, 1000.0), (50.0, 60.0)])
def test_kappa_tick_labels_never_overlap(span):
    k = list(np.linspace(*span, 4))
    fig = rate_figure("t", k, {"rate": [0.5, 0.6, 0.7, 0.8]}, {})
    ax = fig.axes[0]
    assert not _labels_overlap(fig, ax)
    assert sum(1 for t in ax.get_xticklabels() if t.get_text()) >= 2


def test_references_are_smooth_curves_on_a_fine_grid():
    spec = load_spec(SPECS / "nesterov.yaml")
    kappas = [2.0, 10.0, 100.0]
    grid, refs = reference_curves(spec, kappas)
    assert len(grid) >= 400 and set(kappas) <= set(grid)
    g = np.array(grid)
    assert np.allclose(refs["Nesterov's bound"], np.sqrt(1 - 1 / np.sqrt(g)), atol=1e-12)
    fig = rate_figure("t", kappas, {"rate": [0.5, 0.7, 0.9]},
                      {"Nesterov's bound": [None] * 3}, reference_curves=(grid, refs))
    (line,) = [ln for ln in fig.axes[0].lines if ln.get_label() == "Nesterov's bound"]
    assert len(line.get_xdata()) == len(grid)
    assert reference_curves(spec, [10.0]) is None


def test_designed_curve_is_drawn_on_top_and_missing_bounds_are_marked():
    k = [2.0, 10.0, 100.0]
    fig = rate_figure("t", k, {"designed": [0.3, 0.8, 0.95],
                               "lower bound": [0.3, None, 0.95]}, {})
    lines = {ln.get_label(): ln for ln in fig.axes[0].lines}
    assert lines["designed"].get_zorder() > lines["lower bound"].get_zorder()
    assert lines["designed"].get_marker() not in ("", "None", None)
    marked = lines["lower bound: missing"]
    assert list(marked.get_xdata()) == [10.0]


def test_one_dimensional_grid_has_no_points_at_rho_one():
    x = np.linspace(0.0, 1.0, 11)
    rho = np.where(x < 0.7, 0.5 + 0.3 * x, np.nan)
    fig = grid_figure("t", ["beta"], [x], rho, value_point=[0.3])
    ax = fig.axes[0]
    for ln in ax.lines:
        y = np.asarray(ln.get_ydata(), dtype=float)
        if y.size and ln.get_label() != "spec value":
            assert not np.any(np.isclose(y, 1.0)), ln.get_label()
    labels = [h.get_label() for h in ax.get_legend().legend_handles]
    assert "no certificate" in labels


def test_grid_contours_have_no_white_band():
    h = np.linspace(0.0, 0.2, 40)
    b = np.linspace(0.0, 1.0, 40)
    H, B = np.meshgrid(h, b, indexing="ij")
    rho = 0.6 + 0.5 * (H - 0.1) ** 2 + 0.2 * (B - 0.5) ** 2
    rho = np.where(B + 2 * H < 1.1, rho, np.nan)  # a diagonal uncertified region
    fig = grid_figure("t", ["h", "beta"], [h, b], rho)
    ax = fig.axes[0]
    ax.get_legend().remove()
    fig.canvas.draw()
    img = np.asarray(fig.canvas.buffer_rgba())[..., :3]
    bb = ax.get_window_extent()
    H_px = img.shape[0]
    crop = img[int(H_px - bb.y1) + 3:int(H_px - bb.y0) - 3, int(bb.x0) + 3:int(bb.x1) - 3]
    white = np.all(crop >= 250, axis=-1).mean()
    assert white < 0.002, white


def test_uncertified_kappas_are_not_marked_twice():
    fig = rate_figure("t", [2.0, 10.0], {"certified rate": [0.5, None]}, {},
                      uncertified=[10.0])
    labels = [ln.get_label() for ln in fig.axes[0].lines]
    assert "no certificate" in labels and "certified rate: missing" not in labels
