"""Text rig logs: Silverbox CSV, pneumatic-piston whitespace logs with gaps, detection."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from debist.core.errors import RigLogError
from debist.ingest.load import load_rig_log, read_raw
from debist.ingest.spec import IngestSpec

SHARED = Path(__file__).resolve().parents[2].parent / "shared" / "data"
DATA = Path(__file__).resolve().parents[1] / "data"
EXCERPT = DATA / "pneumatic_circle7bar_rows128-427.csv"

SILVERBOX = {
    "sample_time": 0.0016384,
    "q": {"column": 1, "unit": "V"},
    "v1": {"column": 0, "unit": "V"},
}
PISTON = {
    "time": {"column": 0, "unit": "ms"},
    "q": {"column": 4, "unit": "mm"},
    "v1": {"column": 5, "unit": "bar"},
    "force": {"column": 6, "unit": "N"},
}


def shared(*parts: str) -> Path:
    path = SHARED.joinpath(*parts)
    if not path.exists():
        pytest.skip(f"shared data set {path} not present (a clone has no ../shared)")
    return path


# ----------------------------------------------------------------------------- Silverbox
def test_silverbox_full_file():
    (df,) = load_rig_log(shared("silverbox", "SNLS80mV.csv"), IngestSpec.from_dict(SILVERBOX))
    assert df.shape == (131072, 3)
    assert list(df.columns) == ["t", "q", "v1"]
    assert (df.dtypes == np.float64).all()
    assert isinstance(df.index, pd.RangeIndex)
    assert df["v1"].iloc[0] == 0.0057756  # column 0 = input u
    assert df["q"].iloc[0] == 0.0093978  # column 1 = output y, a voltage
    np.testing.assert_array_equal(df["t"].to_numpy(), np.arange(131072) * 1.6384e-3)
    assert df.attrs["units"] == {"t": "s", "q": "V", "v1": "V"}
    assert df.attrs["channels"] == {"t": "k * 0.0016384 s", "q": "column 1", "v1": "column 0"}
    assert df.attrs["format"] == "csv"
    assert df.attrs["segment"] == 0 and df.attrs["n_segments"] == 1
    assert df.attrs["source"].endswith("SNLS80mV.csv")


def test_silverbox_estimation_slice_keeps_file_time():
    section = {**SILVERBOX, "slice": [40650, 105712]}
    (df,) = load_rig_log(shared("silverbox", "SNLS80mV.csv"), IngestSpec.from_dict(section))
    assert len(df) == 65062
    assert df["t"].iloc[0] == 40650 * 1.6384e-3  # not rebased
    assert df["t"].iloc[-1] == 105711 * 1.6384e-3
    assert df.attrs["first_index"] == 40650


# ---------------------------------------------------------------------- pneumatic piston
def test_pneumatic_gaps_error_names_file_time_and_length():
    path = shared("pneumatic-piston", "Circle_3bar.csv")
    with pytest.raises(RigLogError) as info:
        load_rig_log(path, IngestSpec.from_dict(PISTON))
    assert "gaps" in str(info.value)
    message = str(info.value)
    assert "Circle_3bar.csv" in message
    assert info.value.sample == 11 and info.value.value == pytest.approx(2.66)
    assert "t = 0.111 s (sample 11)" in message and "lasts 2.66 s" in message
    assert "92 gap(s)" in message  # steps > 15 ms at a 10 ms median
    assert 'gaps = "split"' in message


@pytest.mark.parametrize("tolerance", [1.5, 5.0])
def test_pneumatic_split_segments_are_gap_free_and_preserve_samples(tolerance):
    path = shared("pneumatic-piston", "Circle_3bar.csv")
    raw = pd.read_csv(path, sep=r"\s+", header=None)
    section = {**PISTON, "gaps": "split", "gap_tolerance": tolerance, "min_segment": 100}
    segments = load_rig_log(path, IngestSpec.from_dict(section))
    dropped = segments[0].attrs["dropped_segments"]
    assert sum(len(s) for s in segments) + sum(d["n_samples"] for d in dropped) == len(raw)
    assert all(d["n_samples"] < 100 for d in dropped)
    median = np.median(np.diff(raw[0].to_numpy() * 1e-3))
    for i, seg in enumerate(segments):
        assert len(seg) >= 100
        assert np.diff(seg["t"].to_numpy()).max() <= tolerance * median * (1 + 1e-9)
        assert seg.attrs["segment"] == i and seg.attrs["n_segments"] == len(segments)
        first = seg.attrs["first_index"]
        rows = raw.iloc[first : first + len(seg)]
        np.testing.assert_allclose(seg["t"], rows[0] * 1e-3, rtol=1e-15)  # ms -> s
        np.testing.assert_allclose(seg["q"], rows[4] * 1e-3, rtol=1e-15)  # mm -> m
        np.testing.assert_allclose(seg["v1"], rows[5] * 1e5, rtol=1e-15)  # bar -> Pa
        np.testing.assert_array_equal(seg["force"], rows[6])
    if tolerance == 5.0:  # only the logging gaps of 0.3 s and 2.66 s remain
        assert [len(s) for s in segments] == [3729, 4093]
        assert dropped == [{"first_index": 0, "n_samples": 12, "t_start": 0.0}]
        assert segments[0]["t"].iloc[0] == pytest.approx(2.771)


# ------------------------------------------------------------- committed excerpt (always)
def test_excerpt_gap_error_names_file_time_length_and_count():
    with pytest.raises(RigLogError) as info:
        load_rig_log(EXCERPT, IngestSpec.from_dict(PISTON))
    message = str(info.value)
    assert f"file '{EXCERPT}'" in message
    assert "channel 'column 0'" in message
    assert "1 gap(s)" in message
    assert info.value.sample == 199 and info.value.value == pytest.approx(0.287)
    assert "t = 3.569 s (sample 199)" in message and "lasts 0.287 s" in message


def test_excerpt_split_two_segments_in_si_units():
    section = {**PISTON, "gaps": "split"}
    first, second = load_rig_log(EXCERPT, IngestSpec.from_dict(section))
    assert (len(first), len(second)) == (200, 100)
    assert first["t"].iloc[0] == pytest.approx(1.554)
    assert first["t"].iloc[-1] == pytest.approx(3.569)
    assert second["t"].iloc[0] == pytest.approx(3.856)
    assert first["q"].iloc[0] == pytest.approx(8.855e-3)
    assert first["v1"].iloc[0] == pytest.approx(7.049e5)
    assert first["force"].iloc[0] == 356.49
    assert first.attrs["units"] == {"t": "s", "q": "m", "v1": "Pa", "force": "N"}
    assert second.attrs["first_index"] == 200
    assert first.attrs["dropped_segments"] == []


def test_excerpt_min_segment_drops_short_segment_and_says_so():
    section = {**PISTON, "gaps": "split", "min_segment": 150}
    (only,) = load_rig_log(EXCERPT, IngestSpec.from_dict(section))
    assert len(only) == 200
    assert only.attrs["n_segments"] == 1
    (dropped,) = only.attrs["dropped_segments"]
    assert dropped["first_index"] == 200 and dropped["n_samples"] == 100
    assert dropped["t_start"] == pytest.approx(3.856)


def test_excerpt_all_segments_too_short():
    section = {**PISTON, "gaps": "split", "min_segment": 250}
    with pytest.raises(RigLogError) as err:
        load_rig_log(EXCERPT, IngestSpec.from_dict(section))
    assert "all 2" in str(err.value)
    assert "min_seg" in str(err.value)


def test_excerpt_time_window_before_the_gap_needs_no_split():
    section = {**PISTON, "time_window": [1.6, 3.5]}
    (df,) = load_rig_log(EXCERPT, IngestSpec.from_dict(section))
    t = pd.read_csv(EXCERPT, sep=r"\s+", header=None)[0].to_numpy() * 1e-3
    np.testing.assert_array_equal(df["t"], t[(t >= 1.6) & (t < 3.5)])
    assert len(df) == 188
    assert df.attrs["first_index"] == 5  # 1.607 s


def test_excerpt_linear_resampling_never_crosses_the_gap():
    section = {**PISTON, "gaps": "split", "resample": {"sample_time": 0.02, "method": "linear"}}
    first, second = load_rig_log(EXCERPT, IngestSpec.from_dict(section))
    assert first["t"].iloc[-1] <= 3.569 and second["t"].iloc[0] == pytest.approx(3.856)
    for seg in (first, second):
        np.testing.assert_allclose(np.diff(seg["t"]), 0.02, rtol=1e-9)
    assert first.attrs["resample"] == {"sample_time": 0.02, "method": "linear"}


def test_excerpt_polyphase_refuses_jittery_time():
    section = {**PISTON, "gaps": "split", "resample": {"sample_time": 0.02}}
    with pytest.raises(RigLogError) as err:
        load_rig_log(EXCERPT, IngestSpec.from_dict(section))
    assert "sampling" in str(err.value)
    assert 'method = "linear"' in str(err.value)


# ---------------------------------------------------------------- delimiters and headers
@pytest.mark.parametrize(
    ("text", "names"),
    [
        ("time,laser,u\n0,1,2\n1,2,3\n2,3,4\n", ["time", "laser", "u"]),
        ("\ufefftime;laser;u\n0;1;2\n1;2;3\n2;3;4\n", ["time", "laser", "u"]),
        ("time\tlaser\tu\r\n0\t1\t2\r\n1\t2\t3\r\n2\t3\t4\r\n", ["time", "laser", "u"]),
        ("  time   laser u\n 0  1   2\n1 2 3\n  2 3    4\n", ["time", "laser", "u"]),
        ("0, 1, 2\n\n1, 2, 3\n2, 3, 4\n", ["column 0", "column 1", "column 2"]),
    ],
)
def test_delimiter_and_header_detection(tmp_path, text, names):
    path = tmp_path / "log.txt"
    path.write_bytes(text.encode("utf-8"))
    section = {"time": {"column": 0, "unit": "s"}, "q": {"column": 1, "unit": "mm"}}
    section["v1"] = {"column": 2, "unit": "V"}
    raw = read_raw(path, IngestSpec.from_dict(section))
    assert raw.names == names
    (df,) = load_rig_log(path, IngestSpec.from_dict(section))
    np.testing.assert_array_equal(df.to_numpy(), [[0, 1e-3, 2], [1, 2e-3, 3], [2, 3e-3, 4]])


def test_header_false_reads_first_line_as_data(tmp_path):
    path = tmp_path / "log.csv"
    path.write_text("1,2\n3,4\n5,6\n")
    section = {"sample_time": 1.0, "q": {"column": 1, "unit": "m"}, "header": False}
    section["v1"] = {"column": 0, "unit": "V"}
    (df,) = load_rig_log(path, IngestSpec.from_dict(section))
    assert df["q"].tolist() == [2.0, 4.0, 6.0]


def test_explicit_delimiter(tmp_path):
    path = tmp_path / "log.csv"
    path.write_text("t|q|u\n0|1|2\n1|2|3\n2|3|4\n")
    section = {"time": {"name": "t", "unit": "s"}, "q": {"name": "q", "unit": "m"}}
    section.update(v1={"name": "u", "unit": "V"}, delimiter="|")
    (df,) = load_rig_log(path, IngestSpec.from_dict(section))
    assert df["v1"].tolist() == [2.0, 3.0, 4.0]


def test_name_selection_on_headerless_file_suggests_column():
    section = {**PISTON, "q": {"name": "laser", "unit": "mm"}}
    with pytest.raises(RigLogError) as err:
        load_rig_log(EXCERPT, IngestSpec.from_dict(section))
    assert "'laser'" in str(err.value)


def test_column_out_of_range():
    section = {**PISTON, "q": {"column": 7, "unit": "mm"}}
    with pytest.raises(RigLogError) as err:
        load_rig_log(EXCERPT, IngestSpec.from_dict(section))
    assert "column 7" in str(err.value)
    assert "has 7" in str(err.value)


def test_non_numeric_value_names_channel_sample_and_value(tmp_path):
    path = tmp_path / "log.csv"
    path.write_text("t,q,u\n0,1,2\n1,oops,3\n2,3,4\n")
    section = {"time": {"name": "t", "unit": "s"}, "q": {"name": "q", "unit": "m"}}
    section["v1"] = {"name": "u", "unit": "V"}
    with pytest.raises(RigLogError) as err:
        load_rig_log(path, IngestSpec.from_dict(section))
    assert err.value.path.endswith("log.csv")
    assert err.value.channel == "q"
    assert "'oops'" in str(err.value)
    assert err.value.value == "oops" and err.value.sample == 1


def test_short_row_inside_the_file_is_a_nan_with_index_and_time(tmp_path):
    path = tmp_path / "short.csv"
    path.write_text("0.0,1.0\n0.1,1.1\n0.2\n0.3,1.3\n0.4,1.4\n")  # a field lost mid-file
    section = {"time": {"column": 0, "unit": "s"}, "q": {"column": 1, "unit": "m"}}
    section["v1"] = {"column": 1, "unit": "V"}
    with pytest.raises(RigLogError) as err:
        load_rig_log(path, IngestSpec.from_dict(section))
    assert err.value.path.endswith("short.csv")
    assert err.value.channel == "column 1"
    assert err.value.sample == 2 and np.isnan(err.value.value)


# ------------------------------------------------------------------ truncated text files
CUT_SECTION = {"time": {"column": 0, "unit": "s"}, "q": {"column": 1, "unit": "m"}}
CUT_SECTION["v1"] = {"column": 2, "unit": "V"}


def _fixed_log(n: int = 40) -> list[str]:
    """A %.6f log (time, q, v1) whose last v1 is 1.609438, as a fixed-point writer has it."""
    t = np.arange(n) * 0.01
    v1 = 1.0 + 0.02 * np.arange(n) - 0.17056200000000002
    return [f"{a:.6f},{np.sin(a):.6f},{b:.6f}" for a, b in zip(t, v1, strict=True)]


def _write(path: Path, text: str) -> Path:
    if path.suffix == ".gz":
        import gzip

        path.write_bytes(gzip.compress(text.encode()))
    else:
        path.write_text(text)
    return path


@pytest.mark.parametrize("name", ["cut.csv", "cut.csv.gz"])
@pytest.mark.parametrize("cut", ["1.", "1.6", "1.60943", "1", ""])
def test_number_cut_at_the_end_names_file_and_line(tmp_path, name, cut):
    lines = _fixed_log()
    assert lines[-1].endswith(",1.609438")
    last = lines[-1].rsplit(",", 1)[0] + "," + cut
    path = _write(tmp_path / name, "t,q,v\n" + "\n".join([*lines[:-1], last]))
    with pytest.raises(RigLogError) as err:
        load_rig_log(path, IngestSpec.from_dict(CUT_SECTION))
    assert err.value.path.endswith(name)
    assert err.value.sample == 41 and "newline" in str(err.value)


@pytest.mark.parametrize("name", ["short.csv", "short.csv.gz"])
@pytest.mark.parametrize("final_newline", [True, False])
def test_last_line_with_fewer_fields_names_file_and_line(tmp_path, name, final_newline):
    lines = _fixed_log()
    text = "t,q,v\n\n" + "\n".join([*lines[:-1], lines[-1].rsplit(",", 1)[0]])
    path = _write(tmp_path / name, text + ("\n\n" if final_newline else ""))
    with pytest.raises(RigLogError) as err:
        load_rig_log(path, IngestSpec.from_dict(CUT_SECTION))
    assert err.value.path.endswith(name)
    assert err.value.sample == 42
    assert "has 2" in str(err.value)


@pytest.mark.parametrize("name", ["whole.csv", "whole.csv.gz"])
def test_honest_file_without_final_newline_reads(tmp_path, name):
    lines = _fixed_log()
    path = _write(tmp_path / name, "t,q,v\n" + "\n".join(lines))
    (df,) = load_rig_log(path, IngestSpec.from_dict(CUT_SECTION))
    assert len(df) == 40
    assert df["v1"].iloc[-1] == 1.609438


def _silverbox_lines() -> list[str]:
    import gzip

    root = Path(__file__).resolve().parents[2]
    with gzip.open(root / "data/silverbox/SNLS80mV.csv.gz", "rt") as fh:
        return fh.read().splitlines()[40650:43650]


@pytest.mark.parametrize("name", ["sb.csv", "sb.csv.gz"])
def test_silverbox_slice_without_final_newline_reads_and_its_cuts_are_caught(tmp_path, name):
    """%g-style values (5 significant digits): honest end reads, a cut to <= 3 digits fails."""
    lines = _silverbox_lines()
    section = {"sample_time": 0.0016384, "q": {"column": 1, "unit": "V"}}
    section["v1"] = {"column": 0, "unit": "V"}
    (df,) = load_rig_log(_write(tmp_path / name, "\n".join(lines)), IngestSpec.from_dict(section))
    assert len(df) == 3000
    assert df["q"].iloc[-1] == float(lines[-1].split(",")[1])
    head, value = lines[-1].split(",")
    assert value == "-0.061468"
    for cut in ("-0.06", "-0.0", "-0.", "-0", "-", ""):
        path = _write(tmp_path / name, "\n".join([*lines[:-1], f"{head},{cut}"]))
        with pytest.raises(RigLogError) as err:
            load_rig_log(path, IngestSpec.from_dict(section))
        assert err.value.path.endswith(name)
        assert err.value.sample == 3000 and "newline" in str(err.value)


def test_ragged_rows_are_a_parse_error_naming_the_file(tmp_path):
    path = tmp_path / "ragged.csv"
    path.write_text("t,q,u\n0,1,2\n1,2,3,4,5\n2,3,4\n")
    section = {"time": {"name": "t", "unit": "s"}, "q": {"name": "q", "unit": "m"}}
    section["v1"] = {"name": "u", "unit": "V"}
    with pytest.raises(RigLogError) as err:
        load_rig_log(path, IngestSpec.from_dict(section))
    assert err.value.path.endswith("ragged.csv")
    assert "delimited" in str(err.value)


@pytest.mark.parametrize("header", ["t,q,q", "t;q; q", "t q q", '"t","q","q"'])
def test_a_header_that_names_a_channel_twice_is_refused(tmp_path, header):
    """pandas would read the second ``q`` as ``q.1`` and the mapping take the first one
    silently; the file is refused, naming the channel and both columns."""
    sep = {",": ",", ";": ";", " ": " "}[next(c for c in header if c in ",; ")]
    path = tmp_path / "log.csv"
    path.write_text(header + "\n" + "\n".join(sep.join(["0", "1", "2"]) for _ in range(4)) + "\n")
    section = {"time": {"regex": "^t$", "unit": "s"}, "q": {"regex": "^q$", "unit": "mm"}}
    with pytest.raises(RigLogError) as info:
        load_rig_log(path, IngestSpec.from_dict({**section, "v1": {"column": 2, "unit": "V"}}))
    assert "'q'" in str(info.value)
    assert "columns 1" in str(info.value)
    assert "and 2" in str(info.value)
    assert str(path) in str(info.value)
