"""In-process tests of the CLI's pieces: options <-> SmoothingParams, --fixed files, progress,
summary, exit paths that cannot be provoked from outside, and the parameter table of docs/cli.md."""

from __future__ import annotations

import io
import re
from pathlib import Path

import numpy as np
import pytest

import service.core
from service import cli
from service.cli.progress import ProgressDisplay, format_summary
from service.core import SmoothingParams
from service.core.progress import ProgressEvent

REPO = Path(__file__).resolve().parents[2]


def _ns(*args: str):
    return cli.build_parser().parse_args(["smooth", "in.ply", "-o", "out.ply", *args])


def _circle_obj(path: Path, n: int = 60, noise: float = 0.02) -> Path:
    rng = np.random.default_rng(0)
    t = np.linspace(0, 2 * np.pi, n, endpoint=False)
    pts = np.column_stack([np.cos(t), np.sin(t), np.zeros(n)]) + rng.normal(0, noise, (n, 3))
    lines = [f"v {x:.9f} {y:.9f} {z:.9f}" for x, y, z in pts]
    lines.append("l " + " ".join(str(i + 1) for i in range(n)) + " 1")
    path.write_text("\n".join(lines) + "\n")
    return path


def test_every_field_has_an_option_and_defaults_come_from_the_model():
    ns = _ns("--tau", "0.5")
    params = cli.params_from_args(ns)
    for name, info in SmoothingParams.model_fields.items():
        assert hasattr(ns, name), f"no CLI option for SmoothingParams.{name}"
        if name != "tau":
            assert getattr(params, name) == info.default
    assert params.tau == 0.5


def test_options_map_to_fields():
    params = cli.params_from_args(
        _ns(
            "--lam", "0.05", "--laplacian", "feature", "--weights", "cotangent",
            "--neighborhood", "knn", "--k", "8", "--fix-boundary", "--sigma-f", "0.3",
            "--sigma-h", "1e-6", "--tolerance", "1e-4", "--max-iterations", "20",
            "--preserve-volume", "--solver", "superlu", "--spectrum",
        )
    )  # fmt: skip
    assert params.model_dump() == {
        "lam": 0.05, "tau": None, "rms": None, "laplacian": "feature",
        "weights": "cotangent", "neighborhood": "knn", "k": 8, "sigma_h": 1e-6,
        "sigma_f": 0.3, "robust": "auto", "noise_weights": "auto", "outliers": "auto",
        "tolerance": 1e-4,
        "max_iterations": 20, "fix_boundary": True,
        "preserve_volume": True, "solver": "superlu", "spectrum": True,
        "search": "auto", "method": "tikhonov", "order": 2,
        "displacement": "auto", "tangential": "auto", "presmooth": 2, "junctions": "corner",
        "ends": "auto", "boundary": "auto", "max_deviation": None,
        "strict": False, "tile_points": None, "preset": None,
    }  # fmt: skip


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--tau", "0"], "--tau: must be greater than 0"),
        (["--rms", "nan"], "--rms: must be a finite number"),
        (["--lam", "abc"], "--lam: must be a valid number"),
        (["--tau", "1", "--k", "2"], "--k: must be greater than or equal to 3"),
        (["--tau", "1", "--tolerance", "1"], "--tolerance: must be less than 1"),
        (["--tau", "1", "--solver", "umfpack"], "--solver: must be 'auto', 'cholmod', "),
    ],
)
def test_pydantic_errors_become_one_line(args: list[str], message: str):
    with pytest.raises(cli.CliError) as info:
        cli.params_from_args(_ns(*args))
    assert info.value.code == 2
    assert info.value.message.startswith(message)
    assert "\n" not in info.value.message


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--rms", "1", "--laplacian", "spline"], "--laplacian: must be 'normalized', "),
        (["--tau", "1", "--no-such-option"], "unrecognized arguments: --no-such-option"),
        (["--rms", "1", "--xyz-dims", "0"], "--xyz-dims: must be at least 1"),
        (["--rms", "1", "--xyz-dims", "4"], "--xyz-dims applies to XYZ input only, not ply"),
        (["--rms", "1", "--format", "xyz"], "--output-format xyz contradicts the output file"),
        (["--rms", "1", "--output-format", "xyz"], "--output-format xyz contradicts the output"),
        (["--tau"], "argument --tau: expected one argument"),
    ],
)
def test_usage_errors_in_process(
    args: list[str], message: str, capsys: pytest.CaptureFixture[str], tmp_path: Path
):
    argv = ["smooth", str(tmp_path / "in.ply"), "-o", str(tmp_path / "out.ply"), *args]
    assert cli.main(argv) == 2
    captured = capsys.readouterr()
    assert captured.out == ""
    lines = captured.err.splitlines()
    assert len(lines) == 1 and lines[0].startswith("geosmooth: error: " + message), lines


def test_exactly_one_target_message_names_options():
    ns = _ns("--tau", "1")
    ns.lam = "0.1"  # bypass argparse's own check: the model's validator still refuses
    with pytest.raises(cli.CliError, match=r"at most one of --lam, --tau or --rms"):
        cli.params_from_args(ns)


def test_read_fixed_indices(tmp_path: Path):
    f = tmp_path / "fixed.txt"
    f.write_text("# header\n1, 2,3\n4\t5  # trailing comment\n\n6;7\n")
    assert cli.read_fixed_indices(f) == [1, 2, 3, 4, 5, 6, 7]
    f.write_text("1 2\n3 x\n")
    with pytest.raises(cli.CliError, match="line 2: 'x'") as info:
        cli.read_fixed_indices(f)
    assert info.value.code == 3
    with pytest.raises(cli.CliError) as info:
        cli.read_fixed_indices(tmp_path / "missing.txt")
    assert info.value.code == 3


def _ev(iteration: int, lam: float, phi: float) -> ProgressEvent:
    return ProgressEvent("search", iteration=iteration, lam=lam, phi=phi)


def test_progress_plain_lines_vs_terminal():
    plain = io.StringIO()
    p = ProgressDisplay(plain, tau=2.0, tty=False)
    p(_ev(1, 0.1, 3.0))
    p(_ev(2, 0.2, 2.001))
    p.finish()
    lines = plain.getvalue().splitlines()
    assert len(lines) == 2 and "\r" not in plain.getvalue()
    assert "lambda=2.0000e-01" in lines[1] and "rel.error=5.00e-04" in lines[1]

    term = io.StringIO()
    p = ProgressDisplay(term, tau=None, tty=True)
    p(_ev(1, 0.5, 0.25))
    p(_ev(2, 0.6, 0.2))
    p.finish()
    text = term.getvalue()
    assert text.count("\r") == 2 and text.endswith("\n") and text.count("\n") == 1
    assert "tau=" not in text

    quiet = io.StringIO()
    p = ProgressDisplay(quiet, tau=1.0, enabled=False, tty=True)
    p(_ev(1, 0.5, 0.25))
    p.finish()
    assert quiet.getvalue() == "" and p.calls == 1


def test_summary_paragraph():
    report = {
        "lambda": 0.0123, "phi": 0.4999, "tau": 0.5, "relative_error": 2e-4,
        "converged": True, "iterations": 5, "factorizations": 5, "n_points": 10,
        "dimension": 3, "kind": "mesh", "laplacian": "normalized", "weights": "mean-value",
        "n_fixed": 2, "rms_displacement": 0.01, "max_displacement": 0.03, "volume_scale": None,
        "timings": {"laplacian": 0.01, "total": 0.05}, "solver": "cholmod",
        "warnings": ["something to know"],
    }  # fmt: skip
    text = format_summary(report, source="a.ply", target="b.ply", wall_seconds=0.5, tolerance=1e-3)
    assert "a.ply -> b.ply" in text and "(2 fixed)" in text
    assert "lambda=1.2300e-02 after 5 iterations" in text and "converged" in text
    assert "phi=4.9990e-01 vs tau=5.0000e-01" in text and "tolerance 0.001" in text
    assert "RMS 1.000e-02, max 3.000e-02" in text and "solver cholmod" in text
    assert text.splitlines()[-1] == "  warning: something to know"


def test_help_documents_exit_codes(capsys: pytest.CaptureFixture[str]):
    assert cli.main(["--help"]) == 0
    out = capsys.readouterr().out
    for code in cli.EXIT_CODES:
        assert re.search(rf"^\s+{code}\s+\S", out, re.M), code
    assert cli.main(["smooth", "--help"]) == 0
    out = capsys.readouterr().out
    for name in SmoothingParams.model_fields:
        assert "--" + name.replace("_", "-") in out


def test_exit_status_tables_are_disjoint_and_cover_every_error_class():
    from service import exit_codes
    from service.core.errors import GeosmoothError
    from service.io.errors import FormatError

    assert set(cli.SUBMIT_EXIT_CODES) == {
        exit_codes.EXIT_UNREACHABLE,
        exit_codes.EXIT_REJECTED,
        exit_codes.EXIT_JOB_FAILED,
        exit_codes.EXIT_CANCELLED,
    }
    assert not set(cli.SUBMIT_EXIT_CODES) & set(cli.EXIT_CODES)
    assert not set(cli.SERVE_EXIT_CODES) & set(cli.SUBMIT_EXIT_CODES)
    # uvicorn's own startup failure status (3) is "input file missing" here: serve has its own
    assert 3 not in cli.SERVE_EXIT_CODES and exit_codes.EXIT_ADDRESS not in cli.EXIT_CODES

    def classes(base: type) -> list[type]:
        return [base] + [c for sub in base.__subclasses__() for c in classes(sub)]

    for cls in classes(GeosmoothError) + classes(FormatError):
        assert cls.exit_code in cli.EXIT_CODES, cls  # every typed error's status is documented


def test_internal_error_is_one_line_and_debug_shows_traceback(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str], tmp_path: Path
):
    src = _circle_obj(tmp_path / "circle.obj")

    def boom(*args: object, **kwargs: object) -> None:
        raise RuntimeError("kaboom\nsecond line")

    monkeypatch.setattr(service.core, "smooth", boom)
    monkeypatch.delenv("GEOSMOOTH_DEBUG", raising=False)
    argv = ["smooth", str(src), "-o", str(tmp_path / "o.obj"), "--tau", "0.01", "-q"]
    assert cli.main(argv) == 1
    err = capsys.readouterr().err
    assert err.splitlines() == [
        "geosmooth: error: internal error: RuntimeError: kaboom second line "
        "(set GEOSMOOTH_DEBUG=1 for the traceback)"
    ]
    monkeypatch.setenv("GEOSMOOTH_DEBUG", "1")
    assert cli.main(argv) == 1
    err = capsys.readouterr().err
    assert "Traceback" in err and err.splitlines()[-1].startswith("geosmooth: error:")


def test_parameter_this_geometry_cannot_take(capsys: pytest.CaptureFixture[str], tmp_path: Path):
    src = _circle_obj(tmp_path / "circle.obj")
    out = tmp_path / "o.obj"
    argv = ["smooth", str(src), "-o", str(out), "--rms", "0.01", "--weights", "cotangent"]
    assert cli.main(argv) == 4
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 1 and err[0].startswith("geosmooth: error: --weights: "), err
    assert "triangles" in err[0] and not out.exists()


def test_circle_round_trip_in_process(capsys: pytest.CaptureFixture[str], tmp_path: Path):
    """The whole path in-process: a closed polyline stays closed, the report is strict JSON."""
    import json

    from service.io import read_geometry

    src = _circle_obj(tmp_path / "circle.obj")
    out, rep = tmp_path / "o.json", tmp_path / "r.json"
    argv = ["smooth", str(src), "-o", str(out), "--lam", "0.5", "--report", str(rep)]
    assert cli.main(argv) == 0
    err = capsys.readouterr().err
    assert "lambda given, no search" in err
    doc = read_geometry(out)
    assert doc.source_format == "json" and len(doc.polylines) == 1 and doc.polylines[0].closed
    report = json.loads(rep.read_text(), parse_constant=lambda c: pytest.fail(c))
    assert report["tau"] is None and report["lambda"] == 0.5 and report["iterations"] == 1
    assert report["output_format"] == "json" and report["input_format"] == "obj"


def test_ctrl_c_exits_130_quietly(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str], tmp_path: Path
):
    src = _circle_obj(tmp_path / "circle.obj")

    def interrupted(geometry: object, params: object, progress=None) -> None:
        progress(ProgressEvent("search", tau=0.01, iteration=1, lam=0.1, phi=0.2))
        raise KeyboardInterrupt

    monkeypatch.setattr(service.core, "smooth", interrupted)
    out = tmp_path / "o.obj"
    assert cli.main(["smooth", str(src), "-o", str(out), "--tau", "0.01", "-q"]) == 130
    assert capsys.readouterr().err == ""
    assert not out.exists()


def test_serve_and_submit_are_lazy_and_forward_arguments(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path
):
    import json
    import socket
    import sys
    import types

    from service.cli import submit as submit_command

    calls: dict[str, object] = {}
    server = types.ModuleType("service.api.server")
    server.serve = lambda host, port, workers, data_dir, *, insecure_no_auth: calls.update(  # type: ignore[attr-defined]
        serve=(host, port, workers, data_dir, insecure_no_auth)
    )
    monkeypatch.setitem(sys.modules, "service.api.server", server)
    with socket.socket() as sock:  # a port that is free now
        sock.bind(("127.0.0.1", 0))
        port = sock.getsockname()[1]
    argv = ["serve", "--port", str(port), "--workers", "2", "--data-dir", str(tmp_path / "d")]
    assert cli.main(argv) == 0
    assert calls["serve"] == (None, port, 2, str(tmp_path / "d"), False)  # host: settings

    def remote(ns, params, out_fmt, progress):  # what would go to the server
        calls["submit"] = (ns.input, ns.server, params, out_fmt, ns.weld)
        return b"smoothed", {"history": [], "tau": None}

    monkeypatch.setattr(submit_command, "_remote", remote)
    src, out, rep = tmp_path / "in.ply", tmp_path / "o.obj", tmp_path / "r.json"
    src.write_bytes(b"ply")
    rc = cli.main([
        "submit", str(src), "--server", "http://h:1", "-o", str(out), "--rms", "0.1",
        "--laplacian", "feature", "--report", str(rep), "-q", "--weld",
    ])  # fmt: skip
    assert rc == 0
    path, url, params, fmt, weld = calls["submit"]  # type: ignore[misc]
    assert (path, url, fmt, weld) == (str(src), "http://h:1", "obj", True)
    assert params == {"rms": 0.1, "laplacian": "feature"}  # only what was given
    assert out.read_bytes() == b"smoothed"
    assert json.loads(rep.read_text()) == {"history": [], "tau": None}


def test_smooth_does_not_import_the_http_stack(tmp_path: Path):
    import subprocess
    import sys

    src = REPO / "service" / "samples" / "noisy-helix.obj"
    argv = ["smooth", str(src), "-o", str(tmp_path / "o.obj"), "--rms", "0.03", "-q"]
    code = (
        "import sys, service.cli; "
        f"rc = service.cli.main({argv!r}); "
        "print(rc, sorted(m for m in ('fastapi', 'uvicorn', 'httpx') if m in sys.modules))"
    )
    res = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=60, check=True
    )
    assert res.stdout.strip() == "0 []", res.stderr


def test_cli_docs_list_every_parameter_with_its_default():
    readme = (REPO / "docs" / "cli.md").read_text(encoding="utf-8")
    rows = [ln for ln in readme.splitlines() if ln.startswith("|")]
    for name, info in SmoothingParams.model_fields.items():
        option = "--" + name.replace("_", "-")
        first_cell = re.compile(rf"^\|\s*`{option}[` ]")
        row = next((r for r in rows if first_cell.match(r)), None)
        assert row is not None, f"docs/cli.md parameter table lacks {option}"
        default = info.default
        if default is None:
            assert "—" in row, (option, row)  # lam / tau / rms: no default
        else:
            shown = str(default).lower() if isinstance(default, bool) else str(default)
            assert f"`{shown}`" in row, (option, row)
