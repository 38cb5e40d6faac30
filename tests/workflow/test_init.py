"""`debist init`: a first workflow from one's own rig logs, channels guessed by names and units."""

from __future__ import annotations

import os
import subprocess
import sys
import tomllib
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import scipy.io as sio

import debist
from debist.core.errors import OutputDirError, RigLogError, WorkflowError
from debist.ingest.survey import ChannelInfo, FileSurvey, guess_mapping
from debist.workflow.loader import load_workflow

ROOT = Path(__file__).resolve().parents[2]


def cli(*args):
    from tests.conftest import invoke_cli

    return invoke_cli(*args)


def de_log(n=400, seed=0, q_peak=9.0, v_peak=3.0):
    """A seeded two-membrane record: t [s], q, v1, v2 (units as the caller writes them)."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) * 0.01
    q = q_peak * np.sin(2 * np.pi * 0.3 * t) + 0.01 * q_peak * rng.standard_normal(n)
    v1 = v_peak * (np.sin(2 * np.pi * 0.5 * t) > 0) + 0.001 * v_peak * rng.random(n)
    v2 = v_peak * (np.sin(2 * np.pi * 0.7 * t) > 0) + 0.001 * v_peak * rng.random(n)
    return t, q, v1, v2


def write_mat(path, seed=0, **peaks):
    t, q, v1, v2 = de_log(seed=seed, **peaks)
    sio.savemat(path, {"time_s": t, "laser_pos": q, "HV_left": v1, "HV_right": v2})
    return path


def roles(result, k=0):
    return {g.role: (g.channel.name, g.unit) for g in result.datasets[k].mapping.guesses}


def test_a_plain_mat_pair_is_mapped_by_names_and_sizes(tmp_path):
    est = write_mat(tmp_path / "est.mat", seed=0)
    val = write_mat(tmp_path / "val.mat", seed=1)
    done = debist.init_workflow([est, val], tmp_path / "rig.toml")
    assert roles(done) == {"time": ("time_s", "s"), "q": ("laser_pos", "mm"),
                           "v1": ("HV_left", "kV"), "v2": ("HV_right", "kV")}  # fmt: skip
    raw = tomllib.loads((tmp_path / "rig.toml").read_text(encoding="utf-8"))
    assert raw["ingest"]["q"] == {"name": "laser_pos", "unit": "mm"}
    assert raw["datasets"]["est"] == {"source": "est.mat", "role": "estimation"}
    assert raw["datasets"]["val"] == {"source": "val.mat", "role": "validation"}
    assert raw["report"] == {} and raw["identify"] == {"input_map": "v2"}
    wf = load_workflow(tmp_path / "rig.toml")  # paths relative to the workflow's folder
    assert [d.source for d in wf.datasets] == [est.resolve(), val.resolve()]
    assert wf.output_dir == (tmp_path / "runs" / "rig").resolve()
    assert "name; unit" in done.text and "assumed" in done.text and "peak" in done.text


@pytest.mark.parametrize(
    ("q_peak", "v_peak", "units"),
    [(0.012, 3000.0, ("m", "V")), (12.0, 3.0, ("mm", "kV")), (1.2e4, 2.5, ("um", "kV"))],
)
def test_an_unknown_unit_is_assumed_from_the_size_of_the_values(tmp_path, q_peak, v_peak, units):
    log = write_mat(tmp_path / "log.mat", q_peak=q_peak, v_peak=v_peak)
    found = roles(debist.init_workflow([log], tmp_path / "wf.toml"))
    assert (found["q"][1], found["v1"][1], found["v2"][1]) == (units[0], units[1], units[1])


def test_every_file_gets_the_same_assumed_unit(tmp_path):
    """A validation record that stays near rest must not look like metres."""
    est = write_mat(tmp_path / "est.mat", q_peak=20.0)
    val = write_mat(tmp_path / "val.mat", seed=1, q_peak=0.3)
    done = debist.init_workflow([est, val], tmp_path / "wf.toml")
    assert roles(done, 0)["q"] == roles(done, 1)["q"] == ("laser_pos", "mm")
    assert "q = " not in done.text.split("[datasets.val]")[1]  # no override of its own


def chan(name, unit=None, quantity=None, hi=1.0, increasing=False):
    return ChannelInfo(name, {"name": name}, unit, "file" if unit else "", quantity, 100, True,
                       -hi, hi, increasing)  # fmt: skip


def test_a_recording_maps_the_measured_voltages_in_order_and_no_time():
    survey = FileSurvey(Path("rec.mat"), "mat-v5", (
        chan("Model Root/Reference/DE2/v_ref", "kV", "voltage", 3.0),
        chan("Model Root/HV Amplifier/DE2/v_mon", "kV", "voltage", 3.0),
        chan("Model Root/Sensors/Laser/q", "mm", "length", 12.0),
        chan("Model Root/HV Amplifier/DE1/v_mon", "kV", "voltage", 3.0),
        chan("Model Root/Reference/DE1/v_ref", "kV", "voltage", 3.0),
    ), time_bases=("Periodic Task 1",))  # fmt: skip
    found = {g.role: (g.channel.name, g.unit, g.why) for g in guess_mapping(survey).guesses}
    assert found == {
        "q": ("Model Root/Sensors/Laser/q", "mm", "by its name and unit"),
        "v1": ("Model Root/HV Amplifier/DE1/v_mon", "kV",
               "by its name and unit, a measured voltage"),
        "v2": ("Model Root/HV Amplifier/DE2/v_mon", "kV",
               "by its name and unit, a measured voltage"),
    }  # fmt: skip


@pytest.mark.filterwarnings("ignore:.*the workflow gives no `range`")
def test_a_dspace_recording_file_gets_a_workflow_that_ingests(tmp_path):
    from debist.rig.dspace import Channel, recording, write_recording

    t, q, v1, v2 = de_log()
    task = "Periodic Task 1"
    channels = [Channel("Model Root/Sensors/Laser/q", q, "mm", task),
                Channel("Model Root/HV Amplifier/DE1/v_mon", v1, "kV", task),
                Channel("Model Root/HV Amplifier/DE2/v_mon", v2, "kV", task)]  # fmt: skip
    rec = recording(channels, {task: t})
    write_recording(tmp_path / "r.mat", rec, version="5", created="2026-01-01 00:00:00")
    done = debist.init_workflow([tmp_path / "r.mat"], tmp_path / "wf.toml")
    raw = tomllib.loads(done.text)
    assert "time" not in raw["ingest"] and "# time:" in done.text
    assert raw["ingest"]["v2"] == {"name": "Model Root/HV Amplifier/DE2/v_mon", "unit": "kV"}


def test_init_writes_the_laser_range_of_the_dspace_fixtures_and_runs_warn_nothing(tmp_path):
    """The ILD2300's +-25 mm goes into [ingest] q, so ingest has no range to warn about."""
    import warnings

    from tests.data.make_dspace_fixtures import write_v5, write_v73

    write_v73(tmp_path / "est.mat")
    write_v5(tmp_path / "val.mat")
    with warnings.catch_warnings(record=True) as shown:
        warnings.simplefilter("always")
        done = debist.init_workflow(
            [tmp_path / "est.mat", tmp_path / "val.mat"], tmp_path / "rig.toml"
        )
    raw = tomllib.loads(done.text)
    assert raw["ingest"]["q"] == {"name": "Model Root/Sensors/Laser/q", "unit": "mm",
                                  "range": [-25.0, 25.0]}  # fmt: skip
    assert "q = " not in done.text.split("[datasets.val]")[1]  # the same table: no override
    line = next(x for x in done.text.splitlines() if x.startswith("q = "))
    assert "ILD2300 laser's, -25 to 25 mm (datasheet)" in line
    assert not [w for w in shown if "range" in str(w.message)]  # its own check ingested quietly


def test_without_a_range_a_run_warns_once_naming_every_file(tmp_path):
    """The sensor's documented range applied to three files: one warning line, three files."""
    import warnings

    from tests.data.make_dspace_fixtures import write_v5, write_v73

    logs = [tmp_path / "a.mat", tmp_path / "b.mat", tmp_path / "c.mat"]
    write_v73(logs[0]), write_v5(logs[1]), write_v5(logs[2])
    done = debist.init_workflow(logs, tmp_path / "rig.toml")
    text = done.text.replace(", range = [-25.0, 25.0]", "")
    (tmp_path / "rig.toml").write_text(text, encoding="utf-8")
    with warnings.catch_warnings(record=True) as shown:
        warnings.simplefilter("always")
        code, out = cli("run", tmp_path / "rig.toml", "--stages", "ingest")
    assert code == 0, out
    ranges = [str(w.message) for w in shown if "gives no `range`" in str(w.message)]
    assert len(ranges) == 1, ranges
    assert ranges[0].startswith(f"files '{logs[0]}', '{logs[1]}', '{logs[2]}', channel ")
    notes = debist.open_run(tmp_path / "rig.toml").manifests["ingest"].summary["warnings"]
    assert [n for n in notes if "gives no `range`" in n] == [
        ranges[0].replace(f"'{tmp_path}/", "'")
    ]


def test_a_range_in_metres_is_written_in_metres(tmp_path):
    from debist.rig.dspace import Channel, recording, write_recording

    t, q, v1, v2 = de_log(q_peak=0.009)
    task = "Periodic Task 1"
    channels = [Channel("Model Root/Sensors/Laser/q", q, "m", task),
                Channel("Model Root/HV Amplifier/DE1/v_mon", v1, "kV", task),
                Channel("Model Root/HV Amplifier/DE2/v_mon", v2, "kV", task)]  # fmt: skip
    write_recording(tmp_path / "r.mat", recording(channels, {task: t}), version="5",
                    created="2026-01-01 00:00:00")  # fmt: skip
    raw = tomllib.loads(debist.init_workflow([tmp_path / "r.mat"], tmp_path / "wf.toml").text)
    assert raw["ingest"]["q"]["range"] == [-0.025, 0.025]


def test_a_sensor_of_unknown_range_gets_a_comment_asking_for_one(tmp_path):
    done = debist.init_workflow([write_mat(tmp_path / "est.mat")], tmp_path / "wf.toml")
    raw = tomllib.loads(done.text)
    assert "range" not in raw["ingest"]["q"]
    line = next(x for x in done.text.splitlines() if x.startswith("q = "))
    assert line.endswith("no documented range known for this sensor: add range = [lo, hi]")


def test_list_only_lists_and_writes_nothing(tmp_path):
    log = write_mat(tmp_path / "est.mat")
    before = sorted(tmp_path.iterdir())
    code, out = cli("init", "--list", log)
    assert code == 0, out
    assert all(name in out for name in ("time_s", "laser_pos", "HV_left", "HV_right", "mat-v5"))
    assert sorted(tmp_path.iterdir()) == before


def test_init_never_overwrites_a_file_unless_forced(tmp_path):
    log = write_mat(tmp_path / "est.mat")
    mine = tmp_path / "rig.toml"
    mine.write_text("# mine\n", encoding="utf-8")
    code, out = cli("init", log, "--out", mine)
    assert code == 2
    assert "'" + str(mine) + "' exists" in out and "--force" in out and out.count("\n") == 1
    assert mine.read_text(encoding="utf-8") == "# mine\n"
    code, out = cli("init", log, "--out", mine, "--force")
    assert code == 0, out
    assert "wrote " + str(mine) in " ".join(out.split())
    assert tomllib.loads(mine.read_text(encoding="utf-8"))["workflow"]["name"] == "rig"
    with pytest.raises(WorkflowError) as err:  # not even with force
        debist.init_workflow([log], log, force=True)
    assert "rig" in str(err.value) and "logs" in str(err.value)


@pytest.mark.parametrize("link", [True, False])
def test_a_file_created_while_init_runs_is_kept(tmp_path, monkeypatch, link):
    """The check at the start passes; another program writes --out before init writes it:
    its file stays byte for byte, init exits 2 naming it, and no temporary file is left.
    Also where the file system has no hard links (the exclusive create instead)."""
    from debist.workflow import init as init_module

    log = write_mat(tmp_path / "est.mat")
    out = tmp_path / "rig.toml"
    verify = init_module._verify

    def meanwhile(*args, **kwargs):
        verify(*args, **kwargs)
        out.write_bytes(b"# written by someone else meanwhile\n")

    monkeypatch.setattr(init_module, "_verify", meanwhile)
    if not link:

        def no_links(*_args, **_kwargs):
            raise PermissionError(1, "Operation not permitted")

        monkeypatch.setattr("os.link", no_links)
    code, text = cli("init", log, "--out", out)
    assert code == 2, text
    assert f"'{out}' exists" in " ".join(text.split()) and text.count("\n") == 1
    assert out.read_bytes() == b"# written by someone else meanwhile\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["est.mat", "rig.toml"]


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="needs POSIX FIFOs")
def test_init_refuses_a_fifo_before_opening_it(tmp_path):
    """A FIFO as a rig log would wait forever for a writer: refused at once, one line, exit 2
    (in a subprocess with a time limit, so that a regression fails instead of hanging)."""
    fifo = tmp_path / "log.csv"
    os.mkfifo(fifo)
    for args in (
        ["init", str(fifo), "--out", str(tmp_path / "w.toml")],
        ["init", "--list", str(fifo)],
    ):
        done = subprocess.run(
            [sys.executable, "-m", "debist", *args], capture_output=True, text=True, timeout=120
        )
        assert done.returncode == 2, done.stderr
        (line,) = done.stderr.splitlines()
        assert str(fifo) in line and "not a regular file" in line
    assert sorted(p.name for p in tmp_path.iterdir()) == ["log.csv"]


def test_a_name_the_locale_cannot_encode_is_refused_in_one_line(tmp_path):
    """Under LC_ALL=C without UTF-8 mode, a non-ASCII file name arrives as undecodable bytes
    that no UTF-8 workflow can hold: one line saying so and how to fix it, exit 2."""
    log = write_mat(tmp_path / "m\u00fcller.mat")
    env = {**os.environ, "LC_ALL": "C", "PYTHONUTF8": "0", "PYTHONCOERCECLOCALE": "0"}
    done = subprocess.run(
        [sys.executable, "-m", "debist", "init", log.name, "--out", "w.toml"],
        cwd=tmp_path, env=env, capture_output=True, text=True, timeout=120,
    )  # fmt: skip
    assert done.returncode == 2, done.stderr
    (line,) = done.stderr.splitlines()
    assert "rig log" in line and "LC_ALL=C.UTF-8" in line and "\\xc3\\xbc" in line
    assert sorted(p.name for p in tmp_path.iterdir()) == [log.name]


def test_the_default_out_is_debist_toml_in_the_working_folder(tmp_path, monkeypatch):
    (tmp_path / "data").mkdir()
    log = write_mat(tmp_path / "data" / "est.mat")
    monkeypatch.chdir(tmp_path)
    done = debist.init_workflow([log])
    assert done.path == Path("debist.toml") and (tmp_path / "debist.toml").is_file()
    assert tomllib.loads(done.text)["datasets"]["est"]["source"] == "data/est.mat"


HOSTILE = "we\"ird ]\n[x] \u00fcn\u00efc\u00f6de 'q'\\ #.mat"


def test_a_hostile_file_name_round_trips_through_the_written_toml(tmp_path):
    folder = tmp_path / 'a ]"[b'
    folder.mkdir()
    log = write_mat(folder / HOSTILE)
    done = debist.init_workflow([log], tmp_path / "out dir" / "wf.toml")
    raw = tomllib.loads((tmp_path / "out dir" / "wf.toml").read_text(encoding="utf-8"))
    (name,) = raw["datasets"]
    assert name == "we_ird_x_n_c_de_q"  # a plain file name for ingest/<name>.parquet
    assert raw["datasets"][name]["source"] == f'../a ]"[b/{HOSTILE}'
    wf = load_workflow(done.path)
    assert wf.datasets[0].source == log.resolve()


def test_a_hostile_channel_name_round_trips(tmp_path):
    import pyarrow as pa
    import pyarrow.parquet as pq

    t, q, v1, v2 = de_log()
    weird = 'laser "pos"\n]x['
    table = pa.table({"time": t, weird: q, "v1": v1, "v2": v2})
    pq.write_table(table, tmp_path / "log.parquet")
    done = debist.init_workflow([tmp_path / "log.parquet"], tmp_path / "wf.toml")
    assert tomllib.loads(done.text)["ingest"]["q"] == {"name": weird, "unit": "mm"}


def test_an_unguessable_channel_is_refused_in_one_line_naming_file_channels_and_option(tmp_path):
    t, q, v1, v2 = de_log()
    log = tmp_path / "run7.csv"
    pd.DataFrame({"time": t, "a": q, "HV1": v1, "HV2": v2}).to_csv(log, index=False)
    out_file = tmp_path / "wf.toml"
    code, out = cli("init", log, "--out", out_file)
    assert code == 2 and out.count("\n") == 1, out
    line = " ".join(out.split())
    assert f"file '{log}':" in line and "looks" in line and "q" in line
    assert "its channels: 'time', 'a', 'HV1', 'HV2'; pass --q NAME" in line
    assert not out_file.exists()
    code, out = cli("init", log, "--out", out_file, "--q", "a", "--unit", "q=um")
    assert code == 0, out
    assert tomllib.loads(out_file.read_text(encoding="utf-8"))["ingest"]["q"] == {
        "name": "a", "unit": "um"}  # fmt: skip


def test_ambiguous_inputs_and_unknown_names_are_refused(tmp_path):
    t, q, v1, v2 = de_log()
    log = tmp_path / "x.csv"
    pd.DataFrame({"t": t, "pos": q, "HV1": v1, "HV2": v2, "HV3": v1}).to_csv(log, index=False)
    with pytest.raises(WorkflowError) as err:
        debist.init_workflow([log], tmp_path / "wf.toml")
    assert "ambiguous" in str(err.value)
    assert "'HV3'" in str(err.value)
    assert "--v NAME" in str(err.value)
    done = debist.init_workflow([log], tmp_path / "wf.toml", v=["HV3", "HV1"])
    assert roles(done)["v1"] == ("HV3", "kV") and roles(done)["v2"] == ("HV1", "kV")
    with pytest.raises(WorkflowError) as err:
        debist.init_workflow([log], tmp_path / "other.toml", q="nope")
    assert "'nope'" in str(err.value)
    assert "--q" in str(err.value)
    with pytest.raises(WorkflowError, match=r"--unit q=N.*\[s\]|--unit.*q.unit"):
        debist.init_workflow([log], tmp_path / "other.toml", units=["q=N"])
    assert not (tmp_path / "other.toml").exists()


def test_a_validation_file_names_only_its_own_channels(tmp_path):
    t, q, v1, v2 = de_log()
    pd.DataFrame({"time": t, "laser [mm]": q, "HV1": v1, "HV2": v2}).to_csv(
        tmp_path / "a.csv", index=False)  # fmt: skip
    pd.DataFrame({"t": t, "x [mm]": q, "HV1": v1, "HV2": v2}).to_csv(
        tmp_path / "b.csv", index=False
    )
    pd.DataFrame({"t": t, "x [mm]": q, "HV1": v1}).to_csv(tmp_path / "c.csv", index=False)
    done = debist.init_workflow([tmp_path / "a.csv", tmp_path / "b.csv"], tmp_path / "wf.toml")
    raw = tomllib.loads(done.text)
    assert raw["datasets"]["b"] == {"source": "b.csv", "role": "validation",
                                    "time": {"name": "t", "unit": "s"},
                                    "q": {"name": "x [mm]", "unit": "mm"}}  # fmt: skip
    with pytest.raises(WorkflowError) as err:
        debist.init_workflow([tmp_path / "a.csv", tmp_path / "c.csv"], tmp_path / "wf2.toml")
    assert "1 input(s)" in str(err.value)


def test_csv_with_units_in_its_header_runs_its_ingest(tmp_path):
    t, q, v1, v2 = de_log()
    frame = pd.DataFrame({"Time [s]": t, "x [mm]": q, "U1 (kV)": v1, "U2 (kV)": v2})
    frame.to_csv(tmp_path / "log.csv", index=False)
    code, out = cli("init", tmp_path / "log.csv", "--out", tmp_path / "wf.toml")
    assert code == 0, out
    code, out = cli("ingest", tmp_path / "wf.toml")
    assert code == 0, out
    table = pd.read_parquet(tmp_path / "runs" / "wf" / "ingest" / "log.parquet")
    assert list(table.columns) == ["t", "q", "v1", "v2"]
    np.testing.assert_allclose(table["q"], 1e-3 * q, rtol=1e-12)
    np.testing.assert_allclose(table["v2"], 1e3 * v2, rtol=1e-12)


def test_parquet_with_unit_metadata(tmp_path):
    import pyarrow as pa
    import pyarrow.parquet as pq

    t, q, v1, v2 = de_log()
    fields = [pa.field("clock", pa.float64(), metadata={"unit": "ms"}),
              pa.field("displacement", pa.float64(), metadata={"unit": "um"}),
              pa.field("left", pa.float64(), metadata={"unit": "V"}),
              pa.field("right", pa.float64(), metadata={"unit": "V"})]  # fmt: skip
    table = pa.Table.from_arrays([pa.array(a) for a in (1e3 * t, q, v1, v2)],
                                 schema=pa.schema(fields))  # fmt: skip
    pq.write_table(table, tmp_path / "log.parquet")
    done = debist.init_workflow([tmp_path / "log.parquet"], tmp_path / "wf.toml")
    assert roles(done) == {"time": ("clock", "ms"), "q": ("displacement", "um"),
                           "v1": ("left", "V"), "v2": ("right", "V")}  # fmt: skip
    assert {g.unit_why for g in done.datasets[0].mapping.guesses} == {"from the file"}


def test_a_mapping_that_does_not_ingest_is_refused_and_nothing_is_written(tmp_path):
    t, q, v1, v2 = de_log()
    t[5] = t[4]  # the time stops: not strictly increasing, so not a time
    log = tmp_path / "x.csv"
    pd.DataFrame({"t": t, "pos": q, "HV1": v1, "HV2": v2}).to_csv(log, index=False)
    with pytest.raises(WorkflowError) as err:
        debist.init_workflow([log], tmp_path / "wf.toml")
    assert "channel" in str(err.value) and "time" in str(err.value)
    with pytest.raises(RigLogError) as err:
        debist.init_workflow([log], tmp_path / "wf.toml", time="t")
    assert "mapping" in str(err.value) and "chose" in str(err.value)
    assert not (tmp_path / "wf.toml").exists()
    done = debist.init_workflow([log], tmp_path / "wf.toml", sample_time=0.01)
    assert tomllib.loads(done.text)["ingest"]["sample_time"] == 0.01


def test_the_api_lists_channels():
    (found,) = debist.list_channels(ROOT / "data" / "emps" / "DATA_EMPS.mat")
    assert found.format == "mat-v5"
    assert [c.name for c in found.channels] == ["gtau", "kp", "kv", "qg", "qm", "t", "vir"]
    assert found.channel("t").increasing and found.channel("gtau").samples == 1


# ------------------------------------------------------ shipped examples


def test_an_example_workflow_is_copied_byte_for_byte_with_its_data(tmp_path):
    path = debist.example_workflow("silverbox", tmp_path / "ex")
    assert path == tmp_path / "ex" / "workflows" / "silverbox.toml"
    assert path.read_bytes() == (ROOT / "workflows" / "silverbox.toml").read_bytes()
    data = tmp_path / "ex" / "data" / "silverbox"
    assert sorted(p.name for p in data.iterdir()) == ["README.md", "SNLS80mV.csv.gz"]
    assert (data / "SNLS80mV.csv.gz").read_bytes() == (
        ROOT / "data" / "silverbox" / "SNLS80mV.csv.gz").read_bytes()  # fmt: skip
    wf = load_workflow(path)
    assert wf.output_dir == (tmp_path / "ex" / "runs" / "silverbox").resolve()
    assert debist.example_workflow("silverbox", tmp_path / "ex") == path  # again: kept


def test_an_example_never_overwrites_another_file(tmp_path):
    path = debist.example_workflow("paper-experiment", tmp_path)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["workflows"]  # no data needed
    path.write_text("# edited\n", encoding="utf-8")
    with pytest.raises(OutputDirError) as err:
        debist.example_workflow("paper-experiment", tmp_path)
    assert "exists" in str(err.value) and "file" in str(err.value)
    assert path.read_text(encoding="utf-8") == "# edited\n"
    with pytest.raises(WorkflowError) as err:
        debist.example_workflow("nope", tmp_path)
    assert "'nope'" in str(err.value)


def test_every_shipped_workflow_and_its_data_are_package_data():
    """pyproject's patterns carry every file an example reads (a wheel has them all)."""
    from debist.workflow.examples import _data_files, example_names

    config = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]
    assert config["package-dir"]["debist.examples.workflows"] == "workflows"
    assert config["package-dir"]["debist.examples.data"] == "data"
    patterns = config["package-data"]
    packaged = {
        p.relative_to(ROOT / "workflows").as_posix()
        for pattern in patterns["debist.examples.workflows"]
        for p in (ROOT / "workflows").glob(pattern)
    }
    assert packaged == {p.name for p in (ROOT / "workflows").glob("*.toml")}
    assert set(example_names()) == {name[:-5] for name in packaged}
    data = {
        p.relative_to(ROOT / "data").as_posix()
        for pattern in patterns["debist.examples.data"]
        for p in (ROOT / "data").glob(pattern)
    }
    needed = {
        f
        for name in example_names()
        for f, _ in _data_files((ROOT / "workflows" / f"{name}.toml").read_text(), name)
    }
    assert needed and needed <= data  # fmt: skip


# ------------------------------------------------------------ end to end


@pytest.mark.slow
def test_init_then_run_on_virtual_rig_logs_validates_on_the_unseen_file(tmp_path):
    """Two plain MAT v5 logs of the virtual rig (time_s, laser_pos [mm], HV_* [kV])."""
    from debist.rig.config import RigConfig
    from debist.rig.experiment import run_experiments

    raw = tomllib.loads((ROOT / "workflows" / "paper-experiment.toml").read_text())
    raw["rig"]["experiments"]["identification"]["duration"] = 20.0
    raw["rig"]["experiments"]["validation"]["duration"] = 10.0
    runs, _ = run_experiments(RigConfig.from_dict(raw["rig"], raw["physics"]))
    for name, run in (("est.mat", runs["identification"]), ("val.mat", runs["validation"])):
        log = {"time_s": run.t, "laser_pos": 1e3 * run.q, "HV_left": 1e-3 * run.v1,
               "HV_right": 1e-3 * run.v2}  # fmt: skip
        sio.savemat(tmp_path / name, log)
    code, out = cli("init", tmp_path / "est.mat", tmp_path / "val.mat",
                    "--out", tmp_path / "rig.toml")  # fmt: skip
    assert code == 0, out
    code, out = cli("run", tmp_path / "rig.toml")
    assert code == 0, out
    table = debist.open_run(tmp_path / "rig.toml").nrmse
    unseen = table[(table["role"] == "validation") & (table["model"] == "rbf")]
    assert list(unseen["data set"]) == ["val"]
    assert float(unseen["NRMSE(q) [%]"].iloc[0]) < 5.0
    # the verdict says "simulation only" exactly when a physical curve is identified nowhere
    result = debist.open_run(tmp_path / "rig.toml")
    identified = result.manifests["identify"].summary["identified"]
    nowhere = [n for n in ("d", "g1", "g2") if not identified[n]]
    rows = [r for r in result.manifests["compare"].summary["table"] if r["model"] == "rbf"]
    for r in rows:
        said = f"simulation only: {', '.join(nowhere)} identified nowhere" in r["verdict"]
        assert said == bool(nowhere), (nowhere, r["verdict"])
    assert all("simulation only" not in r["verdict"] for r in
               result.manifests["compare"].summary["table"] if r["model"] == "narx")  # fmt: skip
    assert (tmp_path / "runs" / "rig" / "report" / "report.html").is_file()
