"""Figures a paper can use: smooth references, readable kappa ticks, the designed
curve on top, missing bounds marked, no fake rho = 1 points, no white band in contours."""

from __future__ import annotations

import itertools

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402

from sosalgo.report import grid_figure, rate_figure  # noqa: E402
from sosalgo.spec import load_spec  # noqa: E402
from sosalgo.spec.references import reference_curves  # noqa: E402

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


def _drawn_labels(ax) -> set[str]:
    return {ln.get_label() for ln in ax.lines if not ln.get_label().startswith("_")
            and len(ln.get_xdata())}


def _legend_labels(ax) -> set[str]:
    return {t.get_text() for t in ax.get_legend().get_texts()}


def test_log_kappa_axis_labels_one_two_five_as_plain_numbers():
    fig = rate_figure("t", [1.5, 10.0, 1000.0], {"rate": [0.3, 0.8, 0.99]}, {})
    ax = fig.axes[0]
    fig.canvas.draw()
    lo, hi = ax.get_xlim()
    shown = [t.get_text() for t in ax.get_xticklabels()
             if t.get_text() and lo <= t.get_position()[0] <= hi]
    assert shown == ["2", "5", "10", "20", "50", "100", "200", "500", "1000"]
    assert not _labels_overlap(fig, ax)


def test_legend_lists_exactly_what_is_drawn():
    k = [2.0, 10.0, 100.0]
    fig = rate_figure("t", k, {"designed": [0.3, 0.8, 0.95], "bound": [None] * 3},
                      {"ref": [0.5, 0.9, 0.99], "empty ref": [None] * 3})
    ax = fig.axes[0]
    assert _legend_labels(ax) == _drawn_labels(ax) == {"designed", "bound: missing", "ref"}
    marks = [ln for ln in ax.lines if ln.get_label() == "bound: missing"][0]
    assert list(marks.get_xdata()) == k  # a series without values: marks at every kappa


def _captured_design_figure(monkeypatch, tmp_path, bounds):
    """The figure ``design_figure`` would write, for documents with these lower bounds."""
    import sosalgo.report as report
    from sosalgo.certificates import get_family
    from sosalgo.report.design import design_figure

    figs = []
    monkeypatch.setattr(report, "save_figure", lambda fig, stem: figs.append(fig) or [])
    spec = load_spec(SPECS / "gradient.yaml")
    kappas = [2.0, 10.0, 100.0, 1000.0][:len(bounds)]
    docs = [{"kappa": k, "rho_certified": (k - 1) / (k + 1), "lower_bound": b,
             "rho_at_values": 1 - 1 / k} for k, b in zip(kappas, bounds, strict=True)]
    design_figure(spec, ["h"], [], docs, tmp_path / "d", get_family("theorem1"),
                  "dual certificates")
    return figs[0].axes[0]


def test_design_figure_without_a_bound_says_so(monkeypatch, tmp_path):
    ax = _captured_design_figure(monkeypatch, tmp_path, [None, None, None])
    assert "no lower bound" in ax.get_title() and "dual certificates" not in ax.get_title()
    assert not any("lower bound" in s for s in _legend_labels(ax))
    assert _legend_labels(ax) == _drawn_labels(ax)


def test_design_figure_marks_missing_and_zero_bounds(monkeypatch, tmp_path):
    ax = _captured_design_figure(monkeypatch, tmp_path, [0.3, 0.0, None, 0.99])
    assert "bound: dual certificates" in ax.get_title()
    lines = {ln.get_label(): ln for ln in ax.lines}
    bound = np.asarray(lines["lower bound (proven)"].get_ydata(), dtype=float)
    assert np.isfinite(bound).tolist() == [True, False, False, True]  # 0 proves nothing
    assert list(lines["lower bound (proven): missing"].get_xdata()) == [10.0, 100.0]
    assert _legend_labels(ax) == _drawn_labels(ax)


def test_one_kappa_gives_no_figure_for_any_family(tmp_path):
    from sosalgo.certificates import get_family
    from sosalgo.report.analysis import analysis_figure, families_figure

    spec = load_spec(SPECS / "nesterov.yaml")
    row = {"kappa": 10.0, "rho": 0.82, "certified": True,
           "references": {name: 0.5 for name in spec.references}}
    for fam in ("theorem1", "interpolation"):
        assert families_figure(spec, [(get_family(fam), tmp_path, [row])], tmp_path / "f") == []
    assert analysis_figure(spec, [row], tmp_path / "a") == []
    assert list(tmp_path.iterdir()) == []


def test_contour_labels_are_few_and_spread():
    h = np.linspace(0.0, 0.2, 40)
    b = np.linspace(0.0, 1.0, 40)
    H, B = np.meshgrid(h, b, indexing="ij")
    rho = 0.6 + 2.0 * (H - 0.15) ** 2 + 0.3 * (B - 0.8) ** 2  # minimum near a corner
    fig = grid_figure("t", ["h", "beta"], [h, b], rho)
    ax = fig.axes[0]
    fig.canvas.draw()
    to_axes = ax.transAxes.inverted()
    pos = np.array([to_axes.transform(ax.transData.transform(t.get_position()))
                    for t in ax.texts])
    assert 2 <= len(pos) <= 6
    dist = [np.hypot(*(p - q)) for p, q in itertools.combinations(pos, 2)]
    assert min(dist) > 0.12  # no two labels on top of each other
    assert np.ptp(pos[:, 0]) > 0.3 or np.ptp(pos[:, 1]) > 0.3  # not all in one corner


def test_fig4_curve_without_values_is_only_marked_missing():
    from sosalgo.report.fig4 import _draw_rates

    fig, ax = plt.subplots()
    k = np.array([2.0, 10.0, 100.0])
    data = {"designed (interpolation)": [None] * 3, "designed (Theorem 1)": [0.3, 0.8, 0.95],
            "Nesterov's tuning (interpolation)": [0.4, 0.8, None],
            "Nesterov's tuning (Theorem 1)": [0.4, 0.85, 0.96]}
    _draw_rates(ax, k, np.geomspace(2, 100, 50), data)
    labels = _legend_labels(ax)
    assert "designed (interpolation)" not in labels
    assert {"designed (interpolation): missing",
            "Nesterov's tuning (interpolation): missing"} <= labels
    assert labels == _drawn_labels(ax)
