"""Hostile or careless inputs: each refused in one line (or warned about), never a traceback."""

import gzip
import io
import json
import os
import subprocess
import sys
import warnings

import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner

import debist
from debist.cli import app
from debist.core.errors import (
    ArgumentError,
    ArtifactError,
    OutputDirError,
    PlausibilityWarning,
    RigLogError,
    WorkflowError,
)
from debist.core.preflight import BUDGET_ENV
from debist.differentiate.tables import differentiate_tables
from debist.identify import config as identify_config
from debist.identify.config import MAX_GRID_VALUES
from debist.ingest.compressed import open_gzip
from debist.ingest.patterns import MATCH_SECONDS, search_names
from debist.ingest.stroke import check_stroke
from debist.workflow.tomltext import MAX_NESTING, check_nesting
from tests.conftest import SYNTHETIC_WORKFLOW


def invoke(*args):
    result = CliRunner().invoke(app, [str(a) for a in args])
    return result.exit_code, " ".join(result.output.split())


def deep(n, open_="[", close="]"):
    return open_ * n + close * n


# -- nesting bound of the workflow TOML -------------------------------------------------------


@pytest.mark.parametrize(
    ("line", "key"),
    [
        (f"M = {deep(500)}", "[identify] M"),
        ("extra = { a = " + "{ b = " * 499 + "1" + " }" * 500, "[identify] extra"),
        ("extra = [\n" + "[\n" * 499 + "]\n" * 500, "[identify] extra"),
    ],
)
def test_deeply_nested_workflow_value_is_refused_before_parsing(tmp_path, line, key):
    text = SYNTHETIC_WORKFLOW.format(alpha=1e-6).replace("M = 8", line)
    (tmp_path / "wf.toml").write_text(text)
    code, out = invoke("status", tmp_path / "wf.toml")
    assert code == 2
    assert "wf.toml" in out and key in out and f"{MAX_NESTING} levels" in out
    assert "Traceback" not in out and "RecursionError" not in out


def test_deeply_nested_set_value_is_refused(tmp_path):
    (tmp_path / "wf.toml").write_text(SYNTHETIC_WORKFLOW.format(alpha=1e-6))
    code, out = invoke("status", tmp_path / "wf.toml", "--set", f"identify.M={deep(500)}")
    assert code == 2
    assert "--set" in out and "identify.M" in out and f"{MAX_NESTING} levels" in out


def test_nesting_scan_counts_only_brackets_of_values():
    ok = (
        "[datasets.a]\n[[validate.published]]\n"
        f's = \'{deep(100)}\'\nm = """\n{deep(100)}\n"""\n# {deep(100)}\n'
        f"x = {deep(MAX_NESTING)}\n"
    )
    check_nesting(ok, "wf.toml")
    with pytest.raises(WorkflowError) as err:
        check_nesting(ok + f"y = {deep(MAX_NESTING + 1, '{a=', '}')}", "wf.toml")
    assert "published" in str(err.value)
    assert "line 9" in str(err.value)


# -- gzip rig logs ----------------------------------------------------------------------------


def write_gz_workflow(folder, payload):
    (folder / "rig.csv.gz").write_bytes(payload)
    text = SYNTHETIC_WORKFLOW.format(alpha=1e-6).replace('"rig.csv"', '"rig.csv.gz"')
    (folder / "wf.toml").write_text(text)
    return folder / "wf.toml"


def rig_csv_text(n=6600, amplitude=1.0):
    rows = [
        f"{2.0 * i:.1f},{amplitude * np.sin(i / 50):.6f},{i % 7 / 3:.4f},0.0000" for i in range(n)
    ]
    return "time_ms,laser,v_left,v_right\n" + "\n".join(rows) + "\n"


@pytest.mark.parametrize("keep", [0.3, 0.5, 0.9])
def test_a_gzip_log_cut_short_is_a_one_line_data_error(tmp_path, keep):
    whole = gzip.compress(rig_csv_text().encode())
    wf = write_gz_workflow(tmp_path, whole[: int(keep * len(whole))])
    code, out = invoke("run", wf, "--stages", "ingest")
    assert code == 1
    assert "rig.csv.gz" in out and "truncated" in out and "Aborted" not in out
    assert not (tmp_path / "out" / "ingest").exists()


def test_a_corrupt_gzip_stream_is_named(tmp_path):
    whole = bytearray(gzip.compress(rig_csv_text().encode()))
    whole[len(whole) // 2 : len(whole) // 2 + 64] = bytes(64)  # a block of zeros mid-stream
    wf = write_gz_workflow(tmp_path, bytes(whole))
    code, out = invoke("run", wf, "--stages", "ingest")
    assert code == 1
    assert "rig.csv.gz" in out and "corrupt" in out and "CRC" in out


def test_the_whole_gzip_log_is_read(tmp_path):
    wf = write_gz_workflow(tmp_path, gzip.compress(rig_csv_text().encode()))
    code, out = invoke("run", wf, "--stages", "ingest")
    assert code == 0, out
    assert (tmp_path / "out" / "ingest" / "estimation.parquet").is_file()


def gzip_bomb(mib):
    """``mib`` MiB of ``0\\n`` lines, gzip'd to about 1/1000 of that."""
    buf = io.BytesIO()
    with gzip.GzipFile(fileobj=buf, mode="wb") as gz:
        chunk = b"0\n" * (1 << 19)
        for _ in range(mib):
            gz.write(chunk)
    return buf.getvalue()


def test_a_gzip_bomb_is_refused_at_the_decompressed_limit(tmp_path, monkeypatch):
    monkeypatch.setenv(BUDGET_ENV, "0.12")  # 120 MB: 10 MB of text at 12 bytes per byte
    bomb = gzip_bomb(50)
    assert len(bomb) < 100_000
    wf = write_gz_workflow(tmp_path, bomb)
    code, out = invoke("run", wf, "--stages", "ingest")
    assert code == 1
    assert "rig.csv.gz" in out and "decompresses" in out and "10 MB" in out
    assert "120 MB" in out and BUDGET_ENV in out
    assert not (tmp_path / "out" / "ingest").exists()


def test_the_decompressed_limit_stops_reading_at_the_limit(tmp_path):
    (tmp_path / "bomb.gz").write_bytes(gzip_bomb(8))
    read = 0
    with (
        pytest.raises(RigLogError) as err,
        open_gzip(tmp_path / "bomb.gz", limit=2_100_000) as fh,
    ):
        while chunk := fh.read(1 << 16):
            read += len(chunk)
    assert "bomb" in str(err.value)
    assert "than 2.1 MB" in str(err.value)
    assert 2_000_000 <= read <= 2_100_000


def test_a_log_within_a_low_budget_is_read(tmp_path, monkeypatch):
    monkeypatch.setenv(BUDGET_ENV, "0.12")
    wf = write_gz_workflow(tmp_path, gzip.compress(rig_csv_text().encode()))
    code, out = invoke("run", wf, "--stages", "ingest")
    assert code == 0, out


# -- user regexes -----------------------------------------------------------------------------


def write_regex_workflow(folder, pattern, long_name):
    text = rig_csv_text(200).replace("laser", long_name, 1)
    (folder / "rig.csv").write_text(text)
    wf = SYNTHETIC_WORKFLOW.format(alpha=1e-6).replace(
        'q = { name = "laser", unit = "mm" }', f"q = {{ regex = '{pattern}', unit = \"mm\" }}"
    )
    (folder / "wf.toml").write_text(wf)
    return folder / "wf.toml"


def test_a_catastrophically_backtracking_regex_is_refused_naming_key_and_pattern(tmp_path):
    wf = write_regex_workflow(tmp_path, "^(a|aa)+$", "a" * 3000 + "!")
    code, out = invoke("run", wf, "--stages", "ingest")
    assert code == 2
    assert "rig.csv" in out and "`q` = regex '^(a|aa)+$'" in out
    assert f"{MATCH_SECONDS:g} s" in out and "finish" in out and "3001 characters" in out


def test_nested_repeats_on_a_long_header_finish(tmp_path):
    wf = write_regex_workflow(tmp_path, "^(a+)+$", "a" * 3000 + "!")
    code, out = invoke("run", wf, "--stages", "ingest")
    assert code == 1
    assert "`q` = regex '^(a+)+$'" in out and "matches" in out


def test_a_sound_regex_still_selects_its_channel():
    names = ["time_ms", "Model Root/DE1/v_mon", "Model Root/DE2/v_mon", "Laser/q"]
    assert search_names(r"DE\d/v_mon$", names, "`v1`") == [1, 2]
    assert search_names("^Laser/", names, "`q`") == [3]


# -- Python API arguments ---------------------------------------------------------------------


@pytest.fixture
def synthetic_wf(tmp_path):
    (tmp_path / "rig.csv").write_text(rig_csv_text(10))
    (tmp_path / "wf.toml").write_text(SYNTHETIC_WORKFLOW.format(alpha=1e-6))
    return tmp_path / "wf.toml"


@pytest.mark.parametrize(
    ("nested", "dotted"),
    [
        ({"identify": {"M": 5}}, ["identify.M=5"]),
        ({"compare.narx": {"enabled": False}}, ["compare.narx.enabled=false"]),
        ({"compare": {"narx": {"enabled": False}}}, ["compare.narx.enabled=false"]),
        (
            {"identify.M": 6, "identify": {"sigma_n": 0.25}, "validate": {"substeps": 4}},
            ["identify.M=6", "identify.sigma_n=0.25", "validate.substeps=4"],
        ),
        ({"identify": {"M": np.int64(7)}}, ["identify.M=7"]),
    ],
)
def test_table_valued_overrides_mean_the_dotted_keys(synthetic_wf, nested, dotted):
    by_table = debist.load_workflow(synthetic_wf, nested)
    by_keys = debist.load_workflow(synthetic_wf, dotted)
    assert by_table.sections == by_keys.sections
    assert by_table.sections != debist.load_workflow(synthetic_wf).sections


def test_nested_overrides_keep_the_rest_of_the_section(synthetic_wf):
    wf = debist.load_workflow(synthetic_wf, {"identify": {"M": 5}})
    assert wf.sections["identify"] == {
        "M": 5, "sigma_n": 0.5, "T_z": 0.0, "trim": 50, "max_condition": 1e10
    }  # fmt: skip


@pytest.mark.parametrize("overrides", [{"identify.M": None}, {"identify": {"M": None}}])
def test_none_as_an_override_is_refused_naming_the_key(synthetic_wf, overrides):
    with pytest.raises(WorkflowError) as err:
        debist.load_workflow(synthetic_wf, overrides)
    assert "'identify.M'" in str(err.value)


@pytest.mark.parametrize(
    ("call", "message"),
    [
        (lambda wf: debist.verify(wf, 12345), r"digest: expected a str .*got int 12345"),
        (lambda wf: debist.run(wf, stages=5), r"stages: expected a list of stage names, got int 5"),
        (lambda wf: debist.status(wf, overrides=[("identify.M", 5)]), r"got tuple \('identify"),
        (lambda wf: debist.status(wf, overrides={"identify.M": {1, 2}}), r"of type set, not a"),
        (lambda wf: debist.load_workflow(5), r"workflow: expected a path .*got int 5"),
        (lambda wf: debist.export_model(wf, 3), r"fmt: expected a str .*got int 3"),
        (lambda wf: debist.fleet(wf, "3", folder="f"), r"size: expected an int, got str '3'"),
        (lambda wf: debist.load_model(None), r"path: expected a path .*got NoneType None"),
    ],
)
def test_api_arguments_of_the_wrong_type_are_refused_in_one_line(synthetic_wf, call, message):
    with pytest.raises(ArgumentError, match=message) as info:
        call(synthetic_wf)
    assert isinstance(info.value, TypeError) and isinstance(info.value, WorkflowError)
    assert "\n" not in str(info.value)


# -- export destination -----------------------------------------------------------------------


def test_export_refuses_the_file_system_root(synthetic_wf):
    # no run exists: were the check missing, export would stop at the missing identify
    # stage, never write into /
    with pytest.raises(OutputDirError) as err:
        debist.export_model(synthetic_wf, "c", dest="/")
    assert "'/'" in str(err.value)


def test_export_refuses_the_home_folder(synthetic_wf, tmp_path, monkeypatch):
    home = tmp_path / "home"
    home.mkdir()
    monkeypatch.setenv("HOME", str(home))
    with pytest.raises(OutputDirError) as err:
        debist.export_model(synthetic_wf, "python", dest=home)
    assert "export" in str(err.value) and "home" in str(err.value)
    assert list(home.iterdir()) == []


def test_export_refuses_the_workflow_folder_and_the_data_folder(synthetic_wf, tmp_path):
    with pytest.raises(OutputDirError) as err:
        debist.export_model(synthetic_wf, "c", dest=tmp_path)
    assert "workflow" in str(err.value) and "folder" in str(err.value)
    code, out = invoke("export", synthetic_wf, "--format", "c", "--dest", tmp_path.parent)
    assert code == 2 and "source" in out and "rig.csv" in out


# -- informational warnings -------------------------------------------------------------------


def test_a_spectral_cutoff_above_nyquist_is_warned_about():
    t = np.arange(400) * 2e-3  # 500 Hz sampling: Nyquist 250 Hz
    frame = pd.DataFrame({"t": t, "q": np.sin(2 * np.pi * 3 * t)})
    frame.attrs["source"] = "rig.csv"
    section = {"method": "spectral", "cutoff_hz": 400.0}
    with pytest.warns(PlausibilityWarning) as caught:
        differentiate_tables({"estimation": frame}, section)
    (message,) = [str(w.message) for w in caught if w.category is PlausibilityWarning]
    assert "file 'rig.csv', data set 'estimation'" in message
    assert "[differentiate] cutoff_hz = 400 Hz" in message and "Nyquist" in message
    assert "frequency 250 Hz" in message
    with warnings.catch_warnings():
        warnings.simplefilter("error", PlausibilityWarning)
        differentiate_tables({"estimation": frame}, {"method": "spectral", "cutoff_hz": 200.0})


def test_q_in_mm_declared_as_m_is_warned_about_in_the_cli_and_the_ingest_summary(tmp_path):
    (tmp_path / "rig.csv").write_text(rig_csv_text(amplitude=10.0))  # +-10: mm, really
    wf = SYNTHETIC_WORKFLOW.format(alpha=1e-6).replace(
        'q = { name = "laser", unit = "mm" }', 'q = { name = "laser", unit = "m" }'
    )
    (tmp_path / "wf.toml").write_text(wf)
    with pytest.warns(PlausibilityWarning, match=r"`q` spans 20 m peak to peak"):
        code, out = invoke("run", tmp_path / "wf.toml", "--stages", "ingest")
    assert code == 0, out
    summary = json.loads((tmp_path / "out" / "ingest" / "summary.json").read_text())
    (note,) = [w for w in summary["warnings"] if "spans 20 m" in w]
    assert "file 'rig.csv', channel 'laser'" in note and "`q.unit` = 'm'" in note
    assert "'mm'" in note and "span 20 mm" in note


def test_a_stroke_below_a_tenth_of_a_micrometre_names_the_plausible_unit():
    q = 0.01 * np.sin(np.linspace(0, 6, 200))  # +-10 mm, written in m, declared in nm
    with pytest.warns(PlausibilityWarning, match=r"read in 'm' it would span 0.02 m"):
        check_stroke(q * 1e-9, unit="nm", channel="laser", path="rig.csv")
    with warnings.catch_warnings():
        warnings.simplefilter("error", PlausibilityWarning)
        check_stroke(q, unit="m", channel="laser", path="rig.csv")  # 20 mm: plausible
        check_stroke(np.zeros(5), unit="m", channel="laser", path="rig.csv")  # motionless


# -- [identify.auto] list length --------------------------------------------------------------


def test_a_huge_identify_auto_list_is_refused_naming_key_and_limit(synthetic_wf):
    values = ", ".join(str(4 + k % 20) for k in range(100_000))
    synthetic_wf.write_text(synthetic_wf.read_text() + f"\n[identify.auto]\nM = [{values}]\n")
    with pytest.raises(WorkflowError) as err:
        debist.load_workflow(synthetic_wf)
    assert "has 100000" in str(err.value)
    assert "most 1000" in str(err.value)
    code, out = invoke("status", synthetic_wf)
    assert code == 2 and f"most {MAX_GRID_VALUES}" in out


def test_grid_values_are_validated_once_each(synthetic_wf, monkeypatch):
    calls = []
    real = identify_config.candidate_config
    monkeypatch.setattr(
        identify_config, "candidate_config", lambda *a: calls.append(a[1]) or real(*a)
    )
    values = ", ".join(str(v) for v in [6, 8, 10] * 300)
    synthetic_wf.write_text(synthetic_wf.read_text() + f"\n[identify.auto]\nM = [{values}]\n")
    wf = debist.load_workflow(synthetic_wf)
    assert len(wf.sections["identify"]["auto"]["M"]) == 900
    assert calls == [{"M": 6}, {"M": 8}, {"M": 10}]


# -- hostile environment: FIFOs, locale, symbolic links, edited model --------------------------


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="needs POSIX FIFOs")
def test_a_fifo_as_workflow_file_is_refused_before_opening_it(tmp_path):
    """Opening a FIFO waits for a writer: refused at once in one line, exit 2 (a subprocess
    with a time limit, so that a regression fails instead of hanging the tests)."""
    fifo = tmp_path / "wf.toml"
    os.mkfifo(fifo)
    done = subprocess.run(
        [sys.executable, "-m", "debist", "run", str(fifo)],
        capture_output=True, text=True, timeout=120,
    )  # fmt: skip
    assert done.returncode == 2, done.stderr
    (line,) = done.stderr.splitlines()
    assert str(fifo) in line and "not a regular file" in line
    assert sorted(p.name for p in tmp_path.iterdir()) == ["wf.toml"]


def test_an_output_dir_the_locale_cannot_encode_is_refused_in_one_line(synthetic_wf):
    """LC_ALL=C without UTF-8 mode: the file system encoding is ASCII and 'ü' cannot be a
    file name; one line naming the key, the character and the fix, exit 2, nothing made."""
    text = synthetic_wf.read_text().replace('output_dir = "out"', 'output_dir = "r\u00fcns"')
    synthetic_wf.write_text(text, encoding="utf-8")
    before = sorted(p.name for p in synthetic_wf.parent.iterdir())
    env = {**os.environ, "LC_ALL": "C", "PYTHONUTF8": "0", "PYTHONCOERCECLOCALE": "0"}
    done = subprocess.run(
        [sys.executable, "-m", "debist", "run", synthetic_wf.name],
        cwd=synthetic_wf.parent, env=env, capture_output=True, text=True, timeout=300,
    )  # fmt: skip
    assert done.returncode == 2, done.stderr
    (line,) = done.stderr.splitlines()
    assert "[workflow] output_dir" in line and "(ascii)" in line and "LC_ALL=C.UTF-8" in line
    assert sorted(p.name for p in synthetic_wf.parent.iterdir()) == before


@pytest.mark.parametrize("force", [False, True])
def test_export_never_follows_a_symlinked_export_folder_out_of_the_output_folder(
    synthetic_copy, tmp_path, force
):
    root, _ = synthetic_copy
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    (elsewhere / "debist_model.py").write_text("# a user's file\n")
    (root / "out" / "export").symlink_to(elsewhere, target_is_directory=True)
    code, out = invoke("export", root / "wf.toml", "--format", "python", *(["--force"] * force))
    assert code == 2, out
    assert "symbolic link" in out and str(root / "out" / "export") in out
    assert sorted(p.name for p in elsewhere.iterdir()) == ["debist_model.py"]
    assert (elsewhere / "debist_model.py").read_text() == "# a user's file\n"


def test_export_never_writes_through_a_symlinked_file(synthetic_copy, tmp_path):
    root, _ = synthetic_copy
    target = tmp_path / "mine.py"
    target.write_text("# a user's file\n")
    (root / "out" / "export").mkdir()
    (root / "out" / "export" / "debist_model.py").symlink_to(target)
    code, out = invoke("export", root / "wf.toml", "--format", "python", "--force")
    assert code == 2, out
    assert "symbolic link" in out and "debist_model.py" in out
    assert target.read_text() == "# a user's file\n"
    assert (root / "out" / "export" / "debist_model.py").is_symlink()


@pytest.mark.parametrize(
    ("dataset", "change", "expected"),
    [
        ("model/theta_g", lambda a: np.concatenate([a, a[:, :1]], axis=1), "expected (2, 8)"),
        ("model/theta_c", lambda a: a[:-1], "expected (8,)"),
        ("model/xi", lambda a: a.reshape(2, -1), "expected (M,)"),
        ("model/backbone/g_0", lambda a: np.zeros(3), "expected (2,)"),
    ],
)
def test_an_edited_and_resigned_model_is_refused_on_export_naming_the_dataset(
    synthetic_copy, dataset, change, expected
):
    """model.h5 edited (arrays of another shape) and its manifest re-signed, so the tamper
    check passes: export says which dataset is wrong in one line, exit 1, writes nothing."""
    import h5py

    from tests.engine.test_verify_workflow import resign

    root, _ = synthetic_copy
    path = root / "out" / "identify" / "model.h5"
    with h5py.File(path, "r+") as f:
        value = change(f[dataset][...])
        del f[dataset]
        f[dataset] = value
    resign(root / "out", "identify")
    code, out = invoke("export", root / "wf.toml", "--format", "c")
    assert code == 1, out
    assert str(path) in out and dataset in out and expected in out, out
    assert "Traceback" not in out and not (root / "out" / "export").exists()
    with pytest.raises(ArtifactError, match=dataset):
        debist.load_model(path)


_IN_CALLBACK = """
import ctypes, os, signal, sys, time
import debist.cli as cli

def work():  # stands for the command: numba's compiler calls back into Python via ctypes
    def callback():
        os.kill(os.getpid(), getattr(signal, sys.argv[1]))
        for _ in range(1000):
            pass
    try:
        ctypes.CFUNCTYPE(None)(callback)()
        time.sleep(60)
        print("the signal was lost")
    except KeyboardInterrupt as exc:
        print("stopped by", getattr(exc, "signum", signal.SIGINT))

cli.app = work
cli.main()
"""


@pytest.mark.parametrize("name", ["SIGINT", "SIGTERM"])
def test_a_signal_raised_inside_a_ctypes_callback_is_not_lost(name):
    """Python cannot propagate an exception out of a ctypes callback: it prints "Exception
    ignored" and goes on. The command line sends the signal again to the main thread."""
    import signal

    done = subprocess.run(
        [sys.executable, "-c", _IN_CALLBACK, name], capture_output=True, text=True, timeout=120
    )
    assert done.returncode == 0, done.stderr
    assert done.stdout.split() == ["stopped", "by", str(int(getattr(signal, name)))]
    assert done.stderr == ""
