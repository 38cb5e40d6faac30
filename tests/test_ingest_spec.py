"""IngestSpec.from_dict: the ingest section schema and its WorkflowErrors."""

from __future__ import annotations

import pytest

from pipeline.errors import WorkflowError
from pipeline.ingest import RIG_LOG_FORMATS, ChannelSpec, IngestSpec, ResampleSpec

BASE = {"sample_time": 1e-3, "q": {"column": 1, "unit": "V"}, "v1": {"column": 0, "unit": "V"}}


def spec(**changes):
    section = {**BASE, **changes}
    return IngestSpec.from_dict({k: v for k, v in section.items() if v is not None})


def test_formats_constant():
    assert RIG_LOG_FORMATS == ("auto", "mat", "csv", "parquet")


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


def test_unit_aliases_are_canonicalised():
    s = spec(q={"column": 1, "unit": "\u00b5m"})
    assert s.channels[0].unit == "um"


def test_resample_method_defaults_to_polyphase():
    assert spec(resample={"sample_time": 0.01}).resample == ResampleSpec(0.01, "polyphase")


@pytest.mark.parametrize(
    ("changes", "match"),
    [
        ({"format": "xlsx"}, r"`format` = 'xlsx'.*auto.*mat.*csv.*parquet"),
        ({"sample_time": -1.0}, r"`sample_time` = -1.0: expected a number > 0"),
        ({"sample_time": "1ms"}, r"`sample_time` = '1ms': expected a number"),
        ({"sample_time": True}, r"`sample_time` = True: expected a number"),
        ({"gap_tolerance": 1.0}, r"`gap_tolerance` = 1.0: expected a number > 1"),
        ({"gaps": "interpolate"}, r"`gaps` = 'interpolate'.*error.*split"),
        ({"min_segment": 2}, r"`min_segment` = 2: expected an integer >= 3"),
        ({"min_segment": 10.5}, r"`min_segment` = 10.5: expected an integer"),
        ({"slice": [10, 5]}, r"`slice` = \[10, 5\]: expected \[start, stop\] with start < stop"),
        ({"slice": [1, 2, 3]}, r"`slice` = \[1, 2, 3\]: expected a list of two values"),
        ({"slice": [-1, 5]}, r"`slice` = -1: expected an integer >= 0"),
        ({"time_window": [3.0, 1.0]}, r"`time_window` = \[3.0, 1.0\]: expected start < stop"),
        ({"resample": {"method": "linear"}}, r"`resample`.*missing `sample_time`"),
        ({"resample": {"sample_time": 0.1, "kind": "x"}}, r"`resample.kind` = 'x': unknown key"),
        ({"resample": {"sample_time": 0.1, "method": "fft"}}, r"`resample.method` = 'fft'"),
        ({"delimiter": "ab"}, r"`delimiter` = 'ab'"),
        ({"header": "yes"}, r"`header` = 'yes': expected \"auto\", true or false"),
        ({"smaple_time": 1e-3}, r"`smaple_time` = 0.001: unknown option; known options are"),
        ({"q": None}, r"missing required channel `q`"),
        ({"v1": None}, r"missing required channel `v1`"),
        ({"v3": {"column": 2}}, r"contiguous v1 \.\.\. vN; `v2` is missing but `v3` is given"),
        ({"v0": {"column": 2}}, r"`v0`.*inputs are named v1, v2"),
        ({"v02": {"column": 2}}, r"`v02`.*inputs are named v1, v2"),
        ({"t": {"column": 2}}, r"`t`.*map the time channel with `time"),
        ({"my-channel": {"column": 2}}, r"`my-channel`.*must be an identifier"),
        ({"q": {"column": 1}, "v1": {"name": "a", "column": 0}}, r"`v1`.*exactly one of"),
        ({"q": {"unit": "V"}}, r"`q`.*exactly one of `name`, `regex`, `column`"),
        ({"q": {"column": -1}}, r"`q.column` = -1: expected an integer >= 0"),
        ({"q": {"name": ""}}, r"`q.name` = '': expected a non-empty string"),
        ({"q": {"regex": "a(b"}}, r"`q.regex` = 'a\(b': invalid regular expression"),
        ({"q": {"column": 1, "unit": "furlong"}}, r"`q.unit` = 'furlong': unknown unit"),
        ({"q": {"column": 1, "unit": ["V"]}}, r"`q.unit` = \['V'\]: unknown unit"),
        ({"q": {"column": 1, "scale": 2, "si_unit": ["m"]}}, r"`q.si_unit` = \['m'\]"),
        ({"q": {"column": 1, "unit": "V", "scale": 0}}, r"`q.scale` = 0: expected a non-zero"),
        ({"q": {"column": 1, "si_unit": "mm"}}, r"`q.si_unit` = 'mm': expected one of"),
        ({"q": {"column": 1, "units": "V"}}, r"`q.units` = 'V': unknown key in a channel table"),
        ({"resampel": {"sample_time": 1}}, r"`resampel`.*known options are"),
        ({"time": {"column": 0, "unit": "mm"}}, r"`time.unit` = 'mm': the time channel needs"),
        ({"time": "t"}, r"`time` = 't': expected a table"),
    ],
)
def test_bad_values_raise_workflow_error_naming_key_and_value(changes, match):
    with pytest.raises(WorkflowError, match=match):
        spec(**changes)


def test_csv_without_time_nor_sample_time_is_rejected_at_parse_time():
    with pytest.raises(WorkflowError, match=r"format = 'csv' needs a time channel"):
        spec(format="csv", sample_time=None)
    # "auto" may still find a dSPACE time base; the reader decides
    assert spec(sample_time=None).sample_time is None


def test_workflow_error_is_a_value_error():
    with pytest.raises(ValueError):
        spec(gaps="nope")


def test_section_must_be_a_table():
    with pytest.raises(WorkflowError, match="expected a table"):
        IngestSpec.from_dict(["q"])  # type: ignore[arg-type]
