"""IngestSpec.from_dict: the ingest section schema and its WorkflowErrors."""

from __future__ import annotations

import pytest

from debist.core.errors import WorkflowError
from debist.ingest.load import RIG_LOG_FORMATS
from debist.ingest.spec import ChannelSpec, IngestSpec, ResampleSpec

BASE = {"sample_time": 1e-3, "q": {"column": 1, "unit": "V"}, "v1": {"column": 0, "unit": "V"}}


def spec(**changes):
    section = {**BASE, **changes}
    return IngestSpec.from_dict({k: v for k, v in section.items() if v is not None})


def test_formats_constant():
    assert RIG_LOG_FORMATS == ("auto", "mat", "csv", "parquet", "mf4")


def test_defaults():
    s = spec()
    assert s.format == "auto"
    assert s.sample_time == 1e-3
    assert s.time is None
    assert s.gap_tolerance == 1.5
    assert s.gaps == "error"
    assert s.min_segment == 100
    assert s.resample is None
    assert s.delimiter == "auto"
    assert s.header is None
    assert s.sample_slice is None and s.time_window is None
    assert s.columns == ("t", "q", "v1")
    assert s.n_inputs == 1


def test_full_section_parses_every_key():
    s = IngestSpec.from_dict(
        {
            "format": "mat",
            "sample_time": 0.0016384,
            "time": {"name": "t", "unit": "ms"},
            "q": {"regex": "Laser/q$", "unit": "mm", "scale": 2.0},
            "v1": {"name": "vir", "unit": "V"},
            "v3": {"name": "c", "unit": "kV"},
            "v2": {"regex": "Model Root/.*/v_DE2$", "unit": "kV"},
            "v1_ref": {"regex": "ref", "unit": "kV"},
            "force": {"column": 6, "unit": "V", "scale": 50.0, "si_unit": "N"},
            "slice": [40650, 105712],
            "time_window": [0, 30.5],
            "gap_tolerance": 3,
            "gaps": "split",
            "min_segment": 50,
            "resample": {"sample_time": 0.01, "method": "linear"},
            "delimiter": "tab",
            "header": False,
        }
    )
    # q, inputs in number order, then extras sorted by name
    assert s.columns == ("t", "q", "v1", "v2", "v3", "force", "v1_ref")
    assert s.n_inputs == 3
    assert s.time == ChannelSpec("t", name="t", unit="ms")
    assert s.channels[0] == ChannelSpec("q", regex="Laser/q$", unit="mm", scale=2.0)
    assert s.channels[4] == ChannelSpec("force", column=6, unit="V", scale=50.0, si_unit="N")
    assert s.sample_slice == (40650, 105712)
    assert s.time_window == (0.0, 30.5)
    assert s.gap_tolerance == 3.0
    assert s.resample == ResampleSpec(0.01, "linear")
    assert s.delimiter == "\t"
    assert s.header is False
    assert IngestSpec.from_dict(s.to_dict()) == s


def test_unit_brackets_and_dash_are_canonicalised():
    s = spec(q={"column": 1, "unit": " [\u00b5m] "}, v1={"column": 0, "unit": "-"})
    assert s.channels[0].unit == "\u00b5m"
    assert s.channels[1].unit == "1"
    # any unit pint parses; si_unit is stored as its SI symbol
    s = spec(q={"column": 1, "unit": "V", "scale": 2e-3, "si_unit": "meter"})
    assert s.channels[0].si_unit == "m"


def test_resample_method_defaults_to_polyphase():
    assert spec(resample={"sample_time": 0.01}).resample == ResampleSpec(0.01, "polyphase")


@pytest.mark.parametrize(
    ("changes", "match"),
    [
        (
            {"format": "xlsx"},
            r"^\[ingest\] format: expected 'auto', 'mat', 'csv', 'parquet' or 'mf4', got 'xlsx'$",
        ),
        ({"sample_time": -1.0}, r"^\[ingest\] sample_time: expected a number > 0, got -1.0$"),
        ({"sample_time": "1ms"}, r"^\[ingest\] sample_time: expected a number, got '1ms'$"),
        ({"sample_time": True}, r"^\[ingest\] sample_time: expected a number, got True$"),
        ({"gap_tolerance": 1.0}, r"^\[ingest\] gap_tolerance: expected a number > 1, got 1.0$"),
        ({"gaps": "interpolate"}, r"\[ingest\] gaps: expected 'error' or 'split', got 'interp"),
        ({"min_segment": 2}, r"^\[ingest\] min_segment: expected an integer >= 3, got 2$"),
        ({"min_segment": 10.5}, r"^\[ingest\] min_segment: expected an integer, got 10.5$"),
        (
            {"slice": [10, 5]},
            r"\[ingest\] slice: expected \[start, stop\].*start < stop, got \[10, 5\]",
        ),
        ({"slice": [1, 2, 3]}, r"\[ingest\] slice: expected \[start, stop\].*got \[1, 2, 3\]"),
        ({"slice": [-1, 5]}, r"\[ingest\] slice: expected .*0 <= start < stop, got \[-1, 5\]"),
        ({"time_window": [3.0, 1.0]}, r"\[ingest\] time_window: .*start < stop, got \[3.0, 1.0\]"),
        ({"resample": {"method": "linear"}}, r"\[ingest\] resample.sample_time: required key"),
        ({"resample": {"sample_time": 0.1, "kind": "x"}}, r"unknown key 'resample.kind'"),
        ({"resample": {"sample_time": 0.1, "method": "fft"}}, r"resample.method: .*got 'fft'"),
        ({"delimiter": "ab"}, r"\[ingest\] delimiter: expected .*single.*, got 'ab'$"),
        ({"header": "yes"}, r"\[ingest\] header: expected \"auto\", true or false, got 'yes'$"),
        ({"smaple_time": 1e-3}, r"unknown key 'smaple_time'; did you mean 'sample_time'\?"),
        ({"q": None}, r"\[ingest\] q: missing required channel"),
        ({"v1": None}, r"\[ingest\] v1: missing required channel"),
        ({"v3": {"column": 2}}, r"\[ingest\] v3: inputs must be contiguous v1 \.\.\. vN; `v2` is"),
        ({"v0": {"column": 2}}, r"\[ingest\] v0: inputs are named v1, v2"),
        ({"v02": {"column": 2}}, r"\[ingest\] v02: inputs are named v1, v2"),
        ({"t": {"column": 2}}, r"\[ingest\] t: map the time channel with `time"),
        ({"my-channel": {"column": 2}}, r"\[ingest\] my-channel: .*must be an identifier"),
        ({"q": {"column": 1}, "v1": {"name": "a", "column": 0}}, r"\] v1: give exactly one of"),
        ({"q": {"unit": "V"}}, r"\] q: give exactly one of `name`, `regex`, `column`"),
        ({"q": {"column": -1}}, r"^\[ingest\] q.column: expected an integer >= 0, got -1$"),
        ({"q": {"name": ""}}, r"^\[ingest\] q.name: expected a non-empty string, got ''$"),
        ({"q": {"regex": "a(b"}}, r"\[ingest\] q.regex: expected a valid regular .*, got 'a\(b'"),
        (
            {"q": {"column": 1, "unit": "bananas"}},
            r"q.unit: expected a unit pint parses.*'bananas'",
        ),
        ({"q": {"column": 1, "unit": "degC"}}, r"q.unit: expected a unit pint parses.*'degC'"),
        ({"q": {"column": 1, "unit": ["V"]}}, r"q.unit: expected .*got \['V'\]"),
        ({"q": {"column": 1, "scale": 2, "si_unit": ["m"]}}, r"q.si_unit: .*got \['m'\]"),
        ({"q": {"column": 1, "unit": "V", "scale": 0}}, r"q.scale: expected a non-zero .*got 0"),
        ({"q": {"column": 1, "si_unit": "mm"}}, r"q.si_unit: expected a coherent SI .*, got 'mm'"),
        ({"q": {"column": 1, "units": "V"}}, r"unknown key 'q.units'; did you mean 'unit'\?"),
        ({"resampel": {"sample_time": 1}}, r"unknown key 'resampel'; did you mean 'resample'\?"),
        (
            {"time": {"column": 0, "unit": "mm"}},
            r"^\[ingest\] time.unit: expected a time \[s\] unit for the time channel, got 'mm' "
            r"\(length \[m\]\)$",
        ),
        (
            {"q": {"column": 1, "unit": "N"}},
            r"^\[ingest\] q.unit: expected a length \[m\], angle \[rad\], dimensionless \[1\] "
            r"or voltage \[V\] unit for `q` .*got 'N' \(force \[N\]\)$",
        ),
        (
            {"v1": {"column": 0, "unit": "mm/s"}},
            r"^\[ingest\] v1.unit: expected a voltage \[V\], acceleration .*got 'mm/s' "
            r"\(velocity \[m/s\]\)$",
        ),
        (
            {"q": {"column": 1, "unit": "V", "scale": 2.0, "si_unit": "m/s"}},
            r"^\[ingest\] q.si_unit: expected a length .*got 'm/s' \(velocity \[m/s\]\)$",
        ),
        (
            {"q": {"column": 1, "unit": "V", "si_unit": "m"}},
            r"^\[ingest\] q.si_unit: expected `scale` with an `si_unit` of another quantity",
        ),
        ({"time": "t"}, r"^\[ingest\] time: expected a table, got 't'$"),
    ],
)
def test_bad_values_raise_workflow_error_naming_key_and_value(changes, match):
    with pytest.raises(WorkflowError, match=match):
        spec(**changes)


def test_csv_without_time_nor_sample_time_is_rejected_at_parse_time():
    with pytest.raises(WorkflowError, match=r"\[ingest\] format: 'csv' needs a time channel"):
        spec(format="csv", sample_time=None)
    # "auto" may still find a dSPACE time base; the reader decides
    assert spec(sample_time=None).sample_time is None


def test_workflow_error_is_a_value_error():
    with pytest.raises(ValueError):
        spec(gaps="nope")


def test_section_must_be_a_table():
    with pytest.raises(WorkflowError, match="expected a table"):
        IngestSpec.from_dict(["q"])  # type: ignore[arg-type]
