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


#: A bad [ingest] value: the key and the value the error carries, and facts its message states
#: (what the key expects: a bound, the choices, the selectors).
BAD_VALUES = [
    (
        {"format": "xlsx"},
        "ingest.format",
        "xlsx",
        ("'auto'", "'mat'", "'csv'", "'parquet'", "'mf4'"),
    ),
    ({"sample_time": -1.0}, "ingest.sample_time", -1.0, ("> 0", "got -1.0")),
    ({"sample_time": "1ms"}, "ingest.sample_time", "1ms", ("number", "got '1ms'")),
    ({"sample_time": True}, "ingest.sample_time", True, ("number", "got True")),
    ({"gap_tolerance": 1.0}, "ingest.gap_tolerance", 1.0, ("> 1", "got 1.0")),
    ({"gaps": "interpolate"}, "ingest.gaps", "interpolate", ("'error'", "'split'")),
    ({"min_segment": 2}, "ingest.min_segment", 2, (">= 3", "got 2")),
    ({"min_segment": 10.5}, "ingest.min_segment", 10.5, ("integer", "got 10.5")),
    ({"slice": [10, 5]}, "ingest.slice", [10, 5], ("[start, stop]", "start < stop", "[10, 5]")),
    ({"slice": [1, 2, 3]}, "ingest.slice", [1, 2, 3], ("[start, stop]", "got [1, 2, 3]")),
    ({"slice": [-1, 5]}, "ingest.slice", [-1, 5], ("0 <= start < stop", "got [-1, 5]")),
    ({"time_window": [3.0, 1.0]}, "ingest.time_window", [3.0, 1.0], ("start < stop", "[3.0, 1.0]")),
    ({"resample": {"method": "linear"}}, "ingest.resample.sample_time", None, ("required",)),
    ({"resample": {"sample_time": 0.1, "kind": "x"}}, "ingest.resample.kind", "x", ("unknown",)),
    ({"resample": {"sample_time": 0.1, "method": "fft"}}, "ingest.resample.method", "fft", ()),
    ({"delimiter": "ab"}, "ingest.delimiter", "ab", ("single", "got 'ab'")),
    ({"header": "yes"}, "ingest.header", "yes", ('"auto", true or false', "got 'yes'")),
    ({"smaple_time": 1e-3}, "ingest.smaple_time", 1e-3, ("unknown", "'sample_time'?")),
    ({"q": None}, "ingest.q", None, ("missing", "required")),
    ({"v1": None}, "ingest.v1", None, ("missing", "required")),
    ({"v3": {"column": 2}}, "ingest.v3", None, ("contiguous", "v1 ... vN", "`v2`")),
    ({"v0": {"column": 2}}, "ingest.v0", None, ("v1, v2",)),
    ({"v02": {"column": 2}}, "ingest.v02", None, ("v1, v2",)),
    ({"t": {"column": 2}}, "ingest.t", None, ("`time",)),
    ({"my-channel": {"column": 2}}, "ingest.my-channel", None, ("identifier",)),
    (
        {"q": {"column": 1}, "v1": {"name": "a", "column": 0}},
        "ingest.v1",
        {"name": "a", "column": 0},
        ("exactly", "`name`", "`column`"),
    ),
    ({"q": {"unit": "V"}}, "ingest.q", {"unit": "V"}, ("exactly", "`name`", "`regex`", "`column`")),
    ({"q": {"column": -1}}, "ingest.q.column", -1, (">= 0", "got -1")),
    ({"q": {"name": ""}}, "ingest.q.name", "", ("non-empty", "got ''")),
    ({"q": {"regex": "a(b"}}, "ingest.q.regex", "a(b", ("regular", "got 'a(b'")),
    ({"q": {"column": 1, "unit": "bananas"}}, "ingest.q.unit", "bananas", ("pint",)),
    ({"q": {"column": 1, "unit": "degC"}}, "ingest.q.unit", "degC", ("pint",)),
    ({"q": {"column": 1, "unit": ["V"]}}, "ingest.q.unit", ["V"], ("got ['V']",)),
    ({"q": {"column": 1, "scale": 2, "si_unit": ["m"]}}, "ingest.q.si_unit", ["m"], ("got ['m']",)),
    ({"q": {"column": 1, "unit": "V", "scale": 0}}, "ingest.q.scale", 0, ("non-zero", "got 0")),
    ({"q": {"column": 1, "si_unit": "mm"}}, "ingest.q.si_unit", "mm", ("coherent", "got 'mm'")),
    ({"q": {"column": 1, "units": "V"}}, "ingest.q.units", "V", ("unknown", "'unit'?")),
    ({"resampel": {"sample_time": 1}}, "ingest.resampel", None, ("unknown", "'resample'?")),
    (
        {"time": {"column": 0, "unit": "mm"}},
        "ingest.time.unit",
        "mm",
        ("time [s]", "got 'mm' (length [m])"),
    ),
    (
        {"q": {"column": 1, "unit": "N"}},
        "ingest.q.unit",
        "N",
        ("length [m]", "angle [rad]", "dimensionless [1]", "voltage [V]", "`q`", "(force [N])"),
    ),
    (
        {"v1": {"column": 0, "unit": "mm/s"}},
        "ingest.v1.unit",
        "mm/s",
        ("voltage [V]", "acceleration", "got 'mm/s' (velocity [m/s])"),
    ),
    (
        {"q": {"column": 1, "unit": "V", "scale": 2.0, "si_unit": "m/s"}},
        "ingest.q.si_unit",
        "m/s",
        ("length", "got 'm/s' (velocity [m/s])"),
    ),
    (
        {"q": {"column": 1, "unit": "V", "si_unit": "m"}},
        "ingest.q.si_unit",
        "m",
        ("`scale`", "`si_unit`", "another"),
    ),
    ({"time": "t"}, "ingest.time", "t", ("table", "got 't'")),
]


@pytest.mark.parametrize(("changes", "key", "value", "facts"), BAD_VALUES)
def test_bad_values_raise_workflow_error_naming_key_and_value(changes, key, value, facts):
    with pytest.raises(WorkflowError) as err:
        spec(**changes)
    assert err.value.key == key and err.value.value == value
    assert str(err.value).startswith("[ingest] ")
    for fact in facts:
        assert fact in str(err.value)


def test_csv_without_time_nor_sample_time_is_rejected_at_parse_time():
    with pytest.raises(WorkflowError) as err:
        spec(format="csv", sample_time=None)
    assert err.value.key == "ingest.format"
    assert "'csv'" in str(err.value)
    # "auto" may still find a dSPACE time base; the reader decides
    assert spec(sample_time=None).sample_time is None


def test_workflow_error_is_a_value_error():
    with pytest.raises(ValueError):
        spec(gaps="nope")


def test_section_must_be_a_table():
    with pytest.raises(WorkflowError) as err:
        IngestSpec.from_dict(["q"])  # type: ignore[arg-type]
    assert "expected" in str(err.value)
