"""Input limits: expression size, matrix magnitudes and the fixed-point check, a full disk,
huge grids, a scheduler address that is not a Dask scheduler, pipes and FIFOs as spec paths,
and hostile specs and options through every command: one line, exit 2, never a hang."""

from __future__ import annotations

import csv
import errno
import http.server
import math
import os
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest
import yaml
from click.testing import CliRunner
from hypothesis import given, settings
from hypothesis import strategies as st

from sosalgo.cli import cli
from sosalgo.errors import InputError
from sosalgo.kernel.expr.tree import MAX_DEGREE, MAX_EXPONENT, ExprError, parse_tree
from sosalgo.model import ModelError, bind
from sosalgo.oracles import consistent_solution
from sosalgo.spec import SpecError, load_spec, spec_from_text

from .conftest import SPECS

ROOT = Path(__file__).resolve().parents[1]
NESTEROV = SPECS / "nesterov.yaml"
GRADIENT = SPECS / "gradient.yaml"
PROX_GRADIENT = SPECS / "proximal-gradient.yaml"
ENV = {**os.environ, "PYTHONPATH": str(ROOT)}


def run(args, **kw):
    return CliRunner().invoke(cli, [str(a) for a in args], **kw)


def one_line_exit_2(res, *words):
    assert res.exit_code == 2, res.output
    assert res.stderr.count("\n") == 1 and "Traceback" not in res.stderr, res.stderr
    for w in words:
        assert w in res.stderr, res.stderr


def nesterov_with(**changes) -> str:
    data = yaml.safe_load(NESTEROV.read_text())
    for key, val in changes.items():
        if key == "params":
            data["parameters"].update(val)
        else:
            data["matrices"][key] = val
    return yaml.safe_dump(data)


# --------------------------------------------------------------------- expression bounds

NESTED_POWER = "-h - 1e-9*((((h*L/2)**64)**64)**64)**64"


def test_nested_powers_are_refused_naming_the_field():
    with pytest.raises(SpecError, match=r"matrices\.B\[1\]\[0\]: nested powers"):
        spec_from_text(nesterov_with(B=[[0], [NESTED_POWER]]), "x.yaml")


@pytest.mark.parametrize("command", [["lmi"], ["design", "--kappa", "10", "--time-limit", "10"],
                                     ["pep", "--kappa", "10"], ["analyze", "--verify"]])
def test_nested_powers_are_one_line_for_every_command(tmp_path, command):
    spec = tmp_path / "pow.yaml"
    spec.write_text(nesterov_with(B=[[0], [NESTED_POWER]]))
    extra = [] if command == ["lmi"] else ["--out", tmp_path / "o", "--quiet"]
    res = run([command[0], spec, *command[1:], *extra])
    one_line_exit_2(res, "pow.yaml", "matrices.B[1][0]", "nested powers")
    assert not (tmp_path / "o").exists()


def test_a_chain_of_thirty_squares_is_refused():
    text = "h"
    for _ in range(30):
        text = f"({text})**2"
    with pytest.raises(ExprError, match="nested powers"):
        parse_tree(text, ["h"])
    # the same chain through tied parameters: each one is a harmless square
    params = {"q0": "h", **{f"q{i + 1}": f"q{i}*q{i}" for i in range(30)}}
    with pytest.raises(SpecError, match=r"parameters\.q\d+: degree \d+ exceeds"):
        spec_from_text(nesterov_with(params=params, B=[[0], ["-h - 1e-9*q30"]]), "x.yaml")


def test_a_tree_doubling_through_tied_parameters_is_refused():
    params = {"q0": "h", **{f"q{i + 1}": f"q{i} + sqrt(q{i})" for i in range(30)}}
    with pytest.raises(SpecError, match=r"parameters\.q\d+: \d+ operations exceed"):
        spec_from_text(nesterov_with(params=params, B=[[0], ["-h - 1e-9*q30"]]), "x.yaml")


def test_deep_nesting_through_tied_parameters_is_refused():
    params = {"q0": "h", **{f"q{i + 1}": f"sqrt(sqrt(sqrt(q{i} + 1) + 1) + 1)"
                            for i in range(30)}}
    with pytest.raises(SpecError, match=r"nesting depth \d+ exceeds"):
        spec_from_text(nesterov_with(params=params, B=[[0], ["-h - 1e-9*q30"]]), "x.yaml")


def test_shipped_specs_are_well_inside_the_bounds():
    from sosalgo.kernel.expr.tree import measure

    for path in sorted(SPECS.glob("*.yaml")):
        spec = load_spec(path)
        for rows in spec.matrices.values():
            for e in (e for row in rows for e in row):
                assert measure(e).degree <= MAX_DEGREE / 4, (path, e)


@st.composite
def nested_powers(draw):
    """``((base)**e1)**e2 ...`` and the product of the |exponents| that are at least 1."""
    exps = draw(st.lists(st.sampled_from([-3, -2, 0.5, 1, 2, 3, 4, 8, 16]), min_size=1,
                         max_size=6))
    base = draw(st.sampled_from(["h", "1.0001", "(1 + h)", "kappa"]))
    text, product = base, 1.0
    for e in exps:
        text = f"({text})**({e})"
        product *= max(1.0, abs(e))
    return text, product, base


@settings(max_examples=200, deadline=None, derandomize=True, database=None)
@given(nested_powers())
def test_nested_exponents_multiply(case):
    text, product, base = case
    names = ["h", "kappa"]
    degree = product if base != "1.0001" else 0
    if product > MAX_EXPONENT or degree > MAX_DEGREE:
        with pytest.raises(ExprError):
            parse_tree(text, names)
    else:
        parse_tree(text, names)


@st.composite
def polynomials(draw):
    """Random products, sums and integer powers of h and beta (small, so sympy is fast)."""
    leaves = st.sampled_from(["h", "beta", "2", "(1 + h)", "(beta - h)"])
    expr = st.recursive(leaves, lambda inner: st.one_of(
        st.tuples(inner, inner).map(lambda t: f"({t[0]})*({t[1]})"),
        st.tuples(inner, inner).map(lambda t: f"({t[0]}) + ({t[1]})"),
        st.tuples(inner, st.integers(1, 5)).map(lambda t: f"({t[0]})**{t[1]}")),
        max_leaves=6)
    return draw(expr)


@settings(max_examples=150, deadline=None, derandomize=True, database=None)
@given(polynomials())
def test_accepted_expressions_have_the_degree_bound(text):
    """An accepted expression expands (sympy, independently) to degree <= MAX_DEGREE: the
    bound over-approximates the true degree, never under."""
    import sympy as sp

    try:
        parse_tree(text, ["h", "beta"])
    except ExprError as exc:
        assert "degree" in str(exc) or "nested powers" in str(exc)
        return
    h, beta = sp.symbols("h beta")
    poly = sp.Poly(sp.sympify(text, locals={"h": h, "beta": beta}), h, beta)
    assert poly.total_degree() <= MAX_DEGREE


# --------------------------------------------------------------- magnitudes, fixed point


@pytest.mark.parametrize("d_entry, where", [
    ("[[0, 0], [-h, -1e200]]", "matrices"),  # a huge entry
    ("[[0, 0], [1e200, -h]]", "matrices"),
    ("[[0, 0], [-h, -1e-200]]", "matrices"),
    ("[[0, 0], [-h, -1e100]]", "matrices"),  # no fixed point: D S != 0
])
def test_huge_and_tiny_entries_are_refused(tmp_path, d_entry, where):
    spec = tmp_path / "pg.yaml"
    spec.write_text(PROX_GRADIENT.read_text().replace("D: [[0, 0], [-h, -h]]",
                                                      f"D: {d_entry}"))
    res = run(["pep", spec, "--kappa", "10", "--steps", "2", "--out", tmp_path / "o",
               "--quiet"])
    one_line_exit_2(res, where)
    assert not (tmp_path / "o").exists()


def _system(rng, n, k, consistent):
    """A system with a known solution (rows scaled by huge and tiny factors), or one whose
    right-hand side has one entry moved by 1e-3 relative."""
    lhs = rng.standard_normal((n + 3, n))
    X = rng.standard_normal((n, k))
    rhs = lhs @ X
    if not consistent:
        i = rng.integers(n + 3)
        rhs[i, 0] += 1e-3 * (1 + abs(rhs[i, 0]))
    scale = 10.0 ** rng.uniform(-150, 150, n + 3)
    return lhs * scale[:, None], rhs * scale[:, None]


@pytest.mark.parametrize("seed", range(20))
def test_consistency_check_is_scale_free(seed):
    rng = np.random.default_rng(seed)
    n, k = int(rng.integers(1, 8)), int(rng.integers(1, 4))
    lhs, rhs = _system(rng, n, k, consistent=True)
    X = consistent_solution(lhs, rhs)
    assert X is not None
    lhs, rhs = _system(rng, n, k, consistent=False)
    assert consistent_solution(lhs, rhs) is None


def test_a_huge_parameter_value_is_refused_at_bind():
    spec = load_spec(NESTEROV)
    with pytest.raises(ModelError, match=r"matrices\.B\[1\]\[0\]: .*magnitudes"):
        bind(spec, 10, {"h": 1e306})


def test_tiny_units_stay_usable():
    """m = 1e-300 (entries near 1e300) is a method in other units, not an overflow."""
    spec = spec_from_text(GRADIENT.read_text() + "m: 1e-300\n", "tiny.yaml")
    assert np.all(np.isfinite(bind(spec, 10).B))


# --------------------------------------------------------------------------- full disk


def _disk_fills_after(monkeypatch, lines: int):
    """The CSV writer fails with ENOSPC after ``lines`` lines, leaving half a line."""
    from sosalgo.store import ResumableCSV

    original = ResumableCSV._write_line
    count = {"n": 0}

    def write_line(self, values):
        count["n"] += 1
        if count["n"] > lines:
            self._fh.write("2.5,0.9")  # a partial row, as a full disk leaves it
            self._fh.flush()
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), str(self.path))
        original(self, values)

    monkeypatch.setattr(ResumableCSV, "_write_line", write_line)


def _rows(path: Path) -> list[dict[str, str]]:
    with open(path, newline="") as fh:
        return list(csv.DictReader(fh))


@pytest.mark.parametrize("command, extra, csv_name, key", [
    ("analyze", ["--kappa", "2", "--kappa", "4", "--kappa", "8", "--kappa", "16"],
     "gradient-analysis.csv", "kappa"),
    ("pep", ["--kappa", "10", "--steps", "1..4", "--no-witness"],
     "gradient-pep-k10.csv", "steps"),
])
def test_a_full_disk_is_one_line_and_the_rows_resume(tmp_path, monkeypatch, command, extra,
                                                     csv_name, key):
    out, peer = tmp_path / "o", tmp_path / "peer"
    base = [command, GRADIENT, *extra, "--workers", "1", "--quiet", "--no-plot"]
    with monkeypatch.context() as m:
        _disk_fills_after(m, 3)  # the header and two rows
        res = run([*base, "--out", out])
    one_line_exit_2(res, "No space left on device", "rerun to resume")
    csv_path = next(out.glob("*.csv"))
    kept = _rows(csv_path)
    assert len(kept) >= 2  # the two finished rows (the half line is dropped on reading)
    res = run([*base, "--out", out])
    assert res.exit_code == 0, res.output
    res = run([*base, "--out", peer])  # an independent clean run
    assert res.exit_code == 0, res.output
    resumed, clean = _rows(out / csv_path.name), _rows(peer / csv_path.name)
    assert [r[key] for r in resumed] == [r[key] for r in clean]
    value = "rho" if command == "analyze" else "tau"
    for a, b in zip(resumed, clean, strict=True):
        assert math.isclose(float(a[value]), float(b[value]), rel_tol=1e-6)
    for r in kept[:2]:  # the rows written before the disk filled are the ones kept
        assert r in resumed


# --------------------------------------------------------------------------------- grids


def test_a_huge_grid_is_refused_before_anything_is_allocated(tmp_path, monkeypatch):
    def no_grid(*args, **kw):
        raise AssertionError("the grid was listed")

    monkeypatch.setattr("sosalgo.batch.sweeps.grid_points", no_grid)
    res = run(["grid", SPECS / "three-parameter.yaml", "--kappa", "10", "--points", "2000",
               "--out", tmp_path / "o", "--quiet"])
    one_line_exit_2(res, "--points 2000", "2000^3")
    assert not (tmp_path / "o").exists()


def test_check_grid_points():
    from sosalgo.inputs import MAX_GRID_POINTS, check_grid_points

    assert check_grid_points(1000, 2) == 1_000_000 == MAX_GRID_POINTS
    assert check_grid_points(2000, 1) == 2000
    for points, n in [(1001, 2), (101, 3), (1, 1), (2001, 1), (True, 1), (2.5, 1)]:
        with pytest.raises(InputError, match="--points"):
            check_grid_points(points, n)


# ----------------------------------------------------------------------------- scheduler


class _Quiet(http.server.SimpleHTTPRequestHandler):
    def log_message(self, *args):
        pass


@pytest.fixture
def http_server():
    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), _Quiet)
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    yield f"tcp://127.0.0.1:{server.server_address[1]}"
    server.shutdown()
    server.server_close()


@pytest.fixture
def banner_server():
    """A TCP server that greets with a line of text (as SSH does)."""
    sock = socket.create_server(("127.0.0.1", 0))
    stop = threading.Event()

    def serve():
        sock.settimeout(0.2)
        while not stop.is_set():
            try:
                conn, _ = sock.accept()
            except TimeoutError:
                continue
            with conn:
                conn.sendall(b"SSH-2.0-OpenSSH_9.6\r\n")
                time.sleep(0.2)

    thread = threading.Thread(target=serve, daemon=True)
    thread.start()
    yield f"tcp://127.0.0.1:{sock.getsockname()[1]}"
    stop.set()
    thread.join()
    sock.close()


@pytest.mark.parametrize("server", ["http_server", "banner_server"])
def test_a_scheduler_address_that_is_not_dask_is_one_line(tmp_path, monkeypatch, request,
                                                         server):
    pytest.importorskip("distributed")
    monkeypatch.setattr("sosalgo.batch.executor.HANDSHAKE_TIMEOUT", 1.0)
    address = request.getfixturevalue(server)
    res = run(["analyze", GRADIENT, "--kappa", "4", "--out", tmp_path / "o", "--quiet",
               "--scheduler", address])
    one_line_exit_2(res, "--scheduler", address)
    assert "Dask" in res.stderr
    assert not (tmp_path / "o").exists()


# ------------------------------------------------------------------- pipes and FIFOs


def test_a_fifo_without_a_writer_is_refused_not_waited_on(tmp_path, monkeypatch):
    from sosalgo.spec import loading

    fifo = tmp_path / "spec.yaml"
    os.mkfifo(fifo)
    monkeypatch.setattr(loading, "MAX_WAIT_SECONDS", 0.5)
    with pytest.raises(SpecError, match="nothing to read after 0.5 s"):
        loading.read_spec_text(fifo)


def test_a_fifo_with_a_writer_is_read(tmp_path):
    fifo = tmp_path / "spec.yaml"
    os.mkfifo(fifo)
    text = GRADIENT.read_text()

    def write():
        time.sleep(0.3)  # the reader is waiting first
        with open(fifo, "w") as fh:
            fh.write(text[:100])
            fh.flush()
            time.sleep(0.2)  # a writer that pauses mid-text
            fh.write(text[100:])

    thread = threading.Thread(target=write)
    thread.start()
    spec = load_spec(fifo)
    thread.join()
    assert spec.name == "gradient"


def test_stdin_pipe_is_a_spec(tmp_path):
    proc = subprocess.run([sys.executable, "-m", "sosalgo.cli", "analyze", "/dev/stdin",
                           "--kappa", "4", "--out", str(tmp_path), "--quiet", "--json"],
                          input=GRADIENT.read_text(), capture_output=True, text=True, env=ENV,
                          timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert '"spec": "gradient"' in proc.stdout


@pytest.mark.parametrize("path, words", [
    ("/dev/zero", "larger than"), ("/dev/null", "YAML mapping")])
def test_devices_are_one_line(tmp_path, path, words):
    one_line_exit_2(run(["lmi", path]), path, words)


# ------------------------------------------------------------- hostile specs and options

HOSTILE_PARAMS = [
    ({"h": {"value": "1e400", "range": [0, "2/L"]}}, "parameters.h.value"),
    ({"h": {"value": "nan", "range": [0, "2/L"]}}, "parameters.h.value"),
    ({"h": {"value": "1/L", "range": [0, "inf"]}}, "parameters.h.range"),
    ({"h": {"value": int("9" * 400), "range": [0, "2/L"]}}, "parameters.h.value"),
    ({"h": {"value": "exp(exp(exp(10)))", "range": [0, "2/L"]}}, "parameters.h.value"),
    ({"h": {"value": "max(" + ",".join(["1/L"] * 600) + ")", "range": [0, 1]}},
     "parameters.h.value"),
    ({"h": {"value": "１/L", "range": [0, "2/L"]}}, "parameters.h.value"),
    ({"h": {"value": "().__class__", "range": [0, "2/L"]}}, "parameters.h.value"),
    ({"ħ": {"value": "1/L", "range": [0, "2/L"]}}, "parameters.ħ"),
]


@pytest.mark.parametrize("params, where", HOSTILE_PARAMS)
def test_hostile_parameters_are_one_line(params, where):
    with pytest.raises(SpecError) as info:
        spec_from_text(nesterov_with(params=params), "x.yaml")
    assert where in str(info.value) and "\n" not in str(info.value)


HOSTILE_TEXTS = {
    "empty": "", "blank": "  \n\n", "null": "null\n", "two documents": "---\n---\n",
    "a list": "- 1\n", "deep list": "a: " + "[" * 5000 + "]" * 5000 + "\n",
    "deep mapping": "".join(" " * i + f"k{i}:\n" for i in range(3000)),
    "python tag": 'name: !!python/object/apply:os.system ["true"]\n',
    "bad timestamp": "name: !!timestamp x\n", "huge key": f"{'9' * 5000}: 1\n",
    "matrix 100x100": NESTEROV.read_text().replace(
        "A: [[0, 1], [-beta, 1 + beta]]", "A: " + str([[0] * 100] * 100)),
    "deep matrix": NESTEROV.read_text().replace(
        "A: [[0, 1], [-beta, 1 + beta]]", "A: " + "[" * 500 + "0" + "]" * 500),
    "kappa list too long": NESTEROV.read_text().replace(
        "kappa: [2, 5, 10, 20, 50, 100]", f"kappa: {list(range(2, 12003))}"),
    "m subnormal": "m: 1e-320\n" + NESTEROV.read_text(),
}


@pytest.mark.parametrize("name", HOSTILE_TEXTS)
def test_hostile_texts_are_one_line(name):
    with pytest.raises(SpecError) as info:
        spec_from_text(HOSTILE_TEXTS[name], "x.yaml")
    assert str(info.value).startswith("x.yaml") and "\n" not in str(info.value)


@pytest.mark.parametrize("args, words", [
    (["grid", NESTEROV, "--kappa", "10", "--points", "3", "--free", "h,h"], "--free"),
    (["grid", NESTEROV, "--kappa", "10", "--points", "3", "--free", ","], "--free"),
    (["analyze", NESTEROV, "--kappa", "10", "--out", "/" + "x" * 5000], "--out"),
    (["analyze", NESTEROV, "--kappa", "1e308"], "magnitudes"),
    (["pep", NESTEROV, "--kappa", "10", "--initial", "dist**64**64"], "--initial"),
])
def test_hostile_options_are_one_line(tmp_path, args, words):
    extra = [] if "--out" in args else ["--out", tmp_path / "o"]
    one_line_exit_2(run([*args, *extra, "--quiet"]), words)


def test_binary_and_non_utf8_specs_are_one_line(tmp_path):
    rng = np.random.default_rng(1)
    cases = {"binary.yaml": rng.integers(0, 256, 5000, dtype=np.uint8).tobytes(),
             "utf16.yaml": GRADIENT.read_text().encode("utf-16"),
             "latin1.yaml": "name: caf\xe9\n".encode("latin-1")}
    for name, raw in cases.items():
        path = tmp_path / name
        path.write_bytes(raw)
        one_line_exit_2(run(["lmi", path]), name)


COMMANDS = {
    "analyze": ["--kappa", "10", "--verify"],
    "design": ["--kappa", "10", "--time-limit", "5"],
    "pep": ["--kappa", "10", "--steps", "2"],
    "grid": ["--kappa", "10", "--points", "3"],
    "lmi": [],
}


@pytest.mark.deep
@pytest.mark.parametrize("command", COMMANDS)
@pytest.mark.parametrize("case", ["nested power", "tied squares", "D 1e200", "D -1e-200",
                                  "bom", "deep list"])
def test_every_command_on_hostile_specs(tmp_path, command, case):
    """Each command in its own process: exit 0, 2 or 3 with at most one error line, within a
    guard far above the normal time (the nested power used to run for minutes)."""
    texts = {
        "nested power": nesterov_with(B=[[0], [NESTED_POWER]]),
        "tied squares": nesterov_with(
            params={"q0": "h", **{f"q{i + 1}": f"q{i}*q{i}" for i in range(30)}},
            B=[[0], ["-h - 1e-9*q30"]]),
        "D 1e200": PROX_GRADIENT.read_text().replace("D: [[0, 0], [-h, -h]]",
                                                     "D: [[0, 0], [-h, -1e200]]"),
        "D -1e-200": PROX_GRADIENT.read_text().replace("D: [[0, 0], [-h, -h]]",
                                                       "D: [[0, 0], [-h, -1e-200]]"),
        "bom": "\ufeff" + GRADIENT.read_text(),
        "deep list": HOSTILE_TEXTS["deep matrix"],
    }
    spec = tmp_path / "spec.yaml"
    spec.write_text(texts[case], encoding="utf-8")
    out = [] if command == "lmi" else ["--out", str(tmp_path / "o"), "--quiet"]
    argv = [sys.executable, "-m", "sosalgo.cli", command, str(spec), *COMMANDS[command], *out]
    proc = subprocess.run(argv, capture_output=True, text=True, env=ENV, timeout=300)
    errors = [line for line in proc.stderr.splitlines() if line.startswith("error")]
    assert proc.returncode in (0, 2, 3) and "Traceback" not in proc.stderr, proc.stderr
    assert len(errors) <= 1, proc.stderr
    if case != "bom":
        assert proc.returncode == 2, proc.stderr
