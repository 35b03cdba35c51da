"""Progress on stderr (a terminal and plain logs), a tidy output folder, figure details.

- progress: a forced terminal gets rich's live bar; a log gets plain lines per finished
  row and per phase, also the phases of tasks running in pool workers; ``verify`` and
  ``design`` say what they are doing;
- outputs: after analyze, design, pep, verify and pareto no lock file is left, nothing
  hash-named lies beside the results (kept-aside files are in ``kept/``), and every
  certificate file is named after the spec of the document verified;
- figures: reference curves are the closed forms on a fine kappa grid, two families give
  two rate figures, log-axis tick labels are plain decimals.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from sosalgo.spec import load_spec, read_spec_text

ROOT = Path(__file__).resolve().parents[1]
SPECS = ROOT / "specs"
GRADIENT = SPECS / "gradient.yaml"
ENV = {**os.environ, "PYTHONPATH": str(ROOT)}
HASHED = re.compile(r"-[0-9a-f]{8}(\.csv\.settings\.json|\.csv|\.png|\.pdf|\.json)$")


def _cli(*args: object, env: dict | None = None) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "sosalgo.cli", *map(str, args)],
                          capture_output=True, text=True, env=env or ENV, timeout=600)


# --------------------------------------------------------------------------- progress
def test_a_forced_terminal_gets_the_live_bar(monkeypatch, capsys):
    from sosalgo.batch.executor import Progress, note
    from sosalgo.kernel.phases import show_phase

    monkeypatch.setenv("TTY_COMPATIBLE", "1")  # rich's switch: draw as on a terminal
    monkeypatch.setenv("COLUMNS", "160")  # wide enough for the whole phase
    bar = Progress(3, "demo run")
    assert bar.live is not None
    show_phase("building the model", "budget 4 s")
    note("a message above the bar")
    bar.update(3)
    bar.close()
    err = capsys.readouterr().err
    assert "demo run" in err and "3/3" in err and "a message above the bar" in err
    assert "building the model (0:00) budget 4 s" in err


def test_a_narrow_terminal_cuts_the_phase_not_the_count(monkeypatch, capsys):
    from sosalgo.batch.executor import Progress
    from sosalgo.kernel.phases import show_phase

    monkeypatch.setenv("TTY_COMPATIBLE", "1")
    monkeypatch.setenv("COLUMNS", "80")
    bar = Progress(12, "design three-parameter")
    show_phase("bound", "123 boxes proven, 456 open, below 0.812817, budget 40 s " * 3)
    bar.update(5)
    bar.live.refresh()
    bar.close()
    err = re.sub(r"\x1b\[[0-9;?]*[a-zA-Z]", "", capsys.readouterr().err)
    assert "design three-parameter" in err and "5/12" in err and "ETA" in err, err


def test_plain_mode_says_rows_and_phases(monkeypatch, capsys):
    from sosalgo.batch.executor import Progress
    from sosalgo.kernel.phases import show_phase

    monkeypatch.setenv("TTY_COMPATIBLE", "0")
    bar = Progress(2, "demo run")
    show_phase("grid", "3/10 points")
    bar.update(1)
    bar.update(1)
    bar.close()
    lines = capsys.readouterr().err.splitlines()
    assert lines[0] == "demo run: 0/2 rows"
    assert "demo run | grid 3/10 points" in lines
    assert lines[-1].startswith("demo run: 2/2 rows")  # the last row always says so


def test_phases_of_tasks_in_pool_workers_reach_the_log(tmp_path, monkeypatch, capsys):
    """The workers' phases travel to the bar of the process running the pool, labelled
    by their kappa (every phase is said at once here: no minimum duration)."""
    import sosalgo.batch.executor as executor
    from sosalgo.batch.sweeps import run_analysis_sweep

    monkeypatch.setenv("TTY_COMPATIBLE", "0")
    monkeypatch.setattr(executor, "PLAIN_SECONDS", 0.0)
    spec, text = load_spec(GRADIENT), read_spec_text(GRADIENT)
    kappas = [2.0, 3.0, 5.0, 10.0, 20.0, 50.0, 100.0, 200.0]
    run_analysis_sweep(spec, text, kappas, tmp_path / "g.csv", 1e-4, workers=2)
    err = capsys.readouterr().err
    assert re.search(r"\| kappa \d+: (running|witnessed lower bound)", err), err
    assert "8/8 rows" in err


def test_verify_says_its_phases(tmp_path):
    env = {**ENV, "TTY_COMPATIBLE": "0"}
    res = _cli("analyze", GRADIENT, "--kappa", "2", "--kappa", "4", "--certificate",
               "theorem1", "--out", tmp_path, "--json", "--quiet", "--no-plot", env=env)
    assert res.returncode == 0, res.stderr
    doc = tmp_path / "a.json"
    doc.write_text(res.stdout)
    res = _cli("verify", doc, "--out", tmp_path, env=env)
    assert res.returncode == 0, res.stderr
    assert f"verify {doc}: 0/2 rows" in res.stderr
    assert f"verify {doc} | checking row 1 of 2" in res.stderr
    assert f"verify {doc} | claims" in res.stderr


def test_a_design_sweep_says_each_designs_phases_with_their_budgets(tmp_path, monkeypatch,
                                                                     capsys):
    import sosalgo.batch.executor as executor
    from sosalgo.runs import design_run

    monkeypatch.setenv("TTY_COMPATIBLE", "0")
    monkeypatch.setattr(executor, "PLAIN_SECONDS", 0.0)  # every phase, however short
    design_run(GRADIENT, [2.0, 4.0], tmp_path, time_limit=4, workers=1)
    err = capsys.readouterr().err
    for kappa in (2, 4):
        for phase in ("model building budget", "spec values budget", "bound"):
            assert f"design gradient | kappa {kappa}: {phase}" in err, err


# --------------------------------------------------------------------------- outputs
def _stray(out: Path) -> list[str]:
    """Files that should not be there: lock files anywhere, hash-named files outside
    ``kept/``, temporary files."""
    bad = []
    for p in out.rglob("*"):
        rel = p.relative_to(out)
        if p.name.endswith(".lock") or p.name.endswith(".tmp"):
            bad.append(str(rel))
        elif HASHED.search(p.name) and rel.parts[0] not in ("kept", "certificates"):
            bad.append(str(rel))
    return bad


@pytest.mark.deep
def test_commands_leave_a_tidy_output_folder(tmp_path):
    out = tmp_path / "out"
    runs = [
        ("analyze", GRADIENT, "--kappa", "2", "--kappa", "4"),
        ("analyze", GRADIENT, "--kappa", "2", "--kappa", "5"),  # other settings: kept aside
        ("design", GRADIENT, "--kappa", "4", "--time-limit", "5"),
        ("pep", GRADIENT, "--kappa", "4", "--steps", "2"),
    ]
    for args in runs:
        res = _cli(*args, "--out", out, "--quiet")
        assert res.returncode == 0, (args, res.stderr)
    assert list((out / "kept").glob("gradient-analysis-*.csv"))
    front = _cli("pareto", SPECS / "nesterov.yaml", "--kappa", "10", "--points", "2",
                 "--time-limit", "8", "--out", out, "--json", "--quiet", "--no-plot")
    assert front.returncode == 0, front.stderr
    doc = tmp_path / "front.json"
    doc.write_text(front.stdout)
    res = _cli("verify", doc, "--out", out)
    assert res.returncode in (0, 3), res.stderr
    assert _stray(out) == []
    certs = [p.name for p in (out / "certificates").iterdir()]
    assert certs and all(n.startswith("nesterov-") for n in certs), certs  # its own spec
    assert any(n.startswith("nesterov-tuning-triple-momentum-") for n in certs), certs


# --------------------------------------------------------------------------- figures
def test_reference_curves_are_the_closed_forms_on_a_fine_grid(tmp_path, monkeypatch):
    """Comparing families: every reference is drawn on many more kappas than computed,
    at the closed form's values (1 - 1/kappa for gradient.yaml, 1 - 1/sqrt(kappa))."""
    import sosalgo.report.analysis as rep
    from sosalgo.runs import analyze_run

    drawn = {}

    def capture(title, kappa, series, references, stem, **kw):
        drawn.update(kappa=kappa, curves=kw["reference_curves"])
        return []

    monkeypatch.setattr(rep, "plot_rates", capture)
    analyze_run(GRADIENT, [2.0, 5.0, 20.0], tmp_path, certificate="theorem1,interpolation",
                progress=False, workers=1)
    grid, curves = drawn["curves"]
    grid = np.asarray(grid)
    assert len(grid) >= 100 > len(drawn["kappa"])
    assert np.allclose(curves["1 - 1/kappa"], 1 - 1 / grid)
    assert np.allclose(curves["1 - 1/sqrt(kappa)"], 1 - 1 / np.sqrt(grid))


def test_two_families_give_two_rate_figures(tmp_path):
    from sosalgo.runs import analyze_run

    for fam in (None, "theorem1"):
        analyze_run(GRADIENT, [2.0, 4.0], tmp_path, certificate=fam, progress=False,
                    workers=1)
    assert sorted(p.name for p in tmp_path.glob("gradient-rate*.png")) == [
        "gradient-rate-theorem1.png", "gradient-rate.png"]


def _tick_labels(axis) -> list[str]:
    axis.figure.canvas.draw()
    lo, hi = sorted(axis.get_view_interval())
    return [t.get_text() for t in axis.get_ticklabels()
            if t.get_text() and lo <= t.get_position()[axis is axis.axes.yaxis] <= hi]


def test_pareto_noise_axis_is_labelled_in_plain_decimals():
    from sosalgo.report import pyplot
    from sosalgo.report.pareto import pareto_plot

    points = [{"index": i, "rho": r, "noise": g}
              for i, (r, g) in enumerate([(0.6, 0.55), (0.7, 0.32), (0.8, 0.21), (0.9, 0.15)])]
    doc = {"spec": "demo", "kappa": 10.0, "family": "interpolation", "floor": 0.68,
           "front": points, "points": points,
           "tunings": [{"kind": "tuning", "name": "Nesterov", "rho": 0.82, "noise": 0.4}]}
    fig = pareto_plot(doc)
    labels = _tick_labels(fig.axes[0].yaxis)
    pyplot().close(fig)
    assert len(labels) >= 2, labels
    for text in labels:
        assert re.fullmatch(r"\d+(\.\d+)?", text), labels  # 0.2, 0.5: no 2x10^-1
